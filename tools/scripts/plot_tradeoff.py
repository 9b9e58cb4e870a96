#!/usr/bin/env python3
"""Draws docs/perf/tradeoff.png, the speed-accuracy trade of docs/performance.md: host cost
(median ns per full frame, `graspguide bench --json`) against accuracy (share of instances
whose PWM differs from the float64 reference, plus the worst equilibrium residual), one
point per configuration, and the Cortex-M instruction counts per stage
(`graspguide bench --target m4f --target m7 --target m7d --json`).

    python tools/scripts/plot_tradeoff.py docs/perf/bench_host.json docs/perf/qemu_stages.json
"""

from __future__ import annotations

import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
STAGES = ["frames", "structure", "forces", "qp", "mapping"]


def main(bench_path: str, stages_path: str, out: str = "docs/perf/tradeoff.png") -> int:
    bench = json.loads(pathlib.Path(bench_path).read_text())
    stages = json.loads(pathlib.Path(stages_path).read_text())
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.8))
    for row in bench["results"]:
        timing = row["timing"].get("cxx") or row["timing"].get("internal")
        acc = row["accuracy"]
        if row["group"] not in ("frame", "qp") or timing is None or not acc.get("instances"):
            continue
        miss = (acc["pwm_mismatch"] + acc["failures"]) / acc["instances"]
        marker = "o" if row["k"] == 3 else "s"
        ax.scatter(
            timing["median_ns"],
            max(miss, 1e-4),
            marker=marker,
            color="C0" if row["solver"] == "graspguide" else "C3",
        )
        ax.annotate(
            f"k{row['k']} {row['name']}",
            (timing["median_ns"], max(miss, 1e-4)),
            fontsize=6,
            alpha=0.8,
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("host median time per call (ns, C++ loop or solver's internal time)")
    ax.set_ylabel("PWM != float64 or failed (share, floor 1e-4)")
    ax.set_title("Host: cost vs accuracy (blue: this project, red: peer QP solvers)")
    width = 0.35
    targets = (("cortex-m4f", "C0"), ("cortex-m7", "C1"), ("cortex-m7-double", "C2"))
    for i, (target, colour) in enumerate(targets):
        if target not in stages:
            continue
        for j, k in enumerate(("k3", "k4")):
            vals = [stages[target][k][s]["median"] for s in STAGES]
            xs = [x + (2 * i + j) * width / 3 for x in range(len(STAGES))]
            bx.bar(xs, vals, width / 3, color=colour, alpha=0.5 + 0.4 * j, label=f"{target} {k}")
    bx.set_xticks([x + 0.3 for x in range(len(STAGES))], STAGES)
    bx.set_ylabel("instructions (median over accepted scenes)")
    bx.set_title("On target (QEMU -icount): where a full frame goes")
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(ROOT / out, dpi=130)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1], sys.argv[2]))
