#!/usr/bin/env python3
"""Regenerate the known-answer data of GraspGuide from the float64 reference.

    python tools/scripts/gen_known_answers.py            # writes both files
    python tools/scripts/gen_known_answers.py --check    # exit 1 if they are stale
    python tools/scripts/gen_known_answers.py --check --strict   # byte-exact check

Writes test/data/known_answers.json and test/data/known_answers.h (C++, generated).
Deterministic: every scene comes from numpy.random.default_rng with a fixed seed.

--check regenerates in memory and compares with the checked-in files. The header must
be exactly what this script renders from the checked-in JSON, and the JSON must equal
the regenerated data: strings, ints, booleans and nulls exactly, floats to within
1e-7 relative (so a different LAPACK/BLAS or HiGHS build that changes the last bits of
a result does not count as stale; --strict makes it byte-exact).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any

_HERE = os.path.dirname(os.path.abspath(__file__))
_TOOLS = os.path.dirname(_HERE)
_ROOT = os.path.dirname(_TOOLS)
if _TOOLS not in sys.path:
    sys.path.insert(0, _TOOLS)

import numpy as np  # noqa: E402

from graspguide.core import reference as ref  # noqa: E402
from graspguide.core import scene_generators as scenes  # noqa: E402
from graspguide.core.vocabulary import CONSTRAINT_MODELS, MODES, POLICIES  # noqa: E402

JSON_PATH = os.path.join(_ROOT, "test", "data", "known_answers.json")
HEADER_PATH = os.path.join(_ROOT, "test", "data", "known_answers.h")

BASE_SEED = 20240611
RANDOM_PER_K = 160
COMBOS = [(p, m, c) for p in POLICIES for m in MODES for c in CONSTRAINT_MODELS]

# Random cases whose decisions sit near a threshold are redrawn, so that an
# implementation with different rounding (or float) makes the same discrete decisions.
SLACK_PWM = 1e-3  # |frac(70 + gain |m_i|) - 0.5| must exceed this (PWM counts)
SLACK_OFF = 1e-5  # ||m_i| - kMotorOffLevel| must exceed this
SLACK_COS = 1e-4  # |cos(f, r_i) - kRelevanceCosTol| must exceed this
SLACK_SIN = 1e-4  # |sin(y_i, y_O) - kAxisParallelTol| must exceed this
MIN_RANK_RATIO = 1e-2  # sigma_6 / sigma_1 must exceed this
MARGIN_BAND = (-1e-3, -1e-8)  # margins of the tried models must lie outside this band
FEAS_TOL_RANGE = (1e-12, 1e-4)  # the model used must not change over this kFeasRelTol range
FLOAT_TOL = 1e-7  # --check: relative float tolerance (ill-conditioned cases: ~1e-9)

NOTES = [
    'Inputs: non-finite numbers are stored as the strings "nan", "inf" and "-inf" '
    "(JSON has no portable NaN); every other number is a JSON number written with "
    "Python's repr, which round-trips float64 exactly.",
    "Outputs not defined for a status are null: lambda, levels and relevant before the "
    "QP; error_deg and alpha unless status is ok or nothing_to_display; margin for the "
    "'none' model or before the QP. pwm is always k ints (all 0 unless status is ok). "
    'constraints_used is "" and fallback_mask is 0 unless status is ok.',
    "lambda: 3k contact-frame components [x y z] per contact, the QP optimum "
    "lambda0 + N xi before normalisation, of the model actually used.",
    "levels: the normalised motor levels m (signed for policy Fperp), before the "
    "kMotorOffLevel threshold, which only affects pwm.",
    "margin: max t s.t. G lambda = -w_L, lambda_j >= t ||lambda0|| (j constrained by the "
    "requested model), t <= 1; negative means infeasible. For the paper model with a "
    "pure force the feasible set has no interior, so a feasible margin is 0 up to "
    "LP rounding (|t| < 1e-9): compare margins with an absolute tolerance.",
    "Random cases are redrawn when a discrete decision (PWM rounding, motor off level, "
    "relevance, fallback axis, rank, feasibility) is close to its threshold; see "
    "SLACK_* in the generator. Float implementations may still differ by one PWM count "
    "where float rounding is larger than those slacks.",
    "The header known_answers.h is rendered from this file: regenerate both with "
    "`python tools/scripts/gen_known_answers.py`.",
]


# --------------------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------------------
def enc_num(x: float) -> Any:
    x = float(x)
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return x


def dec_num(x: Any) -> float:
    if isinstance(x, str):
        return {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}[x]
    return float(x)


def _opt_list(v: list[Any] | None, conv=float) -> list[Any] | None:
    return None if v is None else [conv(x) for x in v]


def expected_block(res: dict[str, Any], constraints: str) -> dict[str, Any]:
    margin = res["margins"].get(constraints) if res["margins"] else None
    return {
        "status": res["status"],
        "constraints_used": res["constraints_used"],
        "lambda": _opt_list(res["lambda"]),
        "levels": _opt_list(res["levels"]),
        "pwm": [int(v) for v in res["pwm"]],
        "relevant": _opt_list(res["relevant"], bool),
        "error_deg": res["error_deg"],
        "alpha": res["alpha"],
        "fallback_mask": int(res["fallback_mask"]),
        "margin": margin,
    }


def run_case(scene: dict[str, Any], policy: str, mode: str, constraints: str) -> dict[str, Any]:
    return ref.solve(
        scene["contacts"],
        scene["wrench"],
        policy=policy,
        mode=mode,
        constraints=constraints,
        orientation=scene["orientation"],
        y_axis=scene["y_axis"],
    )


def case_entry(
    name: str,
    scene: dict[str, Any],
    policy: str,
    mode: str,
    constraints: str,
    res: dict[str, Any],
    note: str | None = None,
) -> dict[str, Any]:
    entry = {
        "name": name,
        "k": len(scene["contacts"]),
        "contacts": [[enc_num(v) for v in row] for row in scene["contacts"]],
        "wrench": [enc_num(v) for v in scene["wrench"]],
        "y_axis": [enc_num(v) for v in scene["y_axis"]],
        "orientation": [enc_num(v) for v in scene["orientation"]],
        "policy": policy,
        "mode": mode,
        "constraints": constraints,
    }
    if note:
        entry["note"] = note
    entry["expect"] = expected_block(res, constraints)
    return entry


# --------------------------------------------------------------------------------------
# Self-checks (cheap; the thorough ones are in tools/tests/test_reference.py)
# --------------------------------------------------------------------------------------
def check_result(scene: dict[str, Any], res: dict[str, Any], constraints: str) -> None:
    if res["status"] != "ok":
        return
    C = np.asarray(scene["contacts"], dtype=float)
    w = np.asarray(scene["wrench"], dtype=float)
    y = np.asarray(scene["y_axis"], dtype=float)
    status, frames = ref.contact_frames(C, y / np.linalg.norm(y))
    assert status == "ok"
    G = ref.grasp_matrix(frames)
    w_l = np.concatenate([w[:3], w[3:] / frames["L"]])
    lam = np.asarray(res["lambda"])
    resid = np.linalg.norm(G @ lam + w_l)
    assert resid <= 1e-11 * (np.linalg.norm(lam) + np.linalg.norm(w_l)), (scene["name"], resid)
    used = res["constraints_used"]
    lam0n = np.linalg.norm(res["diagnostics"]["lam0"])
    S = ref.constrained_components(used, len(C))
    if S:
        assert lam[S].min() >= -ref.kFeasRelTol * lam0n, (scene["name"], lam[S].min())
    # Margin vs enumeration: feasible => margin >= -delta (minus LP noise);
    # infeasible => margin < 0 (plus LP noise).
    chain = ref.FALLBACK_CHAIN[constraints]
    for model in chain[: chain.index(used)]:
        t = res["margins"][model]
        assert t < 1e-9, (scene["name"], model, "enumeration infeasible but margin", t)
    t = res["margins"].get(used)
    if t is not None:
        assert t >= -ref.kFeasRelTol - 1e-9, (scene["name"], used, "feasible but margin", t)
    assert abs(np.linalg.norm(res["levels"]) - 1.0) < 1e-12


def feasibility_depends_on_tol(
    scene: dict[str, Any], res: dict[str, Any], constraints: str
) -> bool:
    """True if the model used changes when kFeasRelTol spans FEAS_TOL_RANGE (float's
    1e-4 down to 1e-12): a numerically borderline feasibility decision."""
    for tol in FEAS_TOL_RANGE:
        other = ref.solve(
            scene["contacts"],
            scene["wrench"],
            constraints=constraints,
            orientation=scene["orientation"],
            y_axis=scene["y_axis"],
            compute_margins=False,
            feas_rel_tol=tol,
        )
        if other["constraints_used"] != res["constraints_used"]:
            return True
    return False


def fragile_reason(
    res: dict[str, Any], constraints: str, scene: dict[str, Any] | None = None
) -> str | None:
    """Why a random case is too close to a decision threshold (None if it is not)."""
    if res["status"] != "ok":
        return f"status {res['status']}"
    if (
        scene is not None
        and constraints != "none"
        and feasibility_depends_on_tol(scene, res, constraints)
    ):
        return "feasibility depends on kFeasRelTol"
    d = res["diagnostics"]
    if d["rank_ratio"] < MIN_RANK_RATIO:
        return f"rank ratio {d['rank_ratio']:.3g}"
    for c in d["relevance_cos"]:
        if abs(c - ref.kRelevanceCosTol) < SLACK_COS:
            return f"relevance cosine {c:.3g}"
    for s in d["axis_sin"]:
        if abs(s - ref.kAxisParallelTol) < SLACK_SIN:
            return f"axis sine {s:.3g}"
    chain = ref.FALLBACK_CHAIN[constraints]
    for model in chain[: chain.index(res["constraints_used"]) + 1]:
        t = res["margins"].get(model)
        if t is not None and MARGIN_BAND[0] < t < MARGIN_BAND[1]:
            return f"margin {t:.3g} of {model}"
    for m in res["levels"]:
        if abs(abs(m) - ref.kMotorOffLevel) < SLACK_OFF:
            return f"level {m:.3g} near the off threshold"
    for x, m in zip(d["pwm_raw"], res["levels"]):
        if abs(m) > ref.kMotorOffLevel and abs(x - math.floor(x) - 0.5) < SLACK_PWM:
            return f"pwm {x:.6f} near a rounding half"
    return None


def check_extreme(case: dict[str, Any], res: dict[str, Any]) -> None:
    name = case["name"]
    if case.get("expect_status") is not None:
        assert res["status"] == case["expect_status"], (name, res["status"])
    for key, want in case.get("expect", {}).items():
        got = res["relevant"][0] if key == "relevant0" else res[key]
        if isinstance(want, float):
            assert got is not None and abs(got - want) < 1e-9, (name, key, got, want)
        else:
            assert got == want, (name, key, got, want)


def check_same(name: str, a: dict[str, Any], b: dict[str, Any], other: str) -> None:
    assert a["status"] == b["status"] == "ok", (name, other)
    assert a["pwm"] == b["pwm"], (name, other, a["pwm"], b["pwm"])
    assert a["relevant"] == b["relevant"] and a["constraints_used"] == b["constraints_used"]
    assert np.max(np.abs(np.subtract(a["levels"], b["levels"]))) < 1e-8, (name, other)
    assert abs(a["error_deg"] - b["error_deg"]) < 1e-9, (name, other)


# --------------------------------------------------------------------------------------
# Generation
# --------------------------------------------------------------------------------------
def generate(verbose: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    t0 = time.perf_counter()
    cases: list[dict[str, Any]] = []
    stats = {"redrawn": 0, "redraw_reasons": {}}

    for k in (3, 4):
        for i in range(RANDOM_PER_K):
            policy, mode, constraints = COMBOS[i % len(COMBOS)]
            attempt = 0
            while True:
                seed = [BASE_SEED, k, i] + ([attempt] if attempt else [])
                scene = scenes.random_scene(np.random.default_rng(seed), k)
                res = run_case(scene, policy, mode, constraints)
                why = fragile_reason(res, constraints, scene)
                if why is None:
                    break
                stats["redrawn"] += 1
                key = why.split(" ")[0]
                stats["redraw_reasons"][key] = stats["redraw_reasons"].get(key, 0) + 1
                attempt += 1
                assert attempt < 50, "too many redraws"
            name = f"random_k{k}_{i:03d}_{policy}_{mode}_{constraints}"
            check_result(scene, res, constraints)
            cases.append(
                case_entry(name, scene, policy, mode, constraints, res, note=f"seed {seed}")
            )

    extremes = scenes.extreme_scenes()
    by_name: dict[str, dict[tuple[str, str, str], dict[str, Any]]] = {}
    for case in extremes:
        for policy, mode, constraints in case["runs"]:
            res = run_case(case, policy, mode, constraints)
            if (policy, mode, constraints) == ("F", "C", "paper"):
                check_extreme(case, res)
            check_result(case, res, constraints)
            by_name.setdefault(case["name"], {})[(policy, mode, constraints)] = res
            name = f"{case['name']}__{policy}_{mode}_{constraints}"
            cases.append(
                case_entry(name, case, policy, mode, constraints, res, note=case.get("note"))
            )
    for case in extremes:
        if "same_as" in case:
            for run, res in by_name[case["name"]].items():
                check_same(case["name"], res, by_name[case["same_as"]][run], case["same_as"])

    names = [c["name"] for c in cases]
    assert len(set(names)) == len(names), "duplicate case names"
    seen = {
        (c["policy"], c["mode"], c["constraints"]) for c in cases if c["name"].startswith("random_")
    }
    assert seen == set(COMBOS)

    data = {
        "generator": "tools/scripts/gen_known_answers.py (float64 reference "
        "tools/graspguide/core/reference.py: SVD + exhaustive active-set QP)",
        "generator_env": {"numpy": np.__version__, "scipy": _scipy_version()},
        "notes": NOTES,
        "tolerances": dict(ref.TOLERANCES),
        "cases": cases,
    }
    stats["seconds"] = time.perf_counter() - t0
    stats["cases"] = len(cases)
    return data, stats


def _scipy_version() -> str:
    import scipy

    return scipy.__version__


# --------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------
def render_json(data: dict[str, Any]) -> str:
    return json.dumps(data, indent=1, allow_nan=False) + "\n"


def _cdouble(x: Any) -> str:
    if x is None:
        return "NAN"
    v = dec_num(x)
    if math.isnan(v):
        return "NAN"
    if math.isinf(v):
        return "INFINITY" if v > 0 else "-INFINITY"
    s = "%.17g" % v
    if not any(ch in s for ch in ".en"):
        s += ".0"
    return s


def _cstr(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _carr(values: list[str]) -> str:
    return "{" + ", ".join(values) + "}"


def _pad(values: list[Any], n: int, fill: Any) -> list[Any]:
    values = list(values or [])
    return values + [fill] * (n - len(values))


def render_header(data: dict[str, Any]) -> str:
    out = [
        "// GENERATED by tools/scripts/gen_known_answers.py from the float64 reference",
        "// (tools/graspguide/core/reference.py). DO NOT EDIT: regenerate with",
        "//   python tools/scripts/gen_known_answers.py",
        '// Same cases as test/data/known_answers.json (see its "notes"). Unused entries',
        "// are zero; error_deg and margin are NAN where not applicable.",
        "#pragma once",
        "#include <cmath>",
        "namespace graspguide_test {",
        "struct KnownAnswer {",
        "  const char* name; int k;",
        "  double contacts[4][3]; double wrench[6]; double y_axis[3]; double orientation[4];",
        '  const char* policy;        // "F" or "Fperp"',
        '  const char* mode;          // "C" or "V"',
        "  const char* constraints;   // requested model",
        "  const char* status;        // expected status name",
        '  const char* constraints_used; // "" when status != ok',
        "  double lambda[12]; double levels[4]; int pwm[4]; int relevant[4];",
        "  double error_deg; int fallback_mask; double margin; "
        "// margin of the requested model, NAN if n/a",
        "};",
        "inline const KnownAnswer kKnownAnswers[] = {",
    ]
    for c in data["cases"]:
        e = c["expect"]
        contacts = _pad(
            [_carr([_cdouble(v) for v in row]) for row in c["contacts"]], 4, "{0.0, 0.0, 0.0}"
        )
        lam = _pad([_cdouble(v) for v in (e["lambda"] or [])], 12, "0.0")
        levels = _pad([_cdouble(v) for v in (e["levels"] or [])], 4, "0.0")
        pwm = _pad([str(int(v)) for v in e["pwm"]], 4, "0")
        relevant = _pad([str(int(bool(v))) for v in (e["relevant"] or [])], 4, "0")
        out.append("  {" + _cstr(c["name"]) + ", " + str(c["k"]) + ",")
        out.append("   " + _carr(contacts) + ",")
        out.append(
            "   "
            + _carr([_cdouble(v) for v in c["wrench"]])
            + ", "
            + _carr([_cdouble(v) for v in c["y_axis"]])
            + ", "
            + _carr([_cdouble(v) for v in c["orientation"]])
            + ","
        )
        out.append(
            "   "
            + ", ".join(_cstr(c[key]) for key in ("policy", "mode", "constraints"))
            + ", "
            + _cstr(e["status"])
            + ", "
            + _cstr(e["constraints_used"])
            + ","
        )
        out.append("   " + _carr(lam) + ",")
        out.append("   " + _carr(levels) + ", " + _carr(pwm) + ", " + _carr(relevant) + ",")
        out.append(
            "   "
            + _cdouble(e["error_deg"])
            + ", "
            + str(int(e["fallback_mask"]))
            + ", "
            + _cdouble(e["margin"])
            + "},"
        )
    out += [
        "};",
        f"inline constexpr int kKnownAnswerCount = {len(data['cases'])};",
        "}  // namespace graspguide_test",
        "",
    ]
    return "\n".join(out)


# --------------------------------------------------------------------------------------
# --check
# --------------------------------------------------------------------------------------
def _compare(a: Any, b: Any, path: str, diffs: list[str]) -> None:
    if len(diffs) >= 20:
        return
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            diffs.append(f"{path}: keys {sorted(set(a) ^ set(b))}")
            return
        for key in a:
            _compare(a[key], b[key], f"{path}.{key}", diffs)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            diffs.append(f"{path}: length {len(a)} != {len(b)}")
            return
        for i, (x, y) in enumerate(zip(a, b)):
            _compare(x, y, f"{path}[{i}]", diffs)
    elif (
        (isinstance(a, float) or isinstance(b, float))
        and not isinstance(a, (bool, str))
        and not isinstance(b, (bool, str))
        and a is not None
        and b is not None
    ):
        if abs(a - b) > FLOAT_TOL * max(1.0, abs(a), abs(b)):
            diffs.append(f"{path}: {a!r} != {b!r}")
    elif a != b or type(a) is not type(b):
        diffs.append(f"{path}: {a!r} != {b!r}")


def check(data: dict[str, Any], strict: bool) -> int:
    new_json = render_json(data)
    new_header = render_header(data)
    try:
        with open(JSON_PATH, encoding="utf-8") as fh:
            old_json = fh.read()
        with open(HEADER_PATH, encoding="utf-8") as fh:
            old_header = fh.read()
    except FileNotFoundError as exc:
        print(f"known answers missing: {exc.filename}", file=sys.stderr)
        return 1
    if old_json == new_json and old_header == new_header:
        print("known answers are up to date (byte-identical)")
        return 0
    if strict:
        print("known answers differ from the regenerated files (--strict)", file=sys.stderr)
        return 1
    old = json.loads(old_json)
    if old_header != render_header(old):
        print(
            "known_answers.h is not the rendering of known_answers.json "
            "(edited by hand?); regenerate",
            file=sys.stderr,
        )
        return 1
    diffs: list[str] = []
    _compare(
        {k: v for k, v in old.items() if k != "generator_env"},
        {k: v for k, v in data.items() if k != "generator_env"},
        "$",
        diffs,
    )
    if diffs:
        print(
            "known answers are stale; regenerate with "
            "`python tools/scripts/gen_known_answers.py`. First differences:",
            file=sys.stderr,
        )
        for d in diffs:
            print("  " + d, file=sys.stderr)
        return 1
    print(
        f"known answers are up to date (equal to within {FLOAT_TOL:g} relative; "
        "not byte-identical, e.g. another numpy/scipy build)"
    )
    return 0


def fallback_stats(count: int, seed: int = BASE_SEED + 1) -> None:
    """Print how often the paper model falls back, over `count` random scenes per k."""
    for k in (3, 4):
        total = 0.0
        fell = {"normal": 0, "none": 0}
        pure = [0, 0]  # [scenes, fell back] with zero moment
        slow = 0.0
        band = disagree = 0  # margin within [-2e-9, 1e-9]; margin contradicting enumeration
        borderline = 0  # the paper decision changes over FEAS_TOL_RANGE
        for sc in scenes.random_scenes(seed, k, count):
            t1 = time.perf_counter()
            res = run_case(sc, "F", "C", "paper")
            slow = max(slow, time.perf_counter() - t1)
            total += time.perf_counter() - t1
            assert res["status"] == "ok", (sc["name"], res["status"])
            used = res["constraints_used"]
            if used != "paper":
                fell[used] += 1
            t = res["margins"]["paper"]
            band += -2e-9 <= t <= 1e-9
            disagree += (t < -ref.kFeasRelTol - 1e-9) if used == "paper" else (t >= 1e-9)
            borderline += feasibility_depends_on_tol(sc, res, "paper")
            if not any(sc["wrench"][3:]):
                pure[0] += 1
                pure[1] += used != "paper"
        n_fell = fell["normal"] + fell["none"]
        print(
            f"k={k}: {count} scenes (F/C/paper): paper infeasible in {n_fell} "
            f"({100 * n_fell / count:.1f}%), fell to none in {fell['none']} "
            f"({100 * fell['none'] / count:.1f}%); pure-force scenes {pure[0]}, of which "
            f"{pure[1]} fell back ({100 * pure[1] / max(pure[0], 1):.1f}%); with moment "
            f"{count - pure[0]}, of which {n_fell - pure[1]} fell back "
            f"({100 * (n_fell - pure[1]) / max(count - pure[0], 1):.1f}%); "
            f"{1e3 * total / count:.1f} ms/scene mean, {1e3 * slow:.1f} ms max; paper margin "
            f"in [-2e-9, 1e-9] for {band}, contradicting the enumeration for {disagree}; "
            f"paper decision changes for kFeasRelTol in {FEAS_TOL_RANGE}: {borderline}"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--check",
        action="store_true",
        help="do not write; exit 1 if the checked-in files are stale",
    )
    ap.add_argument("--strict", action="store_true", help="with --check: byte-exact")
    ap.add_argument("-v", "--verbose", action="store_true")
    ap.add_argument(
        "--stats",
        type=int,
        metavar="N",
        help="only print fallback statistics over N random scenes per k",
    )
    args = ap.parse_args(argv)
    if args.stats:
        fallback_stats(args.stats)
        return 0

    data, stats = generate(verbose=args.verbose)
    if args.verbose or not args.check:
        reasons = ", ".join(f"{k}: {v}" for k, v in sorted(stats["redraw_reasons"].items()))
        print(
            f"{stats['cases']} cases in {stats['seconds']:.1f} s; "
            f"{stats['redrawn']} random draws redrawn ({reasons or 'none'})"
        )
    if args.check:
        return check(data, args.strict)
    os.makedirs(os.path.dirname(JSON_PATH), exist_ok=True)
    with open(JSON_PATH, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(render_json(data))
    with open(HEADER_PATH, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(render_header(data))
    print(f"wrote {os.path.relpath(JSON_PATH, _ROOT)} and {os.path.relpath(HEADER_PATH, _ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
