"""Holding the motors at a PWM level (or a pattern of levels) for a while: SET_MOTORS
repeated well inside the device's POSE watchdog, which otherwise switches them off after
:data:`~graspguide.link.messages.POSE_WATCHDOG_MS`, and always a SET_MOTORS of zeros at the
end, whatever ended it (the duration, Ctrl-C, a link error)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from graspguide.link.messages import MAX_CONTACTS, POSE_WATCHDOG_MS

MOTOR_COUNT = MAX_CONTACTS
MOTORS_OFF = (0,) * MOTOR_COUNT
DEFAULT_REFRESH_S = 0.05
# A refresh must leave room for a late send (a slow link, a loaded host) before the
# watchdog fires: at most half its period.
MAX_REFRESH_S = POSE_WATCHDOG_MS / 1000.0 / 2
MAX_DURATION_S = 3600.0

Pwm = tuple[int, int, int, int]
PwmSource = Sequence[int] | Callable[[float], Sequence[int]]


def check_pwm(pwm: Any, field: str = "pwm") -> Pwm:
    """``pwm`` as a tuple of four ints 0..255, or ValueError naming ``field``."""
    try:
        values = list(pwm)
    except TypeError:
        raise ValueError(
            f"{field} must be {MOTOR_COUNT} duties 0..255 (thumb, index, middle, palm), got {pwm!r}"
        ) from None
    if len(values) != MOTOR_COUNT:
        raise ValueError(
            f"{field} must have {MOTOR_COUNT} duties (thumb, index, middle, palm), "
            f"got {len(values)}: {values!r}"
        )
    out = []
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or v != int(v):
            raise ValueError(f"{field}[{i}] must be an integer 0..255, got {v!r}")
        if not 0 <= int(v) <= 255:
            raise ValueError(f"{field}[{i}] must be in 0..255, got {v!r}")
        out.append(int(v))
    return (out[0], out[1], out[2], out[3])


def drive_motors(
    client,
    pwm: PwmSource,
    duration_s: float,
    *,
    refresh_s: float = DEFAULT_REFRESH_S,
    on_step: Callable[[float, Pwm], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> None:
    """Drive the four motors for ``duration_s`` seconds through ``client`` (a
    :class:`~graspguide.link.client.DeviceClient` or anything with ``set_motors``).

    ``pwm``: four duties 0..255 (thumb, index, middle, palm), or a pattern: a callable from
    the seconds since the start to four duties. SET_MOTORS goes out every ``refresh_s``
    (at most half the POSE watchdog) and ``on_step(t_s, pwm)`` is called after each send.
    The motors are switched off (SET_MOTORS zeros) on the way out, always: at the end of the
    duration, on KeyboardInterrupt, on any error (the original error is raised, not the
    one of the switch-off if that fails too)."""
    if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)):
        raise ValueError(f"duration_s must be a number of seconds, got {duration_s!r}")
    if not (math.isfinite(duration_s) and 0 < duration_s <= MAX_DURATION_S):
        raise ValueError(f"duration_s must be in (0, {MAX_DURATION_S:g}] seconds, got {duration_s}")
    if isinstance(refresh_s, bool) or not isinstance(refresh_s, (int, float)):
        raise ValueError(f"refresh_s must be a number of seconds, got {refresh_s!r}")
    if not (math.isfinite(refresh_s) and 0 < refresh_s <= MAX_REFRESH_S):
        raise ValueError(
            f"refresh_s must be in (0, {MAX_REFRESH_S:g}] s (half the device's "
            f"{POSE_WATCHDOG_MS} ms watchdog), got {refresh_s}"
        )
    pattern: Callable[[float], Sequence[int]]
    if callable(pwm):
        pattern = pwm
        check_pwm(pattern(0.0))  # a bad pattern fails before anything is sent
    else:
        fixed = check_pwm(pwm)

        def pattern(t_s: float) -> Sequence[int]:
            return fixed

    start = clock()
    failed = False
    try:
        next_s = 0.0
        while True:
            t_s = clock() - start
            if t_s >= duration_s:
                break
            duty = check_pwm(pattern(t_s))
            client.set_motors(duty)
            if on_step is not None:
                on_step(t_s, duty)
            # Sends on a fixed grid from the start: a slow send does not push later ones
            # back (the watchdog counts from the last one the device received).
            next_s += refresh_s
            now_s = clock() - start
            if next_s <= now_s:
                next_s = now_s
            sleep(max(0.0, min(next_s, duration_s) - now_s))
    except BaseException:
        failed = True
        raise
    finally:
        _switch_off(client, quiet=failed)


def _switch_off(client, quiet: bool) -> None:
    """SET_MOTORS zeros; retried once when a second Ctrl-C cuts the first. ``quiet``: an
    error is already on its way out, so this one's failure must not replace it (the
    device's watchdog still switches the motors off)."""
    for attempt in range(2):
        try:
            client.set_motors(MOTORS_OFF)
            return
        except KeyboardInterrupt:
            if attempt == 1 and not quiet:
                raise
        except Exception:
            if not quiet:
                raise
            return


__all__ = [
    "drive_motors",
    "check_pwm",
    "MOTOR_COUNT",
    "MOTORS_OFF",
    "DEFAULT_REFRESH_S",
    "MAX_REFRESH_S",
    "Pwm",
    "PwmSource",
]
