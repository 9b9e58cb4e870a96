"""The simulated device's own safety rules, end to end over its pseudo-terminal: the
watchdog on a virtual clock (a host that stops sending POSEs turns the motors off, whatever
else it sends), a trial left running by a silent host ends, no request keeps the motors on
past the watchdog even with a 1 MiB store, an error during a host-less run's vibration
pattern keeps them off, and the simulator exits when the process that started it dies
(docs/protocol.md "Safety")."""

from __future__ import annotations

import csv
import dataclasses
import os
import signal
import subprocess
import sys
import time

import pytest
from conftest import REPO_ROOT

from graspguide.devices import sim as gsim
from graspguide.hostless import plan_upload as pu
from graspguide.link import client as gd
from graspguide.link import messages as m
from graspguide.protocol.study_protocol import load_protocol

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
WRENCH = [0.3, -1.2, -0.8, 0, 0, 0]
TILTED = (0.9394, 0.1125, 0.2250, -0.2312)  # far from aligned: the motors are on
WATCHDOG_MS = m.POSE_WATCHDOG_MS


def _rendering(client: gd.DeviceClient, **scene) -> float:
    """A trial with a few POSEs 10 ms apart in virtual time; returns the wall time of the
    last one."""
    client.stop()
    client.set_scene(HAND3, **scene)
    client.start_trial(3, WRENCH)
    for i in range(5):
        tel = client.pose(1_000_000 + 10_000 * i, TILTED)
        assert any(tel.pwm), tel
    return time.monotonic()


def test_virtual_clock_watchdog_fires_while_other_traffic_flows(report_figure):
    """Once, GET_STATUS or even idle 0x00 bytes kept the virtual clock's motors on forever."""
    with gsim.SimulatedDevice(virtual_clock=True) as sim:
        c = gd.DeviceClient(sim, timeout=2.0)
        stale0 = c.status().stale_events
        last_pose = _rendering(c)
        fired_after_ms = None
        while time.monotonic() - last_pose < 3.0:
            sim.write(b"\x00" * 8)  # idle line
            st = c.status()  # and requests that are not POSEs
            if st.stale_events > stale0:
                fired_after_ms = (time.monotonic() - last_pose) * 1000
                break
            time.sleep(0.005)
        assert fired_after_ms is not None, "no stale event in 3 s of non-POSE traffic"
        # The trial itself goes on: the next POSE drives the motors again.
        assert c.status().state is m.DeviceState.TRIAL_RUNNING
        assert any(c.pose(1_060_000, TILTED).pwm)
    report_figure(
        "virtual-clock watchdog: last POSE -> stale (wall, GET_STATUS flowing)",
        f"{fired_after_ms:.1f} ms (watchdog {WATCHDOG_MS} ms)",
    )
    assert WATCHDOG_MS <= fired_after_ms <= WATCHDOG_MS + 100


def test_virtual_clock_trial_of_a_silent_host_ends_in_real_time():
    """A host that stops sending POSEs mid-trial: the trial fails at its timeout once that
    much real time (plus the device's 1 s slack) has passed, with a TRIAL_RESULT."""
    with gsim.SimulatedDevice(virtual_clock=True) as sim:
        c = gd.DeviceClient(sim, timeout=2.0)
        last_pose = _rendering(c, timeout_s=1.0, hold_s=0.5)
        res = c.wait_trial_result(timeout=6.0)
        waited = time.monotonic() - last_pose
        assert res.trial_id == 3 and not res.success
        assert abs(res.completion_s - 1.0) < 1e-6
        assert 1.5 <= waited <= 4.0, waited  # 1 s timeout + 1 s slack, from the first POSE
        st = c.status()
        assert st.state is m.DeviceState.SCENE_SET


