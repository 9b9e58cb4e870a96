"""The cross-compiled firmware (`pio run -e m4f_firmware`, in its own build folder:
graspguide.devices.builds) on QEMU's mps2-an386
(Cortex-M4F) as a device, for ``--port qemu``.

:class:`QemuFirmware` starts ``qemu-system-arm`` on the ELF with UART0 on a host
pseudo-terminal (``-serial pty``) and a QMP socket to read the firmware's globals while it
runs (:meth:`QemuFirmware.motor_registers`: ``m4f_pwm_ccr``, the duties last written to
the motors). :class:`QemuFirmwareDevice` is that, plus a :class:`SerialTransport` on the
pty: a :class:`Transport` like the simulated device.

QEMU notices that the host opened the pty only on a 1 s poll, and drops what the firmware
sends until then: :meth:`QemuFirmwareDevice.start` waits for a first HELLO_REPLY, so the
requests after it see the firmware's usual answer times (a few milliseconds).
"""

from __future__ import annotations

import json
import os
import select
import shutil
import socket
import struct
import subprocess
import tempfile
import time
from typing import IO, Any

from graspguide.devices.sim import die_with_parent
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

QEMU_PORT = "qemu"
QEMU_FIRMWARE_ENV = "GRASPGUIDE_M4F_FIRMWARE"
QEMU_MACHINE = "mps2-an386"
QEMU_BOARD_NAME = "qemu-mps2-an386"  # the firmware's HELLO_REPLY board
# Its own build folder (graspguide.devices.builds): no other env's build deletes it.
FIRMWARE_RELATIVE_PATH = os.path.join(".pio", "build-m4f_firmware", "m4f_firmware", "firmware.elf")
DEFAULT_START_TIMEOUT = 10.0
MOTOR_REGISTERS_SYMBOL = "m4f_pwm_ccr"
DIAGNOSTIC_SYMBOLS = (
    MOTOR_REGISTERS_SYMBOL,
    "m4f_uart_rx_dropped",
    "m4f_uart_tx_frames_dropped",
    "m4f_stack_peak",
)
_PTY_PREFIX = b"char device redirected to "
_INSTALL_HINT = "tools/install-arm.sh (as root) installs QEMU and the ARM toolchain"


def find_qemu() -> str:
    """Path of qemu-system-arm, or DeviceNotFound saying how to install it."""
    qemu = shutil.which("qemu-system-arm")
    if qemu is None:
        raise DeviceNotFound(f"qemu-system-arm is not installed: {_INSTALL_HINT}")
    return qemu


def firmware_build_command(root: str) -> str:
    """The shell command that builds the firmware in the repository ``root``."""
    from graspguide.devices.builds import M4F_FIRMWARE

    return M4F_FIRMWARE.command(root)


def find_firmware_elf(path: str | None = None, build: bool = False) -> str:
    """The firmware's ELF: ``path``, else ``$GRASPGUIDE_M4F_FIRMWARE``, else the pio build's
    output in the repository (``.pio/build-m4f_firmware/m4f_firmware/firmware.elf``). With
    ``build``, a missing one of the repository is built first (pio's progress on stderr;
    it needs the ARM toolchain). SimNotBuilt naming the exact build command when missing."""
    explicit = path or os.environ.get(QEMU_FIRMWARE_ENV)
    if explicit:
        if os.path.isfile(explicit):
            return explicit
        where = "the path given" if path else f"${QEMU_FIRMWARE_ENV}"
        root = find_repo_root()
        how = firmware_build_command(root) if root else "pio run -e m4f_firmware"
        raise SimNotBuilt(
            f"the QEMU firmware {explicit!r} ({where}) does not exist; unset "
            f"{QEMU_FIRMWARE_ENV} for the repository's, which this builds:\n    {how}"
        )
    root = find_repo_root()
    if root is None:
        raise DeviceNotFound(
            "cannot find the GraspGuide repository (platformio.ini) in the working directory "
            f"or its parents: run from the repository or set {QEMU_FIRMWARE_ENV}"
        )
    elf = os.path.join(root, FIRMWARE_RELATIVE_PATH)
    if build and not os.path.isfile(elf):
        from graspguide.devices.builds import M4F_FIRMWARE, ensure_built

        ensure_built(M4F_FIRMWARE, root)
    if not os.path.isfile(elf):
        raise SimNotBuilt(
            f"the QEMU firmware is not built ({elf} is missing; it needs arm-none-eabi-g++: "
            f"{_INSTALL_HINT}); build it with:\n    {firmware_build_command(root)}\n"
            f"or set {QEMU_FIRMWARE_ENV}"
        )
    return elf


