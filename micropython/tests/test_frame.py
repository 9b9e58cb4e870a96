"""The per-frame layer (graspguide_mp.frame) inside MicroPython: the error, alpha and PWM
against the float64 reference, the gravity estimator against the C++ one (both in
tests/data/frame_reference.json, made by tests/host/make_reference.py), and every failure
path of the frame layer, the trial and the IMU health rule."""

import math

from graspguide_mp import frame
from graspguide_mp import status as st
from hostless_helpers import close, load_json

NAN = float("nan")
INF = float("inf")
_REF = None


def _ref():
    global _REF
    if _REF is None:
        _REF = load_json("frame_reference.json")
    return _REF


# ---------------------------------------------------------------- alignment
def test_alignment_matches_reference():
    out = [0.0, 0.0]
    scratch = [0.0, 0.0, 0.0]
    cases = _ref()["alignment"]
    assert len(cases) > 60
    for g, f, err, alpha in cases:
        assert frame.alignment_from_gravity(g, f, out, scratch) == st.OK
        close(out[0], err, 1e-9 + 1e-12 * err, "error_deg for g=%r f=%r" % (g, f))
        close(out[1], alpha, 1e-9, "alpha for g=%r f=%r" % (g, f))


def test_alignment_refuses_bad_gravity():
    out = [7.0, 7.0]
    scratch = [0.0, 0.0, 0.0]
    f = [0.0, 0.0, -1.0]
    for g in ([NAN, 0.0, -1.0], [0.0, INF, -1.0], [0.0, 0.0, -INF]):
        assert frame.alignment_from_gravity(g, f, out, scratch) == st.NON_FINITE_INPUT, g
    for g in ([0.0, 0.0, 0.0], [1e-7, 0.0, 0.0]):
        assert frame.alignment_from_gravity(g, f, out, scratch) == st.BAD_AXIS, g
    assert out == [7.0, 7.0]  # a refused frame writes nothing
    # Finite components whose squares overflow are scaled, not refused.
    assert frame.alignment_from_gravity([0.0, 0.0, -1e300], f, out, scratch) == st.OK
    close(out[0], 0.0, 1e-12, "error_deg of an overflowing gravity")


# ---------------------------------------------------------------- PWM
def test_pwm_matches_reference():
    duty = bytearray(4)
    cases = _ref()["pwm"]
    assert len(cases) > 40
    for levels, mode, alpha, want in cases:
        m = frame.MODE_C if mode == "C" else frame.MODE_V
        frame.pwm_from_plan(frame.PwmPlan(levels, len(levels)), frame.pwm_gain(m, alpha), duty)
        assert list(duty[: len(levels)]) == want, (levels, mode, alpha, list(duty), want)
        assert all(d == 0 for d in duty[len(levels) :])


def test_pwm_with_a_calibration_matches_the_float64_reference():
    # floor_i + G (gain_i |m_i|), rounded half up and clamped: the float64 reference's
    # (tests/host/make_reference.py), the same integers through the doubling trick.
    duty = bytearray(4)
    cases = _ref()["pwm_calibrated"]
    assert len(cases) > 40
    changed = 0
    for levels, mode, alpha, floor, gain, want, identity_pwm in cases:
        m = frame.MODE_C if mode == "C" else frame.MODE_V
        plan = frame.PwmPlan(levels, len(levels), floor, gain)
        frame.pwm_from_plan(plan, frame.pwm_gain(m, alpha), duty)
        assert list(duty[: len(levels)]) == want, (levels, mode, alpha, floor, gain, list(duty))
        assert all(d == 0 for d in duty[len(levels) :])
        changed += want != identity_pwm
    assert changed > len(cases) // 2, "the calibration changed too few cases to test it"


def test_identity_calibration_is_the_papers_pwm():
    duty = bytearray(4)
    plain = bytearray(4)
    for levels, mode, alpha, want in _ref()["pwm"]:
        m = frame.MODE_C if mode == "C" else frame.MODE_V
        plan = frame.PwmPlan(levels, len(levels), frame.IDENTITY_FLOOR, frame.IDENTITY_GAIN)
        frame.pwm_from_plan(plan, frame.pwm_gain(m, alpha), duty)
        frame.pwm_from_plan(frame.PwmPlan(levels, len(levels)), frame.pwm_gain(m, alpha), plain)
        assert duty == plain and list(duty[: len(levels)]) == want


