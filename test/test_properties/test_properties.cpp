// Properties on thousands of random hand-like scenes: equilibrium, constraints, QP
// optimality (KKT, and the same optimum as the SVD route), invariance to units and to
// rotating the scene, float vs double agreement (hard scenes among them). Prints the
// figures behind docs/performance.md.
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

// Recomputes steps 2-5 of solve_grasp on the structured route and checks the QP's
// optimality conditions in the SVD route's null-space coordinates (lambda = lambda0 + N xi,
// rows N_j xi >= -lambda0_j), then the optimum itself against the SVD route's solver: the
// objective is strictly convex, so both must find the same point.
template <int K>
void check_qp_optimality(const RandomScene& s, gg::ConstraintModel requested) {
  gg::ContactFrames<double, K> f;
  ASSERT_EQ((gg::contact_frames<double, K>(s.contacts.leftCols<K>(), gg::Vec3<double>::UnitY(), f)),
            gg::Status::kOk);
  gg::GraspMat<double, K> g;
  gg::grasp_matrix<double, K>(f, g);
  const gg::Vec6<double> w = gg::scaled_wrench<double>(s.wrench, f.length_scale);
  gg::GraspStructure<double, K> st;
  ASSERT_EQ((gg::grasp_structure<double, K>(f, st)), gg::Status::kOk);
  const gg::Vec6<double> w_hat = gg::whitened_wrench<double, K>(st, w);
  const gg::ForceVec<double, K> lambda0 = gg::min_norm_forces<double, K>(st, w_hat);
  const auto des =
      gg::desired_forces<double, K>(lambda0, gg::relevance<double, K>(f, s.wrench.head<3>()));
  const auto start = gg::project_onto_equilibrium<double, K>(st, w_hat, des);
  gg::ForceSolution<double, K> sol;
  ASSERT_EQ((gg::solve_forces<double, K>(f, st, w, lambda0, start, requested, 64, sol)),
            gg::Status::kOk);
  const double scale = lambda0.norm();
  // The solver's own feasibility tolerance grows with |lambda| (force_qp.h).
  const double feas = 1e-9 * (scale + sol.lambda.norm());
  // Equilibrium of the final forces.
  // (relative to the forces too: a paper optimum can hold internal forces far above w).
  EXPECT_LT((g * sol.lambda + w).norm(), 1e-10 * (w.norm() + sol.lambda.norm()));
  // Constraints of the model used.
  const uint16_t constrained = gg::constrained_bits<K>(sol.used);
  for (int j = 0; j < 3 * K; ++j)
    if (constrained & (1u << j)) {
      EXPECT_GE(sol.lambda(j), -feas) << j;
    }
  EXPECT_EQ(sol.active & ~constrained, 0);

  gg::Equilibrium<double, K> eq;
  ASSERT_EQ((gg::equilibrium_svd<double, K>(g, w, eq)), gg::Status::kOk);
  const Eigen::Matrix<double, 3 * K - 6, 1> xi =
      eq.null_basis.transpose() * (sol.lambda - eq.lambda0);
  const Eigen::Matrix<double, 3 * K - 6, 1> xu = eq.null_basis.transpose() * (des - eq.lambda0);
  // Stationarity: xi - xu is a combination of the active rows, with non-negative
  // multipliers wherever those rows are independent (at a degenerate vertex the split
  // between dependent rows is not unique; the comparison below covers those).
  Eigen::Matrix<double, 3 * K - 6, Eigen::Dynamic> aw(3 * K - 6, 0);
  for (int j = 0; j < 3 * K; ++j)
    if (sol.active & (1u << j)) {
      aw.conservativeResize(Eigen::NoChange, aw.cols() + 1);
      aw.col(aw.cols() - 1) = eq.null_basis.row(j).transpose();
      EXPECT_NEAR(sol.lambda(j), 0.0, feas) << j;
    }
  const Eigen::Matrix<double, 3 * K - 6, 1> grad = xi - xu;
  if (aw.cols() == 0) {
    EXPECT_LT(grad.norm(), 1e-9);
  } else {
    const auto qr = aw.colPivHouseholderQr();
    const Eigen::VectorXd mu = qr.solve(grad);
    EXPECT_LT((aw * mu - grad).norm(), 1e-8);
    // x rows that paper_x_rows held as equalities may carry either sign: the implied row
    // they depend on, left out of the active set, is what makes the true multipliers
    // non-negative. Those scenes rest on the comparison with the SVD route below.
    uint16_t fixed = 0, implied = 0;
    if (sol.used == gg::ConstraintModel::kPaper)
      gg::paper_x_rows<double, K>(f, w, gg::Tolerances<double>::kFeasRelTol * scale, fixed,
                                  implied);
    if (qr.rank() == aw.cols() && fixed == 0) {
      EXPECT_GE(mu.minCoeff(), -1e-8);
    }
  }
  // The same optimum and model from the SVD route.
  gg::ForceVec<double, K> reference;
  gg::ConstraintModel used = gg::ConstraintModel::kNone;
  int iterations = 0;
  ASSERT_EQ((gg::solve_forces_svd<double, K>(eq, des, requested, 64, reference, used, iterations)),
            gg::Status::kOk);
  EXPECT_EQ(used, sol.used);
  if (used == sol.used) {
    EXPECT_LT((reference - sol.lambda).norm(), 1e-8 * (1 + reference.norm()));
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

// Hard paper scenes: feasible far from any boundary with the x components at 0, yet a
// float solve can leave them for the normal model. The 'hard' list of
// test/data/hard_hands.json; contacts one per row.
struct HardScene {
  int k;
  double contacts[4][3];
  double wrench[6];
  gg::Policy policy;
};
const HardScene kHardScenes[] = {
    {3,
     {{0.037160008319188385, -0.006663045636920981, 0.03561343252834991},
      {-0.017240429598094464, 0.03316225500504811, 0.0726847032889959},
      {-0.04111005169831705, 0.02374787286847652, 0.08889877899351581},
      {0, 0, 0}},
     {0.05011938700819065, -0.90833882635023, 0.4152211743042617, 0.0, 0.0, 0.0},
     gg::Policy::kF},
    {4,
     {{0.026021286914099086, -0.0059804942656404465, 0.03608174726920736},
      {-0.017752846672399156, 0.033504278900886336, 0.10057581130065865},
      {-0.005245938860003265, 0.02285893468057164, 0.08721554585243048},
      {-0.01293648934799525, 0.01799662072362494, 0.0031679601016966225}},
     {0.6299175468687046, 0.5157666743207229, 0.5806794484111306, 0.0, 0.0, 0.0},
     gg::Policy::kFperp},
    {4,
     {{0.02144295669267866, 0.003228034458116806, 0.0537821843363604},
      {-0.010091286803572665, 0.0169718060081644, 0.08245404972988006},
      {-0.015464190756852349, 0.019785910219387033, 0.0838414216740177},
      {0.012756194163362074, 0.018304109319914094, -0.010414226068240941}},
     {0.9782489579532001, 0.18817261042920472, 0.08729286882521928, 0.0, 0.0, 0.0},
     gg::Policy::kFperp},
    {4,
     {{0.017736046591935707, -0.017874790243182767, 0.04796200469174857},
      {-0.0037583453062300176, 0.013672038860695866, 0.09953894068831734},
      {-0.030748993589733827, 0.03278436423272373, 0.09848311313920391},
      {-0.009559894374844042, -0.013621707542602215, -0.000633945167161061}},
     {0.8932893449984581, 0.4494199829925745, 0.007471612890110519, 0.0, 0.0, 0.0},
     gg::Policy::kFperp},
    {4,
     {{0.052111615480191394, -0.017894334473437964, 0.048440007547803886},
      {0.0005858686822280846, 0.007351937482093906, 0.09949963804503763},
      {-0.025240860453715257, 0.01997191344484333, 0.11965971933978242},
      {-0.001004548279657875, 0.010441876353048026, 0.0016898528550637372}},
     {-0.46756594743893604, 0.798541208959943, 0.3790963233642907, 0.0, 0.0, 0.0},
     gg::Policy::kF},
    {3,
     {{0.031233355405583037, -0.024828400445275765, 0.04082444114975877},
      {-0.024134785697345375, 0.036066336143056356, 0.09368925448559674},
      {-0.005099892551420373, 0.03642351649639351, 0.07553558088243889},
      {0, 0, 0}},
     {0.41003746606116803, 0.774996008485761, 0.48088508321352064, 0.0, 0.0, 0.0},
     gg::Policy::kF},
    {3,
     {{0.018988089669727135, -0.02156155839971737, 0.07072436162089805},
      {-0.006957461629819441, 0.01327627653985124, 0.07887631986409734},
      {-0.03674863778233608, 0.014746335245659641, 0.08732744870040714},
      {0, 0, 0}},
     {0.5682668371035152, 0.46496849751003344, 0.6788792957305657, 0.0, 0.0, 0.0},
     gg::Policy::kFperp},
    {4,
     {{0.03136941810723063, -0.003441462612596726, 0.03546189440136882},
      {0.00868817482604326, 0.025396914609376278, 0.102446516879868},
      {-0.04998238781538508, 0.01844017207267333, 0.07371293370060483},
      {-0.007713261682358435, -0.011281163647774756, 0.008342018392464937}},
     {0.7978405395726501, 0.00048780375371939005, -0.6028683400726235, 0.0, 0.0, 0.0},
     gg::Policy::kFperp},
};

TEST(Properties, HardScenesGiveTheSameModelAndPwmInFloatAndDouble) {
  for (const auto& scene : kHardScenes) {
    RandomScene r;
    r.k = scene.k;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 3; ++j) r.contacts(j, i) = scene.contacts[i][j];
    for (int j = 0; j < 6; ++j) r.wrench(j) = scene.wrench[j];
    r.orientation << 1, 0, 0, 0;
    const auto d =
        solve_once<double>(graspguide_test::make_scene<double>(r, gg::ConstraintModel::kPaper,
                                                               scene.policy, gg::Mode::kC),
                           r.wrench, r.orientation);
    // Float's own QP, the retry in double switched off: it holds these hands by itself.
    // With the retry on (the default), 5 of the 8 run again in double, because float's
    // forces, 1,500 to 21,000 |lambda0|, miss equilibrium by more than 1e-2 |lambda0|
    // (answer_certificate.h).
    auto float_scene = graspguide_test::make_scene<float>(r, gg::ConstraintModel::kPaper,
                                                          scene.policy, gg::Mode::kC);
    float_scene.solver.double_retry = false;
    const auto f = solve_once<float>(float_scene, r.wrench, r.orientation);
    const int n = static_cast<int>(&scene - kHardScenes);
    ASSERT_EQ(d.status, gg::Status::kOk) << n;
    ASSERT_EQ(f.status, gg::Status::kOk) << n;
    EXPECT_EQ(d.grasp.used, gg::ConstraintModel::kPaper) << n;
    EXPECT_EQ(f.grasp.used, d.grasp.used) << n;
    EXPECT_LE(graspguide_test::max_pwm_diff(d.frame.pwm, f.frame.pwm), 1) << n;
    EXPECT_FALSE(f.grasp.retried) << n;
  }
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
        const auto r = solve_once<double>(scene, s.wrench, s.orientation);
        ASSERT_EQ(r.status, gg::Status::kOk);
        iterations.push_back(r.grasp.iterations);
        if (r.grasp.used != model)
          (r.grasp.used == gg::ConstraintModel::kNormal ? to_normal : to_none)++;
      }
      std::sort(iterations.begin(), iterations.end());
      const int median = iterations[total / 2], worst = iterations.back();
      std::printf(
          "k=%d model=%s: QP iterations median %d max %d ; fell back to normal "
          "%.1f%%, to none %.1f%% of %d scenes\n",
          k, gg::constraint_model_name(model), median, worst, 100.0 * to_normal / total,
          100.0 * to_none / total, total);
      EXPECT_LE(worst, gg::kDefaultMaxIterations);
    }
  }
}
