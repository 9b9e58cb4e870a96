"""``--source lsl:...`` (graspguide.sources.lsl_inlet) read from REAL pylsl outlets on the
loopback: the samples and the hand-frame contacts against what was pushed, a lost marker,
a stalled stream on the simulated device (the watchdog's motor-off in the device's trace),
a whole `graspguide stream` trial against the same poses replayed from a CSV, and the
errors.

Discovery: as in test_lab_streams.py, liblsl is configured through LSLAPICFG (KnownPeers =
{127.0.0.1}) for this process and the commands it starts (docs/lab-streams.md)."""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import os
import re
import subprocess
import sys
import threading
import time
import uuid

import numpy as np
import pytest
from conftest import TOOLS_DIR
from test_marker_contacts import axis_angle_quat, qmul, recorded_hand, rotation

SCENE3 = os.path.join(TOOLS_DIR, "examples", "scene_paper_3.toml")
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
FINGERS = ("Thumb", "Index", "Middle", "Palm")
# tracker y up -> world z up: +90 degrees about x (graspguide.sources.poses.TrackerConvention)
Y_UP = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
Q_Y_UP = axis_angle_quat([math.pi / 2, 0, 0])


@pytest.fixture(scope="module")
def lsl(tmp_path_factory):
    cfg = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    cfg.write_text(LSL_CONFIG)
    os.environ["LSLAPICFG"] = str(cfg)
    import pylsl

    return pylsl


def _name() -> str:
    return f"GGHand{os.getpid()}x{uuid.uuid4().hex[:8]}"


def _env() -> dict:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


def labels_for(k: int, style: str = "plain") -> list[str]:
    if style == "plain":
        body = [f"Hand_{a}" for a in "XYZ"] + [f"Hand_Q{a}" for a in "WXYZ"]
        return body + [f"{m}_{a}" for m in FINGERS[:k] for a in "XYZ"]
    # other spellings an app uses: dots, Pos/Rot words, a subject prefix
    body = [f"hand.pos.{a.lower()}" for a in "XYZ"] + [f"Hand Rot{a}" for a in "WXYZ"]
    return body + [f"Subject1:{m}_{a}" for m in FINGERS[:k] for a in "XYZ"]


def mocap_outlet(lsl, name, labels, unit="m", fmt=None, rate=100.0):
    info = lsl.StreamInfo(name, "MoCap", len(labels), rate, fmt or lsl.cf_float32, f"{name}-id")
    chs = info.desc().append_child("channels")
    for label in labels:
        ch = chs.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
        ch.append_child_value("type", "Position")
    return lsl.StreamOutlet(info)


def tracker_rows(hand, k: int, y_up_mm: bool) -> np.ndarray:
    """The samples an app pushes: body x, y, z, qw, qx, qy, qz, then the markers, in the
    tracker's convention (world as is, or millimetres with y up)."""
    rows = []
    for i in range(len(hand["t"])):
        q, p, m = hand["quat"][i], hand["pos"][i], hand["markers"][i][:k]
        if y_up_mm:  # world -> tracker: p_t = M^T p_w, q_t = conj(q_M) q_w q_M
            p = Y_UP.T @ p * 1000
            m = m @ Y_UP * 1000
            q = qmul(qmul(Q_Y_UP * [1, -1, -1, -1], q), Q_Y_UP)
        rows.append(np.concatenate([p, q, m.ravel()]))
    return np.array(rows)


def expected_from(row: np.ndarray, k: int, y_up_mm: bool):
    """(quat, contacts) of one pushed row, converted back independently."""
    p, q, m = row[:3], row[3:7] / np.linalg.norm(row[3:7]), row[7 : 7 + 3 * k].reshape(k, 3)
    if y_up_mm:
        p, m = Y_UP @ p / 1000, m @ Y_UP.T / 1000
        q = qmul(qmul(Q_Y_UP, q), Q_Y_UP * [1, -1, -1, -1])
    return q, (m - p) @ rotation(q)


def push_all(outlet, rows, lsl, dt=0.01):
    t0 = lsl.local_clock()
    for i, row in enumerate(rows):
        outlet.push_sample([float(x) for x in row], t0 + i * dt)


