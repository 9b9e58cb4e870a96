"""The error that ends a `graspguide trial` run (and what the demo and sweep check their
arguments with)."""

from __future__ import annotations


class RunnerError(Exception):
    """The run cannot go on; the message says why and what to do. ``usage`` errors exit
    2, the others 1."""

    def __init__(self, message: str, usage: bool = False):
        super().__init__(message)
        self.usage = usage


__all__ = ["RunnerError"]
