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
// as a violation and turn into a false infeasibility. No null-space basis is ever formed.
//
// The paper model and the x-components: the moment about y_O is sum_i c_i lambda_ix with
// c_i = |s_i x y_O| > 0 (docs/algorithm.md, step 5), so with no such moment every
// lambda_ix >= 0 forces lambda_ix = 0. Those rows join equilibrium as equalities before the
// first iteration instead of being discovered one degenerate step at a time; a moment of
// the wrong sign decides infeasibility in closed form. The equalities are then
// orthonormalised from the rows themselves: projecting e_x through I - G_hat^T G_hat and
// stepping along it would square the conditioning of a hand whose x components
// equilibrium nearly fixes, which float cannot resolve.
#pragma once

#include <cmath>
#include <limits>

#include "graspguide/grasp_structure.h"
#include "graspguide/qp_info.h"
#include "graspguide/scene.h"

namespace graspguide {

// How many ulps of the equality basis, divided by its shortest kept row, a projected row
// must exceed to count as independent of the active rows.
inline constexpr double kBasisNoiseUlps = 4.0;

template <typename T, int K>
struct ForceSolution {
  ForceVec<T, K> lambda;  // the QP optimum, before normalisation
  ConstraintModel used = ConstraintModel::kNone;
  int iterations = 0;   // active-set changes, summed over the models tried
  uint16_t active = 0;  // bit j: lambda_j held at 0 in the model used
  bool firm = true;     // every model found infeasible was found so by a firm verdict
  // The answer is one float can vouch for (answer_certificate.h); always true in double
  // and on the SVD route. solve_grasp retries in double when it is false.
  bool certain = true;
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

// The equality rows in force space: the unit rows e_j of the fixed components, and an
// orthonormal basis q_0..q_(n-1) of the rest, orthogonal to them, with the coordinates
// c_i = q_i . lambda that every solution shares. With no fixed row the q are G_hat's own
// rows, already orthonormal. With fixed rows (the paper model's x components) they come
// from the rows themselves by Gram-Schmidt, not from projecting e_j through
// I - G_hat^T G_hat: a component that equilibrium nearly fixes has |P e_j| ~ 1e-4, and
// stepping along it squares that into a 1e7 amplification, all rounding in float.
template <typename T, int K>
struct EqualityRows {
  WhitenedGrasp<T, K> own;                 // the fixed path's q as rows, zero beyond n
  const WhitenedGrasp<T, K>* q = nullptr;  // the rows in use: G_hat or own
  Vec6<T> c = Vec6<T>::Zero();
  int n = 0;
  uint16_t fixed = 0;
  bool have_c = false;  // c is formed on demand for G_hat's rows
  T smallest = T(1);    // the shortest row Gram-Schmidt kept, before normalising
  bool firm = true;     // a contradiction found was beyond its rounding (QpInfo::firm)

  int rank() const { return n + __builtin_popcount(fixed); }

  // P e_j (j not fixed), the column of the projector onto the free directions. The basis
  // is orthonormal only to working precision, so a column that mostly cancels is
  // projected once more. The unit rows need nothing: e_j has no fixed component, and
  // the q have none either.
  void column(int j, ForceVec<T, K>& v) const {
    v.noalias() = -q->transpose() * q->col(j);
    v(j) += T(1);
    if (v.squaredNorm() < T(0.25)) {
      const Vec6<T> rest = *q * v;
      v.noalias() -= q->transpose() * rest;
    }
  }

