// Each step of Algorithm 1 on its own: frames, grasp matrix, equilibrium (structured and
// SVD routes), the moment about y_O, relevance, desired forces, motor levels, PWM and the
// orientation error.
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

// The frames, grasp matrix and scaled wrench of a random scene, shared by the checks below.
template <typename T, int K>
struct Prepared {
  gg::ContactFrames<T, K> f;
  gg::GraspMat<T, K> g;
  gg::Vec6<T> w;
};

template <typename T, int K>
Prepared<T, K> prepare(const graspguide_test::RandomScene& s) {
  Prepared<T, K> p;
  EXPECT_EQ((gg::contact_frames<T, K>(s.contacts.leftCols<K>().template cast<T>(),
                                      gg::Vec3<T>::UnitY(), p.f)),
            gg::Status::kOk);
  gg::grasp_matrix<T, K>(p.f, p.g);
  p.w = gg::scaled_wrench<T>(s.wrench.cast<T>(), p.f.length_scale);
  return p;
}

template <typename T, int K>
void check_equilibrium_svd() {
  std::mt19937_64 rng(42 + K);
  for (int n = 0; n < 200; ++n) {
    const auto p = prepare<T, K>(graspguide_test::random_scene(rng, K));
    gg::Equilibrium<T, K> eq;
    ASSERT_EQ((gg::equilibrium_svd<T, K>(p.g, p.w, eq)), gg::Status::kOk);
    const T scale = p.w.norm();
    EXPECT_LT((p.w + p.g * eq.lambda0).norm(), T(100) * tol<T>() * scale);
    const auto ntn = (eq.null_basis.transpose() * eq.null_basis).eval();
    EXPECT_TRUE(ntn.isIdentity(T(10) * tol<T>()));
    EXPECT_LT((p.g * eq.null_basis).norm(), T(100) * tol<T>());
    EXPECT_LT((eq.null_basis.transpose() * eq.lambda0).norm(), T(100) * tol<T>() * scale);
    EXPECT_GT(eq.rank_ratio, T(gg::kRankRelTol));
  }
}

TYPED_TEST(Steps, EquilibriumSvdIsAMinimumNormSolutionWithOrthonormalNullBasis) {
  check_equilibrium_svd<TypeParam, 3>();
  check_equilibrium_svd<TypeParam, 4>();
}

// The structured route rests on G G^T = diag(k I, J), J = sum_i (|s_i|^2 I - s_i s_i^T)
// (offsets from the centroid): G_hat = diag(I / sqrt(k), R_J^-T) G with R_J^T R_J = J has
// orthonormal rows. Checked against grasp_matrix() and a full SVD of G.
template <typename T, int K>
void check_grasp_structure() {
  std::mt19937_64 rng(11 + K);
  T worst_lambda0 = 0, worst_ratio = 0;
  for (int n = 0; n < 200; ++n) {
    const auto p = prepare<T, K>(graspguide_test::random_scene(rng, K));
    gg::GraspStructure<T, K> st;
    ASSERT_EQ((gg::grasp_structure<T, K>(p.f, st)), gg::Status::kOk);
    EXPECT_TRUE((st.g_hat * st.g_hat.transpose()).isIdentity(T(10) * tol<T>()));
    gg::Mat3<T> j = gg::Mat3<T>::Zero();
    for (int i = 0; i < K; ++i) {
      const gg::Vec3<T> s = p.f.offset_scaled.col(i);
      j += s.squaredNorm() * gg::Mat3<T>::Identity() - s * s.transpose();
    }
    EXPECT_TRUE(st.j_factor.isUpperTriangular());
    EXPECT_LT((st.j_factor.transpose() * st.j_factor - j).norm(), T(10) * tol<T>() * j.norm());
    Eigen::Matrix<T, 6, 6> whiten = Eigen::Matrix<T, 6, 6>::Zero();
    whiten.template topLeftCorner<3, 3>() = gg::Mat3<T>::Identity() / std::sqrt(T(K));
    whiten.template bottomRightCorner<3, 3>() = st.j_factor.transpose().inverse();
    EXPECT_LT((st.g_hat - whiten * p.g).norm(), T(100) * tol<T>());
    EXPECT_TRUE((gg::whitened_wrench<T, K>(st, p.w)).isApprox(whiten * p.w, T(10) * tol<T>()));

    // lambda0 from both routes, and the rank ratio against the SVD's sigma6 / sigma1.
    const gg::ForceVec<T, K> lambda0 =
        gg::min_norm_forces<T, K>(st, gg::whitened_wrench<T, K>(st, p.w));
    EXPECT_LT((p.w + p.g * lambda0).norm(), T(100) * tol<T>() * p.w.norm());
    gg::Equilibrium<T, K> eq;
    ASSERT_EQ((gg::equilibrium_svd<T, K>(p.g, p.w, eq)), gg::Status::kOk);
    worst_lambda0 = std::max(worst_lambda0, (lambda0 - eq.lambda0).norm() / eq.lambda0.norm());
    // The power steps under-estimate |R_J^-1|, so the ratio can only come out high.
    EXPECT_GE(st.rank_ratio, eq.rank_ratio * (T(1) - T(100) * tol<T>()));
    worst_ratio = std::max(worst_ratio, st.rank_ratio / eq.rank_ratio - T(1));
  }
  EXPECT_LT(worst_lambda0, T(50) * tol<T>());
  // Two power steps estimate sigma_min: within 10 % where the hand is well conditioned
  // (5.4 % at worst on these scenes), far closer near the rank threshold.
  EXPECT_LT(worst_ratio, T(0.1));
}

