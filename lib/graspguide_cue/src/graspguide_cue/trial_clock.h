// The two clocks of a trial on a device: the host's pose timestamps, which decide it, and
// the device's own, which ends it when those timestamps stop advancing.
#pragma once

#include <stdint.h>

namespace graspguide {

// Host timestamps are 32-bit microseconds that wrap every 71.6 min; the trial needs a
// monotonic 64-bit time. Each step is read as a signed 32-bit difference: a wrap is a small
// step forward, and any step of 2^31 us or more forward reads as a step back (trial timeouts
// are at most 1800 s < 2^31 us, so no trial needs one).
class HostTimeline {
 public:
  // The first timestamp of a trial, taken as it is.
  int64_t restart(uint32_t host_us) {
    last_host_us_ = host_us;
    time_us_ = host_us;
    return time_us_;
  }

  int64_t advance(uint32_t host_us) {
    time_us_ += static_cast<int32_t>(host_us - last_host_us_);
    last_host_us_ = host_us;
    return time_us_;
  }

 private:
  uint32_t last_host_us_ = 0;
  int64_t time_us_ = 0;
};

// The device's own clock since a trial's first pose, against the trial's timeout plus a
// slack. Summed step by step into 64 bits, so a long gap between polls (a process stopped
// for minutes) cannot wrap it; each step signed, as a virtual clock may step back a little
// when a late pose resets it.
class TrialDeadline {
 public:
  // Once per trial: double arithmetic is soft float on small MCUs, poll() must stay cheap.
  void start(uint32_t now_us, double timeout_s, uint32_t slack_us) {
    elapsed_us_ = 0;
    last_us_ = now_us;
    limit_us_ = static_cast<int64_t>(timeout_s * 1e6) + slack_us;
  }

  // True once the device clock has run to timeout_s + slack since start().
  bool passed(uint32_t now_us) {
    elapsed_us_ += static_cast<int32_t>(now_us - last_us_);
    last_us_ = now_us;
    return elapsed_us_ >= limit_us_;
  }

 private:
  uint32_t last_us_ = 0;
  int64_t elapsed_us_ = 0;
  int64_t limit_us_ = 0;
};

}  // namespace graspguide
