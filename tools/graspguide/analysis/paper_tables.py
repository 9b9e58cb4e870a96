"""``graspguide analyze``: the paper's tables, statistics and Figure 4 from a study's logs.

Input: one or more study folders ``STUDY/`` (one folder per participant ``STUDY/<PID>/``)
or participant folders, each with its trial records and its TLX records
(:mod:`graspguide.records.files` names them; :mod:`graspguide.records.trial` gives their
fields and checks every line); familiarization trials are not analysed.

What it computes (Section IV of the paper):

* Table I   successes, failures and success rate per condition (modality x k);
* Table II  mean and SD of the completion time per condition (a failed trial counts as
            its logged time, 90 s in the paper's protocol);
* Table III NASA-TLX mean and SD per scale, constant (C) vs varying (V) intensity;
* the statistics: per-participant mean completion time per modality pooled over both
  contact counts; boxplot outliers (below Q1 - 1.5 IQR or above Q3 + 1.5 IQR of a
  modality's participant means; quartiles as matplotlib's boxplot draws them) removed
  together with their paired values, i.e. the participant's whole row; square-root
  transform; Shapiro-Wilk per modality; Mauchly's test of sphericity; one-way
  repeated-measures ANOVA (pingouin, cross-checked with statsmodels' AnovaRM);
  Bonferroni-corrected pairwise paired t-tests;
* Figure 4  mean +- SD of the participant means per modality with the Bonferroni
            p-values, as PNG and SVG;
* ``report.md`` with all of it; it opens with "SIMULATED DATA -- not human results"
  when any record is simulated.

pandas, pingouin, statsmodels and matplotlib are imported when used, so registering the
subcommand costs nothing at start-up.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from graspguide.core.vocabulary import MODALITIES, shown
from graspguide.protocol.tlx import TLX_MAX, TLX_MIN, TLX_NAMES
from graspguide.records.files import TLX_FILE, TRIALS_FILE, ParticipantFiles
from graspguide.records.storage import JsonlDamaged, LeftOutLine, complete_records
from graspguide.records.trial import (
    CONTACT_COUNTS,
    TLX_READ_FIELDS,
    TRIAL_READ_FIELDS,
    RecordError,
    check_tlx_record,
    check_trial_record,
)

# Statistics and Figure 4 order, and the paper's Tables I-II order.
TABLE_ORDER: tuple[str, ...] = ("F+V", "Fperp+V", "F+C", "Fperp+C")
# Table III column order of the paper.
TLX_SCALES: tuple[str, ...] = ("MD", "PD", "TD", "PE", "EF", "FR")
MODE_NAMES = {"C": "Constant intensity (C)", "V": "Varying intensity (V)"}
IQR_FACTOR = 1.5
SIMULATED_BANNER = "SIMULATED DATA — not human results"
# Columns of the frames load() returns: the checked fields of each record
# (records.trial), then ``source``, the record's FILE:LINE.
TRIAL_COLUMNS = (*TRIAL_READ_FIELDS, "source")
TLX_COLUMNS = (*TLX_READ_FIELDS, *TLX_SCALES, "source")

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


class AnalysisError(Exception):
    """Bad or insufficient input; the message says what and where."""


# ======================================================================================
# Loading
# ======================================================================================


def _read_jsonl(path: Path, left_out: list[LeftOutLine]) -> list[tuple[str, dict[str, Any]]]:
    """(``FILE:LINE``, object) for every complete record (records.complete_records); a
    damaged last line is left out and added to ``left_out``, a damaged earlier line is
    an error."""
    try:
        records, tail = complete_records(path)
    except JsonlDamaged as e:
        raise AnalysisError(str(e)) from None
    except OSError as e:
        raise AnalysisError(f"{path}: cannot read ({e.strerror or e})") from None
    if tail is not None:
        left_out.append(tail)
    return records


def _trial_row(where: str, rec: dict[str, Any]) -> dict[str, Any]:
    try:
        return {**check_trial_record(where, rec), "source": where}
    except RecordError as e:
        raise AnalysisError(str(e)) from None


def _tlx_row(where: str, rec: dict[str, Any]) -> dict[str, Any]:
    # A session logged with scales null (a simulated source without a --tlx file, a
    # host-less run) has no answers: Table III leaves it out and says so.
    scales = {s: TLX_NAMES[s] for s in TLX_SCALES}
    try:
        return {**check_tlx_record(where, rec, scales, TLX_MIN, TLX_MAX), "source": where}
    except RecordError as e:
        raise AnalysisError(str(e)) from None


def participant_dirs(paths: Iterable[str | os.PathLike]) -> list[Path]:
    """The participant folders under the given study or participant folders, in order.

    A folder holding trial or TLX records is a participant folder; otherwise its
    subfolders that hold either file are (others, such as ``analysis/``, are skipped).
    """
    found: list[Path] = []
    seen = set()
    for p in paths:
        path = Path(p)
        if not path.exists():
            raise AnalysisError(f"{path}: no such file or folder")
        if not path.is_dir():
            raise AnalysisError(
                f"{path}: not a folder (give a study folder or a participant "
                f"folder holding {TRIALS_FILE} and {TLX_FILE})"
            )
        if ParticipantFiles(str(path)).holds_records():
            candidates = [path]
        else:
            candidates = sorted(
                c for c in path.iterdir() if c.is_dir() and ParticipantFiles(str(c)).holds_records()
            )
            if not candidates:
                raise AnalysisError(
                    f"{path}: no participant data: neither {TRIALS_FILE} here nor a "
                    f"participant folder {path}/<PID>/ holding {TRIALS_FILE} and {TLX_FILE}"
                )
        for c in candidates:
            key = c.resolve()
            if key not in seen:
                seen.add(key)
                found.append(c)
    if not found:
        raise AnalysisError("no study or participant folder given")
    return found


def load(paths: Iterable[str | os.PathLike], left_out: list[LeftOutLine] | None = None):
    """Read study or participant folders into ``(trials, tlx)`` pandas DataFrames.

    ``trials`` has one row per logged trial, familiarization trials included (flagged in
    the ``familiarization`` column; the tables and statistics leave them out), with the
    columns ``TRIAL_COLUMNS``; ``tlx`` one row per session with the columns
    ``TLX_COLUMNS`` (one column per scale). ``source`` is ``FILE:LINE`` of the record.
    Raises ``AnalysisError`` for a missing file, a malformed line (``FILE:LINE``), a
    missing or mistyped field, a trial or session logged twice, or a participant found in
    two folders. A damaged last line of a file (a run killed mid-write) is left out, the
    records before it read, and the line added to ``left_out``.
    """
    import pandas as pd

    trial_rows: list[dict[str, Any]] = []
    tlx_rows: list[dict[str, Any]] = []
    owner: dict[str, Path] = {}
    trial_keys: dict[tuple[str, int, int], str] = {}
    tlx_keys: dict[tuple[str, int], str] = {}
    for folder in participant_dirs(paths):
        for name in (TRIALS_FILE, TLX_FILE):
            if not (folder / name).is_file():
                raise AnalysisError(
                    f"{folder}: missing {name} (a participant folder needs "
                    f"both {TRIALS_FILE} and {TLX_FILE})"
                )
        here = set()
        for path, parse, key_of, what, rows, keys in (
            (
                TRIALS_FILE,
                _trial_row,
                lambda r: (r["participant"], r["session"], r["trial_index"]),
                lambda r: f"trial {r['trial_index']} of session {r['session']}",
                trial_rows,
                trial_keys,
            ),
            (
                TLX_FILE,
                _tlx_row,
                lambda r: (r["participant"], r["session"]),
                lambda r: f"NASA-TLX of session {r['session']}",
                tlx_rows,
                tlx_keys,
            ),
        ):
            for where, rec in _read_jsonl(folder / path, left_out if left_out is not None else []):
                row = parse(where, rec)
                key = key_of(row)
                if key in keys:
                    raise AnalysisError(
                        f"{where}: {what(row)} of {row['participant']} is "
                        f"logged twice (first at {keys[key]})"
                    )
                keys[key] = where
                here.add(row["participant"])
                rows.append(row)
        for pid in here:
            if pid in owner and owner[pid] != folder:
                raise AnalysisError(
                    f"participant {pid} appears in two folders: {owner[pid]} and {folder}"
                )
            owner[pid] = folder
    trials = pd.DataFrame(trial_rows, columns=list(TRIAL_COLUMNS))
    tlx = pd.DataFrame(tlx_rows, columns=list(TLX_COLUMNS))
    if trials.empty:
        raise AnalysisError(
            "no trials in " + ", ".join(f"{f}/{TRIALS_FILE}" for f in participant_dirs(paths))
        )
    return trials, tlx


def _analysed(trials):
    data = trials[~trials["familiarization"].astype(bool)]
    if data.empty:
        raise AnalysisError("every trial is a familiarization trial: nothing to analyse")
    return data


# ======================================================================================
# Tables
# ======================================================================================


def _conditions(data) -> list[tuple[int, str]]:
    present = set(zip(data["k"], data["modality"]))
    return [(k, m) for k in CONTACT_COUNTS for m in TABLE_ORDER if (k, m) in present]


def table1(trials):
    """Table I: per condition (k, modality) the successes, failures, trials and rate."""
    import pandas as pd

    data = _analysed(trials)
    rows = []
    for k, m in _conditions(data):
        sel = data[(data["k"] == k) & (data["modality"] == m)]
        s = int(sel["success"].sum())
        n = int(len(sel))
        rows.append(
            {
                "k": k,
                "modality": m,
                "successes": s,
                "failures": n - s,
                "trials": n,
                "success_rate": s / n,
            }
        )
    return pd.DataFrame(
        rows, columns=["k", "modality", "successes", "failures", "trials", "success_rate"]
    )


def table2(trials):
    """Table II: per condition the mean and SD (n-1) of the completion time in seconds."""
    import pandas as pd

    data = _analysed(trials)
    rows = []
    for k, m in _conditions(data):
        t = data[(data["k"] == k) & (data["modality"] == m)]["completion_s"]
        rows.append(
            {
                "k": k,
                "modality": m,
                "mean_s": float(t.mean()),
                "sd_s": float(t.std(ddof=1)) if len(t) > 1 else math.nan,
                "trials": int(len(t)),
            }
        )
    return pd.DataFrame(rows, columns=["k", "modality", "mean_s", "sd_s", "trials"])


def table3(tlx):
    """Table III: NASA-TLX mean and SD (n-1) per scale, rows C and V (sessions pooled).

    Sessions logged without a questionnaire (``scales`` null) are left out."""
    import pandas as pd

    rows = []
    answered = tlx.dropna(subset=list(TLX_SCALES))
    for mode in ("C", "V"):
        sel = answered[answered["mode"] == mode]
        if sel.empty:
            continue
        row: dict[str, Any] = {"mode": mode, "sessions": int(len(sel))}
        for s in TLX_SCALES:
            row[f"{s}_mean"] = float(sel[s].mean())
            row[f"{s}_sd"] = float(sel[s].std(ddof=1)) if len(sel) > 1 else math.nan
        rows.append(row)
    cols = ["mode", "sessions"] + [f"{s}_{w}" for s in TLX_SCALES for w in ("mean", "sd")]
    return pd.DataFrame(rows, columns=cols)


# ======================================================================================
# Statistics
# ======================================================================================


def participant_means(trials):
    """Per-participant mean completion time (s) per modality, both contact counts pooled.

    A wide DataFrame: index participant, columns ``MODALITIES``. A participant without
    any trial of a modality is an error that names both.
    """
    data = _analysed(trials)
    wide = data.pivot_table(
        index="participant", columns="modality", values="completion_s", aggfunc="mean"
    )
    wide = wide.reindex(columns=list(MODALITIES))
    missing = [(p, m) for p in wide.index for m in MODALITIES if math.isnan(wide.loc[p, m])]
    if missing:
        by: dict[str, list[str]] = {}
        for p, m in missing:
            by.setdefault(p, []).append(m)
        detail = "; ".join(f"{p} has no trials of modality {', '.join(ms)}" for p, ms in by.items())
        raise AnalysisError(
            f"{detail}: the repeated-measures analysis needs every "
            "participant in all four modalities (F+C, Fperp+C, F+V, Fperp+V)"
        )
    wide.columns.name = "modality"
    return wide


def boxplot_outliers(wide):
    """Values beyond 1.5 IQR from the box (per modality column), as matplotlib draws it.

    Returns ``(outliers, bounds)``: a list of ``(participant, modality, value)`` and a
    dict modality -> ``(low, high)`` fences. Quartiles by linear interpolation
    (numpy's default, which matplotlib's boxplot uses).
    """
    import numpy as np

    found = []
    bounds = {}
    for m in wide.columns:
        col = wide[m].to_numpy(dtype=float)
        q1, q3 = np.percentile(col, [25, 75])
        low, high = q1 - IQR_FACTOR * (q3 - q1), q3 + IQR_FACTOR * (q3 - q1)
        bounds[m] = (float(low), float(high))
        for p, v in wide[m].items():
            if v < low or v > high:
                found.append((p, m, float(v)))
    return found, bounds


@dataclass
class Statistics:
    """The paper's statistics on per-participant means (see ``paper_statistics``)."""

    means: Any  # wide DataFrame, every participant, seconds
    outliers: list[tuple[str, str, float]]
    fences: dict[str, tuple[float, float]]
    removed: list[str]  # participants whose whole row was removed
    retained: Any  # wide DataFrame, seconds, after outlier removal
    transformed: Any  # sqrt of retained
    normality: Any  # DataFrame modality -> W, pval, normal
    sphericity: dict[str, Any]  # W, chi2, dof, pval, spher (or note)
    anova: dict[str, Any]  # pingouin: F, df1, df2, p, p_gg, eps, ng2, SS...
    anova_statsmodels: dict[str, Any]  # F, df1, df2, p
    pairwise: Any  # DataFrame A, B, T, dof, p_unc, p_bonf, diff_s
    notes: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return int(len(self.retained))

    @property
    def inferential(self) -> bool:
        """False when too few participants remain for the ANOVA and the t-tests (a pilot):
        the tables, the participant means and Figure 4 are there, the tests are not."""
        return self.anova is not None

    def anova_line(self) -> str:
        a, sm = self.anova, self.anova_statsmodels
        removed = (
            f"{len(self.removed)} removed as boxplot outliers ({', '.join(self.removed)})"
            if self.removed
            else "none removed as outliers"
        )
        if a is None:
            return f"Inferential statistics not computed: {self.notes[0]}."
        return (
            f"One-way repeated-measures ANOVA on sqrt(completion time), n = {self.n} "
            f"participants ({removed}): F({a['df1']:g}, {a['df2']:g}) = {a['F']:.3f}, "
            f"p = {_p(a['p'])}; statsmodels AnovaRM F = {sm['F']:.3f}, p = {_p(sm['p'])}"
        )


