"""Does the float core give the float64 reference's constraint model and PWM (within 1
count) on `paper` scenes? Measured on the host and on the Cortex-M4F under QEMU
(`graspguide bench agreement`), so that a before/after record can be taken on any commit;
tools/tests/core/test_float_paper_agreement.py checks the same scenes against the same
band.

The scenes are hand-like contacts (the project's nominal hand,
``scene_generators.nominal_contacts``, each coordinate moved by up to
``scene_generators.PERTURBATION_M``), a unit force in a uniform direction and no moment,
identity orientation, y_O = [0, 1, 0], k = 3 and 4 alternating, policy F and Fperp
alternating in pairs, mode C, constraints `paper`; plus the hard hands of
test/data/ (:func:`hard_scenes`, :func:`large_set_scenes`, :func:`retry_scenes`).

The modes of `graspguide bench agreement`:

* ``reference``: the float64 reference on the hard and N random scenes, saved (about
  10 ms a scene and job);
* ``host``: the float core this interpreter imports against a saved reference;
* ``layered``: the test's layered check (no saved reference) on many more scenes;
* ``m4f``: for each worktree, write the scenes (float-rounded, with the reference's status
  and PWM on those rounded inputs) into its src/harness/stage_counts/stage_scenes.h,
  `pio run -e m4f_stages` there, run the image on qemu-system-arm and count the agreement.
  It overwrites the worktrees' stage_scenes.h: give it worktrees (`git worktree add`),
  never the main checkout. The harness prints PWM and status, not the model, so on the
  M4F agreement is the status and PWM within 1 count.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from graspguide.bench import stage_scenes
from graspguide.core import reference, scene_generators
from graspguide.repo_root import find_repo_root

#: The hard hands' inputs, in the repository: "hard", "large_set" and "retry" (what each
#: list is: hard_scenes, large_set_scenes, retry_scenes); the native retry test reads the
#: "retry" list too.
HARD_HANDS_FILE = "test/data/hard_hands.json"
#: The names of the hard scenes in a scene set: hard_0, hard_1, ...
HARD_PREFIX = "hard_"

SEED = 17
POLICIES = ("F", "Fperp")
# The band: the float core may pick another model than float64 only on scenes
# whose x-fixed paper margin (reference.paper_margin_x_fixed, relative to ||lambda0||)
# is within this of 0. It is the float core's own feasibility tolerance,
# Tolerances<float>::kFeasRelTol (lib/graspguide/src/graspguide/tolerances.h): float
# accepts a violation up to this fraction of ||lambda0||, so a scene whose margin is
# smaller is feasible to float and infeasible to float64, or the reverse, by design.
# (Float's epsilon, 1.2e-7, times the internal forces of a paper optimum, which reach
# ~1000 ||lambda0||, is of the same order.)
FLOAT_BAND_TOL = 1e-4
# Beyond forces of this many ||lambda0|| the float QP's rounding floor, kRoundingRelTol
# (4 ulps) of ||lambda||, exceeds the whole load: float cannot hold the load apart from
# the forces at all. `layered` counts the disagreements there separately.
FLOAT_FORCE_LIMIT = 1 / 5e-7

_HANDS: dict[str, Any] | None = None


def _hands() -> dict[str, Any]:
    """The hard hands' inputs (HARD_HANDS_FILE of the repository), read once."""
    global _HANDS
    if _HANDS is None:
        root = find_repo_root()
        if root is None:
            raise FileNotFoundError(
                f"the hard hands are {HARD_HANDS_FILE} of the GraspGuide repository: run from it"
            )
        with open(Path(root) / HARD_HANDS_FILE, encoding="utf-8") as f:
            _HANDS = json.load(f)
    return _HANDS


def hard_scenes() -> list[dict[str, Any]]:
    """Eight requests (policy F or Fperp, mode C, constraints paper, no moment) on which a
    float core can choose another model than float64 though their x-fixed margins lie
    outside the band: the float core must agree on each."""
    return list(_hands()["hard"])


def large_set_scenes() -> list[dict[str, Any]]:
    """Hands that `layered` found on sets of one and two million scenes, kept as inputs
    because drawing those sets takes 7 s and 15 s; each equals named_scenes([name],
    set)[0]. p105005: a float solve that stops at a violation its kFeasRelTol allows is
    one dual step short of double's optimum (a motor off, not at 70). p317544: its x-fixed
    equalities keep a row 1.8e-6 long. p670098 and p044122: float64 proves `paper`
    infeasible by 1.1 and 2.2 times the band."""
    return list(_hands()["large_set"])


