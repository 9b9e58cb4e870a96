"""The command line's small promises: a closed output pipe ends a command quietly (a
device run still stops its motors), unknown solve fields get a did-you-mean and the whole
list of fields, and every `device` action's --help has a description and an example."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest
from conftest import TOOLS_DIR

from graspguide.core import solver
from graspguide.core.suggest import closest, did_you_mean, unknown_name

_TOOLS = TOOLS_DIR
_ROOT = os.path.dirname(_TOOLS)
CLI = [sys.executable, "-m", "graspguide"]
HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
GOOD = {"contacts": HAND3, "wrench": [0.3, -1.2, -0.8, 0, 0, 0]}


def run_cli(args, data: bytes = b"", timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        CLI + list(args), input=data, capture_output=True, timeout=timeout, cwd=_ROOT
    )


# --------------------------------------------------------------------------------------
# Unknown names: did you mean, and every accepted name
# --------------------------------------------------------------------------------------
def test_suggest_helper():
    assert closest("unit", ["contacts", "units"]) == "units"
    assert closest("POLICY", ["policy", "mode"]) == "policy"
    assert closest("zzz", ["policy", "mode"]) is None
    assert did_you_mean("zzz", ["policy"]) == ""
    text = unknown_name("source", "vicon", ["synthetic", "participant", "replay"])
    assert text.startswith('unknown source "vicon"; accepted: ')
    for name in ("synthetic", "participant", "replay"):
        assert f'"{name}"' in text


def _solve_answer(request: dict) -> dict:
    proc = run_cli(["solve"], (json.dumps(request) + "\n").encode())
    assert proc.returncode == 0, proc.stderr.decode(errors="replace")
    (line,) = proc.stdout.decode().splitlines()
    return json.loads(line)


def _accepted(message: str) -> list[str]:
    listed = message.split("accepted: ", 1)[1]
    return re.findall(r'"([^"]+)"', listed)


def test_unknown_solve_field_suggests_units_and_lists_every_field():
    answer = _solve_answer({**GOOD, "unit": "mm"})
    assert answer["error"] == "bad_request"
    message = answer["message"]
    assert 'unknown field "unit"' in message
    assert 'did you mean "units"?' in message, message
    every = set(solver.REQUEST_FIELDS) | {"units"}
    assert set(_accepted(message)) == every, message
    # ... and they are the fields the command's help documents.
    help_text = run_cli(["solve", "--help"]).stdout.decode()
    fields = help_text.split("Request fields", 1)[1].split("Numbers may", 1)[0]
    documented = set(re.findall(r"^  (\w+) ", fields, re.MULTILINE))
    assert documented == every, documented


def test_unknown_solve_field_far_from_any_gets_the_list_only():
    message = _solve_answer({**GOOD, "identifier": 7})["message"]
    assert "did you mean" not in message
    assert "units" in _accepted(message)


# --------------------------------------------------------------------------------------
# A closed output pipe (`| head`): no traceback, and a device run still stops the motors
# --------------------------------------------------------------------------------------
def _into_closed_pipe(args, timeout: float = 120.0) -> subprocess.CompletedProcess:
    """Run a command whose stdout is a pipe nobody reads any more (its read end is closed
    before the command starts, as `head` does once it has its lines)."""
    r, w = os.pipe()
    os.close(r)
    try:
        return subprocess.run(
            CLI + list(args), stdout=w, stderr=subprocess.PIPE, timeout=timeout, cwd=_ROOT
        )
    finally:
        os.close(w)


def _quiet(stderr: bytes) -> None:
    text = stderr.decode(errors="replace")
    assert "Traceback" not in text, text
    assert "Exception ignored" not in text, text


def test_dry_run_into_a_closed_pipe_ends_quietly():
    proc = _into_closed_pipe(
        ["trial", "--protocol", "protocols/paper.toml", "--participant", "U3", "--dry-run"]
    )
    _quiet(proc.stderr)
    assert proc.returncode == 1, proc.stderr


def test_analyze_into_a_closed_pipe_ends_quietly(tmp_path):
    from analysis.test_analysis import make_study

    make_study(tmp_path / "S", n=3)
    proc = _into_closed_pipe(["analyze", str(tmp_path / "S"), "--out", str(tmp_path / "out")])
    _quiet(proc.stderr)
    assert proc.returncode == 1, proc.stderr
    assert (tmp_path / "out" / "report.md").is_file()  # the files are written all the same


def test_stream_into_a_closed_pipe_stops_the_motors(tmp_path):
    """`graspguide stream ... | head -1`: the device outlives the host (a simulated device
    the test holds, as a board would) with its POSE watchdog out of the way, so only the
    host's STOP can leave it STOPPED with every motor off."""
    import csv

    from graspguide.devices import sim as link_sim
    from graspguide.link import client as gd
    from graspguide.link import messages as m

    trace = tmp_path / "motors.csv"
    folder = tmp_path / "log"
    with link_sim.SimulatedDevice(trace=str(trace), stale_ms=60000, start=True) as dev:
        p = subprocess.Popen(
            CLI
            + [
                "stream",
                "--port",
                dev.pty_path,
                "--scene",
                os.path.join(_TOOLS, "examples", "scene_paper_3.toml"),
                "--wrench",
                "0.3,-1.2,-0.8",
                "--source",
                "synthetic:rate=100,duration=30",
                "--log",
                str(folder),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            cwd=_ROOT,
        )
        try:
            assert b"t=" in p.stdout.readline()  # streaming (a status line)
            p.stdout.close()  # `head -1` has its line and goes away
            _, err = p.communicate(timeout=30)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        _quiet(err)
        assert p.returncode == 1, err
        client = gd.DeviceClient(dev, timeout=2.0)
        client.drain(0.1)
        assert client.status().state is m.DeviceState.STOPPED
        rows = list(csv.DictReader(open(trace)))  # while the device still runs
    pwm = [[int(r[f"pwm{i}"]) for i in range(4)] for r in rows]
    assert any(any(row) for row in pwm), "the motors never ran: nothing was tested"
    assert pwm[-1] == [0, 0, 0, 0]
    end = [json.loads(line) for line in open(folder / "results.jsonl")][-1]
    assert end["event"] == "end" and end["stop_acknowledged"] is True, end


def test_trial_into_a_closed_pipe_stops_the_motors_and_keeps_the_records(tmp_path):
    """`graspguide trial ... | head -1` on a device that outlives the host: STOPPED, every
    motor off, and trials.jsonl holds only whole records."""
    import csv

    from graspguide.devices import sim as link_sim
    from graspguide.link import client as gd
    from graspguide.link import messages as m

    trace = tmp_path / "motors.csv"
    out = tmp_path / "study"
    with link_sim.SimulatedDevice(trace=str(trace), stale_ms=60000, start=True) as dev:
        p = subprocess.Popen(
            CLI
            + [
                "trial",
                "--protocol",
                "protocols/paper.toml",
                "--participant",
                "U1",
                "--port",
                dev.pty_path,
                "--source",
                "participant",
                "--out",
                str(out),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            cwd=_ROOT,
        )
        try:
            assert p.stdout.readline().startswith(b"[1/100]")  # running
            p.stdout.close()
            _, err = p.communicate(timeout=120)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        _quiet(err)
        assert p.returncode == 1, err
        client = gd.DeviceClient(dev, timeout=2.0)
        client.drain(0.1)
        assert client.status().state is m.DeviceState.STOPPED
        rows = list(csv.DictReader(open(trace)))
    assert [int(rows[-1][f"pwm{i}"]) for i in range(4)] == [0, 0, 0, 0]
    data = (
        (out / "U1" / "trials.jsonl").read_bytes()
        if (out / "U1" / "trials.jsonl").exists()
        else b""
    )
    assert data == b"" or data.endswith(b"\n")
    for line in data.splitlines():
        json.loads(line)


# --------------------------------------------------------------------------------------
# Every action's --help: what it does, and an example
# --------------------------------------------------------------------------------------
def _description_and_examples(text: str) -> tuple[str, list[str]]:
    """The paragraph between the usage and the options, and the example command lines."""
    blocks = text.split("\n\n")
    start = next(i for i, b in enumerate(blocks) if b.startswith("usage:")) + 1
    description = blocks[start] if not blocks[start].startswith("options:") else ""
    examples = [ln.strip() for ln in text.splitlines() if ln.startswith("  graspguide ")]
    return description, examples


@pytest.mark.parametrize(
    "command",
    [
        ["device", "plan"],
        ["device", "run"],
        ["device", "log"],
        ["device", "info"],
        ["device", "erase"],
        ["mp", "build"],
        ["mp", "deploy"],
        ["mp", "run"],
        ["mp", "log"],
        ["analyze"],
    ],
    ids=" ".join,
)
def test_help_has_a_description_and_an_example(command):
    proc = run_cli([*command, "--help"])
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout.decode()
    description, examples = _description_and_examples(text)
    assert len(description.split()) >= 8, text
    assert "example" in text, text
    assert any(e.startswith("graspguide " + " ".join(command) + " ") for e in examples), text
