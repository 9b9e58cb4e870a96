"""The per-frame layer of lib/graspguide_cue in MicroPython: the guidance error and alpha
from gravity, PWM from motor levels, the trial state machine, the IMU health rule and the
gravity estimator. Same numbers and statuses as the C++ (alignment.h, pwm.h, trial.h,
imu_watchdog.h, gravity_estimator.h); no list is made per frame: results go into lists
the caller owns. Lists, not array('d'): reading an array item boxes a new float on the
heap, reading a list item does not. Every float an operation makes is still a heap object
on MicroPython's usual builds (bench_frame.py measures how many bytes a frame costs).

Times are ticks of a free-running microsecond clock with period TICKS_PERIOD (2^30, the
period of time.ticks_us on 32-bit ports, so every tick stays a small int and costs no heap);
differences go through ticks_diff, as the C++ does with unsigned 32-bit ticks."""

import math

from graspguide_mp import status as st

# config.h / tolerances.h
PWM_MIN = 70
PWM_SPAN = 185
MIN_CONTACTS = 3
MAX_CONTACTS = 4
MOTOR_OFF_LEVEL = 1e-3
MIN_QUATERNION_NORM = 1e-6

TICKS_PERIOD = 1 << 30
TICKS_MASK = TICKS_PERIOD - 1
_TICKS_HALF = TICKS_PERIOD >> 1

_INF = math.inf
_RAD_TO_DEG = 180.0 / math.pi
_HALF_SPAN = PWM_SPAN * 0.5


def ticks_add(t, delta):
    return (t + delta) & TICKS_MASK


def ticks_diff(a, b):
    """a - b as a signed number of ticks, right across the clock's wrap."""
    d = (a - b) & TICKS_MASK
    return d - TICKS_PERIOD if d >= _TICKS_HALF else d


def _finite(x):
    # NaN fails both comparisons, infinity one of them.
    return -_INF < x < _INF


# ---------------------------------------------------------------- alignment.h
def asin_deg_ratio(z):
    """asin(sqrt(z)) / sqrt(z) in degrees (scalar_math.h's double version)."""
    if not z > 0.0:
        return _RAD_TO_DEG
    x = math.sqrt(z)
    return math.asin(x) / x * _RAD_TO_DEG


def alignment_to_gravity(f, g, out):
    """out[0] = error_deg, out[1] = alpha for unit f_hat and unit g_hat (hand frame).
    The three ranges of alignment.h: asin's argument stays in [-0.5, 0.5], no cancellation."""
    d0 = f[0] - g[0]
    d1 = f[1] - g[1]
    d2 = f[2] - g[2]
    chord2 = d0 * d0 + d1 * d1 + d2 * d2
    chord = math.sqrt(chord2)
    out[1] = chord * _HALF_SPAN
    if chord2 <= 1.0:
        out[0] = chord * asin_deg_ratio(chord2 * 0.25)
    elif chord2 <= 3.0:
        c = 1.0 - chord2 * 0.5
        out[0] = 90.0 - c * asin_deg_ratio(c * c)
    else:
        s0 = f[0] + g[0]
        s1 = f[1] + g[1]
        s2 = f[2] + g[2]
        sum2 = s0 * s0 + s1 * s1 + s2 * s2
        out[0] = 180.0 - math.sqrt(sum2) * asin_deg_ratio(sum2 * 0.25)


def alignment_from_gravity(gravity, f_hat, out, scratch):
    """Error and alpha (into out) from a gravity direction in the hand frame of any finite
    non-zero length: OK, NON_FINITE_INPUT, or BAD_AXIS when shorter than
    MIN_QUATERNION_NORM. scratch: 3 floats the caller owns (no allocation)."""
    g0 = gravity[0]
    g1 = gravity[1]
    g2 = gravity[2]
    n2 = g0 * g0 + g1 * g1 + g2 * g2
    if not n2 < _INF:
        m = 0.0
        for v in (g0, g1, g2):
            if not _finite(v):
                return st.NON_FINITE_INPUT
            if abs(v) > m:
                m = abs(v)
        g0 /= m
        g1 /= m
        g2 /= m
        n2 = g0 * g0 + g1 * g1 + g2 * g2
    elif not n2 >= MIN_QUATERNION_NORM * MIN_QUATERNION_NORM:
        return st.BAD_AXIS
    inv = 1.0 / math.sqrt(n2)
    scratch[0] = g0 * inv
    scratch[1] = g1 * inv
    scratch[2] = g2 * inv
    alignment_to_gravity(f_hat, scratch, out)
    return st.OK


