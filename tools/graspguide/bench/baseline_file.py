"""The regression baselines' file format, shared by the Cortex-M and AVR targets: nested
JSON objects whose leaves are {"median": N, "max": N}, at a fixed depth."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def read(path: Path, depth: int, error: type[Exception], what: str, top: str) -> dict[str, Any]:
    """The baseline at ``path``; ``error`` (with a message naming ``what`` and the fix) when
    it is missing, unreadable, or not ``depth`` levels of objects (the outer one of ``top``)
    above the leaves."""
    if not path.exists():
        raise error(f"no {what} {path}: write it with --update-baseline")
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise error(f"cannot read the {what} {path}: {e}") from None
    if not isinstance(data, dict):
        raise error(f"{what} {path}: not a JSON object of {top}")
    _check(data, depth, [], path, error, what)
    return data


def _check(node: Any, depth: int, where: list[str], path: Path, error: type[Exception], what: str):
    if depth == 0:
        if not isinstance(node, dict) or not all(
            isinstance(node.get(s), int) for s in ("median", "max")
        ):
            raise error(f'{what} {path}: {" ".join(where)} is not {{"median": N, "max": N}}')
        return
    if not isinstance(node, dict):
        raise error(f"{what} {path}: {' '.join(where) or 'the file'} is not a JSON object")
    for key, child in node.items():
        _check(child, depth - 1, [*where, str(key)], path, error, what)


def write(path: Path, data: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
