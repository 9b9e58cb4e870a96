// The one place steps 1-6 are compiled, for both scalars and both contact counts.
#include "graspguide/projection_qp.h"
#include "graspguide/equilibrium.h"
#define GRASPGUIDE_INSTANTIATING
#include "graspguide/grasp_solution.h"

namespace graspguide {
#define GRASPGUIDE_GRASP_SOLUTION(T, K)                                                       \
  template Status solve_grasp<T, K>(const Contacts<T, K>&, const Vec6<T>&, const Vec3<T>&,   \
                                    ConstraintModel, Policy, const SolverSettings&,           \
                                    const WarmStart&, GraspSolution<T>&);                     \
  template Status solve_forces<T, K>(const Equilibrium<T, K>&, const ForceVec<T, K>&,         \
                                     ConstraintModel, int, ConstraintModel, uint16_t,         \
                                     ForceSolution<T, K>&);
GRASPGUIDE_GRASP_SOLUTION(float, 3)
GRASPGUIDE_GRASP_SOLUTION(float, 4)
GRASPGUIDE_GRASP_SOLUTION(double, 3)
GRASPGUIDE_GRASP_SOLUTION(double, 4)
#undef GRASPGUIDE_GRASP_SOLUTION
}  // namespace graspguide
