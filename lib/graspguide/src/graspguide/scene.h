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
enum class Decomposition : uint8_t { kQR = 0, kSVD = 1 };

constexpr const char* constraint_model_name(ConstraintModel m) {
  return m == ConstraintModel::kPaper ? "paper" : m == ConstraintModel::kNormal ? "normal" : "none";
}
constexpr const char* policy_name(Policy p) { return p == Policy::kF ? "F" : "Fperp"; }
constexpr const char* mode_name(Mode m) { return m == Mode::kC ? "C" : "V"; }

// Parsers return false on unknown names so callers can say what is accepted.
inline bool parse_constraint_model(const char* s, ConstraintModel* out) {
  if (std::strcmp(s, "paper") == 0) { *out = ConstraintModel::kPaper; return true; }
  if (std::strcmp(s, "normal") == 0) { *out = ConstraintModel::kNormal; return true; }
  if (std::strcmp(s, "none") == 0) { *out = ConstraintModel::kNone; return true; }
  return false;
}
inline bool parse_policy(const char* s, Policy* out) {
  if (std::strcmp(s, "F") == 0) { *out = Policy::kF; return true; }
  if (std::strcmp(s, "Fperp") == 0) { *out = Policy::kFperp; return true; }
  return false;
}
inline bool parse_mode(const char* s, Mode* out) {
  if (std::strcmp(s, "C") == 0) { *out = Mode::kC; return true; }
  if (std::strcmp(s, "V") == 0) { *out = Mode::kV; return true; }
  return false;
}

struct SolverSettings {
  int max_iterations = kDefaultMaxIterations;
  Decomposition decomposition = Decomposition::kQR;
  // Off by default: on the M4F a warm-started frame costs no less than a cold one (full
  // frame k=4 median 12,560 vs 12,200 instructions, docs/performance.md): building the
  // previous active set back up outweighs the iterations it saves.
  bool warm_start = false;
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

inline Status validate_trial_config(const TrialConfig& c) {
  const bool finite = c.threshold_deg == c.threshold_deg && c.hold_s == c.hold_s &&
                      c.timeout_s == c.timeout_s && c.threshold_deg < 1e30 &&
                      c.hold_s < 1e30 && c.timeout_s < 1e30;
  if (!finite || c.threshold_deg < 0 || c.threshold_deg > 180 || c.hold_s < 0 ||
      c.timeout_s <= 0)
    return Status::kBadConfig;
  return Status::kOk;
}

}  // namespace graspguide
