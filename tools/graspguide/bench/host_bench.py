"""`graspguide bench`: what a frame costs on the host, and how this project's QP compares
with the solvers a user would otherwise pick, on the same instances, in one process.

Instances (:func:`make_instances`): per contact count k, ``--instances`` seeded random
hands (:func:`graspguide.core.scene_generators.random_scenes`) and the paper's hand
(``scenes.nominal_contacts``, the contacts of ``tools/examples/scene_paper_{3,4}.toml``)
under the 26 unit-force directions of a cube's faces, edges and corners plus the named
nominal-hand cases of :func:`graspguide.core.scene_generators.extreme_scenes` that are
expected to be ok.
Every scene is run twice: constraint model ``paper`` with policy F, mode C, and ``normal``
with Fperp, mode V. The float64 reference (:func:`graspguide.core.reference.solve`: SVD and
exhaustive active-set enumeration) answers every instance once.

The QP (docs/algorithm.md, step 5) is handed to every solver in the same form, computed
once in float64 from the reference's quantities: variables xi (3k - 6 of them),

    min 1/2 |xi - xi_u|^2   s.t.   A xi >= b,   A = N[S, :],  b = -lambda0[S],
    xi_u = N^T (lambda_des - lambda0),            lambda = lambda0 + N xi,

with N an orthonormal basis of null(G) (numpy SVD), S the components the model
constrains (paper: all 3k, normal: the k normal ones), and the fallback chain
paper -> normal -> none, so an instance is solved as the device would solve it. A solver
that declares a model infeasible moves on to the next; its verdicts are checked against
the reference's.

What is timed (see tools/README.md for the columns):

* ``frame``: Guidance<T> frames with new contacts every frame (the whole grasp part:
  contact frames, grasp matrix, decomposition, QP, levels, PWM), timed in a C++ loop
  (``_core.time_frames``): float/double, the structured and the SVD route, and an iteration-limit
  variant. ``fixed``: frames with a fixed posture (orientation only). ``stages``: each
  stage of a frame in its own C++ loop (``_core.time_stages``), to say what dominates.
* ``py-call``: the same through the existing binding, one Python call per frame, and
  through the public API (``graspguide.core.solver``: ``solve``, ``Guidance``), which
  checks the Python types on top of the binding.
* ``qp``: the QP alone: the SVD reference route's null-space QP, the very problem the other
  solvers get, in a C++ loop (``_core.time_qp``; the structured QP is a stage of ``stages``),
  DAQP (its own ``solve_time`` from ``info``, and the Python call), quadprog and OSQP
  (one problem object per shape, reused through ``update()``, warm-started; its own
  ``update + solve + polish`` time) per Python call, and ``scipy.optimize.minimize``
  (SLSQP), the numpy/scipy a user would write.
* ``py-pipeline``: a whole frame written with numpy and scipy (reference geometry,
  ``numpy.linalg.pinv``, ``scipy.linalg.null_space``, SLSQP, motor mapping).

Noise: every series is measured in passes, round-robin over all series so that a
disturbance of the (shared) machine hits all of them alike. A series is repeated (another
pass) while the spread of its pass medians exceeds :data:`MEDIAN_SPREAD_MAX` or that of
its pass 99th percentiles exceeds :data:`P99_SPREAD_MAX`, up to ``max_passes``. The
figures are over ALL samples of all passes (nothing is dropped or picked); the number of
passes, both spreads and whether the series ended stable are reported.
"""

from __future__ import annotations

import contextlib
import gc
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from graspguide.core import _core, reference, solver
from graspguide.core import scene_generators as scenes
from graspguide.exit_codes import EXIT_USAGE, fail

SCHEMA = "graspguide-bench/1"

# The goal: a whole k=4 double frame within 0.6 of DAQP's QP alone on the same instances.
GOAL_RATIO = 0.6

# Noise rule (module docstring): a series is repeated while its pass medians differ by
# more than 10 % or its pass p99s by more than 25 % (the tail is noisier by nature).
MEDIAN_SPREAD_MAX = 0.10
P99_SPREAD_MAX = 0.25

# A solution satisfies the constraints when no constrained component of lambda is below
# -tol * |lambda0| (the same relative measure as the core's kFeasRelTol). Looser than
# kFeasRelTol (1e-9 / 1e-4) so that a solver's own tolerance, not the test, decides.
VIOLATION_TOL = {"double": 1e-6, "float": 1e-3}

# The iteration-limit variant of the frame and the tolerance variant of the QP.
LIMITED_ITERATIONS = 2
LOOSE_FEAS_REL = 1e-6

# OSQP settings: tight tolerances and solution polishing, so that its accuracy is judged
# at its best (its defaults, 1e-3, would fail VIOLATION_TOL on most instances).
OSQP_SETTINGS = dict(
    eps_abs=1e-9, eps_rel=1e-9, polishing=True, warm_starting=True, verbose=False, max_iter=20000
)
SLSQP_OPTIONS = dict(ftol=1e-12, maxiter=200)

RUNS = (("paper", "F", "C"), ("normal", "Fperp", "V"))
CHAIN = {"paper": ("paper", "normal", "none"), "normal": ("normal", "none"), "none": ("none",)}


class BenchError(RuntimeError):
    """The benchmark cannot run as asked (a missing solver, bad options)."""


# --------------------------------------------------------------------------------------
# Instances and the float64 reference
# --------------------------------------------------------------------------------------
@dataclass
class Instance:
    name: str
    group: str  # "random" | "paper"
    k: int
    contacts: list[list[float]]
    wrench: list[float]
    y_axis: list[float]
    orientation: list[float]
    constraints: str
    policy: str
    mode: str
    ref: dict[str, Any] = field(default_factory=dict)  # reference.solve's answer
    # float64 QP data (None unless the reference status is ok)
    G: np.ndarray | None = None
    w_l: np.ndarray | None = None
    lam0: np.ndarray | None = None
    lam_des: np.ndarray | None = None
    N: np.ndarray | None = None
    xi_u: np.ndarray | None = None
    qp: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # model -> (A, b)

    @property
    def ok(self) -> bool:
        return self.ref.get("status") == "ok"

    @property
    def lam0_norm(self) -> float:
        return float(np.linalg.norm(self.lam0))


def _cube_directions() -> list[np.ndarray]:
    """The 26 directions from a cube's centre to its faces, edges and corners."""
    out = []
    for x in (-1, 0, 1):
        for y in (-1, 0, 1):
            for z in (-1, 0, 1):
                if (x, y, z) != (0, 0, 0):
                    v = np.array([x, y, z], dtype=np.float64)
                    out.append(v / np.linalg.norm(v))
    return out


def paper_scenes(k: int) -> list[dict[str, Any]]:
    """The paper's hand (scene_paper_{k}.toml) under the cube's 26 force directions, and
    the named nominal-hand cases of scenes.extreme_scenes() that are expected to be ok."""
    hand = scenes.nominal_contacts(k)
    tilt = scenes.random_quaternion(np.random.default_rng([2024, k]))
    out = []
    for i, d in enumerate(_cube_directions()):
        out.append(
            {
                "name": f"paper_k{k}_dir{i:02d}",
                "k": k,
                "contacts": hand.tolist(),
                "wrench": [*d.tolist(), 0.0, 0.0, 0.0],
                "y_axis": list(scenes.DEFAULT_Y_AXIS),
                "orientation": [float(v) for v in tilt],
            }
        )
    for case in scenes.extreme_scenes():
        if (
            case.get("expect_status") == "ok"
            and case["k"] == k
            and np.array_equal(np.asarray(case["contacts"]), hand)
        ):
            out.append(
                {
                    key: case[key]
                    for key in ("name", "k", "contacts", "wrench", "y_axis", "orientation")
                }
            )
    return out


