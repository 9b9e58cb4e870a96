"""Byte transports to a GraspGuide device: a serial port, or the simulated device.

:class:`Transport` is the small interface :class:`graspguide.link.client.DeviceClient` talks
through (``write``, ``read(max_bytes, timeout)``, ``close``), so tests can put a fake
device behind it. Two implementations:

* :class:`SerialTransport` -- any serial port pyserial opens (``/dev/ttyACM0``, ``COM3``,
  a pseudo-terminal), 115200 baud by default;
* :class:`SimulatedDevice` -- starts the simulated device (``src/sim``, built by
  ``pio run -e sim``), reads the pseudo-terminal path it prints, and talks to it through a
  SerialTransport; closing it terminates the process. It is a context manager.

:func:`open_port` opens either from a ``--port`` value: ``"sim"`` or a port path.

Every failure is a :class:`LinkError` subclass that says what to do about it:
:class:`DeviceNotFound` (no such port, simulated device not built), :class:`LinkTimeout`,
:class:`DeviceDisconnected` (the port went away, the simulated device exited).
"""

from __future__ import annotations

import abc
import errno
import os
import select
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence

DEFAULT_BAUDRATE = 115200
SIM_PORT = "sim"
SIM_ENV = "GRASPGUIDE_SIM"
SIM_RELATIVE_PATH = os.path.join(".pio", "build", "sim", "program")
SIM_READY_PREFIX = "GRASPGUIDE_SIM_PTY "
# The simulated device prints its pty path within a few milliseconds of its start
# (measured: ~3 ms); the limit only guards against a hung process.
DEFAULT_SIM_START_TIMEOUT = 5.0
# SIGTERM, then this long for the simulated device to switch its motors off and exit, then
# SIGKILL.
DEFAULT_SIM_GRACE = 2.0
DEFAULT_WRITE_TIMEOUT = 2.0
PR_SET_PDEATHSIG = 1  # <sys/prctl.h>


# --------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------
class LinkError(Exception):
    """Base of every error of the link to a device (transport and protocol)."""


class DeviceNotFound(LinkError):
    """No device at that port: the port does not exist, or the simulated device is not
    built."""


class SimNotBuilt(DeviceNotFound):
    """The simulated device's program does not exist yet; the message names the command
    that builds it."""


class DeviceDisconnected(LinkError):
    """The port went away while in use (USB unplugged, simulated device exited)."""


class LinkTimeout(LinkError, TimeoutError):
    """Nothing (or not the expected answer) arrived in time."""


# --------------------------------------------------------------------------------------
# Interface
# --------------------------------------------------------------------------------------
class Transport(abc.ABC):
    """A byte pipe to a device. ``read`` returns at most ``max_bytes`` bytes as soon as any
    are available, or ``b""`` after ``timeout`` seconds without any (``timeout=0``: only
    what is already there). ``write`` sends every byte or raises."""

    name: str = "transport"

    @abc.abstractmethod
    def write(self, data: bytes) -> None: ...

    @abc.abstractmethod
    def read(self, max_bytes: int, timeout: float) -> bytes: ...

    @abc.abstractmethod
    def close(self) -> None: ...

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}>"


# --------------------------------------------------------------------------------------
# Serial port
# --------------------------------------------------------------------------------------
def _import_serial():
    try:
        import serial  # noqa: F401
    except ImportError as e:  # pragma: no cover - pyserial is a dependency
        raise LinkError(
            "pyserial is not installed: `pip install pyserial` (or run tools/bootstrap.sh)"
        ) from e
    return serial


