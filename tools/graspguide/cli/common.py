"""What every command's parser shares: the argument parser that takes negative numbers
as values, the numeric argument types, the port arguments, connecting to a device,
and SIGTERM/SIGHUP as Ctrl-C (the one-line error report is graspguide.devices.session's).
Each command module calls its library function by name with explicit keyword arguments."""

from __future__ import annotations

import argparse
import contextlib
import math
import re
import signal
from collections.abc import Callable, Iterator
from typing import Any

from graspguide.link.transport import DEFAULT_BAUDRATE

_NUM = r"(?:(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?|inf(?:inity)?|nan)"
# A word that starts with a negative number and goes on as a comma-separated list of
# numbers: "-1,0,0", "-1e-3", "-.5,2", "-inf".
_NEGATIVE_VALUE = re.compile(rf"-{_NUM}(?:\s*,\s*[-+]?{_NUM})*", re.IGNORECASE)


class ArgumentParser(argparse.ArgumentParser):
    """argparse takes a word that starts with "-" for an option unless it is a plain
    negative number, so `--wrench -1,0,0` failed with "expected one argument". Here every
    negative number or list of numbers is a value (no option of these commands looks like
    one); the option's type then checks it. Subparsers are made of this class too."""

    def _parse_optional(self, arg_string):
        if _NEGATIVE_VALUE.fullmatch(arg_string) and arg_string not in self._option_string_actions:
            return None
        return super()._parse_optional(arg_string)


def int_arg(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: an integer in [lo, hi]."""

    def conv(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"must be between {lo} and {hi}, got {v}")
        return v

    return conv


positive_int = int_arg(1, 1_000_000)


def positive_float(text: str) -> float:
    """An argparse type: seconds in (0, 3600]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 < value <= 3600:
        raise argparse.ArgumentTypeError(f"must be in (0, 3600] seconds, got {value}")
    return value


def add_protocol_argument(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument(
        "--protocol",
        required=required,
        default=None,
        metavar="FILE",
        help="study protocol (protocols/paper.toml; format in docs/study.md)"
        if required
        else "study protocol (default: protocols/paper.toml of the repository)",
    )


def add_jobs_argument(p: argparse.ArgumentParser, what: str) -> None:
    """--jobs of the simulated studies: ``what`` runs at a time, each its own simulator."""
    p.add_argument(
        "--jobs",
        "-j",
        type=int_arg(1, 256),
        default=None,
        metavar="N",
        help=f"{what} at a time, each with its own simulated device (default: the CPU count)",
    )


def add_action(
    sub: Any, name: str, help_table: dict[str, tuple[str, str, str]]
) -> argparse.ArgumentParser:
    """The parser of one action of a command with actions (device, mp): its one-line help,
    description and examples (``help_table[name]``) in --help."""
    short, description, examples = help_table[name]
    return sub.add_parser(
        name,
        help=short,
        description=description,
        epilog="examples:\n" + examples,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def add_port_arguments(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument(
        "--port",
        "-p",
        metavar="PORT",
        required=required,
        help="serial port of the device (e.g. /dev/ttyACM0, COM3; "
        "`graspguide ports` lists them), 'sim' to start the simulated "
        "device (.pio/build-sim/sim/program, or $GRASPGUIDE_SIM), 'promini-sim' for the "
        "Pro Mini sketch under simavr (build/promini/, or $GRASPGUIDE_PROMINI_ELF), "
        "or 'qemu' for the firmware on QEMU's mps2-an386 "
        "(.pio/build-m4f_firmware/m4f_firmware/firmware.elf, or $GRASPGUIDE_M4F_FIRMWARE); "
        "each simulated one is built on first use when it is missing",
    )
    p.add_argument(
        "--baud",
        type=positive_int,
        default=DEFAULT_BAUDRATE,
        metavar="RATE",
        help=f"baud rate (default {DEFAULT_BAUDRATE})",
    )
    p.add_argument(
        "--timeout",
        type=positive_float,
        default=1.0,
        metavar="S",
        help="seconds to wait for each answer of the device (default 1)",
    )


@contextlib.contextmanager
def signals_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP (a `kill`, a closed terminal, a supervisor stopping the run)
    raise KeyboardInterrupt in the main thread, as Ctrl-C does, so every command leaves
    through the same path: STOP sent, logs closed, exit status 130. Only the first one
    interrupts: a second signal must not cut the STOP on the way out short."""
    fired: list[int] = []

    def interrupt(signum, frame):
        if not fired:
            fired.append(signum)
            raise KeyboardInterrupt

    old = {s: signal.signal(s, interrupt) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def connect(args: argparse.Namespace) -> tuple[Any, Any]:
    """(transport, client) for --port after HELLO, or raise LinkError."""
    from graspguide.devices.registry import open_port
    from graspguide.link.client import DeviceClient

    transport = open_port(args.port, baudrate=args.baud)
    try:
        client = DeviceClient(transport, timeout=args.timeout)
        client.hello()
    except BaseException:
        transport.close()
        raise
    return transport, client


# The host-less runner's rest before each trial (graspguide.hostless.runner.DEFAULT_REST_S
# and the device's plan range; not imported here so `graspguide --help` stays fast).
DEFAULT_REST_S = 2.0
_REST_S_MAX = 600.0


def rest_s_arg(text: str) -> float:
    """--rest-s: seconds in [0, 600], the range a host-less plan holds."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not (0 <= v <= _REST_S_MAX):
        raise argparse.ArgumentTypeError(f"must be in [0, {_REST_S_MAX:g}] seconds, got {text}")
    return v


def quaternion_arg(text: str) -> tuple[float, float, float, float]:
    """w,x,y,z: four finite numbers, not all zero (normalised by whoever uses it)."""
    parts = text.replace(" ", "").split(",")
    try:
        q = tuple(float(x) for x in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"want w,x,y,z numbers, got {text!r}") from None
    if len(q) != 4 or not all(math.isfinite(x) for x in q) or not any(q):
        raise argparse.ArgumentTypeError(
            f"want four finite numbers w,x,y,z, not all zero (e.g. 1,0,0,0), got {text!r}"
        )
    return (q[0], q[1], q[2], q[3])


def non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a number of seconds >= 0, got {text!r}")
    return value


def add_lsl_arguments(p: argparse.ArgumentParser) -> None:
    """--lsl [NAME] and --lsl-wait S (graspguide.sources.lab_streams)."""
    p.add_argument(
        "--lsl",
        nargs="?",
        const="GraspGuide",
        default=None,
        metavar="NAME",
        help="publish the telemetry and the trial markers as LSL streams NAME-Telemetry "
        "and NAME-Markers (default NAME: GraspGuide)",
    )
    p.add_argument(
        "--lsl-wait",
        type=non_negative_float,
        default=0.0,
        metavar="S",
        help="with --lsl: wait up to S seconds for a recorder (LabRecorder) to connect "
        "to both streams before the trial starts (default 0: do not wait)",
    )
