"""The host-less runner (hostless_app.h's HostlessRunner, without the link's plan upload:
a MicroPython board gets its plan as a store file): a stored study plan run with no PC.

Per trial: a rest with the motors off, the "ready" pattern, the button, then guidance from
the IMU's gravity estimate until success (error within the threshold for the hold) or the
timeout; the record is appended to the results log BEFORE the success/timeout pattern, so
a power cut anywhere loses at most the trial under way, which runs again. IMU faults turn
the motors off and are counted in the trial's record. Per trial the per-posture work runs
once, through a posture source (the on-board solver or levels the host precomputed); per
sample only the estimator and the per-frame layer run, into buffers made once.

The runner does not read hardware: main.py (or a test) feeds it samples, button edges
and ticks, and it writes the motors."""

import math

from graspguide_mp import frame
from graspguide_mp import plan_file as pf
from graspguide_mp import status as st
from graspguide_mp.results_file import LogRecord, ResultsLog

# Patterns (vibration_pattern.h): (pulses, on_ms, off_ms), told apart by rhythm.
READY_PATTERN = (2, 150, 150)
SUCCESS_PATTERN = (1, 600, 0)
TIMEOUT_PATTERN = (3, 100, 100)
PATTERN_DUTY = 200

# RunEventCode (the link's RunEvent values).
EV_REST = 0
EV_READY = 1
EV_TRIAL_STARTED = 2
EV_SUCCESS = 3
EV_TIMEOUT = 4
EV_PLAN_DONE = 5
EV_LOG_FULL = 6
EV_STORAGE_FAILED = 7
EV_IMU_FAULT = 8
EVENT_NAMES = (
    "rest",
    "ready",
    "trial_started",
    "success",
    "timeout",
    "plan_done",
    "log_full",
    "storage_failed",
    "imu_fault",
)
EVENT_SLOTS = 8

# RunPhase
PH_OFF = 0
PH_REST = 1
PH_READY_PATTERN = 2
PH_WAIT_BUTTON = 3
PH_TRIAL = 4
PH_END_PATTERN = 5

# Why start() refused (HostlessRefusal's run-time part).
REFUSED_NONE = None
REFUSED_NO_PLAN = "no_plan"
REFUSED_LOG_FULL = "log_full"
REFUSED_NOT_ALLOWED = "not_allowed"
REFUSED_STORAGE_FAILED = "storage_failed"  # the log could not be read


def ticks_since(now, then):
    """now - then on the wrapping clock, as an unsigned count (a past time is never
    negative): the C++'s uint32 subtraction, good for 2^30 us = 17.9 min."""
    return (now - then) & frame.TICKS_MASK


def ticks_elapsed(now, then):
    """now - then on the wrapping clock as a signed count (frame.ticks_diff): a "now"
    before "then" is negative, never a period's worth of time."""
    return frame.ticks_diff(now, then)


def pattern_length_us(p):
    pulses, on_ms, off_ms = p
    return 0 if pulses == 0 else (pulses * on_ms + (pulses - 1) * off_ms) * 1000


class PatternPlayer:
    def __init__(self):
        self._p = (0, 0, 0)
        self._k = 0
        self._start = 0
        self._playing = False

    def start(self, p, k, now):
        self._p = p
        self._k = k
        self._start = now
        self._playing = p[0] > 0

    def cancel(self):
        self._playing = False

    def playing(self, now):
        if self._playing and ticks_since(now, self._start) >= pattern_length_us(self._p):
            self._playing = False
        return self._playing

    def pwm_into(self, now, duty):
        """The pattern's duty during a pulse, 0 between pulses and after it."""
        for i in range(4):
            duty[i] = 0
        if not self.playing(now):
            return
        _, on_ms, off_ms = self._p
        if ticks_since(now, self._start) % ((on_ms + off_ms) * 1000) < on_ms * 1000:
            for i in range(self._k if self._k < 4 else 4):
                duty[i] = PATTERN_DUTY


class SolverPostures:
    """The on-board solver (Algorithm 1's structured route, graspguide_mp.solver): a board
    can guide any posture and wrench of its plan."""

    def levels(self, header, trial):
        from graspguide_mp import qp, solver  # only boards that solve pay for it in RAM

        hand = header.hand_k3 if trial.k == 3 else header.hand_k4
        r = solver.solve(
            [list(hand[i]) for i in range(trial.k)],
            list(trial.wrench),
            policy="Fperp" if trial.policy == 1 else "F",
            mode="V" if trial.mode == 1 else "C",
            constraints=qp.MODELS[header.constraints],
            y_axis=list(header.y_axis),
        )
        if r.status != st.OK:
            return r.status, None
        return st.OK, list(r.levels)


