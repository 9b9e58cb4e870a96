"""lib/graspguide_cue_device/src/graspguide_cue_device/link_subset.h: the messages a
per-frame-only board (the Pro Mini) speaks, in C++14 for avr-gcc 5.4 without a C++
standard library: ids, the enums those messages use, one struct per message and a plain
pack or unpack function for each (no templates over field lists, no if constexpr)."""

from __future__ import annotations

from codegen.emit_cpp import cpp_enumerator, cpp_member
from codegen.schema import (
    CRC_SIZE,
    GENERATOR,
    HEADER_SIZE,
    HOST_TO_DEVICE_IDS,
    REGEN,
    SCALARS,
    SOURCE,
    Field,
    Message,
    Schema,
    SchemaError,
    camel,
)

# What the board takes and what it sends; every other host -> device id is answered
# (per_frame_only or unknown_id) from its header alone, so its struct is not needed here.
ACCEPTED = (
    "HELLO",
    "SET_POSTURE",
    "SET_CALIBRATION",
    "START_TRIAL",
    "POSE",
    "STOP",
    "SET_MOTORS",
    "GET_STATUS",
)
SENT = ("ACK", "ERROR", "HELLO_REPLY", "TELEMETRY", "TRIAL_RESULT", "STATUS")
# Ids answered per_frame_only rather than unknown_id: what a full-solve device does instead.
PER_FRAME_ONLY = ("SET_SCENE",)
# Ids every real board answers sim_only, as a full-solve board without a simulator does.
SIM_ONLY = ("SIM_IMU_SAMPLE", "SIM_BUTTON")
# The schema constants the board uses.
CONSTANTS = ("pose_watchdog_ms", "max_contacts", "board_name_size")
# The flag groups whose bits the board sets or reads.
FLAG_GROUPS = ("capability", "telemetry_flag")


def _message(schema: Schema, name: str) -> Message:
    for m in schema.messages:
        if m.name == name:
            return m
    raise SchemaError(f"emit_avr: the subset names {name}, which the schema does not have")


def _put(f: Field, expr: str) -> str:
    if f.kind == "enum":
        return f"put_u8(at, static_cast<uint8_t>({expr}));"
    if f.kind == "bool":
        return f"put_u8(at, {expr} ? 1 : 0);"
    return f"put_{SCALARS[f.kind][3]}(at, {expr});"


def _get(f: Field, expr: str) -> str:
    if f.kind == "enum":
        return f"ok = get_enum(at, &{expr}) && ok;"
    if f.kind == "bool":
        return f"ok = get_bool(at, &{expr}) && ok;"
    return f"get_{SCALARS[f.kind][3]}(at, &{expr});"


def _elements(f: Field) -> list[str]:
    """The C++ expression of every element of the field, in wire order."""
    names = [f"m.{f.name}"]
    for n in f.shape:
        names = [f"{p}[{i}]" for p in names for i in range(n)]
    return names


def _pack(m: Message) -> list[str]:
    L = [f"inline void pack(const {m.class_name}& m, uint8_t* out) {{"]
    if not m.fields:
        L += ["  (void)m;", "  (void)out;", "}"]
        return L
    L.append("  uint8_t* at = out;")
    for f in m.fields:
        if f.kind == "ascii":
            L.append(
                f"  for (uint8_t i = 0; i < {f.size}; ++i) put_u8(at, uint8_t(m.{f.name}[i]));"
            )  # noqa: E501
            continue
        L += [f"  {_put(f, e)}" for e in _elements(f)]
    L.append("}")
    return L


def _unpack(m: Message) -> list[str]:
    L = [
        "// false, *bad_field = the first invalid field's index, for an enum or bool outside",
        "// its set (*out untouched then).",
        f"inline bool unpack(const uint8_t* in, {m.class_name}* out, uint8_t* bad_field) {{",
    ]
    if not m.fields:
        L += ["  (void)in;", "  (void)out;", "  (void)bad_field;", "  return true;", "}"]
        return L
    L += [f"  {m.class_name} m;", "  const uint8_t* at = in;"]
    if not any(f.kind in ("enum", "bool") for f in m.fields):
        L.append("  (void)bad_field;  // every value of these fields is valid")
    for index, f in enumerate(m.fields):
        if f.kind == "ascii":
            raise SchemaError(f"emit_avr: {m.name}.{f.name}: ascii fields are only sent")
        checked = f.kind in ("enum", "bool")
        if checked:
            L.append("  {")
            L.append("    bool ok = true;")
            L += [f"    {_get(f, e)}" for e in _elements(f)]
            L.append("    if (!ok) {")
            L.append(f"      *bad_field = {index};")
            L.append("      return false;")
            L.append("    }")
            L.append("  }")
        else:
            L += [f"  {_get(f, e)}" for e in _elements(f)]
    L += ["  *out = m;", "  return true;", "}"]
    return L


