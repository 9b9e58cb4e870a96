"""`--port promini-sim`: the libsimavr runner (src/harness/promini_sim/runner.c) on a tiny
AVR program of its own (uart_echo.c: echoes UART bytes, shows each as PWM the way
analogWrite drives a pin), and DeviceClient's per-posture path for a per-frame-only board
against a scripted fake device; then the real sketch (promini/GraspGuideProMini, built
by arduino-cli through graspguide.promini.build) under the runner: the same trial as the
simulated device within 1 PWM count, per pose and on the pins; its watchdog in simulated
time; garbage on its UART. avr-gcc, libsimavr-dev, arduino-cli and the simulated device
come from tools/bootstrap.sh: their absence is a failure, never a skip."""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import REPO_ROOT
from fake_device import HAND3, WRENCH, FakeDevice, good_device

from graspguide.core import solver
from graspguide.devices import promini_sim as pms
from graspguide.devices import registry
from graspguide.devices import sim as gsim
from graspguide.link import client as gd
from graspguide.link import messages as m
from graspguide.link import transport as gt

ROOT = Path(REPO_ROOT)
ECHO_SOURCE = ROOT / "src" / "harness" / "promini_sim" / "uart_echo.c"
# uart_echo.c drives OC0A with the byte and OC2B with 255 minus it.
ECHO_MOTORS = ("OC0A", "OC2B", "OC1A", "OC1B")
QUIT_BYTE = ord("Q")


