"""`graspguide plan` and `graspguide mp build|deploy|run` (graspguide.mp).

The plan file is checked against the C++ simulated device's store (the plan region it
writes) and its levels against the C++ core. Deployment runs the real mpremote against the
real MicroPython interpreter (unix port) behind a pty, joined to mpremote by a local TCP
socket (`socket://`, which pyserial opens without the modem-line ioctls a pty refuses);
the bridge restarts the interpreter when mpremote soft-resets it, as a board reboots."""

from __future__ import annotations

import json
import math
import os
import pty
import select
import socket
import struct
import subprocess
import sys
import threading
import tty
import zlib
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from graspguide.cli import main
from graspguide.core import solver
from graspguide.link.client import to_f32
from graspguide.link.messages import PlanBegin, PlanTrial
from graspguide.mp.deploy import MpToolError, build
from graspguide.mp.plan_file import PlanSolveError, encode_plan_file

ROOT = Path(__file__).resolve().parents[3]
PROTOCOL = str(ROOT / "protocols" / "paper.toml")
MICROPYTHON = Path(sys.executable).parent / "micropython"
# The layout as docs (graspguide/mp/plan_file.py) state it, written out independently.
PREAMBLE = struct.Struct("<IHHII")
LEVELS_HEAD = struct.Struct("<IHHI")
LEVELS_TRIAL = struct.Struct("<BBH4f3f")
PLAN_ARGS = ["--participant", "U2", "--rest-s", "1.5", "--imu-to-hand", "0,1,0,0", "--simulated"]
# Layout 2: the 148 bytes of PLAN_BEGIN's fields of layout 1, then pwm_floor u8[4], gain f32[4].
PLAN_LAYOUT = 2
HEADER_BYTES = 148 + 4 + 4 * 4
TRIAL_BYTES = 35
# A participant's calibration as `graspguide calibrate` writes it (the gains exact in f32).
CALIBRATION = {"pwm_floor": [55, 80, 64, 70], "gain": [1.5, 0.75, 1.25, 1.0]}


def _calibration_file(tmp_path: Path) -> str:
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps({"participant": "U2", **CALIBRATION}))
    return str(path)


def _cpp_plan_region(tmp_path: Path, *extra: str) -> bytes:
    """The plan region the C++ simulated device stores for PLAN_ARGS."""
    store = tmp_path / "u2.store"
    rc = main(
        ["device", "plan", "--port", "sim", "--store", str(store), "--protocol", PROTOCOL]
        + PLAN_ARGS
        + list(extra)
    )
    assert rc == 0
    data = store.read_bytes()
    length = PREAMBLE.unpack_from(data)[3]
    return data[: PREAMBLE.size + length]


def _plan_cli(tmp_path: Path, *extra: str) -> bytes:
    out = tmp_path / "plan.bin"
    assert main(["plan", "--protocol", PROTOCOL, "--out", str(out), *PLAN_ARGS, *extra]) == 0
    return out.read_bytes()


def test_plan_file_is_the_cpp_devices_plan_region(tmp_path: Path) -> None:
    region = _cpp_plan_region(tmp_path)
    assert _plan_cli(tmp_path) == region
    begin, _ = _decode_region(region)
    assert (begin.pwm_floor, begin.gain) == ((70,) * 4, (1.0,) * 4), "no calibration: identity"


def test_a_calibrated_plan_file_is_the_cpp_devices_calibrated_plan_region(tmp_path: Path) -> None:
    cal = _calibration_file(tmp_path)
    region = _cpp_plan_region(tmp_path, "--calibration", cal)
    assert _plan_cli(tmp_path, "--calibration", cal) == region
    begin, _ = _decode_region(region)
    assert list(begin.pwm_floor) == CALIBRATION["pwm_floor"]
    assert list(begin.gain) == CALIBRATION["gain"]
    assert region != _plan_cli(tmp_path), "the calibration is part of the plan"


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (None, "does not exist"),
        ("{", "is not JSON"),
        ('{"pwm_floor": [70, 70, 70]}', "missing gain"),
        ('{"pwm_floor": [70, 70, 255, 70], "gain": [1, 1, 1, 1]}', "pwm_floor[2] (middle)"),
        ('{"pwm_floor": [70, 70, 70, 70], "gain": [1, 9, 1, 1]}', "gain[1] (index)"),
    ],
)
def test_plan_with_a_bad_calibration_file_is_a_usage_error_naming_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None, words: str
) -> None:
    path = tmp_path / "calibration.json"
    if content is not None:
        path.write_text(content)
    out = tmp_path / "plan.bin"
    args = ["plan", "--protocol", PROTOCOL, "--out", str(out), *PLAN_ARGS]
    assert main([*args, "--calibration", str(path)]) == 2
    err = capsys.readouterr().err
    assert words in err and str(path) in err, err
    assert not out.exists(), "nothing written from a calibration half read"


