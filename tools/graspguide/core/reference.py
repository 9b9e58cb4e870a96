"""Independent float64 reference of Algorithm 1 (docs/algorithm.md).

This module deliberately shares no method with the C++ core (`lib/graspguide`), which
uses a column-pivoted QR, an explicit null-space basis and a dual active-set solver.
Here instead:

* the rank and the minimum-norm solution come from numpy's (LAPACK) SVD;
* the QP is solved directly in lambda-space,
      min ||lam - lam_des||^2  s.t.  G lam = -w_L,  lam_j >= 0 (j in S),
  by EXHAUSTIVE enumeration of active sets (smallest first), the KKT conditions of
  each solved through the SVD of the free columns of G;
* the feasibility of each constraint model is cross-checked with a linear program
  (scipy.optimize.linprog, HiGHS) that computes a margin t (negative = infeasible).

Only the geometry (frames, grasp matrix, relevance, motor levels, PWM, error) follows
the same formulas as the C++, because those formulas are the specification.

Public API: :func:`solve`, returning a dict with keys status, pwm (k ints), levels (k),
lambda (3k, contact-frame [x y z] per contact: the QP optimum lambda0 + N xi before
normalisation), constraints_used, relevant (k bools), error_deg, alpha, fallback_mask
(bit i: contact i used the fallback axis), margins ({model: t}, None for 'none'),
active_set (the accepted active set, indices into lambda) and diagnostics (internal
quantities used by the known-answer generator). Everything is float64. Works standalone
(only numpy and scipy) so that `tools/scripts/gen_known_answers.py` can import it by adding `tools/`
to ``sys.path``.

Decisions where docs/algorithm.md is silent or ambiguous (see also the module-level
constants below):

* coincident_contacts also fires when two contacts coincide pairwise,
  ``||r_i - r_j|| <= kCoincidentRelTol * L`` (the status name and the C++ message say
  "two contacts coincide"; the doc's formula only tests ``||r_i||``).
* ``bad_axis``: y_O all zero (after the finiteness check), i.e. ``not ||y_O|| > 0``.
* ``zero_wrench``: every wrench component is exactly 0.
* ``nothing_to_display``: ``||m|| == 0`` exactly, as written in the doc.
* Outputs that are not defined for a status are ``None`` (``lambda``, ``levels``,
  ``relevant``, ``error_deg``); ``pwm`` is always a list of ``k`` ints (all 0 unless
  status is ok); ``constraints_used`` is ``""`` unless status is ok.
* ``levels`` are the normalised ``m`` (signed for policy Fperp) *before* the off
  threshold; the threshold only affects ``pwm``.
* ``error_deg``, ``alpha`` and ``fallback_mask`` are reported for statuses ok and
  nothing_to_display only (``None``, ``None`` and 0 otherwise).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from graspguide.core.rotations import quat_to_matrix
from graspguide.core.vocabulary import CONSTRAINT_MODELS, MODES, POLICIES

# --------------------------------------------------------------------------------------
# Tolerances: the float64 column of the table in docs/algorithm.md.
# --------------------------------------------------------------------------------------
kCoincidentRelTol = 1e-4  # ||r_i|| (or ||r_i - r_j||) <= this * L: coincident contacts
kInputPrecisionRelTol = 1e-3  # max|C| * eps above this * L: imprecise_contacts
kAxisParallelTol = 1e-3  # ||y_i x y_O|| below this: fallback axis
kRankRelTol = 1e-4  # sigma_6 / sigma_1 below this: rank deficient
kZeroForceRelTol = 1e-6  # ||f|| <= this * ||w_L||: zero force
kRelevanceCosTol = 1e-5  # f.r_i <= this * ||f|| ||r_i||: relevant
kTinyRel = 1e-12  # ||lam_des|| <= this * ||lam0||: lam_des left at zero
kFeasRelTol = 1e-9  # violation allowed, relative to ||lam0||
kDependentRelTol = 1e-9  # reference: [G; I_S'] with sigma_min/sigma_max below: dependent
kMotorOffLevel = 1e-3  # |m_i| <= this: motor off
kMinQuaternionNorm = 1e-6  # ||q|| below this: bad_quaternion

# Reference-only tolerances (not in the doc's table).
kMultiplierRelTol = 1e-9  # KKT multipliers >= -this * (||lam0|| + ||lam_des||)
kLpTol = 1e-10  # HiGHS primal/dual feasibility tolerance for the margin LP

PWM_BASE = 70
PWM_RANGE = 185
GRAVITY = np.array([0.0, 0.0, -1.0])

TOLERANCES = {
    "kCoincidentRelTol": kCoincidentRelTol,
    "kInputPrecisionRelTol": kInputPrecisionRelTol,
    "kAxisParallelTol": kAxisParallelTol,
    "kRankRelTol": kRankRelTol,
    "kZeroForceRelTol": kZeroForceRelTol,
    "kRelevanceCosTol": kRelevanceCosTol,
    "kTinyRel": kTinyRel,
    "kFeasRelTol": kFeasRelTol,
    "kDependentRelTol": kDependentRelTol,
    "kMotorOffLevel": kMotorOffLevel,
    "kMinQuaternionNorm": kMinQuaternionNorm,
    "kMultiplierRelTol": kMultiplierRelTol,
    "kLpTol": kLpTol,
}

FALLBACK_CHAIN = {
    "paper": ("paper", "normal", "none"),
    "normal": ("normal", "none"),
    "none": ("none",),
}


# --------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _as_float_array(x: Any) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def fallback_axis(y_o: np.ndarray) -> np.ndarray:
    """a = unit(y_O x e), e the basis vector with the smallest |e . y_O| (first on ties)."""
    least = 0
    for j in (1, 2):
        if abs(y_o[j]) < abs(y_o[least]):
            least = j
    e = np.zeros(3)
    e[least] = 1.0
    return _unit(np.cross(y_o, e))


def quaternion_to_matrix(q: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of q = [w, x, y, z] (normalised here), hand -> world."""
    return quat_to_matrix(_as_float_array(q))


