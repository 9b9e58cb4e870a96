"""lib/graspguide_link/src/graspguide_link/messages.h: ids, enums, one struct per message."""

from __future__ import annotations

import math
from typing import Any

from codegen.schema import (
    DEVICE_TO_HOST_IDS,
    GENERATOR,
    HOST_TO_DEVICE_IDS,
    REGEN,
    SCALARS,
    SOURCE,
    Field,
    Message,
    Schema,
    camel,
    f32,
)


def cpp_enumerator(name: str) -> str:
    return "k" + camel(name)


def cpp_float(x: float) -> str:
    """Shortest decimal that reads back as the same float32, as a C++ float literal."""
    if math.isinf(x):
        return "-INFINITY" if x < 0 else "INFINITY"
    for digits in range(1, 10):
        s = f"{x:.{digits}g}"
        if f32(float(s)) == x:
            break
    s = repr(float(s))  # the same number, as Python writes it: 90.0 rather than 9e+01
    if not any(c in s for c in ".en"):
        s += ".0"
    return s + "f"


def cpp_comment(f: Field) -> str:
    unit = f" [{f.unit}]" if f.unit else ""
    return f"{f.type_label}{unit}: {f.doc}" if f.doc else f"{f.type_label}{unit}"


def cpp_member(schema: Schema, f: Field) -> str:
    dims = "".join(f"[{n}]" for n in f.shape)
    if f.kind == "ascii":
        init = "{}" if f.default is None else cpp_value(schema, f, f.default, "")
        return f"char {f.name}[{f.size}] = {init};"
    ctype = f.enum if f.kind == "enum" else SCALARS[f.kind][2]
    if f.default is None:
        init = "{}"
    elif f.shape:
        init = cpp_value(schema, f, f.default, "")
    else:
        init = "{" + cpp_value(schema, f, f.default, "") + "}"
    return f"{ctype} {f.name}{dims} = {init};"


def _loops(f: Field, body: str, indent: str) -> list[str]:
    """Nested index loops over f.shape around body (which uses i0, i1 and `flat`)."""
    lines = []
    idx = ["i0", "i1"][: len(f.shape)]
    for d, (var, n) in enumerate(zip(idx, f.shape)):
        lines.append(f"{indent}{'  ' * d}for (size_t {var} = 0; {var} < {n}; ++{var}) {{")
    lines.append(f"{indent}{'  ' * len(idx)}{body}")
    for d in reversed(range(len(idx))):
        lines.append(f"{indent}{'  ' * d}}}")
    return lines


def _flat_index(f: Field) -> str:
    if len(f.shape) == 1:
        return "i0"
    return f"(i0 * {f.shape[1]} + i1)"


def _element(f: Field) -> str:
    return f.name + "".join(f"[{v}]" for v in ["i0", "i1"][: len(f.shape)])


def cpp_pack(m: Message) -> list[str]:
    L = [
        f"inline LinkStatus pack(const {m.class_name}& m, uint8_t* out, size_t capacity,"
        " size_t* written) {"
    ]
    if not m.fields:
        L.append("  (void)m;")
        L.append("  (void)out;")
    L.append(f"  if (capacity < {m.class_name}::kPayloadSize) return LinkStatus::kBufferTooSmall;")
    # Refuse to emit what no decoder accepts, so every frame we write parses back.
    for f in m.fields:
        if f.kind == "enum":
            if f.shape:
                L += _loops(
                    f, f"if (!is_valid(m.{_element(f)})) return LinkStatus::kBadEnumValue;", "  "
                )
            else:
                L.append(f"  if (!is_valid(m.{f.name})) return LinkStatus::kBadEnumValue;")
        if f.kind == "ascii":
            L.append(
                "  if (!ascii_field_valid("
                f"reinterpret_cast<const uint8_t*>(m.{f.name}), {f.size})) "
                "return LinkStatus::kBadEnumValue;"
            )
    off = 0
    for f in m.fields:
        if f.kind == "ascii":
            L.append(f"  std::memcpy(out + {off}, m.{f.name}, {f.size});")
        else:
            suffix = "u8" if f.kind in ("enum", "bool") else SCALARS[f.kind][3]
            if f.kind == "enum":
                conv = lambda e: f"static_cast<uint8_t>(m.{e})"  # noqa: E731
            elif f.kind == "bool":
                conv = lambda e: f"static_cast<uint8_t>(m.{e} ? 1 : 0)"  # noqa: E731
            else:
                conv = lambda e: f"m.{e}"  # noqa: E731
            if f.shape:
                at = f"out + {off} + {f.size} * {_flat_index(f)}"
                body = f"store_{suffix}({at}, {conv(_element(f))});"
                L += _loops(f, body, "  ")
            else:
                L.append(f"  store_{suffix}(out + {off}, {conv(f.name)});")
        off += f.wire_size
    L.append(f"  *written = {m.class_name}::kPayloadSize;")
    L.append("  return LinkStatus::kOk;")
    L.append("}")
    return L