def render(schema: Schema) -> str:
    s = schema
    accepted = [_message(s, n) for n in ACCEPTED]
    sent = [_message(s, n) for n in SENT]
    per_frame_only = [_message(s, n) for n in PER_FRAME_ONLY]
    sim_only = [_message(s, n) for n in SIM_ONLY]
    used_enums: list[str] = []
    for m in accepted + sent:
        for f in m.fields:
            if f.kind == "enum" and f.enum not in used_enums:
                used_enums.append(f.enum or "")
    largest_accepted = max(m.payload_size for m in accepted)
    largest_sent = max(m.payload_size for m in sent)
    host_to_device = [
        m for m in s.messages if HOST_TO_DEVICE_IDS[0] <= m.msg_id <= HOST_TO_DEVICE_IDS[1]
    ]

    L: list[str] = [
        f"// GENERATED by {GENERATOR} (emit_avr.py) from {SOURCE}.",
        f"// DO NOT EDIT: change the schema, then run `{REGEN}`.",
        "// The per-frame-only board's part of the GraspGuide link (docs/protocol.md): the ids",
        "// and sizes of every host -> device message (so any frame is answered as a full-solve",
        "// device would), and structs with pack/unpack for the messages it takes and sends.",
        "// C++14 without a C++ standard library, for avr-gcc 5.4 as for the host.",
        "#pragma once",
        "",
        "#include <stddef.h>",
        "#include <stdint.h>",
        "",
        '#include "graspguide_cue/status.h"',
        '#include "graspguide_cue_device/wire.h"',
        "",
        "namespace graspguide {",
        "namespace cue_device {",
        "namespace link {",
        "",
        f"constexpr uint8_t kProtocolVersion = {s.version};",
    ]
    for c in s.constants:
        if c.name in CONSTANTS:
            L.append(f"constexpr {c.ctype} k{camel(c.name)} = {c.literal};")
    for fl in s.flags:
        if fl.group in FLAG_GROUPS:
            L.append(f"constexpr uint8_t k{camel(fl.group)}{camel(fl.name)} = 0x{1 << fl.bit:02X};")
    L += [
        "",
        f"constexpr size_t kHeaderSize = {HEADER_SIZE};",
        f"constexpr size_t kCrcSize = {CRC_SIZE};",
        "// The schema's largest payload: a longer frame is too_long, as on every device.",
        f"constexpr size_t kSchemaMaxPayloadSize = {s.max_payload};",
        "// The largest payload this board decodes; larger frames are checked (CRC, length)",
        "// without being stored.",
        f"constexpr size_t kMaxAcceptedPayloadSize = {largest_accepted};",
        f"constexpr size_t kMaxSentPayloadSize = {largest_sent};",
        "",
    ]
    for name in used_enums:
        e = s.enums[name]
        L.append(f"// {e.doc}")
        L.append(f"enum class {e.name} : uint8_t {{")
        for v in e.values:
            L.append(f"  {cpp_enumerator(v.name)} = 0x{v.value:02X},")
        L.append("};")
        L.append(f"constexpr bool is_valid({e.name} v) {{")
        L.append("  switch (v) {")
        for v in e.values:
            L.append(f"    case {e.name}::{cpp_enumerator(v.name)}:")
        L += ["      return true;", "  }", "  return false;", "}"]
        L.append("")

    L.append("enum class MsgId : uint8_t {")
    for m in host_to_device + sent:
        L.append(f"  {cpp_enumerator(m.name)} = 0x{m.msg_id:02X},")
    L.append("};")
    L.append("")
    L.append("// Payload size of a host -> device id; false if no such message exists.")
    L.append("constexpr bool host_payload_size(uint8_t msg_id, size_t* size) {")
    L.append("  switch (msg_id) {")
    for m in host_to_device:
        L += [
            f"    case 0x{m.msg_id:02X}:",
            f"      *size = {m.payload_size};",
            "      return true;",
        ]
    L += ["  }", "  return false;", "}"]
    L.append("")
    L.append(
        "// The ERROR code of a host -> device id this board does not take: per_frame_only for"
    )
    L.append("// what needs the full solve, sim_only for a simulator's, unknown_id for the rest.")
    L.append("constexpr ErrorCode refusal_of(uint8_t msg_id) {")
    L.append("  switch (msg_id) {")
    L += [f"    case 0x{m.msg_id:02X}:" for m in per_frame_only]
    L.append("      return ErrorCode::kPerFrameOnly;")
    L += [f"    case 0x{m.msg_id:02X}:" for m in sim_only]
    L.append("      return ErrorCode::kSimOnly;")
    L += ["  }", "  return ErrorCode::kUnknownId;", "}", ""]
    for m in accepted + sent:
        L.append(f"// {m.name} (0x{m.msg_id:02X}, {m.arrow('->')}).")
        L.append(f"struct {m.class_name} {{")
        L.append(f"  static constexpr uint8_t kId = 0x{m.msg_id:02X};")
        L.append(f"  static constexpr size_t kPayloadSize = {m.payload_size};")
        if m in accepted:
            L += [
                f"  static constexpr uint8_t kField{camel(f.name)} = {i};"
                for i, f in enumerate(m.fields)
            ]
        for f in m.fields:
            L.append(f"  {cpp_member(s, f).replace('gl::', '')}")
        L.append("};")
        L += _pack(m) if m in sent else _unpack(m)
        L.append("")
    core = [v for v in s.enums["ErrorCode"].values if v.value < s.link_error_base]
    L += [
        "// The core's statuses are the first ErrorCodes, name for name and value for value",
        "// (graspguide_cue/status.h): checked here, so a status converts by value.",
        "using CoreStatus = graspguide::Status;",
        f'static_assert(graspguide::kStatusCount == {len(core)}, "statuses and schema differ");',
        "constexpr bool same_value(CoreStatus s, ErrorCode e) { return uint8_t(s) == uint8_t(e); }",
    ]
    for v in core:
        e = cpp_enumerator(v.name)
        check = f"static_assert(same_value(CoreStatus::{e}, ErrorCode::{e}),"
        one_line = f'{check} "{v.name}");'
        # Laid out as clang-format lays it out: the file is checked like hand-written code.
        L += [one_line] if len(one_line) <= 100 else [check, f'              "{v.name}");']
    L += [
        "constexpr ErrorCode error_code_of(CoreStatus s) { return static_cast<ErrorCode>(s); }",
        "",
    ]
    L.append("}  // namespace link")
    L.append("}  // namespace cue_device")
    L.append("}  // namespace graspguide")
    L.append("")
    return "\n".join(L)
