"""The analyses a reviewer would ask for today, beside the paper's own.

The paper pools both contact counts, averages per participant and runs a one-way
repeated-measures ANOVA on four modalities (:func:`graspguide.analysis.paper_tables.
paper_statistics` reproduces that reading: the *per-participant reading*). Beside it,
labelled as today's analyses, this module gives two more readings of the same trials
(familiarization trials left out):

1. **A linear mixed model** (statsmodels ``MixedLM``, formula API, REML):
   ``sqrt(completion_s) ~ C(k) * C(modality)`` with a random intercept per participant,
   fitted to every trial. Reference levels: k = 3 and F+V, so each coefficient is a
   difference on the square-root scale (sqrt s) from 3 contacts, F+V.

   **Timeouts.** A trial not finished in 90 s is logged as 90 s; its true time is only
   known to be at least 90 s (right-censored). statsmodels has no censored mixed model,
   and a mixed logistic model of success is not estimable here: every varying-intensity
   trial succeeds (in the paper and in the simulator), a complete separation that sends
   the V coefficients to infinity. So success is reported as counts (Table I), and the
   rule for times is:

   * *primary*: timeouts kept at 90 s, the paper's own definition of the outcome. It
     replaces each unknown time >= 90 s by 90 s, so it can only understate how slow a
     condition with timeouts is: the modality differences it reports are lower bounds
     in magnitude for the C - V contrasts, never inflated by the ceiling.
   * *sensitivity*: successes only (timeouts excluded). Dropping the slowest trials
     understates the same contrasts further; the gap between the two fits shows how much
     the conclusions lean on the timeouts. A condition without a single success leaves
     the k x modality coding singular; the sensitivity fit then uses one factor over
     the cells present (``sqrt(t) ~ C(cell)``, reference k = 3, F+V) and names the
     empty cells.

   statsmodels fits with Powell then L-BFGS: its default optimizer stalls when the
   participant variance sits at its boundary, 0 (participants who do not differ beyond
   the residual); the text says so when it happens.

2. **Contacts x modality, two-way** (the paper's future work: "the difference between
   multiple contact points strategies"): a two-way repeated-measures ANOVA (pingouin
   ``rm_anova``, ``within=['k', 'modality']``) on the square root of each participant's
   mean completion time per (k, modality) cell, timeouts at 90 s as in the paper's
   tables. Participants lacking a cell are left out and counted. Degrees of freedom are
   printed, with the Greenhouse-Geisser correction for the modality terms.

statsmodels' convergence and boundary warnings are captured and printed with the
result, never written to stderr.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

from graspguide.analysis.paper_tables import (
    TABLE_ORDER,
    AnalysisError,
    _analysed,
    _md_table,
    _text_table,
)
from graspguide.core.vocabulary import shown
from graspguide.records.trial import CONTACT_COUNTS

TIMEOUT_S = 90.0
REVIEWER_LABEL = "Today's analyses (beside the paper's; not in the paper)"
FORMULA = "y ~ C(k, Treatment(3)) * C(modality, Treatment('F+V'))"
CELL_FORMULA = "y ~ C(cell, Treatment('k=3 F+V'))"
# Powell first: statsmodels' default (BFGS) stalls when the participant variance is at
# its boundary, 0; gradient steps from Powell's optimum then give the Hessian.
OPTIMIZERS = ["powell", "lbfgs"]
PRIMARY_RULE = "timeouts kept at 90 s (the paper's outcome; a lower bound for those trials)"
SENSITIVITY_RULE = "successes only (timeouts excluded)"
PER_PARTICIPANT_READING = (
    "the per-participant reading (the paper's one-way rm-ANOVA on participant means, "
    "contacts pooled)"
)


@dataclass
class MixedModelFit:
    """One ``MixedLM`` fit. ``coefficients``: term, coef, ci_low, ci_high, p (95 % Wald)."""

    rule: str
    n_trials: int
    n_participants: int
    n_timeouts: int
    coefficients: Any = None
    group_var: float = math.nan
    resid_var: float = math.nan
    converged: bool | None = None
    warnings: list[str] = field(default_factory=list)
    skipped: str | None = None
    model: str = "k x modality"
    empty_cells: list[str] = field(default_factory=list)


@dataclass
class TwoWayAnova:
    """The contacts x modality rm-ANOVA. ``table``: source, F, df1, df2, p, p_gg, eps, ng2."""

    n_participants: int
    left_out: list[str]
    table: Any = None
    warnings: list[str] = field(default_factory=list)


@dataclass
class ReviewerAnalysis:
    primary: MixedModelFit
    sensitivity: MixedModelFit
    two_way: TwoWayAnova


def _term(name: str) -> str:
    """``C(k, Treatment(3))[T.4]:C(modality, ...)[T.F+C]`` -> ``k=4 x F+C``."""
    if name == "Intercept":
        return "Intercept (k=3, F+V)"
    if name.startswith("C(cell"):
        return shown(name[name.rfind("[T.") + 3 : -1]) + " vs k=3 F+V"
    parts = []
    for piece in name.split(":"):
        factor = "k=" if piece.startswith("C(k") else ""
        level = piece[piece.rfind("[T.") + 3 : -1] if "[T." in piece else piece
        parts.append(factor + shown(level))
    return " x ".join(parts)


def _messages(caught: list[warnings.WarningMessage]) -> list[str]:
    out: list[str] = []
    for w in caught:
        text = f"{w.category.__name__}: {str(w.message).strip()}"
        if text not in out:
            out.append(text)
    return out


def fit_mixed_model(trials, timeouts: str = "keep") -> MixedModelFit:
    """The mixed model on non-familiarization trials; ``timeouts`` ``"keep"`` (at 90 s,
    the primary rule) or ``"exclude"`` (successes only, the sensitivity analysis)."""
    import numpy as np
    import statsmodels.formula.api as smf

    if timeouts not in ("keep", "exclude"):
        raise AnalysisError(f"timeouts must be 'keep' or 'exclude', not {timeouts!r}")
    data = _analysed(trials).copy()
    data["success"] = data["success"].astype(bool)
    n_timeouts = int((~data["success"]).sum())
    rule = PRIMARY_RULE if timeouts == "keep" else SENSITIVITY_RULE
    if timeouts == "exclude":
        data = data[data["success"]]
    data = data[data["modality"].isin(TABLE_ORDER) & data["k"].isin(CONTACT_COUNTS)]
    fit = MixedModelFit(
        rule=rule,
        n_trials=int(len(data)),
        n_participants=int(data["participant"].nunique()),
        n_timeouts=n_timeouts,
    )
    present = set(zip(data["k"], data["modality"]))
    ks = sorted({k for k, _ in present})
    ms = [m for m in TABLE_ORDER if any(mm == m for _, mm in present)]
    empty = [f"k={k} {m}" for k in ks for m in ms if (k, m) not in present]
    if 3 not in ks or "F+V" not in ms:
        fit.skipped = "no trials in the reference cell (k=3, F+V)"
        return fit
    formula = FORMULA
    if empty:
        # Without every cell the k x modality coding is singular; one factor over the
        # cells present keeps each of them as a difference from the reference cell.
        fit.model = "cells"
        fit.empty_cells = empty
        data["cell"] = [f"k={k} {m}" for k, m in zip(data["k"], data["modality"])]
        formula = CELL_FORMULA
    if fit.n_participants < 2:
        fit.skipped = "fewer than 2 participants: no random intercept to estimate"
        return fit
    data["y"] = np.sqrt(data["completion_s"].astype(float))
    data["k"] = data["k"].astype(int)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            model = smf.mixedlm(formula, data, groups=data["participant"])
            res = model.fit(reml=True, method=OPTIMIZERS)
        except (ValueError, np.linalg.LinAlgError) as e:
            fit.skipped = f"the fit failed: {e}"
            fit.warnings = _messages(caught)
            return fit
    fit.warnings = _messages(caught)
    import pandas as pd

    names = list(model.exog_names)
    ci = res.conf_int().loc[names]
    fit.coefficients = pd.DataFrame(
        {
            "term": [_term(n) for n in names],
            "coef": res.fe_params[names].to_numpy(),
            "ci_low": ci.iloc[:, 0].to_numpy(),
            "ci_high": ci.iloc[:, 1].to_numpy(),
            "p": res.pvalues[names].to_numpy(),
        }
    )
    fit.group_var = float(res.cov_re.iloc[0, 0])
    fit.resid_var = float(res.scale)
    fit.converged = bool(res.converged)
    return fit


def two_way_anova(trials) -> TwoWayAnova:
    """Contacts x modality rm-ANOVA on sqrt(participant cell means), timeouts at 90 s."""
    import numpy as np
    import pingouin as pg

    data = _analysed(trials)
    cells = (
        data.groupby(["participant", "k", "modality"], observed=True)["completion_s"]
        .mean()
        .reset_index()
    )
    wide = cells.pivot_table(index="participant", columns=["k", "modality"], values="completion_s")
    ks = sorted(cells["k"].unique())
    ms = [m for m in TABLE_ORDER if m in set(cells["modality"])]
    if len(ks) < 2 or len(ms) < 2:
        raise AnalysisError("the two-way analysis needs both contact counts and two modalities")
    wanted = [(k, m) for k in ks for m in ms]
    wide = wide.reindex(columns=wanted)
    complete = wide.dropna()
    left_out = sorted(set(wide.index) - set(complete.index))
    if len(complete) < 2:
        raise AnalysisError("the two-way analysis needs 2 participants with every cell")
    long = complete.stack(list(range(complete.columns.nlevels))).rename("t").reset_index()
    long["y"] = np.sqrt(long["t"].astype(float))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        aov = pg.rm_anova(
            long, dv="y", within=["k", "modality"], subject="participant", correction=True
        )
    import pandas as pd

    def col(name: str, row) -> float:
        return float(row[name]) if name in row and pd.notna(row[name]) else math.nan

    rows = []
    for _, r in aov.iterrows():
        rows.append(
            {
                "source": str(r["Source"]).replace(" * ", " x "),
                "F": col("F", r),
                "df1": col("ddof1", r),
                "df2": col("ddof2", r),
                "p": col("p_unc", r) if "p_unc" in r else col("p-unc", r),
                "p_gg": col("p_GG_corr", r) if "p_GG_corr" in r else col("p-GG-corr", r),
                "eps": col("eps", r),
                "ng2": col("ng2", r),
            }
        )
    return TwoWayAnova(
        n_participants=int(len(complete)),
        left_out=[str(p) for p in left_out],
        table=pd.DataFrame(rows),
        warnings=_messages(caught),
    )


def reviewer_analysis(trials) -> ReviewerAnalysis:
    """The mixed model (primary and sensitivity timeout rules) and the two-way ANOVA."""
    return ReviewerAnalysis(
        primary=fit_mixed_model(trials, "keep"),
        sensitivity=fit_mixed_model(trials, "exclude"),
        two_way=two_way_anova(trials),
    )


def _p(p: float) -> str:
    if math.isnan(p):
        return "–"
    return "< 0.0001" if p < 1e-4 else f"{p:.4f}"


def _f(x: float, fmt: str = ".3f") -> str:
    return "–" if math.isnan(x) else format(x, fmt)


def _df(x: float) -> str:
    return "–" if math.isnan(x) else (f"{x:.0f}" if float(x).is_integer() else f"{x:.2f}")


_COEF_HEADER = ["term", "coef [sqrt s]", "95 % CI", "p"]
_ANOVA_HEADER = ["source", "F", "df", "p", "p (GG)", "eps", "eta2_G"]


def _coef_rows(fit: MixedModelFit, aligned: bool) -> list[list[str]]:
    rows = [
        [r.term, _f(r.coef), f"[{_f(r.ci_low)}, {_f(r.ci_high)}]", _p(r.p)]
        for r in fit.coefficients.itertuples()
    ]
    if not aligned:
        return rows
    width = max([len(_COEF_HEADER[1])] + [len(r[1]) for r in rows])
    return [[r[0], r[1].rjust(width), *r[2:]] for r in rows]


def _anova_rows(tw: TwoWayAnova) -> list[list[str]]:
    return [
        [
            r.source,
            _f(r.F, ".2f"),
            f"({_df(r.df1)}, {_df(r.df2)})",
            _p(r.p),
            _p(r.p_gg),
            _f(r.eps),
            _f(r.ng2),
        ]
        for r in tw.table.itertuples()
    ]


def _fit_lines(title: str, fit: MixedModelFit, table) -> list[str]:
    lines = [
        f"{title}: {fit.rule}",
        f"{fit.n_trials} trials, {fit.n_participants} participants "
        f"({fit.n_timeouts} timeouts among the non-familiarization trials)",
    ]
    if fit.skipped:
        return [*lines, f"not fitted: {fit.skipped}"]
    if fit.empty_cells:
        lines.append(
            "no trials in "
            + ", ".join(shown(c) for c in fit.empty_cells)
            + ": k x modality is not estimable, so each cell present is compared with "
            "k=3, F+V"
        )
    lines += [
        table(_COEF_HEADER, _coef_rows(fit, table is _text_table)),
        f"participant intercept variance {fit.group_var:.4f}, residual variance "
        f"{fit.resid_var:.4f} [s]; converged: {'yes' if fit.converged else 'no'}",
    ]
    if fit.group_var < 1e-6 * fit.resid_var:
        lines.append(
            "the participant variance is at its boundary (0): participants do not differ "
            "beyond the residual, and the fixed effects are those of ordinary least squares"
        )
    lines += [f"warning: {w}" for w in fit.warnings] or ["no convergence warnings"]
    return lines


def _two_way_lines(tw: TwoWayAnova, table) -> list[str]:
    lines = [
        "Contacts x modality: two-way repeated-measures ANOVA on sqrt(participant cell "
        "means), timeouts at 90 s",
        f"{tw.n_participants} participants"
        + (f" (left out, a cell missing: {', '.join(tw.left_out)})" if tw.left_out else ""),
        table(_ANOVA_HEADER, _anova_rows(tw)),
    ]
    lines += [f"warning: {w}" for w in tw.warnings]
    return lines


def _lines(res: ReviewerAnalysis, table) -> list[str]:
    return [
        f"Model: sqrt(completion time) ~ k x modality, random intercept per participant "
        f"(statsmodels MixedLM, REML); reference k=3, F+V. Third reading: "
        f"{PER_PARTICIPANT_READING}.",
        "",
        *_fit_lines("Mixed model, primary", res.primary, table),
        "",
        *_fit_lines("Mixed model, sensitivity", res.sensitivity, table),
        "",
        *_two_way_lines(res.two_way, table),
    ]


def format_text(res: ReviewerAnalysis) -> str:
    """The analyses as plain text, under their label."""
    return "\n".join([REVIEWER_LABEL, "=" * len(REVIEWER_LABEL), *_lines(res, _text_table)])


def format_markdown(res: ReviewerAnalysis) -> str:
    """The analyses as a markdown section, under their label."""
    # One paragraph per line, so that a table is never continued by the text after it.
    text = "\n\n".join(line for line in _lines(res, _md_table) if line)
    return f"## {REVIEWER_LABEL}\n\n{text}\n"