@pytest.mark.parametrize(
    "k,y_up_mm,style", [(3, False, "plain"), (4, True, "spelled")], ids=["3-world", "4-mm-yup"]
)
def test_samples_and_contacts_equal_what_was_pushed(lsl, k, y_up_mm, style):
    from graspguide.sources.source_spec import open_source

    hand = recorded_hand(seed=k, duration=1.0, k=k)
    rows = tracker_rows(hand, k, y_up_mm).astype(np.float32)
    name = _name()
    outlet = mocap_outlet(lsl, name, labels_for(k, style), "mm" if y_up_mm else "m")
    markers = ";".join(FINGERS[:k])
    src = open_source(
        f"lsl:name={name},markers={markers},tol_mm=0,newest=0,wait=10,end=5",
        tracker="mm/y/right/xyzw" if y_up_mm else None,
    )
    assert src.live and not src.simulated and src.convention.units == ("mm" if y_up_mm else "m")
    push_all(outlet, rows, lsl)
    got = list(itertools.islice(iter(src), len(rows)))
    assert len(got) == len(rows)
    for i, (t_s, quat, contacts) in enumerate(got):
        q, c = expected_from(rows[i].astype(float), k, y_up_mm)
        assert t_s == pytest.approx(i * 0.01, abs=1e-4)
        sign = 1 if np.dot(q, quat) > 0 else -1
        np.testing.assert_allclose(np.asarray(quat) * sign, q, atol=1e-9)
        assert contacts is not None  # tol 0: every noisy sample moves
        np.testing.assert_allclose(contacts, c, atol=1e-9)
        # and they are the hand's true contacts within float32 and the noise (< 3 mm)
        assert np.max(np.abs(np.asarray(contacts) - hand["contacts"][i])) < 0.003
    stats = src.stats()
    assert stats["samples"] == stats["poses"] == stats["reruns"] == len(rows)


def _stream_with_losses(lsl, seed: int, columns: slice):
    """3 s of a hand pushed through a real outlet with ``columns`` NaN for 0.1 s (at 0.5 s)
    and for 1 s (at 1.5 s), read with hold=0.205: the losses (short, long), which samples
    are paused (worked out here), the samples read and the source."""
    from graspguide.sources.source_spec import open_source

    hand = recorded_hand(seed=seed, duration=3.0)
    rows = tracker_rows(hand, 3, False)
    t = hand["t"]
    short = (t >= 0.5) & (t < 0.6)
    long_ = (t >= 1.5) & (t < 2.5)
    rows[short | long_, columns] = np.nan
    # paused: last seen more than hold before. The hold falls between two samples:
    # liblsl's clock correction moves the timestamps by microseconds, which at hold = 0.2 s
    # would decide the 20th sample either way
    last_seen = t[int(np.argmax(long_)) - 1]
    paused = long_ & (t - last_seen > 0.205)
    name = _name()
    outlet = mocap_outlet(lsl, name, labels_for(3), fmt=lsl.cf_double64)
    src = open_source(f"lsl:name={name},tol_mm=0,newest=0,hold=0.205,wait=10,end=5")
    src.notice = io.StringIO()
    push_all(outlet, rows, lsl)
    got = list(itertools.islice(iter(src), int(np.sum(~paused))))
    np.testing.assert_allclose([g[0] for g in got], t[~paused], atol=1e-4)
    s = src.stats()
    assert s["pauses"] == 1 and s["paused"] == int(np.sum(paused))
    assert s["held"] == int(np.sum((short | long_) & ~paused))
    return rows, short | long_, paused, got, src


def test_a_lost_marker_holds_then_pauses_then_resumes_without_a_jump(lsl):
    _, lost, paused, got, src = _stream_with_losses(lsl, 7, slice(10, 13))  # Index
    index_at_loss = None
    prev = None
    for (t_s, _, contacts), i in zip(got, np.flatnonzero(~paused)):
        c = np.asarray(contacts)
        if lost[i]:
            if index_at_loss is None:
                index_at_loss = prev[1]
            np.testing.assert_allclose(c[1], index_at_loss, atol=0)  # held, not made up
        else:
            index_at_loss = None
        if prev is not None:  # no jump: the hand moves < 4 mm per sample here
            assert np.max(np.linalg.norm(c - prev, axis=1)) < 0.004, t_s
        prev = c
    text = src.notice.getvalue()
    assert text.count("paused") == 1 and "marker Index lost for more than 0.205 s" in text, text
    assert text.count("resume") == 1, text
    assert src.stats()["body_lost"] == 0


