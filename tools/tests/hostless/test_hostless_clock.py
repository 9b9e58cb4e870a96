"""The host-less world's view of the simulated device's clock. The simulated device's
virtual clock follows the world's IMU samples, but after the stale time (200 ms) of real
time without one it follows real time: a host slowed at start (a slow disk, a loaded
machine) finds the device's clock ahead of its own, and a host paused mid-run finds it
jumped ahead. The world must read the device's event times as they are, in both
directions and across the 32-bit wrap, and go on from the device's time. SIMULATED
throughout, on the real simulated device."""

from __future__ import annotations

import io
import time

import pytest
from conftest import small_protocol_toml

from graspguide.hostless import runner as hr
from graspguide.link import client as dv
from graspguide.link.messages import RunEvent
from graspguide.protocol import study_protocol as pf
from graspguide.sources.trial_sources import open_runner_source
from graspguide.study.progress import Progress

U32 = 1 << 32
# Longer than the simulated device's stale time (200 ms): its clock then follows real time.
SLOW_S = 0.45
# Longer than the success or timeout pattern (at most 600 ms): the device's next event (the
# rest) comes while the host is paused.
PAUSE_S = 1.0
REST_S = 0.3
SHORT = small_protocol_toml("hostless-clock", seed=5, modalities=("F+V", "Fperp+V"), wrenches=1)


def protocol(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text(SHORT)
    return pf.load_protocol(str(path))


class _Clock:
    """What _event_time_s reads of a HostlessWorld: the world's time and what it has seen
    of the device's."""

    def __init__(self, t_us: int):
        self.t0_us = t_us
        self.t_us = t_us
        self.device_us: int | None = None


@pytest.mark.parametrize(
    ("world_us", "device_us", "expected_us"),
    [
        (0, 0, 0),
        (1_000_000, 990_000, 990_000),  # the sample before: behind
        (0, 300_000, 300_000),  # a device that followed real time before the first sample
        (5_000_000, 5_450_000, 5_450_000),  # ahead mid-run after a host pause
        (U32 - 1_000, 500, U32 + 500),  # ahead across the wrap
        (U32 + 1_000, U32 - 500, U32 - 500),  # behind across the wrap
        (3 * U32 + 7, 7 - 20_000, 3 * U32 + 7 - 20_000),
    ],
)
def test_a_device_time_is_read_as_the_nearest_time_with_those_32_bits(
    world_us, device_us, expected_us
):
    clock = _Clock(world_us)
    got = hr.HostlessWorld._event_time_s(clock, device_us & 0xFFFFFFFF)  # type: ignore[arg-type]
    assert got == pytest.approx(expected_us / 1e6, abs=1e-9)


def _run(tmp_path, client, proto, **kw):
    model = open_runner_source("participant", proto, "U1").model
    said = io.StringIO()
    done = hr.run_hostless(
        proto,
        "U1",
        client,
        str(tmp_path / "study"),
        model,
        rest_s=REST_S,
        progress=Progress(out=said, tty=False),
        err=io.StringIO(),
        **kw,
    )
    return done, said.getvalue()


def _record_events(monkeypatch) -> dict[tuple[int, int, int], None]:
    """Every HOSTLESS_EVENT the world reads, as (event, position, device_time_us), in order."""
    events: dict[tuple[int, int, int], None] = {}
    real_events = hr.HostlessWorld._events

    def seen(world) -> None:
        for ev in world.client.hostless_events:
            events[(int(ev.event), int(ev.position), int(ev.device_time_us))] = None
        real_events(world)

    monkeypatch.setattr(hr.HostlessWorld, "_events", seen)
    return events


def _assert_clock_never_went_back_and_rests_were_whole(events, proto) -> None:
    times = [t for _, _, t in events]
    steps = [((b - a + (1 << 31)) % U32) - (1 << 31) for a, b in zip(times, times[1:])]
    assert steps and min(steps) >= 0, f"the device's clock went back: {list(events)}"
    rest = {p: t for e, p, t in events if e == int(RunEvent.REST)}
    ready = {p: t for e, p, t in events if e == int(RunEvent.READY)}
    assert sorted(rest) == sorted(ready) == list(range(len(pf.plan(proto, "U1"))))
    for p in rest:  # every rest lasts its full time (and the ready pattern after it)
        assert (ready[p] - rest[p]) % U32 >= REST_S * 1e6, f"position {p}: {list(events)}"


def test_a_host_slowed_at_start_finds_the_device_ahead_and_runs_the_plan(tmp_path, monkeypatch):
    """The host takes longer than the stale time before its first sample (as a host does
    whose disk takes 300 ms per fsync): the device's first event is stamped ahead of the
    world's clock. The world goes on from the device's time, so the device's clock never
    goes back and every rest lasts its full time."""
    from graspguide.devices.sim import SimulatedDevice

    proto = protocol(tmp_path)
    events = _record_events(monkeypatch)
    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        client = dv.DeviceClient(dev)
        client.hello()
        time.sleep(SLOW_S)
        done, _ = _run(tmp_path, client, proto, clock_start_us=0)
    assert done.completed == done.planned == len(pf.plan(proto, "U1"))
    assert done.ran == done.planned
    # the device time the run used is the run's own: not 2^32 us, not negative
    assert 0 < done.device_s < done.planned * (proto.timeout_s + 10)
    _assert_clock_never_went_back_and_rests_were_whole(events, proto)


def test_a_host_paused_mid_run_finds_the_device_ahead_and_runs_the_plan(tmp_path, monkeypatch):
    """The host's work on a trial's result (its files, fsync'ed) takes longer than the
    success pattern: the device's rest begins while the host is away, stamped ahead of the
    world's clock. The world moves on by the real time it was away, so no sample turns the
    device's clock back (which would cut the rest short)."""
    from graspguide.devices.sim import SimulatedDevice

    proto = protocol(tmp_path)
    events = _record_events(monkeypatch)
    paused = []

    def slow_disk(result) -> None:  # the host's work on the first result takes PAUSE_S
        if not paused:
            paused.append(result)
            time.sleep(PAUSE_S)

    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        done, _ = _run(tmp_path, dv.DeviceClient(dev), proto, on_trial_result=slow_disk)
    assert paused
    assert done.completed == done.planned and done.ran == done.planned
    _assert_clock_never_went_back_and_rests_were_whole(events, proto)
