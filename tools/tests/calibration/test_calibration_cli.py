"""`graspguide calibrate` end to end: the virtual participant on --port sim, and the
operator's path through a REAL pseudo-terminal (pexpect) against a simulated device the
test holds, so that after the command has gone the device itself says what happened:
its motor trace (every change of duty, in device time) and its STATUS."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys

import pexpect
import pytest

from graspguide.calibration.calibration_file import read_calibration_file
from graspguide.calibration.session import CalibrationSettings, run_procedure
from graspguide.calibration.virtual_observer import VirtualObserver
from graspguide.core import reference
from graspguide.devices.sim import SimulatedDevice
from graspguide.link import messages as m
from graspguide.link.client import DeviceClient

CLI = [sys.executable, "-m", "graspguide", "calibrate"]
HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
WRENCH = [0.3, -1.2, -0.8, 0, 0, 0]
DETECT = re.compile(
    rb"(\w+) detection #\d+ \((catch trial, no stimulus|PWM (\d+))\): did the participant "
    rb"feel it\? \[y/n, q quits\] "
)
COMPARE = re.compile(
    rb"(\w+) matching #\d+ \(1: (\w+) PWM (\d+), 2: (\w+) PWM (\d+)\): which felt "
    rb"stronger\? \[1/2, q quits\] "
)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


def _trace(path) -> list[tuple[int, ...]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["device_time_us", "pwm0", "pwm1", "pwm2", "pwm3"]
    return [tuple(int(x) for x in r) for r in rows[1:]]


@pytest.fixture
def held_sim(tmp_path):
    """A simulated device with a motor trace; the command gets its pty path as --port."""
    trace = tmp_path / "motors.csv"
    with SimulatedDevice(trace=str(trace), start=True) as sim:
        yield sim, trace


def _spawn(args, tmp_path) -> pexpect.spawn:
    return pexpect.spawn(
        CLI[0], CLI[1:] + args, env=_env(), cwd=str(tmp_path), timeout=30, echo=False
    )


# ---- the virtual participant -----------------------------------------------------------
def test_virtual_participant_on_sim(tmp_path):
    """The whole procedure on the simulated device, answered by the virtual participant:
    SIMULATED everywhere, the file holds exactly what the same procedure gives without a
    device (same seeds), and a second run refuses to overwrite it without --force."""
    out = tmp_path / "study"
    args = [
        "--participant",
        "U3",
        "--port",
        "sim",
        "--out",
        str(out),
        "--source",
        "participant:seed=3",
    ]
    proc = subprocess.run(CLI + args, capture_output=True, text=True, env=_env(), timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "SIMULATED participant U3" in proc.stdout
    assert "SIMULATED: the virtual participant (seed 3) answers" in proc.stdout
    rec = read_calibration_file(str(out / "U3" / "calibration.json"))
    assert rec.simulated is True and rec.participant == "U3"
    assert rec.data["virtual_participant"]["seed"] == 3
    assert rec.data["device"]["board"] == "sim-posix"

    class NoDevice:
        def detection(self, finger, pwm):
            pass

        def pair(self, first, second):
            pass

    settings = CalibrationSettings(seed=3)  # the command's defaults, the same seed
    expected = run_procedure(settings, VirtualObserver(3), NoDevice())
    assert rec.calibration == expected.calibration
    assert [t["answer"] for t in rec.trials] == [t["answer"] for t in expected.trials]

    again = subprocess.run(CLI + args, capture_output=True, text=True, env=_env(), timeout=60)
    assert again.returncode == 2
    assert "calibration.json exists: add --force" in again.stderr
    forced = subprocess.run(
        CLI + args + ["--force", "--seed", "4"],
        capture_output=True,
        text=True,
        env=_env(),
        timeout=120,
    )
    assert forced.returncode == 0, forced.stderr
    assert read_calibration_file(str(out / "U3" / "calibration.json")).data["settings"]["seed"] == 4


def test_usage_errors(tmp_path):
    for extra, message in [
        (["--participant", "nobody"], "participant id 'nobody'"),
        (["--participant", "U1", "--fingers", "thumb,pinky"], "unknown finger 'pinky'"),
        (["--participant", "U1", "--reference", "palm"], "--reference palm: must be one of"),
        (["--participant", "U1", "--source", "replay:x.csv"], "use 'operator'"),
    ]:
        proc = subprocess.run(
            CLI + ["--port", "sim", "--out", str(tmp_path)] + extra,
            capture_output=True,
            text=True,
            env=_env(),
            timeout=60,
        )
        assert proc.returncode == 2, (extra, proc.stderr)
        assert message in proc.stderr
    assert not os.listdir(tmp_path)


# ---- the operator at a terminal ----------------------------------------------------------
def test_operator_bad_key_and_quit(tmp_path, held_sim):
    """y, a bad key (asked again), n, then q: exit 130, nothing written, the device
    stopped, its motors off, and every stimulus the terminal announced in its trace."""
    sim, trace = held_sim
    out = tmp_path / "study"
    child = _spawn(
        [
            "--participant",
            "U1",
            "--port",
            sim.pty_path,
            "--out",
            str(out),
            "--stimulus-s",
            "0.05",
            "--seed",
            "1",
            "--operator",
            "pty-test",
        ],
        tmp_path,
    )
    announced = []
    for answer in ("y", "x", "n", "q"):
        child.expect(DETECT)
        announced.append(child.match.group(3))
        child.sendline(answer)
        if answer == "x":
            child.expect(rb"'x'\? type y \(felt it\), n \(did not\) or q \(quit\)")
    child.expect(rb"the operator quit \(q\): aborted, motors off, nothing written")
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 130
    assert not (out / "U1").exists() or not os.listdir(out / "U1")
    # The prompt after "x" is the same trial asked again: 4 prompts, 3 stimuli shown.
    shown = [int(p) for p in announced[:1] + announced[2:] if p is not None]
    rows = _trace(trace)
    on = [r for r in rows if any(r[1:])]
    assert sorted({r[1] for r in on}) == sorted(set(shown))  # thumb's motor only
    assert rows[-1][1:] == (0, 0, 0, 0)
    client = DeviceClient(sim, timeout=2.0)
    status = client.status()
    # No scene was ever set, so STOP leaves it idle: the motors are off in that state.
    assert status.state in (m.DeviceState.IDLE, m.DeviceState.STOPPED)
    assert status.last_error is m.ErrorCode.OK
    assert status.stale_events == 0  # switched off by the host, not by the watchdog


def test_operator_ctrl_c_during_a_stimulus(tmp_path, held_sim):
    """Ctrl-C typed while a 5 s stimulus runs: the motors go off at once (long before the
    stimulus would end; by the host, not the watchdog), nothing written, exit 130."""
    sim, trace = held_sim
    out = tmp_path / "study"
    child = _spawn(
        [
            "--participant",
            "U1",
            "--port",
            sim.pty_path,
            "--out",
            str(out),
            "--stimulus-s",
            "5",
            "--seed",
            "2",
            "--catch-rate",
            "0",
        ],
        tmp_path,
    )
    child.expect(rb"q quits, nothing is written")
    import time

    for _ in range(100):  # wait for the stimulus to show in the trace
        rows = _trace(trace)
        if any(any(r[1:]) for r in rows):
            break
        time.sleep(0.05)
    time.sleep(0.5)
    child.sendintr()
    child.expect(rb"interrupted: motors off, nothing written")
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 130
    rows = _trace(trace)
    first_on = next(r for r in rows if any(r[1:]))
    off = next(r for r in rows if r[0] > first_on[0] and not any(r[1:]))
    assert (off[0] - first_on[0]) / 1e6 < 3.0
    assert rows[-1][1:] == (0, 0, 0, 0)
    assert not (out / "U1").exists() or not os.listdir(out / "U1")
    status = DeviceClient(sim, timeout=2.0).status()
    assert status.stale_events == 0


def _operator_answers(child, floors, magnitudes):
    """Answer like a person whose thresholds are ``floors`` and whose perceived magnitude
    above them grows with ``magnitudes``: until the command ends."""
    while True:
        i = child.expect([DETECT, COMPARE, pexpect.EOF])
        if i == 2:
            return
        if i == 0:
            finger, pwm = child.match.group(1).decode(), child.match.group(3)
            felt = pwm is not None and int(pwm) >= floors[finger]
            child.sendline("y" if felt else "n")
        else:
            g = child.match.groups()
            a = magnitudes[g[1].decode()] * (int(g[2]) - floors[g[1].decode()])
            b = magnitudes[g[3].decode()] * (int(g[4]) - floors[g[3].decode()])
            child.sendline("1" if a >= b else "2")


def test_operator_full_run_and_apply(tmp_path, held_sim):
    """A complete calibration typed at the terminal by a deterministic 'person', then
    --apply: the stored floors are where that person starts to feel, the gain the one
    that makes their thumb feel like their index, and the device's TELEMETRY PWM after
    the command is the float64 reference's mapping with that calibration."""
    sim, trace = held_sim
    out = tmp_path / "study"
    floors = {"thumb": 100, "index": 90}
    magnitudes = {"thumb": 1.25, "index": 1.0}
    ref_pwm = 162
    child = _spawn(
        [
            "--participant",
            "U2",
            "--port",
            sim.pty_path,
            "--out",
            str(out),
            "--fingers",
            "thumb,index",
            "--stimulus-s",
            "0.02",
            "--gap-s",
            "0.02",
            "--reversals",
            "6",
            "--seed",
            "5",
            "--apply",
            "--no-headroom",  # the matched gain itself (headroom: test_calibration_procedure)
        ],
        tmp_path,
    )
    _operator_answers(child, floors, magnitudes)
    child.close()
    assert child.exitstatus == 0, child.before
    rec = read_calibration_file(str(out / "U2" / "calibration.json"))
    assert rec.simulated is False and rec.data["virtual_participant"] is None
    cal = rec.calibration
    # A yes from the floor up: the 1-up-2-down track turns at floor and floor - 2.
    assert floors["thumb"] - 2 <= cal.pwm_floor[0] <= floors["thumb"]
    assert floors["index"] - 2 <= cal.pwm_floor[1] <= floors["index"]
    pse = floors["thumb"] + magnitudes["index"] * (ref_pwm - floors["index"]) / magnitudes["thumb"]
    want_gain = (pse - cal.pwm_floor[0]) / (ref_pwm - cal.pwm_floor[1])
    assert cal.gain[0] == pytest.approx(want_gain, rel=0.03)
    assert cal.gain[1] == 1.0 and cal.pwm_floor[2:] == (70, 70)
    assert rec.false_alarm_rate == 0.0
    assert _trace(trace)[-1][1:] == (0, 0, 0, 0)
    # --apply reached the device: a pose's PWM follows the stored calibration.
    client = DeviceClient(sim, timeout=2.0)
    client.set_scene(HAND3)
    client.start_trial(1, WRENCH)
    q = (0.9, 0.3, -0.2, 0.1)
    tel = client.pose(quat=q)
    client.stop()
    want = reference.solve(HAND3, WRENCH, orientation=q, compute_margins=False)
    assert want["status"] == "ok"
    pwm = reference.pwm_from_levels(want["levels"], "C", want["alpha"], calibration=cal)
    assert max(abs(a - b) for a, b in zip(tel.pwm[:3], pwm)) <= 1, (tel.pwm, pwm)
    identity = reference.pwm_from_levels(want["levels"], "C", want["alpha"])
    assert pwm != identity  # the calibration changes what this pose renders


def test_file_lists_every_trial_typed(tmp_path, held_sim):
    """Every prompt answered is one trial in the file, in order, with its stimulus."""
    sim, _ = held_sim
    out = tmp_path / "study"
    floors = {"index": 95}
    child = _spawn(
        [
            "--participant",
            "U5",
            "--port",
            sim.pty_path,
            "--out",
            str(out),
            "--fingers",
            "index",
            "--stimulus-s",
            "0.02",
            "--reversals",
            "4",
            "--seed",
            "8",
        ],
        tmp_path,
    )
    prompts = []
    while True:
        i = child.expect([DETECT, pexpect.EOF])
        if i == 1:
            break
        pwm = child.match.group(3)
        prompts.append(0 if pwm is None else int(pwm))
        child.sendline("y" if pwm is not None and int(pwm) >= floors["index"] else "n")
    child.close()
    assert child.exitstatus == 0
    data = json.loads((out / "U5" / "calibration.json").read_text())
    assert [t["pwm"] for t in data["trials"]] == prompts
    assert data["trials"][0]["pwm"] == 150  # the staircase starts high
