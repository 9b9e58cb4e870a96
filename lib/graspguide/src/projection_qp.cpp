// The one place the active-set solver is compiled: 3 or 6 variables, 9 or 12 rows.
#define GRASPGUIDE_INSTANTIATING_PROJECTION_QP
#include "graspguide/projection_qp.h"

namespace graspguide {
GRASPGUIDE_PROJECTION_QPS()
}  // namespace graspguide