def _long(wide, value: str = "y"):
    long = wide.reset_index().melt(id_vars="participant", var_name="modality", value_name=value)
    import pandas as pd

    long["modality"] = pd.Categorical(long["modality"], categories=list(MODALITIES), ordered=True)
    return long.sort_values(["participant", "modality"]).reset_index(drop=True)


_PAIRWISE_COLUMNS = ["A", "B", "T", "dof", "p_unc", "p_bonf", "mean_A_s", "mean_B_s", "diff_s"]
# Mauchly's test where it cannot be computed (fewer participants than modalities).
_NO_SPHERICITY: dict[str, Any] = {
    "W": math.nan,
    "chi2": math.nan,
    "dof": len(MODALITIES) * (len(MODALITIES) - 1) // 2 - 1,
    "pval": math.nan,
    "pval_second_order": math.nan,
    "spher": None,
}


def _no_normality():
    """Shapiro-Wilk where it cannot be computed (fewer than 4 participants)."""
    import pandas as pd

    return pd.DataFrame(
        {"W": math.nan, "pval": math.nan, "normal": False},
        index=pd.Index(list(MODALITIES), name="modality"),
    )


def _no_tests() -> dict[str, Any]:
    """The tests' fields of a study on which they cannot be computed."""
    import pandas as pd

    return {
        "normality": _no_normality(),
        "sphericity": dict(_NO_SPHERICITY),
        "anova": None,
        "anova_statsmodels": None,
        "pairwise": pd.DataFrame(columns=_PAIRWISE_COLUMNS),
    }


