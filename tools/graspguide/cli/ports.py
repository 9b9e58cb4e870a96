"""`graspguide ports`: the serial ports, the simulated device 'sim' and the simulated Pro
Mini 'promini-sim'."""

from __future__ import annotations

import argparse
import json
import sys

from graspguide.devices.sim import SIM_PORT
from graspguide.exit_codes import EXIT_OK, fail
from graspguide.link.transport import LinkError

HELP = "list serial ports (and the simulated devices 'sim' and 'promini-sim')"
DESCRIPTION = (
    "List the serial ports pyserial finds, plus the pseudo-ports 'sim' (the "
    "simulated device, started on demand by --port sim) and 'promini-sim' (the Pro Mini "
    "sketch under simavr, --port promini-sim)."
)
RAW_DESCRIPTION = False


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="one JSON object per line")


def run(args: argparse.Namespace) -> int:
    from graspguide.devices.registry import list_serial_ports
    from graspguide.devices.sim import find_sim_binary

    try:
        ports = list_serial_ports()
    except LinkError as e:
        return fail("ports", e)
    try:
        sim = {"device": SIM_PORT, "description": "simulated device", "hwid": find_sim_binary()}
    except LinkError as e:
        sim = {
            "device": SIM_PORT,
            "description": "simulated device (not available)",
            "hwid": str(e).replace("\n", " "),
        }
    from graspguide.devices.promini_sim import PROMINI_SIM_PORT, find_promini_elf

    try:
        promini = {
            "device": PROMINI_SIM_PORT,
            "description": "simulated Pro Mini (the sketch under simavr)",
            "hwid": find_promini_elf(),
        }
    except LinkError as e:
        promini = {
            "device": PROMINI_SIM_PORT,
            "description": "simulated Pro Mini (not available)",
            "hwid": str(e).replace("\n", " "),
        }
    rows = ports + [sim, promini]
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return EXIT_OK
    width = max(len(r["device"]) for r in rows)
    for row in rows:
        extra = f"  [{row['hwid']}]" if row["hwid"] and row["hwid"] != "n/a" else ""
        print(f"{row['device']:<{width}}  {row['description']}{extra}")
    if not ports:
        print("(no serial ports found: is the board plugged in?)", file=sys.stderr)
    return EXIT_OK
