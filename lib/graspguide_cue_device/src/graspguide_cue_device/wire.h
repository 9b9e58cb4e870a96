// The frame's building blocks for a small MCU: little-endian fields, CRC-16/CCITT-FALSE and
// COBS, as lib/graspguide_link defines them for the C++17 ends (docs/protocol.md,
// "Framing"); the native tests check both give the same bytes. The CRC is bitwise: the
// 512-byte table of graspguide_link would sit in the ATmega328P's 2 KB of RAM.
#pragma once

#include <stddef.h>
#include <stdint.h>
#include <string.h>

namespace graspguide {
namespace cue_device {
namespace link {

static_assert(sizeof(float) == 4, "the wire carries IEEE-754 binary32");

inline void put_u8(uint8_t*& p, uint8_t v) { *p++ = v; }
inline void put_u16(uint8_t*& p, uint16_t v) {
  put_u8(p, uint8_t(v));
  put_u8(p, uint8_t(v >> 8));
}
inline void put_u32(uint8_t*& p, uint32_t v) {
  for (uint8_t i = 0; i < 4; ++i) put_u8(p, uint8_t(v >> (8 * i)));
}
inline void put_f32(uint8_t*& p, float v) {
  uint32_t bits = 0;
  memcpy(&bits, &v, sizeof bits);  // the portable bit cast
  put_u32(p, bits);
}

inline void get_u8(const uint8_t*& p, uint8_t* v) { *v = *p++; }
inline void get_u16(const uint8_t*& p, uint16_t* v) {
  *v = uint16_t(p[0] | (uint16_t(p[1]) << 8));
  p += 2;
}
inline void get_u32(const uint8_t*& p, uint32_t* v) {
  uint32_t x = 0;
  for (uint8_t i = 0; i < 4; ++i) x |= uint32_t(p[i]) << (8 * i);
  *v = x;
  p += 4;
}
inline void get_f32(const uint8_t*& p, float* v) {
  uint32_t bits = 0;
  get_u32(p, &bits);
  memcpy(v, &bits, sizeof bits);
}
// false (v untouched) for anything but 0 or 1.
inline bool get_bool(const uint8_t*& p, bool* v) {
  const uint8_t b = *p++;
  if (b > 1) return false;
  *v = b == 1;
  return true;
}
// false (v untouched) for a value outside the enum (its generated is_valid, found by ADL).
template <class E>
bool get_enum(const uint8_t*& p, E* v) {
  const E e = static_cast<E>(*p++);
  if (!is_valid(e)) return false;
  *v = e;
  return true;
}

constexpr uint16_t kCrc16Init = 0xFFFF;
inline uint16_t crc16_update(uint16_t crc, uint8_t byte) {
  crc = uint16_t(crc ^ (uint16_t(byte) << 8));
  for (uint8_t bit = 0; bit < 8; ++bit)
    crc = (crc & 0x8000) ? uint16_t((crc << 1) ^ 0x1021) : uint16_t(crc << 1);
  return crc;
}

// COBS-encodes a frame straight to the stream's sink, one block at a time, so the sender
// needs no second buffer. Sink: void(const uint8_t* data, size_t n).
template <class Sink>
void cobs_write(const uint8_t* in, size_t size, Sink&& sink) {
  size_t start = 0;  // first byte of the current block
  for (;;) {
    size_t end = start;
    while (end < size && in[end] != 0 && end - start < 254) ++end;
    const uint8_t code = uint8_t(end - start + 1);
    sink(&code, 1);
    sink(in + start, end - start);
    if (end - start == 254) {  // a full block stands for no zero
      if (end == size) break;
      start = end;
      continue;
    }
    if (end == size) break;
    start = end + 1;      // past the zero this block stands for
    if (start == size) {  // that zero was the last byte: an empty final block
      const uint8_t one = 1;
      sink(&one, 1);
      break;
    }
  }
  const uint8_t delimiter = 0;
  sink(&delimiter, 1);
}

}  // namespace link
}  // namespace cue_device
}  // namespace graspguide
