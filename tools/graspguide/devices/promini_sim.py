"""The Pro Mini sketch under simavr as a :class:`~graspguide.link.transport.Transport`, for
``--port promini-sim``.

:class:`ProMiniSimDevice` runs ``src/harness/promini_sim/runner.c`` (a libsimavr program:
the ATmega328P at 8 MHz, UART0 on a pseudo-terminal, the motor PWM read from the timers'
registers) on the sketch's ELF, and talks to it exactly as :class:`SimulatedDevice` talks
to the simulated device: it is one, with another command. :func:`build_runner` compiles
the runner with the system C compiler into ``.pio/build-promini_sim/`` when it is missing
or older than its source; :func:`find_promini_elf` locates the sketch's ELF, and
:class:`ProMiniSimDevice` builds the sketch (:func:`build_promini_elf`) when it is missing.
"""

from __future__ import annotations

import fcntl
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence

from graspguide.devices.sim import DEFAULT_SIM_GRACE, DEFAULT_SIM_START_TIMEOUT, SimulatedDevice
from graspguide.link.transport import DEFAULT_BAUDRATE, DeviceNotFound, LinkError, SimNotBuilt
from graspguide.repo_root import find_repo_root as _find_repo_root

PROMINI_SIM_PORT = "promini-sim"
PROMINI_ELF_ENV = "GRASPGUIDE_PROMINI_ELF"
RUNNER_SOURCE = os.path.join("src", "harness", "promini_sim", "runner.c")
# Beside pio's build folders, not in one: pio deletes .pio/build whole when its project
# checksum changes.
RUNNER_RELATIVE_PATH = os.path.join(".pio", "build-promini_sim", "runner")
# Where the sketch's arduino-cli build (graspguide.promini.build) leaves its ELF.
PROMINI_ELF_RELATIVE_PATH = os.path.join("build", "promini", "GraspGuideProMini.ino.elf")
# The sketch's motor pins 3, 9, 10, 11 (promini/GraspGuideProMini/board_glue.h): the
# timer channels that drive motors 0..3.
PROMINI_MOTOR_CHANNELS = ("OC2B", "OC1A", "OC1B", "OC2A")
TIMER_CHANNELS = ("OC0A", "OC0B", "OC1A", "OC1B", "OC2A", "OC2B")
RUNNER_CFLAGS = ("-O2", "-std=c11", "-Wall", "-Wextra", "-Werror")
RUNNER_LIBS = ("-lsimavr",)
# The runner exits with these (runner.c's header).
RUNNER_EXIT_CRASHED = 3
RUNNER_EXIT_MAX_CYCLES = 4


def _repo_root() -> str:
    root = _find_repo_root()
    if root is None:
        raise DeviceNotFound(
            "cannot find the GraspGuide repository (platformio.ini and lib/graspguide_link/) "
            "in the working directory or its parents: run from the repository"
        )
    return root


def build_runner(root: str | None = None, cc: str | None = None) -> str:
    """Path of the compiled runner, compiling it first when it is missing or older than
    ``runner.c``. Concurrent callers (parallel tests) serialise on a lock file and the
    binary appears by an atomic rename, so none ever starts a half-written one."""
    root = root or _repo_root()
    source = os.path.join(root, RUNNER_SOURCE)
    binary = os.path.join(root, RUNNER_RELATIVE_PATH)
    if not os.path.isfile(source):
        raise DeviceNotFound(f"the promini-sim runner's source {source} is missing")

    def fresh() -> bool:
        return os.path.isfile(binary) and os.path.getmtime(binary) >= os.path.getmtime(source)

    if fresh():
        return binary
    compiler = cc or os.environ.get("CC") or shutil.which("cc")
    if not compiler:
        raise SimNotBuilt(
            "no C compiler to build the promini-sim runner: install one (apt-get install gcc) "
            "or set CC"
        )
    os.makedirs(os.path.dirname(binary), exist_ok=True)
    with open(binary + ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if fresh():  # another process built it while this one waited
            return binary
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(binary), prefix=".runner.")
        os.close(fd)
        command = [compiler, *RUNNER_CFLAGS, source, "-o", tmp, *RUNNER_LIBS]
        try:
            done = subprocess.run(command, capture_output=True, text=True)
            if done.returncode != 0:
                raise SimNotBuilt(
                    "cannot build the promini-sim runner (`"
                    + " ".join(command)
                    + "`):\n"
                    + done.stderr.strip()[-2000:]
                    + "\nit needs libsimavr's headers and library: apt-get install "
                    "libsimavr-dev (tools/bootstrap.sh installs it)"
                )
            os.replace(tmp, binary)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return binary