# --------------------------------------------------------------------------------------
# Step 1: contact frames
# --------------------------------------------------------------------------------------
def contact_frames(contacts: np.ndarray, y_o: np.ndarray) -> tuple[str, dict | None]:
    """Centroid, offsets and right-handed contact frames. y_o must be unit.

    Returns (status, frames) with frames = {O, r (k x 3), L, R (k x 3 x 3),
    fallback_mask}; status is "ok", "coincident_contacts" or "imprecise_contacts".
    """
    k = contacts.shape[0]
    rel = contacts - contacts[0]
    mean_rel = rel.mean(axis=0)
    origin = contacts[0] + mean_rel
    r = rel - mean_rel
    norms = np.linalg.norm(r, axis=1)
    L = float(norms.max())
    if not L > 0.0:
        return "coincident_contacts", None
    if np.abs(contacts).max() * np.finfo(np.float64).eps > kInputPrecisionRelTol * L:
        return "imprecise_contacts", None
    tol = kCoincidentRelTol * L
    if np.any(norms <= tol):
        return "coincident_contacts", None
    for i in range(k):
        for j in range(i + 1, k):
            if np.linalg.norm(r[i] - r[j]) <= tol:
                return "coincident_contacts", None
    R = np.zeros((k, 3, 3))
    mask = 0
    for i in range(k):
        y = r[i] / norms[i]
        x = np.cross(y, y_o)
        s = np.linalg.norm(x)
        if s < kAxisParallelTol:
            x = _unit(np.cross(y, fallback_axis(y_o)))
            mask |= 1 << i
        else:
            x = x / s
        z = np.cross(x, y)
        R[i] = np.column_stack([x, y, z])
    return "ok", {"O": origin, "r": r, "L": L, "R": R, "fallback_mask": mask}


