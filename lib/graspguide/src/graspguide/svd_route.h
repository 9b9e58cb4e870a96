// The reference route of steps 2-5: a Jacobi SVD of the whole G^T for lambda0 and an
// orthonormal basis N of null(G), then the paper's QP (eq. 2) in null-space coordinates
// xi (lambda = lambda0 + N xi) through the dual active-set solver of projection_qp.h. It
// shares nothing numerical with the structured route (grasp_structure.h, force_qp.h), so
// the accuracy table compares two methods, not one method twice (docs/performance.md).
// Firmware leaves it out (GRASPGUIDE_WITH_SVD_ROUTE=0), which saves ~9 KB of flash.
#pragma once

#include "graspguide/eigen_decompositions.h"
#include "graspguide/grasp_matrix.h"
#include "graspguide/projection_qp.h"
#include "graspguide/scene.h"

#ifndef GRASPGUIDE_WITH_SVD_ROUTE
#define GRASPGUIDE_WITH_SVD_ROUTE 1
#endif

namespace graspguide {

template <typename T, int K>
struct Equilibrium {
  ForceVec<T, K> lambda0;
  NullBasis<T, K> null_basis;
  T rank_ratio = T(0);  // sigma_6 / sigma_1 of G
};

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

// The paper's QP on lambda = lambda0 + N xi for one model after another (paper -> normal
// -> none): component j of lambda >= 0 is row N_j xi >= -lambda0_j.
template <typename T, int K>
Status solve_forces_svd(const Equilibrium<T, K>& eq, const ForceVec<T, K>& lambda_des,
                        ConstraintModel requested, int max_iterations, ForceVec<T, K>& lambda,
                        ConstraintModel& used, int& iterations,
                        T feasibility_rel = Tolerances<T>::kFeasRelTol) {
  constexpr int kVars = 3 * K - 6;
  ProjectionQp<T, kVars, 3 * K> qp;
  qp.x_unconstrained.noalias() = eq.null_basis.transpose() * (lambda_des - eq.lambda0);
  qp.violation_tol = feasibility_rel * eq.lambda0.norm();
  qp.dependent_tol = Tolerances<T>::kDependentRelTol;
  iterations = 0;
  for (int model = static_cast<int>(requested); model <= static_cast<int>(ConstraintModel::kNone);
       ++model) {
    const auto m = static_cast<ConstraintModel>(model);
    qp.m = 0;
    for (int j = 0; j < 3 * K && m != ConstraintModel::kNone; ++j) {
      if (m == ConstraintModel::kNormal && j % 3 != 1) continue;
      qp.a.row(qp.m) = eq.null_basis.row(j);
      qp.b(qp.m) = -eq.lambda0(j);
      ++qp.m;
    }
    Eigen::Matrix<T, kVars, 1> xi;
    QpInfo info;
    const Status s = solve_projection<T, kVars, 3 * K>(qp, max_iterations, 0, xi, info);
    iterations += info.iterations;
    if (s == Status::kQpInfeasible) continue;
    if (s != Status::kOk) return s;
    lambda.noalias() = eq.lambda0 + eq.null_basis * xi;
    used = m;
    return Status::kOk;
  }
  return Status::kQpInfeasible;  // unreachable: the model "none" has no constraints
}

// Instantiated once in svd_route.cpp (EXTERN empty) and declared extern everywhere else:
// Eigen's SVD is slow to compile, and every test would otherwise compile it again.
#define GRASPGUIDE_SVD_ROUTE(EXTERN, T, K)                                                       \
  EXTERN template Status equilibrium_svd<T, K>(const GraspMat<T, K>&, const Vec6<T>&,            \
                                               Equilibrium<T, K>&);                              \
  EXTERN template Status solve_forces_svd<T, K>(const Equilibrium<T, K>&, const ForceVec<T, K>&, \
                                                ConstraintModel, int, ForceVec<T, K>&,           \
                                                ConstraintModel&, int&, T);
#define GRASPGUIDE_SVD_ROUTES(EXTERN)    \
  GRASPGUIDE_SVD_ROUTE(EXTERN, float, 3) \
  GRASPGUIDE_SVD_ROUTE(EXTERN, float, 4) \
  GRASPGUIDE_SVD_ROUTE(EXTERN, double, 3) GRASPGUIDE_SVD_ROUTE(EXTERN, double, 4)
#if GRASPGUIDE_WITH_SVD_ROUTE && !defined(GRASPGUIDE_INSTANTIATING_SVD_ROUTE)
GRASPGUIDE_SVD_ROUTES(extern)
#endif

}  // namespace graspguide