# Below this share of the total sum of squares, the within-subject error is rounding.
_FLAT_ERROR_SHARE = 1e-12


def _no_error_variance(transformed) -> str | None:
    """Why the RM ANOVA and the paired t-tests are undefined on ``transformed``, or None.

    Both divide by the within-subject error (what neither the participant nor the
    modality explains). When every participant's times differ across modalities by the
    same amounts, e.g. every trial timed out, that error is zero: F is 0/0 or x/0 and the
    libraries return a column-less table or a huge negative F, so no test is reported."""

    y = transformed.to_numpy(dtype=float)
    if y.shape[0] < 2:
        return None
    residual = y - y.mean(axis=1, keepdims=True) - y.mean(axis=0, keepdims=True) + y.mean()
    ss_error = float((residual**2).sum())
    ss_total = float(((y - y.mean()) ** 2).sum())
    if ss_error > _FLAT_ERROR_SHARE * max(ss_total, 1.0):
        return None
    return (
        "the repeated-measures ANOVA and the paired t-tests are undefined: the "
        f"{y.shape[0]} participants' times differ across the modalities by the same "
        "amounts (no within-subject error; e.g. every trial timed out or every time is "
        "equal), so Tables I-III, the participant means and Figure 4 are descriptive only; "
        "check the trials' timeout and the records"
    )


