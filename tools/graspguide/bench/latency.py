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

:func:`measure_tracker_latency` (``--via lsl``) times the path from a tracker instead: an
LSL MoCap outlet's push -> the host's receipt (the product's ``--source lsl:`` source, or
a StreamInlet) -> the POSE written -> the motors (the same device-side figures; on
``qemu`` and a board the TELEMETRY's arrival, an upper bound).
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
    out["p95_us"] = float(np.percentile(a, 95))  # the tracker path's report gives p95
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


# --------------------------------------------------------------------------------------
# From a tracker's LSL sample to the motors (`graspguide latency --via lsl`)
# --------------------------------------------------------------------------------------
#: The tracker's orientations, pushed in turn. Three, not two: a host that sends the newest
#: sample skips one now and then when the device answers more slowly than the tracker
#: pushes, and with three a skip of one still changes the motors on the next POSE.
TRACKER_POSES = (*POSES, [0.9683, -0.1019, 0.2039, 0.1019])
LSL_CHANNELS = ("Hand_QW", "Hand_QX", "Hand_QY", "Hand_QZ")
LSL_POSITION_CHANNELS = ("Hand_X", "Hand_Y", "Hand_Z")
HAND_POSITION_M = (0.0, 0.0, 0.3)  # the rigid body's position: the guidance does not use it
RECEIVERS = ("auto", "source", "inlet")
LSL_RATE_HZ = 100.0
MAX_LSL_RATE_HZ = 1000.0
# pylsl's local_clock and time.monotonic must be one clock for the parts to add up.
CLOCK_AGREEMENT_S = 1e-3
LSL_OPEN_TIMEOUT_S = 10.0
# The sketch's Serial.begin(115200) at 8 MHz: the core's U2X divider (UBRR 8) gives
# 8 MHz / 8 / 9 = 111 111 baud, which simavr's UART models (promini/.../board_glue.h).
PROMINI_LINE_BAUD = AVR_CPU_HZ / 8 / 9
UART_BITS_PER_BYTE = 10  # start, 8 data, stop


class LslLatencyError(RuntimeError):
    """The tracker path cannot be measured here (no pylsl, no network, clocks that are not
    one); the message says why and what to do."""


def lsl_clock_offset_s(pylsl: Any) -> float:
    """pylsl.local_clock() minus time.monotonic() (the midpoint of two reads around it)."""
    best = math.inf
    offset = 0.0
    for _ in range(5):  # the read with the shortest bracket: least disturbed by the scheduler
        m0 = time.monotonic()
        lsl_now = pylsl.local_clock()
        m1 = time.monotonic()
        if m1 - m0 < best:
            best, offset = m1 - m0, lsl_now - (m0 + m1) / 2
    return offset


def check_lsl_clock(pylsl: Any) -> float:
    """The offset (s) of LSL's clock from the host's monotonic clock; LslLatencyError when
    they differ by more than CLOCK_AGREEMENT_S (the parts would not be on one clock)."""
    offset = lsl_clock_offset_s(pylsl)
    if abs(offset) > CLOCK_AGREEMENT_S:
        raise LslLatencyError(
            f"pylsl.local_clock() and time.monotonic() differ by {offset * 1e3:.3f} ms here "
            f"(more than {CLOCK_AGREEMENT_S * 1e3:g} ms): they are not one clock, so a push "
            "time and the device's motor time cannot be subtracted; measure on Linux, where "
            "both are CLOCK_MONOTONIC"
        )
    return offset


class _TimedWrites:
    """A transport whose writes are stamped (monotonic ns just before the bytes go to the
    link) and counted; everything else is the transport's."""

    def __init__(self, transport: Any):
        self._transport = transport
        self.last_write_ns = 0
        self.last_write_bytes = 0

    def write(self, data: bytes) -> None:
        self.last_write_ns = time.monotonic_ns()
        self.last_write_bytes = len(data)
        self._transport.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._transport, name)


