#!/usr/bin/env python3
"""Instruction counts of Algorithm 1 per stage on Cortex-M4F and Cortex-M7, under QEMU.

Runs the stage images (src/harness/stage_counts/, built by `pio run -e m4f_stages -e m7_stages`) on
qemu-system-arm with -icount shift=0 and semihosting, reads one line per scene, and
reports for k = 3 and 4 the median and maximum instructions of each stage (contact
frames, grasp matrix, decomposition, QP, motor mapping) and of whole frames (cold, warm,
SVD route, fixed posture), over the scenes the solver accepts; plus the agreement of the
target's float PWM with the float64 reference, and the stack high-water mark.

Counts are deterministic, so a checked-in baseline (tools/perf/stage_baseline.json) is
compared exactly: any median or maximum more than 10 % above it fails.

    python tools/scripts/qemu_stages.py                 # run, print, compare (exit 1 on regression)
    python tools/scripts/qemu_stages.py --json out.json # also write every figure
    python tools/scripts/qemu_stages.py --update-baseline
"""

from __future__ import annotations

import argparse
import json
import pathlib
import shutil
import statistics
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
BASELINE = ROOT / "tools" / "perf" / "stage_baseline.json"
# name -> (pio env, QEMU machine)
TARGETS = {"cortex-m4f": ("m4f_stages", "mps2-an386"), "cortex-m7": ("m7_stages", "mps2-an500")}
STAGES = [
    "frames",
    "grasp",
    "decomposition",
    "qp",
    "mapping",
    "full_cold",
    "full_warm",
    "full_svd",
    "fixed",
]
TOLERANCE = 0.10
# The float core refuses these far-offset hands as imprecise where float64 still solves
# them (docs/algorithm.md): a documented refusal, not a disagreement.
FLOAT_ONLY_REFUSALS = {"imprecise_contacts"}
INSTRUCTIONS_PER_TICK = 40  # 1 GHz virtual clock (-icount shift=0) / 25 MHz SysTick


class StageError(RuntimeError):
    pass


def run_image(elf: pathlib.Path, machine: str, timeout_s: float = 300.0) -> list[str]:
    if not elf.exists():
        raise StageError(f"{elf} is missing: build it with `pio run -e {elf.parent.name}`")
    qemu = shutil.which("qemu-system-arm")
    if qemu is None:
        raise StageError("qemu-system-arm is not installed: run tools/install-arm.sh")
    cmd = [
        qemu,
        "-M",
        machine,
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
        "-icount",
        "shift=0",
        "-kernel",
        str(elf),
    ]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    # QEMU writes semihosting output (SYS_WRITE0) to its stderr.
    lines = [line for line in p.stderr.splitlines() if line]
    if p.returncode != 0 or not lines or not lines[-1].startswith("END "):
        tail = "\n".join((lines + p.stdout.splitlines())[-5:])
        raise StageError(f"{elf.name} on {machine} exited {p.returncode}:\n{tail}")
    return lines


def parse(lines: list[str]) -> dict[str, object]:
    cal = next(line for line in lines if line.startswith("CAL ")).split()[1:]
    empty, loop_a, loop_b = (int(x) for x in cal)
    # Two loops of 200,000 and 600,000 instructions: their difference is free of call cost.
    per_tick = 400000 / (loop_b - loop_a)
    if abs(per_tick - INSTRUCTIONS_PER_TICK) > 0.5:
        raise StageError(
            f"calibration: {per_tick:.2f} instructions per SysTick tick, "
            f"expected {INSTRUCTIONS_PER_TICK} (is -icount shift=0 set?)"
        )
    columns = next(line for line in lines if line.startswith("COLUMNS ")).split()[1:]
    rows = []
    for line in lines:
        if not line.startswith("S "):
            continue
        v = dict(zip(columns, line.split()[1:]))
        rows.append(v)
    stack = int(next(line for line in lines if line.startswith("STACK ")).split()[1])
    return {"empty_ticks": empty, "rows": rows, "stack_bytes": stack}


def summarize(parsed: dict[str, object]) -> dict[str, object]:
    rows = parsed["rows"]
    out: dict[str, object] = {"scenes": len(rows), "stack_high_water_bytes": parsed["stack_bytes"]}
    for k in ("3", "4"):
        ok = [r for r in rows if r["k"] == k and r["status"] == "ok"]
        per_k: dict[str, object] = {"scenes": sum(r["k"] == k for r in rows), "accepted": len(ok)}
        for stage in STAGES:
            vals = [int(r[stage]) * INSTRUCTIONS_PER_TICK for r in ok if int(r[stage]) >= 0]
            per_k[stage] = {
                "median": int(statistics.median(vals)),
                "max": max(vals),
                "n": len(vals),
            }
        worst = max(ok, key=lambda r: int(r["full_cold"]))
        per_k["slowest_scene"] = worst["name"]
        out[f"k{k}"] = per_k
    agree = within1 = compared = 0
    status_same = refused_float_only = status_differ = 0
    differ: list[str] = []
    for r in rows:
        if r["status"] == r["ref_status"]:
            status_same += 1
        elif r["status"] in FLOAT_ONLY_REFUSALS and r["ref_status"] == "ok":
            refused_float_only += 1
        else:
            status_differ += 1
            differ.append(f"{r['name']}: {r['status']} vs reference {r['ref_status']}")
        if r["status"] == "ok" and r["ref_status"] == "ok":
            d = max(abs(int(r[f"pwm{i}"]) - int(r[f"ref{i}"])) for i in range(4))
            compared += 1
            agree += d == 0
            within1 += d <= 1
    out["pwm_vs_float64"] = {
        "compared": compared,
        "exact": agree,
        "within_1": within1,
        "within_1_share": within1 / compared if compared else None,
    }
    out["status_vs_float64"] = {
        "same": status_same,
        "float_only_refusals": refused_float_only,
        "different": status_differ,
        "differences": differ,
    }
    return out


