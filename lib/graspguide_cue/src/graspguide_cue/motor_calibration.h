// A participant's per-motor calibration (docs/calibration.md): perceived vibration
// differs by finger and person, so each motor gets its own PWM floor and gain,
//   duty_i = floor(pwm_floor_i + G * (gain_i * |m_i|) + 0.5), clamped to 0..255
// (pwm.h; G = kPwmSpan in mode C, alpha in mode V). The identity (kPwmMin, 1) is the
// paper's mapping bit for bit. The ranges are tools/graspguide/core/motor_calibration.py's.
#pragma once

#include <stdint.h>

#include "graspguide_cue/config.h"
#include "graspguide_cue/scalar_math.h"

namespace graspguide {

// 255 would leave no duty above the floor.
constexpr uint8_t kCalibrationFloorMax = 254;
// A gain outside this range is a measurement gone wrong (or a typo), not a finger.
constexpr float kCalibrationGainMin = 0.25f;
constexpr float kCalibrationGainMax = 4.0f;

// float, not the core's scalar: it is what the wire and a stored plan carry.
struct MotorCalibration {
  uint8_t pwm_floor[kMaxContacts] = {kPwmMin, kPwmMin, kPwmMin, kPwmMin};
  float gain[kMaxContacts] = {1.0f, 1.0f, 1.0f, 1.0f};
};

// Why a calibration is refused; the field names match the protocol's (SET_CALIBRATION and
// PLAN_BEGIN), so a device can name the field in its ERROR.
enum class CalibrationCheck : uint8_t {
  kOk = 0,
  kPwmFloorTooHigh,  // a floor above kCalibrationFloorMax
  kGainNotFinite,    // NaN or infinite
  kGainOutOfRange,   // outside kCalibrationGainMin..kCalibrationGainMax
};

enum class CalibrationField : uint8_t { kNone = 0, kPwmFloor, kGain };

inline CalibrationField calibration_field(CalibrationCheck c) {
  return c == CalibrationCheck::kOk                ? CalibrationField::kNone
         : c == CalibrationCheck::kPwmFloorTooHigh ? CalibrationField::kPwmFloor
                                                   : CalibrationField::kGain;
}

// *motor, when given, is the first motor at fault (0..kMaxContacts-1).
inline CalibrationCheck check_calibration(const MotorCalibration& c, uint8_t* motor = nullptr) {
  for (uint8_t i = 0; i < kMaxContacts; ++i) {
    CalibrationCheck bad = CalibrationCheck::kOk;
    if (c.pwm_floor[i] > kCalibrationFloorMax)
      bad = CalibrationCheck::kPwmFloorTooHigh;
    else if (!scalar_math::is_finite(c.gain[i]))
      bad = CalibrationCheck::kGainNotFinite;
    else if (!(c.gain[i] >= kCalibrationGainMin && c.gain[i] <= kCalibrationGainMax))
      bad = CalibrationCheck::kGainOutOfRange;
    if (bad != CalibrationCheck::kOk) {
      if (motor) *motor = i;
      return bad;
    }
  }
  return CalibrationCheck::kOk;
}

inline bool is_identity(const MotorCalibration& c) {
  for (int i = 0; i < kMaxContacts; ++i)
    if (c.pwm_floor[i] != kPwmMin || c.gain[i] != 1.0f) return false;
  return true;
}

}  // namespace graspguide