class _Tracker:
    """A MoCap LSL outlet, as a lab's tracker app publishes a rigid body (``Hand_X, Hand_Y,
    Hand_Z`` in metres, ``Hand_QW, Hand_QX, Hand_QY, Hand_QZ``, labelled in its desc),
    pushing TRACKER_POSES in turn at ``rate_hz`` from its own thread, each sample stamped
    with local_clock() read just before its push."""

    def __init__(self, pylsl: Any, rate_hz: float):
        import threading

        self.name = f"GraspGuideLatencyTracker-{os.getpid()}-{time.monotonic_ns() % 10**9}"
        labels = LSL_POSITION_CHANNELS + LSL_CHANNELS
        info = pylsl.StreamInfo(
            self.name, "MoCap", len(labels), rate_hz, pylsl.cf_double64, self.name
        )
        channels = info.desc().append_child("channels")
        for label in labels:
            ch = channels.append_child("channel")
            ch.append_child_value("label", label)
            position = label in LSL_POSITION_CHANNELS
            ch.append_child_value("type", "Position" if position else "Orientation")
            ch.append_child_value("unit", "m" if position else "quaternion")
        self._pylsl = pylsl
        self.outlet = pylsl.StreamOutlet(info)
        self.rate_hz = rate_hz
        self.pushed_s: list[float] = []
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lsl-tracker", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        try:
            period_ns = int(1e9 / self.rate_hz)
            next_ns = time.monotonic_ns()
            i = 0
            while not self._stop.is_set():
                wait_ns = next_ns - time.monotonic_ns()
                if wait_ns > 0 and self._stop.wait(wait_ns / 1e9):
                    break
                next_ns += period_ns
                sample = [*HAND_POSITION_M, *TRACKER_POSES[i % len(TRACKER_POSES)]]
                stamp = self._pylsl.local_clock()
                self.outlet.push_sample(sample, stamp)
                self.pushed_s.append(stamp)
                i += 1
        except BaseException as e:  # reported by stop(): a thread's exception is lost else
            self.error = e

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)


class _BatchStamps:
    """An inlet that remembers the timestamp of the last sample of its latest pull (a
    pull_sample, then the pull_chunk of what else is waiting): the one the product's source
    sends, since it sends the newest."""

    def __init__(self, inlet: Any):
        self._inlet = inlet
        self.last_s: float | None = None

    def pull_sample(self, *args: Any, **kwargs: Any) -> Any:
        sample, stamp = self._inlet.pull_sample(*args, **kwargs)
        if sample is not None:
            self.last_s = float(stamp)
        return sample, stamp

    def pull_chunk(self, *args: Any, **kwargs: Any) -> Any:
        rows, stamps = self._inlet.pull_chunk(*args, **kwargs)
        if stamps:
            self.last_s = float(stamps[-1])
        return rows, stamps

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inlet, name)


class _ProductReceiver:
    """The samples through the product's ``--source lsl:...`` (graspguide.sources.lsl_inlet):
    the measured path is the one `graspguide stream` reads a tracker with."""

    what = (
        "graspguide.sources.lsl_inlet (the --source lsl: source: liblsl's proc_clocksync "
        "adds time_correction, the newest sample of each pull is sent)"
    )

    def __init__(self, tracker: _Tracker, timeout: float):
        from graspguide.sources.lsl_inlet import open_lsl_source
        from graspguide.sources.poses import SourceError

        # stall/end: a tracker that stops is an error here within a second, not a pause
        spec = f"source_id={tracker.name},markers=none,newest=1,wait={timeout:g},stall=0.2,end=1"
        try:
            self.source = open_lsl_source(spec)
        except SourceError as e:
            raise LslLatencyError(f"{e} (the tracker's own outlet, on this machine)") from None
        self._stamps = _BatchStamps(self.source.inlet)
        self.source.inlet = self._stamps
        self._samples = iter(self.source)
        self._last: tuple[float, float] | None = None  # (t_s, push time) of the last sample

    def next(self) -> tuple[Sequence[float], float]:
        """The next quaternion to send and its push time on this machine's LSL clock."""
        try:
            t_s, quat, _ = next(self._samples)
        except StopIteration:
            raise LslLatencyError("the LSL source ended: no sample from the tracker") from None
        stamp = self._stamps.last_s
        assert stamp is not None  # a sample was yielded, so one was pulled
        # The source's own times must advance as the stamps do: else the sample it sent is
        # not the newest of the pull, and the push time taken here would be another's.
        if self._last is not None:
            step_s = (stamp - self._last[1]) - (t_s - self._last[0])
            if abs(step_s) > 1e-6:
                raise LslLatencyError(
                    f"the LSL source's sample at t_s {t_s:.6f} s is not the newest pulled "
                    f"({step_s * 1e6:.1f} us apart): its push time is unknown here; measure "
                    "with --lsl-receiver inlet"
                )
        self._last = (float(t_s), stamp)
        return quat, stamp

    def time_correction(self) -> float:
        return float(self._stamps.time_correction(LSL_OPEN_TIMEOUT_S))

    def superseded(self) -> int:
        return int(self.source.stats()["skipped"])

    def close(self) -> None:
        close = getattr(self._samples, "close", None)
        if close is not None:
            close()  # its finally closes the inlet's stream
        else:
            self.source.inlet.close_stream()


