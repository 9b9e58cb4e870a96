"""Talk to a GraspGuide device (a board or the simulated device) over the serial protocol
of docs/protocol.md.

>>> from graspguide.devices.registry import open_port
>>> from graspguide.link.client import DeviceClient
>>> with DeviceClient(open_port("sim")) as dev:
...     info = dev.hello()
...     dev.set_scene(contacts, policy="F", mode="V")
...     dev.start_trial(1, wrench)
...     tel = dev.pose(t_us, quat)          # one POSE -> its TELEMETRY
...     answers = dev.pose_batch(poses)  # pipelined: each POSE's TELEMETRY or ERROR
...     dev.stop()

Requests are numbered by a :class:`SequenceCounter` and their answers matched by seq
(ACK, ERROR, HELLO_REPLY carry ``request_seq``); a POSE's TELEMETRY is matched by its
echoed ``host_time_us`` and order, a GET_STATUS by the next STATUS. Frames that answer
nothing pending are kept, never dropped: TRIAL_RESULTs in :attr:`DeviceClient.trial_results`,
unmatched TELEMETRY in :attr:`DeviceClient.telemetry_backlog`, the rest in
:attr:`DeviceClient.unmatched`.

Errors (all :class:`LinkError` subclasses): :class:`DeviceError` (the device answered
ERROR: ``code`` is the generated :class:`ErrorCode`, ``code_name`` its schema name,
``detail``, ``meaning``), :class:`LinkTimeout` (no answer within the per-request
``timeout``; the message says what was and was not received), :class:`ProtocolMismatch`
(the device speaks another protocol version), :class:`DeviceDisconnected`,
:class:`DeviceNotFound`.

Not thread-safe: one thread talks to one client.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import time
from binascii import crc_hqx as _crc_hqx
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

from graspguide.core.motor_calibration import MotorCalibration
from graspguide.core.vocabulary import CONSTRAINT_MODELS, MODES, POLICIES
from graspguide.link.codec import (
    COBS_MAX_BLOCK_DATA,
    COBS_MAX_CODE,
    CRC,
    CRC16_INIT,
    HEADER,
    Accept,
    FrameParser,
    ParseEvent,
    SequenceCounter,
    check_frame,
    cobs_decode,
    cobs_encode,
    encode_message,
    message_of,
)
from graspguide.link.errors import BadCobsError, BadEnumValueError, ProtocolError
from graspguide.link.messages import (
    CAPABILITY_FULL_SOLVE,
    CAPABILITY_PER_FRAME,
    ERROR_MEANINGS,
    LINK_ERROR_BASE,
    LOG_ERASE_KEY,
    MAX_CONTACTS,
    MESSAGES,
    PROTOCOL_VERSION,
    TELEMETRY_FLAG_TRIAL_RUNNING,
    Ack,
    ConstraintModel,
    DeviceState,
    Error,
    ErrorCode,
    GetStatus,
    Hello,
    HelloReply,
    HostlessEvent,
    HostlessRun,
    LogErase,
    LogInfo,
    LogInfoGet,
    LogRead,
    LogRecord,
    Mode,
    MsgId,
    PlanBegin,
    PlanCommit,
    PlanTrial,
    Policy,
    Pose,
    SetCalibration,
    SetMotors,
    SetPosture,
    SetScene,
    SimButton,
    SimImuSample,
    StartTrial,
    Status,
    Stop,
    Telemetry,
    TrialResult,
)
from graspguide.link.transport import (
    DeviceDisconnected,
    DeviceNotFound,
    LinkError,
    LinkTimeout,
    SimNotBuilt,
    Transport,
)

DEFAULT_TIMEOUT = 1.0  # s, per request: a board answers in a few ms at 115200 baud
READ_CHUNK = 4096  # bytes per transport read
POLL_INTERVAL = 0.05  # s, longest single blocking read (keeps deadlines responsive)
# PLAN_COMMIT solves every trial of the plan once before it answers (100 solves, plus a
# write to non-volatile storage): a board needs longer than for one request.
PLAN_COMMIT_TIMEOUT_S = 10.0

# Fast paths of the per-pose traffic (a study streams ~10^6 POSE/TELEMETRY pairs): a POSE
# without contacts packed by the generated Pose.STRUCT with its all-zero tail's COBS blocks
# precomputed, and a TELEMETRY unpacked by Telemetry.STRUCT straight into its dataclass;
# framing, CRC and COBS are codec's. Anything unusual (a bad CRC, a broken COBS block, an
# enum value out of its set, another message) goes through the byte-wise FrameParser and
# the generic codecs, so counters and events are those of the reference path; tests check
# both agree.
_POSE_ID = int(MsgId.POSE)
# encode_pose_fast packs by position and relies on everything after quat_wxyz being zero.
assert tuple(s.name for s in Pose.FIELDS) == (
    "host_time_us",
    "quat_wxyz",
    "has_contacts",
    "contacts",
)
_POSE_HEAD = struct.Struct(HEADER.format + Pose.FIELDS[0].format + Pose.FIELDS[1].format)
_POSE_TAIL_COBS = b"\x01" * (HEADER.size + Pose.STRUCT.size - _POSE_HEAD.size - 1)
_POSE_ZEROS = bytes(len(_POSE_TAIL_COBS) + 1)
_COBS_CODE = [bytes((n + 1,)) for n in range(COBS_MAX_BLOCK_DATA)]
_TELEMETRY_ID = int(MsgId.TELEMETRY)
# A whole decoded TELEMETRY frame (header, payload, CRC) in one unpack.
_TELEMETRY_FRAME = struct.Struct(HEADER.format + Telemetry.STRUCT.format[1:] + CRC.format[1:])
_TELEMETRY_BODY = _TELEMETRY_FRAME.size - CRC.size
_TELEMETRY_WIRE = _TELEMETRY_FRAME.size + 1
assert _TELEMETRY_WIRE < COBS_MAX_CODE  # one COBS block: _telemetry_frame relies on it
# _telemetry_frame assigns the flattened values by position: a schema change must show here.
assert [spec.name for spec in Telemetry.FIELDS] == [
    "host_time_us",
    "error_deg",
    "alpha",
    "pwm",
    "constraints_used",
    "solver_status",
    "iterations",
    "flags",
    "compute_time_us",
]
_CONSTRAINT_BY_VALUE = {int(e): e for e in ConstraintModel}
_ERRORCODE_BY_VALUE = {int(e): e for e in ErrorCode}
_set = object.__setattr__
_new = object.__new__
# DeviceClient.counters(): the totals by attribute name, and each queue's count by the name
# it is reported under.
_TOTALS = ("bytes_received", "frames_received", "host_bad_frames", "device_frames_lost")
_QUEUES = {
    "trial_results_queued": "trial_results",
    "hostless_events_queued": "hostless_events",
    "unmatched": "unmatched",
    "telemetry_backlog": "telemetry_backlog",
}


def _cobs_crc(crc: int) -> bytes:
    """The COBS blocks of a CRC's two bytes (little-endian), which end a POSE's frame."""
    lo, hi = crc & 0xFF, crc >> 8
    if lo and hi:
        return bytes((3, lo, hi))
    if hi:
        return bytes((1, 2, hi))
    return bytes((2, lo, 1)) if lo else b"\x01\x01\x01"


def encode_pose_fast(seq: int, t_us: int, quat: Sequence[float]) -> bytes | None:
    """The wire bytes of a POSE without contacts, or None when a value needs the generic
    path (a quaternion component beyond the float32 range, not a number).

    The frame is a head (header, host_time_us, quat_wxyz), zero bytes, then the CRC: its
    COBS is the head's blocks (the last one ended by the first zero), one 0x01 block per
    further zero, then the CRC's blocks."""
    try:
        w, x, y, z = quat
        head = _POSE_HEAD.pack(PROTOCOL_VERSION, _POSE_ID, seq, int(t_us) & 0xFFFFFFFF, w, x, y, z)
    except (OverflowError, struct.error, TypeError, ValueError):
        return None
    # The CRC continued over the zeros: the same as crc16(head + zeros), without the copy.
    crc = _crc_hqx(_POSE_ZEROS, _crc_hqx(head, CRC16_INIT))
    if len(head) < COBS_MAX_BLOCK_DATA:  # always: one COBS block per zero, split in C
        blocks = b"".join([_COBS_CODE[len(part)] + part for part in head.split(b"\0")])
    else:  # pragma: no cover - a schema with a head this long
        blocks = cobs_encode(head)
    return blocks + _POSE_TAIL_COBS + _cobs_crc(crc) + b"\0"


