"""One rule says whether a run is SIMULATED, for `stream` and `trial` alike, in their
records and on the terminal: the source says whether it is simulated (the virtual
participant, the scripted hand, a replayed file; not a live tracker), and so does a
simulated device port (sim, promini-sim, qemu)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pexpect
import pytest
from conftest import REPO_ROOT, small_protocol_toml, subprocess_env

from graspguide.sources import poses as sources
from graspguide.sources import trial_sources
from graspguide.sources.source_spec import open_source

SCENE3 = os.path.join(REPO_ROOT, "tools", "examples", "scene_paper_3.toml")


def _run(args, timeout=120) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "graspguide", *args]
    return subprocess.run(
        cmd, capture_output=True, text=True, timeout=timeout, env=subprocess_env(), cwd=REPO_ROOT
    )


def _protocol(tmp_path) -> str:
    path = tmp_path / "tiny.toml"
    path.write_text(small_protocol_toml("tiny", 3, timeout_s=20.0, modalities=("F+V",), wrenches=1))
    return str(path)


@pytest.mark.parametrize(
    "spec,source_simulated,port,simulated",
    [
        ("participant", True, "/dev/ttyACM0", True),
        ("synthetic", True, "/dev/ttyACM0", True),
        ("replay:x.csv", True, "/dev/ttyACM0", True),
        ("plugin:lab.vicon:Hand", False, "/dev/ttyACM0", False),
        ("plugin:lab.vicon:Hand", False, "sim", True),
        ("plugin:lab.vicon:Hand", False, "promini-sim", True),
        ("plugin:lab.vicon:Hand", False, "qemu", True),
    ],
)
def test_the_rule(spec, source_simulated, port, simulated):
    why = trial_sources.simulation(spec, source_simulated, port)
    assert (why is not None) == simulated, why


def test_the_sources_say_whether_they_are_simulated(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n")
    assert open_source("synthetic").simulated is True
    assert open_source(f"replay:{path}").simulated is True

    class Live(sources.TrackerAdapter):
        def raw_samples(self):
            return iter(())

    assert Live().simulated is False


def test_stream_with_the_synthetic_hand_is_simulated_in_its_record_and_output(tmp_path):
    log = tmp_path / "s"
    done = _run(
        ["stream", "--port", "sim", "--virtual-clock", "--scene", SCENE3]
        + ["--wrench", "0.3,-1.2,-0.8", "--source", "synthetic:duration=4", "--log", str(log)]
    )
    assert done.returncode == 0, done.stderr
    config = json.load(open(log / "config.json"))
    assert config["simulated"] is True, config
    assert "SIMULATED" in done.stderr, done.stderr
    assert done.stdout.splitlines()[-1].startswith("SIMULATED "), done.stdout


def test_trial_with_the_virtual_participant_says_simulated_and_records_it(tmp_path):
    out = tmp_path / "out"
    done = _run(
        ["trial", "--protocol", _protocol(tmp_path), "--participant", "U1", "--port", "sim"]
        + ["--source", "participant", "--out", str(out)]
    )
    assert done.returncode == 0, done.stderr
    assert "SIMULATED" in done.stderr and "virtual participant" in done.stderr, done.stderr
    done_line = [line for line in done.stdout.splitlines() if "trials done" in line]
    assert done_line and done_line[0].startswith("SIMULATED "), done.stdout
    records = [json.loads(line) for line in open(out / "U1" / "trials.jsonl")]
    assert records and all(r["simulated"] is True for r in records)


def test_trial_and_stream_agree_on_the_synthetic_hand(tmp_path):
    """The same source on the same port: the same word in both commands' records."""
    out = tmp_path / "out"
    done = _run(
        ["trial", "--protocol", _protocol(tmp_path), "--participant", "U1", "--port", "sim"]
        + ["--source", "synthetic", "--out", str(out)]
    )
    assert done.returncode == 0, done.stderr
    records = [json.loads(line) for line in open(out / "U1" / "trials.jsonl")]
    log = tmp_path / "s"
    stream = _run(
        ["stream", "--port", "sim", "--virtual-clock", "--scene", SCENE3]
        + ["--wrench", "0.3,-1.2,-0.8", "--source", "synthetic:duration=2", "--log", str(log)]
    )
    assert stream.returncode == 0, stream.stderr
    assert {r["simulated"] for r in records} == {json.load(open(log / "config.json"))["simulated"]}


def test_trial_with_operator_keys_and_the_virtual_participant_is_not_a_person(tmp_path):
    env = subprocess_env()
    child = pexpect.spawn(
        sys.executable,
        ["-m", "graspguide", "trial", "--protocol", _protocol(tmp_path), "--participant", "U1"]
        + ["--port", "sim", "--source", "participant", "--out", str(tmp_path / "o")]
        + ["--operator"],
        env=env,
        cwd=REPO_ROOT,
        encoding="utf-8",
        timeout=30,
        dimensions=(40, 200),
    )
    try:
        child.expect("press Enter when the participant is ready")
        seen = child.before
        child.kill(signal.SIGINT)
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert "a run with a person" not in seen, seen
    assert "SIMULATED" in seen, seen
