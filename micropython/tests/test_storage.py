"""The plan region and the results log inside MicroPython: CRC-32, round trips, the range
checks naming their field, a power cut at every byte of a plan save and of a record, a
full log, read faults, and the file-backed store. (tools/tests/test_micropython_formats.py
checks the bytes against the C++ simulated device's store.)"""

import os

from graspguide_mp import plan_file as pf
from graspguide_mp import results_file as rf
from graspguide_mp import store
from graspguide_mp.fake_hal import CutStore
from hostless_helpers import make_plan

NAN = float("nan")


def _record(trial, i):
    r = rf.LogRecord(trial)
    r.success = i % 2 == 0
    r.completion_s = 1.25 + i
    r.first_entry_s = 0.5 if r.success else -1.0
    r.final_error_deg = 2.5
    r.samples = 100 + i
    r.imu_faults = i
    return r


def test_crc32():
    # The published check value of CRC-32/ISO-HDLC (zlib, PNG).
    assert store.crc32_nibble(b"123456789") == 0xCBF43926
    data = bytes(range(256)) * 3
    assert store.crc32(data) == store.crc32_nibble(data)
    assert store.crc32(data[100:], store.crc32(data[:100])) == store.crc32(data)


def test_layout_sizes():
    # results_log.h / plan_store.h: the same arithmetic from the same field sizes.
    assert pf.REGION_BYTES % pf.SECTOR_BYTES == 0
    assert pf.REGION_BYTES >= pf.PREAMBLE_BYTES + pf.payload_bytes(pf.MAX_PLAN_TRIALS)
    assert len(pf.encode_header(pf.PlanHeader())) == pf.HEADER_BYTES
    assert len(pf.encode_trial(pf.PlanTrial())) == pf.TRIAL_BYTES
    assert len(rf.encode_slot(rf.LogRecord(), 0)) == rf.SLOT_BYTES
    assert rf.SLOT_BYTES % rf.SLOT_ALIGN_BYTES == 0


def test_plan_round_trip():
    s = store.MemoryStore()
    p = make_plan(5)
    assert pf.load_plan(s) == (pf.NO_PLAN, None)
    assert pf.save_plan(s, p) == pf.OK
    status, q = pf.load_plan(s)
    assert status == pf.OK
    assert pf.encode_plan(q) == pf.encode_plan(p)
    assert pf.plan_id(q) == pf.plan_id(p)
    assert q.header.participant_name() == "U1"


def _calibrated(p, floor=(60, 75, 80, 90), gain=(1.25, 0.75, 2.0, 0.5)):
    p.header.pwm_floor = list(floor)
    p.header.gain = list(gain)
    return p


def test_plan_with_a_calibration_is_stored_and_reloaded():
    s = store.MemoryStore()
    p = _calibrated(make_plan(4))
    assert pf.save_plan(s, p) == pf.OK
    status, q = pf.load_plan(s)
    assert status == pf.OK
    assert q.header.pwm_floor == [60, 75, 80, 90]
    # float32 on the store: these gains are exact in binary32.
    assert q.header.gain == [1.25, 0.75, 2.0, 0.5]
    assert pf.plan_id(q) == pf.plan_id(p)
    # The calibration is part of the plan: the same trials under another calibration are
    # another plan (its records are not this one's).
    assert pf.plan_id(make_plan(4)) != pf.plan_id(p)
    assert make_plan(1).header.pwm_floor == [70, 70, 70, 70]
    assert make_plan(1).header.gain == [1.0, 1.0, 1.0, 1.0]


def _layout1_region(p):
    """The region an older firmware (layout 1: the header without the calibration) wrote."""
    import struct

    header = pf.encode_header(p.header)[: pf.HEADER_BYTES - 20]
    payload = header + b"".join(pf.encode_trial(t) for t in p.trials)
    pre = struct.pack("<IHHII", pf.PLAN_MAGIC, 1, 0, len(payload), store.crc32(payload))
    return pre + payload


def test_an_old_layout_plan_is_refused_never_misread():
    p = make_plan(3)
    s = store.MemoryStore()
    assert s.write(0, _layout1_region(p))
    assert pf.load_plan(s) == (pf.OLD_LAYOUT, None)
    assert "graspguide plan" in pf.OLD_LAYOUT_FIX
    # A whole plan of this layout relabelled version 1 is refused the same way: its
    # version, not its length or CRC, decides.
    s = store.MemoryStore()
    assert pf.save_plan(s, _calibrated(make_plan(3))) == pf.OK
    s.data[4] = 1
    assert pf.load_plan(s) == (pf.OLD_LAYOUT, None)
    # Storing the plan again replaces it.
    assert pf.save_plan(s, p) == pf.OK
    status, q = pf.load_plan(s)
    assert status == pf.OK and pf.plan_id(q) == pf.plan_id(p)


