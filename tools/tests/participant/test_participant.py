"""The virtual participant (graspguide.participant.model): determinism, ERM lag, reaction delay,
speed bound, mode C vs V, the Bayesian reading and the posterior-ordered search, the
draws across participants, input errors, and the closed loop against the C++ core.

Everything the participant produces is SIMULATED (never human data).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import TOOLS_DIR, subprocess_env

from graspguide.core import _core
from graspguide.participant import bayes_reading, perception, population
from graspguide.participant.model import (
    PWM_FLOOR,
    FeelLagError,
    ParticipantParams,
    VirtualParticipant,
    parse_spec,
    quaternion_angle_deg,
)
from graspguide.protocol import scene_file as gs

EXAMPLES = os.path.join(TOOLS_DIR, "examples")
SCENE4 = gs.load_scene(os.path.join(EXAMPLES, "scene_paper_4.toml"))
CONTACTS4 = [list(c) for c in SCENE4.contacts]
Y_AXIS = list(SCENE4.y_axis)
IDENTITY = (1.0, 0.0, 0.0, 0.0)
THRESHOLD_DEG, HOLD_S, TIMEOUT_S = 3.0, 0.5, 90.0


def motor_speeds(vp):
    """The model's ERM speeds in PWM units (its first-order lag of the PWM)."""
    return [float(v) for v in vp._motor]


#: The participant at the population's medians (no draw across participants).
NOMINAL = "participant:vary=0"


def noise_free_percept(vp, speeds):
    """The percept of ``speeds`` without intensity noise or counting error."""
    k = len(speeds)
    p = vp.params
    return perception.perceive(
        speeds,
        [0.0] * k,
        1.0,
        vp._gains[:k],
        p.weber_frac,
        p.finger_gain_sd,
        perception.miss_probabilities(p.miss_per_extra, k),
    )


def read_direction(vp, speeds):
    """The most probable weight direction of the participant's noise-free reading of
    ``speeds`` (unit, hand frame) or None when nothing is felt."""
    pc = noise_free_percept(vp, speeds)
    if pc is None:
        return None
    w = vp.posterior(pc)
    gx, gy, gz = bayes_reading.direction_grid()
    i = int(np.argmax(w))
    return np.array([gx[i], gy[i], gz[i]])


