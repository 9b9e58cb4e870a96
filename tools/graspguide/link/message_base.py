"""What every link message shares: its field descriptions, value checks and payload codec.

The generated :mod:`graspguide.link.messages` holds only data (ids, enums, one dataclass
per message with its FIELDS and STRUCT); this module turns that data into behaviour, so
the generator never carries code as text.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterator
from typing import Any, ClassVar, NamedTuple, TypeVar

from graspguide.link.errors import BadEnumValueError, BadLengthError, FieldValueError


class FieldSpec(NamedTuple):
    """One field of a message: the schema's description of it."""

    name: str
    kind: str  # u8 u16 u32 i8 i16 i32 f32 bool ascii enum
    shape: tuple[int, ...]  # () for a scalar
    enum: type[enum.IntEnum] | None  # the enum class when kind == "enum"
    size: int  # bytes of one element
    unit: str
    doc: str
    format: str  # the field's struct codes: "I", "4f", "12f"; STRUCT is "<" + theirs in order


INT_RANGES = {
    "u8": (0, 0xFF),
    "u16": (0, 0xFFFF),
    "u32": (0, 0xFFFFFFFF),
    "i8": (-0x80, 0x7F),
    "i16": (-0x8000, 0x7FFF),
    "i32": (-0x80000000, 0x7FFFFFFF),
}
_F32 = struct.Struct("<f")


def _enum_of(spec: FieldSpec) -> type[enum.IntEnum]:
    if spec.enum is None:  # the generator gives every enum field its class
        raise TypeError(f"{spec.name}: an enum field without its enum class")
    return spec.enum


def _scalar(spec: FieldSpec, v: Any) -> Any:
    """A value as messages store it (float32-rounded floats, enum members), or
    FieldValueError."""
    where = spec.name
    if spec.kind == "f32":
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise FieldValueError(f"{where}: expected a number, got {v!r}")
        try:
            return _F32.unpack(_F32.pack(float(v)))[0]
        except (OverflowError, struct.error) as e:
            raise FieldValueError(f"{where}: {v!r} does not fit float32") from e
    if spec.kind == "bool":
        if isinstance(v, bool):
            return v
        if isinstance(v, int) and v in (0, 1):
            return bool(v)
        raise FieldValueError(f"{where}: expected a bool, got {v!r}")
    if spec.kind == "enum":
        cls = _enum_of(spec)
        if isinstance(v, bool) or not isinstance(v, int):
            raise FieldValueError(f"{where}: expected {cls.__name__}, got {v!r}")
        try:
            return cls(v)
        except ValueError as e:
            raise FieldValueError(f"{where}: {v!r} is not a {cls.__name__}") from e
    if spec.kind == "ascii":
        if (
            not isinstance(v, str)
            or len(v) > spec.size
            or any(not 0x20 <= ord(c) <= 0x7E for c in v)
        ):
            raise FieldValueError(
                f"{where}: expected printable ASCII of at most {spec.size} characters, got {v!r}"
            )
        return v
    lo, hi = INT_RANGES[spec.kind]
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise FieldValueError(f"{where}: expected an integer in [{lo}, {hi}], got {v!r}")
    return v


def _shaped(spec: FieldSpec, v: Any, shape: tuple[int, ...]) -> Any:
    if not shape:
        return _scalar(spec, v)
    if isinstance(v, (str, bytes)) or not hasattr(v, "__len__") or len(v) != shape[0]:
        raise FieldValueError(f"{spec.name}: expected shape {spec.shape}, got {v!r}")
    return tuple(_shaped(spec, x, shape[1:]) for x in v)


def _flatten(spec: FieldSpec, v: Any) -> Iterator[Any]:
    if isinstance(v, tuple):
        for x in v:
            yield from _flatten(spec, x)
    elif spec.kind == "ascii":
        yield v.encode("ascii")
    elif spec.kind in ("enum", "bool"):
        yield int(v)
    else:
        yield v


