// The SVD route's active-set solver (projection_qp.h) on problems with known answers,
// degenerate vertices, infeasible sets, its iteration cap and warm starts, then KKT checks
// on random degenerate problems; the structured route's solver (force_qp.h) on hand scenes:
// infeasible sets, its iteration cap and rows that depend on the active ones.
#include <gtest/gtest.h>

#include <random>

#include "common/hand_scenes.h"
#include "graspguide.h"
#include "graspguide/projection_qp.h"

namespace gg = graspguide;

template <typename T, int N, int M>
gg::ProjectionQp<T, N, M> problem(std::initializer_list<std::initializer_list<double>> rows,
                                  std::initializer_list<double> b,
                                  std::initializer_list<double> xu) {
  gg::ProjectionQp<T, N, M> p;
  p.a.setZero();
  p.b.setZero();
  int r = 0;
  for (const auto& row : rows) {
    int c = 0;
    for (double v : row) p.a(r, c++) = T(v);
    ++r;
  }
  p.m = r;
  r = 0;
  for (double v : b) p.b(r++) = T(v);
  r = 0;
  for (double v : xu) p.x_unconstrained(r++) = T(v);
  p.violation_tol = T(1e-9);
  p.dependent_tol = T(1e-9);
  return p;
}

using P3 = gg::ProjectionQp<double, 3, 9>;
using V3 = Eigen::Vector3d;

TEST(ProjectionQp, FeasibleUnconstrainedOptimumTakesNoIteration) {
  auto p = problem<double, 3, 9>({{1, 0, 0}, {0, 1, 0}}, {0, 0}, {1, 2, 3});
  V3 x;
  gg::QpInfo info;
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 10, 0, x, info)), gg::Status::kOk);
  EXPECT_TRUE(x.isApprox(V3(1, 2, 3)));
  EXPECT_EQ(info.iterations, 0);
  EXPECT_EQ(info.active, 0);
}

TEST(ProjectionQp, ProjectionOntoAHalfSpace) {
  // x + y + z >= 3 from the origin: the foot of the perpendicular is (1, 1, 1).
  auto p = problem<double, 3, 9>({{1, 1, 1}}, {3}, {0, 0, 0});
  V3 x;
  gg::QpInfo info;
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 10, 0, x, info)), gg::Status::kOk);
  EXPECT_TRUE(x.isApprox(V3(1, 1, 1), 1e-12));
  EXPECT_EQ(info.active, 1);
}

TEST(ProjectionQp, BoxProjectionClamps) {
  auto p =
      problem<double, 3, 9>({{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}},
                            {0, -1, 0, -1, 0, -1}, {-2, 0.5, 7});
  V3 x;
  gg::QpInfo info;
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 20, 0, x, info)), gg::Status::kOk);
  EXPECT_TRUE(x.isApprox(V3(0, 0.5, 1), 1e-12));
}

TEST(ProjectionQp, DegenerateVertexWithMoreActiveConstraintsThanVariables) {
  // x >= 0, y >= 0, -x - y >= 0 and z >= 0 twice: the set in (x, y) is the single point 0,
  // as the paper model's x-components are. Five active rows, three variables.
  auto p = problem<double, 3, 9>({{1, 0, 0}, {0, 1, 0}, {-1, -1, 0}, {0, 0, 1}, {0, 0, 1}},
                                 {0, 0, 0, 0, 0}, {1, 2, -3});
  V3 x;
  gg::QpInfo info;
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 20, 0, x, info)), gg::Status::kOk);
  EXPECT_LT(x.norm(), 1e-12);
  EXPECT_LE(__builtin_popcount(info.active), 3);  // never more active rows than variables
}

