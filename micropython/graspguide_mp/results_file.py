"""The results log in the store after the plan region: results_log.h's slots, byte for byte.

A slot (72 bytes) is erased (all 0xFF), valid, or torn. Layout: magic "GGLR", plan_id, the
record (the plan trial, success, completion_s, first_entry_s, final_error_deg, samples,
imu_faults), zero padding, CRC-32 of all that, and the commit byte 0xA5, written last: a
write cut at any byte leaves the commit byte erased, so the slot reads torn. Torn slots
are counted and skipped, never returned and never written again; appends go after the
last written slot, and a full log refuses (nothing overwritten)."""

import struct

from graspguide_mp import plan_file as pf
from graspguide_mp.store import crc32

LOG_MAGIC = 0x524C4747  # "GGLR"
COMMIT_BYTE = 0xA5
RECORD_BYTES = pf.TRIAL_BYTES + 1 + 3 * 4 + 4 + 2
SLOT_ALIGN_BYTES = 8
SLOT_BYTES = (
    (4 + 4 + RECORD_BYTES + 4 + 1 + SLOT_ALIGN_BYTES - 1) // SLOT_ALIGN_BYTES * SLOT_ALIGN_BYTES
)
CRC_OFFSET = SLOT_BYTES - 5
COMMIT_OFFSET = SLOT_BYTES - 1
MAX_SLOTS = 0xFFFF
ERASE_CHUNK_SLOTS = 8

_ERASED = 0
_VALID = 1
_TORN = 2
_REST_FMT = "<BfffIH"
_ERASED_SLOT = b"\xff" * SLOT_BYTES


class LogRecord:
    def __init__(self, trial=None):
        self.trial = trial if trial is not None else pf.PlanTrial()
        self.success = False
        self.completion_s = 0.0
        self.first_entry_s = -1.0
        self.final_error_deg = 0.0
        self.samples = 0
        self.imu_faults = 0


def encode_slot(r, plan_id):
    body = (
        struct.pack("<II", LOG_MAGIC, plan_id)
        + pf.encode_trial(r.trial)
        + struct.pack(
            _REST_FMT,
            1 if r.success else 0,
            r.completion_s,
            r.first_entry_s,
            r.final_error_deg,
            r.samples,
            r.imu_faults,
        )
    )
    body += b"\0" * (CRC_OFFSET - len(body))
    return body + struct.pack("<I", crc32(body)) + bytes((COMMIT_BYTE,))


def classify(slot):
    """(kind, record or None, plan_id)."""
    if slot == _ERASED_SLOT:
        return _ERASED, None, 0
    if slot[COMMIT_OFFSET] != COMMIT_BYTE:
        return _TORN, None, 0
    (crc,) = struct.unpack("<I", slot[CRC_OFFSET : CRC_OFFSET + 4])
    if crc != crc32(slot[:CRC_OFFSET]):
        return _TORN, None, 0
    magic, plan_id = struct.unpack("<II", slot[:8])
    if magic != LOG_MAGIC:
        return _TORN, None, 0
    t = pf.decode_trial(slot[8 : 8 + pf.TRIAL_BYTES])
    at = 8 + pf.TRIAL_BYTES
    v = struct.unpack(_REST_FMT, slot[at : at + RECORD_BYTES - pf.TRIAL_BYTES])
    if t is None or v[0] > 1:
        return _TORN, None, 0
    r = LogRecord(t)
    r.success = v[0] == 1
    r.completion_s, r.first_entry_s, r.final_error_deg, r.samples, r.imu_faults = v[1:]
    return _VALID, r, plan_id


