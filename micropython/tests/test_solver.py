"""The port's per-posture solver, run INSIDE MicroPython (tests/run.py, or this file
directly): the float64 reference's known answers (test/data/known_answers.json, made by
tools/graspguide/core/reference.py: SVD and an exhaustive active-set QP, nothing shared
with this port), equilibrium and the constraint models checked from the grasp matrix
built independently here, motors off on every error, and solve_server's line handling."""

import json
import math
import sys

if __name__ == "__main__":  # run directly: the port's root holds graspguide_mp
    sys.path.insert(0, (__file__.rsplit("/", 1)[0] if "/" in __file__ else ".") + "/..")

from graspguide_mp import status as st
from graspguide_mp.solver import K_MOTOR_OFF_LEVEL, solve

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
HAND4 = HAND3 + [[0.0, 0.045, 0.0]]
_NON_FINITE = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}


def _parent(path):
    i = path.rfind("/")
    return path[:i] if i > 0 else "."


def _known_answers_path():
    return _parent(__file__) + "/../../test/data/known_answers.json"


def _decode(x):
    if isinstance(x, str):
        return _NON_FINITE[x]
    if isinstance(x, list):
        return [_decode(v) for v in x]
    return float(x)


def _solve_case(case):
    return solve(
        _decode(case["contacts"]),
        _decode(case["wrench"]),
        case["policy"],
        case["mode"],
        case["constraints"],
        _decode(case["orientation"]),
        _decode(case["y_axis"]),
    )


def _norm(v):
    return math.sqrt(sum(x * x for x in v))


def test_known_answers():
    path = _known_answers_path()
    try:
        with open(path) as f:
            cases = json.load(f)["cases"]
    except OSError:
        raise AssertionError(
            path + " not found: run from the repository's micropython/ folder"
        ) from None
    assert len(cases) > 100
    problems = []
    n_ok = 0
    for case in cases:
        expect = case["expect"]
        res = _solve_case(case)
        name = st.name(res.status)
        if name != expect["status"]:
            problems.append(case["name"] + ": " + name + " != " + expect["status"])
            continue
        if name != "ok":
            assert res.pwm == [0] * len(res.pwm), case["name"]
            continue
        n_ok += 1
        if res.used != expect["constraints_used"] or res.relevant != expect["relevant"]:
            problems.append(case["name"] + ": model or relevance")
        for a, b in zip(res.pwm, expect["pwm"]):
            if abs(a - b) > 1:
                problems.append(case["name"] + ": pwm %s vs %s" % (res.pwm, expect["pwm"]))
                break
        ref = expect["lambda"]
        diff = _norm([a - b for a, b in zip(res.lam, ref)])
        if not diff <= 1e-6 * _norm(ref):
            problems.append(case["name"] + ": lambda off by %g" % diff)
        if not abs(res.error_deg - expect["error_deg"]) <= 1e-6:
            problems.append(case["name"] + ": error_deg")
    assert n_ok > 100, n_ok
    assert not problems, "\n".join(problems[:20])


