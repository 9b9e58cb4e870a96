#!/usr/bin/env python3
"""Instructions per gravity-estimator update on the Cortex-M4F (docs/hostless.md): builds the
`m4f_imu` image (src/harness/imu_cost/) and runs it under QEMU mps2-an386 with
-icount shift=0, as `graspguide bench --target m4f` runs the stage counts. The image
times each of 2,000 updates alone (median and maximum, to one 40-instruction SysTick
tick) and the whole stream together (the mean, to the instruction), and checks that the
estimate ends within 3 degrees (the estimator's goal) of the stream's own gravity.

    python tools/scripts/imu_cost.py [--no-build] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from graspguide.bench import targets

ROOT = Path(__file__).resolve().parents[2]
IMAGE = targets.Target("m4f-imu", "cortex-m4f-imu", "m4f_imu", "mps2-an386")
MAX_FINAL_ERROR_DEG = 3.0  # the goal's max: the estimate must have tracked the stream, not only run


def parse(lines: list[str]) -> dict[str, float]:
    fields = {line.split()[0]: line.split()[1:] for line in lines if line.strip()}
    missing = [k for k in ("CAL", "IMU", "EACH", "TOTAL", "ERROR_MDEG") if k not in fields]
    if missing:
        raise targets.BadOutput(f"the imu_cost image printed no {', '.join(missing)} line")
    empty = targets._check_calibration(fields["CAL"], 1)
    samples = int(fields["IMU"][1])
    failed = int(fields["IMU"][3])
    if failed:
        raise targets.BadOutput(f"{failed} of {samples} updates were refused")
    per_tick = targets.INSTRUCTIONS_PER_TICK
    each = fields["EACH"]
    return {
        "samples": samples,
        "median": (int(each[1]) - empty) * per_tick,
        "max": (int(each[3]) - empty) * per_tick,
        "mean": (int(fields["TOTAL"][0]) - empty) * per_tick / samples,
        "final_error_deg": int(fields["ERROR_MDEG"][0]) / 1000.0,
        "stack_bytes": int(fields["STACK"][0]) if "STACK" in fields else -1,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-build", action="store_true", help="run the image as it is")
    ap.add_argument("--json", type=Path, help="also write the figures here")
    args = ap.parse_args()
    try:
        if not args.no_build:
            targets.build(ROOT, [IMAGE])
        r = parse(targets.run_image(ROOT, IMAGE))
    except targets.TargetError as e:
        print(f"imu_cost: {e}", file=sys.stderr)
        return 1
    print(
        f"cortex-m4f GravityEstimator<float>::update, {r['samples']} samples at 100 Hz, "
        f"90 deg/s: median {r['median']:.0f} / max {r['max']:.0f} instructions (to one "
        f"40-instruction tick), mean {r['mean']:.0f}; final error {r['final_error_deg']:.3f} deg"
    )
    if args.json:
        args.json.write_text(json.dumps(r, indent=2) + "\n")
    if not r["final_error_deg"] <= MAX_FINAL_ERROR_DEG:
        print(f"imu_cost: the estimate ended {r['final_error_deg']} deg off", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
