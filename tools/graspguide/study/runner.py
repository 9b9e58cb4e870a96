"""`graspguide trial`: run a participant's planned trials (protocol.study_protocol) through
a device, log every trial and frame, ask the NASA-TLX after each session, and resume after
a crash or Ctrl-C without repeating or losing a completed trial.

Output: the study folder ``OUT`` (``--out``) as :mod:`graspguide.records.files` lays it
out (the analysis reads exactly this, docs/study.md describes it):

* the study file -- the normalised protocol, its ``config_hash`` and the drawn wrenches
  (written once; a later run with another protocol into the same OUT is refused);
* per participant, the trial records -- one :class:`graspguide.records.trial.TrialRecord`
  per completed trial, appended and fsync'ed as one line when its TRIAL_RESULT arrived;
* the TLX records -- one :class:`graspguide.records.trial.TlxRecord` per finished session
  (``scales`` null when the source is simulated and no --tlx file was given: never
  invented);
* the frames of each trial -- every POSE and its TELEMETRY
  (:data:`graspguide.records.frames.FRAME_COLUMNS`), written to a temporary file and
  renamed before the trial's line is appended;
* the participant's plan, and the runs file (one line per run start and end: device,
  source, resumed trials, damaged lines found, exit);
* the events file -- the operator's pauses, resumes, redos, skips and notes, one fsync'ed
  line each (``time``, ``participant``, ``trial_index``, ``kind``, ``reason`` or
  ``text``); a skipped trial is recorded only there (never as a trial record, so the
  analysis cannot count it as a failure), and a resumed run does not run it;
* the frames set aside -- those of an attempt the operator ended with a redo or a skip
  (a paused attempt's frames are discarded).

With a person (:class:`OperatorConsole` given): a rest of ``rest_s`` between trials, a
ready prompt before each, and the operator's keys during a trial (p pause: STOP, the
trial restarts from scratch on Enter; r redo and s skip with a typed reason; n a note);
the closed loop then always runs in lockstep. Without a console nothing of this runs and
the fast path is the one described below (``rest_s``, 0 by default, still sleeps between
trials). :class:`graspguide.records.events.TrialObserver` objects get the run's events
and every TELEMETRY.

Resume: completed ``trial_index`` values in the trial records are skipped. A last line
without its newline or not valid JSON (a write cut by a power loss) is reported, moved to
``<file>.damaged-<time>`` and its trial run again; a damaged line before the last
one stops the run (it needs a person to look).

Sources (``--source``): ``synthetic[:...]`` and ``replay:FILE`` (open loop: the hand moves
whatever the motors do; each trial replays the file from its start; after the source
ends its last pose is held until the device ends the trial), ``lsl:...`` (a live LSL
MoCap stream, real time: each trial takes its samples from its START on; a gap sends no
POSE, the device's watchdog turns the motors off, and the trial goes on; a live source
that ends is no pose to hold: the trial ends unrecorded, RunnerError),
``participant[:PARAMS]`` (the virtual participant,
``graspguide.participant.model.VirtualParticipant.from_spec(PARAMS, seed)``), and
``plugin:MODULE:CLASS[:ARG]``: a :class:`graspguide.sources.poses.TrackerAdapter` (a live
tracker, a person: real time, TLX asked) or a closed-loop class. A closed-loop source has
``rate_hz``, ``SIMULATED``, ``begin_trial(*, contacts, y_axis, wrench, policy, mode,
start_quat)`` and ``step(t_s, pwm) -> quat (w, x, y, z)``; it runs in lockstep with the
device: ``step`` is called once per pose at ``t_s = i / pose_rate_hz`` (the protocol's
``[study] pose_rate_hz``; i = 0, 1, ...) with the PWM of the previous pose's TELEMETRY
(zeros for i = 0) and returns the pose to send. Open-loop sources also run at the
protocol's pose rate, except a replay (its own timestamps) and ``synthetic:rate=..``.

Pipelining (on the virtual clock, a closed-loop source with ``feel``/``act``/``max_lead``,
i.e. the virtual participant): up to :func:`pipeline_window` POSEs (reaction time x pose
rate - 1: 20 at 0.21 s and 100 Hz) go out before their predecessors' TELEMETRY. The poses
come from ``model.act(t)`` and each TELEMETRY is given to ``model.feel(t, pwm)`` as it
arrives: one model step per pose, no copy, no speculation. The model guarantees (and
checks: FeelLagError) that act(t) depends only on PWM felt a reaction time before t, so
the poses are bit for bit the lockstep ones (graspguide.study.pose_loop.PipelinedPoses); a
FeelLagError reruns the trial in lockstep. Trials, frames and resume are those of
lockstep (tools/tests/study/test_demo.py compares them frame for frame);
``StudyRunner(pipeline=1)`` forces lockstep, and a source without feel/act always runs in
lockstep.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import fcntl
import json
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TextIO

from graspguide.core.motor_calibration import MotorCalibration
from graspguide.link.messages import POSE_WATCHDOG_MS
from graspguide.link.transport import LinkError
from graspguide.protocol.study_protocol import (
    PlannedTrial,
    Protocol,
    Session,
    draw_familiarization_wrenches,
    draw_wrenches,
    plan,
    session_order,
)
from graspguide.protocol.tlx import TLX_SCALES, ask_tlx
from graspguide.records.events import (
    NOTE,
    PAUSE,
    REDO,
    RESUME,
    SESSION_START,
    SKIP,
    STUDY_END,
    TRIAL_END,
    TRIAL_START,
    TrialObserver,
)
from graspguide.records.files import ParticipantFiles, study_file
from graspguide.records.frames import FramesFile, frame_rows
from graspguide.records.storage import (
    JsonlDamaged,
    RecordWriteError,
    append_json_line,
    read_jsonl,
    set_aside_damaged_tail,
    write_json_file,
)
from graspguide.records.trial import TlxRecord, TrialRecord
from graspguide.run_errors import RunnerError
from graspguide.sources.trial_sources import RunnerSource
from graspguide.study.pose_loop import (
    Diverged,
    LockstepPoses,
    LoopResult,
    OpenLoopPoses,
    PipelinedPoses,
    PoseLoop,
    PoseLoopError,
    Stamped,
    TrialOverrun,
    pipeline_window,
)
from graspguide.study.progress import Progress, format_duration, time_left_s

STUDY_FORMAT = "graspguide-study/1"
# A trial whose device clock passed timeout_s by this much without a TRIAL_RESULT is an
# error (the device should have ended it).
RESULT_MARGIN_S = 2.0
# The rest between two trials of a person when --rest-s is not given (seconds).
PERSON_REST_S = 5.0


def _now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


class _OperatorStop(Exception):
    """The operator pressed p, r or s during a trial (raised between two poses)."""

    def __init__(self, key: str):
        super().__init__(key)
        self.key = key


class _Keyed:
    """A trial's poses with the operator's keys read before each one (never waiting)."""

    window = 1

    def __init__(self, poses: Any, poll: Callable[[], None]):
        self._poses = poses
        self._poll = poll
        self.feel = poses.feel

    def next_batch(self, index: int) -> Any:
        self._poll()
        return self._poses.next_batch(index)


# Said after a disk fault (RecordWriteError): every completed trial is kept.
_RESUME_HINT = ", then run again (completed trials are kept)"


def append_line(path: str, obj: Any) -> None:
    """Append one record to a run's JSON Lines file, whole or not at all."""
    append_json_line(path, obj, _RESUME_HINT)