def paper_statistics(means, remove_outliers: bool = True) -> Statistics:
    """The paper's analysis of completion time on a wide participant x modality frame.

    ``means``: index participant, columns ``MODALITIES`` (seconds), e.g. from
    ``participant_means``. Outlier rows removed (``remove_outliers``), square root,
    Shapiro-Wilk per modality, Mauchly, one-way RM ANOVA (pingouin; statsmodels AnovaRM
    alongside), Bonferroni-corrected paired t-tests (pingouin ``padjust='bonf'``).
    """
    import numpy as np

    means = means.reindex(columns=list(MODALITIES)).astype(float)
    means.index = means.index.map(str).rename("participant")
    means.columns.name = "modality"
    if means.isna().any().any():
        raise AnalysisError("participant means contain missing values")
    notes: list[str] = []
    if len(means) == 0:
        raise AnalysisError("no participant has trials of all four modalities to analyse")
    if remove_outliers:
        outliers, fences = boxplot_outliers(means)
    else:
        outliers, fences = [], {}
    removed = sorted({p for p, _, _ in outliers}, key=list(means.index).index)
    retained = means.drop(index=removed)
    if (retained < 0).any().any():
        raise AnalysisError("negative completion times cannot be square-root transformed")
    transformed = np.sqrt(retained)
    flat = _no_error_variance(transformed)
    if len(retained) >= 2 and flat is None:
        tests = _repeated_measures_tests(retained, transformed, notes)
    elif flat is not None:
        notes = [flat]
        tests = _no_tests()
    else:
        # A pilot (or outlier removal) leaves one participant: no within-subject variance,
        # so no test; the descriptive results stand on their own.
        if removed:
            why = (
                f"the repeated-measures ANOVA and the paired t-tests need at least 2 "
                f"participants; after removing the boxplot outliers ({', '.join(removed)}) "
                f"{len(retained)} remains: analyse more participants, or keep the "
                "outliers (--keep-outliers)"
            )
        else:
            why = (
                f"the repeated-measures ANOVA and the paired t-tests need at least 2 "
                f"participants with all four modalities; this study has {len(means)} "
                f"({', '.join(map(str, means.index))}), e.g. a pilot: Tables I-III, the "
                "participant means and Figure 4 are descriptive only"
            )
        notes = [why]
        tests = _no_tests()
    return Statistics(
        means=means,
        outliers=outliers,
        fences=fences,
        removed=removed,
        retained=retained,
        transformed=transformed,
        notes=notes,
        **tests,
    )


