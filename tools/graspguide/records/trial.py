"""The records of a study: one line of ``trials.jsonl`` per completed trial
(:class:`TrialRecord`) and one line of ``tlx.jsonl`` per finished session
(:class:`TlxRecord`), what each field means and its unit, and the checks every reader
applies (:func:`check_trial_record`, :func:`check_tlx_record`).

The writers (the runner, the host-less download) build the records here and append them
with :func:`graspguide.records.storage.append_json_line` (sorted keys, one line each); the
readers (the analysis, the plots) check each line here, so a reader's message names the
file, the line, the field and what to do.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping
from typing import Any

from graspguide.core.vocabulary import MODALITIES, MODES, POLICIES

CONTACT_COUNTS = (3, 4)
# What to do about a record a reader refuses.
FIX_HINT = (
    "correct that line, or move it aside and run the same `graspguide trial` command "
    "again to record that trial anew"
)


class RecordError(ValueError):
    """A record a reader cannot take: ``str()`` names where (``FILE:LINE``), the field,
    what it must be and what to do."""

    def __init__(self, where: str, field: str, problem: str, fix: str = FIX_HINT):
        super().__init__(f"{where}: {problem}; {fix}")
        self.where = where
        self.field = field
        self.problem = problem


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _is_bool(v: Any) -> bool:
    return isinstance(v, bool)


@dataclasses.dataclass(frozen=True)
class Check:
    """How a reader checks a field: ``ok(value)``; ``what`` it must be; ``required``: a
    record without it is refused (otherwise a missing or null value is accepted);
    ``column``: the field is in the row the check returns (else only checked)."""

    ok: Callable[[Any], bool]
    what: str
    required: bool = True
    column: bool = True


def _field(doc: str, unit: str = "", check: Check | None = None, **kw: Any) -> Any:
    return dataclasses.field(metadata={"doc": doc, "unit": unit, "check": check}, **kw)


_PARTICIPANT = Check(lambda v: isinstance(v, str) and v.strip() != "", "a non-empty string")
_BOOL = Check(_is_bool, "true or false")
_MODALITY = Check(lambda v: v in MODALITIES, "one of " + ", ".join(MODALITIES))
_K = Check(lambda v: _is_int(v) and v in CONTACT_COUNTS, "3 or 4")


@dataclasses.dataclass(frozen=True)
class TrialRecord:
    """One completed trial: a line of ``OUT/<PID>/trials.jsonl``. The fields, in the
    order of :data:`TRIAL_FIELDS`; :meth:`to_dict` is what the line holds (the host-less
    fields only in a host-less download's records)."""

    participant: str = _field(
        "the participant's id (U1, P03); also the folder's name", "", _PARTICIPANT
    )
    simulated: bool = _field(
        "true when no human took part (a simulated source or device)", "", _BOOL
    )
    trial_index: int = _field(
        "the trial's place in the participant's plan, 1..N",
        "",
        Check(lambda v: _is_int(v) and v >= 1, "an integer >= 1"),
    )
    session: int = _field(
        "0: familiarization; 1..S: the (k, modality) sessions in run order",
        "",
        Check(_is_int, "an integer"),
    )
    session_trial: int = _field("the trial's place in its session, 1..n")
    k: int = _field("contacts of the hand: motors in use", "contacts", _K)
    policy: str = _field(
        "the guidance policy: F or Fperp",
        "",
        Check(lambda v: v in POLICIES, " or ".join(repr(p) for p in POLICIES), required=False),
    )
    mode: str = _field(
        "the intensity mode: C (constant) or V (varying)",
        "",
        Check(lambda v: v in MODES, " or ".join(repr(m) for m in MODES), required=False),
    )
    modality: str = _field("policy+mode (F+V, Fperp+V, F+C, Fperp+C)", "", _MODALITY)
    wrench_id: str = _field(
        "the protocol's name of the wrench: W01.., F01.. in familiarization",
        "",
        Check(
            lambda v: _is_int(v) or (isinstance(v, str) and v != ""),
            "an integer or a wrench name",
            required=False,
        ),
    )
    wrench: tuple[float, ...] = _field(
        "the target wrench: force x, y, z then torque x, y, z",
        "N, N m",
        Check(
            lambda v: isinstance(v, list) and len(v) == 6 and all(_is_number(x) for x in v),
            "a list of 6 finite numbers",
            required=False,
            column=False,
        ),
    )
    single_motor: bool = _field(
        "exactly one motor drives this wrench in the reference condition",
        "",
        Check(_is_bool, "true or false", required=False),
    )
    wrench_class: str = _field('"single" or "multi" in the reference condition; "" for F..')
    success: bool = _field("the device saw the error held below the threshold", "", _BOOL)
    completion_s: float = _field(
        "time to success; the trial's timeout for a failure",
        "s",
        Check(lambda v: _is_number(v) and v >= 0, "a finite number of seconds >= 0"),
    )
    familiarization: bool = _field("a familiarization trial (not analysed)", "", _BOOL)
    first_entry_s: float = _field("first time the error went below the threshold; -1: never", "s")
    final_error_deg: float = _field("the guidance error when the trial ended", "deg")
    poses: int = _field("POSEs the device took (host-less: IMU samples)", "poses")
    wall_s: float | None = _field("the trial's wall-clock time; null host-less (no clock)", "s")
    config_hash: str = _field(
        "sha256 of the protocol (hex); host-less: its first 8 bytes as 16 hex digits"
    )
    source: str = _field('the pose source: "participant", "synthetic", ..., "hostless"')
    recorded_at: str = _field("when the record was written: ISO 8601, UTC, milliseconds")
    hostless: bool | None = _field(
        "true in a host-less download's records; absent otherwise", default=None
    )
    imu_faults: int | None = _field(
        "host-less: IMU reads that failed during the trial; absent otherwise",
        "reads",
        default=None,
    )

    def to_dict(self) -> dict[str, Any]:
        """The line's object (the host-less fields only when set)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in HOSTLESS_FIELDS and value is None:
                continue
            out[f.name] = list(value) if f.name == "wrench" else value
        return out

    @classmethod
    def from_dict(cls, rec: Mapping[str, Any], where: str = "a trial record") -> TrialRecord:
        """The record of a line's object; RecordError for a missing or unknown field."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(rec) - names)
        if unknown:
            raise RecordError(where, unknown[0], f"unknown field '{unknown[0]}'")
        missing = [n for n in TRIAL_FIELDS if n not in rec]
        if missing:
            raise RecordError(where, missing[0], f"missing field '{missing[0]}'")
        values = dict(rec)
        values["wrench"] = tuple(values["wrench"])
        return cls(**values)

    @classmethod
    def of_planned(cls, planned: Mapping[str, Any], **outcome: Any) -> TrialRecord:
        """The record of a planned trial (PlannedTrial.to_dict()) and its outcome."""
        fields = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in planned.items() if k in fields}, **outcome)


