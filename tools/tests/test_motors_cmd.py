"""`graspguide motors` and its library: drive_motors (SET_MOTORS kept inside the POSE
watchdog, always zeros at the end), the patterns, and the command on the simulated device
and the Pro Mini under simavr through a real pseudo-terminal (trace lines; Ctrl-C leaves
the motors off)."""

from __future__ import annotations

import pytest

from graspguide.link import messages as m
from graspguide.link.motor_drive import MOTORS_OFF, drive_motors


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