def test_pwm_off_rules():
    duty = bytearray(b"\x09\x09\x09\x09")
    plan = frame.PwmPlan([0.5, NAN, frame.MOTOR_OFF_LEVEL, -0.5], 4)
    frame.pwm_from_plan(plan, NAN, duty)
    assert duty == b"\0\0\0\0", "a NaN gain leaves every motor off"
    frame.pwm_from_plan(plan, 100.0, duty)
    assert duty[1] == 0 and duty[2] == 0, "NaN and off-level motors stay off"
    assert duty[0] == duty[3] > frame.PWM_MIN
    frame.pwm_from_plan(plan, 1e12, duty)
    assert duty[0] == 255 and duty[3] == 255
    frame.pwm_from_plan(plan, -1e12, duty)
    assert duty[0] == 0 and duty[3] == 0, "below zero clamps to off"
    inf_plan = frame.PwmPlan([INF, 0.2, 0.0], 3)
    frame.pwm_from_plan(inf_plan, 10.0, duty)
    assert duty[0] == 255 and duty[1] == round(frame.PWM_MIN + 10.0 * 0.2)


# ---------------------------------------------------------------- trial
def test_trial_succeeds_after_hold():
    t = frame.Trial()
    assert t.start(3.0, 0.5, 90.0, 1000) == st.OK
    t.update(1000, 10.0)
    t.update(2000, 2.0)  # enters
    t.update(500000, 2.5)
    assert t.running()
    t.update(501999, 3.0)
    assert t.running(), "0.499999 s of hold is not enough"
    t.update(502000, 3.0)
    assert t.state == frame.TRIAL_SUCCEEDED and t.success
    close(t.completion_s, 0.501, 1e-12, "completion_s")
    close(t.first_entry_s, 0.001, 1e-12, "first_entry_s")
    assert t.update(600000, 50.0) == st.OK and t.final_error_deg == 3.0, "ended: ignored"


def test_trial_leaving_restarts_hold_and_times_out():
    t = frame.Trial()
    t.start(3.0, 0.5, 1.0, 0)
    t.update(100000, 1.0)
    t.update(400000, 3.5)  # left: the hold starts again
    t.update(500000, 1.0)
    t.update(900000, 1.0)
    assert t.running()
    t.update(1200000, 1.0)  # past the timeout, although held 0.7 s
    assert t.state == frame.TRIAL_FAILED and not t.success
    assert t.completion_s == 1.0, "a timeout is reported as exactly the timeout"
    close(t.first_entry_s, 0.1, 1e-12, "first_entry_s")


def test_trial_refusals():
    t = frame.Trial()
    for args in (
        (-0.1, 0.5, 90.0),
        (181.0, 0.5, 90.0),
        (3.0, -1.0, 90.0),
        (3.0, 601.0, 900.0),
        (3.0, 0.5, 0.0),
        (3.0, 0.5, 1801.0),
        (3.0, 2.0, 1.0),
        (NAN, 0.5, 90.0),
    ):
        assert t.start(args[0], args[1], args[2], 0) == st.BAD_CONFIG, args
        assert not t.running()
    t.start(3.0, 0.5, 90.0, 1000)
    assert t.update(999, 1.0) == st.TIME_WENT_BACKWARDS
    assert t.update(2000, NAN) == st.NON_FINITE_INPUT
    assert t.first_entry_s == -1.0 and t.running(), "refused samples change nothing"
    t.expire()
    assert t.state == frame.TRIAL_FAILED and t.completion_s == 90.0
    t.start(3.0, 0.5, 90.0, 0)
    t.abort()
    assert t.state == frame.TRIAL_IDLE


# ---------------------------------------------------------------- IMU health rule
A = [0.1, 0.2, 9.8]
G = [0.01, -0.02, 0.03]


