"""SET_CALIBRATION on the devices (a participant's per-motor PWM floor and gain):
the simulated device (`--port sim`), the Pro Mini sketch under simavr (`--port
promini-sim`, its posture solved on the host) and the m4f firmware on QEMU (`--port qemu`).

On each: a trial after SET_CALIBRATION reports, in every TELEMETRY, the PWM of the float64
reference (graspguide.core.reference.pwm_from_levels with that calibration) on the levels
the host core solves in float and the alpha the device reports; the identity gives back the
PWM of an uncalibrated device exactly; the values a device must refuse (a floor of 255, a
NaN gain, a gain of 5) and a calibration during a trial raise DeviceError naming the field
or the state, and leave the previous calibration in force; SET_MOTORS stays raw (the bench
drive a calibration measures with). The simulated device and simavr come from
tools/bootstrap.sh: their absence is a failure. QEMU is skipped, with the reason, when
qemu-system-arm or the firmware ELF is missing (as tools/tests/test_qemu_firmware.py).
"""

from __future__ import annotations

import csv
import math
import os
import shutil
import statistics
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT

from graspguide.core import reference, solver
from graspguide.core.motor_calibration import MotorCalibration
from graspguide.devices import promini_sim as pms
from graspguide.devices import qemu_firmware
from graspguide.devices import sim as gsim
from graspguide.link import client as gd
from graspguide.link import messages as m

ROOT = Path(REPO_ROOT)
HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
WRENCH = [0.3, -1.2, -0.8, 0.0, 0.0, 0.0]
SWEEP_AXIS = (0.6, 0.0, 0.8)
# Floors and gains far from the identity on every motor, each within the allowed ranges.
CALIBRATION = MotorCalibration(pwm_floor=(40, 95, 120, 60), gain=(1.7, 0.6, 2.35, 1.1))
RAW_DRIVE = (100, 120, 140, 0)  # SET_MOTORS duties, none equal to a calibrated one
QEMU_ELF = os.environ.get(qemu_firmware.QEMU_FIRMWARE_ENV) or str(
    ROOT / qemu_firmware.FIRMWARE_RELATIVE_PATH
)
FIRST_ANSWER_TIMEOUT = 5.0  # QEMU polls an unopened pty once a second


class Board:
    """A started device, a client on it, and how to read what its motors carry."""

    def __init__(self, kind: str, transport, trace: Path | None):
        self.kind, self.transport, self.trace = kind, transport, trace
        self.client = gd.DeviceClient(transport, timeout=3.0)
        self.client.hello(timeout=FIRST_ANSWER_TIMEOUT)

    def motor_states(self) -> list[tuple[int, ...]]:
        """Every PWM state the motors took (a trace), or the last one (QEMU's registers)."""
        if self.trace is None:
            return [tuple(self.transport.motor_registers())]
        with open(self.trace) as f:
            rows = list(csv.reader(f))
        return [tuple(int(v) for v in r[1:]) for r in rows[1:]]


@pytest.fixture(scope="module", params=["sim", "promini-sim", "qemu"])
def board(request, tmp_path_factory) -> Iterator[Board]:
    kind = request.param
    trace = tmp_path_factory.mktemp(kind) / "motors.csv"
    if kind == "sim":
        transport = gsim.SimulatedDevice(virtual_clock=True, trace=str(trace)).start()
    elif kind == "promini-sim":
        elf = request.getfixturevalue("sketch_elf")
        transport = pms.ProMiniSimDevice(elf=elf, trace=str(trace)).start()
    else:
        if shutil.which("qemu-system-arm") is None:
            pytest.skip("qemu-system-arm is not installed (as root: tools/install-arm.sh)")
        if not os.path.isfile(QEMU_ELF):
            pytest.skip(f"the QEMU firmware {QEMU_ELF} is not built: `pio run -e m4f_firmware`")
        transport = qemu_firmware.QemuFirmwareDevice(elf=QEMU_ELF).start()
        trace = None
    try:
        yield Board(kind, transport, trace)
    finally:
        transport.close()


@pytest.fixture
def dev(board) -> Board:
    board.client.stop()
    board.client.set_calibration(MotorCalibration.identity())
    board.client.drain()
    board.client.trial_results.clear()
    return board


def sweep(n: int, from_deg: float = 60.0, to_deg: float = 20.0) -> list[tuple[float, ...]]:
    """Orientations turning towards the identity about one axis: the error falls but stays
    above the success threshold, so the trial keeps running and alpha changes every pose."""
    out = []
    for i in range(n):
        a = math.radians(from_deg + (to_deg - from_deg) * i / (n - 1))
        s = math.sin(a / 2)
        out.append((math.cos(a / 2), s * SWEEP_AXIS[0], s * SWEEP_AXIS[1], s * SWEEP_AXIS[2]))
    return out


def run_trial(c: gd.DeviceClient, mode: str, n: int = 30) -> list[m.Telemetry]:
    c.set_scene(HAND3, mode=mode)
    c.start_trial(7, WRENCH)
    out = []
    for i, q in enumerate(sweep(n)):
        tel = c.pose(1_000 + i * 10_000, q)
        assert tel.solver_status is m.ErrorCode.OK, tel
        out.append(tel)
    c.stop()
    return out


def reference_pwm(tel: m.Telemetry, mode: str, cal: MotorCalibration | None) -> list[int]:
    """The float64 reference's PWM on the host core's float levels and the device's alpha."""
    levels = solver.solve(HAND3, WRENCH, mode=mode, scalar="float")["levels"]
    return reference.pwm_from_levels(np.asarray(levels), mode, float(tel.alpha), cal)


