// Each step of Algorithm 1 on its own: frames, grasp matrix, equilibrium (QR and SVD),
// relevance, desired forces, motor levels, PWM and the orientation error.
#include <gtest/gtest.h>

#include "common/hand_scenes.h"
#include "graspguide.h"

namespace gg = graspguide;
using graspguide_test::nominal_hand;

template <typename T>
class Steps : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(Steps, Scalars);

template <typename T>
T tol() {
  return std::is_same<T, float>::value ? T(2e-5) : T(1e-12);
}

template <typename T, int K>
gg::Contacts<T, K> hand() {
  return nominal_hand().leftCols<K>().template cast<T>();
}

// ---------------------------------------------------------------- contact frames

TYPED_TEST(Steps, FramesAreRightHandedRotationsWithRadialY) {
  using T = TypeParam;
  gg::ContactFrames<T, 4> f;
  const auto c = hand<T, 4>();
  ASSERT_EQ((gg::contact_frames<T, 4>(c, gg::Vec3<T>::UnitY(), f)), gg::Status::kOk);
  EXPECT_TRUE(f.origin.isApprox(c.rowwise().mean(), tol<T>()));
  EXPECT_EQ(f.fallback_mask, 0);
  for (int i = 0; i < 4; ++i) {
    const gg::Mat3<T>& r = f.rotation[i];
    EXPECT_TRUE((r.transpose() * r).isIdentity(tol<T>())) << i;
    EXPECT_NEAR(r.determinant(), T(1), tol<T>()) << i;  // the paper's y x x would give -1
    const gg::Vec3<T> radial = (c.col(i) - f.origin).normalized();
    EXPECT_TRUE(r.col(1).isApprox(radial, tol<T>())) << i;
    EXPECT_NEAR(r.col(0).dot(gg::Vec3<T>::UnitY()), T(0), tol<T>()) << i;  // x_i ⟂ y_O
    EXPECT_TRUE(r.col(2).isApprox(r.col(0).cross(r.col(1)), tol<T>())) << i;
  }
  EXPECT_NEAR(f.offset_scaled.colwise().norm().maxCoeff(), T(1), tol<T>());
}

TYPED_TEST(Steps, AxisLengthDoesNotMatter) {
  using T = TypeParam;
  gg::ContactFrames<T, 3> a, b;
  const gg::Vec3<T> y(T(0.2), T(1), T(-0.1));
  ASSERT_EQ((gg::contact_frames<T, 3>(hand<T, 3>(), y, a)), gg::Status::kOk);
  ASSERT_EQ((gg::contact_frames<T, 3>(hand<T, 3>(), T(7.5) * y, b)), gg::Status::kOk);
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(a.rotation[i].isApprox(b.rotation[i], tol<T>()));
}

TYPED_TEST(Steps, ContactOnTheAxisUsesTheFallbackAndSaysSo) {
  using T = TypeParam;
  gg::Contacts<T, 3> c;
  // Contact 0 lies straight "above" the centroid along y: y_0 is parallel to y_O.
  c << T(0), T(-1), T(1), T(2), T(-1), T(-1), T(0), T(0), T(0);
  gg::ContactFrames<T, 3> f;
  ASSERT_EQ((gg::contact_frames<T, 3>(c, gg::Vec3<T>::UnitY(), f)), gg::Status::kOk);
  EXPECT_EQ(f.fallback_mask, 1);
  const gg::Mat3<T>& r = f.rotation[0];
  EXPECT_TRUE(r.col(1).isApprox(gg::Vec3<T>::UnitY(), tol<T>()));
  EXPECT_NEAR(r.determinant(), T(1), tol<T>());
  // Documented fallback for y_O = +y: a = -z, x_0 = unit(y_0 x a) = -x.
  EXPECT_TRUE(r.col(0).isApprox(-gg::Vec3<T>::UnitX(), tol<T>()));
}

