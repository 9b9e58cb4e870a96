"""`--source natnet:...` against a stand-in Motive on 127.0.0.1 (unicast, real UDP).

The packets are built here with struct from the published NatNet 3.1/4.1 layout (the
NatNet SDK's NatNetClient.py: server info; model definitions; frame of data = frame
number, marker sets, legacy unlabelled markers, rigid bodies (id, position, quaternion
x,y,z,w, marker error, params bit 0 = tracking valid), skeletons, assets (4.1), labelled
markers (id, position, size, params bit 0 = occluded, residual), force plates, devices,
suffix (timecode, timestamp as a double, three 64-bit stamps, 4.x precision timestamp,
params)), not with the decoder under test. The expected world values come from scipy's
Rotation and Motive's stated axes (x right, y up, z towards the viewer), not from
TrackerConvention.
"""

from __future__ import annotations

import csv
import io
import json
import os
import socket
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from conftest import small_protocol_toml, subprocess_env
from scipy.spatial.transform import Rotation

from graspguide.sources.natnet_source import MAX_BAD_PACKETS, parse_spec
from graspguide.sources.poses import SourceError
from graspguide.sources.source_spec import open_source

NAT_CONNECT, NAT_SERVERINFO, NAT_REQUEST_MODELDEF, NAT_MODELDEF, NAT_FRAMEOFDATA = 0, 1, 4, 5, 7
HAND_ID, OTHER_ID, MODEL = 3, 1, 3
MARKER_IDS = [MODEL << 16 | k for k in (1, 2, 3)]
# Motive's y-up frame in this project's world: x_t = x_w, y_t = z_w, z_t = -y_w
WORLD_TO_MOTIVE = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])


def packet(message_id: int, payload: bytes) -> bytes:
    return struct.pack("<HH", message_id, len(payload)) + payload


def server_info(version: tuple[int, int]) -> bytes:
    return packet(NAT_SERVERINFO, b"Motive".ljust(256, b"\0") + bytes([3, 1, 0, 0, *version, 0, 0]))


def model_definitions(version: tuple[int, int], bodies: dict[str, int]) -> bytes:
    out = struct.pack("<I", len(bodies))
    for name, body_id in bodies.items():
        desc = name.encode() + b"\0" + struct.pack("<ii3f", body_id, -1, 0, 0, 0)
        desc += struct.pack("<I", 0)  # no markers: positions, labels (and 4.x names) empty
        out += struct.pack("<I", 1)  # data type 1: rigid body
        if version >= (4, 1):
            out += struct.pack("<I", len(desc))
        out += desc
    return packet(NAT_MODELDEF, out)


def frame(version, number, t, bodies, markers) -> bytes:
    """bodies: (id, pos, quat_xyzw, tracking_valid); markers: (id, pos, occluded)."""
    sized = version >= (4, 1)

    def section(count: int, body: bytes) -> bytes:
        return struct.pack("<I", count) + (struct.pack("<I", len(body)) if sized else b"") + body

    p = struct.pack("<I", number)
    marker_set = b"all\0" + struct.pack("<I", len(markers))
    marker_set += b"".join(struct.pack("<3f", *m[1]) for m in markers)
    p += section(1, marker_set)
    p += section(1, struct.pack("<3f", 0.5, 0.6, 0.7))  # one unlabelled marker
    p += section(
        len(bodies),
        b"".join(
            struct.pack("<I3f4ffh", i, *pos, *q, 0.0002, 1 if valid else 0)
            for i, pos, q, valid in bodies
        ),
    )
    p += section(0, b"")  # skeletons
    if sized:
        p += section(0, b"")  # assets
    p += section(
        len(markers),
        b"".join(
            struct.pack("<I3ffhf", i, *pos, 0.014, 0x01 if occ else 0x04, 0.0003)
            for i, pos, occ in markers
        ),
    )
    p += section(0, b"")  # force plates
    p += section(0, b"")  # devices
    p += struct.pack("<IId3Q", 0, 0, t, 11, 12, 13)
    if version[0] >= 4:
        p += struct.pack("<II", int(t), 0)  # precision timestamp
    p += struct.pack("<h", 0)
    return packet(NAT_FRAMEOFDATA, p)


def f32(values) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float32)]


