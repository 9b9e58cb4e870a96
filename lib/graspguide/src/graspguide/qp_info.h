// What an active-set solve reports besides its answer (both routes' solvers).
#pragma once

#include <cstdint>

namespace graspguide {

struct QpInfo {
  int iterations = 0;   // active-set changes (additions and removals)
  uint16_t active = 0;  // bit j: constraint j active at the solution
  // An infeasibility verdict cleared the rounding that could have produced it by
  // kFirmVerdictFactor (force_qp.h); a float verdict that did not is retried in double.
  bool firm = true;
};

}  // namespace graspguide
