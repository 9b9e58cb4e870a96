#!/usr/bin/env python3
"""Print the gravity-estimation comparison (SIMULATED streams): the device's
estimator (lib/graspguide_cue/.../gravity_estimator.h through _core), VQF and x-io Fusion,
error RMS and max in degrees during guidance motion, per stream.

    python tools/scripts/imu_compare.py [--json FILE] [--seed N] [--duration-s S]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from graspguide.imu import compare, synthetic


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", type=Path, help="also write the figures to this file")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--duration-s", type=float, default=synthetic.DURATION_S)
    p.add_argument("--protocol", default="protocols/paper.toml")
    a = p.parse_args(argv)
    if not a.duration_s > synthetic.REST_S:
        p.error(f"--duration-s must exceed the {synthetic.REST_S:g} s rest, got {a.duration_s}")
    streams = synthetic.make_streams(a.protocol, a.seed, a.duration_s)
    result = compare.compare(streams)
    print(compare.format_table(result))
    if a.json:
        a.json.write_text(compare.to_json(result, streams) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