def _qp_data(inst: Instance) -> None:
    """G, w_L, lambda0, lambda_des from the reference's own functions; N from numpy's SVD."""
    C = np.asarray(inst.contacts, dtype=np.float64)
    y = np.asarray(inst.y_axis, dtype=np.float64)
    status, frames = reference.contact_frames(C, y / np.linalg.norm(y))
    if status != "ok":  # the reference said ok, so this cannot happen
        raise BenchError(f"{inst.name}: reference frames {status}")
    G = reference.grasp_matrix(frames)
    w = np.asarray(inst.wrench, dtype=np.float64)
    inst.G = G
    inst.w_l = np.concatenate([w[:3], w[3:] / frames["L"]])
    diag = inst.ref["diagnostics"]
    inst.lam0 = np.asarray(diag["lam0"], dtype=np.float64)
    inst.lam_des = np.asarray(diag["lam_des"], dtype=np.float64)
    _, _, vt = np.linalg.svd(G)
    inst.N = np.ascontiguousarray(vt[6:].T)
    inst.xi_u = inst.N.T @ (inst.lam_des - inst.lam0)
    for model in ("paper", "normal"):
        S = reference.constrained_components(model, inst.k)
        inst.qp[model] = (np.ascontiguousarray(inst.N[S, :]), -inst.lam0[S])


def _instance(sc: dict[str, Any], group: str, model: str, policy: str, mode: str) -> Instance:
    """One scene under one model, policy and mode, with the reference's answer and, when
    it is ok, the QP data."""
    inst = Instance(
        name=f"{sc['name']}/{model}",
        group=group,
        k=int(sc["k"]),
        contacts=[list(map(float, c)) for c in sc["contacts"]],
        wrench=list(map(float, sc["wrench"])),
        y_axis=list(map(float, sc["y_axis"])),
        orientation=list(map(float, sc["orientation"])),
        constraints=model,
        policy=policy,
        mode=mode,
    )
    inst.ref = reference.solve(
        inst.contacts,
        inst.wrench,
        policy,
        mode,
        model,
        inst.orientation,
        inst.y_axis,
        compute_margins=False,
    )
    if inst.ok:
        _qp_data(inst)
    return inst


def make_instances(
    count: int, seed: int, ks: Sequence[int], progress: Callable[[str], None] | None = None
) -> list[Instance]:
    """Random hands and paper scenes for each k, each with both runs, with the reference
    answer and the QP data attached."""
    if count < 0:
        raise BenchError("the number of random instances must be >= 0")
    out: list[Instance] = []
    for k in ks:
        if k not in (3, 4):
            raise BenchError(f"k must be 3 or 4, got {k}")
        groups = [("random", scenes.random_scenes(seed, k, count)), ("paper", paper_scenes(k))]
        for group, scs in groups:
            for sc in scs:
                for model, policy, mode in RUNS:
                    out.append(_instance(sc, group, model, policy, mode))
        if progress:
            progress(
                f"k={k}: {sum(1 for i in out if i.k == k)} instances with their float64 reference"
            )
    return out


# --------------------------------------------------------------------------------------
# Accuracy against the reference
# --------------------------------------------------------------------------------------
def reference_pwm(inst: Instance, lam: np.ndarray) -> list[int] | None:
    """PWM of lambda through the reference's motor mapping (policy, mode, alpha)."""
    m = reference.motor_levels(lam, inst.policy)
    n = float(np.linalg.norm(m))
    if not (n > 0.0) or not np.all(np.isfinite(m)):
        return None
    return reference.pwm_from_levels(m / n, inst.mode, inst.ref["alpha"])


@dataclass
class Outcome:
    """One solver's answer on one instance: a status, the model it used, lambda, PWM."""

    status: str  # "ok" or what went wrong (a core status, an error)
    used: str = ""
    lam: np.ndarray | None = None
    pwm: list[int] | None = None


def binding_outcome(d: dict[str, Any]) -> Outcome:
    """The Outcome of one answer dict of the binding (_core.solve, Guidance.update)."""
    lam = d["lambda"]
    return Outcome(
        d["status"], d["constraints_used"], None if lam is None else np.asarray(lam), d["pwm"]
    )


def judge(inst: Instance, out: Outcome, scalar: str = "double") -> dict[str, Any]:
    """Compare one outcome with the reference. `failure` is None or the reason: the
    solver's own error, a constraint model other than the reference's (a wrong
    feasibility verdict), a violation above VIOLATION_TOL, a status other than the
    reference's, or a missing PWM."""
    rec: dict[str, Any] = {
        "instance": inst.name,
        "status": out.status,
        "used": out.used,
        "failure": None,
    }
    rec["agree"] = False  # same status, and where ok the same model and PWM within 1
    if not inst.ok:  # a frame that must fail: it must fail with the reference's status
        if out.status != inst.ref["status"]:
            rec["failure"] = f"status {out.status}, reference {inst.ref['status']}"
        rec["agree"] = out.status == inst.ref["status"]
        return rec
    if out.status != "ok" or out.lam is None:
        rec["failure"] = out.status if out.status != "ok" else "no solution"
        return rec
    lam = np.asarray(out.lam, dtype=np.float64)
    lam_ref = np.asarray(inst.ref["lambda"], dtype=np.float64)
    scale = inst.lam0_norm
    S = reference.constrained_components(out.used or "none", inst.k)
    viol = max(0.0, -float(lam[S].min())) / scale if S else 0.0
    j = float(np.sum((lam - inst.lam_des) ** 2))
    j_ref = float(np.sum((lam_ref - inst.lam_des) ** 2))
    rec["violation_rel"] = viol
    rec["objective_gap_rel"] = (j - j_ref) / max(j_ref, 1e-300)
    rec["lambda_err_rel"] = float(np.linalg.norm(lam - lam_ref) / np.linalg.norm(lam_ref))
    rec["equilibrium_residual_rel"] = float(
        np.linalg.norm(inst.G @ lam + inst.w_l) / np.linalg.norm(inst.w_l)
    )
    pwm = out.pwm if out.pwm is not None else reference_pwm(inst, lam)
    if pwm is None:
        rec["failure"] = "nothing_to_display"
    else:
        rec["pwm_diff"] = int(max(abs(a - b) for a, b in zip(pwm, inst.ref["pwm"])))
    if not math.isfinite(viol):
        rec["failure"] = "non-finite solution"
    elif out.used != inst.ref["constraints_used"]:
        rec["failure"] = f"wrong model: {out.used}, reference {inst.ref['constraints_used']}"
    elif viol > VIOLATION_TOL[scalar]:
        rec["failure"] = "constraint violation"
    rec["agree"] = out.used == inst.ref["constraints_used"] and rec.get("pwm_diff", 2) <= 1
    return rec