class Scene:
    """A hand pose and three fingertips in the world, and as Motive streams them."""

    def __init__(self, seed: int, shift: float = 0.0):
        """``shift``: metres the fingertips are moved along the hand's x."""
        rng = np.random.default_rng(seed)
        self.r_world = Rotation.random(random_state=seed)
        self.t_world = rng.uniform(-1, 1, 3) + [0, 0, 1.2]
        self.contacts = [
            [0.06 + shift, 0.03, 0.0],
            [0.07 + shift, -0.02, 0.01],
            [0.05 + shift, -0.05, 0.0],
        ]
        a = WORLD_TO_MOTIVE
        r_motive = Rotation.from_matrix(a @ self.r_world.as_matrix() @ a.T)
        self.pos = f32(a @ self.t_world)
        self.quat_xyzw = f32(r_motive.as_quat())  # scipy's order is x, y, z, w
        markers_world = [self.t_world + self.r_world.apply(c) for c in self.contacts]
        self.markers = [f32(a @ m) for m in markers_world]

    def expected(self):
        """What the streamed (float32) values are in the world: orientation, contacts."""
        a = WORLD_TO_MOTIVE
        r = Rotation.from_matrix(a.T @ Rotation.from_quat(self.quat_xyzw).as_matrix() @ a)
        t = a.T @ np.array(self.pos)
        contacts = [r.inv().apply(a.T @ np.array(m) - t) for m in self.markers]
        return r, contacts

    def frame(self, version, number, t, tracked=True, drop=(), occlude=()):
        bodies = [
            (OTHER_ID, [0.1, 0.2, 0.3], [0.0, 0.0, 0.0, 1.0], True),
            (HAND_ID, self.pos, self.quat_xyzw, tracked),
        ]
        markers = [
            (mid, pos, k in occlude)
            for k, (mid, pos) in enumerate(zip(MARKER_IDS, self.markers))
            if k not in drop
        ]
        return frame(version, number, t, bodies, markers)


class StandIn:
    """A stand-in Motive: answers the connect request (and the model-definition request)
    on its command port, then sends the given packets to the client that connected. An
    item that is a number is a pause of that many seconds; an Event is set when reached;
    a (Event, "wait") pair waits for that event."""

    def __init__(self, version, packets, bodies=None, wait=5.0):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(wait)
        self.port = self.sock.getsockname()[1]
        self.version, self.packets, self.bodies = version, packets, bodies
        self.requests: list[int] = []
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        data, client = self.sock.recvfrom(1 << 16)
        self.requests.append(struct.unpack_from("<H", data)[0])
        self.sock.sendto(server_info(self.version), client)
        if self.bodies is not None:
            data, client = self.sock.recvfrom(1 << 16)
            self.requests.append(struct.unpack_from("<H", data)[0])
            self.sock.sendto(model_definitions(self.version, self.bodies), client)
        for p in self.packets:
            if isinstance(p, float):
                time.sleep(p)
            elif isinstance(p, threading.Event):
                p.set()
            elif isinstance(p, tuple):
                p[0].wait(10)
            else:
                self.sock.sendto(p, client)
                time.sleep(0.002)  # keep the loopback socket's buffer from overflowing

    def spec(self, **extra) -> str:
        keys = {"server": "127.0.0.1", "local": "127.0.0.1", "multicast": "off"}
        keys.update(command_port=str(self.port), body=str(HAND_ID), timeout="3")
        keys.update(extra)
        return "natnet:" + ",".join(f"{k}={v}" for k, v in keys.items())

    def close(self):
        self.thread.join(5)
        self.sock.close()


def markers_key() -> str:
    return ";".join(f"{m >> 16}.{m & 0xFFFF}" for m in MARKER_IDS)


def quat_close(wxyz, r: Rotation, tol: float) -> bool:
    w, x, y, z = wxyz
    return bool(np.allclose(np.abs(np.dot([x, y, z, w], r.as_quat())), 1.0, atol=tol))


