// Step 3: the minimum-norm contact forces lambda0 = -G^+ w and an orthonormal basis N of
// null(G), from a column-pivoting QR of G^T (default: cheap on a microcontroller) or a
// Jacobi SVD (reference route, for accuracy comparisons).
#pragma once

#include "graspguide/eigen_decompositions.h"
#include "graspguide/grasp_matrix.h"
#include "graspguide/scene.h"

namespace graspguide {

template <typename T, int K>
struct Equilibrium {
  ForceVec<T, K> lambda0;
  NullBasis<T, K> null_basis;
  T rank_ratio = T(0);  // sigma_min / sigma_max (an estimate of it on the QR route)
};

template <typename T, int K>
Status equilibrium_qr(const GraspMat<T, K>& g, const Vec6<T>& w, Equilibrium<T, K>& out) {
  using Qr = Eigen::ColPivHouseholderQR<GraspMatT<T, K>>;
  Qr qr;
  qr.compute(g.transpose());
  const auto& packed = qr.matrixQR();
  const T r_max = std::abs(packed(0, 0));
  out.rank_ratio = r_max > T(0) ? std::abs(packed(5, 5)) / r_max : T(0);
  if (!(out.rank_ratio >= T(kRankRelTol))) return Status::kRankDeficient;

  Eigen::Matrix<T, 3 * K, 3 * K> q = qr.householderQ();
  // G^T P = Q R  =>  G^+ = Q_1 R^-T P^T.
  Vec6<T> y = qr.colsPermutation().transpose() * w;
  packed.template topLeftCorner<6, 6>().template triangularView<Eigen::Upper>()
      .transpose().solveInPlace(y);
  out.lambda0.noalias() = -q.template leftCols<6>() * y;
  out.null_basis = q.template rightCols<3 * K - 6>();
  return Status::kOk;
}

template <typename T, int K>
Status equilibrium_svd(const GraspMat<T, K>& g, const Vec6<T>& w, Equilibrium<T, K>& out) {
  Eigen::JacobiSVD<GraspMatT<T, K>> svd;
  svd.compute(g.transpose(), Eigen::ComputeFullU | Eigen::ComputeFullV);
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

template <typename T, int K>
Status equilibrium(const GraspMat<T, K>& g, const Vec6<T>& w, Decomposition d,
                   Equilibrium<T, K>& out) {
  return d == Decomposition::kSVD ? equilibrium_svd<T, K>(g, w, out)
                                  : equilibrium_qr<T, K>(g, w, out);
}

// Instantiated once in equilibrium_qr.cpp / equilibrium_svd.cpp (EXTERN empty) and
// declared extern everywhere else: Eigen's decompositions are slow to compile, and every
// test would otherwise compile them again.
#define GRASPGUIDE_EQUILIBRIUM(EXTERN, ROUTE, T, K) \
  EXTERN template Status ROUTE<T, K>(const GraspMat<T, K>&, const Vec6<T>&, Equilibrium<T, K>&);
#define GRASPGUIDE_EQUILIBRIA(EXTERN, ROUTE)                                    \
  GRASPGUIDE_EQUILIBRIUM(EXTERN, ROUTE, float, 3)                               \
  GRASPGUIDE_EQUILIBRIUM(EXTERN, ROUTE, float, 4)                               \
  GRASPGUIDE_EQUILIBRIUM(EXTERN, ROUTE, double, 3)                              \
  GRASPGUIDE_EQUILIBRIUM(EXTERN, ROUTE, double, 4)
#ifndef GRASPGUIDE_INSTANTIATING_EQUILIBRIUM
GRASPGUIDE_EQUILIBRIA(extern, equilibrium_qr)
GRASPGUIDE_EQUILIBRIA(extern, equilibrium_svd)
#endif

}  // namespace graspguide
