"""`graspguide latency`: the latency self-test of a device (graspguide.bench.latency)."""

from __future__ import annotations

import argparse
import json
import sys

from graspguide.cli.common import add_port_arguments, int_arg, signals_interrupt
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, fail

HELP = (
    "latency self-test: POSE -> TELEMETRY round trips and POSE -> PWM applied, or a "
    "tracker's LSL sample -> PWM (--via lsl)"
)

DESCRIPTION = """\
Measure how late a device answers and drives its motors: HELLO, a 3-contact scene (a
per-frame board gets the posture the host solves), START_TRIAL, then --count POSEs, each
sent when the previous one is answered (or at --rate-hz), alternating between two hand
orientations so that every POSE changes the motors.

Prints, for each figure, the percentiles p50/p90/p99 and the maximum and a histogram:
  POSE -> TELEMETRY  round trip on the host's clock, every device kind;
  POSE -> PWM        where the device reports it: promini-sim exactly in the AVR's CPU
                     cycles (UART receipt of the POSE's last byte -> last motor-channel
                     change); sim from the host's write to the device's motor change on
                     the shared monotonic clock; not measured on qemu or a board (said so).

With --via lsl, the POSEs come from a tracker instead: an LSL MoCap outlet (a rigid body
Hand: Hand_X,Y,Z and Hand_QW,QX,QY,QZ) pushes three hand orientations in turn at --rate-hz
(default 100) from its own thread; the host receives them through the product's
`--source lsl:` source (time correction applied; --lsl-receiver inlet: a pylsl
StreamInlet used directly the same way) and sends the newest sample as a POSE once the
previous one is answered, until --count POSEs have changed the motors.
Prints the median, p95 and max of each part and of the total:
  push_to_pull       the tracker's push -> the host has pulled the sample;
  pull_to_written    pulled -> the POSE's bytes handed to the link;
  sim:         written_to_pwm (the device's motor change, CLOCK_MONOTONIC);
  promini-sim: line_time (the POSE's bytes at the sketch's baud, computed) and rx_to_pwm
               (UART receipt -> motor change, AVR cycles);
  qemu, a board: written_to_telemetry, so the total is push -> TELEMETRY, an upper
               bound of push -> PWM (the firmware writes the motors before it answers).
pylsl's clock and the host's monotonic clock are compared first: more than 1 ms apart,
the command refuses (exit 1).

docs/latency.md has the figures measured per device kind and what they include."""

EPILOG = """\
examples:
  graspguide latency --port sim
  graspguide latency --port promini-sim --count 500 --json promini.json
  graspguide latency --port qemu --rate-hz 100
  graspguide latency --port /dev/ttyACM0 --count 1000
  graspguide latency --port sim --via lsl
  graspguide latency --port promini-sim --via lsl --rate-hz 60 --json tracker.json

exit status: 0 measured, 1 on a link error, an unwritable --json file or LSL that cannot
be used here (--via lsl), 2 on a usage
error, 130 on Ctrl-C, SIGTERM or SIGHUP (STOP sent first)."""


def _rate_hz(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of POSEs a second: {text!r}") from None
    if not 10 <= value <= 10_000:
        raise argparse.ArgumentTypeError(
            f"must be in [10, 10000] Hz (a POSE at least every 100 ms keeps the device's "
            f"200 ms watchdog fed), got {text}"
        )
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_port_arguments(p, required=True)
    p.add_argument(
        "--count",
        type=int_arg(1, 100_000),
        default=200,
        metavar="N",
        help="POSEs to time (default 200)",
    )
    p.add_argument(
        "--rate-hz",
        type=_rate_hz,
        default=None,
        metavar="R",
        help="send POSEs at this rate (default: each as soon as the previous is answered); "
        "with --via lsl the tracker's push rate, at most 1000 (default 100)",
    )
    p.add_argument(
        "--via",
        choices=("direct", "lsl"),
        default="direct",
        help="direct: the host sends POSEs itself (default); lsl: they come from a "
        "tracker's LSL outlet, timed from its push to the motors",
    )
    p.add_argument(
        "--lsl-receiver",
        choices=("auto", "source", "inlet"),
        default="auto",
        help="with --via lsl, what receives the tracker's samples: source, the "
        "product's --source lsl: source; inlet, a pylsl StreamInlet used directly the same "
        "way; auto (default), the source where it is installed",
    )
    p.add_argument(
        "--json", metavar="FILE", default=None, help="also write the figures as JSON to FILE"
    )


@signals_interrupt()  # SIGTERM and SIGHUP end the test like Ctrl-C (STOP sent)
def run(args: argparse.Namespace) -> int:
    from graspguide.bench.latency import measure_latency, report_lines
    from graspguide.link.transport import LinkError

    if args.via == "lsl":
        return _run_lsl(args)
    try:
        result = measure_latency(args.port, args.count, args.rate_hz, args.baud, args.timeout)
    except LinkError as e:
        return fail("latency", e)
    except KeyboardInterrupt:
        print("graspguide latency: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    print("\n".join(report_lines(result)))
    if args.json:
        try:
            with open(args.json, "w") as f:
                json.dump(result.to_dict(), f, indent=1)
                f.write("\n")
        except OSError as e:
            return fail("latency", f"cannot write --json {args.json}: {e}", EXIT_FAILURE)
    return EXIT_OK


def _run_lsl(args: argparse.Namespace) -> int:
    from graspguide.bench.latency import (
        LSL_RATE_HZ,
        MAX_LSL_RATE_HZ,
        LslLatencyError,
        measure_tracker_latency,
        tracker_report_lines,
    )
    from graspguide.exit_codes import EXIT_USAGE
    from graspguide.link.transport import LinkError

    rate = LSL_RATE_HZ if args.rate_hz is None else args.rate_hz
    if rate > MAX_LSL_RATE_HZ:
        return fail(
            "latency",
            ValueError(
                f"--rate-hz with --via lsl is the tracker's push rate: at most "
                f"{MAX_LSL_RATE_HZ:g}, got {rate:g}"
            ),
            EXIT_USAGE,
        )
    try:
        result = measure_tracker_latency(
            args.port, args.count, rate, args.baud, args.timeout, receiver=args.lsl_receiver
        )
    except (LinkError, LslLatencyError) as e:
        return fail("latency", e)
    except KeyboardInterrupt:
        print("graspguide latency: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    print("\n".join(tracker_report_lines(result)))
    if args.json:
        try:
            with open(args.json, "w") as f:
                json.dump(result.to_dict(), f, indent=1)
                f.write("\n")
        except OSError as e:
            return fail("latency", f"cannot write --json {args.json}: {e}", EXIT_FAILURE)
    return EXIT_OK
