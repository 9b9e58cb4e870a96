"""`graspguide trial` applies the participant's stored calibration (OUT/PID/calibration.json,
written by `graspguide calibrate`) on the device, logs it, and sends the identity when
there is none, so a device never keeps an earlier participant's calibration.

Whether the device applied it is read from the trial frames themselves: in mode C a
posture's PWM is constant, so a motor's uncalibrated duty p = round(70 + 185 |m|) bounds
|m| to +-0.5 / 185, and the calibrated duty must be round(floor + 185 gain |m|) for a
|m| in that interval."""

from __future__ import annotations

import csv
import json
import os

import pytest
from conftest import small_protocol_toml

from graspguide.calibration.calibration_file import calibration_path
from graspguide.cli import main
from graspguide.core.reference import PWM_BASE, PWM_RANGE


@pytest.fixture
def protocol(tmp_path):
    path = tmp_path / "fc.toml"
    path.write_text(
        small_protocol_toml("calibrated", seed=5, participants=1, modalities=("F+C",), wrenches=2)
    )
    return str(path)


def _trial(protocol: str, out: str) -> int:
    return main(
        [
            "trial",
            "--protocol",
            protocol,
            "--participant",
            "U1",
            "--port",
            "sim",
            "--source",
            "participant",
            "--out",
            out,
        ]
    )


def _first_pwm(out: str) -> dict[int, list[int]]:
    """trial_index -> the PWM of its first frame whose solver status is ok."""
    firsts = {}
    with open(os.path.join(out, "U1", "trials.jsonl"), encoding="utf-8") as f:
        for line in f:
            index = json.loads(line)["trial_index"]
            frames = os.path.join(out, "U1", "frames", f"trial-{index:04d}.csv")
            with open(frames, encoding="utf-8") as g:
                for row in csv.DictReader(g):
                    if int(row["solver_status"]) == 0:
                        firsts[index] = [int(row[f"pwm{i}"]) for i in range(4)]
                        break
    return firsts


def _run_start(out: str) -> dict:
    with open(os.path.join(out, "U1", "runs.jsonl"), encoding="utf-8") as f:
        return next(r for r in map(json.loads, f) if r.get("event") == "start")


def _store_calibration(out: str, cal: dict) -> None:
    """OUT/U1/calibration.json as `graspguide calibrate` writes it (the virtual participant
    answering), its calibration then replaced by ``cal`` as it is, unchecked."""
    assert (
        main(
            [
                "calibrate",
                "--participant",
                "U1",
                "--port",
                "sim",
                "--source",
                "participant:seed=2",
                "--out",
                out,
            ]
        )
        == 0
    )
    path = calibration_path(out, "U1")
    with open(path, encoding="utf-8") as f:
        record = json.load(f)
    record["calibration"] = cal
    with open(path, "w", encoding="utf-8") as f:
        json.dump(record, f)


def test_trial_applies_the_stored_calibration(tmp_path, protocol):
    plain, calibrated = str(tmp_path / "plain"), str(tmp_path / "cal")
    assert _trial(protocol, plain) == 0
    cal = {"pwm_floor": [90, 75, 100, 70], "gain": [1.3, 0.8, 1.1, 1.0]}
    _store_calibration(calibrated, cal)
    assert _trial(protocol, calibrated) == 0
    assert _run_start(calibrated)["calibration"] == cal
    assert _run_start(plain)["calibration"] is None

    before, after = _first_pwm(plain), _first_pwm(calibrated)
    assert before.keys() == after.keys() and before
    motors_checked = 0
    for index, p_plain in before.items():
        for i, (p, q) in enumerate(zip(p_plain, after[index], strict=True)):
            if p == 0:
                assert q == 0, (index, i)
                continue
            lo = (p - 0.5 - PWM_BASE) / PWM_RANGE
            hi = (p + 0.5 - PWM_BASE) / PWM_RANGE
            floor, gain = cal["pwm_floor"][i], cal["gain"][i]
            allowed = range(
                min(255, round(floor + PWM_RANGE * gain * max(lo, 0.0) - 0.5)),
                min(255, round(floor + PWM_RANGE * gain * hi + 0.5)) + 1,
            )
            assert q in allowed, (index, i, p, q, allowed)
            motors_checked += 1
    assert motors_checked >= 3


def test_a_bad_calibration_file_stops_the_run_before_the_device(tmp_path, protocol, capsys):
    out = str(tmp_path / "bad")
    _store_calibration(out, {"pwm_floor": [70, 70, 70], "gain": [1.0, 1.0, 1.0, 1.0]})
    assert _trial(protocol, out) == 2
    err = capsys.readouterr().err
    assert "calibration.json" in err and ("pwm_floor" in err or "gain" in err), err
    assert not os.path.exists(os.path.join(out, "U1", "trials.jsonl"))
