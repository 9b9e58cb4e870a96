// A trial's parameters and their accepted ranges. Defaults are the paper's experiment:
// 3 degrees held for 0.5 s, 90 s timeout.
#pragma once

#include <stdint.h>

#include "graspguide_cue/status.h"

namespace graspguide {

struct TrialConfig {
  double threshold_deg = 3.0;
  double hold_s = 0.5;
  double timeout_s = 90.0;
};

// The accepted range of each trial field. Past these the trial's microsecond arithmetic
// (int64, and the device's 32-bit host timestamps, which wrap every 2^32 us = 71.6 min)
// would overflow or a trial could not end; inside them every value is exact in float.
// Every reader checks them: the core, the device (SET_SCENE), and the host's scene and
// study-protocol files (through the Python binding's TRIAL_LIMITS).
enum class TrialField : uint8_t { kNone = 0, kThresholdDeg, kHoldS, kTimeoutS };

struct TrialFieldRange {
  const char* key;  // the name in SET_SCENE, scene and protocol files
  double min, max;
  bool min_exclusive;  // timeout_s must be > 0; the others may equal their minimum
};

constexpr double kTrialThresholdMaxDeg = 180.0;  // the largest possible error
constexpr double kTrialHoldMaxS = 600.0;
constexpr double kTrialTimeoutMaxS = 1800.0;  // < 2^31 us: a jump is unambiguous

constexpr TrialFieldRange trial_field_range(TrialField f) {
  return f == TrialField::kThresholdDeg
             ? TrialFieldRange{"threshold_deg", 0.0, kTrialThresholdMaxDeg, false}
         : f == TrialField::kHoldS    ? TrialFieldRange{"hold_s", 0.0, kTrialHoldMaxS, false}
         : f == TrialField::kTimeoutS ? TrialFieldRange{"timeout_s", 0.0, kTrialTimeoutMaxS, true}
                                      : TrialFieldRange{"", 0.0, 0.0, false};
}

// NaN fails both comparisons, so it is out of every range. One return statement: the
// Arduino IDE compiles C++11, whose constexpr functions allow nothing else.
constexpr bool in_range_of(TrialFieldRange r, double v) {
  return (r.min_exclusive ? v > r.min : v >= r.min) && v <= r.max;
}

constexpr bool in_trial_range(TrialField f, double v) {
  return in_range_of(trial_field_range(f), v);
}

// kOk, or kBadConfig with *bad naming the first offending field. A hold longer than the
// timeout could never succeed, so it is refused as a bad hold_s.
inline Status validate_trial_config(const TrialConfig& c, TrialField* bad = nullptr) {
  TrialField f = TrialField::kNone;
  if (!in_trial_range(TrialField::kThresholdDeg, c.threshold_deg))
    f = TrialField::kThresholdDeg;
  else if (!in_trial_range(TrialField::kHoldS, c.hold_s))
    f = TrialField::kHoldS;
  else if (!in_trial_range(TrialField::kTimeoutS, c.timeout_s))
    f = TrialField::kTimeoutS;
  else if (c.hold_s > c.timeout_s)
    f = TrialField::kHoldS;
  if (bad) *bad = f;
  return f == TrialField::kNone ? Status::kOk : Status::kBadConfig;
}

}  // namespace graspguide