def _need(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        pytest.fail(f"{tool} is missing: run tools/bootstrap.sh (it installs gcc-avr)")
    return path


@pytest.fixture(scope="module")
def runner() -> str:
    return pms.build_runner(str(ROOT))


@pytest.fixture(scope="module")
def echo_elf(tmp_path_factory) -> str:
    elf = tmp_path_factory.mktemp("promini_sim") / "uart_echo.elf"
    cmd = [_need("avr-gcc"), "-mmcu=atmega328p", "-DF_CPU=8000000UL", "-Os"]
    cmd += ["-Wall", "-Wextra", "-Werror", str(ECHO_SOURCE), "-o", str(elf)]
    subprocess.run(cmd, check=True)
    return str(elf)


def _read_exactly(dev: gt.Transport, n: int, timeout_s: float = 5.0) -> bytes:
    got = b""
    deadline = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        got += dev.read(n - len(got), 0.1)
    return got


def _trace_rows(path: Path) -> list[tuple[int, ...]]:
    with open(path) as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["device_time_us", "pwm0", "pwm1", "pwm2", "pwm3"]
    return [tuple(int(v) for v in r) for r in rows[1:]]


def _is_subsequence(wanted: list, seen: list) -> bool:
    it = iter(seen)
    return all(any(w == s for s in it) for w in wanted)


def _duties(b: int) -> tuple[int, int]:
    """What the pins of uart_echo.c carry after byte b: the duty, or fully on/off when
    analogWrite-style 0 and 255 disconnect the timer."""
    return b, 255 - b


# --------------------------------------------------------------------------------------
# The runner on uart_echo.elf
# --------------------------------------------------------------------------------------
def test_every_byte_value_echoes_unchanged_and_shows_as_pwm_from_the_timer_registers(
    runner, echo_elf, tmp_path
):
    trace, marks, stats = tmp_path / "t.csv", tmp_path / "marks.txt", tmp_path / "stats.txt"
    sent = [b for b in range(256) if b != QUIT_BYTE]
    with pms.ProMiniSimDevice(
        elf=echo_elf,
        runner=runner,
        trace=str(trace),
        motors=ECHO_MOTORS,
        marks=str(marks),
        stats=str(stats),
    ) as dev:
        assert dev.name == f"promini-sim ({dev.pty_path})"
        for b in sent:  # one at a time: each PWM state lasts until the next byte
            dev.write(bytes([b]))
            assert _read_exactly(dev, 1) == bytes([b])
    assert dev.exit_code == 0
    rows = _trace_rows(trace)
    times = [r[0] for r in rows]
    assert times == sorted(times)
    assert rows[0][1:] == (0, 0, 0, 0), "motors off at boot"
    assert rows[-1][1:] == (0, 0, 0, 0), "motors off when the runner is stopped"
    states = [r[1:3] for r in rows]
    assert _is_subsequence([_duties(b) for b in sent], states)
    assert all(r[3:] == (0, 0) for r in rows), "OC1A and OC1B are never driven"
    cycles = [int(x) for x in marks.read_text().split()]
    assert len(cycles) == len(sent) and min(cycles) > 0
    figures = pms.read_stats(str(stats))
    assert figures["uart_bytes_dropped"] == 0
    assert 0 < figures["stack_bytes_max"] < 2048
    assert figures["simulated_us"] == figures["cycles"] // 8


def test_the_uart_runs_at_the_programmed_baud_rate_in_simulated_time(runner, echo_elf, tmp_path):
    """uart_echo.c programs UBRR 8 with U2X: 72 cycles a bit at 8 MHz. simavr 1.6 frames a
    byte as 11 bits (it always counts a parity bit; a real 8N1 line sends 10) and raises
    UDRE only once the previous byte is out, so an echoed burst advances one byte per 11
    bit times plus the sketch's few cycles -- in simulated time, whatever the host's
    speed (fast mode)."""
    trace = tmp_path / "t.csv"
    burst = bytes(b for b in range(1, 102) if b != QUIT_BYTE)
    with pms.ProMiniSimDevice(
        elf=echo_elf, runner=runner, trace=str(trace), motors=ECHO_MOTORS, fast=True
    ) as dev:
        dev.write(burst)
        assert _read_exactly(dev, len(burst)) == burst
    rows = _trace_rows(trace)
    first = next(r[0] for r in rows if r[1:3] == _duties(burst[1]))
    last = next(r[0] for r in rows if r[1:3] == _duties(burst[-1]))
    per_byte_us = (last - first) / (len(burst) - 2)
    simavr_byte_us = 11 * (8 + 1) * 8 / 8  # 11 bits of (UBRR + 1) * 8 cycles, 8 cycles/us
    assert simavr_byte_us <= per_byte_us <= simavr_byte_us + 2


def test_simulated_time_is_held_to_real_time(runner, echo_elf, tmp_path):
    stats = tmp_path / "stats.txt"
    t0 = time.perf_counter()
    done = subprocess.run(
        [runner, echo_elf, "--max-cycles", "4000000", "--stats", str(stats)],
        capture_output=True,
        timeout=30,
    )
    wall_s = time.perf_counter() - t0
    assert done.returncode == pms.RUNNER_EXIT_MAX_CYCLES, done.stderr
    assert done.stdout.startswith(b"GRASPGUIDE_SIM_PTY /dev/")
    assert pms.read_stats(str(stats))["cycles"] >= 4_000_000
    assert wall_s >= 0.45, f"0.5 s of simulated time took {wall_s:.3f} s of real time"


def test_the_sketch_ending_ends_the_runner_with_status_0(runner, echo_elf):
    dev = pms.ProMiniSimDevice(elf=echo_elf, runner=runner, fast=True).start()
    try:
        dev.write(bytes([QUIT_BYTE]))
        assert _read_exactly(dev, 1) == bytes([QUIT_BYTE])
        assert dev.process is not None
        assert dev.process.wait(timeout=5) == 0
    finally:
        dev.close()


def test_the_runner_dies_with_its_parent_and_switches_the_motors_off(runner, echo_elf, tmp_path):
    trace = tmp_path / "t.csv"
    parent_code = (
        "import subprocess, sys, time\n"
        f"p = subprocess.Popen([{runner!r}, {echo_elf!r}, '--trace', {str(trace)!r}, "
        f"'--motors', {','.join(ECHO_MOTORS)!r}], stdout=subprocess.PIPE)\n"
        "line = p.stdout.readline().decode().split()[1]\n"
        "import os\n"
        "fd = os.open(line, os.O_RDWR | os.O_NOCTTY)\n"
        "os.write(fd, bytes([77]))\n"
        "os.read(fd, 1)\n"
        "print(p.pid, flush=True)\n"
        "time.sleep(60)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", parent_code], stdout=subprocess.PIPE)
    try:
        assert parent.stdout is not None
        child = int(parent.stdout.readline())
        assert _trace_rows(trace)[-1][1:3] == _duties(77)
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.monotonic() + 5
    while os.path.exists(f"/proc/{child}") and time.monotonic() < deadline:
        with open(f"/proc/{child}/stat") as f:
            if f.read().split(") ")[1].startswith("Z"):
                break  # exited; init has not reaped it yet
        time.sleep(0.02)
    else:
        assert not os.path.exists(f"/proc/{child}"), "the runner outlived its parent"
    assert _trace_rows(trace)[-1][1:] == (0, 0, 0, 0)