class _DirectReceiver:
    """The samples through a pylsl StreamInlet used directly, as the product's source does
    (time_correction added, the newest sample of each pull): for when that source is not
    installed, or to compare with it."""

    what = "a pylsl StreamInlet used directly (time_correction added, the newest sample sent)"

    def __init__(self, pylsl: Any, tracker: _Tracker, timeout: float):
        found = pylsl.resolve_byprop("source_id", tracker.name, 1, timeout)
        if not found:
            raise LslLatencyError(
                f"the tracker's own LSL outlet {tracker.name} was not found in {timeout:g} s: "
                "LSL discovery does not work here (a firewall, or no multicast: set LSLAPICFG "
                "to an lsl_api.cfg with KnownPeers = {127.0.0.1}, docs/lab-streams.md)"
            )
        self.inlet = pylsl.StreamInlet(found[0], max_buflen=10, recover=False)
        self.inlet.open_stream(timeout)
        self.correction = float(self.inlet.time_correction(timeout))
        self._superseded = 0

    def next(self) -> tuple[Sequence[float], float]:
        # Past the watchdog's 200 ms the device would switch the motors off anyway.
        sample, stamp = self.inlet.pull_sample(timeout=0.2)
        if sample is None:
            raise LslLatencyError("no sample from the tracker's outlet in 0.2 s")
        more, stamps = self.inlet.pull_chunk(timeout=0.0)
        if more:
            self._superseded += len(more)
            sample, stamp = more[-1], stamps[-1]
        return sample[len(LSL_POSITION_CHANNELS) :], float(stamp) + self.correction

    def time_correction(self) -> float:
        return self.correction

    def superseded(self) -> int:
        return self._superseded

    def close(self) -> None:
        # before the outlet goes: an inlet whose outlet vanishes logs an error
        self.inlet.close_stream()


def _open_receiver(pylsl: Any, tracker: _Tracker, receiver: str) -> Any:
    if receiver == "inlet":
        return _DirectReceiver(pylsl, tracker, LSL_OPEN_TIMEOUT_S)
    try:
        import graspguide.sources.lsl_inlet  # noqa: F401
    except ImportError:
        if receiver == "source":
            raise LslLatencyError(
                "graspguide.sources.lsl_inlet (the --source lsl: source) is not installed"
            ) from None
        return _DirectReceiver(pylsl, tracker, LSL_OPEN_TIMEOUT_S)
    return _ProductReceiver(tracker, LSL_OPEN_TIMEOUT_S)


@dataclass
class TrackerSample:
    """One POSE sent from a tracker sample: its push time (s, its LSL timestamp plus the
    time correction: this machine's clock), and on the host's monotonic clock (ns) when it
    was pulled, its POSE written, its TELEMETRY back; the POSE's wire bytes and the duties
    its TELEMETRY reported."""

    push_s: float
    pulled_ns: int
    written_ns: int
    answered_ns: int
    wire_bytes: int
    pwm: tuple[int, ...]
    changed: bool


@dataclass
class TrackerPart:
    name: str
    what: str
    summary: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "what": self.what, **self.summary}


