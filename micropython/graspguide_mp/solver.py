"""Algorithm 1 for one posture (docs/algorithm.md, steps 1-7), a port of the C++ core's
structured route (lib/graspguide/src/graspguide: contact_frames.h, grasp_structure.h,
relevance.h, force_qp.h via qp.py, motor_levels.h; graspguide_cue: alignment.h, pwm.h)
to MicroPython: lists of floats, no numpy.

solve(...) returns a Result; on any status but OK every PWM is 0 (motors off).

The interpreter's float is the port's float: double on the unix port and on boards built
with MICROPY_FLOAT_IMPL_DOUBLE, single on most boards. PRECISIONS holds the tolerances of
each (tolerances.h: the QP's follow the precision, the geometry's do not); solve() picks
them from the interpreter unless told.
"""

import math

from graspguide_mp import qp
from graspguide_mp import status as st
from graspguide_mp.linalg import all_finite, cross, dot, norm, stable_norm

# tolerances.h, graspguide_cue/tolerances.h
K_COINCIDENT_REL_TOL = 1e-4
K_INPUT_PRECISION_REL_TOL = 1e-3
K_AXIS_PARALLEL_TOL = 1e-3
K_RANK_REL_TOL = 1e-4
K_ZERO_FORCE_REL_TOL = 1e-6
K_RELEVANCE_COS_TOL = 1e-5
K_TINY_REL = 1e-12
K_MOTOR_OFF_LEVEL = 1e-3
K_MIN_QUATERNION_NORM = 1e-6
K_DEFAULT_MAX_ITERATIONS = 64
PWM_MIN = 70
PWM_SPAN = 185
_RAD_TO_DEG = 180.0 / math.pi

# (kFeasRelTol, kRoundingRelTol, kStructuredDependentTol, machine epsilon, kUnitNormSlack,
# largest finite)
PRECISIONS = {
    "double": (
        1e-9,
        1e-9,
        1e-9,
        2.220446049250313e-16,
        8.8817841970012523e-16,
        1.7976931348623157e308,
    ),
    "single": (1e-4, 5e-7, 1e-6, 1.1920929e-07, 4.76837158e-7, 3.4028235e38),
}


def interpreter_precision():
    """ "double" when this interpreter's float has a 53-bit mantissa, else "single"."""
    return "double" if 1.0 + 2.0**-40 != 1.0 else "single"


class Frames:
    """ContactFrames (contact_frames.h) for k contacts: s_i = (C_i - O) / L, R_i as
    3x3 row lists, c_i = |s_i x y_O|."""

    def __init__(self, k):
        self.k = k
        self.length_scale = 0.0
        self.offset_scaled = [[0.0, 0.0, 0.0] for _ in range(k)]
        self.rotation = [[[0.0] * 3 for _ in range(3)] for _ in range(k)]
        self.axis = [0.0, 1.0, 0.0]
        self.x_moment = [0.0] * k
        self.fallback_mask = 0


class Result:
    def __init__(self, k):
        self.status = st.OK
        self.k = k
        self.pwm = [0] * k
        self.levels = None
        self.lam = None
        self.used = ""
        self.relevant = None
        self.error_deg = None
        self.alpha = None
        self.iterations = 0
        self.fallback_mask = 0


def _unit3(v):
    n = norm(v, 3)
    return [v[0] / n, v[1] / n, v[2] / n]


def fallback_axis(y_o):
    least = 0
    for j in (1, 2):
        if abs(y_o[j]) < abs(y_o[least]):
            least = j
    e = [0.0, 0.0, 0.0]
    e[least] = 1.0
    return _unit3(cross(y_o, e))


