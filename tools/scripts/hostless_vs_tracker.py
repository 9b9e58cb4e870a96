#!/usr/bin/env python3
"""Success rates and mean completion times of the host-less simulated study beside the
tracker-driven one (docs/hostless.md): the same protocol, virtual participants U1..Un and seeds,
each run both ways on its own simulated device. SIMULATED: virtual participants.

* tracker-driven: `graspguide trial --port sim --source participant` (the device gets the
  participant's exact hand pose);
* host-less: `graspguide trial ... --hostless` (the device estimates gravity from a
  simulated IMU on the hand and runs the trials from its stored plan); from its
  world.jsonl, what the estimate did to success detection: the true error of the exact
  hand pose during the hold of every success the device declared.

    python tools/scripts/hostless_vs_tracker.py [--participants N] [--protocol FILE]
        [--out DIR] [--jobs J] [--json FILE]

Both studies go to OUT/tracker and OUT/hostless (default logs/hostless-vs-tracker); they
resume like the demo, so running again only compares again.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from typing import Any

from graspguide.analysis.outcome_summary import format_outcome, outcome_summary
from graspguide.protocol.study_protocol import load_protocol
from graspguide.records.storage import read_jsonl
from graspguide.study.demo import HostlessTrialJob
from graspguide.study.jobs import TrialJob, default_out, default_protocol, run_trial_jobs

KINDS = ("tracker", "hostless")


def _rows(study_dir: str, pids: Sequence[str]) -> dict[tuple[int, str], list[dict[str, Any]]]:
    """The main (not familiarization) trials of ``pids`` by (k, modality)."""
    rows: dict[tuple[int, str], list[dict[str, Any]]] = {}
    for pid in pids:
        for r in read_jsonl(os.path.join(study_dir, pid, "trials.jsonl")).records:
            if not r.get("familiarization"):
                rows.setdefault((r["k"], r["modality"]), []).append(r)
    return rows


def _truth(study_dir: str, pids: Sequence[str]) -> dict[str, Any]:
    """What the IMU estimate did to success detection: from OUT/hostless/PID/world.jsonl,
    the true error (the exact hand pose) beside the device's at each host-less result."""
    lines = []
    for pid in pids:
        path = os.path.join(study_dir, pid, "world.jsonl")
        if os.path.exists(path):
            lines += read_jsonl(path).records
    ok = [r for r in lines if r["success"] and r["true_max_error_over_hold_deg"] is not None]
    ends = [
        abs(r["device_final_error_deg"] - r["true_final_error_deg"])
        for r in lines
        if r["true_final_error_deg"] is not None
    ]
    return {
        "results": len(lines),
        "successes": len(ok),
        # a success the device declared while the true error left the threshold in the hold
        "successes_true_error_above_threshold": sum(
            1 for r in ok if r["true_max_error_over_hold_deg"] >= r["threshold_deg"]
        ),
        "successes_true_final_error_above_threshold": sum(
            1 for r in ok if r["true_final_error_deg"] >= r["threshold_deg"]
        ),
        "max_true_error_over_hold_deg": max(
            (r["true_max_error_over_hold_deg"] for r in ok), default=None
        ),
        "max_true_final_error_of_successes_deg": max(
            (r["true_final_error_deg"] for r in ok), default=None
        ),
        "end_error_diff_rms_deg": math.sqrt(sum(d * d for d in ends) / len(ends)) if ends else None,
        "end_error_diff_max_deg": max(ends, default=None),
    }


def compare(out: str, pids: Sequence[str]) -> dict[str, Any]:
    by_kind = {kind: _rows(os.path.join(out, kind), pids) for kind in KINDS}
    keys = sorted(set(by_kind["tracker"]) | set(by_kind["hostless"]))
    table = []
    for k, modality in keys:
        table.append(
            {
                "k": k,
                "modality": modality,
                **{kind: outcome_summary(by_kind[kind].get((k, modality), [])) for kind in KINDS},
            }
        )
    total = {
        kind: outcome_summary([r for rs in by_kind[kind].values() for r in rs]) for kind in KINDS
    }
    return {
        "simulated": True,
        "participants": list(pids),
        "by_condition": table,
        "all": total,
        "hostless_truth": _truth(os.path.join(out, "hostless"), pids),
    }


def _cell(s: dict[str, Any]) -> str:
    return format_outcome(s, count_width=3, time_digits=2)


def format_table(res: dict[str, Any]) -> str:
    lines = [
        f"SIMULATED: virtual participants {', '.join(res['participants'])}; main trials; "
        "successes, rate, mean completion time (a failure counts as the timeout)",
        f"{'condition':<14} {'tracker-driven':>22}   {'host-less (IMU)':>22}",
    ]
    for row in res["by_condition"]:
        cond = f"k={row['k']} {row['modality']}"
        lines.append(f"{cond:<14} {_cell(row['tracker'])}   {_cell(row['hostless'])}")
    lines.append(f"{'all':<14} {_cell(res['all']['tracker'])}   {_cell(res['all']['hostless'])}")
    t = res["hostless_truth"]
    if t["results"]:
        lines.append(
            f"host-less, true error (exact hand pose) vs the device's IMU estimate, "
            f"{t['results']} results: |device - true| at the end RMS "
            f"{t['end_error_diff_rms_deg']:.2f} deg, max {t['end_error_diff_max_deg']:.2f} deg"
        )
        if t["successes"]:
            lines.append(
                f"  of {t['successes']} successes the device declared, "
                f"{t['successes_true_error_above_threshold']} had a true error at or above the "
                f"threshold during the hold (max over holds "
                f"{t['max_true_error_over_hold_deg']:.2f} deg), "
                f"{t['successes_true_final_error_above_threshold']} at the end (max "
                f"{t['max_true_final_error_of_successes_deg']:.2f} deg)"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--participants", type=int, default=1, metavar="N")
    p.add_argument("--protocol", default=None, help="default protocols/paper.toml")
    p.add_argument("--out", default=None, help="default logs/hostless-vs-tracker")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures here")
    a = p.parse_args(argv)
    if not 1 <= a.participants <= 256:
        p.error(f"--participants must be in 1..256, got {a.participants}")
    if a.jobs < 1:
        p.error(f"--jobs must be at least 1, got {a.jobs}")
    protocol = a.protocol or default_protocol()
    load_protocol(protocol)  # a bad file fails here, with its message
    out = a.out or default_out("hostless-vs-tracker")
    pids = [f"U{i}" for i in range(1, a.participants + 1)]
    tasks: list[TrialJob] = []
    for kind, job in (("tracker", TrialJob), ("hostless", HostlessTrialJob)):
        study = os.path.join(out, kind)
        for pid in pids:
            tasks.append(
                job(
                    protocol,
                    study,
                    pid,
                    "participant",
                    os.path.join(out, "logs", f"{kind}-{pid}.log"),
                )
            )

    def on_exit(job: TrialJob, rc: int) -> None:
        kind = "hostless" if isinstance(job, HostlessTrialJob) else "tracker"
        print(f"{kind} {job.participant}: exit {rc} ({job.log})", file=sys.stderr, flush=True)

    interrupted, failed = run_trial_jobs(tasks, a.jobs, on_exit)
    if interrupted:
        print("interrupted; run again to resume", file=sys.stderr)
        return 130
    if failed:
        print(
            "failed: " + ", ".join(f"{j.participant} ({j.log})" for j, _ in failed),
            file=sys.stderr,
        )
        return 1
    res = compare(out, pids)
    print(format_table(res))
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump(res, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