def compare(current: dict[str, object], baseline: dict[str, object]) -> list[str]:
    grown = []
    for target, base in baseline.items():
        cur = current.get(target)
        if cur is None:
            continue
        for k in ("k3", "k4"):
            for stage in STAGES:
                for stat in ("median", "max"):
                    b = base[k][stage][stat]
                    c = cur[k][stage][stat]
                    # A stage's count is read off a SysTick that ticks every 40
                    # instructions, at a phase that any code change before it moves: one
                    # tick more is the counter's resolution, not growth (grasp k3 is 5 ticks).
                    if c > max(b * (1 + TOLERANCE), b + INSTRUCTIONS_PER_TICK):
                        grown.append(
                            f"{target} {k} {stage} {stat}: {c} instructions, "
                            f"baseline {b} (+{100 * (c / b - 1):.1f} %)"
                        )
    return grown


def print_table(results: dict[str, dict[str, object]], out=sys.stdout) -> None:
    for target, r in results.items():
        print(
            f"== {target}: instructions per stage (median / max over accepted scenes), "
            f"{r['scenes']} scenes, stack high-water {r['stack_high_water_bytes']} B",
            file=out,
        )
        print(
            f"{'stage':<15}{'k=3 median':>12}{'k=3 max':>10}{'k=4 median':>12}{'k=4 max':>10}",
            file=out,
        )
        for stage in STAGES:
            a, b = r["k3"][stage], r["k4"][stage]
            print(
                f"{stage:<15}{a['median']:>12,}{a['max']:>10,}{b['median']:>12,}{b['max']:>10,}",
                file=out,
            )
        p, s = r["pwm_vs_float64"], r["status_vs_float64"]
        print(
            f"float PWM vs float64 reference: {p['within_1']}/{p['compared']} within 1 count "
            f"({p['exact']} exact); status: {s['same']} same, {s['float_only_refusals']} "
            f"float-only refusals, {s['different']} different",
            file=out,
        )
        for d in s["differences"]:
            print(f"  differs: {d}", file=out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", metavar="FILE", help="write every figure to FILE")
    ap.add_argument("--raw", metavar="DIR", help="keep each target's raw output lines in DIR")
    ap.add_argument(
        "--update-baseline",
        action="store_true",
        help=f"write the figures as the new baseline ({BASELINE.relative_to(ROOT)})",
    )
    ap.add_argument(
        "--target",
        choices=sorted(TARGETS),
        action="append",
        help="only this target (repeatable); default all",
    )
    args = ap.parse_args()
    results: dict[str, dict[str, object]] = {}
    try:
        for target in args.target or sorted(TARGETS):
            env, machine = TARGETS[target]
            lines = run_image(ROOT / ".pio" / "build" / env / "firmware.elf", machine)
            if args.raw:
                pathlib.Path(args.raw).mkdir(parents=True, exist_ok=True)
                (pathlib.Path(args.raw) / f"{target}.txt").write_text("\n".join(lines) + "\n")
            results[target] = summarize(parse(lines))
    except (StageError, subprocess.TimeoutExpired) as e:
        print(f"qemu_stages: {e}", file=sys.stderr)
        return 2
    print_table(results)
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(results, indent=2) + "\n")
    slim = {
        t: {
            k: {s: {"median": r[k][s]["median"], "max": r[k][s]["max"]} for s in STAGES}
            for k in ("k3", "k4")
        }
        for t, r in results.items()
    }
    if args.update_baseline:
        BASELINE.write_text(json.dumps(slim, indent=2, sort_keys=True) + "\n")
        print(f"baseline written: {BASELINE.relative_to(ROOT)}")
        return 0
    if not BASELINE.exists():
        print(
            f"no baseline yet ({BASELINE.relative_to(ROOT)}): run with --update-baseline",
            file=sys.stderr,
        )
        return 1
    grown = compare(slim, json.loads(BASELINE.read_text()))
    bad_status = [t for t, r in results.items() if r["status_vs_float64"]["different"]]
    for g in grown:
        print(f"REGRESSION {g}")
    for t in bad_status:
        print(f"FAIL {t}: statuses differ from the float64 reference (listed above)")
    print(
        f"baseline check: {'FAILED' if grown or bad_status else 'ok'} "
        f"(tolerance +{int(TOLERANCE * 100)} % per stage, at least one {INSTRUCTIONS_PER_TICK}-"
        "instruction tick, median and max)"
    )
    return 1 if grown or bad_status else 0


if __name__ == "__main__":
    sys.exit(main())