class SerialTransport(Transport):
    """A serial port through pyserial. ``port`` is any path or name pyserial accepts.

    The port is opened in raw binary mode; bytes already waiting in its input buffer (a
    previous session's leftovers) are discarded at open unless ``flush_on_open=False``.
    """

    def __init__(
        self,
        port: str,
        baudrate: int = DEFAULT_BAUDRATE,
        write_timeout: float = DEFAULT_WRITE_TIMEOUT,
        flush_on_open: bool = True,
        exclusive: bool | None = None,
    ):
        serial = _import_serial()
        self.name = port
        self.port = port
        self.baudrate = baudrate
        self.bytes_read = 0
        self.bytes_written = 0
        kwargs = dict(baudrate=baudrate, timeout=0, write_timeout=write_timeout)
        if exclusive is not None:
            kwargs["exclusive"] = exclusive
        try:
            self._ser = serial.Serial(port, **kwargs)
        except serial.SerialException as e:
            raise self._open_error(e) from e
        except (ValueError, OSError) as e:
            raise LinkError(f"cannot open {port} at {baudrate} baud: {e}") from e
        if flush_on_open:
            try:
                self._ser.reset_input_buffer()
            except Exception:  # pragma: no cover - some drivers do not support it
                pass
        self._posix_fd = None
        if os.name == "posix":
            try:
                self._posix_fd = self._ser.fileno()
            except Exception:  # pragma: no cover - non-fd backends (URLs)
                self._posix_fd = None

    def _open_error(self, e: Exception) -> LinkError:
        port = self.port
        err = getattr(e, "errno", None)
        text = str(e)
        if err == errno.ENOENT or "No such file" in text:
            return DeviceNotFound(
                f"no serial port {port!r}: run `graspguide ports` to list the ports, check "
                "the cable, or use --port sim for the simulated device"
            )
        if err in (errno.EACCES, errno.EPERM) or "Permission denied" in text:
            return LinkError(
                f"permission denied opening {port}: add your user to the port's group "
                "(usually `dialout`: sudo usermod -aG dialout $USER, then log in again) or "
                "run as root"
            )
        if err == errno.EBUSY or "busy" in text.lower() or "lock" in text.lower():
            return LinkError(
                f"{port} is busy: another program (a serial monitor?) has it "
                "open; close it and retry"
            )
        return LinkError(f"cannot open {port}: {text}")

    @property
    def serial(self):
        """The underlying ``serial.Serial``."""
        return self._ser

    def write(self, data: bytes) -> None:
        serial = _import_serial()
        if not data:
            return
        try:
            n = None
            if self._posix_fd is not None:
                # One os.write: what pyserial's write does first, without its per-call
                # bookkeeping (a study writes ~10^6 small frames); the rest, if the
                # kernel took only part, through pyserial (write timeout and all).
                try:
                    done = os.write(self._posix_fd, data)
                except (BlockingIOError, InterruptedError):
                    done = 0
                if done < len(data):
                    rest = self._ser.write(data[done:])
                    n = done + (len(data) - done if rest is None else rest)
                else:
                    n = done
            else:  # pragma: no cover - Windows and URL handlers
                n = self._ser.write(data)
        except serial.SerialTimeoutException as e:
            raise LinkTimeout(
                f"writing {len(data)} bytes to {self.port} timed out: the device is not "
                "reading (flow control? a stuck board?)"
            ) from e
        except serial.SerialException as e:
            raise DeviceDisconnected(f"{self.port} went away while writing: {e}") from e
        except OSError as e:
            raise DeviceDisconnected(f"{self.port} went away while writing: {e}") from e
        if n is not None and n != len(data):
            raise LinkTimeout(f"only {n} of {len(data)} bytes were written to {self.port}")
        self.bytes_written += len(data)

    def read(self, max_bytes: int, timeout: float) -> bytes:
        serial = _import_serial()
        if max_bytes <= 0:
            return b""
        timeout = max(0.0, float(timeout))
        try:
            if self._posix_fd is not None:
                # select, then one os.read of what is there (pyserial's read with
                # timeout 0 is the same two calls plus bookkeeping).
                ready, _, _ = select.select([self._posix_fd], [], [], timeout)
                if not ready:
                    return b""
                try:
                    data = os.read(self._posix_fd, max_bytes)
                except (BlockingIOError, InterruptedError):
                    return b""
                if not data:
                    raise serial.SerialException(
                        "device reports readiness to read but returned no data (device "
                        "disconnected or multiple access on port?)"
                    )
            else:  # pragma: no cover - Windows and URL handlers
                deadline = time.monotonic() + timeout
                while True:
                    waiting = self._ser.in_waiting
                    if waiting:
                        data = self._ser.read(min(waiting, max_bytes))
                        break
                    if time.monotonic() >= deadline:
                        return b""
                    time.sleep(0.0005)
        except serial.SerialException as e:
            raise DeviceDisconnected(f"{self.port} went away while reading: {e}") from e
        except OSError as e:
            raise DeviceDisconnected(f"{self.port} went away while reading: {e}") from e
        self.bytes_read += len(data)
        return data

    def close(self) -> None:
        try:
            self._ser.close()
        except Exception:  # pragma: no cover - closing a dead port
            pass