# The design of every within-subject test: each participant under every modality.
_WITHIN = {"within": "modality", "subject": "participant"}


def _quietly(test: Callable[..., Any], long, **options) -> Any:
    """A pingouin test of the square-rooted times ``y`` of the long frame, its warnings
    (small samples, deprecations) silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return test(long, dv="y", **options)


def _repeated_measures_tests(retained, transformed, notes: list[str]) -> dict[str, Any]:
    """Shapiro-Wilk, Mauchly, the RM ANOVA and the Bonferroni-corrected paired t-tests on
    at least 2 participants; what could not be computed is said in ``notes``."""
    import pandas as pd
    import pingouin as pg
    from statsmodels.stats.anova import AnovaRM

    long = _long(transformed)
    n = len(retained)

    # Shapiro-Wilk per modality (pingouin needs >= 4 values per group).
    if n >= 4:
        normality = _quietly(pg.normality, long, group="modality", method="shapiro")
        normality = normality.reindex(list(MODALITIES))
    else:
        normality = _no_normality()
        notes.append(f"Shapiro-Wilk not computed: it needs at least 4 participants, {n} remain")

    # Mauchly: the covariance of the k-1 = 3 differences must be of full rank: n >= 4.
    if n >= len(MODALITIES):
        sph = _quietly(pg.sphericity, long, **_WITHIN, method="mauchly")
        # p from the chi-square approximation (what SPSS reports, and the paper: chi2(5) =
        # 10.56, p = 0.061); pingouin's p adds R's second-order term (mauchly.test).
        from scipy.stats import chi2 as _chi2

        p_chi2 = float(_chi2.sf(float(sph.chi2), int(sph.dof)))
        sphericity = {
            "W": float(sph.W),
            "chi2": float(sph.chi2),
            "dof": int(sph.dof),
            "pval": p_chi2,
            "pval_second_order": float(sph.pval),
            "spher": bool(p_chi2 > 0.05),
        }
    else:
        sphericity = dict(_NO_SPHERICITY)
        notes.append(
            f"Mauchly's test not computed: it needs at least {len(MODALITIES)} "
            f"participants, {n} remain"
        )

    aov = _quietly(pg.rm_anova, long, **_WITHIN, detailed=True, correction=True)
    r0, r1 = aov.iloc[0], aov.iloc[1]
    anova = {
        "F": float(r0["F"]),
        "df1": float(r0["DF"]),
        "df2": float(r1["DF"]),
        "p": float(r0["p_unc"]),
        "SS": float(r0["SS"]),
        "SS_error": float(r1["SS"]),
        "MS": float(r0["MS"]),
        "MS_error": float(r1["MS"]),
        "p_gg": float(r0["p_GG_corr"]) if "p_GG_corr" in aov else math.nan,
        "eps_gg": float(r0["eps"]) if "eps" in aov else math.nan,
        "ng2": float(r0["ng2"]) if "ng2" in aov else math.nan,
    }

    sm_data = long.assign(modality=long["modality"].astype(str))
    sm = AnovaRM(sm_data, depvar="y", subject="participant", within=["modality"]).fit()
    t = sm.anova_table.iloc[0]
    anova_sm = {
        "F": float(t["F Value"]),
        "df1": float(t["Num DF"]),
        "df2": float(t["Den DF"]),
        "p": float(t["Pr > F"]),
    }

    pw = _quietly(pg.pairwise_tests, long, **_WITHIN, padjust="bonf", parametric=True)
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
    return {
        "normality": normality,
        "sphericity": sphericity,
        "anova": anova,
        "anova_statsmodels": anova_sm,
        "pairwise": pd.DataFrame(rows, columns=_PAIRWISE_COLUMNS),
    }


# ======================================================================================
# Figure 4
# ======================================================================================


def _p(p: float) -> str:
    if p != p:
        return "n/a"
    if p < 0.0005:
        return f"{p:.2g}" if p >= 1e-300 else "< 1e-300"
    return f"{p:.3f}"


def figure4(
    stats: Statistics, out_dir: str | os.PathLike, simulated: bool = False, stem: str = "figure4"
) -> list[Path]:
    """Mean +- SD per modality (retained participants' means, s) with the Bonferroni p
    of every pair above the bars; writes ``stem.png`` and ``stem.svg`` (Agg)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    means = [float(stats.retained[m].mean()) for m in MODALITIES]
    sds = [float(stats.retained[m].std(ddof=1)) if stats.n > 1 else 0.0 for m in MODALITIES]
    colors = ["#c0504d", "#e6a19f", "#4f81bd", "#a7c0de"]
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    x = list(range(len(MODALITIES)))
    ax.bar(x, means, yerr=sds, capsize=6, color=colors, edgecolor="black", linewidth=0.8)
    ax.set_xticks(x, [shown(m) for m in MODALITIES])
    ax.set_ylabel("completion time [s] (participant means)")
    top = max(m + s for m, s in zip(means, sds))
    step = 0.09 * top if top > 0 else 1.0
    level = top + 0.5 * step
    # Short spans first, so brackets nest.
    pairs = sorted(
        stats.pairwise.itertuples(index=False),
        key=lambda r: (abs(MODALITIES.index(r.A) - MODALITIES.index(r.B)), MODALITIES.index(r.A)),
    )
    for r in pairs:
        i, j = sorted((MODALITIES.index(r.A), MODALITIES.index(r.B)))
        ax.plot(
            [i, i, j, j],
            [level, level + 0.25 * step, level + 0.25 * step, level],
            color="black",
            linewidth=0.8,
        )
        ax.text(
            (i + j) / 2,
            level + 0.3 * step,
            f"p = {_p(r.p_bonf)}",
            ha="center",
            va="bottom",
            fontsize=8,
        )
        level += step
    ax.set_ylim(0, level + 0.5 * step)
    a = stats.anova
    if a is None:
        title = f"n = {stats.n}: descriptive only (the tests need at least 2 participants)"
    else:
        title = (
            f"RM ANOVA F({a['df1']:g}, {a['df2']:g}) = {a['F']:.2f}, p = {_p(a['p'])}; "
            f"n = {stats.n}; Bonferroni p"
        )
    if simulated:
        title = SIMULATED_BANNER + "\n" + title
    ax.set_title(title, fontsize=9, color="black")
    ax.spines[["top", "right"]].set_visible(False)
    fig.tight_layout()
    paths = [out / f"{stem}.png", out / f"{stem}.svg"]
    fig.savefig(paths[0], dpi=150, metadata={"Software": None})
    fig.savefig(paths[1], metadata={"Date": None})
    plt.close(fig)
    return paths


# ======================================================================================
# Report
# ======================================================================================


def _md_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(str(c) for c in r) + " |")
    return "\n".join(lines)