  // The part every solution shares, sum_i c_i q_i: with no fixed row, lambda0.
  void shared_part(const ForceVec<T, K>& start, ForceVec<T, K>& out) {
    if (!have_c) c.noalias() = *q * start;
    have_c = true;
    out.noalias() = q->transpose() * c;
  }
};

// G_hat's rows.
template <typename T, int K>
void whitened_rows(const GraspStructure<T, K>& st, EqualityRows<T, K>& eq) {
  eq.q = &st.g_hat;
  eq.n = 6;
}

// The rows lambda_j = 0 (j in fixed), then G_hat's rows, G_hat lambda = -w_hat read off
// start, orthogonalised against them (which only zeroes their fixed components) and
// against each other by Gram-Schmidt twice. A row that the earlier ones span to within
// dependent_tol adds nothing, if its right-hand side agrees within consistency_tol;
// otherwise the equalities contradict each other (equilibrium needs a fixed component
// that is not zero) and the result is kQpInfeasible. The caller may know that `known`
// dependences hold (the paper model's moment row about y_O, which paper_x_rows decided in
// closed form): when no more than that many rows turn out dependent, their right-hand
// sides are not checked again from rounded sums.
template <typename T, int K>
Status fixed_rows(const GraspStructure<T, K>& st, const ForceVec<T, K>& start, uint16_t fixed,
                  T dependent_tol, T consistency_tol, int known, EqualityRows<T, K>& eq) {
  eq.own.setZero();
  eq.q = &eq.own;
  eq.n = 0;
  eq.fixed = fixed;
  eq.have_c = true;
  eq.firm = true;
  const T eps = std::numeric_limits<T>::epsilon();
  int dependent = 0;
  bool consistent = true;
  for (int r = 0; r < 6; ++r) {
    ForceVec<T, K> v = st.g_hat.row(r).transpose();
    T rhs = v.dot(start);
    T size = std::abs(rhs);  // what the right-hand side's cancellations started from
    for (int j = 0; j < 3 * K; ++j)
      if (fixed & (1u << j)) v(j) = T(0);  // lambda_j = 0: no right-hand side to carry
    for (int pass = 0; pass < 2; ++pass)
      for (int i = 0; i < eq.n; ++i) {
        const T d = eq.own.row(i).dot(v.transpose());
        v.noalias() -= d * eq.own.row(i).transpose();
        rhs -= d * eq.c(i);
        size += std::abs(d * eq.c(i));
      }
    const T norm = v.norm();
    if (!(norm > dependent_tol)) {
      // Beyond the tolerance, the right-hand side carries the rounding of its own
      // cancellations, and the dropped left-over row (norm) sees the solution, whose
      // shared part the c so far hold: a hand whose x components equilibrium nearly fixes
      // holds forces 1e4 |lambda0| there, and in float that alone is 1e-3 |lambda0|.
      const T bound = consistency_tol + T(kBasisNoiseUlps) * eps * size + norm * eq.c.norm();
      ++dependent;
      if (!(std::abs(rhs) <= bound)) {
        // Never firm: float cannot tell a dependent row from a real one shorter than
        // dependent_tol, along which float64 may hold the hand with 1e6 |lambda0|. Rare: no
        // contradiction here in 20,000 random hands.
        consistent = false;
        eq.firm = false;
      }
      continue;
    }
    eq.own.row(eq.n) = v.transpose() / norm;
    eq.c(eq.n++) = rhs / norm;
    if (norm < eq.smallest) eq.smallest = norm;
  }
  return consistent || dependent <= known ? Status::kOk : Status::kQpInfeasible;
}

// The steps of DualActiveSet are named for the reader, not called by the CPU: each is
// inlined into project_forces's loop, so the solver's state stays in registers and the
// stage counts are those of one function.
#define GRASPGUIDE_QP_STEP __attribute__((always_inline)) inline

// The arrays of one dual active-set solve, apart from its scalars: the arrays' addresses
// go to the steps the compiler keeps out of line (the active rows' split, add and drop;
// the equalities' columns), and a scalar beside them would be reloaded after every such
// call, where on its own it stays in a register.
template <typename T, int K>
struct DualActiveSetArrays {
  using Rows = ActiveRows<T, K>;
  using Vec = ForceVec<T, K>;
  static constexpr int kMax = Rows::kMax;

  EqualityRows<T, K> eq;
  Rows rows;
  int w[kMax];  // constraint index of each active row
  T u[kMax];    // its multiplier
  // The candidate's steps: v = P e_cand, z its part the active rows cannot reach, d its
  // part they can (Q^T v) and coeff = r^-1 d.
  Vec v, z;
  T d[kMax], coeff[kMax];
  Vec shared;  // the equalities' shared part, formed the first time a dependent row needs it
  bool have_shared = false;

