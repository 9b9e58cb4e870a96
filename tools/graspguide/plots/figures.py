"""The figures of `graspguide plot` (matplotlib, Agg): a trial (the guidance error on a log
axis with the success threshold and the hold window, the PWM of each finger's motor below
it on the same time axis, the outcome and condition in the title) and a participant's
session overview (each trial's completion time in run order, successes and timeouts
marked, the sessions and their conditions as bands). The fingers have the same colours in
every figure (Okabe-Ito, readable with colour blindness and in greyscale by line width)."""

from __future__ import annotations

from typing import Any

from graspguide.core.vocabulary import FINGERS, shown
from graspguide.plots.run_folder import Criteria, Participant, TrialFrames, TrialInfo

FINGER_COLOURS = {
    "thumb": "#E69F00",
    "index": "#0072B2",
    "middle": "#009E73",
    "palm": "#CC79A7",
}
# Where motors overlap (mode C drives every active motor at full duty; every motor runs
# at the floor near the target) the thicker line of the finger before shows around the
# thinner one, the line styles differ, and each finger has its own marker at its own
# places along the line: no finger hides another, in greyscale too.
FINGER_WIDTHS = {"thumb": 4.4, "index": 3.2, "middle": 2.1, "palm": 1.2}
FINGER_STYLES = {"thumb": "-", "index": (0, (5, 1.5)), "middle": (0, (2, 1.2)), "palm": "-."}
FINGER_MARKERS = {"thumb": "o", "index": "s", "middle": "^", "palm": "D"}
# Markers along each PWM line, and the share of that spacing by which each finger's
# markers are shifted, so two fingers' markers never sit on the same sample.
PWM_MARKERS_PER_LINE = 12
ERROR_COLOUR = "black"
THRESHOLD_COLOUR = "#D55E00"
HOLD_COLOUR = "#56B4E9"
SUCCESS_COLOUR = "#0072B2"
TIMEOUT_COLOUR = "#D55E00"
FAMILIARIZATION_COLOUR = "0.55"
# The error axis is logarithmic: a 3 degree threshold is a hair above zero on a linear
# axis that must also show a 120 degree start. Fixed limits make trials comparable.
ERROR_LIMITS_DEG = (0.1, 180.0)
ERROR_TICKS_DEG = (0.1, 0.3, 1, 3, 10, 30, 90, 180)
PWM_TICKS = (0, 64, 128, 192, 255)
DPI = 200


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _seconds(x: float) -> str:
    return f"{x:.2f}".rstrip("0").rstrip(".")


def outcome_text(trial: TrialInfo, criteria: Criteria) -> str:
    """ "success at 3.75 s", "timeout at 90 s" or, for a session with no TRIAL_RESULT,
    "no result (ended at 12.3 s)"."""
    if trial.success is None:
        return "no TRIAL_RESULT (the session ended first)"
    if trial.success:
        return f"success at {_seconds(trial.completion_s or 0.0)} s"
    # A failed trial is a timeout: the record says timeout_s, the protocol's limit.
    at = trial.completion_s if trial.completion_s is not None else criteria.timeout_s
    return f"timeout at {_seconds(at)} s"


def _vector(values: list[float], scale: float = 1.0, digits: int = 2) -> str:
    # round() then + 0.0: no "-0.00" for a component that is only a rounding error.
    return "(" + ", ".join(f"{round(v * scale, digits) + 0.0:.{digits}f}" for v in values) + ")"


