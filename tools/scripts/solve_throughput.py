#!/usr/bin/env python3
"""How many request lines per second `graspguide solve` answers, on a seeded, realistic
mix of requests made with the project's scene generators.

    python tools/scripts/solve_throughput.py generate [--count N] [--seed S] [--bad-share F]
    python tools/scripts/solve_throughput.py time [--count N] [--repeat R] [--bad-share F]

``generate`` writes the requests (JSON Lines) to stdout: a before/after diff of
`graspguide solve`'s answers to them shows that a change kept the output byte for byte.
``time`` writes them to a temporary file and runs the `graspguide solve` command of the
active environment on it ``--repeat`` times (file in, file out, so the terminal is not
timed), and once on an empty input to take the interpreter's start-up out; it prints
lines/s with and without the start-up, and lines per CPU second of the command (less
disturbed by other load on a shared machine than the wall time).

The mix: hand-like scenes (``random_scenes``, k = 3 and 4) over every policy, mode and
constraint model, some with optional fields left out, integer zeros or millimetres; the
named edge cases (``extreme_scenes``); and a ``--bad-share`` of broken lines: NaN and
infinities, booleans, strings and nulls for numbers, missing and unknown fields, wrong
lengths, absurd magnitudes, hands and moments in the wrong unit, bad names and bad JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from graspguide.core import scene_generators as scenes

POLICIES = ("F", "Fperp")
MODES = ("C", "V")
MODELS = ("paper", "normal", "none")
FIELDS = ("contacts", "wrench", "orientation", "y_axis")


def _valid(rng: np.random.Generator, sc: dict) -> dict:
    """One well-formed request for a generated scene, in one of the forms users send."""
    req = {key: sc[key] for key in ("contacts", "wrench")}
    if rng.random() < 0.8:
        req["orientation"] = sc["orientation"]
    if rng.random() < 0.2:
        req["y_axis"] = [0, 1, 0]  # integers are numbers too
    for key, names in (("policy", POLICIES), ("mode", MODES), ("constraints", MODELS)):
        if rng.random() < 0.9:
            req[key] = names[int(rng.integers(len(names)))]
    form = rng.random()
    if form < 0.1:  # a pure force written as a person would: integer zeros
        req["wrench"] = [round(v, 3) for v in req["wrench"][:3]] + [0, 0, 0]
    elif form < 0.2:  # the same hand in millimetres (moments in N mm)
        req["units"] = "mm"
        req["contacts"] = [[v * 1000.0 for v in c] for c in req["contacts"]]
        req["wrench"] = req["wrench"][:3] + [v * 1000.0 for v in req["wrench"][3:]]
    return req


def _broken(rng: np.random.Generator, req: dict) -> str:
    """A request line with one fault, drawn from the faults users make."""
    req = json.loads(json.dumps(req))  # a deep copy
    field = FIELDS[int(rng.integers(len(FIELDS)))]
    if field not in req:
        req[field] = [1, 0, 0, 0] if field == "orientation" else [0, 1, 0]
    target = req[field]
    row = target[int(rng.integers(len(target)))] if field == "contacts" else target
    index = int(rng.integers(len(row)))
    kind = int(rng.integers(16))
    if kind == 0:
        row[index] = float("nan")
    elif kind == 1:
        row[index] = float(rng.choice([np.inf, -np.inf]))
    elif kind == 2:
        row[index] = bool(rng.random() < 0.5)
    elif kind == 3:
        row[index] = str(row[index])
    elif kind == 4:
        row[index] = None
    elif kind == 5:
        del row[index]
    elif kind == 6:
        row.append(0.0)
    elif kind == 7:
        row[index] = float(rng.choice([1e300, -1e300, 1e-300, 10.0 ** int(rng.integers(3, 30))]))
    elif kind == 8:
        req[field] = {"x": 1}
    elif kind == 9:
        del req[field if field in ("contacts", "wrench") else "contacts"]
    elif kind == 10:
        req["contsraints"] = "normal"
    elif kind == 11:
        key = ("policy", "mode", "constraints", "units")[int(rng.integers(4))]
        bad_names = ["f", "fperp", "c", "Paper", "soft", "cm", "", 1, None]
        req[key] = bad_names[int(rng.integers(len(bad_names)))]
    elif kind == 12:  # a hand in mm without "units": "mm"
        req["contacts"] = [[v * 1000.0 for v in c] for c in req["contacts"]]
    elif kind == 13:  # a moment in N mm with contacts in metres
        req["wrench"] = req["wrench"][:3] + [5.0, 0.0, -2.0]
    elif kind == 14:
        req["contacts"] = req["contacts"][: int(rng.integers(0, 3))] or [[1, 2]] * 3
    else:
        line = json.dumps(req, allow_nan=True)
        cut = int(rng.integers(1, len(line)))
        return str(rng.choice([line[:cut], line.replace('"', "'"), line + " {}", "[1, 2]", ""]))
    return json.dumps(req, allow_nan=True)


def requests(count: int, seed: int, bad_share: float) -> list[str]:
    """``count`` request lines, the same for the same arguments."""
    rng = np.random.default_rng([seed, 12])
    pool = scenes.random_scenes(seed, 3, 500) + scenes.random_scenes(seed, 4, 500)
    extremes = scenes.extreme_scenes()
    lines = []
    for _ in range(count):
        draw = rng.random()
        if draw < 0.05:
            sc = extremes[int(rng.integers(len(extremes)))]
            req = {key: sc[key] for key in FIELDS}
            req.update(policy="F", mode="C", constraints="paper", units="any")
            lines.append(json.dumps(req, allow_nan=True))
            continue
        req = _valid(rng, pool[int(rng.integers(len(pool)))])
        if draw < 0.05 + bad_share:
            lines.append(_broken(rng, req))
        else:
            lines.append(json.dumps(req, allow_nan=True))
    return lines


def _command() -> list[str]:
    exe = shutil.which("graspguide")
    if exe is None:
        sys.exit("solve_throughput: no graspguide command on PATH; activate the .venv")
    return [exe, "solve"]


def _children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run(path_in: str, path_out: str) -> tuple[float, float]:
    """Wall and CPU seconds of one run (the CPU time is less disturbed by other load)."""
    t0, c0 = time.perf_counter(), _children_cpu_s()
    subprocess.run([*_command(), "--input", path_in, "--output", path_out], check=True)
    return time.perf_counter() - t0, _children_cpu_s() - c0


def time_command(lines: list[str], repeat: int) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as d:
        src, empty, out = (os.path.join(d, n) for n in ("in.jsonl", "empty.jsonl", "out.jsonl"))
        with open(src, "w", encoding="ascii") as f:
            f.write("\n".join(lines) + "\n")
        open(empty, "w").close()
        runs, starts = [], []
        for _ in range(repeat):  # alternated, so a noisy moment hits both alike
            starts.append(_run(empty, out))
            runs.append(_run(src, out))
        with open(out, encoding="ascii") as f:
            answers = sum(1 for _ in f)
    wall, start = (statistics.median(r[0] for r in rs) for rs in (runs, starts))
    cpu, start_cpu = (statistics.median(r[1] for r in rs) for rs in (runs, starts))
    return {
        "lines": len(lines),
        "answers": answers,
        "wall_s": wall,
        "startup_s": start,
        "lines_per_s": len(lines) / wall,
        "lines_per_s_after_startup": len(lines) / (wall - start),
        "cpu_s": cpu,
        "lines_per_cpu_s_after_startup": len(lines) / (cpu - start_cpu),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("action", choices=("generate", "time"))
    p.add_argument("--count", type=int, default=50_000, help="request lines (default 50000)")
    p.add_argument("--seed", type=int, default=1, help="seed (default 1)")
    p.add_argument(
        "--bad-share", type=float, default=0.1, help="share of broken lines, 0..0.95 (default 0.1)"
    )
    p.add_argument("--repeat", type=int, default=5, help="timed runs, median taken (default 5)")
    a = p.parse_args()
    if not 0.0 <= a.bad_share <= 0.95:
        p.error(f"--bad-share must be between 0 and 0.95, got {a.bad_share}")
    if a.count < 1 or a.repeat < 1:
        p.error("--count and --repeat must be >= 1")
    lines = requests(a.count, a.seed, a.bad_share)
    if a.action == "generate":
        sys.stdout.write("\n".join(lines) + "\n")
        return 0
    r = time_command(lines, a.repeat)
    print(
        f"graspguide solve: {r['lines']} lines ({r['answers']} answers) in {r['wall_s']:.3f} s "
        f"(median of {a.repeat}): {r['lines_per_s']:,.0f} lines/s; start-up "
        f"{r['startup_s']:.3f} s, {r['lines_per_s_after_startup']:,.0f} lines/s after it; "
        f"{r['lines_per_cpu_s_after_startup']:,.0f} lines per CPU second after it"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