def summarize_accuracy(records: list[dict[str, Any]]) -> dict[str, Any]:
    def collect(key):
        return [r[key] for r in records if key in r and r[key] is not None]

    failures = [
        {"instance": r["instance"], "reason": r["failure"]} for r in records if r["failure"]
    ]
    reasons: dict[str, int] = {}
    for f in failures:
        key = f["reason"].split(":")[0]
        reasons[key] = reasons.get(key, 0) + 1
    diffs = collect("pwm_diff")
    gaps = [abs(g) for g in collect("objective_gap_rel")]
    agree = sum(1 for r in records if r.get("agree"))
    return {
        "instances": len(records),
        "agree": agree,
        "agree_share": agree / len(records) if records else None,
        "failures": len(failures),
        "failure_reasons": reasons,
        "failed": failures,
        "compared_pwm": len(diffs),
        "pwm_mismatch": sum(1 for d in diffs if d > 0),
        "pwm_mismatch_over_1": sum(1 for d in diffs if d > 1),
        "pwm_mismatches_over_1": [
            {"instance": r["instance"], "pwm_diff": r["pwm_diff"]}
            for r in records
            if r.get("pwm_diff", 0) > 1
        ],
        "max_pwm_diff": max(diffs) if diffs else None,
        "max_violation_rel": max(collect("violation_rel"), default=None),
        "max_objective_gap_rel": max(gaps, default=None),
        "median_objective_gap_rel": float(np.median(gaps)) if gaps else None,
        "max_lambda_err_rel": max(collect("lambda_err_rel"), default=None),
        "max_equilibrium_residual_rel": max(collect("equilibrium_residual_rel"), default=None),
    }


# --------------------------------------------------------------------------------------
# The accuracy set (--accuracy-scenes): more hands than the timing can afford, judged
# like the timed frames, so the cost-against-accuracy table can rest on a larger sample.
# --------------------------------------------------------------------------------------
# Its hands are drawn with seed + this offset, so they are not the timing set's hands.
ACCURACY_SEED_OFFSET = 10
# Scene i takes combination i mod 12, in the stage scenes' order (policy, mode, model).
COMBINATIONS = tuple(
    (model, policy, mode)
    for policy in ("F", "Fperp")
    for mode in ("C", "V")
    for model in ("paper", "normal", "none")
)
# The frame configurations the table weighs: (scalar, decomposition), cheapest first.
FRAME_ROUTES = (
    ("float", "structured"),
    ("double", "structured"),
    ("float", "svd"),
    ("double", "svd"),
)


def frame_name(scalar: str, decomposition: str) -> str:
    return f"frame {scalar} {decomposition}"


def accuracy_instances(
    count: int, seed: int, ks: Sequence[int], progress: Callable[[str], None] | None = None
) -> list[Instance]:
    """``count`` random hands per k (seed ``seed + ACCURACY_SEED_OFFSET``), scene i under
    ``COMBINATIONS[i % 12]``, each with its float64 reference."""
    out: list[Instance] = []
    for k in ks:
        t0 = time.perf_counter()
        for i, sc in enumerate(scenes.random_scenes(seed + ACCURACY_SEED_OFFSET, k, count)):
            out.append(_instance(sc, "accuracy", *COMBINATIONS[i % len(COMBINATIONS)]))
        if progress:
            progress(
                f"accuracy set k={k}: {count} scenes with their float64 reference "
                f"in {time.perf_counter() - t0:.0f} s"
            )
    return out


def solve_args(inst: Instance, scalar: str) -> tuple[Any, ...]:
    """The positional arguments _core.solve and solver.solve share, up to the scalar."""
    return (
        inst.contacts,
        inst.wrench,
        inst.policy,
        inst.mode,
        inst.constraints,
        inst.orientation,
        inst.y_axis,
        scalar,
    )


def run_accuracy_set(insts: list[Instance], ks: Sequence[int]) -> list[dict[str, Any]]:
    """Every frame route on every instance of the accuracy set, one ``_core.solve`` call
    each (the same Guidance<T> frame the C++ loop times), judged against the reference."""
    results = []
    for k in ks:
        mine = [i for i in insts if i.k == k]
        for scalar, dec in FRAME_ROUTES:
            records = [
                judge(
                    inst,
                    binding_outcome(
                        _core.solve(*solve_args(inst, scalar), dec, _core.kDefaultMaxIterations)
                    ),
                    scalar,
                )
                for inst in mine
            ]
            results.append(
                {
                    "name": frame_name(scalar, dec),
                    "k": k,
                    "scalar": scalar,
                    "decomposition": dec,
                    "accuracy": summarize_accuracy(records),
                }
            )
    return results


# --------------------------------------------------------------------------------------
# Peer QP solvers (Python), each: solve(xi_u, A, b) -> (verdict, xi, internal) with
# verdict "optimal", "infeasible" or an error text, and internal None or a tuple of the
# solver's own times in ns.
# --------------------------------------------------------------------------------------
DAQP_EXITFLAGS = {
    2: "soft optimal",
    1: "optimal",
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "iteration limit",
    -5: "nonconvex",
    -6: "overdetermined initial active set",
}


class DaqpSolver:
    """daqp.solve, the one-shot call (H = I is factorised in its setup)."""

    name = "daqp"

    def __init__(self):
        import daqp

        self._daqp = daqp
        self.version = getattr(daqp, "__version__", None) or _dist_version("daqp")

    def solve(self, xi_u, A, b):
        n, m = xi_u.size, b.size
        x, _, flag, info = self._daqp.solve(
            np.eye(n), -xi_u, A, np.full(m, 1e30), b, np.zeros(m, dtype=np.int32)
        )
        # DAQP's own clocks, in seconds: (solve, setup + solve).
        internal = (info["solve_time"] * 1e9, (info["setup_time"] + info["solve_time"]) * 1e9)
        if flag in (1, 2):
            return "optimal", np.asarray(x, dtype=np.float64), internal
        if flag == -1:
            return "infeasible", None, internal
        return f"daqp exitflag {flag} ({DAQP_EXITFLAGS.get(flag, 'unknown')})", None, internal


class QuadprogSolver:
    name = "quadprog"

    def __init__(self):
        import quadprog

        self._solve_qp = quadprog.solve_qp
        self.version = _dist_version("quadprog")

    def solve(self, xi_u, A, b):
        try:
            x = self._solve_qp(np.eye(xi_u.size), xi_u, np.ascontiguousarray(A.T), b, 0)[0]
        except ValueError as e:
            if "inconsistent" in str(e):
                return "infeasible", None, None
            return f"quadprog: {e}", None, None
        return "optimal", np.asarray(x, dtype=np.float64), None


class OsqpSolver:
    """One OSQP problem per shape (variables, rows), set up once and then only updated
    (q, l, u and the values of A, whose sparsity pattern is kept dense), warm-started
    from whatever it solved last."""

    name = "osqp"

    def __init__(self):
        import osqp
        import scipy.sparse as sp

        self._osqp = osqp
        self._sp = sp
        self.version = getattr(osqp, "__version__", None) or _dist_version("osqp")
        self.problems: dict[tuple[int, int], Any] = {}
        self.setups = 0
        self.updates = 0
        self.last_iterations = 0

    def _dense_csc(self, A):
        m, n = A.shape
        indptr = np.arange(0, m * n + 1, m)
        indices = np.tile(np.arange(m), n)
        return self._sp.csc_matrix((A.flatten(order="F"), indices, indptr), shape=(m, n))

    def solve(self, xi_u, A, b):
        m, n = A.shape
        upper = np.full(m, np.inf)
        prob = self.problems.get((n, m))
        if prob is None:
            prob = self._osqp.OSQP()
            prob.setup(
                self._sp.csc_matrix(np.eye(n)), -xi_u, self._dense_csc(A), b, upper, **OSQP_SETTINGS
            )
            self.problems[(n, m)] = prob
            self.setups += 1
        else:
            prob.update(q=-xi_u, l=b, u=upper, Ax=A.flatten(order="F"))
            self.updates += 1
        res = prob.solve(raise_error=False)  # statuses are judged below, not raised
        info = res.info
        self.last_iterations = info.iter
        internal = ((info.update_time + info.solve_time + info.polish_time) * 1e9,)
        status = info.status_val
        S = self._osqp.SolverStatus
        if status in (S.OSQP_SOLVED, S.OSQP_SOLVED_INACCURATE):
            return "optimal", np.asarray(res.x, dtype=np.float64), internal
        if status in (S.OSQP_PRIMAL_INFEASIBLE, S.OSQP_PRIMAL_INFEASIBLE_INACCURATE):
            return "infeasible", None, internal
        return f"osqp {info.status}", None, internal


