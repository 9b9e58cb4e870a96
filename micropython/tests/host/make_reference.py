"""HOST side (CPython with numpy and the installed graspguide package, not MicroPython):
writes the data the port's interpreter tests compare against, from independent sources:

  tests/data/frame_reference.json   error/alpha and PWM (also under motor calibrations)
      from the float64 reference (graspguide.core.reference: atan2 of the rotated force,
      round-half-away PWM), and
      the C++ gravity estimator (graspguide.core._core, double) on a simulated IMU stream;
  tests/data/hostless_script.json   one host-less trial of the virtual participant: the
      IMU samples (graspguide.hostless.imu_world) of a hand the virtual participant moves
      in reaction to the PWM a host-side device shows (the C++ estimator, the reference's
      error, PWM under the script's motor calibration, levels from the C++ core), and
      that device's PWM and trial outcome.
      SIMULATED: a model, never a measurement.

    python micropython/tests/host/make_reference.py

tools/tests/test_micropython_formats.py regenerates both and checks the committed files
agree, so they cannot drift from the C++ and the reference."""

import json
import math
import os
import sys

import numpy as np

from graspguide.core import _core, reference
from graspguide.core.motor_calibration import MotorCalibration
from graspguide.hostless.imu_world import ImuWorld
from graspguide.imu.synthetic import sweep_poses
from graspguide.participant.model import VirtualParticipant

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "data")
HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
SEED = 14


def f32(x):
    return float(np.float32(x))


def rot(q):
    return reference.quaternion_to_matrix(np.asarray(q, dtype=float))


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def alignment_cases(rng):
    """(gravity in the hand frame, f_hat, error_deg, alpha): random poses, and angles at
    the formula's range boundaries and ends, at several gravity lengths."""
    cases = []
    angles = [0.0, 1e-7, 0.01, 3.0, 59.999, 60.0, 60.001, 119.999, 120.0, 120.001, 179.99, 179.9999]
    for i in range(60 + len(angles)):
        q = unit(rng.normal(size=4))
        g = rot(q).T @ np.array([0.0, 0.0, -1.0])
        if i < 60:
            f = unit(rng.normal(size=3))
        else:
            # f at a chosen angle from g: along g, turned about a random perpendicular.
            th = math.radians(angles[i - 60])
            u = unit(np.cross(g, rng.normal(size=3)))
            f = unit(math.cos(th) * g + math.sin(th) * u)
        err, alpha = reference.guidance(q, f)
        scale = [1.0, 9.80665, 1e-3, 1e200][i % 4]
        cases.append([list(g * scale), list(f), err, alpha])
    return cases


def pwm_cases(rng):
    """(levels, mode, alpha, pwm) from the reference's PWM rounding."""
    cases = []
    special = [0.0, 1e-3, 1.0001e-3, -0.25, 1.0, -1.0, 0.5, 2.0]
    for i in range(80):
        k = 3 + (i % 2)
        levels = list(rng.uniform(-1.0, 1.0, size=k))
        levels[i % k] = special[i % len(special)]
        mode = "C" if i % 3 == 0 else "V"
        alpha = (
            float(rng.uniform(0.0, 185.0)) if i % 5 else [0.0, 185.0, 92.5, 1e-9, 184.999][i % 4]
        )
        if mode == "V" and i % 7 == 0:
            # A duty exactly half-way between two integers: the rounding rule decides.
            a = abs(levels[0]) if abs(levels[0]) > 1e-3 else 0.5
            alpha = (100.5 - 70.0) / a
        pwm = reference.pwm_from_levels(np.asarray(levels), mode, alpha)
        cases.append([levels, mode, alpha, pwm])
    return cases


def calibrated_pwm(levels, mode, alpha, floor, gain):
    """The float64 reference's PWM under a calibration: floor_i + G (gain_i |m_i|), rounded
    half away from zero and clamped (G = 185 in mode C, alpha in mode V)."""
    cal = MotorCalibration(tuple(int(f) for f in floor), tuple(float(g) for g in gain))
    return reference.pwm_from_levels(np.asarray(levels, dtype=float), mode, alpha, cal)


