"""End to end against the simulated device over a real pseudo-terminal (src/sim, built by
`pio run -e sim`; tools/bootstrap.sh builds it), and -- with `pytest --port PATH` -- the
hardware subset against a real board.

Figures measured here (sim start time, frames/s, watchdog latency from the motor trace,
kill latency, agreement counts core-float vs device) are printed in the
"device measurements" section at the end of the pytest run.

Times: the simulated device's real clock and Python's time.monotonic_ns() are both
CLOCK_MONOTONIC, so host times and the trace's device_time_us compare directly (both in
microseconds wrapped to u32).
"""

from __future__ import annotations

import csv
import json
import math
import os
import select
import signal
import statistics
import subprocess
import sys
import time

import numpy as np
import pytest
from bad_requests import BAD_CASES, GOOD_LINE
from conftest import TOOLS_DIR
from known_answer_requests import load_cases, request_lines

from graspguide.core import scene_generators as scenes
from graspguide.core import solver
from graspguide.devices import registry
from graspguide.devices import sim as gsim
from graspguide.link import client as gd
from graspguide.link import codec as framing
from graspguide.link import messages as m
from graspguide.link import transport as gt

_TOOLS = TOOLS_DIR
_ROOT = os.path.dirname(_TOOLS)
EXAMPLES = os.path.join(_TOOLS, "examples", "solve_requests.jsonl")
CLI = [sys.executable, "-m", "graspguide"]

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
WRENCH = [0.3, -1.2, -0.8, 0, 0, 0]
WATCHDOG_MS = m.POSE_WATCHDOG_MS
SLACK_MS = 20
U32 = 1 << 32


def _env():
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


def pipelined(client, poses, window):
    """POSEs sent ``window`` at a time (pose_batch) until the trial ends: the TELEMETRY
    answers in order and the round trips per second. After the POSE that ended a trial,
    the rest of its batch must be refused with not_allowed_in_state, and no more are sent."""
    telemetry = []
    t0 = time.perf_counter()
    poses = list(poses)
    for start in range(0, len(poses), window):
        answers = client.pose_batch(poses[start : start + window])
        tel = [a for a in answers if isinstance(a, m.Telemetry)]
        assert answers[: len(tel)] == tel  # only a trial's end is followed by refusals
        assert all(a.code == m.ErrorCode.NOT_ALLOWED_IN_STATE for a in answers[len(tel) :])
        telemetry += tel
        if len(tel) < len(answers):
            break
    return telemetry, len(telemetry) / (time.perf_counter() - t0)


def us_after(later: int, earlier: int) -> int:
    """later - earlier for u32 microsecond clocks (either may have wrapped)."""
    d = (later - earlier) % U32
    return d - U32 if d >= U32 // 2 else d


