// Properties on thousands of random hand-like scenes: equilibrium, constraints, QP
// optimality (KKT), invariance to units and to rotating the scene, warm = cold start,
// float vs double agreement. Prints the figures reported in the closing notes.
#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide.h"

namespace gg = graspguide;
using graspguide_test::random_scene;
using graspguide_test::RandomScene;
using graspguide_test::solve_once;

constexpr gg::ConstraintModel kModels[] = {
    gg::ConstraintModel::kPaper, gg::ConstraintModel::kNormal, gg::ConstraintModel::kNone};
constexpr gg::Policy kPolicies[] = {gg::Policy::kF, gg::Policy::kFperp};
constexpr gg::Mode kModes[] = {gg::Mode::kC, gg::Mode::kV};

struct Combo {
  gg::ConstraintModel model;
  gg::Policy policy;
  gg::Mode mode;
};
Combo combo(int n) { return {kModels[n % 3], kPolicies[(n / 3) % 2], kModes[(n / 6) % 2]}; }

// Recomputes the steps of solve_grasp to check the QP's optimality conditions.
template <int K>
void check_qp_optimality(const RandomScene& s, gg::ConstraintModel requested) {
  gg::ContactFrames<double, K> f;
  ASSERT_EQ((gg::contact_frames<double, K>(s.contacts.leftCols<K>(), gg::Vec3<double>::UnitY(), f)),
            gg::Status::kOk);
  gg::GraspMat<double, K> g;
  gg::grasp_matrix<double, K>(f, g);
  const gg::Vec6<double> w = gg::scaled_wrench<double>(s.wrench, f.length_scale);
  gg::Equilibrium<double, K> eq;
  ASSERT_EQ((gg::equilibrium<double, K>(f, w, gg::Decomposition::kQR, eq)), gg::Status::kOk);
  const auto des =
      gg::desired_forces<double, K>(eq.lambda0, gg::relevance<double, K>(f, s.wrench.head<3>()));
  gg::ForceSolution<double, K> sol;
  ASSERT_EQ(
      (gg::solve_forces<double, K>(eq, des, requested, 64, gg::ConstraintModel::kNone, 0, sol)),
      gg::Status::kOk);
  const double scale = eq.lambda0.norm();
  // Equilibrium of the final forces.
  EXPECT_LT((g * sol.lambda + w).norm(), 1e-10 * w.norm());
  // Constraints of the model used.
  gg::ProjectionQp<double, 3 * K - 6, 3 * K> qp;
  gg::constraint_rows<double, K>(eq, sol.used, qp);
  const Eigen::Matrix<double, 3 * K - 6, 1> xi =
      eq.null_basis.transpose() * (sol.lambda - eq.lambda0);
  const Eigen::Matrix<double, 3 * K - 6, 1> xu = eq.null_basis.transpose() * (des - eq.lambda0);
  for (int j = 0; j < qp.m; ++j) EXPECT_GE(qp.a.row(j).dot(xi) - qp.b(j), -1e-9 * scale);
  // Stationarity: xi - xu is a non-negative combination of the active rows.
  Eigen::Matrix<double, 3 * K - 6, Eigen::Dynamic> aw(3 * K - 6, 0);
  for (int j = 0; j < qp.m; ++j)
    if (sol.active & (1u << j)) {
      aw.conservativeResize(Eigen::NoChange, aw.cols() + 1);
      aw.col(aw.cols() - 1) = qp.a.row(j).transpose();
      EXPECT_NEAR(qp.a.row(j).dot(xi), qp.b(j), 1e-9 * scale);
    }
  const Eigen::Matrix<double, 3 * K - 6, 1> grad = xi - xu;
  if (aw.cols() == 0) {
    EXPECT_LT(grad.norm(), 1e-9);
  } else {
    const Eigen::VectorXd mu = aw.colPivHouseholderQr().solve(grad);
    EXPECT_LT((aw * mu - grad).norm(), 1e-8);
    EXPECT_GE(mu.minCoeff(), -1e-8);
  }
}

TEST(Properties, EquilibriumConstraintsAndKktOnRandomScenes) {
  std::mt19937_64 rng(2024);
  for (int n = 0; n < 3000; ++n) {
    const auto s = random_scene(rng, 3 + n % 2);
    SCOPED_TRACE(n);
    if (s.k == 3)
      check_qp_optimality<3>(s, kModels[(n / 2) % 3]);
    else
      check_qp_optimality<4>(s, kModels[(n / 2) % 3]);
  }
}