def _wire_scalar(spec: FieldSpec, index: int, v: Any) -> Any:
    if spec.kind == "enum":
        cls = _enum_of(spec)
        try:
            return cls(v)
        except ValueError:
            raise BadEnumValueError(
                f"{spec.name}: {v} is not a {cls.__name__}", field=index
            ) from None
    if spec.kind == "bool":
        if v not in (0, 1):
            raise BadEnumValueError(f"{spec.name}: {v} is not 0 or 1", field=index)
        return v == 1
    if spec.kind == "ascii":
        text, _, pad = v.partition(b"\0")
        if pad.strip(b"\0") or any(not 0x20 <= c <= 0x7E for c in text):
            raise BadEnumValueError(
                f"{spec.name}: {v!r} is not NUL-padded printable ASCII", field=index
            )
        return text.decode("ascii")
    return v


def _unflatten(spec: FieldSpec, index: int, it: Iterator[Any], shape: tuple[int, ...]) -> Any:
    if not shape:
        return _wire_scalar(spec, index, next(it))
    return tuple(_unflatten(spec, index, it, shape[1:]) for _ in range(shape[0]))


def _to_json(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_to_json(x) for x in v]
    if isinstance(v, enum.IntEnum):
        return v.name.lower()
    return v


def _from_json(spec: FieldSpec, v: Any) -> Any:
    if isinstance(v, list):
        return [_from_json(spec, x) for x in v]
    if spec.kind == "enum" and isinstance(v, str):
        cls = _enum_of(spec)
        try:
            return cls[v.upper()]
        except KeyError:
            raise FieldValueError(f"{spec.name}: {v!r} is not a {cls.__name__} name") from None
    return v


M = TypeVar("M", bound="Message")


class Message:
    """The base of every generated message dataclass, which only declares its fields."""

    MSG_ID: ClassVar[int]
    NAME: ClassVar[str]
    DIRECTION: ClassVar[str]
    PAYLOAD_SIZE: ClassVar[int]
    FIELDS: ClassVar[tuple[FieldSpec, ...]]
    # The payload's layout (little-endian, every array flattened): fast paths that pack
    # or unpack one message type directly use it rather than a format of their own.
    STRUCT: ClassVar[struct.Struct]

    def __post_init__(self) -> None:
        for spec in self.FIELDS:
            object.__setattr__(self, spec.name, _shaped(spec, getattr(self, spec.name), spec.shape))

    def pack(self) -> bytes:
        """The payload bytes (little-endian)."""
        values = [x for spec in self.FIELDS for x in _flatten(spec, getattr(self, spec.name))]
        return self.STRUCT.pack(*values)

    @classmethod
    def unpack(cls: type[M], payload: bytes) -> M:
        """The message of a payload; BadLengthError or BadEnumValueError."""
        if len(payload) != cls.PAYLOAD_SIZE:
            raise BadLengthError(
                f"{cls.NAME}: payload of {len(payload)} bytes, expected {cls.PAYLOAD_SIZE}"
            )
        it = iter(cls.STRUCT.unpack(bytes(payload)))
        values = {s.name: _unflatten(s, i, it, s.shape) for i, s in enumerate(cls.FIELDS)}
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly: enums by schema name, arrays as lists."""
        return {spec.name: _to_json(getattr(self, spec.name)) for spec in self.FIELDS}

    @classmethod
    def from_dict(cls: type[M], data: dict[str, Any]) -> M:
        """Inverse of to_dict (enum members may be given by schema name or value); missing
        fields take their defaults, unknown ones raise FieldValueError."""
        specs = {spec.name: spec for spec in cls.FIELDS}
        unknown = sorted(set(data) - set(specs))
        if unknown:
            raise FieldValueError(f"{cls.NAME}: unknown fields {unknown}")
        return cls(**{k: _from_json(specs[k], v) for k, v in data.items()})


__all__ = ["FieldSpec", "INT_RANGES", "Message"]
