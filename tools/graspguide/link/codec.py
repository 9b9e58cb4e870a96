"""Frames of the GraspGuide link (docs/protocol.md), the same as lib/graspguide_link:

    wire = COBS( version:u8 | msg_id:u8 | seq:u16 LE | payload | crc16:u16 LE ) 0x00

with CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over version..payload.
:class:`FrameParser` is the C++ FrameParser's twin: same events, same resynchronization
(after any error it drops bytes up to the next 0x00), same counters.
"""

from __future__ import annotations

import binascii
import enum
import struct
from dataclasses import dataclass

from graspguide.link.errors import (
    BadCobsError,
    BadCrcError,
    BadLengthError,
    BadVersionError,
    FrameError,
    IncompleteFrameError,
    TooLongError,
    TooShortError,
    UnknownIdError,
)
from graspguide.link.messages import (
    DEVICE_TO_HOST_IDS,
    HOST_TO_DEVICE_IDS,
    MAX_PAYLOAD_SIZE,
    PROTOCOL_VERSION,
    payload_size_of,
    unpack_payload,
)

FRAME_DELIMITER = 0x00
HEADER_SIZE = 4  # version, msg_id, seq
CRC_SIZE = 2
FRAME_OVERHEAD = HEADER_SIZE + CRC_SIZE
MAX_RAW_FRAME_SIZE = FRAME_OVERHEAD + MAX_PAYLOAD_SIZE
COBS_MAX_CODE = 0xFF
COBS_MAX_BLOCK_DATA = 254
CRC16_POLY = 0x1021
CRC16_INIT = 0xFFFF

HEADER = struct.Struct("<BBH")  # version, msg_id, seq
CRC = struct.Struct("<H")
_COBS_CODE = [bytes((n + 1,)) for n in range(COBS_MAX_BLOCK_DATA)]


def crc16(data: bytes, crc: int = CRC16_INIT) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection: binascii's crc_hqx, in
    C); pass a previous result as ``crc`` to continue."""
    return binascii.crc_hqx(data, crc)


def cobs_max_encoded_size(size: int) -> int:
    return size + size // COBS_MAX_BLOCK_DATA + 1


def cobs_encode(data: bytes) -> bytes:
    """COBS without the delimiter. A block of 254 data bytes that ends the input gets no
    extra 0x01 code after it (the rule the C++ side and the golden frames share)."""
    if len(data) < COBS_MAX_BLOCK_DATA:  # every frame: one block per zero, split in C
        return b"".join([_COBS_CODE[len(part)] + part for part in data.split(b"\0")])
    out = bytearray()
    i, n = 0, len(data)
    while True:
        code_at = len(out)
        out.append(0)
        start = i
        while i < n and data[i] != 0 and i - start < COBS_MAX_BLOCK_DATA:
            i += 1
        out += data[start:i]
        out[code_at] = i - start + 1
        if i - start == COBS_MAX_BLOCK_DATA:
            if i == n:
                return bytes(out)
            continue  # a full block stands for no zero: the next block starts at data[i]
        if i == n:
            return bytes(out)
        i += 1  # the zero this block stands for
        if i == n:  # that zero was the last byte: an empty final block
            out.append(1)
            return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of cobs_encode (delimiter excluded); BadCobsError for an empty input, a
    0x00 inside it, or a block that runs past its end."""
    if not data:
        raise BadCobsError("empty COBS data")
    if 0 in data:  # one scan in C rather than one per block
        raise BadCobsError(f"0x00 at offset {data.index(0)} of COBS data")
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        j = i + data[i]
        if j > n:
            raise BadCobsError(f"COBS block at offset {i} runs past the end")
        out += data[i + 1 : j]
        if j < n and data[i] != COBS_MAX_CODE:
            out.append(0)
        i = j
    return bytes(out)


class ParseEvent(enum.Enum):
    """What one byte completed; the same events as the C++ ParseEvent."""

    NONE = "none"
    FRAME = "frame"
    BAD_CRC = "bad_crc"
    BAD_COBS = "bad_cobs"
    TOO_LONG = "too_long"
    TOO_SHORT = "too_short"
    BAD_VERSION = "bad_version"
    UNKNOWN_ID = "unknown_id"
    BAD_LENGTH = "bad_length"


# Events after which the frame's header passed the CRC and can be answered with its seq.
TRUSTED_HEADER_EVENTS = frozenset(
    {ParseEvent.FRAME, ParseEvent.BAD_VERSION, ParseEvent.UNKNOWN_ID, ParseEvent.BAD_LENGTH}
)