def read_trace(path):
    """[(device_time_us, (pwm0..pwm3))] of a --trace CSV."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert rows and rows[0] == ["device_time_us", "pwm0", "pwm1", "pwm2", "pwm3"], rows[:1]
    return [(int(r[0]), tuple(int(x) for x in r[1:])) for r in rows[1:]]


def last_on_then_off(trace):
    """(time of the last motor change with some motor on, time of the all-off change
    that follows it)."""
    for i in range(len(trace) - 1, 0, -1):
        if any(trace[i - 1][1]) and not any(trace[i][1]):
            return trace[i - 1][0], trace[i][0]
    raise AssertionError(f"no on -> off change in the trace: {trace[-5:]}")


def aligned_quaternion(contacts, wrench, **kw):
    """A hand orientation with zero guidance error: the force direction f (hand frame)
    probed through alpha = |R f - g| / 2 * 185 for three orientations, then rotated onto
    g = (0, 0, -1)."""
    s = math.sqrt(0.5)

    def fz(q):  # z of R f, from |R f - g|^2 = 2 + 2 (R f)_z
        d = 2 * solver.solve(contacts, wrench, orientation=q, **kw)["alpha"] / solver.PWM_SPAN
        return (d * d - 2) / 2

    f = np.array([fz([s, 0, -s, 0]), fz([s, s, 0, 0]), fz([1, 0, 0, 0])])
    f /= np.linalg.norm(f)
    axis = np.cross(f, [0, 0, -1.0])
    angle = math.atan2(np.linalg.norm(axis), -f[2])
    q = [math.cos(angle / 2)] + list(math.sin(angle / 2) * axis / np.linalg.norm(axis))
    assert solver.solve(contacts, wrench, orientation=q, **kw)["error_deg"] < 0.01
    return q


def two_pwm_orientations(contacts, wrench, mode="V"):
    """Two orientations whose PWM differ (mode V), so every pose changes the motors and
    shows in the trace."""
    qa, qb = [1.0, 0, 0, 0], [0.9394, 0.1125, 0.2250, -0.2312]
    pa = solver.solve(contacts, wrench, mode=mode, orientation=qa, scalar="float")["pwm"]
    pb = solver.solve(contacts, wrench, mode=mode, orientation=qb, scalar="float")["pwm"]
    assert pa != pb and any(pa) and any(pb)
    return qa, qb


# --------------------------------------------------------------------------------------
# Fixtures
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def vsim():
    """One simulated device in virtual time for the module, and a client."""
    with gsim.SimulatedDevice(virtual_clock=True) as sim:
        client = gd.DeviceClient(sim, timeout=2.0)
        client.hello()
        yield client


@pytest.fixture
def client(vsim):
    vsim.stop()
    vsim.drain()
    vsim.trial_results.clear()
    return vsim


# --------------------------------------------------------------------------------------
# Start, identity
# --------------------------------------------------------------------------------------
def test_sim_starts_in_well_under_a_second(report_figure):
    times = []
    for _ in range(5):
        with gsim.SimulatedDevice() as sim:
            times.append(sim.start_time_s)
            assert sim.alive() and sim.pty_path.startswith("/dev/")
        assert sim.exit_code == 0  # SIGTERM: motors off, clean exit
    report_figure(
        "sim start (spawn -> pty path)",
        f"median {1e3 * statistics.median(times):.1f} ms, max "
        f"{1e3 * max(times):.1f} ms over {len(times)} starts",
    )
    assert max(times) < 0.5, times


def test_hello_identity(client):
    info = client.hello()
    assert info.protocol_version == m.PROTOCOL_VERSION
    assert info.board == "sim-posix"
    assert info.scalar == 4 and info.max_contacts == m.MAX_CONTACTS
    assert len(info.firmware_version) == 3
    st = client.status()
    assert st.state in (m.DeviceState.IDLE, m.DeviceState.STOPPED)


def test_open_port_sim_is_a_transport():
    with registry.open_port("sim") as t:
        assert isinstance(t, gt.Transport) and t.alive()
        assert gd.DeviceClient(t).hello().board == "sim-posix"
    assert not t.alive()


# --------------------------------------------------------------------------------------
# Telemetry PWM == the core in float
# --------------------------------------------------------------------------------------
def test_random_scenes_stream_matches_core_float(client, report_figure):
    rng = np.random.default_rng(20261122)
    counts = {"poses": 0, "exact": 0, "off_by_1": 0, "worse": 0, "errors_agreed": 0, "scenes": 0}
    worse = []
    t = 0
    policies, constraints = ("F", "Fperp"), ("paper", "normal", "none")
    base = scenes.random_scenes(7, 3, 30) + scenes.random_scenes(7, 4, 30)
    for i, scene in enumerate(base):
        for mode in ("C", "V"):
            kw = dict(
                policy=policies[i % 2],
                mode=mode,
                constraints=constraints[i % 3],
                y_axis=scene["y_axis"],
            )
            counts["scenes"] += 1
            client.stop()
            try:
                client.set_scene(scene["contacts"], **kw)
                client.start_trial(i, scene["wrench"])
            except gd.DeviceError as e:
                ref = solver.solve(scene["contacts"], scene["wrench"], scalar="float", **kw)
                assert e.code_name == ref["status"], (scene["name"], str(e))
                counts["errors_agreed"] += 1
                continue
            poses = []
            for j in range(10):
                q = scenes.random_quaternion(rng) if j else scene["orientation"]
                moved = None
                if j >= 8:  # POSE with moved contacts: the grasp part runs again
                    moved = (
                        np.asarray(scene["contacts"]) + rng.uniform(-0.003, 0.003, (scene["k"], 3))
                    ).tolist()
                t += 10_000
                poses.append((t, list(q), moved))
            # Eight pipelined, then the two with contacts (the generic path) one at a time.
            telemetry = client.pose_batch([(t, q) for t, q, _ in poses[:8]])
            telemetry += [client.pose(t, q, contacts=c) for t, q, c in poses[8:]]
            assert [type(a) for a in telemetry] == [m.Telemetry] * len(poses)
            assert not client.trial_results
            for (_, quat, moved), tel in zip(poses, telemetry):
                contacts = moved if moved is not None else scene["contacts"]
                ref = solver.solve(
                    contacts, scene["wrench"], orientation=quat, scalar="float", **kw
                )
                status = tel.solver_status.name.lower()
                assert status == ref["status"], (scene["name"], status, ref["status"])
                counts["poses"] += 1
                if status != "ok":
                    counts["errors_agreed"] += 1
                    continue
                if moved is not None:
                    assert tel.flags & m.TELEMETRY_FLAG_GRASP_RECOMPUTED
                got = list(tel.pwm[: scene["k"]])
                diff = max(abs(a - b) for a, b in zip(got, ref["pwm"]))
                key = "exact" if diff == 0 else "off_by_1" if diff == 1 else "worse"
                counts[key] += 1
                if diff > 1:
                    worse.append((scene["name"], mode, got, ref["pwm"]))
                assert tel.constraints_used.name.lower() == ref["constraints_used"]
                assert tel.error_deg == pytest.approx(ref["error_deg"], abs=1e-3)
                assert tel.alpha == pytest.approx(ref["alpha"], abs=1e-3)
    client.stop()
    report_figure(
        "random scenes: device PWM vs core float",
        f"{counts['scenes']} scene x mode runs, {counts['poses']} poses: "
        f"{counts['exact']} exact, {counts['off_by_1']} off by 1, "
        f"{counts['worse']} worse; {counts['errors_agreed']} errors with the "
        "same status",
    )
    assert counts["scenes"] >= 100 and counts["exact"] >= 0.99 * counts["poses"]
    assert not worse, worse


# --------------------------------------------------------------------------------------
# Trials in virtual time
# --------------------------------------------------------------------------------------
def test_failing_trial_runs_90_s_in_virtual_time(client, report_figure):
    client.set_scene(HAND3)  # threshold 3 deg, hold 0.5 s, timeout 90 s
    client.start_trial(41, WRENCH)
    period_us = 10_000
    t0 = time.perf_counter()
    telemetry, _ = pipelined(
        client, ((i * period_us, (1.0, 0, 0, 0)) for i in range(10_000)), window=32
    )  # identity: 57 deg off, never succeeds
    wall = time.perf_counter() - t0
    r = client.wait_trial_result(timeout=1.0)
    assert r.trial_id == 41 and not client.trial_results
    assert r.success is False and r.completion_s == 90.0 and r.first_entry_s == -1.0
    assert r.final_error_deg == pytest.approx(57.1, abs=0.1)
    assert len(telemetry) == 9001  # t = 0 .. 90 s
    assert telemetry[-1].pwm == (0, 0, 0, 0)  # the pose that ended it: motors off
    assert client.status().state is m.DeviceState.SCENE_SET
    report_figure(
        "90 s failing trial (virtual clock)",
        f"{wall:.2f} s wall for {len(telemetry)} poses, reported {r.completion_s} s",
    )
    assert wall < 5.0


def test_succeeding_trial_reports_the_hold(client, report_figure):
    q = aligned_quaternion(HAND3, WRENCH)
    hold = 0.5
    client.set_scene(HAND3, hold_s=hold)
    client.start_trial(42, WRENCH)
    telemetry, _ = pipelined(client, ((i * 10_000, q) for i in range(1000)), window=16)
    r = client.wait_trial_result(timeout=1.0)
    assert r.success is True and r.trial_id == 42 and not client.trial_results
    assert r.first_entry_s == 0.0
    assert abs(r.completion_s - hold) <= 0.0101, r  # within one pose period
    assert r.final_error_deg < 0.01
    assert 50 <= len(telemetry) <= 52
    report_figure(
        "succeeding trial",
        f"completion {r.completion_s:.3f} s for a hold of {hold} s (poses every 10 ms)",
    )


def test_trial_result_after_single_poses_is_queued(client):
    client.set_scene(HAND3, hold_s=0.05)
    client.start_trial(43, WRENCH)
    q = aligned_quaternion(HAND3, WRENCH)
    for i in range(10):
        tel = client.pose(i * 10_000, q)
        if client.trial_results:  # came right behind this TELEMETRY
            break
    assert i == 5 and tel.pwm == (0, 0, 0, 0)  # 0.05 s after the first pose: ended, off
    r = client.wait_trial_result(timeout=1.0)
    assert r.success and r.trial_id == 43 and r.completion_s == pytest.approx(0.05)
    assert not client.trial_results


def test_frames_per_second(client, report_figure):
    client.set_scene(HAND3, mode="V", timeout_s=600)  # the poses span 35 s
    client.start_trial(44, WRENCH)
    n = 4000
    rng = np.random.default_rng(3)
    quats = [list(scenes.random_quaternion(rng)) for _ in range(64)]
    rates = {}
    for window in (1, 32):
        base = 1_000_000 * window
        telemetry, rates[window] = pipelined(
            client, ((base + i * 1000, quats[i % 64]) for i in range(n)), window
        )
        assert [t.host_time_us for t in telemetry] == [base + i * 1000 for i in range(n)]
    client.stop()
    report_figure(
        "POSE -> TELEMETRY round trips over the pty (virtual clock)",
        f"{rates[32]:.0f} frames/s pipelined (batches of 32), {rates[1]:.0f} frames/s one at a "
        "time",
    )
    assert rates[32] > 1000


# --------------------------------------------------------------------------------------
# Watchdog, host death, STOP: real time, read from the motor trace
# --------------------------------------------------------------------------------------
def _start_rendering(client, qa, qb, n, period_s=0.01):
    client.stop()
    client.set_scene(HAND3, mode="V")
    client.start_trial(7, WRENCH)
    last = None
    for i in range(n):
        due = time.monotonic() + period_s
        last = gd.host_time_us()
        tel = client.pose(last, (qa, qb)[i % 2])
        assert any(tel.pwm), tel
        time.sleep(max(0.0, due - time.monotonic()))
    return last


def test_stale_stream_turns_motors_off_within_the_watchdog(tmp_path, report_figure):
    trace = tmp_path / "motors.csv"
    qa, qb = two_pwm_orientations(HAND3, WRENCH)
    with gsim.SimulatedDevice(trace=str(trace)) as sim:
        c = gd.DeviceClient(sim)
        stale0 = c.status().stale_events
        last_sent = _start_rendering(c, qa, qb, 30)
        time.sleep((WATCHDOG_MS + 250) / 1000)
        st = c.status()
        assert st.stale_events == stale0 + 1 and st.state is m.DeviceState.TRIAL_RUNNING
    last_pose, off = last_on_then_off(read_trace(trace))
    latency_ms = us_after(off, last_pose) / 1000
    host_ms = us_after(off, last_sent) / 1000
    report_figure(
        "watchdog: last pose -> motors off (trace)",
        f"{latency_ms:.2f} ms (watchdog {WATCHDOG_MS} ms; {host_ms:.2f} ms from the host's send)",
    )
    assert WATCHDOG_MS - 1 <= latency_ms <= WATCHDOG_MS + SLACK_MS


CHILD = r"""
import sys, time
from graspguide.link.client import DeviceClient, host_time_us
from graspguide.link.transport import SerialTransport
c = DeviceClient(SerialTransport(sys.argv[1]))
qs = [[1.0, 0, 0, 0], [0.9394, 0.1125, 0.2250, -0.2312]]
c.stop()
c.set_scene(%r, mode="V")
c.start_trial(8, %r)
i = 0
while True:
    due = time.monotonic() + 0.01
    c.pose(host_time_us(), qs[i %% 2])
    if i == 0:
        print("streaming", flush=True)
    i += 1
    time.sleep(max(0.0, due - time.monotonic()))