def trial_title(trial: TrialInfo, criteria: Criteria) -> str:
    who = (
        f"{trial.participant} trial {trial.trial}" if trial.participant else f"trial {trial.trial}"
    )
    if trial.familiarization:
        who += " (familiarization)"
    elif trial.session is not None:
        who += f", session {trial.session}"
    line1 = f"{who}: {outcome_text(trial, criteria)}"
    cond = (
        f"{shown(trial.modality)}, k = {trial.k} (policy {shown(trial.policy)}, mode {trial.mode})"
    )
    wrench = f"F = {_vector(trial.wrench[:3])} N"
    moment = trial.wrench[3:6]
    if any(moment):
        # The paper's moments are a few mN m: in N m they would all print as 0.00.
        if max(abs(m) for m in moment) < 0.1:
            wrench += f", M = {_vector(moment, 1000.0, 1)} mN m"
        else:
            wrench += f", M = {_vector(moment)} N m"
    if trial.wrench_id:
        wrench = f"{trial.wrench_id}: {wrench}"
    if trial.simulated and trial.participant:
        cond += "; SIMULATED participant"
    elif trial.simulated:  # a session: the poses did not come from a person
        cond += f"; SIMULATED (source {trial.source})" if trial.source else "; SIMULATED"
    elif not trial.participant and trial.source:
        cond += f"; source {trial.source}"
    return f"{line1}\n{cond}\nwrench {wrench}"


