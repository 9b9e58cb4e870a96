"""`graspguide trial`: run a participant's planned trials (graspguide.study.study_protocol) through
a device, log every trial and frame, ask the NASA-TLX after each session, and resume after
a crash or Ctrl-C without repeating or losing a completed trial.

Output (``OUT`` = ``--out``; the analysis reads exactly this, docs/study.md describes it):

* ``OUT/study.json`` -- the normalised protocol, its ``config_hash`` and the drawn wrenches
  (written once; a later run with another protocol into the same OUT is refused);
* ``OUT/<PID>/trials.jsonl`` -- one JSON object per completed trial, appended and fsync'ed
  as one line when its TRIAL_RESULT arrived (fields in :data:`TRIAL_FIELDS` and
  docs/study.md);
* ``OUT/<PID>/tlx.jsonl`` -- one object per finished session (``scales`` null when the
  source is simulated and no --tlx file was given: never invented);
* ``OUT/<PID>/frames/trial-NNNN.csv`` -- every POSE and its TELEMETRY (:data:`FRAME_COLUMNS`),
  written to ``.tmp`` and renamed before the trial's line is appended;
* ``OUT/<PID>/plan.json`` (the participant's plan), ``OUT/<PID>/runs.jsonl`` (one line per
  run start and end: device, source, resumed trials, damaged lines found, exit).

Resume: completed ``trial_index`` values in trials.jsonl are skipped. A last line without
its newline or not valid JSON (a write cut by a power loss) is reported, moved to
``trials.jsonl.damaged-<time>`` and its trial run again; a damaged line before the last
one stops the run (it needs a person to look).

Sources (``--source``): ``synthetic[:...]`` and ``replay:FILE`` (open loop: the hand moves
whatever the motors do; after the source ends its last pose is held until the device
ends the trial), ``participant[:PARAMS]`` (the virtual participant,
``graspguide.study.participant.VirtualParticipant.from_spec(PARAMS, seed)``), and
``plugin:MODULE:CLASS[:ARG]``: a :class:`graspguide.study.sources.TrackerAdapter` (a live
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
the poses are bit for bit the lockstep ones (StudyRunner._closed_loop_pipelined); a
FeelLagError reruns the trial in lockstep. Trials, frames and resume are those of
lockstep (tools/tests/test_demo.py compares them frame for frame);
``StudyRunner(pipeline=1)`` forces lockstep, and a source without feel/act always runs in
lockstep.
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import importlib
import json
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, TextIO

from graspguide.study.records import (
    RecordWriteError,
    append_record,
    open_append,
    write_json_file,
)
from graspguide.study.study_protocol import (
    PlannedTrial,
    Protocol,
    Session,
    derive_seed,
    draw_familiarization_wrenches,
    draw_wrenches,
    plan,
    session_order,
)

TLX_SCALES = ("MD", "TD", "PD", "PE", "EF", "FR")
TLX_NAMES = {
    "MD": "Mental Demand",
    "TD": "Temporal Demand",
    "PD": "Physical Demand",
    "PE": "Performance",
    "EF": "Effort",
    "FR": "Frustration",
}
TLX_MIN, TLX_MAX = 1, 21
FRAME_COLUMNS = [
    "t_s",
    "host_time_us",
    "qw",
    "qx",
    "qy",
    "qz",
    "error_deg",
    "alpha",
    "pwm0",
    "pwm1",
    "pwm2",
    "pwm3",
    "solver_status",
    "flags",
]
TRIAL_FIELDS = (
    "participant",
    "simulated",
    "trial_index",
    "session",
    "session_trial",
    "k",
    "policy",
    "mode",
    "modality",
    "wrench_id",
    "wrench",
    "single_motor",
    "wrench_class",
    "success",
    "completion_s",
    "familiarization",
    "first_entry_s",
    "final_error_deg",
    "poses",
    "wall_s",
    "config_hash",
    "source",
    "recorded_at",
)
STUDY_FORMAT = "graspguide-study/1"
# A trial whose device clock passed timeout_s by this much without a TRIAL_RESULT is an
# error (the device should have ended it).
RESULT_MARGIN_S = 2.0


class RunnerError(Exception):
    """The run cannot go on; the message says why and what to do. ``usage`` errors exit
    2, the others 1."""

    def __init__(self, message: str, usage: bool = False):
        super().__init__(message)
        self.usage = usage


def _now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _dumps(obj: Any) -> str:
    return json.dumps(
        obj, sort_keys=True, ensure_ascii=True, allow_nan=False, separators=(", ", ": ")
    )


# Said after a disk fault (RecordWriteError): every completed trial is kept.
_RESUME_HINT = ", then run again (completed trials are kept)"


def append_line(path: str, obj: Any) -> None:
    """Append one JSON line, fsync'ed, whole or not at all (RecordWriteError)."""
    data = (_dumps(obj) + "\n").encode("utf-8")
    fd = open_append(path, _RESUME_HINT)
    try:
        append_record(fd, path, data, sync=True, hint=_RESUME_HINT)
    finally:
        os.close(fd)


def write_json_atomic(path: str, data: Any) -> None:
    write_json_file(path, data, _RESUME_HINT, indent=2, sort_keys=True)


