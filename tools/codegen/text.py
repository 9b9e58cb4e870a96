"""Text that the C++ and the Python emitters lay out alike, each in its own comment
syntax."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Protocol, TypeVar


class _Documented(Protocol):
    doc: str


T = TypeVar("T", bound=_Documented)


def documented(items: Iterable[T], comment: str, declare: Callable[[T], str]) -> list[str]:
    """Each item's declaration (``declare(item)``) under its doc, as a line opening with
    ``comment``."""
    return [line for item in items for line in (f"{comment} {item.doc}", declare(item))]