@pytest.mark.parametrize("version", [(3, 1), (4, 1)])
def test_frames_decode_to_world_poses_and_contacts(version):
    scene = Scene(seed=7)
    packets = [scene.frame(version, n, 10.0 + n / 120, tracked=True) for n in range(6)]
    server = StandIn(version, packets, bodies={"Wand": OTHER_ID, "Hand": HAND_ID})
    try:
        source = open_source(server.spec(body="Hand", markers=markers_key()))
        assert source.describe()["natnet_version"] == f"{version[0]}.{version[1]}.0.0"
        assert source.describe()["body_id"] == HAND_ID
        samples = [s for _, s in zip(range(6), source)]
    finally:
        server.close()
    assert server.requests == [NAT_CONNECT, NAT_REQUEST_MODELDEF]
    r, contacts = scene.expected()
    assert [s[0] for s in samples] == pytest.approx([n / 120 for n in range(6)], abs=1e-9)
    for _, q, _c in samples:
        assert quat_close(q, r, 1e-6)
    # the hand holds still: the first sample carries the contacts, the rest none (the
    # device keeps them: the re-run rule, tol_mm 2 by default)
    assert np.allclose(samples[0][2], contacts, atol=1e-6)
    assert [s[2] for s in samples[1:]] == [None] * 5
    # float32 on the wire: the world values come back to float32 precision
    assert np.allclose(samples[0][2], scene.contacts, atol=1e-5)
    assert quat_close(samples[0][1], scene.r_world, 1e-6)
    stats = source.stats()
    assert (stats["samples"], stats["poses"], stats["reruns"], stats["tol_mm"]) == (6, 6, 1, 2)


@pytest.mark.parametrize("tol_mm, sent", [("0.5", [0, 1, 2, 3, 4, 5]), ("2", [0, 3])])
def test_contacts_are_sent_only_when_they_moved_past_tol_mm(tol_mm, sent):
    version = (4, 1)
    # the fingertips slide 0.7 mm a frame along the hand's x: past 2 mm on the 3rd frame
    packets = [Scene(seed=5, shift=n * 0.0007).frame(version, n, n * 0.01) for n in range(6)]
    server = StandIn(version, packets)
    try:
        source = open_source(server.spec(markers=markers_key(), tol_mm=tol_mm))
        samples = [s for _, s in zip(range(6), source)]
    finally:
        server.close()
    assert [n for n, s in enumerate(samples) if s[2] is not None] == sent
    for n in sent:
        assert np.allclose(samples[n][2], Scene(seed=5, shift=n * 0.0007).expected()[1], atol=1e-6)
    assert source.stats()["reruns"] == len(sent)
    assert source.describe()["tol_mm"] == float(tol_mm)


def test_untracked_body_is_held_then_paused_then_resumes():
    version = (4, 1)
    scene, other = Scene(seed=1), Scene(seed=2)
    packets = [scene.frame(version, n, n * 0.01) for n in range(3)]
    # untracked: the stream carries another pose the source must not take
    packets += [other.frame(version, n, n * 0.01, tracked=False) for n in range(3, 12)]
    packets += [scene.frame(version, n, n * 0.01) for n in range(12, 15)]
    server = StandIn(version, packets)
    try:
        source = open_source(server.spec(hold="0.045"))
        source.notice = io.StringIO()
        # frames 3..6 are within 0.045 s of the last tracked frame (t=0.02): held; frames
        # 7..11 paused (not sent); 12..14 tracked again
        samples = [s for _, s in zip(range(10), source)]
    finally:
        server.close()
    assert [s[0] for s in samples] == pytest.approx([n * 0.01 for n in (*range(7), 12, 13, 14)])
    assert all(s[1] == samples[2][1] for s in samples[3:7])
    r = scene.expected()[0]
    assert all(quat_close(s[1], r, 1e-6) for s in samples)  # never the other pose
    text = source.notice.getvalue()
    assert text.count("paused") == 1 and text.count("resume") == 1, text
    assert "rigid body 3 lost for more than 0.045 s: paused, no POSE sent" in text
    assert "rigid body 3 seen again: POSEs resume" in text
    stats = source.stats()
    assert (stats["body_lost"], stats["held"], stats["paused"], stats["pauses"]) == (9, 4, 5, 1)


