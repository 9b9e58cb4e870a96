"""The command line's small promises: a closed output pipe ends a command quietly (a
device run still stops its motors), unknown solve fields get a did-you-mean and the whole
list of fields, and every `device` action's --help has a description and an example."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

from graspguide.core import solver
from graspguide.core.suggest import closest, did_you_mean, unknown_name

_TOOLS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
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
