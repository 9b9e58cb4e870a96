"""The host's side of `--port sim`: the simulated device it starts never outlives it, and a
Ctrl-C or SIGTERM of `graspguide trial` reaches the host alone, which sends STOP before it
closes the simulator (tools/graspguide/link/transport.py, SimulatedDevice.start).

The simulator's own rule (it exits when its parent goes, tools/tests/test_sim_safety.py)
is one half; these tests check the other: the child is started in its own session with
PR_SET_PDEATHSIG, so even a simulator that does not watch its parent is ended."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from conftest import REPO_ROOT, subprocess_env

from graspguide.devices import sim as gsim

PAPER = os.path.join(REPO_ROOT, "protocols", "paper.toml")


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(") ", 1)[1][0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def _children(pid: int, exe: str) -> list:
    """Pids of the processes whose parent is ``pid`` and whose program is ``exe``."""
    exe = os.path.realpath(exe)
    out = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                ppid = int(f.read().rsplit(") ", 1)[1].split()[1])
            prog = os.readlink(f"/proc/{d}/exe").removesuffix(" (deleted)")
        except (OSError, ValueError, IndexError):
            continue
        if ppid == pid and prog == exe:
            out.append(int(d))
    return out


def _gone_within(pid: int, limit_s: float) -> float:
    """Seconds until ``pid`` is gone; fails (and kills it) if it outlives ``limit_s``."""
    t0 = time.monotonic()
    while _alive(pid):
        if time.monotonic() - t0 > limit_s:
            os.kill(pid, signal.SIGKILL)
            pytest.fail(f"simulator {pid} still running {limit_s} s after its host died")
        time.sleep(0.005)
    return time.monotonic() - t0


# A simulator that does not watch its parent (the real one does): only the host's
# PR_SET_PDEATHSIG can end it when the host is SIGKILLed.
STAND_IN = """\
#!{python}
import os, signal, time
master, slave = os.openpty()
print("GRASPGUIDE_SIM_PTY " + os.ttyname(slave), flush=True)
while True:
    time.sleep(60)
"""

HOST = textwrap.dedent("""
    import sys
    from graspguide.devices.sim import SimulatedDevice
    sim = SimulatedDevice(binary=sys.argv[1] or None).start()
    print(sim.process.pid, flush=True)
    sys.stdin.read()
""")


@pytest.mark.parametrize("which", ["stand-in", "sim"])
def test_sigkilled_host_leaves_no_simulator(tmp_path, which, report_figure):
    binary = ""
    if which == "stand-in":
        binary = str(tmp_path / "stand_in")
        with open(binary, "w") as f:
            f.write(STAND_IN.format(python=sys.executable))
        os.chmod(binary, 0o755)
    host = subprocess.Popen(
        [sys.executable, "-c", HOST, binary],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=subprocess_env(),
    )
    try:
        line = host.stdout.readline()
        assert line.strip().isdigit(), host.stderr.read()
        sim_pid = int(line)
        assert _alive(sim_pid)
        with open(f"/proc/{sim_pid}/stat") as f:  # its own session and process group
            fields = f.read().rsplit(") ", 1)[1].split()
        assert int(fields[2]) == int(fields[3]) == sim_pid != os.getpgid(host.pid)
        host.send_signal(signal.SIGKILL)
        host.wait(timeout=10)
        gone_s = _gone_within(sim_pid, 2.0)
    finally:
        if host.poll() is None:
            host.kill()
            host.wait()
        for f in (host.stdin, host.stdout, host.stderr):
            f.close()
    report_figure(f"host SIGKILLed -> its {which} gone", f"{1e3 * gone_s:.1f} ms")


def _wait_trials(path: str, n: int, proc: subprocess.Popen, limit_s: float = 60.0) -> None:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        try:
            with open(path, "rb") as f:
                if f.read().count(b"\n") >= n:
                    return
        except FileNotFoundError:
            pass
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    raise AssertionError(f"{path}: fewer than {n} trials after {limit_s} s")


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm"])
def test_interrupted_trial_stops_cleanly_and_leaves_no_simulator(tmp_path, how):
    """Ctrl-C in a terminal is SIGINT to the whole foreground process group. Once, it
    reached the simulator too, which exited before the host's STOP: "STOP failed: the
    simulated device exited ..." twice."""
    out = tmp_path / "study"
    cmd = [
        sys.executable,
        "-m",
        "graspguide",
        "trial",
        "--protocol",
        PAPER,
        "--participant",
        "U1",
        "--port",
        "sim",
        "--source",
        "participant",
        "--out",
        str(out),
    ]
    p = subprocess.Popen(
        cmd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=subprocess_env(),
        start_new_session=True,
        cwd=REPO_ROOT,
    )
    try:
        _wait_trials(str(out / "U1" / "trials.jsonl"), 2, p)
        sims = _children(p.pid, gsim.find_sim_binary())
        assert len(sims) == 1, sims
        if how == "ctrl-c":
            os.killpg(p.pid, signal.SIGINT)  # as the terminal does
        else:
            p.send_signal(signal.SIGTERM)
        _, stderr = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == 130, stderr
    assert "STOP failed" not in stderr and "Traceback" not in stderr, stderr
    assert "interrupted" in stderr
    _gone_within(sims[0], 2.0)
    with open(out / "U1" / "runs.jsonl", encoding="utf-8") as f:
        assert '"outcome": "interrupted"' in f.read().splitlines()[-1]
