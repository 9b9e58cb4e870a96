"""`graspguide device log` on a results log with a damaged record: the device skips the
damaged (torn) slot, and its next run runs that trial again, after the trials already
recorded, so the log holds it out of plan order. The download takes such a log, says which
trial's record was damaged (run again, or not yet), and never refuses a folder because of
it. The fakes are test_hostless_client's scripted device; the device's own behaviour is
tested in test/test_hostless and micropython/tests/test_runner.py."""

from __future__ import annotations

import dataclasses
import io
import json

import pytest
from test_hostless_client import PAPER, REST_S, HostlessFake, hostless_client, outcome

from graspguide.hostless import device_log as dl
from graspguide.hostless import plan_upload as pu
from graspguide.protocol.study_protocol import load_protocol


@pytest.fixture(scope="module")
def paper():
    protocol = load_protocol(PAPER)
    planned = pu.planned_trials(protocol, "U1")
    begin, trials = pu.plan_messages(protocol, "U1", planned, simulated=True, rest_s=REST_S)
    return protocol, planned, begin, trials


def _device(paper, order: list[int], torn: int) -> HostlessFake:
    """A device holding the paper plan and records of the trials at these plan positions,
    in this log order."""
    _, _, begin, trials = paper
    fake = HostlessFake()
    fake.store(begin, trials, 0)
    fake.records = [outcome(trials[p], i) for i, p in enumerate(order)]
    fake.torn = torn
    return fake


def _reindexed(records: list) -> list:
    return [dataclasses.replace(r, index=i) for i, r in enumerate(records)]


def _trial_indices(path) -> list[int]:
    with open(path, encoding="utf-8") as f:
        return [json.loads(line)["trial_index"] for line in f]


def test_a_trial_run_again_after_its_record_was_damaged_is_downloaded_and_named(paper, tmp_path):
    # Plan trials 1..4; record 1 (trial 2) damaged; the next run ran trial 2 again after 4.
    fake = _device(paper, [0, 2, 3, 1], torn=1)
    err = io.StringIO()
    s = dl.download_log(hostless_client(fake), str(tmp_path), err=err)
    assert (s.records, s.total, s.torn_records) == (4, 4, 1)
    assert _trial_indices(tmp_path / "U1" / "trials.jsonl") == [1, 2, 3, 4]
    text = err.getvalue()
    assert "1 torn record(s)" in text and "damaged" in text, text
    assert "trial_index 2 ran again" in text and "device record 3" in text, text
    assert "no record" not in text, text


def test_a_damaged_record_whose_trial_has_not_run_again_is_named(paper, tmp_path):
    fake = _device(paper, [0, 2, 3], torn=1)  # trial 2's record damaged, not run again yet
    err = io.StringIO()
    s = dl.download_log(hostless_client(fake), str(tmp_path), err=err)
    assert (s.records, s.total) == (3, 3)
    text = err.getvalue()
    assert "trial_index 2 has no record" in text, text
    assert "runs it again" in text, text


def test_a_trial_downloaded_before_its_record_was_damaged_keeps_its_first_result(paper, tmp_path):
    fake = _device(paper, [0, 1, 2], torn=0)
    client = hostless_client(fake)
    dl.download_log(client, str(tmp_path), err=io.StringIO())
    path = tmp_path / "U1" / "trials.jsonl"
    first_trial_2 = [json.loads(x) for x in path.read_text().splitlines()][1]
    # Record 1 went bad on the device, and the next run ran trial 2 again after trial 4.
    _, _, _, trials = paper
    rerun = dataclasses.replace(outcome(trials[1], 3), completion_s=33.5, success=True)
    fake.records = _reindexed([fake.records[0], fake.records[2], outcome(trials[3], 2), rerun])
    fake.torn = 1
    err = io.StringIO()
    s = dl.download_log(client, str(tmp_path), err=err)
    assert (s.records, s.new, s.total) == (4, 1, 4)
    lines = [json.loads(x) for x in path.read_text().splitlines()]
    assert [r["trial_index"] for r in lines] == [1, 2, 3, 4]
    assert lines[1] == first_trial_2, "the result downloaded first is kept"
    text = err.getvalue()
    assert "trial_index 2 ran again" in text and "keeps the result downloaded" in text, text


def test_a_result_that_differs_without_a_damaged_record_is_still_refused(paper, tmp_path):
    fake = _device(paper, [0, 1, 2], torn=0)
    client = hostless_client(fake)
    dl.download_log(client, str(tmp_path), err=io.StringIO())
    fake.records[1] = dataclasses.replace(fake.records[1], completion_s=33.5)
    with pytest.raises(dl.DeviceLogError, match="another result"):
        dl.download_log(client, str(tmp_path), err=io.StringIO())


def test_on_the_simulated_device_a_damaged_record_is_run_again_once_and_named(tmp_path, capsys):
    """The real simulated device: a study killed after 3 trials, one bit of its second
    record flipped in the store file, the study resumed on a restarted device: trial 2
    runs again after the trials already recorded, no trial runs twice, and the download
    names it."""
    from test_hostless_study import REST_S as STUDY_REST_S
    from test_hostless_study import _KillAfter, read_lines, short_protocol

    from graspguide.devices.sim import SimulatedDevice
    from graspguide.hostless import runner as hr
    from graspguide.link import client as dv
    from graspguide.link.transport import LinkError
    from graspguide.protocol import study_protocol as sp
    from graspguide.sources.trial_sources import open_runner_source
    from graspguide.study.progress import Progress

    _, protocol = short_protocol(tmp_path)
    out = tmp_path / "study"
    store = tmp_path / "store.bin"
    quiet = Progress(out=io.StringIO(), tty=False)
    with SimulatedDevice(virtual_clock=True, store=str(store), start=True) as dev:
        client = _KillAfter(dv.DeviceClient(dev, timeout=1.0), dev, 3, 150)
        model = open_runner_source("participant", protocol, "U1").model
        with pytest.raises(LinkError):
            hr.run_hostless(
                protocol,
                "U1",
                client,
                str(out),
                model,
                rest_s=STUDY_REST_S,
                on_trial_result=client.on_result,
                progress=quiet,
                err=io.StringIO(),
            )
    # The second record's slot: after the 8 KiB plan region, 72 bytes a slot.
    data = bytearray(store.read_bytes())
    slot = 8192 + 72
    assert data[slot : slot + 4] == b"GGLR", "the second slot holds a record"
    data[slot + 12] ^= 0x10  # one bit of its trial fields
    store.write_bytes(bytes(data))

    capsys.readouterr()
    with SimulatedDevice(virtual_clock=True, store=str(store), start=True) as dev:
        client = dv.DeviceClient(dev, timeout=1.0)
        client.hello()
        info = client.log_info()
        assert info.torn_records == 1 and info.records >= 2
        model = open_runner_source("participant", protocol, "U1").model
        hr.run_hostless(
            protocol,
            "U1",
            client,
            str(out),
            model,
            rest_s=STUDY_REST_S,
            progress=quiet,
            err=io.StringIO(),
        )
        final_info = client.log_info()
        order = [client.log_read(i).trial_index for i in range(final_info.records)]
    planned = [t.trial_index for t in sp.plan(protocol, "U1")]
    damaged = planned[1]
    assert sorted(order) == sorted(planned), order  # each planned trial once
    assert order.index(damaged) > order.index(planned[2]), order  # run again, later
    final = read_lines(out / "U1" / "trials.jsonl")
    assert [r["trial_index"] for r in final] == sorted(planned)
    text = capsys.readouterr().err  # the download's warning
    assert f"trial_index {damaged} ran again" in text, text
