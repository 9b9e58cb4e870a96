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
#include "graspguide/qp_info.h"
#include "graspguide/status.h"
#include "graspguide/types.h"

namespace graspguide {

template <typename T, int N, int M>
struct ProjectionQp {
  Eigen::Matrix<T, M, N> a;  // rows 0..m-1 used
  Eigen::Matrix<T, M, 1> b;
  int m = 0;
  Eigen::Matrix<T, N, 1> x_unconstrained;
  T violation_tol = T(0);  // a constraint counts as violated below b - violation_tol
  T dependent_tol = T(0);  // |projection of a row| below this times the largest row
                           // norm: the row depends on the active rows
};

namespace detail {

// The active rows as columns, A_W^T = J [R; 0]: J orthogonal, R upper triangular, both
// N x N and updated by Givens rotations when a row enters or leaves (Goldfarb-Idnani's
// own scheme for a unit Hessian), instead of refactorising the active set in every
// iteration. R holds the identity outside its leading q x q block, so that fixed-size
// triangular solves act on that block and leave the rest alone: every size is fixed at
// compile time, and Eigen unrolls them instead of calling its run-time-sized kernels.
template <typename T, int N>
struct ActiveFactor {
  using Vec = Eigen::Matrix<T, N, 1>;
  using Mat = Eigen::Matrix<T, N, N>;

  Mat j = Mat::Identity();
  Mat r = Mat::Identity();
  int q = 0;
  bool rotated = false;  // J is still the identity: most problems need one or two rows

  // d = J^T v; z = the part of v orthogonal to the active rows; coeff (first q entries,
  // zero after) with A_W^T coeff = v - z. Returns |z|.
  T split(const Vec& v, Vec& d, Vec& z, Vec& coeff) const {
    if (!rotated) {  // q == 0 as well: nothing is active yet
      d = v;
      z = v;
      coeff.setZero();
      return v.norm();
    }
    d.noalias() = j.transpose() * v;
    Vec free = d;
    for (int i = 0; i < q; ++i) free(i) = T(0);
    z.noalias() = j * free;
    coeff = d - free;
    r.template triangularView<Eigen::Upper>().solveInPlace(coeff);
    return free.norm();
  }

  // Makes the row whose d = J^T a (from split) active, as column q.
  void add(Vec d) {
    for (int i = N - 1; i > q; --i) {
      Eigen::JacobiRotation<T> g;
      g.makeGivens(T(d(i - 1)), T(d(i)));
      d.applyOnTheLeft(i - 1, i, g.adjoint());
      d(i) = T(0);
      j.applyOnTheRight(i - 1, i, g);
    }
    for (int i = 0; i < N; ++i) r(i, q) = i <= q ? d(i) : T(0);
    ++q;
    rotated = true;
  }

  // Removes active column l; the columns after it move down by one.
  void drop(int l) {
    for (int c = l; c + 1 < q; ++c) r.col(c) = r.col(c + 1);
    for (int c = l; c + 1 < q; ++c) {
      Eigen::JacobiRotation<T> g;
      g.makeGivens(T(r(c, c)), T(r(c + 1, c)));
      r.applyOnTheLeft(c, c + 1, g.adjoint());
      r(c + 1, c) = T(0);
      j.applyOnTheRight(c, c + 1, g);
    }
    --q;
    r.col(q).setZero();
    r(q, q) = T(1);
  }

