"""`graspguide latency --via lsl`: a real LSL MoCap outlet pushes hand orientations, the
host receives them (through the product's `--source lsl:` source, or a StreamInlet used
directly) and sends POSEs; each POSE's parts, from the tracker's push to the PWM the device
applied, must add up to its total, stay positive and bounded, and agree with the host's
own round trip (the motors change before the answer is back).

Discovery: as in sources/test_lab_streams.py, liblsl is pointed at the loopback through
LSLAPICFG (a container often has no multicast)."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest
from conftest import subprocess_env

from graspguide.devices.promini_sim import PROMINI_ELF_ENV

CLI = [sys.executable, "-m", "graspguide"]
LSL_CONFIG = """\
[ports]
IPv6 = disable
[lab]
KnownPeers = {127.0.0.1}
ResolveScope = machine
[log]
level = -2
"""
# Far above any figure measured on this machine (a few ms), far below what a queue of
# stale samples or a clock mix-up gives (hundreds of ms to hours).
TOTAL_BOUND_US = 1_000_000
# The parts are differences of µs stamps on one clock: their sum may differ from the
# total by the rounding of each.
SUM_TOLERANCE_US = 2.0


@pytest.fixture(scope="module")
def lsl_env(tmp_path_factory):
    from graspguide.sources.lab_streams import network_problem

    problem = network_problem()
    if problem:
        pytest.skip(f"LSL needs a network interface: {problem}")
    cfg = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    cfg.write_text(LSL_CONFIG)
    env = subprocess_env()
    env["LSLAPICFG"] = str(cfg)
    return env


def _tracker_latency(env, port: str, tmp_path, count: int, *extra: str) -> dict:
    out = tmp_path / f"{port}-lsl.json"
    done = subprocess.run(
        CLI
        + ["latency", "--port", port, "--via", "lsl", "--count", str(count)]
        + ["--json", str(out), *extra],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert "median" in done.stdout and "p95" in done.stdout, done.stdout
    return json.loads(out.read_text())


def _parts(r: dict) -> dict[str, list[float]]:
    return {p["name"]: p["samples_us"] for p in r["parts"]}


def _check_consistent(r: dict, count: int) -> None:
    """Every POSE: the parts add up to the total, each is positive, the total is bounded;
    the push times are the outlet's own stamps; the counts add up."""
    parts = _parts(r)
    total = r["total"]["samples_us"]
    assert r["total"]["n"] == count == len(total)
    for name, values in parts.items():
        assert len(values) == count, name
        assert min(values) > 0, (name, min(values))
    for i, t in enumerate(total):
        assert sum(v[i] for v in parts.values()) == pytest.approx(t, abs=SUM_TOLERANCE_US)
        assert 0 < t < TOTAL_BOUND_US, (i, t)
    s = r["total"]
    assert s["min_us"] <= s["p50_us"] <= s["p95_us"] <= s["max_us"]
    # One clock: pylsl's and the host's agree, the correction between two processes of one
    # machine is an estimate of zero, and each push time received is an outlet stamp.
    assert abs(r["clock_offset_s"]) < 1e-3
    assert abs(r["time_correction_s"]) < 1e-3
    assert r["stamp_vs_push_max_us"] < 1000
    assert r["poses_sent"] + r["samples_superseded"] <= r["samples_pushed"]
    assert r["poses_sent"] == count + r["poses_without_motor_change"] + r["poses_unmatched"]