def _telemetry_frame(enc: bytes) -> tuple[int, Telemetry] | None:
    """(seq, TELEMETRY) of one frame off the wire (COBS, no delimiter) without the generic
    decoders; None for anything else: another message or version, a broken COBS block, a
    bad CRC, an enum value not in its set (the generic path then counts it)."""
    n = len(enc)
    # COBS adds one byte to a frame this short; version and id are its first block's.
    if n != _TELEMETRY_WIRE or enc[0] < 3 or enc[2] != _TELEMETRY_ID or 0 in enc:
        return None
    # COBS decoding of a frame shorter than one full block: each code byte but the first
    # becomes the zero it stands for.
    raw = bytearray(enc)
    j = raw[0]
    while j < n:
        code = raw[j]
        raw[j] = 0
        j += code
    if j != n:
        return None
    del raw[0]
    (
        version,
        _,
        seq,
        t_us,
        err,
        alpha,
        p0,
        p1,
        p2,
        p3,
        used,
        status,
        iters,
        flags,
        compute,
        crc,
    ) = _TELEMETRY_FRAME.unpack(raw)
    if version != PROTOCOL_VERSION or _crc_hqx(raw[:_TELEMETRY_BODY], CRC16_INIT) != crc:
        return None
    used_e = _CONSTRAINT_BY_VALUE.get(used)
    status_e = _ERRORCODE_BY_VALUE.get(status)
    if used_e is None or status_e is None:
        return None
    tel = _new(Telemetry)
    # The frozen dataclass's fields set at once, as its __init__ would.
    _set(
        tel,
        "__dict__",
        {
            "host_time_us": t_us,
            "error_deg": err,
            "alpha": alpha,
            "pwm": (p0, p1, p2, p3),
            "constraints_used": used_e,
            "solver_status": status_e,
            "iterations": iters,
            "flags": flags,
            "compute_time_us": compute,
        },
    )
    return seq, tel


# The names the core and `graspguide solve` use (the vocabulary), and the wire enums.
POLICY_NAMES = {name: Policy[name.upper()] for name in POLICIES}
MODE_NAMES = {name: Mode[name.upper()] for name in MODES}
CONSTRAINT_NAMES = {name: ConstraintModel[name.upper()] for name in CONSTRAINT_MODELS}
_F32 = struct.Struct("<f")
_POLICY_NAME = {v: k for k, v in POLICY_NAMES.items()}
_MODE_NAME = {v: k for k, v in MODE_NAMES.items()}
_CONSTRAINT_NAME = {v: k for k, v in CONSTRAINT_NAMES.items()}
# What a DeviceError raised for the host's own solve of a per-frame-only board's posture
# says instead of the device's word.
HOST_SOLVE_SOURCE = "host core"
# The core statuses of a scene's geometry, and a wrench to have a solve report them.
_GEOMETRY_STATUSES = frozenset(
    (
        "non_finite_input",
        "bad_contact_count",
        "bad_axis",
        "coincident_contacts",
        "imprecise_contacts",
    )
)
_PROBE_WRENCH = (0.0, 0.0, -1.0, 0.0, 0.0, 0.0)


def code_name(code: int | ErrorCode) -> str:
    """The schema name of an ErrorCode value (``"coincident_contacts"``), or ``"0x.."``."""
    try:
        return ErrorCode(code).name.lower()
    except ValueError:
        return f"0x{int(code):02x}"


def _msg_name(msg_id: int) -> str:
    cls = MESSAGES.get(msg_id)
    return cls.NAME if cls is not None else f"id 0x{msg_id:02X}"


# --------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------
class ProtocolMismatch(LinkError):
    """The device speaks another protocol version (HELLO_REPLY, or ERROR bad_version, or
    frames of another version)."""

    def __init__(self, message: str, device_version: int | None = None):
        super().__init__(message)
        self.device_version = device_version


class PerFrameOnly(LinkError):
    """A request a per-frame-only board (HELLO_REPLY without full_solve) cannot take, such
    as a POSE carrying contacts: the host solves the posture once per trial."""


