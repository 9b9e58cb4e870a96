"""`graspguide trial --hostless`: a participant's study run host-less on the simulated
device. SIMULATED throughout.

The host uploads the plan (unless the device already stores this participant's plan of
this protocol), starts the device's own run (HOSTLESS_RUN) and from then on is only the
physical world:

* it sends an IMU sample (graspguide.hostless.imu_world) every 1 / pose_rate_hz of the
  device's virtual clock, which follows the samples, at rest and while waiting too;
* between trials the hand goes back to the protocol's ``start_quat`` (a minimum-jerk turn
  at HAND_RETURN_PEAK_DPS) and rests there; ``reaction_s`` after the device's ``ready``
  (and after the hand is back) the participant presses the button for BUTTON_PRESS_S;
* from ``trial_started`` the hand is the virtual participant's, stepped with the PWM of
  the last TELEMETRY, exactly as the tracker-driven runner steps it;
* at ``plan_done`` it downloads the device's log (graspguide.hostless.device_log) into
  the runner's folder format, so `graspguide analyze` reads it unchanged.

It also writes what the tracker runner writes around the trials, with that runner's own
code: OUT/study.json, OUT/PID/plan.json, OUT/PID/runs.jsonl; OUT/PID/world.jsonl holds,
per trial result seen, the true error of the hand pose the world sent (the core on the
exact orientation) at the end and over the hold, beside the device's estimate; the
download writes
OUT/PID/trials.jsonl and OUT/PID/tlx.jsonl with null scales (a simulated participant
answers no questionnaire; none is invented).

Errors and Ctrl-C send STOP; the device's store keeps every completed trial, and running
again resumes at the first trial without a record.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
import time
import weakref
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TextIO

import numpy as np

from graspguide.core.motor_calibration import MotorCalibration
from graspguide.hostless.imu_world import ImuWorld, unit_quaternion
from graspguide.imu.synthetic import ImuNoise
from graspguide.protocol.study_protocol import PlannedTrial, Protocol, derive_seed
from graspguide.records.files import WORLD_FILE
from graspguide.run_errors import RunnerError
from graspguide.study.progress import Progress
from graspguide.study.runner import RESULT_MARGIN_S, StudyRunner, append_line, read_run_jsonl

#: Rest before each trial's ready pattern [s] (the plan's rest_s; the schema allows 0..600).
DEFAULT_REST_S = 2.0
REST_S_MAX = 600.0
#: From the ready pattern to the button press [s]: a simple tactile reaction (about 0.2 s)
#: plus reaching for the button.
DEFAULT_REACTION_S = 0.5
REACTION_S_MAX = 60.0
#: How long the button is held down [s].
BUTTON_PRESS_S = 0.1
#: Peak speed of the hand going back to the start pose after a trial [deg/s]: faster than
#: guided motion (the person knows where the start is) but within the gyroscope's range.
HAND_RETURN_PEAK_DPS = 180.0
#: A rest, a ready or a trial start later than expected by this much of device time is an
#: error (the device stopped following the samples or the button).
EVENT_MARGIN_S = 5.0
#: The protocol's clock is in microseconds on a 32-bit counter; the device compares times
#: modulo 2^32.
_U32 = 0xFFFFFFFF
_HALF_U32 = 1 << 31
#: Real time between two samples after which the world's clock moves on by that real time
#: [s]. The simulated device's virtual clock follows real time once no sample has come for
#: its stale time (200 ms): a host paused that long (a slow disk, a loaded machine) finds
#: the device's clock ahead, and a sample stamped before it would turn the device's clock
#: back. Half the stale time, so the world has moved on before the device has.
FOLLOW_REAL_TIME_AFTER_S = 0.1
#: How long to wait for the device's first event after HOSTLESS_RUN [s]: it tells the world
#: where the device's clock is before the first sample.
FIRST_EVENT_WAIT_S = 2.0
#: Minimum jerk: peak speed = this x amplitude / duration.
_MIN_JERK_PEAK = 1.875
#: Where the world's clock stopped, per device client: a later run on the same device
#: continues from there (the device's clock follows the samples and must not go back).
_WORLD_CLOCK_US: weakref.WeakKeyDictionary[Any, int] = weakref.WeakKeyDictionary()


@dataclass
class HostlessSummary:
    participant: str
    planned: int
    completed: int
    before: int  # records stored before this run
    ran: int  # TRIAL_RESULTs seen in this run
    uploaded: bool
    device_s: float
    results: list[Any] = field(default_factory=list)
    download: Any = None


def _slerp(q0: np.ndarray, q1: np.ndarray, u: float) -> np.ndarray:
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - u) * th) * q0 + math.sin(u * th) * q1) / math.sin(th)


class _HandReturn:
    """A minimum-jerk turn from ``q_from`` to ``q_to`` starting at ``t0_s``."""

    def __init__(self, q_from: Sequence[float], q_to: np.ndarray, t0_s: float):
        self.q0 = unit_quaternion(q_from, "hand orientation")
        self.q1 = q_to
        d = min(1.0, abs(float(np.dot(self.q0, self.q1))))
        angle_deg = math.degrees(2 * math.acos(d))
        self.t0_s = t0_s
        self.duration_s = _MIN_JERK_PEAK * angle_deg / HAND_RETURN_PEAK_DPS
        self.end_s = t0_s + self.duration_s

    def at(self, t_s: float) -> np.ndarray:
        if t_s >= self.end_s or self.duration_s <= 0:
            return self.q1
        s = max(0.0, (t_s - self.t0_s) / self.duration_s)
        u = s * s * s * (10 - 15 * s + 6 * s * s)
        return _slerp(self.q0, self.q1, u)


def check_settings(rest_s: float, reaction_s: float, imu_to_hand: Sequence[float]) -> None:
    """RunnerError (usage) naming the option when one is out of its range."""
    if not (
        isinstance(rest_s, (int, float)) and math.isfinite(rest_s) and 0 <= rest_s <= REST_S_MAX
    ):
        raise RunnerError(
            f"--rest-s must be in [0, {REST_S_MAX:g}] seconds, got {rest_s!r}", usage=True
        )
    if not (
        isinstance(reaction_s, (int, float))
        and math.isfinite(reaction_s)
        and 0 <= reaction_s <= REACTION_S_MAX
    ):
        raise RunnerError(
            f"reaction_s must be in [0, {REACTION_S_MAX:g}] seconds, got {reaction_s!r}", usage=True
        )
    try:
        unit_quaternion(imu_to_hand, "--imu-to-hand")
    except ValueError as e:
        raise RunnerError(str(e), usage=True) from None


class _Source:
    """The StudyRunner's view of the virtual participant behind the IMU world (its files
    are labelled with it: simulated, no TLX asked)."""

    closed_loop = True
    simulated = True
    live = False

    def __init__(self, model: Any, spec: str):
        self.model = model
        self.rate_hz = float(getattr(model, "rate_hz", 0.0))
        self.spec = spec

    def describe(self) -> dict[str, Any]:
        return {
            "source": self.spec,
            "kind": "hostless_world",
            "class": type(self.model).__name__,
            "simulated": True,
        }


class TrueError:
    """The guidance error of the hand pose the world really sent (the core on the host,
    the exact orientation), beside what the device estimated from the IMU: how the
    estimate's error moves success detection. One line per trial result (WORLD_FILE)."""

    def __init__(self, protocol: Protocol):
        self.p = protocol
        self.guide: Any = None
        self.trial: PlannedTrial | None = None
        self.window: deque[tuple[float, float]] = deque()
        self.last_deg: float | None = None

    def begin(self, trial: PlannedTrial) -> None:
        from graspguide.core import _core

        g = _core.Guidance()
        status = g.set_scene(
            [list(c) for c in self.p.hands[trial.k]],
            policy=trial.policy,
            mode=trial.mode,
            y_axis=list(self.p.y_axis),
        )
        if status != "ok" or g.set_wrench(list(trial.wrench)) != "ok":
            raise RunnerError(f"trial {trial.trial_index}: the core refuses its scene: {status}")
        self.guide, self.trial = g, trial
        self.window.clear()
        self.last_deg = None

    def sample(self, t_s: float, q: np.ndarray) -> None:
        res = self.guide.update([float(x) for x in q])
        self.last_deg = float(res["error_deg"]) if res["status"] == "ok" else None
        if self.last_deg is not None:
            self.window.append((t_s, self.last_deg))
        # the hold before now: the device ends a success hold_s after the first sample
        # below the threshold, so that sample is at t_s - hold_s (half a period of slack
        # for the float clock), and the one before it is no part of the hold
        start = t_s - self.p.hold_s - 0.5 / self.p.pose_rate_hz
        while self.window and self.window[0][0] < start:
            self.window.popleft()

    def result(self, r: Any, t_s: float) -> dict[str, Any]:
        trial = self.trial
        hold = [e for _, e in self.window]
        return {
            "trial_index": trial.trial_index if trial else int(r.trial_id),
            "simulated": True,
            "success": bool(r.success),
            "device_final_error_deg": round(float(r.final_error_deg), 6),
            "true_final_error_deg": None if self.last_deg is None else round(self.last_deg, 6),
            "true_max_error_over_hold_deg": round(max(hold), 6) if hold else None,
            "threshold_deg": self.p.threshold_deg,
            "hold_s": self.p.hold_s,
            "device_time_s": round(t_s, 6),
        }