_EVENT_ERRORS: dict[ParseEvent, type] = {
    ParseEvent.BAD_CRC: BadCrcError,
    ParseEvent.BAD_COBS: BadCobsError,
    ParseEvent.TOO_LONG: TooLongError,
    ParseEvent.TOO_SHORT: TooShortError,
    ParseEvent.BAD_VERSION: BadVersionError,
    ParseEvent.UNKNOWN_ID: UnknownIdError,
    ParseEvent.BAD_LENGTH: BadLengthError,
}


class Accept(enum.Enum):
    """Which ids a receiver accepts; the others are unknown_id."""

    ALL = "all"
    HOST_TO_DEVICE = "host_to_device"
    DEVICE_TO_HOST = "device_to_host"

    def accepts(self, msg_id: int) -> bool:
        if self is Accept.ALL:
            return True
        ids = HOST_TO_DEVICE_IDS if self is Accept.HOST_TO_DEVICE else DEVICE_TO_HOST_IDS
        return msg_id in ids


@dataclass(frozen=True)
class Frame:
    version: int
    msg_id: int
    seq: int
    payload: bytes


def encode_frame(
    msg_id: int, seq: int, payload: bytes = b"", version: int = PROTOCOL_VERSION
) -> bytes:
    """One frame on the wire, delimiter included. Any header is allowed (tests forge bad
    frames with it); TooLongError for a payload above MAX_PAYLOAD_SIZE."""
    if len(payload) > MAX_PAYLOAD_SIZE:
        raise TooLongError(f"payload of {len(payload)} bytes > {MAX_PAYLOAD_SIZE}")
    raw = HEADER.pack(version, msg_id, seq) + bytes(payload)
    raw += CRC.pack(crc16(raw))
    return cobs_encode(raw) + bytes([FRAME_DELIMITER])


def check_frame(raw: bytes, accept: Accept = Accept.ALL) -> tuple[ParseEvent, Frame | None]:
    """Checks one COBS-decoded frame in the C++ order: size, CRC, version, id, length.
    The frame is returned whenever its CRC passed."""
    if len(raw) < FRAME_OVERHEAD:
        return ParseEvent.TOO_SHORT, None
    if len(raw) > MAX_RAW_FRAME_SIZE:
        return ParseEvent.TOO_LONG, None
    body = raw[:-CRC_SIZE]
    if crc16(body) != CRC.unpack_from(raw, len(body))[0]:
        return ParseEvent.BAD_CRC, None
    version, msg_id, seq = HEADER.unpack_from(body)
    frame = Frame(version, msg_id, seq, bytes(body[HEADER_SIZE:]))
    if version != PROTOCOL_VERSION:
        return ParseEvent.BAD_VERSION, frame
    expected = payload_size_of(msg_id)
    if expected is None or not accept.accepts(msg_id):
        return ParseEvent.UNKNOWN_ID, frame
    if len(frame.payload) != expected:
        return ParseEvent.BAD_LENGTH, frame
    return ParseEvent.FRAME, frame