class _FramesFile:
    """A trial's frames CSV (a temporary file until the trial is recorded): a write
    error becomes RecordWriteError naming it, and the partial file is removed on close
    (it holds no record, and on a full disk its space is wanted)."""

    def __init__(self, path: str):
        self.path = path
        self.failed = False
        try:
            self.f = open(path, "w", encoding="utf-8", newline="", buffering=1 << 20)
        except OSError as e:
            raise RecordWriteError(path, e, _RESUME_HINT) from e

    def _fault(self, e: OSError) -> RecordWriteError:
        self.failed = True
        return RecordWriteError(self.path, e, _RESUME_HINT)

    def write(self, text: str) -> None:
        try:
            self.f.write(text)
        except OSError as e:
            raise self._fault(e) from e

    def restart(self) -> None:
        try:
            self.f.seek(0)
            self.f.truncate()
        except OSError as e:
            raise self._fault(e) from e
        self.write(_FRAME_HEADER)

    def sync(self) -> None:
        try:
            self.f.flush()
            os.fsync(self.f.fileno())
        except OSError as e:
            raise self._fault(e) from e

    def close(self) -> None:
        try:
            self.f.close()
        except OSError:
            self.failed = True  # the buffer's rest did not fit either
        if self.failed:
            try:
                os.unlink(self.path)
            except OSError:
                pass


@dataclass
class JsonlContents:
    records: list[dict[str, Any]]
    damaged_tail: bytes | None = None  # a half-written last line, if any
    good_size: int = 0  # bytes of the complete, valid prefix


def read_jsonl(path: str) -> JsonlContents:
    """The records of an append-only JSON Lines file. A damaged *last* line (no newline,
    or not a JSON object) is returned in ``damaged_tail``; a damaged earlier line raises
    RunnerError."""
    if not os.path.exists(path):
        return JsonlContents([])
    with open(path, "rb") as f:
        data = f.read()
    records: list[dict[str, Any]] = []
    pos = 0
    line_no = 0
    while pos < len(data):
        line_no += 1
        nl = data.find(b"\n", pos)
        if nl == -1:  # no newline: a cut write
            return JsonlContents(records, data[pos:], pos)
        line = data[pos:nl]
        if line.strip():
            try:
                obj = json.loads(line.decode("utf-8"))
                if not isinstance(obj, dict):
                    raise ValueError("not an object")
            except (ValueError, UnicodeDecodeError):
                if nl == len(data) - 1:  # the last line
                    return JsonlContents(records, data[pos:], pos)
                raise RunnerError(
                    f"{path}: line {line_no} is damaged (not a JSON object) "
                    "and more lines follow it; this is not a cut write: "
                    "inspect the file, repair or move it, and run again"
                ) from None
            records.append(obj)
        pos = nl + 1
    return JsonlContents(records, None, pos)


def set_aside_damaged_tail(path: str, contents: JsonlContents) -> str:
    """Move a damaged last line to ``PATH.damaged-<time>`` and cut it from the file.
    Returns the new file's path."""
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%S%fZ")
    aside = f"{path}.damaged-{stamp}"
    with open(aside, "wb") as f:
        f.write(contents.damaged_tail or b"")
        f.flush()
        os.fsync(f.fileno())
    with open(path, "r+b") as f:
        f.truncate(contents.good_size)
        f.flush()
        os.fsync(f.fileno())
    return aside