def contact_frames(contacts, k, y_axis, eps, out):
    axis_norm = stable_norm(y_axis, 3)
    if not axis_norm > 0.0:
        return st.BAD_AXIS
    y_o = [y_axis[0] / axis_norm, y_axis[1] / axis_norm, y_axis[2] / axis_norm]
    # Centroid relative to the first contact: a common offset costs nothing beyond the
    # rounding of the inputs.
    first = contacts[0]
    mean = [0.0, 0.0, 0.0]
    for i in range(k):
        c = contacts[i]
        for j in range(3):
            mean[j] += c[j] - first[j]
    for j in range(3):
        mean[j] /= k
    r = [[contacts[i][j] - first[j] - mean[j] for j in range(3)] for i in range(k)]
    r_norm = [norm(r[i], 3) for i in range(k)]
    scale = 0.0
    for v in r_norm:
        if v > scale:
            scale = v
    coincident = K_COINCIDENT_REL_TOL * scale
    if not scale > 0.0:
        return st.COINCIDENT_CONTACTS
    magnitude = 0.0
    for c in contacts:
        for v in c:
            if abs(v) > magnitude:
                magnitude = abs(v)
    if magnitude * eps > K_INPUT_PRECISION_REL_TOL * scale:
        return st.IMPRECISE_CONTACTS
    for i in range(k):
        if r_norm[i] <= coincident:
            return st.COINCIDENT_CONTACTS
        for j in range(i + 1, k):
            d = [r[i][0] - r[j][0], r[i][1] - r[j][1], r[i][2] - r[j][2]]
            if norm(d, 3) <= coincident:
                return st.COINCIDENT_CONTACTS
    out.length_scale = scale
    out.axis = y_o
    out.fallback_mask = 0
    for i in range(k):
        ri = r[i]
        out.offset_scaled[i] = [ri[0] / scale, ri[1] / scale, ri[2] / scale]
        rn = r_norm[i]
        y = [ri[0] / rn, ri[1] / rn, ri[2] / rn]
        x = cross(y, y_o)
        s = norm(x, 3)
        out.x_moment[i] = s * rn / scale
        if s < K_AXIS_PARALLEL_TOL:
            x = _unit3(cross(y, fallback_axis(y_o)))
            out.fallback_mask |= 1 << i
        else:
            x = [x[0] / s, x[1] / s, x[2] / s]
        z = cross(x, y)
        rot = out.rotation[i]
        for a in range(3):
            rot[a][0] = x[a]
            rot[a][1] = y[a]
            rot[a][2] = z[a]
    return st.OK


def _inverse_norm_upper3(r):
    """1 / sigma_min of an upper-triangular 3x3, by two power steps (grasp_structure.h)."""
    m00 = 1.0 / r[0][0]
    m11 = 1.0 / r[1][1]
    m22 = 1.0 / r[2][2]
    m01 = -r[0][1] * m00 * m11
    m12 = -r[1][2] * m11 * m22
    m02 = -(r[0][1] * m12 + r[0][2] * m22) * m00
    m = ((m00, m01, m02), (0.0, m11, m12), (0.0, 0.0, m22))
    cols = ((m00, 0.0, 0.0), (m01, m11, 0.0), (m02, m12, m22))
    longest = 0
    for c in (1, 2):
        if dot(cols[c], cols[c], 3) > dot(cols[longest], cols[longest], 3):
            longest = c
    x = _unit3(cols[longest])
    estimate = 0.0
    for _ in range(2):
        y = [m[0][j] * x[0] + m[1][j] * x[1] + m[2][j] * x[2] for j in range(3)]
        x = [dot(m[i], y, 3) for i in range(3)]
        xn = norm(x, 3)
        estimate = math.sqrt(xn)
        x = [x[0] / xn, x[1] / xn, x[2] / xn]
    return estimate


