"""graspguide bench: the figures it reports are what it claims they are.

One quick in-process run (a few random hands plus the paper's hand scenes, k = 3 and 4,
every solver) is shared by the tests; they check the accounting against independent
recomputation, not just that keys exist.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import TOOLS_DIR

from graspguide.bench import host_bench as bench
from graspguide.core import reference
from graspguide.protocol.scene_file import load_scene

TOOLS_DIR = TOOLS_DIR


def subprocess_env() -> dict:
    """No PYTHONPATH: it could put tools/ (without the extension) before the package."""
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


OPTS = bench.Options(instances=3, seed=11, ks=(3, 4), quick=True, min_passes=1, max_passes=2)


@pytest.fixture(scope="module")
def run(core):
    insts, configs = bench.run_configs(OPTS)
    rep = bench.report(OPTS, insts, configs, elapsed_s=0.0)
    return insts, configs, rep


def _by_name(configs, name, k):
    return next(c for c in configs if c.name == name and c.k == k)


def test_instances_are_the_paper_hand_and_seeded_random_hands(run):
    insts, _, _ = run
    for k in (3, 4):
        # The paper scenes use the contacts of tools/examples/scene_paper_{k}.toml.
        scene = load_scene(os.path.join(TOOLS_DIR, "examples", f"scene_paper_{k}.toml"))
        paper = [i for i in insts if i.k == k and i.group == "paper"]
        assert len(paper) >= 2 * 26
        for inst in paper:
            np.testing.assert_allclose(inst.contacts, scene.contacts, rtol=0, atol=1e-15)
        rand = [i for i in insts if i.k == k and i.group == "random"]
        assert len(rand) == 2 * OPTS.instances
        # Same seed, same hands: the instance set is reproducible.
        again = bench.make_instances(OPTS.instances, OPTS.seed, (k,))
        assert [i.contacts for i in again if i.group == "random"] == [i.contacts for i in rand]
    # The QP data is the reference's: lambda0 + N xi_u is the reference's unconstrained
    # optimum, N is an orthonormal basis of null(G).
    for inst in (i for i in insts if i.ok):
        n = 3 * inst.k - 6
        np.testing.assert_allclose(inst.N.T @ inst.N, np.eye(n), atol=1e-12)
        np.testing.assert_allclose(inst.G @ inst.N, 0, atol=1e-12)
        assert np.linalg.norm(inst.G @ inst.lam0 + inst.w_l) <= 1e-12 * np.linalg.norm(inst.w_l)


def test_every_solution_satisfies_the_constraints_or_is_a_failure(run):
    insts, configs, rep = run
    checked = 0
    for cfg in configs:
        if cfg.outcomes is None:  # stage timings answer nothing
            continue
        tol = bench.VIOLATION_TOL[cfg.scalar]
        summary = next(r for r in rep["results"] if r["name"] == cfg.name and r["k"] == cfg.k)
        failed = {f["instance"] for f in summary["accuracy"]["failed"]}
        assert len(cfg.outcomes) == len(cfg.instances), cfg.name  # nothing dropped
        for inst, out in zip(cfg.instances, cfg.outcomes):
            if out.lam is None or not inst.ok:
                assert inst.name in failed or out.status == inst.ref["status"], cfg.name
                continue
            # Independent of bench.judge: the model the solver says it used, its rows.
            lam = np.asarray(out.lam, dtype=np.float64)
            S = reference.constrained_components(out.used, inst.k)
            worst = max(0.0, -float(lam[S].min())) if S else 0.0
            ok_constraints = worst <= tol * inst.lam0_norm
            assert ok_constraints or inst.name in failed, (cfg.name, inst.name, worst)
            if out.used != inst.ref["constraints_used"]:
                assert inst.name in failed, (cfg.name, inst.name, out.used)
            checked += 1
        assert summary["accuracy"]["failures"] == len(summary["accuracy"]["failed"])
    assert checked > 1000


def test_this_projects_pwm_equals_the_reference_on_the_paper_scenes(run):
    _, configs, _ = run
    names = [
        c.name
        for c in configs
        if c.k == 3
        and c.solver == "graspguide"
        and c.group in ("frame", "fixed", "py-call")
        and c.settings.get("max_iterations", 64) == 64
    ]
    # 2 scalars x 2 routes, 2 fixed-posture scalars, and the py-call configurations.
    assert len(names) >= 4 + 2 + 3
    for k in (3, 4):
        for name in names:
            cfg = _by_name(configs, name, k)
            for inst, out in zip(cfg.instances, cfg.outcomes):
                if inst.group != "paper":
                    continue
                assert out.status == inst.ref["status"] == "ok", (name, inst.name)
                diff = max(abs(a - b) for a, b in zip(out.pwm, inst.ref["pwm"]))
                assert diff <= 1, (name, inst.name, out.pwm, inst.ref["pwm"])


def test_report_has_the_documented_keys_and_finite_times(run, tmp_path):
    _, _, rep = run
    path = tmp_path / "bench.json"
    bench.write_json(rep, str(path))
    data = json.loads(path.read_text())  # strict JSON: write_json refuses NaN
    assert data["schema"] == bench.SCHEMA
    for key in ("settings", "machine", "instances", "results", "goal", "elapsed_s"):
        assert key in data
    groups = {r["group"] for r in data["results"]}
    assert groups == {"frame", "fixed", "stages", "py-call", "qp", "py-pipeline"}
    solvers = {r["solver"] for r in data["results"]}
    assert {"graspguide", "daqp", "quadprog", "osqp", "scipy-slsqp", "numpy+scipy"} <= solvers
    for r in data["results"]:
        assert set(r) >= {
            "name",
            "group",
            "solver",
            "k",
            "scalar",
            "settings",
            "timing",
            "accuracy",
        }
        for t in r["timing"].values():
            for key in (
                "median_ns",
                "p99_ns",
                "passes",
                "samples",
                "median_spread",
                "p99_spread",
                "stable",
            ):
                assert key in t, (r["name"], key)
            assert math.isfinite(t["median_ns"]) and 0 < t["median_ns"] <= t["p99_ns"]
            assert 1 <= t["passes"] <= OPTS.max_passes
        a = r["accuracy"]
        for key in (
            "instances",
            "failures",
            "failure_reasons",
            "failed",
            "pwm_mismatch",
            "max_pwm_diff",
            "max_violation_rel",
            "max_objective_gap_rel",
        ):
            assert key in a
    g = data["goal"]
    assert g["ratio"] == pytest.approx(g["frame_median_ns"] / g["daqp_solve_median_ns"])
    assert g["met"] == (g["ratio"] <= bench.GOAL_RATIO)
    assert "ratio" in bench.format_table(rep).split("goal")[1]


def _agrees(inst, out) -> bool:
    """Independent of bench.judge: the reference's status, and where it is ok the
    reference's model and a PWM within 1 count."""
    if out.status != inst.ref["status"]:
        return False
    if not inst.ok:
        return True
    diff = max(abs(a - b) for a, b in zip(out.pwm, inst.ref["pwm"]))
    return out.used == inst.ref["constraints_used"] and diff <= 1


