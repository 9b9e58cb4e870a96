"""Download a MicroPython board's results (``graspguide mp log``): mpremote copies the
board's store file, which holds the plan and the log in the C++ device's layout byte for
byte, and the C++ simulated device opened on that copy answers the same LOG_INFO and
LOG_READ as a board, so the download is `graspguide device log`'s, unchanged."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any, TextIO

from graspguide.mp.deploy import STORE_FILE, invoke, mpremote


def copy_command(port: str, board_path: str, local: Path) -> list[str]:
    """The mpremote command line that copies the board's store file to ``local``."""
    return mpremote() + ["connect", port, "fs", "cp", f":{board_path}", str(local)]


def download_board_log(
    port: str, out_dir: str, board_path: str = STORE_FILE, err: TextIO | None = None
) -> Any:
    """Copies the store from the board on ``port`` and writes its records into
    ``out_dir/<participant>/`` (graspguide.hostless.device_log). Returns the download's
    summary; MpToolError when mpremote fails, DeviceLogError/LinkError as device log."""
    from graspguide.devices.registry import open_port
    from graspguide.hostless.device_log import download_log
    from graspguide.link.client import DeviceClient

    with tempfile.TemporaryDirectory(prefix="graspguide-mp-log-") as tmp:
        local = Path(tmp) / "store.bin"
        invoke(copy_command(port, board_path, local))
        with open_port("sim", store=str(local)) as transport:
            client = DeviceClient(transport)
            client.hello()
            return download_log(client, out_dir, err=err or sys.stderr)


__all__ = ["copy_command", "download_board_log"]