class PrecomputedPostures:
    """Levels the host worked out (the same C++ core), by trial_index, for boards where the
    on-board solve is too slow. table: {trial_index: (status_code, levels or None)}."""

    def __init__(self, table, plan_id=None):
        self.table = table
        # The plan the levels were solved for (None: unknown); main.py uses them only
        # under that plan.
        self.plan_id = plan_id

    def levels(self, header, trial):
        entry = self.table.get(trial.trial_index)
        if entry is None:
            # A plan and a levels file that do not belong together: nothing to guide by.
            return st.BAD_CONFIG, None
        return entry

    @staticmethod
    def load(path):
        """A levels file: `plan_id XXXXXXXX`, then one line per trial, `trial_index
        status_name m1 m2 m3 [m4]` ('#' starts a comment). ValueError naming the line on
        anything else."""
        table = {}
        plan_id = None
        with open(path) as f:
            n = 0
            for line in f:
                n += 1
                line = line.split("#")[0].strip()
                if not line:
                    continue
                parts = line.split()
                if parts[0] == "plan_id" and len(parts) == 2:
                    plan_id = int(parts[1], 16)
                    continue
                try:
                    index = int(parts[0])
                    code = st.code_of(parts[1])
                    levels = [float(x) for x in parts[2:]]
                except (IndexError, ValueError):
                    code = -1
                if code < 0 or (code == st.OK and len(levels) not in (3, 4)):
                    raise ValueError(
                        "%s line %d: expected `trial_index status m1 m2 m3 [m4]`, got %r"
                        % (path, n, line)
                    )
                table[index] = (code, levels if code == st.OK else None)
        return PrecomputedPostures(table, plan_id)


