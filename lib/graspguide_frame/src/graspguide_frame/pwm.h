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

// What the PWM of one posture needs, worked out once per posture: which motors are on, and
// 2 |m_i| for the rounding below. A frame then costs one multiplication, one addition and
// one conversion per motor that is on (pwm_from_plan).
template <typename T>
struct PwmPlan {
  uint8_t on = 0;  // bit i: motor i is on
  T twice_level[kMaxContacts] = {T(0), T(0), T(0), T(0)};
  // Below this gain no motor reaches 255, so a frame needs no comparison per motor.
  T gain_limit = T(0);
};

// levels[0..k-1]; a level at or below kMotorOffLevel is off, so float noise never switches
// a motor on at kPwmMin.
template <typename T>
PwmPlan<T> plan_pwm(const T* levels, int k) {
  PwmPlan<T> plan;
  T largest = T(0);
  for (int i = 0; i < k && i < kMaxContacts; ++i) {
    const T level = frame_math::abs_of(levels[i]);
    if (!(level > T(kMotorOffLevel))) continue;  // NaN too
    plan.on = static_cast<uint8_t>(plan.on | (1u << i));
    plan.twice_level[i] = level + level;
    if (plan.twice_level[i] > largest) largest = plan.twice_level[i];
  }
  // The sum below stays under 2 * 255 - 1 up to this gain (rounding may take it a little
  // past: a sum under 511 still gives at most 255). An infinite level leaves the limit 0.
  if (largest > T(0) && largest <= frame_math::Limits<T>::kMax)
    plan.gain_limit = T(2 * 255 - 1 - 2 * kPwmMin) / largest;
  return plan;
}

// floor((kPwmMin + gain |m_i|) + 0.5) = (trunc(2 kPwmMin + gain 2 |m_i|) + 1) / 2 when the sum
// is >= 0, and doubling is exact in binary floating point: the same number as the
// reference's rounding, without floor() (an 8-bit AVR pays ~200 cycles for each). Clamped
// to 0..255; a NaN gain leaves every motor off.
template <typename T>
Pwm pwm_from_plan(const PwmPlan<T>& plan, T gain) {
  const bool in_range = gain >= T(0) && gain < plan.gain_limit;
  Pwm out;
  for (int i = 0; i < kMaxContacts; ++i) {
    if (!(plan.on & (1u << i))) continue;
    const T twice = T(2 * kPwmMin) + gain * plan.twice_level[i];
    if (!in_range) {
      if (!(twice >= T(0))) continue;  // below 0 (clamped), or NaN
      if (twice >= T(2 * 255 - 1)) {
        out.duty[i] = 255;
        continue;
      }
    }
    out.duty[i] = static_cast<uint8_t>((static_cast<uint16_t>(twice) + 1u) >> 1);
  }
  return out;
}

template <typename T>
Pwm pwm_from_levels(const T* levels, int k, T gain) {
  return pwm_from_plan(plan_pwm(levels, k), gain);
}

}  // namespace graspguide
