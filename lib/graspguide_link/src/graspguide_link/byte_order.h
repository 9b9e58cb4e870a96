// Little-endian loads and stores: the wire order is fixed, whatever the CPU's order.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

namespace graspguide::link {

static_assert(sizeof(float) == 4 && std::numeric_limits<float>::is_iec559,
              "the wire carries IEEE-754 binary32");

inline void store_u8(uint8_t* p, uint8_t v) { p[0] = v; }
inline void store_u16(uint8_t* p, uint16_t v) {
  p[0] = static_cast<uint8_t>(v);
  p[1] = static_cast<uint8_t>(v >> 8);
}
inline void store_u32(uint8_t* p, uint32_t v) {
  for (size_t i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
inline void store_i8(uint8_t* p, int8_t v) { store_u8(p, static_cast<uint8_t>(v)); }
inline void store_i16(uint8_t* p, int16_t v) { store_u16(p, static_cast<uint16_t>(v)); }
inline void store_i32(uint8_t* p, int32_t v) { store_u32(p, static_cast<uint32_t>(v)); }

// memcpy is the portable bit cast in C++17 (no type punning through unions).
inline uint32_t f32_bits(float v) {
  uint32_t bits = 0;
  std::memcpy(&bits, &v, sizeof bits);
  return bits;
}
inline float f32_from_bits(uint32_t bits) {
  float v = 0;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}
inline void store_f32(uint8_t* p, float v) { store_u32(p, f32_bits(v)); }

inline uint8_t load_u8(const uint8_t* p) { return p[0]; }
inline uint16_t load_u16(const uint8_t* p) {
  return static_cast<uint16_t>(p[0] | (static_cast<uint16_t>(p[1]) << 8));
}
inline uint32_t load_u32(const uint8_t* p) {
  uint32_t v = 0;
  for (size_t i = 0; i < 4; ++i) v |= static_cast<uint32_t>(p[i]) << (8 * i);
  return v;
}
inline int8_t load_i8(const uint8_t* p) { return static_cast<int8_t>(load_u8(p)); }
inline int16_t load_i16(const uint8_t* p) { return static_cast<int16_t>(load_u16(p)); }
inline int32_t load_i32(const uint8_t* p) { return static_cast<int32_t>(load_u32(p)); }
inline float load_f32(const uint8_t* p) { return f32_from_bits(load_u32(p)); }

// An ascii field is printable ASCII padded with NULs to its size, so that it decodes to
// one string and re-encodes to the same bytes.
inline bool ascii_field_valid(const uint8_t* p, size_t size) {
  size_t i = 0;
  while (i < size && p[i] != 0) {
    if (p[i] < 0x20 || p[i] > 0x7E) return false;
    ++i;
  }
  for (; i < size; ++i)
    if (p[i] != 0) return false;
  return true;
}

}  // namespace graspguide::link