class ResultsLog:
    def __init__(self, store):
        self.store = store
        self.mounted = False
        self.capacity = 0
        self._reset_counts()

    def _reset_counts(self):
        self.records = 0
        self.torn = 0
        self.next_slot = 0
        self._first_plan_id = 0
        self._mixed_plans = False

    @staticmethod
    def slot_offset(s):
        return pf.REGION_BYTES + s * SLOT_BYTES

    def mount(self):
        """Scans every slot (an erase cut by a power loss may leave erased slots in front
        of old records): OK, TOO_SMALL or STORAGE_FAILED."""
        self._reset_counts()
        self.mounted = False
        size = self.store.size_bytes()
        if size < pf.REGION_BYTES + SLOT_BYTES:
            return pf.TOO_SMALL
        slots = (size - pf.REGION_BYTES) // SLOT_BYTES
        self.capacity = slots if slots < MAX_SLOTS else MAX_SLOTS
        for i in range(self.capacity):
            slot = self.store.read(self.slot_offset(i), SLOT_BYTES)
            if slot is None:
                self._reset_counts()
                return pf.STORAGE_FAILED
            kind, _, plan_id = classify(slot)
            if kind == _ERASED:
                continue
            self._count(kind, plan_id)
            self.next_slot = i + 1
        self.mounted = True
        return pf.OK

    def full(self):
        return self.next_slot >= self.capacity

    def append(self, r, plan_id):
        """OK; FULL (nothing written); STORAGE_FAILED (not mounted, or the write failed:
        the slot is then counted as a remount would see it)."""
        if not self.mounted:
            return pf.STORAGE_FAILED
        if self.full():
            return pf.FULL
        slot = encode_slot(r, plan_id)
        at = self.slot_offset(self.next_slot)
        if self.store.write(at, slot):
            self._count(_VALID, plan_id)
            self.next_slot += 1
            return pf.OK
        back = self.store.read(at, SLOT_BYTES)
        if back is None:
            # What the slot holds is unknown: never write it again, and call it torn.
            self.torn += 1
            self.next_slot += 1
            return pf.STORAGE_FAILED
        kind, _, pid = classify(back)
        if kind != _ERASED:
            self._count(kind, pid)
            self.next_slot += 1
        return pf.STORAGE_FAILED

    def read(self, index):
        """(status, record, plan_id) of the index-th valid record (0 = oldest)."""
        if index >= self.records:
            return pf.NO_RECORD, None, 0
        valid = 0
        for s in range(self.next_slot):
            slot = self.store.read(self.slot_offset(s), SLOT_BYTES)
            if slot is None:
                return pf.STORAGE_FAILED, None, 0
            kind, r, pid = classify(slot)
            if kind != _VALID:
                continue
            if valid == index:
                return pf.OK, r, pid
            valid += 1
        return pf.STORAGE_FAILED, None, 0

    def trial_indices(self, plan_id):
        """The trial_index of every valid record made under plan_id, oldest first, in one
        pass over the slots; None when a read fails."""
        out = []
        for s in range(self.next_slot):
            slot = self.store.read(self.slot_offset(s), SLOT_BYTES)
            if slot is None:
                return None
            kind, r, pid = classify(slot)
            if kind == _VALID and pid == plan_id:
                out.append(r.trial.trial_index)
        return out

    def erase(self):
        """Every slot back to 0xFF from the last to the first (the plan region is not
        touched), then a remount."""
        if self.capacity == 0:
            m = self.mount()
            if m != pf.OK:
                return m
        end = self.capacity
        while end > 0:
            n = end if end < ERASE_CHUNK_SLOTS else ERASE_CHUNK_SLOTS
            end -= n
            if not self.store.write(self.slot_offset(end), b"\xff" * (n * SLOT_BYTES)):
                self.mount()
                return pf.STORAGE_FAILED
        return self.mount()

    def holds_other_plan(self, plan_id):
        if self.records == 0:
            return False
        return self._mixed_plans or self._first_plan_id != plan_id

    def _count(self, kind, plan_id):
        if kind == _TORN:
            self.torn += 1
            return
        if kind != _VALID:
            return
        if self.records == 0:
            self._first_plan_id = plan_id
        elif plan_id != self._first_plan_id:
            self._mixed_plans = True
        self.records += 1
