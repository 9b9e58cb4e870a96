"""The nanobind binding graspguide.core._core and its Python wrapper graspguide.core.solver."""

from __future__ import annotations

import collections
import decimal
import fractions
import itertools
import json
import math
import os
import types

import numpy as np
import pytest
from conftest import TOOLS_DIR

from graspguide.core import _core, solver
from graspguide.core import scene_generators as scenes

EXAMPLES = os.path.join(
    TOOLS_DIR,
    "examples",
    "solve_requests.jsonl",
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
    "retried",
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
    assert len(set(_core.STATUS_NAMES)) == len(_core.STATUS_NAMES) == 19
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
        decomposition="structured",
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
    qr = _core.solve(HAND4, PURE_F, orientation=Q_TILT, decomposition="structured")
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
            for decomposition in ("structured", "svd"):
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


# --------------------------------------------------------------------------------------
# Fast paths: they only accept, and nothing the thorough checks refuse
# --------------------------------------------------------------------------------------
class _NoPlainCore:
    """The binding with its plain-type fast path answering "not plain" to everything."""

    def __getattr__(self, name):
        return getattr(_core, name)

    @staticmethod
    def solve_plain(*args):
        return None

    @staticmethod
    def plain_numbers(*args):
        return None


class _Float(float):
    def __float__(self):  # float() disagrees with the stored value
        return 2.0


class _Int(int):
    pass


class _Str(str):
    pass


class _List(list):
    pass


def _outcome(fn, *args, **kw):
    """What a call gives: its result, or its exception's type, code and message."""
    try:
        return ("result", json.dumps(fn(*args, **kw), allow_nan=True, sort_keys=True))
    except Exception as e:  # noqa: BLE001 - the exception is the outcome compared
        return ("raised", type(e).__name__, getattr(e, "code", None), str(e))


@pytest.fixture
def thorough(monkeypatch):
    """``thorough(fn, ...)``: the outcome of fn with every fast path of solver off."""

    def run(fn, *args, **kw):
        with monkeypatch.context() as m:
            m.setattr(solver, "_core", _NoPlainCore())
            m.setattr(solver, "_plain_numbers", lambda x, n: None)
            m.setattr(solver, "_float64_array", lambda x: False)
            m.setattr(solver, "_plain_fields", lambda obj: None)
            return _outcome(fn, *args, **kw)

    return run


def _numbers(good):
    """A field's value in every form a caller might pass, plain or not, good or bad.
    Built afresh per call: the generator is used up by one."""
    good = list(good)
    ints = [int(round(v)) for v in good]
    rest = good[1:]
    return {
        "list": list(good),
        "tuple": tuple(good),
        "ints": ints,
        "mixed": [good[0], *ints[1:]],
        "nan": [math.nan, *rest],
        "inf": [-math.inf, *rest],
        "2**53+1": [2**53 + 1, *rest],
        "huge int": [10**400, *rest],
        "-huge int": [-(10**400), *rest],
        "float64 array": np.array(good),
        "big-endian array": np.array(good, dtype=">f8"),
        "float32 array": np.array(good, np.float32),
        "int64 array": np.array(ints),
        "bool array": np.array(good) > 0,
        "2-D array": np.array([good]),
        "0-D array": np.array(good[0]),
        "masked array": np.ma.masked_array(good),
        "short": good[:-1],
        "long": [*good, 0.0],
        "empty": [],
        "bool": [True, *rest],
        "numpy bool": [np.bool_(False), *rest],
        "None inside": [None, *rest],
        "str inside": ["1", *rest],
        "nested": [[good[0]], *rest],
        "numpy float64s": [np.float64(v) for v in good],
        "numpy int64": [np.int64(1), *rest],
        "float subclass": [_Float(1.0), *rest],
        "int subclass": [_Int(1), *rest],
        "Fraction": [fractions.Fraction(1, 3), *rest],
        "Decimal": [decimal.Decimal("0.1"), *rest],
        "list subclass": _List(good),
        "range": range(len(good)),
        "generator": (v for v in good),
        "string": "1" * len(good),
        "bytes": b"1" * len(good),
        "dict": dict(enumerate(good)),
        "None": None,
        "number": 1.0,
    }


def _contact_forms():
    rows = [list(c) for c in HAND3]
    forms = {
        "tuples": tuple(tuple(r) for r in rows),
        "array": np.array(rows),
        "float32 array": np.array(rows, np.float32),
        "(3, 2) array": np.array(rows)[:, :2],
        "(3, 3, 1) array": np.array(rows)[:, :, None],
        "flat array": np.array(rows).ravel(),
        "array rows": [np.array(r) for r in rows],
        "no rows": [],
        "2 rows": rows[:2],
        "5 rows": rows + HAND4[3:] + [[0.0, 0.0, 0.1]],
        "64 rows": rows * 21 + rows[:1],
        "65 rows": rows * 21 + rows[:2],
        "70 rows, the last bad": rows * 23 + [[0.0, 0.0]],
        "(70, 3) array": np.array(rows * 23 + rows[:1]),
        "flat list": [v for r in rows for v in r],
    }
    for name, row in _numbers(HAND3[1]).items():
        forms[f"row {name}"] = [rows[0], row, rows[2]]
    return forms


_NAMES = {
    "policy": ["F", "Fperp", "f", "F\0perp", _Str("F"), None, 1, b"F", "\ud800", ""],
    "mode": ["C", "V", "v", _Str("V"), None, 0],
    "constraints": ["paper", "normal", "none", "Paper", _Str("none"), None, ["paper"]],
}
_OPTIONS = {
    "scalar": ["double", "float", "half", None, _Str("float"), 1],
    "decomposition": [*solver.DECOMPOSITIONS, "lu", None, _Str(solver.DEFAULT_DECOMPOSITION)],
    "max_iterations": [64, 1, 0, -5, 2**31, 2**40, -(2**40), 10**30, True, 2.5, None, "64"]
    + [np.int64(5), _Int(3)],
}
_FIELDS = {"wrench": PURE_F, "orientation": Q_TILT, "y_axis": [0.0, 1.0, 0.0]}


def _solve_cases():
    base = {"contacts": HAND3, "wrench": PURE_F, "orientation": Q_TILT}
    cases = [(f"contacts {n}", {**base, "contacts": v}) for n, v in _contact_forms().items()]
    for field, good in _FIELDS.items():
        cases += [(f"{field} {n}", {**base, field: v}) for n, v in _numbers(good).items()]
    for field, values in {**_NAMES, **_OPTIONS}.items():
        cases += [(f"{field} {v!r}", {**base, field: v}) for v in values]
    return cases


def test_fast_paths_accept_and_refuse_as_the_thorough_checks(thorough):
    """Every form of every argument: solve() gives the same result, or raises the same
    exception with the same message, with and without its fast paths."""
    cases = list(zip(_solve_cases(), _solve_cases()))  # two sets: a generator is used up
    assert len(cases) > 150
    for (name, fast_kw), (_, slow_kw) in cases:
        assert _outcome(solver.solve, **fast_kw) == thorough(solver.solve, **slow_kw), name
    # The checks whose fast path is one line of their own: a bool is no int, a str
    # subclass is a str.
    with pytest.raises(TypeError, match="^max_iterations must be an int, got boolean true$"):
        solver.solve(HAND3, PURE_F, max_iterations=True)
    assert solver.solve(HAND3, PURE_F, _Str("Fperp"), _Str("V")) == solver.solve(
        HAND3, PURE_F, "Fperp", "V"
    )


def _requests():
    good = {"contacts": HAND3, "wrench": PURE_F}
    requests = [
        good,
        {**good, "units": "mm"},
        {**good, "policy": "Fperp", "mode": "V", "constraints": "none", "y_axis": [0, 1, 0]},
        {"contacts": HAND3},
        {},
        types.MappingProxyType(good),
        collections.OrderedDict(good),
        [good],
        None,
        {1: 2, **good},
    ]
    requests += [{**good, "contacts": v} for v in _contact_forms().values()]
    for field, value in _FIELDS.items():
        requests += [{**good, field: v} for v in _numbers(value).values()]
    return requests


def _guidance_calls():
    """One call on a Guidance with a scene and a wrench, per form of each argument."""
    calls = [lambda g, v=v: g.update(v) for v in _numbers(Q_TILT).values()]
    calls += [lambda g, v=v: g.set_wrench(v) for v in _numbers(PURE_F).values()]
    calls += [lambda g, v=v: g.set_contacts(v) for v in _contact_forms().values()]
    calls += [lambda g, v=v: g.set_scene(v) for v in _contact_forms().values()]
    calls += [
        lambda g, k=k, v=v: g.set_scene(HAND3, **{k: v}) for k, vs in _NAMES.items() for v in vs
    ]
    return calls


def _on_guidance(call):
    g = solver.Guidance()
    assert g.set_scene(HAND3) == "ok" and g.set_wrench(PURE_F) == "ok"
    return call(g)


def test_fast_paths_of_parse_request_and_guidance(thorough):
    for fast, slow in zip(_requests(), _requests()):
        assert _outcome(solver.parse_request, fast) == thorough(solver.parse_request, slow), fast
    for i, (fast, slow) in enumerate(zip(_guidance_calls(), _guidance_calls())):
        assert _outcome(_on_guidance, fast) == thorough(_on_guidance, slow), i


def test_plain_arguments_take_the_bindings_fast_path():
    """The plain forms are answered by _core.solve_plain itself (no Python check), with
    the binding's own result; any other form is left to the thorough checks."""
    plain = ["list", "tuple", "ints", "mixed", "nan", "inf", "2**53+1"]
    for name, value in _numbers(PURE_F).items():
        args = (HAND3, value, "F", "C", "paper", Q_TILT, [0.0, 1.0, 0.0])
        res = _core.solve_plain(*args, "double", solver.DEFAULT_DECOMPOSITION, 64)
        if name in plain:
            assert res == _core.solve(*args, "double", solver.DEFAULT_DECOMPOSITION, 64), name
        else:
            assert res is None, name
    numbers = _core.plain_numbers(
        tuple(map(tuple, HAND4)), [1, 2, 3, 4, 5, 10**20], Q_TILT, [0, 1, 0]
    )
    assert numbers == (
        [list(c) for c in HAND4],
        [1.0, 2.0, 3.0, 4.0, 5.0, 1e20],
        Q_TILT,
        [0.0, 1.0, 0.0],
    )
    assert all(type(v) is float for v in numbers[1] + numbers[3])
    assert _core.plain_numbers(HAND3, PURE_F, Q_TILT, [0, 1, True]) is None