def _wd(now=0):
    return frame.ImuWatchdog(78.45, 34.9, now)


def _feed(wd, n, t0, dt=10000, accel=None):
    t = t0
    for i in range(n):
        a = accel if accel is not None else [A[0] + i * 1e-3, A[1], A[2]]
        wd.on_sample(a, G, t)
        t += dt
    return t


def test_imu_starts_stale_and_recovers_after_n_good_samples():
    wd = _wd()
    assert wd.status == st.IMU_STALE and not wd.motors_allowed()
    t = _feed(wd, frame.IMU_RECOVERY_SAMPLES - 1, 0)
    assert wd.status == st.IMU_STALE
    _feed(wd, 1, t)
    assert wd.motors_allowed()
    assert wd.fault_total() == 0, "the start is no fault"


def test_imu_stale_and_recovery():
    wd = _wd()
    t = _feed(wd, 12, 0)
    last = t - 10000
    assert wd.poll(last + 99999) == st.OK
    assert wd.poll(last + 100000) == st.IMU_STALE and wd.stale_count == 1
    wd.poll(last + 500000)
    assert wd.stale_count == 1, "an onset counts once"
    t = _feed(wd, frame.IMU_RECOVERY_SAMPLES - 1, last + 600000)
    assert not wd.motors_allowed()
    _feed(wd, 1, t)
    assert wd.motors_allowed()


def test_imu_stale_across_clock_wrap():
    start = frame.TICKS_PERIOD - 50000
    wd = _wd(start)
    t = start
    for i in range(12):
        wd.on_sample([A[0] + i * 1e-3, A[1], A[2]], G, t)
        t = frame.ticks_add(t, 10000)
    last = frame.ticks_add(t, -10000)
    assert last < start, "the clock wrapped"
    assert wd.poll(frame.ticks_add(last, 50000)) == st.OK
    assert wd.poll(frame.ticks_add(last, 100000)) == st.IMU_STALE
    # A sample stamped just after a poll's "now" is not ancient.
    wd2 = _wd(0)
    _feed(wd2, 12, 0)
    wd2.on_sample([1.0, 2.0, 3.0], G, 200000)
    assert wd2.poll(199000) == st.OK


def test_imu_stuck():
    wd = _wd()
    t = _feed(wd, 12, 0)
    t = _feed(wd, frame.IMU_STUCK_SAMPLES - 1, t, accel=[1.0, 2.0, 9.0])
    assert wd.motors_allowed()
    t = _feed(wd, 1, t, accel=[1.0, 2.0, 9.0])
    assert wd.status == st.IMU_STUCK and wd.stuck_count == 1
    t = _feed(wd, 5, t, accel=[1.0, 2.0, 9.0])
    assert wd.stuck_count == 1
    t = _feed(wd, frame.IMU_RECOVERY_SAMPLES, t)
    assert wd.motors_allowed()


def test_imu_out_of_range():
    for bad in ([80.0, 0.0, 9.8], [0.0, NAN, 9.8], [0.0, 0.0, -INF]):
        wd = _wd()
        t = _feed(wd, 12, 0)
        wd.on_sample(bad, G, t)
        assert wd.status == st.IMU_OUT_OF_RANGE and wd.out_of_range_count == 1, bad
        assert not wd.motors_allowed()
    wd = _wd()
    t = _feed(wd, 12, 0)
    wd.on_sample(A, [0.0, 35.0, 0.0], t)
    assert wd.status == st.IMU_OUT_OF_RANGE, "the gyro's full scale too"


def test_imu_bad_config_holds_motors_off():
    for args in ((0.0, 34.9), (NAN, 34.9), (78.0, INF), (78.0, -1.0)):
        wd = frame.ImuWatchdog(args[0], args[1], 0)
        _feed(wd, 30, 0)
        assert wd.status == st.BAD_IMU_CONFIG and not wd.motors_allowed(), args
    for kw in ({"stale_ms": 0}, {"stale_ms": 60001}, {"stuck_samples": 1}, {"recovery_samples": 0}):
        wd = frame.ImuWatchdog(78.0, 34.9, 0, **kw)
        _feed(wd, 30, 0)
        assert wd.status == st.BAD_IMU_CONFIG, kw