def test_a_lost_rigid_body_holds_its_pose_then_pauses_then_resumes(lsl):
    # the body lost; its markers still stream
    rows, lost, paused, got, src = _stream_with_losses(lsl, 8, slice(0, 7))
    prev_quat = None
    for (_, quat, contacts), i in zip(got, np.flatnonzero(~paused)):
        if lost[i]:
            # the last pose and contacts stand in: a stale pose would misplace the markers
            assert quat == prev_quat and contacts is None  # tol 0: nothing moved, none sent
        else:
            q, c = expected_from(rows[i], 3, False)
            sign = 1 if np.dot(q, quat) > 0 else -1
            np.testing.assert_allclose(np.asarray(quat) * sign, q, atol=1e-9)
            np.testing.assert_allclose(contacts, c, atol=1e-9)
        prev_quat = quat
    text = src.notice.getvalue()
    assert text.count("paused") == 1 and "rigid body Hand lost for more than 0.205 s" in text
    assert text.count("resume") == 1 and "rigid body Hand and every marker seen again" in text
    assert src.stats()["body_lost"] == int(np.sum(lost))


def us_after(later: int, earlier: int) -> int:
    d = (later - earlier) % (1 << 32)
    return d - (1 << 32) if d >= 1 << 31 else d


class _Poses:
    """A session log that keeps each POSE's timestamp (run_stream's ``log``)."""

    def __init__(self):
        self.t_us: list[int] = []

    def pose(self, t_us, t_s, quat, has_contacts):
        self.t_us.append(t_us)

    def telemetry(self, tel):
        pass

    def result(self, r):
        pass


class _StartOn:
    """An observer that starts the publisher when the trial starts (the device is ready)."""

    def __init__(self, thread: threading.Thread):
        self.thread = thread

    def on_event(self, name, **fields):
        if name == "trial_start":
            self.thread.start()

    def on_telemetry(self, *args):
        pass


def _aimed(scene, wrench, duration, seed):
    from graspguide.sources.poses import SyntheticSource

    return list(
        SyntheticSource(rate=100, duration=duration, seed=seed).aim(
            scene.contacts, wrench, scene.policy, scene.constraints, scene.y_axis
        )
    )


def _rigid_rows(traj, contacts) -> list[list[float]]:
    """Rows of a hand at a fixed place with the scene's contacts as rigid markers."""
    p = np.array([0.3, 0.1, 0.9])
    rows = []
    for _, q, _ in traj:
        m = p + np.asarray(contacts) @ rotation(q).T
        rows.append([*p, *q, *m.ravel()])
    return rows


