"""Disk faults while logging: a full disk, a file size limit, a read-only folder. Each gives
one clear line (what happened, which file, what to do) and leaves only whole records:
a record the disk took only part of is cut back off the file (session_log.append_record).

The faults are real: RLIMIT_FSIZE (with SIGXFSZ ignored, as Python does) makes the kernel
take only the bytes below the limit and then refuse with EFBIG; a 64 KiB tmpfs fills up
(a short write, then ENOSPC); a tmpfs remounted read-only refuses with EROFS. The tmpfs
tests need mount(8) and root (skipped otherwise: we run as root, where chmod does not stop
a write)."""

from __future__ import annotations

import json
import os
import re
import resource
import signal
import subprocess
import sys
import textwrap

import pytest
from conftest import TESTS_DIR as CONFTEST_DIR
from conftest import subprocess_env
from test_runner import TESTS_DIR, small_protocol

# Appends records until the disk refuses one; prints how many it wrote and the error.
WRITER = textwrap.dedent("""
    import json, resource, signal, sys
    kind, target, limit = sys.argv[1], sys.argv[2], int(sys.argv[3])
    if limit:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
    if kind == "trials":
        from graspguide.study.runner import append_line
        write = lambda rec: append_line(target, rec)
    else:
        from graspguide.records.storage import SessionLog
        log = SessionLog(target)
        write = log.result if kind == "results" else \\
            lambda rec: log.pose(rec["i"], 0.5, (1.0, 0.0, 0.0, 0.0), False)
    written, error = 0, None
    try:
        for i in range(100000):
            write({"i": i, "pad": "x" * 300})
            written += 1
    except Exception as e:
        error = [type(e).__name__, str(e)]
    print(json.dumps({"written": written, "error": error}))
""")

FILES = {"trials": "trials.jsonl", "results": "results.jsonl", "poses": "poses.csv"}


def _write_until_fault(kind, folder, limit=0):
    target = str(folder / FILES[kind]) if kind == "trials" else str(folder)
    p = subprocess.run(
        [sys.executable, "-c", WRITER, kind, target, str(limit)],
        capture_output=True,
        text=True,
        env=subprocess_env(),
        timeout=60,
    )
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout), str(folder / FILES[kind])


def _whole_records(kind, path, written):
    """The file holds exactly ``written`` complete records, in order, and nothing else."""
    with open(path, "rb") as f:
        data = f.read()
    assert data.endswith(b"\n"), f"{path} ends with a cut line: {data[-60:]!r}"
    rows = data.decode().splitlines()
    if kind == "poses":
        assert rows[0].startswith("send_time_s,")
        assert [int(r.split(",")[1]) for r in rows[1:]] == list(range(written))
    else:
        assert [json.loads(r)["i"] for r in rows] == list(range(written))


@pytest.mark.parametrize("kind", list(FILES))
def test_file_size_limit_cuts_no_record(tmp_path, kind):
    limit = 5000 + 123  # inside a record: a short write, then EFBIG
    out, path = _write_until_fault(kind, tmp_path, limit)
    assert out["written"] >= 5 and out["error"], out
    name, message = out["error"]
    assert name == "RecordWriteError", out
    assert message.startswith(f"cannot write {path}: the file reached a size limit"), message
    assert "\n" not in message and "record was not written" in message
    assert os.path.getsize(path) <= limit
    _whole_records(kind, path, out["written"])


def _mount(where, options):
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True, text=True
    )
    if r.returncode != 0:
        pytest.skip(
            f"cannot mount a tmpfs ({r.stderr.strip() or r.returncode}): needs root and mount(8)"
        )


@pytest.fixture
def small_disk(tmp_path):
    """A 64 KiB file system of its own."""
    disk = tmp_path / "disk"
    disk.mkdir()
    _mount(disk, "size=64k")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


@pytest.mark.parametrize("kind", list(FILES))
def test_full_disk_cuts_no_record(small_disk, kind):
    out, path = _write_until_fault(kind, small_disk)
    assert out["written"] >= 50 and out["error"], out
    name, message = out["error"]
    assert name == "RecordWriteError", out
    assert message.startswith(f"cannot write {path}: the disk is full"), message
    assert "free some space" in message and "\n" not in message
    _whole_records(kind, path, out["written"])


# --------------------------------------------------------------------------------------
def _error_lines(stderr: str) -> list[str]:
    """stderr's lines but the notice a simulated run starts with ("graspguide X:
    SIMULATED: ..."), which comes before any error and is not part of it."""
    return [
        line
        for line in stderr.splitlines()
        if line.strip() and not re.match(r"graspguide \w+: SIMULATED: ", line)
    ]


# `graspguide trial`: one line, exit 1, and the same command completes the study later
# --------------------------------------------------------------------------------------
def _quick_protocol(tmp_path, count):
    """The small protocol with trials of a few poses (no hold, a hand that aligns at
    once), so trials.jsonl soon outgrows every frames file."""
    path, _ = small_protocol(tmp_path, count=count)
    with open(path, encoding="utf-8") as f:
        text = f.read()
    with open(path, "w", encoding="utf-8") as f:
        f.write(text.replace("hold_s = 0.5", "hold_s = 0.0"))
    return path


