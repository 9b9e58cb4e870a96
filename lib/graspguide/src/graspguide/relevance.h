// Step 4: which contacts can push against the force, and the desired forces built from
// them (C_i = 1 iff f . (C_i - O) <= 0).
#pragma once

#include "graspguide/contact_frames.h"

namespace graspguide {

// Bit i set: contact i is relevant. A small cosine band counts as "on the boundary",
// so float and double take the same side for forces exactly on it.
template <typename T, int K>
uint8_t relevance(const ContactFrames<T, K>& frames, const Vec3<T>& force) {
  const T f_norm = force.norm();
  uint8_t mask = 0;
  for (int i = 0; i < K; ++i) {
    const auto r = frames.offset_scaled.col(i);
    if (force.dot(r) <= T(kRelevanceCosTol) * f_norm * r.norm())
      mask = static_cast<uint8_t>(mask | (1u << i));
  }
  return mask;
}

// lambda_des,i = C_i lambda0_i, normalised; left at zero if no relevant force remains.
template <typename T, int K>
ForceVec<T, K> desired_forces(const ForceVec<T, K>& lambda0, uint8_t mask) {
  ForceVec<T, K> des = ForceVec<T, K>::Zero();
  for (int i = 0; i < K; ++i)
    if (mask & (1u << i)) des.template segment<3>(3 * i) = lambda0.template segment<3>(3 * i);
  const T n = des.norm();
  if (n > T(kTinyRel) * lambda0.norm())
    des /= n;
  else
    des.setZero();
  return des;
}

}  // namespace graspguide
