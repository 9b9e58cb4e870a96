// Step 2: the grasp matrix of hard-finger contacts, G_i = [R_i ; skew(r_i / L) R_i], as the
// SVD reference route forms it (the structured route never does: grasp_structure.h).
#pragma once

#include "graspguide/contact_frames.h"

namespace graspguide {

template <typename T>
Mat3<T> skew(const Vec3<T>& v) {
  Mat3<T> s;
  s << T(0), -v(2), v(1), v(2), T(0), -v(0), -v(1), v(0), T(0);
  return s;
}

// Moment rows use the offsets divided by L (docs/algorithm.md, step 2): an exact row
// scaling that keeps G's singular values independent of the length unit.
template <typename T, int K>
void grasp_matrix(const ContactFrames<T, K>& frames, GraspMat<T, K>& g) {
  for (int i = 0; i < K; ++i) {
    g.template block<3, 3>(0, 3 * i) = frames.rotation[i];
    g.template block<3, 3>(3, 3 * i).noalias() =
        skew<T>(frames.offset_scaled.col(i)) * frames.rotation[i];
  }
}

// The wrench in the same scaled units: moments divided by L.
template <typename T>
Vec6<T> scaled_wrench(const Vec6<T>& w, T length_scale) {
  Vec6<T> s = w;
  s.template tail<3>() /= length_scale;
  return s;
}

}  // namespace graspguide
