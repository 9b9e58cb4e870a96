"""`graspguide motors` and its library: drive_motors (SET_MOTORS kept inside the POSE
watchdog, always zeros at the end), the patterns, and the command on the simulated device
and the Pro Mini under simavr through a real pseudo-terminal (trace lines; Ctrl-C leaves
the motors off)."""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import time

import pytest
from conftest import subprocess_env

from graspguide.devices.promini_sim import ProMiniSimDevice
from graspguide.devices.sim import SimulatedDevice
from graspguide.link import messages as m
from graspguide.link.client import DeviceClient
from graspguide.link.motor_drive import MOTORS_OFF, drive_motors
from graspguide.link.motor_patterns import HOSTLESS_PATTERNS, parse_fingers, parse_pattern
from graspguide.link.transport import SerialTransport


# --------------------------------------------------------------------------------------
# drive_motors against a recording client and a fake clock
# --------------------------------------------------------------------------------------
class RecordingClient:
    """set_motors calls with the fake clock's time; ``fail_at``: the call number that
    raises ``error``."""

    def __init__(self, clock, fail_at: int | None = None, error: BaseException | None = None):
        self.clock = clock
        self.sent: list[tuple[float, tuple]] = []
        self.fail_at = fail_at
        self.error = error

    def set_motors(self, pwm):
        self.sent.append((self.clock(), tuple(pwm)))
        if self.fail_at is not None and len(self.sent) == self.fail_at:
            raise self.error  # type: ignore[misc]


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        assert s >= 0
        self.now += s


def test_drive_motors_refreshes_inside_the_watchdog_and_ends_with_zeros():
    clock = FakeClock()
    client = RecordingClient(clock)
    steps = []
    drive_motors(
        client,
        [10, 20, 30, 40],
        1.0,
        refresh_s=0.05,
        on_step=lambda t, p: steps.append((t, p)),
        clock=clock,
        sleep=clock.sleep,
    )
    on = [p for _, p in client.sent[:-1]]
    assert on and all(p == (10, 20, 30, 40) for p in on)
    assert client.sent[-1][1] == MOTORS_OFF
    times = [t for t, _ in client.sent]
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert max(gaps) < m.POSE_WATCHDOG_MS / 1000.0
    # 1 s at 50 ms: one send per step from 0 up to before the end.
    assert len(on) == round(1.0 / 0.05)
    assert [p for _, p in steps] == on
    assert times[-1] - times[0] == pytest.approx(1.0)


def test_drive_motors_follows_a_pattern():
    clock = FakeClock()
    client = RecordingClient(clock)

    def pattern(t_s: float):
        return [255, 0, 0, 0] if t_s < 0.5 else [0, 255, 0, 0]

    drive_motors(client, pattern, 1.0, clock=clock, sleep=clock.sleep)
    start = client.sent[0][0]
    for t, p in client.sent[:-1]:
        assert list(p) == pattern(t - start)
    assert client.sent[-1][1] == MOTORS_OFF


@pytest.mark.parametrize("error", [KeyboardInterrupt(), ConnectionError("link lost")])
def test_drive_motors_switches_off_on_interrupt_and_errors(error):
    clock = FakeClock()
    client = RecordingClient(clock, fail_at=3, error=error)
    with pytest.raises(type(error)):
        drive_motors(client, [200] * 4, 5.0, clock=clock, sleep=clock.sleep)
    assert client.sent[-1][1] == MOTORS_OFF and len(client.sent) == 4


def test_drive_motors_keeps_the_original_error_when_switching_off_fails():
    class Broken:
        def set_motors(self, pwm):
            raise OSError(f"port gone ({pwm})")

    with pytest.raises(OSError, match=r"\(\(200, 200, 200, 200\)\)"):
        drive_motors(Broken(), [200] * 4, 1.0)