# --------------------------------------------------------------------------------------
# Simulated device
# --------------------------------------------------------------------------------------
def _candidate_roots() -> list[str]:
    """Directories that may be the repository: the working directory and its parents,
    the parent of the virtual environment (the repo keeps .venv at its top), and the
    package's own parents (a source checkout)."""
    roots: list[str] = []

    def walk(start: str) -> None:
        d = os.path.abspath(start)
        while True:
            if d not in roots:
                roots.append(d)
            parent = os.path.dirname(d)
            if parent == d:
                return
            d = parent

    try:
        walk(os.getcwd())
    except OSError:  # pragma: no cover - cwd deleted
        pass
    roots.append(os.path.dirname(os.path.abspath(sys.prefix)))
    walk(os.path.dirname(os.path.abspath(__file__)))
    return roots


def find_repo_root() -> str | None:
    """The GraspGuide repository (a directory with platformio.ini and src/sim), or None."""
    for root in _candidate_roots():
        if os.path.isfile(os.path.join(root, "platformio.ini")) and os.path.isdir(
            os.path.join(root, "src", "sim")
        ):
            return root
    return None


def sim_build_command(root: str) -> str:
    """The shell command that builds the simulated device in the repository ``root``."""
    return (
        f"cd {shlex.quote(root)} && PLATFORMIO_CORE_DIR=.pio-core "
        "PLATFORMIO_DISABLE_UPGRADE_CHECK=true .venv/bin/pio run -e sim"
    )


def find_sim_binary(path: str | None = None) -> str:
    """Path of the simulated device's program: ``path``, else ``$GRASPGUIDE_SIM``, else
    ``<repo>/.pio/build/sim/program``. Raises SimNotBuilt (with the build command) when it
    does not exist, DeviceNotFound when no repository can be found. Never builds."""
    explicit = path or os.environ.get(SIM_ENV)
    if explicit:
        if os.path.isfile(explicit) and os.access(explicit, os.X_OK):
            return explicit
        where = "the path given" if path else f"${SIM_ENV}"
        raise SimNotBuilt(
            f"simulated device {explicit!r} ({where}) does not exist or is not "
            f"executable; build it with `pio run -e sim` or unset {SIM_ENV}"
        )
    root = find_repo_root()
    if root is None:
        raise DeviceNotFound(
            "cannot find the simulated device: no GraspGuide repository (platformio.ini and "
            f"src/sim/) in the working directory or its parents; run from the repository "
            f"or set {SIM_ENV}=/path/to/.pio/build/sim/program"
        )
    binary = os.path.join(root, SIM_RELATIVE_PATH)
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


