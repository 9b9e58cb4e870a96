// Step 2 on the structured route: the grasp matrix whitened by (G G^T)^(-1/2), in closed
// form. With offsets from the centroid, G G^T = diag(k I, J), J = S^T S, where S stacks
// skew(s_i)^T (s_i = r_i / L). A QR S = Q R_J gives J's Cholesky factor without forming J
// (forming it would square the conditioning of a near-collinear hand in float), and
//   G_hat = diag(I / sqrt(k), R_J^-T) G,   block i = [R_i / sqrt(k) ; Q_i^T R_i],
// has orthonormal rows. Everything the later steps need follows from G_hat alone: the
// minimum-norm forces -G_hat^T w_hat, and the projector onto the equilibrium set,
// I - G_hat^T G_hat, whose columns the QP forms on demand. See docs/algorithm.md, step 2.
#pragma once

#include <cmath>

#include "graspguide/contact_frames.h"

namespace graspguide {

template <typename T, int K>
using WhitenedGrasp = Eigen::Matrix<T, 6, 3 * K>;

template <typename T, int K>
struct GraspStructure {
  WhitenedGrasp<T, K> g_hat;           // rows orthonormal
  Mat3<T> j_factor = Mat3<T>::Zero();  // R_J, upper triangular, J = R_J^T R_J
  T rank_ratio = T(0);                 // sigma_min(G) / sigma_max(G)
};

namespace detail {

// The largest singular value of the inverse of an upper-triangular 3x3 R, i.e. 1 /
// sigma_min(R), by two power steps on R^-T R^-1 from its longest column. The rank test
// only matters where sigma_min is far below the others (ratio near kRankRelTol), and
// there the steps converge to working precision.
template <typename T>
T inverse_norm_upper3(const Mat3<T>& r) {
  Mat3<T> m = Mat3<T>::Zero();
  m(0, 0) = T(1) / r(0, 0);
  m(1, 1) = T(1) / r(1, 1);
  m(2, 2) = T(1) / r(2, 2);
  m(0, 1) = -r(0, 1) * m(0, 0) * m(1, 1);
  m(1, 2) = -r(1, 2) * m(1, 1) * m(2, 2);
  m(0, 2) = -(r(0, 1) * m(1, 2) + r(0, 2) * m(2, 2)) * m(0, 0);
  int longest = 0;
  for (int c = 1; c < 3; ++c)
    if (m.col(c).squaredNorm() > m.col(longest).squaredNorm()) longest = c;
  Vec3<T> x = m.col(longest).normalized();
  T estimate = T(0);
  for (int step = 0; step < 2; ++step) {
    const Vec3<T> y = m.transpose() * x;
    x.noalias() = m * y;
    estimate = std::sqrt(x.norm());
    x.normalize();
  }
  return estimate;
}

}  // namespace detail

// kRankDeficient when sigma_min(G) / sigma_max(G) < kRankRelTol. sigma(G) = {sqrt(k)
// (three times), sigma(R_J)}, and sigma_max(R_J) <= sqrt(k) because every |s_i| <= 1, so
// the ratio is sigma_min(R_J) / sqrt(k).
template <typename T, int K>
Status grasp_structure(const ContactFrames<T, K>& frames, GraspStructure<T, K>& out) {
  // S, one 3x3 block skew(s_i)^T = skew(-s_i) per contact.
  Eigen::Matrix<T, 3 * K, 3> s;
  for (int i = 0; i < K; ++i) {
    const Vec3<T> v = frames.offset_scaled.col(i);
    s.template block<3, 3>(3 * i, 0) << T(0), v(2), -v(1), -v(2), T(0), v(0), v(1), -v(0), T(0);
  }
  // Gram-Schmidt with one reorthogonalisation ("twice is enough"): Q orthonormal to
  // working precision, so G_hat's rows are too, whatever the hand's shape.
  Mat3<T>& r = out.j_factor;
  r.setZero();
  const T tiny = T(kTinyRel) * std::sqrt(T(K));
  for (int c = 0; c < 3; ++c) {
    for (int pass = 0; pass < 2; ++pass) {
      for (int p = 0; p < c; ++p) {
        const T d = s.col(p).dot(s.col(c));
        s.col(c) -= d * s.col(p);
        r(p, c) += d;
      }
    }
    r(c, c) = s.col(c).norm();
    if (!(r(c, c) > tiny)) {
      out.rank_ratio = T(0);
      return Status::kRankDeficient;
    }
    s.col(c) /= r(c, c);
  }
  out.rank_ratio = T(1) / (detail::inverse_norm_upper3<T>(r) * std::sqrt(T(K)));
  if (!(out.rank_ratio >= T(kRankRelTol))) return Status::kRankDeficient;

  const T inv_sqrt_k = T(1) / std::sqrt(T(K));
  for (int i = 0; i < K; ++i) {
    out.g_hat.template block<3, 3>(0, 3 * i) = frames.rotation[i] * inv_sqrt_k;
    out.g_hat.template block<3, 3>(3, 3 * i).noalias() =
        s.template block<3, 3>(3 * i, 0).transpose() * frames.rotation[i];
  }
  return Status::kOk;
}

// w_hat = diag(I / sqrt(k), R_J^-T) w, for the scaled wrench w = [f; tau / L].
template <typename T, int K>
Vec6<T> whitened_wrench(const GraspStructure<T, K>& st, const Vec6<T>& w) {
  Vec6<T> out;
  out.template head<3>() = w.template head<3>() / std::sqrt(T(K));
  out.template tail<3>() = w.template tail<3>();
  st.j_factor.transpose().template triangularView<Eigen::Lower>().solveInPlace(
      out.template tail<3>());
  return out;
}

// lambda0 = -G^+ w = -G_hat^T w_hat: per contact, R_i^T (-f/k + s_i x J^-1 tau).
template <typename T, int K>
ForceVec<T, K> min_norm_forces(const GraspStructure<T, K>& st, const Vec6<T>& w_hat) {
  ForceVec<T, K> lambda0;
  lambda0.noalias() = -st.g_hat.transpose() * w_hat;
  return lambda0;
}

// The unconstrained optimum of the QP: lambda_des projected onto {G lambda = -w}.
template <typename T, int K>
ForceVec<T, K> project_onto_equilibrium(const GraspStructure<T, K>& st, const Vec6<T>& w_hat,
                                        const ForceVec<T, K>& lambda_des) {
  Vec6<T> residual = w_hat;
  residual.noalias() += st.g_hat * lambda_des;
  ForceVec<T, K> out = lambda_des;
  out.noalias() -= st.g_hat.transpose() * residual;
  return out;
}

}  // namespace graspguide