def grasp_structure(frames, g_hat, j_factor):
    """G_hat (6 rows of 3k) and R_J (3x3, upper) in place; returns (status, rank_ratio)."""
    k = frames.k
    dim = 3 * k
    # S's columns: block i of S is skew(s_i)^T.
    s = [[0.0] * dim for _ in range(3)]
    for i in range(k):
        v = frames.offset_scaled[i]
        b = 3 * i
        s[0][b + 1] = -v[2]
        s[0][b + 2] = v[1]
        s[1][b] = v[2]
        s[1][b + 2] = -v[0]
        s[2][b] = -v[1]
        s[2][b + 1] = v[0]
    r = j_factor
    for a in range(3):
        for b in range(3):
            r[a][b] = 0.0
    tiny = K_TINY_REL * math.sqrt(k)
    for c in range(3):
        sc = s[c]
        for _ in range(2):  # Gram-Schmidt twice: Q orthonormal to working precision
            for p in range(c):
                sp = s[p]
                d = dot(sp, sc, dim)
                for j in range(dim):
                    sc[j] -= d * sp[j]
                r[p][c] += d
        rc = norm(sc, dim)
        r[c][c] = rc
        if not rc > tiny:
            return st.RANK_DEFICIENT, 0.0
        for j in range(dim):
            sc[j] /= rc
    rank_ratio = 1.0 / (_inverse_norm_upper3(r) * math.sqrt(k))
    if not rank_ratio >= K_RANK_REL_TOL:
        return st.RANK_DEFICIENT, rank_ratio
    inv_sqrt_k = 1.0 / math.sqrt(k)
    for i in range(k):
        rot = frames.rotation[i]
        b = 3 * i
        for a in range(3):
            top = g_hat[a]
            bottom = g_hat[3 + a]
            qa = s[a]
            for c in range(3):
                top[b + c] = rot[a][c] * inv_sqrt_k
                bottom[b + c] = qa[b] * rot[0][c] + qa[b + 1] * rot[1][c] + qa[b + 2] * rot[2][c]
    return st.OK, rank_ratio


def whitened_wrench(j_factor, k, w):
    r = j_factor
    sk = math.sqrt(k)
    t0 = w[3] / r[0][0]
    t1 = (w[4] - r[0][1] * t0) / r[1][1]
    t2 = (w[5] - r[0][2] * t0 - r[1][2] * t1) / r[2][2]
    return [w[0] / sk, w[1] / sk, w[2] / sk, t0, t1, t2]


def _g_hat_t_times(g_hat, dim, x, sign, out):
    """out = sign * G_hat^T x."""
    for j in range(dim):
        s = 0.0
        for row in range(6):
            s += g_hat[row][j] * x[row]
        out[j] = sign * s


def relevance(frames, force):
    f_norm = norm(force, 3)
    mask = 0
    for i in range(frames.k):
        r = frames.offset_scaled[i]
        if dot(force, r, 3) <= K_RELEVANCE_COS_TOL * f_norm * norm(r, 3):
            mask |= 1 << i
    return mask


def desired_forces(lambda0, k, mask):
    dim = 3 * k
    des = [0.0] * dim
    for i in range(k):
        if mask & (1 << i):
            for a in range(3):
                des[3 * i + a] = lambda0[3 * i + a]
    n = norm(des, dim)
    if n > K_TINY_REL * norm(lambda0, dim):
        for j in range(dim):
            des[j] /= n
    else:
        for j in range(dim):
            des[j] = 0.0
    return des


def motor_levels(lam, k, policy_fperp):
    """The normalised levels m, or None for nothing_to_display (motor_levels.h)."""
    dim = 3 * k
    n = norm(lam, dim)
    if not n > 0.0 or not all_finite(lam):
        return None
    m = [0.0] * k
    for i in range(k):
        b = 3 * i
        if policy_fperp:
            m[i] = lam[b + 1] / n
        else:
            m[i] = (
                math.sqrt(lam[b] * lam[b] + lam[b + 1] * lam[b + 1] + lam[b + 2] * lam[b + 2]) / n
            )
    mn = norm(m, k)
    if not mn > 0.0:
        return None
    for i in range(k):
        m[i] /= mn
    return m


