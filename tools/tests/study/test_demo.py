"""`graspguide demo` end to end on a tiny protocol (tables, figure, kill and resume), the
pipelined closed loop against lockstep, and the client's fast codecs against the
reference ones. Everything here is simulated."""

from __future__ import annotations

import collections
import io
import json
import os
import random
import signal
import struct
import subprocess
import sys
import time

from conftest import subprocess_env

from graspguide.link import client as dv
from graspguide.link import codec
from graspguide.link import messages as m
from graspguide.protocol import study_protocol as pf
from graspguide.sources.trial_sources import open_runner_source
from graspguide.study import runner as rn
from graspguide.study.pose_loop import PipelinedPoses, PoseLoop, TrialOverrun, pipeline_window
from graspguide.study.progress import Progress

TINY = """
[study]
name = "tiny"
seed = 7
participants = 2
pose_rate_hz = 100.0

[trial]
threshold_deg = 3.0
hold_s = 0.5
timeout_s = {timeout}
constraints = "paper"
start_quat = [1.0, 0.0, 0.0, 0.0]

[hand]
units = "m"
y_axis = [0.0, 1.0, 0.0]

[hand.k3]
thumb  = [0.045, 0.045, 0.035]
index  = [0.015, 0.095, 0.040]
middle = [-0.010, 0.100, 0.040]

[conditions]
modalities = ["F+C", "Fperp+C", "F+V", "Fperp+V"]
contact_counts = [3]

[wrenches]
count = 2
single_motor = 1

[familiarization]
trials = 0
"""


def tiny_protocol(tmp_path, timeout=15.0):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY.format(timeout=timeout))
    return str(path), pf.load_protocol(str(path))


def demo_cmd(protocol, out, *extra):
    return [
        sys.executable,
        "-m",
        "graspguide",
        "demo",
        "--protocol",
        protocol,
        "--out",
        str(out),
        "--participants",
        "2",
        *extra,
    ]


def records(path):
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f]


KEYS = (
    "trial_index",
    "session",
    "modality",
    "wrench_id",
    "success",
    "completion_s",
    "first_entry_s",
    "final_error_deg",
    "poses",
)


def outcome(out, pid):
    return [[r[k] for k in KEYS] for r in records(out / pid / "trials.jsonl")]