  // A row the active ones determine: on this face its value follows from equilibrium
  // alone, lambda_c = lambda0_c - sum_i coeff_i lambda0_(w_i), free of the rounding the
  // iterate carries from large steps. `size` is what its sum's cancellations started from.
  T dependent_value(const Vec& start, int cand, T& size) {
    if (!have_shared) {
      eq.shared_part(start, shared);
      have_shared = true;
    }
    T value = shared(cand);
    size = std::abs(shared(cand));
    for (int i = 0; i < rows.n; ++i) {
      value -= coeff[i] * shared(w[i]);
      size += std::abs(coeff[i] * shared(w[i]));
    }
    return value;
  }
};

// One dual active-set solve (project_forces) and its steps. The equalities are always
// held (eq); rows holds the active inequality rows as an orthonormal basis, w their
// indices and u their multipliers. Each candidate row is added by steps along
// z = (I - Q Q^T) P e_cand in the primal and -coeff = -r^-1 Q^T P e_cand in the dual.
template <typename T, int K>
struct DualActiveSet {
  using Rows = ActiveRows<T, K>;
  using Vec = ForceVec<T, K>;
  static constexpr int kMax = Rows::kMax;
  // A row's projection is known to a few ulps absolute, so a step t along it is off by
  // ~2 eps |t|. Two ulps, not four: a bound of four ulps per step grows past violations
  // that float computes to 3e-7 (a bound of 7e-5), and hides them.
  static constexpr T kStepUlps = T(2) * std::numeric_limits<T>::epsilon();

  DualActiveSet(DualActiveSetArrays<T, K>& arrays, const Vec& start_, Vec& lambda_,
                uint16_t constrained_, T violation_tol_, T rel_tol_)
      : start(start_),
        lambda(lambda_),
        constrained(constrained_),
        violation_tol(violation_tol_),
        rel_tol(rel_tol_),
        a(arrays),
        eq(arrays.eq),
        rows(arrays.rows),
        w(arrays.w),
        u(arrays.u),
        v(arrays.v),
        z(arrays.z),
        d(arrays.d),
        coeff(arrays.coeff) {}

  const Vec& start;
  Vec& lambda;
  const uint16_t constrained;
  const T violation_tol;
  const T rel_tol;

  DualActiveSetArrays<T, K>& a;
  EqualityRows<T, K>& eq;
  Rows& rows;
  int (&w)[kMax];
  T (&u)[kMax];
  Vec &v, &z;
  T (&d)[kMax];
  T (&coeff)[kMax];

  T dep_tol = T(0);
  int limit = 0;        // the most independent inequality rows beside the equalities
  uint16_t active = 0;  // fixed rows are held by eq, never by `rows`
  // Rows found to hold at the current vertex although rounding shows them violated;
  // cleared whenever the active set changes.
  uint16_t settled = 0;
  // A running bound on the rounding error the steps have put into lambda. A step along a
  // row 1e-4 long (a near-degenerate vertex) is large, and so is its error; violations
  // below the bound are rounding, not a reason to move again.
  T step_error = T(0);

  // The equalities: equilibrium, and the fixed rows held at zero (kQpInfeasible if
  // equilibrium contradicts them). lambda starts at the unconstrained optimum on them:
  // their shared part plus the free part of start.
  GRASPGUIDE_QP_STEP Status hold_equalities(const GraspStructure<T, K>& st, uint16_t fixed,
                                            T dependent_tol, int known_dependences, QpInfo& info) {
    if (fixed == 0) {
      whitened_rows<T, K>(st, eq);
      lambda = start;
    } else {
      const Status s =
          fixed_rows<T, K>(st, start, fixed, dependent_tol, violation_tol, known_dependences, eq);
      if (s != Status::kOk) {
        info.firm = eq.firm;
        return s;
      }
      // The shared part plus the free part of start (start less its parts along the q and
      // its fixed components).
      const Vec6<T> along = eq.c - eq.own * start;
      lambda = start;
      lambda.noalias() += eq.own.transpose() * along;
      for (int j = 0; j < 3 * K; ++j)
        if (fixed & (1u << j)) lambda(j) = T(0);
    }
    // The basis is as accurate as its shortest kept row allows: Gram-Schmidt divided that
    // row's rounding (a few eps) by its length, so a column shorter than that is noise.
    const T basis_noise = T(kBasisNoiseUlps) * std::numeric_limits<T>::epsilon() / eq.smallest;
    dep_tol = dependent_tol > basis_noise ? dependent_tol : basis_noise;
    // At most this many independent inequality rows fit beside the equalities, and never
    // more than the active-row arrays hold, whatever a degenerate hand's rank.
    limit = 3 * K - eq.rank() < kMax ? 3 * K - eq.rank() : kMax;
    active = fixed;
    return Status::kOk;
  }