class DeviceError(LinkError):
    """The device refused a request with ERROR (or a POSE's TELEMETRY carried a core
    status other than ok, when asked to raise for it).

    ``code`` (:class:`ErrorCode`, or int if unknown), ``code_name`` (the schema's name,
    e.g. ``"not_allowed_in_state"``), ``detail`` (the ERROR's detail byte), ``meaning``
    (the schema's text), ``request`` (the refused message's name), ``request_seq``.
    """

    def __init__(
        self,
        request: str,
        request_seq: int | None,
        code: int,
        detail: int = 0,
        source: str = "ERROR",
        context: str = "",
    ):
        try:
            self.code: ErrorCode | int = ErrorCode(code)
        except ValueError:
            self.code = int(code)
        self.code_name = code_name(code)
        self.detail = int(detail)
        self.request = request
        self.request_seq = request_seq
        self.source = source
        self.context = context
        self.meaning = ERROR_MEANINGS.get(self.code_name, "unknown error code")
        super().__init__(self._describe())

    def _detail_text(self) -> str:
        d, name = self.detail, self.code_name
        if name == "not_allowed_in_state":
            try:
                state = DeviceState(d).name.lower()
            except ValueError:
                state = f"state {d}"
            hint = {
                "trial_running": "send STOP first",
                "scene_set": "send START_TRIAL first",
                "stopped": "send START_TRIAL first (STOP ended the trial)",
                "idle": "send SET_SCENE first",
            }.get(state, "")
            return f"; the device is {state}" + (f": {hint}" if hint else "")
        if name == "no_scene":
            return f"; {_msg_name(d)} needs a valid SET_SCENE first"
        if name in ("unknown_id", "bad_length"):
            return f"; message {_msg_name(d)} (id 0x{d:02X})"
        if name == "bad_version":
            return f"; the device received protocol version {d}, it speaks {PROTOCOL_VERSION}"
        if name == "bad_enum_value":
            cls = next((c for c in MESSAGES.values() if c.NAME == self.request), None)
            if cls is not None and d < len(cls.FIELDS):
                return f"; field {cls.FIELDS[d].name!r} (index {d})"
            return f"; field index {d}"
        if name == "bad_config" and self.request == SetCalibration.NAME:
            return _calibration_field_text(d)
        if name == "bad_config" and self.request == SetScene.NAME:
            text = _trial_field_text(d)
            if text:
                return text
        if name == "bad_plan":
            return _plan_detail_text(self.request, d)
        if name == "no_plan":
            return (
                f"; {_msg_name(d)} needs a plan: PLAN_BEGIN before PLAN_TRIAL and "
                "PLAN_COMMIT, a stored plan before HOSTLESS_RUN (upload one with "
                "`graspguide trial --hostless`)"
            )
        if name == "sim_only":
            return f"; {_msg_name(d)} is for the simulated device only"
        if self.request == PlanCommit.NAME and int(self.code) < LINK_ERROR_BASE:
            # A core status of PLAN_COMMIT: the trial at this position cannot be solved.
            return f"; the plan's trial at position {d} cannot be solved"
        return f"; detail {d}" if d else ""

    def _describe(self) -> str:
        seq = "" if self.request_seq is None else f" (seq {self.request_seq})"
        verb = "refused" if self.source == "ERROR" else "could not solve"
        meaning = self.meaning.split("; detail = ")[0]  # the detail is spelled out below
        context = f" ({self.context})" if self.context else ""
        who = "the host's core" if self.source == HOST_SOLVE_SOURCE else "device"
        return (
            f"{who} {verb} {self.request}{seq}{context}: {self.code_name} -- "
            f"{meaning}{self._detail_text()}"
        )


def _calibration_field_text(index: int) -> str:
    """'; field 'gain' (index 1) ...' for SET_CALIBRATION's bad_config, with the range the
    device holds it to."""
    fields = SetCalibration.FIELDS
    if not 0 <= index < len(fields):
        return f"; detail {index}"
    name = fields[index].name
    rule = {
        "pwm_floor": "every floor must be 0..254 PWM counts",
        "gain": "every gain must be finite and in 0.25..4 (1 = the paper's mapping)",
    }.get(name, fields[index].doc)
    return f"; field {name!r} (index {index}): {rule}"


def _plan_detail_text(request: str, index: int) -> str:
    """What a bad_plan's detail names: the field of PLAN_BEGIN / PLAN_TRIAL (with the
    core's range for a trial setting, else the schema's description), the first missing
    trial of PLAN_COMMIT, the wrong key of LOG_ERASE."""
    if request == PlanCommit.NAME:
        return (
            f"; the plan's trial at position {index} is missing or the trial count differs "
            "from PLAN_BEGIN's: upload the whole plan again"
        )
    if request == LogErase.NAME:
        return f"; LOG_ERASE.key must be 0x{LOG_ERASE_KEY:08X}"
    cls: Any = {PlanBegin.NAME: PlanBegin, PlanTrial.NAME: PlanTrial}.get(request)
    if cls is None or not 0 <= index < len(cls.FIELDS):
        return f"; detail {index}"
    text = _trial_field_text(index, cls)
    if text:
        return text
    f = cls.FIELDS[index]
    return f"; field {f.name!r} (index {index}) is out of range: {f.doc}"


def _trial_field_text(index: int, cls: Any = SetScene) -> str:
    """'; field 'hold_s' (index 7) must be in [0, 600] s ...' for the SET_SCENE (or
    ``cls``) field a bad_config's detail names, with the core's range (TRIAL_LIMITS); ''
    when the index is not a trial field (a device that does not name it sends 0, the
    index of k)."""
    if not 0 <= index < len(cls.FIELDS):
        return ""
    f = cls.FIELDS[index]
    try:
        from graspguide.core._core import TRIAL_LIMITS  # type: ignore[import-untyped]
    except ImportError:  # pragma: no cover - host tools without the built extension
        TRIAL_LIMITS = {}
    r = TRIAL_LIMITS.get(f.name)
    if r is None:
        return ""
    unit = f" {f.unit}" if f.unit else ""
    low = "(" if r["min_exclusive"] else "["
    text = f"; field {f.name!r} (index {index}) must be in {low}{r['min']:g}, {r['max']:g}]{unit}"
    if f.name == "hold_s":
        text += " and at most timeout_s"
    return text


# --------------------------------------------------------------------------------------
# Values
# --------------------------------------------------------------------------------------
def to_f32(x: Any) -> float:
    """A number as float32 (round to nearest); beyond the float32 range it is +-inf, as
    C++ converts a double to float. NaN stays NaN."""
    x = float(x)
    try:
        return _F32.unpack(_F32.pack(x))[0]
    except (OverflowError, struct.error):
        return math.copysign(math.inf, x)


def _enum(value: Any, names: dict[str, Any], enum_cls, what: str):
    if isinstance(value, enum_cls):
        return value
    if isinstance(value, str):
        if value in names:
            return names[value]
        try:
            return enum_cls[value.upper()]
        except KeyError:
            pass
    elif isinstance(value, int) and not isinstance(value, bool):
        try:
            return enum_cls(value)
        except ValueError:
            pass
    raise ValueError(f"unknown {what} {value!r}; accepted: {', '.join(names)}")


