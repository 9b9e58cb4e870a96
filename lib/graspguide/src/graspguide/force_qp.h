// Step 5: the paper's QP (eq. 2) on lambda = lambda0 + N xi, with the constraint models
// paper / normal / none and the fallback paper -> normal -> none.
#pragma once

#include "graspguide/equilibrium.h"
#include "graspguide/projection_qp.h"

namespace graspguide {

template <typename T, int K>
struct ForceSolution {
  ForceVec<T, K> lambda;  // lambda0 + N xi*, before normalisation
  ConstraintModel used = ConstraintModel::kNone;
  int iterations = 0;   // summed over the models tried
  uint16_t active = 0;  // active set of the model used (warm start)
};

// Rows of the constraint matrix for one model: component j of lambda >= 0.
template <typename T, int K>
void constraint_rows(const Equilibrium<T, K>& eq, ConstraintModel model,
                     ProjectionQp<T, 3 * K - 6, 3 * K>& qp) {
  qp.m = 0;
  if (model == ConstraintModel::kNone) return;
  for (int j = 0; j < 3 * K; ++j) {
    if (model == ConstraintModel::kNormal && j % 3 != 1) continue;
    qp.a.row(qp.m) = eq.null_basis.row(j);
    qp.b(qp.m) = -eq.lambda0(j);
    ++qp.m;
  }
}

// warm_model / warm_active: the model and active set of the previous frame; the warm
// start is used only when the same model is tried again. feasibility_rel (relative to
// |lambda0|) is a parameter so that the benchmark can measure the tolerance trade.
template <typename T, int K>
Status solve_forces(const Equilibrium<T, K>& eq, const ForceVec<T, K>& lambda_des,
                    ConstraintModel requested, int max_iterations, ConstraintModel warm_model,
                    uint16_t warm_active, ForceSolution<T, K>& out,
                    T feasibility_rel = Tolerances<T>::kFeasRelTol) {
  constexpr int kVars = 3 * K - 6;
  ProjectionQp<T, kVars, 3 * K> qp;
  qp.x_unconstrained.noalias() = eq.null_basis.transpose() * (lambda_des - eq.lambda0);
  qp.violation_tol = feasibility_rel * eq.lambda0.norm();
  qp.dependent_tol = Tolerances<T>::kDependentRelTol;
  out.iterations = 0;

  for (int model = static_cast<int>(requested); model <= static_cast<int>(ConstraintModel::kNone);
       ++model) {
    const auto m = static_cast<ConstraintModel>(model);
    constraint_rows<T, K>(eq, m, qp);
    Eigen::Matrix<T, kVars, 1> xi;
    QpInfo info;
    const uint16_t warm = (m == warm_model) ? warm_active : 0;
    const Status s = solve_projection<T, kVars, 3 * K>(qp, max_iterations, warm, xi, info);
    out.iterations += info.iterations;
    if (s == Status::kQpInfeasible) continue;
    if (s != Status::kOk) return s;
    out.lambda.noalias() = eq.lambda0 + eq.null_basis * xi;
    out.used = m;
    out.active = info.active;
    return Status::kOk;
  }
  return Status::kQpInfeasible;  // unreachable: the model "none" has no constraints
}

}  // namespace graspguide
