// The guidance error: the angle between the force the motors render (f_hat, a unit vector in
// the hand frame, fixed while the posture is) and gravity, and the gain alpha of mode V.
// Both come from d = |f_hat - g_hat|, with g_hat gravity in the hand frame:
//   alpha = d / 2 * kPwmSpan,   error = 2 asin(d / 2)   (d / 2 = sin(error / 2)).
// asin of the half chord keeps full accuracy near 0 degrees, where acos of a dot product
// loses it; near 180 degrees the other half chord |f_hat + g_hat| / 2 = cos(error / 2) takes
// over, so 180 degrees is as accurate. Rotation invariance means only gravity has to be
// rotated, and only its row of R(q) is computed. docs/per-frame-layer.md has the costs.
#pragma once

#include "graspguide_cue/config.h"
#include "graspguide_cue/scalar_math.h"
#include "graspguide_cue/status.h"
#include "graspguide_cue/tolerances.h"

namespace graspguide {

template <typename T>
struct Alignment {
  T error_deg = T(0);  // angle between f_hat and gravity, in [0, 180]
  T alpha = T(0);      // |f_hat - g_hat| / 2 * kPwmSpan, in [0, kPwmSpan]
};

namespace detail {

// g = |q|^2 R(q)^T (0, 0, -1) for q = [w, x, y, z] (hand -> world), and |q|^2.
template <typename T>
inline T scaled_gravity(T w, T x, T y, T z, T g[3]) {
  const T p = w * w + z * z;
  const T r = x * x + y * y;
  const T a = w * y - x * z;
  const T b = y * z + w * x;
  g[0] = a + a;
  g[1] = -(b + b);
  g[2] = r - p;
  return p + r;
}

// The largest |v_i|, or a negative value when one is NaN or infinite.
template <typename T>
inline T finite_max_abs(const T* v, int n) {
  T m = T(0);
  for (int i = 0; i < n; ++i) {
    if (!scalar_math::is_finite(v[i])) return T(-1);
    const T a = scalar_math::abs_of(v[i]);
    if (a > m) m = a;
  }
  return m;
}

}  // namespace detail

// Gravity in the hand frame, g = R(q)^T (0, 0, -1), unit length, for a quaternion
// [w, x, y, z] of any finite non-zero scale: kNonFiniteInput, or kBadQuaternion when
// |q| < kMinQuaternionNorm.
template <typename T>
Status gravity_in_hand(const T wxyz[4], T g[3]) {
  T n2 = detail::scaled_gravity(wxyz[0], wxyz[1], wxyz[2], wxyz[3], g);
  // A tracker's unit quaternion: also proves n2 finite and large enough, in one comparison.
  if (scalar_math::abs_of(n2 - T(1)) <= FrameTolerances<T>::kUnitNormSlack) return Status::kOk;
  if (!(n2 <= scalar_math::Limits<T>::kMax)) {
    // A NaN or an infinity, or finite components whose squares overflow.
    const T m = detail::finite_max_abs(wxyz, 4);
    if (m < T(0)) return Status::kNonFiniteInput;
    const T inv = T(1) / m;
    n2 = detail::scaled_gravity(wxyz[0] * inv, wxyz[1] * inv, wxyz[2] * inv, wxyz[3] * inv, g);
  } else if (!(n2 >= T(kMinQuaternionNorm * kMinQuaternionNorm))) {
    return Status::kBadQuaternion;
  }
  const T inv = T(1) / n2;
  for (int i = 0; i < 3; ++i) g[i] *= inv;
  return Status::kOk;
}

// The error and alpha for unit f_hat and unit g_hat, both in the hand frame.
template <typename T>
Alignment<T> alignment_to_gravity(const T f_hat[3], const T g_hat[3]) {
  using scalar_math::asin_deg_ratio;
  const T d0 = f_hat[0] - g_hat[0], d1 = f_hat[1] - g_hat[1], d2 = f_hat[2] - g_hat[2];
  const T chord2 = d0 * d0 + d1 * d1 + d2 * d2;  // d^2 = 4 sin^2(error / 2)
  const T chord = scalar_math::sqrt_of(chord2);
  Alignment<T> a;
  a.alpha = chord * T(kPwmSpan * 0.5);
  // Three ranges, each with an argument of asin in [-0.5, 0.5] computed without cancellation;
  // 2 asin(d / 2) = d asin(x) / x with x = d / 2.
  if (chord2 <= T(1)) {  // error <= 60 degrees: sin(error / 2) <= 0.5
    a.error_deg = chord * asin_deg_ratio(chord2 * T(0.25));
  } else if (chord2 <= T(3)) {  // <= 120 degrees: cos(error) = 1 - d^2 / 2 in [-0.5, 0.5]
    const T c = T(1) - chord2 * T(0.5);
    a.error_deg = T(90) - c * asin_deg_ratio(c * c);
  } else {  // cos(error / 2) = |f_hat + g_hat| / 2 < 0.5, accurate up to 180 degrees
    const T s0 = f_hat[0] + g_hat[0], s1 = f_hat[1] + g_hat[1], s2 = f_hat[2] + g_hat[2];
    const T sum2 = s0 * s0 + s1 * s1 + s2 * s2;
    a.error_deg = T(180) - scalar_math::sqrt_of(sum2) * asin_deg_ratio(sum2 * T(0.25));
  }
  return a;
}

// From the hand's orientation q = [w, x, y, z] (hand -> world), as the tracker sends it.
template <typename T>
Status alignment_from_quaternion(const T wxyz[4], const T f_hat[3], Alignment<T>& out) {
  T g[3];
  const Status s = gravity_in_hand(wxyz, g);
  if (s != Status::kOk) return s;
  out = alignment_to_gravity(f_hat, g);
  return Status::kOk;
}

// From a gravity direction measured in the hand frame (an IMU's accelerometer at rest), of
// any finite non-zero length: kNonFiniteInput, or kBadAxis when shorter than
// kMinQuaternionNorm.
template <typename T>
Status alignment_from_gravity(const T gravity[3], const T f_hat[3], Alignment<T>& out) {
  T g[3] = {gravity[0], gravity[1], gravity[2]};
  T n2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
  if (!(n2 <= scalar_math::Limits<T>::kMax)) {
    const T m = detail::finite_max_abs(g, 3);
    if (m < T(0)) return Status::kNonFiniteInput;
    for (int i = 0; i < 3; ++i) g[i] /= m;
    n2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
  } else if (!(n2 >= T(kMinQuaternionNorm * kMinQuaternionNorm))) {
    return Status::kBadAxis;
  }
  const T inv = T(1) / scalar_math::sqrt_of(n2);
  for (int i = 0; i < 3; ++i) g[i] *= inv;
  out = alignment_to_gravity(f_hat, g);
  return Status::kOk;
}

}  // namespace graspguide
