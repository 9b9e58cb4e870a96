// The one place the SVD route is compiled, for both scalars and both contact counts.
#define GRASPGUIDE_INSTANTIATING
#include "graspguide/equilibrium.h"

namespace graspguide {
template Status equilibrium_svd<float, 3>(const GraspMat<float, 3>&, const Vec6<float>&, Equilibrium<float, 3>&);
template Status equilibrium_svd<float, 4>(const GraspMat<float, 4>&, const Vec6<float>&, Equilibrium<float, 4>&);
template Status equilibrium_svd<double, 3>(const GraspMat<double, 3>&, const Vec6<double>&, Equilibrium<double, 3>&);
template Status equilibrium_svd<double, 4>(const GraspMat<double, 4>&, const Vec6<double>&, Equilibrium<double, 4>&);
}  // namespace graspguide