def pwm_from_levels(levels, k, gain, largest_finite):
    """graspguide_cue/pwm.h: floor(70 + gain |m_i| + 0.5) clamped to 0..255, computed as
    (trunc(140 + gain 2|m_i|) + 1) >> 1 like the C++; levels at or below 1e-3 are off."""
    out = [0] * k
    twice = [0.0] * k
    largest = 0.0
    on = 0
    for i in range(k):
        level = abs(levels[i])
        if not level > K_MOTOR_OFF_LEVEL:
            continue
        on |= 1 << i
        twice[i] = level + level
        if twice[i] > largest:
            largest = twice[i]
    gain_limit = 0.0
    if largest > 0.0 and largest <= largest_finite:
        gain_limit = (2 * 255 - 1 - 2 * PWM_MIN) / largest
    in_range = gain >= 0.0 and gain < gain_limit
    for i in range(k):
        if not on & (1 << i):
            continue
        t = 2.0 * PWM_MIN + gain * twice[i]
        if not in_range:
            if not t >= 0.0:
                continue
            if t >= 2 * 255 - 1:
                out[i] = 255
                continue
        out[i] = (int(t) + 1) >> 1
    return out


def _asin_deg_ratio(z):
    if not z > 0.0:
        return _RAD_TO_DEG
    x = math.sqrt(z)
    return math.asin(x) / x * _RAD_TO_DEG


def _scaled_gravity(w, x, y, z, g):
    p = w * w + z * z
    r = x * x + y * y
    a = w * y - x * z
    b = y * z + w * x
    g[0] = a + a
    g[1] = -(b + b)
    g[2] = r - p
    return p + r


def gravity_in_hand(q, g, slack, largest_finite):
    """g = R(q)^T (0, 0, -1), unit (alignment.h); returns a status code."""
    n2 = _scaled_gravity(q[0], q[1], q[2], q[3], g)
    if abs(n2 - 1.0) <= slack:
        return st.OK
    if not n2 <= largest_finite:
        if not all_finite(q):
            return st.NON_FINITE_INPUT
        m = max(abs(q[0]), abs(q[1]), abs(q[2]), abs(q[3]))
        inv = 1.0 / m
        n2 = _scaled_gravity(q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv, g)
    elif not n2 >= K_MIN_QUATERNION_NORM * K_MIN_QUATERNION_NORM:
        return st.BAD_QUATERNION
    inv = 1.0 / n2
    for i in range(3):
        g[i] *= inv
    return st.OK


def alignment_to_gravity(f_hat, g_hat):
    """(error_deg, alpha) in three ranges of the half chord (alignment.h)."""
    d0 = f_hat[0] - g_hat[0]
    d1 = f_hat[1] - g_hat[1]
    d2 = f_hat[2] - g_hat[2]
    chord2 = d0 * d0 + d1 * d1 + d2 * d2
    chord = math.sqrt(chord2)
    alpha = chord * (PWM_SPAN * 0.5)
    if chord2 <= 1.0:
        err = chord * _asin_deg_ratio(chord2 * 0.25)
    elif chord2 <= 3.0:
        c = 1.0 - chord2 * 0.5
        err = 90.0 - c * _asin_deg_ratio(c * c)
    else:
        s0 = f_hat[0] + g_hat[0]
        s1 = f_hat[1] + g_hat[1]
        s2 = f_hat[2] + g_hat[2]
        sum2 = s0 * s0 + s1 * s1 + s2 * s2
        err = 180.0 - math.sqrt(sum2) * _asin_deg_ratio(sum2 * 0.25)
    return err, alpha


def _fail(res, code):
    res.status = code
    for i in range(res.k):
        res.pwm[i] = 0
    return res


