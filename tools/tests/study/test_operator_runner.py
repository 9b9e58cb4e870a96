"""`graspguide trial` with a person (graspguide.study.runner, operator_console, dry_run):
through a real pseudo-terminal, the ready prompt, the rest, the operator's keys (pause,
redo and skip with a reason, notes) logged in events.jsonl against the right trial,
resume after Ctrl-C honouring a skip and a redo, the NASA-TLX anchors per scale, the
terminal restored on the way out; --dry-run without a device and its time estimate; the
observers' events in order."""

from __future__ import annotations

import io
import json
import os
import re
import sys
import termios
import time
import tomllib

import pexpect
import pytest
from conftest import TESTS_DIR as CONFTEST_DIR
from conftest import small_protocol_toml, subprocess_env

from graspguide import cli
from graspguide.participant.model import VirtualParticipant
from graspguide.protocol import study_protocol as pf
from graspguide.protocol.tlx import TLX_NAMES, TLX_SCALES
from graspguide.records.events import EVENT_NAMES, TrialObserver
from graspguide.records.frames import FRAME_COLUMNS
from graspguide.sources.trial_sources import ClosedLoopSource
from graspguide.study import runner as rn
from graspguide.study.operator_console import OperatorConsole
from graspguide.study.progress import Progress, time_left_s

TESTS_DIR = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(
    os.path.dirname(os.path.dirname(TESTS_DIR))
)  # where --port sim finds the device


class PersonParticipant(VirtualParticipant):
    """The virtual participant standing in for a person: not SIMULATED, so the runner
    treats it as one (real time, the ready prompt, the operator's keys, TLX asked)."""

    SIMULATED = False


# The test double of test_runner (it turns the hand at a bounded speed while a motor
# runs): a trial lasts about a second in real time, long enough to press a key in it.
PERSON = "plugin:test_runner:HumanLike:speed=30"
READY = "press Enter when the participant is ready"


def protocol_file(tmp_path, modalities=("F+V", "F+C"), wrenches=2):
    path = tmp_path / "people.toml"
    path.write_text(
        small_protocol_toml(
            "people", 5, timeout_s=20.0, modalities=modalities, wrenches=wrenches, single_motor=0
        )
    )
    return str(path)


def tlx_file(tmp_path, sessions):
    path = tmp_path / "tlx.jsonl"
    path.write_text(
        "".join(
            json.dumps({"session": s, **{sc: 10 for sc in TLX_SCALES}}) + "\n"
            for s in range(1, sessions + 1)
        )
    )
    return str(path)


def spawn(args):
    env = subprocess_env()
    env["PYTHONPATH"] = os.pathsep.join(
        [TESTS_DIR, CONFTEST_DIR]
    )  # the test sources; graspguide stays the installed one
    return pexpect.spawn(
        sys.executable,
        ["-m", "graspguide", "trial", *args],
        env=env,
        cwd=ROOT,
        encoding="utf-8",
        timeout=30,
        dimensions=(40, 200),
    )


def finish(child):
    """(exit status, whether the child left its terminal in line mode with echo)."""
    child.expect(pexpect.EOF)
    child.wait()
    cooked = terminal_is_cooked(child)
    child.close()
    code = child.exitstatus if child.signalstatus is None else -child.signalstatus
    return code, cooked


def terminal_is_cooked(child):
    # On Linux the pty's settings are read on the master side too.
    lflag = termios.tcgetattr(child.child_fd)[3]
    return bool(lflag & termios.ICANON) and bool(lflag & termios.ECHO)


def events(out, pid="U1"):
    with open(os.path.join(out, pid, "events.jsonl"), encoding="utf-8") as f:
        return [json.loads(line) for line in f]


def trial_indices(out, pid="U1"):
    with open(os.path.join(out, pid, "trials.jsonl"), encoding="utf-8") as f:
        return [json.loads(line)["trial_index"] for line in f]


