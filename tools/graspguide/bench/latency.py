"""The latency self-test (`graspguide latency`): how late a device answers a POSE and, where
the device reports it, how late its motors follow.

One trial on a fixed 3-contact scene (the paper's hand; a per-frame board gets the posture
the host solves), then ``count`` POSEs, alternating between two hand orientations so that
every POSE changes the motors' duties (a change is what the device-side figures can see):

* **POSE -> TELEMETRY** round trip, every device kind: host clock
  (``time.perf_counter_ns``) from just before the POSE is encoded and written to the
  decoded TELEMETRY that answers it.
* **POSE -> PWM applied**, where the device reports it:

  - ``promini-sim``: exact, in the AVR's CPU cycles (8 MHz) -- from the UART receive
    interrupt for the POSE's closing byte to the last change of the motor channels that
    POSE caused (the simavr runner's ``--events``);
  - ``sim``: from the host's write of the POSE to the device's motor change, both on the
    machine's monotonic clock (the simulated device's ``--trace`` rows are stamped with
    CLOCK_MONOTONIC), 1 µs resolution: the pseudo-terminal's delivery included;
  - ``qemu`` and a serial board: not measured (no device-side clock the host can read
    per POSE); on ``qemu`` the motor registers are read once at the end and compared with
    the last TELEMETRY's PWM.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

# The paper's 3-contact hand and a wrench whose guidance keeps the motors on in both poses.
HAND3_M = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
WRENCH = [0.3, -1.2, -0.8, 0.0, 0.0, 0.0]
POSES = ([0.9394, 0.1125, 0.2250, -0.2312], [1.0, 0.0, 0.0, 0.0])
TRIAL_ID = 0x1A7
PERCENTILES = (50, 90, 99)
HISTOGRAM_BINS = 12
AVR_CPU_HZ = 8_000_000  # the Pro Mini's clock (src/harness/promini_sim/runner.c)
MIN_RATE_HZ = 10.0  # a POSE at least every 100 ms: inside the 200 ms watchdog
MAX_COUNT = 100_000


def summarize(samples_us: Sequence[float]) -> dict[str, Any]:
    """Percentiles, min/max/mean, a histogram (``HISTOGRAM_BINS`` equal bins from the
    minimum to the maximum) and the samples themselves, in the POSEs' order."""
    a = np.asarray(samples_us, dtype=float)
    if a.size == 0:
        raise ValueError("no samples to summarize")
    counts, edges = np.histogram(a, bins=HISTOGRAM_BINS)
    out: dict[str, Any] = {"n": int(a.size)}
    for p in PERCENTILES:
        out[f"p{p}_us"] = float(np.percentile(a, p))
    out.update(
        min_us=float(a.min()),
        max_us=float(a.max()),
        mean_us=float(a.mean()),
        histogram={"edges_us": [float(e) for e in edges], "counts": [int(c) for c in counts]},
        samples_us=[float(x) for x in a],
    )
    return out


def histogram_text(summary: dict[str, Any], width: int = 40) -> list[str]:
    """The histogram as text lines: ``  lo .. hi ms | #### count``."""
    edges = summary["histogram"]["edges_us"]
    counts = summary["histogram"]["counts"]
    top = max(counts) or 1
    lines = []
    for lo, hi, c in zip(edges, edges[1:], counts):
        bar = "#" * (math.ceil(width * c / top) if c else 0)
        lines.append(f"  {lo / 1e3:8.3f} .. {hi / 1e3:8.3f} ms | {bar} {c}")
    return lines


def percentile_line(summary: dict[str, Any]) -> str:
    ps = "  ".join(f"p{p} {summary[f'p{p}_us'] / 1e3:.3f}" for p in PERCENTILES)
    return f"{ps}  max {summary['max_us'] / 1e3:.3f} ms  (n={summary['n']})"


@dataclass
class PoseTiming:
    """One POSE: host monotonic time of its write (µs), its round trip (µs), the duties
    its TELEMETRY reported."""

    sent_monotonic_us: int
    rtt_us: float
    pwm: tuple[int, ...]