def _trial(path, out, limit=0):
    def limited():  # pragma: no cover - runs in the child
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))

    env = subprocess_env()
    env["PYTHONPATH"] = os.pathsep.join(
        [TESTS_DIR, CONFTEST_DIR]
    )  # the test source (test_runner.AligningHand)
    env["PYTHONDONTWRITEBYTECODE"] = "1"  # no .pyc write against the limit
    cmd = [
        sys.executable,
        "-m",
        "graspguide",
        "trial",
        "--protocol",
        path,
        "--participant",
        "U2",
        "--port",
        "sim",
        "--source",
        "plugin:test_runner:AligningHand:speed=1e6",
        "--out",
        str(out),
    ]
    return subprocess.run(
        cmd,
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        preexec_fn=limited if limit else None,
    )


def _sizes(folder):
    return {
        os.path.join(d, n): os.path.getsize(os.path.join(d, n))
        for d, _, names in os.walk(folder)
        for n in names
    }


def test_trial_on_a_size_limit_stops_with_one_line_and_resumes(tmp_path):
    path = _quick_protocol(tmp_path, count=4)
    ref = _trial(path, tmp_path / "ref")
    assert ref.returncode == 0, ref.stderr
    ref_trials = tmp_path / "ref" / "U2" / "trials.jsonl"
    lines = ref_trials.read_bytes().splitlines(keepends=True)
    # A resumed study whose trials.jsonl is already larger than any other file the run
    # writes, with a limit inside its next record: that record is the one refused.
    biggest_other = max(
        s for p, s in _sizes(tmp_path / "ref").items() if not p.endswith("trials.jsonl")
    )
    n = next(i for i in range(1, len(lines)) if len(b"".join(lines[:i])) > biggest_other)
    prefix = b"".join(lines[:n])
    limit = len(prefix) + len(lines[n]) // 2
    out = tmp_path / "out"
    (out / "U2").mkdir(parents=True)
    trials = out / "U2" / "trials.jsonl"
    trials.write_bytes(prefix)
    p = _trial(path, out, limit)
    assert p.returncode == 1, (p.stdout, p.stderr)
    err = _error_lines(p.stderr)
    assert len(err) == 1 and "Traceback" not in p.stderr, p.stderr
    assert err[0].startswith(
        f"graspguide trial: error: cannot write {trials}: the file reached a size limit"
    ), err
    assert "completed trials are kept" in err[0]
    assert trials.read_bytes() == prefix  # the refused record left nothing
    with open(out / "U2" / "runs.jsonl", encoding="utf-8") as f:
        assert json.loads(f.read().splitlines()[-1])["outcome"] == "error"
    # the same command without the limit completes the study as one run would have
    p = _trial(path, out)
    assert p.returncode == 0, p.stderr
    keys = ("trial_index", "success", "completion_s", "poses")
    got = [json.loads(x) for x in trials.read_bytes().splitlines()]
    want = [json.loads(x) for x in lines]
    assert [[r[k] for k in keys] for r in got] == [[r[k] for k in keys] for r in want]


def test_trial_into_a_read_only_folder_says_so_in_one_line(tmp_path):
    path = _quick_protocol(tmp_path, count=1)
    ro = tmp_path / "ro"
    ro.mkdir()
    _mount(ro, "size=1m")
    try:
        done = _trial(path, ro / "study")  # a study begun earlier
        assert done.returncode == 0, done.stderr
        before = _sizes(ro)
        r = subprocess.run(["mount", "-o", "remount,ro", str(ro)], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        p = _trial(path, ro / "study")
        assert p.returncode == 1, (p.stdout, p.stderr)
        err = _error_lines(p.stderr)
        assert len(err) == 1 and "Traceback" not in p.stderr, p.stderr
        assert err[0].startswith(f"graspguide trial: error: cannot write {ro / 'study'}"), err
        assert "read-only file system" in err[0] and "use a folder you can write to" in err[0]
        assert _sizes(ro) == before
    finally:
        subprocess.run(["umount", "-l", str(ro)], capture_output=True)


def test_stream_log_on_a_size_limit_stops_with_one_line(tmp_path):
    """`graspguide stream --log` whose telemetry.csv hits a size limit: once a traceback
    (and a second one from writing the end record); now one line, exit 1, whole rows."""

    def limited():  # pragma: no cover - runs in the child
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, resource.RLIM_INFINITY))

    scene = os.path.join(
        os.path.dirname(os.path.dirname(TESTS_DIR)), "examples", "scene_paper_3.toml"
    )
    env = subprocess_env()
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    folder = tmp_path / "session"
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "graspguide",
            "stream",
            "--port",
            "sim",
            "--virtual-clock",
            "--scene",
            scene,
            "--wrench",
            "0.3,-1.2,-0.8",
            "--source",
            "synthetic:rate=240,duration=60,seed=0",
            "--log",
            str(folder),
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        preexec_fn=limited,
    )
    assert p.returncode == 1, (p.stdout, p.stderr)
    err = _error_lines(p.stderr)
    assert len(err) == 1 and "Traceback" not in p.stderr, p.stderr
    assert (
        err[0].startswith("graspguide stream: error: cannot write ") and "size limit" in err[0]
    ), err
    for name in ("poses.csv", "telemetry.csv"):
        data = (folder / name).read_bytes()
        assert data.endswith(b"\n"), name  # no cut row