def test_ready_prompt_rest_and_every_key_logged_against_its_trial(tmp_path):
    path = protocol_file(tmp_path)
    out = str(tmp_path / "out")
    planned = len(pf.plan(pf.load_protocol(path), "U1"))
    child = spawn(
        ["--protocol", path, "--participant", "U1", "--port", "sim", "--source", PERSON]
        + ["--out", out, "--rest-s", "0.4", "--tlx", tlx_file(tmp_path, 2)]
    )
    child.expect(f"Trial 1/{planned}, session 1, k=3 F\\+V W\\d+ \\(~[^)]+ left\\): {READY}")
    assert not terminal_is_cooked(child)  # cbreak: keys without Enter
    child.send("n")
    child.expect("note: ")
    child.sendline("pilot hand strap loose")
    child.expect(READY)
    child.send("\r")
    child.expect(r"\[1/4\]")  # the trial runs
    child.send("p")
    child.expect("paused: press Enter to resume")
    child.send("\r")
    child.expect(r"\[1/4\].*success")
    child.expect("rest 0.4 s")
    child.expect(f"Trial 2/{planned}, .*{READY}")
    child.send("\r")
    child.expect(r"\[2/4\]")
    child.send("r")
    child.expect("reason for the redo: ")
    child.sendline("participant sneezed")
    child.expect(r"\[2/4\].*success")
    child.expect(f"Trial 3/{planned}, .*{READY}")
    child.send("s")
    child.expect("reason for the skip: ")
    child.sendline("")  # a skip needs a reason: asked again
    child.expect("a skip needs a reason")
    child.sendline("thimble fell off")
    child.expect(f"Trial 4/{planned}, .*{READY}")
    child.send("\r")
    child.expect(r"\[4/4\]")
    child.send("nwinced\r")  # a note typed while the trial runs, without stopping it
    child.expect(r"\[4/4\].*success")
    child.expect("1 skipped by the operator")
    assert finish(child) == (0, True)

    got = [(e["kind"], e["trial_index"], e.get("reason") or e.get("text")) for e in events(out)]
    assert got == [
        ("note", 1, "pilot hand strap loose"),
        ("pause", 1, None),
        ("resume", 1, None),
        ("redo", 2, "participant sneezed"),
        ("skip", 3, "thimble fell off"),
        ("note", 4, "winced"),
    ]
    assert all(re.match(r"\d{4}-\d\d-\d\dT", e["time"]) for e in events(out))
    assert trial_indices(out) == [1, 2, 4]
    redo = events(out)[3]
    aside = os.path.join(out, "U1", redo["frames"])
    assert os.path.dirname(aside).endswith(os.path.join("frames", "aside"))
    with open(aside) as f:
        assert f.readline().strip() == ",".join(FRAME_COLUMNS) and f.readline()
    # the paused attempt's frames are gone, the recorded trials' frames are whole
    frames = sorted(os.listdir(os.path.join(out, "U1", "frames")))
    assert frames == ["aside", "trial-0001.csv", "trial-0002.csv", "trial-0004.csv"]


def test_ctrl_c_then_resume_honours_the_skip_and_the_redo(tmp_path):
    path = protocol_file(tmp_path)
    out = str(tmp_path / "out")
    args = ["--protocol", path, "--participant", "U1", "--port", "sim", "--source", PERSON]
    args += ["--out", out, "--rest-s", "0", "--tlx", tlx_file(tmp_path, 2)]
    child = spawn(args)
    child.expect(f"Trial 1/4, .*{READY}")
    child.send("s")
    child.expect("reason for the skip: ")
    child.sendline("late arrival")
    child.expect(f"Trial 2/4, .*{READY}")
    child.send("\r")
    child.expect(r"\[2/4\]")
    child.send("r")
    child.expect("reason for the redo: ")
    child.sendline("looked away")
    child.expect(r"\[2/4\].*success")
    child.expect(f"Trial 3/4, .*{READY}")
    child.sendintr()
    child.expect("interrupted")
    assert finish(child) == (130, True)
    assert trial_indices(out) == [2]

    child = spawn(args)
    child.expect(r"resuming U1: 1 of 4")
    child.expect(f"Trial 3/4, .*{READY}")  # 1 skipped, 2 done: neither again
    child.send("\r")
    child.expect(f"Trial 4/4, .*{READY}")
    child.send("\r")
    child.expect("1 skipped by the operator")
    assert finish(child) == (0, True)
    assert trial_indices(out) == [2, 3, 4]
    kinds = [(e["kind"], e["trial_index"]) for e in events(out)]
    assert kinds == [("skip", 1), ("redo", 2)]
    with open(os.path.join(out, "U1", "runs.jsonl")) as f:
        runs = [json.loads(line) for line in f]
    assert [r.get("outcome") for r in runs if r["event"] == "end"] == ["interrupted", "complete"]
    assert runs[-1]["skipped_by_operator"] == [1]