def _text_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    cells = [list(map(str, header))] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    out = []
    for n, r in enumerate(cells):
        out.append(
            "  ".join(
                c.rjust(w) if n and i > 1 else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths))
            ).rstrip()
        )
        if n == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out)


def _t1_rows(t1):
    return [
        (r.k, r.modality, r.successes, r.failures, r.trials, f"{100 * r.success_rate:.0f}%")
        for r in t1.itertuples(index=False)
    ]


def _t2_rows(t2):
    return [
        (r.k, r.modality, f"{r.mean_s:.2f}", f"{r.sd_s:.2f}", r.trials)
        for r in t2.itertuples(index=False)
    ]


T1_HEADER = ("k", "modality", "successes", "failures", "trials", "rate")
T2_HEADER = ("k", "modality", "mean [s]", "SD [s]", "trials")


@dataclass
class Result:
    trials: Any
    tlx: Any
    table1: Any
    table2: Any
    table3: Any
    stats: Statistics
    simulated_participants: list[str]
    participants: list[str]
    familiarization_excluded: int
    sources: list[Path]
    # Damaged last lines left out (a run killed mid-write): said in the report and output.
    left_out: list[LeftOutLine] = field(default_factory=list)

    @property
    def simulated(self) -> bool:
        return bool(self.simulated_participants)


def _banner(res: Result) -> str | None:
    if not res.simulated:
        return None
    sims = res.simulated_participants
    if len(sims) == len(res.participants):
        who = f"all {len(sims)} participants are virtual (simulated=true)"
    else:
        who = (
            f"{len(sims)} of {len(res.participants)} participants have simulated records "
            f"({', '.join(sims)})"
        )
    return f"{SIMULATED_BANNER}: {who}."


def _capitalized(text: str) -> str:
    return text[:1].upper() + text[1:]


