"""The trial-level analysis: pairing by block, the ceiling-safe outlier rule, the RM
ANOVA against sums of squares computed here, Greenhouse-Geisser, and degenerate input."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pingouin  # noqa: F401  (imported at collection, so no test pays for it)
import pytest

from graspguide.analysis.paper_tables import AnalysisError
from graspguide.analysis.trial_statistics import (
    ceiling_outliers,
    format_markdown,
    format_text,
    trial_level_statistics,
)
from graspguide.core.vocabulary import MODALITIES

CEIL = 90.0


def frame(blocks: dict[tuple[str, int, str], dict[str, float]]) -> pd.DataFrame:
    """One trial row per (block, modality); a time at the ceiling is a failed trial."""
    rows = []
    for (p, k, w), times in blocks.items():
        for m, t in times.items():
            rows.append(
                {
                    "participant": p,
                    "k": k,
                    "modality": m,
                    "wrench_id": w,
                    "completion_s": float(t),
                    "success": t < CEIL,
                    "familiarization": False,
                }
            )
    return pd.DataFrame(rows)


def wide_blocks(values: np.ndarray) -> dict[tuple[str, int, str], dict[str, float]]:
    """Blocks from an n x 4 array of times (columns in MODALITIES order)."""
    return {
        (f"U{i % 3 + 1}", 3, f"W{i:02d}"): dict(zip(MODALITIES, map(float, row)))
        for i, row in enumerate(values)
    }


def small_set() -> dict[tuple[str, int, str], dict[str, float]]:
    """3 participants x 1 k x 3 wrenches; U2/W02's F+V at 80 s is the planted outlier;
    U1/W01's F+C is a 90 s timeout, far above the F+C successes."""
    fc = [90.0, 31, 24, 35, 28, 33, 26, 30, 29]
    fpc = [27, 34, 30, 25, 36, 29, 32, 28, 31]
    fv = [10, 12, 11, 13, 80.0, 9, 12, 11, 10.5]
    fpv = [9, 11, 10, 12, 13, 10, 11, 9.5, 12]
    blocks = {}
    i = 0
    for p in ("U1", "U2", "U3"):
        for w in ("W01", "W02", "W03"):
            blocks[(p, 3, w)] = dict(zip(MODALITIES, (fc[i], fpc[i], fv[i], fpv[i])))
            i += 1
    return blocks


def test_planted_outlier_removes_its_block_and_the_timeout_stays():
    blocks = small_set()
    blocks[("U3", 4, "W01")] = {m: 20.0 for m in MODALITIES[:3]}  # no F+V: incomplete
    s = trial_level_statistics(frame(blocks))
    assert s.blocks_total == 10
    assert s.incomplete_blocks == 1
    flagged = s.flagged()
    assert list(zip(flagged["participant"], flagged["wrench_id"], flagged["modality"])) == [
        ("U2", "W02", "F+V")
    ]
    assert float(flagged["completion_s"].iloc[0]) == 80.0
    # The whole block goes: 4 trials, 3 of them paired, not flagged.
    assert len(s.removed) == 4
    assert set(s.removed["modality"]) == set(MODALITIES)
    assert s.n_blocks == 8
    assert "U2/k3/W02" not in s.retained.index
    # The timeout is neither flagged nor dropped: it enters the ANOVA at 90 s.
    assert s.retained.loc["U1/k3/W01", "F+C"] == CEIL
    assert s.censored_retained["F+C"] == 1
    text = format_text(s)
    assert "U2 k=3 W02 F+V 80.00 s" in text
    assert "| U2 | 3 | W02 | F+V | 80.00 |" in format_markdown(s)


def test_outliers_kept_when_asked():
    s = trial_level_statistics(frame(small_set()), remove_outliers=False)
    assert s.n_blocks == 9 and len(s.removed) == 0
    assert s.retained.loc["U2/k3/W02", "F+V"] == 80.0
    assert "outlier removal off" in format_text(s)


