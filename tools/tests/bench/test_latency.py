"""`graspguide latency`: the figures' summaries, the matching of device-side events to
POSEs, and the command on the simulated device, the Pro Mini under simavr and the QEMU
firmware (each run's percentiles ordered and positive, its histogram holding every POSE,
the device-side POSE -> PWM figure where the device kind reports it)."""

from __future__ import annotations

import json
import random
import subprocess
import sys

import numpy as np
import pytest
from conftest import subprocess_env

from graspguide.bench.latency import (
    HISTOGRAM_BINS,
    PoseTiming,
    histogram_text,
    pwm_latencies_cycles,
    pwm_latencies_trace,
    summarize,
)
from graspguide.devices.promini_sim import PROMINI_ELF_ENV

CLI = [sys.executable, "-m", "graspguide"]


def test_summary_percentiles_are_numpys_and_the_histogram_holds_every_sample():
    rng = random.Random(16)
    samples = [rng.lognormvariate(6, 0.7) for _ in range(997)]
    s = summarize(samples)
    for p in (50, 90, 99):
        assert s[f"p{p}_us"] == pytest.approx(float(np.percentile(samples, p)))
    assert s["min_us"] <= s["p50_us"] <= s["p90_us"] <= s["p99_us"] <= s["max_us"]
    assert sum(s["histogram"]["counts"]) == len(samples) == s["n"]
    assert len(s["histogram"]["counts"]) == HISTOGRAM_BINS
    assert s["histogram"]["edges_us"][0] == min(samples)
    assert s["histogram"]["edges_us"][-1] == max(samples)
    lines = histogram_text(s)
    assert len(lines) == HISTOGRAM_BINS
    assert sum(int(line.rsplit(" ", 1)[1]) for line in lines) == len(samples)


def test_summary_refuses_no_samples():
    with pytest.raises(ValueError, match="no samples"):
        summarize([])


def test_cycles_pair_each_pose_with_the_last_change_before_the_next_frame():
    rng = random.Random(3)
    setup_ends = [100, 900]  # HELLO, START_TRIAL: not POSEs
    ends, changes, expected = list(setup_ends), [(950, (1, 0, 0, 0))], []
    t = 2000
    for i in range(20):
        ends.append(t)
        if i == 7:
            expected.append(None)  # a POSE that changed nothing
        else:
            offsets = sorted(rng.sample(range(1, 5000), 3))
            changes += [(t + o, (i, i, i, 0)) for o in offsets]
            expected.append(offsets[-1])
        t += 6000
    ends.append(t)  # STOP
    changes.append((t + 10, (0, 0, 0, 0)))  # STOP's motors off: not a POSE's
    assert pwm_latencies_cycles(ends, changes, 20) == expected
    with pytest.raises(ValueError, match="fewer than"):
        pwm_latencies_cycles(ends[:5], changes, 20)


def test_trace_rows_are_matched_by_duties_across_the_32_bit_wrap():
    base = 2**32 - 150  # the device's µs counter wraps between the POSEs
    timings = [
        PoseTiming(base, 90.0, (5, 6, 7, 0)),
        PoseTiming(base + 100, 80.0, (8, 9, 10, 0)),
        PoseTiming(base + 200, 70.0, (8, 9, 10, 0)),  # no change: nothing to time
    ]
    rows = [
        ((base - 40) & 0xFFFFFFFF, (8, 9, 10, 0)),  # before every POSE: not an answer
        ((base + 30) & 0xFFFFFFFF, (5, 6, 7, 0)),
        ((base + 160) & 0xFFFFFFFF, (8, 9, 10, 0)),
    ]
    assert pwm_latencies_trace(timings, rows) == [30.0, 60.0, None]


def _latency(port: str, tmp_path, count: int, *extra: str, elf: str | None = None) -> dict:
    out = tmp_path / f"{port}.json"
    env = subprocess_env()
    if elf is not None:
        env[PROMINI_ELF_ENV] = elf
    done = subprocess.run(
        CLI + ["latency", "--port", port, "--count", str(count), "--json", str(out), *extra],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert "POSE -> TELEMETRY" in done.stdout and "p99" in done.stdout
    return json.loads(out.read_text())


def _check_summary(s: dict, n: int) -> None:
    assert s["n"] == n == len(s["samples_us"])
    assert 0 < s["min_us"] <= s["p50_us"] <= s["p90_us"] <= s["p99_us"] <= s["max_us"]
    assert sum(s["histogram"]["counts"]) == n
    assert s["histogram"]["edges_us"] == sorted(s["histogram"]["edges_us"])


def test_latency_on_sim(tmp_path, report_figure):
    r = _latency("sim", tmp_path, 100)
    _check_summary(r["pose_to_telemetry"], 100)
    # Every POSE alternates the hand's orientation, so each changes the motors.
    _check_summary(r["pose_to_pwm"], 100)
    assert r["pose_to_pwm_unmatched"] == 0
    # The motors change before the answer is back: each POSE's PWM within its round trip.
    for pwm_us, rtt_us in zip(r["pose_to_pwm"]["samples_us"], r["pose_to_telemetry"]["samples_us"]):
        assert pwm_us <= rtt_us + 2  # the 1 us trace stamps
    report_figure("latency sim: POSE->TELEMETRY p50", f"{r['pose_to_telemetry']['p50_us']:.0f} us")


def test_latency_on_promini_sim(tmp_path, report_figure, sketch_elf):
    r = _latency("promini-sim", tmp_path, 60, elf=sketch_elf)
    _check_summary(r["pose_to_telemetry"], 60)
    _check_summary(r["pose_to_pwm"], 60)
    assert "AVR cycles" in r["pose_to_pwm_method"]
    # Device-side, from the POSE's last byte: shorter than the host's round trip, which also
    # carries the POSE's and the TELEMETRY's bytes at 115200 baud.
    for pwm_us, rtt_us in zip(r["pose_to_pwm"]["samples_us"], r["pose_to_telemetry"]["samples_us"]):
        assert pwm_us < rtt_us
    report_figure("latency promini-sim: POSE->PWM p50", f"{r['pose_to_pwm']['p50_us']:.0f} us")


def test_latency_on_qemu(tmp_path):
    from graspguide.devices import qemu_firmware
    from graspguide.link.transport import DeviceNotFound

    try:
        qemu_firmware.find_qemu()
        qemu_firmware.find_firmware_elf()
    except DeviceNotFound as e:
        pytest.skip(f"QEMU firmware test: {e}")
    r = _latency("qemu", tmp_path, 50, "--rate-hz", "100")
    _check_summary(r["pose_to_telemetry"], 50)
    assert r["pose_to_pwm"] is None and r["pose_to_pwm_method"].startswith("not measured")
    assert any("equal to the last TELEMETRY" in n for n in r["notes"]), r["notes"]


@pytest.mark.parametrize(
    "extra, option",
    [
        (["--count", "0"], "--count"),
        (["--rate-hz", "5"], "--rate-hz"),
        (["--rate-hz", "fast"], "--rate-hz"),
    ],
)
def test_bad_arguments_are_usage_errors_naming_the_option(extra, option):
    done = subprocess.run(
        CLI + ["latency", "--port", "sim", *extra],
        capture_output=True,
        text=True,
        env=subprocess_env(),
        timeout=60,
    )
    assert done.returncode == 2 and option in done.stderr, done.stderr
