"""A session logged by `graspguide stream --log DIR` replays: `--source replay:DIR/poses.csv`
(or `replay:DIR`) sends the poses the logged session sent, at their times, and the
simulated device gives the same trial."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys

import pytest
from conftest import REPO_ROOT

from graspguide.sources import poses as sources
from graspguide.sources.source_spec import open_source

SCENE3 = os.path.join(REPO_ROOT, "tools", "examples", "scene_paper_3.toml")


def _stream(source: str, log) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    cmd = [sys.executable, "-m", "graspguide", "stream", "--port", "sim", "--virtual-clock"]
    cmd += ["--scene", SCENE3, "--wrench", "0.3,-1.2,-0.8", "--source", source]
    cmd += ["--log", str(log)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=REPO_ROOT)
    assert done.returncode == 0, done.stderr
    return done


def _poses(log) -> list[list[float]]:
    with open(log / "poses.csv") as f:
        return [[float(r[c]) for c in ("t_s", "qw", "qx", "qy", "qz")] for r in csv.DictReader(f)]


def _trial(log) -> dict:
    return [json.loads(line) for line in open(log / "results.jsonl")][0]


@pytest.mark.parametrize("what", ["poses.csv", "folder"])
def test_a_stream_log_replays_as_the_same_trial(tmp_path, what):
    first = tmp_path / "s1"
    _stream("synthetic:rate=240,duration=10,seed=3", first)
    source = first / "poses.csv" if what == "poses.csv" else first
    again = tmp_path / "s2"
    _stream(f"replay:{source}", again)
    # the same poses at the same times (the replay starts at the log's first pose)
    assert _poses(again) == _poses(first)
    a, b = _trial(first), _trial(again)
    assert a["success"] is True
    for key in ("success", "completion_s", "first_entry_s", "final_error_deg"):
        assert a[key] == b[key], (key, a, b)


def test_a_logged_pose_with_contacts_is_refused_by_name(tmp_path):
    """The session log keeps whether a POSE carried contacts, not the contacts: such a
    log cannot be replayed as it ran, and the message says so."""
    log = tmp_path / "poses.csv"
    log.write_text(
        "send_time_s,host_time_us,t_s,qw,qx,qy,qz,has_contacts\n"
        "0.01,100,0.0,1.0,0.0,0.0,0.0,0\n"
        "0.02,200,0.01,1.0,0.0,0.0,0.0,1\n"
    )
    with pytest.raises(sources.SourceError, match=r"poses.csv:3: .*contacts"):
        open_source(f"replay:{log}")


def test_an_unknown_column_is_named(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("t_s,qw,qx,qy,qz,speed\n0,1,0,0,0,3\n")
    with pytest.raises(sources.SourceError, match=r"p.csv:1: .*speed"):
        open_source(f"replay:{path}")
