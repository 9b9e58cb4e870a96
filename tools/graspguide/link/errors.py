"""Typed errors of the GraspGuide link protocol.

Each decode error names the wire ErrorCode it corresponds to (``code``), so a host can
log it like the device's ERROR messages.
"""

from __future__ import annotations


class ProtocolError(Exception):
    """Base of every protocol error."""

    code: str = ""


class FrameError(ProtocolError):
    """A frame could not be decoded. ``header`` is (version, msg_id, seq) when the CRC
    passed, so the header can be trusted; None otherwise."""

    def __init__(self, message: str, header: tuple | None = None) -> None:
        super().__init__(message)
        self.header = header


class BadCrcError(FrameError):
    """The CRC-16 does not match: some byte changed on the line, so not even the header is
    trusted and the device does not answer."""

    code = "bad_crc"


class BadCobsError(FrameError):
    code = "bad_cobs"  # the last COBS block runs past the delimiter


class TooLongError(FrameError):
    """More bytes than the largest message's frame; the rest up to the delimiter is dropped."""

    code = "too_long"


class TooShortError(FrameError):
    code = "too_short"  # fewer bytes than header + CRC


class BadVersionError(FrameError):
    """A frame of another protocol version (its CRC passed, so ``header`` names it): the two
    ends were built from different schemas."""

    code = "bad_version"


class UnknownIdError(FrameError):
    code = "unknown_id"  # no message has this id, or it travels the other way


class BadLengthError(FrameError):
    """The payload's size is not the one its message id declares."""

    code = "bad_length"


class IncompleteFrameError(FrameError):
    """decode_frame() was not given exactly one frame ending in its 0x00 delimiter."""

    code = "incomplete_frame"


class BadEnumValueError(ProtocolError):
    """A payload's enum, bool or ascii field holds a value outside its declared set.
    ``field`` is the field's index in the message (ERROR.detail of the device)."""

    code = "bad_enum_value"

    def __init__(self, message: str, field: int) -> None:
        super().__init__(message)
        self.field = field


class FieldValueError(ProtocolError, ValueError):
    """A message was built with a value its field cannot carry (wrong type, shape or
    range, a float beyond float32, an unknown enum value)."""

    code = "field_value"


__all__ = [
    "ProtocolError",
    "FrameError",
    "BadCrcError",
    "BadCobsError",
    "TooLongError",
    "TooShortError",
    "BadVersionError",
    "UnknownIdError",
    "BadLengthError",
    "IncompleteFrameError",
    "BadEnumValueError",
    "FieldValueError",
]
