"""A command's device session: the port opened (the simulator on its virtual clock when
asked), its DeviceClient, and STOP then the port closed on every way out, with the
commands' STOP report."""

from __future__ import annotations

import sys

from graspguide.devices.registry import open_port
from graspguide.link.client import DeviceClient
from graspguide.link.messages import DeviceState
from graspguide.link.transport import LinkError

# How long the device's state is awaited after STOP: a confirmation, not worth a long wait.
STATE_TIMEOUT_S = 1.0


class DeviceSession:
    """Opens ``port`` (raises LinkError) and holds its client; :meth:`close` sends STOP and
    closes the port, whatever happened before."""

    def __init__(
        self, command: str, port: str, baud: int, timeout: float, virtual_clock: bool = False
    ) -> None:
        kwargs = {"virtual_clock": True} if virtual_clock else {}
        self.command = command
        self.transport = open_port(port, baudrate=baud, **kwargs)
        self.client = DeviceClient(self.transport, timeout=timeout)
        self.stop_acknowledged = False
        self.final_state: DeviceState | None = None  # the device's state after STOP

    def close(self) -> bool:
        """STOP, then the device's state (GET_STATUS: the confirmation that the motors are
        off), then close the port. False when STOP failed (said on stderr); a second
        Ctrl-C during STOP is not a failure: the user asked to leave."""
        try:
            self.client.stop()
            self.stop_acknowledged = True
            try:
                self.final_state = self.client.status(timeout=STATE_TIMEOUT_S).state
            except (LinkError, OSError):
                self.final_state = None  # the ACK stands; the state is only a confirmation
        except (LinkError, OSError) as e:
            print(f"graspguide {self.command}: STOP failed: {e}", file=sys.stderr)
            return False
        except KeyboardInterrupt:
            pass
        finally:
            self.transport.close()
        return True

    def motors_text(self) -> str:
        """What is known of the motors after :meth:`close`, from the device's answers:
        ``off (STOP acknowledged, device stopped)``, or why it is not known."""
        if not self.stop_acknowledged:
            return (
                "not confirmed off: STOP was not acknowledged (the device's watchdog turns "
                "them off 200 ms after the last POSE)"
            )
        if self.final_state in (DeviceState.STOPPED, DeviceState.IDLE):
            return f"off (STOP acknowledged, device {self.final_state.name.lower()})"
        if self.final_state is None:
            return "off (STOP acknowledged)"
        return (
            f"STOP acknowledged but the device says {self.final_state.name.lower()}: check "
            "the motors"
        )


__all__ = ["DeviceSession"]
