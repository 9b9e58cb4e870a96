// Motor levels to 8-bit PWM (step 6's last part): duty = floor((kPwmMin + gain |m_i|) + 0.5),
// clamped to 0..255, with gain = kPwmSpan in mode C and alpha in mode V. Rounded in this
// order because the float64 reference does it so.
#pragma once

#include <stdint.h>

#include "graspguide_frame/config.h"
#include "graspguide_frame/scalar_math.h"
#include "graspguide_frame/tolerances.h"

namespace graspguide {

// C: constant intensity; V: proportional to the guidance error (alpha).
enum class Mode : uint8_t { kC = 0, kV = 1 };

constexpr const char* mode_name(Mode m) { return m == Mode::kC ? "C" : "V"; }

// 8-bit PWM per motor; unused motors (k = 3) stay 0.
struct Pwm {
  uint8_t duty[kMaxContacts] = {0, 0, 0, 0};
};

template <typename T>
constexpr T pwm_gain(Mode mode, T alpha) {
  return mode == Mode::kC ? T(kPwmSpan) : alpha;
}

// levels[0..k-1]; a level at or below kMotorOffLevel is off, so float noise never switches
// a motor on at kPwmMin. A NaN gain leaves every motor off.
template <typename T>
Pwm pwm_from_levels(const T* levels, int k, T gain) {
  // floor((kPwmMin + x) + 0.5) = (trunc(2 kPwmMin + 2x) + 1) / 2 for 2 kPwmMin + 2x >= 0,
  // and doubling is exact in binary floating point, so this rounds exactly as the reference
  // does with one addition and no floor() per motor (an 8-bit AVR pays ~300 cycles for each).
  const T gain2 = gain + gain;
  // With gain >= 0 the sum is >= 0 for every level: one comparison instead of one per motor.
  const bool check_sign = !(gain2 >= T(0));
  Pwm out;
  for (int i = 0; i < k && i < kMaxContacts; ++i) {
    const T level = frame_math::abs_of(levels[i]);
    if (!(level > T(kMotorOffLevel))) continue;
    const T twice = T(2 * kPwmMin) + gain2 * level;
    if (check_sign && !(twice >= T(0))) continue;  // below 0 (clamped) or NaN
    out.duty[i] = twice >= T(2 * 255 - 1)
                      ? 255
                      : static_cast<uint8_t>((static_cast<uint16_t>(twice) + 1u) >> 1);
  }
  return out;
}

}  // namespace graspguide
