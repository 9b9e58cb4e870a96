"""`graspguide trial --source lsl:...` on the simulated device in real time, fed by a REAL
pylsl outlet on the loopback: each trial's outcome (success, completion and first-entry
times) against the same motion replayed from a CSV file by `graspguide trial --source
replay:FILE.csv`; a stall in the stream (no sample for longer than ``stall``) sends no
POSE, the device's watchdog turns the motors off, the run says so on stderr and goes on;
a stream that goes silent ends the run unrecorded, and resuming completes it.

The outlet's motion per trial: the run's own marker stream (``--lsl``) says when a trial
starts; the outlet then publishes that trial's motion (a scripted hand turning to align
the trial's force with gravity, with the hand's three contacts as rigid markers) from its
start, and after the trial_end marker a far-off hand for a while (what a tracker shows
between trials: the trial must not take it). A trial takes the samples from its START
on, so its first sample may be any of the motion's first few (the outlet begins when the
marker arrives); the replay is that motion from the trial's first sample on, as a
replay restarts its file each trial.

Discovery: liblsl is configured through LSLAPICFG (KnownPeers = {127.0.0.1}) for this
process and the commands it starts, as in the other LSL tests (docs/lab-streams.md)."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
import threading
import time
import uuid

import numpy as np
import pytest
from conftest import small_protocol_toml, subprocess_env

LSL_CONFIG = """\
[ports]
IPv6 = disable
[lab]
KnownPeers = {127.0.0.1}
ResolveScope = machine
[log]
level = -2
"""
MARKERS = ("Thumb", "Index", "Middle")
LABELS = [f"Hand_{a}" for a in "XYZ"] + [f"Hand_Q{a}" for a in "WXYZ"]
LABELS += [f"{m}_{a}" for m in MARKERS for a in "XYZ"]
HAND_AT = np.array([0.3, 0.1, 0.9])  # the rigid body's place in the tracker (m)
RATE = 100.0
# trial 2's stall: the motion's samples in this window are never published
GAP = (0.3, 0.8)
PROTOCOL = {"seed": 5, "participants": 1, "timeout_s": 10.0, "modalities": ("F+C",)}
TLX = '{"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": 3}\n'


@pytest.fixture(scope="module")
def lsl(tmp_path_factory):
    cfg = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    cfg.write_text(LSL_CONFIG)
    os.environ["LSLAPICFG"] = str(cfg)
    import pylsl

    return pylsl


def _name() -> str:
    return f"GGTrial{os.getpid()}x{uuid.uuid4().hex[:8]}"


def rotation(q) -> np.ndarray:
    """The rotation matrix of the unit quaternion w, x, y, z (hand -> world)."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def motions(protocol_path):
    """Each planned trial's motion: (t_s, quat) of a scripted hand turning to align the
    trial's force with gravity within 1.5 s, then holding; and the hand's contacts."""
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
        out[t.trial_index] = [(t_s, np.asarray(q)) for t_s, q, _ in src]
    return out, np.asarray(proto.hands[planned[0].k])


def row_of(q, contacts) -> list[float]:
    """A sample as a MoCap app publishes it: the body's place and orientation, then the
    fingertip markers where the rigid hand puts them."""
    markers = HAND_AT + contacts @ rotation(q).T
    return [*HAND_AT, *q, *markers.ravel()]