# ---------------------------------------------------------------- gravity estimator
def test_estimator_matches_cpp():
    ref = _ref()["estimator"]
    est = frame.GravityEstimator()
    dt = ref["dt_s"]
    worst = 0.0
    for i in range(len(ref["accel"])):
        assert est.update(ref["accel"][i], ref["gyro"][i], dt) == st.OK
        assert est.accel_trusted == ref["trusted"][i], "gate at sample %d" % i
        for j in range(3):
            d = abs(est.gravity[j] - ref["gravity"][i][j])
            worst = d if d > worst else worst
            close(est.bias_radps[j], ref["bias"][i][j], 1e-12, "bias[%d] at sample %d" % (j, i))
    assert worst <= 1e-12, "gravity differs from the C++ by %g" % worst
    assert not all(ref["trusted"]), "the stream has knocks the gate drops"


def test_estimator_refusals_change_nothing():
    est = frame.GravityEstimator()
    assert est.update([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.01) == st.BAD_AXIS
    assert not est.initialised
    assert est.update([0.0, 0.0, 9.8], [0.0, 0.0, 0.0], 0.01) == st.OK
    before = list(est.gravity)
    for a, g, dt, want in (
        ([NAN, 0.0, 9.8], [0.0, 0.0, 0.0], 0.01, st.NON_FINITE_INPUT),
        ([0.0, 0.0, 9.8], [0.0, INF, 0.0], 0.01, st.NON_FINITE_INPUT),
        ([0.0, 0.0, 9.8], [0.0, 0.0, 0.0], NAN, st.NON_FINITE_INPUT),
        ([0.0, 0.0, 9.8], [0.0, 0.0, 0.0], 0.0, st.BAD_CONFIG),
        ([0.0, 0.0, 9.8], [0.0, 0.0, 0.0], -0.01, st.BAD_CONFIG),
        ([0.0, 0.0, 9.8], [0.0, 0.0, 0.0], 0.1001, st.BAD_CONFIG),
    ):
        assert est.update(a, g, dt) == want, (a, g, dt)
        assert list(est.gravity) == before
    # After the first estimate a zero accelerometer is simply not trusted.
    assert est.update([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.01) == st.OK
    assert not est.accel_trusted


def test_estimator_bias_clamp_and_gains():
    est = frame.GravityEstimator()
    assert est.configure(0.4, -0.1, 2.0) == st.BAD_CONFIG
    assert est.configure(0.4, 0.1, 0.0) == st.BAD_CONFIG
    assert est.configure(NAN, 0.1, 2.0) == st.BAD_CONFIG
    assert est.ki_per_s2 == frame.GRAVITY_KI_PER_S2, "a refused gain changes nothing"
    assert est.configure(0.4, 1000.0, 2.0) == st.OK
    est.update([0.0, 0.0, 9.8], [0.0, 0.0, 0.0], 0.01)
    # The accelerometer says 90 degrees away: the integrator runs into its clamp.
    for _ in range(50):
        est.update([9.8, 0.0, 0.0], [0.0, 0.0, 0.0], 0.01)
    b = max(abs(est.bias_radps[0]), abs(est.bias_radps[1]), abs(est.bias_radps[2]))
    assert b == frame.MAX_GYRO_BIAS_RADPS, b


def test_estimator_fused():
    est = frame.GravityEstimator()
    assert est.set_fused([0.0, NAN, 1.0]) == st.NON_FINITE_INPUT
    assert est.set_fused([0.0, 0.0, 1e-7]) == st.BAD_AXIS
    assert not est.initialised
    assert est.set_fused([0.0, 3.0, 4.0]) == st.OK
    close(est.gravity[1], -0.6, 1e-15, "fused gravity y")
    close(est.gravity[2], -0.8, 1e-15, "fused gravity z")
    assert est.set_fused([1e300, 1e300, 0.0]) == st.OK
    close(est.gravity[0], -math.sqrt(0.5), 1e-15, "fused gravity from huge components")
