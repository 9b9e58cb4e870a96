"""The ``graspguide`` command line: one command table, one module a command.

Each command module (``graspguide.cli.<name>``) has ``HELP``, ``DESCRIPTION``, optionally
``EPILOG`` and ``RAW_DESCRIPTION = False`` (argparse's own wrapping), an
``add_arguments(parser)`` that only declares its options, and ``run(args) -> exit
status`` that calls its library function by name, each option passed as an explicit
keyword argument. The arguments they share are in
:mod:`graspguide.cli.common`, the exit statuses in :mod:`graspguide.exit_codes`. See
``graspguide COMMAND --help``.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys
from collections.abc import Iterable, Sequence
from typing import Any, TextIO

from graspguide import __version__
from graspguide.cli.common import ArgumentParser
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE

#: Every subcommand, once, in the order `graspguide --help` lists them.
COMMANDS = (
    "solve",
    "ports",
    "info",
    "stream",
    "bench",
    "trial",
    "analyze",
    "demo",
    "sweep",
    "observer",
    "device",
    "plan",
    "mp",
    "motors",
    "calibrate",
    "plot",
    "latency",
)


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="graspguide",
        description="GraspGuide host tools: hand guidance by a grasping metaphor "
        "(Algorithm 1 from the C++ core in lib/graspguide).",
        epilog="Run 'graspguide COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        command = importlib.import_module(f"graspguide.cli.{name}")
        p = sub.add_parser(
            name,
            help=command.HELP,
            description=command.DESCRIPTION,
            epilog=getattr(command, "EPILOG", None),
            formatter_class=(
                argparse.RawDescriptionHelpFormatter
                if getattr(command, "RAW_DESCRIPTION", True)
                else argparse.HelpFormatter
            ),
        )
        command.add_arguments(p)
        p.set_defaults(handler=command.run, command_parser=p)
    return parser


class _OutputPipe:
    """sys.stdout while a command runs, for the reader that stops reading (`| head`):
    the first write into the closed pipe points file descriptor 1 at /dev/null and raises
    BrokenPipeError, so the command ends on its usual error path (a device run sends STOP
    and closes its logs there); every later write, such as a status line printed while
    it cleans up, goes to /dev/null instead of raising again and cutting the clean-up
    short."""

    def __init__(self, stream: TextIO):
        self.stream = stream
        self.reader_left = False

    def _left(self, e: BrokenPipeError) -> None:
        if self.reader_left:
            return
        self.reader_left = True
        _discard_stdout(self.stream)
        raise BrokenPipeError(
            errno.EPIPE, "the output pipe closed: its reader (e.g. `| head`) stopped reading"
        ) from e

    def write(self, text: str) -> int:
        try:
            return self.stream.write(text)
        except BrokenPipeError as e:
            self._left(e)
            return len(text)

    def writelines(self, lines: Iterable[str]) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self.stream.flush()
        except BrokenPipeError as e:
            self._left(e)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


def _discard_stdout(stream: TextIO) -> None:
    """Point the stream's file descriptor at /dev/null: what is still buffered, and
    Python's flush at exit, then go nowhere instead of raising BrokenPipeError again."""
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):  # not a file (a test's capture)
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)


def main(argv: Sequence[str] | None = None) -> int:
    """Runs one command; its exit status. When the reader of the output goes away, the
    command ends without a traceback and with status 1 (unless it ended otherwise)."""
    parser = build_parser()
    stdout = sys.stdout
    pipe = _OutputPipe(stdout)
    sys.stdout = pipe  # type: ignore[assignment]
    code = EXIT_FAILURE
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help(sys.stderr)
            return EXIT_USAGE
        code = args.handler(args)
        sys.stdout.flush()  # the last lines too: a closed pipe shows here, not at exit
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    except BrokenPipeError:
        if not pipe.reader_left:  # a pipe other than stdout: not ours to hide
            raise
        code = EXIT_FAILURE
    finally:
        if sys.stdout is pipe:
            sys.stdout = stdout
    if pipe.reader_left and code == EXIT_OK:
        return EXIT_FAILURE
    return code


__all__ = ["COMMANDS", "build_parser", "main"]