@dataclass
class LatencyResult:
    port: str
    board: str
    count: int
    rate_hz: float | None
    rtt: dict[str, Any]
    pwm: dict[str, Any] | None
    pwm_method: str
    pwm_not_measured: int = 0
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "port": self.port,
            "board": self.board,
            "count": self.count,
            "rate_hz": self.rate_hz,
            "pose_to_telemetry": self.rtt,
            "pose_to_pwm": self.pwm,
            "pose_to_pwm_method": self.pwm_method,
            "pose_to_pwm_unmatched": self.pwm_not_measured,
            "notes": self.notes,
        }


def pwm_latencies_cycles(
    frame_ends: Sequence[int], changes: Sequence[tuple[int, tuple[int, ...]]], poses: int
) -> list[int | None]:
    """The POSEs are the ``poses`` frames before the last one (the STOP that ended the
    test): for each, the cycles from its closing byte to the last motor change before the
    next frame's (None: that POSE changed nothing)."""
    if len(frame_ends) < poses + 1:
        raise ValueError(
            f"the runner saw {len(frame_ends)} frames, fewer than the {poses} POSEs and STOP sent"
        )
    ends = list(frame_ends)[-(poses + 1) :]
    out: list[int | None] = []
    for start, stop in zip(ends, ends[1:]):
        inside = [c for c, _ in changes if start <= c < stop]
        out.append(inside[-1] - start if inside else None)
    return out


def pwm_latencies_trace(
    timings: Sequence[PoseTiming], rows: Sequence[tuple[int, tuple[int, ...]]]
) -> list[float | None]:
    """For each POSE, µs from its host write to the first trace row (device monotonic µs,
    32 bits) after it that shows its TELEMETRY's duties (None: none before the next POSE)."""
    out: list[float | None] = []
    for i, t in enumerate(timings):
        start = t.sent_monotonic_us & 0xFFFFFFFF
        limit = (
            (timings[i + 1].sent_monotonic_us - t.sent_monotonic_us)
            if i + 1 < len(timings)
            else 10**6
        )
        found = None
        for stamp, duties in rows:
            dt = (stamp - start) & 0xFFFFFFFF  # the device's clock wraps at 2^32 µs
            if dt < limit and tuple(duties) == tuple(t.pwm):
                found = float(dt)
                break
        out.append(found)
    return out


def _read_trace(path: str) -> list[tuple[int, tuple[int, ...]]]:
    rows = []
    with open(path) as f:
        next(f, None)
        for line in f:
            parts = line.strip().split(",")
            if len(parts) == 5:
                rows.append((int(parts[0]), tuple(int(x) for x in parts[1:])))
    return rows


def _longest_trial_s() -> float:
    from graspguide.core._core import TRIAL_LIMITS  # type: ignore[import-untyped]

    return float(TRIAL_LIMITS["timeout_s"]["max"])


def _open_device(port: str, baud: int, workdir: str):
    """(transport, kind, device-side file): the transport with the device-side recorder
    the kind has."""
    from graspguide.devices import promini_sim, sim
    from graspguide.devices.registry import open_port

    if port == sim.SIM_PORT:
        trace = os.path.join(workdir, "motors.csv")
        return open_port(port, baudrate=baud, trace=trace), "sim", trace
    if port == promini_sim.PROMINI_SIM_PORT:
        events = os.path.join(workdir, "events.txt")
        return open_port(port, baudrate=baud, events=events), "promini-sim", events
    return open_port(port, baudrate=baud), port, None


