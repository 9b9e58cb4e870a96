"""The nanobind binding graspguide.core._core and its Python wrapper graspguide.core.solver."""

from __future__ import annotations

import itertools
import json
import math
import os

import numpy as np
import pytest

from graspguide.core import _core, solver
from graspguide.core import scene_generators as scenes

EXAMPLES = os.path.join(
    os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples", "solve_requests.jsonl"
)

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
HAND4 = HAND3 + [[0.0, 0.045, 0.0]]
PURE_F = [0.3, -1.2, -0.8, 0.0, 0.0, 0.0]
Q_TILT = [0.9394, 0.1125, 0.2250, -0.2312]
COMBOS = list(itertools.product(("F", "Fperp"), ("C", "V"), ("paper", "normal", "none")))
RESULT_KEYS = {
    "status",
    "pwm",
    "levels",
    "lambda",
    "constraints_used",
    "relevant",
    "error_deg",
    "alpha",
    "fallback_mask",
    "iterations",
    "rank_ratio",
    "recomputed",
}


def _example_requests():
    out = []
    with open(EXAMPLES, encoding="utf-8") as f:
        for line in f:
            if line.strip():
                obj = json.loads(line)
                if set(obj) <= set(solver.REQUEST_FIELDS):
                    out.append(obj)
    assert len(out) >= 4
    return out


def _scenes():
    """The example requests and seeded hand-like scenes (scenes.random_scenes), each
    with every policy/mode/constraints combination."""
    out = []
    for req in _example_requests():
        base = {k: v for k, v in req.items() if k not in ("policy", "mode", "constraints")}
        out += [dict(base, policy=p, mode=m, constraints=c) for p, m, c in COMBOS]
    for k in (3, 4):
        for sc in scenes.random_scenes(4242, k, 40):
            base = {key: sc[key] for key in ("contacts", "wrench", "orientation", "y_axis")}
            out += [dict(base, policy=p, mode=m, constraints=c) for p, m, c in COMBOS]
    return out


# --------------------------------------------------------------------------------------
# Module contents
# --------------------------------------------------------------------------------------
def test_module_constants():
    assert _core.STATUS_NAMES[0] == "ok"
    assert len(set(_core.STATUS_NAMES)) == len(_core.STATUS_NAMES) == 15
    for name in (
        "non_finite_input",
        "bad_contact_count",
        "bad_axis",
        "bad_quaternion",
        "coincident_contacts",
        "imprecise_contacts",
        "zero_wrench",
        "zero_force",
        "rank_deficient",
        "qp_infeasible",
        "qp_iteration_limit",
        "nothing_to_display",
        "bad_config",
    ):
        assert name in _core.STATUS_NAMES
    for name in _core.STATUS_NAMES:
        message = _core.status_message(name)
        assert message and message == _core.STATUS_MESSAGES[name]
        assert solver.status_message(name) == message
    with pytest.raises(ValueError):
        _core.status_message("no_such_status")
    assert (_core.kPwmMin, _core.kPwmSpan) == (70, 185)
    assert (_core.kMinContacts, _core.kMaxContacts) == (3, 4)
    assert _core.kDefaultMaxIterations == 64
    assert _core.POLICIES == ("F", "Fperp")
    assert _core.MODES == ("C", "V")
    assert _core.CONSTRAINT_MODELS == ("paper", "normal", "none")
    tol = _core.TOLERANCES
    assert tol["double"]["kFeasRelTol"] == 1e-9
    assert tol["float"]["kFeasRelTol"] == pytest.approx(1e-4)
    for scalar in ("double", "float"):
        assert tol[scalar]["kCoincidentRelTol"] == 1e-4
        assert tol[scalar]["kMotorOffLevel"] == 1e-3
        assert tol[scalar]["kMinQuaternionNorm"] == 1e-6