# ---------------------------------------------------------------- pwm.h
MODE_C = 0
MODE_V = 1


def pwm_gain(mode, alpha):
    return float(PWM_SPAN) if mode == MODE_C else alpha


# A participant's calibration (graspguide_cue/motor_calibration.h): per motor a PWM floor
# and a gain; IDENTITY_FLOOR / IDENTITY_GAIN give the paper's mapping bit for bit.
CALIBRATION_MOTORS = 4
IDENTITY_FLOOR = (PWM_MIN,) * CALIBRATION_MOTORS
IDENTITY_GAIN = (1.0,) * CALIBRATION_MOTORS


class PwmPlan:
    """What one posture's PWM needs, worked out once (pwm.h's plan_pwm with a calibration):
    which motors are on, 2 floor_i, 2 (gain_i |m_i|), and the gain below which no motor
    reaches 255."""

    def __init__(self, levels=None, k=0, pwm_floor=IDENTITY_FLOOR, gain=IDENTITY_GAIN):
        self.on = 0
        self.twice_floor = [0, 0, 0, 0]
        self.twice_level = [0.0, 0.0, 0.0, 0.0]
        self.gain_limit = 0.0
        if levels is not None:
            self.set(levels, k, pwm_floor, gain)

    def set(self, levels, k, pwm_floor=IDENTITY_FLOOR, gain=IDENTITY_GAIN):
        self.on = 0
        self.gain_limit = _INF
        for i in range(MAX_CONTACTS):
            self.twice_level[i] = 0.0
            self.twice_floor[i] = 2 * pwm_floor[i]
            if i >= k:
                continue
            level = abs(levels[i])
            # At or below the off level (and NaN) a motor stays off: float noise never
            # switches it on at its floor. The rule is on |m_i|, before the gain.
            if not level > MOTOR_OFF_LEVEL:
                continue
            self.on |= 1 << i
            # gain_i |m_i| first, then doubled (exact): the reference's order,
            # floor_i + G (gain_i |m_i|).
            scaled = gain[i] * level
            self.twice_level[i] = scaled + scaled
            if self.twice_level[i] > 0.0:
                limit = (2 * 255 - 1 - self.twice_floor[i]) / self.twice_level[i]
                if limit < self.gain_limit:
                    self.gain_limit = limit
        # No motor on, or an infinite level: every frame takes the checked path.
        if not self.gain_limit < _INF or self.gain_limit != self.gain_limit:
            self.gain_limit = 0.0
        return self


def pwm_from_plan(plan, gain, duty):
    """duty[0..3] (a bytearray) = floor(floor_i + gain (gain_i |m_i|) + 0.5) clamped to
    0..255, by pwm.h's doubling trick (the same integers as the float64 reference's
    rounding)."""
    in_range = 0.0 <= gain < plan.gain_limit
    on = plan.on
    for i in range(MAX_CONTACTS):
        duty[i] = 0
        if not on & (1 << i):
            continue
        twice = plan.twice_floor[i] + gain * plan.twice_level[i]
        if not in_range:
            if not twice >= 0.0:  # below 0 (clamped), or NaN
                continue
            if twice >= 2 * 255 - 1:
                duty[i] = 255
                continue
        duty[i] = (int(twice) + 1) >> 1


def pwm_from_levels(levels, k, gain, pwm_floor=IDENTITY_FLOOR, calibration_gain=IDENTITY_GAIN):
    duty = bytearray(MAX_CONTACTS)
    pwm_from_plan(PwmPlan(levels, k, pwm_floor, calibration_gain), gain, duty)
    return duty


# ---------------------------------------------------------------- trial_config.h
THRESHOLD_MAX_DEG = 180.0
HOLD_MAX_S = 600.0
TIMEOUT_MAX_S = 1800.0


def trial_config_field(threshold_deg, hold_s, timeout_s):
    """None when the trial's parameters are in range, else the first bad field's name."""
    if not 0.0 <= threshold_deg <= THRESHOLD_MAX_DEG:
        return "threshold_deg"
    if not 0.0 <= hold_s <= HOLD_MAX_S:
        return "hold_s"
    if not 0.0 < timeout_s <= TIMEOUT_MAX_S:
        return "timeout_s"
    if hold_s > timeout_s:
        return "hold_s"
    return None


# ---------------------------------------------------------------- trial.h
TRIAL_IDLE = 0
TRIAL_RUNNING = 1
TRIAL_SUCCEEDED = 2
TRIAL_FAILED = 3


