"""Shared setup of the tools tests.

The binding and CLI tests run against the package INSTALLED in the interpreter's
environment (``tools/bootstrap.sh`` installs ./tools into .venv), because only that copy
has the compiled extension ``graspguide.core._core``. Other test modules put ``tools/`` at the
front of ``sys.path`` to reach the pure-Python reference; importing the installed
package here, first, keeps ``graspguide`` the installed one for the whole session.
"""

from __future__ import annotations

import os
import pathlib
import signal
import sys

import pytest

# A suite started as a background job of a non-interactive shell (a CI runner's, or
# `cmd &` in a script) inherits SIGINT ignored, and exec keeps an ignored signal ignored
# in every child: the commands under test would then never see the Ctrl-C the tests
# send. A handler here is reset to the default by exec, as a terminal's children have it.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

TESTS_DIR = os.path.dirname(os.path.abspath(__file__))
TOOLS_DIR = os.path.dirname(TESTS_DIR)
REPO_ROOT = os.path.dirname(TOOLS_DIR)
KNOWN_ANSWERS = os.path.join(REPO_ROOT, "test", "data", "known_answers.json")
EXAMPLES = os.path.join(TOOLS_DIR, "examples", "solve_requests.jsonl")

_saved_path = list(sys.path)
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.getcwd()) != TOOLS_DIR]
try:
    import graspguide  # noqa: E402

    try:
        from graspguide.core import _core  # noqa: E402,F401
    except ImportError as e:  # pragma: no cover - setup problem
        _CORE_ERROR = (
            f"graspguide.core._core is not importable ({e}); graspguide comes from "
            f"{os.path.dirname(graspguide.__file__)}. Run `bash tools/bootstrap.sh` "
            "and the tests with .venv/bin/python (tools/run-tests.sh does both)."
        )
    else:
        _CORE_ERROR = None
finally:
    sys.path[:] = _saved_path


@pytest.fixture(scope="session")
def core():
    if _CORE_ERROR:
        pytest.fail(_CORE_ERROR)
    from graspguide.core import _core as module

    return module


def small_protocol_toml(
    name: str,
    seed: int,
    participants: int = 2,
    timeout_s: float = 60.0,
    modalities: tuple[str, ...] = ("F+C", "Fperp+C", "F+V", "Fperp+V"),
    wrenches: int = 2,
    single_motor: int = 1,
    familiarization_trials: int = 0,
) -> str:
    """A study protocol file (docs/study.md) with the paper's three-finger hand, small
    enough for a test: its sessions, wrenches and timeout as given."""
    mods = ", ".join(f'"{m}"' for m in modalities)
    return f"""
[study]
name = "{name}"
seed = {seed}
participants = {participants}
pose_rate_hz = 100.0

[trial]
threshold_deg = 3.0
hold_s = 0.5
timeout_s = {timeout_s!r}
constraints = "paper"
start_quat = [1.0, 0.0, 0.0, 0.0]

[hand]
units = "m"
y_axis = [0.0, 1.0, 0.0]

[hand.k3]
thumb  = [0.045, 0.045, 0.035]
index  = [0.015, 0.095, 0.040]
middle = [-0.010, 0.100, 0.040]

[conditions]
modalities = [{mods}]
contact_counts = [3]

[wrenches]
count = {wrenches}
single_motor = {single_motor}

[familiarization]
trials = {familiarization_trials}
"""


def subprocess_env() -> dict:
    """Environment for CLI subprocesses: no PYTHONPATH (it could put tools/, without the
    compiled extension, in front of the installed package)."""
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    env["PYTHONIOENCODING"] = "utf-8"
    return env


@pytest.fixture(scope="session")
def sketch_build(tmp_path_factory):
    """The Pro Mini sketch, built once per test run with arduino-cli into a temporary
    folder (graspguide.promini.build): no test depends on a build left in build/promini."""
    from graspguide.promini import build

    return build.build_sketch(pathlib.Path(REPO_ROOT), tmp_path_factory.mktemp("promini_sketch"))


@pytest.fixture(scope="session")
def sketch_elf(sketch_build) -> str:
    """Its ELF, for --port promini-sim (graspguide.devices.promini_sim: pass it as ``elf=`` or
    in $GRASPGUIDE_PROMINI_ELF to a command)."""
    return str(sketch_build.elf)


# --------------------------------------------------------------------------------------
# Devices: `--port PATH` runs the hardware subset of test_device_e2e.py against a board;
# without it those tests are skipped (and say so). The simulated-device tests always run.
# --------------------------------------------------------------------------------------
HARDWARE_SKIP_REASON = (
    "hardware test: no board given; run pytest with --port PATH "
    "(e.g. --port /dev/ttyACM0) to run it against a real device"
)


def pytest_addoption(parser):
    group = parser.getgroup("graspguide", "GraspGuide device tests")
    group.addoption(
        "--port",
        action="store",
        default=None,
        metavar="PATH",
        help="serial port of a GraspGuide board: runs the hardware tests of "
        "test_device_e2e.py against it (skipped without this option)",
    )
    group.addoption(
        "--baud",
        action="store",
        type=int,
        default=115200,
        metavar="RATE",
        help="baud rate for --port (default 115200)",
    )


@pytest.fixture(scope="session")
def hardware_port(request):
    """The --port given on the command line; skips the test without one."""
    port = request.config.getoption("--port")
    if not port:
        pytest.skip(HARDWARE_SKIP_REASON)
    return port


def running_in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under CI=true a skip is a failure (the QEMU firmware tests without QEMU or their
    ELF, a missing data file, ...): CI promises that every check that can run here ran.
    Only the hardware tests still skip, since no board is attached to a CI machine (the
    simulated device runs the same checks)."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped and running_in_ci() and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        if HARDWARE_SKIP_REASON not in reason:
            report.outcome = "failed"
            report.longrepr = f"CI=true: this test may not skip here: {reason}"


# Figures the device tests measure (start time, frames/s, latencies, agreement counts),
# printed together at the end of the run so they show in tools/run-tests.sh's output.
_MEASUREMENTS = []


@pytest.fixture(scope="session")
def report_figure():
    """report_figure(name, value_text): one line in the end-of-run summary."""

    def add(name: str, text: str) -> None:
        _MEASUREMENTS.append((name, text))

    return add


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if _MEASUREMENTS:
        terminalreporter.section("device measurements")
        width = max(len(n) for n, _ in _MEASUREMENTS)
        for name, text in _MEASUREMENTS:
            terminalreporter.write_line(f"{name:<{width}}  {text}")
