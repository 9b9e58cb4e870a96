"""The study plan in the store: plan_store.h's region at offset 0, byte for byte.

Preamble (16 bytes): magic "GGPL", layout version, reserved 0, payload length, payload
CRC-32; then the header (168 bytes: PLAN_BEGIN's fields, the participant's motor
calibration last) and trial_count trials (35 bytes each), little-endian field by field.
A plan of an older layout (version 1 had no calibration) loads as OLD_LAYOUT: never read
with this layout's fields, and named so the plan can be stored again. Saving zeroes the
old magic first and writes the new one last, so a cut at any byte leaves the old plan or
no plan, never a wrong one. The range checks are
study_plan.h's check_header / check_trial, with the same field indices."""

import math
import struct

from graspguide_mp import frame
from graspguide_mp.store import crc32

MAX_PLAN_TRIALS = 128
PARTICIPANT_BYTES = 8
CONFIG_HASH_BYTES = 8
HEADER_BYTES = 168
TRIAL_BYTES = 35
PREAMBLE_BYTES = 16
PLAN_MAGIC = 0x4C504747  # "GGPL"
# 2: the header ends with the calibration (pwm_floor u8[4], gain f32[4]).
LAYOUT_VERSION = 2
SECTOR_BYTES = 4096
REGION_BYTES = (
    (PREAMBLE_BYTES + HEADER_BYTES + TRIAL_BYTES * MAX_PLAN_TRIALS + SECTOR_BYTES - 1)
    // SECTOR_BYTES
    * SECTOR_BYTES
)

REST_MAX_S = 600.0
HAND_MAX_M = 1.0
QUAT_NORM_MIN = 0.5
QUAT_NORM_MAX = 2.0
CONSTRAINTS_MAX = 2
POLICY_MAX = 1
MODE_MAX = 1
WRENCH_CLASS_MAX = 2
# The calibration's ranges (motor_calibration.h; tools/graspguide/core/motor_calibration.py).
CALIBRATION_FLOOR_MAX = 254
CALIBRATION_GAIN_MIN = 0.25
CALIBRATION_GAIN_MAX = 4.0

# PLAN_BEGIN's fields in the schema's order: the index is what a refusal reports.
HEADER_FIELDS = (
    "participant",
    "simulated",
    "config_hash",
    "trial_count",
    "constraints",
    "y_axis",
    "threshold_deg",
    "hold_s",
    "timeout_s",
    "rest_s",
    "hand_k3",
    "hand_k4",
    "imu_to_hand_wxyz",
    "pwm_floor",
    "gain",
)
TRIAL_FIELDS = (
    "position",
    "trial_index",
    "session",
    "session_trial",
    "k",
    "policy",
    "mode",
    "familiarization",
    "single_motor",
    "wrench_class",
    "wrench_number",
    "wrench",
)

# Store results (plan_store.h's StoreStatus), shared with results_file.
OK = 0
NO_PLAN = 1
FULL = 2
STORAGE_FAILED = 3
TOO_SMALL = 4
NO_RECORD = 5
BAD_PLAN = 6
OLD_LAYOUT = 7  # a whole plan of another layout version: store the plan again
STORE_STATUS_NAMES = (
    "ok",
    "no_plan",
    "full",
    "storage_failed",
    "too_small",
    "no_record",
    "bad_plan",
    "old_layout",
)

# What to do about a plan of an older layout: main.py prints it.
OLD_LAYOUT_FIX = (
    "the plan was written for an older firmware (plan layout before version %d, without the"
    " motor calibration): write it again with `graspguide plan` (or `graspguide mp deploy"
    " --plan-protocol`)" % LAYOUT_VERSION
)

_HEADER_FMT = "<8sB8sHB3f4f9f12f4f4B4f"
_TRIAL_FMT = "<HBBBBBBBBB6f"
_PREAMBLE_FMT = "<IHHII"