def test_a_host_that_stops_reading_loses_whole_answers_only():
    """The simulated device writes its answers in blocks; a host that stops reading loses
    whole frames (each one given up alone after the write timeout), never gets two frames
    run together, and is answered again once it reads."""
    with gsim.SimulatedDevice(virtual_clock=True, stale_ms=60_000) as sim:
        c = gd.DeviceClient(sim, timeout=2.0)
        c.set_scene(HAND3, timeout_s=1800.0)
        c.start_trial(3, WRENCH)
        fd = sim.serial_transport.serial.fileno()
        sent = []
        while len(sent) < 20_000:  # until the device stops reading too
            times = [10_000 * (len(sent) + i) for i in range(50)]
            wire = b"".join(gd.encode_pose_fast(i, t, TILTED) or b"" for i, t in enumerate(times))
            try:
                n = os.write(fd, b"\x00" + wire)
            except BlockingIOError:
                n = 0
            sent += times
            if n < len(wire) + 1:
                break
            time.sleep(0.005)
        time.sleep(0.5)  # the device gives up frames meanwhile
        c.drain(2.0)
        got = [t.host_time_us for t in c.telemetry_backlog]
        assert got and set(got) <= set(sent) and got == sorted(got) and len(got) < len(sent)
        assert c.device_frames_lost > 0  # the frames the device gave up ...
        assert c.host_bad_frames <= c.device_frames_lost  # ... at most one cut short each
        tel = c.pose(10_000 * len(sent) + 10_000, TILTED)  # answered again
        assert tel.host_time_us == 10_000 * len(sent) + 10_000