class SimulatedDevice(Transport):
    """The simulated device as a process on a pseudo-terminal, and a Transport to it.

    ``with SimulatedDevice(virtual_clock=True, trace="motors.csv") as sim:`` starts
    ``<repo>/.pio/build/sim/program`` (or ``binary``, or ``$GRASPGUIDE_SIM``), waits for
    the ``GRASPGUIDE_SIM_PTY <path>`` line (at most ``start_timeout`` s), and opens the pty
    with a :class:`SerialTransport`; leaving the block closes the port, sends SIGTERM
    (the device switches its motors off and exits) and SIGKILL after ``grace`` seconds.

    ``virtual_clock``: device time = the POSE timestamps (a 90 s trial runs as fast as the
    host streams); ``trace``: CSV of every motor change; ``stale_ms``: POSE watchdog.
    After start: ``pty_path``, ``process``, ``start_time_s`` (spawn to pty line).
    """

    def __init__(
        self,
        virtual_clock: bool = False,
        trace: str | None = None,
        stale_ms: int | None = None,
        binary: str | None = None,
        start_timeout: float = DEFAULT_SIM_START_TIMEOUT,
        grace: float = DEFAULT_SIM_GRACE,
        baudrate: int = DEFAULT_BAUDRATE,
        extra_args: Sequence[str] = (),
        start: bool = False,
    ):
        self.binary = find_sim_binary(binary)
        self.virtual_clock = virtual_clock
        self.trace = trace
        self.stale_ms = stale_ms
        self.start_timeout = start_timeout
        self.grace = grace
        self.baudrate = baudrate
        self.extra_args = list(extra_args)
        self.process: subprocess.Popen | None = None
        self.pty_path: str | None = None
        self.start_time_s: float | None = None
        self.exit_code: int | None = None
        self._serial: SerialTransport | None = None
        self._stderr = None
        self.name = "sim"
        if start:
            self.start()

    @property
    def command(self) -> list[str]:
        cmd = [self.binary]
        if self.virtual_clock:
            cmd.append("--virtual-clock")
        if self.trace:
            cmd += ["--trace", os.fspath(self.trace)]
        if self.stale_ms is not None:
            cmd += ["--stale-ms", str(int(self.stale_ms))]
        return cmd + self.extra_args

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
                f"cannot start the simulated device {self.binary}: {e}; "
                "rebuild it with `pio run -e sim`"
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

    def _check_alive(self, what: str, cause: Exception) -> LinkError:
        code = None if self.process is None else self.process.poll()
        if code is not None:
            return DeviceDisconnected(
                f"the simulated device exited with code {code} while "
                f"{what}; stderr: {self._stderr_text() or '(empty)'}"
            )
        return cause if isinstance(cause, LinkError) else LinkError(str(cause))

    def _transport(self) -> SerialTransport:
        if self._serial is None:
            raise LinkError(
                "the simulated device is not running: call start() or use it as a context manager"
            )
        return self._serial

    @property
    def serial_transport(self) -> SerialTransport:
        return self._transport()

    def write(self, data: bytes) -> None:
        try:
            self._transport().write(data)
        except LinkError as e:
            raise self._check_alive("writing", e) from e

    def read(self, max_bytes: int, timeout: float) -> bytes:
        try:
            return self._transport().read(max_bytes, timeout)
        except LinkError as e:
            raise self._check_alive("reading", e) from e

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


def open_port(port: str, baudrate: int = DEFAULT_BAUDRATE, **kwargs) -> Transport:
    """A started Transport for a ``--port`` value: ``"sim"`` starts the simulated device
    (keyword arguments go to :class:`SimulatedDevice`: virtual_clock, trace, stale_ms,
    binary, start_timeout), anything else opens that serial port (keyword arguments go to
    :class:`SerialTransport`). Close it (or use ``with``) when done."""
    if not port:
        raise DeviceNotFound(
            "no port given: use --port PATH (see `graspguide ports`) or --port sim"
        )
    if port == SIM_PORT:
        return SimulatedDevice(baudrate=baudrate, **kwargs).start()
    return SerialTransport(port, baudrate=baudrate, **kwargs)


def list_serial_ports() -> list[dict]:
    """The serial ports pyserial finds: dicts with device, description, hwid."""
    _import_serial()
    from serial.tools import list_ports

    out = []
    for p in sorted(list_ports.comports(), key=lambda p: p.device):
        out.append({"device": p.device, "description": p.description or "", "hwid": p.hwid or ""})
    return out


__all__ = [
    "Transport",
    "SerialTransport",
    "SimulatedDevice",
    "open_port",
    "list_serial_ports",
    "find_sim_binary",
    "find_repo_root",
    "sim_build_command",
    "LinkError",
    "DeviceNotFound",
    "SimNotBuilt",
    "DeviceDisconnected",
    "LinkTimeout",
    "DEFAULT_BAUDRATE",
    "SIM_PORT",
    "SIM_ENV",
    "die_with_parent",
]
