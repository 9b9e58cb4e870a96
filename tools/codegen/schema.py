"""The link schema (tools/codegen/link_messages.toml): its model, loaded and validated.

Only the standard library is used (Python >= 3.11 for tomllib), so the generator runs
before the package is installed.
"""

from __future__ import annotations

import math
import os
import re
import struct
import tomllib
from dataclasses import dataclass, field
from typing import Any

SCHEMA_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "link_messages.toml")
# What the banners of the generated files name.
GENERATOR = "tools/codegen"
SOURCE = "tools/codegen/link_messages.toml"
REGEN = "python3 tools/codegen"

# Frame layout (docs/protocol.md): COBS(version | msg_id | seq u16 | payload | crc u16) 0x00
HEADER_SIZE = 4
CRC_SIZE = 2
COBS_MAX_BLOCK = 0xFF
HOST_TO_DEVICE_IDS = (0x01, 0x3F)
DEVICE_TO_HOST_IDS = (0x80, 0xBF)

# kind -> (struct code, bytes, C++ type, C++ store/load suffix, min, max)
SCALARS: dict[str, tuple[str, int, str, str, int, int]] = {
    "u8": ("B", 1, "uint8_t", "u8", 0, 0xFF),
    "u16": ("H", 2, "uint16_t", "u16", 0, 0xFFFF),
    "u32": ("I", 4, "uint32_t", "u32", 0, 0xFFFFFFFF),
    "i8": ("b", 1, "int8_t", "i8", -0x80, 0x7F),
    "i16": ("h", 2, "int16_t", "i16", -0x8000, 0x7FFF),
    "i32": ("i", 4, "int32_t", "i32", -0x80000000, 0x7FFFFFFF),
    "f32": ("f", 4, "float", "f32", 0, 0),
    "bool": ("B", 1, "bool", "u8", 0, 1),
}


class SchemaError(Exception):
    pass


# --------------------------------------------------------------------------------------
# Schema model
# --------------------------------------------------------------------------------------


@dataclass
class EnumValue:
    name: str
    value: int
    doc: str


@dataclass
class Enum:
    name: str
    doc: str
    values: list[EnumValue]


@dataclass
class Field:
    name: str
    kind: str  # a SCALARS key, "enum" or "ascii"
    enum: str | None
    shape: tuple[int, ...]
    size: int  # bytes of one element
    unit: str
    doc: str
    default: Any = None  # canonical like a golden value; None: zero / first enum value

    @property
    def count(self) -> int:
        return math.prod(self.shape) if self.shape else 1

    @property
    def wire_size(self) -> int:
        return self.size * self.count

    @property
    def struct_code(self) -> str:
        if self.kind == "ascii":
            return f"{self.size}s"
        code = "B" if self.kind == "enum" else SCALARS[self.kind][0]
        return code * self.count if self.count <= 2 else f"{self.count}{code}"

    @property
    def type_label(self) -> str:
        base = (
            self.enum
            if self.kind == "enum"
            else (f"ascii[{self.size}]" if self.kind == "ascii" else self.kind)
        )
        return base + "".join(f"[{n}]" for n in self.shape)


@dataclass
class Message:
    name: str
    msg_id: int
    direction: str
    doc: str
    fields: list[Field]

    @property
    def class_name(self) -> str:
        return camel(self.name)

    def arrow(self, sign: str) -> str:
        ends = ("host", "device") if self.direction == "host_to_device" else ("device", "host")
        return f" {sign} ".join(ends)

    @property
    def payload_size(self) -> int:
        return sum(f.wire_size for f in self.fields)

    @property
    def struct_format(self) -> str:
        return "<" + "".join(f.struct_code for f in self.fields)


@dataclass
class Constant:
    name: str
    value: int
    ctype: str
    doc: str
    hex: bool = False  # written 0x..: a flag bit

    @property
    def literal(self) -> str:
        return f"0x{self.value:02X}" if self.hex else str(self.value)


@dataclass
class Flag:
    group: str
    name: str
    bit: int
    doc: str


@dataclass
class Golden:
    name: str
    message: Message
    seq: int
    fields: dict[str, Any]  # canonical: floats rounded to f32, enums as names


@dataclass
class FieldCopy:
    """A named set of a message's fields that the device copies between the message and its
    own types (copy_NAME_fields in messages.h): the message's fields, less `skip`."""

    name: str
    message: Message
    doc: str
    fields: list[Field]


@dataclass
class Schema:
    version: int
    link_error_base: int
    constants: list[Constant]
    enums: dict[str, Enum]
    flags: list[Flag]
    messages: list[Message]
    goldens: list[Golden]
    copies: list[FieldCopy] = field(default_factory=list)

    @property
    def named_constants(self) -> list[Constant]:
        """The version and the error base, the constants, then every flag bit as a u8
        constant named group_name: what both languages declare as named values."""
        head = [
            Constant(
                "protocol_version", self.version, "uint8_t", "Frames of any other are bad_version."
            ),
            Constant(
                "link_error_base",
                self.link_error_base,
                "uint8_t",
                "ErrorCode values below this are graspguide::Status values; from it, link codes.",
                hex=True,
            ),
        ]
        bits = [
            Constant(f"{f.group}_{f.name}", 1 << f.bit, "uint8_t", f.doc, hex=True)
            for f in self.flags
        ]
        return head + self.constants + bits

    @property
    def max_payload(self) -> int:
        return max(m.payload_size for m in self.messages)