def _wrenches(n: int, seed: int):
    """Seeded unit forces (N), some with a moment (N m) about the centroid."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        f = rng.normal(size=3)
        # Not np.linalg.norm: its BLAS dot differs in the last bit between CPUs, and the
        # golden record below hashes trajectories that start from these wrenches.
        f /= math.sqrt(sum(float(v) * float(v) for v in f))
        m = rng.normal(size=3) * 0.01 if i % 3 == 2 else np.zeros(3)
        out.append([float(v) for v in f] + [float(v) for v in m])
    return out


def closed_loop(
    wrench,
    mode="V",
    policy="F",
    seed=0,
    spec="participant",
    contacts=CONTACTS4,
    start=IDENTITY,
    timeout_s=TIMEOUT_S,
    record=False,
):
    """The core as the device: PWM from the current orientation, fed to the next step.

    Returns (success, time_s, poses) with the trial rule of docs/algorithm.md step 7
    (error <= 3 deg held 0.5 s, 90 s timeout)."""
    vp = VirtualParticipant.from_spec(spec, seed)
    vp.begin_trial(
        contacts=contacts, y_axis=Y_AXIS, wrench=wrench, policy=policy, mode=mode, start_quat=start
    )
    q = start
    entry = None
    poses = []
    n = int(round(timeout_s * vp.rate_hz))
    for i in range(n + 1):
        t = i / vp.rate_hz
        res = _core.solve(
            contacts=contacts,
            wrench=wrench,
            policy=policy,
            mode=mode,
            constraints="paper",
            orientation=list(q),
            y_axis=Y_AXIS,
        )
        assert res["status"] == "ok", res["status"]
        if res["error_deg"] <= THRESHOLD_DEG:
            entry = t if entry is None else entry
            if t - entry >= HOLD_S:
                return True, t, poses
        else:
            entry = None
        q = vp.step(t, res["pwm"])
        if record:
            poses.append((t, q, list(res["pwm"])))
    return False, timeout_s, poses


def open_loop(vp, pwm, seconds, t0=0.0):
    """Feed a constant PWM for `seconds`; return [(t, quat)]."""
    out = []
    n = int(round(seconds * vp.rate_hz))
    for i in range(n):
        t = t0 + i / vp.rate_hz
        out.append((t, vp.step(t, pwm)))
    return out


def new_participant(spec=NOMINAL, seed=1, mode="V", policy="F", wrench=None):
    vp = VirtualParticipant.from_spec(spec, seed)
    vp.begin_trial(
        contacts=CONTACTS4,
        y_axis=Y_AXIS,
        wrench=wrench or [0, 0, -1, 0, 0, 0],
        policy=policy,
        mode=mode,
        start_quat=IDENTITY,
    )
    return vp


# --------------------------------------------------------------------------------------
def test_labelled_simulated_and_defaults():
    vp = VirtualParticipant.from_spec(NOMINAL, 3)
    assert VirtualParticipant.SIMULATED is True and vp.SIMULATED is True
    assert vp.params == ParticipantParams(vary=0)
    assert vp.rate_hz == 100.0
    p = parse_spec("participant:reaction_time_s=0.4, rate_hz=50")
    assert p.reaction_time_s == 0.4 and p.rate_hz == 50.0
    assert VirtualParticipant.from_spec("participant:rate_hz=50", 0).rate_hz == 50.0
    # The runner may pass only what follows 'participant:'.
    assert VirtualParticipant.from_spec("vary=0", 0).params == ParticipantParams(vary=0)
    assert VirtualParticipant.from_spec("rate_hz=50", 0).rate_hz == 50.0
    assert parse_spec("reading=learned").reading == "learned"


def test_participants_differ_and_a_given_key_is_fixed():
    """from_spec draws each participant's parameters from their distributions, seeded by
    its seed: the same seed gives the same person, other seeds other people, every draw
    inside its stated range and spread around its median; a key of the spec is not drawn
    and leaves every other draw as it was."""
    people = [VirtualParticipant.from_spec("participant", s).params for s in range(200)]
    assert VirtualParticipant.from_spec("participant", 7).params == people[7]
    for name, (kind, a, _sd, lo, hi) in population.DISTRIBUTIONS.items():
        v = np.array([getattr(p, name) for p in people])
        assert v.min() >= lo and v.max() <= hi, name
        assert len(set(v.tolist())) > 150, name  # drawn, not fixed
        median = 10 ** (a / 20) - 1 if kind == "weber_db" else a
        assert float(np.median(v)) == pytest.approx(median, rel=0.1), name
        assert getattr(ParticipantParams(), name) == pytest.approx(median, rel=0.02), name
    fixed = VirtualParticipant.from_spec("participant:reaction_time_s=0.3", 7).params
    assert fixed.reaction_time_s == 0.3
    assert fixed.weber_frac == people[7].weber_frac != people[8].weber_frac
    assert fixed.peak_speed_deg_s == people[7].peak_speed_deg_s
    # Per-finger gains and proprioceptive bias: the person's own, the same in every trial.
    a, b = (
        VirtualParticipant.from_spec("participant", 1),
        VirtualParticipant.from_spec("participant", 2),
    )
    assert a._gains != b._gains and a._prop_bias != b._prop_bias
    assert VirtualParticipant.from_spec("participant", 1)._gains == a._gains


def test_seeded_determinism():
    w = _wrenches(1, 7)[0]
    a = closed_loop(w, seed=11, timeout_s=8.0, record=True)[2]
    b = closed_loop(w, seed=11, timeout_s=8.0, record=True)[2]
    c = closed_loop(w, seed=12, timeout_s=8.0, record=True)[2]
    assert len(a) > 100
    assert [q for _, q, _ in a] == [q for _, q, _ in b]
    n = min(len(a), len(c))
    assert max(quaternion_angle_deg(a[i][1], c[i][1]) for i in range(n)) > 0.5


def test_wrench_is_not_used_for_decisions():
    """Same PWM stream and noise stream, different wrench argument: the same trajectory."""
    pwm = [150, 0, 120, 90]
    for mode in ("C", "V"):
        runs = []
        for wrench in ([0, 0, -1, 0, 0, 0], [1, 0, 0, 0, 0.1, 0]):
            vp = VirtualParticipant.from_spec("participant", 1)
            vp.begin_trial(
                contacts=CONTACTS4,
                y_axis=Y_AXIS,
                wrench=wrench,
                policy="F",
                mode=mode,
                start_quat=IDENTITY,
                noise_seed=9,
            )
            runs.append(open_loop(vp, pwm, 6.0))
        assert runs[0] == runs[1]
        assert quaternion_angle_deg(runs[0][-1][1], IDENTITY) > 5.0


def test_trial_reproducible_whatever_ran_before():
    """A trial's trajectory depends on the participant seed and the trial, not on the
    trials before it (a resumed study reproduces an uninterrupted one)."""
    w1, w2 = _wrenches(2, 5)

    def run(vp, w):
        vp.begin_trial(
            contacts=CONTACTS4, y_axis=Y_AXIS, wrench=w, policy="F", mode="V", start_quat=IDENTITY
        )
        return open_loop(vp, [150, 0, 120, 90], 3.0)

    fresh = run(VirtualParticipant.from_spec("participant", 3), w2)
    vp = VirtualParticipant.from_spec("participant", 3)
    run(vp, w1)
    assert run(vp, w2) == fresh
    assert run(VirtualParticipant.from_spec("participant", 4), w2) != fresh


@pytest.mark.parametrize("tau", [0.06, 0.1])
def test_erm_lag_reaches_63_percent_after_tau(tau):
    vp = new_participant(spec=f"participant:erm_tau_s={tau}")
    dt = 1.0 / vp.rate_hz
    target = 200.0
    crossed = None
    for i in range(100):
        t = i * dt
        vp.step(t, [int(target), 0, 0, 0])
        speed = motor_speeds(vp)[0]
        assert motor_speeds(vp)[1:] == [0.0, 0.0, 0.0]
        if crossed is None and speed >= (1 - math.exp(-1)) * target - 1e-9:
            crossed = t + dt  # the first sample's PWM acts over the preceding dt
    assert crossed == pytest.approx(tau, abs=dt)
    assert motor_speeds(vp)[0] == pytest.approx(target, rel=1e-3)
    # And back down (stop) with the same lag.
    t0 = 100 * dt
    vp.step(t0, [0, 0, 0, 0])
    for i in range(1, 200):
        vp.step(t0 + i * dt, [0, 0, 0, 0])
        if motor_speeds(vp)[0] <= math.exp(-1) * target:
            assert (i + 1) * dt == pytest.approx(tau, abs=dt)
            break
    else:
        pytest.fail("the motor never spun down")


@pytest.mark.parametrize("mode", ["C", "V"])
@pytest.mark.parametrize(
    "spec,tremor", [("participant:tremor_amplitude_deg=0", False), ("participant", True)]
)
def test_no_rotation_before_reaction_time(spec, tremor, mode):
    vp = new_participant(spec=spec, mode=mode)
    rt = vp.params.reaction_time_s
    silent = open_loop(vp, [0, 0, 0, 0], 1.0)  # no cue for 1 s
    cue_t = 1.0
    cued = open_loop(vp, [200, 0, 150, 100], 4.0, t0=cue_t)
    allowance = 2 * vp.params.tremor_amplitude_deg + 1e-9
    for _t, q in silent + [p for p in cued if p[0] < cue_t + rt]:
        angle = quaternion_angle_deg(q, IDENTITY)
        if tremor:
            assert angle <= allowance
        else:
            assert angle == 0.0
    if tremor:  # the tremor is there, and of the right size
        assert max(quaternion_angle_deg(q, IDENTITY) for _, q in silent) > 0.2 * allowance
    # ... and the hand does turn afterwards.
    assert max(quaternion_angle_deg(q, IDENTITY) for _, q in cued) > 10.0


def test_angular_speed_is_bounded():
    p = ParticipantParams()
    tremor_speed = 2 * math.pi * p.tremor_frequency_hz * p.tremor_amplitude_deg * math.sqrt(2)
    bound = p.peak_speed_deg_s + tremor_speed
    peak = 0.0
    for w in _wrenches(4, 3):
        for mode in ("V", "C"):
            _, _, poses = closed_loop(
                w, mode=mode, seed=5, timeout_s=20.0, record=True, spec=NOMINAL
            )
            for (t0, q0, _), (t1, q1, _) in zip(poses, poses[1:]):
                peak = max(peak, quaternion_angle_deg(q0, q1) / (t1 - t0))
    assert peak <= bound * (1 + 1e-9)
    assert peak > 0.5 * p.peak_speed_deg_s  # the bound is actually approached


def test_speed_bound_follows_the_parameter():
    _, _, poses = closed_loop(
        _wrenches(1, 3)[0],
        seed=5,
        timeout_s=10.0,
        record=True,
        spec="participant:peak_speed_deg_s=30,tremor_amplitude_deg=0",
    )
    speeds = [quaternion_angle_deg(a[1], b[1]) / (b[0] - a[0]) for a, b in zip(poses, poses[1:])]
    assert max(speeds) <= 30.0 * (1 + 1e-9)
    assert max(speeds) > 15.0


def test_the_reading_uses_relative_levels_and_which_motors_vibrate():
    """The posterior depends on the relative levels only: scaling every level above the
    floor (70) by a common factor leaves its most probable direction where it was; which
    motors vibrate moves it far. In V the same scaling changes the felt distance."""
    base = [170, 0, 130, 90]  # levels above the floor 100, 0, 60, 20
    half = _scaled(base, 0.5)  # 120, 0, 100, 80: the same relative levels
    assert half == [120, 0, 100, 80]
    for mode in ("C", "V"):
        vp = new_participant(mode=mode)
        d_base = read_direction(vp, base)
        d_half = read_direction(vp, half)
        assert np.allclose(d_base, d_half, atol=1e-12)
        if mode == "C":
            assert vp.felt_distance_deg(base) is None  # no magnitude at all in C
        else:
            far, near = vp.felt_distance_deg(base), vp.felt_distance_deg(half)
            assert far == pytest.approx(
                2 * math.degrees(math.asin(math.sqrt(100**2 + 60**2 + 20**2) / 185)), rel=1e-6
            )
            assert near < 0.6 * far  # V: weaker means closer
    vp = new_participant(mode="C")
    other = read_direction(vp, [0, 170, 130, 90])
    assert math.degrees(math.acos(float(np.clip(other @ read_direction(vp, base), -1, 1)))) > 20


def test_the_reading_recovers_the_direction_the_map_was_built_from():
    """Noise-free, with equal fingers, the reading of the pattern Algorithm 1 gives for a
    grid direction puts that direction among the most probable ones: the posterior
    weight there is 1 (the maximum), over 50 directions of each hand and policy."""
    gx, gy, gz = bayes_reading.direction_grid()
    rng = np.random.default_rng(3)
    for k in (3, 4):
        for policy in ("F", "Fperp"):
            vp = new_participant(spec=NOMINAL + ",finger_gain_sd=0", mode="C", policy=policy)
            vp.begin_trial(
                contacts=CONTACTS4[:k],
                y_axis=Y_AXIS,
                wrench=[0, 0, -1, 0, 0, 0],
                policy=policy,
                mode="C",
                start_quat=IDENTITY,
            )
            pm = bayes_reading.pattern_map(vp._contacts, vp._y_axis, policy)
            for i in rng.integers(0, len(gx), size=50).tolist():
                lev = np.exp(pm.ln_level[i]) * pm.on[i]
                pwm = [PWM_FLOOR + 185 * v if on else 0 for v, on in zip(lev, pm.on[i])]
                w = vp.posterior(noise_free_percept(vp, pwm))
                assert w[i] == pytest.approx(1.0, abs=1e-9), (k, policy, i)


def test_the_grid_covers_the_sphere_within_two_degrees():
    gx, gy, gz = bayes_reading.direction_grid()
    g = np.stack([gx, gy, gz], axis=1)
    q = np.random.default_rng(0).normal(size=(20000, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    best = np.max(q @ g.T, axis=1)
    assert math.degrees(math.acos(best.min())) < 2.0
    nb = bayes_reading.cap_neighbours(3.0)
    for i in (0, 17, 2999, 5999):  # the band search finds every point within 3 deg
        want = np.nonzero(g @ g[i] >= math.cos(math.radians(3.0)))[0]
        assert sorted(nb[i].tolist()) == want.tolist()


def test_counting_errors_miss_the_weakest_motor_at_the_stated_rate():
    k = 4
    miss = perception.miss_probabilities(0.1, k)
    assert miss == (0.0, 0.0, 0.0, 0.1, pytest.approx(0.2))
    rng = np.random.default_rng(1)
    speeds = [200.0, 0.0, 150.0, 90.0]  # three on: the weakest (90) is missed 10 %
    missed = 0
    for _ in range(4000):
        pc = perception.perceive(speeds, [0.0] * k, float(rng.uniform()), [1.0] * k, 0.5, 0.2, miss)
        assert pc.on[0] and pc.on[2] and not pc.on[1]
        missed += not pc.on[3]
    assert abs(missed / 4000 - 0.1) < 0.02
    two = perception.perceive([200.0, 0.0, 90.0, 0.0], [0.0] * k, 0.0, [1.0] * k, 0.5, 0.2, miss)
    assert two.on == (True, False, True, False)  # two vibrations are never miscounted


def test_the_perceived_levels_carry_the_weber_noise():
    """The log of the perceived speed above... : its SD is half ln(1 + W) of the speed."""
    W = 0.53
    rng = np.random.default_rng(2)
    speeds = [255.0, 255.0, 0.0, 0.0]
    lv = []
    for _ in range(4000):
        pc = perception.perceive(
            speeds, rng.standard_normal(4).tolist(), 1.0, [1.0] * 4, W, 0.0, (0,) * 5
        )
        lv.append(pc.ln_level[0] - pc.ln_level[1])
    # ln(s' - 70) with s' = 255 exp(h e): SD ~ h 255 / 185 per motor, sqrt(2) for the difference
    h = 0.5 * math.log1p(W)
    assert np.std(lv) == pytest.approx(math.sqrt(2) * h * 255 / 185, rel=0.1)


def _scaled(pwm, c):
    return [0 if v == 0 else int(round(PWM_FLOOR + c * (v - PWM_FLOOR))) for v in pwm]


def _c_run(pwm, mode="C", spec=NOMINAL + ",erm_tau_s=0.0001", seconds=20.0, seed=4):
    vp = VirtualParticipant.from_spec(spec, seed)
    vp.begin_trial(
        contacts=CONTACTS4,
        y_axis=Y_AXIS,
        wrench=[0, 0, -1, 0, 0, 0],
        policy="F",
        mode=mode,
        start_quat=IDENTITY,
        noise_seed=21,
    )
    return [q for _, q in open_loop(vp, pwm, seconds)], vp


@pytest.mark.parametrize("scale", [0.5, 1.85])
def test_mode_c_every_decision_ignores_magnitude(scale):
    """Mode C never uses magnitude: with the same noise stream and a noise-free intensity
    reading, scaling every PWM above the motor floor (70) by a common factor leaves the
    whole trajectory unchanged (every decision of the search, over 20 s; the ERM made
    fast so that the motors are read at their steady speed). In V the same scaling
    changes the trajectory."""
    base = [170, 0, 130, 90]
    scaled = _scaled(base, scale)
    assert [v - PWM_FLOOR for v in scaled if v] == [scale * (v - PWM_FLOOR) for v in base if v]
    spec = NOMINAL + ",erm_tau_s=0.0001,weber_frac=0"
    a, _ = _c_run(base, spec=spec)
    b, _ = _c_run(scaled, spec=spec)
    assert len(a) == len(b) == 2000
    assert max(quaternion_angle_deg(x, y) for x, y in zip(a, b)) < 1e-4
    assert quaternion_angle_deg(a[-1], IDENTITY) > 5.0  # it did move and search
    v_a, _ = _c_run(base, mode="V")
    v_b, _ = _c_run(scaled, mode="V")
    assert max(quaternion_angle_deg(x, y) for x, y in zip(v_a, v_b)) > 1.0


def _down_in_hand(q):
    """Hand-frame direction that points down (along gravity) at orientation q."""
    w, x, y, z = q
    # R^T g with g = (0, 0, -1): minus the third row of R.
    return -np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])


def _holds(poses, min_s=0.3):
    """(start, end, pose) of every stretch where the hand is still for >= min_s."""
    still, run = [], []
    for (_t0, q0), (t1, q1) in zip(poses, poses[1:]):
        if quaternion_angle_deg(q0, q1) < 1e-9:
            run.append(t1)
        else:
            if run and run[-1] - run[0] >= min_s:
                still.append((run[0], run[-1], q0))
            run = []
    return still


def test_mode_c_search_follows_the_posterior_and_never_returns():
    """With a cue that never stops, the C participant (exact proprioception, no motor
    noise, no tremor) holds poses: each for about the task's hold (no dwell beyond it:
    the device ends a trial itself), never within the threshold of a pose it held before,
    the most probable ones first."""
    spec = (
        NOMINAL + ",tremor_amplitude_deg=0,motor_noise_frac=0,prop_bias_sd_deg=0,"
        "prop_trial_sd_deg=0,prop_drift_frac=0"
    )
    poses, vp = _c_run([170, 0, 130, 90], spec=spec, seconds=60.0, seed=3)
    holds = _holds(list(zip([i / 100 for i in range(len(poses))], poses)))[1:]
    assert len(holds) >= 40
    p = vp.params
    lengths = [end - start for start, end, _ in holds]
    assert vp.hold_s() == pytest.approx(0.5 * (1 + 2 * 0.1))
    assert np.median(lengths) == pytest.approx(vp.hold_s(), abs=0.03)
    assert max(lengths) < p.task_hold_s + 3 * p.erm_tau_s + p.reaction_time_s  # no extra dwell
    dirs = np.array([_down_in_hand(q) for _, _, q in holds])
    sep = np.degrees(np.arccos(np.clip(dirs @ dirs.T, -1, 1)))
    np.fill_diagonal(sep, 180.0)
    assert sep.min() > p.task_threshold_deg  # never the same place twice
    # The probable directions first (weighed against the travel to them): the first 40
    # held directions are all among the more probable half of the sphere, on average in
    # its top quarter.
    w = np.array(vp._search["w"])
    gx, gy, gz = bayes_reading.direction_grid()
    g = np.stack([gx, gy, gz], axis=1)
    held_w = [w[int(np.argmax(g @ d))] for d in dirs[:40]]
    assert min(held_w) >= np.quantile(w, 0.5)
    assert np.mean(held_w) >= np.quantile(w, 0.75)


def test_mode_c_converges_with_the_core_when_the_reading_is_near(report_figure):
    """Closed loop with the C++ core, mode C, 4 contacts, seeded wrenches, a sharp reader
    (Weber fraction 0.05, equal fingers, no counting error) with exact proprioception:
    whenever its noise-free reading puts the most probable direction within 10 deg of
    the true weight direction, the search reaches the 3 deg threshold (held 0.5 s)
    within 90 s; reported with the reading's error."""
    spec = (
        NOMINAL + ",prop_bias_sd_deg=0,prop_trial_sd_deg=0,prop_drift_frac=0,"
        "weber_frac=0.05,finger_gain_sd=0,miss_per_extra=0"
    )
    near, far = [], []
    for policy in ("F", "Fperp"):
        for i, w in enumerate(_wrenches(10, 77)):
            w = w[:3] + [0.0, 0.0, 0.0]
            res = _core.solve(
                contacts=CONTACTS4,
                wrench=w,
                policy=policy,
                mode="C",
                constraints="paper",
                orientation=list(IDENTITY),
                y_axis=Y_AXIS,
            )
            vp = new_participant(spec=spec, mode="C", policy=policy)
            d = read_direction(vp, [float(v) for v in res["pwm"]])
            f = np.array(w[:3]) / np.linalg.norm(w[:3])
            err = math.degrees(math.acos(float(np.clip(d @ f, -1, 1))))
            ok, t = closed_loop(w, mode="C", policy=policy, seed=300 + i, spec=spec)[:2]
            (near if err <= 10.0 else far).append((policy, i, round(err, 1), ok, t))
    report_figure(
        "participant closed loop C (4 contacts, 10 wrenches x F/Fperp)",
        f"reading within 10 deg: {sum(r[3] for r in near)}/{len(near)} reached; "
        f"farther: {sum(r[3] for r in far)}/{len(far)}",
    )
    assert len(near) >= 6, near
    assert all(r[3] for r in near), near