def test_a_stalled_stream_leaves_the_motors_to_the_watchdog_and_says_so(lsl, tmp_path):
    from graspguide.devices import sim as gsim
    from graspguide.link import client as gd
    from graspguide.link.messages import POSE_WATCHDOG_MS
    from graspguide.protocol.scene_file import load_scene
    from graspguide.sources.source_spec import open_source
    from graspguide.study.stream_session import run_stream

    scene = load_scene(SCENE3)
    wrench = [0.3, -1.2, -0.8, 0, 0, 0]
    rows = _rigid_rows(_aimed(scene, wrench, 5.0, 1)[:100], scene.contacts)  # 1 s, far off
    name = _name()
    outlet = mocap_outlet(lsl, name, labels_for(3), fmt=lsl.cf_double64)
    src = open_source(f"lsl:name={name},wait=10,stall=0.3,end=1.0")
    src.notice = io.StringIO()

    def publish():
        due = time.monotonic()
        for row in rows:
            outlet.push_sample(row)
            due += 0.01
            time.sleep(max(0.0, due - time.monotonic()))
        # then nothing more: the outlet stays, its samples stop

    trace = tmp_path / "motors.csv"
    log = _Poses()
    with gsim.SimulatedDevice(trace=str(trace)) as sim:
        c = gd.DeviceClient(sim)
        c.hello()
        stale0 = c.status().stale_events
        pub = threading.Thread(target=publish)
        try:
            summary = run_stream(c, scene, wrench, src, 1, False, log, observers=[_StartOn(pub)])
        finally:
            if pub.is_alive():
                pub.join()
        st = c.status()
        c.stop()
    assert summary["trial_result"] is None and summary["sent"] == len(log.t_us) > 80
    assert st.stale_events == stale0 + 1  # the device's watchdog fired, once
    with open(trace, newline="") as f:
        trace_rows = [(int(r[0]), [int(x) for x in r[1:]]) for r in list(csv.reader(f))[1:]]
    offs = [
        t
        for (t, pwm), (_, before) in zip(trace_rows[1:], trace_rows)
        if any(before) and not any(pwm)
    ]
    assert offs, trace_rows[-5:]
    latency_ms = us_after(offs[-1], log.t_us[-1]) / 1000
    assert POSE_WATCHDOG_MS - 1 <= latency_ms <= POSE_WATCHDOG_MS + 20, latency_ms
    text = src.notice.getvalue()
    assert text.count("stalled for") == 1, text
    assert (
        f"no POSE sent; the device's watchdog turns the motors off {POSE_WATCHDOG_MS} ms after "
        "the last POSE"
    ) in text
    assert "no sample for 1 s: the source ends" in text
    assert src.stats()["stalls"] == 1


RESULT = re.compile(r"trial 1: (success|failure) completion_s=([\d.]+) first_entry_s=([-\d.]+)")


def _result(out: str):
    m = RESULT.search(out)
    assert m, out
    return m.group(1), float(m.group(2)), float(m.group(3))


def test_a_stream_trial_from_lsl_matches_the_same_poses_replayed(lsl, tmp_path, report_figure):
    from graspguide.protocol.scene_file import load_scene

    scene = load_scene(SCENE3)
    wrench = [0.3, -1.2, -0.8, 0, 0, 0]
    traj = _aimed(scene, wrench, 3.0, 2)
    rows = _rigid_rows(traj, scene.contacts)
    name, ours = _name(), _name()
    outlet = mocap_outlet(lsl, name, labels_for(3), fmt=lsl.cf_double64)
    base = ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH]
    proc = subprocess.Popen(
        [sys.executable, "-m", "graspguide", "stream", *base]
        + ["--source", f"lsl:name={name},wait=20,end=3", "--lsl", ours, "--lsl-wait", "30"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
        cwd=tmp_path,
    )
    try:
        # the command's own marker stream says when its trial starts
        marks = lsl.StreamInlet(lsl.resolve_byprop("name", f"{ours}-Markers", 1, 20)[0])
        tel = lsl.StreamInlet(lsl.resolve_byprop("name", f"{ours}-Telemetry", 1, 20)[0])
        marks.open_stream(20)
        tel.open_stream(20)
        end = time.monotonic() + 30
        while time.monotonic() < end:
            m, _ = marks.pull_sample(timeout=0.1)
            if m and json.loads(m[0])["event"] == "trial_start":
                break
        else:
            pytest.fail("no trial_start marker")
        due = time.monotonic()
        for row in rows:
            outlet.push_sample(row)
            due += 0.01
            time.sleep(max(0.0, due - time.monotonic()))
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    live = _result(out)

    csv_path = tmp_path / "same.csv"
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            ["t_s", "qw", "qx", "qy", "qz"]
            + [f"{n}_{a}" for n in ("thumb", "index", "middle") for a in "xyz"]
        )
        for t_s, q, _ in traj:
            w.writerow([t_s, *q, *np.asarray(scene.contacts).ravel()])
    done = subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", *base, "--source", f"replay:{csv_path}"],
        capture_output=True,
        text=True,
        env=_env(),
        cwd=tmp_path,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    replayed = _result(done.stdout)
    report_figure(
        "lsl trial vs replay (completion_s, first_entry_s)",
        f"lsl {live[1]:.3f}, {live[2]:.3f}; replay {replayed[1]:.3f}, {replayed[2]:.3f}",
    )
    assert live[0] == replayed[0] == "success", (live, replayed)
    # within one 10 ms frame (the hold ends on one POSE or the next, by a ms of jitter)
    assert abs(live[1] - replayed[1]) <= 0.012, (live, replayed)
    assert abs(live[2] - replayed[2]) <= 0.012, (live, replayed)


