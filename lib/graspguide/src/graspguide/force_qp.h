// Step 5 on the structured route: the paper's QP (eq. 2) in force space,
//   min |lambda - lambda_des|^2   s.t.   G lambda = -w,   lambda_j >= 0 (j in the model),
// by a dual active-set method (Goldfarb-Idnani) with a unit Hessian. The equality rows are
// always active: every step stays in null(G), along P e_j = e_j - G_hat^T G_hat e_j, the
// column of the projector onto null(G) that grasp_structure.h makes cheap to form. The
// active rows are kept as an orthonormal basis of their projections (Gram-Schmidt with
// reorthogonalisation, Givens rotations when a row leaves), so a row that depends on the
// active ones is recognised to working precision and never produces a primal step, only
// a dual step or an infeasibility certificate: the degenerate vertices of the paper's
// model are the common case, not an accident. Such a dependent row's value on the current
// face is taken from equilibrium alone (lambda0 and its coefficients on the active rows),
// not from the iterate, whose large steps carry rounding that float would otherwise read
// as a violation and turn into a false infeasibility (issue 17). No null-space basis is
// ever formed.
//
// The paper model and the x-components: the moment about y_O is sum_i c_i lambda_ix with
// c_i = |s_i x y_O| > 0 (docs/algorithm.md, step 5), so with no such moment every
// lambda_ix >= 0 forces lambda_ix = 0. Those rows are made active (as equalities) before
// the first iteration instead of being discovered one degenerate step at a time, which is
// both faster and what keeps float on the same vertex as double (issue 17); a moment of
// the wrong sign decides infeasibility in closed form.
#pragma once

#include <cmath>
#include <limits>

#include "graspguide/grasp_structure.h"
#include "graspguide/qp_info.h"
#include "graspguide/scene.h"

namespace graspguide {

template <typename T, int K>
struct ForceSolution {
  ForceVec<T, K> lambda;  // the QP optimum, before normalisation
  ConstraintModel used = ConstraintModel::kNone;
  int iterations = 0;   // active-set changes, summed over the models tried
  uint16_t active = 0;  // bit j: lambda_j held at 0 in the model used
};

// Bit j of a 3k-bit mask: component j of lambda (contact j / 3, axis j % 3: x y z).
template <int K>
constexpr uint16_t axis_bits(int axis) {
  uint16_t m = 0;
  for (int i = 0; i < K; ++i) m = static_cast<uint16_t>(m | (1u << (3 * i + axis)));
  return m;
}

template <int K>
constexpr uint16_t constrained_bits(ConstraintModel model) {
  return model == ConstraintModel::kPaper    ? static_cast<uint16_t>((1u << (3 * K)) - 1u)
         : model == ConstraintModel::kNormal ? axis_bits<K>(1)
                                             : uint16_t(0);
}

namespace detail {

// An orthonormal basis q_0..q_{n-1} of the projected active rows P e_{w_i} and the upper
// triangular r with [P e_w0 ... P e_w(n-1)] = [q_0 ... q_(n-1)] r.
template <typename T, int K>
struct ActiveRows {
  static constexpr int kDim = 3 * K;
  static constexpr int kMax = 3 * K - 6;  // dim null(G): at most this many independent rows
  using Vec = ForceVec<T, K>;

  Vec q[kMax];
  T r[kMax][kMax];
  int n = 0;

  // d = Q^T v, z = v - Q d (the part of v the active rows cannot reach), coeff = r^-1 d.
  // Returns |z|. Classical Gram-Schmidt, repeated when it cancelled more than half of v.
  T split(const Vec& v, T* d, Vec& z, T* coeff) const {
    z = v;
    for (int i = 0; i < n; ++i) {
      d[i] = q[i].dot(z);
      z.noalias() -= d[i] * q[i];
    }
    T z_sq = z.squaredNorm();
    if (n > 0 && z_sq < T(0.25) * v.squaredNorm()) {
      for (int i = 0; i < n; ++i) {
        const T e = q[i].dot(z);
        d[i] += e;
        z.noalias() -= e * q[i];
      }
      z_sq = z.squaredNorm();
    }
    for (int i = n - 1; i >= 0; --i) {
      T s = d[i];
      for (int c = i + 1; c < n; ++c) s -= r[i][c] * coeff[c];
      coeff[i] = s / r[i][i];
    }
    return std::sqrt(z_sq);
  }

