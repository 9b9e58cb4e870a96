"""`graspguide trial` (graspguide.study.runner): a small protocol run against the simulated device
with a closed-loop test source, the output layout the analysis reads, resume after
SIGTERM and SIGKILL (every trial exactly once), a half-written last line, NASA-TLX from a
file, interactively and absent for simulated sources, and STOP on every way out."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import signal
import subprocess
import time
import tomllib

import numpy as np
import pytest
from conftest import TESTS_DIR as CONFTEST_DIR
from conftest import subprocess_env

from graspguide import cli
from graspguide.core.rotations import quat_angle_deg, slerp
from graspguide.exit_codes import EXIT_USAGE
from graspguide.protocol import study_protocol as pf
from graspguide.protocol.tlx import load_tlx_file
from graspguide.records.frames import FRAME_COLUMNS
from graspguide.records.trial import TRIAL_FIELDS
from graspguide.run_errors import RunnerError
from graspguide.sources.poses import aligned_quaternion
from graspguide.sources.trial_sources import ClosedLoopSource, open_runner_source
from graspguide.study import runner as rn
from graspguide.study.jobs import TrialJob
from graspguide.study.progress import Progress

TESTS_DIR = os.path.dirname(os.path.abspath(__file__))


# --------------------------------------------------------------------------------------
# A closed-loop test double of the participant model (not the virtual participant): while
# any motor runs it turns the hand towards the orientation that the core says aligns the
# force with gravity, at a bounded angular speed.
# --------------------------------------------------------------------------------------
@dataclasses.dataclass(eq=False)
class AligningHand:
    SIMULATED = True

    rate_hz: float = 100.0
    speed_deg_s: float = 120.0
    delay_s: float = 0.0
    fail_at: int = 0  # raise at this many steps (over all trials)
    fail_with: str = ""
    steps: int = dataclasses.field(default=0, init=False)
    trials: int = dataclasses.field(default=0, init=False)

    @classmethod
    def from_spec(cls, spec: str, seed: int) -> AligningHand:
        kw = {}
        names = {"rate": "rate_hz", "speed": "speed_deg_s", "delay": "delay_s"}
        for item in filter(None, spec.split(",")):
            key, _, value = item.partition("=")
            if key not in names:
                raise ValueError(f"AligningHand: unknown option {key!r}")
            kw[names[key]] = float(value)
        return cls(**kw)

    def begin_trial(self, *, contacts, y_axis, wrench, policy, mode, start_quat):
        self.target = aligned_quaternion(contacts, wrench, policy, "paper", y_axis)
        self.q = np.asarray(start_quat, dtype=float)
        self.t = 0.0
        self.trials += 1

    def step(self, t_s, pwm):
        self.steps += 1
        if self.fail_at and self.steps >= self.fail_at:
            if self.fail_with == "interrupt":
                raise KeyboardInterrupt
            raise RuntimeError("source failed")
        if self.delay_s:
            time.sleep(self.delay_s)
        dt, self.t = t_s - self.t, t_s
        if any(pwm):
            angle = quat_angle_deg(self.q, self.target)
            if angle > 1e-9:
                self.q = slerp(self.q, self.target, min(1.0, self.speed_deg_s * dt / angle))
        return tuple(float(x) for x in self.q)


class HumanLike(AligningHand):
    SIMULATED = False


SMALL = """
[study]
name = "small"
seed = 11
pose_rate_hz = 100.0

[trial]
threshold_deg = 3.0
hold_s = 0.5
timeout_s = {timeout}

[hand]
units = "m"

[hand.k3]
thumb  = [0.045, 0.045, 0.035]
index  = [0.015, 0.095, 0.040]
middle = [-0.010, 0.100, 0.040]

[conditions]
contact_counts = [3]

[wrenches]
count = 2
single_motor = 1