def test_missing_marker_is_held_then_paused_then_resumes_without_a_jump():
    version = (3, 1)
    # the fingertips slide 0.1 mm a frame: every frame's contacts differ (tol_mm=0.05)
    scenes = [Scene(seed=3, shift=n * 0.0001) for n in range(14)]
    packets = [scenes[n].frame(version, n, n * 0.01) for n in range(2)]
    packets += [scenes[2].frame(version, 2, 0.02, occlude=(1,))]
    packets += [scenes[n].frame(version, n, n * 0.01, drop=(1,)) for n in range(3, 8)]
    packets += [scenes[n].frame(version, n, n * 0.01) for n in range(8, 11)]
    # a second episode: one message each again
    packets += [scenes[n].frame(version, n, n * 0.01, drop=(1,)) for n in range(11, 14)]
    server = StandIn(version, packets)
    try:
        source = open_source(server.spec(markers=markers_key(), hold="0.035", tol_mm="0.05"))
        source.notice = io.StringIO()
        # the last sight at t=0.01: held through t=0.04 (frames 2..4), paused 5..7, seen
        # again 8..10; lost again at 11, held through 13
        samples = [s for _, s in zip(range(11), source)]
    finally:
        server.close()
    frames = [0, 1, 2, 3, 4, 8, 9, 10, 11, 12, 13]
    assert [s[0] for s in samples] == pytest.approx([n * 0.01 for n in frames])
    for n, s in zip(frames, samples):
        want = scenes[n].expected()[1]
        if n in (2, 3, 4):  # the index keeps its last hand-frame position; the others live
            want[1] = scenes[1].expected()[1][1]
        elif n in (11, 12, 13):
            want[1] = scenes[10].expected()[1][1]
        assert np.allclose(s[2], want, atol=1e-6), n
    # no jump on resuming: the index comes back where the hand has it, 0.7 mm on
    moved = np.linalg.norm(np.subtract(samples[5][2][1], samples[4][2][1]))
    assert moved == pytest.approx(0.0007, abs=1e-6)
    text = source.notice.getvalue()
    name = f"marker {MARKER_IDS[1]} (3.2)"
    assert text.count("paused") == 1 and text.count("resume") == 1, text
    assert f"{name} lost for more than 0.035 s: paused" in text
    stats = source.stats()
    assert (stats["held"], stats["paused"], stats["pauses"]) == (6, 3, 1)


def test_a_marker_never_seen_is_an_error_naming_it():
    version = (4, 1)
    scene = Scene(seed=6)
    packets = [scene.frame(version, n, n * 0.01, drop=(2,)) for n in range(150)]
    server = StandIn(version, packets)
    try:
        source = open_source(server.spec(markers=markers_key(), timeout="0.2"))
        source.notice = io.StringIO()
        with pytest.raises(SourceError, match=rf"labelled marker {MARKER_IDS[2]} \(3\.3\) has not"):
            next(iter(source))
    finally:
        server.close()
    assert source.notice.getvalue().count("waiting for the first sight of marker") == 1


def test_malformed_packets_are_skipped_with_a_warning(capfd):
    version = (4, 1)
    scene = Scene(seed=4)
    good = scene.frame(version, 0, 0.0)
    truncated = good[:40]  # the header still announces the whole frame
    payload = bytearray(good[4:])
    struct.pack_into("<I", payload, 4, 10**6)  # a marker-set count far past the data
    undecodable = packet(NAT_FRAMEOFDATA, bytes(payload))
    packets = [b"\x07", truncated, undecodable, good, scene.frame(version, 1, 0.01)]
    server = StandIn(version, packets)
    try:
        source = open_source(server.spec())
        samples = [s for _, s in zip(range(2), source)]
        assert source.skipped_packets == 3
    finally:
        server.close()
    assert [s[0] for s in samples] == pytest.approx([0.0, 0.01])
    err = capfd.readouterr().err
    assert "shorter than the NatNet header" in err
    assert "truncated packet" in err
    assert "undecodable frame of data" in err


def test_a_run_of_bad_packets_stops_the_source(capfd):
    server = StandIn((4, 1), [b"\x07\x00\xff\xff"] * MAX_BAD_PACKETS)
    try:
        source = open_source(server.spec())
        with pytest.raises(SourceError, match="undecodable packets in a row"):
            next(iter(source))
    finally:
        server.close()


def test_no_server_is_a_clear_error():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        with pytest.raises(SourceError, match=rf"no answer from a NatNet server at .*:{port}"):
            open_source(
                f"natnet:server=127.0.0.1,local=127.0.0.1,multicast=off,body=1,"
                f"command_port={port},timeout=0.3"
            )