@pytest.mark.parametrize(
    "pwm, duration_s, refresh_s, field",
    [
        ([1, 2, 3], 1.0, 0.05, "pwm"),
        ([1, 2, 3, 256], 1.0, 0.05, r"pwm\[3\]"),
        ([1, 2, -1, 0], 1.0, 0.05, r"pwm\[2\]"),
        ([1.5, 2, 3, 0], 1.0, 0.05, r"pwm\[0\]"),
        ("abcd", 1.0, 0.05, r"pwm\[0\]"),
        (lambda t: [0, 0, 0, 300], 1.0, 0.05, r"pwm\[3\]"),
        ([1, 2, 3, 4], 0.0, 0.05, "duration_s"),
        ([1, 2, 3, 4], float("nan"), 0.05, "duration_s"),
        ([1, 2, 3, 4], 1.0, 0.15, "refresh_s"),
        ([1, 2, 3, 4], 1.0, 0.0, "refresh_s"),
    ],
)
def test_drive_motors_rejects_bad_arguments_naming_the_field(pwm, duration_s, refresh_s, field):
    clock = FakeClock()
    client = RecordingClient(clock)
    with pytest.raises(ValueError, match=field):
        drive_motors(client, pwm, duration_s, refresh_s=refresh_s, clock=clock, sleep=clock.sleep)
    assert client.sent == [], "nothing may be sent when the arguments are bad"


# --------------------------------------------------------------------------------------
# Patterns
# --------------------------------------------------------------------------------------
def test_pulse_pattern_is_on_then_off_on_the_selected_fingers_only():
    spec = parse_pattern("pulse:on_ms=100,off_ms=300,pwm=150", (1,), None)
    for t_s in (0.0, 0.05, 0.099, 0.4, 0.45):
        assert spec.pattern(t_s) == (0, 150, 0, 0), t_s
    for t_s in (0.1, 0.2, 0.399):
        assert spec.pattern(t_s) == MOTORS_OFF, t_s


def test_ramp_pattern_spans_the_duration_monotonically():
    spec = parse_pattern("ramp:from=70,to=255", (0, 1, 2, 3), 2.0)
    duties = [spec.pattern(t / 100)[0] for t in range(0, 201)]
    assert duties[0] == 70 and duties[-1] == 255
    assert all(b >= a for a, b in zip(duties, duties[1:]))
    assert len(set(spec.pattern(1.0))) == 1  # every finger alike


def test_sweep_pattern_visits_each_selected_finger_alone():
    spec = parse_pattern("sweep:pwm=99,step_ms=100", (0, 2, 3), 1.0)
    on = [tuple(i for i, d in enumerate(spec.pattern(k * 0.1 + 0.05)) if d) for k in range(6)]
    assert on == [(0,), (2,), (3,), (0,), (2,), (3,)]


def test_hostless_patterns_end_after_their_pulses():
    for name, (pulses, on_ms, off_ms) in HOSTLESS_PATTERNS.items():
        spec = parse_pattern(name, (0, 1, 2), None)
        assert spec.length_s == pytest.approx((pulses * on_ms + (pulses - 1) * off_ms) / 1e3)
        starts = [k for k in range(int(spec.length_s * 1000)) if any(spec.pattern(k / 1000))]
        rising = [k for k in starts if k == 0 or not any(spec.pattern((k - 1) / 1000))]
        assert len(rising) == pulses, name
        assert spec.pattern(spec.length_s + 0.01) == MOTORS_OFF


@pytest.mark.parametrize(
    "spec, field",
    [
        ("wobble", "unknown pattern 'wobble'"),
        ("pulse:on_ms=0", "on_ms"),
        ("pulse:pwm=256", "pwm"),
        ("pulse:speed=3", "unknown key 'speed'"),
        ("ramp:from=x", "from"),
        ("sweep:step_ms", "step_ms"),
    ],
)
def test_bad_pattern_specs_name_the_part(spec, field):
    with pytest.raises(ValueError, match=re.escape(field)):
        parse_pattern(spec, (0,), 1.0)


def test_fingers_by_name_number_and_all():
    assert parse_fingers("thumb,3") == (0, 2)
    assert parse_fingers("all") == (0, 1, 2, 3)
    assert parse_fingers("palm") == (3,)
    with pytest.raises(ValueError, match="--finger"):
        parse_fingers("5")


