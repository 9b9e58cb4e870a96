// Numerical stability at the extremes, each with its expected status or result, and the
// guarantees of the frame loop: motors off on any error, recovery, the fixed-posture fast
// path, and no heap allocation.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <limits>
#include <new>

#include "common/hand_scenes.h"
#include "graspguide.h"

namespace gg = graspguide;

// Counts every operator new of the test program, to prove the frame loop allocates nothing
// outside Eigen as well.
static std::atomic<long> g_allocations{0};
void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
using graspguide_test::nominal_hand;
using graspguide_test::solve_once;

template <typename T>
class Extremes : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(Extremes, Scalars);

template <typename T>
gg::Scene<T> hand_scene(int k = 4) {
  gg::Scene<T> s;
  s.k = k;
  s.contacts = nominal_hand().cast<T>();
  return s;
}

gg::Vec6<double> weight() {
  gg::Vec6<double> w;
  w << 0.4, -1.0, 0.3, 0, 0, 0;
  return w;
}

const Eigen::Vector4d kIdentity(1, 0, 0, 0);

void expect_off(const gg::Pwm& p) {
  for (int i = 0; i < gg::kMaxContacts; ++i) EXPECT_EQ(p.duty[i], 0) << i;
}

TYPED_TEST(Extremes, CoincidentContacts) {
  using T = TypeParam;
  auto s = hand_scene<T>();
  s.contacts.col(2) = s.contacts.col(1);
  const auto r = solve_once<T>(s, weight(), kIdentity);
  EXPECT_EQ(r.status, gg::Status::kCoincidentContacts);
  expect_off(r.frame.pwm);
}

TYPED_TEST(Extremes, CollinearContactsAreRankDeficient) {
  using T = TypeParam;
  auto s = hand_scene<T>(3);
  s.contacts.col(1) = s.contacts.col(0) + T(0.4) * (s.contacts.col(2) - s.contacts.col(0));
  const auto r = solve_once<T>(s, weight(), kIdentity);
  EXPECT_EQ(r.status, gg::Status::kRankDeficient);
  expect_off(r.frame.pwm);
}

TYPED_TEST(Extremes, ContactExactlyOnTheAxisUsesTheFallbackAndStillRenders) {
  using T = TypeParam;
  gg::Scene<T> s;
  s.k = 3;
  // Centroid (0, 0.03, 0): the third contact sits straight along +y from it.
  s.contacts.template leftCols<3>() << T(-0.03), T(0.03), T(0), T(0), T(0), T(0.09), T(0.01),
      T(-0.01), T(0);
  const auto r = solve_once<T>(s, weight(), kIdentity);
  ASSERT_EQ(r.status, gg::Status::kOk);
  EXPECT_EQ(r.grasp.fallback_mask, 0b100);
  EXPECT_GT(r.frame.pwm.duty[0] + r.frame.pwm.duty[1] + r.frame.pwm.duty[2], 0);
}

TYPED_TEST(Extremes, TinyAndHugeHandsGiveTheSamePwm) {
  using T = TypeParam;
  const auto base = solve_once<T>(hand_scene<T>(), weight(), kIdentity);
  ASSERT_EQ(base.status, gg::Status::kOk);
  for (double unit : {2e-3, 200.0}) {  // contacts ~0.1 mm apart; ~10 m apart
    auto s = hand_scene<T>();
    s.contacts *= T(unit);
    const auto r = solve_once<T>(s, weight(), kIdentity);
    ASSERT_EQ(r.status, gg::Status::kOk) << unit;
    EXPECT_LE(graspguide_test::max_pwm_diff(r.frame.pwm, base.frame.pwm), 1) << unit;
  }
}

TEST(ExtremesDouble, OffsetOfAMillionFromTheOriginChangesNothing) {
  const auto base = solve_once<double>(hand_scene<double>(), weight(), kIdentity);
  auto s = hand_scene<double>();
  s.contacts.colwise() += Eigen::Vector3d(1e6, -1e6, 1e6);
  const auto r = solve_once<double>(s, weight(), kIdentity);
  ASSERT_EQ(r.status, gg::Status::kOk);
  EXPECT_EQ(graspguide_test::max_pwm_diff(r.frame.pwm, base.frame.pwm), 0);
  EXPECT_LT((r.grasp.lambda - base.grasp.lambda).norm(), 1e-6 * base.grasp.lambda.norm());
}