TEST(ProjectionQp, DependentRowsInFloatDoNotBreakIt) {
  // Three rows with c1 a1 + c2 a2 + c3 a3 = 0 up to float rounding, b = 0: a flat set.
  using P = gg::ProjectionQp<float, 3, 9>;
  P p;
  p.a.setZero();
  p.b.setZero();
  const Eigen::Vector3f a1(0.3f, -0.7f, 0.2f), a2(-0.1f, 0.4f, 0.5f);
  p.a.row(0) = a1.transpose();
  p.a.row(1) = a2.transpose();
  p.a.row(2) = (-(0.7f * a1 + 1.3f * a2) / 0.9f).transpose();
  p.m = 3;
  p.x_unconstrained = Eigen::Vector3f(1.f, -2.f, 0.5f);
  p.violation_tol = 1e-4f;
  p.dependent_tol = 1e-4f;
  Eigen::Vector3f x;
  gg::QpInfo info;
  ASSERT_EQ((gg::solve_projection<float, 3, 9>(p, 20, 0, x, info)), gg::Status::kOk);
  for (int j = 0; j < 3; ++j) EXPECT_GT(p.a.row(j).dot(x), -1e-4f);
  // The answer is the projection onto the line {a1.x = 0, a2.x = 0}.
  Eigen::Vector3f dir = a1.cross(a2).normalized();
  EXPECT_TRUE(x.isApprox(dir * dir.dot(p.x_unconstrained), 1e-4f));
}

TEST(ProjectionQp, InfeasibleSetsAreReportedNotGuessed) {
  V3 x;
  gg::QpInfo info;
  auto p = problem<double, 3, 9>({{1, 0, 0}, {-1, 0, 0}}, {1, 0}, {0, 0, 0});  // x >= 1, x <= 0
  EXPECT_EQ((gg::solve_projection<double, 3, 9>(p, 20, 0, x, info)), gg::Status::kQpInfeasible);
  auto zero_row = problem<double, 3, 9>({{0, 0, 0}}, {1}, {0, 0, 0});  // 0 >= 1
  EXPECT_EQ((gg::solve_projection<double, 3, 9>(zero_row, 20, 0, x, info)),
            gg::Status::kQpInfeasible);
  auto harmless = problem<double, 3, 9>({{0, 0, 0}}, {-1}, {4, 5, 6});  // 0 >= -1
  EXPECT_EQ((gg::solve_projection<double, 3, 9>(harmless, 20, 0, x, info)), gg::Status::kOk);
  EXPECT_TRUE(x.isApprox(V3(4, 5, 6)));
  // A violation within the tolerance is not a violation.
  auto within = problem<double, 3, 9>({{1, 0, 0}, {-1, 0, 0}}, {1e-10, 0}, {-1, 0, 0});
  EXPECT_EQ((gg::solve_projection<double, 3, 9>(within, 20, 0, x, info)), gg::Status::kOk);
}

TEST(ProjectionQp, IterationCapIsAStatus) {
  auto p = problem<double, 3, 9>({{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {1, 1, 1}, {0, 0, 0});
  V3 x;
  gg::QpInfo info;
  EXPECT_EQ((gg::solve_projection<double, 3, 9>(p, 2, 0, x, info)), gg::Status::kQpIterationLimit);
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 3, 0, x, info)), gg::Status::kOk);
  EXPECT_TRUE(x.isApprox(V3(1, 1, 1)));
  EXPECT_EQ(info.iterations, 3);
}

TEST(ProjectionQp, WarmStartGivesTheSameAnswerInFewerIterations) {
  auto p =
      problem<double, 3, 9>({{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}}, {1, 1, 1, 0}, {0, 0, 0});
  V3 cold, warm, wrong;
  gg::QpInfo ci, wi, xi;
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 20, 0, cold, ci)), gg::Status::kOk);
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 20, ci.active, warm, wi)), gg::Status::kOk);
  EXPECT_TRUE(warm.isApprox(cold, 1e-12));
  EXPECT_EQ(wi.iterations, 0);
  EXPECT_GT(ci.iterations, 0);
  // A wrong guess (only the redundant row 3) still converges to the same point.
  ASSERT_EQ((gg::solve_projection<double, 3, 9>(p, 20, 1u << 3, wrong, xi)), gg::Status::kOk);
  EXPECT_TRUE(wrong.isApprox(cold, 1e-12));
}

