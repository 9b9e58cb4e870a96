"""What `graspguide plot` reads: a study folder written by `graspguide trial` (the study
file, each participant's trial records and frames; a participant folder alone is read
with its parent's study file) or a session folder written by `graspguide stream --log`
(its config, telemetry, poses and results). The names are in
:mod:`graspguide.records.files`, the formats in docs/study.md,
:mod:`graspguide.records.trial` and :mod:`graspguide.records.storage`.

Every problem is a :class:`PlotInputError` whose message names the file (and line) and
says what to do; ``usage`` ones (no such folder, trial or participant) exit 2, damaged
data 1."""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from graspguide.core.vocabulary import FINGERS, modality
from graspguide.records import files
from graspguide.records.files import STUDY_FILE, TRIALS_FILE, ParticipantFiles
from graspguide.records.storage import JsonlDamaged, LeftOutLine, complete_records
from graspguide.records.trial import RecordError, check_trial_record


class PlotInputError(Exception):
    """The run folder cannot be plotted; the message names the file and what to do.
    ``usage``: the command line asked for something that is not there (exit 2);
    otherwise the data are damaged (exit 1)."""

    def __init__(self, message: str, usage: bool = False):
        super().__init__(message)
        self.usage = usage


@dataclass(frozen=True)
class Criteria:
    """The success rule of the trials: the error stays below ``threshold_deg`` for
    ``hold_s``, within ``timeout_s`` (the protocol's [trial] or the session's scene)."""

    threshold_deg: float
    hold_s: float
    timeout_s: float


@dataclass
class TrialInfo:
    """One trial's record: its condition and outcome, and where its frames are."""

    participant: str  # "" for a session folder
    trial: int  # trial_index of a study, trial_id of a session
    k: int
    policy: str
    mode: str
    wrench: list[float]
    # None: no TRIAL_RESULT in a session folder (the source ended first, or Ctrl-C).
    success: bool | None
    completion_s: float | None
    frames_path: str
    source: str = ""
    simulated: bool = False
    session: int | None = None
    wrench_id: str = ""
    familiarization: bool = False

    @property
    def modality(self) -> str:
        return modality(self.policy, self.mode)


@dataclass
class TrialFrames:
    """A trial's time series: seconds since the trial start, the guidance error and the
    PWM duty (0..255) of each motor, in FINGERS order."""

    t_s: list[float]
    error_deg: list[float]
    pwm: list[list[int]] = field(default_factory=lambda: [[] for _ in FINGERS])


@dataclass
class Participant:
    pid: str
    trials: list[TrialInfo]


@dataclass
class RunFolder:
    kind: str  # "study" or "session"
    path: str
    criteria: Criteria
    participants: list[Participant]
    # Damaged last lines of the records, left out (a run killed mid-write): the command
    # warns about each.
    left_out: list[LeftOutLine] = field(default_factory=list)


# --------------------------------------------------------------------------------------
# Small readers
# --------------------------------------------------------------------------------------
_REDO_HINT = (
    "copy the run folder again from where it was recorded, or plot the other trials (--trial N)"
)


def _read_json(path: str) -> Any:
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except json.JSONDecodeError as e:
        raise PlotInputError(f"{path}:{e.lineno}: malformed JSON ({e.msg}); {_REDO_HINT}") from None
    except OSError as e:
        raise PlotInputError(f"cannot read {path}: {e.strerror or e}") from None


def _records(path: str, left_out: list[LeftOutLine]) -> list[tuple[str, dict[str, Any]]]:
    """(``FILE:LINE``, object) per complete record (records.complete_records): a damaged
    last line, what a run killed mid-write leaves, is added to ``left_out``; a damaged
    earlier line is an error."""
    try:
        records, tail = complete_records(path)
    except JsonlDamaged as e:
        raise PlotInputError(f"{e}; {_REDO_HINT}") from None
    except OSError as e:
        raise PlotInputError(f"cannot read {path}: {e.strerror or e}") from None
    if tail is not None:
        left_out.append(tail)
    return records


def _field(rec: dict[str, Any], key: str, where: str, ok, what: str) -> Any:
    if key not in rec:
        raise PlotInputError(f"{where}: missing field '{key}' ({what}); {_REDO_HINT}")
    value = rec[key]
    if not ok(value):
        raise PlotInputError(
            f"{where}: field '{key}' must be {what}, got {json.dumps(value)}; {_REDO_HINT}"
        )
    return value


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _is_wrench(v: Any) -> bool:
    return isinstance(v, list) and len(v) in (3, 6) and all(_is_number(x) for x in v)


