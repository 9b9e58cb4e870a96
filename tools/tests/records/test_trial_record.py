"""The trial and TLX records (graspguide.records.trial): the type reads back to the same
bytes as the runner wrote, every field says what it means, and a reader's refusal names
the file, the line, the field and what to do."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from graspguide.records.storage import dumps_record
from graspguide.records.trial import (
    FIX_HINT,
    HOSTLESS_FIELDS,
    TLX_FIELDS,
    TRIAL_FIELDS,
    TRIAL_READ_FIELDS,
    RecordError,
    TlxRecord,
    TrialRecord,
    check_tlx_record,
    check_trial_record,
    field_docs,
)

STUDY = Path(__file__).parents[1] / "data" / "plot_structure" / "study"
TRIAL_LINES = (STUDY / "U1" / "trials.jsonl").read_text(encoding="utf-8").splitlines()
SCALES = {"MD": "Mental Demand", "PD": "Physical Demand", "TD": "Temporal Demand"}


def _record(line: int = 1) -> dict:
    """A line of the test data (written by `graspguide trial`) as an object."""
    return json.loads(TRIAL_LINES[line])


@pytest.mark.parametrize("line", range(len(TRIAL_LINES)))
def test_a_runner_line_reads_back_to_the_same_bytes(line):
    """The runner's lines (test data written by `graspguide trial`) go through the type
    and back to exactly the same text: same keys, same values, same formatting."""
    text = TRIAL_LINES[line]
    record = TrialRecord.from_dict(json.loads(text))
    assert dumps_record(record.to_dict()) == text
    assert list(record.to_dict()) == list(TRIAL_FIELDS)  # no host-less field on a runner line


def test_a_hostless_record_round_trips_with_its_own_fields():
    rec = {**_record(), "hostless": True, "imu_faults": 2, "wall_s": None, "source": "hostless"}
    record = TrialRecord.from_dict(rec)
    assert record.hostless is True and record.imu_faults == 2
    again = record.to_dict()
    assert again == rec and list(again)[-2:] == list(HOSTLESS_FIELDS)
    assert TrialRecord.from_dict(again) == record


def test_from_dict_names_a_missing_or_unknown_field():
    rec = _record()
    del rec["poses"]
    with pytest.raises(RecordError, match="missing field 'poses'") as e:
        TrialRecord.from_dict(rec, "U1/trials.jsonl:2")
    assert e.value.field == "poses" and str(e.value).startswith("U1/trials.jsonl:2: ")
    with pytest.raises(RecordError, match="unknown field 'pose_count'"):
        TrialRecord.from_dict({**_record(), "pose_count": 3})


def test_every_field_says_what_it_means_and_the_numbers_their_unit():
    for record_type, names in ((TrialRecord, TRIAL_FIELDS), (TlxRecord, TLX_FIELDS)):
        docs = field_docs(record_type)
        assert set(names) <= set(docs)
        assert all(meaning for meaning, _ in docs.values()), record_type
    docs = field_docs()
    for name in ("completion_s", "first_entry_s", "wall_s"):
        assert docs[name][1] == "s", name
    assert docs["final_error_deg"][1] == "deg"
    assert "N" in docs["wrench"][1]


def test_the_reader_row_holds_the_checked_fields_in_record_order():
    row = check_trial_record("f:1", _record())
    assert tuple(row) == TRIAL_READ_FIELDS
    order = [TRIAL_FIELDS.index(n) for n in TRIAL_READ_FIELDS]
    assert order == sorted(order)
    assert isinstance(row["completion_s"], float)


REQUIRED = [
    f.name
    for f in dataclasses.fields(TrialRecord)
    if f.metadata["check"] is not None and f.metadata["check"].required
]


@pytest.mark.parametrize("name", REQUIRED)
def test_a_reader_names_a_missing_field_and_how_to_fix_it(name):
    rec = _record()
    del rec[name]
    with pytest.raises(RecordError) as e:
        check_trial_record("S/U1/trials.jsonl:7", rec)
    msg = str(e.value)
    assert e.value.field == name
    assert msg.startswith(f"S/U1/trials.jsonl:7: missing field '{name}' (")
    assert msg.endswith(FIX_HINT) and "graspguide trial" in msg


@pytest.mark.parametrize(
    "name, value, what",
    [
        ("k", 5, "3 or 4"),
        ("trial_index", 0, "an integer >= 1"),
        ("success", "yes", "true or false"),
        ("completion_s", -1.0, "a finite number of seconds >= 0"),
        ("modality", "F+X", "one of"),
        ("wrench", [1.0, 2.0], "a list of 6 finite numbers"),
        ("participant", " ", "a non-empty string"),
    ],
)
def test_a_reader_names_a_bad_field_its_value_and_what_it_must_be(name, value, what):
    rec = {**_record(), name: value}
    with pytest.raises(RecordError) as e:
        check_trial_record("f:3", rec)
    assert e.value.field == name
    assert f"f:3: field '{name}' must be {what}" in str(e.value)
    assert f"got {json.dumps(value)}" in str(e.value) and str(e.value).endswith(FIX_HINT)


def test_optional_fields_may_be_absent_and_policy_and_mode_come_from_the_modality():
    rec = _record()
    for name in ("policy", "mode", "wrench_id", "wrench", "single_motor"):
        del rec[name]
    row = check_trial_record("f:1", rec)
    assert (row["policy"], row["mode"]) == tuple(rec["modality"].split("+"))
    assert row["wrench_id"] is None and row["single_motor"] is None


def test_a_policy_that_contradicts_the_modality_is_refused():
    rec = {**_record(), "modality": "F+V", "policy": "Fperp"}
    with pytest.raises(RecordError, match="modality 'F\\+V' contradicts policy 'Fperp'"):
        check_trial_record("f:1", rec)


def test_a_line_that_is_not_an_object_is_refused():
    with pytest.raises(RecordError, match="expected a JSON object, got list"):
        check_trial_record("f:1", [1, 2])


def _tlx(**changes) -> dict:
    rec = TlxRecord(
        participant="U1",
        simulated=True,
        session=1,
        k=3,
        modality="F+V",
        policy="F",
        mode="V",
        scales={"MD": 3, "PD": 4, "TD": 5},
        origin="file",
        config_hash="ab" * 32,
        recorded_at="2026-11-24T15:33:22.294+00:00",
    ).to_dict()
    return {**rec, **changes}


def test_tlx_record_keys_are_the_runners_and_its_ratings_are_read_by_scale():
    rec = _tlx()
    assert tuple(rec) == TLX_FIELDS
    row = check_tlx_record("t:1", rec, SCALES, 1, 21)
    assert [row[s] for s in SCALES] == [3, 4, 5]
    unanswered = check_tlx_record("t:1", _tlx(scales=None), SCALES, 1, 21)
    assert all(unanswered[s] is None for s in SCALES)


def test_tlx_reader_names_the_missing_scale_and_the_bad_rating():
    with pytest.raises(RecordError, match="scales has no 'TD' \\(Temporal Demand\\)"):
        check_tlx_record("t:2", _tlx(scales={"MD": 3, "PD": 4}), SCALES, 1, 21)
    with pytest.raises(RecordError, match="t:2: scales.PD must be an integer 1..21, got 22"):
        check_tlx_record("t:2", _tlx(scales={"MD": 3, "PD": 22, "TD": 1}), SCALES, 1, 21)
    with pytest.raises(RecordError, match="modality 'F\\+V' contradicts mode 'C'"):
        check_tlx_record("t:2", _tlx(mode="C"), SCALES, 1, 21)