def test_plan_checks_name_the_field():
    cases = (
        ("participant", lambda p: setattr(p.header, "participant", b"\0" * 8)),
        ("participant", lambda p: setattr(p.header, "participant", b"U\x01\0\0\0\0\0\0")),
        ("trial_count", lambda p: setattr(p.header, "trial_count", 0)),
        ("constraints", lambda p: setattr(p.header, "constraints", 3)),
        ("y_axis", lambda p: setattr(p.header, "y_axis", [0.0, 0.0, 0.0])),
        ("threshold_deg", lambda p: setattr(p.header, "threshold_deg", 181.0)),
        ("hold_s", lambda p: setattr(p.header, "hold_s", 100.0)),
        ("timeout_s", lambda p: setattr(p.header, "timeout_s", 0.0)),
        ("rest_s", lambda p: setattr(p.header, "rest_s", 601.0)),
        ("hand_k3", lambda p: setattr(p.header, "hand_k3", [[0.0] * 3, [1.5, 0, 0], [0.0] * 3])),
        ("hand_k4", lambda p: setattr(p.header, "hand_k4", [[0.0] * 3] * 3 + [[0, 0, NAN]])),
        ("imu_to_hand_wxyz", lambda p: setattr(p.header, "imu_to_hand_wxyz", [3.0, 0, 0, 0])),
        ("pwm_floor", lambda p: setattr(p.header, "pwm_floor", [70, 70, 255, 70])),
        ("pwm_floor", lambda p: setattr(p.header, "pwm_floor", [70, -1, 70, 70])),
        ("pwm_floor", lambda p: setattr(p.header, "pwm_floor", [70, 70, 70])),
        ("gain", lambda p: setattr(p.header, "gain", [1.0, 1.0, 0.2, 1.0])),
        ("gain", lambda p: setattr(p.header, "gain", [1.0, 4.5, 1.0, 1.0])),
        ("gain", lambda p: setattr(p.header, "gain", [NAN, 1.0, 1.0, 1.0])),
        ("trial_index", lambda p: setattr(p.trials[1], "trial_index", 0)),
        ("session_trial", lambda p: setattr(p.trials[1], "session_trial", 0)),
        ("k", lambda p: setattr(p.trials[1], "k", 5)),
        ("policy", lambda p: setattr(p.trials[1], "policy", 2)),
        ("mode", lambda p: setattr(p.trials[1], "mode", 2)),
        ("wrench_class", lambda p: setattr(p.trials[1], "wrench_class", 3)),
        ("wrench", lambda p: setattr(p.trials[1], "wrench", [0.0, 0.0, 0.0, 1.0, 0.0, 0.0])),
    )
    for field, spoil in cases:
        p = make_plan(3)
        spoil(p)
        try:
            pf.check_plan(p)
        except pf.PlanError as e:
            assert e.field == field, (field, str(e))
            assert field in str(e)
        else:
            raise AssertionError("a bad %s passed the checks" % field)
        s = store.MemoryStore()
        assert pf.save_plan(s, p) == pf.BAD_PLAN
        assert s.data == b"\xff" * len(s.data), "a refused plan writes nothing"


def test_plan_save_cut_at_every_byte():
    old = make_plan(2, participant=b"OLD")
    new = _calibrated(make_plan(3, participant=b"NEW"))
    total = 4 + pf.PREAMBLE_BYTES - 4 + pf.payload_bytes(3) + 4
    seen_none = 0
    for budget in range(total + 1):
        s = CutStore(pf.REGION_BYTES + 4096)
        assert pf.save_plan(s, old) == pf.OK
        s.budget = budget
        result = pf.save_plan(s, new)
        status, got = pf.load_plan(s)
        if budget >= total - 1 and result == pf.OK:
            assert status == pf.OK and pf.encode_plan(got) == pf.encode_plan(new)
        elif budget == 0:
            assert status == pf.OK and pf.encode_plan(got) == pf.encode_plan(old)
        else:
            # Never a wrong plan: the old one's magic went first.
            assert status == pf.NO_PLAN and got is None, budget
            seen_none += 1
    assert seen_none > pf.payload_bytes(3)


def test_plan_region_rejects_damage():
    s = store.MemoryStore()
    assert pf.save_plan(s, make_plan(2)) == pf.OK
    for at in (5, pf.PREAMBLE_BYTES + 3, pf.PREAMBLE_BYTES + pf.HEADER_BYTES + 7):
        d = CutStore(len(s.data))
        d.data[:] = s.data
        d.data[at] ^= 0x01
        assert pf.load_plan(d)[0] == pf.NO_PLAN, at
    d = CutStore(len(s.data))
    d.data[:] = s.data
    d.read_fails = True
    assert pf.load_plan(d)[0] == pf.STORAGE_FAILED
    assert pf.load_plan(store.MemoryStore(pf.REGION_BYTES - 1))[0] == pf.TOO_SMALL


def test_log_round_trip_and_reopen():
    s = store.MemoryStore()
    p = make_plan(4)
    pid = pf.plan_id(p)
    log = rf.ResultsLog(s)
    assert log.mount() == pf.OK and log.records == 0
    assert log.capacity == (len(s.data) - pf.REGION_BYTES) // rf.SLOT_BYTES
    for i in range(4):
        assert log.append(_record(p.trials[i], i), pid) == pf.OK
    again = rf.ResultsLog(s)
    assert again.mount() == pf.OK and again.records == 4 and again.torn == 0
    for i in range(4):
        status, r, got_pid = again.read(i)
        assert status == pf.OK and got_pid == pid
        want = _record(p.trials[i], i)
        assert rf.encode_slot(r, pid) == rf.encode_slot(want, pid)
    assert again.read(4)[0] == pf.NO_RECORD
    assert not again.holds_other_plan(pid)
    assert again.holds_other_plan(pid ^ 1)


