"""`graspguide trial --record FILE.xdf` on the simulated device (virtual clock), read back
with pyxdf: one pose sample per POSE sent, value for value against the trial's frames
files; the session clock (a trial's start offset plus its t_s) against the POSE
timestamps the device got; the TELEMETRY and the markers against the trial records; and
one trial's poses cut from the recording, replayed by `graspguide trial`, give that
trial's PWM again, frame for frame."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest
import pyxdf
from conftest import small_protocol_toml, subprocess_env

TINY = small_protocol_toml(
    "tiny-record", seed=11, participants=1, timeout_s=15.0, modalities=("F+C",), wrenches=2
)


def trial(protocol, out, *args):
    return subprocess.run(
        [sys.executable, "-m", "graspguide", "trial", "--protocol", str(protocol)]
        + ["--participant", "U1", "--port", "sim", "--out", str(out), *args],
        capture_output=True,
        text=True,
        timeout=120,
        env=subprocess_env(),
    )


def frames(out, index):
    with open(out / "U1" / "frames" / f"trial-{index:04d}.csv", newline="") as f:
        return list(csv.DictReader(f))


def trial_records(out):
    with open(out / "U1" / "trials.jsonl", encoding="utf-8") as f:
        return [json.loads(line) for line in f]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    d = tmp_path_factory.mktemp("trial-record")
    protocol = d / "tiny.toml"
    protocol.write_text(TINY)
    run = trial(protocol, d / "A", "--source", "synthetic", "--record", str(d / "A.xdf"))
    assert run.returncode == 0, run.stdout + run.stderr
    streams, _ = pyxdf.load_xdf(str(d / "A.xdf"))
    by_type = {s["info"]["type"][0]: s for s in streams}
    assert sorted(by_type) == ["GraspGuide", "Markers", "MoCap"]
    return d, protocol, by_type


def _trial_spans(markers):
    """(trial_index, start time, end time or inf) of each trial_start marker."""
    events = [json.loads(v[0]) for v in markers["time_series"]]
    starts = [
        (e["trial_index"], t)
        for e, t in zip(events, markers["time_stamps"])
        if e["event"] == "trial_start"
    ]
    ends = [t for _, t in starts[1:]] + [np.inf]
    return [(i, t0, t1) for (i, t0), t1 in zip(starts, ends)]


def test_one_pose_sample_per_pose_sent_on_the_session_clock(recorded):
    d, _, x = recorded
    hand, tel, markers = x["MoCap"], x["GraspGuide"], x["Markers"]
    desc = hand["info"]["desc"][0]
    assert desc["clock"][0]["name"] == ["session_time"]
    assert "start offset" in desc["clock"][0]["description"][0]
    assert desc["acquisition"][0]["participant"] == ["U1"]
    spans = _trial_spans(markers)
    assert [i for i, _, _ in spans] == [r["trial_index"] for r in trial_records(d / "A")]
    assert len(spans) == 2
    stamps = hand["time_stamps"]
    total = 0
    for index, t0, t1 in spans:
        rows = frames(d / "A", index)
        mine = (stamps >= t0) & (stamps < t1)
        assert int(mine.sum()) == len(rows) > 50
        logged = np.array([[float(r[k]) for k in ("qw", "qx", "qy", "qz")] for r in rows])
        assert hand["time_series"][mine].tobytes() == logged.tobytes()  # value for value
        t_s = np.array([float(r["t_s"]) for r in rows])
        # the trial's start offset plus its t_s (the frames keep t_s to the microsecond)
        np.testing.assert_allclose(stamps[mine] - t0, t_s, atol=1e-6, rtol=0)
        # on the virtual clock that is the POSE timestamp the device got, in seconds
        host_us = np.array([int(r["host_time_us"]) for r in rows])
        assert (np.round(stamps[mine] * 1e6).astype(np.int64) % 2**32 == host_us).all()
        # each TELEMETRY: the PWM the frames hold, stamped as its POSE, its trial time kept
        pwm = np.array([[int(r[f"pwm{j}"]) for j in range(4)] for r in rows])
        assert (tel["time_series"][mine][:, 2:6].astype(int) == pwm).all()
        assert tel["time_stamps"][mine].tobytes() == stamps[mine].tobytes()
        np.testing.assert_allclose(tel["time_series"][mine][:, 7], t_s, atol=1e-5)
        total += len(rows)
    assert len(stamps) == total == sum(r["poses"] for r in trial_records(d / "A"))
    assert np.all(np.diff(stamps) > 0)  # one clock for the whole run, never back


def test_the_markers_are_the_runs_events(recorded):
    d, _, x = recorded
    markers = x["Markers"]
    events = [json.loads(v[0]) for v in markers["time_series"]]
    assert [e["event"] for e in events] == [
        "session_start",
        "trial_start",
        "trial_end",
        "trial_start",
        "trial_end",
        "study_end",
    ]
    ends = [e for e in events if e["event"] == "trial_end"]
    for e, r in zip(ends, trial_records(d / "A")):
        assert (e["trial_index"], e["success"]) == (r["trial_index"], r["success"])
        assert e["completion_s"] == pytest.approx(r["completion_s"], abs=1e-6)
    assert events[-1]["outcome"] == "complete" and events[-1]["ran"] == 2
    # a trial_end is stamped with its trial's last POSE
    hand_t = x["MoCap"]["time_stamps"]
    t = markers["time_stamps"]
    spans = _trial_spans(markers)
    for (_, t0, t1), end_t in zip(spans, [t[2], t[4]]):
        assert end_t == hand_t[(hand_t >= t0) & (hand_t < t1)][-1]


def test_one_trials_poses_from_the_recording_replay_to_the_same_pwm(recorded):
    d, protocol, x = recorded
    hand, markers = x["MoCap"], x["Markers"]
    index, t0, t1 = _trial_spans(markers)[1]  # the second trial: a non-zero offset
    assert t0 > 1.0
    mine = (hand["time_stamps"] >= t0) & (hand["time_stamps"] < t1)
    cut = d / "trial2.csv"
    with open(cut, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t_s", "qw", "qx", "qy", "qz"])
        for t, q in zip(hand["time_stamps"][mine], hand["time_series"][mine]):
            w.writerow([repr(float(t - t0)), *(repr(float(v)) for v in q)])
    # every trial replays the file from its start; the second trial gets its own poses
    run = trial(protocol, d / "B", "--source", f"replay:{cut}")
    assert run.returncode == 0, run.stdout + run.stderr
    original, replayed = frames(d / "A", index), frames(d / "B", index)
    cols = ["t_s", "qw", "qx", "qy", "qz", "pwm0", "pwm1", "pwm2", "pwm3", "error_deg"]
    assert [[r[c] for c in cols] for r in replayed] == [[r[c] for c in cols] for r in original]
    assert any(r["pwm0"] != "0" or r["pwm1"] != "0" for r in original)  # the motors ran
    rec_a = [r for r in trial_records(d / "A") if r["trial_index"] == index][0]
    rec_b = [r for r in trial_records(d / "B") if r["trial_index"] == index][0]
    for key in ("success", "completion_s", "first_entry_s", "final_error_deg", "poses"):
        assert rec_a[key] == rec_b[key], key


def test_record_refuses_an_existing_file_and_dry_run(recorded, tmp_path):
    d, protocol, _ = recorded
    again = trial(protocol, tmp_path / "C", "--source", "synthetic", "--record", str(d / "A.xdf"))
    assert again.returncode == 2 and "A.xdf" in again.stderr, again.stderr
    assert not (tmp_path / "C" / "U1" / "trials.jsonl").exists()
    dry = subprocess.run(
        [sys.executable, "-m", "graspguide", "trial", "--protocol", str(protocol)]
        + ["--participant", "U1", "--dry-run", "--record", str(tmp_path / "D.xdf")],
        capture_output=True,
        text=True,
        timeout=60,
        env=subprocess_env(),
    )
    assert dry.returncode == 2 and "--dry-run goes without" in dry.stderr, dry.stderr
