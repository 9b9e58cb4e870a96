"""`graspguide stream` end to end against the simulated device (virtual clock) with the
synthetic source, and its session folder."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys

import pytest
from conftest import TOOLS_DIR

from graspguide.protocol import scene_file as gs
from graspguide.sources.source_spec import open_source

_TOOLS = TOOLS_DIR
SCENE3 = os.path.join(_TOOLS, "examples", "scene_paper_3.toml")
SCENE4 = os.path.join(_TOOLS, "examples", "scene_paper_4.toml")
CLI = [sys.executable, "-m", "graspguide", "stream"]
WRENCH = "0.3,-1.2,-0.8"


def run(args, timeout=60):
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return subprocess.run(CLI + args, capture_output=True, text=True, timeout=timeout, env=env)


@pytest.mark.parametrize("scene_file", [SCENE3, SCENE4])
def test_synthetic_trial_succeeds_and_log_is_consistent(tmp_path, scene_file):
    folder = tmp_path / "session"
    p = run(
        [
            "--port",
            "sim",
            "--virtual-clock",
            "--scene",
            scene_file,
            "--wrench",
            WRENCH,
            "--source",
            "synthetic:rate=240,duration=10,seed=0",
            "--log",
            str(folder),
            "--trial-id",
            "17",
        ]
    )
    assert p.returncode == 0, p.stderr
    assert "trial 17: success" in p.stdout, p.stdout
    assert "error=" in p.stdout  # plain periodic status lines (stdout not a TTY)
    assert sorted(os.listdir(folder)) == [
        "config.json",
        "device.json",
        "poses.csv",
        "results.jsonl",
        "scene.json",
        "telemetry.csv",
    ]
    scene = json.load(open(folder / "scene.json"))
    config = json.load(open(folder / "config.json"))
    device = json.load(open(folder / "device.json"))
    assert scene == gs.load_scene(scene_file).to_dict() == config["scene"]
    assert config["config_hash"] == gs.config_hash({"scene": scene, "wrench": config["wrench"]})
    assert config["wrench"] == [0.3, -1.2, -0.8, 0.0, 0.0, 0.0] and config["trial_id"] == 17
    assert device["protocol_version"] >= 1 and device["max_contacts"] >= scene["k"]
    poses = list(csv.DictReader(open(folder / "poses.csv")))
    tel = list(csv.DictReader(open(folder / "telemetry.csv")))
    results = [json.loads(line) for line in open(folder / "results.jsonl")]
    # every POSE sent got its TELEMETRY, in order
    assert len(poses) == len(tel) > 100
    assert [r["host_time_us"] for r in poses] == [r["host_time_us"] for r in tel]
    assert all(r["solver_status"] == "ok" for r in tel)
    trial, end = results
    assert trial["trial_id"] == 17 and trial["success"] is True
    assert trial["final_error_deg"] < 3.0 and trial["completion_s"] < 10.0
    assert float(tel[-1]["error_deg"]) == pytest.approx(trial["final_error_deg"], abs=1e-6)
    assert [tel[-1][f"pwm{i}"] for i in range(4)] == ["0"] * 4  # ended: motors off
    assert end["event"] == "end" and end["exit_code"] == 0 and end["sent"] == len(poses)
    # the trial ended before the source did (10 s at 240 Hz)
    assert len(poses) < 2401


def test_negative_wrench_runs_a_trial():
    """`--wrench -1,0,0` was read by argparse as an option ("expected one argument")."""
    p = run(
        [
            "--port",
            "sim",
            "--virtual-clock",
            "--scene",
            SCENE3,
            "--wrench",
            "-1,0,-0.5",
            "--source",
            "synthetic:rate=240,duration=10,seed=0",
        ]
    )
    assert p.returncode == 0, p.stderr
    assert "trial 1: success" in p.stdout, p.stdout


def test_source_ending_first_stops_and_exits_0(tmp_path):
    csv_path = tmp_path / "identity.csv"  # identity: 57 degrees off, never succeeds
    csv_path.write_text("t_s,qw,qx,qy,qz\n" + "".join(f"{i * 0.01},1,0,0,0\n" for i in range(101)))
    p = run(
        [
            "--port",
            "sim",
            "--virtual-clock",
            "--scene",
            SCENE3,
            "--wrench",
            WRENCH,
            "--source",
            f"replay:{csv_path}",
            "--log",
            str(tmp_path / "log"),
        ]
    )
    assert p.returncode == 0, p.stderr
    assert "no trial result: the source ended first (101 poses sent" in p.stdout
    tmp_path = tmp_path / "log"
    results = [json.loads(line) for line in open(tmp_path / "results.jsonl")]
    assert len(results) == 1 and results[0]["event"] == "end"


def test_tracker_export_replayed_with_tracker_flag_succeeds(tmp_path):
    """The synthetic hand written as an OptiTrack export (y up, x,y,z,w): streamed with
    --tracker optitrack it succeeds; streamed as if it were world data it cannot."""
    from graspguide.core import rotations
    from graspguide.sources import poses as sources

    scene = gs.load_scene(SCENE3)
    hand = open_source("synthetic:rate=100,duration=6,seed=3")
    hand.aim(
        scene.contacts, [0.3, -1.2, -0.8, 0, 0, 0], scene.policy, scene.constraints, scene.y_axis
    )
    m = sources.TRACKER_PRESETS["optitrack"].matrix
    rows = []
    for t, q, _ in hand:
        w, x, y, z = rotations.matrix_to_quat(m.T @ rotations.quat_to_matrix(q) @ m)
        rows.append(f"{t:.6f},{x:.17g},{y:.17g},{z:.17g},{w:.17g}\n")  # OptiTrack: x,y,z,w
    assert len(rows) == 601
    csv_path = tmp_path / "optitrack.csv"
    csv_path.write_text("t_s,qw,qx,qy,qz\n" + "".join(rows))
    ok = run(
        [
            "--port",
            "sim",
            "--virtual-clock",
            "--scene",
            SCENE3,
            "--wrench",
            WRENCH,
            "--source",
            f"replay:{csv_path}",
            "--tracker",
            "optitrack",
        ]
    )
    assert ok.returncode == 0, ok.stderr
    assert "trial 1: success" in ok.stdout, ok.stdout
    raw = run(
        [
            "--port",
            "sim",
            "--virtual-clock",
            "--scene",
            SCENE3,
            "--wrench",
            WRENCH,
            "--source",
            f"replay:{csv_path}",
        ]
    )
    assert raw.returncode == 0, raw.stderr
    assert "success" not in raw.stdout, raw.stdout


def test_run_stream_then_stop_leaves_device_idle():
    from graspguide.devices import sim as link_sim
    from graspguide.link import client as gd
    from graspguide.link import messages as m
    from graspguide.study.stream_session import run_stream

    scene = gs.load_scene(SCENE3)
    src = open_source("synthetic:rate=100,duration=0.5")
    with link_sim.SimulatedDevice(virtual_clock=True) as sim:
        client = gd.DeviceClient(sim, timeout=2.0)
        client.hello()
        summary = run_stream(client, scene, [0.3, -1.2, -0.8, 0, 0, 0], src, virtual_clock=True)
        assert summary["trial_result"] is None and summary["sent"] == 51
        assert client.status().state is m.DeviceState.TRIAL_RUNNING
        client.stop()
        assert client.status().state is m.DeviceState.STOPPED


@pytest.mark.parametrize(
    "args, code, words",
    [
        (
            [
                "--port",
                "sim",
                "--scene",
                "/nonexistent.toml",
                "--wrench",
                WRENCH,
                "--source",
                "synthetic",
            ],
            2,
            "cannot read the scene file",
        ),
        (
            ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH, "--source", "bogus"],
            2,
            "unknown source",
        ),
        (
            [
                "--port",
                "/dev/graspguide-no-such-port",
                "--scene",
                SCENE3,
                "--wrench",
                WRENCH,
                "--source",
                "synthetic",
            ],
            1,
            "error",
        ),
        (
            [
                "--port",
                "/dev/ttyS0",
                "--virtual-clock",
                "--scene",
                SCENE3,
                "--wrench",
                WRENCH,
                "--source",
                "synthetic",
            ],
            2,
            "--virtual-clock is for --port sim",
        ),
        (
            ["--port", "sim", "--scene", SCENE3, "--wrench", "1,2", "--source", "synthetic"],
            2,
            "3 or 6",
        ),
        (
            [
                "--port",
                "sim",
                "--scene",
                SCENE3,
                "--wrench",
                WRENCH,
                "--source",
                "synthetic",
                "--tracker",
                "vicon",
            ],
            2,
            "only applies to replay",
        ),
        (
            [
                "--port",
                "sim",
                "--scene",
                SCENE3,
                "--wrench",
                "-0.3,-1.2,-0.8,5,0,-2",
                "--source",
                "synthetic",
            ],
            2,
            "looks like N mm",
        ),
        (
            ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH]
            + ["--source", "participant:reaction_time=0.3"],
            2,
            'unknown participant key "reaction_time" (did you mean "reaction_time_s"?)',
        ),
        (
            ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH]
            + ["--source", "participant:seed=x"],
            2,
            "seed must be an integer",
        ),
        (
            ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH]
            + ["--source", "synthetic", "--lsl-wait", "5"],
            2,
            "--lsl-wait is for --lsl",
        ),
        (
            ["--port", "sim", "--scene", SCENE3, "--wrench", WRENCH]
            + ["--source", "synthetic", "--lsl", "a/b"],
            2,
            "--lsl name 'a/b'",
        ),
    ],
)
def test_errors_and_exit_codes(args, code, words):
    p = run(args)
    assert p.returncode == code, (p.returncode, p.stderr)
    assert words in p.stderr, p.stderr


def test_ctrl_c_stops_and_keeps_the_log(tmp_path):
    import signal
    import time

    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    folder = tmp_path / "log"
    p = subprocess.Popen(
        CLI
        + [
            "--port",
            "sim",
            "--scene",
            SCENE3,
            "--wrench",
            WRENCH,
            "--source",
            "synthetic:rate=100,duration=30",
            "--log",
            str(folder),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert p.stdout.readline().startswith("t=")  # streaming in real time
        time.sleep(0.3)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=10)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130 and "interrupted" in err, (p.returncode, err)
    results = [json.loads(line) for line in open(folder / "results.jsonl")]
    assert results[-1]["event"] == "end" and results[-1]["exit_code"] == 130
    poses = list(csv.DictReader(open(folder / "poses.csv")))
    tel = list(csv.DictReader(open(folder / "telemetry.csv")))
    assert 10 <= len(tel) <= len(poses) <= len(tel) + 1


# --------------------------------------------------------------------------------------
# SIGTERM and SIGHUP: like Ctrl-C (STOP, the end record, exit 130)
# --------------------------------------------------------------------------------------
def _start_streaming(port, folder, extra=()):
    import signal  # noqa: F401  (the callers send it)

    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    p = subprocess.Popen(
        CLI
        + [
            "--port",
            port,
            "--scene",
            SCENE3,
            "--wrench",
            WRENCH,
            "--source",
            "synthetic:rate=100,duration=30",
            "--log",
            str(folder),
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        line = p.stdout.readline()
        assert line.startswith("t="), (line, p.poll())  # streaming in real time
    except BaseException:
        p.kill()
        p.wait()
        raise
    return p


def _signal_and_wait(p, sig):
    import time

    time.sleep(0.3)
    p.send_signal(sig)
    try:
        return p.communicate(timeout=15)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGHUP"])
def test_sigterm_and_sighup_stop_and_keep_the_log(tmp_path, signame):
    import signal

    folder = tmp_path / "log"
    p = _start_streaming("sim", folder)
    out, err = _signal_and_wait(p, getattr(signal, signame))
    assert p.returncode == 130 and "interrupted" in err, (p.returncode, err)
    assert "STOP failed" not in err, err
    end = [json.loads(line) for line in open(folder / "results.jsonl")][-1]
    assert end["event"] == "end" and end["exit_code"] == 130, end
    assert end["stop_acknowledged"] is True, end
    tel = list(csv.DictReader(open(folder / "telemetry.csv")))
    assert len(tel) >= 10


def test_sigterm_stop_reaches_the_device(tmp_path):
    """The device outlives the host here (a simulated device the test holds, as a board
    would), with its POSE watchdog out of the way: after SIGTERM the device is STOPPED
    and its motor trace ends with every motor off, which only STOP can do."""
    import signal

    from graspguide.devices import sim as link_sim
    from graspguide.link import client as gd
    from graspguide.link import messages as m

    trace = tmp_path / "motors.csv"
    with link_sim.SimulatedDevice(trace=str(trace), stale_ms=60000, start=True) as dev:
        p = _start_streaming(dev.pty_path, tmp_path / "log")
        _, err = _signal_and_wait(p, signal.SIGTERM)
        assert p.returncode == 130, (p.returncode, err)
        client = gd.DeviceClient(dev, timeout=2.0)
        client.drain(0.1)
        assert client.status().state is m.DeviceState.STOPPED
        # read while the device runs: its exit would switch the motors off by itself
        rows = list(csv.DictReader(open(trace)))
    pwm = [[int(r[f"pwm{i}"]) for i in range(4)] for r in rows]
    assert any(any(row) for row in pwm), "the motors never ran: nothing was tested"
    assert pwm[-1] == [0, 0, 0, 0]


def test_participant_source_reaches_a_trial_result(tmp_path):
    """`--source participant` (closed loop, SIMULATED) on the virtual clock: the device's
    TRIAL_RESULT, the run labelled simulated in output, config and log, and the poses the
    participant's (pipelined) ones: every POSE answered, in order."""
    scene_v = tmp_path / "scene_v.toml"
    # mode V: the virtual participant succeeds there (mode C is the paper's harder one)
    scene_v.write_text(open(SCENE3).read().replace('mode = "C"', 'mode = "V"'))
    folder = tmp_path / "run"
    args = ["--port", "sim", "--virtual-clock", "--scene", str(scene_v), "--wrench", WRENCH]
    p = run(args + ["--source", "participant:seed=2", "--log", str(folder), "--trial-id", "5"])
    assert p.returncode == 0, p.stderr
    assert "SIMULATED trial 5: success" in p.stdout, p.stdout
    assert "SIMULATED" in p.stderr and "virtual participant" in p.stderr
    config = json.load(open(folder / "config.json"))
    assert config["simulated"] is True and config["source"]["simulated"] is True
    assert config["source"]["kind"] == "closed_loop"
    poses = list(csv.DictReader(open(folder / "poses.csv")))
    tel = list(csv.DictReader(open(folder / "telemetry.csv")))
    trial, end = [json.loads(line) for line in open(folder / "results.jsonl")]
    assert trial["trial_id"] == 5 and trial["success"] is True
    # pipelined: the POSEs already written when the trial ended are refused (no TELEMETRY)
    from graspguide.study.pose_loop import MAX_PIPELINE

    assert 0 <= len(poses) - len(tel) < MAX_PIPELINE
    assert [r["host_time_us"] for r in poses[: len(tel)]] == [r["host_time_us"] for r in tel]
    assert end["sent"] == len(poses) and end["received"] == len(tel) and end["exit_code"] == 0
    # the same seed gives the same trial (the participant is seeded, the device exact)
    again = run(args + ["--source", "participant:seed=2", "--trial-id", "5"])
    assert again.stdout.splitlines()[-1] == p.stdout.splitlines()[-1]