class SlsqpSolver:
    """scipy.optimize.minimize(method='SLSQP') with analytic gradients, started at xi_u;
    anything but success counts as 'infeasible' and moves to the next model, as a user's
    fallback chain would do (a wrong verdict then shows as a wrong model)."""

    name = "scipy-slsqp"

    def __init__(self):
        import scipy
        from scipy.optimize import minimize

        self._minimize = minimize
        self.version = scipy.__version__

    def solve(self, xi_u, A, b):
        res = self._minimize(
            lambda x: 0.5 * float((x - xi_u) @ (x - xi_u)),
            xi_u.copy(),
            jac=lambda x: x - xi_u,
            method="SLSQP",
            constraints=[{"type": "ineq", "fun": lambda x: A @ x - b, "jac": lambda x: A}],
            options=SLSQP_OPTIONS,
        )
        if res.success:
            return "optimal", np.asarray(res.x, dtype=np.float64), None
        return "infeasible", None, None


def _dist_version(name: str) -> str | None:
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:  # noqa: BLE001 - a version is only informational
        return None


def solve_chain(solver, inst: Instance) -> tuple[Outcome, float, tuple[float, ...] | None]:
    """The fallback chain with one peer solver: (outcome, wall ns of the solver calls,
    the solver's own times summed over its calls, or None)."""
    wall = 0.0
    internal: tuple[float, ...] | None = ()
    for model in CHAIN[inst.constraints]:
        if model == "none":  # no constraints: the unconstrained optimum, no solver call
            lam = inst.lam0 + inst.N @ inst.xi_u
            return Outcome("ok", "none", lam), wall, internal or None
        A, b = inst.qp[model]
        t0 = time.perf_counter_ns()
        try:
            verdict, xi, t_int = solver.solve(inst.xi_u, A, b)
        except Exception as e:  # noqa: BLE001 - a solver crash is a failure, reported
            verdict, xi, t_int = f"{type(e).__name__}: {e}", None, None
        wall += time.perf_counter_ns() - t0
        if internal is not None and t_int is not None:
            internal = (
                tuple(t_int) if not internal else tuple(a + b for a, b in zip(internal, t_int))
            )
        else:
            internal = None
        if verdict == "infeasible":
            continue
        if verdict != "optimal":
            return Outcome(f"error: {verdict}"), wall, internal or None
        return Outcome("ok", model, inst.lam0 + inst.N @ xi), wall, internal or None
    raise AssertionError("unreachable: the chain ends with 'none'")


def numpy_pipeline(inst: Instance, slsqp: SlsqpSolver) -> Outcome:
    """A whole frame as a user would write it with numpy and scipy."""
    from scipy.linalg import null_space

    C = np.asarray(inst.contacts, dtype=np.float64)
    y = np.asarray(inst.y_axis, dtype=np.float64)
    status, frames = reference.contact_frames(C, y / np.linalg.norm(y))
    if status != "ok":
        return Outcome(status)
    G = reference.grasp_matrix(frames)
    w = np.asarray(inst.wrench, dtype=np.float64)
    f = w[:3]
    w_l = np.concatenate([f, w[3:] / frames["L"]])
    lam0 = -np.linalg.pinv(G) @ w_l
    N = null_space(G)
    lam_des = reference.desired_forces(reference.relevance(f, frames["r"]), lam0)
    xi_u = N.T @ (lam_des - lam0)
    for model in CHAIN[inst.constraints]:
        if model == "none":
            lam, used = lam0 + N @ xi_u, "none"
            break
        S = reference.constrained_components(model, inst.k)
        verdict, xi, _ = slsqp.solve(xi_u, N[S, :], -lam0[S])
        if verdict == "optimal":
            lam, used = lam0 + N @ xi, model
            break
    m = reference.motor_levels(lam, inst.policy)
    _, alpha = reference.guidance(np.asarray(inst.orientation), f)
    pwm = reference.pwm_from_levels(m / np.linalg.norm(m), inst.mode, alpha)
    return Outcome("ok", used, lam, pwm)


# --------------------------------------------------------------------------------------
# Timing series
# --------------------------------------------------------------------------------------
def _percentile(values: Sequence[float], q: float) -> float:
    return float(np.percentile(np.asarray(values, dtype=np.float64), q))


@dataclass
class Series:
    """The samples of one timed quantity, per pass."""

    label: str  # e.g. "C++ loop", "internal solve_time", "Python call"
    passes: list[list[float]] = field(default_factory=list)

    def add(self, samples: list[float]) -> None:
        self.passes.append([float(s) for s in samples])

    def spreads(self) -> tuple[float, float]:
        meds = [float(np.median(p)) for p in self.passes if p]
        p99s = [_percentile(p, 99) for p in self.passes if p]
        if len(meds) < 2:
            return 0.0, 0.0
        return (
            (max(meds) - min(meds)) / max(min(meds), 1e-12),
            (max(p99s) - min(p99s)) / max(min(p99s), 1e-12),
        )

    def stable(self) -> bool:
        if not any(self.passes):
            return True
        med, p99 = self.spreads()
        return med <= MEDIAN_SPREAD_MAX and p99 <= P99_SPREAD_MAX

    def summary(self) -> dict[str, Any]:
        pooled = [s for p in self.passes for s in p]
        med, p99 = self.spreads()
        if not pooled:
            return {"label": self.label, "samples": 0, "passes": len(self.passes)}
        return {
            "label": self.label,
            "median_ns": float(np.median(pooled)),
            "p99_ns": _percentile(pooled, 99),
            "mean_ns": float(np.mean(pooled)),
            "min_ns": float(np.min(pooled)),
            "max_ns": float(np.max(pooled)),
            "samples": len(pooled),
            "passes": len(self.passes),
            "pass_medians_ns": [float(np.median(p)) for p in self.passes],
            "median_spread": med,
            "p99_spread": p99,
            "stable": self.stable(),
        }


@dataclass
class Config:
    """One benchmarked configuration on one k: run_pass() adds one pass to every series."""

    name: str
    group: str  # frame | fixed | py-call | qp | py-pipeline
    solver: str
    k: int
    scalar: str
    settings: dict[str, Any]
    run: Callable[[Config], None]
    instances: list[Instance]
    series: dict[str, Series] = field(default_factory=dict)
    outcomes: list[Outcome] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def serie(self, key: str, label: str) -> Series:
        if key not in self.series:
            self.series[key] = Series(label)
        return self.series[key]

    def stable(self) -> bool:
        return all(s.stable() for s in self.series.values())

    def result(self) -> dict[str, Any]:
        records = [
            judge(inst, out, self.scalar) for inst, out in zip(self.instances, self.outcomes or [])
        ]
        return {
            "name": self.name,
            "group": self.group,
            "solver": self.solver,
            "k": self.k,
            "scalar": self.scalar,
            "settings": self.settings,
            "timing": {key: s.summary() for key, s in self.series.items()},
            "accuracy": summarize_accuracy(records),
            **self.extra,
        }


