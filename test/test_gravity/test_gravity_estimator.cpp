// The gravity estimator of the per-frame layer on simulated IMU samples of known motion:
// the truth is propagated here in long double with the exact rotation (Rodrigues), so the
// filter's first-order step and its gains are what is tested.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "graspguide_cue/alignment.h"
#include "graspguide_cue/gravity_estimator.h"

namespace gg = graspguide;

namespace {

constexpr double kG = gg::kStandardGravity_mps2;
constexpr double kRate_hz = 100.0;
constexpr double kDt_s = 1.0 / kRate_hz;
// MPU-6050-class white noise per sample at 100 Hz (tools/graspguide/imu/synthetic.py).
constexpr double kGyroNoise_radps = 0.005 * 3.14159265358979 / 180 * 7.0710678;
constexpr double kAccelNoise_mps2 = 400e-6 * kG * 7.0710678;
// What "converged" means here [deg]: the RMS goal.
constexpr double kConvergedDeg = 1.0;

double angle_deg(const double a[3], const double b[3]) {
  const double c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                       a[0] * b[1] - a[1] * b[0]};
  const double cross = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
  return std::atan2(cross, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) * 180 / 3.14159265358979;
}

// True gravity (unit, hand frame, down) of a hand turning at a constant body rate w: the
// world's fixed vector seen from the hand turns by -w; exact rotation by angle |w| dt.
void turn(double g[3], const double w[3], double dt) {
  const long double n =
      std::sqrt((long double)w[0] * w[0] + (long double)w[1] * w[1] + (long double)w[2] * w[2]);
  if (n == 0) return;
  const long double th = -n * dt, u[3] = {w[0] / n, w[1] / n, w[2] / n};
  const long double c = std::cos(th), s = std::sin(th);
  const long double d = u[0] * g[0] + u[1] * g[1] + u[2] * g[2];
  const long double x[3] = {u[1] * g[2] - u[2] * g[1], u[2] * g[0] - u[0] * g[2],
                            u[0] * g[1] - u[1] * g[0]};
  for (int i = 0; i < 3; ++i) g[i] = double(g[i] * c + x[i] * s + u[i] * d * (1 - c));
}

struct Sim {
  std::mt19937 rng{12345};
  std::normal_distribution<double> n{0.0, 1.0};
  double g[3] = {0.3, -0.2, -0.93};
  Sim() {
    const double m = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
    for (double& v : g) v /= m;
  }
  // One step of a hand turning at w_true with gyro bias b: feeds the estimator.
  template <typename T>
  gg::Status step(gg::GravityEstimator<T>& est, const double w_true[3], const double b[3]) {
    turn(g, w_true, kDt_s);
    T a[3], w[3];
    for (int i = 0; i < 3; ++i) {
      a[i] = T(-g[i] * kG + n(rng) * kAccelNoise_mps2);
      w[i] = T(w_true[i] + b[i] + n(rng) * kGyroNoise_radps);
    }
    return est.update(a, w, T(kDt_s));
  }
  template <typename T>
  double error_deg(const gg::GravityEstimator<T>& est) const {
    const double e[3] = {double(est.gravity()[0]), double(est.gravity()[1]),
                         double(est.gravity()[2])};
    return angle_deg(e, g);
  }
};

template <typename T>
class Gravity : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(Gravity, Scalars);

TYPED_TEST(Gravity, AStaticHandConvergesToGravityDespiteBias) {
  using T = TypeParam;
  gg::GravityEstimator<T> est;
  Sim sim;
  const double still[3] = {0, 0, 0}, bias[3] = {0.01, -0.014, 0.007};  // ~0.6-0.8 deg/s
  double worst_late = 0;
  for (int i = 0; i < int(60 * kRate_hz); ++i) {
    ASSERT_EQ(sim.step(est, still, bias), gg::Status::kOk);
    if (i > int(30 * kRate_hz)) worst_late = std::fmax(worst_late, sim.error_deg(est));
  }
  EXPECT_LT(worst_late, kConvergedDeg * 0.25);
  // The bias across gravity is observable at rest, along it (yaw) is not.
  double across[3], b_est[3];
  for (int i = 0; i < 3; ++i) b_est[i] = double(est.bias_radps()[i]);
  const double along = b_est[0] * sim.g[0] + b_est[1] * sim.g[1] + b_est[2] * sim.g[2];
  const double true_along = bias[0] * sim.g[0] + bias[1] * sim.g[1] + bias[2] * sim.g[2];
  for (int i = 0; i < 3; ++i)
    across[i] = (b_est[i] - along * sim.g[i]) - (bias[i] - true_along * sim.g[i]);
  EXPECT_LT(std::sqrt(across[0] * across[0] + across[1] * across[1] + across[2] * across[2]),
            0.1 * std::sqrt(bias[0] * bias[0] + bias[1] * bias[1] + bias[2] * bias[2]));
}