@pytest.mark.parametrize(
    "spec, message",
    [
        ("natnet:server=127.0.0.1,bdy=3", r'bad option .*did you mean "body"'),
        ("natnet:server=127.0.0.1,body=3,data_prot=1511", r'did you mean "data_port"'),
        ("natnet:server=127.0.0.1", "body is required"),
        ("natnet:server=motive-pc,body=3", "server must be an IPv4 address"),
        ("natnet:body=3,command_port=70000", "command_port must be a port number"),
        ("natnet:body=3,markers=1;2", "markers needs 3 or 4 IDs"),
        ("natnet:body=3,markers=1;x;3", "'x' is not a labelled-marker ID"),
        ("natnet:body=3,hold=-1", "hold must be seconds"),
        ("natnet:body=3,tol_mm=-1", "tol_mm must be millimetres in 0..1000"),
        ("natnet:body=3,tol=1", r'did you mean "tol_mm"'),
        ("natnet:body=3,multicast=10.0.0.1", "multicast must be a group"),
        ("natnet:body=3,body=4", "body is given twice"),
        ("natnet:body=3,stall=0", "stall must be seconds"),
        ("natnet:body=3,stall=2,end=1", r"end \(1 s\) must not be shorter than stall"),
    ],
)
def test_bad_spec_names_the_key(spec, message):
    with pytest.raises(SourceError, match=message):
        open_source(spec)


def test_defaults_are_motives():
    spec = parse_spec("body=Hand")
    assert (spec.multicast, spec.command_port, spec.data_port) == ("239.255.42.99", 1510, 1511)
    assert (spec.hold, spec.tol_mm) == (0.2, 2.0)
    assert (spec.stall, spec.end) == (0.5, 10.0)
    assert parse_spec("body=1,markers=65537;1.2;1.3").markers == (65537, 65538, 65539)


def test_a_stall_is_said_once_and_samples_resume():
    version = (4, 1)
    scene = Scene(seed=8)
    packets = [scene.frame(version, n, n * 0.01) for n in range(5)]
    packets += [0.45]  # Motive goes quiet for longer than stall, then streams again
    packets += [scene.frame(version, n, n * 0.01) for n in range(50, 55)]
    server = StandIn(version, packets)
    try:
        source = open_source(server.spec(stall="0.15", end="2"))
        source.notice = io.StringIO()
        got = []
        for sample in source:
            got.append((time.monotonic(), sample))
            if len(got) == 10:
                break
    finally:
        server.close()
    assert [s[0] for _, s in got] == pytest.approx([n * 0.01 for n in (*range(5), *range(50, 55))])
    r = scene.expected()[0]
    assert all(quat_close(s[1], r, 1e-6) for _, s in got)
    waits = np.diff([t for t, _ in got])
    assert waits[4] >= 0.4 and np.delete(waits, 4).max() < 0.1, waits
    text = source.notice.getvalue()
    assert text.count("stalled for") == 1 and text.count("POSEs resume") == 1, text
    assert (
        "no POSE sent; the device's watchdog turns the motors off 200 ms after the last POSE"
        in (text)
    )
    resumed = float(text.split("frames again after ")[1].split(" s")[0])
    assert resumed == pytest.approx(waits[4], abs=0.02)
    assert source.stats()["stalls"] == 1


def test_silence_longer_than_end_ends_the_iteration():
    version = (4, 1)
    scene = Scene(seed=11)
    done = threading.Event()
    # the server stays up but sends nothing after three frames
    server = StandIn(version, [scene.frame(version, n, n * 0.01) for n in range(3)] + [(done, "w")])
    try:
        source = open_source(server.spec(stall="0.1", end="0.4"))
        source.notice = io.StringIO()
        start = time.monotonic()
        samples = list(source)
        elapsed = time.monotonic() - start
    finally:
        done.set()
        server.close()
    assert [s[0] for s in samples] == pytest.approx([0.0, 0.01, 0.02])
    assert 0.4 <= elapsed < 1.0, elapsed
    text = source.notice.getvalue()
    assert text.count("stalled for") == 1 and "no frame for 0.4 s: the source ends" in text, text
    assert source.stats()["stalls"] == 1