def solve(
    contacts,
    wrench,
    policy="F",
    mode="C",
    constraints="paper",
    orientation=(1.0, 0.0, 0.0, 0.0),
    y_axis=(0.0, 1.0, 0.0),
    max_iterations=K_DEFAULT_MAX_ITERATIONS,
    precision=None,
):
    """One request (the C++ Guidance::solve's order of checks). Names are checked by the
    caller (solve_server.py); an unknown one here is a ValueError."""
    k = len(contacts)
    res = Result(k)
    tol = PRECISIONS[precision or interpreter_precision()]
    feas_rel, rounding_rel, dependent_tol, eps, slack, largest_finite = tol
    model = qp.MODELS.index(constraints)
    if policy not in ("F", "Fperp") or mode not in ("C", "V"):
        raise ValueError("policy must be F or Fperp, mode C or V")
    shown = k if k <= 4 else 4
    for i in range(shown):
        if not all_finite(contacts[i]):
            return _fail(res, st.NON_FINITE_INPUT)
    if not (all_finite(y_axis) and all_finite(wrench) and all_finite(orientation)):
        return _fail(res, st.NON_FINITE_INPUT)
    if k not in (3, 4):
        return _fail(res, st.BAD_CONTACT_COUNT)
    for c in contacts:
        if len(c) != 3:
            return _fail(res, st.BAD_CONTACT_COUNT)
    if not norm(y_axis, 3) > 0.0:  # set_scene's plain norm: 1e-200 is no axis either
        return _fail(res, st.BAD_AXIS)
    g = [0.0, 0.0, 0.0]
    s = gravity_in_hand(orientation, g, slack, largest_finite)
    if s != st.OK:
        return _fail(res, s)

    frames = Frames(k)
    s = contact_frames(contacts, k, y_axis, eps, frames)
    if s != st.OK:
        return _fail(res, s)
    L = frames.length_scale
    w = [wrench[0], wrench[1], wrench[2], wrench[3] / L, wrench[4] / L, wrench[5] / L]
    w_norm = stable_norm(w, 6)
    if not w_norm > 0.0:
        return _fail(res, st.ZERO_WRENCH)
    force = [wrench[0], wrench[1], wrench[2]]
    f_norm = stable_norm(force, 3)
    if not f_norm > K_ZERO_FORCE_REL_TOL * w_norm:
        return _fail(res, st.ZERO_FORCE)

    dim = 3 * k
    g_hat = [[0.0] * dim for _ in range(6)]
    j_factor = [[0.0] * 3 for _ in range(3)]
    s, _ = grasp_structure(frames, g_hat, j_factor)
    if s != st.OK:
        return _fail(res, s)
    w_hat = whitened_wrench(j_factor, k, w)
    lambda0 = [0.0] * dim
    _g_hat_t_times(g_hat, dim, w_hat, -1.0, lambda0)
    relevant = relevance(frames, force)
    des = desired_forces(lambda0, k, relevant)
    # start = des - G_hat^T (G_hat des + w_hat): the unconstrained optimum.
    resid = [w_hat[row] + dot(g_hat[row], des, dim) for row in range(6)]
    start = [0.0] * dim
    _g_hat_t_times(g_hat, dim, resid, -1.0, start)
    for j in range(dim):
        start[j] += des[j]

    lam = [0.0] * dim
    sol = [2, 0, 0]
    s = qp.solve_forces(
        frames,
        g_hat,
        w,
        lambda0,
        start,
        model,
        max_iterations,
        (feas_rel, rounding_rel, dependent_tol, eps),
        lam,
        sol,
    )
    res.iterations = sol[1]
    if s != st.OK:
        return _fail(res, s)
    levels = motor_levels(lam, k, policy == "Fperp")
    if levels is None:
        return _fail(res, st.NOTHING_TO_DISPLAY)

    f_hat = [force[0] / f_norm, force[1] / f_norm, force[2] / f_norm]
    err, alpha = alignment_to_gravity(f_hat, g)
    gain = float(PWM_SPAN) if mode == "C" else alpha
    res.pwm = pwm_from_levels(levels, k, gain, largest_finite)
    res.levels = levels
    res.lam = lam
    res.used = qp.MODELS[sol[0]]
    res.relevant = [bool(relevant & (1 << i)) for i in range(k)]
    res.error_deg = err
    res.alpha = alpha
    res.fallback_mask = frames.fallback_mask
    return res