def test_tlx_anchors_shown_per_scale_with_the_virtual_participant_as_a_person(tmp_path):
    path = protocol_file(tmp_path, modalities=("F+V",), wrenches=1)
    out = str(tmp_path / "out")
    child = spawn(
        ["--protocol", path, "--participant", "U1", "--port", "sim"]
        + ["--source", "plugin:test_operator_runner:PersonParticipant", "--out", out]
    )
    child.expect(f"Trial 1/1, .*{READY}")
    child.send("\r")
    child.expect("NASA-TLX for session 1", timeout=60)
    for i, sc in enumerate(TLX_SCALES):
        low, high = ("perfect", "failure") if sc == "PE" else ("very low", "very high")
        child.expect(
            re.escape(f"{sc} ({TLX_NAMES[sc]}): ")
            + r"[^\r\n]*"
            + re.escape(f"1 = {low} .. 21 = {high}")
        )
        child.expect(re.escape(f"{sc} ({TLX_NAMES[sc]}) [1-21]: "))
        child.sendline(str(i + 2))
    child.expect("save these answers")  # shown for review, saved on Enter
    child.sendline("")
    assert finish(child) == (0, True)
    with open(os.path.join(out, "U1", "tlx.jsonl")) as f:
        (rec,) = [json.loads(line) for line in f]
    assert rec["scales"] == {sc: i + 2 for i, sc in enumerate(TLX_SCALES)}
    # asked of the person; SIMULATED all the same: the device is the simulated one
    assert rec["origin"] == "interactive" and rec["simulated"] is True


def test_dry_run_needs_no_device_and_its_estimate_follows_the_protocol(
    tmp_path, capsys, monkeypatch
):
    path = protocol_file(tmp_path, modalities=("F+V", "F+C", "Fperp+V"), wrenches=3)
    monkeypatch.chdir(tmp_path)
    before = sorted(os.listdir(tmp_path))
    rest = 7.5
    assert (
        cli.main(
            ["trial", "--protocol", path, "--participant", "U2", "--dry-run", "--rest-s", str(rest)]
        )
        == 0
    )
    shown = capsys.readouterr().out
    assert sorted(os.listdir(tmp_path)) == before  # nothing written
    # independently of the planner: the protocol file's counts and times
    with open(path, "rb") as f:
        toml = tomllib.load(f)
    n = len(toml["conditions"]["contact_counts"]) * len(toml["conditions"]["modalities"]) * toml[
        "wrenches"
    ]["count"] + toml.get("familiarization", {}).get("trials", 0)
    hold, timeout = toml["trial"]["hold_s"], toml["trial"]["timeout_s"]
    best, worst = n * hold + (n - 1) * rest, n * timeout + (n - 1) * rest
    m = re.search(r"estimated time: best (\d+) s .* worst (\d+) s", shown)
    assert m, shown
    assert (int(m.group(1)), int(m.group(2))) == (round(best), round(worst))
    assert len(re.findall(r"^  trial \d+/\d+: ", shown, re.M)) == n
    sessions = len(toml["conditions"]["contact_counts"]) * len(toml["conditions"]["modalities"])
    assert len(re.findall(r"^  NASA-TLX for session \d+", shown, re.M)) == sessions
    assert "PE (Performance): " in shown and "1 = perfect .. 21 = failure" in shown


def test_without_dry_run_port_and_source_are_required(tmp_path, capsys):
    path = protocol_file(tmp_path)
    assert cli.main(["trial", "--protocol", path, "--participant", "U1"]) == 2
    assert "--port and --source required (or --dry-run" in capsys.readouterr().err


def test_person_rest_default_agrees_with_the_cli():
    from graspguide.cli import trial as trial_cli

    assert trial_cli.PERSON_REST_S == rn.PERSON_REST_S


def test_time_left_from_the_mean_duration_or_the_timeout():
    assert time_left_s(3, [], 5.0, 90.0) == 3 * 90.0 + 2 * 5.0
    assert time_left_s(4, [2.0, 4.0], 1.0, 90.0) == 4 * 3.0 + 3 * 1.0
    assert time_left_s(1, [2.0], 5.0, 90.0) == 2.0


class Recorder:
    def __init__(self):
        self.events = []
        self.telemetry = 0

    def on_event(self, name, **fields):
        self.events.append((name, fields))

    def on_telemetry(self, t_s, error_deg, alpha, pwm, status):
        assert len(pwm) == 4 and isinstance(status, int)
        self.telemetry += 1