def test_runner_errors_are_clear(runner, echo_elf, tmp_path):
    bad = subprocess.run([runner, echo_elf, "--motors", "OC0A,PD6"], capture_output=True, text=True)
    assert bad.returncode == 2 and "--motors" in bad.stderr
    missing = subprocess.run([runner, str(tmp_path / "none.elf")], capture_output=True, text=True)
    assert missing.returncode == 2 and "cannot read" in missing.stderr
    with pytest.raises(ValueError, match="four timer channels"):
        pms.runner_options(motors=["OC0A", "OC0B", "OC3A", "OC1B"])
    with pytest.raises(gt.SimNotBuilt, match="graspguide.promini.build"):
        pms.ProMiniSimDevice(elf=str(tmp_path / "none.elf"), runner=runner)
    with pytest.raises(gt.LinkError, match="virtual-clock is for --port sim"):
        pms.ProMiniSimDevice(elf=echo_elf, runner=runner, virtual_clock=True)


def test_open_port_starts_promini_sim(runner, echo_elf):
    with registry.open_port("promini-sim", elf=echo_elf, runner=runner, fast=True) as dev:
        assert isinstance(dev, pms.ProMiniSimDevice) and dev.alive()
        dev.write(b"\x2a")
        assert _read_exactly(dev, 1) == b"\x2a"
    assert not dev.alive()


def test_build_runner_rebuilds_only_a_stale_binary(runner):
    before = os.path.getmtime(runner)
    assert pms.build_runner(str(ROOT)) == runner
    assert os.path.getmtime(runner) == before


# --------------------------------------------------------------------------------------
# DeviceClient and a per-frame-only board (scripted)
# --------------------------------------------------------------------------------------
def per_frame_board(msg, seq):
    """A per-frame-only board: HELLO_REPLY with per_frame and no full_solve, SET_SCENE and
    contacts refused with per_frame_only, the rest as the good device."""
    if isinstance(msg, m.Hello):
        (reply,) = good_device(msg, seq)
        return [dataclasses.replace(reply, board="promini", capabilities=m.CAPABILITY_PER_FRAME)]
    if isinstance(msg, m.SetScene):
        return [m.Error(request_seq=seq, code=m.ErrorCode.PER_FRAME_ONLY, detail=msg.MSG_ID)]
    return good_device(msg, seq)


def _f32(values):
    return [gd.to_f32(v) for v in values]


def _expected_posture(contacts, wrench, policy, mode, constraints):
    """Levels and f-hat from the C++ core on the float32 values a full-solve board gets."""
    res = solver.solve(
        [_f32(c) for c in contacts],
        _f32(wrench),
        policy=policy,
        mode=mode,
        constraints=constraints,
        y_axis=[0.0, 1.0, 0.0],
    )
    assert res["status"] == "ok"
    force = _f32(wrench)[:3]
    norm = math.sqrt(sum(f * f for f in force))
    return _f32(res["levels"]), _f32([f / norm for f in force])


