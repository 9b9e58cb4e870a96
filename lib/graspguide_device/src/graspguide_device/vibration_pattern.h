// The host-less device's only way to talk to the wearer: short vibration patterns on every
// thimble of the trial, told apart by rhythm rather than strength (a wearer compares
// rhythms reliably; intensities differ by finger and person).
#pragma once

#include <stdint.h>

#include "graspguide_cue/pwm.h"

#ifndef GRASPGUIDE_PATTERN_DUTY
// Well above the PWM floor (70), so every finger feels it, and below 255, so a pattern
// never reads as the strongest guidance cue.
#define GRASPGUIDE_PATTERN_DUTY 200
#endif

namespace graspguide::device {

struct VibrationPattern {
  uint8_t pulses = 0;
  uint16_t on_ms = 0;
  uint16_t off_ms = 0;
};

// Two short pulses: "ready, press the button when you are".
inline constexpr VibrationPattern kReadyPattern{2, 150, 150};
// One long pulse: "success".
inline constexpr VibrationPattern kSuccessPattern{1, 600, 0};
// Three short pulses: "time is up".
inline constexpr VibrationPattern kTimeoutPattern{3, 100, 100};
inline constexpr uint8_t kPatternDuty = GRASPGUIDE_PATTERN_DUTY;

inline constexpr uint32_t pattern_length_us(const VibrationPattern& p) {
  return p.pulses == 0 ? 0u
                       : (uint32_t(p.pulses) * p.on_ms + uint32_t(p.pulses - 1) * p.off_ms) * 1000u;
}

// Plays one pattern on the first k motors, on the device's clock (ticks wrap: unsigned
// differences).
class PatternPlayer {
 public:
  void start(const VibrationPattern& p, uint8_t k, uint32_t now_us) {
    pattern_ = p;
    k_ = k;
    start_us_ = now_us;
    playing_ = p.pulses > 0;
  }

  void cancel() { playing_ = false; }

  bool playing(uint32_t now_us) {
    if (playing_ && now_us - start_us_ >= pattern_length_us(pattern_)) playing_ = false;
    return playing_;
  }

  // What the motors show now: the pattern's duty during a pulse, zero between pulses and
  // once it is over.
  Pwm pwm(uint32_t now_us) {
    Pwm out;
    if (!playing(now_us)) return out;
    const uint32_t period_us = (uint32_t(pattern_.on_ms) + pattern_.off_ms) * 1000u;
    const uint32_t in_period_us = (now_us - start_us_) % period_us;
    if (in_period_us < uint32_t(pattern_.on_ms) * 1000u)
      for (uint8_t i = 0; i < k_ && i < kMaxContacts; ++i) out.duty[i] = kPatternDuty;
    return out;
  }

 private:
  VibrationPattern pattern_;
  uint8_t k_ = 0;
  uint32_t start_us_ = 0;
  bool playing_ = false;
};

}  // namespace graspguide::device