# Keys only a host-less download's records carry.
HOSTLESS_FIELDS = ("hostless", "imu_faults")
#: Every trial record's fields, in order.
TRIAL_FIELDS = tuple(
    f.name for f in dataclasses.fields(TrialRecord) if f.name not in HOSTLESS_FIELDS
)


def field_docs(record_type: type = TrialRecord) -> dict[str, tuple[str, str]]:
    """name -> (meaning, unit) of a record type's fields."""
    return {
        f.name: (f.metadata.get("doc", ""), f.metadata.get("unit", ""))
        for f in dataclasses.fields(record_type)
    }


def _checks(record_type: type) -> list[tuple[str, Check]]:
    return [
        (f.name, f.metadata["check"])
        for f in dataclasses.fields(record_type)
        if f.metadata.get("check") is not None
    ]


def _checked(where: str, rec: Mapping[str, Any], name: str, check: Check) -> Any:
    if name not in rec or (not check.required and rec[name] is None):
        if check.required:
            raise RecordError(where, name, f"missing field '{name}' ({check.what})")
        return None
    value = rec[name]
    if not check.ok(value):
        raise RecordError(
            where, name, f"field '{name}' must be {check.what}, got {json.dumps(value)}"
        )
    return value


def _checked_row(where: str, rec: Any, record_type: type) -> dict[str, Any]:
    if not isinstance(rec, Mapping):
        raise RecordError(where, "", f"expected a JSON object, got {type(rec).__name__}")
    row = {}
    for name, check in _checks(record_type):
        value = _checked(where, rec, name, check)
        if check.column:
            row[name] = value
    return row


#: The fields :func:`check_trial_record` returns, in order.
TRIAL_READ_FIELDS = tuple(n for n, c in _checks(TrialRecord) if c.column)