# --------------------------------------------------------------------------------------
# graspguide demo
# --------------------------------------------------------------------------------------
def test_demo_prints_tables_and_writes_figure(tmp_path):
    protocol, proto = tiny_protocol(tmp_path)
    out = tmp_path / "study"
    p = subprocess.run(
        demo_cmd(protocol, out, "--jobs", "2"),
        env=subprocess_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 0, p.stdout + p.stderr
    assert "SIMULATED" in p.stdout
    assert "Table I" in p.stdout and "Table II" in p.stdout
    assert "repeated-measures ANOVA" in p.stdout
    assert "The paper's Tables I-II beside this study (simulated)" in p.stdout
    # A tiny study may not support every reading; each is then said, never left out.
    assert "RM ANOVA: F(3, " in p.stdout or "Not computed, trial-level statistics" in p.stdout
    assert "Contacts x modality" in p.stdout or "Not computed, mixed model" in p.stdout
    names = ("figure4.png", "figure4.svg", "report.md", "table1.csv", "table2.csv")
    for name in (*names, "trials.png", "trials.svg", "paper_vs_study.csv"):
        assert (out / "analysis" / name).stat().st_size > 0, name
    assert "SIMULATED" in (out / "analysis" / "report.md").read_text().upper()
    planned = len(pf.plan(proto, "U1"))
    for pid in ("U1", "U2"):
        recs = records(out / pid / "trials.jsonl")
        assert [r["trial_index"] for r in recs] == list(range(1, planned + 1))
        assert all(r["simulated"] for r in recs)
    # a completed study run again is only analysed again
    p2 = subprocess.run(
        demo_cmd(protocol, out), env=subprocess_env(), capture_output=True, text=True, timeout=120
    )
    assert p2.returncode == 0, p2.stderr
    assert "is complete" in p2.stdout and "analysing it again" in p2.stdout
    assert "Table I" in p2.stdout
    assert len(records(out / "U1" / "trials.jsonl")) == planned


def test_demo_killed_mid_study_resumes_every_trial_exactly_once(tmp_path):
    protocol, proto = tiny_protocol(tmp_path)
    out = tmp_path / "study"
    planned = len(pf.plan(proto, "U1"))
    trials = out / "U1" / "trials.jsonl"
    proc = subprocess.Popen(
        demo_cmd(protocol, out, "--jobs", "1"),
        env=subprocess_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if trials.exists() and trials.read_bytes().count(b"\n") >= 2:
                break
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.01)
        else:
            raise AssertionError("no trial completed within 60 s")
        os.killpg(proc.pid, signal.SIGKILL)  # the demo, its runners, their devices
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    killed = trials.read_bytes()
    n_killed = killed.count(b"\n")
    assert 2 <= n_killed < planned
    assert (
        not (out / "U2" / "trials.jsonl").exists()
        or (out / "U2" / "trials.jsonl").read_bytes().count(b"\n") < planned
    )
    p = subprocess.run(
        demo_cmd(protocol, out), env=subprocess_env(), capture_output=True, text=True, timeout=120
    )
    assert p.returncode == 0, p.stdout + p.stderr
    assert "resuming" in p.stdout and "Table I" in p.stdout
    assert trials.read_bytes().startswith(killed)  # nothing rewritten
    for pid in ("U1", "U2"):
        idx = [r["trial_index"] for r in records(out / pid / "trials.jsonl")]
        assert sorted(idx) == list(range(1, planned + 1)) and len(set(idx)) == len(idx)
        assert sorted(os.listdir(out / pid / "frames")) == [
            f"trial-{i:04d}.csv" for i in range(1, planned + 1)
        ]
    # ... and gives what an uninterrupted study gives
    once = tmp_path / "once"
    p = subprocess.run(
        demo_cmd(protocol, once), env=subprocess_env(), capture_output=True, text=True, timeout=120
    )
    assert p.returncode == 0, p.stderr
    for pid in ("U1", "U2"):
        assert outcome(out, pid) == outcome(once, pid)


def test_demo_usage_errors(tmp_path):
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "graspguide",
            "demo",
            "--protocol",
            str(tmp_path / "none.toml"),
            "--out",
            str(tmp_path / "o"),
        ],
        env=subprocess_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2 and "graspguide demo: error:" in p.stderr
    protocol, _ = tiny_protocol(tmp_path)
    p = subprocess.run(
        demo_cmd(protocol, tmp_path / "o", "--source", "synthetic"),
        env=subprocess_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2 and "virtual participant" in p.stderr


# --------------------------------------------------------------------------------------
# Pipelined closed loop == lockstep
# --------------------------------------------------------------------------------------
def _run(protocol, out, pid, pipeline):
    from graspguide.devices.sim import SimulatedDevice

    with SimulatedDevice(virtual_clock=True, start=True) as dev:
        client = dv.DeviceClient(dev)
        source = open_runner_source("participant:reaction_time_s=0.21", protocol, pid)
        runner = rn.StudyRunner(
            protocol,
            pid,
            str(out),
            source,
            client,
            True,
            progress=Progress(out=io.StringIO(), tty=False),
            pipeline=pipeline,
            err=io.StringIO(),
        )
        window = runner._window(True)
        runner.run()
    return runner, window


def test_pipelined_and_lockstep_runs_give_identical_trials(tmp_path):
    _, protocol = tiny_protocol(tmp_path, timeout=20.0)
    lock, w_lock = _run(protocol, tmp_path / "lock", "U2", pipeline=1)
    pipe, w_pipe = _run(protocol, tmp_path / "pipe", "U2", pipeline=None)
    assert w_lock == 1
    assert w_pipe == 20  # reaction time 0.21 s at 100 Hz: 21 - 1 poses in flight
    assert pipe.pipeline_fallbacks == 0
    strip = ("wall_s", "recorded_at")
    a = [
        {k: v for k, v in r.items() if k not in strip}
        for r in records(tmp_path / "lock" / "U2" / "trials.jsonl")
    ]
    b = [
        {k: v for k, v in r.items() if k not in strip}
        for r in records(tmp_path / "pipe" / "U2" / "trials.jsonl")
    ]
    assert a == b and len(a) == len(pf.plan(protocol, "U2"))
    frames = sorted(os.listdir(tmp_path / "lock" / "U2" / "frames"))
    for name in frames:  # every frame, byte for byte
        assert (tmp_path / "lock" / "U2" / "frames" / name).read_bytes() == (
            tmp_path / "pipe" / "U2" / "frames" / name
        ).read_bytes(), name


def test_pipeline_window_only_for_the_virtual_participant():
    from graspguide.participant.model import VirtualParticipant

    vp = VirtualParticipant.from_spec("", 1)
    assert pipeline_window(vp, 100.0) == 20
    assert pipeline_window(VirtualParticipant.from_spec("reaction_time_s=0.05", 1), 100.0) == 4
    assert pipeline_window(VirtualParticipant.from_spec("reaction_time_s=0.015", 1), 100.0) == 1
    assert pipeline_window(object(), 100.0) == 1


class _AnsweringClient:
    """Answers every POSE of a batch at once with a TELEMETRY of a running trial, and
    logs when each batch was written."""

    timeout = 0.1

    def __init__(self, log):
        self.log = log
        self.trial_results = collections.deque()
        self.written = 0

    def pose_batch(self, poses, timeout=None, on_written=None):
        self.written += len(poses)
        self.log.append(("written", self.written))
        if on_written is not None:
            on_written()
        flags = m.TELEMETRY_FLAG_TRIAL_RUNNING
        return [m.Telemetry(host_time_us=t, pwm=(1, 2, 3, 0), flags=flags) for t, _ in poses]

    def drain(self, timeout=0.0):
        return 0


class _StillHand:
    def act(self, t):
        return (1.0, 0.0, 0.0, 0.0)

    def feel(self, t, pwm):
        pass


def test_pose_loop_writes_every_frame_once_in_order_while_the_next_batch_is_out():
    log = []
    loop = PoseLoop(
        _AnsweringClient(log),
        virtual_clock=True,
        limit_s=0.5,
        on_frames=lambda first, stamped, tels: log.append(("frames", first, len(tels))),
    )
    try:
        loop.run(PipelinedPoses(_StillHand(), 100.0, 3, 8, RuntimeError))
    except TrialOverrun as e:
        assert round(e.t_s, 6) == 0.51  # the first pose past the limit
    else:
        raise AssertionError("the trial should have run past its limit")
    # Batch b's frames are written once batch b + 1 is out; the last batch's (4 frames:
    # 0.48 .. 0.51 s) on the way out, before run() raises: every frame once, in order.
    expected = [("written", 8)]
    for b in range(1, 7):
        expected += [("written", 8 * (b + 1)), ("frames", 8 * (b - 1), 8)]
    expected.append(("frames", 48, 4))
    assert log == expected
    assert loop.frames == 52


# --------------------------------------------------------------------------------------
# The client's fast codecs == the reference ones
# --------------------------------------------------------------------------------------
def test_fast_pose_encoding_matches_the_reference():
    rnd = random.Random(5)
    specials = [0.0, -0.0, 1.0, float("inf"), float("nan"), 1e-45, 3.4e38]
    for _ in range(3000):
        q = [rnd.choice(specials + [rnd.uniform(-2, 2)] * 4) for _ in range(4)]
        seq, t = rnd.randrange(65536), rnd.randrange(2**32)
        ref = codec.encode_message(m.Pose(host_time_us=t, quat_wxyz=tuple(q)), seq)
        assert dv.encode_pose_fast(seq, t, q) == ref
    assert dv.encode_pose_fast(1, 0, [1e300, 0, 0, 0]) is None  # generic path: +inf


class _Chunks:
    """A transport replaying fixed read chunks."""

    name = "chunks"

    def __init__(self, chunks):
        self.chunks = list(chunks)

    def write(self, data):
        pass

    def read(self, n, timeout):
        return self.chunks.pop(0) if self.chunks else b""

    def close(self):
        pass


def test_fast_frame_path_matches_the_byte_wise_parser(monkeypatch):
    rnd = random.Random(9)
    seq = codec.SequenceCounter()
    frames = []
    for i in range(300):
        kind = rnd.random()
        if kind < 0.6:
            msg = m.Telemetry(
                host_time_us=rnd.randrange(2**32),
                error_deg=rnd.uniform(0, 90),
                alpha=rnd.uniform(0, 200),
                pwm=tuple(rnd.randrange(256) for _ in range(4)),
                flags=rnd.choice([0, 2, 3]),
                iterations=rnd.randrange(256),
            )
            wire = codec.encode_message(msg, seq.next())
        elif kind < 0.75:
            wire = codec.encode_message(
                m.TrialResult(trial_id=i, success=True, completion_s=1.5), seq.next()
            )
        elif kind < 0.85:  # a bad enum value
            raw = bytearray(
                codec.cobs_decode(
                    codec.encode_message(m.Telemetry(host_time_us=i), seq.next())[:-1]
                )
            )
            raw[4 + 17] = 200  # solver_status
            body = bytes(raw[:-2])
            raw[-2:] = struct.pack("<H", codec.crc16(body))
            wire = codec.cobs_encode(bytes(raw)) + b"\0"
        elif kind < 0.95:  # a corrupted byte
            wire = bytearray(codec.encode_message(m.Telemetry(host_time_us=i), seq.next()))
            wire[rnd.randrange(len(wire) - 1)] ^= 1 << rnd.randrange(8)
            wire = (
                bytes(wire).replace(b"\0", b"\1", wire.count(0) - 1)
                if wire.count(0) > 1
                else bytes(wire)
            )
        else:
            wire = b"\0\0"  # idle delimiters
        frames.append(wire)
    stream = b"".join(frames)
    cuts = sorted(rnd.sample(range(1, len(stream)), 120))
    chunks = [stream[a:b] for a, b in zip([0] + cuts, cuts + [len(stream)])]

    def drain(client):
        for _ in range(len(chunks)):
            client._pump(0.0)
        return (
            [(it.seq, it.message) for it in client._inbox],
            client.counters(),
            client.parse_counts,
        )

    fast = drain(dv.DeviceClient(_Chunks(chunks), send_idle_delimiter=False))
    monkeypatch.setattr(dv.DeviceClient, "_fast_frame", lambda self, enc, now: False)
    ref = drain(dv.DeviceClient(_Chunks(chunks), send_idle_delimiter=False))
    assert fast == ref
    assert len(fast[0]) > 150
