"""Download a host-less device's results log into the runner's folder format, so
`graspguide analyze OUT` reads a host-less study as it reads a host-driven one.

``OUT/<participant>/`` (names in :mod:`graspguide.records.files`):

* the trial records -- one :class:`graspguide.records.trial.TrialRecord` per device
  record (``poses`` = the IMU samples the trial used, ``wall_s`` null: the device has no
  wall clock, ``source`` "hostless", ``recorded_at`` the download time, and the host-less
  fields ``hostless`` true and ``imu_faults``); written whole (temporary file, fsync,
  rename);
* the TLX records -- one line per session with records, ``scales`` null (the device asks
  no questionnaire); lines already there (answers typed in later) are kept;
* the device log file -- the LOG_INFO, the device's HELLO_REPLY and the download time.

Downloading again into the same folder gives the same records (a record already there
keeps its ``recorded_at``); records the folder holds and the device no longer does (its
log was erased after an earlier download) are kept. A folder holding trials of another
participant, protocol (config_hash), kind (simulated or not) or a host-driven run is
refused, as is a record that contradicts one already downloaded: nothing is overwritten.

A damaged record (torn: a write cut by a power loss, or a bit flipped in storage) is
skipped by the device, whose next run runs that trial again after the trials already
recorded, so the log then holds it out of plan order. The download takes such a log and
says which trial's record was damaged: run again (its record comes after a later trial's)
or not yet (no record, below the highest trial recorded). A trial downloaded before its
record was damaged keeps the result downloaded first; the device's later run of it is not
used, and the warning says so.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
import os
import re
import sys
from collections.abc import Sequence
from typing import Any, TextIO

from graspguide.link.client import to_f32
from graspguide.link.messages import CAPABILITY_HOSTLESS, LogInfo, LogRecord, WrenchClass
from graspguide.records.files import ParticipantFiles, study_file
from graspguide.records.storage import (
    JsonlDamaged,
    RecordWriteError,
    read_jsonl,
    write_json_file,
    write_json_lines,
)
from graspguide.records.trial import HOSTLESS_FIELDS, TlxRecord, TrialRecord

SOURCE = "hostless"
DEVICE_LOG_FORMAT = "graspguide-device-log/1"
# Keys that may differ between two downloads of the same record.
DOWNLOAD_KEYS = ("recorded_at",)
# A participant id becomes a folder name: only these characters (the runner's ids).
PARTICIPANT_FOLDER_RE = re.compile(r"^[A-Za-z0-9_-]+$")
POLICY_TEXT = {"F": "F", "FPERP": "Fperp"}
MODE_TEXT = {"C": "C", "V": "V"}
CLASS_TEXT = {WrenchClass.SINGLE: "single", WrenchClass.MULTI: "multi", WrenchClass.NONE: ""}
CONTACT_COUNTS = (3, 4)
# float32 has 6 to 9 significant decimal digits: the shortest of these that reads back
# as the same float32 is what the JSON holds (0.2582, not 0.25819998979568481).
F32_DIGITS = range(6, 10)
_HINT = "; then download again (the device keeps its records)"


class DeviceLogError(Exception):
    """The log cannot be downloaded (no plan on the device, a record out of range) or not
    into this folder (``usage``: it holds another study). The message says what to do."""

    def __init__(self, message: str, usage: bool = False):
        super().__init__(message)
        self.usage = usage


@dataclasses.dataclass(frozen=True)
class DownloadSummary:
    participant: str
    config_hash: str  # the 16 hex digits of the plan's prefix
    simulated: bool
    folder: str  # OUT/<participant>
    plan_trials: int
    records: int  # records the device holds (downloaded now)
    new: int  # of them, not in the folder before
    total: int  # trial records in the folder now
    capacity: int
    torn_records: int  # records the device found torn by a power loss and skipped
    running: bool  # a host-less run went on during the download


def _now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def f32_value(x: float) -> float:
    """A float32 as the shortest decimal that reads back as the same float32."""
    x = float(x)
    if not math.isfinite(x):
        return x
    for digits in F32_DIGITS:
        short = float(f"{x:.{digits}g}")
        if to_f32(short) == x:
            return short
    return x


def log_info_dict(info: LogInfo) -> dict[str, Any]:
    return {
        "plan_stored": bool(info.plan_stored),
        "participant": info.participant,
        "simulated": bool(info.simulated),
        "config_hash": bytes(info.config_hash).hex(),
        "plan_trials": info.plan_trials,
        "records": info.records,
        "capacity": info.capacity,
        "torn_records": info.torn_records,
        "running": bool(info.running),
    }


def _hello_dict(hello: Any) -> dict[str, Any]:
    return {
        "board": hello.board,
        "protocol_version": hello.protocol_version,
        "firmware_version": ".".join(str(v) for v in hello.firmware_version),
        "build_id": f"{hello.build_id:08x}",
        "scalar_bytes": hello.scalar,
        "max_contacts": hello.max_contacts,
        "capabilities": hello.capabilities,
    }


def trial_record(info: LogInfo, rec: LogRecord, recorded_at: str) -> dict[str, Any]:
    """One LOG_RECORD as a trial record's line; DeviceLogError for a value the analysis
    could not take (the record is then not trusted)."""
    where = f"device log record {rec.index} (trial_index {rec.trial_index})"
    if rec.k not in CONTACT_COUNTS:
        raise DeviceLogError(f"{where}: k = {rec.k}, not 3 or 4; the log is damaged")
    for name in ("completion_s", "final_error_deg", "first_entry_s"):
        if not math.isfinite(getattr(rec, name)):
            raise DeviceLogError(f"{where}: {name} is not a finite number; the log is damaged")
    if rec.completion_s < 0:
        raise DeviceLogError(f"{where}: completion_s {rec.completion_s} < 0; the log is damaged")
    policy = POLICY_TEXT[rec.policy.name]
    mode = MODE_TEXT[rec.mode.name]
    prefix = "F" if rec.familiarization else "W"
    return TrialRecord(
        participant=info.participant,
        simulated=bool(info.simulated),
        trial_index=rec.trial_index,
        session=rec.session,
        session_trial=rec.session_trial,
        k=rec.k,
        policy=policy,
        mode=mode,
        modality=f"{policy}+{mode}",
        wrench_id=f"{prefix}{rec.wrench_number:02d}",
        wrench=tuple(f32_value(v) for v in rec.wrench),
        single_motor=bool(rec.single_motor),
        wrench_class=CLASS_TEXT[rec.wrench_class],
        success=bool(rec.success),
        completion_s=f32_value(rec.completion_s),
        familiarization=bool(rec.familiarization),
        first_entry_s=f32_value(rec.first_entry_s),
        final_error_deg=f32_value(rec.final_error_deg),
        poses=rec.samples,
        wall_s=None,
        config_hash=bytes(info.config_hash).hex(),
        source=SOURCE,
        recorded_at=recorded_at,
        hostless=True,
        imu_faults=rec.imu_faults,
    ).to_dict()


def _same_record(a: dict[str, Any], b: dict[str, Any]) -> bool:
    def strip(r: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in r.items() if k not in DOWNLOAD_KEYS}

    return strip(a) == strip(b)


def _read_existing(path: str) -> list[dict[str, Any]]:
    try:
        contents = read_jsonl(path)
    except JsonlDamaged as e:
        raise DeviceLogError(
            f"{e}: inspect the file, or download into another folder", usage=True
        ) from None
    except OSError as e:
        raise DeviceLogError(f"cannot read {path}: {e.strerror or e}", True) from None
    if contents.damaged_tail is not None:
        raise DeviceLogError(
            f"{path}: line {contents.tail_line} is damaged (a write cut short?); move the "
            "file away or download into another folder",
            usage=True,
        )
    return contents.records


def _check_folder(
    out_dir: str, trials_path: str, existing: Sequence[dict[str, Any]], info: LogInfo
) -> None:
    """Refuse a folder that holds another study: nothing in it is overwritten."""
    config = bytes(info.config_hash).hex()
    study_path = study_file(out_dir)
    if os.path.exists(study_path):
        try:
            with open(study_path, encoding="utf-8") as f:
                study_hash = str(json.load(f).get("config_hash", ""))
        except (OSError, ValueError, AttributeError) as e:
            raise DeviceLogError(f"{study_path} is unreadable ({e}); move it away", True) from None
        if not study_hash.startswith(config):
            raise DeviceLogError(
                f"{out_dir} holds a study with another protocol (config_hash "
                f"{study_hash[:16]}..., the device's plan {config}): use another --out",
                usage=True,
            )
    for n, rec in enumerate(existing, start=1):
        where = f"{trials_path}:{n}"
        if rec.get("participant") != info.participant:
            raise DeviceLogError(
                f"{where} holds trials of participant {rec.get('participant')!r}, the device's "
                f"log is {info.participant!r}'s: use another --out",
                usage=True,
            )
        if rec.get("config_hash") is None or not str(rec.get("config_hash")).startswith(config):
            raise DeviceLogError(
                f"{where} holds trials of another protocol (config_hash "
                f"{str(rec.get('config_hash'))[:16]}, the device's plan {config}): use another "
                "--out",
                usage=True,
            )
        if rec.get("hostless") is not True:
            raise DeviceLogError(
                f"{where} holds a host-driven trial (source {rec.get('source')!r}); host-less "
                "records are never mixed into it: use another --out",
                usage=True,
            )
        if rec.get("simulated") is not bool(info.simulated):
            raise DeviceLogError(
                f"{where} holds {'simulated' if rec.get('simulated') else 'human'} trials, "
                f"the device's are {'simulated' if info.simulated else 'human'}: never mix "
                "them; use another --out",
                usage=True,
            )


def _tlx_lines(
    existing: list[dict[str, Any]], trials: Sequence[dict[str, Any]], config: str, now: str
) -> list[dict[str, Any]]:
    """The lines already there, plus a scales-null line for every session with records
    and no line yet: the analysis needs the file; no answer is invented."""
    have = {r.get("session") for r in existing}
    out = list(existing)
    for t in trials:
        s = t["session"]
        if s >= 1 and s not in have:
            have.add(s)
            out.append(
                TlxRecord(
                    participant=t["participant"],
                    simulated=t["simulated"],
                    session=s,
                    k=t["k"],
                    modality=t["modality"],
                    policy=t["policy"],
                    mode=t["mode"],
                    scales=None,
                    origin="absent: host-less run, the device asks no questionnaire",
                    config_hash=config,
                    recorded_at=now,
                ).to_dict()
            )
    return sorted(out, key=lambda r: r.get("session", 0))


def _damage_text(rerun: dict[int, int], kept_first: list[int], missing: list[int]) -> str:
    """Which trials a damaged record belonged to, as far as the log shows it."""
    parts = []
    for idx, index in sorted(rerun.items()):
        text = f"trial_index {idx} ran again after its record was damaged (device record {index})"
        if idx in kept_first:
            text += (
                "; the folder keeps the result downloaded before the damage, the device's "
                "later run of it is not used"
            )
        parts.append(text)
    if missing:
        listed = ", ".join(str(i) for i in missing)
        parts.append(
            f"trial_index {listed} has no record: the next host-less run (`graspguide trial "
            "--hostless`, or the board at power-up) runs it again"
        )
    if not parts:
        parts.append("their trials have no record until the next host-less run runs them again")
    return "; " + "; ".join(parts)


def download_log(
    client: Any, out_dir: str, err: TextIO | None = None, timeout: float | None = None
) -> DownloadSummary:
    """LOG_INFO, then LOG_READ 0..records-1, into ``out_dir/<participant>/`` (see the
    module's text). Raises DeviceLogError (``usage`` for a folder that holds another
    study), LinkError, RecordWriteError. Torn records are reported on ``err``."""
    err = err or sys.stderr
    hello = client.device_info or client.hello(timeout)
    client.require_capability(CAPABILITY_HOSTLESS, "a host-less results log")
    info = client.log_info(timeout)
    if not info.plan_stored:
        raise DeviceLogError(
            "the device holds no host-less plan, so no results log: upload a plan and run "
            "it first (`graspguide trial --hostless`)"
        )
    participant = info.participant
    if not PARTICIPANT_FOLDER_RE.match(participant):
        raise DeviceLogError(
            f"the device's plan names participant {participant!r}, which cannot be a folder "
            "name (letters, digits, '-' and '_' only); upload the plan again with a plain id"
        )
    config = bytes(info.config_hash).hex()
    now = _now_iso()
    downloaded: dict[int, dict[str, Any]] = {}
    # Trials run again after their record was damaged: trial_index -> device record.
    rerun: dict[int, int] = {}
    highest = 0
    for index in range(info.records):
        rec = client.log_read(index, timeout)
        if rec.trial_index in downloaded:
            raise DeviceLogError(
                f"device log record {index} repeats trial_index {rec.trial_index}; the log "
                "is inconsistent: keep the device as it is and report it"
            )
        downloaded[rec.trial_index] = trial_record(info, rec, now)
        if info.torn_records and rec.trial_index < highest:
            rerun[rec.trial_index] = index
        highest = max(highest, rec.trial_index)

    files = ParticipantFiles.of(out_dir, participant)
    pdir = files.folder
    trials_path = files.trials
    tlx_path = files.tlx
    existing = _read_existing(trials_path)
    _check_folder(out_dir, trials_path, existing, info)
    merged: dict[int, dict[str, Any]] = {}
    for rec in existing:
        idx = rec.get("trial_index")
        if not isinstance(idx, int) or idx in merged:
            raise DeviceLogError(
                f"{trials_path}: trial_index {idx!r} is missing or appears twice; inspect the "
                "file or download into another folder",
                usage=True,
            )
        merged[idx] = rec
    new = 0
    kept_first: list[int] = []
    for idx, rec in downloaded.items():
        old = merged.get(idx)
        if old is None:
            merged[idx] = rec
            new += 1
        elif idx in rerun and not _same_record(old, rec):
            kept_first.append(idx)  # the first run's result, downloaded while it was intact
        elif not _same_record(old, rec):
            raise DeviceLogError(
                f"{trials_path}: trial {idx} already holds another result than the device's "
                "record (the log was erased and the plan run again?); nothing was changed: "
                "download into another folder",
                usage=True,
            )
    trials = [merged[i] for i in sorted(merged)]
    tlx = _tlx_lines(_read_existing(tlx_path), trials, config, now)
    try:
        os.makedirs(pdir, exist_ok=True)
    except OSError as e:
        raise RecordWriteError(pdir, e, _HINT) from e
    write_json_lines(trials_path, trials, _HINT)
    write_json_lines(tlx_path, tlx, _HINT)
    write_json_file(
        files.device_log,
        {
            "format": DEVICE_LOG_FORMAT,
            "downloaded_at": now,
            "log_info": log_info_dict(info),
            "device": _hello_dict(hello),
            "port": getattr(client.transport, "name", ""),
        },
        _HINT,
        indent=2,
        sort_keys=True,
    )
    if info.torn_records:
        print(
            f"graspguide device log: warning: the device found {info.torn_records} torn "
            "record(s) (damaged: a write cut by a power loss, or a bit flipped in storage) "
            "and skipped them"
            + _damage_text(rerun, kept_first, sorted(set(range(1, highest)) - set(downloaded))),
            file=err,
            flush=True,
        )
    if info.capacity and info.records >= info.capacity:
        print(
            f"graspguide device log: warning: the device's log is full ({info.records} of "
            f"{info.capacity} records): it runs no further trial until erased; now that "
            "they are downloaded, `graspguide device erase --yes` frees it",
            file=err,
            flush=True,
        )
    if info.running:
        print(
            "graspguide device log: warning: a host-less run goes on; records stored after "
            "this download are not in it (download again when it ends)",
            file=err,
            flush=True,
        )
    return DownloadSummary(
        participant=participant,
        config_hash=config,
        simulated=bool(info.simulated),
        folder=pdir,
        plan_trials=info.plan_trials,
        records=len(downloaded),
        new=new,
        total=len(trials),
        capacity=info.capacity,
        torn_records=info.torn_records,
        running=bool(info.running),
    )


__all__ = [
    "download_log",
    "DownloadSummary",
    "DeviceLogError",
    "trial_record",
    "log_info_dict",
    "f32_value",
    "HOSTLESS_FIELDS",
    "SOURCE",
]
