// Motor levels to 8-bit PWM (step 6's last part):
//   duty_i = floor((floor_i + gain (gain_i |m_i|)) + 0.5), clamped to 0..255,
// with gain = kPwmSpan in mode C and alpha in mode V, and floor_i, gain_i the participant's
// calibration (motor_calibration.h; kPwmMin and 1 without one). Rounded in this order
// because the float64 reference does it so.
#pragma once

#include <stdint.h>

#include "graspguide_cue/config.h"
#include "graspguide_cue/motor_calibration.h"
#include "graspguide_cue/scalar_math.h"
#include "graspguide_cue/tolerances.h"

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

// What the PWM of one posture needs, worked out once per posture: which motors are on,
// gain_i 2 |m_i| and, with a calibration, 2 floor_i, for the rounding below. A frame then
// costs one multiplication, one addition and one conversion per motor that is on
// (pwm_from_plan).
template <typename T>
struct PwmPlan {
  // Bits 0..3: motor i is on. kCalibratedBit: twice_floor holds the floors; without it
  // every floor is kPwmMin, an immediate in the frame's code (the paper's mapping costs an
  // AVR no load per motor, and its plan no floors to write).
  static constexpr uint8_t kCalibratedBit = 0x80;
  uint8_t on = 0;
  T twice_scaled[kMaxContacts] = {T(0), T(0), T(0), T(0)};  // gain_i 2 |m_i|
  // Below this gain no motor reaches 255, so a frame needs no comparison per motor.
  T gain_limit = T(0);
  // 2 floor_i, read only under kCalibratedBit (for the motors that are on); left
  // unwritten otherwise because writing it costs the paper's per-posture plan 12 %.
  T twice_floor[kMaxContacts];
};

// levels[0..k-1]; a level at or below kMotorOffLevel is off, so float noise never switches
// a motor on at its floor. The calibration must pass check_calibration (a device refuses
// any other); the identity gives the paper's mapping bit for bit: 2 kPwmMin and 1 * 2 |m_i|
// are exact.
// Without a calibration (the paper's mapping): the floors are kPwmMin and the gains 1, so
// one division gives the limit (the calibrated plan below costs an AVR twice as much).
template <typename T>
PwmPlan<T> plan_pwm(const T* levels, int k) {
  PwmPlan<T> plan;
  T largest = T(0);
  for (int i = 0; i < k && i < kMaxContacts; ++i) {
    const T level = scalar_math::abs_of(levels[i]);
    if (!(level > T(kMotorOffLevel))) continue;  // NaN too
    plan.on = static_cast<uint8_t>(plan.on | (1u << i));
    plan.twice_scaled[i] = level + level;
    if (plan.twice_scaled[i] > largest) largest = plan.twice_scaled[i];
  }
  if (largest > T(0) && largest <= scalar_math::Limits<T>::kMax)
    plan.gain_limit = T(2 * 255 - 1 - 2 * kPwmMin) / largest;
  return plan;
}

template <typename T>
PwmPlan<T> plan_pwm(const T* levels, int k, const MotorCalibration& calibration) {
  if (is_identity(calibration)) return plan_pwm(levels, k);
  PwmPlan<T> plan;
  bool unbounded = false;
  // The motor that reaches 255 first: the largest twice_scaled / room, found with
  // multiplications (a division costs an 8-bit AVR ~500 cycles; one is paid below).
  T room_first = T(1), scaled_first = T(0);
  for (int i = 0; i < k && i < kMaxContacts; ++i) {
    const T level = scalar_math::abs_of(levels[i]);
    if (!(level > T(kMotorOffLevel))) continue;  // NaN too
    plan.on = static_cast<uint8_t>(plan.on | (1u << i) | PwmPlan<T>::kCalibratedBit);
    plan.twice_floor[i] = T(2 * int(calibration.pwm_floor[i]));
    plan.twice_scaled[i] = T(calibration.gain[i]) * (level + level);
    if (!(plan.twice_scaled[i] <= scalar_math::Limits<T>::kMax)) {
      unbounded = true;  // an infinite level: every frame compares
      continue;
    }
    const T room = T(2 * 255 - 1) - plan.twice_floor[i];
    // Equal rooms (the identity) compare twice_scaled itself, so the limit is exactly
    // (2 * 255 - 1 - 2 kPwmMin) / the largest, bit for bit the uncalibrated one.
    const bool first = room == room_first ? plan.twice_scaled[i] > scaled_first
                                          : plan.twice_scaled[i] * room_first > scaled_first * room;
    if (scaled_first == T(0) || first) {
      room_first = room;
      scaled_first = plan.twice_scaled[i];
    }
  }
  // The sum below stays under 2 * 255 - 1 up to this gain (rounding may take it a little
  // past: a sum under 511 still gives at most 255).
  if (scaled_first > T(0) && !unbounded) plan.gain_limit = room_first / scaled_first;
  return plan;
}

// floor((floor_i + gain gain_i |m_i|) + 0.5) = (trunc(2 floor_i + gain gain_i 2 |m_i|) + 1) / 2
// when the sum is >= 0, and doubling is exact in binary floating point: the same number as
// the reference's rounding, without floor() (an 8-bit AVR pays ~200 cycles for each).
// Clamped to 0..255; a NaN gain leaves every motor off.
namespace detail {

// One frame's loop; floor_of(i) is 2 floor_i (a constant for the paper's mapping).
template <typename T, typename TwiceFloor>
inline Pwm pwm_loop(const PwmPlan<T>& plan, T gain, TwiceFloor twice_floor) {
  const bool in_range = gain >= T(0) && gain < plan.gain_limit;
  Pwm out;
  for (int i = 0; i < kMaxContacts; ++i) {
    if (!(plan.on & (1u << i))) continue;
    const T twice = twice_floor(i) + gain * plan.twice_scaled[i];
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

}  // namespace detail

// Two copies of the loop, so the paper's mapping keeps its immediate floor: loading a
// floor per motor cost the ATmega328P's k=4 frame 20 cycles (docs/performance.md).
template <typename T>
Pwm pwm_from_plan(const PwmPlan<T>& plan, T gain) {
  if (plan.on & PwmPlan<T>::kCalibratedBit)
    return detail::pwm_loop(plan, gain, [&plan](int i) { return plan.twice_floor[i]; });
  return detail::pwm_loop(plan, gain, [](int) { return T(2 * kPwmMin); });
}

template <typename T>
Pwm pwm_from_levels(const T* levels, int k, T gain) {
  return pwm_from_plan(plan_pwm(levels, k), gain);
}

template <typename T>
Pwm pwm_from_levels(const T* levels, int k, T gain, const MotorCalibration& calibration) {
  return pwm_from_plan(plan_pwm(levels, k, calibration), gain);
}

}  // namespace graspguide