class HostlessWorld:
    """One host-less run: the device's events in, IMU samples and button presses out."""

    def __init__(
        self,
        protocol: Protocol,
        client: Any,
        model: Any,
        plan_by_index: dict[int, PlannedTrial],
        world: ImuWorld,
        rest_s: float,
        reaction_s: float,
        clock_start_us: int,
        on_trial_result: Callable[[Any], None] | None,
        progress: Progress,
        total: int,
        on_sample: Callable[[float, np.ndarray, Any, PlannedTrial | None], None] | None = None,
        on_truth: Callable[[dict[str, Any]], None] | None = None,
    ):
        self.p = protocol
        self.client = client
        self.model = model
        self.plan_by_index = plan_by_index
        self.world = world
        self.rest_s = rest_s
        self.reaction_s = reaction_s
        self.on_trial_result = on_trial_result
        self.on_sample = on_sample
        self.progress = progress
        self.total = total
        self.period_us = 1e6 / protocol.pose_rate_hz
        self.t0_us = int(clock_start_us)
        self.i = 0
        self.t_us = self.t0_us
        #: The latest device time seen in an event, unwrapped onto the world's clock.
        self.device_us: int | None = None
        #: Device time the world skipped to stay at or after the device's clock [us].
        self.skipped_us = 0
        self.start_q = unit_quaternion(protocol.start_quat, "[trial] start_quat")
        self.q = self.start_q.copy()
        self.state = "wait_rest"  # wait_rest, rest, ready, trial, done
        self.state_since_s = self._t_s()
        self.ret: _HandReturn | None = None
        self.press_at_s: float | None = None
        self.release_at_s: float | None = None
        self.trial: PlannedTrial | None = None
        self.trial_t0_s = 0.0
        self.pwm: list[int] = [0, 0, 0, 0]
        self.results: list[Any] = []
        self.imu_faults = 0
        self.truth = TrueError(protocol)
        self.on_truth = on_truth

    def _t_s(self) -> float:
        return self.t_us / 1e6

    def _event_time_s(self, device_time_us: int) -> float:
        """A device time (u32) as this world's time [s]: the time with those low 32 bits
        nearest the world's view of the device's clock (the world's time, or the latest
        device time seen when that is later), behind it or ahead of it by up to 2^31 us.
        The device's clock is ahead after it followed real time while the host was slow
        (before the first sample, or in a pause), behind by the samples since the event."""
        ref = self.t_us if self.device_us is None else max(self.t_us, self.device_us)
        t_us = ref + (((int(device_time_us) - ref + _HALF_U32) & _U32) - _HALF_U32)
        self.device_us = t_us if self.device_us is None else max(self.device_us, t_us)
        return t_us / 1e6

    def _skip_to(self, t_us: int) -> None:
        """The world's clock jumps ahead to ``t_us`` (the device's clock is there), so that
        no sample turns the device's clock back."""
        if t_us > self.t_us:
            self.skipped_us += t_us - self.t_us
            self.t0_us += t_us - self.t_us
            self.t_us = t_us

    # ---- the device's events
    def _events(self) -> None:
        from graspguide.link.messages import RunEvent

        events = list(self.client.hostless_events)
        self.client.hostless_events.clear()
        for ev in events:
            kind = RunEvent(int(ev.event))
            t_s = self._event_time_s(ev.device_time_us)
            # An event ahead of the world: the device's clock followed real time while the
            # host was slow; the world goes on from there.
            self._skip_to(int(self.device_us or 0))
            if kind is RunEvent.REST:
                self.state, self.state_since_s = "rest", t_s
            elif kind is RunEvent.READY:
                self.state, self.state_since_s = "ready", t_s
                back_s = self.ret.end_s if self.ret is not None else t_s
                self.press_at_s = max(t_s, back_s) + self.reaction_s
            elif kind is RunEvent.TRIAL_STARTED:
                self._begin_trial(int(ev.trial_index), t_s)
            elif kind in (RunEvent.SUCCESS, RunEvent.TIMEOUT):
                self.state, self.state_since_s = "wait_rest", t_s
                self.trial = None
                self.ret = _HandReturn(self.q, self.start_q, self._t_s())
            elif kind is RunEvent.PLAN_DONE:
                self.state = "done"
            elif kind is RunEvent.IMU_FAULT:
                # The device goes on (motors off until the IMU recovers; the trial's record
                # counts it). In a simulation it means the host paused longer than the
                # simulated device's real-time stale rule (a loaded machine), or a world
                # model bug: said, counted, not fatal.
                self.imu_faults += 1
                self.progress.line(
                    f"warning: the device reported an IMU fault at plan position "
                    f"{ev.position} (trial {ev.trial_index}); the trial goes on and its record "
                    "counts it (a host pause longer than the simulator's stale rule does this)"
                )
            else:
                raise RunnerError(
                    f"the device ended the host-less run: {kind.name.lower()} at plan position "
                    f"{ev.position} (trial {ev.trial_index}); completed trials are stored: "
                    + {
                        RunEvent.LOG_FULL: "download the log (graspguide device log), erase "
                        "it, and run again",
                        RunEvent.STORAGE_FAILED: "check the device's store file",
                    }.get(kind, "see the device's STATUS")
                )
        results = list(self.client.trial_results)
        self.client.trial_results.clear()
        for r in results:
            self.results.append(r)
            if self.on_truth is not None:
                self.on_truth(self.truth.result(r, self._t_s()))
            t = self.plan_by_index.get(int(r.trial_id))
            if t is not None:
                outcome = f"success {float(r.completion_s):.2f} s" if r.success else "timeout"
                self.progress.line(
                    f"[{t.trial_index}/{self.total}] "
                    + ("familiarization" if t.familiarization else f"session {t.session}")
                    + f" {t.modality} k={t.k} {t.wrench_id}: {outcome} (host-less, simulated)"
                )
            if self.on_trial_result is not None:
                self.on_trial_result(r)

    def _begin_trial(self, trial_index: int, t_s: float) -> None:
        trial = self.plan_by_index.get(trial_index)
        if trial is None:
            raise RunnerError(
                f"the device started trial {trial_index}, which is not in this participant's "
                "plan: the device stores another plan; download and erase its log, then run again"
            )
        self.trial = trial
        self.trial_t0_s = t_s
        self.state, self.state_since_s = "trial", t_s
        self.ret = None
        self.model.begin_trial(
            contacts=[list(c) for c in self.p.hands[trial.k]],
            y_axis=list(self.p.y_axis),
            wrench=list(trial.wrench),
            policy=trial.policy,
            mode=trial.mode,
            start_quat=list(self.p.start_quat),
        )
        # The trial's first pose (t = 0) is the sample that started it, whose hand was at
        # rest at start_quat: step there with nothing felt, as the tracker runner does.
        self.model.step(0.0, [0] * trial.k)
        self.truth.begin(trial)

    # ---- the world
    def _hand(self, t_s: float) -> np.ndarray:
        if self.state == "trial" and self.trial is not None:
            k = self.trial.k
            return np.asarray(self.model.step(t_s - self.trial_t0_s, self.pwm[:k]), dtype=float)
        if self.ret is not None:
            return self.ret.at(t_s)
        return self.start_q

    def _button(self, t_s: float) -> None:
        if self.press_at_s is not None and t_s >= self.press_at_s:
            self.client.sim_button(True)
            self.press_at_s = None
            self.release_at_s = t_s + BUTTON_PRESS_S
        elif self.release_at_s is not None and t_s >= self.release_at_s:
            self.client.sim_button(False)
            self.release_at_s = None
        else:
            return
        self._events()

    def _check_stall(self, t_s: float) -> None:
        late = t_s - self.state_since_s
        if self.state == "trial":
            if late > self.p.timeout_s + RESULT_MARGIN_S:
                raise RunnerError(
                    f"trial {self.trial.trial_index if self.trial else '?'}: no result "
                    f"{late:.1f} s into a {self.p.timeout_s:g} s trial; is the device's clock "
                    "following the IMU samples?"
                )
            return
        limit = self.rest_s + self.reaction_s + BUTTON_PRESS_S + EVENT_MARGIN_S
        if self.ret is not None:
            limit += self.ret.duration_s
        if late > limit:
            expected = {
                "wait_rest": "a rest (HOSTLESS_EVENT rest)",
                "rest": "the ready pattern",
                "ready": "the trial to start after the button press",
            }[self.state]
            raise RunnerError(
                f"the device sent no event for {late:.1f} s of its clock; expected "
                f"{expected}. Is it running the host-less plan (LOG_INFO.running)?"
            )

    def run(self) -> float:
        """Samples until plan_done; returns the device time used [s]."""
        # HOSTLESS_RUN's answer brings the first event (the rest), stamped with the device's
        # clock, which may be ahead of the world's: the world starts from there.
        deadline = time.monotonic() + FIRST_EVENT_WAIT_S
        while not self.client.hostless_events and time.monotonic() < deadline:
            self.client.drain(0.02)
        self._events()
        start_us = self.t_us
        last_real = time.monotonic()
        while self.state != "done":
            self.i += 1
            self.t_us = self.t0_us + int(round(self.i * self.period_us))
            now_real = time.monotonic()
            if now_real - last_real > FOLLOW_REAL_TIME_AFTER_S:
                # The host was paused (the disk, the machine): the device's clock may have
                # followed real time meanwhile; the world's moves on by as much.
                self._skip_to(self.t_us + int((now_real - last_real) * 1e6))
            last_real = now_real
            self._button(self._t_s())
            if self.state == "done":
                break
            t_s = self._t_s()  # after the button's events, which may move the world on
            self.q = self._hand(t_s)
            s = self.world.sample(t_s, self.q)
            tel = self.client.sim_imu_sample(self.t_us & _U32, s.accel_mps2, s.gyro_radps)
            if self.trial is not None:  # before its result: the sample that ended it counts
                self.truth.sample(t_s, self.q)
            self._events()
            if tel is None:
                if self.state == "done":
                    break
                raise RunnerError(
                    "the device acknowledged an IMU sample instead of answering it with "
                    "TELEMETRY: its host-less run is not going (stopped, or never started)"
                )
            if self.on_sample is not None:
                self.on_sample(t_s, self.q, tel, self.trial)
            self.pwm = list(tel.pwm)
            self._check_stall(t_s)
        return (self.t_us - start_us) / 1e6


