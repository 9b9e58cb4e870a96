"""The ``graspguide`` command line: one command table, one module a command.

Each command module (``graspguide.cli.<name>``) has ``HELP``, ``DESCRIPTION``, optionally
``EPILOG`` and ``RAW_DESCRIPTION = False`` (argparse's own wrapping), an
``add_arguments(parser)`` that only declares its options, and ``run(args) -> exit
status`` that calls the library. The arguments they share are in
:mod:`graspguide.cli.common`, the exit statuses in :mod:`graspguide.exit_codes`. See
``graspguide COMMAND --help``.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from graspguide import __version__
from graspguide.cli.common import ArgumentParser
from graspguide.exit_codes import EXIT_INTERRUPTED, EXIT_USAGE

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


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help(sys.stderr)
            return EXIT_USAGE
        return args.handler(args)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


__all__ = ["COMMANDS", "build_parser", "main"]