def pwm_calibrated_cases(rng):
    """(levels, mode, alpha, pwm_floor, gain, pwm, the identity's pwm): random calibrations
    in the calibration's ranges (floors 0..254, gains 0.25..4, float32 as stored), edges of
    both, and duties exactly half-way between two integers."""
    cases = []
    for i in range(80):
        k = 3 + (i % 2)
        levels = list(rng.uniform(-1.0, 1.0, size=k))
        if i % 9 == 0:
            levels[i % k] = [0.0, 1e-3, 1.0001e-3][i % 3]
        mode = "C" if i % 3 == 0 else "V"
        alpha = float(rng.uniform(0.0, 185.0))
        floor = [int(x) for x in rng.integers(0, 255, size=4)]
        gain = [f32(x) for x in rng.uniform(0.25, 4.0, size=4)]
        if i % 10 == 1:
            floor = [0, 254, 70, 1]
            gain = [0.25, 4.0, 1.0, 0.25]
        if mode == "V" and i % 7 == 0:
            # A duty exactly half-way: gain_i |m_i| and alpha chosen so x = floor + 20.5.
            gain[0] = 0.5
            levels[0] = 0.5
            alpha = 20.5 / 0.25
        pwm = calibrated_pwm(levels, mode, alpha, floor, gain)
        identity = reference.pwm_from_levels(np.asarray(levels), mode, alpha)
        cases.append([levels, mode, alpha, floor, gain, pwm, identity])
    return cases


def estimator_case():
    """A 100 Hz sweep (harder than guidance) with knocks that the gate must drop, through
    the C++ estimator in double: inputs and the gravity and bias after each sample."""
    rate = 100.0
    poses = sweep_poses(rate, 12.0)
    world = ImuWorld(rate, SEED)
    accel, gyro = [], []
    for i, q in enumerate(poses):
        s = world.sample(i / rate, q)
        a = list(s.accel_mps2)
        if i % 97 == 50:  # a knock: far from 1 g, not trusted
            a = [a[0] + 15.0, a[1], a[2]]
        accel.append([f32(x) for x in a])
        gyro.append([f32(x) for x in s.gyro_radps])
    est = _core.GravityEstimator("double")
    gravity, bias, trusted = [], [], []
    for a, g in zip(accel, gyro):
        status = est.update(a, g, 0.01)
        if status != "ok":
            raise SystemExit(f"the C++ estimator refused a sample: {status}")
        gravity.append(list(est.gravity))
        bias.append(list(est.bias_radps))
        trusted.append(bool(est.accel_trusted))
    return {
        "dt_s": 0.01,
        "accel": accel,
        "gyro": gyro,
        "gravity": gravity,
        "bias": bias,
        "trusted": trusted,
    }


