"""`graspguide motors`: buzz one thimble or all of them at a PWM level or a pattern
(graspguide.link.motor_drive, graspguide.link.motor_patterns)."""

from __future__ import annotations

import argparse
import sys

from graspguide.cli.common import add_port_arguments, int_arg, signals_interrupt
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, fail

HELP = "bench test: drive a thimble's motor (or all) at a PWM level or a pattern"

DESCRIPTION = """\
Drive the motors directly (SET_MOTORS) for --duration-s seconds: the named --finger at
--pwm N, or a --pattern. SET_MOTORS is repeated every 50 ms, well inside the device's
200 ms POSE watchdog, so the motors stay on for as long as asked; they are switched off
(SET_MOTORS zeros, then STOP) at the end, on Ctrl-C, SIGTERM, SIGHUP and on any error.

Each change of the duties prints one line: the time since the start and every finger's
PWM; the last line says "motors off".

patterns: pulse[:on_ms=200,off_ms=200,pwm=200]   on and off in turn
          ramp[:from=70,to=255,period_s=0]        linear over the duration (or each period)
          sweep[:pwm=200,step_ms=500]             each selected finger alone in turn
          ready, success, timeout                 the host-less device's patterns
                                                  (docs/hostless.md)

Works on every device kind: a board's serial port, --port sim, promini-sim, qemu. A
device refuses SET_MOTORS while a trial runs (exit status 1)."""

EPILOG = """\
examples:
  graspguide motors --port sim --finger index --pwm 180 --duration-s 2
  graspguide motors --port /dev/ttyACM0 --finger all --pattern pulse:on_ms=200,off_ms=200
  graspguide motors --port /dev/ttyACM0 --pattern sweep:pwm=220,step_ms=400 --duration-s 4
  graspguide motors --port qemu --finger thumb,middle --pattern ramp:from=70,to=255

exit status: 0 done (motors off), 1 on a link error or a refusal by the device, 2 on a
usage error, 130 on Ctrl-C, SIGTERM or SIGHUP (motors switched off first)."""

DEFAULT_DURATION_S = 2.0


def _duration_s(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not 0 < value <= 3600:
        raise argparse.ArgumentTypeError(f"must be in (0, 3600] seconds, got {text}")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_port_arguments(p, required=True)
    p.add_argument(
        "--finger",
        default="all",
        metavar="FINGER",
        help="thumb, index, middle, palm, all, or 1..4; comma-separated for several (default all)",
    )
    level = p.add_mutually_exclusive_group(required=True)
    level.add_argument(
        "--pwm", type=int_arg(0, 255), metavar="N", help="constant duty 0..255 on the fingers"
    )
    level.add_argument(
        "--pattern",
        metavar="SPEC",
        help="pulse[:on_ms=,off_ms=,pwm=], ramp[:from=,to=,period_s=], "
        "sweep[:pwm=,step_ms=], ready, success or timeout",
    )
    p.add_argument(
        "--duration-s",
        type=_duration_s,
        default=None,
        metavar="S",
        help=f"how long (default {DEFAULT_DURATION_S:g} s; a host-less pattern: its length)",
    )


def _trace_line(t_s: float, pwm: tuple[int, ...]) -> str:
    from graspguide.link.motor_patterns import FINGER_NAMES

    duties = "  ".join(f"{name} {duty:3d}" for name, duty in zip(FINGER_NAMES, pwm))
    return f"{t_s:7.3f} s  {duties}"


@signals_interrupt()  # SIGTERM and SIGHUP switch the motors off like Ctrl-C
def run(args: argparse.Namespace) -> int:
    from graspguide.devices.session import DeviceSession
    from graspguide.link.messages import POSE_WATCHDOG_MS
    from graspguide.link.motor_drive import drive_motors
    from graspguide.link.motor_patterns import parse_fingers, parse_pattern
    from graspguide.link.transport import LinkError

    parser = args.command_parser
    try:
        fingers = parse_fingers(args.finger)
        duration_s = args.duration_s
        if args.pattern is not None:
            spec = parse_pattern(args.pattern, fingers, duration_s)
            source = spec.pattern
            if duration_s is None:
                duration_s = spec.length_s or DEFAULT_DURATION_S
        else:
            pwm = [0, 0, 0, 0]
            for f in fingers:
                pwm[f] = args.pwm
            source = tuple(pwm)  # type: ignore[assignment]
            duration_s = duration_s or DEFAULT_DURATION_S
    except ValueError as e:
        parser.error(str(e))

    last: list[tuple[int, ...]] = []

    def show(t_s: float, duty: tuple[int, ...]) -> None:
        if not last or last[0] != duty:
            last[:] = [duty]
            print(_trace_line(t_s, duty), flush=True)

    try:
        device = DeviceSession("motors", args.port, args.baud, args.timeout)
    except LinkError as e:
        return fail("motors", e)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    code = EXIT_OK
    stopped = False
    try:
        device.client.hello()
        drive_motors(device.client, source, duration_s, on_step=show)
    except LinkError as e:
        code = fail("motors", e)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        print("graspguide motors: interrupted", file=sys.stderr)
    finally:
        stopped = device.close()
        if not stopped:
            code = code or EXIT_FAILURE
    if stopped:
        print("motors off", flush=True)
    else:
        print(
            "motors off not confirmed: the device's watchdog switches them off "
            f"{POSE_WATCHDOG_MS} ms after the last SET_MOTORS",
            flush=True,
        )
    return code