class Publisher(threading.Thread):
    """The tracker: follows the run's markers and publishes each trial's motion."""

    def __init__(self, lsl, outlet, marks, motion, contacts, gaps):
        super().__init__(daemon=True)
        self.lsl, self.outlet, self.marks = lsl, outlet, marks
        self.motion, self.contacts, self.gaps = motion, contacts, gaps
        self.seen: list[dict] = []
        self.stop_after: int | None = None  # go silent from this trial on
        self.error: BaseException | None = None

    def _marker(self, timeout: float) -> dict | None:
        m, _ = self.marks.pull_sample(timeout=timeout)
        if m is None:
            return None
        event = json.loads(m[0])
        self.seen.append(event)
        return event

    def _paced(self, rows, until_event: str) -> str | None:
        """Pushes ``rows`` (None: skip a period) at RATE until an ``until_event`` marker."""
        due = time.monotonic()
        for row in rows:
            if row is not None:
                self.outlet.push_sample(row)
            due += 1.0 / RATE
            while True:
                event = self._marker(0.0)
                if event is not None and event["event"] == until_event:
                    return until_event
                if event is None:
                    break
            time.sleep(max(0.0, due - time.monotonic()))
        return None

    def run(self) -> None:
        try:
            while True:
                event = self._marker(0.05)
                if event is None:
                    continue
                if event["event"] == "study_end":
                    return
                if event["event"] != "trial_start":
                    continue
                index = event["trial_index"]
                if self.stop_after is not None and index >= self.stop_after:
                    continue  # the tracker is off
                lo, hi = self.gaps.get(index, (math.inf, math.inf))
                rows = [
                    None if lo <= t_s < hi else row_of(q, self.contacts)
                    for t_s, q in self.motion[index]
                ]
                rows += [rows[-1]] * int(30 * RATE)  # the hand stays: 30 s at most
                if self._paced(rows, "trial_end") is None:
                    return
                # between trials the hand is elsewhere: never part of the next trial
                far = row_of(np.array([0.0, 1.0, 0.0, 0.0]), self.contacts)
                if self._paced([far] * int(0.3 * RATE), "study_end") is not None:
                    return
        except BaseException as e:  # reported by the test
            self.error = e


def run_trial(protocol, out, source, *extra, stdin=None):
    return subprocess.Popen(
        [sys.executable, "-m", "graspguide", "trial", "--protocol", str(protocol)]
        + ["--participant", "U1", "--port", "sim", "--source", source, "--out", str(out)]
        + list(extra),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        env=subprocess_env(),
    )


def lsl_run(lsl, tmp_path, protocol, gaps, stop_after=None, out=None, extra=()):
    motion, contacts = motions(protocol)
    name, ours = _name(), _name()
    info = lsl.StreamInfo(name, "MoCap", len(LABELS), RATE, lsl.cf_double64, f"{name}-id")
    chs = info.desc().append_child("channels")
    for label in LABELS:
        chs.append_child("channel").append_child_value("label", label).append_child_value(
            "unit", "m"
        )
    outlet = lsl.StreamOutlet(info)
    tlx = tmp_path / "tlx.jsonl"
    tlx.write_text(TLX)
    out = out or tmp_path / "lsl"
    proc = run_trial(
        protocol,
        out,
        f"lsl:name={name},wait=20,stall=0.25,end=2",
        "--rest-s",
        "1",
        "--tlx",
        str(tlx),
        "--lsl",
        ours,
        "--lsl-wait",
        "30",
        *extra,
    )
    try:
        # the run waits (--lsl-wait) for a recorder of both its streams
        inlets = {}
        for kind in ("Markers", "Telemetry"):
            found = lsl.resolve_byprop("name", f"{ours}-{kind}", 1, 20)
            assert found, f"the run's {kind} stream was not found"
            inlets[kind] = lsl.StreamInlet(found[0], max_buflen=60)
            inlets[kind].open_stream(20)
        marks = inlets["Markers"]
        pub = Publisher(lsl, outlet, marks, motion, contacts, gaps)
        pub.stop_after = stop_after
        pub.start()
        stdout, stderr = proc.communicate(timeout=90)
        pub.join(10)
        assert not pub.is_alive(), "the publisher missed the study_end marker"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert pub.error is None, pub.error
    return proc.returncode, stdout, stderr, out, motion, contacts


def records(out):
    with open(out / "U1" / "trials.jsonl", encoding="utf-8") as f:
        return {r["trial_index"]: r for r in map(json.loads, f)}


def frames(out, index):
    with open(out / "U1" / "frames" / f"trial-{index:04d}.csv", newline="") as f:
        return list(csv.DictReader(f))


def first_taken(out, index, motion) -> int:
    """Which sample of the motion the trial's first POSE was (the outlet may have begun
    before the trial read its first sample)."""
    first = frames(out, index)[0]
    q = np.array([float(first[k]) for k in ("qw", "qx", "qy", "qz")])
    dist = [min(np.linalg.norm(q - m), np.linalg.norm(q + m)) for _, m in motion]
    k = int(np.argmin(dist))
    assert dist[k] < 1e-9, dist[k]
    return k


