"""Step 5 on the structured route, a port of lib/graspguide/src/graspguide/force_qp.h: the
paper's QP in force space, min |lam - lam_des|^2 s.t. G lam = -w, lam_j >= 0 (j in the
model), by a dual active-set method (Goldfarb-Idnani, unit Hessian) whose steps stay in
null(G) along projector columns P e_j formed on demand from G_hat's orthonormal rows.
docs/algorithm.md, step 5, says why each guard below exists; the comments here only
point at the C++ they mirror, so the two can be read side by side."""

import math

from graspguide_mp import status as st
from graspguide_mp.linalg import dot, norm, popcount

MODELS = ("paper", "normal", "none")
_BASIS_NOISE_ULPS = 4.0
_INF = math.inf


def axis_bits(k, axis):
    m = 0
    for i in range(k):
        m |= 1 << (3 * i + axis)
    return m


def constrained_bits(k, model):
    if model == 0:
        return (1 << (3 * k)) - 1
    if model == 1:
        return axis_bits(k, 1)
    return 0


class _ActiveRows:
    """Orthonormal basis q of the projected active rows and the upper triangle r
    (ActiveRows in force_qp.h)."""

    def __init__(self, n, kmax):
        self.dim = n
        self.kmax = kmax
        self.q = [[0.0] * n for _ in range(kmax)]
        self.r = [[0.0] * kmax for _ in range(kmax)]
        self.n = 0

    def split(self, v, d, z, coeff):
        dim = self.dim
        q = self.q
        for j in range(dim):
            z[j] = v[j]
        for i in range(self.n):
            qi = q[i]
            di = dot(qi, z, dim)
            d[i] = di
            for j in range(dim):
                z[j] -= di * qi[j]
        z_sq = dot(z, z, dim)
        # Classical Gram-Schmidt cancelled more than half of v: once more.
        if self.n > 0 and z_sq < 0.25 * dot(v, v, dim):
            for i in range(self.n):
                qi = q[i]
                e = dot(qi, z, dim)
                d[i] += e
                for j in range(dim):
                    z[j] -= e * qi[j]
            z_sq = dot(z, z, dim)
        r = self.r
        for i in range(self.n - 1, -1, -1):
            s = d[i]
            for c in range(i + 1, self.n):
                s -= r[i][c] * coeff[c]
            coeff[i] = s / r[i][i]
        return math.sqrt(z_sq)

    def add(self, d, z, z_norm):
        n = self.n
        r = self.r
        for i in range(n):
            r[i][n] = d[i]
        for i in range(n + 1, self.kmax):
            r[i][n] = 0.0
        r[n][n] = z_norm
        qn = self.q[n]
        for j in range(self.dim):
            qn[j] = z[j] / z_norm
        self.n = n + 1

    def drop(self, first):
        n = self.n
        r = self.r
        q = self.q
        for c in range(first, n - 1):
            for i in range(c + 2):
                r[i][c] = r[i][c + 1]
        for c in range(first, n - 1):
            a = r[c][c]
            b = r[c + 1][c]
            h = math.sqrt(a * a + b * b)
            if h > 0.0:
                cs = a / h
                sn = b / h
                for kk in range(c, n - 1):
                    x = r[c][kk]
                    y = r[c + 1][kk]
                    r[c][kk] = cs * x + sn * y
                    r[c + 1][kk] = -sn * x + cs * y
                qc = q[c]
                qd = q[c + 1]
                for j in range(self.dim):
                    x = qc[j]
                    y = qd[j]
                    qc[j] = cs * x + sn * y
                    qd[j] = -sn * x + cs * y
            r[c + 1][c] = 0.0
        self.n = n - 1


class _EqualityRows:
    """The equality rows: G_hat's own, or (with fixed rows) an orthonormal basis built
    from them with the fixed unit rows taken out (EqualityRows in force_qp.h)."""

    def __init__(self, g_hat, dim):
        self.q = g_hat
        self.dim = dim
        self.c = [0.0] * 6
        self.n = 6
        self.fixed = 0
        self.have_c = False
        self.smallest = 1.0

    def rank(self):
        return self.n + popcount(self.fixed)

    def column(self, j, v):
        dim = self.dim
        q = self.q
        for m in range(dim):
            v[m] = 0.0
        for r in range(self.n):
            qr = q[r]
            a = qr[j]
            for m in range(dim):
                v[m] -= qr[m] * a
        v[j] += 1.0
        if dot(v, v, dim) < 0.25:
            for r in range(self.n):
                qr = q[r]
                a = dot(qr, v, dim)
                for m in range(dim):
                    v[m] -= qr[m] * a

    def shared_part(self, start, out):
        dim = self.dim
        q = self.q
        if not self.have_c:
            for r in range(self.n):
                self.c[r] = dot(q[r], start, dim)
        self.have_c = True
        for m in range(dim):
            out[m] = 0.0
        for r in range(self.n):
            qr = q[r]
            a = self.c[r]
            for m in range(dim):
                out[m] += qr[m] * a


