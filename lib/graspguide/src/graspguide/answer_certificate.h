// Whether float can vouch for the structured route's answer, or solve_grasp must ask
// double. Float decides most hands as double does; where it cannot, its own figures say
// so, and one retry in double per posture costs less than a wrong cue:
//   - an infeasibility verdict within its rounding (ForceSolution::firm, force_qp.h);
//   - an optimum that misses equilibrium by more than kCertainResidualRel |lambda0|: the
//     rounding of forces 1e4 times |lambda0| or more, or of a step along a row that
//     rounding made look independent.
#pragma once

#include "graspguide/force_qp.h"
#include "graspguide/tolerances.h"

namespace graspguide {

template <typename T, int K>
bool answer_certain(const GraspStructure<T, K>& st, const Vec6<T>& w_hat,
                    const ForceVec<T, K>& lambda0, const ForceSolution<T, K>& forces) {
  if (!forces.firm) return false;
  // G_hat's rows are orthonormal, so this is the force-space distance to equilibrium.
  Vec6<T> residual = w_hat;
  residual.noalias() += st.g_hat * forces.lambda;
  return residual.norm() <= Tolerances<T>::kCertainResidualRel * lambda0.norm();
}

}  // namespace graspguide
