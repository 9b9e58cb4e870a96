// Step 7a: the guidance error between the rendered force and gravity, and the
// error-proportional gain alpha of mode V.
#pragma once

#include <cmath>

#include "graspguide/status.h"
#include "graspguide/tolerances.h"
#include "graspguide/types.h"

namespace graspguide {

// [w, x, y, z] -> unit quaternion; any finite non-zero scale is the same rotation.
template <typename T>
Status unit_quaternion(const Eigen::Matrix<T, 4, 1>& wxyz, Quat<T>& q) {
  if (!wxyz.allFinite()) return Status::kNonFiniteInput;
  const T n = wxyz.stableNorm();  // no overflow for huge, no underflow for tiny scales
  if (!(n >= T(kMinQuaternionNorm))) return Status::kBadQuaternion;
  q = Quat<T>(wxyz(0) / n, wxyz(1) / n, wxyz(2) / n, wxyz(3) / n);
  return Status::kOk;
}

template <typename T>
struct Alignment {
  T error_deg = T(0);  // angle between R f_hat and g
  T alpha = T(0);      // |R f_hat - g| / 2 * kPwmSpan
};

template <typename T>
Alignment<T> alignment(const Quat<T>& hand_to_world, const Vec3<T>& force_unit) {
  const Vec3<T> g(T(0), T(0), T(-1));
  const Vec3<T> fw = hand_to_world * force_unit;
  Alignment<T> a;
  // atan2 keeps full accuracy near 0 degrees, where acos of a dot product loses it.
  const T rad = std::atan2(fw.cross(g).norm(), fw.dot(g));
  a.error_deg = rad * T(180.0 / 3.14159265358979323846);
  a.alpha = (fw - g).norm() / T(2) * T(kPwmSpan);
  return a;
}

}  // namespace graspguide
