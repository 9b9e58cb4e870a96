// An in-memory NvStorage for tests, with the faults a real store has: a power cut that tears
// a write, and a medium that stops reading.
#pragma once

#include <cstring>

#include "graspguide_device/nv_storage.h"

namespace graspguide::device {

template <uint32_t N>
class RamStorage final : public NvStorage {
 public:
  RamStorage() { std::memset(bytes_, 0xFF, N); }

  uint32_t size_bytes() const override { return N; }

  bool read(uint32_t offset, uint8_t* out, uint32_t n) override {
    if (reads_fail_ || !nv_range_ok(N, offset, n)) return false;
    std::memcpy(out, bytes_ + offset, n);
    return true;
  }

  bool write(uint32_t offset, const uint8_t* data, uint32_t n) override {
    if (!nv_range_ok(N, offset, n)) return false;
    if (dead_) return false;
    if (cut_armed_ && n > budget_) {
      // The power goes: only the first budget_ bytes reach the medium, and nothing after.
      std::memcpy(bytes_ + offset, data, budget_);
      budget_ = 0;
      dead_ = true;
      return false;
    }
    if (cut_armed_) budget_ -= n;
    std::memcpy(bytes_ + offset, data, n);
    ++writes_;
    return true;
  }

  // A power cut after n more bytes: writes go through while they fit in n; the one that does
  // not stores only what is left of n and returns false, and every later write fails. With n
  // below the next write's length, that write stores its first n bytes. This counts across
  // writes, so a test can cut an operation made of several writes at any byte.
  void fail_writes_after_bytes(uint32_t n) {
    cut_armed_ = true;
    budget_ = n;
  }
  void fail_reads(bool fail = true) { reads_fail_ = fail; }
  // Power back: writes work again (what was torn stays torn).
  void restore_power() {
    cut_armed_ = dead_ = false;
    budget_ = 0;
  }

  uint8_t* bytes() { return bytes_; }
  const uint8_t* bytes() const { return bytes_; }
  uint32_t writes() const { return writes_; }

 private:
  uint8_t bytes_[N];
  bool cut_armed_ = false, dead_ = false, reads_fail_ = false;
  uint32_t budget_ = 0;
  uint32_t writes_ = 0;
};

}  // namespace graspguide::device