def test_anova_matches_sums_of_squares_computed_here():
    rng = np.random.default_rng(7)
    n = 12
    times = rng.uniform(10, 30, size=(n, 4)) + np.array([8.0, 6.0, 0.0, 1.0])
    s = trial_level_statistics(frame(wide_blocks(times)))
    assert s.removed.empty
    y = np.sqrt(times)
    grand = y.mean()
    ss_mod = n * ((y.mean(axis=0) - grand) ** 2).sum()
    ss_subj = 4 * ((y.mean(axis=1) - grand) ** 2).sum()
    ss_err = ((y - grand) ** 2).sum() - ss_mod - ss_subj
    df1, df2 = 3, 3 * (n - 1)
    f = (ss_mod / df1) / (ss_err / df2)
    assert s.anova["df1"] == df1
    assert s.anova["df2"] == df2
    assert s.anova["F"] == pytest.approx(f, rel=1e-9)
    assert s.anova["np2"] == pytest.approx(ss_mod / (ss_mod + ss_err), rel=1e-9)
    assert f"F({df1}, {df2}) = {f:.3f}" in format_text(s)
    # Pairwise differences are of the untransformed means, in seconds.
    row = s.pairwise[(s.pairwise["A"] == "F+C") & (s.pairwise["B"] == "F+V")].iloc[0]
    assert row["diff_s"] == pytest.approx(times[:, 0].mean() - times[:, 2].mean())
    assert len(s.pairwise) == 6


def test_greenhouse_geisser_when_sphericity_is_violated():
    rng = np.random.default_rng(3)
    n = 40
    subject = rng.normal(0, 0.5, size=(n, 1))
    noise = rng.normal(0, 1, size=(n, 4)) * np.array([2.0, 0.1, 0.1, 0.1])
    root = 8.0 + subject + noise + np.array([0.0, 0.5, -1.0, -1.2])
    s = trial_level_statistics(frame(wide_blocks(root**2)))
    assert s.sphericity["pval"] < 0.05
    assert s.gg_applied
    eps = s.anova["eps"]
    assert 1 / 3 <= eps < 1
    assert s.anova["df1_gg"] == pytest.approx(3 * eps)
    assert s.anova["df2_gg"] == pytest.approx(3 * (s.n_blocks - 1) * eps)
    assert s.anova["p_gg"] > s.anova["p"]
    text = format_text(s)
    assert f"GG-corrected (epsilon = {eps:.3f}) F({3 * eps:.2f}, " in text


def test_no_correction_printed_when_sphericity_holds():
    rng = np.random.default_rng(11)
    times = rng.uniform(10, 30, size=(20, 4))
    s = trial_level_statistics(frame(wide_blocks(times)))
    assert not s.gg_applied
    assert "GG-corrected" not in format_text(s)


def test_timeouts_and_zero_iqr_flag_nothing():
    # All at the ceiling: censored, no fences.
    flags, fences = ceiling_outliers([CEIL] * 9, [True] * 9)
    assert flags == [False] * 9
    assert fences["successes"] == 0
    # IQR of the successes is 0: nothing is flagged, not even the far success.
    flags, fences = ceiling_outliers([20.0] * 7 + [50.0, CEIL], [False] * 8 + [True])
    assert fences["iqr"] == 0
    assert not any(flags)
    # A C column mostly at the ceiling: quartiles over all trials would be 90 s and flag
    # the two successes; over the successes there are too few to flag anything.
    times = np.tile([30.0, 28.0, 12.0, 11.0], (9, 1))
    times[:, 0] = [CEIL] * 7 + [30.0, 40.0]
    times[:, 1] += np.arange(9)
    times[:, 2] += np.arange(9) * 0.5
    times[:, 3] += np.arange(9) * 0.3
    s = trial_level_statistics(frame(wide_blocks(times)))
    assert s.removed.empty
    assert s.censored_retained["F+C"] == 7


def test_no_complete_block():
    blocks = {k: {m: t for m, t in v.items() if m != "Fperp+V"} for k, v in small_set().items()}
    with pytest.raises(AnalysisError, match="no complete block"):
        trial_level_statistics(frame(blocks))


def test_fewer_than_three_blocks():
    blocks = dict(list(small_set().items())[1:3])
    with pytest.raises(AnalysisError, match="fewer than 3 blocks"):
        trial_level_statistics(frame(blocks))


def test_zero_variance_modality():
    times = np.tile([30.0, 28.0, 12.0, 11.0], (6, 1)) + np.arange(6)[:, None]
    times[:, 1] = CEIL
    with pytest.raises(AnalysisError, match="Fperp\\+C has zero variance"):
        trial_level_statistics(frame(wide_blocks(times)))


def test_a_modality_twice_in_a_block_cannot_be_paired():
    data = frame(small_set())
    data = pd.concat([data, data.iloc[[0]]], ignore_index=True)
    with pytest.raises(AnalysisError, match="cannot be paired"):
        trial_level_statistics(data)


def test_familiarization_trials_are_left_out():
    data = frame(small_set())
    extra = frame({("U1", 3, "W09"): {m: 15.0 + i for i, m in enumerate(MODALITIES)}})
    extra["familiarization"] = True
    s = trial_level_statistics(pd.concat([data, extra], ignore_index=True))
    assert s.blocks_total == 9