PARENT = r"""
import subprocess, sys
# A plain Popen: no PR_SET_PDEATHSIG, no new session. The simulator must notice by itself.
p = subprocess.Popen([sys.argv[1]], stdout=subprocess.PIPE, stdin=subprocess.DEVNULL)
line = p.stdout.readline()
print(p.pid, line.decode().strip(), flush=True)
sys.stdin.read()
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ", 1)[1][0] != "Z"
    except FileNotFoundError:
        return False


def test_simulator_exits_when_its_parent_is_killed(report_figure):
    """Once, 39 simulators piled up after their hosts were SIGKILLed."""
    binary = gsim.find_sim_binary(None)
    parent = subprocess.Popen(
        [sys.executable, "-c", PARENT, binary], stdin=subprocess.PIPE, stdout=subprocess.PIPE
    )
    try:
        first = parent.stdout.readline().decode().split()
        assert len(first) == 3 and first[1] == "GRASPGUIDE_SIM_PTY", first
        sim_pid = int(first[0])
        assert _alive(sim_pid)
        t0 = time.monotonic()
        parent.send_signal(signal.SIGKILL)
        parent.wait(timeout=10)
        while _alive(sim_pid) and time.monotonic() - t0 < 5:
            time.sleep(0.005)
        gone_ms = (time.monotonic() - t0) * 1000
        still = _alive(sim_pid)
        if still:
            os.kill(sim_pid, signal.SIGKILL)
        assert not still, "the simulator outlived its parent by 5 s"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        parent.stdout.close()
        parent.stdin.close()
    report_figure("simulator exit after its parent's SIGKILL", f"{gone_ms:.1f} ms")
    assert gone_ms < 1000


# --------------------------------------------------------------------------------------
# The host-less store: requests that block the loop, and errors during a run
# --------------------------------------------------------------------------------------
PAPER = os.path.join(REPO_ROOT, "protocols", "paper.toml")
BIG_STORE_BYTES = 1 << 20  # 1 MiB: room for the plan and about 14,000 records
U32 = 1 << 32
STORAGE_REQUESTS = ("PLAN_BEGIN", "PLAN_TRIAL", "PLAN_COMMIT", "LOG_ERASE")
ANSWER_TYPES = {
    "HELLO": m.HelloReply,
    "GET_STATUS": m.Status,
    "LOG_INFO_GET": m.LogInfo,
    "LOG_READ": m.LogRecord,
}


def _paper_plan(**changes) -> tuple[m.PlanBegin, list[m.PlanTrial]]:
    protocol = load_protocol(PAPER)
    planned = pu.planned_trials(protocol, "U1")
    begin, trials = pu.plan_messages(protocol, "U1", planned, simulated=True, rest_s=0.0)
    return dataclasses.replace(begin, **changes), trials


def _now_us() -> int:
    """The host's CLOCK_MONOTONIC in us on 32 bits: the simulated device's real-time clock
    (and so its motor trace) reads the same clock."""
    return (time.monotonic_ns() // 1000) % U32


def _trace_rows(path) -> list[tuple[int, tuple[int, ...]]]:
    with open(path, newline="") as f:
        return [(int(r[0]), tuple(int(v) for v in r[1:])) for r in list(csv.reader(f))[1:] if r]


def _motors_off_after(path, t0_us: int) -> int | None:
    """us from t0_us (device clock) to the first all-off row of the motor trace at or after
    it; None while the motors are still on."""
    for t_us, pwm in _trace_rows(path):
        dt = (t_us - t0_us) % U32
        if dt < U32 // 2 and not any(pwm):
            return dt
    return None


def _fill_log_with_copies(store, before: bytes) -> None:
    """Every slot of the results log a copy of the one record written since ``before``: the
    changed bytes are that slot (its magic first, its commit byte last)."""
    data = bytearray(store.read_bytes())
    changed = [i for i, (a, b) in enumerate(zip(before, data)) if a != b]
    first, last = changed[0], changed[-1]
    slot = bytes(data[first : last + 1])
    for at in range(first, len(data) - len(slot) + 1, len(slot)):
        data[at : at + len(slot)] = slot
    store.write_bytes(bytes(data))


def _one_hostless_record(c: gd.DeviceClient) -> None:
    """One trial of the stored plan run host-less in real time: no IMU samples, so it times
    out (the plan's timeout_s) and its record is stored; then STOP."""
    c.hostless_run()
    deadline = time.monotonic() + 10
    pressed = False
    while time.monotonic() < deadline:
        c.drain(0.02)
        events = [e.event for e in c.hostless_events]
        if m.RunEvent.READY in events and not pressed:
            c.sim_button(True)
            c.sim_button(False)
            pressed = True
        if m.RunEvent.TIMEOUT in events or m.RunEvent.SUCCESS in events:
            break
    c.stop()
    assert c.log_info().records == 1, [e.event for e in c.hostless_events]


@pytest.fixture(scope="module")
def full_big_store(tmp_path_factory):
    """A 1 MiB store (on the disk, as tmp_path is) holding the paper plan (0.5 s trials)
    and a log filled to capacity, so an erase, a commit and a read of the last record each
    do all the work they can."""
    d = tmp_path_factory.mktemp("bigstore")
    store = d / "big.store"
    args = ["--store", str(store), "--store-bytes", str(BIG_STORE_BYTES)]
    begin, trials = _paper_plan(timeout_s=0.5, hold_s=0.2)
    with gsim.SimulatedDevice(extra_args=args) as sim:
        c = gd.DeviceClient(sim, timeout=5.0)
        c.hello()
        c.upload_plan(begin, trials)
    before = store.read_bytes()
    with gsim.SimulatedDevice(extra_args=args) as sim:
        c = gd.DeviceClient(sim, timeout=5.0)
        c.hello()
        _one_hostless_record(c)
    _fill_log_with_copies(store, before)
    return store, args, begin, trials


def test_no_request_keeps_the_motors_on_past_the_watchdog_with_a_1mib_store(
    full_big_store, tmp_path, report_figure
):
    """Once, LOG_ERASE (every slot rewritten and synced) and PLAN_COMMIT were taken while a
    trial or SET_MOTORS drove the motors, and blocked the loop with them on: up to 7.5 s
    after the last POSE. Every request is sent right after a POSE (and the storage ones
    after SET_MOTORS too), and the motor trace says when they went off."""
    store, args, begin, trials = full_big_store
    trace = tmp_path / "motors.csv"
    with gsim.SimulatedDevice(trace=str(trace), extra_args=args) as sim:
        c = gd.DeviceClient(sim, timeout=30.0)
        c.hello()
        info = c.log_info()
        assert info.records == info.capacity > 10_000, info
        last = info.records - 1
        requests = {
            "nothing": None,
            "HELLO": m.Hello(protocol_version=m.PROTOCOL_VERSION),
            "GET_STATUS": m.GetStatus(),
            "SET_SCENE": m.SetScene(k=3, contacts=(*map(tuple, HAND3), (0.0, 0.0, 0.0))),
            "START_TRIAL": m.StartTrial(trial_id=4, wrench=tuple(WRENCH)),
            "SET_CALIBRATION": m.SetCalibration(),
            "SET_POSTURE": m.SetPosture(),
            "HOSTLESS_RUN": m.HostlessRun(),
            "LOG_INFO_GET": m.LogInfoGet(),
            "LOG_READ": m.LogRead(index=last),
            "SIM_IMU_SAMPLE": m.SimImuSample(accel_mps2=(0.0, 0.0, 9.81)),
            "SIM_BUTTON": m.SimButton(pressed=True),
            "PLAN_BEGIN": begin,
            "PLAN_TRIAL": trials[0],
            "PLAN_COMMIT": m.PlanCommit(trial_count=len(trials)),
            "LOG_ERASE": m.LogErase(key=m.LOG_ERASE_KEY),
        }

        def tracker() -> int:
            c.set_scene(HAND3, timeout_s=60.0)
            c.start_trial(3, WRENCH)
            t = 1_000_000
            for _ in range(3):
                t0 = _now_us()
                assert any(c.pose(t, TILTED).pwm)
                t += 10_000
            return t0

        def bench() -> int:
            t0 = _now_us()
            c.set_motors([200, 200, 200, 0])
            return t0

        on_ms: dict[str, float] = {}
        answers: dict[str, str] = {}
        for name, msg in requests.items():
            for how, motors_on in (("after POSE", tracker), ("after SET_MOTORS", bench)):
                if how == "after SET_MOTORS" and name not in STORAGE_REQUESTS:
                    continue
                c.stop()
                if name in ("PLAN_TRIAL", "PLAN_COMMIT"):  # an open upload: work for them
                    c._request(begin)
                    for t in trials:
                        c._request(t)
                t0 = motors_on()
                if msg is not None:
                    kind = ANSWER_TYPES.get(name, m.Ack)
                    try:
                        c._request(msg, kind, match=lambda x, k=kind: isinstance(x, k))
                        answers[f"{name} {how}"] = "answered"
                    except gd.DeviceError as e:
                        answers[f"{name} {how}"] = e.code_name
                deadline = time.monotonic() + 3.0
                off = None
                while off is None and time.monotonic() < deadline:
                    time.sleep(0.05)
                    off = _motors_off_after(trace, t0)
                on_ms[f"{name} {how}"] = (off if off is not None else 1e9) / 1000
        c.stop()
        # With the motors off the same requests are taken: the erase's own length, for scale.
        t = time.monotonic()
        c.log_erase()
        erase_s = time.monotonic() - t
        assert c.log_info().records == 0

    worst = max(on_ms, key=on_ms.get)
    report_figure(
        "motors on after the last POSE / SET_MOTORS, worst request (1 MiB store, real time)",
        f"{on_ms[worst]:.1f} ms ({worst}; watchdog {WATCHDOG_MS} ms; an erase then took "
        f"{erase_s * 1000:.0f} ms)",
    )
    for request in STORAGE_REQUESTS:
        for how in ("after POSE", "after SET_MOTORS"):
            key = f"{request} {how}"
            assert answers[key] == "not_allowed_in_state", (key, answers[key])
            assert on_ms[key] < 50, (key, on_ms[key])  # off with the refusal, not the watchdog
    assert on_ms[worst] <= WATCHDOG_MS + 100, on_ms


def test_an_error_during_a_hostless_pattern_stops_the_run_and_its_motors(tmp_path):
    """Once, an ERROR in a ready pattern turned the motors off for 0 us: the trace read
    200 -> 0 -> 200 at one device time, since the pattern player wrote them on again in the
    same loop. Now the ERROR ends the run (as STOP does) and the motors stay off."""
    begin, trials = _paper_plan(rest_s=0.0)
    trace = tmp_path / "motors.csv"
    args = ["--store", str(tmp_path / "U1.store")]
    with gsim.SimulatedDevice(virtual_clock=True, trace=str(trace), extra_args=args) as sim:
        c = gd.DeviceClient(sim, timeout=5.0)
        c.hello()
        c.upload_plan(begin, trials)
        c.hostless_run()
        still = ((0.0, 0.0, 9.81), (0.0, 0.0, 0.0))
        tel = c.sim_imu_sample(10_000, *still)
        assert tel is not None and any(tel.pwm), tel  # the ready pattern's first pulse
        with pytest.raises(gd.DeviceError, match="not_allowed_in_state"):
            c.set_motors([0, 0, 0, 0])  # a tracker request during the run: an ERROR
        rows = _trace_rows(trace)
        assert not any(rows[-1][1]), rows[-3:]  # off, and not on again in the same loop
        for t_us in range(20_000, 500_000, 20_000):  # the rest of the pattern's time
            assert c.sim_imu_sample(t_us, *still) is None  # no run: ACK, no TELEMETRY
        assert not c.log_info().running
        assert _trace_rows(trace) == rows, "the motors moved after the ERROR"
        c.hostless_run()  # the host starts it again
        assert c.log_info().running