TYPED_TEST(Steps, FrameFailures) {
  using T = TypeParam;
  gg::ContactFrames<T, 3> f;
  auto c = hand<T, 3>();
  const gg::Vec3<T> y = gg::Vec3<T>::UnitY();
  EXPECT_EQ((gg::contact_frames<T, 3>(c, gg::Vec3<T>::Zero(), f)), gg::Status::kBadAxis);
  gg::Vec3<T> bad_axis = y;
  bad_axis(2) = std::numeric_limits<T>::quiet_NaN();
  EXPECT_EQ((gg::contact_frames<T, 3>(c, bad_axis, f)), gg::Status::kNonFiniteInput);
  auto nan = c;
  nan(1, 2) = std::numeric_limits<T>::infinity();
  EXPECT_EQ((gg::contact_frames<T, 3>(nan, y, f)), gg::Status::kNonFiniteInput);
  auto same = c;
  same.col(1) = same.col(0);
  EXPECT_EQ((gg::contact_frames<T, 3>(same, y, f)), gg::Status::kCoincidentContacts);
  gg::Contacts<T, 3> all = gg::Contacts<T, 3>::Constant(T(0.3));
  EXPECT_EQ((gg::contact_frames<T, 3>(all, y, f)), gg::Status::kCoincidentContacts);
  gg::Contacts<T, 4> centre = hand<T, 4>();
  centre.col(3) = centre.template leftCols<3>().rowwise().mean();  // palm at the centroid
  gg::ContactFrames<T, 4> f4;
  EXPECT_EQ((gg::contact_frames<T, 4>(centre, y, f4)), gg::Status::kCoincidentContacts);
}

// ---------------------------------------------------------------- grasp matrix

TYPED_TEST(Steps, GraspMatrixMapsContactForcesToTheWrenchAboutTheCentroid) {
  using T = TypeParam;
  const auto c = hand<T, 4>();
  gg::ContactFrames<T, 4> f;
  ASSERT_EQ((gg::contact_frames<T, 4>(c, gg::Vec3<T>::UnitY(), f)), gg::Status::kOk);
  gg::GraspMat<T, 4> g;
  gg::grasp_matrix<T, 4>(f, g);
  gg::ForceVec<T, 4> lambda;
  for (int j = 0; j < 12; ++j) lambda(j) = T(0.1) * T(j) - T(0.4);
  // Direct physics: force sum and moment about O of the contact forces.
  gg::Vec3<T> force = gg::Vec3<T>::Zero(), moment = gg::Vec3<T>::Zero();
  for (int i = 0; i < 4; ++i) {
    const gg::Vec3<T> fi = f.rotation[i] * lambda.template segment<3>(3 * i);
    force += fi;
    moment += (c.col(i) - f.origin).cross(fi);
  }
  const gg::Vec6<T> w = g * lambda;
  EXPECT_TRUE(w.template head<3>().isApprox(force, tol<T>()));
  // Moment rows are in units of L (docs/algorithm.md step 2).
  EXPECT_TRUE((w.template tail<3>() * f.length_scale).isApprox(moment, T(100) * tol<T>()));
  // The same scaling applied to a wrench.
  gg::Vec6<T> wr;
  wr << T(1), T(2), T(3), T(4), T(5), T(6);
  const gg::Vec6<T> ws = gg::scaled_wrench<T>(wr, T(2));
  EXPECT_EQ(ws(0), T(1));
  EXPECT_EQ(ws(5), T(3));
}

// ---------------------------------------------------------------- equilibrium

template <typename T, int K>
void check_equilibrium(gg::Decomposition d) {
  std::mt19937_64 rng(42 + K);
  for (int n = 0; n < 200; ++n) {
    const auto s = graspguide_test::random_scene(rng, K);
    gg::ContactFrames<T, K> f;
    ASSERT_EQ((gg::contact_frames<T, K>(s.contacts.leftCols<K>().template cast<T>(),
                                        gg::Vec3<T>::UnitY(), f)),
              gg::Status::kOk);
    gg::GraspMat<T, K> g;
    gg::grasp_matrix<T, K>(f, g);
    const gg::Vec6<T> w = gg::scaled_wrench<T>(s.wrench.cast<T>(), f.length_scale);
    gg::Equilibrium<T, K> eq;
    ASSERT_EQ((gg::equilibrium<T, K>(f, w, d, eq)), gg::Status::kOk);
    const T scale = w.norm();
    EXPECT_LT((w + g * eq.lambda0).norm(), T(100) * tol<T>() * scale);
    const auto ntn = (eq.null_basis.transpose() * eq.null_basis).eval();
    EXPECT_TRUE(ntn.isIdentity(T(10) * tol<T>()));
    EXPECT_LT((g * eq.null_basis).norm(), T(100) * tol<T>());
    EXPECT_LT((eq.null_basis.transpose() * eq.lambda0).norm(), T(100) * tol<T>() * scale);
    EXPECT_GT(eq.rank_ratio, T(gg::kRankRelTol));
  }
}

TYPED_TEST(Steps, EquilibriumQrIsAMinimumNormSolutionWithOrthonormalNullBasis) {
  check_equilibrium<TypeParam, 3>(gg::Decomposition::kQR);
  check_equilibrium<TypeParam, 4>(gg::Decomposition::kQR);
}

