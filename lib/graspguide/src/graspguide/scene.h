// What a scene models: the contacts, the axis y_O, and how forces become vibration.
#pragma once

#include <cstring>

#include "graspguide/status.h"
#include "graspguide/tolerances.h"
#include "graspguide/types.h"

namespace graspguide {

enum class ConstraintModel : uint8_t { kPaper = 0, kNormal = 1, kNone = 2 };
enum class Policy : uint8_t { kF = 0, kFperp = 1 };
enum class Mode : uint8_t { kC = 0, kV = 1 };
// The structured route (grasp_structure.h, force_qp.h) or the SVD reference route
// (svd_route.h), which the accuracy table compares (docs/performance.md).
enum class Decomposition : uint8_t { kStructured = 0, kSVD = 1 };

constexpr const char* constraint_model_name(ConstraintModel m) {
  return m == ConstraintModel::kPaper ? "paper" : m == ConstraintModel::kNormal ? "normal" : "none";
}
constexpr const char* policy_name(Policy p) { return p == Policy::kF ? "F" : "Fperp"; }
constexpr const char* mode_name(Mode m) { return m == Mode::kC ? "C" : "V"; }

// Parsers return false on unknown names so callers can say what is accepted. Each one
// asks the *_name function above for every value, so a name is written in one place only.
template <typename E, int kCount>
bool parse_name(const char* s, const char* (*name_of)(E), E* out) {
  for (int i = 0; i < kCount; ++i) {
    const E e = static_cast<E>(i);
    if (std::strcmp(s, name_of(e)) == 0) {
      *out = e;
      return true;
    }
  }
  return false;
}
inline bool parse_constraint_model(const char* s, ConstraintModel* out) {
  return parse_name<ConstraintModel, 3>(s, constraint_model_name, out);
}
inline bool parse_policy(const char* s, Policy* out) {
  return parse_name<Policy, 2>(s, policy_name, out);
}
inline bool parse_mode(const char* s, Mode* out) { return parse_name<Mode, 2>(s, mode_name, out); }

struct SolverSettings {
  int max_iterations = kDefaultMaxIterations;
  Decomposition decomposition = Decomposition::kStructured;
};

// Defaults are the paper's experiment: 3 degrees held for 0.5 s, 90 s timeout.
struct TrialConfig {
  double threshold_deg = 3.0;
  double hold_s = 0.5;
  double timeout_s = 90.0;
};

template <typename T>
struct Scene {
  int k = 3;
  Eigen::Matrix<T, 3, kMaxContacts> contacts = Eigen::Matrix<T, 3, kMaxContacts>::Zero();
  Vec3<T> y_axis = Vec3<T>::UnitY();
  ConstraintModel constraints = ConstraintModel::kPaper;
  Policy policy = Policy::kF;
  Mode mode = Mode::kC;
  TrialConfig trial;
  SolverSettings solver;
};

// The accepted range of each trial field. Past these the trial's microsecond arithmetic
// (int64, and the device's 32-bit host timestamps, which wrap every 2^32 us = 71.6 min)
// would overflow or a trial could not end; inside them every value is exact in float.
// Every reader checks them: the core here, the device (SET_SCENE), and the host's scene and
// study-protocol files (through the Python binding's TRIAL_LIMITS).
enum class TrialField : uint8_t { kNone = 0, kThresholdDeg, kHoldS, kTimeoutS };

struct TrialFieldRange {
  const char* key;  // the name in SET_SCENE, scene and protocol files
  double min, max;
  bool min_exclusive;  // timeout_s must be > 0; the others may equal their minimum
};

inline constexpr double kTrialThresholdMaxDeg = 180.0;  // the largest possible error
inline constexpr double kTrialHoldMaxS = 600.0;
inline constexpr double kTrialTimeoutMaxS = 1800.0;  // < 2^31 us: a jump is unambiguous

constexpr TrialFieldRange trial_field_range(TrialField f) {
  return f == TrialField::kThresholdDeg
             ? TrialFieldRange{"threshold_deg", 0.0, kTrialThresholdMaxDeg, false}
         : f == TrialField::kHoldS    ? TrialFieldRange{"hold_s", 0.0, kTrialHoldMaxS, false}
         : f == TrialField::kTimeoutS ? TrialFieldRange{"timeout_s", 0.0, kTrialTimeoutMaxS, true}
                                      : TrialFieldRange{"", 0.0, 0.0, false};
}

constexpr bool in_trial_range(TrialField f, double v) {
  const TrialFieldRange r = trial_field_range(f);
  // NaN fails both comparisons, so it is out of every range.
  return (r.min_exclusive ? v > r.min : v >= r.min) && v <= r.max;
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
