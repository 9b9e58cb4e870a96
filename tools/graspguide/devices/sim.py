"""The simulated device (src/boards/posix_sim, built by ``pio run -e sim`` into its own
build folder, graspguide.devices.builds) as a
:class:`~graspguide.link.transport.Transport`: :class:`SimulatedDevice` starts the
process, reads the pseudo-terminal path it prints, talks to it through a SerialTransport
and, on close, stops it (SIGTERM, then SIGKILL). It is a context manager.
:func:`find_sim_binary` locates the program; :func:`die_with_parent` makes a child
process die with its parent.
"""

from __future__ import annotations

import os
import select
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from typing import IO

from graspguide.link.transport import (
    DEFAULT_BAUDRATE,
    ChildPtyTransport,
    DeviceDisconnected,
    DeviceNotFound,
    LinkError,
    LinkTimeout,
    SerialTransport,
    SimNotBuilt,
)
from graspguide.repo_root import find_repo_root

SIM_PORT = "sim"
SIM_ENV = "GRASPGUIDE_SIM"
# Its own build folder (graspguide.devices.builds): no other env's build deletes it.
SIM_RELATIVE_PATH = os.path.join(".pio", "build-sim", "sim", "program")
SIM_READY_PREFIX = "GRASPGUIDE_SIM_PTY "
# The simulated device prints its pty path within a few milliseconds of its start
# (measured: ~3 ms); the limit only guards against a hung process.
DEFAULT_SIM_START_TIMEOUT = 5.0
# SIGTERM, then this long for the simulated device to switch its motors off and exit, then
# SIGKILL.
DEFAULT_SIM_GRACE = 2.0
PR_SET_PDEATHSIG = 1  # <sys/prctl.h>


# --------------------------------------------------------------------------------------
# Simulated device
# --------------------------------------------------------------------------------------
def sim_build_command(root: str) -> str:
    """The shell command that builds the simulated device in the repository ``root``."""
    from graspguide.devices.builds import SIM

    return SIM.command(root)


def find_sim_binary(path: str | None = None, build: bool = False) -> str:
    """Path of the simulated device's program: ``path``, else ``$GRASPGUIDE_SIM``, else
    ``<repo>/.pio/build-sim/sim/program``. Raises SimNotBuilt (with the build command) when
    it does not exist, DeviceNotFound when no repository can be found. With ``build``, a
    missing program of the repository is built first (pio's progress on stderr)."""
    explicit = path or os.environ.get(SIM_ENV)
    if explicit:
        if os.path.isfile(explicit) and os.access(explicit, os.X_OK):
            return explicit
        where = "the path given" if path else f"${SIM_ENV}"
        root = find_repo_root()
        how = sim_build_command(root) if root else "pio run -e sim"
        raise SimNotBuilt(
            f"simulated device {explicit!r} ({where}) does not exist or is not "
            f"executable; unset {SIM_ENV} for the repository's, which this builds:\n    {how}"
        )
    root = find_repo_root()
    if root is None:
        raise DeviceNotFound(
            "cannot find the simulated device: no GraspGuide repository (platformio.ini and "
            "lib/graspguide_link/) in the working directory or its parents; run from the "
            f"repository or set {SIM_ENV}=/path/to/.pio/build-sim/sim/program"
        )
    binary = os.path.join(root, SIM_RELATIVE_PATH)
    if build and not os.path.isfile(binary):
        from graspguide.devices.builds import SIM, ensure_built

        ensure_built(SIM, root)
    if not (os.path.isfile(binary) and os.access(binary, os.X_OK)):
        raise SimNotBuilt(
            f"the simulated device is not built ({binary} is missing); build "
            f"it with:\n    {sim_build_command(root)}\n(tools/bootstrap.sh "
            "does this too)"
        )
    return binary