class HostlessRunner:
    def __init__(self, motors, clock, store, postures, accel_fs_mps2, gyro_fs_radps, six_axis=True):
        self.motors = motors
        self.clock = clock
        self.store = store
        self.postures = postures
        self.log = ResultsLog(store)
        self.six_axis = six_axis
        self.imu = frame.ImuWatchdog(accel_fs_mps2, gyro_fs_radps, clock.now_us())
        self.estimator = frame.GravityEstimator()
        self.trial = frame.Trial()
        self.patterns = PatternPlayer()
        self.plan = None
        self.plan_status = pf.NO_PLAN
        self.plan_id = 0
        self.phase = PH_OFF
        self.position = 0
        self.events = []
        self.result_pending = None  # (trial_index, Trial) of the trial that just ended
        # Per-frame buffers, made once: a sample allocates no list.
        self.duty = bytearray(4)
        self._off = bytearray(4)
        self.f_hat = [0.0, 0.0, -1.0]
        self.g_hand = [0.0, 0.0, -1.0]
        self._scratch = [0.0, 0.0, 0.0]
        self._align = [0.0, 0.0]
        self._rot = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        self.pwm_plan = frame.PwmPlan()
        self.mode = frame.MODE_C
        self.error_deg = 0.0
        self.alpha = 0.0
        self.frame_status = st.OK
        self._phase_start = 0
        self._rest_us = 0
        self._trial_started = 0
        self._trial_elapsed_us = 0
        self._last_sample = 0
        self._have_sample = False
        self._samples = 0
        self._faults_at_start = 0
        self._recorded = bytearray(0)  # by plan position: 1 = a valid record
        self._last_success = False
        self._rest_elapsed_us = 0

    # ---------------------------------------------------------------- boot and run
    def boot(self):
        """At power-up: the stored plan (if any) and the log. Returns the log's mount
        status (plan_file's OK, TOO_SMALL or STORAGE_FAILED)."""
        s, p = pf.load_plan(self.store)
        self.plan_status = s  # OLD_LAYOUT: main.py says how to store the plan again
        self.plan = p if s == pf.OK else None
        if self.plan is not None:
            self._adopt_plan()
        return self.log.mount()

    def running(self):
        return self.phase != PH_OFF

    def start(self):
        """From the first plan trial without a valid record, then each later one without
        one. Records are matched to the plan by trial_index, not counted: a damaged record
        in the middle leaves only its own trial without a record, and that trial runs again
        after those already recorded; no trial with a record runs twice. A full log is
        refused before anything moves. Returns None, or why it refused."""
        if self.running():
            return REFUSED_NOT_ALLOWED
        if self.plan is None:
            return REFUSED_NO_PLAN
        if not self._mark_recorded():
            return REFUSED_STORAGE_FAILED
        self.position = self._first_unrecorded(0)
        if self.position >= self.plan.header.trial_count:
            self._emit(EV_PLAN_DONE)
            return REFUSED_NONE
        if self.log.full():
            return REFUSED_LOG_FULL
        self._begin_rest(self.clock.now_us())
        return REFUSED_NONE

    def stop(self):
        """Ends the run at once: motors off, an unfinished trial has no record and runs
        again on the next start()."""
        self.phase = PH_OFF
        self.patterns.cancel()
        self.trial.abort()
        self._motors_off()

    def on_button(self, pressed, now):
        if not pressed or self.phase != PH_WAIT_BUTTON:
            return
        h = self.plan.header
        self.phase = PH_TRIAL
        self._trial_started = now
        self._trial_elapsed_us = 0
        self._samples = 0
        # A fault already holding the motors off counts for this trial too.
        self._faults_at_start = self.imu.fault_total() - (0 if self.imu.motors_allowed() else 1)
        self.trial.start(h.threshold_deg, h.hold_s, h.timeout_s, 0)
        self._emit(EV_TRIAL_STARTED)

    def on_sample(self, accel, gyro, t):
        """One IMU sample in the IMU's axes, stamped with the clock's ticks. Returns the
        frame's status; error_deg, alpha and duty hold the frame's output. A sample
        stamped before the last one is refused (_time_went_backwards)."""
        if self._have_sample and ticks_elapsed(t, self._last_sample) < 0:
            return self._time_went_backwards(t)
        was_allowed = self.imu.motors_allowed()
        health = self.imu.on_sample(accel, gyro, t)
        # Any fault's onset in a trial is news (stale is found by tick(), below).
        if was_allowed and health != st.OK and self.phase == PH_TRIAL:
            self._emit(EV_IMU_FAULT)
        if health == st.OK:
            self._estimate(accel, gyro, t)
        self._last_sample = t
        self._have_sample = True
        self.frame_status = health
        if self.phase == PH_TRIAL:
            self._samples += 1
            self._guide(t, health)
        self.tick(t)
        return self.frame_status

    def tick(self, now):
        """Every control loop: the IMU's stale rule, the rest and pattern timers, and a
        trial's timeout when samples stopped coming."""
        was_allowed = self.imu.motors_allowed()
        self.imu.poll(now)
        if was_allowed and not self.imu.motors_allowed() and self.phase == PH_TRIAL:
            self._motors_off()
            self._emit(EV_IMU_FAULT)
        ph = self.phase
        # Elapsed phase time is a signed difference: a "now" from before the phase began
        # (read just before a sample stamped later) is no time.
        if ph == PH_REST:
            # Summed step by step: a rest (up to 600 s) is longer than the signed half
            # period of the ticks (2^29 us = 537 s).
            step = ticks_elapsed(now, self._phase_start)
            if step > 0:
                self._rest_elapsed_us += step
                self._phase_start = now
            if self._rest_elapsed_us >= self._rest_us:
                self._start_pattern(PH_READY_PATTERN, READY_PATTERN, now)
        elif ph == PH_READY_PATTERN or ph == PH_END_PATTERN:
            if ticks_elapsed(now, self._phase_start) < 0:
                return
            self.patterns.pwm_into(now, self.duty)
            self.motors.write(self.duty)
            if not self.patterns.playing(now):
                if ph == PH_READY_PATTERN:
                    self.phase = PH_WAIT_BUTTON
                    self._emit(EV_READY)
                else:
                    self._next_trial(now)
        elif ph == PH_TRIAL:
            # The trial's time is the device's, samples or not: a dead IMU still ends
            # the trial at its timeout (a failure, motors already off).
            self._advance_trial_clock(now)
            if self._trial_elapsed_us >= int(self.plan.header.timeout_s * 1e6):
                self.trial.expire()
                self._finish_trial(now)

    def pop_event(self):
        """The oldest event (code, position, trial_index, ticks), or None."""
        return self.events.pop(0) if self.events else None

    # ---------------------------------------------------------------- internals
    def _current(self):
        return self.plan.trials[self.position]

    def _mark_recorded(self):
        """Which plan positions hold a valid record of this plan: each record marks the
        first unmarked position with its trial_index. False when the log cannot be read."""
        trials = self.plan.trials
        n = self.plan.header.trial_count
        self._recorded = bytearray(n)
        indices = self.log.trial_indices(self.plan_id)
        if indices is None:
            return False
        for index in indices:
            for p in range(n):
                if not self._recorded[p] and trials[p].trial_index == index:
                    self._recorded[p] = 1
                    break
        return True

    def _first_unrecorded(self, p):
        n = self.plan.header.trial_count
        while p < n and self._recorded[p]:
            p += 1
        return p

    def _time_went_backwards(self, t):
        """A sample stamped before the last one: the clock cannot time this phase any more.
        The sample is not used (TIME_WENT_BACKWARDS, motors off) and time counts on from
        its stamp, so a clock that really restarted costs one sample, not the run. A trial
        under way is aborted with no record and no result and begins again with its rest
        (as the tracker path ends a trial whose POSE steps back); a rest or a pattern
        starts over from this stamp. No duration is ever made from the step."""
        self._last_sample = t
        self._motors_off()
        self.frame_status = st.TIME_WENT_BACKWARDS
        ph = self.phase
        if ph == PH_TRIAL:
            self.trial.abort()
            self._begin_rest(t)
        elif ph == PH_REST:
            self._phase_start = t
            self._rest_elapsed_us = 0
        elif ph == PH_READY_PATTERN:
            self._start_pattern(PH_READY_PATTERN, READY_PATTERN, t)
        elif ph == PH_END_PATTERN:
            p = SUCCESS_PATTERN if self._last_success else TIMEOUT_PATTERN
            self._start_pattern(PH_END_PATTERN, p, t)
        return st.TIME_WENT_BACKWARDS

    def _start_pattern(self, phase, p, now):
        self.phase = phase
        self._phase_start = now
        self.patterns.start(p, self._current().k, now)

    def _advance_trial_clock(self, now):
        """The trial's time since the press, in steps read as signed differences: a "now"
        before the last one adds nothing (and is not kept)."""
        step = ticks_elapsed(now, self._trial_started)
        if step > 0:
            self._trial_elapsed_us += step
            self._trial_started = now

    def _adopt_plan(self):
        """The plan's IMU mounting as a rotation matrix, IMU axes -> hand axes (the
        quaternion was checked finite with a norm in [0.5, 2])."""
        self.plan_id = pf.plan_id(self.plan)
        q = self.plan.header.imu_to_hand_wxyz
        n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        w, x, y, z = q[0] / n, q[1] / n, q[2] / n, q[3] / n
        r = self._rot
        r[0] = 1 - 2 * (y * y + z * z)
        r[1] = 2 * (x * y - w * z)
        r[2] = 2 * (x * z + w * y)
        r[3] = 2 * (x * y + w * z)
        r[4] = 1 - 2 * (x * x + z * z)
        r[5] = 2 * (y * z - w * x)
        r[6] = 2 * (x * z - w * y)
        r[7] = 2 * (y * z + w * x)
        r[8] = 1 - 2 * (x * x + y * y)

    def _prepare(self, t):
        """The posture's part, once per trial: f_hat from the wrench, the motors' levels
        from the posture source, and the PWM plan."""
        w = t.wrench
        m = max(abs(w[0]), abs(w[1]), abs(w[2]))
        if not m > 0.0:
            return st.ZERO_FORCE
        f0, f1, f2 = w[0] / m, w[1] / m, w[2] / m
        n = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        s, levels = self.postures.levels(self.plan.header, t)
        if s != st.OK:
            return s
        if levels is None or len(levels) != t.k:
            return st.BAD_CONTACT_COUNT
        self.f_hat[0] = f0 / n
        self.f_hat[1] = f1 / n
        self.f_hat[2] = f2 / n
        h = self.plan.header
        # The participant's calibration applies to every trial's PWM (not to the patterns,
        # which are told apart by rhythm at one fixed duty).
        self.pwm_plan.set(levels, t.k, h.pwm_floor, h.gain)
        self.mode = t.mode
        return st.OK

    def _begin_rest(self, now):
        self.phase = PH_REST
        self._phase_start = now
        self._rest_elapsed_us = 0
        self._rest_us = int(self.plan.header.rest_s * 1e6)
        self._motors_off()
        if self._prepare(self._current()) != st.OK:
            self.stop()
            self._emit(EV_STORAGE_FAILED)
            return
        self._emit(EV_REST)

    def _estimate(self, accel, gyro, t):
        if not self.six_axis:
            # A fused chip's gravity points up like the accelerometer; set_fused flips it.
            self.estimator.set_fused(accel)
            return
        dt_s = ticks_since(t, self._last_sample) * 1e-6
        # After a gap (or the first sample) the filter restarts from the accelerometer: a
        # first-order step over a long gap would be wrong, and the gap's motion is unknown.
        if not self._have_sample or not 0.0 < dt_s <= frame.MAX_SAMPLE_INTERVAL_S:
            self.estimator.reset()
            self.estimator.update(accel, gyro, 0.01)
            return
        self.estimator.update(accel, gyro, dt_s)

    def _guide(self, now, health):
        self._advance_trial_clock(now)
        if health != st.OK or not self.estimator.initialised:
            self._motors_off()
            self.frame_status = health if health != st.OK else st.IMU_STALE
            return
        g = self.estimator.gravity
        r = self._rot
        gh = self.g_hand
        gh[0] = r[0] * g[0] + r[1] * g[1] + r[2] * g[2]
        gh[1] = r[3] * g[0] + r[4] * g[1] + r[5] * g[2]
        gh[2] = r[6] * g[0] + r[7] * g[1] + r[8] * g[2]
        s = frame.alignment_from_gravity(gh, self.f_hat, self._align, self._scratch)
        self.frame_status = s
        if s != st.OK:
            self._motors_off()
            return
        self.error_deg = self._align[0]
        self.alpha = self._align[1]
        self.trial.update(self._trial_elapsed_us, self.error_deg)
        if not self.trial.running():
            self._finish_trial(now)
            return
        gain = frame.PWM_SPAN if self.mode == frame.MODE_C else self.alpha
        frame.pwm_from_plan(self.pwm_plan, gain, self.duty)
        self.motors.write(self.duty)

    def _finish_trial(self, now):
        """The record first: once it is stored the wearer is told, and only then does the
        next trial begin."""
        self._motors_off()
        t = self._current()
        rec = LogRecord(t)
        tr = self.trial
        rec.success = tr.success
        rec.completion_s = tr.completion_s
        rec.first_entry_s = tr.first_entry_s
        rec.final_error_deg = tr.final_error_deg
        rec.samples = self._samples
        faults = self.imu.fault_total() - self._faults_at_start
        rec.imu_faults = faults if faults < 0xFFFF else 0xFFFF
        s = self.log.append(rec, self.plan_id)
        if s != pf.OK:
            self.stop()
            self._emit(EV_LOG_FULL if s == pf.FULL else EV_STORAGE_FAILED)
            return
        self._recorded[self.position] = 1
        self._last_success = rec.success
        self.result_pending = (t.trial_index, rec)
        self._emit(EV_SUCCESS if rec.success else EV_TIMEOUT)
        self._start_pattern(
            PH_END_PATTERN, SUCCESS_PATTERN if rec.success else TIMEOUT_PATTERN, now
        )

    def _next_trial(self, now):
        self.position = self._first_unrecorded(self.position + 1)
        if self.position >= self.plan.header.trial_count:
            self.phase = PH_OFF
            self._motors_off()
            self._emit(EV_PLAN_DONE)
            return
        if self.log.full():
            self.stop()
            self._emit(EV_LOG_FULL)
            return
        self._begin_rest(now)

    def _emit(self, code):
        n = self.plan.header.trial_count if self.plan is not None else 0
        pos = self.position if self.position < n else (n - 1 if n else 0)
        index = self.plan.trials[pos].trial_index if n else 0
        if len(self.events) == EVENT_SLOTS:  # the oldest goes: nobody is listening
            self.events.pop(0)
        self.events.append((code, pos, index, self.clock.now_us()))

    def _motors_off(self):
        for i in range(4):
            self.duty[i] = 0
        self.motors.write(self._off)