# --------------------------------------------------------------------------------------
# Step 2: grasp matrix (moment rows scaled by 1/L)
# --------------------------------------------------------------------------------------
def grasp_matrix(frames: dict) -> np.ndarray:
    r, L, R = frames["r"], frames["L"], frames["R"]
    k = r.shape[0]
    G = np.zeros((6, 3 * k))
    for i in range(k):
        G[0:3, 3 * i : 3 * i + 3] = R[i]
        G[3:6, 3 * i : 3 * i + 3] = _skew(r[i] / L) @ R[i]
    return G


# --------------------------------------------------------------------------------------
# Step 3: rank and minimum-norm solution (SVD)
# --------------------------------------------------------------------------------------
def rank_ratio(G: np.ndarray) -> float:
    s = np.linalg.svd(G, compute_uv=False)
    return float(s[5] / s[0]) if s[0] > 0 else 0.0


def min_norm_solution(G: np.ndarray, w_l: np.ndarray) -> np.ndarray:
    """lam0 = -pinv(G) w_L."""
    return -np.linalg.pinv(G) @ w_l


# --------------------------------------------------------------------------------------
# Step 4: relevance and desired forces
# --------------------------------------------------------------------------------------
def relevance(f: np.ndarray, r: np.ndarray) -> np.ndarray:
    nf = np.linalg.norm(f)
    return np.array([float(f @ ri) <= kRelevanceCosTol * nf * np.linalg.norm(ri) for ri in r])


def desired_forces(relevant: np.ndarray, lam0: np.ndarray) -> np.ndarray:
    mask = np.repeat(relevant.astype(np.float64), 3)
    lam_des = mask * lam0
    n = np.linalg.norm(lam_des)
    if n <= kTinyRel * np.linalg.norm(lam0):
        return np.zeros_like(lam0)
    return lam_des / n


# --------------------------------------------------------------------------------------
# Step 5: the QP by exhaustive active-set enumeration, and the LP margin
# --------------------------------------------------------------------------------------
def constrained_components(model: str, k: int) -> list[int]:
    if model == "paper":
        return list(range(3 * k))
    if model == "normal":
        return [3 * i + 1 for i in range(k)]
    if model == "none":
        return []
    raise ValueError(f"unknown constraint model {model!r}")