def _fixed_rows(g_hat, dim, start, fixed, dependent_tol, consistency_tol, eps, known, eq):
    own = [[0.0] * dim for _ in range(6)]
    eq.q = own
    eq.n = 0
    eq.fixed = fixed
    eq.have_c = True
    dependent = 0
    consistent = True
    for row in range(6):
        v = list(g_hat[row])
        rhs = dot(v, start, dim)
        size = abs(rhs)
        for j in range(dim):
            if fixed & (1 << j):
                v[j] = 0.0
        for _ in range(2):
            for i in range(eq.n):
                oi = own[i]
                d = dot(oi, v, dim)
                for j in range(dim):
                    v[j] -= d * oi[j]
                t_ = d * eq.c[i]
                rhs -= t_
                size += abs(t_)
        nv = norm(v, dim)
        if not nv > dependent_tol:
            # The allowance for the right-hand side's own rounding (force_qp.h).
            bound = consistency_tol + _BASIS_NOISE_ULPS * eps * size + nv * norm(eq.c, 6)
            dependent += 1
            if not abs(rhs) <= bound:
                consistent = False
            continue
        on = own[eq.n]
        for j in range(dim):
            on[j] = v[j] / nv
        eq.c[eq.n] = rhs / nv
        eq.n += 1
        if nv < eq.smallest:
            eq.smallest = nv
    # `known` dependences the caller decided (force_qp.h: the moment row about y_O).
    return st.OK if consistent or dependent <= known else st.QP_INFEASIBLE


def project_forces(
    g_hat,
    k,
    start,
    constrained,
    fixed,
    violation_tol,
    rel_tol,
    dependent_tol,
    eps,
    max_iterations,
    lam,
    info,
    known_dependences=0,
):
    """From start (on the equilibrium set) to the projection onto the model's set; lam
    is written in place. info = [iterations, active]. Returns a status code."""
    dim = 3 * k
    kmax = dim - 6
    rows = _ActiveRows(dim, kmax)
    w = [0] * kmax
    u = [0.0] * kmax
    info[0] = 0
    info[1] = 0
    v = [0.0] * dim
    z = [0.0] * dim
    eq = _EqualityRows(g_hat, dim)
    if fixed == 0:
        for j in range(dim):
            lam[j] = start[j]
    else:
        s = _fixed_rows(
            g_hat, dim, start, fixed, dependent_tol, violation_tol, eps, known_dependences, eq
        )
        if s != st.OK:
            return s
        for j in range(dim):
            lam[j] = start[j]
        own = eq.q
        for r in range(eq.n):
            along = eq.c[r] - dot(own[r], start, dim)
            orow = own[r]
            for j in range(dim):
                lam[j] += orow[j] * along
        for j in range(dim):
            if fixed & (1 << j):
                lam[j] = 0.0
    basis_noise = _BASIS_NOISE_ULPS * eps / eq.smallest
    dep_tol = dependent_tol if dependent_tol > basis_noise else basis_noise
    limit = dim - eq.rank()
    if limit > kmax:
        limit = kmax
    active = fixed
    step_error = 0.0
    step_ulps = 2.0 * eps
    d = [0.0] * kmax
    coeff = [0.0] * kmax
    settled = 0
    shared = [0.0] * dim
    have_shared = False

    while True:
        # A violation counts once it exceeds the iterate's rounding, the steps' bound only
        # up to violation_tol, which itself only judges infeasibility (force_qp.h).
        tol = rel_tol * norm(lam, dim)
        hidden = step_error if step_error < violation_tol else violation_tol
        if hidden > tol:
            tol = hidden
        cand = -1
        worst = -tol
        for j in range(dim):
            if not (constrained & (1 << j)) or ((active | settled) & (1 << j)):
                continue
            if lam[j] < worst:
                worst = lam[j]
                cand = j
        if cand < 0:
            break

        eq.column(cand, v)
        u_cand = 0.0
        while True:
            info[0] += 1
            if info[0] > max_iterations:
                return st.QP_ITERATION_LIMIT
            z_norm = rows.split(v, d, z, coeff)
            dependent = (not z_norm > dep_tol) or rows.n >= limit
            if dependent and u_cand == 0.0:
                # The row's value on this face from equilibrium alone (force_qp.h).
                if not have_shared:
                    eq.shared_part(start, shared)
                    have_shared = True
                value = shared[cand]
                size = abs(shared[cand])
                for i in range(rows.n):
                    t_ = coeff[i] * shared[w[i]]
                    value -= t_
                    size += abs(t_)
                can_leave = False
                for i in range(rows.n):
                    can_leave = can_leave or coeff[i] > 0.0
                rounding = tol if tol > step_ulps * size else step_ulps * size
                if value >= -rounding or (
                    not can_leave and value >= -(violation_tol + step_ulps * size)
                ):
                    settled |= 1 << cand
                    break
            t_dual = _INF
            drop = -1
            for i in range(rows.n):
                if not coeff[i] > 0.0:
                    continue
                ratio = u[i] / coeff[i]
                if ratio < t_dual:
                    t_dual = ratio
                    drop = i
            if dependent and drop < 0:
                return st.QP_INFEASIBLE
            t_primal = _INF if dependent else -lam[cand] / (z_norm * z_norm)
            t = t_primal if t_primal <= t_dual else t_dual
            if not dependent:
                for j in range(dim):
                    lam[j] += t * z[j]
                step_error += step_ulps * abs(t)
            for i in range(rows.n):
                u[i] -= t * coeff[i]
            u_cand += t

            if t_primal <= t_dual:
                lam[cand] = 0.0
                w[rows.n] = cand
                u[rows.n] = u_cand
                active |= 1 << cand
                rows.add(d, z, z_norm)
                settled = 0
                break
            active &= ~(1 << w[drop])
            settled = 0
            for i in range(drop, rows.n - 1):
                w[i] = w[i + 1]
                u[i] = u[i + 1]
            rows.drop(drop)
    ln = rel_tol * norm(lam, dim)
    tol = violation_tol if violation_tol > ln else ln
    if step_error > tol:
        tol = step_error
    for j in range(dim):
        bit = 1 << j
        if (active & bit) or ((settled & bit) and abs(lam[j]) <= tol):
            lam[j] = 0.0
    info[1] = active
    for x in lam:
        if not (x - x == 0.0):
            return st.NON_FINITE_INPUT
    return st.OK


