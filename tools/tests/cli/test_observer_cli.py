"""`graspguide observer`: the ideal-observer bounds as a command (SIMULATED): its options
reach the library by name, a tiny run prints and writes the labelled table, and bad input
ends with the usage status and a message that names it."""

from __future__ import annotations

import inspect
import os
import re

import pytest
from conftest import REPO_ROOT

from graspguide import cli
from graspguide.participant import ideal_observer

ROW = re.compile(r"^\| ([34]) \| (F|Fperp)\+([CV]) \| ([0-9.]+) % \| ([0-9.]+) % \| ([0-9.]+) % \|")


def test_each_option_reaches_the_library_by_name(monkeypatch):
    calls = []

    def recorder(*args, **kwargs):
        calls.append((args, kwargs))
        return 0

    original = ideal_observer.run
    monkeypatch.setattr(ideal_observer, "run", recorder)
    argv = [
        "observer",
        "--protocol",
        "p.toml",
        "--n-prior",
        "300",
        "--n-trials",
        "7",
        "--seed",
        "5",
        "--weber",
        "0.2",
        "--per-wrench",
        "--out",
        "b.md",
    ]
    assert cli.main(argv) == 0
    expected = dict(
        protocol="p.toml",
        seed=5,
        n_prior=300,
        n_trials=7,
        weber=0.2,
        per_wrench=True,
        out="b.md",
    )
    assert calls == [((), expected)]
    # the test's list is the function's whole signature: no parameter left to its default
    assert set(expected) == set(inspect.signature(original).parameters)
    calls.clear()
    assert cli.main(["observer", "--markdown", "m.md"]) == 0  # the other name of --out
    assert calls[0][1]["out"] == "m.md"
    assert calls[0][1]["protocol"] is None  # the library picks the repository's paper.toml


def test_a_tiny_run_prints_and_writes_the_simulated_bounds(tmp_path, capsys):
    out = tmp_path / "bounds.md"
    argv = ["observer", "--n-prior", "200", "--n-trials", "10", "--per-wrench"]
    assert cli.main([*argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("SIMULATED ideal-observer bounds: ")
    assert os.path.join(REPO_ROOT, "protocols", "paper.toml") in printed
    rows = [ROW.match(line) for line in printed.splitlines() if ROW.match(line)]
    # every condition of the paper protocol once
    assert sorted((m[1], m[2], m[3]) for m in rows) == sorted(
        (k, p, m) for k in "34" for p in ("F", "Fperp") for m in "CV"
    )
    for m in rows:
        onoff, intensity, bound = (float(m[i]) for i in (4, 5, 6))
        assert 0.0 <= onoff <= 100.0 and 0.0 <= intensity <= 100.0
        assert bound == (intensity if m[3] == "C" else 100.0)
    assert "per wrench of the protocol" in printed and "| W12 |" in printed
    text = out.read_text(encoding="utf-8")
    assert text.startswith("# Ideal-observer bounds (SIMULATED: model bounds, not human data)")
    # the file holds what was printed (the table and the per-wrench masses)
    for m in rows:
        assert m[0] in text
    assert f"Wrote {out}" in printed
    # the same seed gives the same figures
    again = tmp_path / "again.md"
    assert cli.main([*argv, "--out", str(again)]) == 0
    assert again.read_text(encoding="utf-8") == text


def test_a_bad_protocol_file_is_a_usage_error_naming_it(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    with open(os.path.join(REPO_ROOT, "protocols", "paper.toml"), encoding="utf-8") as f:
        paper = f.read()
    assert 'moments = "zero"' in paper
    bad.write_text(paper.replace('moments = "zero"', 'moments = "few"'), encoding="utf-8")
    assert cli.main(["observer", "--protocol", str(bad), "--n-prior", "10"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("graspguide observer: error: ") and str(bad) in err
    assert "[wrenches] moments" in err


@pytest.mark.parametrize(
    "argv,says",
    [
        (["--weber", "0"], "must be in (0, 5]"),
        (["--weber", "nan"], "must be in (0, 5]"),
        (["--n-prior", "5"], "must be between 10 and"),
        (["--n-trials", "0"], "must be between 1 and"),
    ],
)
def test_bad_options_are_usage_errors(argv, says, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["observer", *argv])
    assert e.value.code == 2
    assert says in capsys.readouterr().err


def test_an_output_file_that_cannot_be_written_fails_before_printing(tmp_path, capsys):
    out = tmp_path / "no-such-dir" / "b.md"
    assert cli.main(["observer", "--n-prior", "50", "--n-trials", "2", "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert "cannot write" in captured.err and str(out) in captured.err
    assert "SIMULATED" not in captured.out