_SNAKE = re.compile(r"^[a-z][a-z0-9_]*$")
_MSG_NAME = re.compile(r"^[A-Z][A-Z0-9_]*$")


def camel(snake: str) -> str:
    return "".join(p[:1].upper() + p[1:] for p in snake.lower().split("_"))


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _require(cond: bool, msg: str) -> None:
    if not cond:
        raise SchemaError(msg)


def load_schema(path: str = SCHEMA_PATH) -> Schema:
    with open(path, "rb") as fh:
        raw = tomllib.load(fh)
    proto = raw.get("protocol", {})
    version = proto.get("version")
    _require(isinstance(version, int) and 1 <= version <= 0xFF, "protocol.version must be 1..255")
    base = proto.get("link_error_base")
    _require(isinstance(base, int) and 0 < base <= 0xFF, "protocol.link_error_base must be 1..255")

    constants = []
    for c in raw.get("constant", []):
        _require(_SNAKE.match(c["name"]) is not None, f"constant name {c['name']!r}")
        _require(c["type"] in ("u8", "u16", "u32"), f"constant {c['name']}: type u8/u16/u32")
        lo, hi = SCALARS[c["type"]][4:6]
        _require(lo <= c["value"] <= hi, f"constant {c['name']} out of range")
        constants.append(Constant(c["name"], c["value"], SCALARS[c["type"]][2], c.get("doc", "")))
    const_by_name = {c.name: c.value for c in constants}

    enums: dict[str, Enum] = {}
    for e in raw.get("enum", []):
        _require(
            re.match(r"^[A-Z][A-Za-z0-9]*$", e["name"]) is not None, f"enum name {e['name']!r}"
        )
        _require(e["name"] not in enums and e["name"] not in SCALARS, f"duplicate enum {e['name']}")
        values = [EnumValue(v["name"], v["value"], v.get("doc", "")) for v in e["values"]]
        _require(bool(values), f"enum {e['name']} has no values")
        names = [v.name for v in values]
        nums = [v.value for v in values]
        _require(len(set(names)) == len(names), f"enum {e['name']}: duplicate names")
        _require(len(set(nums)) == len(nums), f"enum {e['name']}: duplicate values")
        for v in values:
            _require(_SNAKE.match(v.name) is not None, f"enum {e['name']}: value name {v.name!r}")
            _require(0 <= v.value <= 0xFF, f"enum {e['name']}.{v.name}: value must fit u8")
        enums[e["name"]] = Enum(e["name"], e.get("doc", ""), values)
    _require("ErrorCode" in enums, "the schema must declare enum ErrorCode")
    codes = enums["ErrorCode"].values
    core = [v.value for v in codes if v.value < base]
    _require(core == list(range(len(core))), "ErrorCode: core codes must be 0, 1, 2, ... in order")
    _require(codes[0].name == "ok", "ErrorCode 0 must be ok")

    flags = []
    for group in raw.get("flags", []):
        bits = set()
        for v in group["values"]:
            _require(0 <= v["bit"] <= 7 and v["bit"] not in bits, f"flag {v['name']}: bit")
            bits.add(v["bit"])
            flags.append(Flag(group["name"], v["name"], v["bit"], v.get("doc", "")))

    messages: list[Message] = []
    for m in raw.get("message", []):
        name = m["name"]
        _require(_MSG_NAME.match(name) is not None, f"message name {name!r}")
        direction = m["direction"]
        _require(direction in ("host_to_device", "device_to_host"), f"{name}: direction")
        lo, hi = HOST_TO_DEVICE_IDS if direction == "host_to_device" else DEVICE_TO_HOST_IDS
        _require(lo <= m["id"] <= hi, f"{name}: id 0x{m['id']:02X} outside 0x{lo:02X}..0x{hi:02X}")
        fields = []
        for f in m.get("fields", []):
            fname, ftype = f["name"], f["type"]
            _require(_SNAKE.match(fname) is not None, f"{name}.{fname}: field name")
            shape = tuple(f.get("shape", ()))
            _require(
                all(isinstance(n, int) and n > 0 for n in shape) and len(shape) <= 2,
                f"{name}.{fname}: shape must be 1 or 2 positive sizes",
            )
            if ftype in SCALARS:
                fields.append(
                    Field(
                        fname,
                        ftype,
                        None,
                        shape,
                        SCALARS[ftype][1],
                        f.get("unit", ""),
                        f.get("doc", ""),
                    )
                )
            elif ftype in enums:
                fields.append(
                    Field(fname, "enum", ftype, shape, 1, f.get("unit", ""), f.get("doc", ""))
                )
            elif ftype == "ascii":
                _require(
                    not shape and isinstance(f.get("size"), int) and f["size"] > 0,
                    f"{name}.{fname}: ascii needs a size and no shape",
                )
                fields.append(
                    Field(fname, "ascii", None, (), f["size"], f.get("unit", ""), f.get("doc", ""))
                )
            else:
                raise SchemaError(f"{name}.{fname}: unknown type {ftype!r}")
        _require(len({f.name for f in fields}) == len(fields), f"{name}: duplicate field names")
        for f, spec in zip(fields, m.get("fields", [])):
            if "default" in spec:
                f.default = _canonical(enums, f, spec["default"], f"{name}.{f.name} default")
        messages.append(Message(name, m["id"], direction, m.get("doc", ""), fields))
    _require(len({m.name for m in messages}) == len(messages), "duplicate message names")
    _require(len({m.msg_id for m in messages}) == len(messages), "duplicate message ids")

    # Shapes that hold contacts or the board name must agree with the named constants.
    for m in messages:
        for f in m.fields:
            if f.name == "contacts":
                _require(f.shape == (const_by_name["max_contacts"], 3), f"{m.name}.contacts shape")
            if f.name == "board":
                _require(f.size == const_by_name["board_name_size"], f"{m.name}.board size")

    for m in messages:
        # C++ and Python name a message's struct and an enum alike: they would collide.
        _require(m.class_name not in enums, f"{m.name}: its class name {m.class_name} is an enum's")
        for f in m.fields:
            if f.name == "participant":
                _require(f.size == const_by_name["participant_id_size"], f"{m.name}.participant")
            if f.name == "config_hash":
                _require(f.shape == (const_by_name["config_hash_size"],), f"{m.name}.config_hash")

    schema = Schema(version, base, constants, enums, flags, messages, [])
    by_name = {m.name: m for m in messages}
    for c in raw.get("copy", []):
        _require(_SNAKE.match(c["name"]) is not None, f"copy name {c['name']!r}")
        _require(c["message"] in by_name, f"copy {c['name']}: unknown message {c['message']}")
        msg = by_name[c["message"]]
        skip = set(c.get("skip", []))
        for other in c.get("skip_fields_of", []):
            _require(other in by_name, f"copy {c['name']}: unknown message {other}")
            skip |= {f.name for f in by_name[other].fields}
        unknown = set(c.get("skip", [])) - {f.name for f in msg.fields}
        _require(not unknown, f"copy {c['name']}: {msg.name} has no field {sorted(unknown)}")
        kept = [f for f in msg.fields if f.name not in skip]
        _require(bool(kept), f"copy {c['name']}: no field left to copy")
        schema.copies.append(FieldCopy(c["name"], msg, c.get("doc", ""), kept))
    _require(len({c.name for c in schema.copies}) == len(schema.copies), "duplicate copy names")
    for g in raw.get("golden", []):
        _require(g["message"] in by_name, f"golden {g['name']}: unknown message {g['message']}")
        msg = by_name[g["message"]]
        _require(0 <= g["seq"] <= 0xFFFF, f"golden {g['name']}: seq")
        given = dict(g.get("fields", {}))
        _require(
            set(given) == {f.name for f in msg.fields},
            f"golden {g['name']}: fields must be exactly {[f.name for f in msg.fields]}",
        )
        canon = {
            f.name: _canonical(schema.enums, f, given[f.name], f"golden {g['name']}.{f.name}")
            for f in msg.fields
        }
        schema.goldens.append(Golden(g["name"], msg, g["seq"], canon))
    _require(len({g.name for g in schema.goldens}) == len(schema.goldens), "duplicate golden names")
    _require(
        {g.message.name for g in schema.goldens} == set(by_name),
        "every message needs at least one golden frame",
    )
    return schema


def _canonical(enums: dict[str, Enum], f: Field, value: Any, where: str) -> Any:
    def one(v: Any) -> Any:
        if f.kind == "f32":
            _require(isinstance(v, (int, float)) and not isinstance(v, bool), f"{where}: number")
            return f32(float(v))
        if f.kind == "bool":
            _require(isinstance(v, bool), f"{where}: true/false")
            return v
        if f.kind == "enum":
            names = [e.name for e in enums[f.enum].values]
            _require(v in names, f"{where}: one of {names}")
            return v
        if f.kind == "ascii":
            _require(
                isinstance(v, str) and len(v) <= f.size and all(0x20 <= ord(c) <= 0x7E for c in v),
                f"{where}: printable ASCII <= {f.size}",
            )
            return v
        lo, hi = SCALARS[f.kind][4:6]
        _require(
            isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi, f"{where}: int range"
        )
        return v

    def walk(v: Any, shape: tuple[int, ...]) -> Any:
        if not shape:
            return one(v)
        _require(isinstance(v, list) and len(v) == shape[0], f"{where}: shape {f.shape}")
        return [walk(x, shape[1:]) for x in v]

    return walk(value, f.shape)