def replay_outcome(tmp_path, protocol, index, motion, contacts, k, gap):
    """The trial's outcome with its motion from sample ``k`` on (less the stall's
    samples) replayed from a CSV file, each trial replaying it from its start."""
    path = tmp_path / f"trial{index}.csv"
    t_k = motion[k][0]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            ["t_s", "qw", "qx", "qy", "qz"]
            + [f"{n}_{a}" for n in ("thumb", "index", "middle") for a in "xyz"]
        )
        for t_s, q in motion[k:]:
            if not gap[0] <= t_s < gap[1]:
                w.writerow([t_s - t_k, *q, *contacts.ravel()])
    out = tmp_path / f"replay{index}"
    proc = run_trial(protocol, out, f"replay:{path}")
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 0, stdout + stderr
    return records(out)[index]


KEYS = ("success", "completion_s", "first_entry_s")


def test_trial_from_lsl_matches_the_same_motion_replayed_and_a_stall_is_no_fault(
    lsl, tmp_path, report_figure
):
    protocol = tmp_path / "p.toml"
    protocol.write_text(small_protocol_toml("lsl-trial", **PROTOCOL))
    gaps = {2: GAP}
    code, stdout, stderr, out, motion, contacts = lsl_run(lsl, tmp_path, protocol, gaps)
    assert code == 0, stdout + stderr
    live = records(out)
    assert sorted(live) == [1, 2]
    figures = []
    for index in (1, 2):
        k = first_taken(out, index, motion[index])
        assert k * 10 <= 300, k  # the trial took the motion from near its start
        gap = gaps.get(index, (math.inf, math.inf))
        replayed = replay_outcome(tmp_path, protocol, index, motion[index], contacts, k, gap)
        got = [live[index][key] for key in KEYS]
        want = [replayed[key] for key in KEYS]
        figures.append(
            f"trial {index}: lsl {got[1]:.3f}/{got[2]:.3f}, replay {want[1]:.3f}/{want[2]:.3f}"
        )
        assert got[0] is want[0] is True, (index, got, want)
        # within one 10 ms frame: the device times the POSEs as they arrive in real time
        assert abs(got[1] - want[1]) <= 0.012, (index, got, want)
        assert abs(got[2] - want[2]) <= 0.012, (index, got, want)
        # the far-off hand published between trials is no POSE of any trial
        rows = frames(out, index)
        assert all(abs(float(r["qx"])) < 0.99 for r in rows), index
    report_figure("trial lsl vs replay (completion_s/first_entry_s)", "; ".join(figures))
    # the stall: said by the source as it happened and by the run for its trial
    assert stderr.count("stalled for") == 1, stderr
    said = [line for line in stderr.splitlines() if "gaps in the tracker's stream" in line]
    assert len(said) == 1 and said[0].startswith("graspguide trial: trial 2: "), stderr
    assert "stalls (no sample): 1" in said[0] and "not a link fault" in said[0], said
    assert "watchdog turned the motors off 200 ms after the last one (1 time)" in said[0]
    # trial 2's frames: no POSE during the stall, whose length is the gap published
    t = np.array([float(r["t_s"]) for r in frames(out, 2)])
    assert np.max(np.diff(t)) == pytest.approx(GAP[1] - GAP[0] + 0.01, abs=0.03)
    with open(out / "U1" / "runs.jsonl", encoding="utf-8") as f:
        end = [json.loads(line) for line in f][-1]
    assert end["outcome"] == "complete" and end["source_stats"]["stalls"] == 1, end


def test_a_silent_stream_ends_the_run_unrecorded_and_a_resume_completes_it(lsl, tmp_path):
    protocol = tmp_path / "p.toml"
    protocol.write_text(small_protocol_toml("lsl-end", **PROTOCOL))
    out = tmp_path / "lsl"
    code, stdout, stderr, _, _, _ = lsl_run(lsl, tmp_path, protocol, {}, stop_after=2, out=out)
    assert code == 1, stdout + stderr
    said = [line for line in stderr.splitlines() if line.startswith("graspguide trial: error:")]
    assert len(said) == 1 and "trial 2: the live source lsl:name=" in said[0], stderr
    assert "ended before the device ended the trial" in said[0]
    assert "no sample for 2 s: the source ends" in stderr
    assert "run the same command again to resume" in stderr
    assert sorted(records(out)) == [1]
    assert not (out / "U1" / "frames" / "trial-0002.csv").exists()
    code, stdout, stderr, _, _, _ = lsl_run(lsl, tmp_path, protocol, {}, out=out)
    assert code == 0, stdout + stderr
    assert sorted(records(out)) == [1, 2] and records(out)[2]["success"] is True
