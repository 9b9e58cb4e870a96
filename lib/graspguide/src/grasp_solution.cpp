// The one place steps 1-6 are compiled, for both scalars and both contact counts.
#define GRASPGUIDE_INSTANTIATING_GRASP_SOLUTION
#include "graspguide/grasp_solution.h"

namespace graspguide {
GRASPGUIDE_GRASP_SOLUTIONS()
}  // namespace graspguide
