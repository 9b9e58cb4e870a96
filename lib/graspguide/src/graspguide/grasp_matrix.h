// Step 2: the grasp matrix of hard-finger contacts, G_i = [R_i ; skew(r_i / L) R_i].
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

// Orthonormal contrasts H (K x (K-1)): columns orthonormal and orthogonal to (1, ..., 1),
// so that f = (H (x) I3) z spans exactly the force sets with zero resultant. A table of T,
// so that unrolled loops multiply by constants instead of converting from double.
template <typename T, int K>
struct Contrasts;
template <typename T>
struct Contrasts<T, 3> {
  static constexpr T h[3][2] = {{T(0.70710678118654752440), T(0.40824829046386301637)},
                                {T(-0.70710678118654752440), T(0.40824829046386301637)},
                                {T(0), T(-0.81649658092772603273)}};
};
// Hadamard contrasts: every entry is +-1/2.
template <typename T>
struct Contrasts<T, 4> {
  static constexpr T h[4][3] = {{T(0.5), T(0.5), T(0.5)},
                                {T(0.5), T(-0.5), T(-0.5)},
                                {T(-0.5), T(0.5), T(-0.5)},
                                {T(-0.5), T(-0.5), T(0.5)}};
};

// The reduced grasp matrix of the QR route (docs/algorithm.md, step 3): the moment
// rows of G on the zero-resultant forces, transposed. With offsets from the centroid,
// G G^T = diag(k I, M M^T), so G's singular values are sqrt(k) and those of M; the
// null space of G is the null space of M lifted through H, and the decomposition
// shrinks from a 3k x 6 to a 3(k-1) x 3 matrix. Forces here are in the object frame.
template <typename T, int K>
void reduced_grasp_matrix(const ContactFrames<T, K>& frames, ReducedGraspT<T, K>& mt) {
  for (int r = 0; r < K - 1; ++r) {
    Vec3<T> q = Vec3<T>::Zero();
    for (int i = 0; i < K; ++i) q += Contrasts<T, K>::h[i][r] * frames.offset_scaled.col(i);
    // Block r of M is skew(q_r); of M^T, skew(-q_r).
    mt.template block<3, 3>(3 * r, 0) = skew<T>(-q);
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
