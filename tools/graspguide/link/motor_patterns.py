"""Motor patterns for the bench test (`graspguide motors --pattern SPEC`): a pattern is a
function from the seconds since its start to the four motors' duties, for
:func:`graspguide.link.motor_drive.drive_motors`.

SPEC is ``NAME[:key=value,...]``:

* ``pulse:on_ms=200,off_ms=200,pwm=200`` -- on and off in turn;
* ``ramp:from=70,to=255`` -- a linear ramp over the duration (``period_s`` to repeat it);
* ``sweep:pwm=200,step_ms=500`` -- each selected finger alone in turn;
* ``ready``, ``success``, ``timeout`` -- the host-less device's patterns (docs/hostless.md):
  two 150 ms pulses, one 600 ms pulse, three 100 ms pulses, at PWM 200.

Every pattern drives only the selected fingers (``fingers``); the others stay at 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from graspguide.link.motor_drive import MOTOR_COUNT, Pwm

FINGER_NAMES = ("thumb", "index", "middle", "palm")

# The host-less device's patterns and their duty (lib/graspguide_device/.../
# vibration_pattern.h: kReadyPattern, kSuccessPattern, kTimeoutPattern,
# GRASPGUIDE_PATTERN_DUTY), so a wearer can feel them on the bench before a study.
HOSTLESS_PATTERN_DUTY = 200
HOSTLESS_PATTERNS = {  # name: (pulses, on_ms, off_ms)
    "ready": (2, 150, 150),
    "success": (1, 600, 0),
    "timeout": (3, 100, 100),
}

Pattern = Callable[[float], Pwm]


@dataclass(frozen=True)
class PatternSpec:
    """A parsed --pattern: ``pattern`` (t_s -> duties), ``length_s`` (its natural length:
    a host-less pattern's, else None) and ``text`` (the spec, for the trace)."""

    pattern: Pattern
    length_s: float | None
    text: str


_PARAMETERS = {
    "pulse": {"on_ms": 200.0, "off_ms": 200.0, "pwm": 200.0},
    "ramp": {"from": 70.0, "to": 255.0, "period_s": 0.0},
    "sweep": {"pwm": 200.0, "step_ms": 500.0},
    **{name: {} for name in HOSTLESS_PATTERNS},
}
PATTERN_NAMES = tuple(_PARAMETERS)


def _duty(value: float, key: str) -> int:
    if value != int(value) or not 0 <= value <= 255:
        raise ValueError(f"--pattern {key}= must be an integer PWM 0..255, got {value:g}")
    return int(value)


def _positive(value: float, key: str) -> float:
    if not 0 < value <= 3_600_000:
        raise ValueError(f"--pattern {key}= must be positive, got {value:g}")
    return value


def _on(fingers: Sequence[int], duty: int) -> Pwm:
    pwm = [0] * MOTOR_COUNT
    for f in fingers:
        pwm[f] = duty
    return (pwm[0], pwm[1], pwm[2], pwm[3])


def parse_pattern(spec: str, fingers: Sequence[int], duration_s: float | None) -> PatternSpec:
    """The pattern of ``spec`` on the motors ``fingers`` (indices 0..3), for a run of
    ``duration_s`` (the ramp spans it; None: the pattern's natural length, or 2 s).
    ValueError naming the bad part and listing the valid ones."""
    if not fingers or any(not 0 <= f < MOTOR_COUNT for f in fingers):
        raise ValueError(f"fingers must be motor indices 0..{MOTOR_COUNT - 1}, got {fingers}")
    name, _, rest = spec.strip().partition(":")
    name = name.strip().lower()
    if name not in _PARAMETERS:
        raise ValueError(
            f"--pattern: unknown pattern {name!r}; one of {', '.join(PATTERN_NAMES)} "
            "(e.g. pulse:on_ms=200,off_ms=200 or ramp:from=70,to=255)"
        )
    params = dict(_PARAMETERS[name])
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if key not in params:
            known = ", ".join(params) or "none"
            raise ValueError(f"--pattern {name}: unknown key {key!r} (keys: {known})")
        try:
            number = float(value) if eq else math.nan
        except ValueError:
            number = math.nan
        if not math.isfinite(number):
            raise ValueError(f"--pattern {name}: {key}= needs a number, got {item!r}")
        params[key] = number
    fingers = tuple(fingers)

    if name in HOSTLESS_PATTERNS:
        pulses, on, off = HOSTLESS_PATTERNS[name]
        length_s = (pulses * on + (pulses - 1) * off) / 1000.0
        return PatternSpec(
            _pulses(fingers, HOSTLESS_PATTERN_DUTY, on, off, length_s), length_s, spec
        )
    if name == "pulse":
        on_ms = _positive(params["on_ms"], "on_ms")
        off_ms = params["off_ms"]
        if not 0 <= off_ms <= 3_600_000:
            raise ValueError(f"--pattern off_ms= must be 0 or more, got {off_ms:g}")
        return PatternSpec(
            _pulses(fingers, _duty(params["pwm"], "pwm"), on_ms, off_ms, None), None, spec
        )
    if name == "ramp":
        lo, hi = _duty(params["from"], "from"), _duty(params["to"], "to")
        period_s = params["period_s"]
        if period_s < 0:
            raise ValueError(
                f"--pattern period_s= must be 0 (the duration) or more, got {period_s:g}"
            )
        span_s = period_s or duration_s or 2.0

        def ramp(t_s: float) -> Pwm:
            frac = (t_s % span_s) / span_s if period_s else min(1.0, t_s / span_s)
            return _on(fingers, int(round(lo + (hi - lo) * frac)))

        return PatternSpec(ramp, None, spec)
    # sweep
    duty = _duty(params["pwm"], "pwm")
    step_s = _positive(params["step_ms"], "step_ms") / 1000.0

    def sweep(t_s: float) -> Pwm:
        return _on((fingers[int(t_s // step_s) % len(fingers)],), duty)

    return PatternSpec(sweep, None, spec)


def _pulses(
    fingers: tuple[int, ...], duty: int, on_ms: float, off_ms: float, length_s: float | None
) -> Pattern:
    period_s = (on_ms + off_ms) / 1000.0

    def pulse(t_s: float) -> Pwm:
        if length_s is not None and t_s >= length_s:
            return _on(fingers, 0)
        return _on(fingers, duty if (t_s % period_s) < on_ms / 1000.0 else 0)

    return pulse


def parse_fingers(text: str) -> tuple[int, ...]:
    """--finger: thumb|index|middle|palm|all or 1..4, comma-separated; motor indices."""
    out: list[int] = []
    for word in filter(None, (w.strip().lower() for w in text.split(","))):
        if word == "all":
            out.extend(range(MOTOR_COUNT))
        elif word in FINGER_NAMES:
            out.append(FINGER_NAMES.index(word))
        elif word.isdigit() and 1 <= int(word) <= MOTOR_COUNT:
            out.append(int(word) - 1)
        else:
            raise ValueError(
                f"--finger: {word!r} is not a finger; use {'|'.join(FINGER_NAMES)}|all or "
                f"1..{MOTOR_COUNT}, comma-separated"
            )
    if not out:
        raise ValueError("--finger: name at least one finger (e.g. --finger index)")
    return tuple(sorted(set(out)))


__all__ = [
    "PatternSpec",
    "parse_pattern",
    "parse_fingers",
    "FINGER_NAMES",
    "PATTERN_NAMES",
    "HOSTLESS_PATTERNS",
    "HOSTLESS_PATTERN_DUTY",
]