# --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "spec,words",
    [
        ("participant:bogus=1", ["unknown participant parameter", "reaction_time_s"]),
        ("participant:reaction_time_s=abc", ["not a number"]),
        ("participant:reaction_time_s=-0.1", ["reaction_time_s", "> 0"]),
        ("participant:erm_tau_s=nan", ["erm_tau_s", "finite"]),
        ("participant:weber_frac=1.5", ["weber_frac", "< 1"]),
        ("participant:rate_hz", ["not key=value"]),
        ("participant:", ["no key=value"]),
        ("human", ["'human' is not key=value", "participant:key=value"]),
        ("rate_hz=abc", ["not a number"]),
        ("participant:rate_hz=100,rate_hz=50", ["given twice"]),
    ],
)
def test_bad_spec_says_what_to_fix(spec, words):
    with pytest.raises(ValueError) as e:
        VirtualParticipant.from_spec(spec, 0)
    for w in words:
        assert w in str(e.value)


@pytest.mark.parametrize(
    "pwm,words",
    [
        ([float("nan"), 0, 0, 0], ["finite"]),
        ([0, 0, 0], ["4 values"]),
        ([0, 0, 0, 0, 0], ["4 values"]),
        ([0, 0, 300, 0], ["0..255"]),
        ([0, -1, 0, 0], ["0..255"]),
        (["a", 0, 0, 0], ["numbers"]),
        ("1234", ["numbers"]),
    ],
)
def test_bad_pwm_is_a_clear_error(pwm, words):
    vp = new_participant()
    with pytest.raises(ValueError) as e:
        vp.step(0.0, pwm)
    for w in words:
        assert w in str(e.value)