def cpp_unpack(m: Message) -> list[str]:
    L = [
        f"inline LinkStatus unpack(const uint8_t* in, size_t size, {m.class_name}* out,",
        "                         uint8_t* bad_field = nullptr) {",
    ]
    if not m.fields:
        L.append("  (void)in;")
        L.append("  (void)out;")
    if not any(f.kind in ("enum", "bool", "ascii") for f in m.fields):
        L.append("  (void)bad_field;")
    L.append(f"  if (size != {m.class_name}::kPayloadSize) return LinkStatus::kBadLength;")
    if m.fields:
        L.append(f"  {m.class_name} m;")
    off = 0
    for index, f in enumerate(m.fields):
        bad = (
            f"{{ if (bad_field != nullptr) *bad_field = {index}; "
            "return LinkStatus::kBadEnumValue; }"
        )
        if f.kind == "ascii":
            L.append(f"  if (!ascii_field_valid(in + {off}, {f.size})) {bad}")
            L.append(f"  std::memcpy(m.{f.name}, in + {off}, {f.size});")
        elif f.kind in ("enum", "bool"):
            at = f"in + {off}" + (f" + {_flat_index(f)}" if f.shape else "")
            if f.kind == "enum":
                body = [
                    f"const {f.enum} v = static_cast<{f.enum}>(load_u8({at}));",
                    f"if (!is_valid(v)) {bad}",
                    f"m.{_element(f) if f.shape else f.name} = v;",
                ]
            else:
                body = [
                    f"const uint8_t v = load_u8({at});",
                    f"if (v > 1) {bad}",
                    f"m.{_element(f) if f.shape else f.name} = v == 1;",
                ]
            if f.shape:
                L += _loops(f, "{ " + " ".join(body) + " }", "  ")
            else:
                L.append("  {")
                L += ["    " + b for b in body]
                L.append("  }")
        else:
            suffix = SCALARS[f.kind][3]
            if f.shape:
                body = f"m.{_element(f)} = load_{suffix}(in + {off} + {f.size} * {_flat_index(f)});"
                L += _loops(f, body, "  ")
            else:
                L.append(f"  m.{f.name} = load_{suffix}(in + {off});")
        off += f.wire_size
    if m.fields:
        L.append("  *out = m;")
    L.append("  return LinkStatus::kOk;")
    L.append("}")
    return L


def cpp_equal(m: Message) -> list[str]:
    c = m.class_name
    L = [f"inline bool operator==(const {c}& a, const {c}& b) {{"]
    if not m.fields:
        L += ["  (void)a;", "  (void)b;", "  return true;", "}"]
    else:
        L.append("  bool same = true;")
        for f in m.fields:
            if f.kind == "ascii":
                L.append(f"  same = same && std::memcmp(a.{f.name}, b.{f.name}, {f.size}) == 0;")
                continue
            if f.kind == "f32":
                cmp = lambda e: f"f32_bits(a.{e}) == f32_bits(b.{e})"  # noqa: E731
            else:
                cmp = lambda e: f"a.{e} == b.{e}"  # noqa: E731
            if f.shape:
                L += _loops(f, f"same = same && {cmp(_element(f))};", "  ")
            else:
                L.append(f"  same = same && {cmp(f.name)};")
        L += ["  return same;", "}"]
    L += [f"inline bool operator!=(const {c}& a, const {c}& b) {{ return !(a == b); }}"]
    return L


