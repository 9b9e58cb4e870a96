"""Where the GraspGuide repository is: the device builds, the Pro Mini sketch and the
simulated devices are found relative to it, from the working directory, the virtual
environment or this installed package."""

from __future__ import annotations

import os
import sys


def _candidate_roots() -> list[str]:
    """Directories that may be the repository: the working directory and its parents,
    the parent of the virtual environment (the repo keeps .venv at its top), and the
    package's own parents (a source checkout)."""
    roots: list[str] = []

    def walk(start: str) -> None:
        d = os.path.abspath(start)
        while True:
            if d not in roots:
                roots.append(d)
            parent = os.path.dirname(d)
            if parent == d:
                return
            d = parent

    try:
        walk(os.getcwd())
    except OSError:  # pragma: no cover - cwd deleted
        pass
    roots.append(os.path.dirname(os.path.abspath(sys.prefix)))
    walk(os.path.dirname(os.path.abspath(__file__)))
    return roots


def find_repo_root() -> str | None:
    """The GraspGuide repository (a directory with platformio.ini and lib/graspguide_link),
    or None."""
    for root in _candidate_roots():
        if os.path.isfile(os.path.join(root, "platformio.ini")) and os.path.isdir(
            os.path.join(root, "lib", "graspguide_link")
        ):
            return root
    return None


__all__ = ["find_repo_root"]