def test_bad_trial_inputs():
    vp = VirtualParticipant.from_spec("participant", 0)
    with pytest.raises(RuntimeError):
        vp.step(0.0, [0, 0, 0, 0])
    good = dict(
        contacts=CONTACTS4,
        y_axis=Y_AXIS,
        wrench=[0, 0, -1, 0, 0, 0],
        policy="F",
        mode="V",
        start_quat=IDENTITY,
    )
    for key, bad in (
        ("policy", "G"),
        ("mode", "X"),
        ("contacts", [[0, 0, 0]] * 2),
        ("wrench", [0, 0, 1]),
        ("wrench", [0, 0, float("inf"), 0, 0, 0]),
        ("start_quat", [0, 0, 0, 0]),
        ("y_axis", [0, 0, 0]),
    ):
        with pytest.raises(ValueError):
            vp.begin_trial(**{**good, key: bad})
    vp.begin_trial(**good)
    vp.step(1.0, [0, 0, 0, 0])
    with pytest.raises(ValueError, match="backwards"):
        vp.step(0.5, [0, 0, 0, 0])
    with pytest.raises(ValueError):
        VirtualParticipant(ParticipantParams(rate_hz=0.0), 0)


# --------------------------------------------------------------------------------------
def test_closed_loop_with_the_core_reaches_threshold_in_mode_v(report_figure):
    """The paper's 4-contact scene, 8 seeded wrenches, mode V, both policies: most trials
    reach 3 deg (held 0.5 s) within 90 s of virtual time."""
    results = {}
    for policy in ("F", "Fperp"):
        for i, w in enumerate(_wrenches(8, 2026)):
            results[policy, i] = closed_loop(w, mode="V", policy=policy, seed=100 + i)[:2]
    for policy in ("F", "Fperp"):
        rows = [results[policy, i] for i in range(8)]
        ok = [t for s, t in rows if s]
        report_figure(
            f"participant closed loop V {policy} (4 contacts, 8 wrenches)",
            f"{len(ok)}/8 reached 3 deg; mean time of successes "
            f"{np.mean(ok):.1f} s, max {max(ok):.1f} s",
        )
        assert len(ok) >= 6, rows