# --------------------------------------------------------------------------------------
# NASA-TLX
# --------------------------------------------------------------------------------------
def check_tlx_value(scale: str, value: Any) -> int:
    """An integer 1..21, else ValueError saying what is wrong."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(
            f"{scale} ({TLX_NAMES[scale]}) must be an integer {TLX_MIN}..{TLX_MAX}, got {value!r}"
        )
    if not TLX_MIN <= value <= TLX_MAX:
        raise ValueError(
            f"{scale} ({TLX_NAMES[scale]}) must be in {TLX_MIN}..{TLX_MAX}, got {value}"
        )
    return int(value)


def load_tlx_file(
    path: str, participant: str, sessions: Sequence[Session]
) -> dict[int, dict[str, int]]:
    """``--tlx FILE``: JSON Lines, one object per session: ``{"session": 1, "MD": 5,
    "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": 3}``, optionally ``"participant"``,
    ``"modality"`` and ``"k"`` (checked against the plan when present). Blank lines are
    skipped. Returns session -> scales; RunnerError (usage) naming the line otherwise."""
    by_session = {s.session: s for s in sessions}
    out: dict[int, dict[str, int]] = {}
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise RunnerError(f"--tlx {path}: cannot read it: {e.strerror}", usage=True) from None
    except UnicodeDecodeError:
        raise RunnerError(f"--tlx {path}: not UTF-8 text", usage=True) from None
    allowed = set(TLX_SCALES) | {"session", "participant", "modality", "k"}
    for no, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        where = f"--tlx {path}:{no}"
        try:
            obj = json.loads(line)
        except ValueError as e:
            raise RunnerError(
                f"{where}: not JSON ({e}); one object per line such as "
                '{"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, '
                '"FR": 3}',
                usage=True,
            ) from None
        if not isinstance(obj, dict):
            raise RunnerError(f"{where}: must be a JSON object", usage=True)
        unknown = sorted(set(obj) - allowed)
        if unknown:
            raise RunnerError(
                f"{where}: unknown key {unknown[0]!r}; keys: session, "
                f"{', '.join(TLX_SCALES)} (and optionally participant, "
                "modality, k)",
                usage=True,
            )
        s = obj.get("session")
        if isinstance(s, bool) or not isinstance(s, int) or s not in by_session:
            raise RunnerError(
                f"{where}: session must be one of this participant's sessions "
                f"1..{len(sessions)}, got {s!r}",
                usage=True,
            )
        if s in out:
            raise RunnerError(f"{where}: session {s} is given twice", usage=True)
        if "participant" in obj and obj["participant"] != participant:
            raise RunnerError(
                f"{where}: participant {obj['participant']!r} is not "
                f"{participant!r}: is this the right file?",
                usage=True,
            )
        sess = by_session[s]
        if "modality" in obj and obj["modality"] != sess.modality:
            raise RunnerError(
                f"{where}: session {s} of {participant} is {sess.modality}, "
                f"the file says {obj['modality']!r}",
                usage=True,
            )
        if "k" in obj and obj["k"] != sess.k:
            raise RunnerError(
                f"{where}: session {s} of {participant} has k = {sess.k}, the "
                f"file says {obj['k']!r}",
                usage=True,
            )
        missing = [sc for sc in TLX_SCALES if sc not in obj]
        if missing:
            raise RunnerError(
                f"{where}: missing {', '.join(missing)} (the six scales "
                f"{', '.join(TLX_SCALES)}, integers {TLX_MIN}..{TLX_MAX})",
                usage=True,
            )
        scales = {}
        for sc in TLX_SCALES:
            try:
                scales[sc] = check_tlx_value(sc, obj[sc])
            except ValueError as e:
                raise RunnerError(f"{where}: {e}", usage=True) from None
        out[s] = scales
    return out


def ask_tlx(
    session: Session, ask: Callable[[str], str], out: TextIO, attempts: int = 5
) -> dict[str, int]:
    """The six scales asked one by one (``ask`` is input()); a bad answer is asked again
    (at most ``attempts`` times); EOF raises RunnerError."""
    print(
        f"NASA-TLX for session {session.session} ({session.modality}, k = {session.k}): "
        f"answer each scale with an integer {TLX_MIN} (very low) .. {TLX_MAX} (very high)",
        file=out,
        flush=True,
    )
    scales: dict[str, int] = {}
    for sc in TLX_SCALES:
        for _ in range(attempts):
            try:
                text = ask(f"  {sc} ({TLX_NAMES[sc]}) [{TLX_MIN}-{TLX_MAX}]: ")
            except EOFError:
                raise RunnerError(
                    "the NASA-TLX answers ended (stdin closed); give them with "
                    "--tlx FILE and run again (completed trials are kept)"
                ) from None
            text = text.strip()
            try:
                scales[sc] = check_tlx_value(sc, int(text))
                break
            except ValueError as e:
                msg = (
                    str(e)
                    if text.lstrip("+-").isdigit()
                    else f"{sc}: {text!r} is not an integer {TLX_MIN}..{TLX_MAX}"
                )
                print(f"  {msg}; try again", file=out, flush=True)
        else:
            raise RunnerError(f"no valid answer for {sc} after {attempts} attempts")
    return scales


# --------------------------------------------------------------------------------------
# Sources
# --------------------------------------------------------------------------------------
class RunnerSource:
    """What the runner needs of a source. ``closed_loop``: begin_trial/step in lockstep;
    else ``samples(trial)`` yields (t_s, quat, contacts). ``simulated``: no person (TLX
    recorded as absent unless --tlx). ``live``: real-time (a tracker)."""

    closed_loop = False
    simulated = True
    live = False
    rate_hz: float = 100.0

    def describe(self) -> dict[str, Any]:  # pragma: no cover - interface
        raise NotImplementedError


class ClosedLoopSource(RunnerSource):
    closed_loop = True

    def __init__(self, model: Any, spec: str):
        for attr in ("rate_hz", "begin_trial", "step"):
            if not hasattr(model, attr):
                raise RunnerError(
                    f"--source {spec}: {type(model).__name__} has no {attr}; a "
                    "closed-loop source needs rate_hz, SIMULATED, "
                    "begin_trial(...) and step(t_s, pwm)",
                    usage=True,
                )
        self.model = model
        self.spec = spec
        self.rate_hz = float(model.rate_hz)
        if not 0 < self.rate_hz <= 10000:
            raise RunnerError(
                f"--source {spec}: rate_hz must be in (0, 10000], got {model.rate_hz!r}", usage=True
            )
        self.simulated = bool(getattr(model, "SIMULATED", True))

    def describe(self) -> dict[str, Any]:
        d = {
            "source": self.spec,
            "kind": "closed_loop",
            "class": type(self.model).__name__,
            "source_rate_hz": self.rate_hz,
            "simulated": self.simulated,
        }
        extra = getattr(self.model, "describe", None)
        if callable(extra):
            try:
                d["model"] = extra()
            except Exception:  # pragma: no cover - a model's describe is informational
                pass
        return d


class OpenLoopSource(RunnerSource):
    def __init__(
        self,
        spec: str,
        make: Callable[[PlannedTrial], Any],
        rate_hz: float,
        simulated: bool,
        live: bool,
        info: dict[str, Any],
    ):
        self.spec = spec
        self.make = make
        self.rate_hz = float(rate_hz)
        self.simulated = simulated
        self.live = live
        self.info = info

    def samples(self, trial: PlannedTrial) -> Iterator[tuple[float, Any, Any]]:
        return iter(self.make(trial))

    def describe(self) -> dict[str, Any]:
        return {
            **self.info,
            "source": self.spec,
            "kind": "open_loop",
            "rate_hz": self.rate_hz,
            "simulated": self.simulated,
        }


def open_runner_source(spec: str, protocol: Protocol, participant: str) -> RunnerSource:
    """The source of ``--source SPEC`` for this protocol and participant."""
    from graspguide.study.sources import (
        SourceError,
        SyntheticSource,
        TrackerAdapter,
        open_source,
    )

    kind, _, rest = spec.partition(":")
    seed = derive_seed(protocol.seed, "source", participant) % 2**32
    if kind == "participant":
        try:
            mod = importlib.import_module(".participant", __package__)
            cls = mod.VirtualParticipant
        except (ImportError, AttributeError) as e:
            raise RunnerError(
                f"--source {spec}: the virtual participant "
                f"(graspguide.study.participant.VirtualParticipant) is not available: "
                f"{e}",
                usage=True,
            ) from None
        try:
            model = cls.from_spec(rest, seed)
        except (ValueError, TypeError) as e:
            raise RunnerError(f"--source {spec}: {e}", usage=True) from None
        return ClosedLoopSource(model, spec)
    if kind == "plugin":
        module_name, _, tail = rest.partition(":")
        class_name, _, arg = tail.partition(":")
        if not module_name or not class_name:
            raise RunnerError(
                "--source plugin needs a module and a class: plugin:MODULE:CLASS[:ARG]", usage=True
            )
        try:
            cls = getattr(importlib.import_module(module_name), class_name)
        except (ImportError, AttributeError) as e:
            raise RunnerError(
                f"--source {spec}: cannot load {module_name}.{class_name}: {e}", usage=True
            ) from None
        if isinstance(cls, type) and issubclass(cls, TrackerAdapter):
            adapter = cls(arg) if arg else cls()
            return OpenLoopSource(
                spec,
                lambda trial: adapter,
                adapter.rate_hz or 100.0,
                simulated=bool(getattr(adapter, "SIMULATED", False)),
                live=True,
                info=adapter.describe(),
            )
        try:
            model = (
                cls.from_spec(arg, seed)
                if hasattr(cls, "from_spec")
                else (cls(arg) if arg else cls())
            )
        except (ValueError, TypeError) as e:
            raise RunnerError(f"--source {spec}: {e}", usage=True) from None
        return ClosedLoopSource(model, spec)
    if kind in ("synthetic", "replay"):
        try:
            base = open_source(spec)
        except SourceError as e:
            raise RunnerError(f"--source: {e}", usage=True) from None
        if isinstance(base, SyntheticSource):
            rate = base.rate_hz if "rate=" in rest else protocol.pose_rate_hz

            def make(trial: PlannedTrial) -> SyntheticSource:
                s = SyntheticSource(
                    rate=rate,
                    duration=base.duration,
                    seed=derive_seed(base.seed, participant, trial.trial_index) % 2**32,
                    tremor_deg=base.tremor_deg,
                )
                return s.aim(
                    [list(c) for c in protocol.hands[trial.k]],
                    list(trial.wrench),
                    trial.policy,
                    protocol.constraints,
                    list(protocol.y_axis),
                )

            return OpenLoopSource(spec, make, rate, True, False, base.describe())
        return OpenLoopSource(
            spec,
            lambda trial: base,
            base.rate_hz or protocol.pose_rate_hz,
            True,
            False,
            base.describe(),
        )
    raise RunnerError(
        f"unknown --source {spec!r}: use participant[:PARAMS], "
        "synthetic[:rate=..,duration=..,seed=..], replay:FILE.csv or "
        "plugin:MODULE:CLASS[:ARG]",
        usage=True,
    )


# --------------------------------------------------------------------------------------
# Progress
# --------------------------------------------------------------------------------------
class Progress:
    """Trial n of N, the condition and the live error: one rewritten line on a terminal,
    plain lines (one per trial; every ``period_s`` of a real-time trial) otherwise."""

    def __init__(self, out: TextIO | None = None, tty: bool | None = None, period_s: float = 5.0):
        self.out = out or sys.stdout
        self.tty = self.out.isatty() if tty is None else tty
        self.period_s = period_s
        self._last = 0.0
        self._next_t = 0.0
        self._head = ""

    def line(self, text: str) -> None:
        if self.tty:
            self.out.write("\r\x1b[K")
        print(text, file=self.out, flush=True)

    def trial_start(self, trial: PlannedTrial, total: int, sessions: int) -> None:
        sess = "familiarization" if trial.familiarization else f"session {trial.session}/{sessions}"
        self._head = (
            f"[{trial.trial_index}/{total}] {sess} {trial.modality} k={trial.k} {trial.wrench_id}"
        )
        self._next_t = self.period_s
        if self.tty:
            self.out.write(f"\r\x1b[K{self._head} ...")
            self.out.flush()

    def frame(self, t_s: float, error_deg: float, pwm: Sequence[int], real_time: bool) -> None:
        if self.tty:
            now = time.monotonic()
            if now - self._last >= 0.1:
                self._last = now
                self.out.write(
                    f"\r\x1b[K{self._head} t={t_s:6.2f}s error={error_deg:6.2f}deg pwm={list(pwm)}"
                )
                self.out.flush()
        elif real_time and t_s >= self._next_t:
            self._next_t = t_s + self.period_s
            print(
                f"{self._head} t={t_s:6.2f}s error={error_deg:6.2f}deg", file=self.out, flush=True
            )

    def trial_end(self, record: dict[str, Any]) -> None:
        outcome = (
            f"success {record['completion_s']:.2f} s"
            if record["success"]
            else f"failure ({record['completion_s']:g} s)"
        )
        self.line(f"{self._head} {outcome}, final error {record['final_error_deg']:.2f} deg")


# --------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------
class StudyRunner:
    """One participant's run into ``out_dir``. :meth:`run` goes through the plan; the
    caller owns the device client (HELLO is sent here, STOP in :meth:`run`'s finally)."""

    def __init__(
        self,
        protocol: Protocol,
        participant: str,
        out_dir: str,
        source: RunnerSource,
        client: Any,
        virtual_clock: bool,
        tlx: dict[int, dict[str, int]] | None = None,
        ask: Callable[[str], str] | None = None,
        progress: Progress | None = None,
        protocol_file: str | None = None,
        err: TextIO | None = None,
        port: str = "",
        pipeline: int | None = None,
    ):
        self.protocol = protocol
        # POSEs sent ahead of their TELEMETRY (closed loop, virtual clock): None = what
        # the source allows (pipeline_window), 1 = lockstep. See _closed_loop_pipelined.
        self.pipeline = pipeline
        self.pipeline_fallbacks = 0
        self.participant = participant
        self.out_dir = out_dir
        self.source = source
        self.client = client
        self.virtual_clock = virtual_clock
        self.tlx_given = tlx
        self.ask = ask or input
        self.progress = progress or Progress()
        self.protocol_file = protocol_file
        self.err = err or sys.stderr
        self.port = port
        self.pdir = os.path.join(out_dir, participant)
        self.trials_path = os.path.join(self.pdir, "trials.jsonl")
        self.tlx_path = os.path.join(self.pdir, "tlx.jsonl")
        self.frames_dir = os.path.join(self.pdir, "frames")
        self.runs_path = os.path.join(self.pdir, "runs.jsonl")
        self.wrenches = draw_wrenches(protocol)
        self.fam_wrenches = draw_familiarization_wrenches(protocol)
        self.sessions = session_order(protocol, participant)
        self.plan = plan(protocol, participant, self.wrenches, self.fam_wrenches)
        self.config_hash = protocol.config_hash
        self._vt_base_us = 0
        self._scene_key: tuple[int, str, str] | None = None
        self._lock_fd: int | None = None
        self.ran = 0
        self.skipped = 0
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
        study_path = os.path.join(self.out_dir, "study.json")
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
            os.path.join(self.pdir, "plan.json"),
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
        return done, tlx_done

    def _lock(self) -> None:
        path = os.path.join(self.pdir, ".lock")
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
        contents = read_jsonl(path)
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
            if bool(rec.get("simulated")) != self.source.simulated:
                kind = "simulated" if rec.get("simulated") else "human"
                raise RunnerError(
                    f"{self.trials_path} holds {kind} trials; this source is "
                    f"{'simulated' if self.source.simulated else 'a person'}: "
                    "use another --out or --participant, never mix them",
                    usage=True,
                )
            done.add(idx)
        return done

    def _tlx_sessions(self) -> set:
        return {rec.get("session") for rec in self._read_checked(self.tlx_path)}

    def _log_run(self, event: str, **extra: Any) -> None:
        append_line(
            self.runs_path,
            {"event": event, "time": _now_iso(), "participant": self.participant, **extra},
        )

    # ---- one trial
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

    def _poses(self, trial: PlannedTrial) -> Iterator[tuple[float, Any, Any]]:
        """Open loop: the source's samples, then its last pose held at its rate."""
        period = 1.0 / self.source.rate_hz
        last = None
        for sample in self.source.samples(trial):  # type: ignore[attr-defined]
            last = sample
            yield sample
        if last is None:
            raise RunnerError(f"--source {self.source.describe()['source']} gave no pose")
        t, q, c = last
        while True:
            t += period
            yield (t, q, c)

    # ---- pipelining (closed loop, virtual clock)
    def _window(self, closed: bool) -> int:
        """POSEs in flight: 1 (lockstep) unless the source is a closed loop on the virtual
        clock whose :func:`pipeline_window` allows more (and --pipeline did not say 1)."""
        if not closed or not self.virtual_clock or self.pipeline == 1:
            return 1
        limit = pipeline_window(self.source.model, self.protocol.pose_rate_hz)  # type: ignore
        if self.pipeline is not None:
            limit = min(limit, int(self.pipeline))
        return max(1, limit)

    def _restart_trial(self, trial: PlannedTrial, model: Any, contacts: list[list[float]]) -> None:
        p = self.protocol
        try:
            self.client.stop()
        except Exception:
            pass
        self.client.drain(0.05)
        self.client.trial_results.clear()
        self.client.unmatched.clear()
        self._vt_base_us += int(round((p.timeout_s + 2 * RESULT_MARGIN_S) * 1e6))
        self._scene_key = None
        self._scene(trial)
        self.client.start_trial(trial.trial_index & 0xFFFF, list(trial.wrench))
        model.begin_trial(
            contacts=contacts,
            y_axis=list(p.y_axis),
            wrench=list(trial.wrench),
            policy=trial.policy,
            mode=trial.mode,
            start_quat=list(p.start_quat),
        )

    def _trial_result(self, trial: PlannedTrial) -> Any:
        """The TRIAL_RESULT of a trial the device has ended (already queued, or awaited)."""
        from graspguide.link.client import LinkTimeout

        client = self.client
        if client.trial_results:
            return client.trial_results.popleft()
        try:
            return client.wait_trial_result(client.timeout)
        except LinkTimeout:
            raise RunnerError(
                f"trial {trial.trial_index}: the device ended the trial but no TRIAL_RESULT arrived"
            ) from None

    def _no_result_error(self, trial: PlannedTrial, t_s: float) -> RunnerError:
        return RunnerError(
            f"trial {trial.trial_index}: no TRIAL_RESULT {t_s:.1f} s into a "
            f"{self.protocol.timeout_s:g} s trial; is the device's clock "
            "following the poses?"
        )

    def _closed_loop_pipelined(
        self, trial: PlannedTrial, model: Any, rate: float, window: int, fh: Any
    ) -> tuple[Any, int, float]:
        """The closed loop with up to ``window`` POSEs in flight, giving exactly what
        lockstep gives, for a source that separates feeling from acting (``feel``/``act``,
        the virtual participant: docs/participant.md, "feel and act").

        Lockstep: ``quat_i = model.step(t_i, pwm of TELEMETRY i-1)``, which is
        ``model.feel(t_{i-1}, pwm of TELEMETRY i-1)`` then ``model.act(t_i)``. Here, in
        batches: the poses i .. i+window-1 are ``model.act(t)`` with the TELEMETRY up to
        i-1 felt, the batch goes out in one write (:meth:`DeviceClient.pose_batch`), and
        each answer is felt (``model.feel``) as it comes, in order. The model guarantees
        that act(t) depends only on PWM felt a reaction time before t, so with window <=
        ``model.max_lead(rate)`` every pose equals, bit for bit, the lockstep one, with
        one model step per pose and no copy; the device handles POSEs one after the
        other (the answer to one does not depend on the later ones), so it answers as in
        lockstep. POSEs sent after the one that ends the trial are refused (ERROR
        not_allowed_in_state) and not recorded. An act() too far ahead raises the
        model's FeelLagError, turned into _Diverged (the caller runs the trial again in
        lockstep): a broken source cannot give a wrong record."""
        from graspguide.link.messages import TELEMETRY_FLAG_TRIAL_RUNNING, Error, ErrorCode

        p = self.protocol
        k = trial.k
        base = self._vt_base_us
        client = self.client
        write = fh.write
        frame = self.progress.frame
        act = model.act
        feel = model.feel
        lag_error = _feel_lag_error()
        i = 0
        poses = 0
        limit = p.timeout_s + RESULT_MARGIN_S
        while True:
            batch = []
            try:
                for j in range(i, i + window):
                    t = j / rate
                    batch.append((t, tuple(map(float, act(t)))))
            except lag_error as e:
                raise _Diverged(f"pose {i + len(batch)} could not be acted ahead: {e}") from None
            stamped = [(t, _virtual_us(base, t), q) for t, q in batch]
            answers = client.pose_batch([(t_us, q) for _, t_us, q in stamped])
            for j, ((t_s, t_us, quat), tel) in enumerate(zip(stamped, answers)):
                if isinstance(tel, Error):
                    raise RunnerError(
                        f"trial {trial.trial_index}: the device refused pose "
                        f"{i + j} ({ErrorCode(tel.code).name.lower()}) while "
                        "the trial was running"
                    )
                poses += 1
                pwm = tel.pwm[:k]
                write(_frame_row(t_s, t_us, quat, tel))
                frame(t_s, float(tel.error_deg), pwm, False)
                if not int(tel.flags) & TELEMETRY_FLAG_TRIAL_RUNNING:
                    # The trial ended with this pose; the rest of the batch was refused.
                    for rest in answers[j + 1 :]:
                        if not isinstance(rest, Error):
                            raise RunnerError(
                                f"trial {trial.trial_index}: the device "
                                "answered a POSE after the trial ended"
                            )
                    return self._trial_result(trial), poses, t_s
                if t_s > limit:
                    raise self._no_result_error(trial, t_s)
                try:
                    feel(t_s, list(pwm))
                except ValueError as e:
                    raise RunnerError(
                        f"trial {trial.trial_index}: pose {i + j}: the model "
                        f"refused the TELEMETRY's PWM: {e}"
                    ) from None
            i += len(batch)

    def run_trial(self, trial: PlannedTrial) -> dict[str, Any]:
        from graspguide.link.client import host_time_us
        from graspguide.link.messages import TELEMETRY_FLAG_TRIAL_RUNNING

        p = self.protocol
        self._scene(trial)
        self.client.trial_results.clear()
        self.client.start_trial(trial.trial_index & 0xFFFF, list(trial.wrench))
        contacts = [list(c) for c in p.hands[trial.k]]
        closed = self.source.closed_loop
        if closed:
            model = self.source.model  # type: ignore[attr-defined]
            model.begin_trial(
                contacts=contacts,
                y_axis=list(p.y_axis),
                wrench=list(trial.wrench),
                policy=trial.policy,
                mode=trial.mode,
                start_quat=list(p.start_quat),
            )
            rate = p.pose_rate_hz  # the study's pose rate (the tracker's)
            it = None
        else:
            it = self._poses(trial)
        frames_tmp = os.path.join(self.frames_dir, f"trial-{trial.trial_index:04d}.csv.tmp")
        frames_path = frames_tmp[:-4]
        f = _FramesFile(frames_tmp)
        f.write(_FRAME_HEADER)
        result = None
        poses = 0
        pwm: list[int] = [0] * trial.k
        t_s = 0.0
        wall0 = time.monotonic()
        window = self._window(closed)
        try:
            i = 0
            while window > 1:
                try:
                    result, poses, t_s = self._closed_loop_pipelined(trial, model, rate, window, f)
                    break
                except _Diverged as e:
                    # Never expected (see _closed_loop_pipelined); the poses the device
                    # got are not the lockstep ones: run the whole trial again in lockstep.
                    self.pipeline_fallbacks += 1
                    print(
                        f"graspguide trial: warning: trial {trial.trial_index}: {e}; "
                        "running it again in lockstep",
                        file=self.err,
                        flush=True,
                    )
                    f.restart()
                    self._restart_trial(trial, model, contacts)
                    window = 1
            while window <= 1:
                if closed:
                    t_s = i / rate
                    quat = model.step(t_s, list(pwm))
                    pose_contacts = None
                else:
                    t_s, quat, pose_contacts = next(it)  # type: ignore[arg-type]
                quat = [float(x) for x in quat]
                if self.virtual_clock:
                    t_us = _virtual_us(self._vt_base_us, t_s)
                else:
                    wait = wall0 + t_s - time.monotonic()
                    if wait > 0:
                        time.sleep(wait)
                    t_us = host_time_us()
                tel = self.client.pose(t_us, quat, pose_contacts)
                poses += 1
                i += 1
                pwm = [int(x) for x in tel.pwm[: trial.k]]
                f.write(_frame_row(t_s, t_us, quat, tel))
                self.progress.frame(t_s, float(tel.error_deg), pwm, not self.virtual_clock)
                if self.client.trial_results or not int(tel.flags) & TELEMETRY_FLAG_TRIAL_RUNNING:
                    result = self._trial_result(trial)
                    break
                if t_s > p.timeout_s + RESULT_MARGIN_S and self.virtual_clock:
                    raise self._no_result_error(trial, t_s)
                if (
                    not self.virtual_clock
                    and time.monotonic() - wall0 > p.timeout_s + 10 * RESULT_MARGIN_S
                ):
                    raise RunnerError(
                        f"trial {trial.trial_index}: no TRIAL_RESULT after "
                        f"{time.monotonic() - wall0:.1f} s"
                    )
            f.sync()
        finally:
            f.close()
        if int(result.trial_id) != trial.trial_index & 0xFFFF:
            raise RunnerError(
                f"trial {trial.trial_index}: the device answered with the "
                f"TRIAL_RESULT of trial id {result.trial_id}; run again (this "
                "trial was not recorded)"
            )
        try:
            os.replace(frames_tmp, frames_path)
        except OSError as e:
            raise RecordWriteError(frames_path, e, _RESUME_HINT) from e
        self._vt_base_us += int(round((t_s + 1.0) * 1e6))
        success = bool(result.success)
        completion = round(float(result.completion_s), 6) if success else float(p.timeout_s)
        record = {
            "participant": self.participant,
            "simulated": self.source.simulated,
            **{k: v for k, v in trial.to_dict().items() if k != "participant"},
            "success": success,
            "completion_s": completion,
            "first_entry_s": round(float(result.first_entry_s), 6),
            "final_error_deg": round(float(result.final_error_deg), 6),
            "poses": poses,
            "wall_s": round(time.monotonic() - wall0, 4),
            "config_hash": self.config_hash,
            "source": self.source.describe()["source"],
            "recorded_at": _now_iso(),
        }
        return record

    # ---- TLX
    def _tlx(self, session: Session) -> None:
        if self.tlx_given is not None and session.session in self.tlx_given:
            scales: dict[str, int] | None = self.tlx_given[session.session]
            origin = "file"
        elif self.tlx_given is not None and not self.source.simulated:
            raise RunnerError(
                f"the --tlx file has no line for session {session.session} "
                f"({session.modality}, k = {session.k}); add it and run again "
                "(completed trials are kept)",
                usage=True,
            )
        elif self.source.simulated:
            scales, origin = None, "absent: simulated source, no --tlx"
        else:
            scales = ask_tlx(session, self.ask, self.progress.out)
            origin = "interactive"
        append_line(
            self.tlx_path,
            {
                "participant": self.participant,
                "simulated": self.source.simulated,
                "session": session.session,
                "k": session.k,
                "modality": session.modality,
                "policy": session.policy,
                "mode": session.mode,
                "scales": scales,
                "origin": origin,
                "config_hash": self.config_hash,
                "recorded_at": _now_iso(),
            },
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
        )
        if done:
            self.progress.line(
                f"resuming {self.participant}: {len(done)} of {len(self.plan)} "
                "trials already completed are skipped"
            )
        total = len(self.plan)
        n_sessions = len(self.sessions)
        outcome = "error"
        cause: BaseException | None = None
        try:
            by_session: dict[int, list[PlannedTrial]] = {}
            for t in self.plan:
                by_session.setdefault(t.session, []).append(t)
            for sess_no in sorted(by_session):
                for trial in by_session[sess_no]:
                    if trial.trial_index in done:
                        continue
                    self.progress.trial_start(trial, total, n_sessions)
                    record = self.run_trial(trial)
                    append_line(self.trials_path, record)
                    done.add(trial.trial_index)
                    self.ran += 1
                    self.progress.trial_end(record)
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
                self.client.stop()
            except Exception as e:
                if outcome == "complete":
                    raise  # the run's only error: report it
                # keep the error that ended the run; this one is secondary
                print(f"graspguide trial: STOP failed: {e}", file=self.err, flush=True)
            finally:
                try:
                    self._log_run(
                        "end", outcome=outcome, ran=self.ran, completed=len(done), planned=total
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


#: One FRAME_COLUMNS row as csv.writer writes it for these fields (floats by repr, none
#: needs quoting); the pipelined loop formats its rows with it.
_FRAME_ROW = "%r,%d,%r,%r,%r,%r,%r,%r,%d,%d,%d,%d,%d,%d\n"
_FRAME_HEADER = ",".join(FRAME_COLUMNS) + "\n"


def _frame_row(t_s: float, t_us: int, quat: Sequence[float], tel: Any) -> str:
    """One FRAME_COLUMNS row: the POSE sent and its TELEMETRY."""
    return _FRAME_ROW % (
        (round(t_s, 6), t_us)
        + tuple(quat)
        + (float(tel.error_deg), float(tel.alpha))
        + tuple(tel.pwm)
        + (int(tel.solver_status), int(tel.flags))
    )


def _virtual_us(base_us: int, t_s: float) -> int:
    """The POSE timestamp of trial time t_s on the virtual clock (32-bit, wrapping)."""
    return (base_us + int(round(t_s * 1e6))) & 0xFFFFFFFF


class _Diverged(Exception):
    """A pose sent ahead is not the lockstep one (the trial is run again in lockstep)."""


#: Most POSEs ever in flight.
MAX_PIPELINE = 32


def _feel_lag_error() -> Any:
    try:
        from graspguide.study.participant import FeelLagError
    except ImportError:  # pragma: no cover
        return RuntimeError
    return FeelLagError


def pipeline_window(model: Any, pose_rate_hz: float) -> int:
    """How many POSEs a closed-loop source may have in flight (1 = lockstep).

    A source that separates feeling from acting (callable ``feel``, ``act`` and
    ``max_lead``, like the virtual participant: docs/participant.md, "feel and act") is
    pipelined ``model.max_lead(pose_rate_hz)`` poses deep (at most MAX_PIPELINE); for
    the virtual participant floor(reaction_time_s * rate) - 1, 20 at 0.21 s and 100 Hz
    (its pose at t depends only on PWM felt a reaction time earlier). Any other source
    runs in lockstep."""
    if not all(callable(getattr(model, name, None)) for name in ("feel", "act", "max_lead")):
        return 1
    try:
        n = int(model.max_lead(float(pose_rate_hz)))
    except Exception:
        return 1
    return max(1, min(MAX_PIPELINE, n))


def summary_lines(out_dir: str, participant: str) -> list[str]:
    """Per-modality successes and mean completion time of a participant (main trials)."""
    recs = read_jsonl(os.path.join(out_dir, participant, "trials.jsonl")).records
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


__all__ = [
    "StudyRunner",
    "RunnerError",
    "RunnerSource",
    "ClosedLoopSource",
    "OpenLoopSource",
    "open_runner_source",
    "load_tlx_file",
    "ask_tlx",
    "check_tlx_value",
    "read_jsonl",
    "Progress",
    "TLX_SCALES",
    "FRAME_COLUMNS",
    "TRIAL_FIELDS",
    "summary_lines",
]