class PlanHeader:
    def __init__(self):
        self.participant = b"\0" * PARTICIPANT_BYTES
        self.simulated = False
        self.config_hash = b"\0" * CONFIG_HASH_BYTES
        self.trial_count = 0
        self.constraints = 0
        self.y_axis = [0.0, 1.0, 0.0]
        self.threshold_deg = 3.0
        self.hold_s = 0.5
        self.timeout_s = 90.0
        self.rest_s = 2.0
        self.hand_k3 = [[0.0, 0.0, 0.0] for _ in range(3)]
        self.hand_k4 = [[0.0, 0.0, 0.0] for _ in range(4)]
        self.imu_to_hand_wxyz = [1.0, 0.0, 0.0, 0.0]
        # The participant's calibration (graspguide calibrate); identity = the paper's PWM.
        self.pwm_floor = list(frame.IDENTITY_FLOOR)
        self.gain = list(frame.IDENTITY_GAIN)

    def participant_name(self):
        return self.participant.split(b"\0")[0].decode()


class PlanTrial:
    def __init__(self):
        self.trial_index = 0
        self.session = 0
        self.session_trial = 0
        self.k = 3
        self.policy = 0
        self.mode = 0
        self.familiarization = False
        self.single_motor = False
        self.wrench_class = 0
        self.wrench_number = 0
        self.wrench = [0.0] * 6

    def same(self, other):
        return encode_trial(self) == encode_trial(other)


class Plan:
    def __init__(self, header=None, trials=None):
        self.header = header if header is not None else PlanHeader()
        self.trials = trials if trials is not None else []


class PlanError(ValueError):
    """A plan field out of range: .field names it (the schema's name), .index is its
    PLAN_BEGIN / PLAN_TRIAL index as the C++ device reports it."""

    def __init__(self, what, field, index, message):
        super().__init__("%s field %s: %s" % (what, field, message))
        self.field = field
        self.index = index


# ---------------------------------------------------------------- codec
def encode_header(h):
    flat = []
    for row in h.hand_k3:
        flat.extend(row)
    flat4 = []
    for row in h.hand_k4:
        flat4.extend(row)
    return struct.pack(
        _HEADER_FMT,
        bytes(h.participant),
        1 if h.simulated else 0,
        bytes(h.config_hash),
        h.trial_count,
        h.constraints,
        *(
            list(h.y_axis)
            + [h.threshold_deg, h.hold_s, h.timeout_s, h.rest_s]
            + flat
            + flat4
            + list(h.imu_to_hand_wxyz)
            + list(h.pwm_floor)
            + list(h.gain)
        ),
    )


def decode_header(b):
    """A PlanHeader from its 168 bytes, or None when a stored bool is not 0 or 1 (not
    data this code wrote)."""
    v = struct.unpack(_HEADER_FMT, b)
    if v[1] > 1:
        return None
    h = PlanHeader()
    h.participant = v[0]
    h.simulated = v[1] == 1
    h.config_hash = v[2]
    h.trial_count = v[3]
    h.constraints = v[4]
    f = v[5:]
    h.y_axis = list(f[0:3])
    h.threshold_deg, h.hold_s, h.timeout_s, h.rest_s = f[3:7]
    h.hand_k3 = [list(f[7 + 3 * i : 10 + 3 * i]) for i in range(3)]
    h.hand_k4 = [list(f[16 + 3 * i : 19 + 3 * i]) for i in range(4)]
    h.imu_to_hand_wxyz = list(f[28:32])
    h.pwm_floor = list(f[32:36])
    h.gain = list(f[36:40])
    return h


def encode_trial(t):
    return struct.pack(
        _TRIAL_FMT,
        t.trial_index,
        t.session,
        t.session_trial,
        t.k,
        t.policy,
        t.mode,
        1 if t.familiarization else 0,
        1 if t.single_motor else 0,
        t.wrench_class,
        t.wrench_number,
        *t.wrench,
    )


def decode_trial(b):
    v = struct.unpack(_TRIAL_FMT, b)
    if v[6] > 1 or v[7] > 1:
        return None
    t = PlanTrial()
    t.trial_index, t.session, t.session_trial, t.k, t.policy, t.mode = v[0:6]
    t.familiarization = v[6] == 1
    t.single_motor = v[7] == 1
    t.wrench_class = v[8]
    t.wrench_number = v[9]
    t.wrench = list(v[10:16])
    return t


def encode_plan(p):
    parts = [encode_header(p.header)]
    n = p.header.trial_count if p.header.trial_count <= MAX_PLAN_TRIALS else 0
    for i in range(n):
        parts.append(encode_trial(p.trials[i]))
    return b"".join(parts)