def _decode_region(region: bytes) -> tuple[PlanBegin, list[PlanTrial]]:
    magic, version, _, length, crc = PREAMBLE.unpack_from(region)
    assert (magic, version, zlib.crc32(region[16:])) == (0x4C504747, PLAN_LAYOUT, crc)
    begin = PlanBegin.unpack(region[16 : 16 + HEADER_BYTES])
    assert length == HEADER_BYTES + TRIAL_BYTES * begin.trial_count
    trials = []
    for i in range(begin.trial_count):
        at = 16 + HEADER_BYTES + TRIAL_BYTES * i
        trials.append(PlanTrial.unpack(struct.pack("<H", i) + region[at : at + TRIAL_BYTES]))
    return begin, trials


def test_plan_levels_are_the_cpp_cores_for_the_stored_posture(tmp_path: Path) -> None:
    region = _cpp_plan_region(tmp_path)
    data = _plan_cli(tmp_path, "--levels")
    assert data[: len(region)] == region
    begin, trials = _decode_region(region)
    block = data[len(region) :]
    magic, version, count, plan_id = LEVELS_HEAD.unpack_from(block)
    assert (magic, version, count) == (0x564C4747, 1, len(trials))
    assert plan_id == zlib.crc32(region[16:])
    body_end = LEVELS_HEAD.size + LEVELS_TRIAL.size * count
    assert len(block) == body_end + 4
    assert struct.unpack_from("<I", block, body_end)[0] == zlib.crc32(block[:body_end])
    policy = {0: "F", 1: "Fperp"}
    mode = {0: "C", 1: "V"}
    constraints = {0: "paper", 1: "normal", 2: "none"}
    for i, t in enumerate(trials):
        status, k, reserved, *rest = LEVELS_TRIAL.unpack_from(block, LEVELS_HEAD.size + 32 * i)
        levels, f_hat = rest[:4], rest[4:]
        want = solver.solve(
            [list(c) for c in (begin.hand_k3 if t.k == 3 else begin.hand_k4)],
            list(t.wrench),
            policy=policy[t.policy],
            mode=mode[t.mode],
            constraints=constraints[begin.constraints],
            y_axis=list(begin.y_axis),
        )
        assert (status, k, reserved) == (solver.STATUS_NAMES.index(want["status"]), t.k, 0)
        assert levels == [to_f32(v) for v in want["levels"]] + [0.0] * (4 - t.k)
        force = t.wrench[:3]
        norm = math.sqrt(sum(f * f for f in force))
        assert f_hat == pytest.approx([f / norm for f in force], abs=1e-7)


def test_new_store_is_the_cpp_devices_store_after_storing_the_plan(tmp_path: Path) -> None:
    from graspguide.mp.plan_file import STORE_BYTES, fresh_store

    _cpp_plan_region(tmp_path)  # the simulated device's fresh 0xFF store, then the plan
    new = fresh_store(_plan_cli(tmp_path, "--levels"))
    # What the port's FileStore makes of it: extended to its size with erased bytes.
    padded = new + b"\xff" * (STORE_BYTES - len(new))
    assert padded == (tmp_path / "u2.store").read_bytes()


