"""The paper's statistics at trial level: trials paired by participant x contacts x wrench.

Section IV of the paper runs a one-way repeated-measures ANOVA over the four feedback
modalities and removes "7 outliers (4 in F+V, and 3 in F_perp+V) ... together with the
paired ones without affecting the dataset balancing", outliers being "cases in which
people do not fail the trial, but needed considerably more time". Eight participant
means cannot hold 7 outliers in two modalities; single trials can. This module is that
reading (:mod:`graspguide.analysis.paper_tables` keeps the per-participant one):

* **Block.** One participant, one contact count k, one wrench: the paper renders each
  wrench in every modality, so a block holds four paired trials. It is the ANOVA's
  subject. Blocks missing a modality are dropped and counted; a block with two trials of
  one modality is an error (the pairing would be ambiguous).
* **Timeouts.** A trial is *censored* when it failed or its time reached the ceiling
  (``ceiling_s``, 90 s in the paper's protocol): its true time is only known to exceed
  the ceiling. Censored trials stay in the ANOVA at their logged time (90 s), because
  the paper counts a failure as its time (Table II) and its outliers are explicitly not
  failures; dropping timeouts would drop whole blocks and with them most C trials.
* **Outliers (the ceiling rule).** Per modality, the boxplot fences Q1 - 1.5 IQR and
  Q3 + 1.5 IQR (quartiles by linear interpolation, as matplotlib's boxplot draws them)
  are computed on that modality's *uncensored* (successful) trial times only, and only
  successful trials above the upper fence are flagged:
  - a timeout is a censored value, not an extreme measurement, so it is never flagged
    and never moves the quartiles (with most C trials at exactly 90 s, quartiles over
    all trials collapse to 90 s and every C success would be flagged);
  - only the upper fence flags, as the paper's outliers are trials that "needed
    considerably more time"; a fast success is not removed;
  - nothing is flagged in a modality whose IQR is 0 or that has fewer than 4 successes
    (no box to measure a distance from).
  A flagged trial removes its whole block (all four modalities); the removed trials are
  reported with their values.
* **Tests.** Square root of the times; Shapiro-Wilk per modality; Mauchly's test of
  sphericity; one-way RM ANOVA (F, df1, df2, partial eta squared; the
  Greenhouse-Geisser-corrected df and p are used when Mauchly rejects at 0.05);
  Bonferroni-corrected paired t-tests between the six pairs (p on the square-root
  scale, differences of means in seconds). pingouin computes all of it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

from graspguide.analysis.paper_tables import AnalysisError, _analysed, _p
from graspguide.core.vocabulary import MODALITIES, shown

BLOCK_KEYS = ("participant", "k", "wrench_id")
MIN_SUCCESSES_FOR_FENCES = 4
MIN_BLOCKS = 3
SPHERICITY_ALPHA = 0.05


@dataclass
class TrialLevelStatistics:
    """What :func:`trial_level_statistics` found; every frame is a pandas DataFrame."""

    ceiling_s: float
    blocks_total: int
    incomplete_blocks: int  # dropped: a modality missing
    retained: Any  # wide: index = block id, columns = MODALITIES, seconds
    # the flagged trials and their paired ones: block, participant, k, wrench_id,
    # modality, completion_s, flagged
    removed: Any
    fences: dict[str, dict[str, float]]  # per modality: q1, q3, iqr, upper, successes
    censored_retained: dict[str, int]  # timeouts kept in the ANOVA, per modality
    normality: Any  # per modality: W, pval, normal
    sphericity: dict[str, Any]  # W, chi2, dof, pval, spher
    anova: dict[str, float]  # F, df1, df2, p, np2, eps, df1_gg, df2_gg, p_gg
    pairwise: Any  # A, B, T, dof, p_unc, p_bonf, mean_A_s, mean_B_s, diff_s
    notes: list[str] = field(default_factory=list)

    @property
    def n_blocks(self) -> int:
        return len(self.retained)

    @property
    def gg_applied(self) -> bool:
        p = self.sphericity["pval"]
        return bool(p == p and p < SPHERICITY_ALPHA)

    def flagged(self):
        """The trials that were outliers themselves (not their paired values)."""
        return self.removed[self.removed["flagged"]]


def _block_id(participant: Any, k: Any, wrench: Any) -> str:
    return f"{participant}/k{k}/{wrench}"


def ceiling_outliers(
    times, censored, ceiling_s: float = 90.0
) -> tuple[list[bool], dict[str, float]]:
    """Flags per trial of one modality by the rule of the module docstring.

    ``times`` and ``censored`` are equal-length sequences. Returns the flags and the
    fences (``q1``, ``q3``, ``iqr``, ``upper``, ``successes``; NaN when not computed)."""
    import numpy as np

    t = np.asarray(times, dtype=float)
    c = np.asarray(censored, dtype=bool) | (t >= ceiling_s)
    ok = t[~c]
    fences = {"q1": math.nan, "q3": math.nan, "iqr": math.nan, "upper": math.nan}
    fences["successes"] = float(len(ok))
    if len(ok) < MIN_SUCCESSES_FOR_FENCES:
        return [False] * len(t), fences
    q1, q3 = (float(q) for q in np.percentile(ok, [25, 75]))
    iqr = q3 - q1
    fences.update(q1=q1, q3=q3, iqr=iqr)
    if iqr <= 0:
        return [False] * len(t), fences
    upper = q3 + 1.5 * iqr
    fences["upper"] = upper
    return [bool(not ci and ti > upper) for ti, ci in zip(t, c)], fences


def _quiet(test, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return test(*args, **kwargs)


def trial_level_statistics(
    trials, ceiling_s: float = 90.0, remove_outliers: bool = True
) -> TrialLevelStatistics:
    """The paper's statistics on trials paired by block (see the module docstring).
    ``remove_outliers=False`` keeps every complete block (the flags are still counted).

    ``trials`` is the frame :func:`graspguide.analysis.paper_tables.load` returns;
    familiarization trials are left out. Raises :class:`AnalysisError` when no block has
    all four modalities, a block has one modality twice, fewer than 3 blocks remain after
    outlier removal, or a modality has zero variance after removal."""
    import numpy as np
    import pandas as pd
    import pingouin as pg

    data = _analysed(trials).copy()
    data = data[data["modality"].isin(MODALITIES)]
    if (data["completion_s"] < 0).any():
        raise AnalysisError("negative completion times cannot be square-root transformed")
    data["block"] = [_block_id(*r) for r in zip(*(data[c] for c in BLOCK_KEYS))]
    counts = data.groupby(["block", "modality"]).size()
    twice = counts[counts > 1]
    if len(twice):
        b, m = twice.index[0]
        raise AnalysisError(
            f"block {b} has {int(twice.iloc[0])} trials of {m} ({len(twice)} such cases): "
            "trials cannot be paired by participant x contacts x wrench"
        )
    per_block = data.groupby("block")["modality"].nunique()
    complete = per_block[per_block == len(MODALITIES)].index
    blocks_total = int(len(per_block))
    incomplete = blocks_total - len(complete)
    if len(complete) == 0:
        raise AnalysisError(
            f"no complete block: none of {blocks_total} participant x contacts x wrench "
            "blocks has a trial of every modality"
        )
    data = data[data["block"].isin(complete)].copy()
    data["censored"] = ~data["success"].astype(bool) | (data["completion_s"] >= ceiling_s)

    fences: dict[str, dict[str, float]] = {}
    flagged_rows = []
    for m in MODALITIES:
        sub = data[data["modality"] == m]
        flags, fences[m] = ceiling_outliers(sub["completion_s"], sub["censored"], ceiling_s)
        flagged_rows.extend(idx for idx, f in zip(sub.index, flags) if f)
    flagged_blocks = set(data.loc[flagged_rows, "block"]) if remove_outliers else set()
    cols = ["block", *BLOCK_KEYS, "modality", "completion_s"]
    removed = data[data["block"].isin(flagged_blocks)][cols].copy()
    removed["flagged"] = removed.index.isin(flagged_rows)
    removed = removed.sort_values(["block", "modality"]).reset_index(drop=True)
    kept = data[~data["block"].isin(flagged_blocks)]

    n = kept["block"].nunique()
    if n < MIN_BLOCKS:
        raise AnalysisError(
            f"fewer than {MIN_BLOCKS} blocks: {n} complete block(s) remain after removing "
            f"{len(flagged_blocks)} with outliers"
        )
    retained = kept.pivot(index="block", columns="modality", values="completion_s")[
        list(MODALITIES)
    ]
    root = np.sqrt(retained)
    for m in MODALITIES:
        if retained[m].nunique() < 2:
            raise AnalysisError(
                f"{m} has zero variance after outlier removal (every one of its {n} "
                f"trials is {float(retained[m].iloc[0]):g} s): the tests cannot be computed"
            )
    censored_retained = {
        m: int(kept[(kept["modality"] == m)]["censored"].sum()) for m in MODALITIES
    }

    long = root.reset_index().melt(id_vars="block", var_name="modality", value_name="y")
    long["modality"] = pd.Categorical(long["modality"], categories=list(MODALITIES))
    within = {"dv": "y", "within": "modality", "subject": "block"}

    notes: list[str] = []
    if not remove_outliers:
        notes.append("outlier removal off: every complete block is analysed")
    normality = _quiet(pg.normality, long, dv="y", group="modality", method="shapiro")
    normality = normality.reindex(list(MODALITIES))
    if n > 5000:
        notes.append("Shapiro-Wilk p is approximate above 5000 values per modality")

    sph = _quiet(pg.sphericity, long, **within, method="mauchly")
    sphericity = {
        "W": float(sph.W),
        "chi2": float(sph.chi2),
        "dof": int(sph.dof),
        "pval": float(sph.pval),
        "spher": bool(sph.spher),
    }

    aov = _quiet(pg.rm_anova, long, **within, detailed=True, correction=True, effsize="np2")
    r0, r1 = aov.iloc[0], aov.iloc[1]
    df1, df2 = float(r0["DF"]), float(r1["DF"])
    eps = float(r0["eps"]) if "eps" in aov else math.nan
    anova = {
        "F": float(r0["F"]),
        "df1": df1,
        "df2": df2,
        "p": float(r0["p_unc"]),
        "np2": float(r0["np2"]),
        "eps": eps,
        "df1_gg": df1 * eps,
        "df2_gg": df2 * eps,
        "p_gg": float(r0["p_GG_corr"]) if "p_GG_corr" in aov else math.nan,
    }

    pw = _quiet(pg.pairwise_tests, long, **within, padjust="bonf", parametric=True)
    rows = []
    for _, r in pw.iterrows():
        a, b = str(r["A"]), str(r["B"])
        rows.append(
            {
                "A": a,
                "B": b,
                "T": float(r["T"]),
                "dof": float(r["dof"]),
                "p_unc": float(r["p_unc"]),
                "p_bonf": float(r["p_corr"]),
                "mean_A_s": float(retained[a].mean()),
                "mean_B_s": float(retained[b].mean()),
                "diff_s": float(retained[a].mean() - retained[b].mean()),
            }
        )
    return TrialLevelStatistics(
        ceiling_s=ceiling_s,
        blocks_total=blocks_total,
        incomplete_blocks=incomplete,
        retained=retained,
        removed=removed,
        fences=fences,
        censored_retained=censored_retained,
        normality=normality,
        sphericity=sphericity,
        anova=anova,
        pairwise=pd.DataFrame(rows),
        notes=notes,
    )


def _df(x: float) -> str:
    return f"{x:.0f}" if float(x).is_integer() else f"{x:.2f}"


def anova_line(stats: TrialLevelStatistics) -> str:
    a = stats.anova
    line = (
        f"F({_df(a['df1'])}, {_df(a['df2'])}) = {a['F']:.3f}, p = {_p(a['p'])}, "
        f"partial eta^2 = {a['np2']:.3f}"
    )
    if stats.gg_applied:
        line += (
            f"; GG-corrected (epsilon = {a['eps']:.3f}) F({_df(a['df1_gg'])}, "
            f"{_df(a['df2_gg'])}) = {a['F']:.3f}, p = {_p(a['p_gg'])}"
        )
    return line


def _summary_lines(stats: TrialLevelStatistics) -> list[str]:
    s = stats.sphericity
    flagged = stats.flagged()
    by_mod = {m: int((flagged["modality"] == m).sum()) for m in MODALITIES}
    return [
        f"blocks (participant x k x wrench): {stats.blocks_total}; dropped for a missing "
        f"modality: {stats.incomplete_blocks}; removed for outliers: "
        f"{stats.removed['block'].nunique()}; analysed: {stats.n_blocks}",
        "outliers (successful trials above Q3 + 1.5 IQR of the modality's successes; "
        "timeouts never flagged): " + ", ".join(f"{shown(m)} {by_mod[m]}" for m in MODALITIES),
        f"timeouts kept at {stats.ceiling_s:g} s: "
        + ", ".join(f"{shown(m)} {stats.censored_retained[m]}" for m in MODALITIES),
        f"Mauchly: W = {s['W']:.3f}, chi2({s['dof']}) = {s['chi2']:.2f}, p = {_p(s['pval'])}"
        + (" -> sphericity violated, Greenhouse-Geisser applied" if stats.gg_applied else ""),
    ]


def format_text(stats: TrialLevelStatistics) -> str:
    """Plain-text report of the trial-level analysis, degrees of freedom printed."""
    lines = ["Trial-level repeated-measures analysis (square-rooted completion times)"]
    lines += _summary_lines(stats)
    for r in stats.flagged().itertuples(index=False):
        lines.append(
            f"  removed outlier: {r.participant} k={r.k} {r.wrench_id} "
            f"{shown(r.modality)} {r.completion_s:.2f} s (with its 3 paired trials)"
        )
    lines.append(
        "Shapiro-Wilk: "
        + ", ".join(
            f"{shown(m)} W = {float(stats.normality.loc[m, 'W']):.3f} "
            f"p = {_p(float(stats.normality.loc[m, 'pval']))}"
            for m in MODALITIES
        )
    )
    lines.append("RM ANOVA: " + anova_line(stats))
    lines.append("Bonferroni pairwise (difference of means in s; p on the sqrt scale):")
    for r in stats.pairwise.itertuples(index=False):
        lines.append(
            f"  {shown(r.A)} - {shown(r.B)}: {r.diff_s:+.2f} s, "
            f"t({_df(r.dof)}) = {r.T:.2f}, p_bonf = {_p(r.p_bonf)}"
        )
    lines += [f"note: {n}" for n in stats.notes]
    return "\n".join(lines) + "\n"


def format_markdown(stats: TrialLevelStatistics) -> str:
    """The same as :func:`format_text`, as a ``report.md`` section."""
    out = ["## Trial-level statistics (the paper's reading)", ""]
    out += [f"- {line}" for line in _summary_lines(stats)]
    out += [f"- RM ANOVA: {anova_line(stats)}", ""]
    out += [
        "| modality | mean [s] | SD [s] | Shapiro-Wilk W | p | outliers |",
        "|---|---|---|---|---|---|",
    ]
    flagged = stats.flagged()
    for m in MODALITIES:
        col = stats.retained[m]
        out.append(
            f"| {shown(m)} | {col.mean():.2f} | {col.std(ddof=1):.2f} | "
            f"{float(stats.normality.loc[m, 'W']):.3f} | "
            f"{_p(float(stats.normality.loc[m, 'pval']))} | "
            f"{int((flagged['modality'] == m).sum())} |"
        )
    out += ["", "| pair | difference [s] | t | df | p (Bonferroni) |", "|---|---|---|---|---|"]
    for r in stats.pairwise.itertuples(index=False):
        out.append(
            f"| {shown(r.A)} - {shown(r.B)} | {r.diff_s:+.2f} | {r.T:.2f} | {_df(r.dof)} | "
            f"{_p(r.p_bonf)} |"
        )
    if len(flagged):
        out += ["", "Removed outliers (each with its 3 paired trials):", ""]
        out += ["| participant | k | wrench | modality | time [s] |", "|---|---|---|---|---|"]
        for r in flagged.itertuples(index=False):
            out.append(
                f"| {r.participant} | {r.k} | {r.wrench_id} | {shown(r.modality)} | "
                f"{r.completion_s:.2f} |"
            )
    out += ["", *(f"Note: {n}" for n in stats.notes)]
    return "\n".join(out) + "\n"
