// Step 7a on Eigen types: the per-frame layer's guidance error and alpha
// (graspguide_cue/alignment.h) for callers that hold Eigen vectors and quaternions.
#pragma once

#include "graspguide/types.h"
#include "graspguide_cue/alignment.h"

namespace graspguide {

// [w, x, y, z] -> unit quaternion; any finite non-zero scale is the same rotation. The
// checks (and so the statuses) are the per-frame layer's.
template <typename T>
Status unit_quaternion(const Eigen::Matrix<T, 4, 1>& wxyz, Quat<T>& q) {
  T g[3];
  const Status s = gravity_in_hand<T>(wxyz.data(), g);
  if (s != Status::kOk) return s;
  const T n = wxyz.stableNorm();  // no overflow for huge, no underflow for tiny scales
  q = Quat<T>(wxyz(0) / n, wxyz(1) / n, wxyz(2) / n, wxyz(3) / n);
  return Status::kOk;
}

// For a unit quaternion (unit_quaternion's output) and a unit force direction.
template <typename T>
Alignment<T> alignment(const Quat<T>& hand_to_world, const Vec3<T>& force_unit) {
  const T wxyz[4] = {hand_to_world.w(), hand_to_world.x(), hand_to_world.y(), hand_to_world.z()};
  T g[3];
  gravity_in_hand<T>(wxyz, g);  // a unit quaternion always passes
  return alignment_to_gravity<T>(force_unit.data(), g);
}

}  // namespace graspguide
