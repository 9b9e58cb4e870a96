"""`graspguide stream` paces its POSEs to what the link carries: the real Pro Mini sketch
under simavr (`--port promini-sim`, a 115200-baud UART in simulated time held to real
time) cannot take a 240 Hz source one POSE at a time. The host sends the newest pose
each time (older ones are skipped, never queued), says once that it paces and why, and
shows the rate it achieves; every POSE sent is answered (nothing dropped)."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys

from conftest import REPO_ROOT

from graspguide.devices import promini_sim as pms

SCENE3 = os.path.join(REPO_ROOT, "tools", "examples", "scene_paper_3.toml")
SOURCE_RATE = 240.0


def _stream(port: str, log, sketch_elf: str, source: str):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env[pms.PROMINI_ELF_ENV] = sketch_elf
    cmd = [sys.executable, "-m", "graspguide", "stream", "--port", port]
    cmd += ["--scene", SCENE3, "--wrench", "0.3,-1.2,-0.8", "--source", source]
    cmd += ["--log", str(log)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=REPO_ROOT)
    assert done.returncode == 0, done.stderr
    return done


def test_stream_to_the_pro_mini_paces_to_the_link_and_says_so(sketch_elf, tmp_path):
    log = tmp_path / "s"
    done = _stream("promini-sim", log, sketch_elf, f"synthetic:rate={SOURCE_RATE:g},duration=4")
    # said once, with why: the link's figures
    pacing = [line for line in done.stderr.splitlines() if "pacing" in line]
    assert len(pacing) == 1, done.stderr
    assert "115200 baud" in pacing[0] and "newest" in pacing[0], pacing[0]
    end = [json.loads(line) for line in open(log / "results.jsonl")][-1]
    assert end["event"] == "end", end
    # nothing silently lost: every POSE sent has its TELEMETRY, none dropped
    poses = list(csv.DictReader(open(log / "poses.csv")))
    tel = list(csv.DictReader(open(log / "telemetry.csv")))
    assert end["sent"] == len(poses) == len(tel) == end["received"], end
    assert end["dropped"] == 0, end
    # the poses the link could not carry were skipped for newer ones, and counted
    assert end["skipped"] > 0 and end["paced"] is True, end
    # the achieved rate is shown (the summary line) and is what was sent
    m = re.search(r"at ([0-9.]+) POSE/s", done.stdout)
    assert m, done.stdout
    shown = float(m.group(1))
    assert abs(shown - end["rate_hz"]) < 0.15, (shown, end)
    assert abs(end["rate_hz"] - end["sent"] / end["elapsed_s"]) < 0.5, end
    assert shown < SOURCE_RATE
    assert "0 dropped" in done.stdout, done.stdout
    # each POSE is the newest pose due when it went: their times never go back, and no
    # pose sent is more than a link round trip plus a source period old
    t = [float(r["t_s"]) for r in poses]
    assert t == sorted(t)
    gaps = [b - a for a, b in zip(t, t[1:])]
    assert max(gaps) < 0.1, max(gaps)


def test_stream_to_the_simulated_device_is_not_paced(tmp_path):
    """A link that carries the source: no pacing message, nothing skipped."""
    log = tmp_path / "s"
    done = _stream("sim", log, "", "synthetic:rate=100,duration=1")
    assert "pacing" not in done.stderr, done.stderr
    end = [json.loads(line) for line in open(log / "results.jsonl")][-1]
    assert end["paced"] is False and end["dropped"] == 0, end
    # a hiccup may skip a pose or two for a newer one, never a steady share
    assert end["skipped"] <= 0.1 * (end["sent"] + end["skipped"]), end


def test_a_live_tracker_is_not_read_ahead(tmp_path):
    """A live tracker's generator gives each frame when it happens: the stream sends the
    frame it got, never waits for the next one to see whether it is newer."""
    from graspguide.devices.session import DeviceSession
    from graspguide.link.transport import DEFAULT_BAUDRATE
    from graspguide.protocol.scene_file import load_scene
    from graspguide.sources.poses import TrackerAdapter
    from graspguide.study.stream_session import run_stream

    pulled: list[int] = []
    sent: list[float] = []

    class Tracker(TrackerAdapter):
        name, rate_hz = "test tracker", 50.0

        def raw_samples(self):
            for i in range(10):
                pulled.append(i)
                yield i / 50.0, (1.0, 0.0, 0.0, 0.0), None

    class Log:
        def pose(self, t_us, t_s, quat, has_contacts):
            sent.append(t_s)
            assert pulled[-1] == round(t_s * 50), (pulled, t_s)  # nothing pulled ahead

        def telemetry(self, tel):
            pass

        def result(self, result):
            pass

    device = DeviceSession("stream", "sim", DEFAULT_BAUDRATE, 2.0)
    try:
        device.client.hello()
        summary = run_stream(
            device.client, load_scene(SCENE3), [0.3, -1.2, -0.8, 0, 0, 0], Tracker(), log=Log()
        )
    finally:
        device.close()
    assert len(sent) == 10 and summary["skipped"] == 0