def _plan_matches(info: Any, participant: str, hash8: bytes, n: int) -> bool:
    return (
        bool(info.plan_stored)
        and str(info.participant).rstrip("\0") == participant
        and bytes(info.config_hash) == hash8
        and int(info.plan_trials) == n
    )


def _uploaded_calibration(runs_path: str) -> tuple[dict[str, Any], str | None] | None:
    """(calibration, its file) of the last plan this folder's runs uploaded (runs.jsonl's
    start events), or None when none of them uploaded one."""
    found = None
    try:
        with open(runs_path, encoding="utf-8") as f:
            for line in f:
                try:
                    event = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line cut by a crash: the others still count
                if event.get("event") == "start" and event.get("plan_uploaded"):
                    cal = event.get("calibration")
                    if isinstance(cal, dict):
                        found = (cal, event.get("calibration_file"))
                    else:  # uploaded before plans carried a calibration: the identity
                        found = (MotorCalibration.identity().to_json(), None)
    except FileNotFoundError:
        return None
    return found


def run_hostless(
    protocol: Protocol,
    participant: str,
    client: Any,
    out_dir: str,
    source_model: Any,
    rest_s: float = DEFAULT_REST_S,
    reaction_s: float = DEFAULT_REACTION_S,
    imu_to_hand: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    *,
    source_spec: str = "participant",
    imu_noise: ImuNoise | None = None,
    clock_start_us: int | None = None,
    on_trial_result: Callable[[Any], None] | None = None,
    on_sample: Callable[[float, np.ndarray, Any, PlannedTrial | None], None] | None = None,
    progress: Progress | None = None,
    err: TextIO | None = None,
    protocol_file: str | None = None,
    port: str = "",
    calibration: MotorCalibration | None = None,
    calibration_file: str | None = None,
) -> HostlessSummary:
    """Run what is left of ``participant``'s plan host-less on ``client`` (a DeviceClient
    of a device with CAPABILITY_HOSTLESS and CAPABILITY_SIM_MESSAGES), then download its log
    into ``out_dir``. ``source_model``: the virtual participant (begin_trial, step).
    ``clock_start_us``: the world's clock at the start (the device's clock follows it);
    default: where the last run on this client ended, else 0, so that a run resumed on
    the same device never turns its clock back.
    ``on_trial_result`` is called with every TRIAL_RESULT as it arrives, ``on_sample(t_s,
    hand_quat, telemetry, trial or None)`` after every sample's TELEMETRY. ``calibration``
    (the identity when None; read from ``calibration_file``, logged) goes into the plan:
    the device applies it to every trial's PWM. Raises
    RunnerError, LinkError (DeviceError), KeyboardInterrupt; STOP is sent on every way
    out, and the device's store keeps every completed trial."""
    from graspguide.hostless.device_log import download_log
    from graspguide.hostless.plan_upload import plan_messages
    from graspguide.link.client import DeviceError
    from graspguide.link.messages import CAPABILITY_HOSTLESS, CAPABILITY_SIM_MESSAGES

    check_settings(rest_s, reaction_s, imu_to_hand)
    progress = progress or Progress()
    err = err or sys.stderr
    source = _Source(source_model, source_spec)
    runner = StudyRunner(
        protocol,
        participant,
        out_dir,
        source,  # type: ignore[arg-type]
        client,
        virtual_clock=True,
        progress=progress,
        protocol_file=protocol_file,
        err=err,
        port=port,
    )
    runner._lock()
    try:
        runner.prepare()
        info = client.hello()
        caps = int(getattr(info, "capabilities", 0))
        need = CAPABILITY_HOSTLESS | CAPABILITY_SIM_MESSAGES
        if caps & need != need:
            raise RunnerError(
                f"the device at {port or 'this port'} ({info.board}, capabilities "
                f"0x{caps:02x}) cannot run a simulated host-less study: it needs "
                "CAPABILITY_HOSTLESS and CAPABILITY_SIM_MESSAGES, which only the simulated "
                "device built from this tree has (`pio run -e sim`); use --port sim"
            )
        client.stop()  # a run left going by an earlier host
        hash8 = bytes.fromhex(protocol.config_hash)[:8]
        n = len(runner.plan)
        log = client.log_info()
        same_study = _plan_matches(log, participant, hash8, n)
        want_cal = (calibration or MotorCalibration.identity()).to_json()
        upload = not same_study
        if same_study:
            # LOG_INFO does not show the stored plan's calibration: the host's own log of
            # the upload (runs.jsonl) says which one it was.
            recorded = _uploaded_calibration(runner.runs_path)
            if recorded is None:
                # Not uploaded from this folder: the same plan again keeps its records;
                # one with another calibration is refused while records are stored.
                upload = calibration is not None and not calibration.is_identity()
            elif recorded[0] != want_cal:
                raise RunnerError(
                    f"the device stores {participant}'s plan with the calibration "
                    f"{recorded[0]} ({recorded[1] or 'none given'}), this run has {want_cal} "
                    f"({calibration_file or 'none given'}): resume with the calibration the "
                    "study began with, or download the records (`graspguide device log "
                    "--port P --out DIR`), erase them (`graspguide device erase --port P "
                    "--yes`) and start again"
                )
        if upload:
            begin, trials = plan_messages(
                protocol,
                participant,
                runner.plan,
                simulated=True,
                rest_s=float(rest_s),
                imu_to_hand_wxyz=tuple(float(x) for x in imu_to_hand),
                calibration=calibration,
            )
            try:
                client.upload_plan(begin, trials, calibration=calibration)
            except DeviceError as e:
                if e.code_name == "log_not_empty" and same_study:
                    raise RunnerError(
                        f"the device stores {participant}'s plan with records made under "
                        f"another calibration or settings than this run's (calibration "
                        f"{calibration_file or 'none'}): resume with those the study began "
                        "with, or download its records (`graspguide device log --port P "
                        "--out DIR`), erase them (`graspguide device erase --port P --yes`) "
                        "and start again"
                    ) from None
                if e.code_name == "log_not_empty":
                    raise RunnerError(
                        f"the device's log holds records of another plan (participant "
                        f"{str(log.participant).rstrip(chr(0)) or '?'}): download them "
                        "(`graspguide device log --port P --out DIR`), erase them "
                        "(`graspguide device erase --port P --yes`), then run again"
                    ) from None
                raise
            log = client.log_info()
        uploaded = upload
        before = int(log.records)
        runner._log_run(
            "start",
            config_hash=runner.config_hash,
            source=source.describe(),
            port=port,
            hostless=True,
            simulated=True,
            rest_s=rest_s,
            reaction_s=reaction_s,
            imu_to_hand_wxyz=list(imu_to_hand),
            imu_noise=dataclasses.asdict(imu_noise or ImuNoise()),
            plan_uploaded=uploaded,
            calibration=(calibration or MotorCalibration.identity()).to_json(),
            calibration_file=calibration_file,
            records_before=before,
            device={
                "board": info.board,
                "build_id": f"{info.build_id:08x}",
                "firmware": ".".join(map(str, info.firmware_version)),
                "capabilities": caps,
            },
        )
        if before:
            progress.line(
                f"resuming {participant} host-less: {before} of {n} trials are already "
                "stored on the device and are skipped"
            )
        world = ImuWorld(
            protocol.pose_rate_hz,
            derive_seed(protocol.seed, "imu-world", participant) % 2**32,
            imu_noise,
            imu_to_hand,
        )
        hw = HostlessWorld(
            protocol,
            client,
            source_model,
            {t.trial_index & 0xFFFF: t for t in runner.plan},
            world,
            float(rest_s),
            float(reaction_s),
            _WORLD_CLOCK_US.get(client, 0) if clock_start_us is None else clock_start_us,
            on_trial_result,
            progress,
            n,
            on_sample,
            lambda line: append_line(os.path.join(runner.pdir, WORLD_FILE), line),
        )
        outcome = "error"
        device_s = 0.0
        try:
            if before < n:
                client.hostless_run()
                device_s = hw.run()
            outcome = "complete"
        except KeyboardInterrupt:
            outcome = "interrupted"
            raise
        finally:
            _WORLD_CLOCK_US[client] = hw.t_us + int(round(hw.period_us))
            try:
                client.stop()
            except Exception as e:
                if outcome == "complete":
                    raise
                print(f"graspguide trial: STOP failed: {e}", file=err, flush=True)
            if outcome != "complete":
                try:
                    runner._log_run("end", outcome=outcome, ran=len(hw.results), hostless=True)
                except Exception as e:  # the error that ended the run is the one to report
                    print(f"graspguide trial: warning: {e}", file=err, flush=True)
        download = download_log(client, out_dir)
        records = read_run_jsonl(runner.trials_path).records
        done = {r.get("trial_index") for r in records}
        missing = [t.trial_index for t in runner.plan if t.trial_index not in done]
        if missing:
            raise RunnerError(
                f"the device said plan_done but its log lacks trials {missing[:5]}"
                f"{'...' if len(missing) > 5 else ''}; inspect `graspguide device info`"
            )
        runner._log_run(
            "end",
            outcome="complete",
            ran=len(hw.results),
            completed=len(done),
            planned=n,
            device_s=round(device_s, 3),
            hostless=True,
        )
        return HostlessSummary(
            participant,
            n,
            len(done),
            before,
            len(hw.results),
            uploaded,
            device_s,
            hw.results,
            download,
        )
    finally:
        runner._unlock()


