"""The pose rate the Pro Mini sustains: POSEs streamed at a fixed rate (not waiting for
their TELEMETRY, as a tracker streams) to the sketch under simavr, whose time is held to
real time; counts the TELEMETRYs that came back, the bytes simavr's UART dropped and the
bad frames the sketch's parser counted (bytes lost before the sketch read them).

    python tools/scripts/promini_pose_rate.py [--rates 40,60,80,100] [--seconds 3]

Needs the sketch built (python -m graspguide.promini.build). SIMULATED: cycle-exact AVR,
but the host's pacing is Python's."""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time

from graspguide.devices.promini_sim import ProMiniSimDevice, read_stats
from graspguide.link.client import DeviceClient, encode_pose_fast
from graspguide.link.messages import Telemetry

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.04], [-0.01, 0.1, 0.04]]
WRENCH = [0.4, -1.0, 0.3, 0.0, 0.0, 0.0]


def one_rate(rate_hz: float, seconds: float) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        stats = os.path.join(tmp, "stats.txt")
        with ProMiniSimDevice(stats=stats) as dev:
            c = DeviceClient(dev, timeout=2.0)
            c.hello(timeout=5.0)
            c.set_scene(HAND3, mode="V", timeout_s=600.0)
            c.start_trial(1, WRENCH)
            n = int(rate_hz * seconds)
            t0 = time.monotonic()
            for i in range(n):
                a = math.radians(60.0 - 30.0 * i / n)  # turning, never within 3 degrees
                q = (math.cos(a / 2), math.sin(a / 2), 0.0, 0.0)
                frame = encode_pose_fast(i & 0xFFFF, 1_000 + int(i * 1e6 / rate_hz), q)
                assert frame is not None
                c._write(frame)
                c._pump(0.0)
                wait = t0 + (i + 1) / rate_hz - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            c.drain(2.0)
            status = c.status(timeout=5.0)
            got = sum(1 for m in c.telemetry_backlog if isinstance(m, Telemetry))
        figures = read_stats(stats)
    return {
        "rate_hz": rate_hz,
        "sent": n,
        "answered": got,
        "dropped": figures["uart_bytes_dropped"],
        "bad_frames": status.bad_frames,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rates", default="40,60,70,80,100")
    p.add_argument("--seconds", type=float, default=3.0)
    args = p.parse_args()
    print("SIMULATED (simavr, real-time): POSE stream -> TELEMETRY")
    for r in [float(x) for x in args.rates.split(",")]:
        f = one_rate(r, args.seconds)
        print(
            f"  {f['rate_hz']:5.0f} poses/s: {f['answered']:4d} of {f['sent']:4d} answered, "
            f"{f['dropped']} UART bytes dropped in simavr, {f['bad_frames']} bad frames "
            "counted by the sketch's parser (frames that arrived damaged: bytes the AVR could not "
            "keep)"
        )


if __name__ == "__main__":
    main()