def test_agreement_counts_the_answers_that_match_the_reference(run):
    _, configs, rep = run
    counted = 0
    for cfg in configs:
        if cfg.group not in ("frame", "fixed", "py-call"):
            continue
        summary = next(r for r in rep["results"] if r["name"] == cfg.name and r["k"] == cfg.k)
        a = summary["accuracy"]
        expected = sum(_agrees(i, o) for i, o in zip(cfg.instances, cfg.outcomes))
        assert a["agree"] == expected, cfg.name
        assert a["agree_share"] == pytest.approx(expected / len(cfg.instances))
        counted += 1
    assert counted >= 2 * (4 + 1 + 2 + 3)  # per k: 4 routes, max_it, 2 fixed, 3 py-call


def test_agreement_fails_a_pwm_two_counts_off_a_wrong_model_and_a_wrong_status(run):
    insts, _, _ = run
    inst = next(i for i in insts if i.ok and i.ref["constraints_used"] == "normal")
    lam = np.asarray(inst.ref["lambda"])
    pwm = list(inst.ref["pwm"])
    bumped = [pwm[0] + (1 if pwm[0] < 255 else -1)] + pwm[1:]
    far = [pwm[0] + (2 if pwm[0] < 254 else -2)] + pwm[1:]
    assert bench.judge(inst, bench.Outcome("ok", "normal", lam, bumped))["agree"]
    assert not bench.judge(inst, bench.Outcome("ok", "normal", lam, far))["agree"]
    assert not bench.judge(inst, bench.Outcome("ok", "none", lam, pwm))["agree"]
    assert not bench.judge(inst, bench.Outcome("qp_iteration_limit"))["agree"]
    # A scene the reference refuses: the same status agrees, an answer does not.
    refused = dataclasses.replace(inst, ref={**inst.ref, "status": "zero_force"})
    assert bench.judge(refused, bench.Outcome(refused.ref["status"]))["agree"]
    assert not bench.judge(refused, bench.Outcome("ok", "none", lam, pwm))["agree"]


