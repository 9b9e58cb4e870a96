"""The trials as they happened: every analysed trial's completion time per modality, one
panel per contact count, with the 90 s timeout drawn as a line and the timeouts marked
on it, the trials an outlier rule removed shown apart, and the paper's mean ± SD per
condition as reference markers.

A bar of means hides what a ceiling does to a condition (most constant-intensity trials
end at exactly 90 s) and a mean ± SD bar runs below zero and above the timeout when the
times pile up at both ends; the points and the clipped reference bars do not.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from graspguide.core.vocabulary import MODALITIES, shown

#: The trial rule's timeout (docs/study.md): a trial that has not succeeded ends here.
TIMEOUT_S = 90.0
#: Horizontal spread of the points around their modality, in axis units.
JITTER = 0.18
#: The jitter's seed: the same trials give the same picture.
JITTER_SEED = 0
COLORS = {"F+C": "#c0504d", "Fperp+C": "#e6a19f", "F+V": "#4f81bd", "Fperp+V": "#a7c0de"}

#: A removed trial: (participant, k, wrench_id, modality).
RemovedTrial = tuple[str, int, str, str]


def sd_range(mean: float | None, sd: float | None, timeout_s: float = TIMEOUT_S):
    """(below, above) the mean for its ± SD bar, cut at 0 s and at the timeout: no trial
    is shorter than 0 or longer than the timeout (a failure counts as it), whatever the SD
    of a condition piled up at both ends says."""
    if mean is None or not sd:
        return 0.0, 0.0
    return min(sd, max(mean, 0.0)), min(sd, max(timeout_s - mean, 0.0))


def trial_figure(
    trials: Any,
    out_dir: str | os.PathLike,
    removed: Iterable[RemovedTrial] = (),
    paper: Mapping[tuple[int, str], tuple[float, float]] | None = None,
    simulated: bool = False,
    stem: str = "trials",
) -> list[Path]:
    """Writes ``stem.png`` and ``stem.svg`` and returns their paths.

    ``trials``: the analysed trials (no familiarization) with columns participant, k,
    wrench_id, modality, completion_s and success. ``removed``: trials an outlier rule took
    out, drawn as hollow markers. ``paper``: (k, modality) -> (mean, SD) in seconds, drawn
    as black diamonds with the SD bar clipped to [0, 90 s].
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    import numpy as np

    gone = {(str(p), int(k), str(w), str(m)) for p, k, w, m in removed}
    ks = sorted({int(k) for k in trials["k"]})
    if not ks:
        raise ValueError("trial_figure: no trials to draw")
    rng = np.random.default_rng(JITTER_SEED)
    fig, axes = plt.subplots(1, len(ks), figsize=(4.6 * len(ks), 4.8), sharey=True, squeeze=False)
    for ax, k in zip(axes[0], ks):
        here = trials[trials["k"] == k]
        for i, m in enumerate(MODALITIES):
            cell = here[here["modality"] == m]
            if cell.empty:
                continue
            keys = zip(cell["participant"], cell["k"], cell["wrench_id"], cell["modality"])
            out = np.array([(str(p), int(kk), str(w), str(mm)) in gone for p, kk, w, mm in keys])
            t = cell["completion_s"].to_numpy(dtype=float)
            ok = cell["success"].to_numpy(dtype=bool)
            x = i + rng.uniform(-JITTER, JITTER, size=len(t))
            kept = ~out
            if kept.any():
                ax.boxplot(
                    t[kept],
                    positions=[i],
                    widths=0.55,
                    showfliers=False,
                    medianprops={"color": "black"},
                    boxprops={"color": "#555555"},
                    whiskerprops={"color": "#555555"},
                    capprops={"color": "#555555"},
                )
            done = kept & ok
            ax.scatter(x[done], t[done], s=12, color=COLORS[m], edgecolor="black", linewidth=0.3)
            timed_out = kept & ~ok
            ax.scatter(x[timed_out], t[timed_out], s=16, marker="x", color=COLORS[m], linewidth=1)
            ax.scatter(x[out], t[out], s=22, facecolors="none", edgecolors="#d62728", linewidth=1.0)
            # The timeouts sit on one line; their count says how many.
            ax.text(
                i,
                TIMEOUT_S + 2.5,
                f"{int(timed_out.sum())}/{int(kept.sum())}",
                ha="center",
                va="bottom",
                fontsize=7,
            )
            if paper and (k, m) in paper:
                mean, sd = paper[(k, m)]
                lo, hi = sd_range(mean, sd)
                ax.errorbar(
                    [i + 0.36],
                    [mean],
                    yerr=[[lo], [hi]],
                    fmt="D",
                    color="black",
                    markersize=5,
                    capsize=3,
                    linewidth=1,
                )
        ax.axhline(TIMEOUT_S, color="#777777", linestyle="--", linewidth=0.9)
        ax.set_xticks(range(len(MODALITIES)), [shown(m) for m in MODALITIES])
        ax.set_xlim(-0.6, len(MODALITIES) - 0.4)
        ax.set_title(f"{k} contacts", fontsize=10)
        ax.spines[["top", "right"]].set_visible(False)
    axes[0][0].set_ylim(0, TIMEOUT_S * 1.1)
    axes[0][0].set_ylabel("completion time [s], one point a trial")
    legend = [
        plt.Line2D([], [], marker="o", linestyle="", color="#888888", label="success"),
        plt.Line2D([], [], marker="x", linestyle="", color="#888888", label="timeout (90 s)"),
        # In the legend, not on the plot: the timeouts' markers fill the line's whole width.
        plt.Line2D(
            [],
            [],
            linestyle="--",
            color="#777777",
            label="90 s timeout (numbers above it: timeouts / trials)",
        ),
        plt.Line2D(
            [],
            [],
            marker="o",
            linestyle="",
            markerfacecolor="none",
            color="#d62728",
            label="removed as outlier",
        ),
    ]
    if paper:
        legend.append(
            plt.Line2D([], [], marker="D", linestyle="", color="black", label="paper mean ± SD")
        )
    fig.legend(handles=legend, loc="lower center", ncol=len(legend), fontsize=8, frameon=False)
    title = "Trial completion times per modality"
    if simulated:
        from graspguide.analysis.paper_tables import SIMULATED_BANNER

        title = SIMULATED_BANNER + "\n" + title
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    out_path = Path(out_dir)
    out_path.mkdir(parents=True, exist_ok=True)
    paths = [out_path / f"{stem}.png", out_path / f"{stem}.svg"]
    fig.savefig(paths[0], dpi=150, metadata={"Software": None})
    fig.savefig(paths[1], metadata={"Date": None})
    plt.close(fig)
    return paths