// Random problems built to be degenerate (duplicated and dependent rows, flat sets) and
// checked against the KKT conditions of the projection.
template <int N, int M>
void kkt_on_random_problems(unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  std::uniform_int_distribution<int> rows(1, M);
  int feasible = 0, infeasible = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    gg::ProjectionQp<double, N, M> p;
    p.m = rows(rng);
    const Eigen::Matrix<double, N, 1> anchor =
        Eigen::Matrix<double, N, 1>::NullaryExpr([&] { return g(rng); });
    for (int j = 0; j < p.m; ++j) {
      for (int c = 0; c < N; ++c) p.a(j, c) = g(rng);
      if (j >= 2 && trial % 3 == 0) p.a.row(j) = -(p.a.row(j - 1) + 0.5 * p.a.row(j - 2));
      if (j >= 1 && trial % 5 == 0) p.a.row(j) = p.a.row(j - 1);
      // b through a common point keeps most problems feasible, some on a flat set.
      p.b(j) = p.a.row(j).dot(anchor) - (trial % 2 ? std::abs(g(rng)) : 0.0);
      if (trial % 7 == 0) p.b(j) += std::abs(g(rng));
    }
    p.x_unconstrained = Eigen::Matrix<double, N, 1>::NullaryExpr([&] { return 3 * g(rng); });
    p.violation_tol = 1e-9;
    p.dependent_tol = 1e-9;
    Eigen::Matrix<double, N, 1> x;
    gg::QpInfo info;
    const gg::Status s = gg::solve_projection<double, N, M>(p, 100, 0, x, info);
    ASSERT_NE(s, gg::Status::kQpIterationLimit) << trial;
    if (s == gg::Status::kQpInfeasible) {
      ++infeasible;
      // Infeasible only if the anchor itself violates a row (the anchor-built rows with a
      // non-negative shift are all satisfied by it).
      double worst = 0;
      for (int j = 0; j < p.m; ++j) worst = std::min(worst, p.a.row(j).dot(anchor) - p.b(j));
      EXPECT_LT(worst, -1e-9) << trial;
      continue;
    }
    ASSERT_EQ(s, gg::Status::kOk);
    ++feasible;
    // Primal feasibility.
    for (int j = 0; j < p.m; ++j) EXPECT_GE(p.a.row(j).dot(x) - p.b(j), -1e-8) << trial;
    // Stationarity with non-negative multipliers on the reported active set.
    Eigen::Matrix<double, N, Eigen::Dynamic> aw(N, 0);
    for (int j = 0; j < p.m; ++j)
      if (info.active & (1u << j)) {
        aw.conservativeResize(N, aw.cols() + 1);
        aw.col(aw.cols() - 1) = p.a.row(j).transpose();
        EXPECT_NEAR(p.a.row(j).dot(x), p.b(j), 1e-8) << trial;
      }
    const Eigen::Matrix<double, N, 1> grad = x - p.x_unconstrained;
    if (aw.cols() == 0) {
      EXPECT_LT(grad.norm(), 1e-9) << trial;
    } else {
      const Eigen::VectorXd mu = aw.colPivHouseholderQr().solve(grad);
      EXPECT_LT((aw * mu - grad).norm(), 1e-7 * (1 + grad.norm())) << trial;
      EXPECT_GE(mu.minCoeff(), -1e-7) << trial;
    }
    // Warm start from its own active set reproduces the answer.
    Eigen::Matrix<double, N, 1> again;
    gg::QpInfo info2;
    ASSERT_EQ((gg::solve_projection<double, N, M>(p, 100, info.active, again, info2)),
              gg::Status::kOk);
    EXPECT_LT((again - x).norm(), 1e-9 * (1 + x.norm())) << trial;
  }
  EXPECT_GT(feasible, 1000);
  EXPECT_GT(infeasible, 10);
}

