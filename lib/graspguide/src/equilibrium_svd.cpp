// The one place the SVD route is compiled, for both scalars and both contact counts
// (nothing when a build leaves the route out).
#define GRASPGUIDE_INSTANTIATING_EQUILIBRIUM
#include "graspguide/equilibrium.h"

namespace graspguide {
#if GRASPGUIDE_WITH_SVD_ROUTE
GRASPGUIDE_EQUILIBRIA(, GRASPGUIDE_EQUILIBRIUM_SVD)
#endif
}  // namespace graspguide