def _criteria(section: Any, where: str) -> Criteria:
    if not isinstance(section, dict):
        raise PlotInputError(f"{where}: expected an object with threshold_deg, hold_s, timeout_s")
    values = [
        float(_field(section, key, where, lambda v: _is_number(v) and v >= 0, "a number >= 0"))
        for key in ("threshold_deg", "hold_s", "timeout_s")
    ]
    return Criteria(*values)


# --------------------------------------------------------------------------------------
# The CSV time series
# --------------------------------------------------------------------------------------
def read_csv_columns(path: str, columns: Sequence[str]) -> tuple[dict[str, list[str]], int]:
    """The named columns of a CSV file (as text) and its row count. A file cut mid-line
    (no newline at its end), a row with another field count than the header or a missing
    column is a PlotInputError naming the file and line."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        raise PlotInputError(f"{path}: no such file; {_REDO_HINT}") from None
    except OSError as e:
        raise PlotInputError(f"cannot read {path}: {e.strerror or e}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise PlotInputError(f"{path}: not UTF-8 text ({e}); {_REDO_HINT}") from None
    if not text:
        raise PlotInputError(f"{path}: empty (not even the header line); {_REDO_HINT}")
    lines = text.count("\n")
    if not text.endswith("\n"):
        raise PlotInputError(
            f"{path}:{lines + 1}: the file is cut mid-line (its last line has no newline: "
            f"a copy or write cut short); {_REDO_HINT}"
        )
    rows = list(csv.reader(io.StringIO(text)))
    header = rows[0]
    missing = [c for c in columns if c not in header]
    if missing:
        raise PlotInputError(
            f"{path}:1: missing column(s) {', '.join(missing)} (header: {','.join(header)}); "
            "is it a file of this project's format (docs/study.md)?"
        )
    index = [header.index(c) for c in columns]
    out: dict[str, list[str]] = {c: [] for c in columns}
    for line_no, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise PlotInputError(
                f"{path}:{line_no}: {len(row)} fields, the header has {len(header)} "
                f"(a damaged line); {_REDO_HINT}"
            )
        for c, i in zip(columns, index):
            out[c].append(row[i])
    return out, len(rows) - 1


def _numbers(path: str, name: str, texts: list[str], conv=float) -> list:
    values = []
    for row, text in enumerate(texts, start=2):
        try:
            v = conv(text)
        except ValueError:
            raise PlotInputError(
                f"{path}:{row}: column {name}: not a number: {text!r}; {_REDO_HINT}"
            ) from None
        if isinstance(v, float) and not math.isfinite(v):
            raise PlotInputError(f"{path}:{row}: column {name}: {text}; {_REDO_HINT}")
        values.append(v)
    return values


_PWM = [f"pwm{i}" for i in range(len(FINGERS))]


def _guidance(path: str, cols: dict[str, list[str]], t_s: list[float]) -> TrialFrames:
    frames = TrialFrames(t_s, _numbers(path, "error_deg", cols["error_deg"]))
    frames.pwm = [_numbers(path, c, cols[c], int) for c in _PWM]
    return frames


def _study_frames(path: str) -> TrialFrames:
    cols, n = read_csv_columns(path, ["t_s", "error_deg", *_PWM])
    if n == 0:
        raise PlotInputError(f"{path}: no frames (only the header); {_REDO_HINT}")
    return _guidance(path, cols, _numbers(path, "t_s", cols["t_s"]))


def _session_frames(folder: str) -> TrialFrames:
    """A session's TELEMETRY against the trial time of the POSE each one answers
    (poses.csv maps the echoed host_time_us to t_s; without it, host time since the
    first TELEMETRY)."""
    tel_path = os.path.join(folder, files.SESSION_TELEMETRY_FILE)
    cols, n = read_csv_columns(tel_path, ["host_time_us", "error_deg", *_PWM])
    if n == 0:
        raise PlotInputError(f"{tel_path}: no TELEMETRY recorded (only the header)")
    host_us = _numbers(tel_path, "host_time_us", cols["host_time_us"], int)
    pose_time: dict[int, float] = {}
    poses_path = os.path.join(folder, files.SESSION_POSES_FILE)
    if os.path.exists(poses_path):
        pcols, _ = read_csv_columns(poses_path, ["host_time_us", "t_s"])
        for us, t in zip(
            _numbers(poses_path, "host_time_us", pcols["host_time_us"], int),
            _numbers(poses_path, "t_s", pcols["t_s"]),
        ):
            pose_time[us] = t
    t0 = host_us[0]
    t_s = [pose_time.get(us, (us - t0) / 1e6) for us in host_us]
    return _guidance(tel_path, cols, t_s)


def load_frames(trial: TrialInfo) -> TrialFrames:
    """The time series of ``trial`` (from its frames file or its session folder)."""
    if os.path.isdir(trial.frames_path):
        return _session_frames(trial.frames_path)
    return _study_frames(trial.frames_path)


# --------------------------------------------------------------------------------------
# The folders
# --------------------------------------------------------------------------------------
def _study_trial(pdir: str, where: str, rec: dict[str, Any]) -> TrialInfo:
    try:
        row = check_trial_record(where, rec)
    except RecordError as e:
        raise PlotInputError(f"{e.where}: {e.problem}; {_REDO_HINT}") from None
    # A figure draws the target wrench: the plots need it, the analysis does not.
    wrench = _field(rec, "wrench", where, _is_wrench, "3 or 6 numbers")
    return TrialInfo(
        participant=row["participant"],
        trial=row["trial_index"],
        k=row["k"],
        policy=row["policy"],
        mode=row["mode"],
        wrench=[float(x) for x in wrench],
        success=row["success"],
        completion_s=row["completion_s"],
        frames_path=ParticipantFiles(pdir).frames(row["trial_index"]),
        source=str(rec.get("source", "")),
        simulated=row["simulated"],
        session=row["session"],
        wrench_id=str(rec.get("wrench_id", "")),
        familiarization=row["familiarization"],
    )


def _participant(pdir: str, left_out: list[LeftOutLine]) -> Participant:
    path = ParticipantFiles(pdir).trials
    trials = [_study_trial(pdir, where, rec) for where, rec in _records(path, left_out)]
    trials.sort(key=lambda t: t.trial)
    return Participant(os.path.basename(os.path.normpath(pdir)), trials)


def _study_criteria(study_json: str) -> Criteria:
    study = _read_json(study_json)
    protocol = study.get("protocol") if isinstance(study, dict) else None
    trial = protocol.get("trial") if isinstance(protocol, dict) else None
    return _criteria(trial, f"{study_json}: protocol.trial")


def _session(folder: str, left_out: list[LeftOutLine]) -> RunFolder:
    config_path = os.path.join(folder, files.SESSION_CONFIG_FILE)
    if not os.path.exists(config_path):
        raise PlotInputError(
            f"{config_path}: missing; the session's scene (threshold, hold, k, policy, mode) "
            "and wrench come from it (`graspguide stream --log DIR` writes it)"
        )
    config = _read_json(config_path)
    if not isinstance(config, dict):
        raise PlotInputError(f"{config_path}: expected a JSON object")
    scene = config.get("scene")
    criteria = _criteria(scene, f"{config_path}: scene")
    assert isinstance(scene, dict)
    where = f"{config_path}: scene"
    k = _field(scene, "k", where, lambda v: v in (3, 4), "3 or 4")
    policy = _field(scene, "policy", where, lambda v: v in ("F", "Fperp"), "'F' or 'Fperp'")
    mode = _field(scene, "mode", where, lambda v: v in ("C", "V"), "'C' or 'V'")
    wrench = _field(config, "wrench", config_path, _is_wrench, "3 or 6 numbers")
    trial_id = config.get("trial_id", 1)
    success = completion = None
    for rec_where, rec in _records(os.path.join(folder, files.SESSION_RESULTS_FILE), left_out):
        if "success" in rec:  # a TRIAL_RESULT (the end record has "event")
            success = _field(rec, "success", rec_where, lambda v: isinstance(v, bool), "bool")
            completion = float(
                _field(rec, "completion_s", rec_where, _is_number, "a number of seconds")
            )
    source = config.get("source")
    info = TrialInfo(
        participant="",
        trial=trial_id if _is_int(trial_id) else 1,
        k=k,
        policy=policy,
        mode=mode,
        wrench=[float(x) for x in wrench],
        success=success,
        completion_s=completion,
        frames_path=folder,
        source=str(source.get("source", "")) if isinstance(source, dict) else "",
        # `graspguide stream --log` records whether the poses came from the virtual
        # participant (config.json "simulated").
        simulated=config.get("simulated") is True,
    )
    return RunFolder("session", folder, criteria, [Participant("", [info])], left_out)


def open_run(path: str, participant: str | None = None) -> RunFolder:
    """The run folder at ``path``: a study folder (every participant, or ``participant``),
    a participant folder of a study, or a session folder. A damaged last line of the
    records is left out and listed in ``left_out``."""
    left_out: list[LeftOutLine] = []
    if not os.path.exists(path):
        raise PlotInputError(
            f"{path}: no such folder; give the --out folder of `graspguide trial` or the "
            "--log folder of `graspguide stream`",
            usage=True,
        )
    if not os.path.isdir(path):
        raise PlotInputError(
            f"{path}: not a folder; give the folder that holds {STUDY_FILE} "
            f"(graspguide trial --out) or {files.SESSION_TELEMETRY_FILE} (graspguide stream "
            "--log)",
            usage=True,
        )
    if all(os.path.exists(os.path.join(path, f)) for f in files.SESSION_MARKERS):
        if participant:
            raise PlotInputError(
                f"{path} is a session folder (graspguide stream --log): it has no "
                "participants; leave out --participant",
                usage=True,
            )
        return _session(path, left_out)
    if os.path.exists(os.path.join(path, TRIALS_FILE)):  # a participant folder
        study_json = os.path.join(os.path.dirname(os.path.abspath(path)), STUDY_FILE)
        if not os.path.exists(study_json):
            raise PlotInputError(
                f"{study_json}: missing; the threshold and hold of the trials come from the "
                f"study's protocol: plot the study folder (the one with {STUDY_FILE})",
                usage=True,
            )
        p = _participant(path, left_out)
        if participant and participant != p.pid:
            raise PlotInputError(
                f"{path} is participant {p.pid}'s folder, not {participant}'s", usage=True
            )
        return RunFolder("study", path, _study_criteria(study_json), [p], left_out)
    study_json = os.path.join(path, STUDY_FILE)
    if not os.path.exists(study_json):
        raise PlotInputError(
            f"{path}: neither a study folder (no {STUDY_FILE}; `graspguide trial --out` writes "
            "one) nor a session folder (no "
            + " and ".join(files.SESSION_MARKERS)
            + "; `graspguide "
            "stream --log` writes them)",
            usage=True,
        )
    criteria = _study_criteria(study_json)
    pids = sorted(d for d in os.listdir(path) if os.path.isfile(os.path.join(path, d, TRIALS_FILE)))
    if participant:
        if participant not in pids:
            have = ", ".join(pids) or "none"
            raise PlotInputError(
                f"{path}: no participant {participant} (no {participant}/{TRIALS_FILE}; "
                f"participants: {have})",
                usage=True,
            )
        pids = [participant]
    if not pids:
        raise PlotInputError(
            f"{path}: no participant has completed a trial yet (no PID/{TRIALS_FILE})",
            usage=True,
        )
    parts = [_participant(os.path.join(path, pid), left_out) for pid in pids]
    return RunFolder("study", path, criteria, parts, left_out)


def select_trial(run: RunFolder, trial: int) -> list[TrialInfo]:
    """Trial ``trial`` of each participant that has it, or a usage PlotInputError that
    lists the trials there are."""
    found = [t for p in run.participants for t in p.trials if t.trial == trial]
    if not found:
        have = sorted({t.trial for p in run.participants for t in p.trials})
        listed = _ranges(have) or "none"
        raise PlotInputError(
            f"{run.path}: no trial {trial} (the trials recorded there: {listed})", usage=True
        )
    return found


def _ranges(values: list[int]) -> str:
    """1..5, 7, 9..10"""
    parts: list[str] = []
    i = 0
    while i < len(values):
        j = i
        while j + 1 < len(values) and values[j + 1] == values[j] + 1:
            j += 1
        parts.append(str(values[i]) if i == j else f"{values[i]}..{values[j]}")
        i = j + 1
    return ", ".join(parts)


__all__ = [
    "Criteria",
    "Participant",
    "PlotInputError",
    "RunFolder",
    "TrialFrames",
    "TrialInfo",
    "load_frames",
    "open_run",
    "read_csv_columns",
    "select_trial",
]
