"""The virtual participant's opt-in per-finger model (``participant:fingers=N``): the
per-finger strengths are the calibration observer's, and a calibration equal to the
observer's truth equalises them. SIMULATED: a model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_participant import CONTACTS4, Y_AXIS, _wrenches

from graspguide.calibration.session import DEFAULT_REFERENCE
from graspguide.calibration.virtual_observer import VirtualObserver
from graspguide.core import _core
from graspguide.core.motor_calibration import FINGER_NAMES, MotorCalibration
from graspguide.core.reference import pwm_from_levels
from graspguide.participant.model import (
    PWM_RANGE,
    VirtualParticipant,
    parse_spec,
)

IDENTITY = (1.0, 0.0, 0.0, 0.0)


def _loop(vp, wrench, mode, seconds, calibration=None):
    """Closed loop with the core as the device (its PWM, optionally through a
    calibration, fed back); the poses."""
    vp.begin_trial(
        contacts=CONTACTS4, y_axis=Y_AXIS, wrench=wrench, policy="F", mode=mode, start_quat=IDENTITY
    )
    q, poses = IDENTITY, []
    for i in range(int(seconds * vp.rate_hz)):
        res = _core.solve(
            contacts=CONTACTS4,
            wrench=wrench,
            policy="F",
            mode=mode,
            constraints="paper",
            orientation=list(q),
            y_axis=Y_AXIS,
        )
        assert res["status"] == "ok", res["status"]
        pwm = res["pwm"]
        if calibration is not None:
            pwm = pwm_from_levels(np.asarray(res["levels"]), mode, res["alpha"], calibration)
        q = vp.step(i / vp.rate_hz, pwm)
        poses.append(q)
    return poses


def test_default_participant_feels_with_its_own_gains_not_the_calibrations():
    """Without fingers=N the participant feels every motor from half the floor, with its
    own per-finger gains (drawn from its seed); fingers=N replaces them with the
    calibration observer's thresholds and magnitudes."""
    vp = _vp("participant")
    assert vp.fingers_seed is None
    speeds = [200.0, 120.0, 40.0, 30.0]
    pc = vp.percept(speeds)
    assert pc.on[:3] == (True, True, True) and not pc.on[3]  # 30 < 35: not felt
    other = _vp("participant:fingers=3")
    assert other.fingers_seed == 3
    assert other.percept([200.0, 0.0, 0.0, 0.0]).ln_level != pc.ln_level


def _vp(spec, mode="V"):
    vp = VirtualParticipant.from_spec(spec, 5)
    vp.begin_trial(
        contacts=CONTACTS4,
        y_axis=Y_AXIS,
        wrench=[0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        policy="F",
        mode=mode,
        start_quat=IDENTITY,
    )
    return vp


@pytest.mark.parametrize("n", [1, 7, 12345])
def test_per_finger_strengths_are_the_observers(n):
    obs = VirtualObserver(seed=n)
    vp = _vp(f"participant:fingers={n}")
    assert vp.fingers_seed == n
    rng = np.random.default_rng(n)
    for _ in range(50):
        speeds = rng.uniform(0.0, 255.0, size=4).tolist()
        want = [obs.magnitude(f, s) for f, s in zip(FINGER_NAMES, speeds)]
        assert vp.perceived(speeds) == pytest.approx(want, rel=1e-12, abs=1e-12)
        # The distance (no noise): the strengths on the reference finger's scale.
        scale = obs.fingers[DEFAULT_REFERENCE].magnitude * PWM_RANGE
        level = min(1.0, math.sqrt(sum(p * p for p in want)) / scale)
        d = vp.felt_distance_deg(speeds)
        if any(p > 0 for p in want):
            assert d == pytest.approx(math.degrees(2 * math.asin(level)), rel=1e-12)
        else:
            assert d is None
    # Below every finger's threshold nothing is felt: no direction, no distance.
    below = [obs.fingers[f].threshold_pwm - 0.5 for f in FINGER_NAMES]
    assert vp.percept(below) is None
    assert vp.felt_distance_deg(below) is None
    # ... though the uniform model feels those speeds (all >= 35).
    assert _vp("participant").percept(below) is not None


def _true_calibration(obs):
    ref = DEFAULT_REFERENCE
    return MotorCalibration(
        tuple(int(round(obs.fingers[f].threshold_pwm)) for f in FINGER_NAMES),
        tuple(obs.true_gain(f, ref) for f in FINGER_NAMES),
    )


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6, 7, 8])
@pytest.mark.parametrize("mode", ["C", "V"])
def test_true_calibration_equalises_the_fingers(n, mode):
    obs = VirtualObserver(seed=n)
    vp = _vp(f"participant:fingers={n}", mode)
    weber_sd = vp._speed_sd()  # of the perceived speed, per reading
    cal = _true_calibration(obs)
    worst_uncal = 0.0
    for level in (0.2, 0.5, 0.8):
        m = np.full(4, level)
        alpha = PWM_RANGE * 0.6 if mode == "V" else 0.0
        g = PWM_RANGE if mode == "C" else alpha
        pwm = pwm_from_levels(m, mode, alpha, cal)
        if max(pwm) >= 255:  # saturated: the top of the range cannot be equalised
            continue
        p = vp.perceived(pwm)
        ref = obs.fingers[DEFAULT_REFERENCE].magnitude * g * level  # what every finger should feel
        for f, pi in zip(FINGER_NAMES, p):
            # Rounding the floor and the duty is at most one count on the finger.
            tol = weber_sd * ref + obs.fingers[f].magnitude * 1.0
            assert abs(pi - ref) <= tol, (f, level, pi, ref)
        raw = vp.perceived(pwm_from_levels(m, mode, alpha, None))
        worst_uncal = max(worst_uncal, (max(raw) - min(raw)) / ref)
    # Without the calibration the same levels feel unequal (the test would catch nothing
    # if the fingers were alike).
    assert worst_uncal > weber_sd


def test_calibrated_closed_loop_runs_and_uses_the_fingers():
    """The per-finger participant in a closed loop through a calibrated mapping moves,
    and differently from the uniform one (it feels other strengths)."""
    w = _wrenches(1, 2026)[0]
    cal = _true_calibration(VirtualObserver(seed=3))
    a = _loop(VirtualParticipant.from_spec("participant:fingers=3", 9), w, "V", 5.0, cal)
    b = _loop(VirtualParticipant.from_spec("participant", 9), w, "V", 5.0, cal)
    assert a[-1] != IDENTITY and a != b


@pytest.mark.parametrize(
    "spec, words",
    [
        ("participant:fingers=x", ["fingers", "integer"]),
        ("participant:fingers=1,fingers=2", ["fingers", "twice"]),
        ("participant:fingerz=1", ["fingerz", "fingers"]),
    ],
)
def test_bad_fingers_spec_says_what_to_fix(spec, words):
    with pytest.raises(ValueError) as e:
        VirtualParticipant.from_spec(spec, 1)
    for word in words:
        assert word in str(e.value)


def test_parse_spec_refuses_fingers_and_from_spec_keeps_other_keys():
    with pytest.raises(ValueError, match="from_spec"):
        parse_spec("participant:fingers=3")
    vp = VirtualParticipant.from_spec("participant:fingers=3,reaction_time_s=0.3", 1)
    assert vp.fingers_seed == 3 and vp.params.reaction_time_s == 0.3
    assert VirtualParticipant.from_spec("fingers=4", 1).fingers_seed == 4