@pytest.mark.parametrize("receiver", ["source", "inlet"])
def test_tracker_latency_on_sim(lsl_env, tmp_path, receiver, report_figure):
    count = 40
    r = _tracker_latency(lsl_env, "sim", tmp_path, count, "--lsl-receiver", receiver)
    _check_consistent(r, count)
    assert list(_parts(r)) == ["push_to_pull", "pull_to_written", "written_to_pwm"]
    assert r["total"]["name"] == "push_to_pwm" and not r["total_is_upper_bound"]
    assert r["receiver"].startswith(
        "graspguide.sources.lsl_inlet" if receiver == "source" else "a pylsl StreamInlet"
    )
    # The device stamps its motor change on CLOCK_MONOTONIC, the host its write and the
    # TELEMETRY's arrival: the change comes between them, POSE by POSE.
    to_pwm = _parts(r)["written_to_pwm"]
    for pwm_us, rtt_us in zip(to_pwm, r["pose_to_telemetry"]["samples_us"]):
        assert pwm_us <= rtt_us + SUM_TOLERANCE_US
    report_figure(
        f"latency sim via LSL ({receiver}): push -> PWM median",
        f"{r['total']['p50_us']:.0f} us",
    )


def test_tracker_latency_on_promini_sim(lsl_env, tmp_path, sketch_elf):
    count = 30
    env = dict(lsl_env)
    env[PROMINI_ELF_ENV] = sketch_elf
    r = _tracker_latency(env, "promini-sim", tmp_path, count)
    _check_consistent(r, count)
    parts = _parts(r)
    assert list(parts) == ["push_to_pull", "pull_to_written", "line_time", "rx_to_pwm"]
    # Every POSE (no contacts) is one frame size; at 111 111 baud a byte is 90 us.
    line = parts["line_time"]
    assert max(line) - min(line) < 1e-6
    frame_bytes = line[0] / 90.0
    assert abs(frame_bytes - round(frame_bytes)) < 1e-6 and 60 <= round(frame_bytes) <= 100
    # Device-side, from the POSE's last byte: inside the host's round trip, which also
    # carries the POSE's and the TELEMETRY's bytes. (Not line time + rx_to_pwm: both are
    # simulated time, which runs faster than real time while the runner catches up.)
    for rx_us, rtt_us in zip(parts["rx_to_pwm"], r["pose_to_telemetry"]["samples_us"]):
        assert rx_us < rtt_us


def test_tracker_latency_on_qemu(lsl_env, tmp_path):
    from graspguide.devices import qemu_firmware
    from graspguide.link.transport import DeviceNotFound

    try:
        qemu_firmware.find_qemu()
        qemu_firmware.find_firmware_elf()
    except DeviceNotFound as e:
        pytest.skip(f"QEMU firmware test: {e}")
    count = 30
    r = _tracker_latency(lsl_env, "qemu", tmp_path, count)
    _check_consistent(r, count)
    assert list(_parts(r)) == ["push_to_pull", "pull_to_written", "written_to_telemetry"]
    assert r["total"]["name"] == "push_to_telemetry" and r["total_is_upper_bound"]
    assert any("equal to the last TELEMETRY" in n for n in r["notes"]), r["notes"]


def test_lsl_clock_is_the_monotonic_clock_and_another_is_refused():
    import pylsl

    from graspguide.bench.latency import LslLatencyError, check_lsl_clock

    assert abs(check_lsl_clock(pylsl)) < 1e-3

    class Late:
        """A clock 5 ms ahead of the monotonic one, as another time base would be."""

        @staticmethod
        def local_clock() -> float:
            return time.monotonic() + 0.005

    with pytest.raises(LslLatencyError, match=r"differ by 5\.\d+ ms"):
        check_lsl_clock(Late)


@pytest.mark.parametrize(
    "extra, option",
    [
        (["--rate-hz", "2000"], "--rate-hz"),
        (["--lsl-receiver", "socket"], "--lsl-receiver"),
        (["--via", "udp"], "--via"),
    ],
)
def test_bad_tracker_arguments_are_usage_errors_naming_the_option(extra, option):
    done = subprocess.run(
        CLI + ["latency", "--port", "sim", "--via", "lsl", *extra],
        capture_output=True,
        text=True,
        env=subprocess_env(),
        timeout=60,
    )
    assert done.returncode == 2 and option in done.stderr, done.stderr
