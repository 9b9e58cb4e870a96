"""`graspguide info`: who a device is (HELLO_REPLY) and how it is (STATUS)."""

from __future__ import annotations

import argparse
import json

from graspguide.cli.common import add_port_arguments, connect
from graspguide.exit_codes import EXIT_OK, fail
from graspguide.link.transport import LinkError

HELP = "identify a device: HELLO_REPLY and STATUS"
DESCRIPTION = (
    "Ask a device who it is (HELLO -> HELLO_REPLY: protocol and firmware "
    "version, board, scalar, contacts, build id, capabilities: full_solve, per_frame, "
    "hostless, sim_messages) and how it is (GET_STATUS "
    "-> STATUS: state, frames received, bad frames, stale events, last "
    "error)."
)
EPILOG = "examples:\n  graspguide info --port sim\n  graspguide info --port /dev/ttyACM0 --json"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_port_arguments(p, required=True)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def capability_names(bits: int) -> list[str]:
    """The names of HELLO_REPLY.capabilities' bits (CAPABILITY_* of the protocol, lower
    case), lowest bit first; a bit the host does not know as ``bit0xNN``."""
    from graspguide.link import messages

    known = {
        int(getattr(messages, name)): name[len("CAPABILITY_") :].lower()
        for name in dir(messages)
        if name.startswith("CAPABILITY_")
    }
    return [known.get(1 << i, f"bit0x{1 << i:02x}") for i in range(8) if bits & (1 << i)]


def run(args: argparse.Namespace) -> int:
    from graspguide.link.messages import PROTOCOL_VERSION

    try:
        transport, client = connect(args)
    except LinkError as e:
        return fail("info", e)
    try:
        hello = client.hello()
        status = client.status()
    except LinkError as e:
        return fail("info", e)
    finally:
        transport.close()
    scalar = {4: "float", 8: "double"}.get(hello.scalar, "unknown")
    data = {
        "port": args.port,
        "transport": transport.name,
        "protocol_version": hello.protocol_version,
        "firmware_version": ".".join(str(v) for v in hello.firmware_version),
        "board": hello.board,
        "scalar": scalar,
        "scalar_bytes": hello.scalar,
        "max_contacts": hello.max_contacts,
        "build_id": f"{hello.build_id:08x}",
        "capabilities": capability_names(hello.capabilities),
        "capabilities_bits": hello.capabilities,
        "state": status.state.name.lower(),
        "frames_received": status.frames_received,
        "bad_frames": status.bad_frames,
        "stale_events": status.stale_events,
        "last_error": status.last_error.name.lower(),
        "host_bad_frames": client.host_bad_frames,
    }
    if args.json:
        print(json.dumps(data))
        return EXIT_OK
    rows = [
        ("port", data["transport"]),
        ("protocol", f"{hello.protocol_version} (host {PROTOCOL_VERSION})"),
        ("firmware", data["firmware_version"]),
        ("board", hello.board),
        ("scalar", f"{scalar} ({hello.scalar} bytes)"),
        ("max contacts", str(hello.max_contacts)),
        ("build id", data["build_id"]),
        (
            "capabilities",
            f"{', '.join(data['capabilities']) or 'none'} (0x{hello.capabilities:02x})",
        ),
        ("state", data["state"]),
        ("frames received", str(status.frames_received)),
        ("bad frames", f"{status.bad_frames} (device), {client.host_bad_frames} (host)"),
        ("stale events", str(status.stale_events)),
        ("last error", data["last_error"]),
    ]
    for key, value in rows:
        print(f"{key + ':':<17}{value}")
    return EXIT_OK