def test_observers_receive_the_events_in_order_and_every_telemetry(tmp_path):
    from test_runner import AligningHand

    from graspguide.devices.sim import SimulatedDevice
    from graspguide.link.client import DeviceClient

    path = protocol_file(tmp_path)
    protocol = pf.load_protocol(path)
    rec = Recorder()
    assert isinstance(rec, TrialObserver)
    out = tmp_path / "out"
    with SimulatedDevice(virtual_clock=True, start=True) as dev:
        runner = rn.StudyRunner(
            protocol,
            "U1",
            str(out),
            ClosedLoopSource(AligningHand(), "test"),
            DeviceClient(dev),
            virtual_clock=True,
            progress=Progress(out=io.StringIO(), tty=False),
            observers=[rec],
        )
        runner.run()
    plan = pf.plan(protocol, "U1")
    expected = []
    for t in plan:
        if t.session_trial == 1:
            expected.append(("session_start", t.session))
        expected += [("trial_start", t.trial_index), ("trial_end", t.trial_index)]
    expected.append(("study_end", None))
    got = [
        (n, f.get("session") if n == "session_start" else f.get("trial_index"))
        for n, f in rec.events
    ]
    assert got == expected
    assert {n for n, _ in rec.events} <= set(EVENT_NAMES)
    with open(out / "U1" / "trials.jsonl") as f:
        records = [json.loads(line) for line in f]
    ends = [f for n, f in rec.events if n == "trial_end"]
    assert [(e["success"], e["completion_s"]) for e in ends] == [
        (r["success"], r["completion_s"]) for r in records
    ]
    assert rec.telemetry == sum(r["poses"] for r in records)
    assert rec.events[-1][1]["outcome"] == "complete"


@pytest.mark.parametrize("flag", ["--operator"])
def test_operator_needs_a_terminal(tmp_path, capsys, flag):
    path = protocol_file(tmp_path)
    code = cli.main(
        ["trial", "--protocol", path, "--participant", "U1", "--port", "sim"]
        + ["--source", "participant", "--out", str(tmp_path / "o"), flag]
    )
    assert code == 2
    assert "--operator needs a terminal on stdin" in capsys.readouterr().err


def test_console_keeps_keys_typed_ahead_and_edits_notes():
    """Keys typed quickly after p, r or s (a pause's Enter, a reason) are not lost; a note
    is edited with Backspace; the terminal is back in line mode afterwards."""
    master, slave = os.openpty()
    try:
        echo = io.StringIO()
        with OperatorConsole(fd=slave, out=echo) as con:
            assert not termios.tcgetattr(slave)[3] & termios.ICANON
            os.write(master, b"p\r")
            assert _poll_until(con) == [("key", "p")]
            assert con.wait_key(1.0) == "\n"
            os.write(master, b"nabc\x7fd\r")
            assert _poll_until(con) == [("note", "abd")]
            os.write(master, b"rlooked away\r")
            assert _poll_until(con) == [("key", "r")]
            assert con.read_line("reason: ") == "looked away"
            assert con.wait_key(0.05) is None
        assert termios.tcgetattr(slave)[3] & termios.ICANON
    finally:
        os.close(master)
        os.close(slave)


def _poll_until(con, limit_s=2.0):
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        got = con.poll()
        if got:
            return got
        time.sleep(0.01)
    return []


def test_observers_get_the_operators_events_between_the_trials_own(tmp_path):
    """One trial with keys typed ahead on a real pty: Enter, p (pause), Enter (resume), r
    and a reason (redo), n and a note: the observer sees them between the attempts'
    trial_start events, in order, and events.jsonl holds the same."""
    from test_runner import AligningHand

    from graspguide.devices.sim import SimulatedDevice
    from graspguide.link.client import DeviceClient

    path = protocol_file(tmp_path, modalities=("F+V",), wrenches=1)
    protocol = pf.load_protocol(path)
    rec = Recorder()
    out = tmp_path / "out"
    master, slave = os.openpty()
    try:
        os.write(master, b"\rp\rrwhy\rnfine now\r")
        with (
            SimulatedDevice(virtual_clock=True, start=True) as dev,
            OperatorConsole(fd=slave, out=io.StringIO()) as con,
        ):
            rn.StudyRunner(
                protocol,
                "U1",
                str(out),
                ClosedLoopSource(AligningHand(), "test"),
                DeviceClient(dev),
                virtual_clock=True,
                progress=Progress(out=io.StringIO(), tty=False),
                operator=con,
                observers=[rec],
            ).run()
    finally:
        os.close(master)
        os.close(slave)
    got = [(n, f.get("attempt")) for n, f in rec.events if n != "session_start"]
    assert got == [
        ("trial_start", 1),
        ("pause", 1),
        ("resume", 2),
        ("trial_start", 2),
        ("redo", 2),
        ("trial_start", 3),
        ("note", None),
        ("trial_end", None),
        ("study_end", None),
    ]
    logged = [(e["kind"], e["trial_index"], e.get("reason") or e.get("text")) for e in events(out)]
    assert logged == [
        ("pause", 1, None),
        ("resume", 1, None),
        ("redo", 1, "why"),
        ("note", 1, "fine now"),
    ]
    assert trial_indices(out) == [1]
