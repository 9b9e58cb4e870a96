// The host-less study plan as the device holds it: the fields of PLAN_BEGIN (PlanHeader) and
// of each PLAN_TRIAL (PlanTrial), and the range checks a plan must pass before it is stored
// or run. Free of Eigen and of the core, so the plan store and the results log stay small.
#pragma once

#include <cmath>
#include <cstdint>

#include "graspguide_cue/motor_calibration.h"
#include "graspguide_cue/pwm.h"
#include "graspguide_cue/trial_config.h"

namespace graspguide::device {

inline constexpr uint16_t kMaxPlanTrials = 128;  // == the link's max_plan_trials
inline constexpr uint8_t kPlanParticipantBytes = 8;
inline constexpr uint8_t kPlanConfigHashBytes = 8;

inline constexpr float kPlanRestMaxS = 600.0f;
// A contact farther than this from the hand frame's origin is no hand posture.
inline constexpr float kPlanHandMaxM = 1.0f;
// The IMU mounting quaternion is normalised by its user; a norm far from 1 means it was
// mistyped, not merely rounded.
inline constexpr float kPlanQuatNormMin = 0.5f;
inline constexpr float kPlanQuatNormMax = 2.0f;
inline constexpr uint8_t kPlanConstraintsMax = 2;  // graspguide::ConstraintModel::kNone
inline constexpr uint8_t kPlanPolicyMax = 1;       // graspguide::Policy::kFperp
inline constexpr uint8_t kPlanModeMax = static_cast<uint8_t>(Mode::kV);

enum class WrenchClassCode : uint8_t { kNone = 0, kSingle = 1, kMulti = 2 };

struct PlanTrial {
  uint16_t trial_index = 0;
  uint8_t session = 0, session_trial = 0, k = 3;
  uint8_t policy = 0;  // graspguide::Policy value (0 F, 1 Fperp)
  uint8_t mode = 0;    // graspguide::Mode value (0 C, 1 V)
  bool familiarization = false, single_motor = false;
  uint8_t wrench_class = 0, wrench_number = 0;
  float wrench[6] = {};
};

struct PlanHeader {
  char participant[kPlanParticipantBytes] = {};
  bool simulated = false;
  uint8_t config_hash[kPlanConfigHashBytes] = {};
  uint16_t trial_count = 0;
  uint8_t constraints = 0;  // graspguide::ConstraintModel value
  float y_axis[3] = {0, 1, 0};
  float threshold_deg = 3, hold_s = 0.5f, timeout_s = 90, rest_s = 2;
  float hand_k3[3][3] = {};
  float hand_k4[4][3] = {};
  float imu_to_hand_wxyz[4] = {1, 0, 0, 0};
  // The participant's per-motor calibration, applied to every trial's PWM; the identity
  // (kPwmMin, 1) is the paper's mapping.
  uint8_t pwm_floor[kMaxContacts] = {kPwmMin, kPwmMin, kPwmMin, kPwmMin};
  float gain[kMaxContacts] = {1, 1, 1, 1};
};

struct StudyPlan {
  PlanHeader header;
  PlanTrial trials[kMaxPlanTrials];
};

// The index of each field in its message (the schema's order), reported in ERROR.detail.
enum class PlanBeginField : uint8_t {
  kParticipant = 0,
  kSimulated,
  kConfigHash,
  kTrialCount,
  kConstraints,
  kYAxis,
  kThresholdDeg,
  kHoldS,
  kTimeoutS,
  kRestS,
  kHandK3,
  kHandK4,
  kImuToHandWxyz,
  kPwmFloor,
  kGain,
};
enum class PlanTrialField : uint8_t {
  kPosition = 0,
  kTrialIndex,
  kSession,
  kSessionTrial,
  kK,
  kPolicy,
  kMode,
  kFamiliarization,
  kSingleMotor,
  kWrenchClass,
  kWrenchNumber,
  kWrench,
};

enum class PlanCheck : uint8_t { kOk = 0, kBadField };

// The plan's calibration as the per-frame layer takes it (the same fields, the same order).
inline MotorCalibration plan_calibration(const PlanHeader& h) {
  MotorCalibration c;
  for (int i = 0; i < kMaxContacts; ++i) {
    c.pwm_floor[i] = h.pwm_floor[i];
    c.gain[i] = h.gain[i];
  }
  return c;
}

namespace detail {

inline bool all_finite(const float* v, int n) {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

inline bool all_within(const float* v, int n, float limit) {
  for (int i = 0; i < n; ++i)
    if (!(std::fabs(v[i]) <= limit)) return false;  // NaN too
  return true;
}

// Printable ASCII up to the first NUL, NUL after it (the wire's padding), and not empty:
// it names the participant's folder in the downloaded results.
inline bool participant_ok(const char (&p)[kPlanParticipantBytes]) {
  if (p[0] == '\0') return false;
  bool ended = false;
  for (char ch : p) {
    const auto c = static_cast<unsigned char>(ch);
    if (ended) {
      if (c != 0) return false;
    } else if (c == 0) {
      ended = true;
    } else if (c < 0x20 || c > 0x7E) {
      return false;
    }
  }
  return true;
}

inline PlanCheck bad(uint8_t field, uint8_t* bad_field) {
  if (bad_field) *bad_field = field;
  return PlanCheck::kBadField;
}

}  // namespace detail

// kOk, or kBadField with *bad_field = the first offending PLAN_BEGIN field's index.
inline PlanCheck check_header(const PlanHeader& h, uint8_t* bad_field) {
  using F = PlanBeginField;
  using namespace detail;
  const auto fail = [bad_field](F f) { return bad(static_cast<uint8_t>(f), bad_field); };
  if (!participant_ok(h.participant)) return fail(F::kParticipant);
  if (h.trial_count < 1 || h.trial_count > kMaxPlanTrials) return fail(F::kTrialCount);
  if (h.constraints > kPlanConstraintsMax) return fail(F::kConstraints);
  if (!all_finite(h.y_axis, 3) || (h.y_axis[0] == 0 && h.y_axis[1] == 0 && h.y_axis[2] == 0))
    return fail(F::kYAxis);
  // The trial's own ranges, from the one place that defines them.
  TrialConfig tc;
  tc.threshold_deg = h.threshold_deg;
  tc.hold_s = h.hold_s;
  tc.timeout_s = h.timeout_s;
  TrialField tf = TrialField::kNone;
  if (validate_trial_config(tc, &tf) != Status::kOk)
    return fail(tf == TrialField::kThresholdDeg ? F::kThresholdDeg
                : tf == TrialField::kHoldS      ? F::kHoldS
                                                : F::kTimeoutS);
  if (!(h.rest_s >= 0.0f && h.rest_s <= kPlanRestMaxS)) return fail(F::kRestS);
  if (!all_within(&h.hand_k3[0][0], 9, kPlanHandMaxM)) return fail(F::kHandK3);
  if (!all_within(&h.hand_k4[0][0], 12, kPlanHandMaxM)) return fail(F::kHandK4);
  const float* q = h.imu_to_hand_wxyz;
  if (!all_finite(q, 4)) return fail(F::kImuToHandWxyz);
  const float n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
  if (!(n2 >= kPlanQuatNormMin * kPlanQuatNormMin && n2 <= kPlanQuatNormMax * kPlanQuatNormMax))
    return fail(F::kImuToHandWxyz);
  // SET_CALIBRATION's ranges, from the one place that defines them.
  const CalibrationCheck cc = check_calibration(plan_calibration(h));
  if (cc != CalibrationCheck::kOk)
    return fail(calibration_field(cc) == CalibrationField::kPwmFloor ? F::kPwmFloor : F::kGain);
  if (bad_field) *bad_field = 0;
  return PlanCheck::kOk;
}

// kOk, or kBadField with *bad_field = the first offending PLAN_TRIAL field's index. The
// position (field 0) is the link's to check: it is not part of the stored trial.
inline PlanCheck check_trial(const PlanTrial& t, uint8_t* bad_field) {
  using F = PlanTrialField;
  using namespace detail;
  const auto fail = [bad_field](F f) { return bad(static_cast<uint8_t>(f), bad_field); };
  if (t.trial_index < 1) return fail(F::kTrialIndex);  // the study numbers trials 1..N
  if (t.session_trial < 1) return fail(F::kSessionTrial);
  if (t.k != 3 && t.k != 4) return fail(F::kK);
  if (t.policy > kPlanPolicyMax) return fail(F::kPolicy);
  if (t.mode > kPlanModeMax) return fail(F::kMode);
  if (t.wrench_class > static_cast<uint8_t>(WrenchClassCode::kMulti)) return fail(F::kWrenchClass);
  // A zero force has no direction to guide along.
  if (!all_finite(t.wrench, 6) || (t.wrench[0] == 0 && t.wrench[1] == 0 && t.wrench[2] == 0))
    return fail(F::kWrench);
  if (bad_field) *bad_field = 0;
  return PlanCheck::kOk;
}

}  // namespace graspguide::device
