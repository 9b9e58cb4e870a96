"""The port registry: a ``--port`` value to a started transport. ``sim``, ``promini-sim``
and ``qemu`` start a simulated device; anything else is a serial port. The transports
(:mod:`graspguide.link.transport`) know nothing of these, as mpremote and esptool keep
their port registries apart from the transport."""

from __future__ import annotations

from graspguide.devices import promini_sim, qemu_firmware, sim
from graspguide.link.transport import (
    DEFAULT_BAUDRATE,
    DeviceNotFound,
    SerialTransport,
    Transport,
    import_serial,
)


def open_port(port: str, baudrate: int = DEFAULT_BAUDRATE, **kwargs) -> Transport:
    """A started Transport for a ``--port`` value: ``"sim"`` starts the simulated device
    (keyword arguments go to :class:`SimulatedDevice`: virtual_clock, trace, stale_ms,
    binary, start_timeout, store), ``"promini-sim"`` the Pro Mini sketch under simavr
    (keyword arguments go to :class:`ProMiniSimDevice`: elf, trace, motors, marks, stats,
    fast), ``"qemu"`` the m4f firmware on QEMU (keyword arguments go to
    :class:`QemuFirmwareDevice`: elf, start_timeout), anything else opens that serial port
    (keyword arguments go to :class:`SerialTransport`). Close it (or use ``with``) when
    done."""
    if not port:
        raise DeviceNotFound(
            "no port given: use --port PATH (see `graspguide ports`) or --port sim"
        )

    if port == sim.SIM_PORT:
        return sim.SimulatedDevice(baudrate=baudrate, **kwargs).start()
    if port == promini_sim.PROMINI_SIM_PORT:
        return promini_sim.ProMiniSimDevice(baudrate=baudrate, **kwargs).start()
    if port == qemu_firmware.QEMU_PORT:
        return qemu_firmware.QemuFirmwareDevice(baudrate=baudrate, **kwargs).start()
    return SerialTransport(port, baudrate=baudrate, **kwargs)


def list_serial_ports() -> list[dict]:
    """The serial ports pyserial finds: dicts with device, description, hwid."""
    import_serial()
    from serial.tools import list_ports

    out = []
    for p in sorted(list_ports.comports(), key=lambda p: p.device):
        out.append({"device": p.device, "description": p.description or "", "hwid": p.hwid or ""})
    return out


__all__ = ["open_port", "list_serial_ports"]