TEST(ProjectionQp, KktHoldsOnRandomDegenerateProblems3x9) { kkt_on_random_problems<3, 9>(1); }
TEST(ProjectionQp, KktHoldsOnRandomDegenerateProblems6x12) { kkt_on_random_problems<6, 12>(2); }

// ---------------------------------------------------------------- force_qp.h

// A random hand scene ready for project_forces: frames, structure, wrench, the
// unconstrained optimum and the violation tolerance solve_forces would use.
template <int K>
struct ForceProblem {
  gg::ContactFrames<double, K> f;
  gg::GraspStructure<double, K> st;
  gg::Vec6<double> w;
  gg::ForceVec<double, K> lambda0, start;
  double violation_tol = 0;
};

template <int K>
ForceProblem<K> force_problem(const graspguide_test::RandomScene& s) {
  ForceProblem<K> p;
  EXPECT_EQ(
      (gg::contact_frames<double, K>(s.contacts.leftCols<K>(), gg::Vec3<double>::UnitY(), p.f)),
      gg::Status::kOk);
  EXPECT_EQ((gg::grasp_structure<double, K>(p.f, p.st)), gg::Status::kOk);
  p.w = gg::scaled_wrench<double>(s.wrench, p.f.length_scale);
  const gg::Vec6<double> w_hat = gg::whitened_wrench<double, K>(p.st, p.w);
  p.lambda0 = gg::min_norm_forces<double, K>(p.st, w_hat);
  const auto des =
      gg::desired_forces<double, K>(p.lambda0, gg::relevance<double, K>(p.f, s.wrench.head<3>()));
  p.start = gg::project_onto_equilibrium<double, K>(p.st, w_hat, des);
  p.violation_tol = gg::Tolerances<double>::kFeasRelTol * p.lambda0.norm();
  return p;
}

template <int K>
gg::Status project(const ForceProblem<K>& p, uint16_t constrained, uint16_t fixed, int max_it,
                   gg::ForceVec<double, K>& lambda, gg::QpInfo& info, int known = 0) {
  return gg::project_forces<double, K>(
      p.st, p.start, constrained, fixed, p.violation_tol, gg::Tolerances<double>::kFeasRelTol,
      gg::Tolerances<double>::kDependentRelTol, max_it, lambda, info, known);
}

// Where the SVD route's solver finds no point for a model, project_forces must say
// kQpInfeasible too rather than return a point.
TEST(ForceQp, InfeasibleModelsAreReportedLikeTheSvdRoute) {
  std::mt19937_64 rng(31);
  int infeasible = 0;
  for (int n = 0; n < 400; ++n) {
    const auto s = graspguide_test::random_scene(rng, 3);
    const auto p = force_problem<3>(s);
    gg::GraspMat<double, 3> g;
    gg::grasp_matrix<double, 3>(p.f, g);
    gg::Equilibrium<double, 3> eq;
    ASSERT_EQ((gg::equilibrium_svd<double, 3>(g, p.w, eq)), gg::Status::kOk);
    gg::ForceVec<double, 3> reference, lambda;
    gg::ConstraintModel used = gg::ConstraintModel::kNone;
    int iterations = 0;
    ASSERT_EQ((gg::solve_forces_svd<double, 3>(eq, p.start, gg::ConstraintModel::kPaper, 64,
                                               reference, used, iterations)),
              gg::Status::kOk);
    if (used == gg::ConstraintModel::kPaper) continue;
    ++infeasible;
    gg::QpInfo info;
    EXPECT_EQ(
        project<3>(p, gg::constrained_bits<3>(gg::ConstraintModel::kPaper), 0, 64, lambda, info),
        gg::Status::kQpInfeasible)
        << n;
  }
  EXPECT_GT(infeasible, 5);
}

