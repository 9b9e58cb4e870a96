// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor).
// A 512-byte constexpr table: one lookup per byte is cheap on a small MCU, and the
// table is built by the compiler, so it cannot be mistyped.
#pragma once

#include <cstddef>
#include <cstdint>

namespace graspguide::link {

inline constexpr uint16_t kCrc16Poly = 0x1021;
inline constexpr uint16_t kCrc16Init = 0xFFFF;

namespace detail {
struct Crc16Table {
  uint16_t entry[256];
};
constexpr Crc16Table make_crc16_table() {
  Crc16Table t{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint16_t crc = static_cast<uint16_t>(i << 8);
    for (int bit = 0; bit < 8; ++bit)
      crc = static_cast<uint16_t>((crc & 0x8000) ? (crc << 1) ^ kCrc16Poly : crc << 1);
    t.entry[i] = crc;
  }
  return t;
}
inline constexpr Crc16Table kCrc16Table = make_crc16_table();
}  // namespace detail

constexpr uint16_t crc16_update(uint16_t crc, uint8_t byte) {
  return static_cast<uint16_t>((crc << 8) ^ detail::kCrc16Table.entry[((crc >> 8) ^ byte) & 0xFF]);
}

// Pass a previous result as `crc` to continue over several buffers.
constexpr uint16_t crc16(const uint8_t* data, size_t size, uint16_t crc = kCrc16Init) {
  for (size_t i = 0; i < size; ++i) crc = crc16_update(crc, data[i]);
  return crc;
}

namespace detail {
constexpr uint16_t crc16_of_check_string() {
  constexpr char kCheck[] = "123456789";
  uint16_t crc = kCrc16Init;
  for (size_t i = 0; i + 1 < sizeof kCheck; ++i)
    crc = crc16_update(crc, static_cast<uint8_t>(kCheck[i]));
  return crc;
}
}  // namespace detail
static_assert(detail::crc16_of_check_string() == 0x29B1, "CRC-16/CCITT-FALSE check value");

}  // namespace graspguide::link