TYPED_TEST(Steps, EquilibriumSvdIsAMinimumNormSolutionWithOrthonormalNullBasis) {
  check_equilibrium<TypeParam, 3>(gg::Decomposition::kSVD);
  check_equilibrium<TypeParam, 4>(gg::Decomposition::kSVD);
}

// The two routes must give the same lambda0 and span the same null space.
TYPED_TEST(Steps, QrAgreesWithSvd) {
  using T = TypeParam;
  std::mt19937_64 rng(7);
  T worst = 0;
  for (int n = 0; n < 500; ++n) {
    const auto s = graspguide_test::random_scene(rng, 4);
    gg::ContactFrames<T, 4> f;
    ASSERT_EQ((gg::contact_frames<T, 4>(s.contacts.template cast<T>(), gg::Vec3<T>::UnitY(), f)),
              gg::Status::kOk);
    gg::GraspMat<T, 4> g;
    gg::grasp_matrix<T, 4>(f, g);
    const gg::Vec6<T> w = gg::scaled_wrench<T>(s.wrench.cast<T>(), f.length_scale);
    gg::Equilibrium<T, 4> qr, svd;
    ASSERT_EQ((gg::equilibrium<T, 4>(f, w, gg::Decomposition::kQR, qr)), gg::Status::kOk);
    ASSERT_EQ((gg::equilibrium<T, 4>(f, w, gg::Decomposition::kSVD, svd)), gg::Status::kOk);
    worst = std::max(worst, (qr.lambda0 - svd.lambda0).norm() / svd.lambda0.norm());
    const auto proj_qr = (qr.null_basis * qr.null_basis.transpose()).eval();
    const auto proj_svd = (svd.null_basis * svd.null_basis.transpose()).eval();
    EXPECT_LT((proj_qr - proj_svd).norm(), T(100) * tol<T>());
  }
  EXPECT_LT(worst, T(50) * tol<T>());
}

// The QR route rests on G G^T = diag(k I, M M^T) (offsets from the centroid): G's
// singular values are sqrt(k) three times and those of the reduced matrix M. Checked
// against a full SVD of G, with the QR route's estimate of the rank ratio alongside.
template <typename T, int K>
void check_reduced_grasp_matrix() {
  std::mt19937_64 rng(11 + K);
  for (int n = 0; n < 200; ++n) {
    const auto s = graspguide_test::random_scene(rng, K);
    gg::ContactFrames<T, K> f;
    ASSERT_EQ((gg::contact_frames<T, K>(s.contacts.template leftCols<K>().template cast<T>(),
                                        gg::Vec3<T>::UnitY(), f)),
              gg::Status::kOk);
    gg::GraspMat<T, K> g;
    gg::grasp_matrix<T, K>(f, g);
    gg::ReducedGraspT<T, K> mt;
    gg::reduced_grasp_matrix<T, K>(f, mt);
    Eigen::Matrix<T, 6, 6> expected = Eigen::Matrix<T, 6, 6>::Zero();
    expected.template topLeftCorner<3, 3>() = T(K) * gg::Mat3<T>::Identity();
    expected.template bottomRightCorner<3, 3>() = mt.transpose() * mt;
    EXPECT_LT((g * g.transpose() - expected).norm(), T(20) * tol<T>() * T(K));

    const Eigen::JacobiSVD<gg::GraspMatT<T, K>> svd(g.transpose());
    const T exact = svd.singularValues()(5) / svd.singularValues()(0);
    gg::Equilibrium<T, K> eq;
    ASSERT_EQ((gg::equilibrium<T, K>(f, gg::Vec6<T>::Unit(2), gg::Decomposition::kQR, eq)),
              gg::Status::kOk);
    // Column pivoting brackets each singular value within a factor sqrt(3) for 3 columns.
    EXPECT_GE(eq.rank_ratio, exact / T(3) * (T(1) - T(10) * tol<T>()));
    EXPECT_LE(eq.rank_ratio, exact * T(3) * (T(1) + T(10) * tol<T>()));
  }
}

TYPED_TEST(Steps, ReducedGraspMatrixCarriesTheMomentSingularValuesOfG) {
  check_reduced_grasp_matrix<TypeParam, 3>();
  check_reduced_grasp_matrix<TypeParam, 4>();
}