@dataclass
class TrackerLatencyResult:
    port: str
    kind: str
    board: str
    count: int
    rate_hz: float
    receiver: str
    parts: list[TrackerPart]
    total: TrackerPart
    total_is_upper_bound: bool
    round_trip: dict[str, Any]
    poses_sent: int
    samples_pushed: int
    samples_superseded: int
    unchanged: int
    unmatched: int
    time_correction_s: float
    clock_offset_s: float
    stamp_vs_push_max_us: float
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "via": "lsl",
            "port": self.port,
            "kind": self.kind,
            "board": self.board,
            "count": self.count,
            "rate_hz": self.rate_hz,
            "receiver": self.receiver,
            "parts": [p.to_dict() for p in self.parts],
            "total": self.total.to_dict(),
            "total_is_upper_bound": self.total_is_upper_bound,
            "pose_to_telemetry": self.round_trip,
            "poses_sent": self.poses_sent,
            "samples_pushed": self.samples_pushed,
            "samples_superseded": self.samples_superseded,
            "poses_without_motor_change": self.unchanged,
            "poses_unmatched": self.unmatched,
            "time_correction_s": self.time_correction_s,
            "clock_offset_s": self.clock_offset_s,
            "stamp_vs_push_max_us": self.stamp_vs_push_max_us,
            "notes": self.notes,
        }


def _load_lsl() -> Any:
    from graspguide.sources.lab_streams import LabStreamsError, _load_pylsl, network_problem

    problem = network_problem()
    if problem:
        raise LslLatencyError(problem)
    try:
        return _load_pylsl(configure_log=True)
    except LabStreamsError as e:
        raise LslLatencyError(str(e)) from None