@pytest.mark.parametrize("hello_first", [True, False])
def test_a_per_frame_board_gets_the_hosts_posture_then_start_trial(hello_first):
    c = gd.DeviceClient(FakeDevice(per_frame_board), timeout=0.2)
    if hello_first:
        c.hello()
    assert c.set_scene(HAND3, policy="Fperp", mode="V", constraints="normal", hold_s=0.7) is None
    assert c.host_solves_posture
    c.start_trial(9, WRENCH)
    tel = c.pose(1000, (1, 0, 0, 0))
    assert tel.host_time_us == 1000
    sent = [type(msg) for _, msg in c.transport.received]
    tail = [m.SetPosture, m.StartTrial, m.Pose]
    assert sent[-3:] == tail
    assert sent.count(m.SetScene) == (0 if hello_first else 1)
    posture = c.transport.received[-3][1]
    levels, f_hat = _expected_posture(HAND3, WRENCH, "Fperp", "V", "normal")
    assert posture.k == 3 and posture.mode is m.Mode.V
    assert list(posture.levels[:3]) == levels and posture.levels[3] == 0.0
    assert list(posture.force_unit) == f_hat
    assert list(posture.wrench) == _f32(WRENCH) == list(c.transport.received[-2][1].wrench)
    assert posture.hold_s == gd.to_f32(0.7) and posture.threshold_deg == 3.0


def test_a_full_solve_board_still_gets_set_scene():
    c = gd.DeviceClient(FakeDevice(good_device), timeout=0.2)
    c.hello()
    assert isinstance(c.set_scene(HAND3), m.Ack)
    c.start_trial(1, WRENCH)
    assert not c.host_solves_posture
    assert [type(msg) for _, msg in c.transport.received[1:]] == [m.SetScene, m.StartTrial]


def test_per_frame_board_refusals_are_raised_on_the_host_before_sending():
    c = gd.DeviceClient(FakeDevice(per_frame_board), timeout=0.2)
    c.hello()
    sent_before = len(c.transport.received)
    with pytest.raises(gd.DeviceError, match="host's core could not solve SET_SCENE") as e:
        c.set_scene([HAND3[0], HAND3[0], HAND3[2]])
    assert e.value.code is m.ErrorCode.COINCIDENT_CONTACTS
    with pytest.raises(gd.DeviceError) as e:
        c.set_scene(HAND3 + HAND3[:2])
    assert e.value.code is m.ErrorCode.BAD_CONTACT_COUNT
    c.set_scene(HAND3)
    with pytest.raises(gd.DeviceError) as e:
        c.start_trial(1, [0, 0, 0, 0, 0, 0])
    assert e.value.code is m.ErrorCode.ZERO_WRENCH
    with pytest.raises(gd.PerFrameOnly, match="cannot carry contacts"):
        c.pose(5, (1, 0, 0, 0), contacts=HAND3)
    assert len(c.transport.received) == sent_before, "nothing reached the board"


# --------------------------------------------------------------------------------------
# The real sketch (promini/GraspGuideProMini, built by arduino-cli) under the runner
# --------------------------------------------------------------------------------------
STALE_TIMEOUT_MS = 200  # GRASPGUIDE_STALE_TIMEOUT_MS of lib/graspguide_cue_device
SWEEP_AXIS = (0.6, 0.0, 0.8)


def _sweep(n: int, from_deg: float = 60.0, to_deg: float = 20.0) -> list[tuple[float, ...]]:
    """Orientations turning towards the identity about one axis: the guidance error falls
    but stays above the success threshold, so the trial keeps running."""
    out = []
    for i in range(n):
        a = math.radians(from_deg + (to_deg - from_deg) * i / (n - 1))
        s = math.sin(a / 2)
        out.append((math.cos(a / 2), s * SWEEP_AXIS[0], s * SWEEP_AXIS[1], s * SWEEP_AXIS[2]))
    return out


def _run_trial(transport: gt.Transport, poses, period_us: int = 10_000) -> list[tuple[int, ...]]:
    c = gd.DeviceClient(transport, timeout=2.0)
    c.hello(timeout=5.0)
    c.set_scene(HAND3, mode="V")
    c.start_trial(3, WRENCH)
    pwm = []
    for i, q in enumerate(poses):
        tel = c.pose(1_000 + i * period_us, q)
        assert tel.solver_status is m.ErrorCode.OK, tel
        pwm.append(tuple(tel.pwm))
    c.stop()
    return pwm


