"""Pose sources (graspguide.sources.poses): replay CSV, synthetic hand, tracker conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graspguide.core import rotations as rot
from graspguide.core import solver
from graspguide.sources import poses as src
from graspguide.sources.source_spec import open_source

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
WRENCH = [0.3, -1.2, -0.8, 0, 0, 0]
TH = math.radians(30)
C, S = math.cos(TH / 2), math.sin(TH / 2)


def world(axis):
    return rot.quat_from_axis_angle(axis, TH)


# A rotation of 30 degrees about the tracker's up axis and about its x axis, written the
# way each tracker reports them (its own axes, its quaternion order), by hand.
CASES = {
    # name: (rotation about up in tracker order, about x in tracker order, up point)
    "vicon": ((0, 0, S, C), (S, 0, 0, C), (0, 0, 1000.0)),
    "optitrack": ((0, S, 0, C), (S, 0, 0, C), (0, 1.0, 0)),
    "leap": ((0, S, 0, C), (S, 0, 0, C), (0, 1000.0, 0)),
    "world": ((C, 0, 0, S), (C, S, 0, 0), (0, 0, 1.0)),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_preset_converts_known_rotation_to_world(name):
    conv = src.TRACKER_PRESETS[name]
    about_up, about_x, up_point = CASES[name]
    assert rot.quat_angle_deg(conv.quaternion(about_up), world([0, 0, 1])) < 1e-9
    assert rot.quat_angle_deg(conv.quaternion(about_x), world([1, 0, 0])) < 1e-9
    assert conv.position(up_point) == pytest.approx([0, 0, 1.0])


def test_y_up_forward_axis_and_units():
    leap = src.TRACKER_PRESETS["leap"]
    # Leap/OptiTrack +z (towards the user) is world -y in a right-handed z-up world
    assert leap.position([0, 0, 100.0]) == pytest.approx([0, -0.1, 0])
    assert leap.position([250.0, 0, 0]) == pytest.approx([0.25, 0, 0])
    # a rotation about tracker z becomes one about world -y
    q = leap.quaternion((0, 0, S, C))
    assert rot.quat_angle_deg(q, world([0, -1, 0])) < 1e-9


def test_swapped_quaternion_order_is_caught():
    vicon = src.TRACKER_PRESETS["vicon"]
    wrong = src.TrackerConvention("mm", "z", "right", "wxyz")
    about_up = CASES["vicon"][0]
    assert rot.quat_angle_deg(wrong.quaternion(about_up), world([0, 0, 1])) > 1.0
    assert rot.quat_angle_deg(vicon.quaternion(about_up), world([0, 0, 1])) < 1e-9


def test_swapped_up_axis_is_caught():
    wrong = src.TrackerConvention("m", "z", "right", "xyzw")  # OptiTrack taken as z-up
    about_up = CASES["optitrack"][0]
    assert rot.quat_angle_deg(wrong.quaternion(about_up), world([0, 0, 1])) > 1.0
    assert wrong.position(CASES["optitrack"][2]) != pytest.approx([0, 0, 1.0])


def test_left_handed_mirror_gives_proper_rotation():
    lh = src.TrackerConvention("m", "y", "left", "wxyz")
    m = lh.matrix
    assert np.linalg.det(m) == pytest.approx(-1.0)
    q = lh.quaternion(rot.quat_from_axis_angle([0, 1, 0], TH))
    # a left-handed frame's positive turn about up is a negative turn about world z
    assert rot.quat_angle_deg(q, rot.quat_from_axis_angle([0, 0, 1], -TH)) < 1e-9


def test_bad_convention():
    with pytest.raises(src.SourceError, match="quat_order"):
        src.TrackerConvention("m", "z", "right", "xwyz")


# ---- replay -----------------------------------------------------------------------------
def write(tmp_path, text, name="poses.csv"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_replay_reads_quaternions_and_contacts(tmp_path):
    head = "t_s,qw,qx,qy,qz," + ",".join(
        f"{n}_{a}" for n in ("thumb", "index", "middle") for a in "xyz"
    )
    rows = [
        f"{10 + i * 0.01},1,0,0,0," + ",".join(str(v) for c in HAND3 for v in c) for i in range(5)
    ]
    s = open_source("replay:" + write(tmp_path, "\n".join([head] + rows) + "\n"))
    got = list(s)
    assert len(got) == 5 and got[0][0] == 0.0 and got[1][0] == pytest.approx(0.01)
    assert got[0][1] == (1, 0, 0, 0) and got[0][2] == HAND3
    assert s.rate_hz == pytest.approx(100.0)


def test_replay_without_contacts(tmp_path):
    s = open_source("replay:" + write(tmp_path, "t_s,qw,qx,qy,qz\n0,1,0,0,0\n0.1,0,1,0,0\n"))
    assert [x[2] for x in s] == [None, None]


@pytest.mark.parametrize(
    "text, where, words",
    [
        ("", "", "empty file"),
        ("t,qw,qx,qy,qz\n0,1,0,0,0\n", ":1:", "header must name the columns"),
        ("t_s,qw,qx,qy,qz,thumb_x\n0,1,0,0,0,1\n", ":1:", "contact columns"),
        ("t_s,qw,qx,qy,qz\n0,1,0,0,0\n0.1,1,0,0\n", ":3:", "4 values"),
        ("t_s,qw,qx,qy,qz\n0,1,0,0,0\n0.1,1,0,zero,0\n", ":3:", "not a number: 'zero'"),
        ("t_s,qw,qx,qy,qz\n0,1,0,0,0\n0,1,0,0,0\n", ":3:", "must increase"),
        ("t_s,qw,qx,qy,qz\n0,2,0,0,0\n", ":2:", "unit length"),
        ("t_s,qw,qx,qy,qz\n", "", "no samples"),
    ],
)
def test_replay_errors_name_the_line(tmp_path, text, where, words):
    path = write(tmp_path, text)
    with pytest.raises(src.SourceError) as e:
        open_source("replay:" + path)
    assert str(e.value).startswith(path + where) and words in str(e.value), str(e.value)


# ---- synthetic ----------------------------------------------------------------------------
def test_synthetic_deterministic_rate_and_duration():
    a = list(open_source("synthetic:rate=100,duration=2,seed=3"))
    b = list(open_source("synthetic:rate=100,duration=2,seed=3"))
    c = list(open_source("synthetic:rate=100,duration=2,seed=4"))
    assert a == b and a != c
    assert len(a) == 201 and a[-1][0] == pytest.approx(2.0)
    assert all(abs(np.linalg.norm(q) - 1) < 1e-9 for _, q, _ in a)


def test_synthetic_converges_to_aligned_orientation():
    s = src.SyntheticSource(rate=50, duration=6, seed=1).aim(HAND3, WRENCH)
    samples = list(s)
    err = [solver.solve(HAND3, WRENCH, orientation=list(q))["error_deg"] for _, q, _ in samples]
    assert 39 < err[0] < 81  # starts 40..80 degrees off (plus tremor)
    tail = [e for (t, _, _), e in zip(samples, err) if t >= 0.65 * 6]
    assert max(tail) < 2.0  # holds below the paper's 3 degree threshold
    # smooth: no jump of more than a few degrees between samples at 50 Hz
    steps = [rot.quat_angle_deg(a[1], b[1]) for a, b in zip(samples, samples[1:])]
    assert max(steps) < 5


@pytest.mark.parametrize(
    "spec, words",
    [
        ("synthetic:rate=0", "rate"),
        ("synthetic:speed=3", "bad option"),
        ("synthetic:seed=x", "seed must be a number"),
        ("tracker", "unknown source"),
        ("replay:", "replay needs a file"),
    ],
)
def test_bad_specs(spec, words):
    with pytest.raises(src.SourceError, match=words):
        open_source(spec)


# ---- tracker exports and live adapters --------------------------------------------------
VICON_HEAD = "t_s,qw,qx,qy,qz," + ",".join(
    f"{n}_{a}" for n in ("thumb", "index", "middle") for a in "xyz"
)


def vicon_row(t, q_xyzw):
    # the columns keep their names; the values are Vicon's: x,y,z,w order and millimetres
    return (
        f"{t},"
        + ",".join(str(v) for v in q_xyzw)
        + ","
        + ",".join(str(1000 * v) for c in HAND3 for v in c)
    )


def test_replay_with_tracker_converts_a_raw_export(tmp_path):
    path = write(
        tmp_path,
        "\n".join([VICON_HEAD, vicon_row(0, CASES["vicon"][0]), vicon_row(0.01, CASES["vicon"][1])])
        + "\n",
    )
    got = list(open_source("replay:" + path, tracker="vicon"))
    assert rot.quat_angle_deg(got[0][1], world([0, 0, 1])) < 1e-9
    assert rot.quat_angle_deg(got[1][1], world([1, 0, 0])) < 1e-9
    assert np.allclose(got[0][2], HAND3)
    # the same file read as if it were already in world convention (metres) is refused:
    # its contacts span 78 "m", no hand
    with pytest.raises(src.SourceError) as e:
        open_source("replay:" + path)
    assert str(e.value).startswith(path + ":2:") and "looks like millimetres" in str(e.value)
    assert "--tracker mm/z/right/wxyz" in str(e.value)


def test_tracker_by_explicit_convention_and_bad_names(tmp_path):
    assert src.tracker_convention("mm/y/right/xyzw") == src.TRACKER_PRESETS["leap"]
    with pytest.raises(src.SourceError, match="unknown tracker 'kinect'"):
        src.tracker_convention("kinect")
    with pytest.raises(src.SourceError, match="up_axis"):
        src.tracker_convention("mm/x/right/xyzw")
    with pytest.raises(src.SourceError, match="only applies to replay"):
        open_source("synthetic", tracker="vicon")


class _FakeOptiTrack(src.TrackerAdapter):
    """Stands in for a lab's NatNet client: yields what the SDK would, in its convention."""

    name, rate_hz = "optitrack-test", 120.0
    convention = src.TRACKER_PRESETS["optitrack"]

    def __init__(self, arg="about-up"):
        self.q = CASES["optitrack"][0 if arg == "about-up" else 1]

    def raw_samples(self):
        for i in range(3):
            yield 5.0 + i / 120.0, self.q, [[0.0, 1.0, 0.0]] * 3


