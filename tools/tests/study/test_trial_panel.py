"""What the operator sees during `graspguide trial` (in a REAL pseudo-terminal): the stream
panel (graspguide.study.live_view) for each trial -- the fingers by name with their cue
levels, the error against the threshold, the hold progress, trial n of N, SIMULATED when
the run is -- and, with a person, the NASA-TLX answers shown for review before they are
saved (confirm, change a scale, or answer all again); with input that is not a terminal
the answers are saved as given, as before."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pexpect
from conftest import REPO_ROOT, small_protocol_toml, subprocess_env
from conftest import TESTS_DIR as CONFTEST_DIR

from graspguide.protocol.tlx import TLX_NAMES, TLX_SCALES

TESTS_DIR = os.path.dirname(os.path.abspath(__file__))
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
# The virtual participant standing in for a person (test_operator_runner): not SIMULATED.
PERSON = "plugin:test_operator_runner:PersonParticipant"
READY = "press Enter when the participant is ready"


def _protocol(tmp_path, wrenches=2, timeout_s=20.0) -> str:
    path = tmp_path / "tiny.toml"
    path.write_text(
        small_protocol_toml("tiny", 3, timeout_s=timeout_s, modalities=("F+V",), wrenches=wrenches)
    )
    return str(path)


def _spawn(args) -> pexpect.spawn:
    env = subprocess_env()
    env["PYTHONPATH"] = os.pathsep.join(
        [TESTS_DIR, CONFTEST_DIR]
    )  # the test sources; graspguide stays the installed one
    env.update(TERM="xterm-256color", COLUMNS="120", LINES="40")
    return pexpect.spawn(
        sys.executable,
        ["-m", "graspguide", "trial", *args],
        env=env,
        cwd=REPO_ROOT,
        encoding="utf-8",
        timeout=60,
        dimensions=(40, 120),
    )


def test_trial_shows_the_stream_panel_for_each_trial(tmp_path):
    child = _spawn(
        ["--protocol", _protocol(tmp_path), "--participant", "U1", "--port", "sim"]
        + ["--source", "participant", "--out", str(tmp_path / "out")]
    )
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0, child.before
    text = ANSI.sub("", child.before)
    assert "pwm=[" not in text  # the bare line is gone
    assert "graspguide trial (SIMULATED)" in text, text[-3000:]
    records = [json.loads(line) for line in open(tmp_path / "out" / "U1" / "trials.jsonl")]
    total = len(records)
    assert total == 2
    for n, rec in enumerate(records, start=1):
        # the panel's rows for this trial: trial n of N with its condition
        assert re.search(rf"trial\s+│\s+\[{n}/{total}\] session 1/1 F\+V k=3", text), text
        state = "success" if rec["success"] else "timeout"
        assert re.search(rf"state\s+│\s+{state}", text), text
    for finger in ("thumb", "index", "middle"):
        assert re.search(rf"{finger}\s+│\s+\d+ ", text), finger  # its cue level
    assert re.search(r"error\s+│\s+[0-9.]+ deg \(threshold 3\.0\)", text)
    assert re.search(r"hold\s+│\s+(not )?below 3\.0 deg", text)
    # every trial's outcome stays on screen as a line
    assert len(re.findall(r"\[\d/2\] session 1/1 F\+V k=3 \S+ (success|failure)", text)) == 2


def _answer_tlx(child, values):
    for sc, v in zip(TLX_SCALES, values):
        child.expect(re.escape(f"{sc} ({TLX_NAMES[sc]}) [1-21]: "))
        child.sendline(str(v))


def test_the_tlx_answers_are_reviewed_before_they_are_saved(tmp_path):
    out = tmp_path / "out"
    child = _spawn(
        ["--protocol", _protocol(tmp_path, wrenches=1, timeout_s=5.0), "--participant", "U1"]
        + ["--port", "sim", "--source", PERSON, "--out", str(out), "--rest-s", "0"]
    )
    child.expect(READY)
    child.send("\r")
    child.expect("NASA-TLX for session 1", timeout=60)
    _answer_tlx(child, [2, 3, 4, 5, 6, 7])
    # the answers shown, then a change to one scale
    child.expect(r"MD 2 +TD 3 +PD 4 +PE 5 +EF 6 +FR 7")
    child.expect("save")
    child.sendline("md")
    child.expect(re.escape(f"MD ({TLX_NAMES['MD']}) [1-21]: "))
    child.sendline("9")
    child.expect(r"MD 9 +TD 3 +PD 4 +PE 5 +EF 6 +FR 7")
    # then all of them again
    child.expect("save")
    child.sendline("r")
    _answer_tlx(child, [11, 12, 13, 14, 15, 16])
    child.expect(r"MD 11 +TD 12 +PD 13 +PE 14 +EF 15 +FR 16")
    child.expect("save")
    assert not (out / "U1" / "tlx.jsonl").exists()  # nothing saved before the confirmation
    child.sendline("")
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0, child.before
    (rec,) = [json.loads(line) for line in open(out / "U1" / "tlx.jsonl")]
    assert rec["scales"] == dict(zip(TLX_SCALES, [11, 12, 13, 14, 15, 16]))
    assert rec["origin"] == "interactive"


def test_tlx_answers_from_input_that_is_not_a_terminal_are_saved_as_given(tmp_path):
    out = tmp_path / "out"
    env = subprocess_env()
    env["PYTHONPATH"] = os.pathsep.join([TESTS_DIR, CONFTEST_DIR])
    done = subprocess.run(
        [sys.executable, "-m", "graspguide", "trial", "--protocol"]
        + [_protocol(tmp_path, wrenches=1, timeout_s=5.0), "--participant", "U1"]
        + ["--port", "sim", "--source", PERSON, "--out", str(out), "--rest-s", "0"],
        input="2\n3\n4\n5\n6\n7\n",
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=REPO_ROOT,
    )
    assert done.returncode == 0, done.stderr
    assert "save" not in done.stdout  # no review: nobody at a terminal to confirm
    (rec,) = [json.loads(line) for line in open(out / "U1" / "tlx.jsonl")]
    assert rec["scales"] == dict(zip(TLX_SCALES, [2, 3, 4, 5, 6, 7]))
