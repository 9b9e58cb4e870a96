"""The ``graspguide`` command line: one command table, one module a command."""

from graspguide.cli.app import main

__all__ = ["main"]