# --------------------------------------------------------------------------------------
# The command, in a real pseudo-terminal
# --------------------------------------------------------------------------------------
CLI = [sys.executable, "-m", "graspguide"]
TRACE_LINE = re.compile(
    rb"^\s*(\d+\.\d+) s  thumb\s+(\d+)  index\s+(\d+)  middle\s+(\d+)  palm\s+(\d+)\r?$", re.M
)


def run_in_pty(argv, interrupt_after=None, timeout_s=30.0):
    """Run ``argv`` on a new pseudo-terminal; with ``interrupt_after`` (a regex), type
    Ctrl-C once the output matches it. Returns (exit status, output bytes)."""
    pid, fd = os.forkpty()
    if pid == 0:  # pragma: no cover - the child
        try:
            os.execvpe(argv[0], argv, subprocess_env())
        finally:
            os._exit(127)
    out = b""
    sent = False
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([fd], [], [], 0.1)
            if ready:
                try:
                    chunk = os.read(fd, 4096)
                except OSError:  # EIO: the child closed the terminal
                    break
                if not chunk:
                    break
                out += chunk
            if interrupt_after is not None and not sent and re.search(interrupt_after, out):
                os.write(fd, b"\x03")
                sent = True
        else:
            os.kill(pid, signal.SIGKILL)
            pytest.fail(f"{argv} did not end within {timeout_s} s; output {out!r}")
    finally:
        _, status = os.waitpid(pid, 0)
        os.close(fd)
    if interrupt_after is not None:
        assert sent, f"never saw {interrupt_after!r} in {out!r}"
    return os.waitstatus_to_exitcode(status), out


def _trace_rows(path) -> list[tuple[int, ...]]:
    with open(path) as f:
        next(f)
        return [tuple(int(x) for x in line.split(",")[1:]) for line in f if line.strip()]


@pytest.fixture
def sim_with_trace(tmp_path):
    trace = tmp_path / "motors.csv"
    with SimulatedDevice(trace=str(trace)) as sim:
        yield sim, trace


def test_motors_on_sim_prints_a_trace_and_switches_off(sim_with_trace):
    sim, trace = sim_with_trace
    argv = CLI + ["motors", "--port", sim.pty_path, "--finger", "index,palm"]
    argv += ["--pattern", "pulse:on_ms=150,off_ms=150,pwm=180", "--duration-s", "1"]
    code, out = run_in_pty(argv)
    assert code == 0, out
    rows = [tuple(int(x) for x in m_.groups()[1:]) for m_ in TRACE_LINE.finditer(out)]
    times = [float(m_.group(1)) for m_ in TRACE_LINE.finditer(out)]
    assert rows[0] == (0, 180, 0, 180) and (0, 0, 0, 0) in rows, out
    assert all(r in ((0, 180, 0, 180), (0, 0, 0, 0)) for r in rows)
    assert times == sorted(times) and times[-1] < 1.0
    assert out.rstrip().endswith(b"motors off"), out
    # The device drove what the trace said, and ended with everything off.
    device_rows = _trace_rows(trace)
    assert (0, 180, 0, 180) in device_rows and device_rows[-1] == MOTORS_OFF


def test_ctrl_c_leaves_the_motors_off(sim_with_trace):
    sim, trace = sim_with_trace
    argv = CLI + ["motors", "--port", sim.pty_path, "--pwm", "200", "--duration-s", "60"]
    code, out = run_in_pty(argv, interrupt_after=rb"thumb 200  index 200")
    assert code == 130, out
    assert b"interrupted" in out and out.rstrip().endswith(b"motors off"), out
    assert _trace_rows(trace)[-1] == MOTORS_OFF
    assert (200, 200, 200, 200) in _trace_rows(trace)
    # Long after the watchdog: still off, and the device took no bad frame.
    time.sleep(2 * m.POSE_WATCHDOG_MS / 1000.0)
    assert _trace_rows(trace)[-1] == MOTORS_OFF
    with DeviceClient(SerialTransport(sim.pty_path), timeout=2.0) as client:
        status = client.status()
    assert status.bad_frames == 0 and status.state in (m.DeviceState.IDLE, m.DeviceState.STOPPED)


