"""`graspguide sweep`: the guidance speed-accuracy trade, SIMULATED.

For every modality of the protocol (F+C, Fperp+C, F+V, Fperp+V by default) it runs the
study protocol (default ``protocols/paper.toml``) again at other alignment thresholds and
other pose rates, with the virtual participant (:mod:`graspguide.participant.model`, a model,
never human data) on the simulated device (virtual clock), and reports success rate and
completion time against each.

Points: one factor at a time around the protocol's values (the paper's 3 deg / 100 Hz):
every ``--thresholds`` value at the protocol's pose rate, every ``--rates`` value at the
protocol's threshold; with ``--grid`` also every threshold x rate pair.

Each point is a derived protocol, written to ``OUT/points/<point>/protocol.toml``: the
same geometry, seed, conditions and orders, with ``[trial] threshold_deg`` or
``[study] pose_rate_hz`` changed, ``[wrenches] count`` = ``--wrenches`` (the first
wrenches of the paper's seeded draw, the single/multi split scaled), and no
familiarization trials. Each (point, participant) is one ``graspguide trial --port sim``
process (the runner's public interface: its pipelining and speed come for free), ``--jobs``
at a time. The virtual participant is told the point's threshold and hold
(``task_threshold_deg``, ``task_hold_s``; a person is told them in the instructions and
feels them in familiarization) and runs at the point's rate (``rate_hz``).

Resume: a point's folder is the runner's study folder (named by the derived protocol's
config hash); completed trials are kept, so running the same command again only runs
what is missing, and a larger ``--participants`` only adds participants.

Output: ``OUT/sweep.json`` (every point and modality: trials, successes, success rate,
completion time median / mean / SD with failures counted as the timeout (90 s) as the
paper does, and median / mean over successes), ``OUT/sweep.png`` (two rows: against the
threshold and against the pose rate; columns success rate and completion time; one line
per modality) and a table on stdout. Everything is labelled SIMULATED.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import statistics
import sys
import time
from collections.abc import Sequence
from typing import Any

from graspguide.analysis.trial_figure import sd_range
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE
from graspguide.records.files import ParticipantFiles
from graspguide.records.storage import write_file_whole, write_json_file
from graspguide.study.jobs import (
    TrialJob,
    count_lines,
    default_protocol,
    run_trial_jobs,
)
from graspguide.study.jobs import (
    default_out as _default_out,
)
from graspguide.study.jobs import (
    repo_root as _repo_root,
)

SWEEP_FORMAT = "graspguide-sweep/1"
DEFAULT_THRESHOLDS = (1.0, 2.0, 3.0, 5.0, 7.0, 10.0)
DEFAULT_RATES = (30.0, 60.0, 100.0, 240.0)
DEFAULT_SOURCE = "participant"
SIMULATED_NOTE = (
    "SIMULATED: virtual participants (graspguide.participant.model, a model of a "
    "person) on the simulated device; not human data"
)


class SweepError(ValueError):
    """A bad sweep argument or protocol; the message says what to use instead."""


# --------------------------------------------------------------------------------------
# Arguments
# --------------------------------------------------------------------------------------
def parse_values(text: str, what: str, lo: float, hi: float) -> tuple[float, ...]:
    """Comma-separated positive numbers in (lo, hi], sorted, without repeats."""
    items = [s.strip() for s in str(text).split(",")]
    if not items or any(not s for s in items):
        raise SweepError(
            f"--{what}: expected comma-separated numbers such as "
            f"{'1,2,3,5' if what == 'thresholds' else '30,60,100'}, got {text!r}"
        )
    out = []
    for s in items:
        try:
            v = float(s)
        except ValueError:
            raise SweepError(f"--{what}: {s!r} is not a number") from None
        if not math.isfinite(v) or v <= lo or v > hi:
            unit = "degrees" if what == "thresholds" else "poses per second"
            raise SweepError(
                f"--{what}: {s} is out of range: each value must be > {lo:g} and <= {hi:g} {unit}"
            )
        out.append(v)
    return tuple(sorted(set(out)))


def parse_modalities(text: str) -> tuple[str, ...]:
    from graspguide.core.vocabulary import MODALITIES

    items = [s.strip() for s in str(text).split(",") if s.strip()]
    if not items:
        raise SweepError("--modalities: give at least one of " + ", ".join(MODALITIES))
    out: list[str] = []
    for s in items:
        if s in MODALITIES:
            picked = [s]
        elif s in ("C", "V"):  # a mode: both policies
            picked = [f"F+{s}", f"Fperp+{s}"]
        else:
            raise SweepError(
                f"--modalities: unknown modality or mode {s!r}; use "
                + ", ".join(MODALITIES)
                + " or a mode C, V (both policies)"
            )
        out += [m for m in picked if m not in out]
    return tuple(out)


def default_out() -> str:
    return _default_out("guidance-sweep")


# --------------------------------------------------------------------------------------
# Points and derived protocols
# --------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Point:
    threshold_deg: float
    pose_rate_hz: float
    axes: tuple[str, ...]  # "threshold", "rate", "grid": which plots it is on

    @property
    def key(self) -> tuple[float, float]:
        return (self.threshold_deg, self.pose_rate_hz)


def sweep_points(
    thresholds: Sequence[float],
    rates: Sequence[float],
    base_threshold: float,
    base_rate: float,
    grid: bool = False,
) -> list[Point]:
    """One factor at a time around (base_threshold, base_rate), plus the grid if asked;
    every (threshold, rate) once, the base point always included."""
    axes: dict[tuple[float, float], list[str]] = {}

    def add(t: float, r: float, axis: str) -> None:
        lst = axes.setdefault((float(t), float(r)), [])
        if axis not in lst:
            lst.append(axis)

    for t in thresholds:
        add(t, base_rate, "threshold")
    for r in rates:
        add(base_threshold, r, "rate")
    add(base_threshold, base_rate, "threshold")
    add(base_threshold, base_rate, "rate")
    if grid:
        for t in thresholds:
            for r in rates:
                add(t, r, "grid")
    return [Point(t, r, tuple(a)) for (t, r), a in sorted(axes.items())]


def derive_protocol(
    base,
    threshold_deg: float,
    pose_rate_hz: float,
    wrenches: int,
    modalities: Sequence[str] | None = None,
    contacts: Sequence[int] | None = None,
):
    """The protocol of one point: ``base`` with the threshold and pose rate changed,
    ``wrenches`` wrenches (single-motor share scaled), no familiarization trials."""
    from graspguide.protocol.study_protocol import ProtocolFileError

    if threshold_deg >= base.start_error_deg[0]:
        raise SweepError(
            f"threshold {threshold_deg:g} deg: must be below the protocol's "
            f"smallest start error ({base.start_error_deg[0]:g} deg, [wrenches] "
            "start_error_deg), or a trial could start aligned"
        )
    single = int(math.floor(wrenches * base.single_motor / base.wrench_count + 0.5))
    single = max(0, min(wrenches, single))
    changes: dict[str, Any] = dict(
        name=f"{base.name}-sweep",
        threshold_deg=float(threshold_deg),
        pose_rate_hz=float(pose_rate_hz),
        wrench_count=int(wrenches),
        single_motor=single,
        familiarization_trials=0,
    )
    if modalities is not None:
        changes["modalities"] = tuple(modalities)
    if contacts is not None:
        missing = [k for k in contacts if k not in base.hands]
        if missing:
            raise SweepError(f"--contacts: the protocol has no [hand.k{missing[0]}]")
        changes["contact_counts"] = tuple(contacts)
    try:
        return dataclasses.replace(base, **changes)
    except (TypeError, ProtocolFileError) as e:  # pragma: no cover - defensive
        raise SweepError(str(e)) from None


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def protocol_toml(protocol) -> str:
    """A protocol file (metres) that loads back to ``protocol`` (same config hash)."""
    from graspguide.core.vocabulary import FINGERS

    d = protocol.to_dict()
    lines = [f"# A point of `graspguide sweep` (SIMULATED): derived from {protocol.source}", ""]
    for table in ("study", "trial"):
        lines.append(f"[{table}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in d[table].items()]
        lines.append("")
    lines += ["[hand]", 'units = "m"', f"y_axis = {_toml_value(d['hand']['y_axis'])}", ""]
    for k in sorted(protocol.hands):
        lines.append(f"[hand.k{k}]")
        for name, c in zip(FINGERS, protocol.hands[k]):
            lines.append(f"{name} = {_toml_value(list(c))}")
        lines.append("")
    for table in ("conditions", "wrenches", "familiarization"):
        lines.append(f"[{table}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in d[table].items()]
        lines.append("")
    return "\n".join(lines)


def point_source(spec: str, point: Point, hold_s: float) -> str:
    """The --source of a point: the virtual participant is told the point's threshold and
    hold and runs at its rate, unless the spec sets those keys itself."""
    kind, sep, rest = spec.partition(":")
    if kind != "participant":
        return spec
    given = {item.partition("=")[0].strip() for item in rest.split(",") if item.strip()}
    extra = []
    for key, value in (
        ("task_threshold_deg", point.threshold_deg),
        ("task_hold_s", hold_s),
        ("rate_hz", point.pose_rate_hz),
    ):
        if key not in given:
            extra.append(f"{key}={value:g}")
    items = [s for s in rest.split(",") if s.strip()] + extra
    return "participant" + (":" + ",".join(items) if items else "")


def point_dir_name(point: Point, protocol) -> str:
    return f"t{point.threshold_deg:g}_r{point.pose_rate_hz:g}_{protocol.config_hash[:10]}"


# --------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------
def _r(x: float | None, nd: int = 3) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), nd)


def summarize(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Success rate and completion time of main trials (failures count as the timeout,
    which the runner records as their completion_s)."""
    n = len(records)
    times = [float(r["completion_s"]) for r in records]
    ok = [float(r["completion_s"]) for r in records if r["success"]]
    return {
        "trials": n,
        "successes": len(ok),
        "success_rate": _r(len(ok) / n, 4) if n else None,
        "completion_median_s": _r(statistics.median(times)) if n else None,
        "completion_mean_s": _r(statistics.fmean(times)) if n else None,
        "completion_sd_s": _r(statistics.stdev(times)) if n > 1 else None,
        "success_completion_median_s": _r(statistics.median(ok)) if ok else None,
        "success_completion_mean_s": _r(statistics.fmean(ok)) if ok else None,
        "final_error_median_deg": _r(
            statistics.median(float(r["final_error_deg"]) for r in records)
        )
        if n
        else None,
        "poses": int(sum(int(r.get("poses", 0)) for r in records)),
    }