// 120 s of a constant turn w with a gyro bias; the worst error over the last 30 s.
template <typename T>
double worst_late_error(gg::GravityEstimator<T>& est, Sim& sim, const double* w,
                        const double* bias) {
  double worst_late = 0;
  for (int i = 0; i < int(120 * kRate_hz); ++i) {
    EXPECT_EQ(sim.step(est, w, bias), gg::Status::kOk);
    if (i > int(90 * kRate_hz)) worst_late = std::fmax(worst_late, sim.error_deg(est));
  }
  return worst_late;
}

TYPED_TEST(Gravity, AConstantRotationWithBiasConvergesAndTheBiasIsFound) {
  using T = TypeParam;
  gg::GravityEstimator<T> est;
  Sim sim;
  // 45 deg/s about an axis tilted from gravity, so every bias component is seen across it.
  const double w[3] = {0.6, 0.3, 0.4}, bias[3] = {0.012, -0.016, 0.008};
  const double worst_late = worst_late_error<T>(est, sim, w, bias);
  EXPECT_LT(worst_late, kConvergedDeg);
  double miss2 = 0, bias2 = 0;
  for (int i = 0; i < 3; ++i) {
    miss2 += (double(est.bias_radps()[i]) - bias[i]) * (double(est.bias_radps()[i]) - bias[i]);
    bias2 += bias[i] * bias[i];
  }
  EXPECT_LT(std::sqrt(miss2), 0.1 * std::sqrt(bias2));
}

TYPED_TEST(Gravity, WithoutBiasEstimationTheSameRotationMisses) {
  using T = TypeParam;
  gg::GravityEstimator<T> est;
  gg::GravityGains<T> gains;
  gains.ki_per_s2 = T(0);
  ASSERT_EQ(est.configure(gains), gg::Status::kOk);
  Sim sim;
  const double w[3] = {0.6, 0.3, 0.4}, bias[3] = {0.012, -0.016, 0.008};
  const double worst_late = worst_late_error<T>(est, sim, w, bias);
  EXPECT_GT(worst_late, kConvergedDeg);  // so the test above can fail
}

