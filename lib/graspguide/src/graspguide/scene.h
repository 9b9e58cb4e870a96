// What a scene models: the contacts, the axis y_O, and how forces become vibration.
#pragma once

#include <cstring>

#include "graspguide/status.h"
#include "graspguide/tolerances.h"
#include "graspguide/types.h"
// Mode and TrialConfig (with its ranges) are the per-frame layer's.
#include "graspguide_cue/pwm.h"
#include "graspguide_cue/trial_config.h"

namespace graspguide {

enum class ConstraintModel : uint8_t { kPaper = 0, kNormal = 1, kNone = 2 };
enum class Policy : uint8_t { kF = 0, kFperp = 1 };
// The structured route (grasp_structure.h, force_qp.h) or the SVD reference route
// (svd_route.h), which the accuracy table compares (docs/performance.md).
enum class Decomposition : uint8_t { kStructured = 0, kSVD = 1 };

constexpr const char* constraint_model_name(ConstraintModel m) {
  return m == ConstraintModel::kPaper ? "paper" : m == ConstraintModel::kNormal ? "normal" : "none";
}
constexpr const char* policy_name(Policy p) { return p == Policy::kF ? "F" : "Fperp"; }

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
  bool double_retry = GRASPGUIDE_DOUBLE_RETRY != 0;  // float only (answer_certificate.h)
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

}  // namespace graspguide