def read_point_trials(study_dir: str, participants: Sequence[str]) -> list[dict[str, Any]]:
    from graspguide.records.storage import read_jsonl

    out: list[dict[str, Any]] = []
    for pid in participants:
        path = ParticipantFiles.of(study_dir, pid).trials
        if os.path.exists(path):
            out += [r for r in read_jsonl(path).records if not r.get("familiarization")]
    return out


def threshold_pairs(by_threshold: dict[float, list[dict[str, Any]]]) -> dict[str, Any]:
    """The same (participant, trial) at neighbouring thresholds (same rate): how often the
    larger threshold took longer. For an open-loop source (the same trajectory whatever
    the threshold) never; for the closed-loop participant it can (the cue and its search
    change with the threshold)."""
    ts = sorted(by_threshold)
    pairs = longer = 0
    worst = 0.0
    for a, b in zip(ts, ts[1:]):
        ia = {(r["participant"], r["trial_index"]): r for r in by_threshold[a]}
        for r in by_threshold[b]:
            q = ia.get((r["participant"], r["trial_index"]))
            if q is None:
                continue
            pairs += 1
            d = float(r["completion_s"]) - float(q["completion_s"])
            if d > 1e-9:
                longer += 1
                worst = max(worst, d)
    return {"pairs": pairs, "larger_threshold_took_longer": longer, "largest_increase_s": _r(worst)}