def test_levels_text_holds_each_trials_float32_levels(tmp_path: Path) -> None:
    from graspguide.hostless.plan_upload import plan_messages, planned_trials
    from graspguide.mp.plan_file import levels_text
    from graspguide.protocol.study_protocol import load_protocol

    protocol = load_protocol(PROTOCOL)
    begin, trials = plan_messages(protocol, "U1", planned_trials(protocol, "U1"), False, 2.0)
    data, levels = encode_plan_file(begin, trials, with_levels=True)
    block = data[16 + HEADER_BYTES + TRIAL_BYTES * len(trials) + LEVELS_HEAD.size :]
    plan = zlib.crc32(data[16 : 16 + HEADER_BYTES + TRIAL_BYTES * len(trials)])
    text = levels_text(trials, levels, plan).splitlines()
    assert text[1] == f"plan_id {plan:08x}"
    rows = [line.split() for line in text[2:]]
    assert len(rows) == len(trials)
    for i, (row, t) in enumerate(zip(rows, trials)):
        stored = LEVELS_TRIAL.unpack_from(block, 32 * i)[3 : 3 + t.k]
        assert row[:2] == [str(t.trial_index), "ok"]
        assert [to_f32(float(v)) for v in row[2:]] == list(stored)


def test_plan_refuses_a_trial_the_core_cannot_solve() -> None:
    from graspguide.hostless.plan_upload import plan_messages, planned_trials
    from graspguide.protocol.study_protocol import load_protocol

    protocol = load_protocol(PROTOCOL)
    begin, trials = plan_messages(protocol, "U1", planned_trials(protocol, "U1"), False, 2.0)
    trials[3] = replace(trials[3], wrench=(0.0, 0.0, 0.0, 0.1, 0.0, 0.0))
    with pytest.raises(PlanSolveError, match=r"position 3 .*zero_force"):
        encode_plan_file(begin, trials, with_levels=True)


def test_plan_bad_participant_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "p.bin"
    rc = main(["plan", "--protocol", PROTOCOL, "--participant", "U123456789", "--out", str(out)])
    assert rc == 2 and not out.exists()
    assert "U123456789" in capsys.readouterr().err


def test_plan_missing_protocol_or_unwritable_out_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["plan", "--participant", "U1", "--out", str(tmp_path / "p.bin")]) == 2
    assert "--protocol FILE is required" in capsys.readouterr().err
    out = tmp_path / "no-such-dir" / "p.bin"
    assert main(["plan", "--protocol", PROTOCOL, "--participant", "U1", "--out", str(out)]) == 1
    assert f"cannot write {out}" in capsys.readouterr().err


# --- mp build ---------------------------------------------------------------------------
def _fake_port(root: Path, value: int = 42, flat: bool = False) -> Path:
    """A small port: a package with a subpackage (or none: ``flat``, like the real one),
    main.py, and host-only files."""
    port = root / "micropython"
    pkg = port / "graspguide_mp"
    twice = pkg / ("twice.py" if flat else "sub/twice.py")
    twice.parent.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "answer.py").write_text(f"VALUE = {value}\n")
    if not flat:
        (pkg / "sub" / "__init__.py").write_text("")
    twice.write_text("from graspguide_mp.answer import VALUE\ndef twice():\n    return 2 * VALUE\n")
    module = "graspguide_mp.twice" if flat else "graspguide_mp.sub.twice"
    (port / "main.py").write_text(
        f"import os\nfrom {module} import twice\n"
        "try:\n    plan = os.stat('plan.bin')[6]\nexcept OSError:\n    plan = -1\n"
        "print('port says', twice(), 'plan bytes', plan)\n"
    )
    (port / "tests").mkdir()
    (port / "tests" / "test_x.py").write_text("def test_x():\n    pass\n")
    (port / "solve_server.py").write_text("print('host only')\n")
    return port


STAGED = [
    "lib/graspguide_mp/__init__.mpy",
    "lib/graspguide_mp/answer.mpy",
    "lib/graspguide_mp/sub/__init__.mpy",
    "lib/graspguide_mp/sub/twice.mpy",
    "main.py",
]


