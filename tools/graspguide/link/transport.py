"""Byte transports to a GraspGuide device: a serial port, or the simulated device.

:class:`Transport` is the small interface :class:`graspguide.link.client.DeviceClient` talks
through (``write``, ``read(max_bytes, timeout)``, ``close``), so tests can put a fake
device behind it. Two implementations:

* :class:`SerialTransport` -- any serial port pyserial opens (``/dev/ttyACM0``, ``COM3``,
  a pseudo-terminal), 115200 baud by default;
* :class:`graspguide.devices.sim.SimulatedDevice` -- the simulated device's process, talked
  to through a SerialTransport (its own module: launching and reaping a process).

:func:`graspguide.devices.registry.open_port` opens one from a ``--port`` value; this
module knows none of the devices behind it.

Every failure is a :class:`LinkError` subclass that says what to do about it:
:class:`DeviceNotFound` (no such port, simulated device not built), :class:`LinkTimeout`,
:class:`DeviceDisconnected` (the port went away, the simulated device exited).
"""

from __future__ import annotations

import abc
import errno
import os
import select
import time

DEFAULT_BAUDRATE = 115200
DEFAULT_WRITE_TIMEOUT = 2.0


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
def import_serial():
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
        serial = import_serial()
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
        serial = import_serial()
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
        serial = import_serial()
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


class ChildPtyTransport(Transport):
    """A device that is a child process (the simulator, simavr, QEMU) reached through a
    serial transport on its pseudo-terminal. A link error while the child has died is
    reported as its death, with what it printed (:meth:`_gone`)."""

    _serial: SerialTransport | None = None
    #: What "not running" names in the error of a transport used before start().
    child_name = "the device"

    def _transport(self) -> SerialTransport:
        if self._serial is None:
            raise LinkError(
                f"{self.child_name} is not running: call start() or use it as a context manager"
            )
        return self._serial

    @abc.abstractmethod
    def _gone(self, what: str, cause: LinkError) -> LinkError:
        """DeviceDisconnected naming the child's exit when it has exited, else ``cause``."""

    def write(self, data: bytes) -> None:
        try:
            self._transport().write(data)
        except LinkError as e:
            raise self._gone("writing", e) from e

    def read(self, max_bytes: int, timeout: float) -> bytes:
        try:
            return self._transport().read(max_bytes, timeout)
        except LinkError as e:
            raise self._gone("reading", e) from e


__all__ = [
    "Transport",
    "SerialTransport",
    "ChildPtyTransport",
    "import_serial",
    "LinkError",
    "DeviceNotFound",
    "SimNotBuilt",
    "DeviceDisconnected",
    "LinkTimeout",
    "DEFAULT_BAUDRATE",
]