TEST(ForceQp, IterationCapIsAStatus) {
  std::mt19937_64 rng(32);
  int capped = 0;
  for (int n = 0; n < 200; ++n) {
    const auto p = force_problem<4>(graspguide_test::random_scene(rng, 4));
    const uint16_t normal = gg::constrained_bits<4>(gg::ConstraintModel::kNormal);
    gg::ForceVec<double, 4> lambda, again;
    gg::QpInfo info, info2;
    if (project<4>(p, normal, 0, 64, lambda, info) != gg::Status::kOk || info.iterations < 2)
      continue;
    ++capped;
    EXPECT_EQ(project<4>(p, normal, 0, info.iterations - 1, again, info2),
              gg::Status::kQpIterationLimit);
    ASSERT_EQ(project<4>(p, normal, 0, info.iterations, again, info2), gg::Status::kOk);
    EXPECT_EQ(info2.iterations, info.iterations);
    EXPECT_EQ((again - lambda).norm(), 0.0);
  }
  EXPECT_GT(capped, 10);
}

// The feasibility tolerance judges infeasibility only; it is not where the iterations
// stop. With a tolerance 1e7 times wider (1e-2 |lambda0|) every model that holds within
// the tight one reaches the same optimum: a violation the tolerance allows still takes its
// primal or dual step: a float iterate stopped there is one dual step short of the
// optimum, a motor off instead of on.
TEST(ForceQp, TheToleranceDoesNotStopTheIterationsEarly) {
  std::mt19937_64 rng(35);
  int moved = 0, compared = 0;
  for (int n = 0; n < 400; ++n) {
    auto s = graspguide_test::random_scene(rng, 3 + n % 2);
    s.wrench.tail<3>().setZero();
    const auto check = [&](auto k_tag) {
      constexpr int K = decltype(k_tag)::value;
      auto p = force_problem<K>(s);
      uint16_t fixed = 0, implied = 0;
      ASSERT_EQ((gg::paper_x_rows<double, K>(p.f, p.w, p.violation_tol, fixed, implied)),
                gg::Status::kOk);
      const auto x_rows = static_cast<uint16_t>(fixed | implied);
      for (const auto model : {gg::ConstraintModel::kPaper, gg::ConstraintModel::kNormal}) {
        const uint16_t held = model == gg::ConstraintModel::kPaper ? x_rows : 0;
        const int known = model == gg::ConstraintModel::kPaper && implied != 0 ? 1 : 0;
        gg::ForceVec<double, K> tight, loose;
        gg::QpInfo i1, i2;
        if (project<K>(p, gg::constrained_bits<K>(model), held, 64, tight, i1, known) !=
            gg::Status::kOk)
          continue;
        auto wide = p;
        wide.violation_tol = 1e-2 * p.lambda0.norm();
        ASSERT_EQ(project<K>(wide, gg::constrained_bits<K>(model), held, 64, loose, i2, known),
                  gg::Status::kOk)
            << n;
        EXPECT_LT((loose - tight).norm(), 1e-9 * (1 + tight.norm())) << n;
        ++compared;
        // The scenes where a step is taken at all within the wide tolerance.
        bool small = false;
        for (int j = 0; j < 3 * K; ++j)
          small = small || (p.start(j) < 0 && p.start(j) > -wide.violation_tol);
        moved += small;
      }
    };
    if (s.k == 3)
      check(std::integral_constant<int, 3>());
    else
      check(std::integral_constant<int, 4>());
  }
  EXPECT_GT(compared, 300);
  EXPECT_GT(moved, 10);
}

