"""`graspguide stream --record FILE.xdf` and `--source replay:FILE.xdf` end to end on the
simulated device (virtual clock), read back with pyxdf: a recorded run replayed gives the
same TELEMETRY bit for bit and records the same poses; the streams, channels, units and
markers; the stream choice and the errors of a replayed file."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import pyxdf
from conftest import TOOLS_DIR

from graspguide.records.xdf_writer import Channel, XdfWriter
from graspguide.sources.poses import ReplaySource, SourceError, tracker_convention
from graspguide.sources.source_spec import open_source

SCENE3 = os.path.join(TOOLS_DIR, "examples", "scene_paper_3.toml")
WRENCH = "0.3,-1.2,-0.8"
BASE = ["--port", "sim", "--virtual-clock", "--scene", SCENE3, "--wrench", WRENCH]
TELEMETRY_LABELS = [
    "error_deg",
    "alpha",
    "pwm_thumb",
    "pwm_index",
    "pwm_middle",
    "pwm_palm",
    "status",
    "trial_time_s",
]
CONTACT_LABELS = [f"{f}_{a}" for f in ("thumb", "index", "middle") for a in "xyz"]


def stream(*args, timeout=60):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        [sys.executable, "-m", "graspguide", "stream", *BASE, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )


def load(path):
    streams, header = pyxdf.load_xdf(str(path))
    return {s["info"]["type"][0]: s for s in streams}, header


def labels(s):
    return [(c["label"][0], c["unit"][0]) for c in s["info"]["desc"][0]["channels"][0]["channel"]]


def pwm_rows(folder):
    with open(os.path.join(folder, "telemetry.csv"), newline="") as f:
        return [[r[f"pwm{i}"] for i in range(4)] for r in csv.DictReader(f)]


@pytest.fixture(scope="module")
def round_trip(tmp_path_factory):
    d = tmp_path_factory.mktemp("xdf")
    a, b = d / "A.xdf", d / "B.xdf"
    run_a = stream("--source", "synthetic", "--record", str(a), "--log", str(d / "L1"))
    assert run_a.returncode == 0, run_a.stderr
    run_b = stream("--source", f"replay:{a}", "--record", str(b), "--log", str(d / "L2"))
    assert run_b.returncode == 0, run_b.stderr
    return d, run_a, run_b


def test_a_replayed_recording_gives_the_same_telemetry_bit_for_bit(round_trip):
    d, run_a, run_b = round_trip
    assert "trial 1: success" in run_a.stdout and "trial 1: success" in run_b.stdout
    csv_a, csv_b = pwm_rows(d / "L1"), pwm_rows(d / "L2")
    assert len(csv_a) > 100 and csv_a == csv_b
    assert any(row != ["0"] * 4 for row in csv_a)  # the motors did run
    xa, _ = load(d / "A.xdf")
    xb, _ = load(d / "B.xdf")
    tel_a, tel_b = xa["GraspGuide"], xb["GraspGuide"]
    pwm_a = tel_a["time_series"][:, 2:6]
    assert pwm_a.tobytes() == tel_b["time_series"][:, 2:6].tobytes()
    assert tel_a["time_series"].tobytes() == tel_b["time_series"].tobytes()
    # the XDF's PWM is the session log's
    assert pwm_a.astype(int).tolist() == [[int(x) for x in row] for row in csv_a]
    # the recorded poses, value for value and time for time
    hand_a, hand_b = xa["MoCap"], xb["MoCap"]
    assert hand_a["time_series"].tobytes() == hand_b["time_series"].tobytes()
    assert hand_a["time_stamps"].tobytes() == hand_b["time_stamps"].tobytes()


def test_the_recorded_streams_match_the_session_log(round_trip):
    d, _, _ = round_trip
    x, header = load(d / "A.xdf")
    assert header["info"]["version"] == ["1.0"]
    assert sorted(x) == ["GraspGuide", "Markers", "MoCap"]
    hand, tel, markers = x["MoCap"], x["GraspGuide"], x["Markers"]
    assert hand["info"]["name"] == ["GraspGuide-Hand"]
    assert hand["info"]["channel_format"] == ["double64"]
    assert [lab for lab, _ in labels(hand)] == ["qw", "qx", "qy", "qz"]  # synthetic: no contacts
    assert labels(tel) == [
        ("error_deg", "degrees"),
        ("alpha", "pwm_counts"),
        *[(lab, "pwm_counts") for lab in TELEMETRY_LABELS[2:6]],
        ("status", "solver_status_code"),
        ("trial_time_s", "seconds"),
    ]
    clock = hand["info"]["desc"][0]["clock"][0]
    assert clock["name"] == ["trial_time"] and "t_s" in clock["description"][0]
    assert hand["info"]["desc"][0]["acquisition"][0]["simulated"] == ["true"]
    with open(d / "L1" / "poses.csv", newline="") as f:
        poses = list(csv.DictReader(f))
    logged = np.array([[float(r[k]) for k in ("qw", "qx", "qy", "qz")] for r in poses])
    t_log = np.array([float(r["t_s"]) for r in poses])
    assert hand["time_series"].tobytes() == logged.tobytes()
    assert hand["time_stamps"].tobytes() == t_log.tobytes()
    # each TELEMETRY answers the POSE of the same index: stamped with its t_s
    assert tel["time_stamps"].tobytes() == t_log.tobytes()
    assert np.allclose(tel["time_series"][:, 7], t_log, atol=1e-6)  # float32 trial_time_s
    with open(d / "L1" / "telemetry.csv", newline="") as f:
        err = [float(r["error_deg"]) for r in csv.DictReader(f)]
    assert tel["time_series"][:, 0].tolist() == np.float32(err).tolist()
    events = [json.loads(row[0]) for row in markers["time_series"]]
    assert [e["event"] for e in events] == [
        "session_start",
        "trial_start",
        "trial_end",
        "study_end",
    ]
    with open(d / "L1" / "results.jsonl") as f:
        result = json.loads(f.readline())
    assert events[2]["success"] is True
    assert events[2]["completion_s"] == pytest.approx(result["completion_s"])
    assert markers["time_stamps"].tolist() == [0.0, 0.0, t_log[-1], t_log[-1]]
    for s, n in ((hand, len(poses)), (tel, len(poses)), (markers, 4)):
        assert int(s["footer"]["info"]["sample_count"][0]) == n


def test_contacts_are_recorded_and_replayed(tmp_path):
    contacts = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.04], [-0.01, 0.1, 0.04]]
    rows = []
    for i in range(200):
        angle = math.radians(50) * (1 - i / 199)
        q = [math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0]
        c = [x + 1e-4 * i for p in contacts for x in p]
        rows.append([i / 100, *q, *c])
    src = tmp_path / "hand.csv"
    src.write_text(
        "t_s,qw,qx,qy,qz,"
        + ",".join(CONTACT_LABELS)
        + "\n"
        + "".join(",".join(repr(v) for v in r) + "\n" for r in rows)
    )
    c_xdf, d_xdf = tmp_path / "C.xdf", tmp_path / "D.xdf"
    run_c = stream(
        "--source", f"replay:{src}", "--record", str(c_xdf), "--log", str(tmp_path / "Lc")
    )
    assert run_c.returncode == 0, run_c.stderr
    run_d = stream(
        "--source", f"replay:{c_xdf}", "--record", str(d_xdf), "--log", str(tmp_path / "Ld")
    )
    assert run_d.returncode == 0, run_d.stderr
    xc, _ = load(c_xdf)
    xd, _ = load(d_xdf)
    hand = xc["MoCap"]
    assert labels(hand) == [(f"q{c}", "normalized") for c in "wxyz"] + [
        (lab, "meters") for lab in CONTACT_LABELS
    ]
    assert hand["time_series"].tobytes() == np.array([r[1:] for r in rows]).tobytes()
    assert hand["time_series"].tobytes() == xd["MoCap"]["time_series"].tobytes()
    assert pwm_rows(tmp_path / "Lc") == pwm_rows(tmp_path / "Ld")
    samples = list(open_source(f"replay:{c_xdf}"))
    assert samples[7][2] == [rows[7][5:8], rows[7][8:11], rows[7][11:14]]


def foreign_file(path, bodies=("Hand",), mm=False):
    """A LabRecorder-like file of another lab's tracker: rigid bodies labelled
    BODY_QW..BODY_QZ, BODY_X..; an EEG stream first."""
    with XdfWriter(str(path)) as w:
        eeg = w.add_stream("EEG", "EEG", ["Fz"], "float32", 500.0)
        w.write_samples(eeg, [100.0], [[1.0]])
        chans = [
            Channel(f"{b}_{c}") for b in bodies for c in ("X", "Y", "Z", "QX", "QY", "QZ", "QW")
        ]
        mocap = w.add_stream("Motive", "mocap", chans, "float32", 120.0)
        ts, vals = [], []
        for i in range(5):
            angle = 0.1 * i
            q = [math.sin(angle / 2), 0.0, 0.0, math.cos(angle / 2)]  # x, y, z, w
            row = []
            for k, _ in enumerate(bodies):
                row += [k * 10.0 if mm else float(k), 0.0, 0.0, *q]
            ts.append(5000.0 + i / 120)
            vals.append(row)
        w.write_samples(mocap, ts, vals)
    return ts


def test_a_foreign_mocap_stream_is_read_by_labels(tmp_path):
    path = tmp_path / "lab.xdf"
    ts = foreign_file(path)
    src = open_source(f"replay:{path}")
    samples = list(src)
    assert [s[0] for s in samples] == [t - ts[0] for t in ts]
    for i, (_, q, contacts) in enumerate(samples):
        angle = 0.1 * i
        want = [math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0]
        assert list(q) == pytest.approx(want, abs=1e-7) and contacts is None
    assert src.describe()["stream"] == "Motive" and src.rate_hz == pytest.approx(120.0)
    # the same values through --tracker as the CSV replay converts them
    converted = list(open_source(f"replay:{path}", tracker="optitrack"))
    csv_path = tmp_path / "same.csv"
    csv_path.write_text(
        "t_s,qw,qx,qy,qz\n"
        + "".join(
            f"{t - ts[0]!r},{q[0]!r},{q[1]!r},{q[2]!r},{q[3]!r}\n"
            for t, q, _ in samples  # wxyz: the CSV's own order
        )
    )
    # the CSV replay reads its columns as w, x, y, z: give it the world convention with
    # optitrack's axes (y up), so both apply the same axis change
    via_csv = list(ReplaySource(str(csv_path), tracker_convention("m/y/right/wxyz")))
    for (t1, q1, _), (t2, q2, _) in zip(converted, via_csv):
        assert t1 == t2 and list(q1) == pytest.approx(list(q2), abs=1e-12)


def test_the_stream_and_the_body_are_chosen_after_a_hash(tmp_path):
    path = tmp_path / "two.xdf"
    foreign_file(path, bodies=("Hand", "Cup"))
    with pytest.raises(SourceError, match="several rigid bodies \\(cup, hand\\).*#body=NAME"):
        open_source(f"replay:{path}")
    cup = list(open_source(f"replay:{path}#body=Cup"))
    assert cup[0][2] is None and len(cup) == 5
    assert len(list(open_source(f"replay:{path}#name=Motive,body=hand"))) == 5
    with pytest.raises(SourceError, match="no rigid body 'Foot'.*bodies: cup, hand"):
        open_source(f"replay:{path}#body=Foot")
    with pytest.raises(
        SourceError,
        match=f"no stream with name=Nope in {path}; streams: EEG \\(EEG\\), Motive \\(mocap\\)",
    ):
        open_source(f"replay:{path}#name=Nope")
    with pytest.raises(SourceError, match="bad stream choice 'colour=red'"):
        open_source(f"replay:{path}#colour=red")
    with pytest.raises(SourceError, match="EEG.*no orientation channels.*missing qw, qx, qy, qz"):
        open_source(f"replay:{path}#name=EEG")


def test_errors_name_the_file_and_what_is_missing(round_trip, tmp_path):
    d, _, _ = round_trip
    only = tmp_path / "no_mocap.xdf"
    with XdfWriter(str(only)) as w:
        w.add_stream("GraspGuide-Telemetry", "GraspGuide", ["error_deg"], "float32")
        w.add_stream("GraspGuide-Markers", "Markers", ["event_json"], "string")
    p = stream("--source", f"replay:{only}")
    assert p.returncode == 2
    assert (
        f"no MoCap stream in {only}; streams: GraspGuide-Telemetry (GraspGuide), "
        "GraspGuide-Markers (Markers)"
    ) in p.stderr
    bad = tmp_path / "bad_quat.xdf"
    with XdfWriter(str(bad)) as w:
        s = w.add_stream("H", "MoCap", ["qw", "qx", "qy", "qz"], "double64")
        w.write_samples(s, [0.0, 0.1], [[1.0, 0, 0, 0], [2.0, 0, 0, 0]])
    with pytest.raises(SourceError, match=f"{bad}: stream 'H', sample 1: .*not unit length"):
        open_source(f"replay:{bad}")
    with pytest.raises(SourceError, match="cannot read .*nothere.xdf: no such file"):
        open_source(f"replay:{tmp_path}/nothere.xdf")
    garbage = tmp_path / "garbage.xdf"
    garbage.write_bytes(b"not xdf at all")
    with pytest.raises(SourceError, match="garbage.xdf is not a readable XDF file"):
        open_source(f"replay:{garbage}")
    # a recording is never overwritten
    before = (d / "A.xdf").read_bytes()
    p = stream("--source", "synthetic:duration=1", "--record", str(d / "A.xdf"))
    assert p.returncode == 2 and "never overwritten" in p.stderr
    assert (d / "A.xdf").read_bytes() == before