class Trial:
    """The trial as a state machine on injected microsecond times (plain ints, not ticks:
    the runner accumulates them): success once the error stayed within the threshold for
    the hold, failure at the timeout, reported as exactly the timeout."""

    def __init__(self):
        self.state = TRIAL_IDLE
        self.threshold_deg = 3.0
        self._hold_us = 0
        self._timeout_us = 0
        self._start_us = 0
        self._last_us = 0
        self._entry_us = -1
        self._clear_result()

    def _clear_result(self):
        self.success = False
        self.completion_s = 0.0
        self.first_entry_s = -1.0
        self.final_error_deg = 0.0

    def start(self, threshold_deg, hold_s, timeout_s, t_us):
        if trial_config_field(threshold_deg, hold_s, timeout_s) is not None:
            return st.BAD_CONFIG
        self.threshold_deg = threshold_deg
        self._hold_us = int(hold_s * 1e6 + 0.5)
        self._timeout_us = int(timeout_s * 1e6 + 0.5)
        self._start_us = self._last_us = t_us
        self._entry_us = -1
        self._clear_result()
        self.state = TRIAL_RUNNING
        return st.OK

    def update(self, t_us, error_deg):
        """One error sample: OK (state tells whether it ended), or TIME_WENT_BACKWARDS /
        NON_FINITE_INPUT, which change nothing."""
        if self.state != TRIAL_RUNNING:
            return st.OK
        if t_us < self._last_us:
            return st.TIME_WENT_BACKWARDS
        if error_deg != error_deg:
            return st.NON_FINITE_INPUT
        self._last_us = t_us
        elapsed = t_us - self._start_us
        self.final_error_deg = error_deg
        if error_deg <= self.threshold_deg:
            if self._entry_us < 0:
                self._entry_us = t_us
            if self.first_entry_s < 0:
                self.first_entry_s = elapsed * 1e-6
            if t_us - self._entry_us >= self._hold_us and elapsed <= self._timeout_us:
                self._finish(True, elapsed)
                return st.OK
        else:
            self._entry_us = -1
        if elapsed >= self._timeout_us:
            self._finish(False, self._timeout_us)
        return st.OK

    def abort(self):
        if self.state == TRIAL_RUNNING:
            self.state = TRIAL_IDLE

    def expire(self):
        """Ends a running trial as timed out whatever its times say: the caller's clock saw
        the timeout pass (timestamps that stopped advancing)."""
        if self.state == TRIAL_RUNNING:
            self._finish(False, self._timeout_us)

    def running(self):
        return self.state == TRIAL_RUNNING

    def _finish(self, success, elapsed_us):
        self.success = success
        self.completion_s = elapsed_us * 1e-6
        self.state = TRIAL_SUCCEEDED if success else TRIAL_FAILED


# ---------------------------------------------------------------- imu_watchdog.h
IMU_STALE_MS = 100
IMU_STUCK_SAMPLES = 20
IMU_RECOVERY_SAMPLES = 10
IMU_MAX_STALE_MS = 60000


def imu_config_status(stale_ms, stuck_samples, recovery_samples, accel_fs_mps2, gyro_fs_radps):
    ok = (
        1 <= stale_ms <= IMU_MAX_STALE_MS
        and stuck_samples >= 2
        and recovery_samples >= 1
        and _finite(accel_fs_mps2)
        and accel_fs_mps2 > 0.0
        and _finite(gyro_fs_radps)
        and gyro_fs_radps > 0.0
    )
    return st.OK if ok else st.BAD_IMU_CONFIG


