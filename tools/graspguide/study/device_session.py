"""A command's device session: the port opened (the simulator on its virtual clock when
asked), its DeviceClient, and STOP then the port closed on every way out, with the
commands' STOP report."""

from __future__ import annotations

import sys

from graspguide.link.client import DeviceClient
from graspguide.link.transport import LinkError, open_port


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

    def close(self) -> bool:
        """STOP, then close the port. False when STOP failed (said on stderr); a second
        Ctrl-C during STOP is not a failure: the user asked to leave."""
        try:
            self.client.stop()
            self.stop_acknowledged = True
        except (LinkError, OSError) as e:
            print(f"graspguide {self.command}: STOP failed: {e}", file=sys.stderr)
            return False
        except KeyboardInterrupt:
            pass
        finally:
            self.transport.close()
        return True


__all__ = ["DeviceSession"]