def check_trial_record(where: str, rec: Any) -> dict[str, Any]:
    """The checked fields (TRIAL_READ_FIELDS) of a trials.jsonl line's object; RecordError
    naming ``where`` (``FILE:LINE``), the field, what it must be and what to do.
    ``policy`` and ``mode``, when absent, come from ``modality`` (and must agree with
    it); ``completion_s`` is a float."""
    row = _checked_row(where, rec, TrialRecord)
    policy, mode = row["modality"].split("+")
    if (row["policy"] or policy) != policy or (row["mode"] or mode) != mode:
        raise RecordError(
            where,
            "modality",
            f"modality {row['modality']!r} contradicts policy {row['policy']!r} and mode "
            f"{row['mode']!r}",
        )
    row["policy"], row["mode"] = policy, mode
    row["completion_s"] = float(row["completion_s"])
    return row


# ======================================================================================
# The NASA-TLX records
# ======================================================================================
@dataclasses.dataclass(frozen=True)
class TlxRecord:
    """One finished session's NASA-TLX: a line of ``OUT/<PID>/tlx.jsonl``."""

    participant: str = _field("the participant's id", "", _PARTICIPANT)
    simulated: bool = _field("true when no human took part", "", _BOOL)
    session: int = _field("the session, 1..S", "", Check(_is_int, "an integer"))
    k: int = _field(
        "contacts of the hand in this session",
        "contacts",
        Check(_K.ok, _K.what, required=False),
    )
    modality: str = _field(
        "policy+mode of the session", "", Check(_MODALITY.ok, _MODALITY.what, required=False)
    )
    policy: str = _field("the session's guidance policy")
    mode: str = _field(
        "the session's intensity mode: C or V",
        "",
        Check(lambda v: v in MODES, " or ".join(repr(m) for m in MODES)),
    )
    scales: dict[str, int] | None = _field(
        "the six ratings by scale code (1..21); null: no questionnaire was asked "
        "(a simulated source without answers, a host-less run): never invented",
        "rating",
        Check(
            lambda v: v is None or isinstance(v, dict),
            "an object of the six ratings (or null: no questionnaire)",
            column=False,
        ),
    )
    origin: str = _field('where the answers came from: "file", "interactive", "absent: ..."')
    config_hash: str = _field("the protocol's hash, as in the trial records")
    recorded_at: str = _field("when the record was written: ISO 8601, UTC, milliseconds")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


TLX_FIELDS = tuple(f.name for f in dataclasses.fields(TlxRecord))
#: The fields :func:`check_tlx_record` returns, before the scales, in order.
TLX_READ_FIELDS = tuple(n for n, c in _checks(TlxRecord) if c.column)


def check_tlx_record(
    where: str, rec: Any, scales: Mapping[str, str], low: int, high: int
) -> dict[str, Any]:
    """The checked fields (TLX_READ_FIELDS, then one per code of ``scales``: code ->
    name, None when the line's scales are null) of a tlx.jsonl line's object; each
    rating an integer ``low``..``high``. RecordError as :func:`check_trial_record`."""
    row = _checked_row(where, rec, TlxRecord)
    if row["modality"] is not None and row["modality"].split("+")[1] != row["mode"]:
        raise RecordError(
            where, "modality", f"modality {row['modality']!r} contradicts mode {row['mode']!r}"
        )
    given = rec["scales"]
    for code, name in scales.items():
        if given is None:
            row[code] = None
            continue
        if code not in given:
            raise RecordError(
                where,
                "scales",
                f"scales has no '{code}' ({name}); all {len(scales)} of "
                f"{', '.join(scales)} are needed",
            )
        v = given[code]
        if not (_is_int(v) or (_is_number(v) and float(v).is_integer())) or not low <= v <= high:
            raise RecordError(
                where,
                "scales",
                f"scales.{code} must be an integer {low}..{high}, got {json.dumps(v)}",
            )
        row[code] = int(v)
    return row


__all__ = [
    "TrialRecord",
    "TlxRecord",
    "TRIAL_FIELDS",
    "TRIAL_READ_FIELDS",
    "TLX_FIELDS",
    "TLX_READ_FIELDS",
    "HOSTLESS_FIELDS",
    "CONTACT_COUNTS",
    "RecordError",
    "Check",
    "check_trial_record",
    "check_tlx_record",
    "field_docs",
    "FIX_HINT",
]