class ImuWatchdog:
    """Is the IMU fit to guide by? Stale (no sample for stale_ms), stuck (the same six
    channels stuck_samples times in a row), out of range (beyond the part's full scale,
    NaN); after any fault recovery_samples good samples before the motors may run again.
    Counts the onset of each fault. An invalid config holds BAD_IMU_CONFIG for good."""

    def __init__(
        self,
        accel_fs_mps2,
        gyro_fs_radps,
        now_ticks,
        stale_ms=IMU_STALE_MS,
        stuck_samples=IMU_STUCK_SAMPLES,
        recovery_samples=IMU_RECOVERY_SAMPLES,
    ):
        self.accel_fs_mps2 = accel_fs_mps2
        self.gyro_fs_radps = gyro_fs_radps
        self._neg_accel_fs = -accel_fs_mps2
        self._neg_gyro_fs = -gyro_fs_radps
        self.stale_ms = stale_ms
        self.stuck_samples = stuck_samples
        self.recovery_samples = recovery_samples
        self._config_status = imu_config_status(
            stale_ms, stuck_samples, recovery_samples, accel_fs_mps2, gyro_fs_radps
        )
        self._stale_us = stale_ms * 1000
        self.stale_count = 0
        self.stuck_count = 0
        self.out_of_range_count = 0
        self.samples = 0
        self._previous = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        self.restart(now_ticks)

    def restart(self, now_ticks):
        """Forgets the history, keeps the counts: as at construction."""
        self._last_sample = now_ticks
        self._stale = False
        self._stuck = False
        self._out_of_range = False
        self._have_previous = False
        self._repeats = 0
        self._good_run = 0
        self.status = st.IMU_STALE if self._config_status == st.OK else self._config_status

    def fault_total(self):
        return self.stale_count + self.stuck_count + self.out_of_range_count

    def on_sample(self, accel, gyro, time_ticks):
        if self._config_status != st.OK:
            return self.status
        self.samples += 1
        self._last_sample = time_ticks
        self._stale = False
        afs = self.accel_fs_mps2
        gfs = self.gyro_fs_radps
        neg_afs = self._neg_accel_fs
        neg_gfs = self._neg_gyro_fs
        prev = self._previous
        in_range = True
        same = self._have_previous
        for i in range(3):
            a = accel[i]
            g = gyro[i]
            # NaN fails the comparison too: it is out of range. (No abs(): each call
            # would box a new float on the heap.)
            if not (neg_afs <= a <= afs and neg_gfs <= g <= gfs):
                in_range = False
            # Exact on purpose: the same raw counts convert to the same float.
            if same and not (a == prev[i] and g == prev[3 + i]):
                same = False
            prev[i] = a
            prev[3 + i] = g
        self._have_previous = True
        if same:
            if self._repeats < 0xFFFF:
                self._repeats += 1
        else:
            self._repeats = 1
        stuck_now = self._repeats >= self.stuck_samples
        if stuck_now and not self._stuck:
            self.stuck_count += 1
        self._stuck = stuck_now
        if not in_range and not self._out_of_range:
            self.out_of_range_count += 1
        self._out_of_range = not in_range
        if self._out_of_range or self._stuck:
            self._good_run = 0
            self.status = st.IMU_OUT_OF_RANGE if self._out_of_range else st.IMU_STUCK
        elif self.status != st.OK:
            self._good_run += 1
            if self._good_run >= self.recovery_samples:
                self.status = st.OK
        return self.status

    def poll(self, now_ticks):
        """The time check, once per control loop: a signed tick difference, so a sample
        stamped just after now never reads as ancient."""
        if self._config_status != st.OK:
            return self.status
        if not self._stale and ticks_diff(now_ticks, self._last_sample) >= self._stale_us:
            self._stale = True
            self.stale_count += 1
            self._good_run = 0
            self.status = st.IMU_STALE
        return self.status

    def motors_allowed(self):
        return self.status == st.OK


# ---------------------------------------------------------------- gravity_estimator.h
GRAVITY_KP_PER_S = 0.4
GRAVITY_KI_PER_S2 = 0.1
GRAVITY_ACCEL_GATE_MPS2 = 2.0
STANDARD_GRAVITY_MPS2 = 9.80665
MAX_SAMPLE_INTERVAL_S = 0.1
MAX_GYRO_BIAS_RADPS = 0.35
MIN_ACCEL_MPS2 = 1e-3


def gravity_gains_status(kp_per_s, ki_per_s2, accel_gate_mps2):
    if not (_finite(kp_per_s) and _finite(ki_per_s2) and _finite(accel_gate_mps2)):
        return st.BAD_CONFIG
    if kp_per_s < 0.0 or ki_per_s2 < 0.0 or not accel_gate_mps2 > 0.0:
        return st.BAD_CONFIG
    return st.OK


def _clamp_bias(v):
    # The clamp stops the integrator winding up on what is not bias.
    if v > MAX_GYRO_BIAS_RADPS:
        return MAX_GYRO_BIAS_RADPS
    if v < -MAX_GYRO_BIAS_RADPS:
        return -MAX_GYRO_BIAS_RADPS
    return v