def _grasp_residual(contacts, wrench, y_axis, lam):
    """|G lam + w_L| / |w_L|, with G built here from its definition (docs/algorithm.md,
    steps 1-2): R_i = [x_i y_i z_i], G_i = [R_i; skew(s_i) R_i]."""
    k = len(contacts)
    o = [sum(c[j] for c in contacts) / k for j in range(3)]
    r = [[c[j] - o[j] for j in range(3)] for c in contacts]
    L = max(_norm(v) for v in r)
    yn = _norm(y_axis)
    yo = [v / yn for v in y_axis]
    total = [wrench[0], wrench[1], wrench[2], wrench[3] / L, wrench[4] / L, wrench[5] / L]
    for i in range(k):
        y = [v / _norm(r[i]) for v in r[i]]
        x = [y[1] * yo[2] - y[2] * yo[1], y[2] * yo[0] - y[0] * yo[2], y[0] * yo[1] - y[1] * yo[0]]
        xn = _norm(x)
        assert xn > 1e-3, "these scenes need no fallback axis"
        x = [v / xn for v in x]
        z = [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
        f = [lam[3 * i] * x[j] + lam[3 * i + 1] * y[j] + lam[3 * i + 2] * z[j] for j in range(3)]
        s = [v / L for v in r[i]]
        m = [s[1] * f[2] - s[2] * f[1], s[2] * f[0] - s[0] * f[2], s[0] * f[1] - s[1] * f[0]]
        for j in range(3):
            total[j] += f[j]
            total[3 + j] += m[j]
    return _norm(total) / _norm(
        [wrench[0], wrench[1], wrench[2], wrench[3] / L, wrench[4] / L, wrench[5] / L]
    )


def test_equilibrium_and_the_constraint_models():
    y_axis = [0.0, 1.0, 0.0]
    checked = 0
    for contacts in (HAND3, HAND4):
        for wrench in (
            [0.3, -1.2, -0.8, 0.0, 0.0, 0.0],
            [1.0, 0.5, -0.2, 0.0, 0.02, 0.0],
            [-0.4, 0.1, 1.0, 0.01, -0.01, 0.005],
        ):
            for model in ("paper", "normal", "none"):
                res = solve(contacts, wrench, "F", "C", model)
                assert res.status == st.OK, st.name(res.status)
                assert _grasp_residual(contacts, wrench, y_axis, res.lam) < 1e-9
                scale = _norm(res.lam)
                if res.used == "paper":
                    assert min(res.lam) >= -1e-9 * scale, res.lam
                elif res.used == "normal":
                    assert min(res.lam[1::3]) >= -1e-9 * scale, res.lam
                # The fallback chain only ever goes down from the requested model.
                order = ("paper", "normal", "none")
                assert order.index(res.used) >= order.index(model)
                for level, duty in zip(res.levels, res.pwm):
                    assert (duty == 0) == (abs(level) <= K_MOTOR_OFF_LEVEL)
                checked += 1
    assert checked == 18


def test_motors_off_and_the_status_on_every_error():
    nan = float("nan")
    bad = (
        (HAND3, [nan, 0, 0, 0, 0, 0], (1, 0, 0, 0), (0, 1, 0), st.NON_FINITE_INPUT),
        (HAND3[:2], [1, 0, 0, 0, 0, 0], (1, 0, 0, 0), (0, 1, 0), st.BAD_CONTACT_COUNT),
        (HAND3, [1, 0, 0, 0, 0, 0], (1, 0, 0, 0), (0, 0, 0), st.BAD_AXIS),
        (HAND3, [1, 0, 0, 0, 0, 0], (0, 0, 0, 0), (0, 1, 0), st.BAD_QUATERNION),
        (
            [HAND3[0], HAND3[0], HAND3[2]],
            [1, 0, 0, 0, 0, 0],
            (1, 0, 0, 0),
            (0, 1, 0),
            st.COINCIDENT_CONTACTS,
        ),
        (
            [[0, 0, 0], [0.01, 0, 0], [0.03, 0, 0]],
            [1, 0, 0, 0, 0, 0],
            (1, 0, 0, 0),
            (0, 1, 0),
            st.RANK_DEFICIENT,
        ),
        (
            [[c + 1e14 for c in p] for p in HAND3],
            [1, 0, 0, 0, 0, 0],
            (1, 0, 0, 0),
            (0, 1, 0),
            st.IMPRECISE_CONTACTS,
        ),
        (HAND3, [0, 0, 0, 0, 0, 0], (1, 0, 0, 0), (0, 1, 0), st.ZERO_WRENCH),
        (HAND3, [0, 0, 0, 0, 0.1, 0], (1, 0, 0, 0), (0, 1, 0), st.ZERO_FORCE),
    )
    for contacts, wrench, q, axis, want in bad:
        res = solve(contacts, wrench, "F", "C", "paper", q, axis)
        assert res.status == want, (st.name(res.status), st.name(want))
        assert res.pwm == [0] * len(contacts)
        assert res.levels is None and res.lam is None


def test_status_table():
    names = [n for n, _ in st.STATUSES]
    assert len(set(names)) == st.COUNT
    for code in range(st.COUNT):
        assert st.code_of(st.name(code)) == code
        assert st.message(code)
    assert st.name(st.COUNT) == "unknown"


def test_solve_server_lines():
    import solve_server

    ok = json.loads(
        solve_server.respond(
            json.dumps({"contacts": HAND3, "wrench": [0.3, -1.2, -0.8, 0, 0, 0]}), 1
        )
    )
    direct = solve(HAND3, [0.3, -1.2, -0.8, 0, 0, 0])
    assert ok["ok"] and ok["pwm"] == direct.pwm
    assert solve_server.respond("   \n", 2) is None
    bad = json.loads(solve_server.respond("{nope", 3))
    assert bad["error"] == "bad_json" and "line 3" in bad["message"]
    missing = json.loads(solve_server.respond('{"contacts": []}', 4))
    assert missing["error"] == "bad_request"
    nan = json.loads(
        solve_server.respond(json.dumps({"contacts": HAND3, "wrench": ["nan", 0, 0, 0, 0, 0]}), 5)
    )
    assert nan == {
        "ok": False,
        "error": "non_finite_input",
        "message": st.message(st.NON_FINITE_INPUT),
    }


if __name__ == "__main__":
    failed = 0
    for _name in sorted(k for k in dir() if k.startswith("test_")):
        try:
            globals()[_name]()
            print("PASS", _name)
        except Exception as e:
            failed += 1
            print("FAIL", _name, repr(e))
    print("failed:", failed)
    sys.exit(1 if failed else 0)
