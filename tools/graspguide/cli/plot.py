"""`graspguide plot`: a trial's error and PWM against time, and a session overview, as PNG
and SVG (graspguide.plots)."""

from __future__ import annotations

import argparse

from graspguide.cli.common import int_arg

HELP = "draw trials (error, threshold, hold, PWM per finger) and a session overview"

DESCRIPTION = """\
Draw the trials of a run folder as PNG (200 dpi) and SVG (text kept as text):

  a trial: the guidance error angle against time (log axis) with the success threshold
  and, when it succeeded, the hold window (the final hold_s below the threshold); below
  it, on the same time axis, the PWM duty of each finger's motor (thumb, index, middle,
  palm; the same colours in every figure); the title says the outcome (success at X s,
  timeout at T s), the condition (modality, k, policy, mode) and the wrench;

  a session overview per participant: every trial's completion time in run order,
  successes and timeouts marked, the sessions and their conditions as bands.

RUN_DIR is a study folder written by `graspguide trial --out` (study.json,
PID/trials.jsonl, PID/frames/trial-NNNN.csv), one participant's folder of it, or a
session folder written by `graspguide stream --log` (config.json, telemetry.csv,
poses.csv, results.jsonl: one trial, no overview). The threshold, hold and timeout come
from the study's protocol or the session's scene. Files: OUT/PID-trial-NNNN.png/.svg
and OUT/PID-overview.png/.svg (a session folder: OUT/trial-NNNN.png/.svg); each path
written is printed."""

EPILOG = """\
examples:
  graspguide plot runs/study1 --participant U1 --trial 8
  graspguide plot runs/study1 --out figures --format svg
  graspguide plot runs/s1        # a `graspguide stream --log runs/s1` session

exit status: 0 the figures were written; 1 damaged data (a frames file cut mid-line, a
malformed record: the message names the file and line) or a file that cannot be written;
2 a usage error (no such folder, not a run folder, no such participant or trial: the
message lists what there is)."""


def formats_arg(text: str) -> list[str]:
    from graspguide.plots.command import FORMATS

    chosen = [f.strip().lower() for f in text.split(",") if f.strip()]
    bad = [f for f in chosen if f not in FORMATS]
    if bad or not chosen:
        raise argparse.ArgumentTypeError(f"--format takes png, svg or png,svg; got {text!r}")
    return list(dict.fromkeys(chosen))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "run_dir",
        metavar="RUN_DIR",
        help="study folder (graspguide trial --out), a participant's folder of it, or a "
        "session folder (graspguide stream --log)",
    )
    p.add_argument(
        "--trial",
        type=int_arg(0, 1_000_000),
        default=None,
        metavar="N",
        help="draw only trial N (trial_index of the study, trial id of a session); "
        "default: every trial and the overview",
    )
    p.add_argument(
        "--participant",
        metavar="PID",
        default=None,
        help="only this participant of a study folder (default: every one)",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="where to write the figures (default: RUN_DIR/plots)",
    )
    p.add_argument(
        "--format",
        dest="formats",
        type=formats_arg,
        default=["png", "svg"],
        metavar="png,svg",
        help="the file formats (default: png,svg)",
    )


def run(args: argparse.Namespace) -> int:
    from graspguide.plots.command import plot_command

    return plot_command(
        run_dir=args.run_dir,
        trial=args.trial,
        participant=args.participant,
        out=args.out,
        formats=args.formats,
    )
