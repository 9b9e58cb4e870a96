// The one place the QR route is compiled, for both scalars and both contact counts.
#define GRASPGUIDE_INSTANTIATING_EQUILIBRIUM
#include "graspguide/equilibrium.h"

namespace graspguide {
GRASPGUIDE_EQUILIBRIA(, GRASPGUIDE_EQUILIBRIUM_QR)
}  // namespace graspguide