def firmware_symbol(elf: str, name: str) -> int:
    """Address of the global ``name`` of the ELF."""
    from elftools.elf.elffile import ELFFile

    with open(elf, "rb") as f:
        symtab = ELFFile(f).get_section_by_name(".symtab")
        if symtab is None:
            raise LinkError(f"{elf} has no symbol table: not the m4f_firmware image?")
        syms = symtab.get_symbol_by_name(name)  # type: ignore[attr-defined]
        if not syms:
            raise LinkError(f"{elf} has no symbol {name}: not the m4f_firmware image?")
        return int(syms[0]["st_value"])


class Qmp:
    """The least of QEMU's machine protocol needed here: commands and their answers (read
    guest memory while the firmware runs)."""

    def __init__(self, path: str, timeout: float):
        deadline = time.monotonic() + timeout
        while True:
            self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                self.sock.connect(path)
                break
            except OSError:
                self.sock.close()
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.02)
        self.sock.settimeout(timeout)
        self.file = self.sock.makefile("rwb")
        self._next()  # greeting
        self.execute("qmp_capabilities")

    def _next(self) -> dict:
        while True:
            line = self.file.readline()
            if not line:
                raise ConnectionError("QEMU closed its QMP socket")
            msg = json.loads(line)
            if "event" not in msg:
                return msg

    def execute(self, command: str, **arguments: Any) -> Any:
        req: dict[str, Any] = {"execute": command}
        if arguments:
            req["arguments"] = arguments
        self.file.write(json.dumps(req).encode() + b"\n")
        self.file.flush()
        reply = self._next()
        if "error" in reply:
            raise RuntimeError(f"QMP {command}: {reply['error']}")
        return reply["return"]

    def close(self) -> None:
        self.file.close()
        self.sock.close()


class QemuFirmware:
    """qemu-system-arm running the firmware ELF; ``pty_path`` is its UART0, ``qmp`` its
    machine-protocol socket. :meth:`close` kills it."""

    def __init__(
        self,
        elf: str | None = None,
        start_timeout: float = DEFAULT_START_TIMEOUT,
        workdir: str | None = None,
    ):
        self.elf = find_firmware_elf(elf, build=True)
        qemu = find_qemu()
        self.start_timeout = start_timeout
        self._tmpdir = None if workdir else tempfile.TemporaryDirectory(prefix="graspguide-qemu-")
        base = workdir or self._tmpdir.name  # type: ignore[union-attr]
        self.qmp_path = os.path.join(base, "qmp.sock")
        self._stderr: IO[bytes] = tempfile.TemporaryFile()
        self.command = [
            qemu,
            "-M",
            QEMU_MACHINE,
            "-nographic",
            "-monitor",
            "none",
            "-serial",
            "pty",
            "-qmp",
            f"unix:{self.qmp_path},server=on,wait=off",
            "-kernel",
            self.elf,
        ]
        self.qmp: Qmp | None = None
        # Its own session: a terminal's Ctrl-C reaches only the host, which switches the
        # motors off before QEMU goes.
        self.process = subprocess.Popen(
            self.command,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            start_new_session=True,
            preexec_fn=die_with_parent(),
        )
        try:
            self.pty_path = self._pty_line()
            self.qmp = Qmp(self.qmp_path, start_timeout)
            self.symbols = {name: firmware_symbol(self.elf, name) for name in DIAGNOSTIC_SYMBOLS}
        except BaseException:
            self.close()
            raise

    def _pty_line(self) -> str:
        assert self.process.stdout is not None
        fd = self.process.stdout.fileno()
        buf = b""
        deadline = time.monotonic() + self.start_timeout
        while True:
            for line in buf.split(b"\n")[:-1]:
                if line.startswith(_PTY_PREFIX):
                    return line[len(_PTY_PREFIX) :].split(b" ")[0].decode()
            left = deadline - time.monotonic()
            if left <= 0:
                raise LinkTimeout(
                    f"no pty line from {' '.join(self.command)} in {self.start_timeout} s; "
                    f"stdout {buf!r}; {self.stderr_text()}"
                )
            ready, _, _ = select.select([fd], [], [], left)
            if ready:
                chunk = os.read(fd, 4096)
                if not chunk:
                    raise DeviceNotFound(
                        f"qemu exited with {self.process.wait()}: {self.stderr_text()}"
                    )
                buf += chunk

    def stderr_text(self) -> str:
        try:
            self._stderr.seek(0)
            text = self._stderr.read().decode(errors="replace").strip()
        except (OSError, ValueError):
            text = ""
        return "stderr: " + (text or "(empty)")

    def alive(self) -> bool:
        return self.process.poll() is None

    def words(self, symbol: str, count: int = 1) -> tuple[int, ...]:
        """``count`` u32 of the firmware's global ``symbol``, read while it runs."""
        if self.qmp is None:
            raise LinkError("QEMU's QMP socket is closed")
        fd, path = tempfile.mkstemp(suffix=".bin")
        os.close(fd)
        try:
            self.qmp.execute("pmemsave", val=self.symbols[symbol], size=4 * count, filename=path)
            with open(path, "rb") as f:
                return struct.unpack(f"<{count}I", f.read())
        finally:
            os.unlink(path)

    def motor_registers(self) -> tuple[int, ...]:
        """m4f_pwm_ccr[0..3], the duties the firmware last wrote to its motors."""
        return self.words(MOTOR_REGISTERS_SYMBOL, 4)

    def uart_losses(self) -> tuple[int, ...]:
        """(bytes the RX ring dropped, frames the TX ring dropped)."""
        return self.words("m4f_uart_rx_dropped") + self.words("m4f_uart_tx_frames_dropped")

    def close(self) -> None:
        if self.qmp is not None:
            try:
                self.qmp.close()
            except OSError:
                pass
            self.qmp = None
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait(timeout=10)
        if self.process.stdout is not None:
            self.process.stdout.close()
        self._stderr.close()
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None


