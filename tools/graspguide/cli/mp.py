"""`graspguide mp`: the MicroPython port (micropython/) on a board: `build` stages it
compiled, `deploy` copies it (and a plan) with mpremote, `run` starts it
(graspguide.mp)."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from graspguide.cli.common import add_action
from graspguide.cli.plan import add_plan_arguments, plan_bytes
from graspguide.exit_codes import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, fail

HELP = "the MicroPython port on a board: build it, deploy it with mpremote, run it, get its log"

DESCRIPTION = """\
The host-less mode's MicroPython port (micropython/, README: MicroPython) on a board that
runs MicroPython (ESP32, RP2040, ...):

  build   compile micropython/graspguide_mp/ with mpy-cross into --out DIR, laid out as
          the board's file system: main.py, lib/graspguide_mp/*.mpy; with --plan-protocol
          and --participant also plan.bin (graspguide plan's file), with --levels
          graspguide_levels.txt (each trial's levels, which main.py then uses instead of
          solving), with --new-store graspguide.bin (a results store holding the plan)
  deploy  build into a temporary folder (or --staging DIR) and copy it to the board on
          --port with mpremote: lib/graspguide_mp/ is replaced whole, the staged files
          written, every other file left alone (the results store too, unless --new-store)
  run     run main.py on the board now with mpremote, printing its output (Ctrl-C stops
          it); a board also runs it at power-up
  log     copy the board's results store with mpremote and download its records into
          --out DIR/<participant>/ exactly as `graspguide device log` does (the store is
          the C++ device's layout; the simulated device reads the copy)

--arch compiles native code for one board family (xtensawin: ESP32, armv6m: RP2040,
armv7emsp: RP2350 and Cortex-M4F/M7 boards); without it the .mpy files are portable
bytecode. mpremote comes from .venv (or $GRASPGUIDE_MPREMOTE)."""

EPILOG = """\
examples:
  graspguide mp build --out build/mp --plan-protocol protocols/paper.toml --participant U3
  graspguide mp deploy --port /dev/ttyUSB0 --arch xtensawin \\
      --plan-protocol protocols/paper.toml --participant U3 --levels --new-store
  graspguide mp run --port /dev/ttyUSB0

exit status: 0 done, 1 when --port is no serial port here (checked before building), or
when mpy-cross or mpremote fails or is missing, 2 on a usage error."""


# Each action's --help: (one line for `mp --help`, what it does, its examples).
_ACTION_HELP: dict[str, tuple[str, str, str]] = {
    "build": (
        "stage the compiled port (and a plan) in a folder",
        """\
Compile micropython/graspguide_mp/ with mpy-cross into --out DIR, laid out as the
board's file system: main.py and lib/graspguide_mp/*.mpy; with --plan-protocol and
--participant also plan.bin (graspguide plan's file), with --levels
graspguide_levels.txt (each trial's levels, which main.py then uses instead of
solving), with --new-store graspguide.bin (a results store holding the plan). Nothing
is copied to a board: `graspguide mp deploy` does that.""",
        """\
  graspguide mp build --out build/mp
  graspguide mp build --out build/mp --arch xtensawin \\
      --plan-protocol protocols/paper.toml --participant U3 --levels""",
    ),
    "deploy": (
        "build and copy to a board with mpremote",
        """\
Build as `graspguide mp build` does, into a temporary folder (or --staging DIR), and
copy it to the board on --port with mpremote: lib/graspguide_mp/ is replaced whole, the
staged files written, every other file left alone (the results store too, unless
--new-store, which REPLACES the board's records: download them first). --port is
checked first: a port that does not exist is refused before anything is built.""",
        """\
  graspguide mp deploy --port /dev/ttyUSB0 --arch xtensawin
  graspguide mp deploy --port /dev/ttyUSB0 --arch xtensawin \\
      --plan-protocol protocols/paper.toml --participant U3 --levels --new-store""",
    ),
    "run": (
        "start the deployed port on the board",
        """\
Run main.py on the board on --port now with mpremote and print its output until it
ends (Ctrl-C stops it); --no-follow starts it and returns. A board also runs main.py
at power-up.""",
        """\
  graspguide mp run --port /dev/ttyUSB0
  graspguide mp run --port /dev/ttyACM0 --no-follow""",
    ),
    "log": (
        "download the board's results into OUT/<participant>/",
        """\
Copy the board's results store (--store-path, main.py's graspguide.bin by default) with
mpremote and download its records into --out DIR/<participant>/ exactly as
`graspguide device log` does (the store has the C++ device's layout; the simulated
device reads the copy), so `graspguide analyze DIR` reads them.""",
        """\
  graspguide mp log --port /dev/ttyUSB0 --out runs/field
  graspguide analyze runs/field""",
    ),
}


def _add_build_arguments(p: argparse.ArgumentParser) -> None:
    from graspguide.mp.deploy import ARCHES

    p.add_argument(
        "--arch",
        choices=ARCHES,
        help="mpy-cross -march for native code (default: portable bytecode)",
    )
    p.add_argument("--src", metavar="DIR", help="the port's folder (default: micropython/)")
    add_plan_arguments(p, "--plan-protocol")
    p.add_argument(
        "--new-store",
        action="store_true",
        help="also stage a new results store (graspguide.bin) holding the plan, which "
        "micropython/main.py runs; deploying it REPLACES the board's records: download "
        "them first",
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    build = add_action(sub, "build", _ACTION_HELP)
    build.add_argument("--out", required=True, metavar="DIR", help="the staging folder")
    _add_build_arguments(build)
    deploy = add_action(sub, "deploy", _ACTION_HELP)
    deploy.add_argument("--port", required=True, metavar="PORT", help="e.g. /dev/ttyUSB0")
    deploy.add_argument(
        "--staging", metavar="DIR", help="keep the staged files here (default: a temporary folder)"
    )
    _add_build_arguments(deploy)
    run = add_action(sub, "run", _ACTION_HELP)
    run.add_argument("--port", required=True, metavar="PORT", help="e.g. /dev/ttyUSB0")
    run.add_argument("--src", metavar="DIR", help="the port's folder (default: micropython/)")
    run.add_argument(
        "--no-follow", action="store_true", help="start it and return without printing its output"
    )
    _add_log_arguments(sub)


def _add_log_arguments(sub: Any) -> None:
    from graspguide.mp.deploy import STORE_FILE

    log = add_action(sub, "log", _ACTION_HELP)
    log.add_argument("--port", required=True, metavar="PORT", help="e.g. /dev/ttyUSB0")
    log.add_argument("--out", required=True, metavar="DIR", help="the study folder")
    log.add_argument(
        "--store-path",
        default=STORE_FILE,
        metavar="PATH",
        help=f"the store file on the board (default {STORE_FILE}, main.py's)",
    )


def _build(args: argparse.Namespace, out: Path) -> None:
    from graspguide.mp.deploy import LEVELS_FILE, PLAN_FILE, STORE_FILE, build
    from graspguide.mp.plan_file import PLAN_PREAMBLE, fresh_store, levels_text

    files: dict[str, bytes] = {}
    what = "no plan"
    if args.plan_protocol:
        data, trials, levels = plan_bytes(args, args.plan_protocol)
        files[PLAN_FILE] = data
        if args.levels:
            plan = PLAN_PREAMBLE.unpack_from(data)[4]  # the preamble's CRC: the plan's id
            files[LEVELS_FILE] = levels_text(trials, levels, plan).encode()
        if args.new_store:
            files[STORE_FILE] = fresh_store(data)
        what = f"the plan of {args.participant} ({len(trials)} trials"
        what += ", with levels" if args.levels else ""
        what += ", in a NEW results store)" if args.new_store else ")"
    elif args.participant or args.new_store:
        raise ValueError("--participant and --new-store need --plan-protocol FILE")
    staged = build(out, args.src, args.arch, files)
    kind = "bytecode" if args.arch is None else args.arch
    print(f"{out}: {len(staged.files)} files ({kind}), {what}")


def _act(args: argparse.Namespace) -> int:
    from graspguide.mp.deploy import check_port, deploy_command, find_port_dir, invoke
    from graspguide.mp.run import run_command

    if args.action == "build":
        _build(args, Path(args.out))
        return EXIT_OK
    check_port(args.port)  # before a build that would be thrown away, or a claim
    if args.action == "log":
        from graspguide.mp.log import download_board_log

        s = download_board_log(args.port, args.out, args.store_path)
        kind = "SIMULATED participant" if s.simulated else "participant"
        print(
            f"{s.folder}: {s.records} record(s) of {s.plan_trials} planned trials downloaded "
            f"from {args.port} for {kind} {s.participant}; torn records: {s.torn_records}"
        )
        return EXIT_OK
    if args.action == "run":
        entry = find_port_dir(args.src) / "main.py"
        invoke(run_command(args.port, entry, follow=not args.no_follow))
        return EXIT_OK
    with tempfile.TemporaryDirectory(prefix="graspguide-mp-") as tmp:
        staging = Path(args.staging or tmp)
        _build(args, staging)
        invoke(deploy_command(args.port, staging), cwd=staging)
    print(f"deployed to {args.port}; start it with `graspguide mp run --port {args.port}`")
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    from graspguide.hostless.device_log import DeviceLogError
    from graspguide.link.transport import LinkError
    from graspguide.mp.deploy import MpToolError
    from graspguide.mp.plan_file import PlanSolveError
    from graspguide.protocol.study_protocol import ProtocolFileError

    command = f"mp {args.action}"
    try:
        return _act(args)
    except (ProtocolFileError, PlanSolveError, ValueError) as e:
        return fail(command, e, EXIT_USAGE)
    except MpToolError as e:
        return fail(command, e, EXIT_FAILURE)
    except (DeviceLogError, LinkError) as e:
        return fail(command, e, EXIT_USAGE if getattr(e, "usage", False) else EXIT_FAILURE)
    except OSError as e:
        return fail(command, e, EXIT_FAILURE)


__all__ = ["add_arguments", "run", "HELP", "DESCRIPTION", "EPILOG"]