def project_enumerate(
    G: np.ndarray,
    w_l: np.ndarray,
    lam_des: np.ndarray,
    S: Sequence[int],
    lam0_norm: float,
    feas_rel_tol: float = kFeasRelTol,
) -> tuple[bool, np.ndarray | None, tuple[int, ...] | None]:
    """Euclidean projection of lam_des onto {G lam = -w_L, lam_S >= 0}.

    Tries every active subset S' of S, smallest first (lexicographic within a size),
    skipping subsets whose [G; I_S'] is not of full row rank 6 + |S'| (numpy SVD,
    sigma_min / sigma_max <= kDependentRelTol). For each, solves the KKT conditions of
    min 1/2||lam - lam_des||^2 s.t. G lam = -w_L, lam_S' = 0, with Lagrangian
    1/2||lam - lam_des||^2 - mu^T lam_S' + nu^T (G lam + w_L):

        lam - lam_des - sum_{j in S'} mu_j e_j + G^T nu = 0,  G lam = -w_L,  lam_S' = 0.

    Eliminating lam_S' = 0 (exact) leaves, with F the components not in S',

        [ I    G_F^T ] [lam_F]   [lam_des_F]
        [ G_F  0     ] [nu   ] = [-w_L     ],     mu_j = (G^T nu)_j - lam_des_j (j in S'),

    which is solved through the SVD G_F = U Sigma V^T (equivalent to the KKT solve, but
    with the conditioning of G_F instead of its square, which matters on the degenerate
    vertices of the paper model):

        lam_F = lam_des_F - V Sigma^-1 U^T r,   nu = U Sigma^-2 U^T r,   r = G_F lam_des_F + w_L.

    A subset is accepted when lam_S >= -feas_rel_tol ||lam0|| and
    mu >= -kMultiplierRelTol (||lam0|| + ||lam_des||). The first accepted subset gives the
    (unique) optimum. The [G; I_S'] rank test is applied, in order, only to subsets that
    pass the KKT test (the same outcome as testing it first, for less work). Returns
    (feasible, lam, active_set).
    """
    n = G.shape[1]
    delta = feas_rel_tol * lam0_norm
    mu_tol = kMultiplierRelTol * (lam0_norm + float(np.linalg.norm(lam_des)))
    S = list(S)
    S_arr = np.array(S, dtype=int)
    max_size = min(len(S), n - 6)

    def independent(subs: np.ndarray) -> np.ndarray:
        """[G; I_S'] of full row rank, for each row S' of subs (SVD, relative tol)."""
        cnt, size = subs.shape
        A = np.zeros((cnt, 6 + size, n))
        A[:, :6, :] = G
        if size:
            A[np.arange(cnt)[:, None], 6 + np.arange(size)[None, :], subs] = 1.0
        sv = np.linalg.svd(A, compute_uv=False)
        return sv[:, -1] > kDependentRelTol * sv[:, 0]

    for size in range(0, max_size + 1):
        combos = list(itertools.combinations(S, size))
        subsets = np.array(combos, dtype=int).reshape(len(combos), size)
        m = subsets.shape[0]
        nf = n - size
        rows = np.arange(m)[:, None]
        in_subset = np.zeros((m, n), dtype=bool)
        in_subset[rows, subsets] = True
        free = np.nonzero(~in_subset)[1].reshape(m, nf)  # sorted complement of S'
        G_F = np.transpose(G[:, free], (1, 0, 2))  # (m, 6, nf)
        U, sig, Vt = np.linalg.svd(G_F, full_matrices=False)
        usable = sig[:, -1] > kDependentRelTol * sig[:, 0]
        lam_des_F = lam_des[free]
        r = np.einsum("mij,mj->mi", G_F, lam_des_F) + w_l
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            y = np.einsum("mji,mj->mi", U, r) / sig  # Sigma^-1 U^T r
            lam_F = lam_des_F - np.einsum("mji,mj->mi", Vt, y)
            nu = np.einsum("mij,mj->mi", U, y / sig)
            lam = np.zeros((m, n))
            lam[rows, free] = lam_F
            mu = (nu @ G)[rows, subsets] - lam_des[subsets]
            ok = usable & np.all(np.isfinite(lam), axis=1) & np.all(np.isfinite(nu), axis=1)
            if S:
                ok &= np.all(lam[:, S_arr] >= -delta, axis=1)
            if size:
                ok &= np.all(mu >= -mu_tol, axis=1)
        candidates = np.nonzero(ok)[0]
        # The first candidate (in lexicographic order) of full rank wins; rank-test the
        # candidates in small chunks, since the first is usually independent.
        for start in range(0, candidates.size, 8):
            chunk = candidates[start : start + 8]
            full_rank = independent(subsets[chunk])
            if np.any(full_rank):
                i = int(chunk[np.argmax(full_rank)])
                return True, lam[i].copy(), tuple(int(j) for j in subsets[i])
    return False, None, None