def test_closed_loop_mode_c_runs_and_is_slower_than_v(report_figure):
    """Mode C with the same wrenches: reported, and on average not faster than V."""
    times = {"C": [], "V": []}
    succ = {"C": 0, "V": 0}
    for i, w in enumerate(_wrenches(4, 2026)):
        for mode in ("C", "V"):
            s, t = closed_loop(w, mode=mode, policy="F", seed=200 + i)[:2]
            times[mode].append(t)
            succ[mode] += s
    report_figure(
        "participant closed loop C vs V F (4 contacts, 4 wrenches)",
        f"C {succ['C']}/4 mean {np.mean(times['C']):.1f} s; "
        f"V {succ['V']}/4 mean {np.mean(times['V']):.1f} s (90 s = timeout)",
    )
    assert np.mean(times["V"]) <= np.mean(times["C"])


# --------------------------------------------------------------------------------------
# feel / act (docs/participant.md, "feel and act")
# --------------------------------------------------------------------------------------
#: Seeded closed loops against the core (lockstep step(), 30 s each): per trial the sha256
#: of the PWM stream (integers: exact) and, per quaternion component, the sum of the poses
#: and of t x pose (floats: compared within GOLDEN_TOL). The participant at the
#: population's medians (NOMINAL), and two drawn across the population. Regenerate
#: only for a deliberate change of the model (print _golden_runs() and paste it), and
#: say so in the commit: the record exists to catch unintended changes, and to show
#: that a seeded study gives the same trajectories on another machine.
GOLDEN = {
    "0-C-F": (
        "c1f0c1047a59616219ca4555025727df9fec01ef71c76e23882245ff86384d6c",
        [
            2867.3642734659747,
            -217.20780399937692,
            714.5187362610476,
            67.50142251362679,
            42346.16358216564,
            -2333.695287171889,
            13629.929356931645,
            1347.8234864556116,
        ],
    ),
    "0-C-Fperp": (
        "c1f0c1047a59616219ca4555025727df9fec01ef71c76e23882245ff86384d6c",
        [
            2718.5478931696694,
            847.3854210287169,
            751.4981690372358,
            -132.69557206528958,
            39889.418659988325,
            13946.540208473196,
            13499.053042258958,
            -2693.46774669263,
        ],
    ),
    "0-V-F": (
        "2c7c2e0570c7963098540cc0e168a8361830c8b1420734f08854f03c247929ae",
        [
            1864.0056117331017,
            -1966.4682947861504,
            -747.5092536562424,
            -136.6469365057604,
            25360.728638490113,
            -33433.70575099975,
            -8091.509639031292,
            -2084.153776464791,
        ],
    ),
    "0-V-Fperp": (
        "b904198a1695160283c61cb8f270223e06fd8d583f4a8cd9adc05be4172407b4",
        [
            2954.537706624743,
            -42.546388153106285,
            -419.2977319400521,
            -18.02239229875904,
            44314.48023589978,
            -564.9282488568795,
            -6841.318672502313,
            -776.7860039947714,
        ],
    ),
    "1-C-F": (
        "71c63845ba700764d03d1c3763846232ba9458dec910ae086a557c5bdd91df84",
        [
            2177.761411535073,
            222.73660124349348,
            1908.9074754816806,
            -312.7883034569373,
            33532.087348679845,
            4079.2718425445355,
            28221.292428143508,
            -4809.158747829297,
        ],
    ),
    "1-C-Fperp": (
        "71c63845ba700764d03d1c3763846232ba9458dec910ae086a557c5bdd91df84",
        [
            2851.937601378139,
            329.0399596161832,
            581.8652213230066,
            149.81241655987196,
            42108.18090170181,
            6419.277694396338,
            11801.998235264706,
            3806.551545315068,
        ],
    ),
    "1-V-F": (
        "64e38284db39966907bfc18258cfbbf1d09e4c53779c527108163c21e3b8f17e",
        [
            2191.630177496788,
            -1407.8023321337027,
            1155.5132531602635,
            792.9751799736753,
            32074.51209689815,
            -22072.351575123797,
            18100.30497779594,
            12904.445989752863,
        ],
    ),
    "1-V-Fperp": (
        "01279529b2e6792ae77094ff664db1e3b63fdd24daa80a2fb3e0e8b9ed0aafed",
        [
            2017.3013673595717,
            -1289.6166439349229,
            1079.7397780751214,
            987.1080670025406,
            27734.443487548288,
            -21166.861635364603,
            20026.41836921243,
            18131.32443346436,
        ],
    ),
    "2-C-F": (
        "7cfc92e4f8f2f5a0fc9cc6f1ea25926feffea735cce12c40d949d34ad3d281ab",
        [
            2904.1610926758544,
            363.8797236276437,
            339.13193668609085,
            -52.75738909960018,
            43009.823765174224,
            8510.201058970904,
            6987.8231461403875,
            -131.04968149054284,
        ],
    ),
    "2-C-Fperp": (
        "b9dcd918218979f63a3b7ee516c6e69076bc56f4bb21544b0d7f51f37827cf49",
        [
            2726.9292838428555,
            -676.911867967366,
            821.2508308453023,
            182.19833550388793,
            39896.905382667974,
            -9451.034832622257,
            16096.637777401022,
            4658.276852834795,
        ],
    ),
    "2-V-F": (
        "06aec756b6d721b033516c35cc0e4505c0dcb961cfa8e795e641728db2b43f3d",
        [
            2573.901802716495,
            -907.5232477251118,
            -1166.6127772565687,
            204.16601809086495,
            38038.81351613916,
            -14721.799645834935,
            -18249.928607723767,
            3555.159606880254,
        ],
    ),
    "2-V-Fperp": (
        "b0a93e42dc99592a732a0e1926b3ca4abd5f5040cef71e04223b9c148967f21a",
        [
            1757.4165599193989,
            -1330.0242698295324,
            171.14271359027416,
            -1641.0820172242754,
            25578.18457739764,
            -21644.257297445558,
            119.2280009627449,
            -28275.24265625651,
        ],
    ),
    "3-C-F": (
        "d0b4f35bbc430af7bf9b7b944e5701cc019179302ffaa2f3f2433d21c9acfa7d",
        [
            978.1235516397413,
            2587.7279704952966,
            -733.8197124384849,
            119.66452392426116,
            13364.302705534534,
            40676.354882492335,
            -12148.797804205537,
            2555.85683483046,
        ],
    ),
    "3-C-Fperp": (
        "5b746a7846d4058a1481183845a646d4aa9d29deab6c84d87590f80fdfb521ca",
        [
            1501.3563262895484,
            -769.6388870550104,
            -2274.817786553551,
            -448.5215366628239,
            20559.754142769238,
            -11868.618774768076,
            -36328.80053152866,
            -6202.255092826885,
        ],
    ),
    "3-V-F": (
        "42a7df677e01a6a5833888c57f0eff0b0aaf429868b96ae463d5a27db3d54c25",
        [
            1175.1540340886195,
            2232.776938686553,
            -1362.8656166277815,
            225.6658927653668,
            14771.147153575217,
            35262.2112350426,
            -22312.408147018912,
            3333.9486686631353,
        ],
    ),
    "3-V-Fperp": (
        "cb7bd29cd122f21af00e0ba792b2214d9f94607c818c8c89995d544961f940b4",
        [
            644.1243739920486,
            -1950.8593049190436,
            -1403.2542751462197,
            -1147.60384822997,
            7464.311336703363,
            -31617.564905728093,
            -21269.98872047584,
            -18401.085049954552,
        ],
    ),
    "slow-rt": (
        "c24be2d94bf3ee83f6b39a8ebfcaa7c915b73ac3e21cada7280f93129090b26f",
        [
            1986.564959578272,
            2017.661719473714,
            -727.8359522390436,
            -154.12953933968558,
            28500.959997951628,
            32839.12078786267,
            -9577.51030764631,
            -1900.9430848256022,
        ],
    ),
    "drawn-C": (
        "134962889e8396cc223198acb660c0be6ffac5f7ea13925ccfd63e697b535e20",
        [
            1437.5945148425608,
            -2479.6411157657994,
            54.11758934838952,
            -479.7517504403821,
            20021.698194100612,
            -39148.73467389437,
            188.5198381554071,
            -8112.521727232611,
        ],
    ),
    "drawn-V": (
        "f38a79830c641458565ba5a0fe981e90f3f084d15cec4714b5ee224dc4dc9928",
        [
            1315.4502400818342,
            -2466.9867818788694,
            -582.2717657957556,
            -308.3174300656965,
            19124.169682464882,
            -38771.18256001653,
            -6461.881268669354,
            -6655.840842316725,
        ],
    ),
}