def report_markdown(
    res: Result,
    figure_names: Sequence[str] = ("figure4.png", "figure4.svg"),
    after_tables: str = "",
) -> str:
    """report.md's text; ``after_tables`` (markdown) goes between Table II and Table III."""
    st = res.stats
    out: list[str] = ["# GraspGuide study analysis", ""]
    banner = _banner(res)
    if banner:
        out += [
            f"> **{SIMULATED_BANNER}.**",
            ">",
            f"> {_capitalized(banner[len(SIMULATED_BANNER) + 2 :])} These numbers come "
            "from a model of a person following the cues, not from people; do not "
            "report them as human results.",
            "",
        ]
    n_trials = int((~res.trials["familiarization"]).sum())
    out += [
        f"Sources: {', '.join(str(s) for s in res.sources)}  ",
        f"Participants: {len(res.participants)} ({', '.join(res.participants)}); "
        f"{n_trials} trials analysed, {res.familiarization_excluded} familiarization "
        f"trials excluded; {len(res.tlx)} sessions with a NASA-TLX record, "
        f"{int(res.tlx[list(TLX_SCALES)].notna().all(axis=1).sum())} answered.",
        "",
    ]
    if res.left_out:
        out += ["**Left out**: damaged last lines, not records:", ""]
        out += [f"- {line}" for line in res.left_out]
        out += [""]

    out += [
        "## Table I — successfully accomplished tasks",
        "",
        "A target orientation not reached within the trial's time limit (90 s in the "
        "paper's protocol) is a failure.",
        "",
        _md_table(T1_HEADER, _t1_rows(res.table1)),
        "",
    ]
    out += [
        "## Table II — completion time",
        "",
        "Mean and standard deviation (n − 1) per condition; a failed trial counts with "
        "its logged time (90 s).",
        "",
        _md_table(T2_HEADER, _t2_rows(res.table2)),
        "",
    ]
    if after_tables:
        out += [after_tables.rstrip("\n"), ""]
    out += ["## Table III — NASA-TLX workload (1–21, lower is better)", ""]
    unanswered = int(res.tlx[list(TLX_SCALES)].isna().any(axis=1).sum())
    if unanswered:
        out += [
            f"{unanswered} of {len(res.tlx)} sessions were logged without a questionnaire "
            "(scales null: a simulated source without a --tlx file); they are left out.",
            "",
        ]
    if res.table3.empty:
        out += ["No NASA-TLX questionnaires were logged.", ""]
    else:
        header = ["modality", "", "sessions"] + list(TLX_SCALES)
        rows = []
        for r in res.table3.to_dict("records"):
            rows.append(
                [MODE_NAMES[r["mode"]], "mean", r["sessions"]]
                + [f"{r[f'{s}_mean']:.2f}" for s in TLX_SCALES]
            )
            rows.append(["", "SD", ""] + [f"{r[f'{s}_sd']:.2f}" for s in TLX_SCALES])
        out += [
            _md_table(header, rows),
            "",
            "Scales: " + ", ".join(f"{s} {TLX_NAMES[s]}" for s in TLX_SCALES) + ".",
            "",
        ]

    out += [
        "## Per-participant reading (completion time by feedback modality)",
        "",
        "The paper's tests on per-participant means, one reading of its Section IV (the "
        "trial-level reading is below). Mean completion time per participant and "
        "modality, 3 and 4 contact points pooled (seconds):",
        "",
        _md_table(
            ["participant"] + list(MODALITIES),
            [[p] + [f"{st.means.loc[p, m]:.2f}" for m in MODALITIES] for p in st.means.index],
        ),
        "",
    ]
    if st.fences:
        out += [
            "**Outliers** (boxplot rule: beyond 1.5 IQR from the box of a modality's "
            "participant means; each removed with its paired values, i.e. the "
            "participant's whole row):",
            "",
        ]
        if st.outliers:
            out += [
                f"- {p}, {m}: {v:.2f} s (fences {st.fences[m][0]:.2f} … {st.fences[m][1]:.2f} s)"
                for p, m, v in st.outliers
            ]
            out += ["", f"Removed participants: {', '.join(st.removed)}; {st.n} remain.", ""]
        else:
            out += ["- none", ""]
    else:
        out += ["Outlier removal was switched off (--keep-outliers).", ""]
    if not st.inferential:
        out += [f"**Inferential statistics not computed**: {st.notes[0]}.", ""]
    else:
        out += [
            "Data are square-root transformed before the tests.",
            "",
            "**Shapiro–Wilk** per modality (sqrt data):",
            "",
            _md_table(
                ["modality", "W", "p", "normal (p > 0.05)"],
                [
                    [
                        m,
                        f"{st.normality.loc[m, 'W']:.4f}",
                        _p(st.normality.loc[m, "pval"]),
                        "yes" if st.normality.loc[m, "normal"] else "no",
                    ]
                    for m in MODALITIES
                ],
            ),
            "",
        ]
        sp = st.sphericity
        if sp["spher"] is None:
            out += [
                f"**Mauchly's test of sphericity**: not computed (fewer than "
                f"{len(MODALITIES)} participants).",
                "",
            ]
        else:
            out += [
                f"**Mauchly's test of sphericity**: W = {sp['W']:.4f}, "
                f"χ²({sp['dof']}) = {sp['chi2']:.3f}, p = {_p(sp['pval'])} (χ² "
                f"approximation, as the paper reports; with R's second-order term p = "
                f"{_p(sp['pval_second_order'])}) — sphericity "
                + ("not violated." if sp["spher"] else "violated (see the Greenhouse–Geisser p)."),
                "",
            ]
        a, sm = st.anova, st.anova_statsmodels
        out += [
            f"**One-way repeated-measures ANOVA** (pingouin): F({a['df1']:g}, {a['df2']:g}) = "
            f"{a['F']:.3f}, p = {_p(a['p'])}; Greenhouse–Geisser ε = {a['eps_gg']:.3f}, "
            f"p(GG) = {_p(a['p_gg'])}; generalized η² = {a['ng2']:.3f}.  ",
            f"Cross-check (statsmodels AnovaRM): F = {sm['F']:.6f}, p = {sm['p']:.6g} "
            f"(pingouin F = {a['F']:.6f}, p = {a['p']:.6g}; |ΔF| = "
            f"{abs(a['F'] - sm['F']):.2g}).",
            "",
        ]
        out += [
            "**Pairwise paired t-tests**, Bonferroni-corrected (6 comparisons, "
            "p_bonf = min(1, 6 p)); differences of the means in seconds:",
            "",
            _md_table(
                [
                    "A",
                    "B",
                    "mean A [s]",
                    "mean B [s]",
                    "A − B [s]",
                    "t",
                    "df",
                    "p",
                    "p (Bonferroni)",
                ],
                [
                    [
                        r.A,
                        r.B,
                        f"{r.mean_A_s:.2f}",
                        f"{r.mean_B_s:.2f}",
                        f"{r.diff_s:.2f}",
                        f"{r.T:.3f}",
                        f"{r.dof:g}",
                        _p(r.p_unc),
                        _p(r.p_bonf),
                    ]
                    for r in st.pairwise.itertuples(index=False)
                ],
            ),
            "",
        ]
        for note in st.notes:
            out += [f"Note: {note}.", ""]
    out += [
        "## Figure 4",
        "",
        "Mean ± SD of the participant means per modality (after outlier removal), with "
        "the Bonferroni-corrected p-value of every pair."
        if st.inferential
        else f"The participant means per modality (n = {st.n}: no SD, no p-values).",
        "",
    ]
    if figure_names:
        out += [
            f"![Figure 4]({figure_names[0]})",
            "",
            "Files: " + ", ".join(f"`{n}`" for n in figure_names),
            "",
        ]
    return "\n".join(out)


