// Step 6: motor levels from the contact forces, and their 8-bit PWM.
#pragma once

#include <cmath>

#include "graspguide/scene.h"

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

// gain = kPwmSpan in mode C, alpha in mode V. A level at or below kMotorOffLevel is off, so
// float noise never switches a motor on at kPwmMin.
template <typename T, int K>
Pwm pwm_from_levels(const LevelVec<T, K>& m, T gain) {
  Pwm out;
  for (int i = 0; i < K; ++i) {
    const T level = std::abs(m(i));
    if (!(level > T(kMotorOffLevel))) continue;
    T duty = std::floor(T(kPwmMin) + gain * level + T(0.5));
    duty = duty < T(0) ? T(0) : (duty > T(255) ? T(255) : duty);
    out.duty[i] = static_cast<uint8_t>(duty);
  }
  return out;
}

}  // namespace graspguide
