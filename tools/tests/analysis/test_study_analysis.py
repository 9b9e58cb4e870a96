"""graspguide.analysis.study_analysis: every reading in one report, the paper beside it.

The study folders come from the seeded generator in synthetic_study.py, so the trials are
known here; the paper's values come from the shipped paper_values.json, read through its
own loader (never typed into this file).
"""

from __future__ import annotations

import json

import pytest
from synthetic_study import PIDS, make_study

from graspguide import cli
from graspguide.analysis import study_analysis as S
from graspguide.analysis.paper_reference import load_paper_values

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("study") / "STUDY"
    make_study(root, slow={"U3": {"F+V": 6.0}})
    return root


@pytest.fixture(scope="module")
def analysis(study):
    return S.analyze_study([study])


@pytest.fixture(scope="module")
def written(analysis, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    return out, S.write_outputs(analysis, out)


def test_every_reading_is_computed_on_a_full_study(analysis):
    assert analysis.not_computed == {}
    assert analysis.trial_level is not None and analysis.reviewer is not None
    # 8 participants x 2 contact counts x 12 wrenches, each block holding all modalities
    assert analysis.trial_level.blocks_total == 8 * 2 * 12
    n = analysis.trial_level.n_blocks
    assert analysis.trial_level.anova["df1"] == 3
    assert analysis.trial_level.anova["df2"] == 3 * (n - 1)


def test_the_report_carries_the_paper_its_contradiction_and_every_reading(analysis, written):
    out, files = written
    report = (out / "report.md").read_text(encoding="utf-8")
    paper = load_paper_values()
    sections = [
        "## Table II",
        "## The paper beside this study",
        "## Table III",
        "## Per-participant reading",
        "## Trial-level statistics",
        "## Every trial",
        f"## {S.mixed_model.REVIEWER_LABEL}",
    ]
    at = [report.index(s) for s in sections]
    assert at == sorted(at), "sections out of order"
    for row in paper["table2"]["rows"]:
        assert f"{row['mean_s']:.2f} ± {row['sd_s']:.2f}" in report
    assert "contradict each other" in report
    assert "simulated success" in report
    a = analysis.trial_level.anova
    assert f"F({a['df1']:.0f}, {a['df2']:.0f}) = {a['F']:.3f}" in report
    assert "![Every trial](trials.png)" in report


def test_the_files_written_hold_the_figures_and_tables(analysis, written):
    out, files = written
    names = {p.name for p in files}
    assert {"trials.png", "trials.svg", "paper_vs_study.csv", "trial_outliers.csv"} <= names
    assert {"figure4.png", "report.md", "table1.csv"} <= names
    assert (out / "trials.png").read_bytes()[:8] == PNG_MAGIC
    lines = (out / "trial_outliers.csv").read_text().splitlines()
    assert len(lines) - 1 == len(analysis.trial_level.removed)
    rows = (out / "paper_vs_study.csv").read_text().splitlines()
    assert len(rows) - 1 == 8  # 2 contact counts x 4 modalities


def test_the_summary_shows_the_paper_table_and_every_reading(analysis):
    text = S.summary_text(analysis)
    for needle in (
        "Table I: successfully accomplished tasks",
        "The paper's Tables I-II beside this study (simulated)",
        "Per-participant reading",
        "Trial-level repeated-measures analysis",
        "RM ANOVA: F(3, ",
        S.mixed_model.REVIEWER_LABEL,
        "Contacts x modality",
    ):
        assert needle in text, needle


def test_a_reading_the_data_cannot_support_is_said_and_the_rest_still_written(tmp_path):
    """Every trial a timeout: no variance for the trial-level ANOVA. The tables, the
    paper comparison and the trial figure are still produced, and the report says what
    was not computed and why."""
    make_study(tmp_path / "S", n=3)
    for pid in PIDS[:3]:
        f = tmp_path / "S" / pid / "trials.jsonl"
        recs = [json.loads(x) for x in f.read_text().splitlines()]
        for r in recs:
            r.update(success=False, completion_s=90.0)
        f.write_text("".join(json.dumps(r) + "\n" for r in recs))
    a = S.analyze_study([tmp_path / "S"])
    assert a.trial_level is None
    assert "trial-level statistics" in a.not_computed
    files = S.write_outputs(a, tmp_path / "out")
    assert (tmp_path / "out" / "trials.png") in files
    report = (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    assert "## Not computed" in report
    assert a.not_computed["trial-level statistics"] in report
    assert "Not computed, trial-level statistics" in S.summary_text(a)


def test_people_are_this_study_not_simulated(tmp_path):
    make_study(tmp_path / "S", n=3, simulated=False)
    a = S.analyze_study([tmp_path / "S"])
    text = S.summary_text(a)
    assert "this study success" in text and "simulated success" not in text


def test_analyze_command_prints_every_reading(study, tmp_path, capsys):
    assert cli.main(["analyze", str(study), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "The paper's Tables I-II beside this study" in out
    assert "RM ANOVA: F(3, " in out
    assert "trials.png" in out
