// The pose watchdog: motors off when no pose has come for a while. Ticks of any free-running
// 32-bit clock (micros() wraps every 71.6 min, millis() every 49.7 days): the unsigned
// difference is the elapsed time across a wrap, as long as the watchdog is polled at least
// once per wrap.
#pragma once

#include <stdint.h>

namespace graspguide {

class PoseWatchdog {
 public:
  explicit PoseWatchdog(uint32_t timeout_ticks) : timeout_(timeout_ticks) {}

  // A pose (or a direct motor command) arrived: the time starts again.
  void feed(uint32_t now) { last_ = now; }

  // True once timeout_ticks or more have passed since the last feed.
  bool expired(uint32_t now) const { return static_cast<uint32_t>(now - last_) >= timeout_; }

  uint32_t timeout() const { return timeout_; }

 private:
  uint32_t timeout_;
  uint32_t last_ = 0;
};

}  // namespace graspguide
