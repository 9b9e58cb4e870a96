"""Session folder writer (graspguide.records.storage): files, formats, and nothing lost when the
writer is killed (SIGKILL) mid-stream."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import textwrap

from graspguide.link import messages as m
from graspguide.records import storage as sl


def test_files_and_formats(tmp_path):
    folder = str(tmp_path / "s")
    with sl.SessionLog(folder) as log:
        log.scene({"k": 3})
        log.device(m.HelloReply(protocol_version=1, board="sim"))
        log.config({"config_hash": "ab" * 32})
        log.pose(123, 0.5, (1.0, 0.0, 0.0, 0.0), False)
        log.telemetry(m.Telemetry(host_time_us=123, error_deg=4.5, pwm=(1, 2, 3, 0)))
        log.result(m.TrialResult(trial_id=7, success=True, completion_s=1.5))
    assert json.load(open(os.path.join(folder, "device.json")))["board"] == "sim"
    poses = list(csv.reader(open(os.path.join(folder, "poses.csv"))))
    assert poses[0] == sl.POSE_COLUMNS and poses[1][1:] == [
        "123",
        "0.5",
        "1.0",
        "0.0",
        "0.0",
        "0.0",
        "0",
    ]
    tel = list(csv.DictReader(open(os.path.join(folder, "telemetry.csv"))))
    assert tel[0]["error_deg"] == "4.5" and tel[0]["pwm2"] == "3"
    assert tel[0]["solver_status"] == "ok" and tel[0]["constraints_used"] == "paper"
    res = [json.loads(line) for line in open(os.path.join(folder, "results.jsonl"))]
    assert res[0]["trial_id"] == 7 and res[0]["success"] is True
    assert not [f for f in os.listdir(folder) if f.endswith(".tmp")]
    # appending to an existing folder keeps one header
    with sl.SessionLog(folder) as log:
        log.pose(124, 0.6, (1.0, 0.0, 0.0, 0.0), True)
    poses = list(csv.reader(open(os.path.join(folder, "poses.csv"))))
    assert len(poses) == 3 and poses[0] == sl.POSE_COLUMNS


WRITER = textwrap.dedent("""
    import sys
    from graspguide.records import storage as sl
    from graspguide.link import messages as m
    log = sl.SessionLog(sys.argv[1])
    i = 0
    while True:
        log.pose(i, i / 240, (1.0, 0.0, 0.0, 0.0), False)
        log.telemetry(m.Telemetry(host_time_us=i, error_deg=i * 0.25, pwm=(i % 256, 0, 0, 0)))
        if i % 10 == 0:
            log.result({"trial_id": i, "success": True, "pad": "x" * 200})
        print(i, flush=True)   # only after every file got record i
        i += 1
""")


def test_sigkill_mid_stream_loses_nothing_written(tmp_path):
    folder = str(tmp_path / "killed")
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    p = subprocess.Popen(
        [sys.executable, "-c", WRITER, folder], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        last = -1
        for line in p.stdout:
            last = int(line)
            if last >= 300:
                break
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait(5)
    assert p.returncode == -signal.SIGKILL and last >= 300
    for name in ("poses.csv", "telemetry.csv", "results.jsonl"):
        data = open(os.path.join(folder, name), encoding="utf-8").read()
        assert data.endswith("\n"), f"{name}: partial last line {data[-80:]!r}"
    poses = list(csv.DictReader(open(os.path.join(folder, "poses.csv"))))
    tel = list(csv.DictReader(open(os.path.join(folder, "telemetry.csv"))))
    res = [json.loads(x) for x in open(os.path.join(folder, "results.jsonl"))]
    # every record acknowledged before the kill is there, complete and in order
    assert len(poses) >= last + 1 and len(tel) >= last + 1
    assert [int(r["host_time_us"]) for r in poses] == list(range(len(poses)))
    assert [int(r["host_time_us"]) for r in tel] == list(range(len(tel)))
    assert all(len(r) == len(sl.POSE_COLUMNS) and None not in r.values() for r in poses)
    assert all(float(r["error_deg"]) == int(r["host_time_us"]) * 0.25 for r in tel)
    assert [r["trial_id"] for r in res] == list(range(0, 10 * len(res), 10))
    assert len(res) >= last // 10 + 1 and all(r["pad"] == "x" * 200 for r in res)