  // The iterate's rounding: a few ulps of |lambda|, which a paper-model optimum can hold
  // at 1000 times |lambda0|, or the steps' running bound, but that bound only up to
  // violation_tol. The bound adds every step's worst case, and past the tolerance it
  // would hide violations float computes to 0.2 %; a row examined needlessly costs one
  // harmless step, or for a dependent row dependent_value, free of the steps' rounding.
  // violation_tol itself is no reason to stop moving: it judges infeasibility, and a float
  // iterate stopped at a violation it allows is one dual step short of double's optimum,
  // a motor off instead of on.
  GRASPGUIDE_QP_STEP T iterate_rounding() const {
    T tol = rel_tol * lambda.norm();
    const T hidden = step_error < violation_tol ? step_error : violation_tol;
    if (hidden > tol) tol = hidden;
    return tol;
  }

  // The most violated inactive constraint beyond tol (lowest index on ties), or -1.
  GRASPGUIDE_QP_STEP int most_violated_row(T tol) const {
    int cand = -1;
    T worst = -tol;
    for (int j = 0; j < 3 * K; ++j) {
      if (!(constrained & (1u << j)) || ((active | settled) & (1u << j))) continue;
      if (lambda(j) < worst) {
        worst = lambda(j);
        cand = j;
      }
    }
    return cand;
  }

  // Splits the candidate's column against the active rows. With as many active rows as
  // null(G) has dimensions, nothing is left to move along, whatever rounding says.
  // Returns whether the candidate is dependent, and its length |z| in z_norm.
  GRASPGUIDE_QP_STEP bool split_candidate(T& z_norm) {
    z_norm = rows.split(v, d, z, coeff);
    return !(z_norm > dep_tol) || rows.n >= limit;
  }

  // A degenerate vertex (the paper model's common case) holds a dependent row at zero;
  // only a value below zero beyond its formula's own rounding is a real violation. A real
  // violation takes the dual step like any other, unless no active row can leave: then
  // the row holds when the tolerance allows it, and otherwise certifies infeasibility.
  GRASPGUIDE_QP_STEP bool dependent_row_holds(int cand, T tol) {
    T size;
    const T value = a.dependent_value(start, cand, size);
    bool can_leave = false;
    for (int i = 0; i < rows.n; ++i) can_leave = can_leave || coeff[i] > T(0);
    const T rounding = tol > kStepUlps * size ? tol : kStepUlps * size;
    return value >= -rounding || (!can_leave && value >= -(violation_tol + kStepUlps * size));
  }

  // Dual step limit: the first inequality multiplier to reach zero, and its row (or -1).
  GRASPGUIDE_QP_STEP T dual_step_limit(int& drop) const {
    T t_dual = std::numeric_limits<T>::infinity();
    drop = -1;
    for (int i = 0; i < rows.n; ++i) {
      if (!(coeff[i] > T(0))) continue;
      const T ratio = u[i] / coeff[i];
      if (ratio < t_dual) {
        t_dual = ratio;
        drop = i;
      }
    }
    return t_dual;
  }

