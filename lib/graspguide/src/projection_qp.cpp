// The one place the active-set solver is compiled: 3 or 6 variables, 9 or 12 rows.
#define GRASPGUIDE_INSTANTIATING
#include "graspguide/projection_qp.h"

namespace graspguide {
template Status solve_projection<float, 3, 9>(const ProjectionQp<float, 3, 9>&, int, uint16_t,
                                              Eigen::Matrix<float, 3, 1>&, QpInfo&);
template Status solve_projection<float, 6, 12>(const ProjectionQp<float, 6, 12>&, int, uint16_t,
                                               Eigen::Matrix<float, 6, 1>&, QpInfo&);
template Status solve_projection<double, 3, 9>(const ProjectionQp<double, 3, 9>&, int, uint16_t,
                                               Eigen::Matrix<double, 3, 1>&, QpInfo&);
template Status solve_projection<double, 6, 12>(const ProjectionQp<double, 6, 12>&, int, uint16_t,
                                                Eigen::Matrix<double, 6, 1>&, QpInfo&);
}  // namespace graspguide