def paper_x_rows(k, fallback_mask, x_moment, axis, w, violation_tol, out):
    """out = [fixed, implied]; returns OK or QP_INFEASIBLE (paper_x_rows in force_qp.h)."""
    out[0] = 0
    out[1] = 0
    if fallback_mask != 0:
        return st.OK
    largest = 0
    for i in range(1, k):
        if x_moment[i] > x_moment[largest]:
            largest = i
    budget = w[3] * axis[0] + w[4] * axis[1] + w[5] * axis[2]
    slack = violation_tol * x_moment[largest]
    if budget < -slack:
        return st.QP_INFEASIBLE
    if budget <= slack:
        implied = 1 << (3 * largest)
        out[1] = implied
        out[0] = axis_bits(k, 0) & ~implied
    return st.OK


def solve_forces(frames, g_hat, w, lambda0, start, requested, max_iterations, tol, lam, out):
    """The models in turn from `requested` (0 paper, 1 normal, 2 none). out =
    [used, iterations, active]. tol: the precision's (feas_rel, rounding_rel, dependent,
    eps)."""
    k = frames.k
    dim = 3 * k
    feas_rel, rounding_rel, dependent_tol, eps = tol
    violation_tol = feas_rel * norm(lambda0, dim)
    out[1] = 0
    xr = [0, 0]
    info = [0, 0]
    for model in range(requested, 3):
        fixed = 0
        if model == 0:
            if (
                paper_x_rows(
                    k, frames.fallback_mask, frames.x_moment, frames.axis, w, violation_tol, xr
                )
                == st.QP_INFEASIBLE
            ):
                continue
            fixed = xr[0] | xr[1]
        s = project_forces(
            g_hat,
            k,
            start,
            constrained_bits(k, model),
            fixed,
            violation_tol,
            rounding_rel,
            dependent_tol,
            eps,
            max_iterations,
            lam,
            info,
            1 if model == 0 and xr[1] else 0,
        )
        out[1] += info[0]
        if s == st.QP_INFEASIBLE:
            continue
        if s != st.OK:
            return s
        out[0] = model
        out[2] = info[1]
        return st.OK
    return st.QP_INFEASIBLE
