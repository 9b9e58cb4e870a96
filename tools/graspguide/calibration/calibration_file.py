"""A participant's stored calibration, ``OUT/PID/calibration.json`` (OUT: the study
folder of `graspguide trial --out`): the MotorCalibration the device applies, and how it
was measured (every trial, the staircases' reversals, the false-alarm rate, the date, the
operator, whether the participant was simulated). Written whole or not at all, and never
over an existing file unless asked (docs/calibration.md)."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
from typing import Any

from graspguide.core.motor_calibration import MotorCalibration
from graspguide.records.files import CALIBRATION_FILE, ParticipantFiles
from graspguide.records.storage import RecordWriteError, write_json_file

SCHEMA = "graspguide-calibration/1"
FILE_NAME = CALIBRATION_FILE


class CalibrationFileError(ValueError):
    """A calibration file that cannot be read: the message names the file and field."""


@dataclasses.dataclass(frozen=True)
class CalibrationRecord:
    participant: str
    simulated: bool
    date: str
    operator: str
    calibration: MotorCalibration
    fingers: dict[str, Any]
    trials: list[dict[str, Any]]
    false_alarm_rate: float | None
    data: dict[str, Any]  # the whole file


def calibration_path(out_dir: str, participant: str) -> str:
    return ParticipantFiles.of(out_dir, participant).calibration


def write_calibration_file(path: str, data: dict[str, Any], force: bool = False) -> None:
    """Write ``data`` to ``path`` atomically (records.storage.write_json_file: a temporary
    file, fsync, then a rename, or a hard link when not ``force`` so an existing file is
    never replaced). FileExistsError when the file exists and not ``force``;
    RecordWriteError when the disk refuses."""
    folder = os.path.dirname(path) or "."
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise RecordWriteError(folder, e) from e
    try:
        write_json_file(path, data, replace=force, indent=1, sort_keys=True, allow_nan=False)
    except FileExistsError:
        raise FileExistsError(
            errno.EEXIST, f"{path} exists: add --force to replace it", path
        ) from None


def _need(cond: bool, path: str, field: str, what: str, value: Any = None) -> None:
    if not cond:
        got = "" if value is None else f", got {value!r}"
        raise CalibrationFileError(f"{path}: field {field!r} must be {what}{got}")


def read_calibration_file(path: str) -> CalibrationRecord:
    """The calibration at ``path``; CalibrationFileError naming the file and the field
    that is missing or wrong."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise CalibrationFileError(
            f"{path}: no such file (run `graspguide calibrate` for this participant)"
        ) from None
    except OSError as e:
        raise CalibrationFileError(f"{path}: cannot read: {e.strerror or e}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CalibrationFileError(f"{path}: not JSON ({e})") from None
    _need(isinstance(data, dict), path, "(top level)", "an object")
    _need(data.get("schema") == SCHEMA, path, "schema", repr(SCHEMA), data.get("schema"))
    for key in ("participant", "date", "operator"):
        _need(isinstance(data.get(key), str), path, key, "a string", data.get(key))
    _need(
        isinstance(data.get("simulated"), bool),
        path,
        "simulated",
        "true or false",
        data.get("simulated"),
    )
    _need("calibration" in data, path, "calibration", "present (pwm_floor and gain)")
    try:
        cal = MotorCalibration.from_json(data["calibration"], where=f"{path}: calibration")
    except ValueError as e:
        raise CalibrationFileError(str(e)) from None
    _need(isinstance(data.get("fingers"), dict), path, "fingers", "an object")
    _need(isinstance(data.get("trials"), list), path, "trials", "a list")
    fa = data.get("false_alarm_rate")
    _need(
        fa is None or (isinstance(fa, (int, float)) and not isinstance(fa, bool) and 0 <= fa <= 1),
        path,
        "false_alarm_rate",
        "null or a number 0..1",
        fa,
    )
    return CalibrationRecord(
        participant=data["participant"],
        simulated=data["simulated"],
        date=data["date"],
        operator=data["operator"],
        calibration=cal,
        fingers=data["fingers"],
        trials=data["trials"],
        false_alarm_rate=fa,
        data=data,
    )


def load_participant_calibration(out_dir: str, participant: str) -> MotorCalibration | None:
    """The runner's hook: the participant's stored calibration, or None when there is
    none (CalibrationFileError when there is one that cannot be read)."""
    path = calibration_path(out_dir, participant)
    if not os.path.exists(path):
        return None
    record = read_calibration_file(path)
    if record.participant != participant:
        raise CalibrationFileError(
            f"{path}: field 'participant' is {record.participant!r}, not {participant!r}: "
            "the file belongs to another participant"
        )
    return record.calibration


def read_calibration(path: str) -> MotorCalibration:
    """``--calibration FILE``: the file `graspguide calibrate` writes (checked whole), or a
    bare ``{"pwm_floor": [4 counts], "gain": [4 numbers]}``; CalibrationFileError naming
    the file and what is wrong (a plan must never be built from a half-read calibration)."""
    try:
        with open(path, encoding="utf-8") as f:
            obj = json.load(f)
    except FileNotFoundError:
        raise CalibrationFileError(
            f"calibration file {path} does not exist: give the calibration.json that "
            "`graspguide calibrate` wrote (OUT/PID/calibration.json)"
        ) from None
    except OSError as e:
        raise CalibrationFileError(
            f"calibration file {path} cannot be read: {e.strerror or e}"
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CalibrationFileError(
            f"calibration file {path} is not JSON ({e}): it must hold "
            '{"pwm_floor": [4 integers], "gain": [4 numbers]}'
        ) from None
    if isinstance(obj, dict) and "schema" in obj:
        return read_calibration_file(path).calibration
    try:
        return MotorCalibration.from_json(obj, where=f"calibration file {path}")
    except ValueError as e:
        raise CalibrationFileError(str(e)) from None


def describe(cal: MotorCalibration) -> str:
    """One line for the terminal: the floors and gains of motors 1..4."""
    floors = ", ".join(str(v) for v in cal.pwm_floor)
    gains = ", ".join(f"{v:g}" for v in cal.gain)
    return f"PWM floor {floors}; gain {gains} (motors 1..4)"


__all__ = [
    "SCHEMA",
    "FILE_NAME",
    "CalibrationFileError",
    "CalibrationRecord",
    "calibration_path",
    "write_calibration_file",
    "read_calibration_file",
    "load_participant_calibration",
    "read_calibration",
    "describe",
]