# --------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------
def _run_tasks(tasks: list[TrialJob], jobs: int, quiet: bool, err) -> int:
    """Run the tasks' `graspguide trial` processes, ``jobs`` at a time (tag: the point)."""
    if not tasks:
        return EXIT_OK
    done = [0]

    def on_exit(t: TrialJob, rc: int) -> None:
        done[0] += 1
        pt, planned = t.tag
        where = f"threshold {pt.threshold_deg:g} deg, rate {pt.pose_rate_hz:g} Hz, {t.participant}"
        if rc != 0:
            print(
                f"graspguide sweep: {where}: `graspguide trial` exited with {rc}; see {t.log}",
                file=err,
                flush=True,
            )
        elif not quiet:
            print(
                f"  [{done[0]}/{len(tasks)}] {where}: {t.completed_trials()}/{planned} "
                "trials (simulated)",
                flush=True,
            )

    interrupted, failed = run_trial_jobs(tasks, jobs, on_exit)
    if interrupted:
        print(
            "\ngraspguide sweep: interrupted; completed trials are kept: run the same "
            "command again to resume",
            file=err,
        )
        return EXIT_INTERRUPTED
    if failed:
        print(
            f"graspguide sweep: error: {len(failed)} runner process(es) failed; completed "
            "trials are kept: fix the cause and run the same command again",
            file=err,
        )
        return EXIT_FAILURE
    return EXIT_OK