def measure_latency(
    port: str,
    count: int,
    rate_hz: float | None = None,
    baud: int = 115200,
    timeout: float = 1.0,
    progress: Callable[[int], None] | None = None,
) -> LatencyResult:
    """Run the self-test on ``port`` (see the module's docstring); ``rate_hz``: POSEs a
    second (None: each as soon as the previous one is answered). STOP is sent on every way
    out. Raises LinkError, or ValueError naming a bad argument."""
    from graspguide.devices.promini_sim import read_events
    from graspguide.link.client import DeviceClient, host_time_us

    if not isinstance(count, int) or not 1 <= count <= MAX_COUNT:
        raise ValueError(f"count must be an integer in 1..{MAX_COUNT}, got {count!r}")
    if rate_hz is not None and not (math.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= 10_000):
        raise ValueError(
            f"rate_hz must be in [{MIN_RATE_HZ:g}, 10000] (a POSE at least every 100 ms, "
            f"inside the device's watchdog), got {rate_hz}"
        )
    with tempfile.TemporaryDirectory(prefix="graspguide-latency-") as workdir:
        transport, kind, recorder = _open_device(port, baud, workdir)
        timings: list[PoseTiming] = []
        try:
            client = DeviceClient(transport, timeout=timeout)
            board = client.hello().board
            # The longest trial the core allows: no POSE of the test meets its end.
            client.set_scene(
                HAND3_M, policy="F", mode="V", constraints="paper", timeout_s=_longest_trial_s()
            )
            client.start_trial(TRIAL_ID, WRENCH)
            period_ns = None if rate_hz is None else int(1e9 / rate_hz)
            next_ns = time.perf_counter_ns()
            for i in range(count):
                if period_ns is not None:
                    wait_ns = next_ns - time.perf_counter_ns()
                    if wait_ns > 0:
                        time.sleep(wait_ns / 1e9)
                    next_ns += period_ns
                sent_us = time.monotonic_ns() // 1000
                t0 = time.perf_counter_ns()
                tel = client.pose(host_time_us(), POSES[i % 2])
                t1 = time.perf_counter_ns()
                timings.append(PoseTiming(sent_us, (t1 - t0) / 1e3, tuple(tel.pwm)))
                if progress is not None:
                    progress(i + 1)
            registers = None
            firmware = getattr(transport, "firmware", None)
            if firmware is not None:
                registers = tuple(firmware.motor_registers())
            client.stop()
        finally:
            transport.close()

        rtt = summarize([t.rtt_us for t in timings])
        notes: list[str] = []
        pwm_samples: list[float | None]
        if kind == "promini-sim" and recorder:
            frame_ends, changes = read_events(recorder)
            cycles = pwm_latencies_cycles(frame_ends, changes, count)
            pwm_samples = [None if c is None else c * 1e6 / AVR_CPU_HZ for c in cycles]
            method = (
                "device-side, exact: AVR cycles (8 MHz) from the UART receive interrupt for "
                "the POSE's closing byte to the last motor-channel change it caused (simavr)"
            )
        elif kind == "sim" and recorder:
            pwm_samples = list(pwm_latencies_trace(timings, _read_trace(recorder)))
            method = (
                "host write of the POSE -> the simulated device's motor change, both on "
                "CLOCK_MONOTONIC (its --trace), 1 us resolution, pty delivery included"
            )
        else:
            pwm_samples = []
            method = "not measured: this device kind has no per-POSE motor timestamps"
            if registers is not None:
                same = registers == timings[-1].pwm
                notes.append(
                    f"motor registers read through QMP before STOP: {registers}, "
                    f"{'equal to' if same else 'DIFFERENT from'} the last TELEMETRY's PWM "
                    f"{timings[-1].pwm}"
                )
        measured = [s for s in pwm_samples if s is not None]
        return LatencyResult(
            port=port,
            board=board,
            count=count,
            rate_hz=rate_hz,
            rtt=rtt,
            pwm=summarize(measured) if measured else None,
            pwm_method=method,
            pwm_not_measured=len(pwm_samples) - len(measured),
            notes=notes,
        )


def report_lines(result: LatencyResult) -> list[str]:
    """The text report: both figures' percentiles and histograms."""
    pace = "back to back" if result.rate_hz is None else f"{result.rate_hz:g} Hz"
    lines = [
        f"latency self-test on {result.port} (board {result.board}): {result.count} POSEs, {pace}",
        "",
        "POSE -> TELEMETRY round trip (host clock):",
        "  " + percentile_line(result.rtt),
        *histogram_text(result.rtt),
        "",
        "POSE -> PWM applied: " + result.pwm_method,
    ]
    if result.pwm is not None:
        lines.append("  " + percentile_line(result.pwm))
        lines.extend(histogram_text(result.pwm))
        if result.pwm_not_measured:
            lines.append(f"  ({result.pwm_not_measured} POSEs without a motor change to time)")
    lines.extend("note: " + n for n in result.notes)
    return lines


__all__ = [
    "LatencyResult",
    "measure_latency",
    "summarize",
    "histogram_text",
    "report_lines",
    "pwm_latencies_cycles",
    "pwm_latencies_trace",
]