PROMINI_BUILD_COMMAND = ".venv/bin/python -m graspguide.promini.build"


def find_promini_elf(path: str | None = None, build: bool = False) -> str:
    """The sketch's ELF: ``path``, else ``$GRASPGUIDE_PROMINI_ELF``, else the sketch build's
    output in the repository (build/promini/). With ``build``, a missing one of the
    repository is built first (:func:`build_promini_elf`). Raises SimNotBuilt naming the
    build command when missing."""
    explicit = path or os.environ.get(PROMINI_ELF_ENV)
    if explicit:
        if os.path.isfile(explicit):
            return explicit
        where = "the path given" if path else f"${PROMINI_ELF_ENV}"
        raise SimNotBuilt(
            f"Pro Mini firmware {explicit!r} ({where}) does not exist; unset "
            f"{PROMINI_ELF_ENV} for the repository's sketch, which `{PROMINI_BUILD_COMMAND}` "
            "builds"
        )
    root = _repo_root()
    elf = os.path.join(root, PROMINI_ELF_RELATIVE_PATH)
    if build and not os.path.isfile(elf):
        return build_promini_elf(root)
    if not os.path.isfile(elf):
        raise SimNotBuilt(
            f"the Pro Mini sketch is not built ({elf} is missing); build it with "
            f"`cd {shlex.quote(root)} && {PROMINI_BUILD_COMMAND}` (--port promini-sim builds "
            f"it when it is missing) or set {PROMINI_ELF_ENV}=/path/to/sketch.elf"
        )
    return elf


