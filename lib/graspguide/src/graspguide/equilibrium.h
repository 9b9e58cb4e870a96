// Step 3: the minimum-norm contact forces lambda0 = -G^+ w and an orthonormal basis N of
// null(G). Default route: a column-pivoting QR of the reduced grasp matrix M^T
// (3(k-1) x 3, grasp_matrix.h), which the structure of G makes exact. Reference route: a
// Jacobi SVD of the whole G^T, for accuracy comparisons; firmware may leave it out
// (GRASPGUIDE_WITH_SVD_ROUTE=0) to save flash.
#pragma once

#include "graspguide/eigen_decompositions.h"
#include "graspguide/grasp_matrix.h"
#include "graspguide/scene.h"

#ifndef GRASPGUIDE_WITH_SVD_ROUTE
#define GRASPGUIDE_WITH_SVD_ROUTE 1
#endif

namespace graspguide {

template <typename T, int K>
struct Equilibrium {
  ForceVec<T, K> lambda0;
  NullBasis<T, K> null_basis;
  T rank_ratio = T(0);  // sigma_min / sigma_max of G (an estimate of it on the QR route)
};

// x <- Q x for the reflectors of a QR with 3 columns, each applied at a fixed size so
// that Eigen inlines the products (HouseholderSequence works at run-time sizes, through
// its general matrix-vector kernels: 3,000 instructions for Q [0; I] with k = 4 on the
// M4F, measured under QEMU, against 2,120 this way).
template <int J, typename Packed, typename Coeffs, typename Dst>
void apply_householder_q(const Packed& packed, const Coeffs& coeffs, Dst& x) {
  constexpr int kRows = Dst::RowsAtCompileTime;
  typename Dst::Scalar workspace[Dst::ColsAtCompileTime];
  x.template bottomRows<kRows - J>().applyHouseholderOnTheLeft(
      packed.col(J).template tail<kRows - J - 1>(), coeffs(J), workspace);
  if constexpr (J > 0) apply_householder_q<J - 1>(packed, coeffs, x);
}

// G lambda = -w with w = [f; tau]: the forces F_i = R_i lambda_i (object frame) split into
// the equal share -f/k, which has no moment about the centroid, and zero-resultant forces
// (H (x) I3) z with M z = -tau. Both parts are orthogonal, so the minimum-norm lambda takes
// the minimum-norm z = -M^+ tau; null(G) is R^T (H (x) I3) null(M).
template <typename T, int K>
Status equilibrium_qr(const ContactFrames<T, K>& frames, const ReducedGraspT<T, K>& mt,
                      const Vec6<T>& w, Equilibrium<T, K>& out) {
  constexpr int kRows = 3 * (K - 1);
  constexpr int kNull = 3 * K - 6;
  Eigen::ColPivHouseholderQR<ReducedGraspT<T, K>> qr;
  qr.compute(mt);
  const auto& packed = qr.matrixQR();
  // sigma(G) = {sqrt(k) (three times), sigma(M)}; |R_00| and |R_22| estimate sigma(M).
  const T sqrt_k = std::sqrt(T(K));
  const T s_max = std::max(sqrt_k, std::abs(packed(0, 0)));
  const T s_min = std::min(sqrt_k, std::abs(packed(2, 2)));
  out.rank_ratio = s_min / s_max;
  if (!(out.rank_ratio >= T(kRankRelTol))) return Status::kRankDeficient;

  // Only the columns of Q that are used: Q [0; I] (null(M)) and Q [R^-T P^T (-tau); 0].
  Eigen::Matrix<T, kRows, kNull> null_m = Eigen::Matrix<T, kRows, kNull>::Zero();
  null_m.template bottomRows<kNull>().setIdentity();
  apply_householder_q<2>(packed, qr.hCoeffs(), null_m);
  // M^T P = Q R  =>  M^+ = Q_1 R^-T P^T.
  Eigen::Matrix<T, kRows, 1> z = Eigen::Matrix<T, kRows, 1>::Zero();
  z.template head<3>() = qr.colsPermutation().transpose() * (-w.template tail<3>());
  packed.template topLeftCorner<3, 3>()
      .template triangularView<Eigen::Upper>()
      .transpose()
      .solveInPlace(z.template head<3>());
  apply_householder_q<2>(packed, qr.hCoeffs(), z);
  const Vec3<T> share = w.template head<3>() / T(-K);
  for (int i = 0; i < K; ++i) {
    Vec3<T> f = share;
    Eigen::Matrix<T, 3, kNull> n = Eigen::Matrix<T, 3, kNull>::Zero();
    for (int r = 0; r < K - 1; ++r) {
      const T h = Contrasts<T, K>::h[i][r];
      f += h * z.template segment<3>(3 * r);
      n += h * null_m.template middleRows<3>(3 * r);
    }
    out.lambda0.template segment<3>(3 * i).noalias() = frames.rotation[i].transpose() * f;
    out.null_basis.template middleRows<3>(3 * i).noalias() = frames.rotation[i].transpose() * n;
  }
  return Status::kOk;
}

template <typename T, int K>
Status equilibrium_svd(const GraspMat<T, K>& g, const Vec6<T>& w, Equilibrium<T, K>& out) {
  Eigen::JacobiSVD<GraspMatT<T, K>> svd;
  svd.compute(g.transpose(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  // On a matrix holding Inf or NaN, compute() returns early with the singular values
  // unset; the inputs were checked finite, but their products can still overflow.
  if (svd.info() != Eigen::Success) return Status::kNonFiniteInput;
  const auto& sv = svd.singularValues();
  out.rank_ratio = sv(0) > T(0) ? sv(5) / sv(0) : T(0);
  if (!(out.rank_ratio >= T(kRankRelTol))) return Status::kRankDeficient;
  // G^T = U S V^T  =>  G^+ = U_1 S^-1 V^T.
  Vec6<T> y = svd.matrixV().transpose() * w;
  y.array() /= sv.array();
  out.lambda0.noalias() = -svd.matrixU().template leftCols<6>() * y;
  out.null_basis = svd.matrixU().template rightCols<3 * K - 6>();
  return Status::kOk;
}

// Builds only the matrix the chosen route needs.
template <typename T, int K>
Status equilibrium(const ContactFrames<T, K>& frames, const Vec6<T>& w, Decomposition d,
                   Equilibrium<T, K>& out) {
  if (d == Decomposition::kSVD) {
#if GRASPGUIDE_WITH_SVD_ROUTE
    GraspMat<T, K> g;
    grasp_matrix<T, K>(frames, g);
    return equilibrium_svd<T, K>(g, w, out);
#else
    return Status::kBadConfig;
#endif
  }
  ReducedGraspT<T, K> mt;
  reduced_grasp_matrix<T, K>(frames, mt);
  return equilibrium_qr<T, K>(frames, mt, w, out);
}

// Instantiated once in equilibrium_qr.cpp / equilibrium_svd.cpp (EXTERN empty) and
// declared extern everywhere else: Eigen's decompositions are slow to compile, and every
// test would otherwise compile them again.
#define GRASPGUIDE_EQUILIBRIUM_QR(EXTERN, T, K) \
  EXTERN template Status equilibrium_qr<T, K>(  \
      const ContactFrames<T, K>&, const ReducedGraspT<T, K>&, const Vec6<T>&, Equilibrium<T, K>&);
#define GRASPGUIDE_EQUILIBRIUM_SVD(EXTERN, T, K)                                      \
  EXTERN template Status equilibrium_svd<T, K>(const GraspMat<T, K>&, const Vec6<T>&, \
                                               Equilibrium<T, K>&);
#define GRASPGUIDE_EQUILIBRIA(EXTERN, ROUTE) \
  ROUTE(EXTERN, float, 3) ROUTE(EXTERN, float, 4) ROUTE(EXTERN, double, 3) ROUTE(EXTERN, double, 4)
#ifndef GRASPGUIDE_INSTANTIATING_EQUILIBRIUM
GRASPGUIDE_EQUILIBRIA(extern, GRASPGUIDE_EQUILIBRIUM_QR)
GRASPGUIDE_EQUILIBRIA(extern, GRASPGUIDE_EQUILIBRIUM_SVD)
#endif

}  // namespace graspguide
