// Gravity in the hand frame from a 6-axis IMU on the back of the hand, for the host-less
// mode: the only input the guidance error needs (alignment_from_gravity): no magnetometer,
// no yaw.
//
// The method is a Mahony-type complementary filter on the gravity direction alone, with
// gyro-bias estimation and an accelerometer-trust gate:
//   * the gyroscope carries the estimate from sample to sample (g' = g x omega: a vector
//     fixed in the world, seen from a rotating hand), because it is exact over short times
//     and blind to the hand's linear acceleration;
//   * the accelerometer pulls it back towards -a / |a| with gain kp, slowly, because the
//     hand's own acceleration tilts that direction by a few degrees while it moves and
//     averages out; a sample whose magnitude is far from 1 g is not used at all (the gate);
//   * the same error, integrated with gain ki, is the gyro bias estimate: only the bias
//     components across gravity change g, and the hand's turning makes all of them so.
// Tracking the 3-vector instead of a quaternion drops the yaw it cannot observe and costs
// less. tools/graspguide/imu/compare.py measures it against VQF and x-io Fusion on the virtual
// participant's hand streams; that comparison chose the gains.
//
// A chip with on-board fusion (BNO055/BNO08x class) reports gravity itself: set_fused()
// only checks and normalises it.
//
// Conventions: the accelerometer reads specific force (at rest +9.81 m/s^2 on the axis that
// points up), the gyroscope rad/s about the hand's axes; gravity() points down, as
// gravity_in_hand() does for a tracker's quaternion. C++14, no heap, no standard library.
#pragma once

#include "graspguide_cue/scalar_math.h"
#include "graspguide_cue/status.h"
#include "graspguide_cue/tolerances.h"

// Overridable from build_flags: the filter gains (1/s and 1/s^2) and the accelerometer gate
// (m/s^2 away from 1 g). See GravityGains below for why these values.
#ifndef GRASPGUIDE_GRAVITY_KP_PER_S
#define GRASPGUIDE_GRAVITY_KP_PER_S 0.4
#endif
#ifndef GRASPGUIDE_GRAVITY_KI_PER_S2
#define GRASPGUIDE_GRAVITY_KI_PER_S2 0.1
#endif
#ifndef GRASPGUIDE_GRAVITY_ACCEL_GATE_MPS2
#define GRASPGUIDE_GRAVITY_ACCEL_GATE_MPS2 2.0
#endif

namespace graspguide {

// Standard gravity; local gravity differs by < 0.03 m/s^2, far inside the gate.
constexpr double kStandardGravity_mps2 = 9.80665;
// A sample interval outside (0, kMaxSampleInterval_s] is refused (kBadConfig): a longer gap
// means lost samples (an IMU HAL calls it stale and turns the motors off), and one
// first-order step of 90 deg/s over 0.1 s already errs by 0.01 deg.
constexpr double kMaxSampleInterval_s = 0.1;
// The bias estimate is clamped to this per axis: the zero-rate offset of common MEMS gyros
// (MPU-6050: +-20 deg/s, LSM6DS3: +-10 deg/s) stays inside; a larger one means the filter
// is chasing something that is not bias, and the clamp stops the integrator winding up.
constexpr double kMaxGyroBias_radps = 0.35;
// An accelerometer shorter than this (m/s^2) has no direction (free fall, a dead sensor).
constexpr double kMinAccel_mps2 = 1e-3;

template <typename T>
struct GravityGains {
  // Pull towards the accelerometer [1/s]: a 2.5 s time constant. The hand's own
  // acceleration (0.5-1 m/s^2 while it moves, 3-6 degrees of tilt for a few hundred ms)
  // then moves the estimate by well under a degree; on the comparison's streams 0.3 and
  // 0.5 were worse (slower bias and noise averaging against more tilt let through).
  T kp_per_s = T(GRASPGUIDE_GRAVITY_KP_PER_S);
  // Bias integrator [1/s^2]: with kp a loop of natural frequency 0.32 rad/s and damping
  // 0.63, so the bias settles in about 20 s (during the rest before a trial, too); 0.02
  // settled too slowly to beat 1 degree RMS, 0.2 gained nothing. 0 turns it off.
  T ki_per_s2 = T(GRASPGUIDE_GRAVITY_KI_PER_S2);
  // Samples whose |a| differs from 1 g by more than this [m/s^2] are not trusted: 2 m/s^2
  // passes the moving hand's ordinary samples (a tighter 0.5-1 m/s^2 gate starved the
  // correction and measured worse) and drops knocks and jerks.
  T accel_gate_mps2 = T(GRASPGUIDE_GRAVITY_ACCEL_GATE_MPS2);
};

// kBadConfig unless every gain is finite and non-negative (the gate positive).
template <typename T>
inline Status validate_gravity_gains(const GravityGains<T>& g) {
  using scalar_math::is_finite;
  if (!is_finite(g.kp_per_s) || !is_finite(g.ki_per_s2) || !is_finite(g.accel_gate_mps2))
    return Status::kBadConfig;
  if (g.kp_per_s < T(0) || g.ki_per_s2 < T(0) || !(g.accel_gate_mps2 > T(0)))
    return Status::kBadConfig;
  return Status::kOk;
}

template <typename T>
class GravityEstimator {
 public:
  GravityEstimator() { reset(); }

  // Forget the estimate and the bias; the next trusted accelerometer sample starts over.
  void reset() {
    for (int i = 0; i < 3; ++i) g_[i] = bias_[i] = T(0);
    g_[2] = T(-1);
    initialised_ = false;
    accel_trusted_ = false;
  }