#: The poses are plain IEEE arithmetic apart from libm's sin/cos/exp/log/atan2, whose last
#: bit may differ between CPUs (glibc picks an FMA code path when the CPU has one), and the
#: reading grid's elementwise numpy operations, which are exact per element. Measured on
#: these 19 loops without glibc's FMA path (GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA):
#: every PWM the same, no sum moved by more than 7.3e-12; with numpy's AVX2/AVX512/FMA3
#: dispatch disabled (NPY_DISABLE_CPU_FEATURES) or OpenBLAS's Prescott kernel: the same
#: bits. 1e-8 leaves a margin of 1000 above that, while a change of the model moves the
#: PWM stream or the sums by far more (a reaction time 1 us longer fails:
#: test_golden_record_notices_a_tiny_model_change).
GOLDEN_TOL = 1e-8


def _golden_run(w, mode, policy, seed, spec="participant", timeout=30.0):
    import hashlib

    vp = VirtualParticipant.from_spec(spec, seed)
    vp.begin_trial(
        contacts=CONTACTS4,
        y_axis=Y_AXIS,
        wrench=w,
        policy=policy,
        mode=mode,
        start_quat=(1.0, 0, 0, 0),
    )
    q = (1.0, 0.0, 0.0, 0.0)
    h = hashlib.sha256()
    sums = [0.0] * 8
    for i in range(int(round(timeout * vp.rate_hz)) + 1):
        t = i / vp.rate_hz
        res = _core.solve(
            contacts=CONTACTS4,
            wrench=w,
            policy=policy,
            mode=mode,
            constraints="paper",
            orientation=list(q),
            y_axis=Y_AXIS,
        )
        q = vp.step(t, res["pwm"])
        h.update(bytes(res["pwm"]))
        for k in range(4):
            sums[k] += q[k]
            sums[4 + k] += t * q[k]
    return h.hexdigest(), sums


