// The wire codec of every message, written once over its generated for_each_field: pack,
// unpack and wire equality. messages.h declares only each message's struct, sizes and
// field list; the element types a schema may use (u8..i32, f32, bool, one-byte enums,
// NUL-padded ASCII, arrays of them) are handled here, little-endian.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "graspguide_link/byte_order.h"
#include "graspguide_link/link_status.h"

namespace graspguide::link {
namespace wire {

// Writes one element at p and moves p past it: integers little-endian, whatever their size.
template <class T, std::enable_if_t<std::is_integral<T>::value, int> = 0>
void put(uint8_t*& p, T v) {
  static_assert(sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4, "u8..u32, i8..i32");
  using U = std::make_unsigned_t<T>;
  if constexpr (sizeof(T) == 1) {
    store_u8(p, static_cast<U>(v));
  } else if constexpr (sizeof(T) == 2) {
    store_u16(p, static_cast<U>(v));
  } else {
    store_u32(p, static_cast<U>(v));
  }
  p += sizeof(T);
}
inline void put(uint8_t*& p, float v) { put(p, f32_bits(v)); }
inline void put(uint8_t*& p, bool v) { put(p, static_cast<uint8_t>(v ? 1 : 0)); }
template <class E, std::enable_if_t<std::is_enum<E>::value, int> = 0>
void put(uint8_t*& p, E v) {
  put(p, static_cast<uint8_t>(v));
}
template <size_t N>
void put(uint8_t*& p, const char (&text)[N]) {
  std::memcpy(p, text, N);
  p += N;
}
template <class T, size_t N>
void put(uint8_t*& p, const T (&array)[N]) {
  for (const T& x : array) put(p, x);
}

// Reads one element at p into v and moves p past it; false (v untouched) for a value
// outside the element's declared set, which moves p past it too.
template <class T, std::enable_if_t<std::is_integral<T>::value, int> = 0>
bool get(const uint8_t*& p, T& v) {
  if constexpr (sizeof(T) == 1) {
    v = static_cast<T>(load_u8(p));
  } else if constexpr (sizeof(T) == 2) {
    v = static_cast<T>(load_u16(p));
  } else {
    v = static_cast<T>(load_u32(p));
  }
  p += sizeof(T);
  return true;
}
inline bool get(const uint8_t*& p, float& v) {
  uint32_t bits = 0;
  get(p, bits);
  v = f32_from_bits(bits);
  return true;
}
inline bool get(const uint8_t*& p, bool& v) {
  const uint8_t byte = load_u8(p);
  p += 1;
  if (byte > 1) return false;
  v = byte == 1;
  return true;
}
template <class E, std::enable_if_t<std::is_enum<E>::value, int> = 0>
bool get(const uint8_t*& p, E& v) {
  const E e = static_cast<E>(load_u8(p));
  p += 1;
  if (!is_valid(e)) return false;  // the generated is_valid of this enum, found by ADL
  v = e;
  return true;
}
template <size_t N>
bool get(const uint8_t*& p, char (&text)[N]) {
  const bool valid = ascii_field_valid(p, N);
  if (valid) std::memcpy(text, p, N);
  p += N;
  return valid;
}
template <class T, size_t N>
bool get(const uint8_t*& p, T (&array)[N]) {
  bool valid = true;
  for (T& x : array) valid = get(p, x) && valid;
  return valid;
}

// Whether a decoder accepts the value: pack refuses what unpack would reject, so every
// frame written parses back.
template <class T, std::enable_if_t<std::is_arithmetic<T>::value, int> = 0>
bool decodable(const T&) {
  return true;
}
template <class E, std::enable_if_t<std::is_enum<E>::value, int> = 0>
bool decodable(const E& v) {
  return is_valid(v);
}
template <size_t N>
bool decodable(const char (&text)[N]) {
  return ascii_field_valid(reinterpret_cast<const uint8_t*>(text), N);
}
template <class T, size_t N>
bool decodable(const T (&array)[N]) {
  for (const T& x : array) {
    if (!decodable(x)) return false;
  }
  return true;
}

template <class T, class = void>
struct IsMessage : std::false_type {};
template <class T>
struct IsMessage<T, std::void_t<decltype(T::kPayloadSize), decltype(T::kId)>> : std::true_type {};

}  // namespace wire

template <class Msg>
using EnableIfMessage = std::enable_if_t<wire::IsMessage<Msg>::value, int>;

// Writes the kPayloadSize-byte payload; kBadEnumValue for a value no decoder accepts.
template <class Msg, EnableIfMessage<Msg> = 0>
LinkStatus pack(const Msg& m, uint8_t* out, size_t capacity, size_t* written) {
  if (capacity < Msg::kPayloadSize) return LinkStatus::kBufferTooSmall;
  bool ok = true;
  for_each_field(m, [&ok](const char*, const auto& field) { ok = ok && wire::decodable(field); });
  if (!ok) return LinkStatus::kBadEnumValue;
  uint8_t* at = out;
  for_each_field(m, [&at](const char*, const auto& field) { wire::put(at, field); });
  *written = Msg::kPayloadSize;
  return LinkStatus::kOk;
}

// kBadLength for a wrong size; kBadEnumValue (and *bad_field = the field's index) for an
// enum, bool or ascii field outside its declared set. *out is untouched then.
template <class Msg, EnableIfMessage<Msg> = 0>
LinkStatus unpack(const uint8_t* in, size_t size, Msg* out, uint8_t* bad_field = nullptr) {
  if (size != Msg::kPayloadSize) return LinkStatus::kBadLength;
  Msg m;
  const uint8_t* at = in;
  // Every field is read (a bad one moves on like a good one); the first bad one is named.
  uint8_t index = 0;
  uint8_t first_bad = 0xFF;
  for_each_field(m, [&](const char*, auto& field) {
    if (!wire::get(at, field) && first_bad == 0xFF) first_bad = index;
    ++index;
  });
  if (first_bad != 0xFF) {
    if (bad_field != nullptr) *bad_field = first_bad;
    return LinkStatus::kBadEnumValue;
  }
  *out = m;
  return LinkStatus::kOk;
}

// One field of a generated copy_NAME_fields (messages.h) between a message and a device's
// own type: a value by static_cast (an enum to or from its integer, double to float), an
// array element by element.
template <class From, class To>
void copy_field(const From& from, To& to) {
  to = static_cast<To>(from);
}
template <class From, class To, size_t N>
void copy_field(const From (&from)[N], To (&to)[N]) {
  for (size_t i = 0; i < N; ++i) copy_field(from[i], to[i]);
}

// Wire equality: the same payload bytes (floats by bit pattern: NaN == the same NaN,
// -0 != +0; ascii fields over all their bytes).
template <class Msg, EnableIfMessage<Msg> = 0>
bool operator==(const Msg& a, const Msg& b) {
  uint8_t wire_a[Msg::kPayloadSize + 1];  // + 1: a message without fields
  uint8_t wire_b[Msg::kPayloadSize + 1];
  uint8_t* at = wire_a;
  for_each_field(a, [&at](const char*, const auto& field) { wire::put(at, field); });
  at = wire_b;
  for_each_field(b, [&at](const char*, const auto& field) { wire::put(at, field); });
  return std::memcmp(wire_a, wire_b, Msg::kPayloadSize) == 0;
}
template <class Msg, EnableIfMessage<Msg> = 0>
bool operator!=(const Msg& a, const Msg& b) {
  return !(a == b);
}

}  // namespace graspguide::link