  // Solves A_W A_W^T u = rhs (R^T R u = rhs; first q entries) and returns A_W^T u.
  void project(const Vec& rhs, Vec& u, Vec& step) const {
    Vec t = rhs;
    r.transpose().template triangularView<Eigen::Lower>().solveInPlace(t);
    for (int i = q; i < N; ++i) t(i) = T(0);
    step.noalias() = j * t;
    u = t;
    r.template triangularView<Eigen::Upper>().solveInPlace(u);
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
  const T inf = std::numeric_limits<T>::infinity();

  detail::ActiveFactor<T, N> f;
  int w[N];             // active constraint indices, in the factor's column order
  T u[N + 1];           // their multipliers (plus room for a candidate)
  uint16_t active = 0;  // the same set as a mask
  info = QpInfo{};
  x = p.x_unconstrained;
  // Dependence is judged against the largest row, not the row itself: a row that is
  // rounding noise (a force component fixed by equilibrium) must count as dependent,
  // or its 1e-16 norm would turn into a 1e32 step.
  T row_scale = T(0);
  for (int j = 0; j < p.m; ++j) row_scale = std::max(row_scale, p.a.row(j).norm());
  const T dependent_below = p.dependent_tol * row_scale;
  Vec d, z, coeff;

  // Warm start: project onto the previous active set, keep the independent rows, and drop
  // rows with negative multipliers until the pair (x, u) is dual feasible again.
  if (warm_active != 0) {
    for (int j = 0; j < p.m && f.q < N; ++j) {
      if (!(warm_active & (1u << j))) continue;
      if (f.split(p.a.row(j).transpose(), d, z, coeff) > dependent_below) {
        w[f.q] = j;
        active = static_cast<uint16_t>(active | (1u << j));
        f.add(d);
      }
    }
    while (f.q > 0) {
      Vec rhs = Vec::Zero(), mult, step;
      for (int i = 0; i < f.q; ++i) rhs(i) = p.b(w[i]) - p.a.row(w[i]).dot(p.x_unconstrained);
      f.project(rhs, mult, step);
      int worst = -1;
      for (int i = 0; i < f.q; ++i)
        if (mult(i) < T(0) && (worst < 0 || mult(i) < mult(worst))) worst = i;
      if (worst < 0) {
        x = p.x_unconstrained + step;
        for (int i = 0; i < f.q; ++i) u[i] = mult(i);
        break;
      }
      active = static_cast<uint16_t>(active & ~(1u << w[worst]));
      for (int i = worst; i + 1 < f.q; ++i) w[i] = w[i + 1];
      f.drop(worst);
    }
    if (f.q == 0) x = p.x_unconstrained;
  }

  for (;;) {
    // Most violated inactive constraint (lowest index on ties).
    int cand = -1;
    T worst = -p.violation_tol;
    for (int j = 0; j < p.m; ++j) {
      if (active & (1u << j)) continue;
      const T s = p.a.row(j).dot(x) - p.b(j);
      if (s < worst) {
        worst = s;
        cand = j;
      }
    }
    if (cand < 0) break;

    const Vec ap = p.a.row(cand).transpose();
    T u_cand = T(0);
    for (;;) {
      if (++info.iterations > max_iterations) return Status::kQpIterationLimit;
      const T z_norm = f.split(ap, d, z, coeff);
      const bool dependent = !(z_norm > dependent_below);

      // Dual step limit: the first active multiplier to reach zero.
      T t_dual = inf;
      int drop = -1;
      for (int i = 0; i < f.q; ++i) {
        if (coeff(i) > T(0)) {
          const T ratio = u[i] / coeff(i);
          if (ratio < t_dual) {
            t_dual = ratio;
            drop = i;
          }
        }
      }
      const T s = ap.dot(x) - p.b(cand);
      const T t_primal = dependent ? inf : -s / (z_norm * z_norm);
      if (dependent && drop < 0) return Status::kQpInfeasible;

      const T t = t_primal <= t_dual ? t_primal : t_dual;
      if (!dependent) x.noalias() += t * z;
      for (int i = 0; i < f.q; ++i) u[i] -= t * coeff(i);
      u_cand += t;

      if (t_primal <= t_dual) {  // full step: the candidate becomes active
        w[f.q] = cand;
        u[f.q] = u_cand;
        active = static_cast<uint16_t>(active | (1u << cand));
        f.add(d);
        break;
      }
      active = static_cast<uint16_t>(active & ~(1u << w[drop]));
      for (int i = drop; i + 1 < f.q; ++i) {
        w[i] = w[i + 1];
        u[i] = u[i + 1];
      }
      f.drop(drop);  // a partial step leaves the candidate violated: keep going with it
    }
  }
  info.active = active;
  return x.allFinite() ? Status::kOk : Status::kNonFiniteInput;
}

// Defined once in projection_qp.cpp (EXTERN empty), extern everywhere else: 3 or 6
// variables with 9 or 12 rows.
#define GRASPGUIDE_PROJECTION_QP(EXTERN, T, N, M)                                               \
  EXTERN template Status solve_projection<T, N, M>(const ProjectionQp<T, N, M>&, int, uint16_t, \
                                                   Eigen::Matrix<T, N, 1>&, QpInfo&);
#define GRASPGUIDE_PROJECTION_QPS(EXTERN)        \
  GRASPGUIDE_PROJECTION_QP(EXTERN, float, 3, 9)  \
  GRASPGUIDE_PROJECTION_QP(EXTERN, float, 6, 12) \
  GRASPGUIDE_PROJECTION_QP(EXTERN, double, 3, 9) GRASPGUIDE_PROJECTION_QP(EXTERN, double, 6, 12)
#ifndef GRASPGUIDE_INSTANTIATING_PROJECTION_QP
GRASPGUIDE_PROJECTION_QPS(extern)
#endif

}  // namespace graspguide