def test_adapter_converts_every_sample():
    got = list(_FakeOptiTrack())
    assert [round(t, 9) for t, _, _ in got] == [0.0, round(1 / 120, 9), round(2 / 120, 9)]
    for _, q, contacts in got:
        assert rot.quat_angle_deg(q, world([0, 0, 1])) < 1e-9
        assert np.allclose(contacts, [[0, 0, 1.0]] * 3)
    assert _FakeOptiTrack().describe()["tracker_convention"]["up_axis"] == "y"


def test_adapter_rejects_non_finite_samples():
    class Broken(_FakeOptiTrack):
        def raw_samples(self):
            yield 0.0, (float("nan"), 0, 0, 1), None

    with pytest.raises(src.SourceError, match="non-finite"):
        list(Broken())


def test_plugin_source_loads_an_adapter_class(monkeypatch):
    import sys
    import types

    module = types.ModuleType("lab_tracker_for_test")
    module.Hand = _FakeOptiTrack
    module.NotAnAdapter = dict
    monkeypatch.setitem(sys.modules, "lab_tracker_for_test", module)
    s = open_source("plugin:lab_tracker_for_test:Hand:about-x")
    assert rot.quat_angle_deg(next(iter(s))[1], world([1, 0, 0])) < 1e-9
    with pytest.raises(src.SourceError, match="TrackerAdapter subclass"):
        open_source("plugin:lab_tracker_for_test:NotAnAdapter")
    with pytest.raises(src.SourceError, match="cannot import 'no_such_tracker_mod'"):
        open_source("plugin:no_such_tracker_mod:X")
    with pytest.raises(src.SourceError, match="needs a module and a class"):
        open_source("plugin:lab_tracker_for_test")
