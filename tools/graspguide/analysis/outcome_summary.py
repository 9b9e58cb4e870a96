"""Success rate and mean completion of a set of trial records (graspguide.records.trial), for
the comparison scripts (tools/scripts/hostless_vs_tracker.py, calibration_benefit.py)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def outcome_summary(recs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """trials, successes, success_rate, mean_completion_s (a failure counts as its
    timeout, as the analysis does) and mean_success_time_s; None where there is no trial."""
    ok = [r for r in recs if r["success"]]
    return {
        "trials": len(recs),
        "successes": len(ok),
        "success_rate": len(ok) / len(recs) if recs else None,
        "mean_completion_s": sum(r["completion_s"] for r in recs) / len(recs) if recs else None,
        "mean_success_time_s": sum(r["completion_s"] for r in ok) / len(ok) if ok else None,
    }


def format_outcome(s: dict[str, Any], count_width: int = 4, time_digits: int = 1) -> str:
    """ "successes/trials rate% mean s", or a dash as wide when there was no trial."""
    time_width = 5 + time_digits
    width = 2 * count_width + 11 + time_width
    if not s["trials"]:
        return f"{'-':>{width}}"
    return (
        f"{s['successes']:>{count_width}}/{s['trials']:<{count_width}} "
        f"{100 * s['success_rate']:5.1f}% {s['mean_completion_s']:{time_width}.{time_digits}f} s"
    )


__all__ = ["outcome_summary", "format_outcome"]