def feasibility_margin(
    G: np.ndarray, w_l: np.ndarray, S: Sequence[int], lam0_norm: float
) -> float | None:
    """max t s.t. G lam = -w_L, lam_j >= t ||lam0|| (j in S), t <= 1 (HiGHS LP).

    Solved in units of ||lam0|| (lam' = lam / ||lam0||) so the LP tolerances are
    relative. Negative t: the model is infeasible. None for an empty S.
    """
    from scipy.optimize import linprog

    S = list(S)
    if not S:
        return None
    n = G.shape[1]
    c = np.zeros(n + 1)
    c[-1] = -1.0
    A_eq = np.hstack([G, np.zeros((6, 1))])
    b_eq = -w_l / lam0_norm
    A_ub = np.zeros((len(S), n + 1))
    for row, j in enumerate(S):
        A_ub[row, j] = -1.0
        A_ub[row, -1] = 1.0
    b_ub = np.zeros(len(S))
    bounds = [(None, None)] * n + [(None, 1.0)]
    res = linprog(
        c,
        A_ub=A_ub,
        b_ub=b_ub,
        A_eq=A_eq,
        b_eq=b_eq,
        bounds=bounds,
        method="highs",
        options={"primal_feasibility_tolerance": kLpTol, "dual_feasibility_tolerance": kLpTol},
    )
    if res.status != 0:
        raise RuntimeError(f"margin LP failed: {res.message}")
    return float(res.x[-1])


def paper_margin_x_fixed(G: np.ndarray, w_l: np.ndarray, lam0_norm: float) -> float:
    """The paper model's margin with every x component fixed to 0:
    max t s.t. G lam = -w_L, lam_ix = 0, lam_iy, lam_iz >= t ||lam0||, t <= 1.

    Without a moment about y_O, equilibrium forces sum c_i lam_ix = 0, so the paper
    model's own margin (x >= t too) is never above 0 and cannot tell a strongly feasible
    scene from a boundary one; with the x columns dropped the y/z margin can. Raises
    RuntimeError when x = 0 cannot hold equilibrium (a moment about y_O).
    """
    yz = [j for j in range(G.shape[1]) if j % 3 != 0]
    margin = feasibility_margin(G[:, yz], w_l, range(len(yz)), lam0_norm)
    assert margin is not None  # yz is never empty
    return margin


def x_fixed_equilibrium_gap(G: np.ndarray, w_l: np.ndarray, lam0_norm: float) -> float:
    """How far the paper model with every x component fixed to 0 must leave equilibrium:
    min s s.t. |G lam + w_L|_inf <= s ||lam0||, lam_ix = 0, lam_iy, lam_iz >= 0
    (HiGHS LP, in units of ||lam0||). 0 (to HiGHS's tolerance) when
    :func:`paper_margin_x_fixed` has an answer; where that LP is infeasible, because the
    x-fixed equalities contradict the load or their y/z forces cannot hold it, -gap is the
    margin's continuation: a scene infeasible by 4e-6 |lam0| is as near the boundary as
    one with a margin of -4e-6."""
    from scipy.optimize import linprog

    yz = [j for j in range(G.shape[1]) if j % 3 != 0]
    A = G[:, yz]
    n = len(yz)
    ones = np.ones((6, 1))
    # Variables [lam_yz, s]; minimise s.
    c = np.zeros(n + 1)
    c[-1] = 1.0
    A_ub = np.vstack([np.hstack([A, -ones]), np.hstack([-A, -ones])])
    b_ub = np.concatenate([-w_l / lam0_norm, w_l / lam0_norm])
    res = linprog(
        c,
        A_ub=A_ub,
        b_ub=b_ub,
        bounds=[(0.0, None)] * (n + 1),
        method="highs",
        options={"primal_feasibility_tolerance": kLpTol, "dual_feasibility_tolerance": kLpTol},
    )
    if res.status != 0:
        raise RuntimeError(f"equilibrium gap LP failed: {res.message}")
    return float(res.x[-1])


# --------------------------------------------------------------------------------------
# Steps 6-7: motor levels, PWM, orientation
# --------------------------------------------------------------------------------------
def motor_levels(lam: np.ndarray, policy: str) -> np.ndarray:
    """Unnormalised m (before m <- m / ||m||)."""
    lam_star = lam / np.linalg.norm(lam)
    per_contact = lam_star.reshape(-1, 3)
    if policy == "F":
        return np.linalg.norm(per_contact, axis=1)
    if policy == "Fperp":
        return per_contact[:, 1].copy()
    raise ValueError(f"unknown policy {policy!r}")