def _frame_args(insts: list[Instance]):
    """The positional arguments of ``_core.time_frames`` and ``time_stages``: the one
    ``instances`` tuple of per-instance lists."""
    instances = (
        [i.contacts for i in insts],
        [i.wrench for i in insts],
        [i.orientation for i in insts],
        [i.y_axis for i in insts],
        [i.policy for i in insts],
        [i.mode for i in insts],
        [i.constraints for i in insts],
    )
    return (instances,)


def _outcomes_from_core(res: dict[str, Any]) -> list[Outcome]:
    return [
        Outcome(st, used, None if lam is None else np.asarray(lam), list(pwm))
        for st, used, lam, pwm in zip(
            res["status"], res["constraints_used"], res["lambda"], res["pwm"]
        )
    ]


def _flatten(ns: list[list[float]]) -> list[float]:
    return [v for per in ns for v in per]


CXX_WARMUP = 4  # untimed passes of each C++ loop before the timed ones


def _cxx_loop_config(
    name, group, k, scalar, settings, insts, timer, args, collect, **options
) -> Config:
    """A configuration timed by one of the binding's C++ loops (``_core.time_*``) over
    ``settings``' reps and batches; ``collect(cfg, res)`` files what the loop returned."""

    def run(cfg: Config) -> None:
        res = timer(
            *args,
            scalar=scalar,
            reps=settings["reps"],
            batches=settings["batches"],
            warmup=CXX_WARMUP,
            **options,
        )
        collect(cfg, res)

    return Config(name, group, "graspguide", k, scalar, settings, run, insts)


def cxx_frame_config(
    name, insts, k, scalar, decomposition, max_iterations, fixed, reps, batches
) -> Config:
    def collect(cfg: Config, res: dict[str, Any]) -> None:
        cfg.serie("cxx", "C++ loop").add(_flatten(res["ns"]))
        cfg.outcomes = _outcomes_from_core(res)
        cfg.extra["recomputed_per_instance"] = sorted(set(res["recomputed"]))
        cfg.extra["frames_per_instance"] = res["frames_per_instance"]

    settings = {
        "decomposition": decomposition,
        "max_iterations": max_iterations,
        "reps": reps,
        "batches": batches,
    }
    return _cxx_loop_config(
        name,
        "fixed" if fixed else "frame",
        k,
        scalar,
        settings,
        insts,
        _core.time_frames,
        _frame_args(insts),
        collect,
        decomposition=decomposition,
        max_iterations=max_iterations,
        fixed_posture=fixed,
    )


STAGES = ("contact_frames", "structure", "forces", "qp", "levels_pwm")


def cxx_stages_config(name, insts, k, scalar, decomposition, reps, batches) -> Config:
    """Each stage of a frame in its own C++ loop: what dominates a frame."""
    ok = [i for i in insts if i.ok]

    def collect(cfg: Config, res: list[dict[str, Any]]) -> None:
        for stage in STAGES:
            cfg.serie(stage, f"stage {stage}").add([v for d in res for v in d.get(stage, [])])
        cfg.extra["instances_timed"] = sum(1 for d in res if d)

    settings = {
        "decomposition": decomposition,
        "reps": reps,
        "batches": batches,
    }
    return _cxx_loop_config(
        name,
        "stages",
        k,
        scalar,
        settings,
        ok,
        _core.time_stages,
        _frame_args(ok),
        collect,
        decomposition=decomposition,
    )


def _qp_args(insts: list[Instance]):
    return (
        [i.lam0.tolist() for i in insts],
        [i.N.flatten().tolist() for i in insts],
        [i.lam_des.tolist() for i in insts],
        [i.constraints for i in insts],
    )


def cxx_qp_config(name, insts, k, scalar, violation_rel, reps, batches) -> Config:
    def collect(cfg: Config, res: dict[str, Any]) -> None:
        cfg.serie("cxx", "C++ loop").add(_flatten(res["ns"]))
        cfg.outcomes = [
            Outcome(st, used, None if lam is None else np.asarray(lam))
            for st, used, lam in zip(res["status"], res["constraints_used"], res["lambda"])
        ]

    settings = {
        "feas_rel": violation_rel or None,
        "reps": reps,
        "batches": batches,
    }
    return _cxx_loop_config(
        name,
        "qp",
        k,
        scalar,
        settings,
        insts,
        _core.time_qp,
        _qp_args(insts),
        collect,
        violation_rel=violation_rel,
    )


# The series of a py-call configuration: the binding itself, and the same call through the
# public API (graspguide.core.solver: its type checks on top of the binding).
PY_CALL_SERIES = {"py": "Python call", "api": "public API call"}


def _py_call_config(name, insts, k, scalar, calls, binding, pass_timer) -> Config:
    """A configuration of the existing binding timed one Python call at a time, through
    the binding and through the public API. ``pass_timer()`` starts a pass and returns
    ``time(inst, samples)``, which adds the instance's call times to ``samples[key]``
    (keys: :data:`PY_CALL_SERIES`) and returns its Outcome."""

    def run(cfg: Config) -> None:
        samples: dict[str, list[int]] = {key: [] for key in PY_CALL_SERIES}
        time_instance = pass_timer()
        cfg.outcomes = [time_instance(inst, samples) for inst in insts]
        for key, label in PY_CALL_SERIES.items():
            cfg.serie(key, label).add(samples[key])

    settings = {"decomposition": "structured", "calls": calls, "binding": binding}
    return Config(name, "py-call", "graspguide", k, scalar, settings, run, insts)


def _timed_pair(r: int, binding: Callable[[], Any], api: Callable[[], Any], samples) -> Any:
    """Call ``binding`` and ``api`` (which must answer alike), the first alternately, so
    that neither always finds the caches warmed by the other; their times go to
    ``samples``. Returns the binding's answer."""
    answers = {}
    for key in ("py", "api") if r % 2 == 0 else ("api", "py"):
        call = binding if key == "py" else api
        t0 = time.perf_counter_ns()
        answers[key] = call()
        samples[key].append(time.perf_counter_ns() - t0)
    if answers["py"] != answers["api"]:
        raise BenchError(f"the public API and the binding disagree: {answers}")
    return answers["py"]


def py_guidance_config(name, insts, k, calls) -> Config:
    """The existing stateful binding, one Python call per frame (set_contacts + update)."""

    def pass_timer() -> Callable[[Instance, dict[str, list[int]]], Outcome]:
        g = _core.Guidance()
        api = solver.Guidance()

        def time_instance(inst: Instance, samples: dict[str, list[int]]) -> Outcome:
            st = g.set_scene(inst.contacts, inst.policy, inst.mode, inst.constraints, inst.y_axis)
            if st == "ok":
                st = g.set_wrench(inst.wrench)
            api.set_scene(inst.contacts, inst.policy, inst.mode, inst.constraints, inst.y_axis)
            api.set_wrench(inst.wrench)
            if st != "ok":
                return Outcome(st)
            moved = np.nextafter(np.asarray(inst.contacts), np.inf).tolist()
            q = inst.orientation
            for r in range(calls):
                c = moved if r % 2 == 0 else inst.contacts
                _timed_pair(
                    r,
                    lambda c=c: (g.set_contacts(c), g.update(q)),
                    lambda c=c: (api.set_contacts(c), api.update(q)),
                    samples,
                )
            g.set_contacts(moved)
            g.update(q)
            g.set_contacts(inst.contacts)
            return binding_outcome(g.update(q))

        return time_instance

    binding = "_core.Guidance set_contacts + update"
    return _py_call_config(name, insts, k, "double", calls, binding, pass_timer)


