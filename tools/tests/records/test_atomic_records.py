"""The one atomic append and the one whole-file write of the records
(graspguide.records.storage): a record is in the file whole or not at all, a torn last
line (a write cut by a crash or power loss) is left out by the readers and set aside
before the next append, and a file written whole is either the old one or the new one."""

from __future__ import annotations

import errno
import json
import os

import pytest

from graspguide.records import storage


def _lines(*objs) -> bytes:
    return b"".join((storage.dumps_record(o) + "\n").encode() for o in objs)


def test_complete_records_keeps_a_whole_last_record_without_newline(tmp_path):
    f = tmp_path / "t.jsonl"
    f.write_text(json.dumps({"a": 1}) + "\n" + json.dumps({"a": 2}))
    records, left_out = storage.complete_records(f)
    assert [r for _, r in records] == [{"a": 1}, {"a": 2}] and left_out is None


def test_an_append_after_a_torn_tail_gives_only_whole_records(tmp_path):
    """A run killed mid-append leaves a torn last line: the readers leave it out; the
    runner sets it aside (its bytes kept in a file beside) and appends after the whole
    records, so the file again holds whole records only."""
    path = str(tmp_path / "trials.jsonl")
    torn = b'{"trial_index": 3, "succ'
    with open(path, "wb") as f:
        f.write(_lines({"trial_index": 1}, {"trial_index": 2}) + torn)
    records, left_out = storage.complete_records(path)
    assert [r["trial_index"] for _, r in records] == [1, 2]
    assert left_out is not None and left_out.line == 3 and left_out.cut_short
    assert "the 2 complete records before it are read" in str(left_out)

    contents = storage.read_jsonl(path)
    aside = storage.set_aside_damaged_tail(path, contents)
    storage.append_json_line(path, {"trial_index": 3, "success": True})
    with open(aside, "rb") as f:
        assert f.read() == torn
    with open(path, "rb") as f:
        assert f.read() == _lines(
            {"trial_index": 1}, {"trial_index": 2}, {"trial_index": 3, "success": True}
        )
    assert storage.complete_records(path)[1] is None


def test_a_record_the_disk_takes_only_part_of_is_cut_back_off(tmp_path, monkeypatch):
    path = str(tmp_path / "trials.jsonl")
    storage.append_json_line(path, {"trial_index": 1})
    with open(path, "rb") as f:
        before = f.read()
    real_write = os.write

    def half_then_full(fd, data):
        if len(data) > 8:
            return real_write(fd, bytes(data[: len(data) // 2]))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(storage.os, "write", half_then_full)
    with pytest.raises(storage.RecordWriteError) as e:
        storage.append_json_line(path, {"trial_index": 2, "pad": "x" * 40}, " (hint)")
    monkeypatch.undo()
    msg = str(e.value)
    assert path in msg and "the disk is full" in msg and "free some space" in msg
    assert "the record was not written, the file holds only whole records" in msg
    assert msg.endswith(" (hint)")
    with open(path, "rb") as f:
        assert f.read() == before  # the half record is gone
    storage.append_json_line(path, {"trial_index": 2})
    assert [r["trial_index"] for r in storage.read_jsonl(path).records] == [1, 2]


def test_json_lines_written_whole_or_the_old_file_kept(tmp_path, monkeypatch):
    path = str(tmp_path / "tlx.jsonl")
    storage.write_json_lines(path, [{"session": 1}, {"session": 2}])
    with open(path, "rb") as f:
        old = f.read()
    assert old == _lines({"session": 1}, {"session": 2})

    def no_sync(fd):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(storage.os, "fsync", no_sync)
    with pytest.raises(storage.RecordWriteError, match="an I/O error"):
        storage.write_json_lines(path, [{"session": 3}])
    monkeypatch.undo()
    with open(path, "rb") as f:
        assert f.read() == old
    assert os.listdir(tmp_path) == ["tlx.jsonl"]  # no temporary file left


def test_a_whole_file_write_that_must_not_replace_leaves_the_existing_one(tmp_path):
    path = str(tmp_path / "calibration.json")
    storage.write_json_file(path, {"a": 1}, replace=False, indent=1)
    with pytest.raises(FileExistsError):
        storage.write_json_file(path, {"a": 2}, replace=False, indent=1)
    with open(path, encoding="utf-8") as f:
        assert f.read() == '{\n "a": 1\n}\n'
    with pytest.raises(ValueError):  # NaN is not JSON: nothing written, nothing left
        storage.write_json_file(path, {"a": float("nan")}, allow_nan=False)
    assert sorted(os.listdir(tmp_path)) == ["calibration.json"]