@pytest.mark.parametrize("mode", ["C", "V"])
def test_telemetry_pwm_is_the_references_with_the_calibration(dev, mode, report_figure):
    dev.client.set_calibration(CALIBRATION)
    telemetry = run_trial(dev.client, mode)
    diffs = []
    for tel in telemetry:
        want = reference_pwm(tel, mode, CALIBRATION)
        diffs.append(max(abs(a - b) for a, b in zip(tel.pwm[:3], want)))
        assert tel.pwm[3] == 0
    report_figure(
        f"{dev.kind}: calibrated TELEMETRY PWM vs float64 reference (mode {mode})",
        f"{diffs.count(0)}/{len(diffs)} poses exact, largest difference {max(diffs)}",
    )
    assert any(any(t.pwm) for t in telemetry), "the sweep drives the motors"
    assert max(diffs) == 0, diffs


def test_the_identity_gives_back_the_uncalibrated_pwm(dev):
    before = [tuple(t.pwm) for t in run_trial(dev.client, "V")]
    dev.client.set_calibration(CALIBRATION)
    calibrated = [tuple(t.pwm) for t in run_trial(dev.client, "V")]
    dev.client.set_calibration(MotorCalibration.identity())
    after = [tuple(t.pwm) for t in run_trial(dev.client, "V")]
    assert calibrated != before
    assert after == before


@pytest.mark.parametrize(
    "floors, gains, field",
    [
        ((70, 70, 255, 70), (1.0, 1.0, 1.0, 1.0), "pwm_floor"),
        ((70, 70, 70, 70), (1.0, math.nan, 1.0, 1.0), "gain"),
        ((70, 70, 70, 70), (1.0, 1.0, 1.0, 5.0), "gain"),
    ],
)
def test_bad_values_are_refused_naming_the_field_and_the_previous_calibration_stays(
    dev, floors, gains, field
):
    dev.client.set_calibration(CALIBRATION)
    with pytest.raises(gd.DeviceError) as e:
        dev.client.set_calibration(m.SetCalibration(pwm_floor=floors, gain=gains))
    assert e.value.code_name == "bad_config"
    assert m.SetCalibration.FIELDS[e.value.detail].name == field
    assert repr(field) in str(e.value)
    tel = run_trial(dev.client, "V", n=5)
    assert [list(t.pwm[:3]) for t in tel] == [reference_pwm(t, "V", CALIBRATION)[:3] for t in tel]


def test_a_calibration_during_a_trial_is_refused(dev):
    dev.client.set_scene(HAND3, mode="V")
    dev.client.start_trial(8, WRENCH)
    dev.client.pose(1_000, sweep(2)[0])
    with pytest.raises(gd.DeviceError) as e:
        dev.client.set_calibration(CALIBRATION)
    assert e.value.code_name == "not_allowed_in_state"
    assert "trial_running" in str(e.value)
    dev.client.stop()


def test_set_motors_stays_raw_under_a_calibration(dev):
    dev.client.set_calibration(CALIBRATION)
    dev.client.set_motors(RAW_DRIVE)
    deadline = time.monotonic() + 2.0
    while RAW_DRIVE not in dev.motor_states() and time.monotonic() < deadline:
        time.sleep(0.01)
    states = dev.motor_states()
    dev.client.stop()
    assert RAW_DRIVE in states, states[-5:]


def _message_cycles(elf: str, marks: Path, cal: MotorCalibration, mode: str) -> dict[str, float]:
    """Cycles of each message's handling on the sketch (its marks: one per frame handled)."""
    with pms.ProMiniSimDevice(elf=elf, marks=str(marks)) as transport:
        c = gd.DeviceClient(transport, timeout=3.0)
        c.hello(timeout=FIRST_ANSWER_TIMEOUT)
        c.set_scene(HAND3, mode=mode)  # kept on the host: no message
        c.set_calibration(cal)
        c.start_trial(9, WRENCH)  # SET_POSTURE, START_TRIAL
        for i, q in enumerate(sweep(200, from_deg=80.0)):
            c.pose(1_000 + i * 10_000, q)
        c.stop()
    cycles = [int(x) for x in marks.read_text().split()]
    assert len(cycles) == 200 + 5, len(cycles)
    return {
        "SET_CALIBRATION": cycles[1],
        "SET_POSTURE": cycles[2],
        "POSE": statistics.median(cycles[4:-1]),
    }


@pytest.mark.parametrize("mode", ["C", "V"])
def test_what_a_calibration_costs_the_pro_mini(sketch_elf, tmp_path, mode, report_figure):
    """A calibrated plan is paid once per posture; a frame stays one multiply-add per motor
    (docs/per-frame-layer.md quotes these figures)."""
    plain = _message_cycles(sketch_elf, tmp_path / "i.txt", MotorCalibration.identity(), mode)
    cal = _message_cycles(sketch_elf, tmp_path / "c.txt", CALIBRATION, mode)
    report_figure(
        f"promini-sim cycles, identity -> calibrated (mode {mode})",
        ", ".join(f"{k} {plain[k]:,.0f} -> {cal[k]:,.0f}" for k in plain),
    )
    assert cal["POSE"] <= 1.02 * plain["POSE"], (plain, cal)
    assert cal["SET_POSTURE"] <= 1.25 * plain["SET_POSTURE"], (plain, cal)