def hostless_trial_command(
    *,
    protocol: str,
    participant: str,
    source: str,
    port: str,
    baud: int,
    timeout: float,
    out: str,
    store: str | None,
    rest_s: float,
    imu_to_hand: Sequence[float] | None,
    tlx: str | None,
) -> int:
    """`graspguide trial --hostless`: ``participant``'s study run host-less on the
    simulated device (its store ``store``, default OUT/PID/device-store.bin), the world
    driven by the source ``source``; the log downloaded into ``out``. The plan carries the
    participant's calibration: OUT/PID/calibration.json when `graspguide calibrate` wrote
    one (a file that is there but wrong is a usage error), else the identity.
    Returns the exit code."""
    from graspguide.calibration.calibration_file import (
        CalibrationFileError,
        calibration_path,
        load_participant_calibration,
    )
    from graspguide.calibration.calibration_file import (
        describe as describe_calibration,
    )
    from graspguide.devices.registry import open_port
    from graspguide.devices.sim import SIM_PORT
    from graspguide.exit_codes import (
        EXIT_FAILURE,
        EXIT_INTERRUPTED,
        EXIT_OK,
        EXIT_USAGE,
        fail,
        report,
    )
    from graspguide.link.client import DeviceClient
    from graspguide.link.transport import LinkError
    from graspguide.protocol.study_protocol import (
        ProtocolFileError,
        load_protocol,
        participant_number,
    )
    from graspguide.sources.trial_sources import open_runner_source
    from graspguide.study.runner import summary_lines

    try:
        if port != SIM_PORT:
            raise RunnerError(
                "--hostless simulates the physical world for the simulated device: use "
                "--port sim (a board runs host-less from its own IMU and button; fetch its "
                "results with `graspguide device log`)",
                usage=True,
            )
        if tlx is not None:
            raise RunnerError(
                "--tlx does not go with --hostless: the host-less participant is simulated "
                "and its questionnaires are recorded as absent",
                usage=True,
            )
        mount = tuple(float(x) for x in (imu_to_hand or (1.0, 0.0, 0.0, 0.0)))
        norm = math.sqrt(sum(x * x for x in mount))
        if not norm > 0:
            raise RunnerError("--imu-to-hand must not be all zeros", usage=True)
        mount = tuple(x / norm for x in mount)
        check_settings(rest_s, DEFAULT_REACTION_S, mount)
        loaded = load_protocol(protocol)
        participant_number(participant)
        cal = load_participant_calibration(out, participant)
        src = open_runner_source(source, loaded, participant)
        if not (src.closed_loop and src.simulated):
            raise RunnerError(
                f"--hostless needs a simulated closed-loop source (participant[:PARAMS] or a "
                f"closed-loop plugin class), got --source {source}",
                usage=True,
            )
    except (ProtocolFileError, RunnerError, CalibrationFileError, ValueError) as e:
        report("trial", e)
        return EXIT_USAGE
    cal_file = calibration_path(out, participant)
    store_path = store or os.path.join(out, participant, "device-store.bin")
    try:
        os.makedirs(os.path.dirname(os.path.abspath(store_path)), exist_ok=True)
    except OSError as e:
        report("trial", RunnerError(f"--store {store_path}: cannot create its folder: {e}"))
        return EXIT_USAGE
    try:
        transport = open_port(port, baudrate=baud, virtual_clock=True, store=store_path)
    except LinkError as e:
        return fail("trial", e)
    client = DeviceClient(transport, timeout=timeout)
    code = EXIT_OK
    summary: HostlessSummary | None = None
    print(
        f"SIMULATED host-less study: {participant}, the simulated device's store {store_path}",
        flush=True,
    )
    print(
        f"calibration: {cal_file}: {describe_calibration(cal)}"
        if cal is not None
        else "calibration: none (the paper's PWM mapping; `graspguide calibrate` writes "
        f"{cal_file})",
        flush=True,
    )
    try:
        summary = run_hostless(
            loaded,
            participant,
            client,
            out,
            src.model,  # type: ignore[attr-defined]
            rest_s=rest_s,
            imu_to_hand=mount,
            source_spec=source,
            protocol_file=protocol,
            port=port,
            calibration=cal,
            calibration_file=cal_file if cal is not None else None,
        )
        print(
            f"{participant}: all {summary.planned} trials stored on the device and downloaded "
            f"({summary.ran} run now, {summary.before} from earlier runs; "
            f"{summary.device_s:.1f} s of device time); {os.path.join(out, participant)}"
        )
        for line in summary_lines(out, participant):
            print(line)
    except (ProtocolFileError, ValueError) as e:
        report("trial", e)
        code = EXIT_USAGE
    except RunnerError as e:
        report("trial", e)
        code = EXIT_USAGE if e.usage else EXIT_FAILURE
    except LinkError as e:
        code = fail("trial", e)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        print(
            "\ngraspguide trial: interrupted; every completed trial is in the device's store "
            f"({store_path}): run the same command again to resume",
            file=sys.stderr,
        )
    finally:
        try:
            client.stop()
        except (LinkError, OSError) as e:
            print(f"graspguide trial: STOP failed: {e}", file=sys.stderr)
            code = code or EXIT_FAILURE
        except KeyboardInterrupt:
            pass
        finally:
            transport.close()
    return code


__all__ = [
    "hostless_trial_command",
    "run_hostless",
    "HostlessSummary",
    "HostlessWorld",
    "check_settings",
    "DEFAULT_REST_S",
    "DEFAULT_REACTION_S",
    "HAND_RETURN_PEAK_DPS",
]