def test_tradeoff_rows_are_each_frame_routes_time_beside_its_agreement(run):
    _, _, rep = run
    rows = rep["tradeoff"]
    assert [(r["k"], r["scalar"], r["decomposition"]) for r in rows] == [
        (k, s, d) for k in (3, 4) for s, d in bench.FRAME_ROUTES
    ]
    for row in rows:
        res = next(r for r in rep["results"] if r["name"] == row["config"] and r["k"] == row["k"])
        assert row["median_ns"] == res["timing"]["cxx"]["median_ns"]
        assert row["timing_set"]["agree"] == res["accuracy"]["agree"]
        assert row["accuracy_set"] is None  # none was asked for
    assert "cost against accuracy" in bench.format_table(rep)


def test_accuracy_set_is_more_hands_under_every_combination(core):
    opts = bench.Options(instances=3, seed=11, ks=(4,), accuracy_scenes=24)
    acc = bench.measure_accuracy_set(opts)
    assert bench.measure_accuracy_set(bench.Options(accuracy_scenes=0)) is None
    insts = bench.accuracy_instances(24, opts.seed, (4,))
    # Each of the 12 policy/mode/model combinations twice, on hands the timing never saw.
    combos = [(i.constraints, i.policy, i.mode) for i in insts]
    assert sorted(combos) == sorted(2 * list(bench.COMBINATIONS))
    timed = bench.make_instances(24, opts.seed, (4,))
    assert not {str(i.contacts) for i in insts} & {str(i.contacts) for i in timed}
    assert [(r["name"], r["k"]) for r in acc["results"]] == [
        (bench.frame_name(s, d), 4) for s, d in bench.FRAME_ROUTES
    ]
    for r in acc["results"]:
        a = r["accuracy"]
        assert a["instances"] == 24
        outs = [
            bench.binding_outcome(
                core.solve(
                    i.contacts,
                    i.wrench,
                    i.policy,
                    i.mode,
                    i.constraints,
                    i.orientation,
                    i.y_axis,
                    r["scalar"],
                    r["decomposition"],
                    core.kDefaultMaxIterations,
                )
            )
            for i in insts
        ]
        assert a["agree"] == sum(_agrees(i, o) for i, o in zip(insts, outs))
    rows = bench.tradeoff([], acc)
    assert rows == []  # no timed frame, no row: the table weighs time against accuracy


def test_daqp_internal_time_is_its_own_clock(run):
    _, configs, _ = run
    for k in (3, 4):
        t = _by_name(configs, "daqp", k).result()["timing"]
        # The internal solve time excludes the Python call around it, so it is smaller,
        # and setup + solve is at least the solve.
        assert t["internal"]["median_ns"] < t["py"]["median_ns"]
        assert t["internal_setup"]["median_ns"] >= t["internal"]["median_ns"]


def test_cxx_frames_recompute_the_grasp_every_frame(run):
    _, configs, _ = run
    for cfg in configs:
        if cfg.group == "frame":
            assert cfg.extra["recomputed_per_instance"] == [cfg.extra["frames_per_instance"]]
        if cfg.group == "fixed":
            assert cfg.extra["recomputed_per_instance"] == [0]


def test_osqp_problem_objects_are_created_once_and_reused(run):
    insts, configs, _ = run
    for k in (3, 4):
        cfg = _by_name(configs, "osqp", k)
        # One problem per shape (variables, rows): paper and normal models.
        assert cfg.extra["osqp_problems"] == sorted([[3 * k - 6, 3 * k], [3 * k - 6, k]])
        assert cfg.extra["osqp_setups"] == 2
        assert cfg.extra["osqp_updates"] >= len(cfg.instances)

    solver = bench.OsqpSolver()
    a, b = [i for i in insts if i.k == 4 and i.ok and i.constraints == "normal"][:2]
    first = solver.solve(a.xi_u, *a.qp["normal"])
    problem = solver.problems[(6, 4)]
    cold = solver.last_iterations
    second = solver.solve(b.xi_u, *b.qp["normal"])
    assert solver.problems[(6, 4)] is problem and solver.setups == 1 and solver.updates == 1
    # The updated problem is b's, not a's: same answer as a fresh object on b.
    fresh = bench.OsqpSolver().solve(b.xi_u, *b.qp["normal"])
    assert first[0] == second[0] == fresh[0] == "optimal"
    np.testing.assert_allclose(second[1], fresh[1], atol=1e-7)
    assert np.linalg.norm(second[1] - first[1]) > 1e-3
    # Warm start: solving b again starts at b's solution and needs fewer iterations.
    solver.solve(b.xi_u, *b.qp["normal"])
    assert solver.last_iterations < cold