TYPED_TEST(Gravity, BadInputIsRefusedAndChangesNothing) {
  using T = TypeParam;
  const T nan = std::numeric_limits<T>::quiet_NaN(), inf = std::numeric_limits<T>::infinity();
  gg::GravityEstimator<T> est;
  const T zero[3] = {0, 0, 0}, up[3] = {T(0.1), T(0.2), T(kG)}, w[3] = {T(0.1), 0, 0};
  // Nothing to start from: a zero accelerometer before the first estimate.
  EXPECT_EQ(est.update(zero, w, T(kDt_s)), gg::Status::kBadAxis);
  EXPECT_FALSE(est.initialised());
  ASSERT_EQ(est.update(up, w, T(kDt_s)), gg::Status::kOk);
  for (int k = 0; k < 50; ++k) ASSERT_EQ(est.update(up, w, T(kDt_s)), gg::Status::kOk);
  const T g0[3] = {est.gravity()[0], est.gravity()[1], est.gravity()[2]};
  const T b0[3] = {est.bias_radps()[0], est.bias_radps()[1], est.bias_radps()[2]};
  auto unchanged = [&] {
    for (int i = 0; i < 3; ++i) {
      EXPECT_EQ(est.gravity()[i], g0[i]);
      EXPECT_EQ(est.bias_radps()[i], b0[i]);
    }
  };
  for (int i = 0; i < 3; ++i) {
    for (T bad : {nan, inf, -inf}) {
      T a[3] = {up[0], up[1], up[2]}, g[3] = {w[0], w[1], w[2]};
      a[i] = bad;
      EXPECT_EQ(est.update(a, w, T(kDt_s)), gg::Status::kNonFiniteInput);
      unchanged();
      a[i] = up[i];
      g[i] = bad;
      EXPECT_EQ(est.update(a, g, T(kDt_s)), gg::Status::kNonFiniteInput);
      unchanged();
    }
  }
  EXPECT_EQ(est.update(up, w, nan), gg::Status::kNonFiniteInput);
  for (T dt : {T(0), T(-kDt_s), T(gg::kMaxSampleInterval_s * 1.01)}) {
    EXPECT_EQ(est.update(up, w, dt), gg::Status::kBadConfig) << dt;
    unchanged();
  }
  // Once running, a zero or huge accelerometer is only distrusted: the gyro carries on.
  EXPECT_EQ(est.update(zero, zero, T(kDt_s)), gg::Status::kOk);
  EXPECT_FALSE(est.accel_trusted());
  const T huge[3] = {T(3e38), T(3e38), 0};
  EXPECT_EQ(est.update(huge, zero, T(kDt_s)), gg::Status::kOk);
  EXPECT_FALSE(est.accel_trusted());
  // Gains: each field non-finite or negative, and a zero gate.
  gg::GravityGains<T> ok;
  T gg::GravityGains<T>::* fields[3] = {&gg::GravityGains<T>::kp_per_s,
                                        &gg::GravityGains<T>::ki_per_s2,
                                        &gg::GravityGains<T>::accel_gate_mps2};
  for (auto f : fields) {
    for (T bad : {nan, inf, T(-1)}) {
      gg::GravityGains<T> g = ok;
      g.*f = bad;
      EXPECT_EQ(est.configure(g), gg::Status::kBadConfig);
      EXPECT_EQ(est.gains().*f, ok.*f);
    }
  }
  gg::GravityGains<T> no_gate = ok;
  no_gate.accel_gate_mps2 = 0;
  EXPECT_EQ(est.configure(no_gate), gg::Status::kBadConfig);
}

TYPED_TEST(Gravity, TheFusedPathChecksAndNormalises) {
  using T = TypeParam;
  const T nan = std::numeric_limits<T>::quiet_NaN();
  gg::GravityEstimator<T> est;
  // A fused chip's report reads like the accelerometer at rest: up is positive.
  const T reported[3] = {T(1.2), T(-3.4), T(8.9)};
  ASSERT_EQ(est.set_fused(reported), gg::Status::kOk);
  const double n = std::sqrt(1.2 * 1.2 + 3.4 * 3.4 + 8.9 * 8.9);
  const double want[3] = {-1.2 / n, 3.4 / n, -8.9 / n};
  const double got[3] = {double(est.gravity()[0]), double(est.gravity()[1]),
                         double(est.gravity()[2])};
  EXPECT_LT(angle_deg(got, want), 1e-4);
  EXPECT_NEAR(got[0] * got[0] + got[1] * got[1] + got[2] * got[2], 1.0,
              8 * std::numeric_limits<T>::epsilon());
  // Any scale: huge components do not overflow.
  const T big[3] = {T(1e30), 0, 0};
  ASSERT_EQ(est.set_fused(big), gg::Status::kOk);
  EXPECT_EQ(est.gravity()[0], T(-1));
  const T g0[3] = {est.gravity()[0], est.gravity()[1], est.gravity()[2]};
  const T zero[3] = {0, 0, 0}, bad[3] = {0, nan, T(1)};
  EXPECT_EQ(est.set_fused(zero), gg::Status::kBadAxis);
  EXPECT_EQ(est.set_fused(bad), gg::Status::kNonFiniteInput);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(est.gravity()[i], g0[i]);
  // It feeds alignment_from_gravity directly: gravity along the force is 0 degrees.
  const T f_hat[3] = {T(-1), 0, 0};
  gg::Alignment<T> a;
  ASSERT_EQ(gg::alignment_from_gravity(est.gravity(), f_hat, a), gg::Status::kOk);
  EXPECT_LT(double(a.error_deg), 1e-3);
}

}  // namespace