def _device_part(
    kind: str, samples: Sequence[TrackerSample], recorder: str | None, poses_sent: int
) -> tuple[list[tuple[str, str, list[float | None]]], bool]:
    """The device's parts for each sample, after the host's: [(name, what, µs or None)] and
    whether the total is only an upper bound (no motor time on this kind)."""
    from graspguide.devices.promini_sim import read_events

    written_to_answer = [(s.answered_ns - s.written_ns) / 1e3 for s in samples]
    if kind == "sim" and recorder:
        timings = [PoseTiming(s.written_ns // 1000, 0.0, s.pwm) for s in samples]
        # the µs stamps on both sides truncate: the 1 ns of the host's stamp lost here is
        # far inside their 1 µs resolution
        to_pwm = pwm_latencies_trace(timings, _read_trace(recorder))
        head = [(s.written_ns % 1000) / 1e3 for s in samples]
        return [
            (
                "written_to_pwm",
                "POSE written -> the simulated device's motor change (its --trace, "
                "CLOCK_MONOTONIC, 1 us; the pty's delivery included)",
                [None if d is None else d - h for d, h in zip(to_pwm, head)],
            )
        ], False
    if kind == "promini-sim" and recorder:
        frame_ends, changes = read_events(recorder)
        cycles = pwm_latencies_cycles(frame_ends, changes, poses_sent)
        line = [s.wire_bytes * UART_BITS_PER_BYTE * 1e6 / PROMINI_LINE_BAUD for s in samples]
        return [
            (
                "line_time",
                f"the POSE's bytes on the serial line at the sketch's "
                f"{PROMINI_LINE_BAUD:.0f} baud (computed: bytes x 10 bits / baud, "
                "first bit -> the last byte received)",
                list(line),
            ),
            (
                "rx_to_pwm",
                "UART receipt of the POSE's closing byte -> the last motor-channel change it "
                "caused (AVR cycles at 8 MHz, simavr --events: exact)",
                [None if c is None else c * 1e6 / AVR_CPU_HZ for c in cycles],
            ),
        ], False
    return [
        (
            "written_to_telemetry",
            "POSE written -> its TELEMETRY decoded on the host (host clock): an upper bound "
            "of POSE -> PWM, since the firmware writes the motors before it answers",
            list(written_to_answer),
        )
    ], True


def measure_tracker_latency(
    port: str,
    count: int = 200,
    rate_hz: float = LSL_RATE_HZ,
    baud: int = 115200,
    timeout: float = 1.0,
    progress: Callable[[int], None] | None = None,
    receiver: str = "auto",
) -> TrackerLatencyResult:
    """A tracker's LSL sample -> the PWM the device applied (`graspguide latency --via lsl`,
    docs/latency.md): a MoCap outlet pushes TRACKER_POSES in turn at ``rate_hz``; the host
    receives them through ``receiver``: "source", the product's ``--source lsl:`` source
    (graspguide.sources.lsl_inlet); "inlet", a pylsl StreamInlet used directly the same
    way; "auto", the source where it is installed. The newest sample goes out as a POSE
    once the previous is answered, until ``count`` POSEs have changed the motors. Raises
    LslLatencyError, LinkError, or ValueError naming a bad argument."""
    from graspguide.link.client import DeviceClient, host_time_us

    if not isinstance(count, int) or not 1 <= count <= MAX_COUNT:
        raise ValueError(f"count must be an integer in 1..{MAX_COUNT}, got {count!r}")
    if not (math.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= MAX_LSL_RATE_HZ):
        raise ValueError(
            f"rate_hz (the tracker's push rate) must be in [{MIN_RATE_HZ:g}, "
            f"{MAX_LSL_RATE_HZ:g}] (a POSE at least every 100 ms, inside the device's "
            f"watchdog), got {rate_hz}"
        )
    if receiver not in RECEIVERS:
        raise ValueError(f"receiver must be one of {', '.join(RECEIVERS)}, got {receiver!r}")
    pylsl = _load_lsl()
    clock_offset = check_lsl_clock(pylsl)
    # Enough for every POSE to repeat its orientation once, and then some.
    max_poses = 3 * count + 20
    with tempfile.TemporaryDirectory(prefix="graspguide-latency-lsl-") as workdir:
        transport, kind, recorder = _open_device(port, baud, workdir)
        timed = _TimedWrites(transport)
        tracker = rx = None
        samples: list[TrackerSample] = []
        try:
            client = DeviceClient(timed, timeout=timeout)
            board = client.hello().board
            client.set_scene(
                HAND3_M, policy="F", mode="V", constraints="paper", timeout_s=_longest_trial_s()
            )
            tracker = _Tracker(pylsl, rate_hz)
            rx = _open_receiver(pylsl, tracker, receiver)
            client.start_trial(TRIAL_ID, WRENCH)
            tracker.start()
            changed_count = 0
            last_pwm: tuple[int, ...] | None = None
            while changed_count < count and len(samples) < max_poses:
                try:
                    quat, push_s = rx.next()
                except LslLatencyError as e:
                    if tracker.error is not None:
                        raise LslLatencyError(f"{e}: the tracker failed: {tracker.error}") from None
                    raise
                pulled_ns = time.monotonic_ns()
                tel = client.pose(host_time_us(), quat)
                answered_ns = time.monotonic_ns()
                pwm = tuple(tel.pwm)
                changed = pwm != last_pwm
                last_pwm = pwm
                changed_count += changed
                samples.append(
                    TrackerSample(
                        push_s,
                        pulled_ns,
                        timed.last_write_ns,
                        answered_ns,
                        timed.last_write_bytes,
                        pwm,
                        changed,
                    )
                )
                if progress is not None:
                    progress(changed_count)
            tracker.stop()
            correction = rx.time_correction()
            superseded = rx.superseded()
            firmware = getattr(transport, "firmware", None)
            registers = None if firmware is None else tuple(firmware.motor_registers())
            client.stop()
        finally:
            if tracker is not None:
                tracker.stop()
            if rx is not None:
                rx.close()
            transport.close()
        if tracker.error is not None:
            raise LslLatencyError(f"the tracker's outlet thread failed: {tracker.error}")
        notes: list[str] = []
        if registers is not None and samples:
            same = registers == samples[-1].pwm
            notes.append(
                f"motor registers read through QMP before STOP: {registers}, "
                f"{'equal to' if same else 'DIFFERENT from'} the last TELEMETRY's PWM "
                f"{samples[-1].pwm}"
            )
        # Each push time the receiver gave, against the outlet's own stamp of that sample
        # (the nearest): they differ by the time correction only.
        pushed = np.asarray(tracker.pushed_s)
        got = np.asarray([s.push_s for s in samples])
        nearest = np.clip(np.searchsorted(pushed, got), 1, len(pushed) - 1)
        off = np.minimum(np.abs(got - pushed[nearest - 1]), np.abs(got - pushed[nearest]))
        stamp_error_us = float(off.max() * 1e6) if len(off) else 0.0
        device, upper = _device_part(kind, samples, recorder, len(samples))
    if changed_count < count:
        notes.append(
            f"only {changed_count} of the {count} POSEs asked for changed the motors within "
            f"{max_poses} POSEs"
        )
    host_parts: list[tuple[str, str, list[float | None]]] = [
        (
            "push_to_pull",
            "the tracker's push (its LSL timestamp + the time correction) -> the receiver "
            "has handed the sample over (the newest of its pull)",
            [s.pulled_ns / 1e3 - s.push_s * 1e6 for s in samples],
        ),
        (
            "pull_to_written",
            "pulled -> the POSE's bytes handed to the link (encoding included)",
            [(s.written_ns - s.pulled_ns) / 1e3 for s in samples],
        ),
    ]
    all_parts = host_parts + device
    keep = [
        i
        for i, s in enumerate(samples)
        if s.changed and all(values[i] is not None for _, _, values in all_parts)
    ]
    if not keep:
        raise LslLatencyError(f"none of the {len(samples)} POSEs changed the motors to time")
    parts = [
        TrackerPart(name, what, summarize([float(values[i]) for i in keep]))  # type: ignore[arg-type]
        for name, what, values in all_parts
    ]
    totals = [sum(float(values[i]) for _, _, values in all_parts) for i in keep]  # type: ignore[arg-type]
    total_name = "push_to_telemetry" if upper else "push_to_pwm"
    if kind == "promini-sim":
        total_what = (
            "push -> PWM as a Pro Mini on a directly attached serial line would have it: "
            "the host's parts (host clock) + the POSE's line time (computed) + UART receipt "
            "-> PWM (AVR cycles); without the pty's hand-over to the simavr runner and, on "
            "a board, without a USB-serial adapter's latency"
        )
    elif upper:
        total_what = (
            "push -> TELEMETRY received: an upper bound of push -> PWM (no motor-change "
            "time on this device kind)"
        )
    else:
        total_what = "push -> the device's motor change, all on CLOCK_MONOTONIC"
    unchanged = sum(1 for s in samples if not s.changed)
    return TrackerLatencyResult(
        port=port,
        kind=kind,
        board=board,
        count=count,
        rate_hz=rate_hz,
        receiver=rx.what,
        parts=parts,
        total=TrackerPart(total_name, total_what, summarize(totals)),
        total_is_upper_bound=upper,
        round_trip=summarize(
            [(samples[i].answered_ns - samples[i].written_ns) / 1e3 for i in keep]
        ),
        poses_sent=len(samples),
        samples_pushed=len(tracker.pushed_s),
        samples_superseded=superseded,
        unchanged=unchanged,
        unmatched=len(samples) - unchanged - len(keep),
        time_correction_s=correction,
        clock_offset_s=clock_offset,
        stamp_vs_push_max_us=stamp_error_us,
        notes=notes,
    )


def tracker_report_lines(result: TrackerLatencyResult) -> list[str]:
    """The text report: median, p95 and max of each part and of the total."""
    rows = [*result.parts, result.total]
    width = max(len(p.name) for p in rows)
    lines = [
        f"tracker -> motors latency on {result.port} (board {result.board}): LSL MoCap outlet "
        f"at {result.rate_hz:g} Hz, {result.total.summary['n']} POSEs that changed the motors",
        f"receiver: {result.receiver}",
        f"time correction {result.time_correction_s * 1e6:.1f} us; local_clock - monotonic "
        f"{result.clock_offset_s * 1e6:.1f} us; push times received vs the outlet's stamps: "
        f"within {result.stamp_vs_push_max_us:.1f} us",
        "",
        f"  {'part':<{width}}  {'median':>9}  {'p95':>9}  {'max':>9}  (ms)",
    ]
    for p in rows:
        s = p.summary
        lines.append(
            f"  {p.name:<{width}}  {s['p50_us'] / 1e3:9.3f}  {s['p95_us'] / 1e3:9.3f}  "
            f"{s['max_us'] / 1e3:9.3f}"
        )
    lines.append("")
    lines.extend(f"{p.name}: {p.what}" for p in rows)
    if result.total_is_upper_bound:
        lines.append(f"{result.total.name} is an UPPER BOUND of push -> PWM on this device kind")
    lines.append(
        f"{result.samples_pushed} samples pushed, {result.poses_sent} POSEs sent, "
        f"{result.samples_superseded} samples superseded by a newer one before they were "
        f"sent, {result.unchanged} POSEs left the motors as they were, "
        f"{result.unmatched} without a motor change found"
    )
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
    "LslLatencyError",
    "TrackerLatencyResult",
    "measure_tracker_latency",
    "tracker_report_lines",
    "check_lsl_clock",
]