def _golden_runs(spec=NOMINAL):
    got = {}
    for i, w in enumerate(_wrenches(4, 2026)):
        for mode in ("C", "V"):
            for policy in ("F", "Fperp"):
                got[f"{i}-{mode}-{policy}"] = _golden_run(w, mode, policy, 100 + i, spec)
    got["slow-rt"] = _golden_run(
        _wrenches(1, 5)[0], "V", "F", 9, NOMINAL + ",reaction_time_s=0.35,erm_tau_s=0.03"
    )
    # Participants drawn across the population (their own parameters, gains and bias).
    for i, mode in enumerate(("C", "V")):
        got[f"drawn-{mode}"] = _golden_run(_wrenches(1, 11)[0], mode, "F", 500 + i, "participant")
    return got


def _golden_mismatches(got):
    bad = []
    for name, (pwm_hash, sums) in GOLDEN.items():
        g_hash, g_sums = got[name]
        if g_hash != pwm_hash:
            bad.append(f"{name}: PWM stream differs")
        worst = max(abs(a - b) for a, b in zip(g_sums, sums))
        if not worst <= GOLDEN_TOL:
            bad.append(f"{name}: pose sums differ by {worst:.3g} (tolerance {GOLDEN_TOL})")
    return bad


def test_closed_loops_match_the_golden_record():
    got = _golden_runs()
    assert sorted(got) == sorted(GOLDEN)
    assert _golden_mismatches(got) == []


def test_golden_record_notices_a_tiny_model_change():
    """The tolerance is no blind spot: a reaction time 1 us longer fails the record."""
    bad = _golden_mismatches(_golden_runs(NOMINAL + ",reaction_time_s=0.210001"))
    assert len(bad) >= len(GOLDEN) // 2, bad