def test_qp_tolerance_variant_is_the_core_solver_at_the_core_tolerance(run, core):
    insts, _, _ = run
    qps = [i for i in insts if i.ok][:40]
    args = bench._qp_args(qps)
    base = core.time_qp(*args, scalar="double", reps=1, batches=1, warmup=0)
    same = core.time_qp(
        *args,
        scalar="double",
        violation_rel=core.TOLERANCES["double"]["kFeasRelTol"],
        reps=1,
        batches=1,
        warmup=0,
    )
    assert base["lambda"] == same["lambda"]
    assert base["constraints_used"] == same["constraints_used"]


def test_noise_rule_repeats_noisy_series_and_keeps_every_pass():
    def steady(cfg):
        cfg.serie("x", "fake").add([50.0] * 10)

    medians = iter([100, 130, 100, 130, 100])  # pass medians 30 % apart: too noisy

    def noisy(cfg):
        cfg.serie("x", "fake").add([float(next(medians))] * 10)

    a = bench.Config("steady", "frame", "fake", 3, "double", {}, steady, [])
    b = bench.Config("noisy", "frame", "fake", 3, "double", {}, noisy, [])
    bench.run_passes([a, b], bench.Options(min_passes=3, max_passes=5))
    sa, sb = a.series["x"].summary(), b.series["x"].summary()
    assert sa["passes"] == 3 and sa["stable"]  # stops at the minimum
    assert sb["passes"] == 5 and not sb["stable"]  # repeated up to the cap
    assert sb["samples"] == 50  # every pass pooled, none dropped
    assert sb["pass_medians_ns"] == [100, 130, 100, 130, 100]
    assert sb["median_ns"] == 100 and sb["median_spread"] == pytest.approx(0.3)


def test_bad_options_are_clear_errors(core):
    env = subprocess_env()
    for argv, words in (
        (["--k", "5"], "invalid choice"),
        (["--solvers", "daqp,cplex"], "unknown solver 'cplex'"),
        (["--instances", "-1"], "between 0 and 100000"),
        (["--seed", "-3"], "--seed must be >= 0"),
        (["--max-passes", "0"], "--max-passes must be >= 1"),
        (["--accuracy-scenes", "-1"], "--accuracy-scenes must be between 0 and 100000"),
        (["--target", "m4f", "--accuracy-scenes", "5"], "--accuracy-scenes: host benchmark"),
    ):
        p = subprocess.run(
            [sys.executable, "-m", "graspguide", "bench", *argv],
            capture_output=True,
            text=True,
            env=env,
            timeout=60,
        )
        assert p.returncode == 2, (argv, p.stderr)
        assert words in p.stderr, (argv, p.stderr)
    with pytest.raises(ValueError, match="expected 9 \\(k=3\\) or 12"):
        core.time_qp([[0.0] * 5], [[0.0] * 5], [[0.0] * 5], ["paper"])
    with pytest.raises(ValueError, match="one per instance"):
        core.time_frames(([[[0, 0, 0]] * 3], [], [], [], [], [], []))
    for timer, lists in (
        (core.time_frames, [([],) * 7]),
        (core.time_stages, [([],) * 7]),
        (core.time_qp, [[]] * 4),
    ):
        with pytest.raises(ValueError, match="unknown scalar 'half'; accepted"):
            timer(*lists, scalar="half")


def test_cli_writes_json_and_prints_the_table(tmp_path):
    path = tmp_path / "b.json"
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "graspguide",
            "bench",
            "--quick",
            "--k",
            "3",
            "--instances",
            "1",
            "--solvers",
            "daqp",
            "--max-passes",
            "1",
            "--accuracy-scenes",
            "12",
            "--json",
            str(path),
        ],
        capture_output=True,
        text=True,
        env=subprocess_env(),
        timeout=120,
    )
    assert p.returncode == 0, p.stderr
    assert "frame double structured" in p.stdout and "daqp" in p.stdout
    data = json.loads(path.read_text())
    assert data["settings"]["k"] == [3] and data["goal"] is None  # the goal needs k=4
    assert "cost against accuracy" in p.stdout and "agree (12 more/k)" in p.stdout
    assert data["accuracy_set"]["scenes_per_k"] == 12
    assert {r["accuracy_set"]["instances"] for r in data["tradeoff"]} == {12}
    assert all(t["passes"] == 1 for r in data["results"] for t in r["timing"].values())
