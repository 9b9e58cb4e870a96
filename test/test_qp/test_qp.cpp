// The active-set solver on problems with known answers, degenerate vertices, infeasible
// sets, its iteration cap and warm starts; then KKT checks on random degenerate problems.
#include <gtest/gtest.h>

#include <random>

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
