"""How a `graspguide` command ends: its exit status (the runner processes a demo or a
sweep starts read these back) and its one-line error report on stderr."""

import sys

EXIT_OK = 0
EXIT_FAILURE = 1  # a link, disk or run error; or bad data
EXIT_USAGE = 2  # a bad option or input file: the message says what to fix
EXIT_INTERRUPTED = 130  # Ctrl-C, SIGTERM or SIGHUP (128 + SIGINT, as a shell reports it)


def report(command: str, message: object) -> None:
    """The one-line error report of ``graspguide COMMAND`` on stderr."""
    print(f"graspguide {command}: error: {message}", file=sys.stderr)


def fail(command: str, e: BaseException, code: int = EXIT_FAILURE) -> int:
    """Report ``e`` and return the exit status ``code``."""
    report(command, e)
    return code


__all__ = ["EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_INTERRUPTED", "fail", "report"]