_KERNEL_PROBE = """
import hashlib, sys
sys.path[:0] = sys.argv[1:]
import test_participant as T
h = hashlib.sha256()
for mode in ("C", "V"):
    h.update(repr(T.closed_loop(T._wrenches(1, 2026)[0], mode=mode, seed=100, timeout_s=12.0,
                                record=True)).encode())
print(h.hexdigest())
"""


def test_trajectories_do_not_depend_on_the_openblas_kernel():
    """Every pose, bit for bit, the same under OpenBLAS's oldest x86-64 kernel (Prescott,
    which any x86-64 CPU runs) as under the kernel this CPU picks. The kernel is chosen
    when numpy loads, hence the two fresh interpreters. (The old numpy path failed this
    on a SkylakeX CPU.)"""
    # The child imports this module and the same graspguide as this process.
    paths = [
        os.path.dirname(os.path.abspath(__file__)),
        os.path.dirname(os.path.dirname(os.path.abspath(__file__))),  # conftest's folder
        os.path.dirname(os.path.dirname(os.path.abspath(_core.__file__))),
    ]
    digests = {}
    for kernel in (None, "Prescott"):
        env = subprocess_env()
        env.pop("OPENBLAS_CORETYPE", None)
        if kernel:
            env["OPENBLAS_CORETYPE"] = kernel
        out = subprocess.run(
            [sys.executable, "-c", _KERNEL_PROBE, *paths],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert out.returncode == 0, out.stderr
        digests[kernel] = out.stdout.strip()
    assert len(digests[None]) == 64 and digests[None] == digests["Prescott"]


def _lockstep_vs_pipelined(w, mode, policy, seed, spec, lead, n):
    """The core as the device; lockstep step() against act() running `lead` poses ahead
    of feel() (the device's answers arrive `lead` poses late)."""

    def pwm_of(q):
        return _core.solve(
            contacts=CONTACTS4,
            wrench=w,
            policy=policy,
            mode=mode,
            constraints="paper",
            orientation=list(q),
            y_axis=Y_AXIS,
        )["pwm"]

    a = new_participant(spec, seed, mode, policy, w)
    lock = [a.step(0.0, [0, 0, 0, 0])]
    for j in range(1, n):
        lock.append(a.step(j / 100.0, pwm_of(lock[-1])))
    b = new_participant(spec, seed, mode, policy, w)
    pipe = []
    felt = 0
    for j in range(n):
        while felt <= j - lead:
            b.feel(felt / 100.0, pwm_of(pipe[felt]))
            felt += 1
        pipe.append(b.act(j / 100.0))
    return lock, pipe


@pytest.mark.parametrize("mode", ["C", "V"])
def test_act_ahead_of_feel_equals_lockstep_bit_for_bit(mode):
    vp = new_participant()
    assert vp.max_lead(100.0) == 20
    for i, w in enumerate(_wrenches(3, 77)):
        for spec in ("participant", "participant:reaction_time_s=0.05,erm_tau_s=0.01"):
            lead = VirtualParticipant.from_spec(spec, 0).max_lead(100.0)
            lock, pipe = _lockstep_vs_pipelined(w, mode, "F", 40 + i, spec, lead, 1500)
            assert pipe == lock
            assert len({q for q in lock}) > 100  # it moved


def test_act_depends_only_on_pwm_felt_a_reaction_time_earlier():
    """Change every PWM from pose c on: the poses up to c + reaction_time * rate do not
    change (pose j sees the PWM of pose m only if t_m < t_j - reaction_time_s)."""
    rng = np.random.default_rng(5)
    base = rng.integers(0, 256, size=(600, 4))
    changed_somewhere = False
    for mode in ("C", "V"):
        for c in (0, 10, 37, 150, 333):
            other = base.copy()
            other[c:] = rng.integers(0, 256, size=(600 - c, 4))
            out = []
            for pwm in (base, other):
                vp = new_participant(mode=mode, seed=3)
                q = [vp.step(0.0, [0, 0, 0, 0])]
                q += [vp.step((m + 1) / 100.0, list(pwm[m])) for m in range(599)]
                out.append(q)
            unchanged = c + 21  # t_c < t_j - 0.21 s needs j > c + 21
            assert out[0][: unchanged + 1] == out[1][: unchanged + 1], (mode, c)
            changed_somewhere |= out[0] != out[1]
    assert changed_somewhere


def test_act_too_far_ahead_of_feel_is_refused():
    vp = new_participant()
    lead = vp.max_lead(100.0)
    first_refused = None
    for j in range(40):
        try:
            vp.act(j / 100.0)
        except FeelLagError as e:
            first_refused = j
            assert "ahead" in str(e)
            break
    assert first_refused is not None and lead < first_refused <= lead + 3


def test_feel_checks_its_input_once_with_a_clear_error():
    vp = new_participant()
    vp.act(0.0)
    for pwm, words in (
        ([0, 0, float("nan"), 0], "finite"),
        ([0, 0, 0], "4 values"),
        ([0, 0, 0, 0, 0], "4 values"),
        ([0, 0, 256, 0], "0..255"),
        ([True, 0, 0, 0], "numbers"),
        ("abcd", "numbers"),
    ):
        with pytest.raises(ValueError, match=words):
            vp.feel(0.0, pwm)
    with pytest.raises(ValueError, match="oldest pose"):
        vp.feel(0.01, [0, 0, 0, 0])  # no act at 0.01
    vp.feel(0.0, (10, 20.0, np.int64(3), np.float32(4)))  # any numbers: slow path
    with pytest.raises(ValueError, match="oldest pose"):
        vp.feel(0.0, [0, 0, 0, 0])  # felt twice
    vp.act(0.01)
    vp.act(0.02)
    with pytest.raises(RuntimeError, match="feel"):
        vp.step(0.03, [0, 0, 0, 0])  # two poses not felt: ambiguous
    vp.feel(0.01, [0, 0, 0, 0])
    vp.step(0.03, [0, 0, 0, 0])  # feel(0.02, ..) + act(0.03)
    with pytest.raises(ValueError, match="backwards"):
        vp.act(0.025)