""" % (HAND3, WRENCH)


def test_killed_host_turns_motors_off_within_the_watchdog(tmp_path, report_figure):
    trace = tmp_path / "motors.csv"
    with gsim.SimulatedDevice(trace=str(trace)) as sim:
        child = subprocess.Popen(
            [sys.executable, "-c", CHILD, sim.pty_path],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=_env(),
        )
        try:
            ready, _, _ = select.select([child.stdout], [], [], 20)
            assert ready and child.stdout.readline() == b"streaming\n", child.stderr.read().decode()
            time.sleep(0.3)
            killed_at = gd.host_time_us()
            child.send_signal(signal.SIGKILL)
            child.wait(timeout=10)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
            child.stdout.close()
            child.stderr.close()
        time.sleep((WATCHDOG_MS + 250) / 1000)
        c = gd.DeviceClient(sim)
        st = c.status()  # the link still works for a new host
        assert st.stale_events >= 1
    last_pose, off = last_on_then_off(read_trace(trace))
    latency_ms = us_after(off, last_pose) / 1000
    kill_ms = us_after(off, killed_at) / 1000
    report_figure(
        "host SIGKILLed mid-stream -> motors off",
        f"{latency_ms:.2f} ms after its last pose, {kill_ms:.2f} ms after the kill",
    )
    assert latency_ms <= WATCHDOG_MS + SLACK_MS
    assert 0 < kill_ms <= WATCHDOG_MS + SLACK_MS


def test_stop_turns_motors_off_at_once(tmp_path, report_figure):
    trace = tmp_path / "motors.csv"
    qa, qb = two_pwm_orientations(HAND3, WRENCH)
    with gsim.SimulatedDevice(trace=str(trace)) as sim:
        c = gd.DeviceClient(sim)
        _start_rendering(c, qa, qb, 10)
        sent = gd.host_time_us()
        c.stop()
        acked = gd.host_time_us()
        assert c.status().state is m.DeviceState.STOPPED
        with pytest.raises(gd.DeviceError, match="not_allowed_in_state"):
            c.pose(gd.host_time_us(), qa)  # no trial: nothing is rendered
    _, off = last_on_then_off(read_trace(trace))
    after_ms = us_after(off, sent) / 1000
    report_figure(
        "STOP -> motors off (trace)",
        f"{after_ms:.3f} ms after the host sent STOP (ACK after "
        f"{us_after(acked, sent) / 1000:.3f} ms)",
    )
    assert 0 <= us_after(off, sent) and us_after(acked, off) >= 0  # off before the ACK
    assert after_ms < 20


@pytest.mark.parametrize("pause_s", [0.005, 0.1])
def test_stop_after_half_a_frame_and_a_pause_gets_through(tmp_path, pause_s):
    """A write cut short (Ctrl-C, a crash) leaves half a frame in the device's parser;
    the host's 0x00 before each frame ends it, so the STOP that follows is not merged
    with it and lost. 5 ms is shorter than the device's own partial-frame timeout
    (50 ms), so there the host's delimiter alone must save it; 100 ms checks the two
    rules together. Both are shorter than the watchdog: the motors are still on when
    STOP comes."""
    trace = tmp_path / "motors.csv"
    qa, qb = two_pwm_orientations(HAND3, WRENCH)
    with gsim.SimulatedDevice(trace=str(trace)) as sim:
        c = gd.DeviceClient(sim)
        _start_rendering(c, qa, qb, 10)
        bad0 = c.status().bad_frames
        wire = gd.encode_pose_fast(0x7777, gd.host_time_us(), qb)
        sim.write(wire[: len(wire) // 2])  # raw: no delimiter after it
        time.sleep(pause_s)
        sent = gd.host_time_us()
        c.stop(timeout=0.5)  # ACKed (a lost STOP times out)
        st = c.status()
        assert st.state is m.DeviceState.STOPPED
        assert st.bad_frames - bad0 <= 1  # the half frame at most
        with pytest.raises(gd.DeviceError, match="not_allowed_in_state"):
            c.pose(gd.host_time_us(), qa)  # no trial: nothing is rendered
    rows = read_trace(trace)
    _, off = last_on_then_off(rows)
    assert not any(rows[-1][1]) and us_after(off, sent) >= 0  # off, and not before STOP


# --------------------------------------------------------------------------------------
# Bad bytes on the line
# --------------------------------------------------------------------------------------
def test_corrupted_bytes_are_counted_and_the_link_recovers(client):
    before = client.status()
    good = framing.encode_message(m.Hello(), 0x1234)
    bad_crc = bytearray(good)
    bad_crc[-3] ^= 0x01 if bad_crc[-3] != 0x01 else 0x03  # a data byte, never 0x00
    scene = framing.encode_message(m.SetScene(contacts=HAND3 + [[0.0, 0.045, 0.0]]), 0x4321)
    noise = bytes(b % 255 + 1 for b in np.random.default_rng(5).integers(0, 255, 40))
    garbage = [
        noise + b"\x00",  # not a frame (COBS or CRC)
        bytes(bad_crc),  # CRC mismatch
        b"\x05" * 300 + b"\x00",  # too long
        scene[:40] + b"\x00",
    ]  # a frame cut short
    for chunk in garbage:
        client.transport.write(chunk)
        assert client.hello().board == "sim-posix"  # answered right after each
    after = client.status()
    assert after.bad_frames - before.bad_frames == len(garbage)
    assert after.frames_received - before.frames_received == len(garbage) + 1
    # Garbage and a request in one write: the request is still answered.
    client.transport.write(noise + b"\x00")
    assert client.status().bad_frames == after.bad_frames + 1
    assert client.host_bad_frames == 0  # nothing bad came back


def test_refusals_map_to_device_errors(client):
    with pytest.raises(gd.DeviceError) as info:
        client.pose(0, (1, 0, 0, 0))
    assert info.value.code in (m.ErrorCode.NO_SCENE, m.ErrorCode.NOT_ALLOWED_IN_STATE)
    with pytest.raises(gd.DeviceError) as info:
        client.set_scene([HAND3[0]] * 3)
    assert info.value.code is m.ErrorCode.COINCIDENT_CONTACTS
    assert "coincide" in str(info.value)
    client.set_scene(HAND3)
    client.start_trial(1, WRENCH)
    with pytest.raises(gd.DeviceError, match="trial_running: send STOP first") as info:
        client.set_motors([100, 0, 0, 0])
    assert info.value.code_name == "not_allowed_in_state"
    with pytest.raises(gd.DeviceError) as info:
        client.start_trial(2, WRENCH)
    assert info.value.detail == m.DeviceState.TRIAL_RUNNING
    client.stop()
    with pytest.raises(gd.DeviceError, match="zero_wrench"):
        client.start_trial(3, [0] * 6)
    client.set_motors([10, 20, 30, 40])
    assert client.status().last_error is m.ErrorCode.ZERO_WRENCH


# --------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------
def run_cli(args, data=b"", timeout=120):
    return subprocess.run(
        CLI + list(args), input=data, capture_output=True, timeout=timeout, env=_env(), cwd=_ROOT
    )


def _solve(lines, *args):
    proc = run_cli(["solve", *args], "".join(ln + "\n" for ln in lines).encode())
    assert proc.returncode == 0, proc.stderr.decode()
    out = [json.loads(x) for x in proc.stdout.decode().splitlines()]
    assert len(out) == len(lines)
    return out


DEVICE_KEYS = ["ok", "pwm", "constraints_used", "error_deg", "iterations", "alpha"]


def _agree(core, dev):
    """Problems of a device answer against the core-float answer (empty: agree)."""
    if core["ok"] != dev["ok"]:
        return [f"ok {dev['ok']} != core {core['ok']} ({core.get('error') or dev.get('error')})"]
    if not core["ok"]:
        return (
            []
            if (core["error"], core["message"]) == (dev["error"], dev["message"])
            else [f"error {dev['error']} != core {core['error']}"]
        )
    problems = []
    if list(dev) != DEVICE_KEYS:
        problems.append(f"keys {list(dev)}")
    if dev["pwm"] != core["pwm"]:
        problems.append(f"pwm {dev['pwm']} != {core['pwm']}")
    if dev["constraints_used"] != core["constraints_used"]:
        problems.append("constraints_used")
    if not abs(dev["error_deg"] - core["error_deg"]) <= 1e-3:
        problems.append(f"error_deg {dev['error_deg']} vs {core['error_deg']}")
    if dev["iterations"] != core["iterations"]:
        problems.append(f"iterations {dev['iterations']} != {core['iterations']}")
    return problems


def test_cli_device_engine_agrees_on_the_examples():
    with open(EXAMPLES, encoding="utf-8") as f:
        lines = [ln.rstrip("\n") for ln in f if ln.strip()]
    core = _solve(lines, "--scalar", "float")
    dev = _solve(lines, "--engine", "device", "--port", "sim")
    for line, c, d in zip(lines, core, dev):
        assert not _agree(c, d), (line, c, d)
    assert sum(d["ok"] for d in dev) == len(lines) - 1  # the misspelt field


def test_cli_device_engine_agrees_on_the_known_answers(report_figure):
    cases = load_cases()
    lines = request_lines(cases)
    core = _solve(lines, "--scalar", "float")
    dev = _solve(lines, "--engine", "device", "--port", "sim")
    ok_cases = agree_ok = both_refused = 0
    err_cases = agree_err = 0
    ok_problems, order_diffs, err_problems = [], [], []
    for case, c, d in zip(cases, core, dev):
        problems = _agree(c, d)
        if case["expect"]["status"] == "ok":
            ok_cases += 1
            if problems:
                ok_problems.append((case["name"], problems))
            elif c["ok"]:
                agree_ok += 1
            else:
                both_refused += 1  # float refuses contacts it cannot resolve, both sides
        else:
            err_cases += 1
            if not problems:
                agree_err += 1
            elif case["name"].startswith("order_"):
                # Several faults at once: the device checks per message (SET_SCENE, then
                # START_TRIAL, then POSE), the core's one-shot solve in one fixed order.
                order_diffs.append(f"{case['name']}: core {c['error']}, device {d['error']}")
            else:
                err_problems.append((case["name"], problems))
    report_figure(
        "known answers: graspguide solve device vs core float",
        f"{ok_cases} ok cases: {agree_ok} agree, {both_refused} refused by both "
        f"(imprecise_contacts), {len(ok_problems)} differ; {err_cases} error cases: "
        f"{agree_err} same code, {len(order_diffs)} multi-fault cases differ by the "
        f"order of checks ({'; '.join(order_diffs)})",
    )
    assert ok_cases == sum(c["expect"]["status"] == "ok" for c in cases) and ok_cases > 400
    assert agree_ok + both_refused == ok_cases, ok_problems[:5]
    assert both_refused <= 6
    assert not err_problems, err_problems


def test_cli_device_engine_answers_bad_requests_like_the_core():
    """Every bad-input case of bad_requests.py (one fault each): the same code and message
    from the device engine as from the core, and the stream goes on."""
    data = b"".join(line + b"\n" + GOOD_LINE.encode() + b"\n" for _, line, _, _ in BAD_CASES)
    answers = {}
    for engine in (["--scalar", "float"], ["--engine", "device", "--port", "sim"]):
        proc = run_cli(["solve", *engine], data)
        assert proc.returncode == 0, proc.stderr.decode()
        answers[engine[1]] = [json.loads(x) for x in proc.stdout.decode().splitlines()]
    core, dev = answers["float"], answers["device"]
    assert len(core) == len(dev) == 2 * len(BAD_CASES)
    for i, (name, _, code, _) in enumerate(BAD_CASES):
        assert dev[2 * i] == core[2 * i], name
        assert dev[2 * i]["error"] == code, name
        assert dev[2 * i + 1]["ok"] is True and not _agree(core[2 * i + 1], dev[2 * i + 1])


def test_cli_solve_device_usage_errors():
    for args in (
        ["solve", "--engine", "device"],
        ["solve", "--port", "sim"],
        ["solve", "--engine", "device", "--port", "sim", "--scalar", "double"],
        ["solve", "--engine", "device", "--port", "sim", "--decomposition", "svd"],
        ["solve", "--engine", "device", "--port", "sim", "--max-iterations", "3"],
        ["info"],
    ):
        proc = run_cli(args)
        assert proc.returncode == 2, args
        assert proc.stdout == b"" and b"--" in proc.stderr


def test_cli_missing_port_and_missing_sim_say_what_to_do():
    proc = run_cli(["info", "--port", "/dev/graspguide-no-such-port"])
    assert proc.returncode == 1 and b"graspguide ports" in proc.stderr
    env = _env()
    env[gsim.SIM_ENV] = "/nonexistent/program"
    proc = subprocess.run(
        CLI + ["info", "--port", "sim"], capture_output=True, env=env, cwd=_ROOT, timeout=60
    )
    assert proc.returncode == 1 and b"pio run -e sim" in proc.stderr


def test_cli_info_and_ports():
    proc = run_cli(["info", "--port", "sim"])
    assert proc.returncode == 0, proc.stderr.decode()
    text = proc.stdout.decode()
    for word in (
        "board:",
        "sim-posix",
        "protocol:",
        "scalar:",
        "float",
        "state:",
        "bad frames:",
        "stale events:",
    ):
        assert word in text, word
    proc = run_cli(["info", "--port", "sim", "--json"])
    data = json.loads(proc.stdout)
    assert data["board"] == "sim-posix" and data["protocol_version"] == m.PROTOCOL_VERSION
    assert data["bad_frames"] == 0 and data["state"] == "idle"
    proc = run_cli(["ports"])
    assert proc.returncode == 0 and any(
        ln.split()[0] == "sim" for ln in proc.stdout.decode().splitlines()
    )
    proc = run_cli(["ports", "--json"])
    rows = [json.loads(x) for x in proc.stdout.decode().splitlines()]
    by_device = {r["device"]: r for r in rows}
    assert by_device["sim"]["hwid"].endswith("program")
    assert rows[-1]["device"] == "promini-sim" and "description" in rows[-1]


def test_cli_link_failure_mid_stream_keeps_earlier_answers():
    """The device dies while `graspguide solve` runs: the answers so far are out, the
    next request gets a link_error line, and the exit status is 1."""
    good = json.dumps({"contacts": HAND3, "wrench": WRENCH})
    sim = gsim.SimulatedDevice().start()
    proc = subprocess.Popen(
        CLI + ["solve", "--engine", "device", "--port", sim.pty_path],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=_env(),
        cwd=_ROOT,
    )
    try:
        proc.stdin.write(good.encode() + b"\n")
        proc.stdin.flush()
        ready, _, _ = select.select([proc.stdout], [], [], 30)
        assert ready
        assert json.loads(proc.stdout.readline())["ok"] is True
        sim.process.kill()
        sim.process.wait()
        out, err = proc.communicate((good + "\n" + good + "\n").encode(), timeout=30)
        lines = [json.loads(x) for x in out.decode().splitlines()]
        assert len(lines) == 1 and lines[0]["error"] == "link_error", lines
        assert proc.returncode == 1 and b"graspguide solve: error:" in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        sim.close()


# --------------------------------------------------------------------------------------
# Hardware subset: pytest --port /dev/ttyACM0 (skipped without it)
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def board(request, hardware_port):
    """A client on the --port board (the hardware_port fixture of conftest.py skips the
    test, saying why, when no --port was given)."""
    with registry.open_port(hardware_port, baudrate=request.config.getoption("--baud")) as t:
        c = gd.DeviceClient(t, timeout=2.0)
        c.hello()
        yield c
        c.stop()


def test_hw_hello(board):
    info = board.hello()
    assert info.protocol_version == m.PROTOCOL_VERSION
    assert info.max_contacts == m.MAX_CONTACTS and info.scalar in (4, 8)


def test_hw_poses_match_core_float(board):
    board.stop()
    rng = np.random.default_rng(9)
    for mode in ("C", "V"):
        board.set_scene(HAND3, mode=mode)
        board.start_trial(1, WRENCH)
        for _ in range(20):
            q = list(scenes.random_quaternion(rng))
            tel = board.pose(gd.host_time_us(), q, check=True)
            ref = solver.solve(HAND3, WRENCH, mode=mode, orientation=q, scalar="float")
            assert max(abs(a - b) for a, b in zip(tel.pwm[:3], ref["pwm"])) <= 1
        board.stop()


def test_hw_watchdog_and_stop(board):
    board.stop()
    stale0 = board.status().stale_events
    board.set_scene(HAND3)
    board.start_trial(2, WRENCH)
    board.pose(gd.host_time_us(), (1, 0, 0, 0))
    time.sleep((WATCHDOG_MS + 200) / 1000)
    assert board.status().stale_events == stale0 + 1
    board.stop()
    assert board.status().state is m.DeviceState.STOPPED


def test_hw_corrupted_bytes_recover(board):
    before = board.status().bad_frames
    board.transport.write(bytes(range(1, 60)) + b"\x00")
    assert board.hello().protocol_version == m.PROTOCOL_VERSION
    assert board.status().bad_frames == before + 1