def test_a_missing_channel_names_what_was_asked_and_found(lsl):
    from graspguide.sources.poses import SourceError
    from graspguide.sources.source_spec import open_source

    name = _name()
    labels = [x for x in labels_for(3) if x != "Index_Z"]
    _outlet = mocap_outlet(lsl, name, labels)
    with pytest.raises(SourceError) as e:
        open_source(f"lsl:name={name},wait=10")
    text = str(e.value)
    assert "no channel Index_Z" in text and "markers=Thumb;Index;Middle" in text
    assert "Hand_QW, Hand_QX" in text and "Middle_Z" in text  # the labels found
    with pytest.raises(SourceError, match="no channel Wrist_X, Wrist_Y, Wrist_Z, Wrist_QW"):
        open_source(f"lsl:name={name},wait=10,body=Wrist")
    # the rigid body alone is enough without markers
    src = open_source(f"lsl:name={name},wait=10,markers=none")
    assert src.tracking.contacts is None
    del _outlet


def test_no_stream_found_lists_what_is_seen(lsl):
    from graspguide.sources.poses import SourceError
    from graspguide.sources.source_spec import open_source

    seen = _name()
    _outlet = mocap_outlet(lsl, seen, labels_for(3))
    with pytest.raises(SourceError) as e:
        open_source(f"lsl:name={_name()},wait=0.5")
    text = str(e.value)
    assert "no stream with name=" in text and "within 0.5 s" in text
    assert f"name={seen} type=MoCap source_id={seen}-id" in text, text
    del _outlet


@pytest.mark.parametrize(
    "spec,message",
    [
        ("nmae=Hand", "bad key 'nmae=Hand' (did you mean \"name\"?)"),
        ("name=Hand,tol=1", '(did you mean "tol_mm"?)'),
        ("hold=-1", "hold must be in 0..60"),
        ("tol_mm=abc", "tol_mm must be a number"),
        ("markers=Thumb;Index", "markers must name 3 or 4 markers"),
        ("markers=Hand;Index;Middle", "distinct names"),
        ("newest=maybe", "newest must be 1 or 0"),
        ("stall=2,end=1", "end (1 s) must not be shorter than stall (2 s)"),
        ("name=It's", "must not contain quotes"),
        ("name=A,name=B", "name is given twice"),
    ],
)
def test_bad_spec_keys_are_clear_errors(spec, message):
    from graspguide.sources.lsl_inlet import parse_spec
    from graspguide.sources.poses import SourceError

    with pytest.raises(SourceError) as e:
        parse_spec(spec)
    assert message in str(e.value)


def test_cli_lists_streams_and_refuses_a_missing_stream(lsl, tmp_path):
    name = _name()
    _outlet = mocap_outlet(lsl, name, labels_for(3))
    listed = subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", "--source", "lsl:wait=2", "--list"],
        capture_output=True,
        text=True,
        env=_env(),
        cwd=tmp_path,
        timeout=60,
    )
    assert listed.returncode == 0, listed.stderr
    header, *lines = listed.stdout.splitlines()
    assert header.split() == ["name", "type", "source_id", "channels", "rate_hz", "hostname"]
    assert any(line.split()[:5] == [name, "MoCap", f"{name}-id", "16", "100"] for line in lines), (
        listed.stdout
    )
    missing = subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", "--source", f"lsl:name={_name()},wait=0.3"]
        + ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH],
        capture_output=True,
        text=True,
        env=_env(),
        cwd=tmp_path,
        timeout=60,
    )
    assert missing.returncode == 2 and "no stream with name=" in missing.stderr, missing.stderr
    no_port = subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", "--source", "synthetic"]
        + ["--scene", SCENE3, "--wrench", WRENCH],
        capture_output=True,
        text=True,
        env=_env(),
        cwd=tmp_path,
        timeout=60,
    )
    assert no_port.returncode == 2
    assert "the following arguments are required: --port/-p" in no_port.stderr
    del _outlet