def test_the_sketch_gives_the_simulated_devices_pwm_per_pose_within_one_count(
    sketch_elf, runner, tmp_path, report_figure
):
    poses = _sweep(40)
    trace = tmp_path / "promini.csv"
    with gsim.SimulatedDevice(virtual_clock=True) as sim:
        reference = _run_trial(sim, poses)
    with pms.ProMiniSimDevice(elf=sketch_elf, runner=runner, trace=str(trace)) as dev:
        info = gd.DeviceClient(dev).hello(timeout=5.0)
        assert info.capabilities & m.CAPABILITY_PER_FRAME
        assert not info.capabilities & m.CAPABILITY_FULL_SOLVE
        promini = _run_trial(dev, poses)
    assert len(promini) == len(reference) == len(poses)
    assert any(any(p) for p in reference), "the sweep drives the motors"
    worst = max(abs(a - b) for pa, pb in zip(promini, reference) for a, b in zip(pa, pb))
    report_figure("promini-sim vs sim: PWM per pose", f"max diff {worst} count(s), 40 poses")
    assert worst <= 1
    # What the pins carried, read from the timer registers, is what TELEMETRY reported.
    states = [r[1:] for r in _trace_rows(trace)]
    reported = [p for i, p in enumerate(promini) if i == 0 or p != promini[i - 1]]
    assert _is_subsequence(reported, states)
    assert states[-1] == (0, 0, 0, 0)


def test_the_sketchs_watchdog_turns_the_motors_off_in_simulated_time(
    sketch_elf, runner, tmp_path, report_figure
):
    trace = tmp_path / "promini.csv"
    with pms.ProMiniSimDevice(elf=sketch_elf, runner=runner, trace=str(trace)) as dev:
        c = gd.DeviceClient(dev, timeout=2.0)
        c.hello(timeout=5.0)
        c.set_scene(HAND3, mode="V")
        c.start_trial(4, WRENCH)
        for i, q in enumerate(_sweep(10)):
            last_pwm = tuple(c.pose(1_000 + i * 10_000, q).pwm)
            assert any(last_pwm)
        time.sleep((STALE_TIMEOUT_MS + 300) / 1000)
        rows = _trace_rows(trace)
    # The last pose took effect when the pins reached its PWM (the glue sets the channels
    # one after the other); the watchdog has switched them all off at the first all-zero row.
    last_pose_us = max(r[0] for r in rows if r[1:] == last_pwm)
    off_us = [r[0] for r in rows if r[0] > last_pose_us and not any(r[1:])]
    assert off_us, "the motors stayed on without poses"
    latency_ms = (off_us[0] - last_pose_us) / 1000
    report_figure("promini-sim watchdog: last pose -> motors off", f"{latency_ms:.3f} ms simulated")
    # The watchdog is fed when the POSE arrives, ~1 ms (its frame's work) before its PWM
    # reaches the pins: hence up to 2 ms under the timeout, measured from the pins.
    assert STALE_TIMEOUT_MS - 2 <= latency_ms <= STALE_TIMEOUT_MS + 5


def test_cycles_per_pose_and_the_stack_of_the_sketch(
    sketch_build, sketch_elf, runner, tmp_path, report_figure
):
    """The sketch marks each poll that completes a frame (GPIOR0 1 and 2): its cycles are a
    POSE's decode, frame and TELEMETRY encode. The stack is the runner's measured maximum;
    with the static RAM it must fit the 1.5 KB budget."""
    import statistics

    from graspguide.promini import build

    marks, stats = tmp_path / "marks.txt", tmp_path / "stats.txt"
    poses = _sweep(200, from_deg=80.0, to_deg=20.0)
    with pms.ProMiniSimDevice(
        elf=sketch_elf, runner=runner, marks=str(marks), stats=str(stats)
    ) as dev:
        _run_trial(dev, poses)
    cycles = [int(x) for x in marks.read_text().split()]
    # HELLO, SET_POSTURE, START_TRIAL, the POSEs and STOP: one mark per frame.
    assert len(cycles) == len(poses) + 4, len(cycles)
    per_pose = sorted(cycles[3:-1])
    median, worst = statistics.median(per_pose), per_pose[-1]
    figures = pms.read_stats(str(stats))
    report_figure(
        "promini-sim cycles per POSE (decode + frame + TELEMETRY encode)",
        f"median {median:.0f}, max {worst} cycles "
        f"({median / 8:.0f} / {worst / 8:.0f} us at 8 MHz), "
        f"{len(per_pose)} poses; static RAM {sketch_build.static_ram_bytes} B + stack max "
        f"{figures['stack_bytes_max']} B of {build.RAM_BUDGET_BYTES} B",
    )
    # A POSE's work must leave the 8 MHz AVR time for the pose rate the wire carries.
    assert 0 < median <= worst < 80_000
    assert figures["uart_bytes_dropped"] == 0
    assert sketch_build.static_ram_bytes + figures["stack_bytes_max"] <= build.RAM_BUDGET_BYTES