def _contact_slots(contacts: Sequence[Sequence[float]] | None) -> tuple[int, tuple]:
    """(k, 4 slots of [x, y, z] float32). A count other than 3 or 4 is passed on as is
    (the device answers bad_contact_count); only the first 4 contacts fit the frame."""
    rows = [] if contacts is None else [list(r) for r in contacts]
    for i, r in enumerate(rows):
        if len(r) != 3:
            raise ValueError(f"contacts[{i}] must be [x, y, z], got {len(r)} numbers")
    k = min(len(rows), 255)
    slots = [tuple(to_f32(v) for v in r) for r in rows[:MAX_CONTACTS]]
    slots += [(0.0, 0.0, 0.0)] * (MAX_CONTACTS - len(slots))
    return k, tuple(slots)


def _floats(values: Sequence[float], n: int, what: str) -> tuple:
    values = list(values)
    if len(values) != n:
        raise ValueError(f"{what} must have {n} numbers, got {len(values)}")
    return tuple(to_f32(v) for v in values)


def calibration_message(cal: MotorCalibration | SetCalibration) -> SetCalibration:
    """SET_CALIBRATION of ``cal``, its gains rounded to float32 as the wire carries them. A
    SetCalibration goes as it is, unchecked: the device's own checks are then what answers
    (its tests send values a MotorCalibration refuses)."""
    if isinstance(cal, SetCalibration):
        return cal
    if not isinstance(cal, MotorCalibration):
        raise TypeError(
            f"calibration must be a MotorCalibration (graspguide.core.motor_calibration), got "
            f"{type(cal).__name__}"
        )
    return SetCalibration(
        pwm_floor=tuple(int(f) for f in cal.pwm_floor),
        gain=tuple(to_f32(g) for g in cal.gain),
    )


