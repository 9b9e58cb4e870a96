// PWM from motor levels: the rounding the float64 reference uses, the off level, the clamp.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "graspguide_cue/pwm.h"

namespace gg = graspguide;

namespace {

// The reference's formula, evaluated in T exactly as written there.
template <typename T>
int as_written(T level, T gain) {
  const T a = std::fabs(level);
  if (!(a > T(gg::kMotorOffLevel))) return 0;
  const T duty = std::floor((T(gg::kPwmMin) + a * gain) + T(0.5));
  return duty < T(0) ? 0 : (duty > T(255) ? 255 : int(duty));
}

template <typename T>
class PwmTest : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(PwmTest, Scalars);

// pwm.h rounds with one addition instead of floor(); it must be the same number everywhere,
// including exactly at the .5 boundaries.
TYPED_TEST(PwmTest, RoundsExactlyAsTheReferenceFormula) {
  using T = TypeParam;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> level(-1.2, 1.2), gain(-50, 400);
  int checked = 0;
  for (int i = 0; i < 200000; ++i) {
    const T l[4] = {T(level(rng)), T(level(rng)), T(level(rng)), T(level(rng))};
    const T g = T(gain(rng));
    const gg::Pwm p = gg::pwm_from_levels(l, 4, g);
    for (int m = 0; m < 4; ++m, ++checked) ASSERT_EQ(p.duty[m], as_written(l[m], g)) << l[m] << g;
  }
  // Every half-count boundary of the range: level 1, gain = n + 0.5 - kPwmMin.
  for (int n = 0; n <= 256; ++n) {
    const T g = T(n) + T(0.5) - T(gg::kPwmMin);
    const T one[1] = {T(1)};
    EXPECT_EQ(gg::pwm_from_levels(one, 1, g).duty[0], as_written(T(1), g)) << n;
  }
  EXPECT_GT(checked, 0);
}

TYPED_TEST(PwmTest, ModesOffLevelAndClamp) {
  using T = TypeParam;
  const T off = T(gg::kMotorOffLevel);
  const T m[4] = {T(1), off, -T(0.5), T(0.0011)};
  // Mode C: the full span; the level at kMotorOffLevel is off, one just above it is on.
  const gg::Pwm c = gg::pwm_from_levels(m, 4, gg::pwm_gain(gg::Mode::kC, T(0)));
  EXPECT_EQ(c.duty[0], gg::kPwmMin + gg::kPwmSpan);
  EXPECT_EQ(c.duty[1], 0);
  EXPECT_EQ(c.duty[2], as_written(T(-0.5), T(gg::kPwmSpan)));  // the sign does not matter
  EXPECT_EQ(c.duty[3], gg::kPwmMin);
  // Mode V at alpha 0 (aligned): every motor that is on sits at kPwmMin.
  const gg::Pwm v = gg::pwm_from_levels(m, 4, gg::pwm_gain(gg::Mode::kV, T(0)));
  EXPECT_EQ(v.duty[0], gg::kPwmMin);
  EXPECT_EQ(v.duty[1], 0);
  const T big = T(1e30), nan = std::numeric_limits<T>::quiet_NaN();
  EXPECT_EQ(gg::pwm_from_levels(m, 4, big).duty[0], 255);
  EXPECT_EQ(gg::pwm_from_levels(m, 4, T(-1e6)).duty[0], 0);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(gg::pwm_from_levels(m, 4, nan).duty[i], 0);
  const T nan_level[1] = {nan};
  EXPECT_EQ(gg::pwm_from_levels(nan_level, 1, T(100)).duty[0], 0);
}

// A posture's plan: gains on both sides of the limit below which no motor is compared with
// 255, for levels of every size, give the reference's numbers.
TYPED_TEST(PwmTest, APlanGivesTheReferenceNumbersOnBothSidesOfItsGainLimit) {
  using T = TypeParam;
  const T sets[][4] = {
      {T(1), T(0.5), T(0.25), T(0)}, {T(0.3), T(0.3), T(0.002), T(0.9)}, {T(3), T(0), T(0), T(0)}};
  for (const auto& levels : sets) {
    const gg::PwmPlan<T> plan = gg::plan_pwm(levels, 4);
    ASSERT_GT(plan.gain_limit, T(0));
    for (int step = -2000; step <= 2000; ++step) {
      const T gain = plan.gain_limit * (T(1) + T(step) * T(1e-5));
      const gg::Pwm p = gg::pwm_from_plan(plan, gain);
      for (int m = 0; m < 4; ++m) ASSERT_EQ(p.duty[m], as_written(levels[m], gain)) << gain;
    }
  }
  const T none[4] = {T(0), T(0), T(0), T(0)};
  const gg::PwmPlan<T> off = gg::plan_pwm(none, 4);
  EXPECT_EQ(off.on, 0);
  for (int m = 0; m < 4; ++m) EXPECT_EQ(gg::pwm_from_plan(off, T(100)).duty[m], 0);
  const T inf_level[1] = {std::numeric_limits<T>::infinity()};
  EXPECT_EQ(gg::pwm_from_levels(inf_level, 1, T(1)).duty[0], 255);
}

TYPED_TEST(PwmTest, OnlyTheFirstKMotorsAreDriven) {
  using T = TypeParam;
  const T m[4] = {T(0.6), T(0.6), T(0.6), T(0.6)};
  const gg::Pwm p = gg::pwm_from_levels(m, 3, T(gg::kPwmSpan));
  EXPECT_GT(p.duty[2], 0);
  EXPECT_EQ(p.duty[3], 0);
  EXPECT_EQ(gg::pwm_from_levels(m, 9, T(gg::kPwmSpan)).duty[3], p.duty[0]);  // at most 4
}

}  // namespace
