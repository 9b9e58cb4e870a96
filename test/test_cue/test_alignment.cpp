// The guidance error and alpha of the per-frame layer against an independent computation:
// the whole force direction rotated into the world by R(q) and the angle taken with atan2,
// in long double. Float is held to what its rounding of the inputs allows.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <type_traits>

#include "graspguide_cue/alignment.h"

namespace gg = graspguide;

namespace {

struct Expected {
  long double error_deg, alpha;
};

// R(q) f for a unit q, then the angle with (0, 0, -1) and |R f - g| / 2 * kPwmSpan.
Expected reference(const double q_in[4], const double f[3]) {
  long double q[4], n = 0;
  for (int i = 0; i < 4; ++i) n += (long double)q_in[i] * q_in[i];
  n = std::sqrt(n);
  for (int i = 0; i < 4; ++i) q[i] = q_in[i] / n;
  const long double w = q[0], x = q[1], y = q[2], z = q[3];
  const long double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                               {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                               {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  long double fw[3];
  for (int i = 0; i < 3; ++i) fw[i] = r[i][0] * f[0] + r[i][1] * f[1] + r[i][2] * f[2];
  const long double cross = std::sqrt(fw[0] * fw[0] + fw[1] * fw[1]);  // |fw x (0, 0, -1)|
  const long double angle = std::atan2(cross, -fw[2]);
  const long double chord = std::sqrt(fw[0] * fw[0] + fw[1] * fw[1] + (fw[2] + 1) * (fw[2] + 1));
  return {angle * 180 / 3.14159265358979323846264338327950288L, chord / 2 * gg::kPwmSpan};
}

void unit(double v[3]) {
  const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (int i = 0; i < 3; ++i) v[i] /= n;
}

// A quaternion that turns the hand by `deg` about an axis perpendicular to f, so that R f
// makes exactly `deg` degrees with gravity when f points down in the hand frame.
void tilt(double deg, double q[4]) {
  const double h = deg * 3.14159265358979323846 / 360;
  q[0] = std::cos(h);
  q[1] = std::sin(h);
  q[2] = q[3] = 0;
}

template <typename T>
struct Worst {
  double error_deg = 0, alpha = 0;
  void add(const double q[4], const double f[3]) {
    const T qt[4] = {T(q[0]), T(q[1]), T(q[2]), T(q[3])};
    const T ft[3] = {T(f[0]), T(f[1]), T(f[2])};
    // The reference sees exactly the inputs the scalar could hold.
    const double qr[4] = {double(qt[0]), double(qt[1]), double(qt[2]), double(qt[3])};
    double fr[3] = {double(ft[0]), double(ft[1]), double(ft[2])};
    unit(fr);
    gg::Alignment<T> a;
    ASSERT_EQ(gg::alignment_from_quaternion(qt, ft, a), gg::Status::kOk);
    const Expected e = reference(qr, fr);
    error_deg = std::fmax(error_deg, double(std::fabs(a.error_deg - e.error_deg)));
    alpha = std::fmax(alpha, double(std::fabs(a.alpha - e.alpha)));
  }
};

template <typename T>
class AlignmentTest : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(AlignmentTest, Scalars);

// Error bounds per scalar (degrees, PWM counts): a few units in the last place of a
// result near 180 and 185, plus float's rounding of unit inputs.
template <typename T>
constexpr double kErrorTolDeg = std::is_same<T, float>::value ? 1e-4 : 1e-10;
template <typename T>
constexpr double kAlphaTol = std::is_same<T, float>::value ? 1e-4 : 1e-10;

TYPED_TEST(AlignmentTest, MatchesTheRotatedForceOnRandomOrientations) {
  using T = TypeParam;
  std::mt19937 rng(12);
  std::normal_distribution<double> n(0, 1);
  Worst<T> worst;
  for (int i = 0; i < 20000; ++i) {
    double q[4] = {n(rng), n(rng), n(rng), n(rng)};
    double f[3] = {n(rng), n(rng), n(rng)};
    unit(f);
    worst.add(q, f);
  }
  EXPECT_LT(worst.error_deg, kErrorTolDeg<T>);
  EXPECT_LT(worst.alpha, kAlphaTol<T>);
}

// Where acos of a dot product would lose accuracy (0 and 180 degrees), and the trial's
// 3-degree threshold, each at and around the exact angle.
TYPED_TEST(AlignmentTest, IsAccurateNearZeroThreeAndOneHundredEightyDegrees) {
  using T = TypeParam;
  const double down[3] = {0, 0, -1};
  const double centres[] = {0, 3, 60, 120, 180};
  for (double centre : centres) {
    Worst<T> worst;
    for (int i = -200; i <= 200; ++i) {
      double q[4];
      tilt(centre + i * 1e-4, q);
      worst.add(q, down);
    }
    // Near 0 and 180 an absolute error of a few 1e-7 radians in float: 2e-5 degrees.
    const double tol = std::is_same<T, float>::value ? 3e-5 : 1e-10;
    EXPECT_LT(worst.error_deg, tol) << centre;
    EXPECT_LT(worst.alpha, kAlphaTol<T>) << centre;
  }
}

TYPED_TEST(AlignmentTest, AnyScaleOfTheQuaternionIsTheSameRotation) {
  using T = TypeParam;
  const T f[3] = {T(0.6), T(0), T(-0.8)};
  const T q[4] = {T(0.9), T(0.3), T(-0.2), T(0.1)};
  gg::Alignment<T> ref;
  ASSERT_EQ(gg::alignment_from_quaternion(q, f, ref), gg::Status::kOk);
  // 1e30 overflows float's squares (the rescaling path), 1e-5 is far from unit length.
  const T scales[] = {T(3.7), T(1e-5), T(1e30), T(-2)};
  for (T s : scales) {
    const T qs[4] = {q[0] * s, q[1] * s, q[2] * s, q[3] * s};
    gg::Alignment<T> a;
    ASSERT_EQ(gg::alignment_from_quaternion(qs, f, a), gg::Status::kOk) << s;
    EXPECT_NEAR(a.error_deg, ref.error_deg, T(1e-3)) << s;
    EXPECT_NEAR(a.alpha, ref.alpha, T(1e-3)) << s;
  }
}

TYPED_TEST(AlignmentTest, GravityFromAnImuGivesWhatTheQuaternionGives) {
  using T = TypeParam;
  const T f[3] = {T(0.6), T(0), T(-0.8)};
  const T q[4] = {T(0.9), T(0.3), T(-0.2), T(0.1)};
  T g[3];
  ASSERT_EQ(gg::gravity_in_hand(q, g), gg::Status::kOk);
  EXPECT_NEAR(g[0] * g[0] + g[1] * g[1] + g[2] * g[2], T(1), T(1e-6));
  gg::Alignment<T> from_q, from_g;
  ASSERT_EQ(gg::alignment_from_quaternion(q, f, from_q), gg::Status::kOk);
  // An accelerometer's reading in m/s^2, and one so large that its squares overflow float.
  const T scales[] = {T(9.81), T(1e30)};
  for (T s : scales) {
    const T measured[3] = {g[0] * s, g[1] * s, g[2] * s};
    ASSERT_EQ(gg::alignment_from_gravity(measured, f, from_g), gg::Status::kOk) << s;
    EXPECT_NEAR(from_g.error_deg, from_q.error_deg, T(1e-3)) << s;
    EXPECT_NEAR(from_g.alpha, from_q.alpha, T(1e-3)) << s;
  }
}

TYPED_TEST(AlignmentTest, BadInputIsReportedAndLeavesTheOutputAlone) {
  using T = TypeParam;
  const T f[3] = {T(0), T(0), T(-1)};
  const T nan = std::numeric_limits<T>::quiet_NaN();
  const T inf = std::numeric_limits<T>::infinity();
  gg::Alignment<T> a;
  a.error_deg = T(42);
  for (int i = 0; i < 4; ++i) {  // a NaN or an infinity in every position
    for (T bad : {nan, inf, -inf}) {
      T q[4] = {T(1), T(0), T(0), T(0)};
      q[i] = bad;
      EXPECT_EQ(gg::alignment_from_quaternion(q, f, a), gg::Status::kNonFiniteInput) << i;
    }
  }
  const T zero[4] = {T(0), T(0), T(0), T(0)};
  EXPECT_EQ(gg::alignment_from_quaternion(zero, f, a), gg::Status::kBadQuaternion);
  const T tiny[4] = {T(5e-7), T(0), T(0), T(0)};  // |q| below kMinQuaternionNorm
  EXPECT_EQ(gg::alignment_from_quaternion(tiny, f, a), gg::Status::kBadQuaternion);
  const T just_enough[4] = {T(2e-6), T(0), T(0), T(0)};
  EXPECT_EQ(gg::alignment_from_quaternion(just_enough, f, a), gg::Status::kOk);
  a.error_deg = T(42);

  for (int i = 0; i < 3; ++i) {
    T g[3] = {T(0), T(0), T(-1)};
    g[i] = nan;
    EXPECT_EQ(gg::alignment_from_gravity(g, f, a), gg::Status::kNonFiniteInput) << i;
    g[i] = inf;
    EXPECT_EQ(gg::alignment_from_gravity(g, f, a), gg::Status::kNonFiniteInput) << i;
  }
  const T no_gravity[3] = {T(0), T(0), T(0)};
  EXPECT_EQ(gg::alignment_from_gravity(no_gravity, f, a), gg::Status::kBadAxis);
  EXPECT_EQ(a.error_deg, T(42));  // untouched by every failure above
}

// The float polynomial behind the error angle, against libm in double over its whole range.
TEST(AsinDegRatio, FloatPolynomialIsAsAccurateAsItsDocumentationSays) {
  double worst = 0;
  for (int i = 0; i <= 100000; ++i) {
    const float x = 0.5f * float(i) / 100000.0f;
    const double exact = x > 0 ? std::asin(double(x)) / double(x) * (180 / M_PI) : 180 / M_PI;
    const double got = gg::scalar_math::asin_deg_ratio(x * x);
    worst = std::fmax(worst, std::fabs(got - exact) / exact);
  }
  EXPECT_LT(worst, 2e-7);
  EXPECT_NEAR(gg::scalar_math::asin_deg_ratio(0.0), 180 / M_PI, 1e-15);
}

}  // namespace