  Status configure(const GravityGains<T>& gains) {
    const Status s = validate_gravity_gains(gains);
    if (s == Status::kOk) gains_ = gains;
    return s;
  }
  const GravityGains<T>& gains() const { return gains_; }

  // One IMU sample: accel [m/s^2], gyro [rad/s], dt_s since the previous sample. Refused
  // without a change: kNonFiniteInput for NaN or infinity anywhere, kBadConfig for dt_s
  // outside (0, kMaxSampleInterval_s], kBadAxis for a zero accelerometer before the first
  // estimate (after it, such a sample is simply not trusted).
  Status update(const T accel_mps2[3], const T gyro_radps[3], T dt_s) {
    using scalar_math::is_finite;
    for (int i = 0; i < 3; ++i)
      if (!is_finite(accel_mps2[i]) || !is_finite(gyro_radps[i])) return Status::kNonFiniteInput;
    if (!is_finite(dt_s)) return Status::kNonFiniteInput;
    if (!(dt_s > T(0)) || dt_s > T(kMaxSampleInterval_s)) return Status::kBadConfig;

    const T a2 = accel_mps2[0] * accel_mps2[0] + accel_mps2[1] * accel_mps2[1] +
                 accel_mps2[2] * accel_mps2[2];
    // Finite components can still square to infinity: such a sample is no gravity either.
    const bool has_direction =
        a2 >= T(kMinAccel_mps2 * kMinAccel_mps2) && a2 <= scalar_math::Limits<T>::kMax;
    if (!initialised_) {
      if (!has_direction) return Status::kBadAxis;
      const T inv = T(-1) / scalar_math::sqrt_of(a2);
      for (int i = 0; i < 3; ++i) g_[i] = accel_mps2[i] * inv;
      initialised_ = true;
      accel_trusted_ = true;
      return Status::kOk;
    }

    T w[3] = {gyro_radps[0] - bias_[0], gyro_radps[1] - bias_[1], gyro_radps[2] - bias_[2]};
    const T norm_a = has_direction ? scalar_math::sqrt_of(a2) : T(0);
    accel_trusted_ = has_direction && scalar_math::abs_of(norm_a - T(kStandardGravity_mps2)) <=
                                          gains_.accel_gate_mps2;
    if (accel_trusted_) {
      // e = m x g with m = -a / |a| the measured direction: turning g about e moves it
      // towards m (g x (m x g) is m's part across g).
      const T inv = T(-1) / norm_a;
      const T m[3] = {accel_mps2[0] * inv, accel_mps2[1] * inv, accel_mps2[2] * inv};
      const T e[3] = {m[1] * g_[2] - m[2] * g_[1], m[2] * g_[0] - m[0] * g_[2],
                      m[0] * g_[1] - m[1] * g_[0]};
      const T ki_dt = gains_.ki_per_s2 * dt_s;
      const T kMaxBias = T(kMaxGyroBias_radps);
      for (int i = 0; i < 3; ++i) {
        T b = bias_[i] - ki_dt * e[i];
        if (b > kMaxBias) b = kMaxBias;
        if (b < -kMaxBias) b = -kMaxBias;
        bias_[i] = b;
        w[i] += gains_.kp_per_s * e[i];
      }
    }
    // g' = g x w: one first-order step, then back to unit length.
    T n[3] = {g_[0] + (g_[1] * w[2] - g_[2] * w[1]) * dt_s,
              g_[1] + (g_[2] * w[0] - g_[0] * w[2]) * dt_s,
              g_[2] + (g_[0] * w[1] - g_[1] * w[0]) * dt_s};
    const T inv = T(1) / scalar_math::sqrt_of(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int i = 0; i < 3; ++i) g_[i] = n[i] * inv;
    return Status::kOk;
  }

  // A fused chip's gravity report (BNO055 "gravity vector", BNO08x "gravity"), in the
  // accelerometer's sign convention and any unit: checked and normalised, nothing else.
  // kNonFiniteInput, or kBadAxis when shorter than kMinQuaternionNorm; no change then.
  Status set_fused(const T reported[3]) {
    T v[3] = {reported[0], reported[1], reported[2]};
    T m = T(0);
    for (int i = 0; i < 3; ++i) {
      if (!scalar_math::is_finite(v[i])) return Status::kNonFiniteInput;
      const T a = scalar_math::abs_of(v[i]);
      if (a > m) m = a;
    }
    if (!(m >= T(kMinQuaternionNorm))) return Status::kBadAxis;
    // Scaled by the largest component first, so no square overflows or underflows.
    for (int i = 0; i < 3; ++i) v[i] /= m;
    const T inv = T(-1) / scalar_math::sqrt_of(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int i = 0; i < 3; ++i) g_[i] = v[i] * inv;
    initialised_ = true;
    accel_trusted_ = true;
    return Status::kOk;
  }

  // Unit gravity in the hand frame, pointing down: alignment_from_gravity's input.
  const T* gravity() const { return g_; }
  // The gyro bias estimate [rad/s]; only its part across gravity is ever observed.
  const T* bias_radps() const { return bias_; }
  bool initialised() const { return initialised_; }
  // Whether the last sample's accelerometer passed the gate.
  bool accel_trusted() const { return accel_trusted_; }

 private:
  GravityGains<T> gains_;
  T g_[3];
  T bias_[3];
  bool initialised_;
  bool accel_trusted_;
};

}  // namespace graspguide