  // Whether a dependent row that no active row can make room for proves infeasibility
  // firmly: only when it is clearly dependent and its violation clears the tolerance by a
  // margin over its formula's rounding.
  // - Clearly dependent: 99.6 % of dependent rows are left under 0.1 dep_tol long; rows
  //   left 0.11 and 0.5 dep_tol long are real ones, along which float64 holds hands with
  //   5e6 and 4e5 |lambda0|.
  // - The rounding is the terms' and the shared part's. The equality basis divided the
  //   shared part by its shortest row, and coeff = r^-1 d divides by the active rows'
  //   shortest: a basis row 3e-3 long makes it 1e-4 |lambda0|, far above two ulps of the
  //   terms.
  GRASPGUIDE_QP_STEP bool infeasibility_is_firm(int cand, T z_norm) {
    T size;
    const T value = a.dependent_value(start, cand, size);
    T r_min = T(1), spread = T(1);
    for (int i = 0; i < rows.n; ++i) {
      if (std::abs(rows.r[i][i]) < r_min) r_min = std::abs(rows.r[i][i]);
      spread += std::abs(coeff[i]);
    }
    const T noise = kStepUlps * (size + spread * start.norm() / eq.smallest) / r_min;
    return (rows.n >= limit || z_norm <= T(kFirmDependentShare) * dep_tol) &&
           -value >= violation_tol + T(kFirmVerdictFactor) * noise;
  }

  // Moves t along the candidate's steps: lambda along z (unless dependent), the active
  // multipliers along -coeff, the candidate's own multiplier u_cand up.
  GRASPGUIDE_QP_STEP void take_step(T t, bool dependent, T& u_cand) {
    if (!dependent) {
      lambda.noalias() += t * z;
      step_error += kStepUlps * std::abs(t);
    }
    for (int i = 0; i < rows.n; ++i) u[i] -= t * coeff[i];
    u_cand += t;
  }

  // A full step: the candidate reaches zero and becomes active with multiplier u_cand.
  GRASPGUIDE_QP_STEP void add_active_row(int cand, T u_cand, T z_norm) {
    lambda(cand) = T(0);
    w[rows.n] = cand;
    u[rows.n] = u_cand;
    active = static_cast<uint16_t>(active | (1u << cand));
    rows.add(d, z, z_norm);
    settled = 0;
  }

  // A partial step: the blocking active row i leaves, the candidate stays violated.
  GRASPGUIDE_QP_STEP void drop_active_row(int i) {
    active = static_cast<uint16_t>(active & ~(1u << w[i]));
    settled = 0;
    for (int k = i; k + 1 < rows.n; ++k) {
      w[k] = w[k + 1];
      u[k] = u[k + 1];
    }
    rows.drop(i);
  }

  // Makes the violated row cand hold: dual and primal steps until it is active, or is
  // found to hold as a dependent row. kQpInfeasible when it depends on active rows none of
  // which can leave; kQpIterationLimit past max_iterations.
  GRASPGUIDE_QP_STEP Status add_violated_row(int cand, T tol, int max_iterations, QpInfo& info) {
    eq.column(cand, v);
    T u_cand = T(0);
    for (;;) {
      if (++info.iterations > max_iterations) return Status::kQpIterationLimit;
      // |z| and whether the candidate is dependent (no primal step: the active rows
      // determine it), as locals that stay in registers.
      T z_norm;
      const bool dependent = split_candidate(z_norm);
      if (dependent && u_cand == T(0) && dependent_row_holds(cand, tol)) {
        settled = static_cast<uint16_t>(settled | (1u << cand));
        return Status::kOk;
      }
      int drop;
      const T t_dual = dual_step_limit(drop);
      if (dependent && drop < 0) {
        info.firm = infeasibility_is_firm(cand, z_norm);
        return Status::kQpInfeasible;
      }
      const T t_primal =
          dependent ? std::numeric_limits<T>::infinity() : -lambda(cand) / (z_norm * z_norm);
      take_step(t_primal <= t_dual ? t_primal : t_dual, dependent, u_cand);
      if (t_primal <= t_dual) {
        add_active_row(cand, u_cand, z_norm);
        return Status::kOk;
      }
      drop_active_row(drop);
    }
  }