# --------------------------------------------------------------------------------------
# Result dict
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("scalar", ["double", "float"])
@pytest.mark.parametrize("contacts", [HAND3, HAND4], ids=["k3", "k4"])
@pytest.mark.parametrize("combo", COMBOS, ids=["-".join(c) for c in COMBOS])
def test_result_shapes_and_types(scalar, contacts, combo):
    policy, mode, constraints = combo
    k = len(contacts)
    r = _core.solve(contacts, PURE_F, policy, mode, constraints, Q_TILT, [0, 1, 0], scalar)
    assert set(r) == RESULT_KEYS
    assert r["status"] == "ok"
    assert isinstance(r["pwm"], list) and len(r["pwm"]) == k
    assert all(type(v) is int and 0 <= v <= 255 for v in r["pwm"])
    assert all(v == 0 or v >= 70 for v in r["pwm"])
    assert isinstance(r["levels"], list) and len(r["levels"]) == k
    assert all(type(v) is float for v in r["levels"])
    assert math.isclose(math.hypot(*r["levels"]), 1.0, rel_tol=1e-5)
    assert isinstance(r["lambda"], list) and len(r["lambda"]) == 3 * k
    assert all(type(v) is float and math.isfinite(v) for v in r["lambda"])
    assert r["constraints_used"] in ("paper", "normal", "none")
    assert ("paper", "normal", "none").index(r["constraints_used"]) >= (
        "paper",
        "normal",
        "none",
    ).index(constraints)
    assert isinstance(r["relevant"], list) and len(r["relevant"]) == k
    assert all(type(v) is bool for v in r["relevant"])
    assert type(r["error_deg"]) is float and 0.0 <= r["error_deg"] <= 180.0
    assert type(r["alpha"]) is float and 0.0 <= r["alpha"] <= 185.0 + 1e-3
    assert type(r["iterations"]) is int and r["iterations"] >= 0
    assert type(r["fallback_mask"]) is int
    assert type(r["rank_ratio"]) is float and 0.0 < r["rank_ratio"] <= 1.0
    assert r["recomputed"] is True


@pytest.mark.parametrize("scalar", ["double", "float"])
def test_error_result_shape(scalar):
    r = _core.solve(HAND3, [0.0] * 6, scalar=scalar)
    assert set(r) == RESULT_KEYS
    assert r["status"] == "zero_wrench"
    assert r["pwm"] == [0, 0, 0]
    for key in ("levels", "lambda", "relevant", "error_deg", "alpha"):
        assert r[key] is None
    assert r["constraints_used"] == ""


def test_defaults_match_explicit_arguments():
    a = _core.solve(HAND3, PURE_F)
    b = _core.solve(
        HAND3,
        PURE_F,
        policy="F",
        mode="C",
        constraints="paper",
        orientation=[1, 0, 0, 0],
        y_axis=[0, 1, 0],
        scalar="double",
        decomposition="qr",
        max_iterations=64,
    )
    assert a == b
    assert solver.solve(HAND3, PURE_F) == a


@pytest.mark.parametrize("k", [0, 1, 2, 5, 7])
def test_contact_count_is_the_cores_status(k):
    contacts = [[0.01 * i, 0.02 * i * i, 0.003 * i] for i in range(k)]
    for scalar in ("double", "float"):
        r = _core.solve(contacts, PURE_F, scalar=scalar)
        assert r["status"] == "bad_contact_count"
        assert r["pwm"] == [0] * k


@pytest.mark.parametrize("scalar", ["double", "float"])
def test_order_of_checks(scalar):
    """Guidance::solve: non-finite input, contact count, axis, quaternion, geometry."""
    nan = math.nan
    cases = [
        ((HAND3[:2], [0.3, -1.2, nan, 0, 0, 0]), {}, "non_finite_input"),
        ((HAND3[:1] + [[nan, 0, 0]], PURE_F), {}, "non_finite_input"),
        ((HAND3[:2], PURE_F), {"orientation": [nan, 0, 0, 0]}, "non_finite_input"),
        ((HAND3, PURE_F), {"orientation": [nan, 0, 0, 0], "y_axis": [0, 0, 0]}, "non_finite_input"),
        ((HAND3[:2], PURE_F), {"y_axis": [0, 0, 0]}, "bad_contact_count"),
        ((HAND3, PURE_F), {"y_axis": [0, 0, 0], "orientation": [0, 0, 0, 0]}, "bad_axis"),
        (([HAND3[0]] * 3, PURE_F), {"orientation": [0, 0, 0, 0]}, "bad_quaternion"),
        (([HAND3[0]] * 3, [0.0] * 6), {}, "coincident_contacts"),
    ]
    for args, kw, status in cases:
        assert _core.solve(*args, scalar=scalar, **kw)["status"] == status, (args, kw)


