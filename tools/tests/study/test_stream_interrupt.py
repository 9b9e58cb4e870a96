"""Ctrl-C (a real SIGINT) during `graspguide stream` against the simulated device: STOP is
sent, and the last thing the operator sees -- the panel on a terminal, the last plain
line otherwise -- says the trial stopped and the motors are off, as the device confirmed
(its ACK to STOP and its state)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pexpect
from conftest import REPO_ROOT

SCENE3 = os.path.join(REPO_ROOT, "tools", "examples", "scene_paper_3.toml")
ARGS = ["stream", "--port", "sim", "--scene", SCENE3, "--wrench", "0.3,-1.2,-0.8"]
ARGS += ["--source", "synthetic:rate=100,duration=30"]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def _env() -> dict[str, str]:
    env = dict(os.environ, TERM="xterm-256color", COLUMNS="120", LINES="40")
    env.pop("PYTHONPATH", None)
    return env


def test_ctrl_c_off_a_terminal_ends_with_a_stopped_motors_off_line(tmp_path):
    p = subprocess.Popen(
        [sys.executable, "-m", "graspguide", *ARGS],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
        cwd=tmp_path,
    )
    try:
        first = p.stdout.readline()
        assert "state=running" in first, first  # streaming in real time
        time.sleep(0.5)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=15)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130, (p.returncode, err)
    last = out.strip().splitlines()[-1]
    assert "state=stopped" in last, out
    assert "motors off" in last and "STOP acknowledged" in last, last
    assert "device stopped" in last, last


def test_ctrl_c_in_a_terminal_leaves_the_panel_stopped_with_the_motors_off(tmp_path):
    child = pexpect.spawn(
        sys.executable,
        ["-m", "graspguide", *ARGS],
        env=_env(),
        cwd=str(tmp_path),
        dimensions=(40, 120),
        encoding="utf-8",
        timeout=30,
    )
    try:
        child.expect("running")
        time.sleep(0.5)
        child.kill(signal.SIGINT)
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert child.exitstatus == 130, (child.exitstatus, child.signalstatus)
    text = ANSI.sub("", child.before or "")
    # the last panel drawn: its state row and its motors row
    states = re.findall(r"state\s*│?\s*(\w+)", text)
    assert states and states[-1] == "stopped", states[-5:]
    motors = re.findall(r"motors\s*│?\s*([^│\n]+)", text)
    assert motors and "off" in motors[-1] and "STOP acknowledged" in motors[-1], motors[-3:]
    # the fingers' rows of that last panel say off, not the last cue as if still felt
    last_panel = text[[m.start() for m in re.finditer(r"state\s*│?\s*stopped", text)][-1] :]
    for finger in ("thumb", "index", "middle"):
        row = re.findall(finger + r"\s*│?\s*([^│\n]+)", last_panel)
        assert row and row[-1].strip().startswith("0 (off"), (finger, row[-1:])