[familiarization]
trials = {fam}
"""


def small_protocol(tmp_path, timeout=20.0, fam=1, count=2):
    path = tmp_path / "small.toml"
    text = SMALL.format(timeout=timeout, fam=fam).replace("count = 2", f"count = {count}")
    path.write_text(text)
    return str(path), pf.load_protocol(str(path))


class RecordingClient:
    """A DeviceClient whose requests are recorded (names, in order)."""

    def __init__(self, client):
        self._c = client
        self.calls = []

    def __getattr__(self, name):
        attr = getattr(self._c, name)
        if name in ("hello", "set_scene", "start_trial", "stop"):

            def wrapped(*a, **kw):
                self.calls.append(name)
                return attr(*a, **kw)

            return wrapped
        return attr


@pytest.fixture
def sim():
    from graspguide.devices.sim import SimulatedDevice

    with SimulatedDevice(virtual_clock=True, start=True) as dev:
        yield dev


def make_runner(
    protocol, out, source_model, client, participant="U1", tlx=None, ask=None, path="small.toml"
):
    out_text = io.StringIO()
    err = io.StringIO()
    runner = rn.StudyRunner(
        protocol,
        participant,
        str(out),
        ClosedLoopSource(source_model, "plugin:test_runner:AligningHand"),
        client,
        virtual_clock=True,
        tlx=tlx,
        ask=ask,
        progress=Progress(out=out_text, tty=False),
        protocol_file=path,
        err=err,
    )
    return runner, out_text, err


def lines(path):
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f]


# --------------------------------------------------------------------------------------
# A full run
# --------------------------------------------------------------------------------------
def test_full_small_run_and_output_layout(tmp_path, sim):
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path)
    client = RecordingClient(DeviceClient(sim))
    out = tmp_path / "out"
    # the source's own rate (50 Hz) gives way to the protocol's pose rate (100 Hz)
    runner, text, err = make_runner(protocol, out, AligningHand(rate_hz=50.0), client, path=path)
    t0 = time.monotonic()
    result = runner.run()
    elapsed = time.monotonic() - t0
    plan = pf.plan(protocol, "U1")
    assert len(plan) == 1 + 4 * 2
    assert result == {"participant": "U1", "planned": 9, "ran": 9, "skipped": 0, "completed": 9}
    recs = lines(out / "U1" / "trials.jsonl")
    assert [r["trial_index"] for r in recs] == list(range(1, 10))
    for r, t in zip(recs, plan):
        for key in TRIAL_FIELDS:
            assert key in r, key
        assert r["participant"] == "U1" and r["simulated"] is True
        assert (
            r["session"],
            r["k"],
            r["policy"],
            r["mode"],
            r["modality"],
            r["wrench_id"],
            r["single_motor"],
            r["familiarization"],
        ) == (
            t.session,
            t.k,
            t.policy,
            t.mode,
            t.modality,
            t.wrench_id,
            t.single_motor,
            t.familiarization,
        )
        assert r["modality"] == f"{r['policy']}+{r['mode']}"
        assert r["wrench"] == list(t.wrench) and len(r["wrench"]) == 6
        assert r["success"] is True and 0.5 <= r["completion_s"] < 20.0
        assert isinstance(r["completion_s"], float)
        assert r["config_hash"] == protocol.config_hash
        frames = out / "U1" / "frames" / f"trial-{r['trial_index']:04d}.csv"
        with open(frames) as f:
            rows = f.read().splitlines()
        assert rows[0] == ",".join(FRAME_COLUMNS)
        assert len(rows) - 1 == r["poses"]
        assert [float(row.split(",")[0]) for row in rows[1:4]] == [0.0, 0.01, 0.02]
        last = rows[-1].split(",")
        assert float(last[FRAME_COLUMNS.index("error_deg")]) < 3.0
    assert not [n for n in os.listdir(out / "U1" / "frames") if n.endswith(".tmp")]
    # one SET_SCENE per condition change (the familiarization trial has session 1's)
    assert client.calls.count("set_scene") == 4
    assert client.calls.count("start_trial") == 9
    assert client.calls[-1] == "stop"
    tlx = lines(out / "U1" / "tlx.jsonl")
    assert [t["session"] for t in tlx] == [1, 2, 3, 4]
    for t in tlx:
        assert t["scales"] is None and t["simulated"] is True
        assert set(t) >= {"participant", "simulated", "session", "k", "modality", "mode", "scales"}
    study = json.load(open(out / "study.json"))
    assert study["config_hash"] == protocol.config_hash
    assert study["protocol"] == protocol.to_dict()
    assert len(study["wrenches"]) == 2
    assert sum(w["class"] == "single" for w in study["wrenches"]) == 1
    printed = text.getvalue().splitlines()
    assert printed[0].startswith("[1/9] familiarization ")
    assert any(p.startswith("[9/9] session 4/4 ") for p in printed)
    runs = lines(out / "U1" / "runs.jsonl")
    assert [r["event"] for r in runs] == ["start", "end"]
    assert runs[-1]["outcome"] == "complete"
    assert elapsed < 15.0
    # running again does nothing and repeats nothing
    client2 = RecordingClient(DeviceClient(sim))
    runner2, text2, _ = make_runner(protocol, out, AligningHand(), client2, path=path)
    assert runner2.run()["ran"] == 0
    assert "start_trial" not in client2.calls and client2.calls[-1] == "stop"
    assert len(lines(out / "U1" / "trials.jsonl")) == 9
    assert "resuming U1: 9 of 9" in text2.getvalue()


def test_open_loop_source_held_until_timeout(tmp_path, sim):
    """A replay of 0.2 s at the start pose (every wrench starts >= 20 degrees off): its
    last pose is held until the device ends the trial; a failure is recorded with
    completion_s = timeout_s."""
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path, timeout=3.0, fam=0)
    replay = tmp_path / "still.csv"
    replay.write_text("t_s,qw,qx,qy,qz\n" + "".join(f"{i / 100},1,0,0,0\n" for i in range(21)))
    source = open_runner_source(f"replay:{replay}", protocol, "U1")
    assert source.simulated and not source.closed_loop
    out = tmp_path / "out"
    runner = rn.StudyRunner(
        protocol,
        "U1",
        str(out),
        source,
        DeviceClient(sim),
        True,
        progress=Progress(out=io.StringIO(), tty=False),
    )
    runner.run()
    recs = lines(out / "U1" / "trials.jsonl")
    assert len(recs) == 8
    assert all(r["success"] is False and r["completion_s"] == 3.0 for r in recs)
    assert all(r["poses"] >= 300 for r in recs)


# --------------------------------------------------------------------------------------
# Resume: SIGTERM, SIGKILL, damaged last line
# --------------------------------------------------------------------------------------
def _trial_cmd(path, out, extra=(), delay=0.002):
    source = f"plugin:test_runner:AligningHand:delay={delay}"
    return [*TrialJob(str(path), str(out), "U2", source, log="").command(), *extra]


def _env():
    env = subprocess_env()
    env["PYTHONPATH"] = os.pathsep.join(
        [TESTS_DIR, CONFTEST_DIR]
    )  # the test source; graspguide stays the installed one
    return env


def _wait_lines(path, n, proc, limit=30.0):
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        if os.path.exists(path):
            with open(path, "rb") as f:
                if f.read().count(b"\n") >= n:
                    return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    raise AssertionError(f"{path}: fewer than {n} lines after {limit} s")


def test_kill_mid_study_and_resume_every_trial_exactly_once(tmp_path):
    path, protocol = small_protocol(tmp_path, count=3)
    out = tmp_path / "out"
    trials = out / "U2" / "trials.jsonl"
    planned = len(pf.plan(protocol, "U2"))
    assert planned == 13
    # 1) SIGTERM: handled like Ctrl-C (STOP, exit 130, the run's end logged)
    p = subprocess.Popen(
        _trial_cmd(path, out),
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        _wait_lines(trials, 2, p)
        p.send_signal(signal.SIGTERM)
        _, stderr = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == 130, stderr
    assert "interrupted" in stderr and "run the same command again" in stderr
    assert lines(out / "U2" / "runs.jsonl")[-1]["outcome"] == "interrupted"
    # 2) SIGKILL the runner mid-trial (its simulator, in a session of its own, dies with it)
    p = subprocess.Popen(
        _trial_cmd(path, out),
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        before = trials.read_bytes().count(b"\n")
        _wait_lines(trials, before + 3, p)
        time.sleep(0.05)  # into the next trial
        os.killpg(p.pid, signal.SIGKILL)
        p.wait(timeout=10)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == -signal.SIGKILL
    killed_bytes = trials.read_bytes()
    n_killed = killed_bytes.count(b"\n")
    assert 5 <= n_killed < planned
    # 3) the same command again completes the study
    p = subprocess.run(
        _trial_cmd(path, out), env=_env(), capture_output=True, text=True, timeout=60
    )
    assert p.returncode == 0, p.stderr
    assert f"resuming U2: {n_killed} of {planned}" in p.stdout
    final = trials.read_bytes()
    assert final.startswith(killed_bytes)  # append-only: nothing rewritten
    recs = lines(trials)
    assert sorted(r["trial_index"] for r in recs) == list(range(1, planned + 1))
    assert [r["trial_index"] for r in recs] == list(range(1, planned + 1))
    tlx = lines(out / "U2" / "tlx.jsonl")
    assert sorted(t["session"] for t in tlx) == [1, 2, 3, 4]
    frames = os.listdir(out / "U2" / "frames")
    assert sorted(frames) == [f"trial-{i:04d}.csv" for i in range(1, planned + 1)]
    runs = lines(out / "U2" / "runs.jsonl")
    starts = [r for r in runs if r["event"] == "start"]
    assert len(starts) == 3 and starts[-1]["completed_before"] == n_killed
    assert runs[-1]["outcome"] == "complete"
    # the interrupted study gives what an uninterrupted one gives
    p = subprocess.run(
        _trial_cmd(path, tmp_path / "once", delay=0),
        env=_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 0, p.stderr
    keys = ("trial_index", "success", "completion_s", "first_entry_s", "final_error_deg", "poses")
    once = lines(tmp_path / "once" / "U2" / "trials.jsonl")
    assert [[r[k] for k in keys] for r in recs] == [[r[k] for k in keys] for r in once]


def test_half_written_last_line_is_reported_and_rerun(tmp_path, sim):
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path, fam=0)
    out = tmp_path / "out"
    runner, _, _ = make_runner(protocol, out, AligningHand(), DeviceClient(sim), path=path)
    runner.run()
    trials = out / "U1" / "trials.jsonl"
    data = trials.read_bytes()
    cut = data[:-40]  # the last line loses its end
    trials.write_bytes(cut)
    good = cut[: cut.rindex(b"\n") + 1]
    runner, text, err = make_runner(protocol, out, AligningHand(), DeviceClient(sim), path=path)
    assert runner.run()["ran"] == 1
    assert "half-written" in err.getvalue() and "trials.jsonl.damaged-" in err.getvalue()
    aside = [n for n in os.listdir(out / "U1") if n.startswith("trials.jsonl.damaged-")]
    assert len(aside) == 1
    assert (out / "U1" / aside[0]).read_bytes() == cut[len(good) :]
    recs = lines(trials)
    assert sorted(r["trial_index"] for r in recs) == list(range(1, 9))
    assert trials.read_bytes().startswith(good)
    start = [r for r in lines(out / "U1" / "runs.jsonl") if r["event"] == "start"][-1]
    assert start["damaged"] and "half-written" in start["damaged"][0]


def test_damaged_line_before_the_last_stops_the_run(tmp_path, sim):
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path, fam=0)
    out = tmp_path / "out"
    (out / "U1").mkdir(parents=True)
    (out / "U1" / "trials.jsonl").write_text('{"trial_index": 1\n{"trial_index": 2}\n')
    runner, _, _ = make_runner(protocol, out, AligningHand(), DeviceClient(sim), path=path)
    with pytest.raises(RunnerError, match="line 1 is damaged"):
        runner.run()


def test_other_protocol_or_mixed_data_refused(tmp_path, sim):
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path, fam=0, count=1)
    out = tmp_path / "out"
    runner, _, _ = make_runner(protocol, out, AligningHand(), DeviceClient(sim), path=path)
    runner.run()
    text = open(path).read().replace("seed = 11", "seed = 12")
    other = pf.parse_protocol(tomllib.loads(text), "<string>")
    with pytest.raises(RunnerError, match="another protocol"):
        make_runner(other, out, AligningHand(), DeviceClient(sim))[0].run()
    with pytest.raises(RunnerError, match="simulated trials"):
        make_runner(protocol, out, HumanLike(), DeviceClient(sim))[0].run()


# --------------------------------------------------------------------------------------
# NASA-TLX
# --------------------------------------------------------------------------------------
def _tlx_file(tmp_path, rows):
    p = tmp_path / "tlx.jsonl"
    p.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    return str(p)


def _good_tlx(session, **over):
    row = {"session": session, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": session}
    row.update(over)
    return row


def test_tlx_from_file(tmp_path, sim):
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path, fam=0, count=1)
    sessions = pf.session_order(protocol, "U1")
    rows = [_good_tlx(s.session, modality=s.modality, k=3, participant="U1") for s in sessions]
    given = load_tlx_file(_tlx_file(tmp_path, rows), "U1", sessions)
    out = tmp_path / "out"
    runner, _, _ = make_runner(protocol, out, HumanLike(), DeviceClient(sim), tlx=given)
    runner.run()
    tlx = lines(out / "U1" / "tlx.jsonl")
    assert [t["session"] for t in tlx] == [1, 2, 3, 4]
    for t, s in zip(tlx, sessions):
        assert t["origin"] == "file" and t["simulated"] is False
        assert t["modality"] == s.modality and t["mode"] == s.mode and t["k"] == 3
        assert t["scales"] == {"MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": s.session}


@pytest.mark.parametrize(
    "row,needle",
    [
        (_good_tlx(1, MD=0), "MD (Mental Demand) must be in 1..21, got 0"),
        (_good_tlx(1, FR=22), "FR (Frustration) must be in 1..21, got 22"),
        (_good_tlx(1, EF=5.5), "EF (Effort) must be an integer 1..21, got 5.5"),
        (_good_tlx(1, PE="4"), "PE (Performance) must be an integer"),
        (_good_tlx(1, TD=True), "TD (Temporal Demand) must be an integer"),
        ({"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6}, "missing FR"),
        (_good_tlx(1, XX=3), "unknown key 'XX'"),
        (_good_tlx(9), "session must be one of this participant's sessions 1..4"),
        (_good_tlx(1, participant="U7"), "participant 'U7' is not 'U1'"),
        (_good_tlx(1, modality="Fperp+V"), "the file says 'Fperp+V'"),
    ],
)
def test_bad_tlx_values_rejected_with_a_message(tmp_path, capsys, row, needle):
    path, protocol = small_protocol(tmp_path, fam=0, count=1)
    tlx = _tlx_file(tmp_path, [row])
    code = cli.main(
        [
            "trial",
            "--protocol",
            path,
            "--participant",
            "U1",
            "--port",
            "sim",
            "--source",
            "synthetic",
            "--out",
            str(tmp_path / "out"),
            "--tlx",
            tlx,
        ]
    )
    err = capsys.readouterr().err
    assert code == EXIT_USAGE
    assert f"--tlx {tlx}:1: " in err and needle in err, err
    assert not (tmp_path / "out").exists()  # refused before any trial


def test_tlx_asked_interactively_with_retries(tmp_path, sim):
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path, fam=0, count=1)
    answers = iter(["abc", "0", "7"] + ["3"] * 5 + ["4", "5", "6", "7", "8", "9"] * 3)
    prompts = []

    def ask(prompt):
        prompts.append(prompt)
        return next(answers)

    out = tmp_path / "out"
    runner, text, _ = make_runner(protocol, out, HumanLike(), DeviceClient(sim), ask=ask)
    runner.run()
    tlx = lines(out / "U1" / "tlx.jsonl")
    assert tlx[0]["scales"] == {"MD": 7, "TD": 3, "PD": 3, "PE": 3, "EF": 3, "FR": 3}
    assert tlx[1]["scales"] == {"MD": 4, "TD": 5, "PD": 6, "PE": 7, "EF": 8, "FR": 9}
    assert all(t["origin"] == "interactive" and t["simulated"] is False for t in tlx)
    assert prompts[0].strip().startswith("MD (Mental Demand) [1-21]")
    shown = text.getvalue()
    assert "'abc' is not an integer 1..21" in shown and "must be in 1..21, got 0" in shown


def test_tlx_eof_stops_and_resume_asks_again(tmp_path, sim):
    from graspguide.link.client import DeviceClient

    path, protocol = small_protocol(tmp_path, fam=0, count=1)

    def eof(prompt):
        raise EOFError

    out = tmp_path / "out"
    runner, _, _ = make_runner(protocol, out, HumanLike(), DeviceClient(sim), ask=eof)
    with pytest.raises(RunnerError, match="--tlx FILE"):
        runner.run()
    assert len(lines(out / "U1" / "trials.jsonl")) == 1
    assert not (out / "U1" / "tlx.jsonl").exists()
    runner, _, _ = make_runner(protocol, out, HumanLike(), DeviceClient(sim), ask=lambda p: "10")
    assert runner.run()["ran"] == 3
    assert [t["session"] for t in lines(out / "U1" / "tlx.jsonl")] == [1, 2, 3, 4]


# --------------------------------------------------------------------------------------
# STOP on the way out
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("how,exc", [("interrupt", KeyboardInterrupt), ("error", RuntimeError)])
def test_stop_sent_on_exit(tmp_path, sim, how, exc):
    from graspguide.link.client import DeviceClient
    from graspguide.link.messages import DeviceState

    path, protocol = small_protocol(tmp_path, fam=0, count=1)
    client = RecordingClient(DeviceClient(sim))
    # fail in the second trial, mid-stream
    model = AligningHand(fail_at=10**9, fail_with=how)
    out = tmp_path / "out"
    runner, _, _ = make_runner(protocol, out, model, client)
    orig = model.begin_trial

    def begin(**kw):
        orig(**kw)
        if model.trials == 2:
            model.fail_at = model.steps + 20

    model.begin_trial = begin
    with pytest.raises(exc):
        runner.run()
    assert client.calls[-1] == "stop"
    assert client.calls.count("start_trial") == 2
    assert client._c.status().state == DeviceState.STOPPED  # the trial is not running
    assert len(lines(out / "U1" / "trials.jsonl")) == 1
    assert lines(out / "U1" / "runs.jsonl")[-1]["outcome"] == (
        "interrupted" if how == "interrupt" else "error"
    )
    assert not (out / "U1" / "frames" / "trial-0002.csv").exists()


def test_cli_usage_errors(tmp_path, capsys):
    path, _ = small_protocol(tmp_path)
    base = ["trial", "--protocol", path, "--port", "sim", "--out", str(tmp_path / "o")]
    assert cli.main(base + ["--participant", "Ux", "--source", "synthetic"]) == 2
    assert "participant id 'Ux'" in capsys.readouterr().err
    assert cli.main(base + ["--participant", "U1", "--source", "bogus"]) == 2
    assert 'unknown source "bogus"' in capsys.readouterr().err
    assert (
        cli.main(
            [
                "trial",
                "--protocol",
                str(tmp_path / "no.toml"),
                "--participant",
                "U1",
                "--port",
                "sim",
                "--source",
                "synthetic",
            ]
        )
        == 2
    )
    assert "cannot read the protocol file" in capsys.readouterr().err
    assert (
        cli.main(
            base + ["--participant", "U1", "--source", "plugin:test_runner:AligningHand:warp=9"]
        )
        == 2
    )
    assert "unknown option 'warp'" in capsys.readouterr().err


# --------------------------------------------------------------------------------------
# Real time and the terminal view
# --------------------------------------------------------------------------------------
def test_real_time_run_on_the_device_clock(tmp_path):
    """Without the virtual clock (a board, or a person): poses paced by the host clock,
    host_time_us from it, a progress line every period."""
    from graspguide.devices.sim import SimulatedDevice
    from graspguide.link.client import DeviceClient

    path = tmp_path / "rt.toml"
    path.write_text(
        SMALL.format(timeout=5.0, fam=0)
        .replace("contact_counts = [3]", 'contact_counts = [3]\nmodalities = ["F+V"]')
        .replace("single_motor = 1", "single_motor = 0")
        .replace("count = 2", "count = 1")
    )
    protocol = pf.load_protocol(str(path))
    out = tmp_path / "out"
    text = io.StringIO()
    with SimulatedDevice(virtual_clock=False, start=True) as dev:
        runner = rn.StudyRunner(
            protocol,
            "U1",
            str(out),
            ClosedLoopSource(AligningHand(speed_deg_s=240.0), "test"),
            DeviceClient(dev),
            virtual_clock=False,
            progress=Progress(out=text, tty=False, period_s=0.2),
        )
        runner.run()
    (rec,) = lines(out / "U1" / "trials.jsonl")
    assert rec["success"] is True
    assert rec["wall_s"] >= 0.9 * rec["completion_s"]  # paced in real time
    with open(out / "U1" / "frames" / "trial-0001.csv") as f:
        rows = [r.split(",") for r in f.read().splitlines()[1:]]
    times = [int(r[1]) for r in rows]
    assert all(b >= a for a, b in zip(times, times[1:]))
    assert (times[-1] - times[0]) / 1e6 >= 0.9 * float(rows[-1][0])
    assert sum(" t=" in line for line in text.getvalue().splitlines()) >= 2


def test_terminal_progress_line():
    buf = io.StringIO()
    view = Progress(out=buf, tty=True)
    trial = pf.PlannedTrial(
        3,
        "U1",
        1,
        2,
        4,
        "Fperp",
        "V",
        "Fperp+V",
        "W05",
        (0.0, 0.0, -1.0, 0, 0, 0),
        False,
        "multi",
        False,
    )
    view.trial_start(trial, 100, 8)
    view.frame(1.25, 12.5, [0, 120, 80, 70], real_time=False)
    view.trial_end({"success": True, "completion_s": 4.5, "final_error_deg": 1.25})
    shown = buf.getvalue()
    assert "\r\x1b[K[3/100] session 1/8 Fperp+V k=4 W05" in shown
    assert "t=  1.25s error= 12.50deg pwm=[0, 120, 80, 70]" in shown
    assert shown.endswith("W05 success 4.50 s, final error 1.25 deg\n")


def test_device_lost_mid_trial_keeps_the_link_error(tmp_path):
    """The simulated device dies in trial 2: the run ends with the link error (not the
    failed STOP's), trial 1 is kept, the end of the run is logged."""
    from graspguide.devices.sim import SimulatedDevice
    from graspguide.link.client import DeviceClient
    from graspguide.link.transport import LinkError

    path, protocol = small_protocol(tmp_path, fam=0, count=1)
    out = tmp_path / "out"
    with SimulatedDevice(virtual_clock=True, start=True) as dev:
        model = AligningHand()
        orig = model.step

        def step(t_s, pwm):
            if model.trials == 2 and t_s > 0.1 and dev.process.poll() is None:
                dev.process.kill()
                dev.process.wait()
            return orig(t_s, pwm)

        model.step = step
        client = DeviceClient(dev, timeout=0.3)
        runner, _, err = make_runner(protocol, out, model, client)
        with pytest.raises(LinkError):
            runner.run()
    assert "STOP failed" in err.getvalue()
    assert len(lines(out / "U1" / "trials.jsonl")) == 1
    assert lines(out / "U1" / "runs.jsonl")[-1]["outcome"] == "error"