TEST(ExtremesFloat, ContactsTheFloatCannotResolveAreRefusedNotRendered) {
  // 1e4 mm from the origin: float still resolves the hand to ~1e-3 mm.
  auto mm = hand_scene<float>();
  mm.contacts *= 1000.f;
  const auto base = solve_once<float>(mm, weight(), kIdentity);
  mm.contacts.colwise() += Eigen::Vector3f(1e4f, -1e4f, 1e4f);
  const auto near = solve_once<float>(mm, weight(), kIdentity);
  ASSERT_EQ(near.status, gg::Status::kOk);
  EXPECT_LE(graspguide_test::max_pwm_diff(near.frame.pwm, base.frame.pwm), 1);
  // 1e6 away (m or mm): the inputs themselves are rounded by a sizeable part of the hand.
  for (float unit : {1.f, 1000.f}) {
    auto far = hand_scene<float>();
    far.contacts *= unit;
    far.contacts.colwise() += Eigen::Vector3f(1e6f, -1e6f, 1e6f);
    const auto r = solve_once<float>(far, weight(), kIdentity);
    EXPECT_EQ(r.status, gg::Status::kImpreciseContacts) << unit;
    expect_off(r.frame.pwm);
  }
}

TYPED_TEST(Extremes, HugeAndTinyInputScalesDoNotOverflow) {
  using T = TypeParam;
  const T big = std::is_same<T, float>::value ? T(1e30) : T(1e200);
  auto s = hand_scene<T>();
  const auto base = solve_once<T>(s, weight(), Eigen::Vector4d(1, 1, 0, 0).normalized());
  gg::Guidance<T> g;
  gg::FrameResult<T> r;
  // A quaternion whose squared norm overflows is still a 90 degree turn.
  ASSERT_EQ(g.solve(s, weight().cast<T>(), Eigen::Matrix<T, 4, 1>(big, big, T(0), T(0)), r),
            gg::Status::kOk);
  EXPECT_NEAR(r.error_deg, base.frame.error_deg, T(1e-3));
  s.y_axis = gg::Vec3<T>(T(0), big, T(0));
  ASSERT_EQ(g.solve(s, weight().cast<T>(), kIdentity.cast<T>(), r), gg::Status::kOk);
}

TYPED_TEST(Extremes, ZeroForceAndZeroWrench) {
  using T = TypeParam;
  gg::Vec6<double> moment_only;
  moment_only << 0, 0, 0, 0.01, 0.02, 0;
  auto r = solve_once<T>(hand_scene<T>(), moment_only, kIdentity);
  EXPECT_EQ(r.status, gg::Status::kZeroForce);
  expect_off(r.frame.pwm);
  r = solve_once<T>(hand_scene<T>(), gg::Vec6<double>::Zero(), kIdentity);
  EXPECT_EQ(r.status, gg::Status::kZeroWrench);
  expect_off(r.frame.pwm);
}

TYPED_TEST(Extremes, ForceExactlyOnARelevanceBoundary) {
  using T = TypeParam;
  gg::Scene<T> s;
  s.k = 3;
  s.contacts.template leftCols<3>() << T(2), T(-1), T(-1), T(0), T(1), T(-1), T(0), T(0.5), T(-0.5);
  s.y_axis = gg::Vec3<T>::UnitZ();
  gg::Vec6<double> w;
  w << 0, 0, 0, 0, 0, 0;
  w(1) = -1;  // f . r_0 = 0 exactly: contact 0 is relevant, as the paper's "<= 0"
  const auto r = solve_once<T>(s, w, kIdentity);
  ASSERT_EQ(r.status, gg::Status::kOk);
  EXPECT_TRUE(r.grasp.relevant_mask & 1u);
}

