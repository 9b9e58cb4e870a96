"""`graspguide sweep`: the speed-accuracy trade, simulated (graspguide.planning.sweep)."""

from __future__ import annotations

import argparse

from graspguide.cli.common import (
    add_jobs_argument,
    add_protocol_argument,
    int_arg,
)

HELP = (
    "the speed-accuracy trade, simulated: success rate and completion "
    "time against the threshold and the pose rate, per modality"
)

DESCRIPTION = """\
The guidance speed-accuracy trade, SIMULATED: runs the study protocol with the virtual
participant on the simulated device at other alignment thresholds (--thresholds, at the
protocol's pose rate) and other pose rates (--rates, at the protocol's threshold), for
every modality, and reports success rate and completion time (failures counted as the
timeout, as the paper does) against each: OUT/sweep.json, OUT/sweep.png and a table.

Each point runs a derived protocol (same geometry, seed, conditions; --wrenches of the
seeded wrench set; no familiarization) through `graspguide trial --port sim`, one
process per (point, participant), --jobs at a time. Interrupted, the same command
resumes (completed trials are kept in OUT/points/).

Exit status: 0 done, 1 a run failed (its log is named), 2 usage error, 130 interrupted.
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    from graspguide.planning.sweep import DEFAULT_RATES, DEFAULT_SOURCE, DEFAULT_THRESHOLDS

    add_protocol_argument(p, required=False)
    for name, values, help in (
        (
            "--thresholds",
            DEFAULT_THRESHOLDS,
            "alignment thresholds in degrees, each in (0, 90), run at the protocol's pose rate",
        ),
        (
            "--rates",
            DEFAULT_RATES,
            "pose rates in Hz, each in [5, 2000], run at the protocol's threshold",
        ),
    ):
        default = ",".join(f"{v:g}" for v in values)
        p.add_argument(name, default=default, metavar="LIST", help=f"{help} (default {default})")
    p.add_argument(
        "--grid",
        action="store_true",
        help="also run every threshold x rate pair (else one factor at a time)",
    )
    for name, help in (
        (
            "--modalities",
            "modalities (F+C, Fperp+C, F+V, Fperp+V) or modes (C, V = both policies); "
            "default: the protocol's",
        ),
        ("--contacts", "contact counts, 3 and/or 4 (default: the protocol's)"),
    ):
        p.add_argument(name, default=None, metavar="LIST", help=help)
    for name, count, help in (
        ("--participants", 2, "virtual participants U1..UN per point (default 2)"),
        (
            "--wrenches",
            4,
            "target wrenches per session: the first N of the protocol's seeded draw, its "
            "single/multi split scaled (default 4)",
        ),
    ):
        p.add_argument(name, type=int_arg(1, 1000), default=count, metavar="N", help=help)
    p.add_argument(
        "--source",
        default=DEFAULT_SOURCE,
        metavar="SPEC",
        help="participant[:key=value,...] (default; told each point's threshold, "
        "hold and rate unless given here) or another simulated source of "
        "`graspguide trial` (synthetic[:...]: open loop, the same trajectory "
        "at every threshold)",
    )
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="sweep folder (default logs/guidance-sweep in the repository): "
        "points/, sweep.json, sweep.png; running again resumes",
    )
    add_jobs_argument(p, "runner processes")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def run(args: argparse.Namespace) -> int:
    from graspguide.planning import sweep

    return sweep.run(
        thresholds=args.thresholds,
        rates=args.rates,
        protocol=args.protocol,
        grid=args.grid,
        modalities=args.modalities,
        contacts=args.contacts,
        participants=args.participants,
        wrenches=args.wrenches,
        source=args.source,
        out=args.out,
        jobs=args.jobs,
        quiet=args.quiet,
    )