def payload_bytes(trial_count):
    return HEADER_BYTES + TRIAL_BYTES * trial_count


def plan_id(p):
    """CRC-32 of the plan's stored bytes: names the plan in the preamble and in every
    log record made under it."""
    return crc32(encode_plan(p))


# ---------------------------------------------------------------- checks
def _finite(v):
    return -math.inf < v < math.inf


def _all_within(vals, limit):
    for v in vals:
        if not abs(v) <= limit:  # NaN too
            return False
    return True


def _participant_ok(p):
    if len(p) != PARTICIPANT_BYTES or p[0] == 0:
        return False
    ended = False
    for c in p:
        if ended:
            if c != 0:
                return False
        elif c == 0:
            ended = True
        elif c < 0x20 or c > 0x7E:
            return False
    return True


def _header_fail(i, message):
    raise PlanError("PLAN_BEGIN", HEADER_FIELDS[i], i, message)


def check_header(h):
    """Raises PlanError naming the first bad PLAN_BEGIN field, as check_header does."""
    if not _participant_ok(bytes(h.participant)):
        _header_fail(0, "8 bytes of printable ASCII, NUL-padded, not empty (e.g. b'U1')")
    if not 1 <= h.trial_count <= MAX_PLAN_TRIALS:
        _header_fail(3, "1..%d trials, got %r" % (MAX_PLAN_TRIALS, h.trial_count))
    if not 0 <= h.constraints <= CONSTRAINTS_MAX:
        _header_fail(4, "0 paper, 1 normal or 2 none, got %r" % (h.constraints,))
    y = h.y_axis
    if not (_finite(y[0]) and _finite(y[1]) and _finite(y[2])) or (y[0] == y[1] == y[2] == 0):
        _header_fail(5, "a finite non-zero vector, got %r" % (y,))
    bad = frame.trial_config_field(h.threshold_deg, h.hold_s, h.timeout_s)
    if bad is not None:
        _header_fail(
            HEADER_FIELDS.index(bad),
            "0 <= threshold_deg <= 180, 0 <= hold_s <= 600, hold_s <= timeout_s,"
            " 0 < timeout_s <= 1800",
        )
    if not 0.0 <= h.rest_s <= REST_MAX_S:
        _header_fail(9, "0..%g s, got %r" % (REST_MAX_S, h.rest_s))
    for i, rows in ((10, h.hand_k3), (11, h.hand_k4)):
        for row in rows:
            if not _all_within(row, HAND_MAX_M):
                _header_fail(i, "contacts within %g m of the hand frame's origin" % HAND_MAX_M)
    q = h.imu_to_hand_wxyz
    if not (_finite(q[0]) and _finite(q[1]) and _finite(q[2]) and _finite(q[3])):
        _header_fail(12, "four finite numbers (w, x, y, z)")
    n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if not QUAT_NORM_MIN * QUAT_NORM_MIN <= n2 <= QUAT_NORM_MAX * QUAT_NORM_MAX:
        _header_fail(12, "a unit quaternion (norm within 0.5..2), got %r" % (q,))
    fl = h.pwm_floor
    if len(fl) != frame.CALIBRATION_MOTORS or not all(
        isinstance(v, int) and 0 <= v <= CALIBRATION_FLOOR_MAX for v in fl
    ):
        _header_fail(
            13, "4 PWM counts 0..%d (the identity is 70), got %r" % (CALIBRATION_FLOOR_MAX, fl)
        )
    g = h.gain
    if len(g) != frame.CALIBRATION_MOTORS or not all(
        CALIBRATION_GAIN_MIN <= v <= CALIBRATION_GAIN_MAX
        for v in g  # NaN too
    ):
        _header_fail(
            14,
            "4 numbers %g..%g (1 = the paper's mapping), got %r"
            % (CALIBRATION_GAIN_MIN, CALIBRATION_GAIN_MAX, g),
        )


