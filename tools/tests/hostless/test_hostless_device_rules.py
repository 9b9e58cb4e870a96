"""Two rules of the host-less runner, on the real simulated device through the link: an
upload that is never committed leaves the stored plan in use (LOG_INFO shows it and
HOSTLESS_RUN runs it, dropping the open upload), and an IMU sample stamped before the last
one aborts the trial under way with no record and no TRIAL_RESULT (TELEMETRY
time_went_backwards, motors off, the trial begins again with its rest). The runner's own
tests are in test/test_hostless; docs/hostless.md says why."""

from __future__ import annotations

import dataclasses
import io
import os

import pytest
from conftest import REPO_ROOT

from graspguide.devices.sim import SimulatedDevice
from graspguide.hostless import plan_upload as pu
from graspguide.link import client as dv
from graspguide.link import messages as m
from graspguide.protocol.study_protocol import load_protocol

PAPER = os.path.join(REPO_ROOT, "protocols", "paper.toml")
G = 9.80665
PERIOD_US = 10_000


@pytest.fixture(scope="module")
def plan3():
    """The first 3 trials of U1's paper plan, a 0.1 s rest and a 5 s timeout."""
    protocol = load_protocol(PAPER)
    planned = pu.planned_trials(protocol, "U1")[:3]
    begin, trials = pu.plan_messages(protocol, "U1", planned, simulated=True, rest_s=0.1)
    return dataclasses.replace(begin, trial_count=3, timeout_s=5.0), trials


def _events(client) -> list[tuple[str, int]]:
    out = [
        (m.RunEvent(int(e.event)).name.lower(), int(e.trial_index)) for e in client.hostless_events
    ]
    client.hostless_events.clear()
    return out


def test_an_upload_never_committed_leaves_the_stored_plan_in_use(tmp_path, plan3):
    begin, trials = plan3
    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        c = dv.DeviceClient(dev, timeout=2.0)
        c.hello()
        c.upload_plan(begin, trials)
        other = dataclasses.replace(begin, participant="U9", trial_count=2)
        c._request(other, m.Ack)
        c._request(dataclasses.replace(trials[1], position=0), m.Ack)
        # The host goes away here: the upload is never committed.
        info = c.log_info()
        assert info.plan_stored, "LOG_INFO must still describe the stored plan"
        assert (info.participant, info.plan_trials) == ("U1", 3)
        c.hostless_run()
        assert _events(c) == [("rest", trials[0].trial_index)]
        c.stop()
        with pytest.raises(dv.DeviceError) as e:  # the open upload was dropped
            c._request(dataclasses.replace(trials[2], position=1), m.Ack)
        assert e.value.code_name == "no_plan"


def test_a_sample_stamped_back_aborts_the_trial_with_no_record(tmp_path, plan3):
    begin, trials = plan3
    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        c = dv.DeviceClient(dev, timeout=2.0)
        c.hello()
        c.upload_plan(begin, trials)
        t = 1_000_000
        c.sim_imu_sample(t, [0.0, 0.0, G], [0.0, 0.0, 0.0])
        c.hostless_run()
        seen: list[tuple[str, int]] = _events(c)
        for i in range(2000):  # rest, then the ready pattern
            if ("ready", trials[0].trial_index) in seen:
                break
            t += PERIOD_US
            c.sim_imu_sample(t, [1e-3 * (i % 5), 0.0, G], [0.0, 0.0, 0.0])
            seen += _events(c)
        c.sim_button(True)
        seen = _events(c)
        assert ("trial_started", trials[0].trial_index) in seen, seen
        for i in range(50):  # guided, held away from the force
            t += PERIOD_US
            tel = c.sim_imu_sample(t, [G, 1e-3 * (i % 5), 0.0], [0.0, 0.0, 0.0])
            assert tel is not None and tel.flags & m.TELEMETRY_FLAG_TRIAL_RUNNING
        tel = c.sim_imu_sample(t - 1, [G, 0.0, 0.0], [0.0, 0.0, 0.0])  # 1 us back
        assert tel is not None
        assert tel.solver_status == m.ErrorCode.TIME_WENT_BACKWARDS, tel
        assert list(tel.pwm) == [0, 0, 0, 0] and not tel.flags & m.TELEMETRY_FLAG_TRIAL_RUNNING
        assert _events(c) == [("rest", trials[0].trial_index)]
        assert list(c.trial_results) == []
        assert c.log_info().records == 0
        c.stop()


class _OneSampleBack:
    """A DeviceClient whose IMU sends, once, ``after`` samples into the first trial, a
    sample stamped 1 us before the last one (a glitch of the IMU's time stamp)."""

    def __init__(self, client, after: int):
        self._client = client
        self._after = after
        self._last_us: int | None = None
        self.answer: m.Telemetry | None = None
        self.seen: list = []  # every HOSTLESS_EVENT, before the world takes them

    def __getattr__(self, name):
        return getattr(self._client, name)

    def sim_imu_sample(self, time_us, accel, gyro, timeout=None):
        started = any(int(e.event) == m.RunEvent.TRIAL_STARTED for e in self.seen)
        if started and self.answer is None and self._last_us is not None:
            self._after -= 1
            if self._after <= 0:
                self.answer = self._client.sim_imu_sample(self._last_us - 1, accel, gyro)
        self._last_us = int(time_us)
        tel = self._client.sim_imu_sample(time_us, accel, gyro, timeout)
        self.seen.extend(self._client.hostless_events)
        return tel

    def sim_button(self, pressed, timeout=None):
        ack = self._client.sim_button(pressed, timeout)
        self.seen.extend(self._client.hostless_events)
        return ack


def test_a_study_with_one_sample_stamped_back_runs_that_trial_again_once(tmp_path):
    """The host-less world on the simulated device: the trial that saw the step back is
    aborted (no record), runs again, and the study ends with one record per trial."""
    from test_hostless_study import REST_S as STUDY_REST_S
    from test_hostless_study import read_lines, short_protocol

    from graspguide.hostless import runner as hr
    from graspguide.protocol import study_protocol as sp
    from graspguide.sources.trial_sources import open_runner_source
    from graspguide.study.progress import Progress

    _, protocol = short_protocol(tmp_path)
    out = tmp_path / "study"
    results = []
    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        client = _OneSampleBack(dv.DeviceClient(dev, timeout=2.0), after=30)
        model = open_runner_source("participant", protocol, "U1").model
        done = hr.run_hostless(
            protocol,
            "U1",
            client,
            str(out),
            model,
            rest_s=STUDY_REST_S,
            on_trial_result=results.append,
            progress=Progress(out=io.StringIO(), tty=False),
            err=io.StringIO(),
        )
    assert client.answer is not None, "the step back was sent in a trial"
    assert client.answer.solver_status == m.ErrorCode.TIME_WENT_BACKWARDS
    planned = [t.trial_index for t in sp.plan(protocol, "U1")]
    started = [int(e.trial_index) for e in client.seen if int(e.event) == m.RunEvent.TRIAL_STARTED]
    assert started[:2] == [planned[0], planned[0]], started  # aborted, then run again
    assert sorted(int(r.trial_id) for r in results) == planned  # one result per trial
    assert done.completed == done.planned == len(planned)
    final = read_lines(out / "U1" / "trials.jsonl")
    assert [r["trial_index"] for r in final] == planned