def py_solve_config(name, insts, k, scalar, calls) -> Config:
    """The existing one-shot binding (_core.solve: scene, wrench and pose in one call)."""

    def time_instance(inst: Instance, samples: dict[str, list[int]]) -> Outcome:
        args = solve_args(inst, scalar)
        for r in range(calls):
            d = _timed_pair(r, lambda: _core.solve(*args), lambda: solver.solve(*args), samples)
        return binding_outcome(d)

    return _py_call_config(name, insts, k, scalar, calls, "_core.solve", lambda: time_instance)


def peer_config(solver, insts, k, calls) -> Config:
    def run(cfg: Config) -> None:
        wall, internal, setup_solve, outcomes = [], [], [], []
        for inst in insts:
            for _ in range(calls):
                out, t_wall, t_int = solve_chain(solver, inst)
                wall.append(t_wall)
                if t_int is not None:
                    internal.append(t_int[0])
                    if len(t_int) > 1:
                        setup_solve.append(t_int[1])
            outcomes.append(out)
        if internal:
            label = {"daqp": "internal solve_time", "osqp": "internal update+solve+polish"}
            cfg.serie("internal", label.get(solver.name, "internal")).add(internal)
        if setup_solve:
            cfg.serie("internal_setup", "internal setup+solve_time").add(setup_solve)
        cfg.serie("py", "Python call").add(wall)
        cfg.outcomes = outcomes
        if isinstance(solver, OsqpSolver):
            cfg.extra["osqp_setups"] = solver.setups
            cfg.extra["osqp_updates"] = solver.updates
            cfg.extra["osqp_problems"] = sorted([list(s) for s in solver.problems])

    settings: dict[str, Any] = {"calls": calls, "version": solver.version}
    if isinstance(solver, OsqpSolver):
        settings.update(OSQP_SETTINGS)
    if isinstance(solver, SlsqpSolver):
        settings.update(SLSQP_OPTIONS)
    return Config(solver.name, "qp", solver.name, k, "double", settings, run, insts)


def pipeline_config(slsqp, insts, k) -> Config:
    def run(cfg: Config) -> None:
        samples, outcomes = [], []
        for inst in insts:
            t0 = time.perf_counter_ns()
            try:
                out = numpy_pipeline(inst, slsqp)
            except Exception as e:  # noqa: BLE001 - reported as this instance's failure
                out = Outcome(f"error: {type(e).__name__}: {e}")
            samples.append(time.perf_counter_ns() - t0)
            outcomes.append(out)
        cfg.serie("py", "Python call").add(samples)
        cfg.outcomes = outcomes

    return Config(
        "numpy+scipy frame",
        "py-pipeline",
        "numpy+scipy",
        k,
        "double",
        {"qp": "SLSQP", "null_space": "scipy.linalg.null_space", "pinv": "numpy.linalg.pinv"},
        run,
        insts,
    )


# --------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------
@dataclass
class Options:
    instances: int = 200
    seed: int = 1
    ks: tuple[int, ...] = (3, 4)
    quick: bool = False
    min_passes: int = 3
    max_passes: int = 8
    solvers: tuple[str, ...] = ("daqp", "quadprog", "osqp", "scipy-slsqp")
    accuracy_scenes: int = 0  # random hands per k of the accuracy set; 0: none


def build_configs(insts: list[Instance], opts: Options) -> list[Config]:
    quick = opts.quick
    reps, batches = (8, 2) if quick else (16, 3)
    qp_reps = 16 if quick else 32
    calls = 2 if quick else 3
    configs: list[Config] = []
    for k in opts.ks:
        frames = [i for i in insts if i.k == k]
        qps = [i for i in frames if i.ok]
        for scalar in ("double", "float"):
            for dec in ("structured", "svd"):
                configs.append(
                    cxx_frame_config(
                        f"frame {scalar} {dec}",
                        frames,
                        k,
                        scalar,
                        dec,
                        _core.kDefaultMaxIterations,
                        False,
                        reps,
                        batches,
                    )
                )
        configs.append(
            cxx_frame_config(
                f"frame double structured max_it={LIMITED_ITERATIONS}",
                frames,
                k,
                "double",
                "structured",
                LIMITED_ITERATIONS,
                False,
                reps,
                batches,
            )
        )
        for scalar in ("double", "float"):
            configs.append(
                cxx_frame_config(
                    f"fixed posture {scalar}",
                    frames,
                    k,
                    scalar,
                    "structured",
                    _core.kDefaultMaxIterations,
                    True,
                    reps * 8,
                    batches,
                )
            )
        for scalar in ("double", "float"):
            for dec in ("structured", "svd"):
                configs.append(
                    cxx_stages_config(
                        f"stages {scalar} {dec}", frames, k, scalar, dec, reps, batches
                    )
                )
        configs.append(py_guidance_config("py Guidance double", frames, k, calls))
        for scalar in ("double", "float"):
            configs.append(py_solve_config(f"py solve {scalar}", frames, k, scalar, calls))
        configs.append(cxx_qp_config("QP double", qps, k, "double", 0.0, qp_reps, batches))
        configs.append(cxx_qp_config("QP float", qps, k, "float", 0.0, qp_reps, batches))
        configs.append(
            cxx_qp_config(
                f"QP double feas={LOOSE_FEAS_REL:g}",
                qps,
                k,
                "double",
                LOOSE_FEAS_REL,
                qp_reps,
                batches,
            )
        )
        # Fresh solver objects per k: OSQP's problems (one per shape) live in its object.
        peers = make_peers(opts.solvers)
        for name in opts.solvers:
            configs.append(peer_config(peers[name], qps, k, 1 if name == "scipy-slsqp" else calls))
        if "scipy-slsqp" in peers:
            configs.append(pipeline_config(peers["scipy-slsqp"], qps, k))
    return configs


def make_peers(names: Sequence[str]) -> dict[str, Any]:
    makers = {
        "daqp": DaqpSolver,
        "quadprog": QuadprogSolver,
        "osqp": OsqpSolver,
        "scipy-slsqp": SlsqpSolver,
    }
    peers = {}
    for n in names:
        if n not in makers:
            raise BenchError(f"unknown solver {n!r}; accepted: {', '.join(makers)}")
        try:
            peers[n] = makers[n]()
        except ImportError as e:
            raise BenchError(
                f"solver {n!r} is not installed ({e}); install the bench extra: "
                f"pip install -r tools/requirements-dev.txt (or ./tools[bench])"
            ) from None
    return peers


def run_passes(
    configs: list[Config], opts: Options, progress: Callable[[str], None] | None = None
) -> None:
    """min_passes round-robin passes over every config, then more passes for the
    configs that are not stable, up to max_passes."""
    for p in range(opts.max_passes):
        todo = [c for c in configs if p < opts.min_passes or not c.stable()]
        if not todo:
            break
        t0 = time.perf_counter()
        for c in todo:
            # As timeit does: no garbage collection inside the timed Python calls.
            gc_was_enabled = gc.isenabled()
            gc.disable()
            try:
                with _quiet_stdout(c.solver == "osqp"):
                    c.run(c)
            finally:
                if gc_was_enabled:
                    gc.enable()
        if progress:
            progress(f"pass {p + 1}: {len(todo)} series in {time.perf_counter() - t0:.1f} s")