def hostless_script():
    """One trial: rest, ready, the button, guidance until success, then the end pattern,
    with the virtual participant's hand in the loop of a host-side device."""
    period_us = 10000
    mount = [math.cos(math.pi / 8), 0.0, 0.0, math.sin(math.pi / 8)]  # 45 deg about z
    mount32 = [f32(x) for x in mount]
    wrench = [f32(x) for x in (0.0, -0.6, -0.8, 0.001, 0.0, 0.002)]
    hand = [[f32(x) for x in c] for c in HAND3]
    header = {
        "participant": "MP1",
        "threshold_deg": 3.0,
        "hold_s": 0.5,
        "timeout_s": 90.0,
        "rest_s": 2.0,
        "y_axis": [0.0, 1.0, 0.0],
        "hand_k3": hand,
        "imu_to_hand_wxyz": mount32,
        # A participant's calibration (exact in float32), so the trial tests applying it.
        "pwm_floor": [60, 80, 75, 70],
        "gain": [1.5, 0.75, 1.25, 1.0],
    }
    trial = {
        "trial_index": 1,
        "session": 1,
        "session_trial": 1,
        "k": 3,
        "policy": 0,
        "mode": 1,
        "wrench": wrench,
    }
    solved = _core.solve(
        hand,
        wrench,
        "F",
        "V",
        "paper",
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        "double",
        "structured",
        64,
    )
    if solved["status"] != "ok":
        raise SystemExit(f"the C++ core refused the script's posture: {solved['status']}")
    levels = list(solved["levels"])
    f_hat = unit(wrench[:3])
    r_mount = rot(np.asarray(mount32) / np.linalg.norm(mount32))
    world = ImuWorld(100.0, SEED, imu_to_hand_wxyz=mount)
    # The population's median participant with exact position sense: the script tests the
    # port's trial loop, not the model's spread, and a short success keeps the file small.
    model = VirtualParticipant.from_spec(
        "participant:vary=0,prop_bias_sd_deg=0,prop_trial_sd_deg=0,prop_drift_frac=0", SEED
    )
    est = _core.GravityEstimator("double")
    q_start = np.array([1.0, 0.0, 0.0, 0.0])
    button_us = 3_000_000 + 5000  # after rest (2 s) and the ready pattern (0.45 s)
    samples, pwm_log = [], []
    q = q_start
    pwm = [0, 0, 0]
    entry_us = None
    success_at = None
    i = 0
    while True:
        i += 1
        t_us = i * period_us
        if t_us > button_us:
            t_rel = (t_us - button_us) / 1e6
            if success_at is None:
                if not pwm_log:
                    model.begin_trial(
                        contacts=hand,
                        y_axis=[0.0, 1.0, 0.0],
                        wrench=wrench,
                        policy="F",
                        mode="V",
                        start_quat=list(q_start),
                    )
                    model.step(0.0, [0, 0, 0])
                q = np.asarray(model.step(t_rel, pwm), dtype=float)
        s = world.sample(t_us / 1e6, q)
        a = [f32(x) for x in s.accel_mps2]
        g = [f32(x) for x in s.gyro_radps]
        samples.append([t_us] + a + g)
        # The device feeds its estimator only once the IMU rule trusts the IMU: from the
        # recovery count's sample on (imu_watchdog.h: 10 good samples).
        if i >= 10:
            status = est.update(a, g, 0.01)
            if status != "ok":
                raise SystemExit(f"the C++ estimator refused sample {i}: {status}")
        if t_us > button_us and success_at is None:
            g_hand = r_mount @ np.asarray(est.gravity)
            d = unit(g_hand)
            err = math.degrees(math.atan2(np.linalg.norm(np.cross(f_hat, d)), float(f_hat @ d)))
            alpha = float(np.linalg.norm(f_hat - d)) / 2.0 * 185.0
            elapsed = t_us - button_us
            if err <= header["threshold_deg"]:
                entry_us = t_us if entry_us is None else entry_us
                if t_us - entry_us >= 500_000:
                    success_at = len(samples) - 1
                    completion_s = elapsed / 1e6
                    pwm = [0, 0, 0]
            else:
                entry_us = None
            if success_at is None:
                pwm = calibrated_pwm(levels, "V", alpha, header["pwm_floor"], header["gain"])
            pwm_log.append(
                {"sample": len(samples) - 1, "error_deg": err, "alpha": alpha, "pwm": list(pwm)}
            )
            if elapsed > 60_000_000:
                raise SystemExit("the virtual participant did not succeed within 60 s")
        if success_at is not None and len(samples) - 1 >= success_at + 100:
            break  # the 0.6 s success pattern and a margin
    return {
        "SIMULATED": True,
        "period_us": period_us,
        "button_us": button_us,
        "header": header,
        "trial": trial,
        "levels": levels,
        "samples": samples,
        "host": {"frames": pwm_log, "success_sample": success_at, "completion_s": completion_s},
    }


def main(out_dir=DATA):
    os.makedirs(out_dir, exist_ok=True)
    rng = np.random.default_rng(SEED)
    ref = {
        "alignment": alignment_cases(rng),
        "pwm": pwm_cases(rng),
        "pwm_calibrated": pwm_calibrated_cases(rng),
        "estimator": estimator_case(),
    }
    with open(os.path.join(out_dir, "frame_reference.json"), "w") as f:
        json.dump(ref, f, separators=(",", ":"))
    with open(os.path.join(out_dir, "hostless_script.json"), "w") as f:
        json.dump(hostless_script(), f, separators=(",", ":"))


if __name__ == "__main__":
    main(*sys.argv[1:2])