def round_half_away(x: float) -> int:
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def pwm_from_levels(
    levels: np.ndarray, mode: str, alpha: float, calibration: Any = None
) -> list[int]:
    """duty_i = round(floor_i + G * (gain_i * |m_i|)), clamped to 0..255 (G = PWM_RANGE in
    mode C, alpha in V). ``calibration`` (a core.motor_calibration.MotorCalibration, or
    None for the identity) gives floor_i and gain_i; its gains are rounded to float32, as
    SET_CALIBRATION and PLAN_BEGIN carry them."""
    out = []
    for i, mi in enumerate(levels):
        a = abs(float(mi))
        if a <= kMotorOffLevel:
            out.append(0)
            continue
        gain = PWM_RANGE if mode == "C" else alpha
        if calibration is None:
            out.append(min(255, max(0, round_half_away(PWM_BASE + a * gain))))
            continue
        floor_i = float(calibration.pwm_floor[i])
        gain_i = float(np.float32(calibration.gain[i]))
        out.append(min(255, max(0, round_half_away(floor_i + gain * (gain_i * a)))))
    return out


def guidance(q: np.ndarray, f: np.ndarray) -> tuple[float, float]:
    """(error_deg, alpha) for orientation q (hand -> world) and force f (hand frame)."""
    Rq = quaternion_to_matrix(q)
    d = Rq @ (f / np.linalg.norm(f))
    err = math.degrees(math.atan2(float(np.linalg.norm(np.cross(d, GRAVITY))), float(d @ GRAVITY)))
    alpha = float(np.linalg.norm(d - GRAVITY)) / 2.0 * PWM_RANGE
    return err, alpha


# --------------------------------------------------------------------------------------
# The whole pipeline
# --------------------------------------------------------------------------------------
def _result(status: str, k: int, **kw) -> dict[str, Any]:
    out: dict[str, Any] = {
        "status": status,
        "pwm": [0] * k,
        "levels": None,
        "lambda": None,
        "constraints_used": "",
        "relevant": None,
        "error_deg": None,
        "fallback_mask": 0,
        "margins": {},
        "alpha": None,
        "active_set": None,
        "diagnostics": None,
    }
    out.update(kw)
    return out


def _all_finite(x: Any) -> bool:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return bool(np.all(np.isfinite(a)))


