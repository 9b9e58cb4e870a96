// CRC-32 (IEEE 802.3: reflected polynomial 0xEDB88320, initial and final XOR 0xFFFFFFFF, the
// zlib/PNG one) guarding what the device stores. A 16-entry table: 64 bytes of flash instead
// of 1 KiB, and no heap, at two lookups per byte (stored data is read rarely and is small).
#pragma once

#include <cstdint>

namespace graspguide::device {

inline constexpr uint32_t kCrc32Polynomial = 0xEDB88320u;  // reflected 0x04C11DB7

struct Crc32Table {
  uint32_t entry[16];
};

// The CRC of each 4-bit value, worked out by the compiler from the polynomial.
constexpr Crc32Table make_crc32_nibble_table() {
  Crc32Table t{};
  for (uint32_t i = 0; i < 16; ++i) {
    uint32_t c = i;
    for (int bit = 0; bit < 4; ++bit) c = (c & 1u) ? (c >> 1) ^ kCrc32Polynomial : c >> 1;
    t.entry[i] = c;
  }
  return t;
}

inline constexpr Crc32Table kCrc32Nibble = make_crc32_nibble_table();

// Running state: start with Crc32{}, feed bytes with update(), read value().
class Crc32 {
 public:
  void update(const uint8_t* data, uint32_t n) {
    for (uint32_t i = 0; i < n; ++i) {
      state_ ^= data[i];
      state_ = (state_ >> 4) ^ kCrc32Nibble.entry[state_ & 0x0Fu];
      state_ = (state_ >> 4) ^ kCrc32Nibble.entry[state_ & 0x0Fu];
    }
  }
  uint32_t value() const { return state_ ^ 0xFFFFFFFFu; }

 private:
  uint32_t state_ = 0xFFFFFFFFu;
};

inline uint32_t crc32(const uint8_t* data, uint32_t n) {
  Crc32 c;
  c.update(data, n);
  return c.value();
}

}  // namespace graspguide::device
