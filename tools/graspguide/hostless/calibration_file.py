"""A participant's calibration file for a host-less plan: `--calibration FILE` of
`graspguide plan` and `graspguide device plan`, and OUT/PID/calibration.json, which
`graspguide calibrate` writes and `graspguide trial --hostless` picks up by itself.

``--calibration FILE`` takes the file `graspguide calibrate` writes (checked whole by
graspguide.calibration.calibration_file) or a bare ``{"pwm_floor": [4 counts], "gain": [4
numbers]}`` (MotorCalibration.from_json). OUT/PID/calibration.json is read by the same
function the tracker-driven `graspguide trial` uses, so both runs take the same file the same
way. Every problem is a ValueError naming the file, the field and the fix: a plan must never
be built from a calibration that was half read."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping

from graspguide.core.motor_calibration import MotorCalibration

#: Where `graspguide calibrate` leaves a participant's calibration in a study folder.
CALIBRATION_FILE = "calibration.json"


def read_calibration(path: str) -> MotorCalibration:
    """The calibration in ``path``; ValueError naming the file and what is wrong."""
    try:
        with open(path, encoding="utf-8") as f:
            obj = json.load(f)
    except FileNotFoundError:
        raise ValueError(
            f"calibration file {path} does not exist: give the calibration.json that "
            "`graspguide calibrate` wrote (OUT/PID/calibration.json)"
        ) from None
    except OSError as e:
        raise ValueError(f"calibration file {path} cannot be read: {e.strerror or e}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(
            f"calibration file {path} is not JSON ({e}): it must hold "
            '{"pwm_floor": [4 integers], "gain": [4 numbers]}'
        ) from None
    if isinstance(obj, Mapping) and "schema" in obj:  # what `graspguide calibrate` wrote
        from graspguide.calibration.calibration_file import read_calibration_file

        return read_calibration_file(path).calibration
    return MotorCalibration.from_json(obj, where=f"calibration file {path}")


def participant_calibration_path(out_dir: str, participant: str) -> str:
    """OUT/PID/calibration.json: where `graspguide calibrate` stores ``participant``'s."""
    return os.path.join(out_dir, participant, CALIBRATION_FILE)


def participant_calibration(
    out_dir: str, participant: str
) -> tuple[MotorCalibration | None, str | None]:
    """(the calibration, its file) from OUT/PID/calibration.json, or (None, None) when the
    participant has none (the device then keeps the identity, the paper's mapping). A file
    that is there but wrong, or another participant's, is a ValueError: running a study
    with the identity instead of the participant's measured calibration would go
    unnoticed."""
    from graspguide.calibration.calibration_file import load_participant_calibration

    cal = load_participant_calibration(out_dir, participant)
    if cal is None:
        return None, None
    return cal, participant_calibration_path(out_dir, participant)


def describe(cal: MotorCalibration) -> str:
    """One line for the terminal: the floors and gains of motors 1..4."""
    floors = ", ".join(str(v) for v in cal.pwm_floor)
    gains = ", ".join(f"{v:g}" for v in cal.gain)
    return f"PWM floor {floors}; gain {gains} (motors 1..4)"


__all__ = [
    "CALIBRATION_FILE",
    "describe",
    "participant_calibration",
    "participant_calibration_path",
    "read_calibration",
]