def retry_scenes() -> list[dict[str, Any]]:
    """Hands from a set of four million scenes that the float core's certificate sends to
    double (answer_certificate.h), one for each way float shows it cannot vouch for an
    answer; kept as inputs as above (drawing four million takes 30 s). p2204522: an
    infeasibility verdict within the rounding of a basis row 3.4e-3 long. p1453642: forces
    8.7e6 |lambda0| that miss equilibrium by 380 |lambda0| where float64 needs 1.2 in
    `normal`. p106034 and p2811766: a contradiction among the x-fixed equalities (float64
    holds `paper` with 8.9e6 and 7.7e5 |lambda0|). p2629315: a row left 0.48 of the
    dependence threshold long. p088019: forces 1.2e4 |lambda0|, 2 counts off. The
    MicroPython port has no double to retry in (docs/micropython.md)."""
    return list(_hands()["retry"])


def random_paper_scenes(count: int, seed: int = SEED) -> list[dict[str, Any]]:
    """`count` scenes of the measured kind (module docstring), drawn in one batch."""
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    rng = np.random.default_rng(seed)
    p = scene_generators.PERTURBATION_M
    offsets = rng.uniform(-p, p, (count, 4, 3))
    forces = rng.standard_normal((count, 3))
    forces /= np.linalg.norm(forces, axis=1, keepdims=True)
    nominal = {k: scene_generators.nominal_contacts(k) for k in (3, 4)}
    out = []
    for i in range(count):
        k = 3 + i % 2
        out.append(
            {
                "contacts": (nominal[k] + offsets[i, :k]).tolist(),
                "force": forces[i].tolist(),
                "policy": POLICIES[(i // 2) % 2],
            }
        )
    return out


def named_scenes(names: Sequence[str], drawn_from: int = 100_000) -> list[dict[str, Any]]:
    """Random scenes by their names in the set of `drawn_from` scenes (p000123: its 124th),
    for a measurement that needs a few scenes from far into a set (the M4F image holds only
    ~1,300). A name means something only with its set's size: the generator draws every
    offset, then every force, so the same index has another force in a set of another
    size. 100,000 is the test's set."""
    indexes = []
    for name in names:
        if not re.fullmatch(r"p\d{6,}", name):
            raise ValueError(f"scene name {name!r}: expected p followed by 6 digits, e.g. p049778")
        indexes.append(int(name[1:]))
        if indexes[-1] >= drawn_from:
            raise ValueError(f"scene {name} is not in a set of {drawn_from} scenes")
    drawn = random_paper_scenes(drawn_from) if indexes else []
    return [dict(drawn[i], name=f"p{i:06d}") for i in indexes]


def scene_set(count: int) -> list[dict[str, Any]]:
    """The hard scenes, then `count` random ones, each with its name."""
    named = [dict(s, name=f"{HARD_PREFIX}{i}") for i, s in enumerate(hard_scenes())]
    named += [dict(s, name=f"p{i:06d}") for i, s in enumerate(random_paper_scenes(count))]
    return named


def wrench(scene: dict[str, Any]) -> list[float]:
    return [*scene["force"], 0.0, 0.0, 0.0]


def as_float32(scene: dict[str, Any]) -> dict[str, Any]:
    """The scene as a float image reads it from its float literals."""
    f32 = lambda xs: np.asarray(xs, np.float32).astype(np.float64).tolist()  # noqa: E731
    return dict(scene, contacts=f32(scene["contacts"]), force=f32(scene["force"]))


def reference_solve(scene: dict[str, Any]) -> dict[str, Any]:
    """The float64 reference's full result on one scene."""
    return reference.solve(
        scene["contacts"], wrench(scene), scene["policy"], "C", "paper", compute_margins=False
    )


def answer_of(r: dict[str, Any]) -> tuple[str, str, list[int]]:
    """(status, model, pwm) of a reference result."""
    return r["status"], r["constraints_used"], list(r["pwm"])


def reference_answer(scene: dict[str, Any]) -> tuple[str, str, list[int]]:
    """(status, model, pwm) of the float64 reference on one scene."""
    return answer_of(reference_solve(scene))


def force_ratio(r: dict[str, Any]) -> float:
    """||lambda|| / ||lambda0|| of a reference result's optimum, in the model it used."""
    lam0 = np.asarray(r["diagnostics"]["lam0"], np.float64)
    return float(np.linalg.norm(r["lambda"]) / np.linalg.norm(lam0))


def x_fixed_margin(scene: dict[str, Any]) -> float:
    """reference.paper_margin_x_fixed of one scene (HiGHS: a few ms). Where that LP is
    infeasible (no force with x = 0 and any y/z holds equilibrium: the x-fixed equalities
    contradict the load), minus reference.x_fixed_equilibrium_gap, how far such a force
    must leave equilibrium with y/z >= 0: its continuation below zero, so a scene
    infeasible by 1e-6 |lambda0|, inside float's tolerance, counts as inside the band and
    not as far outside it."""
    C = np.asarray(scene["contacts"], np.float64)
    status, frames = reference.contact_frames(C, np.array([0.0, 1.0, 0.0]))
    if status != "ok" or frames is None:
        raise ValueError(f"scene {scene.get('name', '?')}: contacts refused ({status})")
    G = reference.grasp_matrix(frames)
    w_l = np.asarray(wrench(scene))
    lam0_norm = float(np.linalg.norm(reference.min_norm_solution(G, w_l)))
    try:
        return reference.paper_margin_x_fixed(G, w_l, lam0_norm)
    except RuntimeError as e:
        if "infeasible" not in str(e).lower():
            raise
        return -reference.x_fixed_equilibrium_gap(G, w_l, lam0_norm)


def core_result(scene: dict[str, Any], scalar: str) -> dict[str, Any]:
    """The full result of the core this interpreter imports (its default route)."""
    from graspguide.core import solver

    return solver.solve(
        scene["contacts"], wrench(scene), scene["policy"], "C", "paper", scalar=scalar
    )


def core_answer(scene: dict[str, Any], scalar: str) -> tuple[str, str, list[int]]:
    """(status, model, pwm) of the core this interpreter imports (its default route)."""
    r = core_result(scene, scalar)
    return r["status"], r["constraints_used"], list(r["pwm"])


def agrees(a: tuple[str, str, list[int]], b: tuple[str, str, list[int]]) -> bool:
    """Same status and model, every PWM within 1 count."""
    return a[0] == b[0] and a[1] == b[1] and max_pwm_diff(a[2], b[2]) <= 1


def max_pwm_diff(a: Sequence[int], b: Sequence[int]) -> int:
    if len(a) != len(b):
        raise ValueError(f"PWM lengths differ: {list(a)} against {list(b)}")
    return max(abs(int(x) - int(y)) for x, y in zip(a, b))


# ---------------------------------------------------------------------------- reference
def _ref_chunk(args: tuple[int, int, int, bool]) -> list[tuple[str, str, list[int]]]:
    count, start, stop, rounded = args
    scenes = scene_set(count)[start:stop]
    return [reference_answer(as_float32(s) if rounded else s) for s in scenes]


def reference_all(count: int, jobs: int, rounded: bool = False) -> list[tuple[str, str, list[int]]]:
    total = count + len(hard_scenes())
    step = max(1, min(2000, -(-total // max(1, jobs))))
    chunks = [(count, a, min(a + step, total), rounded) for a in range(0, total, step)]
    if jobs <= 1:
        return [r for c in chunks for r in _ref_chunk(c)]
    with ProcessPoolExecutor(jobs) as pool:
        return [r for part in pool.map(_ref_chunk, chunks) for r in part]


def save_reference(path: Path, count: int, answers: list[tuple[str, str, list[int]]]) -> None:
    pwm = np.full((len(answers), 4), -1, np.int16)
    for i, a in enumerate(answers):
        pwm[i, : len(a[2])] = a[2]
    np.savez_compressed(
        path,
        count=count,
        seed=SEED,
        status=np.array([a[0] for a in answers]),
        model=np.array([a[1] for a in answers]),
        pwm=pwm,
    )


def load_reference(path: Path) -> tuple[int, list[tuple[str, str, list[int]]]]:
    d = np.load(path)
    if int(d["seed"]) != SEED:
        raise ValueError(f"{path}: seed {int(d['seed'])}, this command draws with seed {SEED}")
    answers = [
        (str(s), str(m), [int(v) for v in p if v >= 0])
        for s, m, p in zip(d["status"], d["model"], d["pwm"])
    ]
    return int(d["count"]), answers


# ---------------------------------------------------------------------------------- host
def host(count: int, ref_answers: list[tuple[str, str, list[int]]]) -> dict[str, Any]:
    from graspguide.core import _core

    scenes = scene_set(count)
    if len(scenes) != len(ref_answers):
        raise ValueError(f"the reference has {len(ref_answers)} answers for {len(scenes)} scenes")
    bad = [
        i
        for i, (s, r) in enumerate(zip(scenes, ref_answers))
        if not agrees(core_answer(s, "float"), r)
    ]
    margins = {i: x_fixed_margin(scenes[i]) for i in bad}
    n8 = len(hard_scenes())
    return {
        "core": str(Path(_core.__file__).resolve()),
        "hard_scenes": n8,
        "hard_agree": n8 - sum(i < n8 for i in bad),
        "random_scenes": count,
        "random_agree": count - sum(i >= n8 for i in bad),
        "disagreements_outside_band": sum(
            i >= n8 and abs(margins[i]) > FLOAT_BAND_TOL for i in bad
        ),
        "disagreements": [
            {
                "name": scenes[i]["name"],
                "float": core_answer(scenes[i], "float"),
                "reference": ref_answers[i],
                "x_fixed_margin": margins[i],
            }
            for i in bad
        ],
    }


# ------------------------------------------------------------------------------ layered
def layered(count: int, sample_step: int = 0) -> dict[str, Any]:
    """The layered check on `count` random scenes (too many for the reference on each):
    the float and double cores on every scene, the float64 reference where they differ and
    on every `sample_step`-th scene (none when 0). A scene where the cores agree counts as
    agreeing with float64, as the sample and the known answers show the double core right.
    Indexes are into "scenes"; "margins" and "ratios" hold the x-fixed margin and the
    float64 optimum's force ratio of every scene where a core disagrees with float64 or
    the two cores choose another model; "retried" counts the float solves that retried
    in double (a core that reports no "retried" never does)."""
    scenes = scene_set(count)[len(hard_scenes()) :]
    floats, retried = [], 0
    for s in scenes:
        r = core_result(s, "float")
        floats.append((r["status"], r["constraints_used"], list(r["pwm"])))
        retried += bool(r.get("retried", False))
    doubles = [core_answer(s, "double") for s in scenes]
    differ = [i for i, (f, d) in enumerate(zip(floats, doubles)) if f != d]
    sample = range(0, count, sample_step) if sample_step > 0 else range(0)
    solved = {i: reference_solve(scenes[i]) for i in sorted(set(differ) | set(sample))}
    refs = {i: answer_of(r) for i, r in solved.items()}
    float_bad = [i for i in refs if not agrees(floats[i], refs[i])]
    double_bad = [i for i in refs if not agrees(doubles[i], refs[i])]
    other_model = [i for i in differ if floats[i][:2] != doubles[i][:2]]
    odd = set(float_bad + double_bad + other_model)
    margins = {i: x_fixed_margin(scenes[i]) for i in odd}
    ratios = {i: force_ratio(solved[i]) for i in odd}
    return {
        "scenes": scenes,
        "floats": floats,
        "doubles": doubles,
        "differ": differ,
        "refs": refs,
        "float_bad": float_bad,
        "double_bad": double_bad,
        "other_model": other_model,
        "margins": margins,
        "ratios": ratios,
        "retried": retried,
    }


# ----------------------------------------------------------------------------------- m4f
def _f32(x: float) -> float:
    return float(np.float32(x))


def render_header(scenes: list[dict[str, Any]], answers: list[tuple[str, str, list[int]]]) -> str:
    """stage_scenes.h in the StageScene layout both the before and the after harness read,
    written by the same code as the project's own scene set."""
    lines = [
        stage_scenes.scene_line(
            s["name"],
            len(s["contacts"]),
            [[_f32(v) for v in c] for c in s["contacts"]],
            [_f32(v) for v in wrench(s)],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
            s["policy"],
            "C",
            "paper",
            status,
            pwm,
        )
        for s, (status, _model, pwm) in zip(scenes, answers)
    ]
    note = ["GENERATED by `graspguide bench agreement m4f` for a measurement in a worktree."]
    return stage_scenes.header(lines, note)


def run_m4f(worktree: Path, header: str) -> list[str]:
    """Write the header into `worktree`, build m4f_stages there, run it under QEMU."""
    from graspguide.bench import targets

    dest = worktree / "src" / "harness" / "stage_counts" / "stage_scenes.h"
    if not dest.exists():
        raise FileNotFoundError(f"{dest} is missing: is {worktree} a GraspGuide worktree?")
    if (worktree / ".git").is_dir():
        raise ValueError(f"{worktree} is a main checkout: give a `git worktree add` folder")
    dest.write_text(header)
    env = dict(
        os.environ,
        PLATFORMIO_CORE_DIR=os.environ.get(
            "PLATFORMIO_CORE_DIR", str(Path(find_repo_root() or worktree) / ".pio-core")
        ),
        PLATFORMIO_DISABLE_UPGRADE_CHECK="true",
        PLATFORMIO_SETTING_ENABLE_TELEMETRY="No",
    )
    pio = str(Path(sys.executable).with_name("pio"))
    build = subprocess.run(
        ["flock", "/tmp/pio.lock", pio, "run", "-e", "m4f_stages"],
        cwd=worktree,
        env=env,
        capture_output=True,
        text=True,
    )
    if build.returncode != 0:
        tail = "\n".join((build.stdout + build.stderr).splitlines()[-30:])
        raise RuntimeError(f"`pio run -e m4f_stages` failed in {worktree}:\n{tail}")
    size = re.search(r"Flash:.*", build.stdout)
    print(f"{worktree}: built m4f_stages ({size.group(0) if size else 'size not printed'})")
    target = targets.TARGETS["m4f"]
    elf = worktree / ".pio" / "build" / target.env / "firmware.elf"
    cmd = targets.qemu_command("qemu-system-arm", target.machine, elf)
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    lines = p.stderr.splitlines()
    if p.returncode != 0 or not any(ln.startswith("END ") for ln in lines):
        raise RuntimeError(f"QEMU exited {p.returncode} in {worktree}: {lines[-5:]}")
    return lines


def m4f_agreement(lines: list[str], n_hard: int) -> dict[str, Any]:
    """Status equal and PWM within 1 count, read by the harness's COLUMNS names; also each
    scene's cold full frame in instructions ("cold", by name: what a retry in double
    costs) and the image's stack high-water mark in bytes ("stack")."""
    from graspguide.bench import targets

    columns = next(ln.split()[1:] for ln in lines if ln.startswith("COLUMNS "))
    col = {name: i for i, name in enumerate(columns)}
    out: dict[str, Any] = {"hard": [0, 0], "random": [0, 0], "failed": [], "cold": {}}
    out["stack"] = next((int(ln.split()[1]) for ln in lines if ln.startswith("STACK ")), None)
    for ln in lines:
        if not ln.startswith("S "):
            continue
        f = ln.split()[1:]
        k = int(f[col["k"]])
        pwm = [int(f[col[f"pwm{i}"]]) for i in range(k)]
        ref = [int(f[col[f"ref{i}"]]) for i in range(k)]
        ok = f[col["status"]] == f[col["ref_status"]] and max_pwm_diff(pwm, ref) <= 1
        group = "hard" if f[col["name"]].startswith(HARD_PREFIX) else "random"
        out["cold"][f[col["name"]]] = int(f[col["full_cold"]]) * targets.INSTRUCTIONS_PER_TICK
        out[group][0] += ok
        out[group][1] += 1
        if not ok:
            out["failed"].append(f"{f[col['name']]} float {pwm} reference {ref}")
    if out["hard"][1] != n_hard:
        raise ValueError(f"the harness printed {out['hard'][1]} of the {n_hard} hard scenes")
    return out


# ---------------------------------------------------------------------------- commands
def _elapsed(t0: float) -> str:
    return f"({time.perf_counter() - t0:.0f} s)"


def reference_command(*, count: int, jobs: int, out: str) -> int:
    """`graspguide bench agreement reference`: save the float64 reference's answers."""
    t0 = time.perf_counter()
    answers = reference_all(count, jobs)
    save_reference(Path(out), count, answers)
    print(f"wrote {out}: {len(answers)} scenes in {time.perf_counter() - t0:.0f} s")
    return 0


def layered_command(*, count: int) -> int:
    """`graspguide bench agreement layered`: the test's layered check on `count` scenes."""
    t0 = time.perf_counter()
    res = layered(count)
    margins = res["margins"]
    print(
        f"{count} random paper scenes: float and double cores differ on "
        f"{len(res['differ'])}; the float core retried {res['retried']} in double"
    )
    for key, what in (
        ("other_model", "float and double choose another status or model"),
        ("float_bad", "float disagrees with float64"),
        ("double_bad", "double disagrees with float64"),
    ):
        outside = [i for i in res[key] if abs(margins[i]) > FLOAT_BAND_TOL]
        beyond = [i for i in outside if res["ratios"][i] > FLOAT_FORCE_LIMIT]
        print(
            f"{what} on {len(res[key])}, {len(outside)} with |x-fixed margin| > "
            f"{FLOAT_BAND_TOL:g} ({len(beyond)} of them with forces above "
            f"{FLOAT_FORCE_LIMIT:.0e} |lambda0|)"
        )
    for i in res["float_bad"]:
        if abs(margins[i]) > FLOAT_BAND_TOL:
            print(
                f"  {res['scenes'][i]['name']}: float {res['floats'][i]} reference "
                f"{res['refs'][i]} margin {margins[i]:.3g} forces "
                f"{res['ratios'][i]:.3g} |lambda0|"
            )
    print(_elapsed(t0))
    return 0


def host_command(*, reference_path: str, json_path: str | None) -> int:
    """`graspguide bench agreement host`: the imported float core against a saved
    reference."""
    t0 = time.perf_counter()
    count, answers = load_reference(Path(reference_path))
    res = host(count, answers)
    print(f"core: {res['core']}")
    print(f"hard scenes: float agrees with float64 on {res['hard_agree']}/{res['hard_scenes']}")
    print(
        f"random paper scenes: float agrees with float64 on "
        f"{res['random_agree']}/{res['random_scenes']}; disagreements with "
        f"|x-fixed margin| > {FLOAT_BAND_TOL:g}: {res['disagreements_outside_band']}"
    )
    for d in res["disagreements"]:
        print(
            f"  {d['name']}: float {d['float']} reference {d['reference']} "
            f"margin {d['x_fixed_margin']:.3g}"
        )
    if json_path:
        Path(json_path).write_text(json.dumps(res, indent=1))
    print(_elapsed(t0))
    return 0


def m4f_command(
    *,
    worktrees: Sequence[str],
    count: int,
    jobs: int,
    scene_names: Sequence[str],
    scene_set_size: int,
    with_large_set: bool,
    with_retry: bool,
) -> int:
    """`graspguide bench agreement m4f`: the M4F image of each worktree under QEMU."""
    extra = [as_float32(s) for s in named_scenes(scene_names, scene_set_size)]
    if with_large_set:
        extra += [as_float32(s) for s in large_set_scenes()]
    if with_retry:
        extra += [as_float32(s) for s in retry_scenes()]
    scenes = [as_float32(s) for s in scene_set(count)] + extra
    answers = reference_all(count, jobs, rounded=True)
    answers += [reference_answer(s) for s in extra]
    header = render_header(scenes, answers)
    for wt in worktrees:
        res = m4f_agreement(run_m4f(Path(wt).resolve(), header), len(hard_scenes()))
        print(
            f"{wt}: M4F float agrees with float64 (status, PWM within 1) on "
            f"{res['hard'][0]}/{res['hard'][1]} hard scenes and "
            f"{res['random'][0]}/{res['random'][1]} random paper scenes"
            + (f" (with {len(extra)} named by --scene)" if extra else "")
        )
        for line in res["failed"]:
            print(f"  {line}")
        cold = res["cold"]
        named = {s["name"] for s in extra}
        drawn = sorted(
            v for name, v in cold.items() if re.fullmatch(r"p\d+", name) and name not in named
        )
        if drawn:
            print(
                f"  cold full frame, instructions: median {drawn[len(drawn) // 2]:,}, max "
                f"{drawn[-1]:,} over the {len(drawn)} random scenes; stack high-water "
                f"{res['stack']} bytes"
            )
        for s in extra:
            print(f"  {s['name']}: cold full frame {cold.get(s['name'], -1):,} instructions")
    return 0