def check_trial(t):
    """Raises PlanError naming the first bad PLAN_TRIAL field, as check_trial does."""

    def fail(i, message):
        raise PlanError("PLAN_TRIAL", TRIAL_FIELDS[i], i, message)

    if t.trial_index < 1:
        fail(1, "trials are numbered from 1")
    if t.session_trial < 1:
        fail(3, "session trials are numbered from 1")
    if t.k not in (3, 4):
        fail(4, "3 or 4 contacts, got %r" % (t.k,))
    if not 0 <= t.policy <= POLICY_MAX:
        fail(5, "0 F or 1 Fperp, got %r" % (t.policy,))
    if not 0 <= t.mode <= MODE_MAX:
        fail(6, "0 C or 1 V, got %r" % (t.mode,))
    if not 0 <= t.wrench_class <= WRENCH_CLASS_MAX:
        fail(9, "0 none, 1 single or 2 multi, got %r" % (t.wrench_class,))
    w = t.wrench
    if len(w) != 6 or not all(_finite(v) for v in w) or (w[0] == w[1] == w[2] == 0):
        fail(11, "six finite numbers with a non-zero force part, got %r" % (w,))


def check_plan(p):
    check_header(p.header)
    if len(p.trials) < p.header.trial_count:
        _header_fail(3, "%d trials declared, %d given" % (p.header.trial_count, len(p.trials)))
    for i in range(p.header.trial_count):
        check_trial(p.trials[i])


def plan_ok(p):
    try:
        check_plan(p)
    except PlanError:
        return False
    return True


# ---------------------------------------------------------------- the region
def save_plan(store, p):
    """OK, TOO_SMALL, BAD_PLAN (nothing written) or STORAGE_FAILED."""
    if store.size_bytes() < REGION_BYTES:
        return TOO_SMALL
    if not plan_ok(p):
        return BAD_PLAN
    if not store.write(0, b"\0\0\0\0"):
        return STORAGE_FAILED
    payload = encode_plan(p)
    # In 64-byte writes, as the C++ StoreSink does: a cut then tears the same way.
    for at in range(0, len(payload), 64):
        if not store.write(PREAMBLE_BYTES + at, payload[at : at + 64]):
            return STORAGE_FAILED
    pre = struct.pack(_PREAMBLE_FMT, PLAN_MAGIC, LAYOUT_VERSION, 0, len(payload), crc32(payload))
    if not store.write(4, pre[4:]):
        return STORAGE_FAILED
    if not store.write(0, pre[:4]):
        return STORAGE_FAILED
    return OK


def load_plan(store):
    """(status, plan or None): OK with the stored plan; OLD_LAYOUT when the region holds a
    plan of an older layout version (its magic is written last, so that plan was whole);
    NO_PLAN when it holds no complete, intact plan of this layout that passes the checks;
    STORAGE_FAILED on a read fault; TOO_SMALL."""
    if store.size_bytes() < REGION_BYTES:
        return TOO_SMALL, None
    pre = store.read(0, PREAMBLE_BYTES)
    if pre is None:
        return STORAGE_FAILED, None
    magic, version, reserved, length, crc = struct.unpack(_PREAMBLE_FMT, pre)
    if magic == PLAN_MAGIC and reserved == 0 and 1 <= version < LAYOUT_VERSION:
        # A plan stored by an older firmware: its bytes mean other fields here.
        return OLD_LAYOUT, None
    if (
        magic != PLAN_MAGIC
        or version != LAYOUT_VERSION
        or reserved != 0
        or not payload_bytes(1) <= length <= payload_bytes(MAX_PLAN_TRIALS)
    ):
        return NO_PLAN, None
    payload = store.read(PREAMBLE_BYTES, length)
    if payload is None:
        return STORAGE_FAILED, None
    if crc32(payload) != crc:
        return NO_PLAN, None
    h = decode_header(payload[:HEADER_BYTES])
    if h is None or not 1 <= h.trial_count <= MAX_PLAN_TRIALS:
        return NO_PLAN, None
    if length != payload_bytes(h.trial_count):
        return NO_PLAN, None
    trials = []
    for i in range(h.trial_count):
        at = HEADER_BYTES + TRIAL_BYTES * i
        t = decode_trial(payload[at : at + TRIAL_BYTES])
        if t is None:
            return NO_PLAN, None
        trials.append(t)
    p = Plan(h, trials)
    # The CRC vouches for the bytes; the checks for what this port can run.
    if not plan_ok(p):
        return NO_PLAN, None
    return OK, p