def test_a_second_iteration_takes_the_frames_from_its_flush_on():
    version = (3, 1)
    scene, other = Scene(seed=9), Scene(seed=10)
    between, go = threading.Event(), threading.Event()
    packets = [scene.frame(version, n, n * 0.01) for n in range(4)]
    # between the iterations the hand is elsewhere: no sample of the second one
    packets += [other.frame(version, n, n * 0.01) for n in range(4, 10)] + [between, (go, "w")]
    packets += [scene.frame(version, n, n * 0.01) for n in range(10, 14)]
    server = StandIn(version, packets)
    try:
        source = open_source(server.spec(markers=markers_key()))
        first = [s for _, s in zip(range(4), source)]
        assert between.wait(5)
        time.sleep(0.05)  # the last of them reach the socket
        dropped = source.flush()
        go.set()
        second = [s for _, s in zip(range(4), source)]
        source.close()
        source.close()  # again: nothing
        with pytest.raises(SourceError, match="the source is closed"):
            next(iter(source))
    finally:
        go.set()
        server.close()
    assert dropped == 6
    r, contacts = scene.expected()
    for run in (first, second):
        assert [s[0] for s in run] == pytest.approx([0.0, 0.01, 0.02, 0.03])
        assert all(quat_close(s[1], r, 1e-6) for s in run)
        # each iteration's first sample carries the contacts: the device may have dropped them
        assert np.allclose(run[0][2], contacts, atol=1e-6)
        assert [s[2] for s in run[1:]] == [None] * 3
    assert source.stats()["stalls"] == 0


# --------------------------------------------------------------------------------------
# graspguide trial --source natnet:... on the simulated device, in real time
# --------------------------------------------------------------------------------------
LSL_CONFIG = """\
[ports]
IPv6 = disable
[lab]
KnownPeers = {127.0.0.1}
ResolveScope = machine
[log]
level = -2
"""
RATE = 100.0
HAND_AT = np.array([0.3, 0.1, 0.9])  # the rigid body's place in the world (m)
TLX = '{"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": 3}\n'


def trial_motions(protocol_path):
    """Each planned trial's motion (world quaternions w, x, y, z at RATE): a scripted hand
    turning to align the trial's force with gravity within 1.5 s, then holding; and the
    hand's contacts."""
    from graspguide.protocol import study_protocol as pf
    from graspguide.sources.poses import SyntheticSource

    proto = pf.load_protocol(str(protocol_path))
    planned = pf.plan(proto, "U1", pf.draw_wrenches(proto), pf.draw_familiarization_wrenches(proto))
    out = {}
    for t in planned:
        contacts = [list(c) for c in proto.hands[t.k]]
        src = SyntheticSource(rate=RATE, duration=2.5, seed=t.trial_index).aim(
            contacts, list(t.wrench), t.policy, proto.constraints, list(proto.y_axis)
        )
        out[t.trial_index] = [np.asarray(q) for _, q, _ in src]
    return out, np.asarray(proto.hands[planned[0].k])


def motive_frame(number: int, t: float, q_wxyz, contacts) -> bytes:
    """The hand at world orientation ``q_wxyz`` (at HAND_AT, its contacts as labelled
    markers) as Motive streams it (y up)."""
    a = WORLD_TO_MOTIVE
    w, x, y, z = q_wxyz
    r = Rotation.from_quat([x, y, z, w]).as_matrix()
    quat = Rotation.from_matrix(a @ r @ a.T).as_quat()
    markers = [(mid, a @ (HAND_AT + r @ c), False) for mid, c in zip(MARKER_IDS, contacts)]
    return frame((4, 1), number, t, [(HAND_ID, a @ HAND_AT, quat, True)], markers)


