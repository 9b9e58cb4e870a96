"""The simulated device's own safety rules, end to end over its pseudo-terminal: the
watchdog on a virtual clock (a host that stops sending POSEs turns the motors off, whatever
else it sends), a trial left running by a silent host ends, and the simulator exits when
the process that started it dies (docs/protocol.md "Safety")."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from graspguide.link import client as gd
from graspguide.link import messages as m
from graspguide.link import sim as gsim

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