def read_run_jsonl(path: str) -> Any:
    """The records of a run's JSON Lines file (records.read_jsonl); a damaged line before
    the last one is a RunnerError: a person must look."""
    try:
        return read_jsonl(path)
    except JsonlDamaged as e:
        raise RunnerError(
            f"{path}: line {e.line} is damaged (not a JSON object) "
            "and more lines follow it; this is not a cut write: "
            "inspect the file, repair or move it, and run again"
        ) from None


def write_json_atomic(path: str, data: Any) -> None:
    write_json_file(path, data, _RESUME_HINT, indent=2, sort_keys=True)


@dataclasses.dataclass(eq=False)
class StudyRunner:
    """One participant's run into ``out_dir``. :meth:`run` goes through the plan; the
    caller owns the device client (HELLO is sent here, STOP in :meth:`run`'s finally).
    ``tlx``: the NASA-TLX answers by session (else asked with ``ask``, default input);
    ``pipeline``: POSEs sent ahead of their TELEMETRY (closed loop, virtual clock): None =
    what the source allows (pipeline_window), 1 = lockstep. See _closed_loop_pipelined."""

    protocol: Protocol
    participant: str
    out_dir: str
    source: RunnerSource
    client: Any
    virtual_clock: bool
    tlx: dict[int, dict[str, int]] | None = None
    ask: Callable[[str], str] = input
    progress: Progress = dataclasses.field(default_factory=Progress)
    protocol_file: str | None = None
    err: TextIO | None = None
    port: str = ""
    pipeline: int | None = None
    operator: Any = None  # an entered operator_console.OperatorConsole: a person's run
    rest_s: float = 0.0
    observers: Sequence[TrialObserver] = ()
    # The participant's per-motor calibration (graspguide calibrate); None: the paper's
    # mapping. Sent on every run, the identity too, so a device that kept an earlier
    # participant's calibration never renders this one's trials with it.
    calibration: MotorCalibration | None = None
    # Whether the records say SIMULATED (trial_sources.simulation: the source, or a
    # simulated device); None: the source's word. The TLX follows the source alone.
    simulated: bool | None = None

    def __post_init__(self) -> None:
        if self.simulated is None:
            self.simulated = bool(self.source.simulated)
        self.pipeline_fallbacks = 0
        # None given for ask, progress or err (a caller passing its own default through)
        # means the default.
        if self.ask is None:
            self.ask = input
        self.progress = self.progress or Progress()
        self.err = self.err or sys.stderr
        self.files = ParticipantFiles.of(self.out_dir, self.participant)
        self.pdir = self.files.folder
        self.trials_path = self.files.trials
        self.tlx_path = self.files.tlx
        self.frames_dir = self.files.frames_dir
        self.runs_path = self.files.runs
        self.events_path = self.files.events
        self.aside_dir = self.files.aside_dir
        self.durations_s: list[float] = []  # wall time of each recorded trial
        self.wrenches = draw_wrenches(self.protocol)
        self.fam_wrenches = draw_familiarization_wrenches(self.protocol)
        self.sessions = session_order(self.protocol, self.participant)
        self.plan = plan(self.protocol, self.participant, self.wrenches, self.fam_wrenches)
        self.config_hash = self.protocol.config_hash
        self._vt_base_us = 0
        # The session clock of the observers that keep poses (--record): a trial's start
        # offset (see _trial_offset_s) plus the pose's t_s.
        self._session_t0 = time.monotonic()
        self._pose_observers = [o for o in self.observers if callable(getattr(o, "on_pose", None))]
        self._clocked = [o for o in self.observers if callable(getattr(o, "on_trial_clock", None))]
        self._scene_key: tuple[int, str, str] | None = None
        self._lock_fd: int | None = None
        self.ran = 0
        self.skipped = 0
        self.skipped_by_operator: set = set()
        self.damaged: list[str] = []

    # ---- files
    def _study_dict(self) -> dict[str, Any]:
        return {
            "format": STUDY_FORMAT,
            "protocol": self.protocol.to_dict(),
            "config_hash": self.config_hash,
            "protocol_file": self.protocol_file,
            "wrenches": [w.to_dict() for w in self.wrenches],
            "familiarization_wrenches": [w.to_dict() for w in self.fam_wrenches],
            "sessions_per_participant": self.protocol.sessions_per_participant,
            "trials_per_participant": len(self.plan),
            "single_motor_rule": "mode C, protocol constraints, at [trial] start_quat: "
            "exactly one motor PWM > 0",
            "tlx_scales": list(TLX_SCALES),
        }

    def prepare(self) -> tuple[set, set]:
        """Create/check the folders; returns (completed trial indices, sessions with TLX)."""
        study_path = study_file(self.out_dir)
        study = self._study_dict()
        if os.path.exists(study_path):
            try:
                with open(study_path, encoding="utf-8") as f:
                    old = json.load(f)
            except (OSError, ValueError) as e:
                raise RunnerError(
                    f"{study_path} is unreadable ({e}); move it away", usage=True
                ) from None
            if old.get("config_hash") != self.config_hash:
                raise RunnerError(
                    f"{self.out_dir} holds a study with another protocol (config_hash "
                    f"{str(old.get('config_hash'))[:12]}..., this one {self.config_hash[:12]}"
                    "...): use another --out, or the protocol that study was run with",
                    usage=True,
                )
            if old.get("wrenches") != study["wrenches"]:
                raise RunnerError(
                    f"{study_path}: the same protocol now draws other wrenches (a different "
                    "core version?); finish this study with the tools it was started with, "
                    "or use another --out",
                    usage=True,
                )
        else:
            write_json_atomic(study_path, study)
        write_json_atomic(
            self.files.plan,
            {
                "participant": self.participant,
                "config_hash": self.config_hash,
                "sessions": [
                    {"session": s.session, "k": s.k, "modality": s.modality} for s in self.sessions
                ],
                "trials": [t.to_dict() for t in self.plan],
            },
        )
        done = self._completed_trials()
        tlx_done = self._tlx_sessions()
        self.skipped_by_operator = self._skipped_trials()
        return done, tlx_done

    def _lock(self) -> None:
        path = self.files.lock
        try:
            os.makedirs(self.frames_dir, exist_ok=True)
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise RecordWriteError(e.filename or path, e, _RESUME_HINT) from e
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise RunnerError(
                f"another `graspguide trial` is writing {self.pdir}; wait for it or stop it first",
                usage=True,
            ) from None
        self._lock_fd = fd

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None

    def _read_checked(self, path: str) -> list[dict[str, Any]]:
        contents = read_run_jsonl(path)
        if contents.damaged_tail is not None:
            try:
                aside = set_aside_damaged_tail(path, contents)
            except OSError as e:
                raise RecordWriteError(e.filename or path, e, _RESUME_HINT) from e
            msg = (
                f"{path}: the last line was half-written ({len(contents.damaged_tail)} "
                f"bytes, a write cut by a crash or power loss); moved it to {aside} and "
                "will run what it recorded again"
            )
            print(f"graspguide trial: warning: {msg}", file=self.err, flush=True)
            self.damaged.append(msg)
        return contents.records

    def _completed_trials(self) -> set:
        by_index = {t.trial_index: t for t in self.plan}
        done = set()
        for rec in self._read_checked(self.trials_path):
            idx = rec.get("trial_index")
            t = by_index.get(idx)  # type: ignore[arg-type]
            if (
                t is None
                or rec.get("wrench_id") != t.wrench_id
                or rec.get("modality") != t.modality
                or rec.get("k") != t.k
            ):
                raise RunnerError(
                    f"{self.trials_path}: trial {idx} does not match this "
                    f"protocol's plan for {self.participant}; this folder belongs "
                    "to another protocol or participant",
                    usage=True,
                )
            if idx in done:
                raise RunnerError(
                    f"{self.trials_path}: trial {idx} is recorded twice; inspect the file",
                    usage=True,
                )
            if bool(rec.get("simulated")) != self.simulated:
                kind = "simulated" if rec.get("simulated") else "human"
                raise RunnerError(
                    f"{self.trials_path} holds {kind} trials; this run is "
                    f"{'simulated' if self.simulated else 'a person on a board'}: "
                    "use another --out or --participant, never mix them",
                    usage=True,
                )
            done.add(idx)
            if isinstance(rec.get("wall_s"), (int, float)):
                self.durations_s.append(float(rec["wall_s"]))
        return done

    def _skipped_trials(self) -> set:
        """The trials the operator skipped (the events file), which a resumed run honours."""
        if not os.path.exists(self.events_path):
            return set()
        return {
            rec.get("trial_index")
            for rec in self._read_checked(self.events_path)
            if rec.get("kind") == SKIP
        }

    # ---- events (operator's log, observers)
    def _notify(self, name: str, **fields: Any) -> None:
        for obs in self.observers:
            obs.on_event(name, **fields)

    def _event(self, kind: str, trial_index: int | None, **fields: Any) -> None:
        """One operator event: a line in the events file (fsync'ed), then the observers."""
        append_line(
            self.events_path,
            {
                "time": _now_iso(),
                "participant": self.participant,
                "trial_index": trial_index,
                "kind": kind,
                **fields,
            },
        )
        self._notify(kind, trial_index=trial_index, **fields)

    def _tlx_sessions(self) -> set:
        return {rec.get("session") for rec in self._read_checked(self.tlx_path)}

    def _log_run(self, event: str, **extra: Any) -> None:
        append_line(
            self.runs_path,
            {"event": event, "time": _now_iso(), "participant": self.participant, **extra},
        )

    # ---- one trial, top-down: run_trial, then each of its steps in the order they run
    def run_trial(self, trial: PlannedTrial) -> dict[str, Any]:
        """One trial: the device and the model told it, its frames written while the poses
        go out until the device ends it, its TRIAL_RESULT checked, its frames kept; returns
        its record (the caller appends it). RunnerError, RecordWriteError, LinkError;
        _OperatorStop when the operator pressed p, r or s."""
        contacts = [list(c) for c in self.protocol.hands[trial.k]]
        model = self.source.model if self.source.closed_loop else None  # type: ignore[attr-defined]
        counted = self._source_stats()
        stale = self._stale_events() if counted is not None else None
        self._start_trial(trial, model, contacts)
        frames = FramesFile(self.files.partial_frames(trial.trial_index), _RESUME_HINT)
        wall0 = time.monotonic()
        try:
            done = self._drive(trial, model, contacts, frames)
            frames.sync()
        finally:
            frames.close()
        if counted is not None:
            after = self._stale_events() if stale is not None else None
            watchdog = None if after is None or stale is None else (after - stale) % 2**32
            self._say_gaps(trial, counted, self._source_stats(), watchdog)
        result = self._checked_result(trial, done)
        self._keep_frames(trial)
        self._vt_base_us += int(round((done.t_s + 1.0) * 1e6))
        return self._record(trial, result, done.frames, wall0)

    def _source_stats(self) -> dict[str, Any] | None:
        stats = getattr(self.source, "stats", None)
        return stats() if callable(stats) else None

    def _stale_events(self) -> int | None:
        """The device's count of POSE watchdog expiries (STATUS), None when not known."""
        try:
            return int(self.client.status().stale_events)
        except (LinkError, AttributeError):
            return None

    def _say_gaps(
        self,
        trial: PlannedTrial,
        before: dict[str, Any],
        after: dict[str, Any] | None,
        watchdog: int | None,
    ) -> None:
        """On stderr, the gaps of a live tracker during the trial (a stall; a marker or the
        rigid body lost past its hold, a pause): no POSE then, so the device's watchdog
        turned the motors off (``watchdog``: how often its STATUS says it did); the trial
        ran on. The source says each gap as it happens; this is the trial's account, so
        that none reads as a link fault. A loss within the hold is no gap (the last
        position stands in, POSEs go on) and is not counted here."""
        if after is None:
            return
        gaps = [
            (after.get(key, 0) - before.get(key, 0), what)
            for key, what in (
                ("stalls", "stalls (no sample)"),
                ("pauses", "pauses (a marker or the rigid body lost past its hold)"),
            )
        ]
        said = [f"{what}: {n}" for n, what in gaps if n > 0]
        if not said:
            return
        fired = "" if watchdog is None else f" ({watchdog} time{'s' * (watchdog != 1)})"
        print(
            f"graspguide trial: trial {trial.trial_index}: gaps in the tracker's stream, "
            f"{', '.join(said)}: no POSE was sent then and the device's watchdog turned the "
            f"motors off {POSE_WATCHDOG_MS} ms after the last one{fired}; a gap in the "
            "tracking, not a link fault: the trial ran on, its time includes the gap",
            file=self.err,
            flush=True,
        )

    def _start_trial(self, trial: PlannedTrial, model: Any, contacts: list[list[float]]) -> None:
        """SET_SCENE when the condition changed, START_TRIAL, and the closed-loop model
        (None for an open-loop source) told the trial."""
        p = self.protocol
        self._scene(trial)
        self.client.trial_results.clear()
        self.client.start_trial(trial.trial_index & 0xFFFF, list(trial.wrench))
        if model is not None:
            model.begin_trial(
                contacts=contacts,
                y_axis=list(p.y_axis),
                wrench=list(trial.wrench),
                policy=trial.policy,
                mode=trial.mode,
                start_quat=list(p.start_quat),
            )

    def _scene(self, trial: PlannedTrial) -> None:
        key = (trial.k, trial.policy, trial.mode)
        if key == self._scene_key:
            return
        p = self.protocol
        self.client.set_scene(
            [list(c) for c in p.hands[trial.k]],
            y_axis=list(p.y_axis),
            constraints=p.constraints,
            policy=trial.policy,
            mode=trial.mode,
            threshold_deg=p.threshold_deg,
            hold_s=p.hold_s,
            timeout_s=p.timeout_s,
        )
        self._scene_key = key

    def _drive(
        self, trial: PlannedTrial, model: Any, contacts: list[list[float]], frames: FramesFile
    ) -> LoopResult:
        """The poses out and their TELEMETRY into ``frames`` (pose_loop.PoseLoop) until
        the device ends the trial; pipelined when the source allows it, and the whole trial
        again in lockstep should the pipelined poses diverge."""
        p = self.protocol
        console = self.operator
        window = 1 if console is not None else self._window(model is not None)
        on_frames = self._frames_sink(trial, frames)
        pose_observers = self._pose_observers

        def on_send(t_us: int, t_s: float, quat: Sequence[float], contacts: Any) -> None:
            for obs in pose_observers:
                obs.on_pose(t_s, quat, contacts)  # type: ignore[attr-defined]

        while True:
            loop = PoseLoop(
                self.client,
                self.virtual_clock,
                base_us=self._vt_base_us,
                limit_s=p.timeout_s + RESULT_MARGIN_S,
                wall_limit_s=p.timeout_s + 10 * RESULT_MARGIN_S,
                on_send=on_send if pose_observers else None,
                on_frames=on_frames,
            )
            self._tell_clock(self._trial_offset_s(loop))
            poses = self._trial_poses(trial, model, window)
            if console is not None:
                poses = _Keyed(poses, lambda: self._poll_keys(trial))
            try:
                return loop.run(poses)
            except Diverged as e:
                # Never expected (see pose_loop.PipelinedPoses); the poses the device
                # got are not the lockstep ones: run the whole trial again in lockstep.
                self.pipeline_fallbacks += 1
                print(
                    f"graspguide trial: warning: trial {trial.trial_index}: {e}; "
                    "running it again in lockstep",
                    file=self.err,
                    flush=True,
                )
                frames.restart()
                self._restart_trial(trial, model, contacts)
                window = 1
            except TrialOverrun as e:
                if e.real_time:
                    raise RunnerError(
                        f"trial {trial.trial_index}: no TRIAL_RESULT after {e.wall_s:.1f} s"
                    ) from None
                raise RunnerError(
                    f"trial {trial.trial_index}: no TRIAL_RESULT {e.t_s:.1f} s into a "
                    f"{p.timeout_s:g} s trial; is the device's clock following the poses?"
                ) from None
            except PoseLoopError as e:
                raise RunnerError(f"trial {trial.trial_index}: {e}") from None

    def _trial_offset_s(self, loop: PoseLoop | None) -> float:
        """Where a trial's t_s = 0 lies on the session clock: on the virtual clock the
        device's time base of the trial (its POSE timestamps / 1e6), in real time the
        host's monotonic time of its start (the pose loop's, else now) since the run
        began."""
        if self.virtual_clock:
            return self._vt_base_us / 1e6
        start = time.monotonic() if loop is None else loop.wall0
        return start - self._session_t0

    def _tell_clock(self, offset_s: float) -> None:
        for obs in self._clocked:
            obs.on_trial_clock(offset_s)  # type: ignore[attr-defined]

    def _window(self, closed: bool) -> int:
        """POSEs in flight: 1 (lockstep) unless the source is a closed loop on the virtual
        clock whose :func:`pipeline_window` allows more (and --pipeline did not say 1)."""
        if not closed or not self.virtual_clock or self.pipeline == 1:
            return 1
        limit = pipeline_window(self.source.model, self.protocol.pose_rate_hz)  # type: ignore
        if self.pipeline is not None:
            limit = min(limit, int(self.pipeline))
        return max(1, limit)

    def _frames_sink(
        self, trial: PlannedTrial, frames: FramesFile
    ) -> Callable[[int, list[Stamped], list[Any]], None]:
        """What the pose loop does with each batch of frames: the rows into ``frames``,
        the live line, and with observers or a person the TELEMETRY to the observers
        (a note being typed stays visible)."""
        k = trial.k
        real_time = not self.virtual_clock
        progress_frame = self.progress.frame
        observers = self.observers
        console = self.operator

        def on_frames(first: int, stamped: list[Stamped], tels: list[Any]) -> None:
            # One write per batch; the live line shows the batch's last frame (a batch
            # is one frame in real time, and a few ms of wall time on the virtual clock).
            frames.write(frame_rows(stamped, tels))
            tel = tels[-1]
            progress_frame(
                stamped[-1][0], float(tel.error_deg), tel.pwm[:k], real_time, tel.solver_status == 0
            )

        def on_frames_observed(first: int, stamped: list[Stamped], tels: list[Any]) -> None:
            frames.write(frame_rows(stamped, tels))
            for (t_s, _, _, _), tel in zip(stamped, tels):
                err, alpha, pwm, status = (
                    float(tel.error_deg),
                    float(tel.alpha),
                    list(tel.pwm),
                    int(tel.solver_status),
                )
                for obs in observers:
                    obs.on_telemetry(t_s, err, alpha, pwm, status)
            tel = tels[-1]
            if console is None or not console.typing:
                progress_frame(
                    stamped[-1][0],
                    float(tel.error_deg),
                    tel.pwm[:k],
                    real_time,
                    tel.solver_status == 0,
                )

        return on_frames if console is None and not observers else on_frames_observed

    def _trial_poses(self, trial: PlannedTrial, model: Any, window: int) -> Any:
        """Where the trial's poses come from (pose_loop): the open-loop samples, the
        closed loop in lockstep, or pipelined ``window`` deep."""
        rate = self.protocol.pose_rate_hz  # the study's pose rate (the tracker's)
        if model is None:
            return OpenLoopPoses(self._held_samples(trial))
        if window > 1:
            from graspguide.participant.model import FeelLagError

            return PipelinedPoses(model, rate, trial.k, window, FeelLagError)
        return LockstepPoses(model.step, rate, trial.k)

    def _held_samples(self, trial: PlannedTrial) -> Iterator[tuple[float, Any, Any]]:
        """Open loop: the source's samples, then its last pose held at its rate. A live
        source (a tracker) that ends is no pose to hold: a person's hand is not where it
        was seconds ago, so the trial ends unrecorded (RunnerError)."""
        period = 1.0 / self.source.rate_hz
        last = None
        for sample in self.source.samples(trial):  # type: ignore[attr-defined]
            last = sample
            yield sample
        if self.source.live:
            raise RunnerError(
                f"trial {trial.trial_index}: the live source "
                f"{self.source.describe()['source']} ended before the device ended the "
                "trial (no sample for its end time); the trial is not recorded: make sure "
                "the tracker streams, then run the same command again to resume"
            )
        if last is None:
            raise RunnerError(f"--source {self.source.describe()['source']} gave no pose")
        t, q, c = last
        while True:
            t += period
            yield (t, q, c)

    def _restart_trial(self, trial: PlannedTrial, model: Any, contacts: list[list[float]]) -> None:
        """The trial from its start again: STOP, the device drained, a fresh virtual time."""
        try:
            self.client.stop()
        except Exception:
            pass
        self.client.drain(0.05)
        self.client.trial_results.clear()
        self.client.unmatched.clear()
        self._vt_base_us += int(round((self.protocol.timeout_s + 2 * RESULT_MARGIN_S) * 1e6))
        self._scene_key = None
        self._start_trial(trial, model, contacts)

    def _checked_result(self, trial: PlannedTrial, done: LoopResult) -> Any:
        """The trial's TRIAL_RESULT; RunnerError when none came or another trial's did."""
        result = done.trial_result
        if result is None:
            raise RunnerError(
                f"trial {trial.trial_index}: the device ended the trial but no TRIAL_RESULT arrived"
            )
        if int(result.trial_id) != trial.trial_index & 0xFFFF:
            raise RunnerError(
                f"trial {trial.trial_index}: the device answered with the "
                f"TRIAL_RESULT of trial id {result.trial_id}; run again (this "
                "trial was not recorded)"
            )
        return result

    def _keep_frames(self, trial: PlannedTrial) -> None:
        """The trial's frames file renamed to its final name (before its record goes in)."""
        path = self.files.frames(trial.trial_index)
        try:
            os.replace(self.files.partial_frames(trial.trial_index), path)
        except OSError as e:
            raise RecordWriteError(path, e, _RESUME_HINT) from e

    def _record(self, trial: PlannedTrial, result: Any, poses: int, wall0: float) -> dict[str, Any]:
        """The trial's record: its plan, the TRIAL_RESULT (a failure takes the timeout as
        its completion time) and how it ran."""
        success = bool(result.success)
        completion = (
            round(float(result.completion_s), 6) if success else float(self.protocol.timeout_s)
        )
        return TrialRecord.of_planned(
            {**trial.to_dict(), "participant": self.participant},
            simulated=bool(self.simulated),
            success=success,
            completion_s=completion,
            first_entry_s=round(float(result.first_entry_s), 6),
            final_error_deg=round(float(result.final_error_deg), 6),
            poses=poses,
            wall_s=round(time.monotonic() - wall0, 4),
            config_hash=self.config_hash,
            source=self.source.describe()["source"],
            recorded_at=_now_iso(),
        ).to_dict()

    # ---- a person's run: rest, ready prompt, the operator's keys
    def _left_s(self, done: set) -> float | None:
        """The estimated time left (real time only: on the virtual clock it is moot)."""
        if self.virtual_clock:
            return None
        gone = done | self.skipped_by_operator
        remaining = sum(1 for t in self.plan if t.trial_index not in gone)
        return time_left_s(remaining, self.durations_s, self.rest_s, self.protocol.timeout_s)

    def _begin(self, trial: PlannedTrial, done: set, attempt: int) -> None:
        self.progress.trial_start(trial, len(self.plan), len(self.sessions), self._left_s(done))
        self._tell_clock(self._trial_offset_s(None))
        self._notify(
            TRIAL_START,
            trial_index=trial.trial_index,
            session=trial.session,
            k=trial.k,
            modality=trial.modality,
            wrench_id=trial.wrench_id,
            familiarization=trial.familiarization,
            attempt=attempt,
        )

    def _poll_keys(self, trial: PlannedTrial) -> None:
        for kind, value in self.operator.poll():
            if kind == "note":
                self._event(NOTE, trial.trial_index, text=value)
            else:
                raise _OperatorStop(value)

    def _note_key(self, trial: PlannedTrial) -> None:
        text = self.operator.read_line("note: ").strip()
        if text:
            self._event(NOTE, trial.trial_index, text=text)

    def _rest(self, trial: PlannedTrial) -> None:
        """The rest before ``trial`` (not before a run's first): a sleep, or with a person
        a countdown during which notes can be typed."""
        if self.rest_s <= 0:
            return
        if self.operator is None:
            time.sleep(self.rest_s)
            return
        self.progress.line(f"rest {self.rest_s:g} s (n: note)")
        deadline = time.monotonic() + self.rest_s
        while (left := deadline - time.monotonic()) > 0:
            for kind, value in self.operator.poll():
                if kind == "note":
                    self._event(NOTE, trial.trial_index, text=value)
            time.sleep(min(0.05, left))

    def _ready(self, trial: PlannedTrial, done: set) -> bool:
        """The ready prompt: True on Enter, False when the operator skipped the trial."""
        left = self._left_s(done)
        sess = "familiarization" if trial.familiarization else f"session {trial.session}"
        head = (
            f"Trial {trial.trial_index}/{len(self.plan)}, {sess}, k={trial.k} "
            f"{trial.modality} {trial.wrench_id}"
            + ("" if left is None else f" ({format_duration(left)} left)")
        )
        while True:
            self.progress.line(
                f"{head}: press Enter when the participant is ready (s skip, n note)"
            )
            key = (self.operator.wait_key() or "").lower()
            if key == "\n":
                return True
            if key == "s":
                reason = self.operator.read_reason("skip")
                self._event(SKIP, trial.trial_index, reason=reason, attempt=0)
                return False
            if key == "n":
                self._note_key(trial)

    def _frames_tmp(self, trial: PlannedTrial) -> str:
        return self.files.partial_frames(trial.trial_index)

    def _set_aside(self, trial: PlannedTrial) -> str | None:
        """An ended attempt's frames moved aside (path relative to the participant's folder)."""
        tmp = self._frames_tmp(trial)
        if not os.path.exists(tmp):
            return None
        try:
            os.makedirs(self.aside_dir, exist_ok=True)
            attempt = 1
            while True:
                path = self.files.aside(trial.trial_index, attempt)
                if not os.path.exists(path):
                    break
                attempt += 1
            os.replace(tmp, path)
        except OSError as e:
            raise RecordWriteError(e.filename or tmp, e, _RESUME_HINT) from e
        return os.path.relpath(path, self.pdir)

    def _motors_off(self) -> None:
        """STOP now (the operator ended the attempt), then the device ready for a new
        START_TRIAL: no stale TRIAL_RESULT, the scene set again, a fresh virtual time."""
        self.client.stop()
        self.client.drain(0.05)
        self.client.trial_results.clear()
        self.client.unmatched.clear()
        self._scene_key = None
        self._vt_base_us += int(round((self.protocol.timeout_s + 2 * RESULT_MARGIN_S) * 1e6))

    def _person_trial(self, trial: PlannedTrial, done: set) -> dict[str, Any] | None:
        """The trial with the operator's keys: its record, or None when skipped."""
        idx = trial.trial_index
        attempt = 1
        while True:
            self._begin(trial, done, attempt)
            try:
                return self.run_trial(trial)
            except _OperatorStop as stop:
                self._motors_off()
                self.progress.line(f"trial {idx}: stopped, motors off")
                if stop.key == "p":
                    try:
                        os.unlink(self._frames_tmp(trial))
                    except FileNotFoundError:
                        pass
                    self._event(PAUSE, idx, attempt=attempt)
                    while True:
                        self.progress.line(
                            "paused: press Enter to resume (the trial starts again from "
                            "scratch), n: note"
                        )
                        key = (self.operator.wait_key() or "").lower()
                        if key == "\n":
                            break
                        if key == "n":
                            self._note_key(trial)
                    self._event(RESUME, idx, attempt=attempt + 1)
                else:
                    frames = self._set_aside(trial)
                    what = "redo" if stop.key == "r" else "skip"
                    reason = self.operator.read_reason(what)
                    kind = REDO if stop.key == "r" else SKIP
                    self._event(kind, idx, reason=reason, attempt=attempt, frames=frames)
                    if kind == SKIP:
                        return None
                attempt += 1

    # ---- TLX
    def _tlx(self, session: Session) -> None:
        if self.tlx is not None and session.session in self.tlx:
            scales: dict[str, int] | None = self.tlx[session.session]
            origin = "file"
        elif self.tlx is not None and not self.source.simulated:
            raise RunnerError(
                f"the --tlx file has no line for session {session.session} "
                f"({session.modality}, k = {session.k}); add it and run again "
                "(completed trials are kept)",
                usage=True,
            )
        elif self.source.simulated:
            scales, origin = None, "absent: simulated source, no --tlx"
        else:
            # reviewed before saving when someone is at the terminal (the operator console)
            scales = ask_tlx(session, self.ask, self.progress.out, review=self.operator is not None)
            origin = "interactive"
        append_line(
            self.tlx_path,
            TlxRecord(
                participant=self.participant,
                simulated=bool(self.simulated),
                session=session.session,
                k=session.k,
                modality=session.modality,
                policy=session.policy,
                mode=session.mode,
                scales=scales,
                origin=origin,
                config_hash=self.config_hash,
                recorded_at=_now_iso(),
            ).to_dict(),
        )

    # ---- all
    def run(self) -> dict[str, Any]:
        """Run what is left of the plan. Returns a summary; raises RunnerError, LinkError,
        KeyboardInterrupt. STOP is sent on the way out, whatever happens. A disk fault
        (full, read-only, a size limit) is a RunnerError naming the file; no record is
        left half-written."""
        try:
            self._lock()
            try:
                return self._run_locked()
            finally:
                self._unlock()
        except RecordWriteError as e:
            raise RunnerError(str(e)) from e

    def _run_locked(self) -> dict[str, Any]:
        done, tlx_done = self.prepare()
        info = self.client.hello()
        self.client.stop()  # a trial left running by an earlier run would refuse SET_SCENE
        calibration = self.calibration or MotorCalibration.identity()
        self.client.set_calibration(calibration)
        self.skipped = len(done)
        self._log_run(
            "start",
            config_hash=self.config_hash,
            source=self.source.describe(),
            port=self.port,
            virtual_clock=self.virtual_clock,
            device={
                "board": info.board,
                "build_id": f"{info.build_id:08x}",
                "firmware": ".".join(map(str, info.firmware_version)),
            },
            completed_before=len(done),
            damaged=self.damaged,
            calibration=None if self.calibration is None else calibration.to_json(),
        )
        if done:
            self.progress.line(
                f"resuming {self.participant}: {len(done)} of {len(self.plan)} "
                "trials already completed are skipped"
            )
        total = len(self.plan)
        outcome = "error"
        cause: BaseException | None = None
        try:
            by_session: dict[int, list[PlannedTrial]] = {}
            for t in self.plan:
                by_session.setdefault(t.session, []).append(t)
            first = True
            for sess_no in sorted(by_session):
                started = False
                for trial in by_session[sess_no]:
                    if trial.trial_index in done or trial.trial_index in self.skipped_by_operator:
                        continue
                    if not started:
                        started = True
                        self._notify(
                            SESSION_START,
                            session=sess_no,
                            k=trial.k,
                            modality=trial.modality,
                            familiarization=trial.familiarization,
                        )
                    if not first:
                        self._rest(trial)
                    first = False
                    if self.operator is None:
                        self._begin(trial, done, 1)
                        record: dict[str, Any] | None = self.run_trial(trial)
                    elif self._ready(trial, done):
                        record = self._person_trial(trial, done)
                    else:
                        record = None
                    if record is None:  # skipped by the operator (the events file)
                        self.skipped_by_operator.add(trial.trial_index)
                        continue
                    append_line(self.trials_path, record)
                    done.add(trial.trial_index)
                    self.ran += 1
                    self.durations_s.append(record["wall_s"])
                    self.progress.trial_end(record)
                    self._notify(
                        TRIAL_END,
                        trial_index=trial.trial_index,
                        success=record["success"],
                        completion_s=record["completion_s"],
                    )
                if sess_no >= 1 and sess_no not in tlx_done:
                    self._tlx(self.sessions[sess_no - 1])
                    tlx_done.add(sess_no)
            outcome = "complete"
        except KeyboardInterrupt:
            outcome = "interrupted"
            raise
        except BaseException as e:
            cause = e
            raise
        finally:
            try:
                self._notify(STUDY_END, outcome=outcome, ran=self.ran, completed=len(done))
            except Exception as e:  # an observer's fault must not keep the motors on
                print(f"graspguide trial: study_end observer failed: {e}", file=self.err)
            try:
                self.client.stop()
            except Exception as e:
                if outcome == "complete":
                    raise  # the run's only error: report it
                # keep the error that ended the run; this one is secondary
                print(f"graspguide trial: STOP failed: {e}", file=self.err, flush=True)
            finally:
                try:
                    self._log_run(
                        "end",
                        outcome=outcome,
                        ran=self.ran,
                        completed=len(done),
                        planned=total,
                        skipped_by_operator=sorted(self.skipped_by_operator),
                        **(
                            {"source_stats": stats}
                            if (stats := self._source_stats()) is not None
                            else {}
                        ),
                    )
                except RecordWriteError as e:
                    if outcome == "complete":
                        raise
                    # The error that ended the run is reported; a disk fault that ended
                    # it is this one again.
                    if not isinstance(cause, RecordWriteError):
                        print(f"graspguide trial: warning: {e}", file=self.err, flush=True)
        return {
            "participant": self.participant,
            "planned": total,
            "ran": self.ran,
            "skipped": self.skipped,
            "completed": len(done),
        }