def build_promini_elf(root: str, progress: Callable[[str], None] | None = None) -> str:
    """Builds the sketch with arduino-cli (graspguide.promini.build) into build/promini/ of
    ``root`` when its ELF is missing, saying so on ``progress`` (default stderr); returns
    the ELF. Concurrent callers serialise on a lock file, and the folder appears whole (built
    beside it, then renamed), so none ever runs a half-written ELF."""
    from pathlib import Path

    from graspguide.promini.build import ArduinoCliMissing, SketchBuildFailed, build_sketch

    def to_stderr(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    say = progress or to_stderr
    elf = os.path.join(root, PROMINI_ELF_RELATIVE_PATH)
    out_dir = os.path.dirname(elf)
    os.makedirs(os.path.dirname(out_dir), exist_ok=True)
    with open(out_dir + ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if os.path.isfile(elf):  # another process built it while this one waited
            return elf
        say(f"building the Pro Mini sketch (once, about a minute): {PROMINI_BUILD_COMMAND}")
        tmp = tempfile.mkdtemp(dir=os.path.dirname(out_dir), prefix=".promini-")
        try:
            result = build_sketch(Path(root), Path(tmp))
            if os.path.isdir(out_dir):  # a build without its ELF: replaced whole
                shutil.rmtree(out_dir)
            os.replace(tmp, out_dir)
        except (ArduinoCliMissing, SketchBuildFailed) as e:
            raise SimNotBuilt(
                f"cannot build the Pro Mini sketch for --port promini-sim: {e}\nthe command: "
                f"cd {shlex.quote(root)} && {PROMINI_BUILD_COMMAND}"
            ) from None
        finally:
            if os.path.isdir(tmp):
                shutil.rmtree(tmp, ignore_errors=True)
        say(
            f"built the Pro Mini sketch in {result.seconds:.0f} s: {elf} "
            f"({result.flash_bytes} B flash, {result.static_ram_bytes} B static RAM)"
        )
    return elf


def runner_options(
    trace: str | None = None,
    motors: Sequence[str] | None = None,
    marks: str | None = None,
    stats: str | None = None,
    fast: bool = False,
    max_cycles: int | None = None,
    events: str | None = None,
) -> list[str]:
    """The runner's command-line options for these settings (see :class:`ProMiniSimDevice`)."""
    options: list[str] = []
    if trace:
        options += ["--trace", os.fspath(trace)]
    if motors is not None:
        motors = list(motors)
        bad = [m for m in motors if m not in TIMER_CHANNELS]
        if len(motors) != 4 or bad:
            raise ValueError(
                f"motors must name four timer channels, each one of {', '.join(TIMER_CHANNELS)}"
                f"; got {motors}"
            )
        options += ["--motors", ",".join(motors)]
    if marks:
        options += ["--marks", os.fspath(marks)]
    if events:
        options += ["--events", os.fspath(events)]
    if stats:
        options += ["--stats", os.fspath(stats)]
    if fast:
        options.append("--fast")
    if max_cycles is not None:
        if max_cycles <= 0:
            raise ValueError(f"max_cycles must be positive, got {max_cycles}")
        options += ["--max-cycles", str(int(max_cycles))]
    return options


def read_stats(path: str) -> dict[str, int]:
    """The runner's ``--stats`` file as a dict (cycles, simulated_us, stack_bytes_max,
    uart_bytes_dropped)."""
    out: dict[str, int] = {}
    with open(path) as f:
        for line in f:
            key, _, value = line.partition(" ")
            if key:
                out[key] = int(value)
    return out


def read_events(path: str) -> tuple[list[int], list[tuple[int, tuple[int, ...]]]]:
    """The runner's ``--events`` file: (cycles of the frames' closing bytes as the UART
    received them, [(cycle, four duties)] of every motor change), in order."""
    frame_ends: list[int] = []
    pwm: list[tuple[int, tuple[int, ...]]] = []
    with open(path) as f:
        for line in f:
            words = line.split()
            if words and words[0] == "rx_end":
                frame_ends.append(int(words[1]))
            elif words and words[0] == "pwm":
                pwm.append((int(words[1]), tuple(int(w) for w in words[2:6])))
    return frame_ends, pwm


class ProMiniSimDevice(SimulatedDevice):
    """The Pro Mini sketch running cycle-exact under simavr, on a pseudo-terminal.

    ``with ProMiniSimDevice(trace="motors.csv") as dev:`` builds the runner if needed,
    starts it on ``elf`` (default: :func:`find_promini_elf`, the sketch built if needed)
    and opens its pty at 115200 baud; closing sends SIGTERM (the runner records the motors
    off and exits).

    ``trace``: CSV ``device_time_us,pwm0..pwm3`` in simulated time, on every change of the
    motor channels; ``motors``: the four timer channels (``OC0A`` .. ``OC2B``) wired to
    motors 0..3 (default: the sketch's pins, :data:`PROMINI_MOTOR_CHANNELS`); ``marks``:
    file of the cycle counts the sketch brackets with GPIOR0 writes; ``stats``: file of the
    run's figures at exit (:func:`read_stats`); ``fast``: simulated time not held back to
    real time (only for sketches whose behaviour does not depend on time: the watchdog
    would fire early); ``events``: file of cycle-exact events (the UART's receipt of each
    frame's closing byte, every motor change: :func:`read_events`).
    A board's clock is its own: there is no virtual clock.
    """

    def __init__(
        self,
        elf: str | None = None,
        trace: str | None = None,
        motors: Sequence[str] = PROMINI_MOTOR_CHANNELS,
        marks: str | None = None,
        stats: str | None = None,
        fast: bool = False,
        max_cycles: int | None = None,
        events: str | None = None,
        runner: str | None = None,
        virtual_clock: bool = False,
        start_timeout: float = DEFAULT_SIM_START_TIMEOUT,
        grace: float = DEFAULT_SIM_GRACE,
        baudrate: int = DEFAULT_BAUDRATE,
        start: bool = False,
    ):
        if virtual_clock:
            raise LinkError(
                "--virtual-clock is for --port sim: the Pro Mini under simavr keeps its own "
                "clock (simulated time, held to real time)"
            )
        self.elf = find_promini_elf(elf, build=True)
        runner = runner or build_runner()
        options = runner_options(trace, motors, marks, stats, fast, max_cycles, events)
        super().__init__(
            binary=runner,
            start_timeout=start_timeout,
            grace=grace,
            baudrate=baudrate,
            extra_args=[self.elf, *options],
        )
        self.name = PROMINI_SIM_PORT
        if start:
            self.start()

    def start(self) -> ProMiniSimDevice:
        super().start()
        self.name = f"{PROMINI_SIM_PORT} ({self.pty_path})"
        return self

    def __enter__(self) -> ProMiniSimDevice:
        return self.start()


__all__ = [
    "ProMiniSimDevice",
    "build_runner",
    "find_promini_elf",
    "build_promini_elf",
    "read_stats",
    "read_events",
    "runner_options",
    "PROMINI_SIM_PORT",
    "PROMINI_ELF_ENV",
    "PROMINI_MOTOR_CHANNELS",
    "TIMER_CHANNELS",
]