def die_with_parent() -> Callable[[], None] | None:
    """A ``preexec_fn`` for ``subprocess.Popen``: the child gets SIGTERM when the process
    that started it dies, even by SIGKILL (Linux ``PR_SET_PDEATHSIG``), so no simulated
    device or runner outlives its host. None where the call does not exist.

    libc is loaded here, in the parent: the child between fork and exec only calls it
    (importing there could deadlock on a lock another thread held at the fork)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # pragma: no cover - no libc prctl
        return None
    parent = os.getpid()

    def preexec() -> None:  # pragma: no cover - runs in the child
        prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() != parent:  # the parent died before the call: nobody to signal
            os._exit(1)

    return preexec


def _sim_options(
    virtual_clock: bool, trace: str | None, stale_ms: int | None, store: str | None = None
) -> list[str]:
    """The simulated device's command-line options for these settings (see
    :class:`SimulatedDevice`)."""
    options = ["--virtual-clock"] if virtual_clock else []
    if trace:
        options += ["--trace", os.fspath(trace)]
    if stale_ms is not None:
        options += ["--stale-ms", str(int(stale_ms))]
    if store:
        options += ["--store", os.fspath(store)]
    return options


class SimulatedDevice(ChildPtyTransport):
    """The simulated device as a process on a pseudo-terminal, and a Transport to it.

    ``with SimulatedDevice(virtual_clock=True, trace="motors.csv") as sim:`` starts
    ``<repo>/.pio/build-sim/sim/program`` (built first when missing; or ``binary``, or
    ``$GRASPGUIDE_SIM``), waits for
    the ``GRASPGUIDE_SIM_PTY <path>`` line (at most ``start_timeout`` s), and opens the pty
    with a :class:`SerialTransport`; leaving the block closes the port, sends SIGTERM
    (the device switches its motors off and exits) and SIGKILL after ``grace`` seconds.

    ``virtual_clock``: device time = the POSE timestamps (a 90 s trial runs as fast as the
    host streams); ``trace``: CSV of every motor change; ``stale_ms``: POSE watchdog;
    ``store``: the device's non-volatile store file (the host-less plan and results log,
    created on first use, kept across restarts like flash); without it the device has no
    host-less capability.
    After start: ``pty_path``, ``process``, ``start_time_s`` (spawn to pty line).
    """

    child_name = "the simulated device"

    def __init__(
        self,
        virtual_clock: bool = False,
        trace: str | None = None,
        stale_ms: int | None = None,
        binary: str | None = None,
        store: str | None = None,
        start_timeout: float = DEFAULT_SIM_START_TIMEOUT,
        grace: float = DEFAULT_SIM_GRACE,
        baudrate: int = DEFAULT_BAUDRATE,
        extra_args: Sequence[str] = (),
        start: bool = False,
    ):
        self.binary = find_sim_binary(binary, build=True)
        self.command = [
            self.binary,
            *_sim_options(virtual_clock, trace, stale_ms, store),
            *extra_args,
        ]
        self.start_timeout = start_timeout
        self.grace = grace
        self.baudrate = baudrate
        self.process: subprocess.Popen | None = None
        self.pty_path: str | None = None
        self.start_time_s: float | None = None
        self.exit_code: int | None = None
        self._serial: SerialTransport | None = None
        self._stderr: IO[bytes] | None = None
        self.name = "sim"
        if start:
            self.start()

    def start(self) -> SimulatedDevice:
        if self.process is not None:
            return self
        self._stderr = tempfile.TemporaryFile()
        t0 = time.perf_counter()
        try:
            # Its own session: a terminal's Ctrl-C (SIGINT to the foreground process
            # group) reaches only the host, which sends STOP before closing the device.
            self.process = subprocess.Popen(
                self.command,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=self._stderr,
                close_fds=True,
                start_new_session=True,
                preexec_fn=die_with_parent(),
            )
        except OSError as e:
            raise DeviceNotFound(
                f"cannot start the simulated device {self.binary}: {e}; rebuild it:\n    "
                f"{sim_build_command(find_repo_root() or '.')}"
            ) from e
        try:
            self.pty_path = self._read_pty_line(t0)
            self.start_time_s = time.perf_counter() - t0
            self._serial = SerialTransport(self.pty_path, self.baudrate)
        except BaseException:
            self._terminate()
            raise
        self.name = f"sim ({self.pty_path})"
        return self

    def _read_pty_line(self, t0: float) -> str:
        assert self.process is not None and self.process.stdout is not None
        fd = self.process.stdout.fileno()
        buf = b""
        deadline = t0 + self.start_timeout
        while b"\n" not in buf:
            left = deadline - time.perf_counter()
            if left <= 0:
                raise LinkTimeout(
                    f"the simulated device did not print its pty path within "
                    f"{self.start_timeout} s ({shlex.join(self.command)}); stderr: "
                    f"{self._stderr_text() or '(empty)'}"
                )
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(fd, 4096)
            if not chunk:
                code = self.process.wait(timeout=self.grace)
                raise DeviceNotFound(
                    f"the simulated device exited with code {code} before opening its pty "
                    f"({shlex.join(self.command)}); stderr: {self._stderr_text() or '(empty)'}"
                )
            buf += chunk
        line = buf.split(b"\n", 1)[0].decode("utf-8", "replace").strip()
        if not line.startswith(SIM_READY_PREFIX):
            raise DeviceNotFound(
                f"unexpected first line from the simulated device: {line!r} "
                f"(expected '{SIM_READY_PREFIX}<path>'); is {self.binary} "
                "the GraspGuide simulated device?"
            )
        return line[len(SIM_READY_PREFIX) :].strip()

    def _stderr_text(self) -> str:
        if self._stderr is None:
            return ""
        try:
            self._stderr.seek(0)
            return self._stderr.read().decode("utf-8", "replace").strip()[-2000:]
        except (OSError, ValueError):
            return ""

    def _gone(self, what: str, cause: LinkError) -> LinkError:
        code = None if self.process is None else self.process.poll()
        if code is not None:
            return DeviceDisconnected(
                f"the simulated device exited with code {code} while "
                f"{what}; stderr: {self._stderr_text() or '(empty)'}"
            )
        return cause

    @property
    def serial_transport(self) -> SerialTransport:
        return self._transport()

    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def close(self) -> None:
        if self._serial is not None:
            self._serial.close()
            self._serial = None
        self._terminate()

    def _terminate(self) -> None:
        proc = self.process
        if proc is None:
            return
        if proc.poll() is None:
            try:
                proc.send_signal(signal.SIGTERM)
                self.exit_code = proc.wait(timeout=self.grace)
            except subprocess.TimeoutExpired:
                proc.kill()
                self.exit_code = proc.wait()
            except ProcessLookupError:  # pragma: no cover - exited meanwhile
                self.exit_code = proc.wait()
        else:
            self.exit_code = proc.returncode
        if proc.stdout is not None:
            proc.stdout.close()
        if self._stderr is not None:
            self._stderr.close()
            self._stderr = None
        self.process = None

    def __enter__(self) -> SimulatedDevice:
        return self.start()

    def __del__(self):  # pragma: no cover - safety net for a forgotten close()
        try:
            if self.process is not None and self.process.poll() is None:
                self.process.kill()
                self.process.wait(timeout=1)
        except Exception:
            pass


__all__ = [
    "SimulatedDevice",
    "find_sim_binary",
    "sim_build_command",
    "die_with_parent",
    "SIM_PORT",
    "SIM_ENV",
]