def test_torn_record_at_every_cut_point():
    p = make_plan(2)
    pid = pf.plan_id(p)
    for budget in range(rf.SLOT_BYTES):
        s = CutStore(pf.REGION_BYTES + 5 * rf.SLOT_BYTES)
        log = rf.ResultsLog(s)
        log.mount()
        assert log.append(_record(p.trials[0], 0), pid) == pf.OK
        s.budget = budget
        assert log.append(_record(p.trials[1], 1), pid) == pf.STORAGE_FAILED
        s.budget = -1
        # The cut slot is counted as a remount sees it, and never returned.
        for lg in (log, rf.ResultsLog(s)):
            if lg is not log:
                assert lg.mount() == pf.OK
            assert lg.records == 1, budget
            assert lg.torn == (1 if budget > 0 else 0), budget
            assert lg.read(0)[1].trial.trial_index == 1
            assert lg.read(1)[0] == pf.NO_RECORD
        # The next append goes after the torn slot, never over it.
        assert log.append(_record(p.trials[1], 1), pid) == pf.OK
        re = rf.ResultsLog(s)
        re.mount()
        assert re.records == 2 and re.read(1)[1].trial.trial_index == 2
        assert re.next_slot == (3 if budget > 0 else 2)


def test_log_full_erase_and_faults():
    p = make_plan(1)
    pid = pf.plan_id(p)
    s = CutStore(pf.REGION_BYTES + 3 * rf.SLOT_BYTES + 10)
    log = rf.ResultsLog(s)
    assert log.append(_record(p.trials[0], 0), pid) == pf.STORAGE_FAILED, "not mounted"
    log.mount()
    assert log.capacity == 3
    for i in range(3):
        assert log.append(_record(p.trials[0], i), pid) == pf.OK
    assert log.full()
    before = bytes(s.data)
    assert log.append(_record(p.trials[0], 9), pid) == pf.FULL
    assert bytes(s.data) == before, "a full log overwrites nothing"
    region = bytes(s.data[: pf.REGION_BYTES])
    assert log.erase() == pf.OK and log.records == 0 and not log.full()
    assert bytes(s.data[: pf.REGION_BYTES]) == region, "erase leaves the plan"
    s.read_fails = True
    assert log.mount() == pf.STORAGE_FAILED and log.records == 0
    assert rf.ResultsLog(store.MemoryStore(pf.REGION_BYTES + 1)).mount() == pf.TOO_SMALL


def test_log_erased_slot_before_records():
    # An erase cut part way may leave erased slots in front of records: appends go after.
    p = make_plan(1)
    pid = pf.plan_id(p)
    s = store.MemoryStore(pf.REGION_BYTES + 4 * rf.SLOT_BYTES)
    s.write(rf.ResultsLog.slot_offset(2), rf.encode_slot(_record(p.trials[0], 0), pid))
    log = rf.ResultsLog(s)
    log.mount()
    assert log.records == 1 and log.next_slot == 3
    assert log.append(_record(p.trials[0], 1), pid) == pf.OK
    assert s.read(rf.ResultsLog.slot_offset(0), rf.SLOT_BYTES) == b"\xff" * rf.SLOT_BYTES


def test_file_store():
    path = (
        "/tmp/graspguide_mp_test_store_%d.bin" % os.getpid()
        if hasattr(os, "getpid")
        else ("/tmp/graspguide_mp_test_store.bin")
    )
    try:
        os.remove(path)
    except OSError:
        pass
    try:
        fs = store.FileStore(path, 16384)
        assert fs.size_bytes() == 16384 and fs.read(0, 4) == b"\xff" * 4
        p = make_plan(2)
        assert pf.save_plan(fs, p) == pf.OK
        log = rf.ResultsLog(fs)
        log.mount()
        assert log.append(_record(p.trials[0], 0), pf.plan_id(p)) == pf.OK
        assert fs.read(16380, 8) is None and not fs.write(16380, b"12345678")
        fs.close()
        fs = store.FileStore(path, 16384)
        assert pf.load_plan(fs)[0] == pf.OK
        log = rf.ResultsLog(fs)
        log.mount()
        assert log.records == 1
        fs.close()
        try:
            store.FileStore(path, 8192)
        except store.StoreError as e:
            assert "16384 bytes" in str(e) and "8192" in str(e)
        else:
            raise AssertionError("a longer file was taken as a store")
        fs = store.FileStore(path, 20000)  # a shorter file is extended with 0xFF
        assert fs.read(16384, 16) == b"\xff" * 16 and pf.load_plan(fs)[0] == pf.OK
        fs.close()
    finally:
        try:
            os.remove(path)
        except OSError:
            pass