def solve(
    contacts,
    wrench,
    policy: str = "F",
    mode: str = "C",
    constraints: str = "paper",
    orientation=(1.0, 0.0, 0.0, 0.0),
    y_axis=(0.0, 1.0, 0.0),
    compute_margins: bool = True,
    feas_rel_tol: float = kFeasRelTol,
) -> dict[str, Any]:
    """Run Algorithm 1 on one scene; see the module docstring for the output keys.

    contacts: k x 3 (hand frame, any length unit); wrench: [fx fy fz mx my mz] in the
    object frame (moment in force x length unit); orientation: [w x y z] hand -> world.
    feas_rel_tol overrides kFeasRelTol (used to find decisions that depend on it).
    """
    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}")
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}")
    if constraints not in CONSTRAINT_MODELS:
        raise ValueError(f"unknown constraint model {constraints!r}")

    contact_list = [list(c) for c in contacts]
    k = len(contact_list)

    # non_finite_input: any NaN/Inf anywhere.
    if not (
        all(_all_finite(c) for c in contact_list)
        and _all_finite(wrench)
        and _all_finite(y_axis)
        and _all_finite(orientation)
    ):
        return _result("non_finite_input", k)
    if k not in (3, 4) or any(len(c) != 3 for c in contact_list):
        return _result("bad_contact_count", k)
    C = _as_float_array(contact_list)
    w = _as_float_array(wrench).reshape(6)
    y = _as_float_array(y_axis).reshape(3)
    q = _as_float_array(orientation).reshape(4)

    y_norm = float(np.linalg.norm(y))
    if not y_norm > 0.0:
        return _result("bad_axis", k)
    y_o = y / y_norm
    if not float(np.linalg.norm(q)) >= kMinQuaternionNorm:
        return _result("bad_quaternion", k)

    status, frames = contact_frames(C, y_o)
    if status != "ok" or frames is None:
        return _result(status, k)
    mask = frames["fallback_mask"]

    if np.all(w == 0.0):
        return _result("zero_wrench", k)
    f = w[:3]
    w_l = np.concatenate([f, w[3:] / frames["L"]])
    if np.linalg.norm(f) <= kZeroForceRelTol * np.linalg.norm(w_l):
        return _result("zero_force", k)

    G = grasp_matrix(frames)
    if rank_ratio(G) < kRankRelTol:
        return _result("rank_deficient", k)

    lam0 = min_norm_solution(G, w_l)
    lam0_norm = float(np.linalg.norm(lam0))
    rel = relevance(f, frames["r"])
    lam_des = desired_forces(rel, lam0)

    margins: dict[str, float | None] = {}
    if compute_margins:
        for model in CONSTRAINT_MODELS:
            margins[model] = feasibility_margin(G, w_l, constrained_components(model, k), lam0_norm)

    used = None
    lam = None
    active = None
    for model in FALLBACK_CHAIN[constraints]:
        feasible, lam_m, active_m = project_enumerate(
            G, w_l, lam_des, constrained_components(model, k), lam0_norm, feas_rel_tol
        )
        if feasible:
            used, lam, active = model, lam_m, active_m
            break
    assert used is not None and lam is not None, "the 'none' model is always feasible"

    err, alpha = guidance(q, f)
    m = motor_levels(lam, policy)
    m_norm = float(np.linalg.norm(m))
    diagnostics = {
        "L": frames["L"],
        "rank_ratio": rank_ratio(G),
        "relevance_cos": [
            float(f @ ri / (np.linalg.norm(f) * np.linalg.norm(ri))) for ri in frames["r"]
        ],
        "axis_sin": [
            float(np.linalg.norm(np.cross(ri / np.linalg.norm(ri), y_o))) for ri in frames["r"]
        ],
        "lam0": [float(v) for v in lam0],
        "lam_des": [float(v) for v in lam_des],
        "model_used": used,
    }
    common = dict(
        fallback_mask=mask,
        margins=margins,
        relevant=[bool(b) for b in rel],
        **{"lambda": [float(v) for v in lam]},
        error_deg=err,
        alpha=alpha,
        active_set=active,
    )
    if m_norm == 0.0:
        return _result("nothing_to_display", k, levels=[0.0] * k, diagnostics=diagnostics, **common)
    levels = m / m_norm
    gain = PWM_RANGE if mode == "C" else alpha
    diagnostics["pwm_raw"] = [PWM_BASE + abs(float(v)) * gain for v in levels]
    return _result(
        "ok",
        k,
        levels=[float(v) for v in levels],
        pwm=pwm_from_levels(levels, mode, alpha),
        constraints_used=used,
        diagnostics=diagnostics,
        **common,
    )


__all__ = [
    "solve",
    "contact_frames",
    "grasp_matrix",
    "rank_ratio",
    "min_norm_solution",
    "relevance",
    "desired_forces",
    "constrained_components",
    "project_enumerate",
    "feasibility_margin",
    "paper_margin_x_fixed",
    "x_fixed_equilibrium_gap",
    "motor_levels",
    "pwm_from_levels",
    "guidance",
    "quaternion_to_matrix",
    "fallback_axis",
    "round_half_away",
    "TOLERANCES",
    "CONSTRAINT_MODELS",
    "POLICIES",
    "MODES",
]