@pytest.mark.parametrize(
    "field,index", [("contacts", (1, 2)), ("wrench", 4), ("orientation", 0), ("y_axis", 1)]
)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("scalar", ["double", "float"])
def test_non_finite_inputs_reach_the_core(field, index, value, scalar):
    kw = {
        "contacts": [list(c) for c in HAND4],
        "wrench": list(PURE_F),
        "orientation": list(Q_TILT),
        "y_axis": [0.0, 1.0, 0.0],
    }
    if field == "contacts":
        kw["contacts"][index[0]][index[1]] = value
    else:
        kw[field][index] = value
    assert solver.solve(scalar=scalar, **kw)["status"] == "non_finite_input"


def test_max_iterations_and_decomposition():
    assert _core.solve(HAND3, PURE_F, max_iterations=0)["status"] == "bad_config"
    assert _core.solve(HAND3, PURE_F, max_iterations=-5)["status"] == "bad_config"
    # [0, 0, -1] on this hand: paper is infeasible, the solver needs several changes.
    r = _core.solve(HAND3, [0, 0, -1.0, 0, 0, 0], max_iterations=1)
    assert r["status"] == "qp_iteration_limit"
    qr = _core.solve(HAND4, PURE_F, orientation=Q_TILT, decomposition="qr")
    svd = _core.solve(HAND4, PURE_F, orientation=Q_TILT, decomposition="svd")
    assert qr["status"] == svd["status"] == "ok"
    assert np.allclose(qr["lambda"], svd["lambda"], rtol=0, atol=1e-9)
    assert qr["pwm"] == svd["pwm"]


def test_unknown_names_raise_value_error():
    for kw in (
        {"policy": "f"},
        {"mode": "c"},
        {"constraints": "Paper"},
        {"scalar": "half"},
        {"decomposition": "lu"},
        {"policy": "F\0perp"},
    ):
        with pytest.raises(ValueError) as e:
            _core.solve(HAND3, PURE_F, **kw)
        assert "accepted" in str(e.value)


def test_wrong_types_raise_type_error_in_the_binding():
    for args in (
        (HAND3, PURE_F[:5]),
        ("abc", PURE_F),
        (HAND3, None),
        ([[1, 2]], PURE_F),
        (HAND3, PURE_F + [0.0]),
    ):
        with pytest.raises(TypeError):
            _core.solve(*args)


def test_python_validation():
    bad = [
        dict(contacts=HAND3, wrench=[True, 0, 0, 0, 0, 0]),
        dict(contacts=HAND3, wrench=["1", 0, 0, 0, 0, 0]),
        dict(contacts=HAND3, wrench="123456"),
        dict(contacts=HAND3, wrench=PURE_F[:5]),
        dict(contacts=[[1, 2]] * 3, wrench=PURE_F),
        dict(contacts=[[1, 2, None]] * 3, wrench=PURE_F),
        dict(contacts={"a": 1}, wrench=PURE_F),
        dict(contacts=HAND3, wrench=PURE_F, orientation=[1, 0, 0]),
        dict(contacts=HAND3, wrench=PURE_F, y_axis=[0, 1, False]),
        dict(contacts=HAND3, wrench=PURE_F, policy=None),
        dict(contacts=HAND3, wrench=PURE_F, mode="v"),
        dict(contacts=HAND3, wrench=PURE_F, constraints="contact"),
    ]
    for kw in bad:
        with pytest.raises(solver.RequestError) as e:
            solver.solve(**kw)
        assert e.value.code == "bad_request" and e.value.message
    with pytest.raises(ValueError):
        solver.solve(HAND3, PURE_F, scalar="single")
    with pytest.raises(TypeError):
        solver.solve(HAND3, PURE_F, max_iterations=2.5)
    # numpy inputs and huge integers are numbers
    r = solver.solve(np.array(HAND3), np.array(PURE_F), orientation=np.array(Q_TILT))
    assert r["status"] == "ok"
    assert solver.solve(HAND3, [10**400, 0, 0, 0, 0, 0])["status"] == "non_finite_input"


