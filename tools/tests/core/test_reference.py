"""Self-checks of the float64 reference (tools/graspguide/core/reference.py) and the
known-answer data generated from it."""

from __future__ import annotations

import itertools
import json
import math
import os
import sys

import numpy as np
import pytest
from conftest import TOOLS_DIR

_TOOLS = TOOLS_DIR
_ROOT = os.path.dirname(_TOOLS)
if _TOOLS not in sys.path:
    sys.path.insert(0, _TOOLS)

from graspguide.core import reference as ref  # noqa: E402
from graspguide.core import scene_generators as scenes  # noqa: E402
from graspguide.core.vocabulary import CONSTRAINT_MODELS  # noqa: E402

KNOWN_ANSWERS = os.path.join(_ROOT, "test", "data", "known_answers.json")


def _random(k, n, seed=99):
    return scenes.random_scenes(seed, k, n)


def _solve(sc, **kw):
    return ref.solve(
        sc["contacts"], sc["wrench"], orientation=sc["orientation"], y_axis=sc["y_axis"], **kw
    )


def _system(sc):
    C = np.asarray(sc["contacts"], float)
    w = np.asarray(sc["wrench"], float)
    y = np.asarray(sc["y_axis"], float)
    status, frames = ref.contact_frames(C, y / np.linalg.norm(y))
    assert status == "ok"
    G = ref.grasp_matrix(frames)
    w_l = np.concatenate([w[:3], w[3:] / frames["L"]])
    return G, w_l, frames


