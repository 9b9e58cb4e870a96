"""Today's analyses: the mixed model recovers a known effect, the two-way ANOVA's
interaction F matches a direct sum-of-squares computation, and the text reports what
was fitted."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from graspguide.analysis.mixed_model import (
    PRIMARY_RULE,
    SENSITIVITY_RULE,
    fit_mixed_model,
    format_markdown,
    format_text,
    reviewer_analysis,
    two_way_anova,
)

MODALITIES = ("F+V", "Fperp+V", "F+C", "Fperp+C")
COLUMNS = [
    "participant",
    "k",
    "modality",
    "wrench_id",
    "completion_s",
    "success",
    "familiarization",
]


def _synthetic(seed: int, effect: float, n_participants: int = 8, wrenches: int = 12):
    """sqrt(t) = 3 + participant intercept (SD 0.4) + ``effect`` for the C modalities
    + noise (SD 0.3); every trial a success."""
    rng = np.random.default_rng(seed)
    rows = []
    for p in range(n_participants):
        u = rng.normal(0.0, 0.4)
        for k in (3, 4):
            for m in MODALITIES:
                for w in range(wrenches):
                    y = 3.0 + u + (effect if m.endswith("C") else 0.0) + rng.normal(0.0, 0.3)
                    rows.append((f"U{p + 1}", k, m, f"W{w}", y * y, True, False))
    return pd.DataFrame(rows, columns=COLUMNS)


def test_the_mixed_model_recovers_a_known_modality_effect():
    trials = _synthetic(seed=7, effect=2.0)
    # A familiarization trial far off is left out, or the estimates would move.
    trials.loc[len(trials)] = ("U1", 3, "F+V", "W0", 89.0, True, True)
    fit = fit_mixed_model(trials)
    assert fit.skipped is None and fit.rule == PRIMARY_RULE
    assert fit.n_trials == 8 * 2 * 4 * 12 and fit.n_participants == 8
    coef = fit.coefficients.set_index("term")
    # Standard error of a main effect here is about 0.3 * sqrt(2 / 96) = 0.04: the
    # tolerance of 0.15 is over 3.5 of them.
    for term in ("F+C", "F⊥+C"):
        assert coef.loc[term, "coef"] == pytest.approx(2.0, abs=0.15)
        assert coef.loc[term, "ci_low"] < 2.0 < coef.loc[term, "ci_high"]
        assert coef.loc[term, "p"] < 1e-6
    assert abs(coef.loc["F⊥+V", "coef"]) < 0.15
    assert coef.loc["Intercept (k=3, F+V)", "coef"] == pytest.approx(3.0, abs=0.4)
    assert fit.group_var == pytest.approx(0.16, rel=0.9)
    assert fit.resid_var == pytest.approx(0.09, rel=0.2)


def test_timeouts_kept_or_excluded_and_a_missing_cell_named():
    trials = _synthetic(seed=3, effect=1.0, n_participants=4, wrenches=3)
    timeout = (trials["k"] == 3) & (trials["modality"] == "F+C")
    trials.loc[timeout, ["completion_s", "success"]] = (90.0, False)
    keep = fit_mixed_model(trials, "keep")
    assert keep.n_trials == len(trials) and keep.n_timeouts == int(timeout.sum())
    assert keep.model == "k x modality" and not keep.empty_cells
    excl = fit_mixed_model(trials, "exclude")
    assert excl.rule == SENSITIVITY_RULE and excl.n_trials == len(trials) - int(timeout.sum())
    assert excl.empty_cells == ["k=3 F+C"] and excl.model == "cells"
    assert "k=3 F+C vs k=3 F+V" not in set(excl.coefficients["term"])
    assert "k=4 F+C vs k=3 F+V" in set(excl.coefficients["term"])
    with pytest.raises(Exception, match="keep"):
        fit_mixed_model(trials, "drop")


def _interaction_f(y: np.ndarray) -> tuple[float, int, int]:
    """Interaction F of a balanced subjects x A x B table by sums of squares."""
    n, a, b = y.shape
    g = y.mean()
    m_a, m_b, m_s = y.mean(axis=(0, 2)), y.mean(axis=(0, 1)), y.mean(axis=(1, 2))
    m_ab, m_as, m_bs = y.mean(axis=0), y.mean(axis=2), y.mean(axis=1)
    inter = m_ab - m_a[:, None] - m_b[None, :] + g
    ss_ab = n * float((inter**2).sum())
    resid = (
        y
        - m_ab[None]
        - m_as[:, :, None]
        - m_bs[:, None, :]
        + m_a[None, :, None]
        + m_b[None, None, :]
        + m_s[:, None, None]
        - g
    )
    ss_err = float((resid**2).sum())
    df1, df2 = (a - 1) * (b - 1), (a - 1) * (b - 1) * (n - 1)
    return (ss_ab / df1) / (ss_err / df2), df1, df2


def test_the_two_way_interaction_matches_sums_of_squares():
    # sqrt of cell means: 5 participants x 2 contact counts x 4 modalities, by hand.
    y = np.array(
        [
            [[2.0, 2.2, 5.1, 5.3], [2.4, 2.1, 4.2, 4.6]],
            [[2.5, 2.3, 6.0, 5.8], [2.2, 2.6, 4.9, 5.5]],
            [[1.9, 2.0, 5.5, 4.9], [2.1, 2.3, 4.4, 4.0]],
            [[2.8, 2.4, 6.2, 6.6], [2.6, 2.9, 5.1, 5.7]],
            [[2.2, 2.5, 4.8, 5.6], [2.3, 2.0, 4.6, 4.3]],
        ]
    )
    rows = []
    for s in range(5):
        for i, k in enumerate((3, 4)):
            for j, m in enumerate(MODALITIES):
                # Two trials per cell whose mean is y^2: the analysis averages, then roots.
                t = y[s, i, j] ** 2
                for w, dt in (("W1", -0.5), ("W2", 0.5)):
                    rows.append((f"U{s + 1}", k, m, w, t + dt, True, False))
    trials = pd.DataFrame(rows, columns=COLUMNS)
    tw = two_way_anova(trials)
    assert tw.n_participants == 5 and tw.left_out == []
    inter = tw.table.set_index("source").loc["k x modality"]
    f, df1, df2 = _interaction_f(y[:, :, :])
    assert inter["F"] == pytest.approx(f, rel=1e-9)
    assert (inter["df1"], inter["df2"]) == (df1, df2) == (3, 12)


def test_a_participant_without_every_cell_is_left_out_of_the_two_way_analysis():
    trials = _synthetic(seed=5, effect=1.0, n_participants=4, wrenches=2)
    trials = trials[~((trials["participant"] == "U2") & (trials["modality"] == "F+V"))]
    tw = two_way_anova(trials)
    assert tw.left_out == ["U2"] and tw.n_participants == 3


def test_the_text_labels_the_analyses_and_reports_counts_and_df():
    trials = _synthetic(seed=11, effect=1.5, n_participants=4, wrenches=3)
    res = reviewer_analysis(trials)
    text = format_text(res)
    assert text.startswith("Today's analyses")
    assert "per-participant reading" in text
    assert f"{len(trials)} trials, 4 participants" in text
    assert "(3, 9)" in text and "(1, 3)" in text
    md = format_markdown(res)
    assert md.startswith("## Today's analyses") and "| k x modality |" in md


def test_convergence_warnings_are_reported_not_printed(capfd):
    # Identical participants: the participant variance sits at its boundary, 0.
    one = _synthetic(seed=2, effect=1.0, n_participants=1, wrenches=4)
    trials = pd.concat([one.assign(participant=f"U{i}") for i in range(1, 4)], ignore_index=True)
    fit = fit_mixed_model(trials)
    out, err = capfd.readouterr()
    assert err == "" and out == ""
    assert any("boundary" in w for w in fit.warnings)
    assert "participant variance is at its boundary" in format_text(reviewer_analysis(trials))
