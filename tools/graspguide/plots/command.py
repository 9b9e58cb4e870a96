"""`graspguide plot RUN_DIR`: the PNG and SVG files of a run folder's trials and of each
participant's session overview (graspguide.plots.figures), written to --out."""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from typing import Any

from graspguide.exit_codes import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, fail, report
from graspguide.plots.run_folder import (
    PlotInputError,
    RunFolder,
    TrialInfo,
    load_frames,
    open_run,
    select_trial,
)

FORMATS = ("png", "svg")
PLOTS_DIR = "plots"
# Text stays text in the SVG (searchable, editable in a vector editor, what the tests
# read); ids and metadata are fixed so a figure redrawn from the same data is the same file.
SVG_RC = {"svg.fonttype": "none", "svg.hashsalt": "graspguide-plot"}


def save(fig: Any, stem: str, formats: Sequence[str]) -> list[str]:
    """``fig`` as ``stem.png`` (figures.DPI) and/or ``stem.svg``; the paths written."""
    from graspguide.plots.figures import DPI, pyplot

    plt = pyplot()
    paths = []
    with plt.rc_context(SVG_RC):
        for fmt in formats:
            path = f"{stem}.{fmt}"
            meta = {"Software": None} if fmt == "png" else {"Date": None}
            fig.savefig(path, dpi=DPI, metadata=meta)
            paths.append(path)
    return paths


def trial_stem(out: str, trial: TrialInfo) -> str:
    name = f"trial-{trial.trial:04d}"
    return os.path.join(out, f"{trial.participant}-{name}" if trial.participant else name)


def draw_trial(run: RunFolder, trial: TrialInfo, out: str, formats: Sequence[str]) -> list[str]:
    from graspguide.plots.figures import pyplot, trial_figure

    fig = trial_figure(trial, load_frames(trial), run.criteria)
    try:
        return save(fig, trial_stem(out, trial), formats)
    finally:
        pyplot().close(fig)


def draw_overviews(run: RunFolder, out: str, formats: Sequence[str]) -> list[str]:
    from graspguide.plots.figures import overview_figure, pyplot

    paths = []
    for p in run.participants:
        if not p.trials:
            continue
        fig = overview_figure(p, run.criteria)
        try:
            paths += save(fig, os.path.join(out, f"{p.pid}-overview"), formats)
        finally:
            pyplot().close(fig)
    return paths


def _failed(message: str) -> int:
    report("plot", message)
    return EXIT_FAILURE


def plot_command(
    *,
    run_dir: str,
    trial: int | None,
    participant: str | None,
    out: str | None,
    formats: Sequence[str],
) -> int:
    out_dir = out or os.path.join(run_dir, PLOTS_DIR)
    try:
        run = open_run(run_dir, participant)
        for line in run.left_out:
            print(f"graspguide plot: warning: {line}", file=sys.stderr, flush=True)
        trials = (
            select_trial(run, trial)
            if trial is not None
            else [t for p in run.participants for t in p.trials]
        )
        try:
            os.makedirs(out_dir, exist_ok=True)
        except OSError as e:
            return _failed(f"cannot create {out_dir}: {e.strerror or e}; give another --out")
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            return _failed("matplotlib is not installed; run tools/bootstrap.sh")
        written: list[str] = []
        # The overview first: it needs only the records, and a damaged frames file later
        # must not cost the researcher the session's picture.
        if trial is None and run.kind == "study":
            written += draw_overviews(run, out_dir, formats)
        for i, t in enumerate(trials, start=1):
            written += draw_trial(run, t, out_dir, formats)
            if len(trials) > 10 and sys.stderr.isatty():
                print(f"\r{i}/{len(trials)} trials drawn", end="", file=sys.stderr, flush=True)
        if len(trials) > 10 and sys.stderr.isatty():
            print(file=sys.stderr)
    except PlotInputError as e:
        return fail("plot", e, EXIT_USAGE if e.usage else EXIT_FAILURE)
    except OSError as e:
        return _failed(f"cannot write {e.filename or out_dir}: {e.strerror or e}")
    if run.kind == "session" and trial is None:
        print("(a session folder holds one trial: no session overview)")
    for path in written:
        print(path)
    return EXIT_OK


__all__ = ["FORMATS", "draw_overviews", "draw_trial", "plot_command", "save"]
