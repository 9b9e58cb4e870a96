// A dual active-set solver (Goldfarb-Idnani) for the one QP this project needs:
//   min 1/2 |x - x_u|^2  subject to  A x >= b   (unit Hessian, n <= 6, m <= 12).
// It starts from the unconstrained optimum (always dual feasible) and adds violated
// constraints one at a time. A row that depends on the active rows never produces a
// primal step, only a dual step or an infeasibility certificate, which is what makes it
// correct on the degenerate vertices of the paper's constraint model.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "graspguide/eigen_decompositions.h"
#include "graspguide/status.h"
#include "graspguide/types.h"

namespace graspguide {

template <typename T, int N, int M>
struct ProjectionQp {
  Eigen::Matrix<T, M, N> a;   // rows 0..m-1 used
  Eigen::Matrix<T, M, 1> b;
  int m = 0;
  Eigen::Matrix<T, N, 1> x_unconstrained;
  T violation_tol = T(0);     // a constraint counts as violated below b - violation_tol
  T dependent_tol = T(0);     // |projection of a row| below this times the largest row
                              // norm: the row depends on the active rows
};

struct QpInfo {
  int iterations = 0;    // active-set changes (additions and removals)
  uint16_t active = 0;   // bit j: constraint j active at the solution
};

namespace detail {

// Active rows of A as columns, factorised by Householder QR; all sizes bounded by N.
template <typename T, int N>
struct ActiveFactor {
  using Cols = Eigen::Matrix<T, N, Eigen::Dynamic, 0, N, N>;
  using Vec = Eigen::Matrix<T, N, 1>;
  using Small = Eigen::Matrix<T, Eigen::Dynamic, 1, 0, N, 1>;

  Eigen::HouseholderQR<Cols> qr;
  Cols cols;
  int q = 0;

  template <typename RowsA>
  void build(const RowsA& a, const int* idx, int count) {
    q = count;
    cols.resize(N, q);
    for (int i = 0; i < q; ++i) cols.col(i) = a.row(idx[i]).transpose();
    if (q > 0) qr.compute(cols);
  }

  // z: part of v orthogonal to the active rows; r: coefficients with A_W^T r = v - z.
  void split(const Vec& v, Vec& z, Small& r) const {
    r.resize(q);
    if (q == 0) { z = v; return; }
    Vec t = v;
    t.applyOnTheLeft(qr.householderQ().transpose());
    r = t.head(q);
    qr.matrixQR().topLeftCorner(q, q).template triangularView<Eigen::Upper>().solveInPlace(r);
    t.head(q).setZero();
    t.applyOnTheLeft(qr.householderQ());
    z = t;
  }

