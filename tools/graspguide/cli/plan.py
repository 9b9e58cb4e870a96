"""`graspguide plan`: a participant's plan as the file a MicroPython board reads
(graspguide.mp.plan_file), optionally with each trial's motor levels from the C++ core."""

from __future__ import annotations

import argparse
import os
from typing import Any

from graspguide.cli.common import (
    DEFAULT_REST_S,
    quaternion_arg,
    rest_s_arg,
)
from graspguide.exit_codes import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, fail, report

HELP = "write a participant's host-less plan file for a MicroPython board (plan.bin)"

DESCRIPTION = """\
Writes one participant's plan of --protocol to --out in the byte layout of the plan
region a C++ device stores at offset 0 (preamble, header, trials; docs/hostless.md). With
--levels a block follows with each trial's motor levels and force direction, solved once
here by the C++ core, for boards too slow to solve a posture themselves (README:
MicroPython). --calibration FILE puts the participant's calibration (the calibration.json
of `graspguide calibrate`: a PWM floor and gain per motor) into the plan; the board applies
it to every trial (default: the paper's mapping). Every trial is solved either way: a plan
the board would refuse is refused here. `graspguide mp deploy --plan-protocol` writes the
same file onto a board."""

EPILOG = """\
examples:
  graspguide plan --protocol protocols/paper.toml --participant U3 --out plan.bin
  graspguide plan --protocol protocols/paper.toml --participant U3 --levels \\
      --imu-to-hand 0.7071,0,0,0.7071 --out plan.bin
  graspguide plan --protocol protocols/paper.toml --participant U3 \\
      --calibration runs/U3/calibration.json --out plan.bin

exit status: 0 written, 1 on a write error, 2 on a usage error (a bad protocol or
participant or calibration file, a trial the core cannot solve)."""


def add_plan_arguments(p: argparse.ArgumentParser, protocol_flag: str) -> None:
    """The plan's options, shared with `graspguide mp build|deploy` (there the protocol is
    --plan-protocol and optional)."""
    # Checked in run(), not by argparse: a missing one is named there with its fix.
    p.add_argument(
        protocol_flag,
        metavar="FILE",
        help="the study protocol (protocols/paper.toml; docs/study.md): required"
        if protocol_flag == "--protocol"
        else "also write this protocol's plan of --participant as plan.bin",
    )
    p.add_argument("--participant", metavar="PID", help="U1, U2, ... (the plan's participant)")
    p.add_argument(
        "--levels",
        action="store_true",
        help="add each trial's precomputed motor levels (for boards too slow to solve)",
    )
    p.add_argument(
        "--imu-to-hand",
        type=quaternion_arg,
        default=(1.0, 0.0, 0.0, 0.0),
        metavar="W,X,Y,Z",
        help="rotation from the IMU's axes to the hand frame, scalar first (default 1,0,0,0)",
    )
    p.add_argument(
        "--rest-s",
        type=rest_s_arg,
        default=DEFAULT_REST_S,
        metavar="S",
        help=f"rest before each trial's ready pattern (default {DEFAULT_REST_S:g})",
    )
    p.add_argument(
        "--calibration",
        metavar="FILE",
        help="the participant's calibration.json (`graspguide calibrate`): per-motor PWM "
        "floor and gain, applied to every trial (default: the paper's mapping)",
    )
    p.add_argument(
        "--simulated",
        action="store_true",
        help="the participant is simulated (the records say so)",
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_plan_arguments(p, "--protocol")
    p.add_argument("--out", metavar="FILE", help="the plan file to write: required")


def plan_bytes(args: argparse.Namespace, protocol: str) -> tuple[bytes, list[Any], list[Any]]:
    """(the plan file, its PLAN_TRIALs, each trial's TrialLevels). ValueError for bad input."""
    from graspguide.calibration.calibration_file import read_calibration
    from graspguide.mp.plan_file import plan_file_for

    if not args.participant:
        raise ValueError("--participant is required with a protocol: whose plan (U1, U2, ...)")
    return plan_file_for(
        protocol_path=protocol,
        participant=args.participant,
        with_levels=args.levels,
        rest_s=args.rest_s,
        imu_to_hand_wxyz=args.imu_to_hand,
        simulated=args.simulated,
        calibration=read_calibration(args.calibration) if args.calibration else None,
    )


def run(args: argparse.Namespace) -> int:
    from graspguide.protocol.study_protocol import ProtocolFileError

    for flag, value in (("--protocol", args.protocol), ("--out", args.out)):
        if not value:
            report("plan", f"{flag} FILE is required (see `graspguide plan --help`)")
            return EXIT_USAGE
    try:
        data, trials, _ = plan_bytes(args, args.protocol)
    except (ProtocolFileError, ValueError) as e:
        return fail("plan", e, EXIT_USAGE)
    tmp = f"{args.out}.tmp"
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, args.out)  # never half a plan file under its name
    except OSError as e:
        report("plan", f"cannot write {args.out}: {e}")
        return EXIT_FAILURE
    extra = ", with each trial's motor levels" if args.levels else ""
    if args.calibration:
        extra += f", calibrated by {args.calibration}"
    n = len(trials)
    print(
        f"{args.out}: the plan of {args.participant} ({n} trials of {args.protocol}{extra}), "
        f"{len(data)} bytes; copy it to a board with `graspguide mp deploy`"
    )
    return EXIT_OK


__all__ = ["add_arguments", "add_plan_arguments", "plan_bytes", "run", "HELP", "DESCRIPTION"]