class QemuFirmwareDevice(ChildPtyTransport):
    """``--port qemu``: :class:`QemuFirmware` and a serial transport on its pty, ready
    (the first HELLO answered) after :meth:`start`. ``firmware`` is the running QEMU
    (motor registers for the tests and the latency self-test)."""

    child_name = "the QEMU firmware"

    def __init__(
        self,
        elf: str | None = None,
        start_timeout: float = DEFAULT_START_TIMEOUT,
        baudrate: int = DEFAULT_BAUDRATE,
    ):
        self.elf = find_firmware_elf(elf, build=True)
        find_qemu()
        self.start_timeout = start_timeout
        self.baudrate = baudrate
        self.firmware: QemuFirmware | None = None
        self._serial: SerialTransport | None = None
        self.name = QEMU_PORT

    def start(self) -> QemuFirmwareDevice:
        if self.firmware is not None:
            return self
        self.firmware = QemuFirmware(self.elf, self.start_timeout)
        try:
            self._serial = SerialTransport(self.firmware.pty_path, self.baudrate)
            self._wait_connected()
        except BaseException:
            self.close()
            raise
        self.name = f"{QEMU_PORT} ({self.firmware.pty_path})"
        return self

    def _wait_connected(self) -> None:
        from graspguide.link.client import DeviceClient

        probe = DeviceClient(self, timeout=self.start_timeout)
        try:
            probe.hello(timeout=self.start_timeout)
        except LinkTimeout as e:
            raise LinkTimeout(
                f"the QEMU firmware did not answer HELLO within {self.start_timeout} s "
                f"({' '.join(self.firmware.command)}); "  # type: ignore[union-attr]
                f"{self.firmware.stderr_text()}"  # type: ignore[union-attr]
            ) from e

    def _gone(self, what: str, cause: LinkError) -> LinkError:
        fw = self.firmware
        if fw is not None and not fw.alive():
            return DeviceDisconnected(
                f"qemu exited with code {fw.process.poll()} while {what}; {fw.stderr_text()}"
            )
        return cause

    def motor_registers(self) -> tuple[int, ...]:
        if self.firmware is None:
            raise LinkError("the QEMU firmware is not running")
        return self.firmware.motor_registers()

    def close(self) -> None:
        if self._serial is not None:
            self._serial.close()
            self._serial = None
        if self.firmware is not None:
            self.firmware.close()
            self.firmware = None

    def __enter__(self) -> QemuFirmwareDevice:
        return self.start()


__all__ = [
    "QemuFirmware",
    "QemuFirmwareDevice",
    "Qmp",
    "find_firmware_elf",
    "firmware_build_command",
    "find_qemu",
    "firmware_symbol",
    "QEMU_PORT",
    "QEMU_FIRMWARE_ENV",
    "QEMU_BOARD_NAME",
]