def test_weird_values_never_crash():
    values = [
        0.0,
        -0.0,
        1e-320,
        -1e-300,
        1e-30,
        1.0,
        1e30,
        1e300,
        -1e308,
        1.7e308,
        math.inf,
        -math.inf,
        math.nan,
    ]
    rng = np.random.default_rng(5)
    for _ in range(400):
        k = int(rng.integers(3, 5))

        def pick(n):
            return [
                values[i] if rng.random() < 0.3 else float(rng.normal())
                for i in rng.integers(0, len(values), n)
            ]

        contacts = [pick(3) for _ in range(k)]
        for scalar in ("double", "float"):
            for decomposition in ("qr", "svd"):
                r = _core.solve(
                    contacts,
                    pick(6),
                    orientation=pick(4),
                    y_axis=pick(3),
                    scalar=scalar,
                    decomposition=decomposition,
                    constraints=("paper", "normal", "none")[_ % 3],
                )
                assert r["status"] in _core.STATUS_NAMES
                if r["status"] == "ok":
                    assert all(0 <= v <= 255 for v in r["pwm"])
                else:
                    assert r["pwm"] == [0] * k


# --------------------------------------------------------------------------------------
# float vs double
# --------------------------------------------------------------------------------------
def test_float_and_double_agree_within_one_pwm_count():
    cases = _scenes()
    worse = []
    n_ok = 0
    for req in cases:
        d = solver.solve(scalar="double", **req)
        f = solver.solve(scalar="float", **req)
        assert f["status"] == d["status"], req
        if d["status"] != "ok":
            continue
        n_ok += 1
        diff = max(abs(a - b) for a, b in zip(d["pwm"], f["pwm"]))
        if diff > 1 or f["constraints_used"] != d["constraints_used"]:
            worse.append((req, d["pwm"], f["pwm"], d["constraints_used"], f["constraints_used"]))
    assert n_ok > 0.9 * len(cases)
    assert not worse, f"{len(worse)} of {n_ok} scenes differ: {worse[:3]}"


# --------------------------------------------------------------------------------------
# Stateful Guidance
# --------------------------------------------------------------------------------------
def test_guidance_recomputes_only_when_the_grasp_changes():
    g = solver.Guidance()
    assert g.set_scene(HAND4, policy="Fperp", mode="V", constraints="normal") == "ok"
    assert g.k == 4
    assert g.set_wrench(PURE_F) == "ok"
    first = g.update(Q_TILT)
    assert first["status"] == "ok" and first["recomputed"] is True
    one_shot = solver.solve(HAND4, PURE_F, "Fperp", "V", "normal", Q_TILT)
    for key in ("pwm", "levels", "lambda", "error_deg", "alpha", "constraints_used"):
        assert first[key] == one_shot[key]

    # Only the orientation changes: no recomputation, same grasp, new error and PWM.
    q2 = [0.7071068, 0.0, 0.7071068, 0.0]
    second = g.update(q2)
    assert second["status"] == "ok" and second["recomputed"] is False
    assert second["lambda"] == first["lambda"] and second["levels"] == first["levels"]
    assert second["error_deg"] != first["error_deg"]
    assert second == dict(solver.solve(HAND4, PURE_F, "Fperp", "V", "normal", q2), recomputed=False)
    assert g.update(q2)["recomputed"] is False

    # Exactly the same contacts / wrench: still nothing to recompute.
    assert g.set_contacts([list(c) for c in HAND4]) == "ok"
    assert g.set_wrench(list(PURE_F)) == "ok"
    assert g.update(Q_TILT)["recomputed"] is False

    # Contacts change: recomputed, and equal to a one-shot solve of the new scene.
    moved = [list(c) for c in HAND4]
    moved[1][2] += 0.004
    assert g.set_contacts(moved) == "ok"
    third = g.update(Q_TILT)
    assert third["recomputed"] is True
    assert third["lambda"] != first["lambda"]
    ref = solver.solve(moved, PURE_F, "Fperp", "V", "normal", Q_TILT)
    assert np.allclose(third["lambda"], ref["lambda"], rtol=0, atol=1e-12)
    assert g.update(Q_TILT)["recomputed"] is False

    # The wrench changes: recomputed.
    assert g.set_wrench([0.0, 1.0, 0.0, 0.0, 0.05, 0.0]) == "ok"
    assert g.update(Q_TILT)["recomputed"] is True

    # A new scene always recomputes.
    assert g.set_scene(moved, policy="Fperp", mode="V", constraints="normal") == "ok"
    assert g.update(Q_TILT)["recomputed"] is True