def test_garbage_on_the_uart_neither_crashes_nor_hangs_the_sketch(sketch_elf, runner, tmp_path):
    stats = tmp_path / "stats.txt"
    noise = bytes((i * 73 + 41) % 256 for i in range(3000))  # every byte value, no pattern
    with pms.ProMiniSimDevice(elf=sketch_elf, runner=runner, stats=str(stats)) as dev:
        dev.write(noise)
        time.sleep(len(noise) * 100e-6 + 0.2)  # ~99 us a byte in simavr's UART
        assert dev.alive()
        c = gd.DeviceClient(dev, timeout=2.0)
        c.drain(0.2)  # whatever the sketch answered to the noise
        assert c.hello(timeout=5.0).board
        pwm = _run_trial(dev, _sweep(5))
        assert any(any(p) for p in pwm)
    assert dev.exit_code == 0
    figures = pms.read_stats(str(stats))
    assert figures["uart_bytes_dropped"] == 0
    assert figures["stack_bytes_max"] > 0


def _stream(port_args: list[str], source: Path, log: Path, sketch_elf: str):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env[pms.PROMINI_ELF_ENV] = sketch_elf
    cmd = [sys.executable, "-m", "graspguide", "stream", *port_args]
    cmd += ["--scene", str(ROOT / "tools" / "examples" / "scene_paper_3.toml")]
    cmd += ["--wrench", "0.3,-1.2,-0.8", "--source", f"replay:{source}", "--log", str(log)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    with open(log / "telemetry.csv") as f:
        return [tuple(int(r[f"pwm{i}"]) for i in range(4)) for r in csv.DictReader(f)]


def test_graspguide_stream_to_promini_sim_gives_the_pwm_rows_of_sim(sketch_elf, tmp_path):
    poses = _sweep(51)
    source = tmp_path / "sweep.csv"
    rows = "".join(f"{i * 0.02},{q[0]},{q[1]},{q[2]},{q[3]}\n" for i, q in enumerate(poses))
    source.write_text("t_s,qw,qx,qy,qz\n" + rows)
    promini = _stream(["--port", "promini-sim"], source, tmp_path / "promini", sketch_elf)
    sim = _stream(["--port", "sim", "--virtual-clock"], source, tmp_path / "sim", sketch_elf)
    assert len(promini) == len(sim) == len(poses)
    assert any(any(p) for p in sim)
    assert max(abs(a - b) for pa, pb in zip(promini, sim) for a, b in zip(pa, pb)) <= 1


CRASHING_PROGRAM = """
#include <avr/io.h>
int main(void) {
  DDRD |= _BV(PD6);
  PORTD |= _BV(PD6); /* motor 0 (OC0A's pin) fully on */
  ((void (*)(void))0x3000)(); /* into erased flash */
  return 0;
}
"""


def test_a_crashing_avr_ends_the_runner_with_the_motors_off(runner, tmp_path):
    source, elf, trace = tmp_path / "crash.c", tmp_path / "crash.elf", tmp_path / "t.csv"
    source.write_text(CRASHING_PROGRAM)
    subprocess.run(
        [_need("avr-gcc"), "-mmcu=atmega328p", "-Os", str(source), "-o", str(elf)], check=True
    )
    done = subprocess.run(
        [runner, str(elf), "--trace", str(trace), "--motors", ",".join(ECHO_MOTORS)],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == pms.RUNNER_EXIT_CRASHED, done.stderr
    assert "crashed" in done.stderr
    states = [r[1:] for r in _trace_rows(trace)]
    assert (255, 0, 0, 0) in states and states[-1] == (0, 0, 0, 0)
