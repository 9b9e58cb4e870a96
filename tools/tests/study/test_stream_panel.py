"""The live panel of `graspguide stream` (graspguide.study.live_view): in a REAL
pseudo-terminal (pexpect) it names the fingers and shows the threshold, the hold progress
and the trial's state; off a terminal the same in plain lines; and its hold progress
agrees with the device's TRIAL_RESULT."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys

import pexpect
import pytest
from conftest import TOOLS_DIR

from graspguide.protocol import scene_file as gs

_TOOLS = TOOLS_DIR
SCENE3 = os.path.join(_TOOLS, "examples", "scene_paper_3.toml")
WRENCH = "0.3,-1.2,-0.8"
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def _env() -> dict[str, str]:
    env = dict(os.environ, TERM="xterm-256color", COLUMNS="120", LINES="40")
    env.pop("PYTHONPATH", None)
    return env


def _spawn(args: list[str], cwd: str) -> pexpect.spawn:
    return pexpect.spawn(
        sys.executable,
        ["-m", "graspguide", "stream", *args],
        env=_env(),
        cwd=cwd,
        dimensions=(40, 120),
        encoding="utf-8",
        timeout=60,
    )


def _hold_text(scene) -> str:
    return f"below {scene.threshold_deg:.1f} deg for {scene.hold_s:.2f}/{scene.hold_s:.2f} s"


def test_panel_in_a_pty_shows_states_in_order(tmp_path):
    """Real time (synthetic, 3 s): the panel goes running -> holding -> success, names the
    fingers and ends with the full hold against the scene's threshold."""
    scene = gs.load_scene(SCENE3)
    child = _spawn(
        ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH]
        + ["--source", "synthetic:rate=100,duration=3,seed=0"],
        str(tmp_path),
    )
    try:
        child.expect("state")
        for finger in scene.fingers:
            child.expect(finger)
        child.expect(r"running")
        child.expect(r"holding")
        child.expect(r"below 3\.0 deg for 0\.\d\d/0\.50 s")
        child.expect(r"success")
        child.expect("trial 1: success")
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert child.exitstatus == 0, child.before
    text = ANSI.sub("", child.before or "")
    assert "motor 1" not in text


def test_panel_participant_simulated_in_a_pty(tmp_path):
    """The virtual participant as the source (virtual clock): labelled SIMULATED, the
    panel's last state is the TRIAL_RESULT's with the full hold."""
    scene_file = tmp_path / "scene_v.toml"
    # mode V: the virtual participant succeeds there (mode C is the paper's harder one)
    scene_file.write_text(open(SCENE3).read().replace('mode = "C"', 'mode = "V"'))
    scene = gs.load_scene(str(scene_file))
    child = _spawn(
        ["--port", "sim", "--virtual-clock", "--scene", str(scene_file), "--wrench", WRENCH]
        + ["--source", "participant:seed=1", "--log", str(tmp_path / "run")],
        str(tmp_path),
    )
    try:
        child.expect("SIMULATED")
        child.expect(re.escape(_hold_text(scene)))
        child.expect("SIMULATED trial 1: success")
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert child.exitstatus == 0
    results = [json.loads(line) for line in open(tmp_path / "run" / "results.jsonl")]
    assert results[0]["success"] is True


def test_plain_lines_off_a_terminal(tmp_path):
    scene = gs.load_scene(SCENE3)
    env = _env()
    p = subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", "--port", "sim", "--virtual-clock"]
        + ["--scene", SCENE3, "--wrench", WRENCH, "--source", "synthetic:rate=240,seed=0"],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=tmp_path,
    )
    assert p.returncode == 0, p.stderr
    assert "\x1b[" not in p.stdout  # no terminal control codes in a pipe or a file
    lines = [line for line in p.stdout.splitlines() if line.startswith("t=")]
    assert len(lines) >= 2
    for line in lines:
        for finger in scene.fingers:
            assert f" {finger}=" in line, line
        assert not re.search(r"motor ?\d", line), line  # motors go by finger names
    assert "state=running" in lines[0] and "not below 3.0 deg" in lines[0]
    assert "state=success" in lines[-1] and _hold_text(scene) in lines[-1]


@pytest.mark.parametrize("seed", [0, 1])
def test_hold_progress_agrees_with_the_trial_result(tmp_path, seed):
    """TrialProgress fed the logged TELEMETRY reaches the hold exactly when the device
    says the trial succeeded, from the entry the device reports."""
    from graspguide.study.live_view import HOLDING, TrialProgress

    scene = gs.load_scene(SCENE3)
    folder = tmp_path / "run"
    p = subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", "--port", "sim", "--virtual-clock"]
        + ["--scene", SCENE3, "--wrench", WRENCH, "--source", f"synthetic:rate=240,seed={seed}"]
        + ["--log", str(folder)],
        capture_output=True,
        text=True,
        timeout=60,
        env=_env(),
        cwd=tmp_path,
    )
    assert p.returncode == 0, p.stderr
    tel = list(csv.DictReader(open(folder / "telemetry.csv")))
    poses = list(csv.DictReader(open(folder / "poses.csv")))
    result = json.loads(open(folder / "results.jsonl").readline())
    assert result["success"] is True
    progress = TrialProgress(scene.threshold_deg, scene.hold_s, scene.timeout_s)
    reached_at = None
    for row, pose in zip(tel, poses):
        progress.frame(float(pose["t_s"]), float(row["error_deg"]), row["solver_status"] == "ok")
        if progress.state == HOLDING and progress.held_s >= scene.hold_s - 1e-9:
            reached_at = float(pose["t_s"])
            break
    assert reached_at is not None
    # the device times the trial by the POSE timestamps (whole microseconds), float32 out
    assert reached_at == pytest.approx(result["completion_s"], abs=2e-6)
    assert progress.entry_t_s == pytest.approx(reached_at - progress.held_s)
    assert progress.held_s == pytest.approx(scene.hold_s, abs=1.0 / 240 + 1e-6)
