"""The paper's own numbers as data, and the paper-vs-simulated table.

``paper_values.json`` (shipped beside this module) holds the paper's Tables I-III, the
reported one-way repeated-measures ANOVA and the four Bonferroni pairwise differences,
each with the section and table of the paper's text it is transcribed from, and notes
on what the text contradicts (the pairwise differences' labels among them).

:func:`paper_vs_simulated` sets a study's Tables I-II beside the paper's, one row per
contact count and modality.
"""

from __future__ import annotations

import json
import math
import os
from importlib import resources
from typing import Any

from graspguide.analysis.paper_tables import (
    TABLE_ORDER,
    AnalysisError,
    _md_table,
    _text_table,
    table1,
    table2,
)
from graspguide.records.trial import CONTACT_COUNTS

PAPER_VALUES_FILE = "paper_values.json"
_SECTIONS = ("source", "table1", "table2", "table3", "anova", "pairwise", "notes")
_TLX_SCALES = ("MD", "PD", "TD", "PE", "EF", "FR")
COLUMNS = [
    "k",
    "modality",
    "paper_success_pct",
    "sim_success_pct",
    "paper_mean_s",
    "paper_sd_s",
    "sim_mean_s",
    "sim_sd_s",
    "sim_trials",
]


def _need(obj: Any, key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if not isinstance(obj, dict) or key not in obj:
        raise AnalysisError(f"{where}: missing field '{key}'")
    value = obj[key]
    if not isinstance(value, kind) or (kind == (int, float) and isinstance(value, bool)):
        raise AnalysisError(f"{where}: field '{key}' has the wrong type ({type(value).__name__})")
    if isinstance(value, float) and not math.isfinite(value):
        raise AnalysisError(f"{where}: field '{key}' is not finite")
    return value


def _cells(doc: dict[str, Any], table: str, fields: tuple[str, ...], name: str) -> None:
    section = _need(doc, table, dict, name)
    _need(section, "where", str, f"{name}: {table}")
    rows = _need(section, "rows", list, f"{name}: {table}")
    seen = set()
    for i, row in enumerate(rows):
        where = f"{name}: {table}.rows[{i}]"
        k = _need(row, "k", int, where)
        m = _need(row, "modality", str, where)
        if k not in CONTACT_COUNTS or m not in TABLE_ORDER:
            raise AnalysisError(f"{where}: unknown condition k={k} modality={m!r}")
        for f in fields:
            _need(row, f, (int, float), where)
        seen.add((k, m))
    missing = [(k, m) for k in CONTACT_COUNTS for m in TABLE_ORDER if (k, m) not in seen]
    if missing or len(rows) != len(seen):
        raise AnalysisError(
            f"{name}: {table}.rows must hold each condition once (missing: {missing})"
        )


def validate_paper_values(doc: Any, name: str = PAPER_VALUES_FILE) -> dict[str, Any]:
    """Check the structure of the paper's values; ``AnalysisError`` names the bad field."""
    if not isinstance(doc, dict):
        raise AnalysisError(f"{name}: the top level must be an object")
    for key in _SECTIONS:
        _need(doc, key, (dict, list), name)
    _cells(doc, "table1", ("successes", "failures", "success_rate_percent"), name)
    _cells(doc, "table2", ("mean_s", "sd_s"), name)
    t3 = _need(doc, "table3", dict, name)
    _need(t3, "where", str, f"{name}: table3")
    for i, row in enumerate(_need(t3, "rows", list, f"{name}: table3")):
        where = f"{name}: table3.rows[{i}]"
        if _need(row, "mode", str, where) not in ("C", "V"):
            raise AnalysisError(f"{where}: field 'mode' must be C or V")
        if _need(row, "scale", str, where) not in _TLX_SCALES:
            raise AnalysisError(f"{where}: field 'scale' is not a NASA-TLX scale")
        _need(row, "mean", (int, float), where)
        _need(row, "sd", (int, float), where)
    anova = _need(doc, "anova", dict, name)
    _need(anova, "where", str, f"{name}: anova")
    _need(anova, "F", (int, float), f"{name}: anova")
    mauchly = _need(anova, "mauchly", dict, f"{name}: anova")
    for f in ("chi2", "df", "p"):
        _need(mauchly, f, (int, float), f"{name}: anova.mauchly")
    pairwise = _need(doc, "pairwise", dict, name)
    _need(pairwise, "where", str, f"{name}: pairwise")
    for i, d in enumerate(_need(pairwise, "differences_s", list, f"{name}: pairwise")):
        where = f"{name}: pairwise.differences_s[{i}]"
        for f in ("from", "to"):
            if _need(d, f, str, where) not in TABLE_ORDER:
                raise AnalysisError(f"{where}: field '{f}' is not a modality")
        _need(d, "diff_s", (int, float), where)
    for i, note in enumerate(_need(doc, "notes", list, name)):
        _need(note, "id", str, f"{name}: notes[{i}]")
        _need(note, "text", str, f"{name}: notes[{i}]")
    return doc


def load_paper_values(path: str | os.PathLike | None = None) -> dict[str, Any]:
    """The paper's values: the shipped ``paper_values.json``, or ``path``; validated."""
    if path is None:
        name = PAPER_VALUES_FILE
        text = resources.files("graspguide.analysis").joinpath(PAPER_VALUES_FILE).read_text("utf-8")
    else:
        name = os.fspath(path)
        try:
            with open(path, encoding="utf-8") as f:
                text = f.read()
        except OSError as e:
            raise AnalysisError(f"{name}: cannot read ({e.strerror})") from e
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise AnalysisError(f"{name}:{e.lineno}: not valid JSON ({e.msg})") from e
    return validate_paper_values(doc, name)


def paper_vs_simulated(trials, paper: dict[str, Any] | None = None):
    """One row per (k, modality), in the paper's order: the paper's success % and mean ± SD
    (Tables I-II) beside the study's; conditions the study lacks get NaN on its side."""
    import pandas as pd

    paper = load_paper_values() if paper is None else paper
    p1 = {(r["k"], r["modality"]): r for r in paper["table1"]["rows"]}
    p2 = {(r["k"], r["modality"]): r for r in paper["table2"]["rows"]}
    s1 = {(r.k, r.modality): r for r in table1(trials).itertuples()}
    s2 = {(r.k, r.modality): r for r in table2(trials).itertuples()}
    rows = []
    for k in CONTACT_COUNTS:
        for m in TABLE_ORDER:
            a, b = s1.get((k, m)), s2.get((k, m))
            rows.append(
                {
                    "k": k,
                    "modality": m,
                    "paper_success_pct": float(p1[(k, m)]["success_rate_percent"]),
                    "sim_success_pct": 100.0 * a.success_rate if a is not None else math.nan,
                    "paper_mean_s": float(p2[(k, m)]["mean_s"]),
                    "paper_sd_s": float(p2[(k, m)]["sd_s"]),
                    "sim_mean_s": b.mean_s if b is not None else math.nan,
                    "sim_sd_s": b.sd_s if b is not None else math.nan,
                    "sim_trials": int(b.trials) if b is not None else 0,
                }
            )
    return pd.DataFrame(rows, columns=COLUMNS)


def _num(x: float, fmt: str) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def _pct(x: float) -> str:
    return "–" if math.isnan(x) else f"{x:.0f} %"


def _rows(table) -> list[list[str]]:
    from graspguide.core.vocabulary import shown

    return [
        [
            str(r.k),
            shown(r.modality),
            _pct(r.paper_success_pct),
            _pct(r.sim_success_pct),
            f"{_num(r.paper_mean_s, '.2f')} ± {_num(r.paper_sd_s, '.2f')}",
            f"{_num(r.sim_mean_s, '.2f')} ± {_num(r.sim_sd_s, '.2f')}",
            str(r.sim_trials),
        ]
        for r in table.itertuples()
    ]


def _header(side: str) -> list[str]:
    return [
        "k",
        "modality",
        "paper success",
        f"{side} success",
        "paper time [s]",
        f"{side} time [s]",
        f"{side} trials",
    ]


def format_markdown(table, side: str = "simulated") -> str:
    """The paper-vs-study table as a markdown table; ``side`` names the study's columns
    ("simulated", or "this study" for people)."""
    return _md_table(_header(side), _rows(table))


def format_text(table, side: str = "simulated") -> str:
    """The paper-vs-study table as aligned plain text."""
    return _text_table(_header(side), _rows(table))


def _note(paper: dict[str, Any], note_id: str) -> str:
    for n in paper["notes"]:
        if n["id"] == note_id:
            return str(n["text"])
    raise AnalysisError(f"{PAPER_VALUES_FILE}: no note '{note_id}'")


def label_contradiction_markdown(paper: dict[str, Any] | None = None) -> str:
    """A markdown note: the paper's four pairwise differences, and why they cannot all hold."""
    paper = load_paper_values() if paper is None else paper
    from graspguide.core.vocabulary import shown

    d = {(x["from"], x["to"]): x["diff_s"] for x in paper["pairwise"]["differences_s"]}
    lines = [
        "**The paper's pairwise differences contradict each other.** "
        f"As printed ({paper['pairwise']['where']}):",
        "",
    ]
    lines += [f"- {shown(a)} − {shown(b)}: {v:.2f} s" for (a, b), v in d.items()]
    via_fperp_c = d[("Fperp+C", "Fperp+V")] - d[("Fperp+C", "F+V")]
    via_f_c = d[("F+C", "Fperp+V")] - d[("F+C", "F+V")]
    lines += [
        "",
        f"{shown('F+V')} − {shown('Fperp+V')} comes out {via_fperp_c:+.2f} s through "
        f"{shown('Fperp+C')} and {via_f_c:+.2f} s through {shown('F+C')}. "
        + _note(paper, "label_contradiction"),
    ]
    return "\n".join(lines)
