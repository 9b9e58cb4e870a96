"""One wording for "that name is not one we know": the name, the closest known one (a
typo such as "unit" for "units" is the usual cause), and every accepted name, so the
reader can fix the input from the message alone.

    >>> unknown_name("field", "unit", ["contacts", "units"])
    'unknown field "unit" (did you mean "units"?); accepted: "contacts", "units"'
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Iterable, Sequence

# difflib's default: close enough that the suggestion is a typo of it, not a guess.
CUTOFF = 0.6


def _quoted(name: object, limit: int = 40) -> str:
    text = json.dumps(name, ensure_ascii=True) if isinstance(name, str) else repr(name)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def closest(name: object, accepted: Iterable[str]) -> str | None:
    """The accepted name most like ``name`` (exact but for case first), or None."""
    names = list(accepted)
    text = str(name)
    for a in names:
        if a.lower() == text.lower():
            return a
    close = difflib.get_close_matches(text, names, n=1, cutoff=CUTOFF)
    return close[0] if close else None


def did_you_mean(name: object, accepted: Iterable[str]) -> str:
    """' (did you mean "x"?)' for the closest accepted name, or '' when none is close."""
    close = closest(name, accepted)
    return f" (did you mean {_quoted(close)}?)" if close is not None else ""


def unknown_name(what: str, name: object, accepted: Sequence[str]) -> str:
    """'unknown WHAT "name" (did you mean "x"?); accepted: "a", "b", ...'."""
    listed = ", ".join(_quoted(a) for a in accepted)
    return f"unknown {what} {_quoted(name)}{did_you_mean(name, accepted)}; accepted: {listed}"


__all__ = ["CUTOFF", "closest", "did_you_mean", "unknown_name"]
