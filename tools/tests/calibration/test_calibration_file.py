"""The stored calibration (graspguide.calibration.calibration_file): what is written is
what is read back, a bad file is an error that names the file and the field, an existing
file is never replaced without force, and a write that fails leaves nothing behind."""

from __future__ import annotations

import json
import os

import pytest

from graspguide.calibration.calibration_file import (
    CalibrationFileError,
    calibration_path,
    load_participant_calibration,
    read_calibration_file,
    write_calibration_file,
)
from graspguide.calibration.command import _file_data
from graspguide.calibration.session import CalibrationSettings, run_procedure
from graspguide.calibration.virtual_observer import VirtualObserver
from graspguide.core.motor_calibration import MotorCalibration
from graspguide.records.storage import RecordWriteError


class _NoDevice:
    def detection(self, finger, pwm):
        pass

    def pair(self, first, second):
        pass


@pytest.fixture(scope="module")
def data():
    obs = VirtualObserver(11)
    result = run_procedure(CalibrationSettings(seed=11), obs, _NoDevice())
    device = {"port": "test", "board": "none", "firmware": "0.0.0", "protocol_version": 0}
    return _file_data(result, "U4", "tester", obs, device, 1.0)


def test_round_trip(tmp_path, data):
    path = calibration_path(str(tmp_path), "U4")
    write_calibration_file(path, data)
    rec = read_calibration_file(path)
    assert rec.calibration == MotorCalibration.from_json(data["calibration"])
    assert rec.participant == "U4" and rec.simulated is True and rec.operator == "tester"
    assert rec.trials == data["trials"] and rec.fingers == data["fingers"]
    assert rec.false_alarm_rate == data["false_alarm_rate"]
    assert rec.data["virtual_participant"]["seed"] == 11
    assert load_participant_calibration(str(tmp_path), "U4") == rec.calibration
    assert load_participant_calibration(str(tmp_path), "U5") is None
    assert os.listdir(tmp_path / "U4") == ["calibration.json"]  # no temporary file left


def test_never_replaced_without_force(tmp_path, data):
    path = calibration_path(str(tmp_path), "U4")
    write_calibration_file(path, data)
    before = open(path).read()
    changed = dict(data, operator="someone else")
    with pytest.raises(FileExistsError, match="add --force"):
        write_calibration_file(path, changed)
    assert open(path).read() == before
    write_calibration_file(path, changed, force=True)
    assert read_calibration_file(path).operator == "someone else"
    assert os.listdir(tmp_path / "U4") == ["calibration.json"]


def test_a_failed_write_leaves_nothing(tmp_path, data):
    blocker = tmp_path / "U4"
    blocker.write_text("a file where the participant's folder should be")
    with pytest.raises(RecordWriteError, match="U4"):
        write_calibration_file(calibration_path(str(tmp_path), "U4"), data)
    assert blocker.read_text().startswith("a file")
    bad = dict(data, elapsed_s=float("nan"))  # not JSON: the encoder refuses it
    path = calibration_path(str(tmp_path / "x"), "U4")
    with pytest.raises(ValueError):
        write_calibration_file(path, bad)
    assert os.listdir(tmp_path / "x" / "U4") == []


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda d: d.pop("simulated"), "field 'simulated' must be true or false"),
        (lambda d: d.update(simulated="yes"), "field 'simulated' must be true or false"),
        (lambda d: d.update(schema="other/9"), "field 'schema' must be"),
        (lambda d: d.pop("participant"), "field 'participant' must be a string"),
        (lambda d: d.pop("calibration"), "field 'calibration' must be present"),
        (
            lambda d: d["calibration"]["gain"].__setitem__(0, 9.0),
            r"calibration: gain\[0\] \(thumb\)",
        ),
        (lambda d: d["calibration"].pop("pwm_floor"), "calibration: missing pwm_floor"),
        (lambda d: d["calibration"]["pwm_floor"].__setitem__(2, 300), r"pwm_floor\[2\] \(middle\)"),
        (lambda d: d.update(trials={}), "field 'trials' must be a list"),
        (lambda d: d.update(false_alarm_rate=1.5), "field 'false_alarm_rate'"),
    ],
)
def test_bad_file_names_the_field(tmp_path, data, change, message):
    bad = json.loads(json.dumps(data))
    change(bad)
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(CalibrationFileError, match=message) as info:
        read_calibration_file(str(path))
    assert str(path) in str(info.value)


def test_unreadable_files(tmp_path, data):
    path = tmp_path / "calibration.json"
    with pytest.raises(CalibrationFileError, match="no such file .*graspguide calibrate"):
        read_calibration_file(str(path))
    path.write_text("{not json")
    with pytest.raises(CalibrationFileError, match="not JSON"):
        read_calibration_file(str(path))
    other = calibration_path(str(tmp_path), "U9")
    write_calibration_file(other, data)  # U4's file in U9's folder
    with pytest.raises(CalibrationFileError, match="field 'participant' is 'U4', not 'U9'"):
        load_participant_calibration(str(tmp_path), "U9")
