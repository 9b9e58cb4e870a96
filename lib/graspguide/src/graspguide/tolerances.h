// Named tolerances (see docs/algorithm.md, "Tolerances"). Geometry decisions use the
// same value for float and double so both make the same call; QP tolerances follow the
// precision because a float QR of a hand grasp carries relative errors near 1e-6.
#pragma once

// kMotorOffLevel and kMinQuaternionNorm: the per-frame layer's.
#include "graspguide_cue/tolerances.h"

namespace graspguide {

template <typename T>
struct Tolerances;

template <>
struct Tolerances<float> {
  static constexpr float kFeasRelTol = 1e-4f;
  // The share of |lambda| a QP iterate's rounding may take (force_qp.h): 4 ulps. A
  // smaller violation is not worth a step; a larger one is, whatever kFeasRelTol allows,
  // which only judges infeasibility. A wider share (1e-5, 170 ulps) keeps hands float64
  // proves infeasible by twice kFeasRelTol once their forces reach 100 |lambda0|.
  static constexpr float kRoundingRelTol = 5e-7f;
  static constexpr float kDependentRelTol = 1e-4f;
  // The structured QP's rows are projector columns computed to a few ulps (force_qp.h),
  // so dependence is judged 100 times finer than on the SVD route's null basis: 8 ulps,
  // twice what Gram-Schmidt leaves of a dependent row (kBasisNoiseUlps). A k=4 hand can
  // need a row 7e-6 long to hold the paper model, another one 1.8e-6: a threshold of
  // 1e-5 or 2e-6 refuses them.
  static constexpr float kStructuredDependentTol = 1e-6f;
  // How far from equilibrium, relative to |lambda0|, an optimum float vouches for may
  // be. In 20,000 random hands float's answers at forces under 100 |lambda0| miss it by
  // up to 4e-3 (rows within the tolerance are zeroed at the end); the wrong answers larger
  // sets found miss it by 2 to 3e5. Beyond it, double decides.
  static constexpr float kCertainResidualRel = 1e-2f;
};

template <>
struct Tolerances<double> {
  static constexpr double kFeasRelTol = 1e-9;
  static constexpr double kRoundingRelTol = 1e-9;
  static constexpr double kDependentRelTol = 1e-9;
  static constexpr double kStructuredDependentTol = 1e-9;
  static constexpr double kCertainResidualRel = 1e-2;
};

inline constexpr double kCoincidentRelTol = 1e-4;
// Rounding of the inputs may move a contact by at most this fraction of the hand size.
inline constexpr double kInputPrecisionRelTol = 1e-3;
inline constexpr double kAxisParallelTol = 1e-3;
inline constexpr double kRankRelTol = 1e-4;
inline constexpr double kZeroForceRelTol = 1e-6;
inline constexpr double kRelevanceCosTol = 1e-5;
inline constexpr double kTinyRel = 1e-12;
// A QP's infeasibility verdict is firm when its violation exceeds the tolerance by this
// many times the rounding that could have produced it, conditioning included
// (force_qp.h). A float verdict that is not firm is retried in double.
inline constexpr double kFirmVerdictFactor = 16.0;
// ... and when the row it concerns is left shorter than this share of the dependence
// threshold, as 99.6 % of dependent rows are: a real row 0.11 of it long can hold a hand
// with 5e6 |lambda0| in float64.
inline constexpr double kFirmDependentShare = 0.1;

inline constexpr int kDefaultMaxIterations = 64;

}  // namespace graspguide
