// The one place the active-set solver of the SVD reference route is compiled: 3 or 6
// variables, 9 or 12 rows (nothing when a build leaves the route out).
#define GRASPGUIDE_INSTANTIATING_PROJECTION_QP
#include "graspguide/svd_route.h"

namespace graspguide {
#if GRASPGUIDE_WITH_SVD_ROUTE
GRASPGUIDE_PROJECTION_QPS()
#endif
}  // namespace graspguide