  // Rows held at the optimum are zero there by definition: what the later steps left in
  // them is rounding, and a motor whose forces are all held must be off, not at the 1e-3
  // level that turns it on (float at internal forces 1000 times |lambda0|). A dependent row
  // found to hold is zeroed too when it sits within the tolerance.
  GRASPGUIDE_QP_STEP void zero_held_rows() {
    T tol = violation_tol > rel_tol * lambda.norm() ? violation_tol : rel_tol * lambda.norm();
    if (step_error > tol) tol = step_error;
    for (int j = 0; j < 3 * K; ++j)
      if ((active & (1u << j)) || ((settled & (1u << j)) && std::abs(lambda(j)) <= tol))
        lambda(j) = T(0);
  }
};

}  // namespace detail

#undef GRASPGUIDE_QP_STEP

// From start (on the equilibrium set), holds the rows in `fixed` at zero as equalities
// (kQpInfeasible if equilibrium contradicts that), then projects onto
// lambda_j >= -max(violation_tol, rel_tol |lambda|) for every j in `constrained`. A row
// whose projection onto the remaining free directions is shorter than dependent_tol
// (|P e_j| <= 1), or than the equality basis's own rounding, counts as dependent on the
// active rows. known_dependences: how many dependences among the fixed rows and
// equilibrium the caller has already decided hold (fixed_rows). Returns kOk,
// kQpInfeasible or kQpIterationLimit; lambda is valid only on kOk.
template <typename T, int K>
Status project_forces(const GraspStructure<T, K>& st, const ForceVec<T, K>& start,
                      uint16_t constrained, uint16_t fixed, T violation_tol, T rel_tol,
                      T dependent_tol, int max_iterations, ForceVec<T, K>& lambda, QpInfo& info,
                      int known_dependences = 0) {
  info = QpInfo{};
  detail::DualActiveSetArrays<T, K> arrays;
  detail::DualActiveSet<T, K> qp(arrays, start, lambda, constrained, violation_tol, rel_tol);
  Status s = qp.hold_equalities(st, fixed, dependent_tol, known_dependences, info);
  if (s != Status::kOk) return s;
  for (;;) {
    const T tol = qp.iterate_rounding();
    const int cand = qp.most_violated_row(tol);
    if (cand < 0) break;
    s = qp.add_violated_row(cand, tol, max_iterations, info);
    if (s != Status::kOk) return s;
  }
  qp.zero_held_rows();
  info.active = qp.active;
  return lambda.allFinite() ? Status::kOk : Status::kNonFiniteInput;
}

// What the paper model can decide before iterating, from the moment about y_O (the
// budget b = tau . y_O = sum_i c_i lambda_ix): kQpInfeasible when b is negative beyond the
// tolerance; otherwise, when b is zero within it, the x rows it forces to zero: `fixed`,
// all but the one of the contact with the largest c_i, and `implied`, which the others and
// equilibrium hold at b / c_i. solve_forces holds all of them; the moment row about y_O
// then depends on them and drops out, with |b| within the tolerance. In a hand whose
// plane contains y_O, equilibrium may need an x component other than zero: the
// equalities then contradict each other and the model is infeasible.
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
  out.firm = true;
  for (int model = static_cast<int>(requested); model <= static_cast<int>(ConstraintModel::kNone);
       ++model) {
    const auto m = static_cast<ConstraintModel>(model);
    uint16_t fixed = 0, implied = 0;
    // A firm verdict whatever the precision: the budget is one three-term dot product,
    // rounded to a few ulps of |tau|, 1e-3 of the tolerance it is compared with.
    if (m == ConstraintModel::kPaper &&
        paper_x_rows<T, K>(frames, w, violation_tol, fixed, implied) == Status::kQpInfeasible)
      continue;
    QpInfo info;
    const Status s = project_forces<T, K>(
        st, start, constrained_bits<K>(m), static_cast<uint16_t>(fixed | implied), violation_tol,
        Tolerances<T>::kRoundingRelTol, Tolerances<T>::kStructuredDependentTol, max_iterations,
        out.lambda, info, implied != 0 ? 1 : 0);
    out.iterations += info.iterations;
    if (s == Status::kQpInfeasible) {
      out.firm = out.firm && info.firm;
      continue;
    }
    if (s != Status::kOk) return s;
    out.used = m;
    out.active = info.active;
    return Status::kOk;
  }
  return Status::kQpInfeasible;  // unreachable: the model "none" has no constraints
}

}  // namespace graspguide