@contextlib.contextmanager
def _quiet_stdout(active: bool):
    """OSQP's C code prints "Polishing not needed" on stdout even with verbose=False;
    send file descriptor 1 to /dev/null around a whole pass (not per call, which would
    be timed)."""
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def machine_info(peers: dict[str, Any]) -> dict[str, Any]:
    cpu = None
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import scipy

    return {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu": cpu,
        "cpus": os.cpu_count(),
        "loadavg": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "solvers": {n: s.version for n, s in peers.items()},
    }


def goal(results: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Host, k=4, double: this project's median full frame (the shipped settings: the
    structured route, default iteration cap) vs DAQP's median internal solve_time for the
    QP alone on the same instances (the goal: ratio <= GOAL_RATIO). Also: the
    fastest double frame variant, and DAQP's setup + solve."""
    frame = next(
        (r for r in results if r["k"] == 4 and r["name"] == "frame double structured"), None
    )
    daqp = next((r for r in results if r["k"] == 4 and r["solver"] == "daqp"), None)
    if frame is None or daqp is None:
        return None
    variants = [
        r
        for r in results
        if r["k"] == 4
        and r["group"] == "frame"
        and r["scalar"] == "double"
        and r["settings"]["max_iterations"] == _core.kDefaultMaxIterations
    ]
    best = min(variants, key=lambda r: r["timing"]["cxx"]["median_ns"])
    f = frame["timing"]["cxx"]["median_ns"]
    d = daqp["timing"]["internal"]["median_ns"]
    ds = daqp["timing"]["internal_setup"]["median_ns"]
    b = best["timing"]["cxx"]["median_ns"]
    return {
        "description": "k=4, double: median full frame (frame double structured, C++ "
        "loop) / DAQP median internal solve_time for the QP alone",
        "frame_median_ns": f,
        "daqp_solve_median_ns": d,
        "daqp_setup_solve_median_ns": ds,
        "ratio": f / d,
        "ratio_vs_setup_solve": f / ds,
        "met": f <= GOAL_RATIO * d,
        "fastest_frame": best["name"],
        "fastest_frame_median_ns": b,
        "fastest_ratio": b / d,
    }


def _accuracy_figures(a: dict[str, Any]) -> dict[str, Any]:
    return {
        key: a[key]
        for key in (
            "instances",
            "agree",
            "agree_share",
            "compared_pwm",
            "pwm_mismatch",
            "max_pwm_diff",
            "max_lambda_err_rel",
        )
    }


def tradeoff(
    results: list[dict[str, Any]], accuracy_set: dict[str, Any] | None
) -> list[dict[str, Any]]:
    """The cost-against-accuracy rows: per k, each frame route's median time (C++ loop)
    beside its agreement with the float64 reference on the timing instances and, when it
    ran, on the accuracy set."""
    extra = {(r["name"], r["k"]): r["accuracy"] for r in (accuracy_set or {}).get("results", [])}
    rows = []
    for k in sorted({r["k"] for r in results}):
        for scalar, dec in FRAME_ROUTES:
            r = next(
                (x for x in results if x["k"] == k and x["name"] == frame_name(scalar, dec)),
                None,
            )
            if r is None:
                continue
            t = r["timing"]["cxx"]
            acc = extra.get((r["name"], k))
            rows.append(
                {
                    "k": k,
                    "config": r["name"],
                    "scalar": scalar,
                    "decomposition": dec,
                    "median_ns": t.get("median_ns"),
                    "p99_ns": t.get("p99_ns"),
                    "timing_set": _accuracy_figures(r["accuracy"]),
                    "accuracy_set": None if acc is None else _accuracy_figures(acc),
                }
            )
    return rows


def run_configs(
    opts: Options, progress: Callable[[str], None] | None = None
) -> tuple[list[Instance], list[Config]]:
    """Instances with their reference, and every config measured (the report's inputs)."""
    if opts.min_passes < 1 or opts.max_passes < opts.min_passes:
        raise BenchError("need 1 <= min_passes <= max_passes")
    make_peers(opts.solvers)  # a missing solver fails now, before the reference runs
    insts = make_instances(opts.instances, opts.seed, opts.ks, progress)
    configs = build_configs(insts, opts)
    run_passes(configs, opts, progress)
    return insts, configs


def measure_accuracy_set(
    opts: Options, progress: Callable[[str], None] | None = None
) -> dict[str, Any] | None:
    """The accuracy set of ``opts.accuracy_scenes`` hands per k, or None when it is 0."""
    if not opts.accuracy_scenes:
        return None
    t0 = time.perf_counter()
    insts = accuracy_instances(opts.accuracy_scenes, opts.seed, opts.ks, progress)
    results = run_accuracy_set(insts, opts.ks)
    return {
        "scenes_per_k": opts.accuracy_scenes,
        "seed": opts.seed + ACCURACY_SEED_OFFSET,
        "combinations": [list(c) for c in COMBINATIONS],
        "reference_not_ok": sum(1 for i in insts if not i.ok),
        "results": results,
        "elapsed_s": time.perf_counter() - t0,
    }


def report(
    opts: Options,
    insts: list[Instance],
    configs: list[Config],
    elapsed_s: float,
    accuracy_set: dict[str, Any] | None = None,
) -> dict[str, Any]:
    results = [c.result() for c in configs]
    counts = {}
    for k in opts.ks:
        ks = [i for i in insts if i.k == k]
        counts[f"k{k}"] = {
            "frames": len(ks),
            "qp": sum(1 for i in ks if i.ok),
            "random": sum(1 for i in ks if i.group == "random"),
            "paper": sum(1 for i in ks if i.group == "paper"),
            "reference_models_used": {
                m: sum(1 for i in ks if i.ok and i.ref["constraints_used"] == m)
                for m in ("paper", "normal", "none")
            },
            "reference_not_ok": sum(1 for i in ks if not i.ok),
        }
    return {
        "schema": SCHEMA,
        "settings": {
            "instances": opts.instances,
            "seed": opts.seed,
            "k": list(opts.ks),
            "quick": opts.quick,
            "min_passes": opts.min_passes,
            "max_passes": opts.max_passes,
            "solvers": list(opts.solvers),
            "median_spread_max": MEDIAN_SPREAD_MAX,
            "p99_spread_max": P99_SPREAD_MAX,
            "violation_tol": VIOLATION_TOL,
            "runs": [list(r) for r in RUNS],
            "accuracy_scenes": opts.accuracy_scenes,
        },
        "machine": machine_info({n: s for n, s in make_peers(opts.solvers).items()}),
        "instances": counts,
        "results": results,
        "goal": goal(results),
        "accuracy_set": accuracy_set,
        "tradeoff": tradeoff(results, accuracy_set),
        "elapsed_s": elapsed_s,
    }