def host_time_us() -> int:
    """The host's monotonic clock in microseconds, wrapped to u32 (POSE.host_time_us)."""
    return (time.monotonic_ns() // 1000) & 0xFFFFFFFF


class _Received(NamedTuple):
    seq: int
    message: Any
    t_rx: float


# _Received(seq, message, t_rx) without its Python-level __new__ (one per frame received):
# _new_received(_Received, (seq, message, t_rx)).
_new_received = tuple.__new__


def _pose_answer(seq: int, t_us: int) -> Callable[[_Received], bool]:
    """What answers the POSE sent as ``seq`` at ``t_us``: its TELEMETRY (which carries the
    POSE's timestamp, not its seq) or the ERROR that refused it."""

    def is_answer(item: _Received) -> bool:
        m = item.message
        if type(m) is Telemetry:
            return m.host_time_us == t_us
        return isinstance(m, Error) and m.request_seq == seq

    return is_answer


# --------------------------------------------------------------------------------------
# Client
# --------------------------------------------------------------------------------------
class DeviceClient:
    """Requests to one device through a :class:`Transport`.

    ``timeout``: seconds to wait for each answer (per request; per POSE in a batch). On
    creation it sends one 0x00 so the device drops any partial frame (docs/protocol.md),
    and every write of frames starts with a 0x00 for the same reason.
    Counters of what the host saw: :attr:`host_bad_frames` (frames the host's parser or
    decoder rejected), :attr:`device_frames_lost` (gaps in the device's frame numbers),
    :attr:`frames_received`.
    """

    def __init__(
        self,
        transport: Transport,
        timeout: float = DEFAULT_TIMEOUT,
        send_idle_delimiter: bool = True,
    ):
        self.transport = transport
        self.timeout = float(timeout)
        self._seq = SequenceCounter()
        self._parser = FrameParser(Accept.DEVICE_TO_HOST)
        self._inbox: deque[_Received] = deque()
        self.trial_results: deque[TrialResult] = deque()
        self.telemetry_backlog: deque[Telemetry] = deque()
        self.unmatched: deque[Any] = deque()
        # HOSTLESS_EVENTs of a host-less run (unprompted), oldest first.
        self.hostless_events: list[HostlessEvent] = []
        self.device_info: HelloReply | None = None
        self.device_version: int | None = None  # set when frames of another version came
        self.bytes_received = 0
        self.frames_received = 0
        self.undecodable_frames = 0  # CRC passed but a field value is not in its set
        # Good TELEMETRY frames of the fast path: counted here, not in the parser's
        # counts (a dict keyed by an enum costs a Python-level hash per frame), and
        # added to them in parse_counts.
        self._fast_telemetry_frames = 0
        self.device_frames_lost = 0
        self._last_device_seq: int | None = None
        # The scene of a per-frame-only board: kept here, solved at start_trial.
        self._host_scene: SetScene | None = None
        if send_idle_delimiter:
            self.transport.write(b"\x00")

    # ---- context manager
    def close(self) -> None:
        self.transport.close()

    def __enter__(self) -> DeviceClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ---- counters
    @property
    def host_bad_frames(self) -> int:
        """Frames from the device the host dropped: parser errors (CRC, COBS, length,
        version, id) plus frames whose fields could not be decoded."""
        return self._parser.bad_frames + self.undecodable_frames

    @property
    def parse_counts(self) -> dict[str, int]:
        counts = {e.value: n for e, n in self._parser.counts.items()}
        counts[ParseEvent.FRAME.value] += self._fast_telemetry_frames
        counts["undecodable"] = self.undecodable_frames
        return counts

    def counters(self) -> dict[str, int]:
        """The totals under their attributes' names, then how many frames wait in each
        queue."""
        counts = {name: getattr(self, name) for name in _TOTALS}
        counts.update((name, len(getattr(self, queue))) for name, queue in _QUEUES.items())
        return counts

    # ---- receiving
    def _pump(self, timeout: float) -> int:
        """One read (waiting at most ``timeout`` s); parses it into the inbox. Returns the
        number of bytes read. Complete frames take the fast path (see _fast_frame); a
        partial frame and anything the fast path declines go byte-wise through the
        FrameParser."""
        data = self.transport.read(READ_CHUNK, timeout)
        if not data:
            return 0
        self.bytes_received += len(data)
        now = time.monotonic()
        parser = self._parser
        pos, n = 0, len(data)
        if parser._started or parser._dropping:  # finish a frame begun earlier
            end = data.find(0)
            if end < 0:
                self._push_bytes(data, now)
                return n
            self._push_bytes(data[: end + 1], now)
            pos = end + 1
        pieces = (data[pos:] if pos else data).split(b"\0")
        partial = pieces.pop()  # after the last delimiter: a frame still coming, or b""
        fast_frame = self._fast_frame
        for enc in pieces:
            if enc and not fast_frame(enc, now):
                self._push_bytes(enc + b"\0", now)
        if partial:
            self._push_bytes(partial, now)  # parser state
        return n

    def _fast_frame(self, enc: bytes, now: float) -> bool:
        """A complete, well-formed frame handled without the byte-wise parser; False when
        the parser must see it (anything unusual), with nothing changed."""
        fast = _telemetry_frame(enc)
        if fast is not None:
            # The common case (a study's ~10^6 TELEMETRY), _accept inlined.
            seq, msg = fast
            self._fast_telemetry_frames += 1
            self.frames_received += 1
            last = self._last_device_seq
            if last is not None:
                gap = (seq - last - 1) & 0xFFFF
                if gap < 0x8000:
                    self.device_frames_lost += gap
            self._last_device_seq = seq
            self._inbox.append(_new_received(_Received, (seq, msg, now)))
            return True
        try:
            raw = cobs_decode(enc)
        except BadCobsError:
            return False
        # Anything but a good frame (size, CRC, version, id, length) is the parser's.
        event, frame = check_frame(raw, self._parser.accept)
        if event is not ParseEvent.FRAME:
            return False
        self._parser.counts[ParseEvent.FRAME] += 1
        self._parser.frame = frame
        assert frame is not None  # check_frame's FRAME verdict carries it
        try:
            msg = message_of(frame)
        except (BadEnumValueError, ProtocolError):
            self.undecodable_frames += 1
            return True
        self._accept(frame.seq, msg, now)
        return True

    def _accept(self, seq: int, msg: Any, now: float) -> None:
        self.frames_received += 1
        if self._last_device_seq is not None:
            gap = (seq - self._last_device_seq - 1) & 0xFFFF
            if gap < 0x8000:
                self.device_frames_lost += gap
        self._last_device_seq = seq
        self._inbox.append(_Received(seq, msg, now))

    def _push_bytes(self, data: bytes, now: float) -> None:
        """The reference path: every byte through the FrameParser."""
        for byte in data:
            event = self._parser.push(byte)
            if event is ParseEvent.NONE:
                continue
            frame = self._parser.frame
            if frame is None:  # set by the first event with a trusted header, never unset
                continue
            if event is ParseEvent.BAD_VERSION:
                self.device_version = frame.version
                continue
            if event is not ParseEvent.FRAME:
                continue
            try:
                msg = message_of(frame)
            except (BadEnumValueError, ProtocolError):
                self.undecodable_frames += 1
                continue
            self._accept(frame.seq, msg, now)

    def _park(self, item: _Received) -> None:
        """Keep a frame that answers nothing pending."""
        msg = item.message
        if isinstance(msg, TrialResult):
            self.trial_results.append(msg)
        elif isinstance(msg, HostlessEvent):
            self.hostless_events.append(msg)
        elif isinstance(msg, Telemetry):
            self.telemetry_backlog.append(msg)
        else:
            self.unmatched.append(msg)

    def _settle(self) -> None:
        while self._inbox:
            self._park(self._inbox.popleft())

    def drain(self, timeout: float = 0.0) -> int:
        """Read whatever arrives within ``timeout`` s and park it (TRIAL_RESULTs into
        :attr:`trial_results`, ...). Returns the bytes read."""
        deadline = time.monotonic() + timeout
        total = self._pump(0.0)
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            total += self._pump(min(left, POLL_INTERVAL))
        self._pump(0.0)
        self._settle()
        return total

    def _write(self, frames: bytes | bytearray) -> None:
        """Every frame the host sends goes out here, after a 0x00: it ends whatever
        partial frame the device still holds (a write cut short by Ctrl-C, a crash or
        line noise), so a STOP after it cannot merge with those bytes and be lost. The
        frames of one write are separated by their own delimiters."""
        self.transport.write(b"\x00" + frames)

    def _send(self, message) -> int:
        seq = self._seq.next()
        self._write(encode_message(message, seq))
        return seq

    def _timeout_error(
        self, what: str, timeout: float, bytes_before: int, frames_before: int, bad_before: int
    ) -> LinkError:
        if self.device_version is not None and self.device_version != PROTOCOL_VERSION:
            return self._mismatch()
        where = getattr(self.transport, "name", "the device")
        msg = f"no answer to {what} from {where} within {timeout:g} s"
        got_bytes = self.bytes_received - bytes_before
        got_frames = self.frames_received - frames_before
        got_bad = self.host_bad_frames - bad_before
        if self.bytes_received == 0:
            msg += (
                "; nothing at all has been received from it: is it powered and running "
                "the GraspGuide firmware, and is this its port (`graspguide ports`)?"
            )
        elif got_bytes and not got_frames:
            msg += (
                f"; {got_bytes} bytes arrived meanwhile but no valid frame "
                f"({got_bad} rejected): wrong baud rate (the firmware uses 115200) or not "
                "a GraspGuide device?"
            )
        elif got_frames:
            msg += f"; {got_frames} other frames arrived meanwhile (none answers it)"
        else:
            msg += "; the device went silent (busy, reset, or the request was corrupted)"
        return LinkTimeout(msg)

    def _mismatch(self) -> ProtocolMismatch:
        v = self.device_version
        return ProtocolMismatch(
            f"the device speaks protocol version {v}, this host {PROTOCOL_VERSION}: flash "
            "firmware built from the same schema as these host tools (or install the host "
            "tools that match the firmware)",
            device_version=v,
        )

    def _wait(
        self, match: Callable[[_Received], bool], what: str, timeout: float | None
    ) -> _Received:
        timeout = self.timeout if timeout is None else float(timeout)
        deadline = time.monotonic() + timeout
        b0, f0, bad0 = self.bytes_received, self.frames_received, self.host_bad_frames
        while True:
            while self._inbox:
                item = self._inbox.popleft()
                if match(item):
                    return item
                self._park(item)
            if self.device_version is not None and self.device_version != PROTOCOL_VERSION:
                raise self._mismatch()
            left = deadline - time.monotonic()
            if left <= 0:
                raise self._timeout_error(what, timeout, b0, f0, bad0)
            self._pump(min(left, POLL_INTERVAL))

    def _request(
        self,
        message,
        answer_type=Ack,
        timeout: float | None = None,
        match: Callable[[Any], bool] | None = None,
    ):
        """Send one request and return its answer (``answer_type``); ERROR raises
        DeviceError. ``match`` overrides how an answer is recognised."""
        self._pump(0.0)
        self._settle()
        seq = self._send(message)
        name = message.NAME

        def is_answer(item: _Received) -> bool:
            m = item.message
            if isinstance(m, Error):
                return m.request_seq == seq
            if match is not None:
                return match(m)
            return isinstance(m, answer_type) and getattr(m, "request_seq", None) == seq

        item = self._wait(is_answer, f"{name} (seq {seq})", timeout)
        m = item.message
        if isinstance(m, Error):
            raise DeviceError(name, seq, m.code, m.detail)
        # What the device sent right behind the answer (e.g. a TRIAL_RESULT) is parked now.
        self._pump(0.0)
        self._settle()
        return m

    # ---- requests
    def hello(self, timeout: float | None = None) -> HelloReply:
        """HELLO -> HELLO_REPLY (kept in :attr:`device_info`); ProtocolMismatch if the
        device's protocol version differs from this host's."""
        reply = self._request(Hello(protocol_version=PROTOCOL_VERSION), HelloReply, timeout)
        self.device_info = reply
        if reply.protocol_version != PROTOCOL_VERSION:
            self.device_version = reply.protocol_version
            raise self._mismatch()
        return reply

    def set_scene(
        self,
        contacts: Sequence[Sequence[float]],
        y_axis: Sequence[float] = (0.0, 1.0, 0.0),
        constraints: str | ConstraintModel = "paper",
        policy: str | Policy = "F",
        mode: str | Mode = "C",
        threshold_deg: float = 3.0,
        hold_s: float = 0.5,
        timeout_s: float = 90.0,
        timeout: float | None = None,
    ) -> Ack | None:
        """SET_SCENE. ``contacts``: 3 or 4 [x, y, z] (another count is sent as is and the
        device answers bad_contact_count); names as in `graspguide solve` ("F"/"Fperp",
        "C"/"V", "paper"/"normal"/"none") or the wire enums. Values go on the wire as
        float32 (beyond its range: infinite).

        A per-frame-only board (HELLO_REPLY with per_frame and without full_solve, learnt
        from :meth:`hello` or from the board's per_frame_only answer) gets nothing now: the
        scene, checked by the core as the board would, stays on the host and
        :meth:`start_trial` sends the posture it solves (SET_POSTURE). Then the answer is
        None; else the device's ACK."""
        k, slots = _contact_slots(contacts)
        msg = SetScene(
            k=k,
            contacts=slots,
            y_axis=_floats(y_axis, 3, "y_axis"),
            constraints=_enum(constraints, CONSTRAINT_NAMES, ConstraintModel, "constraints"),
            policy=_enum(policy, POLICY_NAMES, Policy, "policy"),
            mode=_enum(mode, MODE_NAMES, Mode, "mode"),
            threshold_deg=to_f32(threshold_deg),
            hold_s=to_f32(hold_s),
            timeout_s=to_f32(timeout_s),
        )
        if self.host_solves_posture:
            self._keep_scene(msg)
            return None
        try:
            ack = self._request(msg, Ack, timeout)
        except DeviceError as e:
            if e.code != ErrorCode.PER_FRAME_ONLY:
                raise
            try:
                self.hello(timeout)  # learn what the board does instead
            except LinkError:
                raise e from None  # the refusal is the news, not a failing HELLO
            if not self.host_solves_posture:
                raise
            self._keep_scene(msg)
            return None
        self._host_scene = None
        return ack

    @property
    def host_solves_posture(self) -> bool:
        """True for a board that does only the per-frame work (its HELLO_REPLY lists
        per_frame, not full_solve): the host solves each posture with the core."""
        info = self.device_info
        return (
            info is not None
            and bool(info.capabilities & CAPABILITY_PER_FRAME)
            and not info.capabilities & CAPABILITY_FULL_SOLVE
        )

    def _keep_scene(self, msg: SetScene) -> None:
        """Checks the scene with the core, as a full-solve board's SET_SCENE would, and keeps
        it for start_trial."""
        from graspguide.core import solver

        self._host_scene = None
        if msg.k not in (3, MAX_CONTACTS):
            status = "bad_contact_count"
        else:
            status = solver.Guidance().set_scene(
                [list(c) for c in msg.contacts[: msg.k]],
                policy=_POLICY_NAME[msg.policy],
                mode=_MODE_NAME[msg.mode],
                constraints=_CONSTRAINT_NAME[msg.constraints],
                y_axis=list(msg.y_axis),
            )
        if status == "ok":
            # Guidance.set_scene takes any geometry; the board's SET_SCENE also refuses
            # coincident or imprecise contacts (geometry_status), which the core's solve
            # reports first, whatever the wrench: a probe's geometry statuses are those.
            probe = solver.solve(
                [list(c) for c in msg.contacts[: msg.k]],
                list(_PROBE_WRENCH),
                policy=_POLICY_NAME[msg.policy],
                mode=_MODE_NAME[msg.mode],
                constraints=_CONSTRAINT_NAME[msg.constraints],
                y_axis=list(msg.y_axis),
            )["status"]
            if probe in _GEOMETRY_STATUSES:
                status = probe
        if status != "ok":
            raise DeviceError(
                "SET_SCENE",
                None,
                ErrorCode[status.upper()],
                source=HOST_SOLVE_SOURCE,
                context="kept on the host for a per-frame-only board",
            )
        self._host_scene = msg

    def solve_posture(self, wrench: Sequence[float]) -> SetPosture:
        """The SET_POSTURE for the kept scene and this wrench: Algorithm 1's levels and the
        force direction from the C++ core, on the float32 values a full-solve board would
        have received (as graspguide.mp.plan_file.solve_levels does). DeviceError (source
        "host core") with the core's status when it cannot be solved."""
        from graspguide.core.posture import solve_posture

        scene = self._host_scene
        if scene is None:
            raise LinkError("no scene kept on the host: call set_scene() first")
        wrench32 = _floats(wrench, 6, "wrench")
        posture = solve_posture(
            [list(c) for c in scene.contacts[: scene.k]],
            wrench32,
            policy=_POLICY_NAME[scene.policy],
            mode=_MODE_NAME[scene.mode],
            constraints=_CONSTRAINT_NAME[scene.constraints],
            y_axis=scene.y_axis,
        )
        if posture.status != "ok":
            raise DeviceError(
                "START_TRIAL",
                None,
                ErrorCode[posture.status.upper()],
                source=HOST_SOLVE_SOURCE,
                context="the posture of a per-frame-only board, solved on the host",
            )
        f_hat = posture.force_unit
        levels = posture.levels
        return SetPosture(
            k=scene.k,
            mode=scene.mode,
            levels=tuple(levels),
            force_unit=f_hat,
            wrench=wrench32,
            threshold_deg=scene.threshold_deg,
            hold_s=scene.hold_s,
            timeout_s=scene.timeout_s,
        )

    def start_trial(
        self, trial_id: int, wrench: Sequence[float], timeout: float | None = None
    ) -> Ack:
        """START_TRIAL with the virtual object's wrench [fx, fy, fz, mx, my, mz]. For a
        per-frame-only board with a scene kept on the host (:meth:`set_scene`), first the
        posture the host solves for it (:meth:`solve_posture`, SET_POSTURE)."""
        if self._host_scene is not None and self.host_solves_posture:
            self._request(self.solve_posture(wrench), Ack, timeout)
        return self._request(
            StartTrial(trial_id=int(trial_id) & 0xFFFF, wrench=_floats(wrench, 6, "wrench")),
            Ack,
            timeout,
        )

    @staticmethod
    def _pose_message(
        t_us: int, quat: Sequence[float], contacts: Sequence[Sequence[float]] | None
    ) -> Pose:
        if contacts is None:
            has, slots = False, ((0.0, 0.0, 0.0),) * MAX_CONTACTS
        else:
            has = True
            _, slots = _contact_slots(contacts)
        return Pose(
            host_time_us=int(t_us) & 0xFFFFFFFF,
            quat_wxyz=_floats(quat, 4, "quat"),
            has_contacts=has,
            contacts=slots,
        )

    def pose(
        self,
        t_us: int | None = None,
        quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
        contacts: Sequence[Sequence[float]] | None = None,
        timeout: float | None = None,
        check: bool = False,
    ) -> Telemetry:
        """POSE -> its TELEMETRY. ``t_us`` defaults to :func:`host_time_us`. A core
        failure is in ``Telemetry.solver_status`` (motors off); ``check=True`` raises it as
        DeviceError instead. A TRIAL_RESULT the pose caused lands in
        :attr:`trial_results` (see :meth:`wait_trial_result`)."""
        if t_us is None:
            t_us = host_time_us()
        if contacts is not None and self.host_solves_posture:
            raise PerFrameOnly(
                f"{getattr(self.transport, 'name', 'the device')} does only the per-frame work "
                "(HELLO_REPLY without full_solve): a POSE cannot carry contacts, the host "
                "solves the posture once per trial; for a new posture call set_scene() and "
                "start_trial() again"
            )
        if contacts is None:
            tel = self._pose_fast(int(t_us) & 0xFFFFFFFF, quat, timeout)
            if tel is not None:
                if check and tel.solver_status != ErrorCode.OK:
                    raise DeviceError("POSE", None, tel.solver_status, 0, source="TELEMETRY")
                return tel
        msg = self._pose_message(t_us, quat, contacts)
        tel = self._request(
            msg,
            Telemetry,
            timeout,
            match=lambda m: isinstance(m, Telemetry) and m.host_time_us == msg.host_time_us,
        )
        if check and tel.solver_status != ErrorCode.OK:
            raise DeviceError("POSE", None, tel.solver_status, 0, source="TELEMETRY")
        return tel

    def _pose_fast(
        self, t_us: int, quat: Sequence[float], timeout: float | None
    ) -> Telemetry | None:
        """POSE -> TELEMETRY without the generic codecs (None: use the generic path).
        Frames already read are parked first, as _request does; what arrives with the
        TELEMETRY (a TRIAL_RESULT) is parked right after it."""
        if len(quat) != 4:
            return None
        seq = self._seq._next
        wire = encode_pose_fast(seq, t_us, quat)
        if wire is None:
            return None
        self._settle()
        self._seq.next()
        self._write(wire)
        m = self._wait(_pose_answer(seq, t_us), f"POSE (seq {seq})", timeout).message
        if isinstance(m, Error):
            raise DeviceError("POSE", seq, m.code, m.detail)
        if not m.flags & TELEMETRY_FLAG_TRIAL_RUNNING:
            self._pump(0.0)  # a TRIAL_RESULT right behind it, as _request
        self._settle()
        return m

    def pose_batch(
        self,
        poses: Sequence[tuple[int, Sequence[float]]],
        timeout: float | None = None,
        on_written: Callable[[], None] | None = None,
    ) -> list[Any]:
        """Several POSEs (``(t_us, quat)``, no contacts) written at once, then their
        answers in order: the TELEMETRY of each, or the ERROR that refused it (e.g.
        not_allowed_in_state for the POSEs that followed the one ending a trial). The
        device handles them one after the other exactly as if each had been sent after
        the previous answer; a TRIAL_RESULT lands in :attr:`trial_results`. ``timeout``
        applies to each answer. ``on_written()`` is called once the POSEs are written,
        before their answers are read: work done there overlaps the device's."""
        wires: list[bytes] = []
        seqs: list[int] = []
        times: list[int] = []
        seq0 = self._seq._next
        for t_us, quat in poses:
            t_us = int(t_us) & 0xFFFFFFFF
            seq = (seq0 + len(seqs)) & 0xFFFF
            wire = encode_pose_fast(seq, t_us, quat) if len(quat) == 4 else None
            if wire is None:
                wire = encode_message(self._pose_message(t_us, quat, None), seq)
            wires.append(wire)
            seqs.append(seq)
            times.append(t_us)
        self._settle()
        self._seq._next = (seq0 + len(seqs)) & 0xFFFF  # every seq numbered above used
        self._write(b"".join(wires))
        if on_written is not None:
            on_written()
        out: list[Any] = []
        inbox = self._inbox
        for seq, t_us in zip(seqs, times):
            # What _wait does first, inlined: the answer may already be in the inbox
            # (one read brings many); else wait for it, as if its POSE had just been
            # sent (``timeout`` applies to each answer).
            while inbox:
                item = inbox.popleft()
                m = item.message
                if type(m) is Telemetry:
                    if m.host_time_us == t_us:
                        break
                elif isinstance(m, Error) and m.request_seq == seq:
                    break
                self._park(item)
            else:
                m = self._wait(_pose_answer(seq, t_us), f"POSE (seq {seq})", timeout).message
            out.append(m)
        self._settle()
        return out

    def stop(self, timeout: float | None = None) -> Ack:
        """STOP: motors off now; a running trial ends without TRIAL_RESULT."""
        return self._request(Stop(), Ack, timeout)

    def set_motors(self, pwm: Sequence[int], timeout: float | None = None) -> Ack:
        """SET_MOTORS (bench test): up to 4 duties 0..255; the POSE watchdog switches them
        off again unless repeated."""
        pwm = [int(p) for p in pwm]
        if len(pwm) > MAX_CONTACTS or any(not 0 <= p <= 255 for p in pwm):
            raise ValueError(f"pwm must be at most {MAX_CONTACTS} values in 0..255, got {pwm}")
        pwm += [0] * (MAX_CONTACTS - len(pwm))
        return self._request(SetMotors(pwm=tuple(pwm)), Ack, timeout)

    def set_calibration(
        self, cal: MotorCalibration | SetCalibration, timeout: float | None = None
    ) -> Ack:
        """SET_CALIBRATION: the participant's per-motor PWM floor and gain, applied to the
        TELEMETRY PWM of every following POSE (SET_MOTORS stays raw). The device refuses it
        during a trial or a host-less run (DeviceError not_allowed_in_state) and names the
        field of a value it will not take (bad_config)."""
        return self._request(calibration_message(cal), Ack, timeout)

    def status(self, timeout: float | None = None) -> Status:
        """GET_STATUS -> STATUS (state, frames_received, bad_frames, stale_events,
        last_error as counted by the device)."""
        return self._request(GetStatus(), Status, timeout, match=lambda m: isinstance(m, Status))

    def wait_trial_result(self, timeout: float | None = None) -> TrialResult:
        """The oldest queued TRIAL_RESULT, waiting up to ``timeout`` s for one."""
        if self.trial_results:
            return self.trial_results.popleft()
        self._settle()
        if self.trial_results:
            return self.trial_results.popleft()
        item = self._wait(lambda it: isinstance(it.message, TrialResult), "a TRIAL_RESULT", timeout)
        return item.message

    # ---- host-less: the plan, the results log, the run (docs/protocol.md)
    def require_capability(self, bit: int, what: str) -> None:
        """LinkError unless the device's HELLO_REPLY (sent first if not yet) lists the
        CAPABILITY_* ``bit``; ``what`` names the feature in the message."""
        info = self.device_info or self.hello()
        if not info.capabilities & bit:
            where = getattr(self.transport, "name", "the device")
            raise LinkError(
                f"{where} ({info.board}, firmware "
                f"{'.'.join(map(str, info.firmware_version))}) cannot do {what} "
                f"(HELLO_REPLY.capabilities 0x{info.capabilities:02x}): flash firmware that "
                "supports it"
            )

    def upload_plan(
        self,
        begin: PlanBegin,
        trials: Sequence[PlanTrial],
        timeout: float | None = None,
        calibration: MotorCalibration | None = None,
    ) -> None:
        """PLAN_BEGIN, every PLAN_TRIAL (``position`` 0..n-1 in order), then PLAN_COMMIT
        (the device solves each trial once and stores the plan). Each is ACKed; an ERROR
        raises DeviceError naming the refused field or trial. ``begin.trial_count`` must
        be ``len(trials)``. ``calibration`` (the identity when None) replaces
        PLAN_BEGIN's pwm_floor and gain: the plan's trials are rendered with it."""
        cal = calibration_message(calibration or MotorCalibration.identity())
        begin = dataclasses.replace(begin, pwm_floor=cal.pwm_floor, gain=cal.gain)
        trials = list(trials)
        if begin.trial_count != len(trials):
            raise ValueError(
                f"PLAN_BEGIN.trial_count is {begin.trial_count} but {len(trials)} PLAN_TRIALs "
                "were given: make them agree"
            )
        for i, t in enumerate(trials):
            if t.position != i:
                raise ValueError(
                    f"PLAN_TRIAL number {i} has position {t.position}: positions must be "
                    "0..n-1 in the order sent"
                )
        self._request(begin, Ack, timeout)
        for t in trials:
            try:
                self._request(t, Ack, timeout)
            except DeviceError as e:
                raise DeviceError(
                    e.request,
                    e.request_seq,
                    int(e.code),
                    e.detail,
                    context=f"plan position {t.position}, trial_index {t.trial_index}",
                ) from None
        commit_timeout = max(self.timeout if timeout is None else timeout, PLAN_COMMIT_TIMEOUT_S)
        self._request(PlanCommit(trial_count=len(trials)), Ack, commit_timeout)

    def log_info(self, timeout: float | None = None) -> LogInfo:
        """LOG_INFO_GET -> LOG_INFO: the stored plan (participant, config_hash, trials) and
        the results log (records, capacity, torn records, running)."""
        return self._request(LogInfoGet(), LogInfo, timeout, match=lambda m: isinstance(m, LogInfo))

    def log_read(self, index: int, timeout: float | None = None) -> LogRecord:
        """LOG_READ -> the LOG_RECORD stored at ``index`` (0..records-1); ERROR no_record
        past the end."""
        index = int(index)
        if not 0 <= index <= 0xFFFF:
            raise ValueError(f"log index must be in 0..65535, got {index}")
        return self._request(
            LogRead(index=index),
            LogRecord,
            timeout,
            match=lambda m: isinstance(m, LogRecord) and m.index == index,
        )

    def log_erase(self, timeout: float | None = None) -> Ack:
        """LOG_ERASE with its key: every record goes (the plan stays). Download first."""
        return self._request(LogErase(key=LOG_ERASE_KEY), Ack, timeout)

    def hostless_run(self, timeout: float | None = None) -> Ack:
        """HOSTLESS_RUN: the device runs the stored plan from its first trial without a
        record; HOSTLESS_EVENTs arrive in :attr:`hostless_events`. STOP ends it."""
        return self._request(HostlessRun(), Ack, timeout)

    def sim_button(self, pressed: bool, timeout: float | None = None) -> Ack:
        """SIMULATION ONLY: SIM_BUTTON (a real board answers sim_only)."""
        return self._request(SimButton(pressed=bool(pressed)), Ack, timeout)

    def sim_imu_sample(
        self,
        time_us: int,
        accel_mps2: Sequence[float],
        gyro_radps: Sequence[float],
        timeout: float | None = None,
    ) -> Telemetry | None:
        """SIMULATION ONLY: one IMU sample of the simulated world. During a host-less run
        the answer is the TELEMETRY the sample produced (returned); otherwise an ACK
        (None). The device sends a HOSTLESS_EVENT or TRIAL_RESULT the sample caused
        before that TELEMETRY, so they are in :attr:`hostless_events` /
        :attr:`trial_results` when this returns."""
        t_us = int(time_us) & 0xFFFFFFFF
        msg = SimImuSample(
            time_us=t_us,
            accel_mps2=_floats(accel_mps2, 3, "accel_mps2"),
            gyro_radps=_floats(gyro_radps, 3, "gyro_radps"),
        )
        self._pump(0.0)
        self._settle()
        seq = self._send(msg)

        def is_answer(item: _Received) -> bool:
            m = item.message
            if type(m) is Telemetry:
                return m.host_time_us == t_us
            return isinstance(m, (Ack, Error)) and m.request_seq == seq

        m = self._wait(is_answer, f"{msg.NAME} (seq {seq})", timeout).message
        if isinstance(m, Error):
            raise DeviceError(msg.NAME, seq, m.code, m.detail)
        self._settle()
        return m if isinstance(m, Telemetry) else None


__all__ = [
    "DeviceClient",
    "DeviceError",
    "PerFrameOnly",
    "ProtocolMismatch",
    "LinkError",
    "LinkTimeout",
    "DeviceNotFound",
    "DeviceDisconnected",
    "SimNotBuilt",
    "ERROR_MEANINGS",
    "code_name",
    "host_time_us",
    "to_f32",
    "POLICY_NAMES",
    "MODE_NAMES",
    "CONSTRAINT_NAMES",
    "DEFAULT_TIMEOUT",
    "PLAN_COMMIT_TIMEOUT_S",
]
