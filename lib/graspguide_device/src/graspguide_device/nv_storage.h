// A byte-addressed non-volatile store: a file in the simulator; flash, EEPROM or a LittleFS
// file on boards. The study plan (plan_store.h) and the results log (results_log.h) share it.
#pragma once

#include <cstdint>

namespace graspguide::device {

// Erased bytes read 0xFF (as erased flash does), so "never written" needs no extra marker.
class NvStorage {
 public:
  virtual uint32_t size_bytes() const = 0;
  // false: the range is outside the store, or the medium failed.
  virtual bool read(uint32_t offset, uint8_t* out, uint32_t n) = 0;
  // true only once the bytes are durable: a power cut after it returns loses none of them.
  // false is a fault; any prefix of the bytes may then be stored (a torn write), which is
  // why every stored structure is checksummed and committed by its last byte written.
  virtual bool write(uint32_t offset, const uint8_t* data, uint32_t n) = 0;

 protected:
  ~NvStorage() = default;
};

// Offset + n fits in a store of size bytes, without wrapping uint32 arithmetic.
inline bool nv_range_ok(uint32_t size, uint32_t offset, uint32_t n) {
  return offset <= size && n <= size - offset;
}

}  // namespace graspguide::device
