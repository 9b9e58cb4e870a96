// The simulated device's clocks: real monotonic time, or a virtual time that only the host
// moves (by its pose timestamps), so a 90 s trial runs in milliseconds.
#pragma once

#include <time.h>

#include "graspguide_hal/hal.h"

namespace graspguide::sim {

class MonotonicClock final : public graspguide::hal::Clock {
 public:
  uint32_t now_us() override {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<uint32_t>(uint64_t(ts.tv_sec) * 1000000u + uint64_t(ts.tv_nsec) / 1000u);
  }
};

class VirtualClock final : public graspguide::hal::Clock {
 public:
  uint32_t now_us() override { return now_us_; }
  void set_us(uint32_t t) { now_us_ = t; }

 private:
  uint32_t now_us_ = 0;
};

}  // namespace graspguide::sim
