"""`graspguide bench`: the host benchmark (graspguide.bench.host_bench)."""

from __future__ import annotations

import argparse

HELP = (
    "host benchmark: full frame and QP alone vs DAQP, quadprog, OSQP, "
    "scipy, with accuracy against the float64 reference"
)
DESCRIPTION = (
    "Time this project's full frame (in C++ and per Python call) and its QP "
    "alone next to DAQP, quadprog, OSQP and scipy on the same instances, "
    "judge every answer against the float64 reference, print a table. "
    "Columns: tools/README.md, 'graspguide bench'."
)
RAW_DESCRIPTION = False


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--instances",
        type=int,
        default=None,
        metavar="N",
        help="random hands per k, 0..100000 (default 200, --quick 20); each runs "
        "with the paper and the normal model, next to the paper's hand scenes",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=1,
        metavar="S",
        help="seed of the random hands, >= 0 (default 1)",
    )
    p.add_argument(
        "--k", choices=("3", "4", "both"), default="both", help="contact counts (default both)"
    )
    p.add_argument(
        "--quick", action="store_true", help="fewer instances, repetitions and passes (a smoke run)"
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        default=None,
        help="also write the full report (every figure, every failure) as JSON",
    )
    p.add_argument(
        "--solvers",
        default="daqp,quadprog,osqp,scipy-slsqp",
        metavar="LIST",
        help="peer solvers, comma-separated (default: daqp,quadprog,osqp,scipy-slsqp)",
    )
    p.add_argument(
        "--max-passes",
        type=int,
        default=None,
        metavar="N",
        help="cap on the passes of a noisy series, >= 1 (default 8, --quick 4)",
    )


def run(args: argparse.Namespace) -> int:
    # graspguide.bench (numpy, the peer solvers) is imported when the command runs, so
    # the other commands do not pay for it at start-up.
    from graspguide.bench import host_bench

    return host_bench.main_args(args)