class FrameParser:
    """Byte-wise parser with a fixed buffer (MAX_RAW_FRAME_SIZE decoded bytes)."""

    BUFFER_SIZE = MAX_RAW_FRAME_SIZE

    def __init__(self, accept: Accept = Accept.ALL) -> None:
        self.accept = accept
        self.frame: Frame | None = None  # set after an event in TRUSTED_HEADER_EVENTS
        self.counts: dict[ParseEvent, int] = {e: 0 for e in ParseEvent if e is not ParseEvent.NONE}
        self._buffer = bytearray()
        self._remaining = 0  # data bytes still to come in the current COBS block
        self._zero_pending = False  # the current block stands for a zero after its data
        self._started = False
        self._dropping = False  # an error was reported: ignore bytes up to the delimiter

    @property
    def good_frames(self) -> int:
        return self.counts[ParseEvent.FRAME]

    @property
    def bad_frames(self) -> int:
        return sum(n for e, n in self.counts.items() if e is not ParseEvent.FRAME)

    def discard_partial(self) -> None:
        """Forgets a partial frame (e.g. after a long silence); counts nothing."""
        self._buffer.clear()
        self._remaining = 0
        self._zero_pending = False
        self._started = False
        self._dropping = False

    def reset_counters(self) -> None:
        for e in self.counts:
            self.counts[e] = 0

    def push(self, byte: int) -> ParseEvent:
        if byte == FRAME_DELIMITER:
            return self._end_of_frame()
        if self._dropping:
            return ParseEvent.NONE
        appended: int | None
        if self._started and self._remaining > 0:
            appended = byte
            self._remaining -= 1
        else:
            # A code byte: the previous block's zero is data now that a block follows.
            appended = 0 if (self._started and self._zero_pending) else None
            self._started = True
            self._remaining = byte - 1
            self._zero_pending = byte != COBS_MAX_CODE
        if appended is not None:
            if len(self._buffer) >= self.BUFFER_SIZE:
                self._dropping = True
                return self._count(ParseEvent.TOO_LONG)
            self._buffer.append(appended)
        return ParseEvent.NONE

    def feed(self, data: bytes) -> list[tuple[ParseEvent, Frame | None]]:
        """Pushes every byte; returns the events other than NONE, each with the frame
        (None unless the event is in TRUSTED_HEADER_EVENTS)."""
        out: list[tuple[ParseEvent, Frame | None]] = []
        for b in data:
            event = self.push(b)
            if event is not ParseEvent.NONE:
                out.append((event, self.frame if event in TRUSTED_HEADER_EVENTS else None))
        return out

    def _end_of_frame(self) -> ParseEvent:
        dropping, started, complete = self._dropping, self._started, self._remaining == 0
        raw = bytes(self._buffer)
        self.discard_partial()
        if dropping or not started:  # already reported, or a lone delimiter (idle line)
            return ParseEvent.NONE
        if not complete:
            return self._count(ParseEvent.BAD_COBS)
        event, frame = check_frame(raw, self.accept)
        if frame is not None:
            self.frame = frame
        return self._count(event)

    def _count(self, event: ParseEvent) -> ParseEvent:
        self.counts[event] += 1
        return event


def decode_frame(wire: bytes, accept: Accept = Accept.ALL) -> Frame:
    """The one frame in ``wire`` (which must end with its 0x00; leading 0x00 are idle).
    Raises the FrameError subclass of the parser's event, or IncompleteFrameError."""
    if not wire or wire[-1] != FRAME_DELIMITER:
        raise IncompleteFrameError("a frame must end with its 0x00 delimiter")
    parser = FrameParser(accept)
    events = parser.feed(wire)
    if not events:
        raise IncompleteFrameError("no frame, only delimiters")
    event, frame = events[0]
    if event is not ParseEvent.FRAME:
        header = None if frame is None else (frame.version, frame.msg_id, frame.seq)
        raise _EVENT_ERRORS[event](f"frame rejected: {event.value}", header)
    if len(events) > 1:
        raise IncompleteFrameError(f"{len(events)} frames where one was expected")
    assert frame is not None  # a FRAME event always carries its frame
    return frame


@dataclass(frozen=True)
class DecodedMessage:
    seq: int
    message: object  # an instance of a class of graspguide.link.messages


def encode_message(message, seq: int) -> bytes:
    """One message as a complete frame on the wire (delimiter included)."""
    if not 0 <= seq <= 0xFFFF:
        raise ValueError(f"seq {seq} is not a u16")
    return encode_frame(message.MSG_ID, seq, message.pack())


def decode_message(wire: bytes, accept: Accept = Accept.ALL) -> DecodedMessage:
    """The message of one frame: decode_frame's errors, then BadEnumValueError."""
    frame = decode_frame(wire, accept)
    return DecodedMessage(frame.seq, unpack_payload(frame.msg_id, frame.payload))


def message_of(frame: Frame):
    """The message of a frame the parser accepted (BadEnumValueError if a field is bad)."""
    return unpack_payload(frame.msg_id, frame.payload)


class SequenceCounter:
    """A sender's u16 frame counter (the host numbers requests, the device its frames)."""

    def __init__(self, start: int = 0) -> None:
        self._next = start & 0xFFFF

    def next(self) -> int:
        seq = self._next
        self._next = (seq + 1) & 0xFFFF
        return seq


__all__ = [
    "FRAME_DELIMITER",
    "HEADER_SIZE",
    "CRC_SIZE",
    "FRAME_OVERHEAD",
    "MAX_RAW_FRAME_SIZE",
    "crc16",
    "cobs_encode",
    "cobs_decode",
    "cobs_max_encoded_size",
    "ParseEvent",
    "TRUSTED_HEADER_EVENTS",
    "Accept",
    "Frame",
    "encode_frame",
    "check_frame",
    "FrameParser",
    "decode_frame",
    "DecodedMessage",
    "encode_message",
    "decode_message",
    "message_of",
    "SequenceCounter",
    "FrameError",
]