def tables_text(res: Result) -> str:
    """The banner of a simulated study, then Tables I-II as plain text."""
    lines = []
    banner = _banner(res)
    if banner:
        lines += [f"*** {banner} ***", ""]
    lines += [
        "Table I: successfully accomplished tasks",
        _text_table(T1_HEADER, _t1_rows(res.table1)),
        "",
        "Table II: completion time",
        _text_table(T2_HEADER, _t2_rows(res.table2)),
    ]
    return "\n".join(lines)


def summary_text(res: Result) -> str:
    return tables_text(res) + "\n\n" + res.stats.anova_line()


def analyze(paths: Iterable[str | os.PathLike], remove_outliers: bool = True) -> Result:
    """Load, then Tables I-III and the statistics (no files written)."""
    paths = list(paths)
    left_out: list[LeftOutLine] = []
    trials, tlx = load(paths, left_out)
    data = _analysed(trials)
    means = participant_means(trials)
    stats = paper_statistics(means, remove_outliers=remove_outliers)
    participants = sorted(set(trials["participant"]) | set(tlx["participant"]))
    sim = set(trials.loc[trials["simulated"].astype(bool), "participant"])
    sim |= set(tlx.loc[tlx["simulated"].astype(bool), "participant"])
    return Result(
        trials=trials,
        tlx=tlx,
        table1=table1(trials),
        table2=table2(trials),
        table3=table3(tlx),
        stats=stats,
        simulated_participants=sorted(sim),
        participants=participants,
        familiarization_excluded=int(len(trials) - len(data)),
        sources=[Path(p) for p in paths],
        left_out=left_out,
    )


def default_out_dir(paths: Sequence[str | os.PathLike]) -> Path:
    """``analysis/`` in the first study folder (the parent of a participant folder)."""
    first = Path(paths[0])
    if ParticipantFiles(str(first)).holds_records():
        first = first.resolve().parent
    return first / "analysis"


def write_outputs(res: Result, out_dir: str | os.PathLike) -> list[Path]:
    """report.md, figure4.png/.svg and the tables as CSV in ``out_dir``."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise AnalysisError(f"{out}: cannot create the output folder ({e.strerror or e})") from None
    figs = figure4(res.stats, out, simulated=res.simulated)
    written = list(figs)
    tables = {
        "table1.csv": res.table1,
        "table2.csv": res.table2,
        "table3.csv": res.table3,
        "pairwise.csv": res.stats.pairwise,
    }
    for name, df in tables.items():
        df.to_csv(out / name, index=False)
        written.append(out / name)
    means = res.stats.means.copy()
    means["removed_as_outlier"] = [p in res.stats.removed for p in means.index]
    means.to_csv(out / "participant_means.csv")
    written.append(out / "participant_means.csv")
    report = out / "report.md"
    report.write_text(report_markdown(res, [f.name for f in figs]) + "\n", encoding="utf-8")
    written.append(report)
    return written