def _fmt(x: float | None, spec: str = "5.1f") -> str:
    return "-" if x is None else format(x, spec)


def table_lines(result: dict[str, Any]) -> list[str]:
    head = (
        f"{'axis':<9} {'thr':>5} {'rate':>5}  {'modality':<8} {'success':>13}  "
        f"{'median':>6}  {'mean +- SD':>13}  {'med.succ':>8}"
    )
    lines = [
        "SIMULATED (virtual participants, not human data); completion time in s, "
        f"failures counted as {result['timeout_s']:g} s",
        head,
        "-" * len(head),
    ]
    for pt in result["points"]:
        named = [a for a in pt["axes"] if a != "grid"]
        axis = "base" if len(named) == 2 else (named[0] if named else "grid")
        for m, s in pt["modalities"].items():
            rate = "-" if s["success_rate"] is None else f"{100 * s['success_rate']:.0f}%"
            succ = f"{s['successes']}/{s['trials']} {rate:>4}"
            ms = f"{_fmt(s['completion_mean_s'])} +- {_fmt(s['completion_sd_s'], '4.1f')}"
            lines.append(
                f"{axis:<9} {pt['threshold_deg']:>5g} {pt['pose_rate_hz']:>5g}  "
                f"{m:<8} {succ:>13}  {_fmt(s['completion_median_s'], '6.1f')}  "
                f"{ms:>13}  {_fmt(s['success_completion_median_s'], '8.2f')}"
            )
    return lines


# Each modality's look in the sweep figure: colour, marker and line style all differ, so
# lines that meet (every modality at 100 % success) stay apart to the eye, in greyscale
# too; the markers shrink down the list, so a later one sits inside an earlier one.
SWEEP_STYLES: dict[str, dict[str, Any]] = {
    "F+C": {"color": "tab:blue", "marker": "o", "linestyle": "-", "markersize": 9},
    "Fperp+C": {"color": "tab:cyan", "marker": "s", "linestyle": "--", "markersize": 7.5},
    "F+V": {"color": "tab:red", "marker": "^", "linestyle": "-.", "markersize": 6.5},
    "Fperp+V": {"color": "tab:orange", "marker": "D", "linestyle": (0, (1, 1.2)), "markersize": 5},
}
_EXTRA_MARKERS = ("v", "P", "X", "*")


def _style(m: str, j: int) -> dict[str, Any]:
    return SWEEP_STYLES.get(
        m, {"marker": _EXTRA_MARKERS[j % len(_EXTRA_MARKERS)], "linestyle": "-", "markersize": 6}
    )


