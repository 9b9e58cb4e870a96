"""Start the deployed port on a board (``graspguide mp run``): mpremote runs the staged
main.py in the board's RAM, against the lib/ and plan.bin that ``graspguide mp deploy``
copied, so what runs is what was deployed."""

from __future__ import annotations

from pathlib import Path

from graspguide.mp.deploy import ENTRY, mpremote


def run_command(port: str, entry: Path, follow: bool = True) -> list[str]:
    """The mpremote command line; with ``follow`` it prints the board's output until the
    program ends or Ctrl-C (sent on to the board as a KeyboardInterrupt)."""
    cmd = mpremote() + ["connect", port, "run"]
    if not follow:
        cmd.append("--no-follow")
    return cmd + [str(entry)]


__all__ = ["ENTRY", "run_command"]
