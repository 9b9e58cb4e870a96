"""The paper's values as data: shipped, validated, true to the paper's text, and set
beside a study's Tables I-II."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path

import pandas as pd
import pytest

from graspguide.analysis.paper_reference import (
    format_markdown,
    format_text,
    label_contradiction_markdown,
    load_paper_values,
    paper_vs_simulated,
)
from graspguide.analysis.paper_tables import AnalysisError

PAPER_TEXT = Path("/work/shared/seed/hand-guidance-grasping-metaphor.txt")
# The paper's column order in Tables I and II, at 3 then at 4 contact points.
PRINTED_ORDER = [(k, m) for k in (3, 4) for m in ("F+V", "Fperp+V", "F+C", "Fperp+C")]


def _printed_row(text: str, label: str) -> list[float]:
    """The numbers of the table row that starts with ``label`` in the paper's text."""
    for line in text.splitlines():
        if line.startswith(label):
            return [float(x) for x in re.findall(r"\d+(?:\.\d+)?", line[len(label) :])]
    raise AssertionError(f"no row {label!r} in the paper's text")


def test_the_shipped_values_match_the_papers_text():
    if not PAPER_TEXT.is_file():
        pytest.skip(f"the paper's text is not at {PAPER_TEXT}")
    text = PAPER_TEXT.read_text(encoding="utf-8")
    paper = load_paper_values()
    t1 = {(r["k"], r["modality"]): r for r in paper["table1"]["rows"]}
    t2 = {(r["k"], r["modality"]): r for r in paper["table2"]["rows"]}
    for label, table, key in (
        ("Successes", t1, "successes"),
        ("Failures", t1, "failures"),
        ("Rate of", t1, "success_rate_percent"),
        ("Mean [s]", t2, "mean_s"),
        ("STD [s]", t2, "sd_s"),
    ):
        printed = _printed_row(text, label)
        assert printed == [table[c][key] for c in PRINTED_ORDER], label
    assert f"F = {paper['anova']['F']}" in text
    m = paper["anova"]["mauchly"]
    assert f"\\chi^2({m['df']}) = {m['chi2']}$, p = {m['p']}" in text
    for d in paper["pairwise"]["differences_s"]:
        assert f"{d['diff_s']} s" in text


def test_the_label_contradiction_is_in_the_printed_differences():
    paper = load_paper_values()
    d = {(x["from"], x["to"]): x["diff_s"] for x in paper["pairwise"]["differences_s"]}
    via_fperp_c = d[("Fperp+C", "Fperp+V")] - d[("Fperp+C", "F+V")]
    via_f_c = d[("F+C", "Fperp+V")] - d[("F+C", "F+V")]
    assert via_fperp_c == pytest.approx(1.57, abs=1e-9)
    assert via_f_c == pytest.approx(-1.58, abs=1e-9)
    # The two V labels of the F+C sentence swapped: both routes agree within rounding.
    assert d[("F+C", "F+V")] - d[("F+C", "Fperp+V")] == pytest.approx(via_fperp_c, abs=0.011)
    note = label_contradiction_markdown(paper)
    assert "+1.57 s" in note and "-1.58 s" in note and "F⊥+C − F⊥+V: 26.34 s" in note


def _write(tmp_path, doc) -> Path:
    path = tmp_path / "values.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("spoil", "named"),
    [
        (
            lambda d: d["table1"]["rows"][2].pop("successes"),
            "table1.rows[2]: missing field 'successes'",
        ),
        (
            lambda d: d["table2"]["rows"][0].__setitem__("mean_s", "8.64"),
            "table2.rows[0]: field 'mean_s'",
        ),
        (lambda d: d["table2"]["rows"].pop(), "table2.rows must hold each condition once"),
        (lambda d: d["anova"]["mauchly"].pop("chi2"), "anova.mauchly: missing field 'chi2'"),
        (
            lambda d: d["pairwise"]["differences_s"][1].__setitem__("to", "F+X"),
            "differences_s[1]: field 'to'",
        ),
        (lambda d: d.pop("table3"), "missing field 'table3'"),
    ],
)
def test_a_malformed_file_names_the_field(tmp_path, spoil, named):
    doc = copy.deepcopy(load_paper_values())
    spoil(doc)
    with pytest.raises(AnalysisError, match=re.escape(named)):
        load_paper_values(_write(tmp_path, doc))


def test_a_file_that_is_not_json_names_its_line(tmp_path):
    path = tmp_path / "values.json"
    path.write_text('{\n "table1": [,]\n}', encoding="utf-8")
    with pytest.raises(AnalysisError, match=r"values\.json:2: not valid JSON"):
        load_paper_values(path)


def test_paper_vs_simulated_sets_a_small_study_beside_the_paper():
    rows = []
    for p in ("U1", "U2"):
        for w in ("W1", "W2"):
            rows.append((p, 3, "F+V", w, 10.0 if p == "U1" else 20.0, True, False))
            ok = w == "W1"
            rows.append((p, 3, "F+C", w, 30.0 if ok else 90.0, ok, False))
    # A familiarization trial is not counted.
    rows.append(("U1", 3, "F+C", "W0", 90.0, False, True))
    trials = pd.DataFrame(
        rows,
        columns=[
            "participant",
            "k",
            "modality",
            "wrench_id",
            "completion_s",
            "success",
            "familiarization",
        ],
    )
    table = paper_vs_simulated(trials)
    assert list(zip(table["k"], table["modality"])) == PRINTED_ORDER
    by = table.set_index(["k", "modality"])
    fv, fc = by.loc[(3, "F+V")], by.loc[(3, "F+C")]
    assert (fv["paper_success_pct"], fv["paper_mean_s"], fv["paper_sd_s"]) == (100.0, 8.64, 5.83)
    assert fv["sim_success_pct"] == 100.0 and fv["sim_mean_s"] == 15.0 and fv["sim_trials"] == 4
    assert fv["sim_sd_s"] == pytest.approx(pd.Series([10.0, 10.0, 20.0, 20.0]).std())
    assert fc["sim_success_pct"] == 50.0 and fc["sim_mean_s"] == 60.0 and fc["sim_trials"] == 4
    assert fc["paper_success_pct"] == 85.0
    absent = by.loc[(4, "Fperp+C")]
    assert math.isnan(absent["sim_mean_s"]) and absent["sim_trials"] == 0
    md = format_markdown(table)
    assert "| 3 | F+C | 85 % | 50 % | 32.90 ± 30.31 | 60.00 ± 34.64 | 4 |" in md
    assert "| 4 | F⊥+C | 84 % | – | 39.47 ± 27.37 | – ± – | 0 |" in md
    assert format_text(table).splitlines()[0].startswith("k  modality")