def summary_lines(out_dir: str, participant: str) -> list[str]:
    """Per-modality successes and mean completion time of a participant (main trials)."""
    recs = read_run_jsonl(ParticipantFiles.of(out_dir, participant).trials).records
    rows: dict[tuple[int, str], list[dict[str, Any]]] = {}
    for r in recs:
        if not r.get("familiarization"):
            rows.setdefault((r["k"], r["modality"]), []).append(r)
    out = []
    for (k, m), rs in sorted(rows.items()):
        ok = sum(1 for r in rs if r["success"])
        mean = sum(r["completion_s"] for r in rs) / len(rs)
        out.append(f"  k={k} {m:<8} {ok:>3}/{len(rs)} successes, mean {mean:6.2f} s")
    return out


def trial_command(
    *,
    protocol: str,
    participant: str,
    source: str,
    port: str,
    baud: int,
    timeout: float,
    out: str,
    tlx: str | None,
    rest_s: float | None = None,
    operator: bool = False,
    lsl: str | None = None,
    lsl_wait: float = 0.0,
    record: str | None = None,
) -> int:
    """`graspguide trial`: ``participant``'s trials of the protocol file ``protocol`` on
    the device at ``port`` into ``out``, poses from the source spec ``source``, the
    NASA-TLX answers from the file ``tlx`` when given; resumed where an earlier run
    stopped; STOP on every way out. ``lsl``: publish the run as the LSL streams
    LSL-Telemetry and LSL-Markers (graspguide.sources.lab_streams), after waiting up to
    ``lsl_wait`` s for a recorder. ``record``: the run's poses, TELEMETRY and markers
    into this XDF file (graspguide.sources.xdf_recording, on the session clock). With a
    person (a source not SIMULATED, or
    ``operator``) and a terminal on stdin: the ready prompt, the rest (``rest_s``, default
    PERSON_REST_S; 0 for a simulated source) and the operator's keys. Returns the exit
    code."""
    from graspguide.calibration.calibration_file import (
        CalibrationFileError,
        calibration_path,
        load_participant_calibration,
    )
    from graspguide.calibration.calibration_file import describe as describe_calibration
    from graspguide.devices.session import DeviceSession
    from graspguide.devices.sim import SIM_PORT
    from graspguide.exit_codes import (
        EXIT_FAILURE,
        EXIT_INTERRUPTED,
        EXIT_OK,
        EXIT_USAGE,
        fail,
        report,
    )
    from graspguide.link.transport import LinkError
    from graspguide.protocol.study_protocol import (
        ProtocolFileError,
        load_protocol,
        participant_number,
    )
    from graspguide.protocol.tlx import load_tlx_file
    from graspguide.sources.trial_sources import open_runner_source, simulation

    protocol_file, source_spec, tlx_file = protocol, source, tlx
    try:
        loaded = load_protocol(protocol_file)
        participant_number(participant)
        calibration = load_participant_calibration(out, participant)
        poses = open_runner_source(source_spec, loaded, participant)
        runner_tlx = None
        if tlx_file is not None:
            runner_tlx = load_tlx_file(tlx_file, participant, session_order(loaded, participant))
    except (ProtocolFileError, RunnerError, CalibrationFileError) as e:
        report("trial", e)
        return EXIT_USAGE
    if calibration is not None:
        print(
            f"{participant}: calibration: {calibration_path(out, participant)}: "
            f"{describe_calibration(calibration)}",
            flush=True,
        )
    from graspguide.study.live_view import TrialPanel
    from graspguide.study.operator_console import KEYS_HELP, ConsoleClosed, OperatorConsole

    why_simulated = simulation(source_spec, poses.simulated, port)
    simulated = why_simulated is not None
    tag = "SIMULATED " if simulated else ""
    if simulated:
        print(f"graspguide trial: SIMULATED: {why_simulated}", file=sys.stderr, flush=True)
    person = operator or not poses.simulated
    console: OperatorConsole | None = None
    if person and OperatorConsole.available():
        console = OperatorConsole()
    elif operator:
        report("trial", "--operator needs a terminal on stdin (the operator's keys)")
        return EXIT_USAGE
    elif person:
        print(
            "graspguide trial: warning: stdin is not a terminal: no ready prompt and no "
            "operator keys; trials follow each other after the rest (--rest-s)",
            file=sys.stderr,
            flush=True,
        )
    if rest_s is None:
        rest_s = PERSON_REST_S if person else 0.0
    virtual_clock = port == SIM_PORT and poses.simulated and not poses.live
    observers: list[TrialObserver] = []
    if lsl is not None:
        from graspguide.sources.lab_streams import (
            LabStreamsError,
            LabStreamsUsageError,
            open_lab_streams,
        )

        try:
            observers.append(
                open_lab_streams(
                    "trial",
                    lsl,
                    lsl_wait,
                    participant=participant,
                    session="trial",
                    nominal_rate_hz=0.0 if virtual_clock else float(loaded.pose_rate_hz),
                    simulated=simulated,
                    extra={"protocol": protocol_file, "source": source_spec},
                )
            )
        except LabStreamsError as e:
            report("trial", e)
            return EXIT_USAGE if isinstance(e, LabStreamsUsageError) else EXIT_FAILURE
    recorder = None
    if record:
        from graspguide.sources.xdf_recording import SESSION_CLOCK, XdfRecorder

        try:
            recorder = XdfRecorder(
                record,
                participant=participant,
                session="trial",
                nominal_rate_hz=0.0 if virtual_clock else float(poses.rate_hz),
                simulated=simulated,
                extra={"protocol": protocol_file, "source": source_spec},
                clock=SESSION_CLOCK,
            )
        except OSError as e:  # an existing file (never overwritten), an unwritable folder
            for obs in observers:
                obs.close()  # type: ignore[attr-defined]
            report("trial", e)
            return EXIT_USAGE
        observers.append(recorder)
    try:
        device = DeviceSession("trial", port, baud, timeout, virtual_clock)
    except LinkError as e:
        for obs in observers:
            obs.close()  # type: ignore[attr-defined]
        return fail("trial", e)
    code = EXIT_OK
    runner = None
    panel = TrialPanel(
        loaded.threshold_deg,
        loaded.hold_s,
        loaded.timeout_s,
        simulated=simulated,
        keys=KEYS_HELP.removeprefix("keys: ") if console is not None else None,
    )
    try:
        if console is not None:
            console.__enter__()
            who = (
                "operator mode with a SIMULATED source (no person)"
                if poses.simulated
                else "a run with a person" + (" on a SIMULATED device" if simulated else "")
            )
            print(
                f"{participant}: {who}; {KEYS_HELP} (during a trial), "
                "Ctrl-C ends the run (resume by running the same command again)",
                flush=True,
            )
        runner = StudyRunner(
            loaded,
            participant,
            out,
            poses,
            device.client,
            virtual_clock,
            tlx=runner_tlx,
            progress=panel,
            protocol_file=protocol_file,
            port=port,
            ask=console.read_line if console is not None else input,
            operator=console,
            rest_s=rest_s,
            observers=observers,
            calibration=calibration,
            simulated=simulated,
        )
        result = runner.run()
        skipped = len(runner.skipped_by_operator)
        print(
            f"{tag}{participant}: all {result['planned']} trials done ({result['ran']} "
            f"run now, {result['skipped']} from earlier runs"
            + (f", {skipped} skipped by the operator" if skipped else "")
            + f"); {os.path.join(out, participant)}"
        )
        for line in summary_lines(out, participant):
            print(line)
    except ProtocolFileError as e:
        report("trial", e)
        code = EXIT_USAGE
    except RunnerError as e:
        report("trial", e)
        code = EXIT_USAGE if e.usage else EXIT_FAILURE
    except LinkError as e:
        code = fail("trial", e)
    except (ConsoleClosed, EOFError):
        report("trial", "the terminal's input ended; run the same command again to resume")
        code = EXIT_FAILURE
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        done = "" if runner is None else f" after {runner.ran} trials"
        print(
            f"\ngraspguide trial: interrupted{done}; completed trials are saved: run "
            "the same command again to resume",
            file=sys.stderr,
        )
    finally:
        panel.close()
        if console is not None:
            console.restore()
        if not device.close():
            code = code or EXIT_FAILURE
        for obs in observers:
            try:
                obs.close()  # type: ignore[attr-defined]
            except OSError as e:  # the recording's disk: the chunks before stay whole
                report("trial", e)
                code = code or EXIT_FAILURE
    return code


__all__ = [
    "StudyRunner",
    "trial_command",
    "read_run_jsonl",
    "summary_lines",
]