// A dependence the caller vouches for (the moment row about y_O, which paper_x_rows
// decided) skips only its own right-hand-side check: with no moment the answer is the
// one the check gives, and a second dependent row, here from holding contact 0 off as
// well, is still checked and contradicts equilibrium.
TEST(ForceQp, AKnownDependenceSkipsOnlyItsOwnCheck) {
  std::mt19937_64 rng(34);
  int same = 0, contradicted = 0;
  for (int n = 0; n < 200; ++n) {
    auto s = graspguide_test::random_scene(rng, 3);
    s.wrench.tail<3>().setZero();
    const auto p = force_problem<3>(s);
    uint16_t fixed = 0, implied = 0;
    ASSERT_EQ((gg::paper_x_rows<double, 3>(p.f, p.w, p.violation_tol, fixed, implied)),
              gg::Status::kOk);
    const uint16_t paper = gg::constrained_bits<3>(gg::ConstraintModel::kPaper);
    const auto x_rows = static_cast<uint16_t>(fixed | implied);
    gg::ForceVec<double, 3> checked, vouched;
    gg::QpInfo i1, i2;
    const gg::Status s1 = project<3>(p, paper, x_rows, 64, checked, i1, 0);
    const gg::Status s2 = project<3>(p, paper, x_rows, 64, vouched, i2, 1);
    EXPECT_EQ(s2, s1) << n;
    if (s1 == gg::Status::kOk && s2 == gg::Status::kOk) {
      EXPECT_EQ((vouched - checked).norm(), 0.0) << n;
      ++same;
    }
    // Contact 0 held off too: 5 rows held, 4 free directions for G's 6 rows, so two
    // dependences, and equilibrium cannot hold with contact 0 off and every x at 0.
    const auto off = static_cast<uint16_t>(x_rows | 0x7u);
    EXPECT_EQ(project<3>(p, paper, off, 64, vouched, i2, 1), gg::Status::kQpInfeasible) << n;
    ++contradicted;
  }
  EXPECT_GT(same, 50);
  EXPECT_EQ(contradicted, 200);
}

// With no moment about y_O every x component of the paper model is 0, and the x rows
// depend on each other (and on equilibrium). Holding them all as equalities meets the last
// one as a dependent row; leaving them as plain inequalities meets them through degenerate
// steps. Both must reach the optimum paper_x_rows' split reaches.
TEST(ForceQp, DependentRowsGiveTheSameOptimum) {
  std::mt19937_64 rng(33);
  int checked = 0;
  for (int n = 0; n < 400; ++n) {
    auto s = graspguide_test::random_scene(rng, 3 + n % 2);
    s.wrench.tail<3>().setZero();
    const auto check = [&](auto k_tag) {
      constexpr int K = decltype(k_tag)::value;
      const auto p = force_problem<K>(s);
      uint16_t fixed = 0, implied = 0;
      ASSERT_EQ((gg::paper_x_rows<double, K>(p.f, p.w, p.violation_tol, fixed, implied)),
                gg::Status::kOk);
      ASSERT_NE(implied, 0);
      const uint16_t paper = gg::constrained_bits<K>(gg::ConstraintModel::kPaper);
      gg::ForceVec<double, K> split, all_fixed, plain;
      gg::QpInfo i1, i2, i3;
      const gg::Status s1 =
          project<K>(p, static_cast<uint16_t>(paper & ~implied), fixed, 64, split, i1);
      const gg::Status s2 =
          project<K>(p, paper, static_cast<uint16_t>(fixed | implied), 64, all_fixed, i2);
      const gg::Status s3 = project<K>(p, paper, 0, 64, plain, i3);
      EXPECT_EQ(s2, s1) << n;
      EXPECT_EQ(s3, s1) << n;
      if (s1 != gg::Status::kOk) return;
      ++checked;
      // All k x rows are held (reported active); it is the moment row about y_O that
      // depends on them and drops out of the equalities.
      EXPECT_EQ(__builtin_popcount(i2.active & gg::axis_bits<K>(0)), K) << n;
      const double scale = 1 + split.norm();
      if (s2 == gg::Status::kOk) {
        EXPECT_LT((all_fixed - split).norm(), 1e-8 * scale) << n;
      }
      if (s3 == gg::Status::kOk) {
        EXPECT_LT((plain - split).norm(), 1e-8 * scale) << n;
      }
      for (int i = 0; i < K; ++i) EXPECT_NEAR(split(3 * i), 0.0, 1e-9 * scale) << n;
    };
    if (s.k == 3)
      check(std::integral_constant<int, 3>());
    else
      check(std::integral_constant<int, 4>());
  }
  EXPECT_GT(checked, 50);
}