def trial_figure(trial: TrialInfo, frames: TrialFrames, criteria: Criteria) -> Any:
    """The figure of one trial (call ``pyplot().close(fig)`` when done)."""
    plt = pyplot()
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    fig, (ax_err, ax_pwm) = plt.subplots(
        2,
        1,
        sharex=True,
        figsize=(8.0, 5.6),
        gridspec_kw={"height_ratios": [3, 2]},
        layout="constrained",
    )
    t = frames.t_s
    end_s = max(t[-1] if t else 0.0, trial.completion_s or 0.0)
    if trial.success is False:
        end_s = max(end_s, criteria.timeout_s)
    lo, hi = ERROR_LIMITS_DEG
    ax_err.plot(
        t,
        [min(max(e, lo), hi) for e in frames.error_deg],
        color=ERROR_COLOUR,
        linewidth=1.2,
        label="error angle",
    )
    ax_err.axhline(
        criteria.threshold_deg,
        color=THRESHOLD_COLOUR,
        linestyle="--",
        linewidth=1.2,
        label=f"threshold {criteria.threshold_deg:g}°",
    )
    if trial.success and trial.completion_s is not None:
        start = max(trial.completion_s - criteria.hold_s, 0.0)
        for ax in (ax_err, ax_pwm):
            ax.axvspan(
                start,
                trial.completion_s,
                color=HOLD_COLOUR,
                alpha=0.3,
                linewidth=0,
                label=f"hold {criteria.hold_s:g} s" if ax is ax_err else None,
            )
    if trial.completion_s is not None:
        for ax in (ax_err, ax_pwm):
            ax.axvline(trial.completion_s, color="0.35", linewidth=0.8, linestyle=":")
        ax_err.annotate(
            outcome_text(trial, criteria),
            xy=(trial.completion_s, hi),
            xytext=(-4, -4),
            textcoords="offset points",
            ha="right",
            va="top",
            fontsize=9,
            color=SUCCESS_COLOUR if trial.success else TIMEOUT_COLOUR,
        )
    ax_err.set_yscale("log")
    ax_err.set_ylim(lo, hi)
    ax_err.yaxis.set_major_locator(FixedLocator(list(ERROR_TICKS_DEG)))
    ax_err.yaxis.set_minor_locator(NullLocator())
    ax_err.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax_err.set_ylabel("error angle [°], log scale")
    ax_err.set_title(trial_title(trial, criteria), fontsize=10, loc="left")
    ax_err.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    ax_err.grid(True, axis="y", color="0.9", linewidth=0.6)

    every = max(1, len(t) // PWM_MARKERS_PER_LINE)
    for i, (finger, series) in enumerate(list(zip(FINGERS, frames.pwm))[: trial.k]):
        ax_pwm.plot(
            t,
            series,
            color=FINGER_COLOURS[finger],
            linewidth=FINGER_WIDTHS[finger],
            linestyle=FINGER_STYLES[finger],
            marker=FINGER_MARKERS[finger],
            markevery=(i * every // 4, every),
            markersize=6,
            markerfacecolor="white",
            markeredgewidth=1.4,
            drawstyle="steps-post",
            label=finger,
        )
    ax_pwm.set_ylim(-8, 263)
    ax_pwm.set_yticks(list(PWM_TICKS))
    ax_pwm.set_ylabel("motor PWM duty")
    ax_pwm.set_xlabel("time since trial start [s]")
    # A little room on the right, so the hold window's end and the motors turning off at
    # the trial's end are not drawn on the frame.
    ax_pwm.set_xlim(0.0, 1.02 * end_s if end_s > 0 else 1.0)
    ax_pwm.legend(
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=9,
        frameon=False,
        title="finger",
        title_fontsize=9,
    )
    ax_pwm.grid(True, axis="y", color="0.9", linewidth=0.6)
    for ax in (ax_err, ax_pwm):
        ax.spines[["top", "right"]].set_visible(False)
    return fig


def _session_label(trials: list[TrialInfo]) -> str:
    if trials[0].familiarization:
        return "familiar-\nization"
    mods = sorted({shown(t.modality) for t in trials})
    ks = "/".join(str(k) for k in sorted({t.k for t in trials}))
    head = f"S{trials[0].session}" if trials[0].session is not None else ""
    return f"{head}\n{' '.join(mods)}\nk = {ks}"


def overview_figure(participant: Participant, criteria: Criteria) -> Any:
    """Every trial's completion time in run order, successes and timeouts marked, the
    sessions (with their condition) as bands."""
    plt = pyplot()
    trials = participant.trials
    fig, ax = plt.subplots(figsize=(max(6.0, min(14.0, 3.0 + 0.12 * len(trials))), 4.4))
    top = criteria.timeout_s
    # Sessions: runs of consecutive trials with the same session number.
    groups: list[list[TrialInfo]] = []
    for t in trials:
        if groups and groups[-1][-1].session == t.session:
            groups[-1].append(t)
        else:
            groups.append([t])
    for i, g in enumerate(groups):
        x0, x1 = g[0].trial - 0.5, g[-1].trial + 0.5
        if i % 2 == 0:
            ax.axvspan(x0, x1, color="0.93", linewidth=0)
        ax.text(
            (x0 + x1) / 2,
            top * 1.04,
            _session_label(g),
            ha="center",
            va="bottom",
            fontsize=8,
        )

    def points(keep) -> tuple[list[int], list[float]]:
        chosen = [t for t in trials if keep(t)]
        return [t.trial for t in chosen], [t.completion_s or 0.0 for t in chosen]

    ax.axhline(top, color="0.5", linestyle=":", linewidth=1.0, label=f"timeout {top:g} s")
    fam = points(lambda t: t.familiarization)
    if fam[0]:
        ax.plot(*fam, "D", color=FAMILIARIZATION_COLOUR, markersize=5, label="familiarization")
    ok = points(lambda t: not t.familiarization and t.success)
    if ok[0]:
        ax.plot(*ok, "o", color=SUCCESS_COLOUR, markersize=6, label="success")
    late = points(lambda t: not t.familiarization and not t.success)
    if late[0]:
        ax.plot(*late, "x", color=TIMEOUT_COLOUR, markersize=8, mew=2, label="timeout")
    main = [t for t in trials if not t.familiarization]
    n_ok = sum(1 for t in main if t.success)
    who = participant.pid or "session"
    title = f"{who}: completion time per trial\n{n_ok} of {len(main)} main trials succeeded"
    if any(t.simulated for t in trials):
        title += "; SIMULATED participant"
    ax.set_title(title, fontsize=10, loc="left", pad=40)
    ax.set_xlabel("trial (run order)")
    ax.set_ylabel("completion time [s]")
    ax.set_xlim(trials[0].trial - 0.5, trials[-1].trial + 0.5)
    ax.set_ylim(0, top * 1.04)
    if len(trials) <= 30:
        ax.set_xticks([t.trial for t in trials])
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    ax.spines[["top", "right"]].set_visible(False)
    fig.set_layout_engine("constrained")
    return fig


__all__ = [
    "DPI",
    "FINGER_COLOURS",
    "FINGER_MARKERS",
    "FINGER_STYLES",
    "outcome_text",
    "overview_figure",
    "pyplot",
    "trial_figure",
    "trial_title",
]