TYPED_TEST(Steps, StructuredGraspHasOrthonormalRowsAndAgreesWithTheSvdRoute) {
  check_grasp_structure<TypeParam, 3>();
  check_grasp_structure<TypeParam, 4>();
}

// The projection of lambda_des onto the equilibrium set: on it, and lambda_des minus it
// lies in the row space of G (orthogonal to the SVD route's null basis).
TYPED_TEST(Steps, ProjectOntoEquilibriumIsTheOrthogonalProjection) {
  using T = TypeParam;
  std::mt19937_64 rng(19);
  std::normal_distribution<double> n01(0, 1);
  for (int n = 0; n < 200; ++n) {
    const auto p = prepare<T, 4>(graspguide_test::random_scene(rng, 4));
    gg::GraspStructure<T, 4> st;
    ASSERT_EQ((gg::grasp_structure<T, 4>(p.f, st)), gg::Status::kOk);
    gg::ForceVec<T, 4> des;
    for (int j = 0; j < 12; ++j) des(j) = T(n01(rng));
    const gg::ForceVec<T, 4> x =
        gg::project_onto_equilibrium<T, 4>(st, gg::whitened_wrench<T, 4>(st, p.w), des);
    EXPECT_LT((p.w + p.g * x).norm(), T(100) * tol<T>() * (p.w.norm() + des.norm()));
    gg::Equilibrium<T, 4> eq;
    ASSERT_EQ((gg::equilibrium_svd<T, 4>(p.g, p.w, eq)), gg::Status::kOk);
    EXPECT_LT((eq.null_basis.transpose() * (des - x)).norm(), T(100) * tol<T>() * des.norm());
  }
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
  gg::GraspStructure<T, 3> st;
  st.rank_ratio = T(1);
  EXPECT_EQ((gg::grasp_structure<T, 3>(f, st)), gg::Status::kRankDeficient);
  EXPECT_LT(st.rank_ratio, T(gg::kRankRelTol));
  gg::GraspMat<T, 3> g;
  gg::grasp_matrix<T, 3>(f, g);
  gg::Equilibrium<T, 3> eq;
  EXPECT_EQ((gg::equilibrium_svd<T, 3>(g, w, eq)), gg::Status::kRankDeficient);
  EXPECT_LT(eq.rank_ratio, T(gg::kRankRelTol));
}

// ---------------------------------------------------------------- the moment about y_O