  // Solve A_W A_W^T u = rhs, i.e. R^T R u = rhs, and return A_W^T u.
  void project(const Small& rhs, Small& u, Vec& step) const {
    u = rhs;
    const auto r = qr.matrixQR().topLeftCorner(q, q).template triangularView<Eigen::Upper>();
    r.transpose().solveInPlace(u);
    Vec t = Vec::Zero();
    t.head(q) = u;
    r.solveInPlace(u);
    t.applyOnTheLeft(qr.householderQ());
    step = t;
  }
};

}  // namespace detail

// warm_active: constraints active at the previous solution (bit mask), or 0 for a cold
// start. Returns kOk, kQpInfeasible or kQpIterationLimit; x is valid only on kOk.
template <typename T, int N, int M>
Status solve_projection(const ProjectionQp<T, N, M>& p, int max_iterations, uint16_t warm_active,
                        Eigen::Matrix<T, N, 1>& x, QpInfo& info) {
  static_assert(M <= 16, "active set is a 16-bit mask");
  using Vec = Eigen::Matrix<T, N, 1>;
  using Small = typename detail::ActiveFactor<T, N>::Small;
  const T inf = std::numeric_limits<T>::infinity();

  detail::ActiveFactor<T, N> f;
  int w[N];        // active constraint indices
  T u[N + 1];      // their multipliers (plus room for a candidate)
  int q = 0;
  info = QpInfo{};
  x = p.x_unconstrained;
  // Dependence is judged against the largest row, not the row itself: a row that is
  // rounding noise (a force component fixed by equilibrium) must count as dependent,
  // or its 1e-16 norm would turn into a 1e32 step.
  T row_scale = T(0);
  for (int j = 0; j < p.m; ++j) row_scale = std::max(row_scale, p.a.row(j).norm());
  const T dependent_below = p.dependent_tol * row_scale;

  // Warm start: project onto the previous active set, keep the independent rows, and drop
  // rows with negative multipliers until the pair (x, u) is dual feasible again.
  if (warm_active != 0) {
    Vec z;
    Small r;
    for (int j = 0; j < p.m && q < N; ++j) {
      if (!(warm_active & (1u << j))) continue;
      f.build(p.a, w, q);
      const Vec aj = p.a.row(j).transpose();
      f.split(aj, z, r);
      if (z.norm() > dependent_below) w[q++] = j;
    }
    while (q > 0) {
      f.build(p.a, w, q);
      Small rhs(q), mult(q);
      for (int i = 0; i < q; ++i) rhs(i) = p.b(w[i]) - p.a.row(w[i]).dot(p.x_unconstrained);
      Vec step;
      f.project(rhs, mult, step);
      int worst = -1;
      for (int i = 0; i < q; ++i)
        if (mult(i) < T(0) && (worst < 0 || mult(i) < mult(worst))) worst = i;
      if (worst < 0) {
        x = p.x_unconstrained + step;
        for (int i = 0; i < q; ++i) u[i] = mult(i);
        break;
      }
      for (int i = worst; i + 1 < q; ++i) w[i] = w[i + 1];
      --q;
    }
    if (q == 0) x = p.x_unconstrained;
  }

  for (;;) {
    // Most violated inactive constraint (lowest index on ties).
    int cand = -1;
    T worst = -p.violation_tol;
    for (int j = 0; j < p.m; ++j) {
      bool active = false;
      for (int i = 0; i < q; ++i) active = active || w[i] == j;
      if (active) continue;
      const T s = p.a.row(j).dot(x) - p.b(j);
      if (s < worst) { worst = s; cand = j; }
    }
    if (cand < 0) break;

    const Vec ap = p.a.row(cand).transpose();
    T u_cand = T(0);
    for (;;) {
      if (++info.iterations > max_iterations) return Status::kQpIterationLimit;
      f.build(p.a, w, q);
      Vec z;
      Small r;
      f.split(ap, z, r);
      const T z_norm = z.norm();
      const bool dependent = !(z_norm > dependent_below);

      // Dual step limit: the first active multiplier to reach zero.
      T t_dual = inf;
      int drop = -1;
      for (int i = 0; i < q; ++i) {
        if (r(i) > T(0)) {
          const T ratio = u[i] / r(i);
          if (ratio < t_dual) { t_dual = ratio; drop = i; }
        }
      }
      const T s = ap.dot(x) - p.b(cand);
      const T t_primal = dependent ? inf : -s / (z_norm * z_norm);
      if (dependent && drop < 0) return Status::kQpInfeasible;

      const T t = t_primal <= t_dual ? t_primal : t_dual;
      if (!dependent) x.noalias() += t * z;
      for (int i = 0; i < q; ++i) u[i] -= t * r(i);
      u_cand += t;

      if (t_primal <= t_dual) {  // full step: the candidate becomes active
        w[q] = cand;
        u[q] = u_cand;
        ++q;
        break;
      }
      for (int i = drop; i + 1 < q; ++i) { w[i] = w[i + 1]; u[i] = u[i + 1]; }
      --q;  // a partial step leaves the candidate violated: keep going with it
    }
  }
  for (int i = 0; i < q; ++i) info.active = static_cast<uint16_t>(info.active | (1u << w[i]));
  return x.allFinite() ? Status::kOk : Status::kNonFiniteInput;
}

// Defined once in projection_qp.cpp (EXTERN empty), extern everywhere else: 3 or 6
// variables with 9 or 12 rows.
#define GRASPGUIDE_PROJECTION_QP(EXTERN, T, N, M)                                             \
  EXTERN template Status solve_projection<T, N, M>(const ProjectionQp<T, N, M>&, int, uint16_t, \
                                                   Eigen::Matrix<T, N, 1>&, QpInfo&);
#define GRASPGUIDE_PROJECTION_QPS(EXTERN)                                                    \
  GRASPGUIDE_PROJECTION_QP(EXTERN, float, 3, 9) GRASPGUIDE_PROJECTION_QP(EXTERN, float, 6, 12) \
  GRASPGUIDE_PROJECTION_QP(EXTERN, double, 3, 9) GRASPGUIDE_PROJECTION_QP(EXTERN, double, 6, 12)
#ifndef GRASPGUIDE_INSTANTIATING_PROJECTION_QP
GRASPGUIDE_PROJECTION_QPS(extern)
#endif

}  // namespace graspguide