def test_guidance_setter_errors_change_nothing():
    g = solver.Guidance()
    assert g.update(Q_TILT)["status"] == "zero_wrench"  # no wrench yet
    assert g.set_scene(HAND3) == "ok"
    assert g.set_wrench(PURE_F) == "ok"
    good = g.update(Q_TILT)
    assert good["status"] == "ok"
    assert g.set_contacts(HAND4) == "bad_contact_count"
    assert g.set_contacts([[math.nan, 0, 0]] + HAND3[1:]) == "non_finite_input"
    assert g.set_wrench([math.inf, 0, 0, 0, 0, 0]) == "non_finite_input"
    assert g.set_scene(HAND3[:2]) == "bad_contact_count"
    assert g.set_scene(HAND3, y_axis=[0, 0, 0]) == "bad_axis"
    assert g.set_scene(HAND3, max_iterations=0) == "bad_config"
    after = g.update(Q_TILT)
    assert after["recomputed"] is False
    assert after["pwm"] == good["pwm"] and after["lambda"] == good["lambda"]
    bad_q = g.update([0, 0, 0, 0])
    assert bad_q["status"] == "bad_quaternion" and bad_q["pwm"] == [0, 0, 0]
    assert g.update([math.nan, 0, 0, 0])["status"] == "non_finite_input"
    # A failing grasp is kept as failing until something changes.
    assert g.set_contacts([HAND3[0], HAND3[0], HAND3[2]]) == "ok"
    assert g.update(Q_TILT)["status"] == "coincident_contacts"
    assert g.update(Q_TILT)["status"] == "coincident_contacts"
    assert g.set_contacts(HAND3) == "ok"
    again = g.update(Q_TILT)  # warm-started from the last good grasp
    assert again["status"] == "ok" and again["recomputed"] is True
    assert again["pwm"] == good["pwm"]
    assert np.allclose(again["lambda"], good["lambda"], rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------
# Against the float64 reference where the QP is degenerate
# --------------------------------------------------------------------------------------
def test_contacts_in_a_plane_containing_y_axis_match_the_reference():
    """All contacts in z = 0 (a plane containing y_O = +y): every lambda_ix is fixed by
    equilibrium, so its constraint row is rounding noise (~1e-16). Such a row must count
    as dependent (an infeasibility certificate), not as a direction for a 1e30 step."""
    from graspguide.core import reference as ref

    rng = np.random.default_rng(1)
    disagree = []
    for t in range(60):
        contacts = rng.uniform(-0.05, 0.05, (3, 3))
        contacts[:, 2] = 0.0
        wrench = np.concatenate([rng.normal(size=3), rng.normal(size=3) * 0.02 * (t % 2)])
        expect = ref.solve(
            contacts.tolist(), wrench.tolist(), constraints="paper", compute_margins=False
        )
        for scalar in ("double", "float"):
            r = _core.solve(contacts.tolist(), wrench.tolist(), constraints="paper", scalar=scalar)
            same = r["status"] == expect["status"]
            if same and r["status"] == "ok":
                same = (
                    r["constraints_used"] == expect["constraints_used"]
                    and max(abs(a - b) for a, b in zip(r["pwm"], expect["pwm"])) <= 1
                    and max(abs(v) for v in r["lambda"]) < 1e3
                )
            if not same:
                disagree.append(
                    (
                        t,
                        scalar,
                        r["constraints_used"],
                        expect["constraints_used"],
                        r["pwm"],
                        expect["pwm"],
                    )
                )
    assert not disagree, disagree[:5]
    r = _core.solve(
        [[0.045, 0.045, 0.0], [0.015, 0.095, 0.0], [-0.01, 0.1, 0.0]], [0, 0, 1.0, 0, 0, 0]
    )
    assert r["constraints_used"] == "normal" and r["pwm"] == [177, 177, 177]
