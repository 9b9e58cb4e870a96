// The one place the SVD reference route is compiled, for both scalars and both contact
// counts (nothing when a build leaves the route out).
#define GRASPGUIDE_INSTANTIATING_SVD_ROUTE
#include "graspguide/svd_route.h"

namespace graspguide {
#if GRASPGUIDE_WITH_SVD_ROUTE
GRASPGUIDE_SVD_ROUTES()
#endif
}  // namespace graspguide