TYPED_TEST(Extremes, PaperInfeasibleScenesFallBackAndSayWhichModel) {
  using T = TypeParam;
  std::mt19937_64 rng(5);
  int fell_back = 0;
  for (int n = 0; n < 200; ++n) {
    const auto rs = graspguide_test::random_scene(rng, 3);
    auto s = graspguide_test::make_scene<T>(rs, gg::ConstraintModel::kPaper, gg::Policy::kF,
                                            gg::Mode::kC);
    const auto r = solve_once<T>(s, rs.wrench, rs.orientation);
    ASSERT_EQ(r.status, gg::Status::kOk);
    if (r.grasp.used != gg::ConstraintModel::kPaper) {
      ++fell_back;
      // The fallback result is exactly what asking for that model gives.
      s.constraints = r.grasp.used;
      const auto direct = solve_once<T>(s, rs.wrench, rs.orientation);
      EXPECT_EQ(graspguide_test::max_pwm_diff(direct.frame.pwm, r.frame.pwm), 0);
    }
  }
  EXPECT_GT(fell_back, 20);  // about half of all directions with three contacts
}

TYPED_TEST(Extremes, NanOrInfAnywhereIsRejectedWithMotorsOff) {
  using T = TypeParam;
  for (double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity()}) {
    for (int field = 0; field < 4; ++field) {
      auto s = hand_scene<T>();
      auto w = weight();
      Eigen::Vector4d q = kIdentity;
      if (field == 0) s.contacts(1, 2) = T(bad);
      if (field == 1) w(4) = bad;
      if (field == 2) q(3) = bad;
      if (field == 3) s.y_axis(0) = T(bad);
      const auto r = solve_once<T>(s, w, q);
      EXPECT_EQ(r.status, gg::Status::kNonFiniteInput) << field;
      expect_off(r.frame.pwm);
    }
  }
}

TYPED_TEST(Extremes, NonUnitQuaternionIsTheSameRotationAndZeroIsAnError) {
  using T = TypeParam;
  const Eigen::Vector4d q = Eigen::Vector4d(0.3, -0.5, 0.7, 0.1).normalized();
  auto s = hand_scene<T>();
  s.mode = gg::Mode::kV;
  const auto unit = solve_once<T>(s, weight(), q);
  const auto scaled = solve_once<T>(s, weight(), 3.7 * q);
  ASSERT_EQ(scaled.status, gg::Status::kOk);
  EXPECT_EQ(graspguide_test::max_pwm_diff(unit.frame.pwm, scaled.frame.pwm), 0);
  EXPECT_NEAR(unit.frame.error_deg, scaled.frame.error_deg, T(1e-4));
  const auto zero = solve_once<T>(s, weight(), Eigen::Vector4d::Zero());
  EXPECT_EQ(zero.status, gg::Status::kBadQuaternion);
  expect_off(zero.frame.pwm);
}

// ---------------------------------------------------------------- the frame loop

TYPED_TEST(Extremes, FixedPostureFramesSkipTheGraspPart) {
  using T = TypeParam;
  gg::Guidance<T> g;
  auto s = hand_scene<T>();
  s.mode = gg::Mode::kV;
  ASSERT_EQ(g.set_scene(s), gg::Status::kOk);
  ASSERT_EQ(g.set_wrench(weight().cast<T>()), gg::Status::kOk);
  gg::FrameResult<T> r;
  ASSERT_EQ(g.update(kIdentity.cast<T>(), r), gg::Status::kOk);
  EXPECT_TRUE(r.recomputed);
  const Eigen::Matrix<T, 4, 1> turned = Eigen::Vector4d(0.9, 0.1, 0.3, 0.2).normalized().cast<T>();
  ASSERT_EQ(g.update(turned, r), gg::Status::kOk);
  EXPECT_FALSE(r.recomputed);  // orientation only: error and alpha, nothing else
  ASSERT_EQ(g.set_contacts(s.contacts), gg::Status::kOk);  // the same posture again
  ASSERT_EQ(g.update(turned, r), gg::Status::kOk);
  EXPECT_FALSE(r.recomputed);
  auto moved = s.contacts;
  moved(0, 1) += T(0.001);
  ASSERT_EQ(g.set_contacts(moved), gg::Status::kOk);
  ASSERT_EQ(g.update(turned, r), gg::Status::kOk);
  EXPECT_TRUE(r.recomputed);
  ASSERT_EQ(g.set_wrench((2.0 * weight()).cast<T>()), gg::Status::kOk);
  ASSERT_EQ(g.update(turned, r), gg::Status::kOk);
  EXPECT_TRUE(r.recomputed);
}

