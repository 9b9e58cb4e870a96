"""A run killed mid-write leaves a damaged last line in trials.jsonl: `graspguide analyze`
and `graspguide plot` read every complete record, leave that line out, say so and how to
record it again, and change no file (graspguide.records.storage.complete_records)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import subprocess_env
from test_analysis import make_study

from graspguide.analysis.paper_tables import analyze

CLI = [sys.executable, "-m", "graspguide"]
PLOT_STUDY = Path(__file__).parents[1] / "data" / "plot_structure" / "study"


def run_cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*CLI, *map(str, args)], capture_output=True, text=True, timeout=300, env=subprocess_env()
    )


def _damage_last_line(path: Path, keep_newline: bool) -> int:
    """Cut the last record mid-way; returns the number of complete records left."""
    rows = path.read_text().splitlines()
    path.write_text("\n".join(rows[:-1]) + "\n" + rows[-1][:37] + ("\n" if keep_newline else ""))
    return len(rows) - 1


@pytest.mark.parametrize("keep_newline", [False, True], ids=["cut-short", "damaged"])
def test_analyze_reads_every_complete_record_and_says_what_to_do(tmp_path, keep_newline):
    make_study(tmp_path / "S", n=3)
    trials = tmp_path / "S" / "U2" / "trials.jsonl"
    whole = analyze([tmp_path / "S"])
    complete = _damage_last_line(trials, keep_newline)
    damaged = trials.read_bytes()

    proc = run_cli("analyze", tmp_path / "S", "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    warning = proc.stderr
    assert f"{trials}:{complete + 1}: the last line is" in warning, warning
    assert f"the {complete} complete records before it are read" in warning
    assert "graspguide trial" in warning and "damaged-<time>" in warning  # the fix
    assert ("a write cut short" in warning) is not keep_newline
    assert trials.read_bytes() == damaged  # nothing changed, nothing lost

    res = analyze([tmp_path / "S"])
    assert len(res.trials) == len(whole.trials) - 1  # only the damaged line is missing
    assert len(res.left_out) == 1
    report = (tmp_path / "out" / "report.md").read_text()
    assert "Left out" in report and f"{trials}:{complete + 1}" in report


def test_a_damaged_line_before_the_last_is_still_an_error(tmp_path):
    make_study(tmp_path / "S", n=3)
    trials = tmp_path / "S" / "U1" / "trials.jsonl"
    rows = trials.read_text().splitlines()
    rows[3] = rows[3][:20]
    trials.write_text("\n".join(rows) + "\n")
    proc = run_cli("analyze", tmp_path / "S", "--out", tmp_path / "out")
    assert proc.returncode == 1
    assert f"{trials}:4: malformed JSON" in proc.stderr


def test_plot_draws_the_complete_trials_and_says_what_was_left_out(tmp_path):
    run = tmp_path / "run"
    shutil.copytree(PLOT_STUDY, run)
    trials = run / "U1" / "trials.jsonl"
    complete = _damage_last_line(trials, keep_newline=False)
    proc = run_cli("plot", run, "--out", tmp_path / "out", "--format", "png")
    assert proc.returncode == 0, proc.stderr
    assert f"{trials}:{complete + 1}: the last line is a write cut short" in proc.stderr
    drawn = sorted(p.name for p in (tmp_path / "out").rglob("*trial-*.png"))
    assert len(drawn) == complete, drawn