def test_mp_build_stages_the_boards_file_system(tmp_path: Path) -> None:
    port = _fake_port(tmp_path)
    out = tmp_path / "stage"
    out.mkdir()
    (out / "lib" / "graspguide_mp").mkdir(parents=True)
    (out / "lib" / "graspguide_mp" / "removed.mpy").write_bytes(b"stale")
    rc = main(
        ["mp", "build", "--out", str(out), "--src", str(port), "--plan-protocol", PROTOCOL]
        + PLAN_ARGS
    )
    assert rc == 0
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert files == sorted(STAGED + ["plan.bin"])
    assert (out / "main.py").read_text() == (port / "main.py").read_text()
    assert (out / "plan.bin").read_bytes() == _plan_cli(tmp_path)
    # The staged layout runs on the real interpreter with lib/ on its path, as on a board.
    res = subprocess.run(
        [str(MICROPYTHON), "main.py"],
        cwd=out,
        env=dict(os.environ, MICROPYPATH=".frozen:lib"),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert res.stdout.split() == [
        "port",
        "says",
        "84",
        "plan",
        "bytes",
        str(len(_plan_cli(tmp_path))),
    ]


def test_mp_build_of_a_module_that_is_not_micropython_names_file_and_line(tmp_path: Path) -> None:
    port = _fake_port(tmp_path)
    (port / "graspguide_mp" / "broken.py").write_text("x = 1\ndef f(:\n    pass\n")
    with pytest.raises(MpToolError, match=r"broken\.py.*line 2"):
        build(tmp_path / "stage", str(port))


def test_mp_build_of_native_code_needs_an_arch(tmp_path: Path) -> None:
    port = _fake_port(tmp_path)
    (port / "graspguide_mp" / "fast.py").write_text(
        "import micropython\n@micropython.native\ndef f(x):\n    return x + 1\n"
    )
    with pytest.raises(MpToolError, match="give --arch"):
        build(tmp_path / "stage", str(port))
    staged = build(tmp_path / "stage", str(port), arch="x64")
    assert "lib/graspguide_mp/fast.mpy" in staged.files


def test_mp_build_of_the_real_port(tmp_path: Path) -> None:
    staged = build(tmp_path / "stage", str(ROOT / "micropython"))
    sources = sorted((ROOT / "micropython" / "graspguide_mp").rglob("*.py"))
    want = {
        "lib/" + p.relative_to(ROOT / "micropython").with_suffix(".mpy").as_posix() for p in sources
    }
    assert set(staged.files) == want | {"main.py"}


# --- mp deploy / run: the exact mpremote command lines -----------------------------------
@pytest.fixture
def tty_path() -> Iterator[str]:
    """A serial port that exists (a pty's), for the commands that check --port first."""
    master, slave = pty.openpty()
    yield os.ttyname(slave)
    os.close(master)
    os.close(slave)


def test_mp_deploy_and_run_command_lines(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tty_path: str
) -> None:
    """mpremote replaced by a recording stub, for this check only: what deploy runs, where,
    with which staged files."""
    record = tmp_path / "calls.jsonl"
    stub = tmp_path / "mpremote-stub"
    stub.write_text(
        f"#!{sys.executable}\nimport json, os, sys\n"
        f"with open({str(record)!r}, 'a') as f:\n"
        "    files = sorted(os.path.relpath(os.path.join(d, n)) for d, _, ns in os.walk('.') "
        "for n in ns)\n"
        "    f.write(json.dumps({'argv': sys.argv[1:], 'files': files}) + '\\n')\n"
    )
    stub.chmod(0o755)
    monkeypatch.setenv("GRASPGUIDE_MPREMOTE", str(stub))
    port = _fake_port(tmp_path)
    assert main(["mp", "deploy", "--port", tty_path, "--src", str(port)]) == 0
    assert (
        main(
            [
                "mp",
                "deploy",
                "--port",
                tty_path,
                "--src",
                str(port),
                "--plan-protocol",
                PROTOCOL,
                "--levels",
                "--new-store",
            ]
            + PLAN_ARGS
        )
        == 0
    )
    assert main(["mp", "run", "--port", tty_path, "--src", str(port)]) == 0
    calls = [json.loads(line) for line in record.read_text().splitlines()]
    assert len(calls) == 3
    for call, plan in zip(calls[:2], (False, True)):
        argv = call["argv"]
        assert argv[:3] == ["connect", tty_path, "exec"]
        assert "_rm('lib/graspguide_mp')" in argv[3]
        assert ("_rm('graspguide_levels.txt')" in argv[3]) == plan
        copies = argv[4:]
        want = ["+", "fs", "cp", "-r", "lib/graspguide_mp", ":lib"]
        want += ["+", "fs", "cp", "main.py", ":main.py"]
        data = ["plan.bin", "graspguide_levels.txt", "graspguide.bin"] if plan else []
        for name in data:
            want += ["+", "fs", "cp", name, ":" + name]
        assert copies == want
        assert call["files"] == sorted(STAGED + data)
    assert calls[2]["argv"] == ["connect", tty_path, "run", str(port / "main.py")]


def test_mp_deploy_without_mpremote_fails_naming_the_fix(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    tty_path: str,
) -> None:
    monkeypatch.setenv("GRASPGUIDE_MPREMOTE", str(tmp_path / "no-such-mpremote"))
    port = _fake_port(tmp_path)
    assert main(["mp", "deploy", "--port", tty_path, "--src", str(port)]) == 1
    assert "cannot run" in capsys.readouterr().err


# --- mp deploy / run end to end: real mpremote, real interpreter --------------------------
class Board:
    """The unix MicroPython interpreter as a board: its file system is ``root`` (with lib/
    on sys.path, as a board's /lib), its REPL behind a pty, offered to mpremote on
    socket://127.0.0.1:PORT. A soft reset (Ctrl-D in the raw REPL) ends the unix
    interpreter, so the bridge starts a new one and answers "soft reboot" like a board."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = f"socket://127.0.0.1:{self.server.getsockname()[1]}"
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _spawn(self) -> tuple[int, subprocess.Popen[bytes]]:
        master, slave = pty.openpty()
        tty.setraw(slave)
        proc = subprocess.Popen(
            [str(MICROPYTHON)],
            stdin=slave,
            stdout=slave,
            stderr=slave,
            cwd=self.root,
            env=dict(os.environ, MICROPYPATH=".frozen:lib"),
        )
        os.close(slave)
        return master, proc

    def _serve(self) -> None:
        self.server.settimeout(0.1)
        while not self.stop.is_set():
            try:
                conn, _ = self.server.accept()
            except TimeoutError:
                continue
            master, proc = self._spawn()
            try:
                self._relay(conn, master, proc)
            finally:
                conn.close()
                proc.kill()
                proc.wait()
                os.close(master)

    def _relay(self, conn: socket.socket, master: int, proc: subprocess.Popen[bytes]) -> None:
        while not self.stop.is_set():
            ready, _, _ = select.select([conn, master], [], [], 0.1)
            if conn in ready:
                data = conn.recv(4096)
                if not data:
                    return
                os.write(master, data)
            if master in ready:
                try:
                    data = os.read(master, 4096)
                except OSError:  # EIO: the interpreter exited (a soft reset)
                    data = b""
                if data:
                    conn.sendall(data)
                    continue
                proc.wait()
                os.close(master)
                master, proc = self._spawn()
                os.write(master, b"\r\x01")  # back to the raw REPL mpremote was in
                conn.sendall(b"soft reboot\r\n")

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        self.server.close()


@pytest.fixture
def board(tmp_path: Path) -> Iterator[Board]:
    root = tmp_path / "board"
    root.mkdir()
    b = Board(root)
    yield b
    b.close()


def test_mp_deploy_and_run_end_to_end_on_the_interpreter(
    tmp_path: Path, board: Board, capfd: pytest.CaptureFixture[str]
) -> None:
    (board.root / "graspguide.store").write_bytes(b"\xff" * 64)  # the results: never touched
    (board.root / "lib" / "graspguide_mp").mkdir(parents=True)
    (board.root / "lib" / "graspguide_mp" / "removed.mpy").write_bytes(b"stale")
    port = _fake_port(tmp_path)
    staging = tmp_path / "staging"
    rc = main(
        ["mp", "deploy", "--port", board.port, "--src", str(port), "--staging", str(staging)]
        + ["--plan-protocol", PROTOCOL, "--levels"]
        + PLAN_ARGS
    )
    assert rc == 0, capfd.readouterr()
    on_board = sorted(
        p.relative_to(board.root).as_posix() for p in board.root.rglob("*") if p.is_file()
    )
    data = ["plan.bin", "graspguide_levels.txt"]
    assert on_board == sorted(STAGED + data + ["graspguide.store"])
    for rel in STAGED + data:
        assert (board.root / rel).read_bytes() == (staging / rel).read_bytes(), rel
    assert (board.root / "graspguide.store").read_bytes() == b"\xff" * 64
    capfd.readouterr()

    assert main(["mp", "run", "--port", board.port, "--src", str(port)]) == 0
    plan_bytes = (staging / "plan.bin").stat().st_size
    assert f"port says 84 plan bytes {plan_bytes}" in capfd.readouterr().out

    # A second deploy replaces the package (a changed module is what runs).
    port2 = _fake_port(tmp_path / "v2", value=5, flat=True)
    assert main(["mp", "deploy", "--port", board.port, "--src", str(port2)]) == 0
    capfd.readouterr()
    assert main(["mp", "run", "--port", board.port, "--src", str(port2)]) == 0
    assert "port says 10" in capfd.readouterr().out
    assert sorted(p.name for p in (board.root / "lib" / "graspguide_mp").iterdir()) == [
        "__init__.mpy",
        "answer.mpy",
        "twice.mpy",
    ]


def test_mp_deploy_of_the_real_port_loads_its_plan_and_levels_on_the_interpreter(
    tmp_path: Path, board: Board, capfd: pytest.CaptureFixture[str]
) -> None:
    """The real port deployed with a new store and levels: the deployed .mpy modules load
    the store's plan and the levels file on the interpreter (main.py itself needs
    machine.PWM/I2C/Pin, which only a board has)."""
    rc = main(
        ["mp", "deploy", "--port", board.port, "--arch", "x64", "--new-store", "--levels"]
        + ["--plan-protocol", PROTOCOL]
        + PLAN_ARGS
    )
    assert rc == 0, capfd.readouterr()
    capfd.readouterr()
    check = (
        "from graspguide_mp.store import FileStore\n"
        "from graspguide_mp import plan_file as pf\n"
        "from graspguide_mp import runner as rn\n"
        "s = FileStore('graspguide.bin')\n"
        "status, plan = pf.load_plan(s)\n"
        "post = rn.PrecomputedPostures.load('graspguide_levels.txt')\n"
        "print('LOADED', status == pf.OK, len(plan.trials), len(post.table))\n"
    )
    res = subprocess.run(
        [str(Path(sys.executable).parent / "mpremote"), "connect", board.port, "exec", check],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    _, trials = _decode_region(_cpp_plan_region(tmp_path))
    assert f"LOADED True {len(trials)} {len(trials)}" in res.stdout, res.stdout + res.stderr


def test_mp_log_downloads_the_boards_records_as_device_log_does(
    tmp_path: Path, board: Board, capfd: pytest.CaptureFixture[str]
) -> None:
    """Records the port wrote on the "board" (the interpreter's file system) come back
    through mpremote and the C++ store reader into the runner's folder format."""
    port_dir = ROOT / "micropython"
    writer = (
        "import sys\n"
        f"sys.path[:0] = [{str(port_dir)!r}, {str(port_dir / 'tests')!r}]\n"
        "from graspguide_mp import plan_file as pf, results_file as rf\n"
        "from graspguide_mp.store import FileStore\n"
        "from hostless_helpers import make_plan\n"
        "plan = make_plan(3, participant=b'U7')\n"
        "store = FileStore('graspguide.bin')\n"
        "assert pf.save_plan(store, plan) == pf.OK\n"
        "log = rf.ResultsLog(store)\n"
        "assert log.mount() == pf.OK\n"
        "for i, ok in ((0, True), (1, False)):\n"
        "    r = rf.LogRecord(plan.trials[i])\n"
        "    r.success, r.completion_s, r.final_error_deg = ok, 4.5 if ok else 90.0, 1.25\n"
        "    assert log.append(r, pf.plan_id(plan)) == pf.OK\n"
        "store.close()\n"
    )
    res = subprocess.run(
        [str(MICROPYTHON), "-c", writer], cwd=board.root, capture_output=True, timeout=60
    )
    assert res.returncode == 0, res.stdout + res.stderr
    out = tmp_path / "study"
    assert main(["mp", "log", "--port", board.port, "--out", str(out)]) == 0, capfd.readouterr()
    assert "2 record(s) of 3 planned trials" in capfd.readouterr().out
    lines = [json.loads(x) for x in (out / "U7" / "trials.jsonl").read_text().splitlines()]
    assert [(r["trial_index"], r["success"], r["completion_s"]) for r in lines] == [
        (1, True, 4.5),
        (2, False, 90.0),
    ]
    assert all(r["hostless"] and r["participant"] == "U7" for r in lines)
    # A store path the board does not have: mpremote fails and the command says so.
    missing = ["mp", "log", "--port", board.port, "--out", str(out), "--store-path", "nope.bin"]
    assert main(missing) == 1
    assert "mpremote exited" in capfd.readouterr().err