TYPED_TEST(Steps, CollinearContactsAreRankDeficientOnBothRoutes) {
  using T = TypeParam;
  gg::Contacts<T, 3> c;
  // On one line, and not symmetric (a symmetric set puts a contact on the centroid).
  c << T(0), T(0.03), T(0.1), T(0), T(0.012), T(0.04), T(0), T(0.006), T(0.02);
  gg::ContactFrames<T, 3> f;
  ASSERT_EQ((gg::contact_frames<T, 3>(c, gg::Vec3<T>::UnitY(), f)), gg::Status::kOk);
  gg::Vec6<T> w;
  w << T(0), T(0), T(-1), T(0), T(0), T(0);
  gg::Equilibrium<T, 3> eq;
  EXPECT_EQ((gg::equilibrium<T, 3>(f, w, gg::Decomposition::kQR, eq)), gg::Status::kRankDeficient);
  EXPECT_LT(eq.rank_ratio, T(gg::kRankRelTol));
  EXPECT_EQ((gg::equilibrium<T, 3>(f, w, gg::Decomposition::kSVD, eq)), gg::Status::kRankDeficient);
  EXPECT_LT(eq.rank_ratio, T(gg::kRankRelTol));
}

// ---------------------------------------------------------------- relevance

TYPED_TEST(Steps, RelevanceMarksContactsOppositeTheForceIncludingTheBoundary) {
  using T = TypeParam;
  gg::Contacts<T, 3> c;
  // Offsets from the centroid (0,0,0): +x, -x + y, -x - y.
  c << T(2), T(-1), T(-1), T(0), T(1), T(-1), T(0), T(0), T(0);
  gg::ContactFrames<T, 3> f;
  ASSERT_EQ((gg::contact_frames<T, 3>(c, gg::Vec3<T>(T(0), T(0), T(1)), f)), gg::Status::kOk);
  EXPECT_EQ((gg::relevance<T, 3>(f, gg::Vec3<T>(T(1), T(0), T(0)))), 0b110);
  EXPECT_EQ((gg::relevance<T, 3>(f, gg::Vec3<T>(T(-1), T(0), T(0)))), 0b001);
  // Exactly on the boundary of contact 0 (f ⟂ r_0): relevant, as the paper's "<= 0".
  EXPECT_EQ((gg::relevance<T, 3>(f, gg::Vec3<T>(T(0), T(1), T(0)))), 0b101);
  EXPECT_EQ((gg::relevance<T, 3>(f, gg::Vec3<T>(T(0), T(0), T(1)))), 0b111);
}

TYPED_TEST(Steps, DesiredForcesKeepRelevantContactsAndNormalise) {
  using T = TypeParam;
  gg::ForceVec<T, 3> l0;
  l0 << T(1), T(2), T(2), T(5), T(5), T(5), T(0), T(3), T(4);
  const auto des = gg::desired_forces<T, 3>(l0, 0b101);
  gg::ForceVec<T, 3> expect;
  expect << T(1), T(2), T(2), T(0), T(0), T(0), T(0), T(3), T(4);
  expect /= std::sqrt(T(34));
  EXPECT_TRUE(des.isApprox(expect, tol<T>()));
  gg::ForceVec<T, 3> zero_relevant = l0;
  zero_relevant.template head<3>().setZero();
  EXPECT_TRUE((gg::desired_forces<T, 3>(zero_relevant, 0b001)).isZero());
}

// ---------------------------------------------------------------- levels and PWM

TYPED_TEST(Steps, MotorLevelsForBothPolicies) {
  using T = TypeParam;
  gg::ForceVec<T, 3> l;
  l << T(0), T(3), T(4), T(0), T(0), T(0), T(2), T(-1), T(2);
  gg::LevelVec<T, 3> m;
  ASSERT_EQ((gg::motor_levels<T, 3>(l, gg::Policy::kF, m)), gg::Status::kOk);
  // |lambda_i| = 5, 0, 3 -> normalised by sqrt(34).
  EXPECT_TRUE(m.isApprox(gg::LevelVec<T, 3>(T(5), T(0), T(3)) / std::sqrt(T(34)), tol<T>()));
  ASSERT_EQ((gg::motor_levels<T, 3>(l, gg::Policy::kFperp, m)), gg::Status::kOk);
  EXPECT_TRUE(m.isApprox(gg::LevelVec<T, 3>(T(3), T(0), T(-1)) / std::sqrt(T(10)), tol<T>()));
  gg::ForceVec<T, 3> tangential = gg::ForceVec<T, 3>::Zero();
  tangential(0) = T(1);
  EXPECT_EQ((gg::motor_levels<T, 3>(tangential, gg::Policy::kFperp, m)),
            gg::Status::kNothingToDisplay);
  EXPECT_EQ((gg::motor_levels<T, 3>(gg::ForceVec<T, 3>::Zero(), gg::Policy::kF, m)),
            gg::Status::kNothingToDisplay);
}