TEST(Properties, PwmIsInvariantToTheLengthUnit) {
  std::mt19937_64 rng(11);
  for (int n = 0; n < 2000; ++n) {
    auto s = random_scene(rng, 3 + n % 2);
    const Combo c = combo(n);
    const auto base = solve_once<double>(
        graspguide_test::make_scene<double>(s, c.model, c.policy, c.mode), s.wrench, s.orientation);
    ASSERT_EQ(base.status, gg::Status::kOk);
    for (double unit : {1e3, 2e-3, 200.0}) {  // mm; contacts ~0.1 mm apart; ~10 m apart
      RandomScene t = s;
      t.contacts *= unit;
      t.wrench.tail<3>() *= unit;  // the same moment, in force x the new length unit
      const auto r =
          solve_once<double>(graspguide_test::make_scene<double>(t, c.model, c.policy, c.mode),
                             t.wrench, t.orientation);
      ASSERT_EQ(r.status, gg::Status::kOk) << n << " unit " << unit;
      EXPECT_EQ(graspguide_test::max_pwm_diff(r.frame.pwm, base.frame.pwm), 0)
          << n << " unit " << unit;
      EXPECT_LT((r.grasp.lambda - base.grasp.lambda).norm(), 1e-9 * base.grasp.lambda.norm());
    }
  }
}

TEST(Properties, PwmIsInvariantToRotatingTheWholeScene) {
  std::mt19937_64 rng(12);
  int exact = 0;
  const int total = 2000;
  for (int n = 0; n < total; ++n) {
    const auto s = random_scene(rng, 3 + n % 2);
    const Combo c = combo(n);
    const auto base = solve_once<double>(
        graspguide_test::make_scene<double>(s, c.model, c.policy, c.mode), s.wrench, s.orientation);
    ASSERT_EQ(base.status, gg::Status::kOk);
    const Eigen::Quaterniond rot(
        Eigen::AngleAxisd(0.1 + n * 0.37, graspguide_test::random_unit(rng)));
    RandomScene t = s;
    t.contacts = rot.toRotationMatrix() * s.contacts;
    t.wrench.head<3>() = rot * s.wrench.head<3>();
    t.wrench.tail<3>() = rot * s.wrench.tail<3>();
    const Eigen::Quaterniond hand(s.orientation(0), s.orientation(1), s.orientation(2),
                                  s.orientation(3));
    const Eigen::Quaterniond moved = hand * rot.conjugate();  // the world sees the same force
    t.orientation << moved.w(), moved.x(), moved.y(), moved.z();
    auto scene = graspguide_test::make_scene<double>(t, c.model, c.policy, c.mode);
    scene.y_axis = rot * Eigen::Vector3d::UnitY();
    const auto r = solve_once<double>(scene, t.wrench, t.orientation);
    ASSERT_EQ(r.status, gg::Status::kOk) << n;
    const int d = graspguide_test::max_pwm_diff(r.frame.pwm, base.frame.pwm);
    EXPECT_LE(d, 1) << n;  // a level on a rounding half may round the other way
    exact += d == 0;
    EXPECT_NEAR(r.frame.error_deg, base.frame.error_deg, 1e-9);
    EXPECT_LT((r.grasp.lambda - base.grasp.lambda).norm(), 1e-9 * base.grasp.lambda.norm());
  }
  EXPECT_GE(exact, total - 2);
}

