// The tolerances of the per-frame work (the per-posture ones are in the core's
// graspguide/tolerances.h). docs/algorithm.md, "Tolerances".
#pragma once

namespace graspguide {

// |m_i| at or below this is a motor off, so float noise never switches one on at kPwmMin.
constexpr double kMotorOffLevel = 1e-3;
// A quaternion (or gravity vector) shorter than this has no direction.
constexpr double kMinQuaternionNorm = 1e-6;

template <typename T>
struct FrameTolerances;

// |q|^2 within this of 1 is used as it is: dividing by |q|^2 would change the gravity
// direction's length by less than that, which moves the error angle by at most this many
// radians (at 0 degrees; relatively less elsewhere): a few units in the last place, while
// the division costs about 900 cycles on an 8-bit AVR (docs/per-frame-layer.md).
template <>
struct FrameTolerances<float> {
  static constexpr float kUnitNormSlack = 4.76837158e-7f;  // 2^-21
};

template <>
struct FrameTolerances<double> {
  static constexpr double kUnitNormSlack = 8.8817841970012523e-16;  // 2^-50
};

}  // namespace graspguide