def _dodged(xs: Sequence[float], j: int, n: int, log: bool) -> list[float]:
    """The x positions of modality ``j`` of ``n``, moved a little apart so that equal
    values of two modalities do not hide each other (by a factor on a log axis)."""
    k = j - (n - 1) / 2
    if log:
        return [x * (1.0 + 0.035 * k) for x in xs]
    return [x + 0.1 * k for x in xs]


def sweep_figure(result: dict[str, Any]) -> Any:
    """Two rows (against the threshold, against the pose rate), two columns (success rate,
    completion time: mean +- SD with failures as the timeout, the bar cut at 0 s and the
    timeout; median over successes, dotted); one line per modality, each with its own
    colour, marker and line style, dodged sideways. Close it with ``plt.close(fig)``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from graspguide.core.vocabulary import shown

    mods = result["modalities"]
    timeout_s = float(result["timeout_s"])
    fig, axes = plt.subplots(2, 2, figsize=(11, 8.2))
    rows = (
        (
            "threshold",
            "threshold_deg",
            f"alignment threshold [deg] (at {result['base']['pose_rate_hz']:g} Hz)",
        ),
        (
            "rate",
            "pose_rate_hz",
            f"pose rate [Hz], log scale (at {result['base']['threshold_deg']:g} deg)",
        ),
    )
    for row, (axis, key, label) in enumerate(rows):
        pts = sorted((p for p in result["points"] if axis in p["axes"]), key=lambda p: p[key])
        xs = [p[key] for p in pts]
        log = row == 1 and min(xs) > 0
        for j, m in enumerate(mods):
            style = _style(m, j)
            off = _dodged(xs, j, len(mods), log)
            sr = [p["modalities"][m]["success_rate"] for p in pts]
            axes[row][0].plot(
                off,
                [math.nan if v is None else 100 * v for v in sr],
                markerfacecolor="none",
                markeredgewidth=1.6,
                label=shown(m),
                **style,
            )
            mean = [p["modalities"][m]["completion_mean_s"] for p in pts]
            sd = [p["modalities"][m]["completion_sd_s"] for p in pts]
            below, above = zip(*(sd_range(mu, s, timeout_s) for mu, s in zip(mean, sd)))
            axes[row][1].errorbar(
                off,
                [math.nan if v is None else v for v in mean],
                yerr=[list(below), list(above)],
                capsize=3,
                markerfacecolor="none",
                markeredgewidth=1.6,
                label=shown(m),
                **style,
            )
            med = [p["modalities"][m]["success_completion_median_s"] for p in pts]
            axes[row][1].plot(
                off,
                [math.nan if v is None else v for v in med],
                linestyle=":",
                marker="x",
                color=style.get("color"),
                linewidth=1.0,
            )
        axes[row][0].set_ylabel("success rate [%]")
        axes[row][0].set_ylim(-3, 125)  # room for the legend above 100 %
        axes[row][0].set_yticks(range(0, 101, 20))
        axes[row][1].set_ylabel(f"completion time [s] (failure = {timeout_s:g} s)")
        axes[row][1].set_ylim(0, timeout_s * 1.4)  # room for the legend
        axes[row][1].axhline(timeout_s, color="0.6", linewidth=0.8, linestyle="--")
        for ax in axes[row]:
            ax.set_xlabel(label)
            ax.grid(True, alpha=0.3)
            if log:
                ax.set_xscale("log")
                ax.set_xticks(xs)
                ax.set_xticklabels([f"{x:g}" for x in xs])
                ax.minorticks_off()
            else:
                ax.set_xticks(xs)
        # Above the 100 % line, where no rate can be: a legend inside the data covers
        # points wherever the rates happen to fall.
        axes[row][0].legend(fontsize=8, loc="upper center", ncol=len(mods))
    handles = [
        Line2D([], [], markerfacecolor="none", label=shown(m), **_style(m, j))
        for j, m in enumerate(mods)
    ] + [
        Line2D(
            [],
            [],
            color="gray",
            marker="o",
            markerfacecolor="none",
            label=f"mean +- SD (within 0..{timeout_s:g} s), failure = {timeout_s:g} s",
        ),
        Line2D([], [], color="gray", marker="x", linestyle=":", label="median of successes"),
    ]
    axes[0][1].legend(handles=handles, fontsize=7, loc="upper right", ncol=3)
    size = (
        f"{result['participants']} virtual participants x {result['wrenches']} wrenches x "
        f"k = {','.join(str(k) for k in result['contact_counts'])} per modality and point"
    )
    fig.suptitle(
        "SIMULATED guidance speed-accuracy trade (virtual participant model, not "
        f"human data)\n{size}",
        fontsize=11,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    return fig


def plot(result: dict[str, Any], path: str) -> None:
    """:func:`sweep_figure` saved as ``path`` (PNG)."""
    import matplotlib.pyplot as plt

    fig = sweep_figure(result)
    try:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        fig.savefig(path, dpi=110)
    finally:
        plt.close(fig)


def _shown_path(path: str) -> str:
    """A path relative to the repository when inside it (for committed outputs)."""
    root = _repo_root()
    full = os.path.abspath(path)
    if root and os.path.commonpath([full, os.path.abspath(root)]) == os.path.abspath(root):
        return os.path.relpath(full, root)
    return path


def run_sweep(
    protocol_path: str,
    thresholds: Sequence[float],
    rates: Sequence[float],
    participants: int,
    wrenches: int,
    out: str,
    jobs: int,
    source: str,
    *,
    modalities: Sequence[str] | None = None,
    contacts: Sequence[int] | None = None,
    grid: bool = False,
    quiet: bool = False,
    err=None,
) -> tuple[int, dict[str, Any] | None]:
    """Run (or resume) the sweep into ``out``; returns (exit status, result dict)."""
    from graspguide.protocol.study_protocol import load_protocol, plan
    from graspguide.run_errors import RunnerError
    from graspguide.sources.trial_sources import open_runner_source

    err = err or sys.stderr
    t0 = time.monotonic()
    base = load_protocol(protocol_path)
    pts = sweep_points(thresholds, rates, base.threshold_deg, base.pose_rate_hz, grid)
    pids = [f"U{i}" for i in range(1, participants + 1)]
    tasks: list[TrialJob] = []
    plan_info: list[tuple[Point, Any, str, str]] = []
    # check every point before writing anything
    derived = []
    for pt in pts:
        proto = derive_protocol(
            base, pt.threshold_deg, pt.pose_rate_hz, wrenches, modalities, contacts
        )
        spec = point_source(source, pt, base.hold_s)
        try:
            src = open_runner_source(spec, proto, "U1")
        except RunnerError as e:
            raise SweepError(str(e)) from None
        if not src.simulated or getattr(src, "live", False):
            raise SweepError(
                f"--source {source}: the sweep runs simulated sources only "
                "(participant[:...], synthetic[:...])"
            )
        derived.append((pt, proto, spec))
    for pt, proto, spec in derived:
        study_dir = os.path.join(out, "points", point_dir_name(pt, proto))
        os.makedirs(study_dir, exist_ok=True)
        ppath = os.path.join(study_dir, "protocol.toml")
        text = protocol_toml(proto)
        if not os.path.exists(ppath) or open(ppath, encoding="utf-8").read() != text:
            write_file_whole(ppath, lambda f, text=text: f.write(text))
        check = load_protocol(ppath)
        if check.config_hash != proto.config_hash:  # pragma: no cover - writer bug
            raise SweepError(f"{ppath}: does not load back to the derived protocol")
        planned = len(plan(check, "U1"))
        plan_info.append((pt, check, study_dir, spec))
        for pid in pids:
            if count_lines(ParticipantFiles.of(study_dir, pid).trials) >= planned:
                continue
            tasks.append(
                TrialJob(
                    ppath,
                    study_dir,
                    pid,
                    spec,
                    os.path.join(study_dir, "logs", f"{pid}.log"),
                    tag=(pt, planned),
                )
            )
    n_trials = sum(len(plan(p, "U1")) for _, p, _, _ in plan_info) * len(pids)
    if not quiet:
        print(
            f"{SIMULATED_NOTE}.\nSweep of {protocol_path}: {len(pts)} points x "
            f"{len(pids)} participants = {n_trials} trials; {len(tasks)} runner processes "
            f"to run, {jobs} at a time; folder {out}",
            flush=True,
        )
    # the slow points (small threshold, high rate) first, so the pool ends together
    tasks.sort(key=lambda t: t.tag[0].pose_rate_hz / t.tag[0].threshold_deg, reverse=True)
    code = _run_tasks(tasks, jobs, quiet, err)
    if code != EXIT_OK:
        return code, None
    run_s = time.monotonic() - t0

    mods = list(plan_info[0][1].modalities)
    points_out = []
    by_threshold: dict[str, dict[float, list[dict[str, Any]]]] = {m: {} for m in mods}
    all_by_threshold: dict[float, list[dict[str, Any]]] = {}
    for pt, proto, study_dir, spec in plan_info:
        recs = read_point_trials(study_dir, pids)
        expected = len(plan(proto, "U1")) * len(pids)
        if len(recs) != expected:
            raise SweepError(f"{study_dir}: {len(recs)} trials recorded, {expected} planned")
        if not all(r.get("simulated") for r in recs):
            raise SweepError(f"{study_dir}: holds trials not marked simulated")
        per_mod = {m: summarize([r for r in recs if r["modality"] == m]) for m in mods}
        per_mode = {
            mode: summarize([r for r in recs if r["mode"] == mode])
            for mode in sorted({r["mode"] for r in recs})
        }
        points_out.append(
            {
                "threshold_deg": pt.threshold_deg,
                "pose_rate_hz": pt.pose_rate_hz,
                "axes": list(pt.axes),
                "folder": os.path.relpath(study_dir, out),
                "config_hash": proto.config_hash,
                "source": spec,
                "modalities": per_mod,
                "modes": per_mode,
                "modes_by_contacts": {
                    f"k{k}/{mode}": summarize(
                        [r for r in recs if r["k"] == k and r["mode"] == mode]
                    )
                    for k in proto.contact_counts
                    for mode in sorted(per_mode)
                },
                "all": summarize(recs),
            }
        )
        if "threshold" in pt.axes:
            all_by_threshold[pt.threshold_deg] = recs
            for m in mods:
                by_threshold[m][pt.threshold_deg] = [r for r in recs if r["modality"] == m]
    proto0 = plan_info[0][1]
    result = {
        "format": SWEEP_FORMAT,
        "simulated": True,
        "note": SIMULATED_NOTE,
        "protocol_file": _shown_path(protocol_path),
        "base_config_hash": base.config_hash,
        "base": {"threshold_deg": base.threshold_deg, "pose_rate_hz": base.pose_rate_hz},
        "hold_s": base.hold_s,
        "timeout_s": base.timeout_s,
        "source": source,
        "participants": len(pids),
        "wrenches": wrenches,
        "wrench_ids": [
            w for w in sorted({r["wrench_id"] for r in read_point_trials(plan_info[0][2], pids)})
        ],
        "contact_counts": list(proto0.contact_counts),
        "modalities": mods,
        "trials_per_point": len(plan(proto0, "U1")) * len(pids),
        "thresholds_deg": list(thresholds),
        "rates_hz": list(rates),
        "grid": grid,
        "completion_rule": (
            f"a failure counts as the timeout ({base.timeout_s:g} s), as the "
            "paper reports; success_completion_* are over successes only"
        ),
        "threshold_pairs": {
            "all": threshold_pairs(all_by_threshold),
            **{m: threshold_pairs(v) for m, v in by_threshold.items()},
        },
        "points": points_out,
        "run_wall_s": round(run_s, 1),
        "runner_processes_run": len(tasks),
        "jobs": jobs,
        "command": None,
    }
    return EXIT_OK, result


def command_line(
    protocol: str | None,
    thresholds: str,
    rates: str,
    grid: bool,
    modalities: str | None,
    contacts: str | None,
    participants: int,
    wrenches: int,
    source: str,
    out: str | None,
) -> str:
    """The command that gives this sweep (every option spelled out)."""
    parts = ["graspguide", "sweep"]
    if protocol:
        parts += ["--protocol", protocol]
    parts += ["--thresholds", thresholds, "--rates", rates]
    if grid:
        parts.append("--grid")
    if modalities:
        parts += ["--modalities", modalities]
    if contacts:
        parts += ["--contacts", contacts]
    parts += ["--participants", str(participants), "--wrenches", str(wrenches)]
    if source != DEFAULT_SOURCE:
        parts += ["--source", source]
    if out:
        parts += ["--out", out]
    return " ".join(parts)


def run(
    *,
    thresholds: str,
    rates: str,
    protocol: str | None = None,
    grid: bool = False,
    modalities: str | None = None,
    contacts: str | None = None,
    participants: int = 2,
    wrenches: int = 4,
    source: str = DEFAULT_SOURCE,
    out: str | None = None,
    jobs: int | None = None,
    quiet: bool = False,
) -> int:
    """`graspguide sweep` with its options as given on the command line (lists as
    comma-separated text); writes OUT/sweep.json, OUT/sweep.png and prints the table.
    Returns the exit code."""
    from graspguide.protocol.study_protocol import POSE_RATE_HZ, ProtocolFileError
    from graspguide.run_errors import RunnerError

    command = command_line(
        protocol, thresholds, rates, grid, modalities, contacts, participants, wrenches, source, out
    )
    prog = "graspguide sweep"
    try:
        threshold_values = parse_values(thresholds, "thresholds", 0.0, 90.0)
        rate_values = parse_values(rates, "rates", 0.0, POSE_RATE_HZ[1])
        if any(r < POSE_RATE_HZ[0] for r in rate_values):
            raise SweepError(
                f"--rates: each value must be at least {POSE_RATE_HZ[0]:g} poses "
                "per second, the protocol file's minimum ([study] pose_rate_hz)"
            )
        if any(t >= 90.0 for t in threshold_values):
            raise SweepError("--thresholds: each value must be below 90 degrees")
        modality_values = parse_modalities(modalities) if modalities else None
        contact_values = None
        if contacts:
            try:
                contact_values = tuple(int(s) for s in contacts.split(","))
            except ValueError:
                raise SweepError(f"--contacts: expected 3, 4 or 3,4, got {contacts!r}") from None
            if (
                not contact_values
                or any(k not in (3, 4) for k in contact_values)
                or len(set(contact_values)) != len(contact_values)
            ):
                raise SweepError(f"--contacts: expected 3, 4 or 3,4, got {contacts!r}")
        out = out or default_out()
        jobs = jobs or os.cpu_count() or 1
        code, result = run_sweep(
            protocol or default_protocol(),
            threshold_values,
            rate_values,
            participants,
            wrenches,
            out,
            jobs,
            source,
            modalities=modality_values,
            contacts=contact_values,
            grid=grid,
            quiet=quiet,
        )
    except (SweepError, ProtocolFileError, RunnerError) as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    if code != EXIT_OK or result is None:
        return code
    result["command"] = command
    os.makedirs(out, exist_ok=True)
    json_path = os.path.join(out, "sweep.json")
    png_path = os.path.join(out, "sweep.png")
    write_json_file(json_path, result, indent=1)
    plot(result, png_path)
    print()
    for line in table_lines(result):
        print(line)
    tp = result["threshold_pairs"]["all"]
    print(
        f"\nSame trial, next larger threshold: took longer in "
        f"{tp['larger_threshold_took_longer']} of {tp['pairs']} pairs "
        "(never for an open-loop source; possible for the closed-loop participant, whose "
        "cue and search change with the threshold)"
    )
    print(
        f"\nWrote {json_path} and {png_path}; {result['run_wall_s']:.1f} s wall, "
        f"{result['runner_processes_run']} runner processes run now ({result['jobs']} "
        "at a time). SIMULATED: no human took part."
    )
    return EXIT_OK


__all__ = [
    "run",
    "run_sweep",
    "sweep_points",
    "derive_protocol",
    "protocol_toml",
    "point_source",
    "summarize",
    "threshold_pairs",
    "table_lines",
    "plot",
    "parse_values",
    "parse_modalities",
    "SweepError",
]