def tracker(marks_ready, holder, motion, contacts, seen):
    """Motive's frames: each trial's motion from its trial_start marker (the run's LSL
    markers), its last pose held until trial_end, then a far-off hand for 0.3 s (which
    no trial may take), then nothing until the next trial."""
    marks_ready.wait(60)
    marks = holder["marks"]
    start = due = time.monotonic()
    number = 0
    rows: list = []
    hold = None
    while True:
        m, _ = marks.pull_sample(timeout=0.0)
        if m is not None:
            event = json.loads(m[0])
            seen.append(event)
            if event["event"] == "study_end":
                return
            if event["event"] == "trial_start":
                rows, hold = list(motion[event["trial_index"]]), True
            elif event["event"] == "trial_end":
                rows, hold = [np.array([0.0, 1.0, 0.0, 0.0])] * int(0.3 * RATE), None
        if rows:
            q = rows.pop(0) if len(rows) > 1 or not hold else rows[0]
            number += 1
            yield motive_frame(number, time.monotonic() - start, q, contacts)
        due += 1.0 / RATE
        time.sleep(max(0.0, due - time.monotonic()))


def test_trial_from_natnet_succeeds_both_trials(tmp_path, monkeypatch, report_figure):
    cfg = tmp_path / "lsl_api.cfg"
    cfg.write_text(LSL_CONFIG)
    monkeypatch.setenv("LSLAPICFG", str(cfg))
    import pylsl

    protocol = tmp_path / "p.toml"
    protocol.write_text(
        small_protocol_toml(
            "natnet-trial", seed=5, participants=1, timeout_s=10.0, modalities=("F+C",)
        )
    )
    motion, contacts = trial_motions(protocol)
    assert sorted(motion) == [1, 2]
    marks_ready, holder, seen = threading.Event(), {}, []
    server = StandIn((4, 1), tracker(marks_ready, holder, motion, contacts, seen), wait=30)
    (tmp_path / "tlx.jsonl").write_text(TLX)
    out, ours = tmp_path / "out", f"GGNatNet{os.getpid()}"
    source = server.spec(markers=markers_key(), stall="0.25", end="3", timeout="5")
    began = time.monotonic()
    proc = subprocess.Popen(
        [sys.executable, "-m", "graspguide", "trial", "--protocol", str(protocol)]
        + ["--participant", "U1", "--port", "sim", "--source", source, "--out", str(out)]
        + ["--rest-s", "1", "--tlx", str(tmp_path / "tlx.jsonl"), "--lsl", ours]
        + ["--lsl-wait", "30"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        env=subprocess_env(),
    )
    try:
        inlets = {}
        # the run waits (--lsl-wait) for a recorder of both its streams
        for kind in ("Markers", "Telemetry"):
            found = pylsl.resolve_byprop("name", f"{ours}-{kind}", 1, 20)
            assert found, f"the run's {kind} stream was not found"
            inlets[kind] = pylsl.StreamInlet(found[0], max_buflen=60)
            inlets[kind].open_stream(20)
        holder["marks"] = inlets["Markers"]
        marks_ready.set()
        stdout, stderr = proc.communicate(timeout=90)
    finally:
        marks_ready.set()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        server.close()
    took = time.monotonic() - began
    assert proc.returncode == 0, stdout + stderr
    assert [e["event"] for e in seen].count("trial_start") == 2
    with open(out / "U1" / "trials.jsonl", encoding="utf-8") as f:
        records = {r["trial_index"]: r for r in map(json.loads, f)}
    assert sorted(records) == [1, 2] and all(records[i]["success"] is True for i in (1, 2))
    for index in (1, 2):
        with open(out / "U1" / "frames" / f"trial-{index:04d}.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        quats = [np.array([float(r[k]) for k in ("qw", "qx", "qy", "qz")]) for r in rows]
        # the trial's first POSE is one of its motion's first samples (float32 on the wire),
        # and the far-off hand sent between trials is no POSE of any trial
        dist = [
            min(np.linalg.norm(quats[0] - q), np.linalg.norm(quats[0] + q)) for q in motion[index]
        ]
        assert min(dist) < 1e-5 and int(np.argmin(dist)) <= 30, (index, min(dist))
        assert all(abs(q[1]) < 0.99 for q in quats), index
    with open(out / "U1" / "runs.jsonl", encoding="utf-8") as f:
        end = [json.loads(line) for line in f][-1]
    assert end["outcome"] == "complete" and end["source_stats"]["stalls"] == 0, end
    assert "gaps in the tracker's stream" not in stderr, stderr
    report_figure(
        "trial natnet (completion_s per trial; wall s)",
        f"{records[1]['completion_s']:.3f}, {records[2]['completion_s']:.3f}; {took:.1f}",
    )
