// Step 1 of Algorithm 1: the centroid O and a right-handed frame at each contact.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "graspguide/status.h"
#include "graspguide/tolerances.h"
#include "graspguide/types.h"

namespace graspguide {

template <typename T, int K>
struct ContactFrames {
  Vec3<T> origin = Vec3<T>::Zero();  // O, in the hand frame
  T length_scale = T(0);             // L = max |C_i - O|
  Contacts<T, K> offset_scaled;      // (C_i - O) / L, one column per contact
  Mat3<T> rotation[K];               // R_i = [x_i y_i z_i], contact i -> object frame
  Vec3<T> axis = Vec3<T>::UnitY();   // y_O, unit
  // c_i = |s_i x y_O| (s_i = (C_i - O) / L): the moment about y_O is -sum_i c_i lambda_ix
  // when no contact uses the fallback (force_qp.h, the paper model's x rows).
  T x_moment[K] = {};
  uint8_t fallback_mask = 0;  // bit i: contact i used the fallback x axis
};

// A unit vector perpendicular to y_O, used when y_i is (anti)parallel to y_O. Built from
// the basis vector least aligned with y_O so it is always well defined.
template <typename T>
Vec3<T> fallback_axis(const Vec3<T>& y_axis_unit) {
  int least = 0;
  for (int j = 1; j < 3; ++j)
    if (std::abs(y_axis_unit(j)) < std::abs(y_axis_unit(least))) least = j;
  return y_axis_unit.cross(Vec3<T>::Unit(least)).normalized();
}

template <typename T, int K>
Status contact_frames(const Contacts<T, K>& contacts, const Vec3<T>& y_axis,
                      ContactFrames<T, K>& out) {
  static_assert(K == 3 || K == 4, "3 or 4 contacts");
  if (!contacts.allFinite() || !y_axis.allFinite()) return Status::kNonFiniteInput;
  const T axis_norm = y_axis.stableNorm();
  if (!(axis_norm > T(0))) return Status::kBadAxis;
  const Vec3<T> y_o = y_axis / axis_norm;

  // Centroid relative to the first contact: a common offset of 1e6 then costs nothing
  // beyond the rounding of the inputs themselves.
  const Vec3<T> first = contacts.col(0);
  Contacts<T, K> rel = contacts.colwise() - first;
  const Vec3<T> mean_rel = rel.rowwise().mean();
  out.origin = first + mean_rel;
  const Contacts<T, K> r = rel.colwise() - mean_rel;

  T scale = T(0);
  for (int i = 0; i < K; ++i) scale = std::max(scale, r.col(i).norm());
  const T coincident = T(kCoincidentRelTol) * scale;
  if (!(scale > T(0))) return Status::kCoincidentContacts;
  // Inputs far from the origin carry their rounding into the geometry: refuse rather than
  // render a hand this precision cannot resolve (a float tracker 1 km away, say).
  const T magnitude = contacts.cwiseAbs().maxCoeff();
  if (magnitude * std::numeric_limits<T>::epsilon() > T(kInputPrecisionRelTol) * scale)
    return Status::kImpreciseContacts;
  for (int i = 0; i < K; ++i) {
    if (r.col(i).norm() <= coincident) return Status::kCoincidentContacts;
    for (int j = i + 1; j < K; ++j)
      if ((r.col(i) - r.col(j)).norm() <= coincident) return Status::kCoincidentContacts;
  }
  out.length_scale = scale;
  out.offset_scaled = r / scale;

  out.axis = y_o;
  out.fallback_mask = 0;
  for (int i = 0; i < K; ++i) {
    const T r_norm = r.col(i).norm();
    const Vec3<T> y = r.col(i) / r_norm;
    Vec3<T> x = y.cross(y_o);
    const T s = x.norm();
    out.x_moment[i] = s * r_norm / scale;
    if (s < T(kAxisParallelTol)) {
      x = y.cross(fallback_axis<T>(y_o)).normalized();
      out.fallback_mask = static_cast<uint8_t>(out.fallback_mask | (1u << i));
    } else {
      x /= s;
    }
    out.rotation[i].col(0) = x;
    out.rotation[i].col(1) = y;
    out.rotation[i].col(2) = x.cross(y);
  }
  return Status::kOk;
}

}  // namespace graspguide