  void add(const T* d, const Vec& z, T z_norm) {
    for (int i = 0; i < n; ++i) r[i][n] = d[i];
    for (int i = n + 1; i < kMax; ++i) r[i][n] = T(0);
    r[n][n] = z_norm;
    q[n] = z / z_norm;
    ++n;
  }

  // Removes active column l: the later columns move down by one, and Givens rotations
  // restore the triangle, rotating the basis alongside.
  void drop(int l) {
    for (int c = l; c + 1 < n; ++c)
      for (int i = 0; i <= c + 1; ++i) r[i][c] = r[i][c + 1];
    for (int c = l; c + 1 < n; ++c) {
      const T a = r[c][c], b = r[c + 1][c];
      const T h = std::hypot(a, b);
      if (h > T(0)) {
        const T cs = a / h, sn = b / h;
        for (int k = c; k + 1 < n; ++k) {
          const T x = r[c][k], y = r[c + 1][k];
          r[c][k] = cs * x + sn * y;
          r[c + 1][k] = -sn * x + cs * y;
        }
        const Vec qc = q[c];
        q[c] = cs * qc + sn * q[c + 1];
        q[c + 1] = -sn * qc + cs * q[c + 1];
      }
      r[c + 1][c] = T(0);
    }
    --n;
  }
};

// P e_j: the column of the projector onto null(G). G_hat's rows are orthonormal only to
// working precision, so I - G_hat^T G_hat is a projector only to working precision too:
// a column that mostly cancels (a component that equilibrium nearly fixes, |P e_j| ~ 1e-4
// next to a contact on the y_O axis) would keep an absolute error of ~eps, a relative
// one of 1e-3 in float, and a step of 1e7 along it would carry that error into the forces.
// Projecting such a column once more removes what is left in the row space.
template <typename T, int K>
void projector_column(const GraspStructure<T, K>& st, int j, ForceVec<T, K>& v) {
  v.noalias() = -st.g_hat.transpose() * st.g_hat.col(j);
  v(j) += T(1);
  if (v.squaredNorm() < T(0.25)) {
    const Vec6<T> rest = st.g_hat * v;
    v.noalias() -= st.g_hat.transpose() * rest;
  }
}

}  // namespace detail

// From start (on the equilibrium set), makes the rows in `fixed` active as equalities,
// then projects onto lambda_j >= -max(violation_tol, rel_tol |lambda|) for every j in
// `constrained`. A row
// whose projection onto the remaining free directions is shorter than dependent_tol
// (|P e_j| <= 1) counts as dependent on the active rows. Returns kOk, kQpInfeasible or
// kQpIterationLimit; lambda is valid only on kOk.
template <typename T, int K>
Status project_forces(const GraspStructure<T, K>& st, const ForceVec<T, K>& start,
                      uint16_t constrained, uint16_t fixed, T violation_tol, T rel_tol,
                      T dependent_tol, int max_iterations, ForceVec<T, K>& lambda, QpInfo& info) {
  using Rows = detail::ActiveRows<T, K>;
  using Vec = ForceVec<T, K>;
  constexpr int kMax = Rows::kMax;
  const T inf = std::numeric_limits<T>::infinity();

  Rows rows;
  int w[kMax];          // constraint index of each active row
  T u[kMax];            // its multiplier
  bool equality[kMax];  // held by `fixed`: never dropped, multiplier of any sign
  uint16_t active = 0;
  info = QpInfo{};
  lambda = start;
  Vec v, z;
  // A running bound on the rounding error the steps have put into lambda: a row's
  // projection is known to a few ulps absolute, so a step t along it is off by ~4 eps |t|.
  // A step along a row 1e-4 long (a near-degenerate vertex) is large, and so is its error;
  // violations below the bound are rounding, not a reason to move again.
  T step_error = T(0);
  const T kStepUlps = T(4) * std::numeric_limits<T>::epsilon();
  T d[kMax], coeff[kMax];
  // Rows found to hold at the current vertex although rounding shows them violated;
  // cleared whenever the active set changes.
  uint16_t settled = 0;
  Vec lambda0;  // -G_hat^T w_hat, formed the first time a dependent row needs it
  bool have_lambda0 = false;

  for (int j = 0; j < 3 * K; ++j) {
    if (!(fixed & (1u << j))) continue;
    if (++info.iterations > max_iterations) return Status::kQpIterationLimit;
    detail::projector_column<T, K>(st, j, v);
    const T z_norm = rows.split(v, d, z, coeff);
    // Fixed by equilibrium and the rows already held: a step along noise would be wrong.
    // The row stays a constraint, so a value other than zero is still caught below.
    if (!(z_norm > dependent_tol) || rows.n == kMax) continue;
    const T t_eq = lambda(j) / (z_norm * z_norm);
    lambda.noalias() -= t_eq * z;
    step_error += kStepUlps * std::abs(t_eq);
    lambda(j) = T(0);
    w[rows.n] = j;
    u[rows.n] = T(0);
    equality[rows.n] = true;
    active = static_cast<uint16_t>(active | (1u << j));
    rows.add(d, z, z_norm);
  }

  for (;;) {
    // The most violated inactive constraint (lowest index on ties). Violations are
    // measured against the larger of the tolerance and its share of the iterate: a
    // paper-model optimum can hold internal forces 1000 times |lambda0|, and in float
    // their rounding alone would otherwise read as a violation.
    T tol = violation_tol > rel_tol * lambda.norm() ? violation_tol : rel_tol * lambda.norm();
    if (step_error > tol) tol = step_error;
    int cand = -1;
    T worst = -tol;
    for (int j = 0; j < 3 * K; ++j) {
      if (!(constrained & (1u << j)) || ((active | settled) & (1u << j))) continue;
      if (lambda(j) < worst) {
        worst = lambda(j);
        cand = j;
      }
    }
    if (cand < 0) break;

    detail::projector_column<T, K>(st, cand, v);
    T u_cand = T(0);
    for (;;) {
      if (++info.iterations > max_iterations) return Status::kQpIterationLimit;
      const T z_norm = rows.split(v, d, z, coeff);
      // With as many active rows as null(G) has dimensions, nothing is left to move along,
      // whatever rounding says.
      const bool dependent = !(z_norm > dependent_tol) || rows.n == kMax;
      if (dependent && u_cand == T(0)) {
        // A row the active ones determine: on this face its value follows from
        // equilibrium alone, lambda_c = lambda0_c - sum_i coeff_i lambda0_(w_i), free of
        // the rounding the iterate carries from large steps. A degenerate vertex (the
        // paper model's common case) holds it at zero; only a value below zero beyond
        // that formula's own rounding is a real violation.
        if (!have_lambda0) {
          const Vec6<T> g_start = st.g_hat * start;
          lambda0.noalias() = st.g_hat.transpose() * g_start;
          have_lambda0 = true;
        }
        T value = lambda0(cand), size = std::abs(lambda0(cand));
        for (int i = 0; i < rows.n; ++i) {
          value -= coeff[i] * lambda0(w[i]);
          size += std::abs(coeff[i] * lambda0(w[i]));
        }
        if (value >= -(violation_tol + kStepUlps * size)) {
          settled = static_cast<uint16_t>(settled | (1u << cand));
          break;
        }
      }
      // Dual step limit: the first inequality multiplier to reach zero.
      T t_dual = inf;
      int drop = -1;
      for (int i = 0; i < rows.n; ++i) {
        if (equality[i] || !(coeff[i] > T(0))) continue;
        const T ratio = u[i] / coeff[i];
        if (ratio < t_dual) {
          t_dual = ratio;
          drop = i;
        }
      }
      if (dependent && drop < 0) return Status::kQpInfeasible;
      const T t_primal = dependent ? inf : -lambda(cand) / (z_norm * z_norm);
      const T t = t_primal <= t_dual ? t_primal : t_dual;
      if (!dependent) {
        lambda.noalias() += t * z;
        step_error += kStepUlps * std::abs(t);
      }
      for (int i = 0; i < rows.n; ++i) u[i] -= t * coeff[i];
      u_cand += t;

      if (t_primal <= t_dual) {  // full step: the candidate becomes active
        lambda(cand) = T(0);
        w[rows.n] = cand;
        u[rows.n] = u_cand;
        equality[rows.n] = false;
        active = static_cast<uint16_t>(active | (1u << cand));
        rows.add(d, z, z_norm);
        settled = 0;
        break;
      }
      // A partial step: the blocking row leaves, the candidate stays violated.
      active = static_cast<uint16_t>(active & ~(1u << w[drop]));
      settled = 0;
      for (int i = drop; i + 1 < rows.n; ++i) {
        w[i] = w[i + 1];
        u[i] = u[i + 1];
        equality[i] = equality[i + 1];
      }
      rows.drop(drop);
    }
  }
  info.active = active;
  return lambda.allFinite() ? Status::kOk : Status::kNonFiniteInput;
}

// What the paper model can decide before iterating, from the moment about y_O (the
// budget b = tau . y_O = sum_i c_i lambda_ix): kQpInfeasible when b is negative beyond the
// tolerance; otherwise, when b is zero within it, `fixed` gets the x rows it forces to
// zero, all but the one of the contact with the largest c_i, `implied`, which equilibrium
// then holds at b / c_i by itself (it stays an ordinary constraint, checked like any other:
// in a hand whose plane contains y_O equilibrium fixes every x, and not always at zero).
template <typename T, int K>
Status paper_x_rows(const ContactFrames<T, K>& frames, const Vec6<T>& w, T violation_tol,
                    uint16_t& fixed, uint16_t& implied) {
  fixed = implied = 0;
  if (frames.fallback_mask != 0) return Status::kOk;  // a fallback x is not in the identity
  int largest = 0;
  for (int i = 1; i < K; ++i)
    if (frames.x_moment[i] > frames.x_moment[largest]) largest = i;
  const T budget = w.template tail<3>().dot(frames.axis);
  const T slack = violation_tol * frames.x_moment[largest];
  if (budget < -slack) return Status::kQpInfeasible;
  if (budget <= slack) {
    implied = static_cast<uint16_t>(1u << (3 * largest));
    fixed = static_cast<uint16_t>(axis_bits<K>(0) & ~implied);
  }
  return Status::kOk;
}

// The models in turn, paper -> normal -> none, from the unconstrained optimum `start`.
// feasibility_rel (relative to |lambda0|) is a parameter so that the benchmark can
// measure the tolerance trade.
template <typename T, int K>
Status solve_forces(const ContactFrames<T, K>& frames, const GraspStructure<T, K>& st,
                    const Vec6<T>& w, const ForceVec<T, K>& lambda0, const ForceVec<T, K>& start,
                    ConstraintModel requested, int max_iterations, ForceSolution<T, K>& out,
                    T feasibility_rel = Tolerances<T>::kFeasRelTol) {
  const T violation_tol = feasibility_rel * lambda0.norm();
  out.iterations = 0;
  for (int model = static_cast<int>(requested); model <= static_cast<int>(ConstraintModel::kNone);
       ++model) {
    const auto m = static_cast<ConstraintModel>(model);
    uint16_t fixed = 0, implied = 0;
    if (m == ConstraintModel::kPaper &&
        paper_x_rows<T, K>(frames, w, violation_tol, fixed, implied) == Status::kQpInfeasible)
      continue;
    QpInfo info;
    const Status s = project_forces<T, K>(st, start, constrained_bits<K>(m), fixed, violation_tol,
                                          feasibility_rel, Tolerances<T>::kStructuredDependentTol,
                                          max_iterations, out.lambda, info);
    out.iterations += info.iterations;
    if (s == Status::kQpInfeasible) continue;
    if (s != Status::kOk) return s;
    out.used = m;
    out.active = info.active;
    return Status::kOk;
  }
  return Status::kQpInfeasible;  // unreachable: the model "none" has no constraints
}

}  // namespace graspguide
