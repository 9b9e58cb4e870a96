"""The trial-level figure: SD bars kept inside [0, 90 s], and a picture from a small set
of trials with a removed one and the paper's reference markers."""

from __future__ import annotations

import random

import pandas as pd
import pytest

from graspguide.analysis.trial_figure import TIMEOUT_S, sd_range, trial_figure


def test_sd_bars_stay_between_zero_and_the_timeout():
    assert sd_range(None, 3.0) == (0.0, 0.0) and sd_range(40.0, None) == (0.0, 0.0)
    assert sd_range(33.0, 30.0) == (30.0, 30.0)
    assert sd_range(10.0, 20.0) == (10.0, 20.0)
    assert sd_range(80.0, 20.0) == (20.0, 10.0)
    rng = random.Random(3)
    for _ in range(1000):
        mean = rng.uniform(0.0, TIMEOUT_S)
        sd = rng.uniform(0.0, 100.0)
        lo, hi = sd_range(mean, sd)
        assert 0.0 <= lo <= sd and 0.0 <= hi <= sd
        assert mean - lo >= 0.0 and mean + hi <= TIMEOUT_S


def _trials():
    rows = []
    for p in ("U1", "U2"):
        for k in (3, 4):
            for w in ("W1", "W2"):
                for i, m in enumerate(("F+C", "Fperp+C", "F+V", "Fperp+V")):
                    t = TIMEOUT_S if m == "F+C" and w == "W1" else 5.0 + 3 * i
                    rows.append((p, k, w, m, t, t < TIMEOUT_S))
    return pd.DataFrame(
        rows, columns=["participant", "k", "wrench_id", "modality", "completion_s", "success"]
    )


def test_the_figure_is_written_with_removed_trials_and_paper_markers(tmp_path):
    paths = trial_figure(
        _trials(),
        tmp_path,
        removed=[("U1", 3, "W2", "F+V")],
        paper={(3, "F+V"): (8.64, 5.83), (4, "F+C"): (38.11, 25.21)},
        simulated=True,
    )
    assert [p.name for p in paths] == ["trials.png", "trials.svg"]
    assert paths[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    svg = paths[1].read_text()
    assert "SIMULATED DATA" in svg and "paper mean" in svg and "removed as outlier" in svg
    # The timeout counts per condition: U1 and U2 timed out in F+C with W1 only.
    assert "2/4" in svg


def test_no_trials_is_an_error(tmp_path):
    with pytest.raises(ValueError, match="no trials"):
        trial_figure(_trials().iloc[0:0], tmp_path)