// For any lambda with G lambda = -w and no fallback contact, sum_i c_i lambda_ix = tau . y_O
// (scaled): the identity the paper model's x rows rest on (force_qp.h).
template <typename T, int K>
void check_moment_identity() {
  std::mt19937_64 rng(23 + K);
  int checked = 0;
  for (int n = 0; n < 300; ++n) {
    const auto p = prepare<T, K>(graspguide_test::random_scene(rng, K));
    if (p.f.fallback_mask != 0) continue;
    gg::GraspStructure<T, K> st;
    ASSERT_EQ((gg::grasp_structure<T, K>(p.f, st)), gg::Status::kOk);
    const gg::Vec6<T> w_hat = gg::whitened_wrench<T, K>(st, p.w);
    const gg::ForceVec<T, K> lambda0 = gg::min_norm_forces<T, K>(st, w_hat);
    gg::ForceSolution<T, K> sol;
    ASSERT_EQ((gg::solve_forces<T, K>(p.f, st, p.w, lambda0, lambda0, gg::ConstraintModel::kNone,
                                      64, sol)),
              gg::Status::kOk);
    const T budget = p.w.template tail<3>().dot(p.f.axis);
    for (const gg::ForceVec<T, K>* l :
         {&lambda0, static_cast<const gg::ForceVec<T, K>*>(&sol.lambda)}) {
      T moment = T(0);
      for (int i = 0; i < K; ++i) moment += p.f.x_moment[i] * (*l)(3 * i);
      EXPECT_NEAR(moment, budget, T(100) * tol<T>() * (p.w.norm() + l->norm())) << n;
    }
    for (int i = 0; i < K; ++i) {
      const gg::Vec3<T> s = p.f.offset_scaled.col(i);
      EXPECT_NEAR(p.f.x_moment[i], s.cross(p.f.axis).norm(), tol<T>());
    }
    ++checked;
  }
  EXPECT_GT(checked, 250);
}

TYPED_TEST(Steps, MomentAboutTheAxisIsCarriedByTheXComponentsAlone) {
  check_moment_identity<TypeParam, 3>();
  check_moment_identity<TypeParam, 4>();
}

TYPED_TEST(Steps, PaperXRowsFollowTheSignOfTheMomentBudget) {
  using T = TypeParam;
  std::mt19937_64 rng(3);
  const auto p = prepare<T, 4>(graspguide_test::random_scene(rng, 4));
  ASSERT_EQ(p.f.fallback_mask, 0);
  int largest = 0;
  for (int i = 1; i < 4; ++i)
    if (p.f.x_moment[i] > p.f.x_moment[largest]) largest = i;
  const T violation_tol = T(1e-3);
  const T slack = violation_tol * p.f.x_moment[largest];
  auto with_budget = [&](T b) {
    gg::Vec6<T> w = p.w;
    w.template tail<3>() = b * p.f.axis;
    return w;
  };
  uint16_t fixed = 1, implied = 1;
  EXPECT_EQ(
      (gg::paper_x_rows<T, 4>(p.f, with_budget(-T(2) * slack), violation_tol, fixed, implied)),
      gg::Status::kQpInfeasible);
  ASSERT_EQ((gg::paper_x_rows<T, 4>(p.f, with_budget(T(0)), violation_tol, fixed, implied)),
            gg::Status::kOk);
  const uint16_t largest_x = static_cast<uint16_t>(1u << (3 * largest));
  EXPECT_EQ(fixed, gg::axis_bits<4>(0) & ~largest_x);
  EXPECT_EQ(implied, largest_x);
  // Within the slack on either side still counts as no moment.
  ASSERT_EQ(
      (gg::paper_x_rows<T, 4>(p.f, with_budget(T(0.5) * slack), violation_tol, fixed, implied)),
      gg::Status::kOk);
  EXPECT_EQ(implied, largest_x);
  ASSERT_EQ((gg::paper_x_rows<T, 4>(p.f, with_budget(T(2) * slack), violation_tol, fixed, implied)),
            gg::Status::kOk);
  EXPECT_EQ(fixed, 0);
  EXPECT_EQ(implied, 0);
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
