// Step 6: motor levels from the contact forces, and their 8-bit PWM.
#pragma once

#include <cmath>

#include "graspguide/scene.h"
#include "graspguide_cue/pwm.h"

namespace graspguide {

// m_i = |lambda*_i| (F) or lambda*_iy (Fperp), then m / |m|.
template <typename T, int K>
Status motor_levels(const ForceVec<T, K>& lambda, Policy policy, LevelVec<T, K>& m) {
  const T n = lambda.norm();
  if (!(n > T(0)) || !lambda.allFinite()) return Status::kNothingToDisplay;
  for (int i = 0; i < K; ++i) {
    const auto li = lambda.template segment<3>(3 * i);
    m(i) = policy == Policy::kF ? li.norm() / n : li(1) / n;
  }
  const T mn = m.norm();
  if (!(mn > T(0))) return Status::kNothingToDisplay;
  m /= mn;
  return Status::kOk;
}

// The per-frame layer's PWM (graspguide_cue/pwm.h) on an Eigen level vector.
template <typename T, int K>
Pwm pwm_from_levels(const LevelVec<T, K>& m, T gain) {
  return pwm_from_levels<T>(m.data(), K, gain);
}

}  // namespace graspguide