TEST(Properties, WarmStartGivesTheSameAnswerAsColdStart) {
  std::mt19937_64 rng(13);
  std::normal_distribution<double> tremor(0.0, 0.0005);  // 0.5 mm tracking noise per frame
  int warm_iterations = 0, cold_iterations = 0;
  for (int seq = 0; seq < 200; ++seq) {
    auto s = random_scene(rng, 3 + seq % 2);
    const Combo c = combo(seq);
    auto scene = graspguide_test::make_scene<double>(s, c.model, c.policy, c.mode);
    scene.solver.warm_start = true;
    gg::Guidance<double> warm;
    ASSERT_EQ(warm.set_scene(scene), gg::Status::kOk);
    ASSERT_EQ(warm.set_wrench(s.wrench), gg::Status::kOk);
    for (int frame = 0; frame < 20; ++frame) {
      for (int i = 0; i < s.k; ++i)
        for (int j = 0; j < 3; ++j) s.contacts(j, i) += tremor(rng);
      ASSERT_EQ(warm.set_contacts(s.contacts), gg::Status::kOk);
      gg::FrameResult<double> fw;
      ASSERT_EQ(warm.update(s.orientation, fw), gg::Status::kOk);
      scene.contacts = s.contacts;
      auto cold_scene = scene;
      cold_scene.solver.warm_start = false;
      const auto cold = solve_once<double>(cold_scene, s.wrench, s.orientation);
      ASSERT_EQ(cold.status, gg::Status::kOk);
      EXPECT_EQ(graspguide_test::max_pwm_diff(fw.pwm, cold.frame.pwm), 0);
      EXPECT_LT((warm.grasp().lambda - cold.grasp.lambda).norm(), 1e-9 * cold.grasp.lambda.norm());
      warm_iterations += warm.grasp().iterations;
      cold_iterations += cold.grasp.iterations;
    }
  }
  std::printf("QP iterations over 4000 tracked frames: warm %d, cold %d\n", warm_iterations,
              cold_iterations);
  EXPECT_LE(warm_iterations, cold_iterations);
}

TEST(Properties, FloatAgreesWithDoubleWithinOnePwmCount) {
  std::mt19937_64 rng(14);
  const int total = 20000;
  int within_one = 0, identical = 0, status_mismatch = 0;
  for (int n = 0; n < total; ++n) {
    const auto s = random_scene(rng, 3 + n % 2);
    const Combo c = combo(n);
    const auto d = solve_once<double>(
        graspguide_test::make_scene<double>(s, c.model, c.policy, c.mode), s.wrench, s.orientation);
    const auto f = solve_once<float>(
        graspguide_test::make_scene<float>(s, c.model, c.policy, c.mode), s.wrench, s.orientation);
    if (d.status != f.status || d.grasp.used != f.grasp.used) {
      ++status_mismatch;
      continue;
    }
    const int diff = graspguide_test::max_pwm_diff(d.frame.pwm, f.frame.pwm);
    within_one += diff <= 1;
    identical += diff == 0;
  }
  const double rate = double(within_one) / total;
  std::printf(
      "float vs double: PWM within 1 count on %d/%d scenes (%.4f%%), identical on %d, "
      "different status/model on %d\n",
      within_one, total, 100 * rate, identical, status_mismatch);
  RecordProperty("float_double_within_one_rate", std::to_string(rate));
  EXPECT_GE(rate, 0.999);
}

// The figures asked for: QP iterations (median, max) per k and the share of scenes whose
// requested model was infeasible, for the paper model and for the normal model.
TEST(Properties, IterationAndFallbackFigures) {
  for (int k : {3, 4}) {
    for (gg::ConstraintModel model : {gg::ConstraintModel::kPaper, gg::ConstraintModel::kNormal}) {
      std::mt19937_64 rng(100 + k);
      std::vector<int> iterations;
      int to_normal = 0, to_none = 0;
      const int total = 10000;
      for (int n = 0; n < total; ++n) {
        const auto s = random_scene(rng, k);
        auto scene = graspguide_test::make_scene<double>(s, model, gg::Policy::kF, gg::Mode::kC);
        scene.solver.warm_start = false;
        const auto r = solve_once<double>(scene, s.wrench, s.orientation);
        ASSERT_EQ(r.status, gg::Status::kOk);
        iterations.push_back(r.grasp.iterations);
        if (r.grasp.used != model)
          (r.grasp.used == gg::ConstraintModel::kNormal ? to_normal : to_none)++;
      }
      std::sort(iterations.begin(), iterations.end());
      const int median = iterations[total / 2], worst = iterations.back();
      std::printf(
          "k=%d model=%s: QP iterations median %d max %d (cold); fell back to normal "
          "%.1f%%, to none %.1f%% of %d scenes\n",
          k, gg::constraint_model_name(model), median, worst, 100.0 * to_normal / total,
          100.0 * to_none / total, total);
      EXPECT_LE(worst, gg::kDefaultMaxIterations);
    }
  }
}