def render(schema: Schema) -> str:
    s = schema
    L: list[str] = [
        f"// GENERATED by {GENERATOR} from {SOURCE}.",
        f"// DO NOT EDIT: change the schema, then run `{REGEN}`.",
        "// The GraspGuide link messages: ids, enums, payload structs, and their wire codecs",
        "// (little-endian, float32). See docs/protocol.md.",
        "#pragma once",
        "",
        "#include <cstddef>",
        "#include <cstdint>",
        "#include <cstring>",
        "",
        '#include "graspguide_link/byte_order.h"',
        '#include "graspguide_link/link_status.h"',
        "",
        "namespace graspguide_link {",
        "",
    ]
    for c in s.named_constants:
        L.append(f"// {c.doc}")
        L.append(f"inline constexpr {c.ctype} k{camel(c.name)} = {c.literal};")
    L += [
        "",
        "// Every schema enum has an EnumInfo: its values in schema order.",
        "template <class E>",
        "struct EnumInfo;",
        "",
    ]
    for e in s.enums.values():
        L.append(f"// {e.doc}")
        L.append(f"enum class {e.name} : uint8_t {{")
        for v in e.values:
            L.append(f"  {cpp_enumerator(v.name)} = 0x{v.value:02X},  // {v.doc}")
        L.append("};")
        L.append("template <>")
        L.append(f"struct EnumInfo<{e.name}> {{")
        L.append(f"  static constexpr size_t kCount = {len(e.values)};")
        L.append(f"  static constexpr {e.name} kValues[kCount] = {{")
        for v in e.values:
            L.append(f"      {e.name}::{cpp_enumerator(v.name)},")
        L.append("  };")
        L.append("};")
        L.append(f"constexpr bool is_valid({e.name} v) {{")
        L.append("  switch (v) {")
        for v in e.values:
            L.append(f"    case {e.name}::{cpp_enumerator(v.name)}:")
        L.append("      return true;")
        L.append("  }")
        L.append("  return false;")
        L.append("}")
        L.append('// The schema\'s snake_case name; "unknown" for a value outside the enum.')
        L.append(f"constexpr const char* enum_name({e.name} v) {{")
        L.append("  switch (v) {")
        for v in e.values:
            L.append(f'    case {e.name}::{cpp_enumerator(v.name)}: return "{v.name}";')
        L.append("  }")
        L.append('  return "unknown";')
        L.append("}")
        L.append("")

    L.append("enum class MsgId : uint8_t {")
    for m in s.messages:
        L.append(f"  {cpp_enumerator(m.name)} = 0x{m.msg_id:02X},")
    L.append("};")
    L.append(f"inline constexpr size_t kMessageCount = {len(s.messages)};")
    L.append(f"inline constexpr size_t kMaxPayloadSize = {s.max_payload};")
    L.append("")
    L.append("constexpr bool is_host_to_device_id(uint8_t id) {")
    L.append(
        f"  return id >= 0x{HOST_TO_DEVICE_IDS[0]:02X} && id <= 0x{HOST_TO_DEVICE_IDS[1]:02X};"
    )
    L.append("}")
    L.append("constexpr bool is_device_to_host_id(uint8_t id) {")
    L.append(
        f"  return id >= 0x{DEVICE_TO_HOST_IDS[0]:02X} && id <= 0x{DEVICE_TO_HOST_IDS[1]:02X};"
    )
    L.append("}")
    L.append("")
    L.append('// The schema\'s name of a message id; "unknown" if no message has it.')
    L.append("constexpr const char* message_name(uint8_t msg_id) {")
    L.append("  switch (msg_id) {")
    for m in s.messages:
        L.append(f'    case 0x{m.msg_id:02X}: return "{m.name}";')
    L.append("  }")
    L.append('  return "unknown";')
    L.append("}")
    L.append("")
    L.append("// Payload size of a message id; false if no message has this id.")
    L.append("constexpr bool payload_size_of(uint8_t msg_id, size_t* size) {")
    L.append("  switch (msg_id) {")
    for m in s.messages:
        L.append(f"    case 0x{m.msg_id:02X}: *size = {m.payload_size}; return true;")
    L.append("  }")
    L.append("  return false;")
    L.append("}")
    L.append("")

    for m in s.messages:
        arrow = m.arrow("->")
        L.append(f"// {m.name} (0x{m.msg_id:02X}, {arrow}): {m.doc}")
        L.append(f"struct {m.class_name} {{")
        L.append(f"  static constexpr MsgId kId = MsgId::{cpp_enumerator(m.name)};")
        L.append(f'  static constexpr const char* kName = "{m.name}";')
        L.append(f"  static constexpr size_t kPayloadSize = {m.payload_size};")
        for f in m.fields:
            L.append(f"  {cpp_member(s, f)}  // {cpp_comment(f)}")
        L.append("};")
        L.append("")
        L.append(f"// Writes the {m.payload_size}-byte payload; refuses values no decoder accepts.")
        L += cpp_pack(m)
        L.append(
            "// kBadLength for a wrong size; kBadEnumValue (and *bad_field = the field's index)"
        )
        L.append(
            "// for an enum, bool or ascii field outside its declared set. *out is untouched then."
        )
        L += cpp_unpack(m)
        L.append("// Wire equality: floats compare by bit pattern (NaN == same NaN, -0 != +0).")
        L += cpp_equal(m)
        L.append('// Calls fn("name", member) for every field, in wire order.')
        for const in ("const ", ""):
            L.append("template <class Fn>")
            L.append(f"void for_each_field({const}{m.class_name}& m, Fn&& fn) {{")
            if not m.fields:
                L += ["  (void)m;", "  (void)fn;"]
            for f in m.fields:
                L.append(f'  fn("{f.name}", m.{f.name});')
            L.append("}")
        L.append("")

    L.append("template <class... Messages>")
    L.append("struct MessageList {};")
    L.append(
        "using AllMessages = MessageList<" + ", ".join(m.class_name for m in s.messages) + ">;"
    )
    L.append("")
    L.append("// Unpacks a payload into the struct its id names and calls visitor(message).")
    L.append("// kUnknownId, or unpack()'s status, without calling the visitor when it fails.")
    L.append("template <class Visitor>")
    L.append(
        "LinkStatus visit_payload(uint8_t msg_id, const uint8_t* payload, size_t size,"
        " Visitor&& visitor,"
    )
    L.append("                         uint8_t* bad_field = nullptr) {")
    L.append("  switch (msg_id) {")
    for m in s.messages:
        L.append(f"    case 0x{m.msg_id:02X}: {{")
        L.append(f"      {m.class_name} m;")
        L.append("      const LinkStatus status = unpack(payload, size, &m, bad_field);")
        L.append("      if (status != LinkStatus::kOk) return status;")
        L.append("      visitor(m);")
        L.append("      return LinkStatus::kOk;")
        L.append("    }")
    L.append("  }")
    L.append("  return LinkStatus::kUnknownId;")
    L.append("}")
    L.append("")
    L.append("}  // namespace graspguide_link")
    L.append("")
    return "\n".join(L)


def cpp_value(schema: Schema, f: Field, v: Any, ns: str = "gl::") -> str:
    if isinstance(v, list):
        return "{" + ", ".join(cpp_value(schema, f, x, ns) for x in v) + "}"
    if f.kind == "f32":
        return cpp_float(v)
    if f.kind == "bool":
        return "true" if v else "false"
    if f.kind == "enum":
        return f"{ns}{f.enum}::{cpp_enumerator(v)}"
    if f.kind == "ascii":
        return (
            "{"
            + ", ".join(
                [f"'{c}'" if c not in "'\\" else f"'\\{c}'" for c in v] + ["0"] * (f.size - len(v))
            )
            + "}"
        )
    if f.kind.startswith("u"):
        return f"{v}u"
    return str(v)