def _rot(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _qmul(p, q):
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


@pytest.mark.parametrize("k", [3, 4])
@pytest.mark.parametrize("model", CONSTRAINT_MODELS)
def test_equilibrium_and_constraints(k, model):
    for sc in _random(k, 25):
        res = _solve(sc, constraints=model)
        assert res["status"] == "ok"
        G, w_l, _ = _system(sc)
        lam = np.asarray(res["lambda"])
        assert np.linalg.norm(G @ lam + w_l) <= 1e-12 * (np.linalg.norm(lam) + 1)
        S = ref.constrained_components(res["constraints_used"], k)
        lam0n = np.linalg.norm(res["diagnostics"]["lam0"])
        if S:
            assert lam[S].min() >= -ref.kFeasRelTol * lam0n


@pytest.mark.parametrize("k", [3, 4])
def test_unconstrained_is_pinv_projection(k):
    for sc in _random(k, 20):
        res = _solve(sc, constraints="none")
        G, w_l, _ = _system(sc)
        Gp = np.linalg.pinv(G)
        lam0 = -Gp @ w_l
        lam_des = np.asarray(res["diagnostics"]["lam_des"])
        expected = lam0 + (np.eye(3 * k) - Gp @ G) @ lam_des
        assert np.allclose(res["lambda"], expected, atol=1e-12, rtol=0)
        assert res["constraints_used"] == "none" and res["active_set"] == ()


def lb_of(S, k):
    lb = np.full(3 * k, -np.inf)
    lb[S] = 0.0
    return lb


def _feasible_points(G, w_l, S, n, rng, box):
    """Vertices of {G lam = -w_L, lam_S >= 0, |lam| <= box} for random objectives."""
    from scipy.optimize import linprog

    m = G.shape[1]
    lb = np.full(m, -box)
    lb[S] = 0.0
    pts = []
    for _ in range(n):
        res = linprog(
            rng.standard_normal(m),
            A_eq=G,
            b_eq=-w_l,
            bounds=list(zip(lb, np.full(m, box))),
            method="highs",
        )
        if res.status == 0:
            pts.append(res.x)
    return pts


@pytest.mark.parametrize("k", [3, 4])
@pytest.mark.parametrize("model", ["paper", "normal"])
def test_qp_optimum_is_the_projection(k, model):
    """Variational inequality <lam_des - lam*, p - lam*> <= 0 over feasible points p,
    and agreement with SLSQP."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(5)
    checked = slsqp_ok = 0
    for sc in _random(k, 12, seed=123):
        res = _solve(sc, constraints=model)
        if res["constraints_used"] != model:
            continue
        checked += 1
        G, w_l, _ = _system(sc)
        lam = np.asarray(res["lambda"])
        lam_des = np.asarray(res["diagnostics"]["lam_des"])
        S = ref.constrained_components(model, k)
        box = 10 * (np.abs(lam).max() + 1)
        for p in _feasible_points(G, w_l, S, 20, rng, box):
            scale = np.linalg.norm(p - lam) * (np.linalg.norm(lam_des - lam) + 1)
            assert (lam_des - lam) @ (p - lam) <= 1e-8 * scale + 1e-12 * (1 + lam @ lam)
        # SLSQP from lam_des (an independent start). On the paper model the feasible set
        # is often a single point (no interior), where SLSQP's line search may give up;
        # there the variational inequality above is the check.
        sol = minimize(
            lambda x, lam_des=lam_des: 0.5 * np.sum((x - lam_des) ** 2),
            lam_des.copy(),
            jac=lambda x, lam_des=lam_des: x - lam_des,
            method="SLSQP",
            bounds=list(zip(lb_of(S, k), [np.inf] * (3 * k))),
            constraints=[
                {
                    "type": "eq",
                    "fun": lambda x, G=G, w_l=w_l: G @ x + w_l,
                    "jac": lambda x, G=G: G,
                }
            ],
            options={"ftol": 1e-15, "maxiter": 1000},
        )
        if sol.success:
            slsqp_ok += 1
            assert np.linalg.norm(sol.x - lam) <= 1e-5 * (1 + np.linalg.norm(lam))
            assert 0.5 * np.sum((lam - lam_des) ** 2) <= sol.fun + 1e-9
    print(f"k={k} {model}: {checked} feasible scenes, SLSQP converged on {slsqp_ok}")
    if model == "normal":
        assert slsqp_ok >= 3
    assert checked >= 3


@pytest.mark.parametrize("k", [3, 4])
def test_margin_agrees_with_enumeration(k):
    for sc in _random(k, 60, seed=7):
        res = _solve(sc, constraints="paper")
        t = res["margins"]["paper"]
        if res["constraints_used"] == "paper":
            assert t >= -ref.kFeasRelTol - 1e-9
        else:
            assert t < 1e-9
        assert res["margins"]["normal"] > 0  # normal always admits an expanding force


def _same_output(a, b, level_tol=1e-9):
    assert a["status"] == b["status"] == "ok"
    assert a["pwm"] == b["pwm"]
    assert a["relevant"] == b["relevant"]
    assert a["constraints_used"] == b["constraints_used"]
    assert np.allclose(a["levels"], b["levels"], atol=level_tol, rtol=0)
    assert abs(a["error_deg"] - b["error_deg"]) < 1e-9


@pytest.mark.parametrize("k", [3, 4])
def test_scale_invariance(k):
    for i, sc in enumerate(_random(k, 20, seed=11)):
        policy, mode, model = [("F", "C", "paper"), ("Fperp", "V", "normal"), ("F", "V", "none")][
            i % 3
        ]
        scaled = dict(sc)
        scaled["contacts"] = (np.asarray(sc["contacts"]) * 1000).tolist()
        w = np.asarray(sc["wrench"])
        scaled["wrench"] = np.concatenate([w[:3], w[3:] * 1000]).tolist()
        a = _solve(sc, policy=policy, mode=mode, constraints=model)
        b = _solve(scaled, policy=policy, mode=mode, constraints=model)
        _same_output(a, b)
        assert np.allclose(a["lambda"], b["lambda"], atol=1e-9, rtol=1e-9)


@pytest.mark.parametrize("k", [3, 4])
def test_rotation_invariance(k):
    rng = np.random.default_rng(3)
    for i, sc in enumerate(_random(k, 20, seed=13)):
        policy, mode, model = [("F", "V", "paper"), ("Fperp", "C", "normal"), ("F", "V", "none")][
            i % 3
        ]
        axis, angle = rng.standard_normal(3), rng.uniform(0, math.pi)
        Q = _rot(axis, angle)
        a_unit = axis / np.linalg.norm(axis)
        q_Q = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * a_unit])
        q_Q_inv = q_Q * np.array([1, -1, -1, -1])
        w = np.asarray(sc["wrench"])
        rot = {
            "contacts": (np.asarray(sc["contacts"]) @ Q.T).tolist(),
            "wrench": np.concatenate([Q @ w[:3], Q @ w[3:]]).tolist(),
            "y_axis": (Q @ np.asarray(sc["y_axis"])).tolist(),
            # world <- hand' = (world <- hand) (hand <- hand') = q * conj(q_Q)
            "orientation": _qmul(np.asarray(sc["orientation"]), q_Q_inv).tolist(),
        }
        a = _solve(sc, policy=policy, mode=mode, constraints=model)
        b = _solve(rot, policy=policy, mode=mode, constraints=model)
        assert a["fallback_mask"] == 0
        _same_output(a, b, level_tol=1e-8)
        assert np.allclose(a["lambda"], b["lambda"], atol=1e-8, rtol=1e-8)


def test_scaled_quaternion_equals_unit():
    for sc in _random(4, 10, seed=17):
        q = np.asarray(sc["orientation"])
        for mode in ("C", "V"):
            a = _solve(sc, mode=mode)
            b = ref.solve(sc["contacts"], sc["wrench"], mode=mode, orientation=(3.7 * q).tolist())
            _same_output(a, b)
            assert abs(a["alpha"] - b["alpha"]) < 1e-9


def test_extreme_scenes_statuses():
    by_name = {}
    for case in scenes.extreme_scenes():
        res = _solve(case)
        by_name[case["name"]] = (case, res)
        if case["expect_status"] is not None:
            assert res["status"] == case["expect_status"], case["name"]
        for key, want in case.get("expect", {}).items():
            got = res["relevant"][0] if key == "relevant0" else res[key]
            assert got == pytest.approx(want, abs=1e-9), (case["name"], key)
    for case, res in by_name.values():
        if "same_as" in case:
            _same_output(res, by_name[case["same_as"]][1], level_tol=1e-8)


def test_pwm_rounding_and_off_threshold():
    assert ref.round_half_away(70.5) == 71 and ref.round_half_away(70.49) == 70
    assert ref.pwm_from_levels(np.array([1.0, 1e-3, -0.5, 0.0011]), "C", 0.0) == [255, 0, 163, 70]
    assert ref.pwm_from_levels(np.array([1.0, 0.5]), "V", 0.0) == [70, 70]


def test_bad_inputs_raise():
    sc = _random(3, 1)[0]
    with pytest.raises(ValueError):
        _solve(sc, policy="G")
    with pytest.raises(ValueError):
        _solve(sc, constraints="soft")


def _decode(x):
    if isinstance(x, str):
        return {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}[x]
    if isinstance(x, list):
        return [_decode(v) for v in x]
    return x


def test_known_answers_reproduce():
    with open(KNOWN_ANSWERS, encoding="utf-8") as fh:
        data = json.load(fh)
    assert data["tolerances"]["kFeasRelTol"] == ref.kFeasRelTol
    for case in data["cases"]:
        res = ref.solve(
            _decode(case["contacts"]),
            _decode(case["wrench"]),
            policy=case["policy"],
            mode=case["mode"],
            constraints=case["constraints"],
            orientation=_decode(case["orientation"]),
            y_axis=_decode(case["y_axis"]),
        )
        e = case["expect"]
        name = case["name"]
        assert res["status"] == e["status"], name
        assert res["constraints_used"] == e["constraints_used"], name
        assert res["pwm"] == e["pwm"], name
        assert res["relevant"] == e["relevant"], name
        assert res["fallback_mask"] == e["fallback_mask"], name
        for key in ("lambda", "levels"):
            if e[key] is None:
                assert res[key] is None, name
            else:
                scale = 1 + np.abs(e[key]).max()
                assert np.allclose(res[key], e[key], atol=1e-9 * scale, rtol=0), name
        if e["error_deg"] is None:
            assert res["error_deg"] is None
        else:
            assert res["error_deg"] == pytest.approx(e["error_deg"], abs=1e-9), name
        m = res["margins"].get(case["constraints"]) if res["margins"] else None
        assert (m is None) == (e["margin"] is None), name
        if m is not None:
            assert m == pytest.approx(e["margin"], abs=1e-8), name


# --------------------------------------------------------------------------------------
# paper_margin_x_fixed (the float core's band is measured in it)
# --------------------------------------------------------------------------------------
def _x_fixed_by_vertices(G, w_l, lam0_norm):
    """The same LP solved without HiGHS: x = 0 leaves lam_yz = p + N z (least squares and
    the SVD null basis), and max t s.t. p + N z >= t, t <= 1 is attained at a vertex of
    (z, t), found by trying every choice of dim(z) + 1 active constraints."""
    yz = [j for j in range(G.shape[1]) if j % 3]
    A, b = G[:, yz], -w_l / lam0_norm
    p = np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.linalg.norm(A @ p - b) <= 1e-9 * (1 + np.linalg.norm(b))
    _, s, Vt = np.linalg.svd(A)
    N = Vt[int(np.sum(s > 1e-10 * s[0])) :].T
    n, d = N.shape
    rows = np.vstack([np.hstack([N, -np.ones((n, 1))]), np.eye(d + 1)[-1:] * -1])  # rows v >= rhs
    rhs = np.concatenate([-p, [-1.0]])
    best = -math.inf
    for idx in itertools.combinations(range(n + 1), d + 1):
        M = rows[list(idx)]
        if np.linalg.cond(M) > 1e12:
            continue
        v = np.linalg.solve(M, rhs[list(idx)])
        if np.all(rows @ v >= rhs - 1e-9 * (1 + np.abs(rhs))):
            best = max(best, float(v[-1]))
    return best


def _identity_yz_system(seed):
    """A grasp matrix whose y/z columns are the identity (lam_yz = -w_L is the only
    equilibrium with x = 0) and whose x columns are random, with a load every y/z force
    can hold with a positive value."""
    rng = np.random.default_rng(seed)
    G = np.zeros((6, 9))
    G[:, [1, 2, 4, 5, 7, 8]] = np.eye(6)
    G[:, [0, 3, 6]] = rng.standard_normal((6, 3))
    return G, -np.array([0.3, 0.5, 0.2, 0.9, 0.4, 0.7])


def test_x_fixed_margin_of_a_system_solved_by_hand():
    # The margin is min(-w_L) / ||lam0||, capped at 1; the x columns must not matter.
    G, w_l = _identity_yz_system(5)
    assert ref.paper_margin_x_fixed(G, w_l, 2.0) == pytest.approx(0.1, abs=1e-9)
    assert ref.paper_margin_x_fixed(G, w_l, 0.1) == 1.0  # 0.2 / 0.1 = 2, capped
    w_l[3] = 0.9  # lam_yz[3] = -0.9: infeasible by 0.9 / ||lam0||
    assert ref.paper_margin_x_fixed(G, w_l, 3.0) == pytest.approx(-0.3, abs=1e-9)


@pytest.mark.parametrize("k", [3, 4])
def test_x_fixed_margin_agrees_with_vertex_enumeration(k):
    below_cap = 0
    for sc in _random(k, 30, seed=21):
        sc = dict(sc)
        w = np.asarray(sc["wrench"], float)
        w[4] = 0.0  # no moment about y_O = [0, 1, 0]: x = 0 can hold equilibrium
        sc["wrench"] = w.tolist()
        G, w_l, _ = _system(sc)
        n0 = float(np.linalg.norm(ref.min_norm_solution(G, w_l)))
        t = ref.paper_margin_x_fixed(G, w_l, n0)
        assert t == pytest.approx(_x_fixed_by_vertices(G, w_l, n0), abs=1e-7), sc["name"]
        below_cap += t < 1.0
    # Three contacts leave one internal force, so many hands sit below the cap and test
    # the LP itself; four-contact hands can always squeeze every y/z component positive
    # (both methods give the cap, 1, on all of these).
    if k == 3:
        assert below_cap >= 3


def test_x_fixed_margin_refuses_a_moment_about_the_y_axis():
    sc = _random(3, 1, seed=21)[0]
    sc = dict(sc, wrench=[0.0, 0.0, -1.0, 0.0, 0.05, 0.0])
    G, w_l, _ = _system(sc)
    with pytest.raises(RuntimeError, match="margin LP failed"):
        ref.paper_margin_x_fixed(G, w_l, float(np.linalg.norm(ref.min_norm_solution(G, w_l))))


# --------------------------------------------------------------------------------------
# x_fixed_equilibrium_gap (the margin's continuation where x = 0 cannot hold equilibrium)
# --------------------------------------------------------------------------------------
def test_x_fixed_gap_of_a_system_solved_by_hand():
    # With lam_yz >= 0 the closest equilibrium misses only the rows whose load needs a
    # negative force, by that force, so the gap is max(0, max(w_L)) / ||lam0||; the x
    # columns must not matter.
    G, w_l = _identity_yz_system(6)
    assert ref.x_fixed_equilibrium_gap(G, w_l, 2.0) == pytest.approx(0.0, abs=1e-9)
    w_l[3], w_l[5] = 0.9, 0.3  # lam_yz[3] = -0.9 and lam_yz[5] = -0.3 would be needed
    assert ref.x_fixed_equilibrium_gap(G, w_l, 3.0) == pytest.approx(0.3, abs=1e-9)


def test_x_fixed_gap_measures_a_moment_about_the_y_axis():
    # The margin LP refuses this hand (above); y/z forces make no moment about y_O, so the
    # gap is at most the moment itself, and positive.
    sc = _random(3, 1, seed=21)[0]
    sc = dict(sc, wrench=[0.0, 0.0, -1.0, 0.0, 0.05, 0.0])
    G, w_l, _ = _system(sc)
    n0 = float(np.linalg.norm(ref.min_norm_solution(G, w_l)))
    gap = ref.x_fixed_equilibrium_gap(G, w_l, n0)
    assert 0.0 < gap <= abs(w_l[4]) / n0 + 1e-9
