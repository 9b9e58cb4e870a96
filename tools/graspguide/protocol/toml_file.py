"""Reading the project's TOML files (scene.toml, protocol files) with errors that name
the file: one place for what every loader needs."""

from __future__ import annotations

import tomllib
from typing import Any


def load_toml(path: str, error: type[Exception], what: str) -> dict[str, Any]:
    """The parsed file; ``error`` (naming the file and ``what`` it is) if it cannot be
    read or is not valid TOML."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as e:
        raise error(f"{path}: cannot read the {what}: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise error(f"{path}: not valid TOML: {e}") from None