class GravityEstimator:
    """Gravity in the hand (IMU) frame from a 6-axis IMU: a Mahony-type complementary
    filter on the gravity direction with gyro-bias estimation and an accelerometer gate,
    gravity_estimator.h's gains and clamp. gravity points down (unit)."""

    def __init__(self):
        self.kp_per_s = GRAVITY_KP_PER_S
        self.ki_per_s2 = GRAVITY_KI_PER_S2
        self.accel_gate_mps2 = GRAVITY_ACCEL_GATE_MPS2
        self._neg_gate = -GRAVITY_ACCEL_GATE_MPS2
        self.gravity = [0.0, 0.0, -1.0]
        self.bias_radps = [0.0, 0.0, 0.0]
        self._w = [0.0, 0.0, 0.0]
        self.initialised = False
        self.accel_trusted = False

    def reset(self):
        g = self.gravity
        b = self.bias_radps
        g[0] = g[1] = 0.0
        g[2] = -1.0
        b[0] = b[1] = b[2] = 0.0
        self.initialised = False
        self.accel_trusted = False

    def configure(self, kp_per_s, ki_per_s2, accel_gate_mps2):
        s = gravity_gains_status(kp_per_s, ki_per_s2, accel_gate_mps2)
        if s == st.OK:
            self.kp_per_s = kp_per_s
            self.ki_per_s2 = ki_per_s2
            self.accel_gate_mps2 = accel_gate_mps2
            self._neg_gate = -accel_gate_mps2
        return s

    def update(self, accel, gyro, dt_s):
        """One sample; refused without a change: NON_FINITE_INPUT, BAD_CONFIG for dt_s
        outside (0, MAX_SAMPLE_INTERVAL_S], BAD_AXIS for no accelerometer direction before
        the first estimate."""
        a0 = accel[0]
        a1 = accel[1]
        a2_ = accel[2]
        if not (
            _finite(a0)
            and _finite(a1)
            and _finite(a2_)
            and _finite(gyro[0])
            and _finite(gyro[1])
            and _finite(gyro[2])
            and _finite(dt_s)
        ):
            return st.NON_FINITE_INPUT
        if not 0.0 < dt_s <= MAX_SAMPLE_INTERVAL_S:
            return st.BAD_CONFIG
        a2 = a0 * a0 + a1 * a1 + a2_ * a2_
        has_direction = MIN_ACCEL_MPS2 * MIN_ACCEL_MPS2 <= a2 < _INF
        g = self.gravity
        if not self.initialised:
            if not has_direction:
                return st.BAD_AXIS
            inv = -1.0 / math.sqrt(a2)
            g[0] = a0 * inv
            g[1] = a1 * inv
            g[2] = a2_ * inv
            self.initialised = True
            self.accel_trusted = True
            return st.OK
        b = self.bias_radps
        w = self._w
        w[0] = gyro[0] - b[0]
        w[1] = gyro[1] - b[1]
        w[2] = gyro[2] - b[2]
        norm_a = math.sqrt(a2) if has_direction else 0.0
        gate = self.accel_gate_mps2
        off = norm_a - STANDARD_GRAVITY_MPS2
        self.accel_trusted = has_direction and self._neg_gate <= off <= gate
        if self.accel_trusted:
            # e = m x g with m = -a/|a|: turning g about e moves it towards m.
            inv = -1.0 / norm_a
            m0 = a0 * inv
            m1 = a1 * inv
            m2 = a2_ * inv
            e0 = m1 * g[2] - m2 * g[1]
            e1 = m2 * g[0] - m0 * g[2]
            e2 = m0 * g[1] - m1 * g[0]
            ki_dt = self.ki_per_s2 * dt_s
            kp = self.kp_per_s
            b[0] = _clamp_bias(b[0] - ki_dt * e0)
            b[1] = _clamp_bias(b[1] - ki_dt * e1)
            b[2] = _clamp_bias(b[2] - ki_dt * e2)
            w[0] += kp * e0
            w[1] += kp * e1
            w[2] += kp * e2
        # g' = g x w: one first-order step, then back to unit length.
        n0 = g[0] + (g[1] * w[2] - g[2] * w[1]) * dt_s
        n1 = g[1] + (g[2] * w[0] - g[0] * w[2]) * dt_s
        n2 = g[2] + (g[0] * w[1] - g[1] * w[0]) * dt_s
        inv = 1.0 / math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        g[0] = n0 * inv
        g[1] = n1 * inv
        g[2] = n2 * inv
        return st.OK

    def set_fused(self, reported):
        """A fused chip's gravity report (accelerometer sign, any unit): checked and
        normalised. NON_FINITE_INPUT, or BAD_AXIS when shorter than MIN_QUATERNION_NORM."""
        m = 0.0
        for i in range(3):
            v = reported[i]
            if not _finite(v):
                return st.NON_FINITE_INPUT
            if abs(v) > m:
                m = abs(v)
        if not m >= MIN_QUATERNION_NORM:
            return st.BAD_AXIS
        v0 = reported[0] / m
        v1 = reported[1] / m
        v2 = reported[2] / m
        inv = -1.0 / math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        g = self.gravity
        g[0] = v0 * inv
        g[1] = v1 * inv
        g[2] = v2 * inv
        self.initialised = True
        self.accel_trusted = True
        return st.OK
