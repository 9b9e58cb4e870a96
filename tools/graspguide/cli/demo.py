"""`graspguide demo`: the paper's study end to end, simulated (graspguide.study.demo)."""

from __future__ import annotations

import argparse

from graspguide.cli.common import (
    add_jobs_argument,
    add_protocol_argument,
    int_arg,
)

HELP = (
    "the paper's study end to end, simulated: 8 virtual "
    "participants, then Tables I-II, the ANOVA and Figure 4"
)

DESCRIPTION = """\
The paper's user study end to end, SIMULATED: the simulated device (virtual clock) and
N virtual participants U1..UN (graspguide.participant.model; a model, never human data) run
through a study protocol with `graspguide trial` (--jobs participants at a time, each
with its own simulated device), then `graspguide analyze`: prints Tables I-II and the
repeated-measures ANOVA, writes Figure 4 (PNG, SVG), report.md and CSV tables to
OUT/analysis/.

Killed or interrupted, the same command resumes: completed trials are kept (OUT/PID/
trials.jsonl, one fsync'ed line per trial) and every trial runs exactly once; a
completed study is only analysed again. Use another --out (or delete OUT) for a fresh
study.

--hostless: every participant runs host-less (`graspguide trial --hostless`): the plan
stored on the simulated device, which runs the trials from a simulated IMU on the
participant's hand and a simulated button; the log is downloaded into the study folder
(default logs/demo-hostless). SIMULATED as well.

Exit status: 0 done, 1 a participant's run or the analysis failed (its log is named),
2 usage error, 130 interrupted (run the same command again to resume).
"""

_count = int_arg(1, 256)
DEFAULT_SOURCE = "participant"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--participants",
        type=_count,
        default=8,
        metavar="N",
        help="virtual participants U1..UN (default 8, as in the paper)",
    )
    add_protocol_argument(p, required=False)
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="study folder (default: logs/demo-study in the repository); "
        "running again into it resumes or, when complete, re-analyses",
    )
    add_jobs_argument(p, "participants run")
    p.add_argument(
        "--source",
        default=DEFAULT_SOURCE,
        metavar="SPEC",
        help="the virtual participant: participant[:key=value,...] "
        "(graspguide.participant.model parameters; default: the documented "
        "defaults)",
    )
    p.add_argument(
        "--hostless",
        action="store_true",
        help="run every participant host-less on the simulated device (plan stored on the "
        "device, simulated IMU and button; `graspguide trial --hostless`); default study "
        "folder logs/demo-hostless",
    )


def run(args: argparse.Namespace) -> int:
    from graspguide.study import demo

    return demo.run(
        participants=args.participants,
        protocol=args.protocol,
        out=args.out,
        jobs=args.jobs,
        source=args.source,
        hostless=args.hostless,
    )