def run_bench(opts: Options, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    t0 = time.perf_counter()
    insts, configs = run_configs(opts, progress)
    accuracy_set = measure_accuracy_set(opts, progress)
    return report(opts, insts, configs, time.perf_counter() - t0, accuracy_set)


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------
def _fmt_ns(v: float | None) -> str:
    if v is None:
        return "-"
    if v >= 1e6:
        return f"{v / 1e6:.2f}ms"
    if v >= 1e4:
        return f"{v / 1e3:.1f}us"
    return f"{v:.0f}"


def _fmt_e(v: float | None) -> str:
    return "-" if v is None else ("0" if v == 0 else f"{v:.0e}")


def _fmt_agree(a: dict[str, Any] | None) -> tuple[str, str, str]:
    """agree n/N (share), max PWM difference, max relative force error."""
    if a is None:
        return ("-", "-", "-")
    share = "" if a["agree_share"] is None else f" ({100 * a['agree_share']:.2f}%)"
    return (
        f"{a['agree']}/{a['instances']}{share}",
        "-" if a["max_pwm_diff"] is None else str(a["max_pwm_diff"]),
        _fmt_e(a["max_lambda_err_rel"]),
    )


def format_tradeoff(report: dict[str, Any]) -> list[str]:
    """The cost-against-accuracy block: per k and frame route, the median frame beside
    the agreement with the float64 reference (same status, and where ok the same model
    and PWM within 1 count) on the timed instances and on the accuracy set."""
    rows = report.get("tradeoff") or []
    if not rows:
        return []
    acc = report.get("accuracy_set")
    head = ["k", "config", "median", "agree (timed)", "dPWM", "|dλ|/|λ|"]
    if acc:
        head += [f"agree ({acc['scenes_per_k']} more/k)", "dPWM", "|dλ|/|λ|"]
    table = [head]
    for r in rows:
        cells = [str(r["k"]), r["config"], _fmt_ns(r["median_ns"]), *_fmt_agree(r["timing_set"])]
        if acc:
            cells += list(_fmt_agree(r["accuracy_set"]))
        table.append(cells)
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    out = ["", "cost against accuracy (frames, C++ loop; agreement with the float64 reference):"]
    for row in table:
        out.append(
            "  ".join(
                c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))
            )
        )
    return out


def format_table(report: dict[str, Any]) -> str:
    head = (
        "config",
        "time",
        "median",
        "p99",
        "pass",
        "fail",
        "agree",
        "viol",
        "gap",
        "PWM!=",
        "dPWM",
    )
    rows = []
    for n, k in enumerate(report["settings"]["k"]):
        if n:
            rows.append(None)
        rows.append((f"k={k}",) + ("",) * (len(head) - 1))
        for r in (x for x in report["results"] if x["k"] == k):
            a = r["accuracy"]
            for t in r["timing"].values():
                passes = f"{t.get('passes', 0)}{'' if t.get('stable', True) else '!'}"
                timing = (
                    r["name"],
                    t["label"],
                    _fmt_ns(t.get("median_ns")),
                    _fmt_ns(t.get("p99_ns")),
                    passes,
                )
                if not a["instances"]:  # stage timings: no answer to judge
                    rows.append(timing + ("-",) * 6)
                    continue
                rows.append(
                    timing
                    + (
                        f"{a['failures']}/{a['instances']}",
                        f"{a['agree']}/{a['instances']}",
                        _fmt_e(a["max_violation_rel"]),
                        _fmt_e(a["max_objective_gap_rel"]),
                        f"{a['pwm_mismatch']}/{a['compared_pwm']}",
                        "-" if a["max_pwm_diff"] is None else str(a["max_pwm_diff"]),
                    )
                )
    widths = [max(len(h), *(len(x[i]) for x in rows if x)) for i, h in enumerate(head)]
    line = "  ".join("-" * w for w in widths)

    def fmt(row):
        return "  ".join(
            c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))
        )

    out = [fmt(head), line]
    for row in rows:
        out.append(line if row is None else fmt(row))
    out.extend(format_tradeoff(report))
    g = report.get("goal")
    if g:
        out.append("")
        out.append(
            f"goal (k=4, double): full frame median {_fmt_ns(g['frame_median_ns'])} ns"
            f" vs DAQP QP-alone internal solve_time median "
            f"{_fmt_ns(g['daqp_solve_median_ns'])} ns: ratio {g['ratio']:.2f} "
            f"({'met' if g['met'] else 'NOT met'}); vs DAQP setup+solve "
            f"{_fmt_ns(g['daqp_setup_solve_median_ns'])} ns: ratio "
            f"{g['ratio_vs_setup_solve']:.2f}; fastest frame variant "
            f"({g['fastest_frame']}) {_fmt_ns(g['fastest_frame_median_ns'])} ns: "
            f"ratio {g['fastest_ratio']:.2f}"
        )
    unstable = [
        f"{r['name']} (k={r['k']}) {t['label']}"
        for r in report["results"]
        for t in r["timing"].values()
        if not t.get("stable", True)
    ]
    if unstable:
        out.append("still noisy after the last pass (marked !): " + "; ".join(unstable))
    out.append(f"times in ns unless marked; {report['elapsed_s']:.0f} s in all")
    return "\n".join(out)


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def write_json(report: dict[str, Any], path: str) -> None:
    tmp = f"{path}.tmp"
    with open(tmp, "w") as f:
        json.dump(_jsonable(report), f, indent=1, allow_nan=False)
        f.write("\n")
    os.replace(tmp, path)


def make_options(
    *,
    instances: int | None,
    seed: int,
    k: str,
    quick: bool,
    solvers: str,
    max_passes: int | None,
    accuracy_scenes: int,
) -> Options:
    """Options from `graspguide bench`'s values (None: the default of --quick or not);
    BenchError says which value is wrong."""
    ks = {"3": (3,), "4": (4,), "both": (3, 4)}.get(str(k))
    if ks is None:
        raise BenchError(f"--k must be 3, 4 or both, got {k!r}")
    if instances is None:
        instances = 20 if quick else 200
    if not 0 <= instances <= 100_000:
        raise BenchError(f"--instances must be between 0 and 100000, got {instances}")
    if seed < 0:
        raise BenchError(f"--seed must be >= 0, got {seed}")
    if max_passes is None:
        max_passes = 4 if quick else 8
    if max_passes < 1:
        raise BenchError(f"--max-passes must be >= 1, got {max_passes}")
    if not 0 <= accuracy_scenes <= 100_000:
        raise BenchError(f"--accuracy-scenes must be between 0 and 100000, got {accuracy_scenes}")
    return Options(
        instances=instances,
        seed=seed,
        ks=ks,
        quick=quick,
        min_passes=min(2 if quick else 3, max_passes),
        max_passes=max_passes,
        solvers=tuple(s.strip() for s in solvers.split(",") if s.strip()),
        accuracy_scenes=accuracy_scenes,
    )


def bench_command(
    *,
    instances: int | None,
    seed: int,
    k: str,
    quick: bool,
    solvers: str,
    max_passes: int | None,
    accuracy_scenes: int,
    json_path: str | None,
) -> int:
    """`graspguide bench`: 0 on success, 2 for bad options or a missing solver."""

    def progress(msg: str) -> None:
        print(f"bench: {msg}", file=sys.stderr, flush=True)

    try:
        opts = make_options(
            instances=instances,
            seed=seed,
            k=k,
            quick=quick,
            solvers=solvers,
            max_passes=max_passes,
            accuracy_scenes=accuracy_scenes,
        )
        report = run_bench(opts, progress)
    except BenchError as e:
        return fail("bench", e, EXIT_USAGE)
    print(format_table(report), flush=True)
    if json_path:
        write_json(report, json_path)
        progress(f"wrote {json_path}")
    return 0