TYPED_TEST(Extremes, AnErrorTurnsMotorsOffAndValidInputRecovers) {
  using T = TypeParam;
  gg::Guidance<T> g;
  auto s = hand_scene<T>();
  ASSERT_EQ(g.set_scene(s), gg::Status::kOk);
  ASSERT_EQ(g.set_wrench(weight().cast<T>()), gg::Status::kOk);
  gg::FrameResult<T> good, bad;
  ASSERT_EQ(g.update(kIdentity.cast<T>(), good), gg::Status::kOk);
  auto broken = s.contacts;
  broken.col(3) = broken.col(0);
  ASSERT_EQ(g.set_contacts(broken), gg::Status::kOk);
  EXPECT_EQ(g.update(kIdentity.cast<T>(), bad), gg::Status::kCoincidentContacts);
  expect_off(bad.pwm);
  EXPECT_EQ(g.update(kIdentity.cast<T>(), bad), gg::Status::kCoincidentContacts);  // still off
  expect_off(bad.pwm);
  ASSERT_EQ(g.set_contacts(s.contacts), gg::Status::kOk);
  gg::FrameResult<T> again;
  ASSERT_EQ(g.update(kIdentity.cast<T>(), again), gg::Status::kOk);
  EXPECT_EQ(graspguide_test::max_pwm_diff(again.pwm, good.pwm), 0);
  // A NaN pose is refused without touching the kept grasp.
  Eigen::Matrix<T, 4, 1> nan_q = kIdentity.cast<T>();
  nan_q(0) = std::numeric_limits<T>::quiet_NaN();
  EXPECT_EQ(g.update(nan_q, bad), gg::Status::kNonFiniteInput);
  expect_off(bad.pwm);
  EXPECT_EQ(g.set_contacts(Eigen::Matrix<T, 3, 4>::Constant(std::numeric_limits<T>::infinity())),
            gg::Status::kNonFiniteInput);
  ASSERT_EQ(g.update(kIdentity.cast<T>(), again), gg::Status::kOk);
  EXPECT_EQ(graspguide_test::max_pwm_diff(again.pwm, good.pwm), 0);
}

TYPED_TEST(Extremes, SceneParametersAreValidated) {
  using T = TypeParam;
  gg::Guidance<T> g;
  auto s = hand_scene<T>();
  s.k = 5;
  EXPECT_EQ(g.set_scene(s), gg::Status::kBadContactCount);
  s = hand_scene<T>();
  s.y_axis.setZero();
  EXPECT_EQ(g.set_scene(s), gg::Status::kBadAxis);
  s = hand_scene<T>();
  s.trial.timeout_s = 0;
  EXPECT_EQ(g.set_scene(s), gg::Status::kBadConfig);
  s = hand_scene<T>();
  s.trial.threshold_deg = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(g.set_scene(s), gg::Status::kBadConfig);
  s = hand_scene<T>();
  s.solver.max_iterations = 0;
  EXPECT_EQ(g.set_scene(s), gg::Status::kBadConfig);
  gg::FrameResult<T> r;
  EXPECT_EQ(g.update(kIdentity.cast<T>(), r), gg::Status::kZeroWrench);  // no wrench yet
}

// EIGEN_RUNTIME_NO_MALLOC is set for the whole native build (platformio.ini), so Eigen
// asserts on any heap allocation while it is forbidden.
TYPED_TEST(Extremes, NoHeapAllocationAtRunTime) {
  using T = TypeParam;
  std::mt19937_64 rng(77);
  gg::Guidance<T> g;
  Eigen::internal::set_is_malloc_allowed(false);
  const long before = g_allocations.load();
  for (int n = 0; n < 200; ++n) {
    const auto rs = graspguide_test::random_scene(rng, 3 + n % 2);
    for (auto d : {gg::Decomposition::kStructured, gg::Decomposition::kSVD}) {
      auto s = graspguide_test::make_scene<T>(rs, gg::ConstraintModel(n % 3), gg::Policy(n % 2),
                                              gg::Mode((n / 2) % 2));
      s.solver.decomposition = d;
      gg::FrameResult<T> r;
      ASSERT_EQ(g.set_scene(s), gg::Status::kOk);
      ASSERT_EQ(g.set_wrench(rs.wrench.cast<T>()), gg::Status::kOk);
      ASSERT_EQ(g.update(rs.orientation.cast<T>(), r), gg::Status::kOk);
    }
  }
  const long allocations = g_allocations.load() - before;
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_EQ(allocations, 0);
}
