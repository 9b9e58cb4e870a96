"""A study's whole analysis: the paper's tables beside the paper's own values, the paper's
statistics at trial level, the per-participant reading, and today's analyses.

Three readings of the same trials, each labelled where it is shown:

1. **Trial level** (:mod:`graspguide.analysis.trial_statistics`): the paper's tests on
   trials paired by participant x contacts x wrench; the reading the paper's words fit.
2. **Per participant** (:mod:`graspguide.analysis.paper_tables`): participant means,
   contacts pooled; kept because it is the other possible reading of the paper.
3. **Today's** (:mod:`graspguide.analysis.mixed_model`): a linear mixed model and the
   contacts x modality two-way ANOVA, what a reviewer would ask for.

A reading that the data cannot support (too few participants, no variance, a condition
missing) is reported as not computed, with the reason; the others still are. The paper's
Tables I-II (:mod:`graspguide.analysis.paper_reference`) sit beside the study's.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from graspguide.analysis import mixed_model, paper_reference, paper_tables, trial_statistics
from graspguide.analysis.paper_tables import AnalysisError, Result
from graspguide.analysis.trial_figure import trial_figure

TRIAL_FIGURE_STEM = "trials"


@dataclass
class StudyAnalysis:
    """Everything :func:`analyze_study` computed; a reading it could not compute is None
    and its reason is in ``not_computed``."""

    base: Result
    paper: dict[str, Any]
    comparison: Any  # paper_reference.paper_vs_simulated's frame
    trial_level: trial_statistics.TrialLevelStatistics | None
    reviewer: mixed_model.ReviewerAnalysis | None
    not_computed: dict[str, str] = field(default_factory=dict)

    @property
    def side_label(self) -> str:
        """What the study's column is called beside the paper's."""
        return "simulated" if self.base.simulated else "this study"


# The errors a reading raises when the data cannot support it; anything else is a bug and
# propagates.
_DATA_ERRORS: tuple[type[BaseException], ...] = (
    AnalysisError,
    ValueError,
    ZeroDivisionError,
    ArithmeticError,
)


def _linalg_error() -> type[BaseException]:
    import numpy as np

    return np.linalg.LinAlgError


def analyze_study(
    paths: Iterable[str | os.PathLike], remove_outliers: bool = True
) -> StudyAnalysis:
    """Load the study, then every reading (no files written). Raises AnalysisError only
    when nothing can be analysed (no trials, unreadable records)."""
    base = paper_tables.analyze(paths, remove_outliers=remove_outliers)
    paper = paper_reference.load_paper_values()
    errors = (*_DATA_ERRORS, _linalg_error())
    not_computed: dict[str, str] = {}
    trial_level = reviewer = None
    try:
        trial_level = trial_statistics.trial_level_statistics(
            base.trials, remove_outliers=remove_outliers
        )
    except errors as e:
        not_computed["trial-level statistics"] = str(e) or type(e).__name__
    try:
        reviewer = mixed_model.reviewer_analysis(base.trials)
    except errors as e:
        not_computed["mixed model and two-way ANOVA"] = str(e) or type(e).__name__
    return StudyAnalysis(
        base=base,
        paper=paper,
        comparison=paper_reference.paper_vs_simulated(base.trials, paper),
        trial_level=trial_level,
        reviewer=reviewer,
        not_computed=not_computed,
    )


def _paper_means(paper: dict[str, Any]) -> dict[tuple[int, str], tuple[float, float]]:
    return {
        (int(r["k"]), str(r["modality"])): (float(r["mean_s"]), float(r["sd_s"]))
        for r in paper["table2"]["rows"]
    }


def _removed_trials(a: StudyAnalysis) -> list[tuple[str, int, str, str]]:
    if a.trial_level is None:
        return []
    r = a.trial_level.removed
    return [
        (str(p), int(k), str(w), str(m))
        for p, k, w, m in zip(r["participant"], r["k"], r["wrench_id"], r["modality"])
    ]


def summary_text(a: StudyAnalysis) -> str:
    """What the terminal shows: Tables I-II, the paper beside the study, every reading."""
    lines = [
        paper_tables.tables_text(a.base),
        "",
        f"The paper's Tables I-II beside this study ({a.side_label}):",
        paper_reference.format_text(a.comparison, a.side_label),
        "",
        "Per-participant reading (participant means, contacts pooled): "
        + a.base.stats.anova_line(),
        "",
    ]
    if a.trial_level is not None:
        lines.append(trial_statistics.format_text(a.trial_level))
    if a.reviewer is not None:
        lines += [mixed_model.format_text(a.reviewer), ""]
    lines += [f"Not computed, {what}: {why}" for what, why in a.not_computed.items()]
    return "\n".join(lines).rstrip("\n")


def _paper_section(a: StudyAnalysis) -> str:
    where = a.paper["source"]
    return "\n".join(
        [
            "## The paper beside this study",
            "",
            f"The paper's Tables I–II ({_cite(where)}) and this study's, condition by "
            f"condition. "
            + (
                "The study is SIMULATED: the participant model's parameters come from "
                "the sources in docs/participant.md and none is fitted to these tables; "
                "the paper is a held-out check."
                if a.base.simulated
                else ""
            ),
            "",
            paper_reference.format_markdown(a.comparison, a.side_label),
            "",
            paper_reference.label_contradiction_markdown(a.paper),
            "",
        ]
    )


def _cite(source: Any) -> str:
    if isinstance(source, dict):
        return f"“{source['paper']}”" if "paper" in source else "the paper"
    return str(source)


def _trial_figure_section(names: Sequence[str]) -> str:
    if not names:
        return ""
    return "\n".join(
        [
            "## Every trial",
            "",
            "One point per trial, per contact count and modality: filled, a success; a "
            "cross at the 90 s line, a timeout; hollow, a trial the trial-level outlier "
            "rule removed (with its paired trials). Black diamonds: the paper's means ± SD "
            "(Table II), SD bars cut at 0 and 90 s.",
            "",
            f"![Every trial]({names[0]})",
            "",
            "Files: " + ", ".join(f"`{n}`" for n in names),
            "",
        ]
    )


def report_markdown(
    a: StudyAnalysis,
    figure_names: Sequence[str] = ("figure4.png", "figure4.svg"),
    trial_figure_names: Sequence[str] = (),
) -> str:
    """report.md: the paper's tables with the paper beside them, the per-participant
    reading with Figure 4, the trial-level reading, every trial, today's analyses."""
    text = paper_tables.report_markdown(a.base, figure_names, after_tables=_paper_section(a))
    out = [text.rstrip("\n"), ""]
    if a.trial_level is not None:
        out += [trial_statistics.format_markdown(a.trial_level)]
    out += [_trial_figure_section(trial_figure_names)]
    if a.reviewer is not None:
        out += [mixed_model.format_markdown(a.reviewer)]
    if a.not_computed:
        out += ["## Not computed", ""]
        out += [f"- {what}: {why}" for what, why in a.not_computed.items()]
        out += [""]
    return "\n".join(part for part in out if part is not None).rstrip("\n") + "\n"


def write_outputs(a: StudyAnalysis, out_dir: str | os.PathLike) -> list[Path]:
    """Everything :func:`paper_tables.write_outputs` writes, with report.md covering every
    reading, plus trials.png/.svg, paper_vs_study.csv and the trial-level removals."""
    written = paper_tables.write_outputs(a.base, out_dir)
    out = Path(out_dir)
    data = a.base.trials[~a.base.trials["familiarization"].astype(bool)]
    trial_figs = trial_figure(
        data,
        out,
        removed=_removed_trials(a),
        paper=_paper_means(a.paper),
        simulated=a.base.simulated,
        stem=TRIAL_FIGURE_STEM,
    )
    written += trial_figs
    a.comparison.to_csv(out / "paper_vs_study.csv", index=False)
    written.append(out / "paper_vs_study.csv")
    if a.trial_level is not None:
        a.trial_level.removed.to_csv(out / "trial_outliers.csv", index=False)
        written.append(out / "trial_outliers.csv")
    figure4_names = [p.name for p in written if p.stem == "figure4"]
    report = out / "report.md"
    report.write_text(
        report_markdown(a, figure4_names, [p.name for p in trial_figs]), encoding="utf-8"
    )
    return written
