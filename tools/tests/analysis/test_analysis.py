"""graspguide.analysis.paper_tables: Tables I-III, the statistics, Figure 4, the report, errors.

Synthetic study folders are written in tmp_path by a seeded generator: 8 participants,
4 modalities x 2 contact counts x 12 wrenches, plus familiarization trials (which the
analysis must leave out) and one NASA-TLX record per session. Failures follow a fixed
pattern so the Table I counts are known by hand.
"""

from __future__ import annotations

import json
import math
import statistics
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import scipy.stats
from synthetic_study import ORDER, PIDS, SCALES, make_participant, make_study

from graspguide import cli
from graspguide.analysis import paper_tables as A


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("study") / "STUDY"
    # U3 is far slower than everyone in F+V: an outlier of that modality's box.
    trials, tlx = make_study(root, slow={"U3": {"F+V": 6.0}})
    return root, trials, tlx


@pytest.fixture(scope="module")
def result(study):
    root, _, _ = study
    return A.analyze([root])


@pytest.fixture(scope="module")
def written(study, result, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    A.write_outputs(result, out)
    return out


# ---------------------------------------------------------------------------- loading
def test_load_reads_every_record_and_flags_familiarization(study):
    root, trials, tlx = study
    t, q = A.load([root])
    assert len(t) == len(trials) == 8 * (4 * 2 * 12 + 3)
    assert int(t["familiarization"].sum()) == 8 * 3
    assert len(q) == len(tlx) == 8 * 8
    assert set(t["participant"]) == set(PIDS)
    assert t["source"].iloc[0].endswith("trials.jsonl:1")
    # A participant folder and its study folder name the same data once.
    t2, _ = A.load([root, root / "U1"])
    assert len(t2) == len(t)


# ---------------------------------------------------------------------------- tables
def test_table1_counts_equal_hand_counts(study, result):
    _, trials, _ = study
    t1 = result.table1
    # the paper's layout: k = 3 then 4, F+V, Fperp+V, F+C, Fperp+C
    assert list(zip(t1["k"], t1["modality"])) == [
        (k, m) for k in (3, 4) for m in ["F+V", "Fperp+V", "F+C", "Fperp+C"]
    ]
    for r in t1.itertuples(index=False):
        hand_s = sum(
            1
            for t in trials
            if not t["familiarization"]
            and t["k"] == r.k
            and t["modality"] == r.modality
            and t["success"]
        )
        hand_f = sum(
            1
            for t in trials
            if not t["familiarization"]
            and t["k"] == r.k
            and t["modality"] == r.modality
            and not t["success"]
        )
        assert (r.successes, r.failures, r.trials) == (hand_s, hand_f, 96)
        # by construction: 2 failures of 12 per participant in C, none in V
        if r.modality.endswith("+C"):
            assert (r.successes, r.failures) == (80, 16)
            assert r.success_rate == pytest.approx(80 / 96)
        else:
            assert (r.successes, r.failures, r.success_rate) == (96, 0, 1.0)


def test_table2_mean_and_sd_per_condition(study, result):
    _, trials, _ = study
    for r in result.table2.itertuples(index=False):
        times = [
            t["completion_s"]
            for t in trials
            if not t["familiarization"] and t["k"] == r.k and t["modality"] == r.modality
        ]
        assert r.trials == len(times) == 96
        assert r.mean_s == pytest.approx(statistics.fmean(times), rel=1e-12)
        assert r.sd_s == pytest.approx(statistics.stdev(times), rel=1e-12)


def test_table3_tlx_by_mode(study, result):
    _, _, tlx = study
    t3 = result.table3.set_index("mode")
    assert list(t3.index) == ["C", "V"]
    for mode in ("C", "V"):
        rows = [q for q in tlx if q["mode"] == mode]
        assert t3.loc[mode, "sessions"] == len(rows) == 32
        for s in SCALES:
            vals = [q["scales"][s] for q in rows]
            assert t3.loc[mode, f"{s}_mean"] == pytest.approx(statistics.fmean(vals))
            assert t3.loc[mode, f"{s}_sd"] == pytest.approx(statistics.stdev(vals))


# ---------------------------------------------------------------------------- statistics
def test_participant_means_pool_contact_counts(study, result):
    _, trials, _ = study
    means = result.stats.means
    assert list(means.columns) == ORDER and sorted(means.index) == PIDS
    for pid in ("U1", "U5"):
        for m in ORDER:
            vals = [
                t["completion_s"]
                for t in trials
                if t["participant"] == pid and t["modality"] == m and not t["familiarization"]
            ]
            assert len(vals) == 24
            assert means.loc[pid, m] == pytest.approx(statistics.fmean(vals), rel=1e-12)


def test_outlier_removed_with_its_paired_values(result):
    st = result.stats
    assert ("U3", "F+V") in [(p, m) for p, m, _ in st.outliers]
    assert "U3" in st.removed
    assert st.removed == sorted({p for p, _, _ in st.outliers})
    # the fences are the boxplot's: Q1 - 1.5 IQR, Q3 + 1.5 IQR of each modality's means
    for m in ORDER:
        col = st.means[m].to_numpy()
        q1, q3 = np.percentile(col, [25, 75])
        assert st.fences[m] == pytest.approx((q1 - 1.5 * (q3 - q1), q3 + 1.5 * (q3 - q1)))
    assert st.means.loc["U3", "F+V"] > st.fences["F+V"][1]
    # every flagged participant's whole row is gone (all four modalities), the rest intact
    kept = [p for p in PIDS if p not in st.removed]
    assert sorted(st.retained.index) == sorted(st.transformed.index) == kept
    assert st.n == len(kept) < 8 and st.anova["df2"] == 3 * (len(kept) - 1)
    np.testing.assert_allclose(
        st.transformed.loc[kept].to_numpy(), np.sqrt(st.means.loc[kept].to_numpy())
    )


def test_keep_outliers_keeps_every_participant(study):
    root, _, _ = study
    res = A.analyze([root], remove_outliers=False)
    assert res.stats.removed == [] and res.stats.n == 8 and res.stats.anova["df2"] == 21


def test_boxplot_outliers_match_matplotlib(result):
    """The fences are those of the boxplot matplotlib would draw (whis=1.5)."""
    import matplotlib.cbook

    st = result.stats
    for m in ORDER:
        b = matplotlib.cbook.boxplot_stats(st.means[m].to_numpy(), whis=1.5)[0]
        flagged = sorted(float(v) for p, mm, v in st.outliers if mm == m)
        assert flagged == sorted(float(v) for v in b["fliers"])


def test_anova_pingouin_agrees_with_statsmodels(result):
    a, sm = result.stats.anova, result.stats.anova_statsmodels
    assert (a["df1"], a["df2"]) == (sm["df1"], sm["df2"]) == (3, 3 * (result.stats.n - 1))
    assert abs(a["F"] - sm["F"]) < 1e-6
    assert abs(a["p"] - sm["p"]) < 1e-6
    # C is much slower than V here: the effect must be strong
    assert a["F"] > 10 and a["p"] < 1e-4


def test_bonferroni_pairs_against_scipy_ttest_rel(result):
    st = result.stats
    pw = st.pairwise
    assert len(pw) == 6
    assert {frozenset((r.A, r.B)) for r in pw.itertuples()} == {
        frozenset((ORDER[i], ORDER[j])) for i in range(4) for j in range(i + 1, 4)
    }
    for r in pw.itertuples():
        t, p = scipy.stats.ttest_rel(st.transformed[r.A], st.transformed[r.B])
        assert r.T == pytest.approx(t, rel=1e-9)
        assert r.p_unc == pytest.approx(p, rel=1e-9)
        assert r.p_bonf == pytest.approx(min(1.0, 6 * p), rel=1e-9)
        assert r.diff_s == pytest.approx(st.retained[r.A].mean() - st.retained[r.B].mean())


def test_shapiro_and_mauchly_against_scipy_and_numpy(result):
    st = result.stats
    for m in ORDER:
        w, p = scipy.stats.shapiro(st.transformed[m])
        assert st.normality.loc[m, "W"] == pytest.approx(w, rel=1e-9)
        assert st.normality.loc[m, "pval"] == pytest.approx(p, rel=1e-9)
    # Mauchly's W from orthonormal contrasts: W = det(S) / (tr(S)/(k-1))^(k-1)
    y = st.transformed[ORDER].to_numpy()
    n, k = y.shape
    c = np.linalg.qr(np.vstack([np.ones(k), np.eye(k)[:-1]]).T)[0][:, 1:]
    s = np.cov(y @ c, rowvar=False)
    w = np.linalg.det(s) / (np.trace(s) / (k - 1)) ** (k - 1)
    d = 1 - (2 * (k - 1) ** 2 + (k - 1) + 2) / (6 * (k - 1) * (n - 1))
    chi2 = -(n - 1) * d * math.log(w)
    dof = k * (k - 1) // 2 - 1
    assert st.sphericity["W"] == pytest.approx(w, rel=1e-9)
    assert st.sphericity["chi2"] == pytest.approx(chi2, rel=1e-9)
    assert st.sphericity["dof"] == dof == 5
    # p as the paper (and SPSS) reports it: the chi-square approximation
    assert st.sphericity["pval"] == pytest.approx(scipy.stats.chi2.sf(chi2, dof), rel=1e-9)
    assert st.sphericity["spher"] == (st.sphericity["pval"] > 0.05)
    assert 0 < st.sphericity["pval_second_order"] < 1


def test_known_answer_anova_from_sums_of_squares():
    """A hand-made 5 x 4 table (values are squares: sqrt gives the integers below);
    F from numpy sums of squares, p from the F distribution."""
    import pandas as pd

    root = np.array(
        [[2, 3, 5, 6], [3, 3, 4, 7], [1, 2, 4, 4], [2, 4, 6, 5], [3, 4, 5, 7]], dtype=float
    )
    wide = pd.DataFrame(root**2, index=[f"P{i}" for i in range(5)], columns=ORDER)
    wide.index.name = "participant"
    st = A.paper_statistics(wide, remove_outliers=True)
    assert st.removed == []
    n, k = root.shape
    grand = root.mean()
    ss_cond = n * ((root.mean(axis=0) - grand) ** 2).sum()
    ss_subj = k * ((root.mean(axis=1) - grand) ** 2).sum()
    ss_err = ((root - grand) ** 2).sum() - ss_cond - ss_subj
    df1, df2 = k - 1, (k - 1) * (n - 1)
    f = (ss_cond / df1) / (ss_err / df2)
    # by hand: column means 2.2, 3.2, 4.8, 5.8; grand 4; SS_cond = 5 * 7.76 = 38.8
    assert ss_cond == pytest.approx(38.8)
    assert st.anova["SS"] == pytest.approx(ss_cond, rel=1e-12)
    assert st.anova["SS_error"] == pytest.approx(ss_err, rel=1e-12)
    assert (st.anova["df1"], st.anova["df2"]) == (df1, df2)
    assert st.anova["F"] == pytest.approx(f, rel=1e-12)
    assert st.anova["p"] == pytest.approx(scipy.stats.f.sf(f, df1, df2), rel=1e-9)
    assert st.anova_statsmodels["F"] == pytest.approx(f, rel=1e-12)


# ---------------------------------------------------------------------------- outputs
def test_figure_files_are_valid_png_and_svg(written):
    png = (written / "figure4.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    root = ET.parse(written / "figure4.svg").getroot()
    assert root.tag.endswith("svg")
    svg = (written / "figure4.svg").read_text()
    assert "p = " in svg or "p&#160;=" in svg or "p =" in svg.replace("&#160;", " ")


def test_report_has_tables_statistics_and_simulated_banner(written, result):
    text = (written / "report.md").read_text(encoding="utf-8")
    head = text[:400]
    assert "SIMULATED DATA — not human results" in head
    for needle in (
        "Table I",
        "Table II",
        "Table III",
        "Shapiro",
        "Mauchly",
        "repeated-measures ANOVA",
        "Bonferroni",
        "figure4.png",
        "U3, F+V",
        "statsmodels AnovaRM",
    ):
        assert needle in text, needle
    assert f"{result.stats.anova['F']:.3f}" in text
    for name in ("table1.csv", "table2.csv", "table3.csv", "pairwise.csv", "participant_means.csv"):
        assert (written / name).stat().st_size > 0


def test_real_data_report_has_no_banner(tmp_path):
    make_study(tmp_path / "S", seed=3, simulated=False)
    res = A.analyze([tmp_path / "S"])
    assert not res.simulated
    assert "SIMULATED" not in A.report_markdown(res)
    assert "SIMULATED" not in A.summary_text(res)


def test_cli_main_prints_tables_and_writes_default_out(study, capsys):
    root, _, _ = study
    assert cli.main(["analyze", str(root)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("*** SIMULATED DATA — not human results")
    assert "Table I" in out and "Table II" in out and "Fperp+C" in out
    assert "One-way repeated-measures ANOVA" in out and "F(3, " in out
    assert "removed as boxplot outliers (U3" in out
    for name in ("report.md", "figure4.png", "figure4.svg"):
        assert (root / "analysis" / name).is_file()
    # the analysis/ folder is not mistaken for a participant on the next run
    assert cli.main(["analyze", str(root)]) == 0


def test_register_adds_analyze_subcommand(study, tmp_path, capsys):
    root, _, _ = study
    parser = cli.build_parser()
    args = parser.parse_args(
        [
            "analyze",
            str(root / "U1"),
            str(root / "U2"),
            "--out",
            str(tmp_path / "o"),
            "--keep-outliers",
        ]
    )
    assert args.handler(args) == 0
    assert "n = 2 participants" in capsys.readouterr().out
    assert (tmp_path / "o" / "report.md").is_file()


# ---------------------------------------------------------------------------- errors
def _error(paths, capsys=None, **kw):
    with pytest.raises(A.AnalysisError) as e:
        A.analyze(paths, **kw)
    return str(e.value)


def test_error_missing_folder(tmp_path):
    assert "no such file or folder" in _error([tmp_path / "nope"])


def test_error_study_without_participants(tmp_path):
    (tmp_path / "empty").mkdir()
    msg = _error([tmp_path / "empty"])
    assert "no participant data" in msg and "trials.jsonl" in msg


def test_error_missing_tlx_file(tmp_path):
    make_study(tmp_path / "S", n=3)
    (tmp_path / "S" / "U2" / "tlx.jsonl").unlink()
    msg = _error([tmp_path / "S"])
    assert "U2" in msg and "missing tlx.jsonl" in msg


def test_error_malformed_json_line_names_file_and_line(tmp_path):
    make_study(tmp_path / "S", n=3)
    f = tmp_path / "S" / "U2" / "trials.jsonl"
    lines = f.read_text().splitlines()
    lines[4] = lines[4][:-3]
    f.write_text("\n".join(lines) + "\n")
    msg = _error([tmp_path / "S"])
    assert f"{f}:5: malformed JSON" in msg


def test_error_bad_field_names_file_line_and_field(tmp_path):
    make_study(tmp_path / "S", n=3)
    f = tmp_path / "S" / "U1" / "trials.jsonl"
    lines = f.read_text().splitlines()
    rec = json.loads(lines[6])
    del rec["completion_s"]
    lines[6] = json.dumps(rec)
    rec = json.loads(lines[7])
    f.write_text("\n".join(lines) + "\n")
    assert f"{f}:7: missing field 'completion_s'" in _error([tmp_path / "S"])
    rec["k"] = 5
    lines[6] = json.dumps(rec)
    f.write_text("\n".join(lines) + "\n")
    assert f"{f}:7: field 'k' must be 3 or 4, got 5" in _error([tmp_path / "S"])


def test_error_bad_tlx_scale(tmp_path):
    make_study(tmp_path / "S", n=3)
    f = tmp_path / "S" / "U3" / "tlx.jsonl"
    lines = f.read_text().splitlines()
    rec = json.loads(lines[1])
    rec["scales"]["FR"] = 22
    lines[1] = json.dumps(rec)
    f.write_text("\n".join(lines) + "\n")
    assert f"{f}:2: scales.FR must be an integer 1..21, got 22" in _error([tmp_path / "S"])


def test_error_duplicate_trial(tmp_path):
    make_study(tmp_path / "S", n=3)
    f = tmp_path / "S" / "U1" / "trials.jsonl"
    lines = f.read_text().splitlines()
    f.write_text("\n".join(lines + [lines[10]]) + "\n")
    msg = _error([tmp_path / "S"])
    assert "logged twice" in msg and f"{f}:11" in msg


def test_error_participant_missing_a_modality_says_which(tmp_path):
    rng = np.random.default_rng(1)
    root = tmp_path / "S"
    for i in range(3):
        make_participant(root, i, rng)
    make_participant(root, 3, rng, modalities=["F+C", "Fperp+C", "F+V"])
    msg = _error([root])
    assert "U4 has no trials of modality Fperp+V" in msg
    assert "all four modalities" in msg


def test_one_participant_gives_tables_and_figure_and_says_why_no_tests(tmp_path, capsys):
    """A pilot: Tables I-III, the means and Figure 4; the tests need 2 participants."""
    trials, _ = make_study(tmp_path / "S", n=1)
    code = cli.main(["analyze", str(tmp_path / "S"), "--out", str(tmp_path / "out")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "Table I" in out and "Table II" in out
    assert "need at least 2 participants" in out and "(U1)" in out
    res = A.analyze([tmp_path / "S"])
    assert not res.stats.inferential and res.stats.n == 1
    analysed = [t for t in trials if not t["familiarization"]]
    assert int(res.table1["trials"].sum()) == len(analysed)
    for name in ("figure4.png", "figure4.svg", "table1.csv", "table2.csv", "report.md"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    report = (tmp_path / "out" / "report.md").read_text()
    assert "Inferential statistics not computed" in report and "ANOVA** (pingouin)" not in report


def test_outlier_removal_leaving_one_participant_says_so():
    """Participant j is the outlier of modality j (j = 0..2): three rows go, one stays."""
    import pandas as pd

    vals = np.array(
        [
            [10.0, 11.0, 12.0, 10.0],
            [11.0, 10.0, 11.0, 11.0],
            [12.0, 12.0, 10.0, 12.0],
            [13.0, 13.0, 13.0, 13.0],
        ]
    )
    for j in range(3):
        vals[j, j] = 100.0
    wide = pd.DataFrame(vals, index=["P0", "P1", "P2", "P3"], columns=ORDER)
    st = A.paper_statistics(wide)
    assert st.removed == ["P0", "P1", "P2"] and st.n == 1 and not st.inferential
    line = st.anova_line()
    assert "need at least 2 participants" in line and "P0, P1, P2" in line
    assert "--keep-outliers" in line
    assert A.paper_statistics(wide, remove_outliers=False).n == 4


def test_small_study_says_what_was_not_computed(tmp_path):
    make_study(tmp_path / "S", n=3)
    res = A.analyze([tmp_path / "S"])
    assert res.stats.n == 3
    assert any("Shapiro-Wilk not computed" in n for n in res.stats.notes)
    assert any("Mauchly's test not computed" in n for n in res.stats.notes)
    assert "Mauchly's test of sphericity**: not computed" in A.report_markdown(res)


def test_error_not_a_folder_and_non_object_line_and_contradiction(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    assert "not a folder" in _error([f])
    make_study(tmp_path / "S", n=3)
    t = tmp_path / "S" / "U2" / "trials.jsonl"
    lines = t.read_text().splitlines()
    t.write_text("\n".join(["[1, 2]"] + lines[1:]) + "\n")
    assert f"{t}:1: expected a JSON object, got list" in _error([tmp_path / "S"])
    rec = json.loads(lines[5])
    rec["policy"] = "Fperp" if rec["policy"] == "F" else "F"
    t.write_text("\n".join(lines[:5] + [json.dumps(rec)] + lines[6:]) + "\n")
    assert f"{t}:6: modality" in _error([tmp_path / "S"])


def test_empty_tlx_file_gives_an_empty_table3(tmp_path):
    make_study(tmp_path / "S", n=4)
    for pid in PIDS[:4]:
        (tmp_path / "S" / pid / "tlx.jsonl").write_text("")
    res = A.analyze([tmp_path / "S"])
    assert res.table3.empty
    assert "No NASA-TLX questionnaires were logged." in A.report_markdown(res)


def test_runner_records_with_named_wrenches_and_extra_fields(tmp_path):
    """What graspguide trial writes: wrench_id names ("W01", familiarization "F01"),
    session 0 for familiarization, and fields the analysis does not use."""
    make_study(tmp_path / "S", n=4)
    for pid in PIDS[:4]:
        f = tmp_path / "S" / pid / "trials.jsonl"
        recs = [json.loads(x) for x in f.read_text().splitlines()]
        for r in recs:
            fam = r["familiarization"]
            r["wrench_id"] = f"{'F' if fam else 'W'}{r['wrench_id'] % 100 + 1:02d}"
            r["session"] = 0 if fam else r["session"]
            r.update(
                session_trial=1,
                wrench_class="multi",
                first_entry_s=1.0,
                final_error_deg=2.0,
                poses=100,
                wall_s=0.1,
                config_hash="abc",
                source="participant",
                recorded_at="2026-11-22T07:00:00Z",
            )
        f.write_text("".join(json.dumps(r) + "\n" for r in recs))
        q = tmp_path / "S" / pid / "tlx.jsonl"
        recs = [json.loads(x) for x in q.read_text().splitlines()]
        for r in recs:
            r.update(policy=r["modality"].split("+")[0], origin="file", config_hash="abc")
        q.write_text("".join(json.dumps(r) + "\n" for r in recs))
    (tmp_path / "S" / "study.json").write_text("{}")
    (tmp_path / "S" / "U1" / "frames").mkdir()
    res = A.analyze([tmp_path / "S"])
    assert res.familiarization_excluded == 4 * 3
    assert list(res.table1["trials"]) == [48] * 8
    assert res.trials["wrench_id"].iloc[-1].startswith("W")
    assert res.trials["source"].iloc[0].endswith("trials.jsonl:1")


def test_tlx_scales_null_are_left_out_of_table3(tmp_path):
    """The runner logs a simulated session without a --tlx file with scales null."""
    _, tlx = make_study(tmp_path / "S", n=4)
    for pid in PIDS[:4]:
        f = tmp_path / "S" / pid / "tlx.jsonl"
        recs = [json.loads(x) for x in f.read_text().splitlines()]
        for r in recs:
            if r["session"] % 2:
                r["scales"] = None
        f.write_text("".join(json.dumps(r) + "\n" for r in recs))
    res = A.analyze([tmp_path / "S"])
    kept = [q for q in tlx if q["session"] % 2 == 0]
    t3 = res.table3.set_index("mode")
    for mode in ("C", "V"):
        vals = [q["scales"]["FR"] for q in kept if q["mode"] == mode]
        assert t3.loc[mode, "sessions"] == len(vals) == 8
        assert t3.loc[mode, "FR_mean"] == pytest.approx(statistics.fmean(vals))
    assert "16 of 32 sessions were logged without a questionnaire" in A.report_markdown(res)


def test_cut_last_line_is_left_out_and_said(tmp_path):
    trials, _ = make_study(tmp_path / "S", n=3)
    f = tmp_path / "S" / "U3" / "trials.jsonl"
    text = f.read_text()
    f.write_text(text[:-20])
    res = A.analyze([tmp_path / "S"])
    n = len(text.splitlines())
    (line,) = res.left_out
    assert str(line).startswith(f"{f}:{n}: the last line is a write cut short")
    assert len(res.trials) == len(trials) - 1


def test_default_out_dir_is_the_study_folders_analysis(tmp_path):
    make_study(tmp_path / "S", n=2)
    assert A.default_out_dir([tmp_path / "S"]) == tmp_path / "S" / "analysis"
    assert A.default_out_dir([tmp_path / "S" / "U2"]) == (tmp_path / "S").resolve() / "analysis"


def test_mauchly_p_is_the_papers_chi_square_approximation():
    """The paper reports chi2(5) = 10.56, p = 0.061: the plain chi-square tail, which
    is what `sphericity["pval"]` holds (pingouin's own p adds R's second-order term)."""
    assert round(float(scipy.stats.chi2.sf(10.56, 5)), 3) == 0.061


def test_cli_error_goes_to_stderr_with_exit_1(tmp_path, capsys):
    assert cli.main(["analyze", str(tmp_path / "missing")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("graspguide analyze: error:") and "no such file" in err
    with pytest.raises(SystemExit) as e:
        cli.main(["analyze"])
    assert e.value.code == 2


def test_pilot_of_one_real_participant_run_is_analysed(tmp_path):
    """`graspguide trial` runs the paper's protocol for one virtual participant (100 trials,
    the simulated device on its virtual clock), then `graspguide analyze` on that folder:
    exit 0, Tables I-II, Figure 4 and why there are no tests (it exited 1 before)."""
    import os
    import subprocess
    import sys

    from conftest import REPO_ROOT, subprocess_env

    study = tmp_path / "pilot"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "graspguide",
            "trial",
            "--protocol",
            os.path.join(REPO_ROOT, "protocols", "paper.toml"),
            "--participant",
            "U1",
            "--port",
            "sim",
            "--source",
            "participant",
            "--out",
            str(study),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env=subprocess_env(),
        cwd=REPO_ROOT,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    lines = (study / "U1" / "trials.jsonl").read_text().splitlines()
    assert len(lines) == 100
    an = subprocess.run(
        [sys.executable, "-m", "graspguide", "analyze", str(study)],
        capture_output=True,
        text=True,
        timeout=300,
        env=subprocess_env(),
        cwd=REPO_ROOT,
    )
    assert an.returncode == 0, an.stderr
    out = an.stdout
    assert "Table I: successfully accomplished tasks" in out
    assert "Table II: completion time" in out
    assert "need at least 2 participants" in out and "(U1)" in out
    assert an.stderr == ""
    png = study / "analysis" / "figure4.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table1 = (study / "analysis" / "table1.csv").read_text().splitlines()
    assert len(table1) == 1 + 8  # header + 2 contact counts x 4
    assert sum(int(r.split(",")[-2]) for r in table1[1:]) == 96  # 100 - 4 familiarization


@pytest.mark.parametrize(
    "rows",
    [
        [[90.0, 90.0, 90.0, 90.0]] * 8,  # every trial timed out
        [[90.0, 90.0, 10.0, 10.0]] * 8,  # C timed out, V all alike
        [[x, x, x, x] for x in range(10, 18)],  # only the participants differ
    ],
    ids=["all-timed-out", "modalities-alike", "participants-only"],
)
def test_no_within_subject_error_gives_descriptive_results_and_says_why(rows):
    """With no within-subject error the F ratio and the t statistics divide by zero:
    pingouin returns a table without T (KeyError before) or an F of -9e31. The tests are
    left out and the report says why."""
    import pandas as pd

    wide = pd.DataFrame(rows, index=[f"U{i + 1}" for i in range(len(rows))], columns=ORDER)
    st = A.paper_statistics(wide, remove_outliers=False)
    assert not st.inferential and st.n == len(rows)
    assert "no within-subject error" in st.anova_line()
    assert st.pairwise.empty


def test_within_subject_error_keeps_the_tests():
    import pandas as pd

    rows = [[x, x + 1.0, x + 2.0, x + 3.0 + 0.1 * (x % 3)] for x in range(10, 18)]
    wide = pd.DataFrame(rows, index=[f"U{i + 1}" for i in range(8)], columns=ORDER)
    st = A.paper_statistics(wide, remove_outliers=False)
    assert st.inferential and st.anova["F"] > 0 and len(st.pairwise) == 6