TYPED_TEST(Steps, PwmMappingOffThresholdRoundingAndGain) {
  using T = TypeParam;
  gg::LevelVec<T, 4> m;
  m << T(1), T(-0.5), T(1e-3), T(0.0011);
  gg::Pwm c = gg::pwm_from_levels<T, 4>(m, T(gg::kPwmSpan));
  EXPECT_EQ(c.duty[0], 255);
  EXPECT_EQ(c.duty[1], 163);  // 70 + 92.5 = 162.5 rounds half up
  EXPECT_EQ(c.duty[2], 0);    // at the off threshold: off, never a stray 70
  EXPECT_EQ(c.duty[3], 70);   // 70 + 0.2035
  gg::Pwm v = gg::pwm_from_levels<T, 4>(m, T(0));
  EXPECT_EQ(v.duty[0], 70);  // mode V, aligned: alpha = 0
  EXPECT_EQ(v.duty[2], 0);
  gg::Pwm big = gg::pwm_from_levels<T, 4>(m, T(1e6));
  EXPECT_EQ(big.duty[0], 255);  // clamped
}

// ---------------------------------------------------------------- orientation

TYPED_TEST(Steps, AlignmentErrorAndAlpha) {
  using T = TypeParam;
  gg::Quat<T> q;
  ASSERT_EQ((gg::unit_quaternion<T>(Eigen::Matrix<T, 4, 1>(T(1), T(0), T(0), T(0)), q)),
            gg::Status::kOk);
  const gg::Vec3<T> down(T(0), T(0), T(-1));
  auto a = gg::alignment<T>(q, down);
  EXPECT_NEAR(a.error_deg, T(0), tol<T>());
  EXPECT_NEAR(a.alpha, T(0), tol<T>());
  a = gg::alignment<T>(q, -down);
  EXPECT_NEAR(a.error_deg, T(180), T(1e-4));
  EXPECT_NEAR(a.alpha, T(gg::kPwmSpan), T(1e-4));
  a = gg::alignment<T>(q, gg::Vec3<T>::UnitX());
  EXPECT_NEAR(a.error_deg, T(90), T(1e-4));
  EXPECT_NEAR(a.alpha, std::sqrt(T(2)) / T(2) * T(gg::kPwmSpan), T(1e-3));
  // Hand rotated 90 deg about world x: hand +y points to world +z, so f = -y is aligned.
  const T h = std::sqrt(T(0.5));
  ASSERT_EQ((gg::unit_quaternion<T>(Eigen::Matrix<T, 4, 1>(h, h, T(0), T(0)), q)), gg::Status::kOk);
  a = gg::alignment<T>(q, -gg::Vec3<T>::UnitY());
  EXPECT_NEAR(a.error_deg, T(0), T(1e-3));
  // Small angles keep their accuracy (atan2, not acos).
  const T tiny = T(1e-3) * T(3.14159265358979323846) / T(180);
  a = gg::alignment<T>(gg::Quat<T>(Eigen::AngleAxis<T>(tiny, gg::Vec3<T>::UnitX())), down);
  EXPECT_NEAR(a.error_deg, T(1e-3), T(1e-6));
}

TYPED_TEST(Steps, QuaternionScaleDoesNotMatterButZeroAndNanAreRejected) {
  using T = TypeParam;
  gg::Quat<T> a, b;
  Eigen::Matrix<T, 4, 1> q(T(0.3), T(-0.5), T(0.7), T(0.1));
  ASSERT_EQ((gg::unit_quaternion<T>(q, a)), gg::Status::kOk);
  ASSERT_EQ((gg::unit_quaternion<T>(Eigen::Matrix<T, 4, 1>(T(3.7) * q), b)), gg::Status::kOk);
  EXPECT_TRUE(a.coeffs().isApprox(b.coeffs(), tol<T>()));
  EXPECT_NEAR(a.norm(), T(1), tol<T>());
  EXPECT_EQ((gg::unit_quaternion<T>(Eigen::Matrix<T, 4, 1>::Zero(), a)),
            gg::Status::kBadQuaternion);
  q(2) = std::numeric_limits<T>::quiet_NaN();
  EXPECT_EQ((gg::unit_quaternion<T>(q, a)), gg::Status::kNonFiniteInput);
}

TEST(Status, EveryStatusHasANameAndAMessage) {
  for (int i = 0; i < gg::kStatusCount; ++i) {
    const auto s = static_cast<gg::Status>(i);
    EXPECT_STRNE(gg::status_name(s), "unknown");
    EXPECT_STRNE(gg::status_message(s), "unknown status");
  }
}
