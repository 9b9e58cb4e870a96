"""The LSL outlets (graspguide.sources.lab_streams) received by a REAL LSL inlet on the
loopback interface: `graspguide stream --lsl` against the simulated device, compared with
its own session log, and the streams' metadata.

Discovery: a container often has no multicast, so liblsl is configured through LSLAPICFG
(a temporary lsl_api.cfg with KnownPeers = {127.0.0.1}: unicast to this machine), for
this process and for the command it starts (docs/lab-streams.md)."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
import time
import uuid

import numpy as np
import pytest
from conftest import TOOLS_DIR

_TOOLS = TOOLS_DIR
SCENE3 = os.path.join(_TOOLS, "examples", "scene_paper_3.toml")
WRENCH = "0.3,-1.2,-0.8"
LSL_CONFIG = """\
[ports]
IPv6 = disable
[lab]
KnownPeers = {127.0.0.1}
ResolveScope = machine
[log]
level = -2
"""


@pytest.fixture(scope="module")
def lsl(tmp_path_factory):
    """pylsl configured for the loopback (before liblsl reads its configuration)."""
    cfg = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    cfg.write_text(LSL_CONFIG)
    os.environ["LSLAPICFG"] = str(cfg)
    import pylsl

    return pylsl


def _name() -> str:
    return f"GGTest{os.getpid()}x{uuid.uuid4().hex[:8]}"


def _resolve(lsl, name: str, timeout_s: float = 20.0):
    found = lsl.resolve_byprop("name", name, 1, timeout_s)
    assert found, f"no LSL stream named {name} found on the loopback in {timeout_s} s"
    return found[0]


def _pull_all(inlet, expected: int, deadline_s: float):
    """Samples until ``expected`` of them or the deadline."""
    samples, stamps = [], []
    end = time.monotonic() + deadline_s
    while len(samples) < expected and time.monotonic() < end:
        chunk, ts = inlet.pull_chunk(timeout=0.2)
        samples.extend(chunk)
        stamps.extend(ts)
    return samples, stamps


def _pull_until_closed(lsl, inlets, deadline_s: float):
    """Each inlet's (samples, timestamps), read in turn until all their outlets are closed
    (inlets made with recover=False) or the deadline."""
    got: list[tuple[list, list]] = [([], []) for _ in inlets]
    open_ = set(range(len(inlets)))
    end = time.monotonic() + deadline_s
    while open_ and time.monotonic() < end:
        for i in sorted(open_):
            try:
                chunk, ts = inlets[i].pull_chunk(timeout=0.05)
            except lsl.util.LostError:
                open_.discard(i)
                continue
            got[i][0].extend(chunk)
            got[i][1].extend(ts)
    return got


def test_stream_lsl_matches_the_session_log(lsl, tmp_path):
    from graspguide.link.messages import ErrorCode
    from graspguide.sources.lab_streams import TELEMETRY_CHANNELS

    name = _name()
    folder = tmp_path / "session"
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "graspguide", "stream", "--port", "sim", "--virtual-clock"]
        + ["--scene", SCENE3, "--wrench", WRENCH, "--source", "synthetic:rate=240,duration=10"]
        + ["--log", str(folder), "--trial-id", "23", "--lsl", name, "--lsl-wait", "60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,  # not tools/: the installed graspguide, with its _core
    )
    try:
        tel_info = _resolve(lsl, f"{name}-Telemetry")
        mark_info = _resolve(lsl, f"{name}-Markers")
        tel_inlet = lsl.StreamInlet(tel_info, max_buflen=360, recover=False)
        mark_inlet = lsl.StreamInlet(mark_info, max_buflen=360, recover=False)
        tel_inlet.open_stream(20)
        mark_inlet.open_stream(20)
        # both read while the command runs, until it closes its outlets (a lost
        # inlet made with recover=False gives nothing more)
        (samples, stamps), (markers, _) = _pull_until_closed(lsl, [tel_inlet, mark_inlet], 120.0)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "trial 23: success" in out, out
    assert "no LSL recorder connected" not in err, err

    rows = list(csv.DictReader(open(folder / "telemetry.csv")))
    poses = list(csv.DictReader(open(folder / "poses.csv")))
    results = [json.loads(line) for line in open(folder / "results.jsonl")]

    # every TELEMETRY of the log, in order, value for value (float32 on the wire)
    assert len(rows) > 100 and len(samples) == len(rows)
    labels = [c[0] for c in TELEMETRY_CHANNELS]
    got = np.asarray(samples, dtype=np.float32)
    want = np.asarray(
        [
            [
                float(r["error_deg"]),
                float(r["alpha"]),
                *(float(r[f"pwm{i}"]) for i in range(4)),
                float(ErrorCode[r["solver_status"].upper()]),
                float(p["t_s"]),
            ]
            for r, p in zip(rows, poses)
        ],
        dtype=np.float32,
    )
    assert got.shape == (len(rows), len(labels))
    np.testing.assert_array_equal(got, want)
    assert all(b >= a for a, b in zip(stamps, stamps[1:]))  # LSL time follows the order

    events = [json.loads(m[0]) for m in markers]
    assert [e["event"] for e in events] == [
        "session_start",
        "trial_start",
        "trial_end",
        "study_end",
    ]
    trial = results[0]
    start, end_ = events[1], events[2]
    assert start["trial_index"] == 23 == end_["trial_index"]
    assert end_["success"] is trial["success"] is True
    assert end_["completion_s"] == pytest.approx(trial["completion_s"], abs=0)
    assert end_["final_error_deg"] == pytest.approx(trial["final_error_deg"], abs=0)
    assert events[0]["threshold_deg"] == json.load(open(folder / "scene.json"))["threshold_deg"]
    assert events[3]["exit_code"] == 0 == results[1]["exit_code"]


def test_outlets_describe_channels_and_keep_source_id(lsl):
    from graspguide.sources.lab_streams import TELEMETRY_CHANNELS, LabStreams, source_id

    name = _name()
    with LabStreams(name, participant="U3", session="s2", nominal_rate_hz=100.0, simulated=True):
        info = lsl.StreamInlet(_resolve(lsl, f"{name}-Telemetry")).info(timeout=10)
        markers = _resolve(lsl, f"{name}-Markers")
    assert info.nominal_srate() == 100.0 and info.type() == "GraspGuide"
    assert info.channel_format() == lsl.cf_float32
    assert info.source_id() == source_id(name, "U3", "s2", "telemetry")
    ch = info.desc().child("channels").child("channel")
    described = []
    while not ch.empty():
        described.append((ch.child_value("label"), ch.child_value("unit"), ch.child_value("type")))
        ch = ch.next_sibling()
    assert tuple(described) == TELEMETRY_CHANNELS
    assert info.desc().child("acquisition").child_value("simulated") == "true"
    assert markers.type() == "Markers" and markers.channel_format() == lsl.cf_string
    # a restarted run of the same participant and session: the same source_id (re-link)
    with LabStreams(name, participant="U3", session="s2"):
        again = _resolve(lsl, f"{name}-Markers")
    assert again.source_id() == markers.source_id() == source_id(name, "U3", "s2", "markers")
    assert source_id(name, "U4", "s2", "markers") != markers.source_id()


def test_observer_interface_pushes_in_order(lsl):
    from graspguide.records.events import TrialObserver
    from graspguide.sources.lab_streams import LabStreams

    name = _name()
    with LabStreams(name) as streams:
        assert isinstance(streams, TrialObserver)
        tel = lsl.StreamInlet(_resolve(lsl, f"{name}-Telemetry"))
        mark = lsl.StreamInlet(_resolve(lsl, f"{name}-Markers"))
        tel.open_stream(10)
        mark.open_stream(10)
        assert streams.wait_for_consumers(10)
        sent = [
            (i / 100, 10.0 - i, 0.5 * i, [70 + i, 0, 255, 3][: 3 + i % 2], i % 2) for i in range(7)
        ]
        for t_s, e, a, pwm, status in sent:
            streams.on_telemetry(t_s, e, a, pwm, status)
        streams.on_event("trial_end", trial_index=4, success=False, final_error_deg=math.nan)
        streams.on_event("note", text='a "quoted" note')
        samples, _ = _pull_all(tel, len(sent), 10.0)
        markers, _ = _pull_all(mark, 2, 10.0)
    want = [
        [e, a, *[float(x) for x in pwm], *[0.0] * (4 - len(pwm)), float(status), t_s]
        for t_s, e, a, pwm, status in sent
    ]
    np.testing.assert_array_equal(np.asarray(samples, np.float32), np.asarray(want, np.float32))
    assert [json.loads(m[0]) for m in markers] == [
        {"event": "trial_end", "trial_index": 4, "success": False, "final_error_deg": None},
        {"event": "note", "text": 'a "quoted" note'},
    ]


def test_missing_liblsl_is_a_clear_error(tmp_path):
    # pylsl's own failure when liblsl cannot be loaded is a RuntimeError at import
    fake = tmp_path / "pylsl"
    fake.mkdir()
    (fake / "__init__.py").write_text(
        "raise RuntimeError('LSL binary library file was not found.')\n"
    )
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    p = subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", "--port", "sim", "--virtual-clock"]
        + ["--scene", SCENE3, "--wrench", WRENCH, "--source", "synthetic", "--lsl"],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=tmp_path,
    )
    assert p.returncode == 1, p.stderr
    assert "cannot load pylsl/liblsl" in p.stderr and "PYLSL_LIB" in p.stderr, p.stderr
    assert "trial 1" not in p.stdout  # no trial ran without its streams


def test_bad_stream_name_is_refused():
    from graspguide.sources.lab_streams import LabStreams, LabStreamsUsageError

    with pytest.raises(LabStreamsUsageError, match="--lsl name"):
        LabStreams("a/b")


def test_interfaces_up_here():
    # this machine reaches its own streams (the tests above): the loopback is up
    from graspguide.sources.lab_streams import interfaces_up, network_problem

    assert "lo" in (interfaces_up() or []) and network_problem() is None


@pytest.mark.parametrize(
    "flags, up",
    [({"lo": 0x9, "eth0": 0x1003}, ["eth0", "lo"]), ({"lo": 0x8, "eth0": 0x1002}, [])],
)
def test_no_interface_up_is_a_clear_error(flags, up):
    # the flags an unshared network namespace shows (lo down), without needing one
    from graspguide.sources.lab_streams import interfaces_up, network_problem

    assert interfaces_up(list(flags), flags.__getitem__) == up
    problem = network_problem(list(flags), flags.__getitem__)
    if up:
        assert problem is None
    else:
        assert problem is not None and "ip link set lo up" in problem


def test_trial_lsl_matches_the_trial_records(lsl, tmp_path):
    """`graspguide trial --lsl`: one telemetry sample per recorded frame, in order and
    value for value, and a trial_start / trial_end marker pair per trial of trials.jsonl."""
    from conftest import small_protocol_toml

    protocol = tmp_path / "p.toml"
    protocol.write_text(
        small_protocol_toml("lsl", seed=4, participants=1, modalities=("F+V",), wrenches=2)
    )
    name = _name()
    out = tmp_path / "study"
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "graspguide", "trial", "--protocol", str(protocol)]
        + ["--participant", "U1", "--port", "sim", "--source", "participant"]
        + ["--out", str(out), "--lsl", name, "--lsl-wait", "60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    try:
        inlets = [
            lsl.StreamInlet(_resolve(lsl, f"{name}-{kind}"), max_buflen=360, recover=False)
            for kind in ("Telemetry", "Markers")
        ]
        for inlet in inlets:
            inlet.open_stream(20)
        (samples, _), (markers, _) = _pull_until_closed(lsl, inlets, 120.0)
        out_text, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "LSL: publishing" in err and "SIMULATED" in err, err

    trials = [json.loads(line) for line in open(out / "U1" / "trials.jsonl")]
    assert len(trials) == 2, out_text
    rows = []
    for t in trials:
        frames = out / "U1" / "frames" / f"trial-{t['trial_index']:04d}.csv"
        rows.extend(csv.DictReader(open(frames)))
    want = np.asarray(
        [
            [
                float(r["error_deg"]),
                float(r["alpha"]),
                *(float(r[f"pwm{i}"]) for i in range(4)),
                float(r["solver_status"]),  # a number in the trial frames
            ]
            for r in rows
        ],
        dtype=np.float32,
    )
    got = np.asarray(samples, dtype=np.float32)
    assert len(rows) > 100 and got.shape[0] == len(rows)
    np.testing.assert_array_equal(got[:, :7], want)

    events = [json.loads(m[0]) for m in markers]
    kinds = [e["event"] for e in events]
    assert kinds[0] == "session_start" and kinds[-1] == "study_end", kinds
    starts = [e for e in events if e["event"] == "trial_start"]
    ends = [e for e in events if e["event"] == "trial_end"]
    assert [e["trial_index"] for e in starts] == [t["trial_index"] for t in trials]
    assert [(e["trial_index"], e["success"]) for e in ends] == [
        (t["trial_index"], t["success"]) for t in trials
    ]
