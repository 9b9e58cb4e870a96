"""A participant's per-motor calibration: the PWM floor and gain each thimble gets.

Perceived vibration differs by finger and by person. `graspguide calibrate` measures, per
thimble, the detection threshold (the floor) and an intensity match to a reference finger
(the gain); the device then maps a motor level ``|m_i|`` to

    duty_i = round(pwm_floor_i + gain_i * G * |m_i|),  clamped to 0..255,

where ``G`` is the PWM span (185) in mode C and alpha in mode V (docs/calibration.md). The
identity calibration (floor 70, gain 1 on every motor) is the paper's mapping, bit for bit.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

from graspguide.core.reference import PWM_BASE

MOTORS = 4  # slots of SET_CALIBRATION and of a host-less plan (motors 1..4)
FINGER_NAMES = ("thumb", "index", "middle", "palm")
#: A gain outside this range is a measurement gone wrong (or a typo), not a finger.
GAIN_RANGE = (0.25, 4.0)
#: The floor is a duty of the 8-bit PWM; 255 would leave no range above it.
FLOOR_RANGE = (0, 254)


@dataclasses.dataclass(frozen=True)
class MotorCalibration:
    """Per-motor PWM floor (counts) and gain (dimensionless), motors 1..4."""

    pwm_floor: tuple[int, ...] = (PWM_BASE,) * MOTORS  # checked: MOTORS values
    gain: tuple[float, ...] = (1.0,) * MOTORS

    def __post_init__(self) -> None:
        check_calibration(self.pwm_floor, self.gain)

    @classmethod
    def identity(cls) -> MotorCalibration:
        return cls()

    def is_identity(self) -> bool:
        return self == MotorCalibration()

    def to_json(self) -> dict[str, Any]:
        return {"pwm_floor": list(self.pwm_floor), "gain": list(self.gain)}

    @classmethod
    def from_json(cls, obj: Mapping[str, Any], where: str = "calibration") -> MotorCalibration:
        """From ``{"pwm_floor": [4 ints], "gain": [4 numbers]}``; ValueError naming the
        field and ``where`` otherwise."""
        if not isinstance(obj, Mapping):
            raise ValueError(f"{where}: must be an object with pwm_floor and gain")
        missing = [k for k in ("pwm_floor", "gain") if k not in obj]
        if missing:
            raise ValueError(
                f"{where}: missing {', '.join(missing)} (pwm_floor: {MOTORS} integers "
                f"{FLOOR_RANGE[0]}..{FLOOR_RANGE[1]}; gain: {MOTORS} numbers "
                f"{GAIN_RANGE[0]:g}..{GAIN_RANGE[1]:g})"
            )
        try:
            return cls(tuple(obj["pwm_floor"]), tuple(obj["gain"]))
        except (TypeError, ValueError) as e:
            raise ValueError(f"{where}: {e}") from None


def check_calibration(pwm_floor: Sequence[Any], gain: Sequence[Any]) -> None:
    """ValueError naming the field, the motor and the allowed range."""
    for name, values in (("pwm_floor", pwm_floor), ("gain", gain)):
        if isinstance(values, (str, bytes)) or len(values) != MOTORS:
            raise ValueError(
                f"{name} must have {MOTORS} values (motors 1..{MOTORS}: "
                f"{', '.join(FINGER_NAMES)}), got {values!r}"
            )
    for i, v in enumerate(pwm_floor):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(
                f"pwm_floor[{i}] ({FINGER_NAMES[i]}) must be an integer PWM count, got {v!r}"
            )
        if not FLOOR_RANGE[0] <= v <= FLOOR_RANGE[1]:
            raise ValueError(
                f"pwm_floor[{i}] ({FINGER_NAMES[i]}) must be in "
                f"{FLOOR_RANGE[0]}..{FLOOR_RANGE[1]} (8-bit PWM counts), got {v}"
            )
    for i, v in enumerate(gain):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"gain[{i}] ({FINGER_NAMES[i]}) must be a finite number, got {v!r}")
        if not GAIN_RANGE[0] <= v <= GAIN_RANGE[1]:
            raise ValueError(
                f"gain[{i}] ({FINGER_NAMES[i]}) must be in {GAIN_RANGE[0]:g}..{GAIN_RANGE[1]:g} "
                f"(1 = the paper's mapping), got {v:g}"
            )


__all__ = [
    "MOTORS",
    "FINGER_NAMES",
    "GAIN_RANGE",
    "FLOOR_RANGE",
    "MotorCalibration",
    "check_calibration",
]