def test_motors_on_promini_sim_drives_the_pins(tmp_path, sketch_elf):
    trace = tmp_path / "pins.csv"
    with ProMiniSimDevice(elf=sketch_elf, trace=str(trace)) as dev:
        argv = CLI + ["motors", "--port", dev.pty_path, "--finger", "middle", "--pwm", "150"]
        code, out = run_in_pty(argv + ["--duration-s", "0.6"])
    assert code == 0, out
    assert b"middle 150" in out and out.rstrip().endswith(b"motors off")
    pins = _trace_rows(trace)
    assert (0, 0, 150, 0) in pins and pins[-1] == MOTORS_OFF


@pytest.mark.parametrize(
    "extra, option",
    [
        (["--pwm", "256"], "--pwm"),
        (["--pwm", "10", "--pattern", "ready"], "--pattern"),
        ([], "--pwm --pattern"),
        (["--pwm", "10", "--finger", "toe"], "--finger"),
        (["--pattern", "pulse:on_ms=-1"], "on_ms"),
        (["--pwm", "10", "--duration-s", "0"], "--duration-s"),
    ],
)
def test_bad_arguments_are_usage_errors_naming_the_option(extra, option):
    done = subprocess.run(
        CLI + ["motors", "--port", "sim", *extra],
        capture_output=True,
        text=True,
        env=subprocess_env(),
        timeout=60,
    )
    assert done.returncode == 2, done
    assert option in done.stderr, done.stderr


def _qemu_or_skip():
    from graspguide.devices import qemu_firmware
    from graspguide.link.transport import DeviceNotFound

    try:
        qemu_firmware.find_qemu()
        return qemu_firmware.find_firmware_elf()
    except DeviceNotFound as e:
        pytest.skip(f"QEMU firmware test: {e}")


def test_ctrl_c_leaves_the_qemu_firmwares_motor_registers_off(tmp_path):
    from graspguide.devices.qemu_firmware import QemuFirmware

    elf = _qemu_or_skip()
    board = QemuFirmware(elf, workdir=str(tmp_path))
    try:
        # The first answer waits for QEMU's 1 s poll of the pty: a longer --timeout.
        argv = CLI + ["motors", "--port", board.pty_path, "--timeout", "5", "--pwm", "120"]
        argv += ["--finger", "thumb", "--duration-s", "60"]
        code, out = run_in_pty(argv, interrupt_after=rb"thumb 120")
        assert code == 130, out
        assert out.rstrip().endswith(b"motors off"), out
        assert board.motor_registers() == MOTORS_OFF
        status_client = DeviceClient(SerialTransport(board.pty_path), timeout=5.0)
        with status_client:
            status = status_client.status()
        assert status.bad_frames == 0 and status.state is not m.DeviceState.TRIAL_RUNNING
    finally:
        board.close()


def test_port_qemu_starts_the_firmware_and_drives_it():
    _qemu_or_skip()
    argv = CLI + ["motors", "--port", "qemu", "--pattern", "success"]
    code, out = run_in_pty(argv)
    assert code == 0, out
    rows = [tuple(int(x) for x in m_.groups()[1:]) for m_ in TRACE_LINE.finditer(out)]
    assert rows[0] == (200, 200, 200, 200), out
    assert out.rstrip().endswith(b"motors off")


def test_sigterm_leaves_the_motors_off(sim_with_trace):
    sim, trace = sim_with_trace
    argv = CLI + ["motors", "--port", sim.pty_path, "--pwm", "90", "--duration-s", "60"]
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=subprocess_env()
    )
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert b"thumb  90" in first, first
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert out.rstrip().endswith(b"motors off"), out
    rows = _trace_rows(trace)
    assert (90, 90, 90, 90) in rows and rows[-1] == MOTORS_OFF
