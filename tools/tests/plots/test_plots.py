"""`graspguide plot`: figures compared by structure (axes, labels, limits, legends), not by
pixels, on a checked-in run (tools/tests/data/plot_structure: a `graspguide trial` study
folder and a `graspguide stream --log` session folder recorded on --port sim, frames
thinned; see docs/plots.md), whose golden structures are the JSON files there. The
expected values that do not come from the golden files come from the run's own records
(study.json, trials.jsonl, config.json, results.jsonl). A fresh run on the simulated
device checks the live formats by labels and counts only (its floats may differ across
CPUs). Regenerate the golden files after an intended change with
``GRASPGUIDE_UPDATE_PLOT_GOLDEN=1 pytest tools/tests/test_plots.py`` and read the diff."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import small_protocol_toml, subprocess_env

from graspguide.core.vocabulary import FINGERS, shown
from graspguide.plots.figures import FINGER_COLOURS, overview_figure, pyplot, trial_figure
from graspguide.plots.run_folder import load_frames, open_run
from graspguide.plots.structure import figure_structure, svg_texts

DATA = Path(__file__).parents[1] / "data" / "plot_structure"
STUDY = DATA / "study"
SESSION = DATA / "session"
CLI = [sys.executable, "-m", "graspguide"]
UPDATE = os.environ.get("GRASPGUIDE_UPDATE_PLOT_GOLDEN") == "1"


def run_cli(*args: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*CLI, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=subprocess_env(),
    )


def _records(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


STUDY_JSON = json.loads((STUDY / "study.json").read_text())
PROTOCOL_TRIAL = STUDY_JSON["protocol"]["trial"]
TRIAL_RECORDS = {r["trial_index"]: r for r in _records(STUDY / "U1" / "trials.jsonl")}
SESSION_SCENE = json.loads((SESSION / "config.json").read_text())["scene"]
SESSION_RESULT = next(r for r in _records(SESSION / "results.jsonl") if "success" in r)


def _figures() -> dict[str, object]:
    """name -> figure of every figure the fixture gives."""
    out = {}
    study = open_run(str(STUDY))
    for p in study.participants:
        out[f"study-{p.pid}-overview"] = overview_figure(p, study.criteria)
        for t in p.trials:
            out[f"study-{p.pid}-trial-{t.trial:04d}"] = trial_figure(
                t, load_frames(t), study.criteria
            )
    session = open_run(str(SESSION))
    t = session.participants[0].trials[0]
    out[f"session-trial-{t.trial:04d}"] = trial_figure(t, load_frames(t), session.criteria)
    return out


@pytest.fixture(scope="module")
def structures() -> dict[str, dict]:
    figs = _figures()
    try:
        return {name: figure_structure(fig) for name, fig in figs.items()}
    finally:
        for fig in figs.values():
            pyplot().close(fig)


def test_the_fixture_has_what_the_figures_must_show():
    outcomes = {(r["k"], r["success"]) for r in TRIAL_RECORDS.values() if not r["familiarization"]}
    assert outcomes == {(3, True), (3, False), (4, True), (4, False)}
    assert any(r["familiarization"] for r in TRIAL_RECORDS.values())
    assert SESSION_RESULT["success"] is True


def test_golden_structures(structures):
    golden_files = sorted(p.stem for p in DATA.glob("*.json"))
    if UPDATE:
        for old in DATA.glob("*.json"):
            old.unlink()
        for name, s in structures.items():
            (DATA / f"{name}.json").write_text(json.dumps(s, indent=2, ensure_ascii=False) + "\n")
        pytest.fail(
            "golden structures rewritten: read `git diff` and run again without the variable"
        )
    assert golden_files == sorted(structures), "a figure without its golden file, or the reverse"
    for name, s in structures.items():
        golden = json.loads((DATA / f"{name}.json").read_text())
        assert s == golden, name


def _hold_span(ax) -> tuple[float, float] | None:
    spans = [p for p in ax.patches if p.get_label() and not p.get_label().startswith("_")]
    if not spans:
        return None
    x0, width = spans[0].get_x(), spans[0].get_width()
    return x0, x0 + width


@pytest.mark.parametrize("index", sorted(TRIAL_RECORDS))
def test_trial_figure_shows_the_records(index):
    """Threshold, hold window, outcome, condition and fingers as the run recorded them."""
    rec = TRIAL_RECORDS[index]
    study = open_run(str(STUDY))
    trial = next(t for t in study.participants[0].trials if t.trial == index)
    fig = trial_figure(trial, load_frames(trial), study.criteria)
    try:
        ax_err, ax_pwm = fig.get_axes()
        title = ax_err.get_title(loc="left")
        if rec["success"]:
            assert f"success at {rec['completion_s']:g} s" in title
            lo, hi = _hold_span(ax_err)
            assert lo == pytest.approx(rec["completion_s"] - PROTOCOL_TRIAL["hold_s"])
            assert hi == pytest.approx(rec["completion_s"])
        else:
            assert f"timeout at {PROTOCOL_TRIAL['timeout_s']:g} s" in title
            assert _hold_span(ax_err) is None
        assert f"{shown(rec['modality'])}, k = {rec['k']}" in title
        assert rec["wrench_id"] in title
        assert "SIMULATED participant" in title
        threshold = [ln for ln in ax_err.get_lines() if ln.get_label().startswith("threshold")]
        assert len(threshold) == 1
        assert set(threshold[0].get_ydata()) == {PROTOCOL_TRIAL["threshold_deg"]}
        pwm = {
            ln.get_label(): ln.get_color() for ln in ax_pwm.get_lines() if ln.get_label()[0] != "_"
        }
        assert list(pwm) == list(FINGERS[: rec["k"]])
        assert all(pwm[f] == FINGER_COLOURS[f] for f in pwm)
        assert ax_pwm.get_xlabel() == "time since trial start [s]"
        assert ax_err.get_shared_x_axes().joined(ax_err, ax_pwm)
    finally:
        pyplot().close(fig)


def test_session_figure_shows_the_result_and_scene():
    session = open_run(str(SESSION))
    trial = session.participants[0].trials[0]
    fig = trial_figure(trial, load_frames(trial), session.criteria)
    try:
        ax_err, _ = fig.get_axes()
        title = ax_err.get_title(loc="left")
        completion = SESSION_RESULT["completion_s"]
        assert f"success at {completion:.2f}".rstrip("0").rstrip(".") in title
        lo, hi = _hold_span(ax_err)
        assert lo == pytest.approx(completion - SESSION_SCENE["hold_s"])
        assert hi == pytest.approx(completion)
        assert f"threshold {SESSION_SCENE['threshold_deg']:g}°" in [
            ln.get_label() for ln in ax_err.get_lines()
        ]
        assert f"k = {SESSION_SCENE['k']}" in title
    finally:
        pyplot().close(fig)


def test_overview_marks_every_trial():
    study = open_run(str(STUDY))
    fig = overview_figure(study.participants[0], study.criteria)
    try:
        (ax,) = fig.get_axes()
        by_label = {ln.get_label(): ln for ln in ax.get_lines()}
        main = [r for r in TRIAL_RECORDS.values() if not r["familiarization"]]
        ok = sorted((r["trial_index"], r["completion_s"]) for r in main if r["success"])
        late = sorted((r["trial_index"], r["completion_s"]) for r in main if not r["success"])
        assert sorted(zip(by_label["success"].get_xdata(), by_label["success"].get_ydata())) == ok
        assert sorted(zip(by_label["timeout"].get_xdata(), by_label["timeout"].get_ydata())) == late
        assert list(by_label["familiarization"].get_xdata()) == [
            r["trial_index"] for r in TRIAL_RECORDS.values() if r["familiarization"]
        ]
        assert f"{len(ok)} of {len(main)} main trials succeeded" in ax.get_title(loc="left")
        sessions = {r["session"] for r in main}
        labels = "\n".join(t.get_text() for t in ax.texts)
        assert all(f"S{s}" in labels for s in sessions)
    finally:
        pyplot().close(fig)


def _check_png(path: Path, figure) -> None:
    from PIL import Image

    with Image.open(path) as im:
        im.load()  # decodes every pixel
        dpi = im.info.get("dpi", (0, 0))
        assert round(dpi[0]) >= 150, dpi
        w, h = figure
        assert im.size == (round(w * dpi[0]), round(h * dpi[1])), im.size


def test_cli_writes_png_and_svg(tmp_path, structures):
    proc = run_cli("plot", STUDY, "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    written = sorted(Path(line) for line in proc.stdout.splitlines())
    expected = sorted(
        tmp_path / f"U1-{name}.{fmt}"
        for name in ["overview", *(f"trial-{i:04d}" for i in TRIAL_RECORDS)]
        for fmt in ("png", "svg")
    )
    assert written == expected
    for index, rec in TRIAL_RECORDS.items():
        stem = tmp_path / f"U1-trial-{index:04d}"
        _check_png(stem.with_suffix(".png"), (8.0, 5.6))
        texts = svg_texts(stem.with_suffix(".svg").read_bytes())
        s = structures[f"study-U1-trial-{index:04d}"]
        # Every label the structure names is text in the SVG (svg.fonttype none).
        wanted = [
            *s["axes"][0]["title"].split("\n"),
            s["axes"][0]["ylabel"],
            s["axes"][1]["ylabel"],
            s["axes"][1]["xlabel"],
            *s["axes"][0]["legend"],
            *s["axes"][1]["legend"],
        ]
        assert set(FINGERS[: rec["k"]]) <= set(texts)
        for text in wanted:
            assert text in texts, (stem, text)
    overview = svg_texts((tmp_path / "U1-overview.svg").read_bytes())
    assert {"success", "timeout", "familiarization", "completion time [s]"} <= set(overview)


def test_cli_one_trial_and_format(tmp_path):
    proc = run_cli(
        "plot", STUDY, "--trial", "3", "--participant", "U1", "--out", tmp_path, "--format", "svg"
    )
    assert proc.returncode == 0, proc.stderr
    assert sorted(os.listdir(tmp_path)) == ["U1-trial-0003.svg"]
    proc = run_cli("plot", SESSION, "--out", tmp_path / "s")
    assert proc.returncode == 0, proc.stderr
    assert sorted(os.listdir(tmp_path / "s")) == ["trial-0001.png", "trial-0001.svg"]
    assert "no session overview" in proc.stdout
    # The default --out is RUN_DIR/plots.
    run = tmp_path / "run"
    shutil.copytree(STUDY, run)
    proc = run_cli("plot", run / "U1", "--trial", "2", "--format", "png")
    assert proc.returncode == 0, proc.stderr
    assert os.listdir(run / "U1" / "plots") == ["U1-trial-0002.png"]


def _bad(args, code: int, *words: str) -> None:
    proc = run_cli("plot", *args)
    assert proc.returncode == code, (args, proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert lines and lines[-1].startswith("graspguide plot: error:"), proc.stderr
    for w in words:
        assert w in proc.stderr, (w, proc.stderr)


def test_bad_input(tmp_path):
    out = ["--out", str(tmp_path / "out")]
    _bad([tmp_path / "nope", *out], 2, str(tmp_path / "nope"), "no such folder")
    _bad([tmp_path, *out], 2, "neither a study folder", "study.json", "telemetry.csv")
    _bad([STUDY, "--trial", "99", *out], 2, "no trial 99", "1..5")
    _bad([STUDY, "--participant", "U9", *out], 2, "no participant U9", "U1")
    _bad([SESSION, "--participant", "U1", *out], 2, "session folder")
    _bad([STUDY, "--format", "pdf", *out], 2, "png, svg")

    run = tmp_path / "run"
    shutil.copytree(STUDY, run)
    frames = run / "U1" / "frames" / "trial-0002.csv"
    data = frames.read_bytes()
    frames.write_bytes(data[: data.rindex(b"\n", 0, len(data) - 1) + 20])  # mid-line
    lines = frames.read_bytes().count(b"\n") + 1
    _bad([run, "--trial", "2", *out], 1, f"{frames}:{lines}", "cut mid-line", "copy the run folder")
    frames.unlink()
    _bad([run, "--trial", "2", *out], 1, str(frames), "no such file")

    trials = run / "U1" / "trials.jsonl"
    rows = trials.read_text().splitlines()
    trials.write_text("\n".join([rows[0], rows[1][:40], *rows[2:]]) + "\n")
    _bad([run, *out], 1, f"{trials}:2", "malformed JSON")

    session = tmp_path / "session"
    shutil.copytree(SESSION, session)
    tel = session / "telemetry.csv"
    tel.write_text(tel.read_text().replace("\n", "\n1,2\n", 1))
    _bad([session, *out], 1, f"{tel}:2", "2 fields")


def test_a_fresh_simulated_run_plots(tmp_path):
    """The live formats (a study on --port sim with the virtual participant, a stream
    session): labels and counts only, not the CPU's floats."""
    protocol = tmp_path / "p.toml"
    protocol.write_text(
        small_protocol_toml("plots", 3, participants=1, timeout_s=6.0, wrenches=1, single_motor=1)
    )
    study = tmp_path / "study"
    proc = run_cli(
        "trial",
        "--protocol",
        protocol,
        "--participant",
        "U1",
        "--port",
        "sim",
        "--source",
        "participant",
        "--out",
        study,
    )
    assert proc.returncode == 0, proc.stderr
    records = _records(study / "U1" / "trials.jsonl")
    proc = run_cli("plot", study, "--out", tmp_path / "plots")
    assert proc.returncode == 0, proc.stderr
    assert len(proc.stdout.splitlines()) == 2 * (len(records) + 1)
    for rec in records:
        texts = svg_texts(
            (tmp_path / "plots" / f"U1-trial-{rec['trial_index']:04d}.svg").read_bytes()
        )
        outcome = "success at" if rec["success"] else "timeout at 6 s"
        assert any(outcome in t for t in texts), texts
        assert {"error angle", "threshold 3°", *FINGERS[: rec["k"]]} <= set(texts)

    session = tmp_path / "session"
    proc = run_cli(
        "stream",
        "--port",
        "sim",
        "--virtual-clock",
        "--scene",
        Path(__file__).parents[3] / "tools" / "examples" / "scene_paper_3.toml",
        "--wrench",
        "0.3,-1.2,-0.8",
        "--source",
        "synthetic:duration=3",
        "--log",
        session,
    )
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("plot", session, "--out", tmp_path / "splots", "--format", "png")
    assert proc.returncode == 0, proc.stderr
    _check_png(tmp_path / "splots" / "trial-0001.png", (8.0, 5.6))
