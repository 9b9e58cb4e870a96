"""`graspguide solve`: JSON Lines requests answered by the core or a device
(graspguide.core.requests)."""

from __future__ import annotations

import argparse
import os
import sys
from typing import BinaryIO, TextIO

from graspguide.cli.common import (
    add_port_arguments,
    connect,
    positive_int,
    signals_interrupt,
)
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, fail
from graspguide.link.transport import LinkError

HELP = "answer JSON Lines requests (contacts, wrench -> PWM) with the C++ core"

DESCRIPTION = """\
Run Algorithm 1 (docs/algorithm.md) on JSON Lines requests with the C++ core.

Reads one JSON object per line from stdin (or --input) and writes exactly one JSON
line per request to stdout (or --output), in input order, flushed after every line:
it can be driven interactively through a pipe. Blank lines are skipped (no output).
A bad request is answered with an error line and the stream goes on.

Request fields (anything else is rejected, so a typo is never ignored):
  contacts     required  3 or 4 [x, y, z] in the hand frame: thumb, index, middle
                         (, palm); in metres (millimetres with "units": "mm")
  wrench       required  [fx, fy, fz, mx, my, mz] in the object frame: force in N,
                         moment about the contacts' centroid in N m (N mm with
                         "units": "mm"): contacts and moments share a length unit
  units        "m" (default) | "mm" | "any": that length unit
  policy       "F" (default) | "Fperp"
  mode         "C" (default) | "V"
  constraints  "paper" (default) | "normal" | "none"
  orientation  [w, x, y, z] hand -> world; default [1, 0, 0, 0] (identity)
  y_axis       the object axis y_O in the hand frame; default [0, 1, 0]
Numbers may also be the JSON extensions NaN, Infinity and -Infinity, and a number
beyond the double range (1e400) is infinite: they reach the core, which answers
non_finite_input. Booleans and strings are never numbers. A contact count other
than 3 or 4 is the core's bad_contact_count.

Units are checked, since the core cannot tell them apart (it uses only ratios of
positions): a hand whose two farthest contacts are less than 5 mm or more than 0.5 m
apart in the stated unit, or a moment whose lever arm |m| / |f| exceeds 10 hand spans
(what a moment in N mm given as N m looks like: 1000 times too large), is a
bad_request that names the likely unit, e.g. "contacts span 77.9423 m ...: looks like
millimetres; give metres (divide by 1000), or add "units": "mm"". "units": "any"
skips both checks (synthetic geometry, such as scale tests of the core).

Success:
  {"ok": true, "pwm": [k ints 0..255], "levels": [k], "lambda": [3k],
   "constraints_used": "paper"|"normal"|"none", "relevant": [k bools],
   "error_deg": float, "iterations": int, "alpha": float, "fallback_mask": int}
Error:
  {"ok": false, "error": CODE, "message": "what is wrong and how to fix it"}
  CODE: "bad_json"     the line is not a JSON object (or not UTF-8, or too long)
        "bad_request"  a missing or unknown field, a wrong type or length, an
                       unknown policy/mode/constraints/units name, a hand or a
                       moment in another unit than stated (see above)
        otherwise the core's status, e.g. "non_finite_input", "bad_contact_count",
        "coincident_contacts", "rank_deficient", "zero_force", "bad_quaternion"

With --engine device --port PORT|sim a device answers instead (the firmware's float
and default route): per request SET_SCENE, START_TRIAL, one POSE, its TELEMETRY, STOP.
Its answers have the keys the wire carries: ok, pwm, constraints_used, error_deg,
iterations, alpha (levels, lambda, relevant and fallback_mask are not on the wire).
Bad requests get the same codes and messages; compare with --scalar float.

Exit status: 0 when the input ends (even if some requests were bad), 2 for a usage
error, 130 when interrupted (Ctrl-C, SIGTERM or SIGHUP; every answer so far is
flushed, and a device is sent STOP), 1 when the reader closes the output pipe, or
when the link to the device fails (that request is answered with error "link_error"
and the reason goes to stderr).
"""

EPILOG = """\
examples:
  echo '{"contacts": [[0.045,0.045,0.035], [0.015,0.095,0.04], [-0.01,0.1,0.04]],
  "wrench": [0.3,-1.2,-0.8,0,0,0]}' | tr -d '\\n' | graspguide solve
  graspguide solve --scalar float --input tools/examples/solve_requests.jsonl
  graspguide solve --engine device --port sim --input tools/examples/solve_requests.jsonl
"""


class _Routes:
    """The binding's equilibrium routes (graspguide.core.solver.DECOMPOSITIONS, the default
    first), looked up only when argparse checks or lists them: every command's parser is
    built at start-up, and the others do not need the core loaded."""

    def __contains__(self, name: object) -> bool:
        return name in _routes()

    def __iter__(self):
        return iter(_routes())


def _routes() -> tuple[str, ...]:
    from graspguide.core.solver import DECOMPOSITIONS

    return DECOMPOSITIONS


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--scalar",
        choices=("double", "float"),
        default=None,
        help="precision of the core: double (default, the host) or float "
        "(what a microcontroller with a single-precision FPU runs; "
        "compare --engine device with this)",
    )
    p.add_argument(
        "--decomposition",
        choices=_Routes(),
        default=None,
        metavar="ROUTE",  # argparse would list the choices when the parser is built
        help="equilibrium route (docs/algorithm.md, step 3): %(choices)s; the first is the "
        "default, the firmware's, the others are reference routes",
    )
    p.add_argument(
        "--max-iterations",
        type=positive_int,
        default=None,
        metavar="N",
        help="cap on the QP's active-set changes (default: the core's "
        "kDefaultMaxIterations, 64); hitting it is the error "
        "qp_iteration_limit",
    )
    p.add_argument(
        "--input",
        "-i",
        metavar="FILE",
        default="-",
        help="read requests from FILE instead of stdin ('-': stdin)",
    )
    p.add_argument(
        "--output",
        "-o",
        metavar="FILE",
        default="-",
        help="write responses to FILE instead of stdout ('-': stdout)",
    )
    p.add_argument(
        "--engine",
        choices=("core", "device"),
        default="core",
        help="who answers: core (default, the C++ core in this process) or "
        "device (the board or simulated device on --port: SET_SCENE, "
        "START_TRIAL, one POSE, TELEMETRY, STOP per request; answers "
        "carry ok, pwm, constraints_used, error_deg, iterations, alpha)",
    )
    add_port_arguments(p, required=False)


def _open_streams(parser: argparse.ArgumentParser, args) -> tuple[BinaryIO, TextIO]:
    if args.input == "-":
        inp = sys.stdin.buffer
    else:
        try:
            inp = open(args.input, "rb")
        except OSError as e:
            parser.error(f"cannot read --input {args.input}: {e.strerror}")
    if args.output == "-":
        out = sys.stdout
    else:
        try:
            out = open(args.output, "w", encoding="ascii", newline="\n")
        except OSError as e:
            parser.error(f"cannot write --output {args.output}: {e.strerror}")
    return inp, out


def _check_engine_options(args) -> None:
    parser = args.command_parser
    if args.engine == "core":
        if args.port is not None:
            parser.error(
                "--port is for --engine device (the core engine runs in this "
                "process); add --engine device"
            )
        return
    if args.port is None:
        parser.error("--engine device needs --port PORT (see `graspguide ports`) or --port sim")
    if args.scalar == "double":
        parser.error(
            "--engine device computes in the firmware's float; drop --scalar "
            "double (compare with --engine core --scalar float)"
        )
    if args.decomposition not in (None, _routes()[0]):
        parser.error(
            f"--engine device uses the firmware's {_routes()[0]} route; drop --decomposition"
        )
    if args.max_iterations is not None:
        parser.error("--engine device uses the firmware's QP iteration cap; drop --max-iterations")


@signals_interrupt()  # with --engine device: a request in flight still ends with STOP
def run(args: argparse.Namespace) -> int:
    _check_engine_options(args)
    inp, out = _open_streams(args.command_parser, args)
    engine = None
    transport = None
    if args.engine == "device":
        from graspguide.link.device_solver import DeviceEngine

        try:
            transport, client = connect(args)
            engine = DeviceEngine(client)
        except LinkError as e:
            if transport is not None:
                transport.close()
            if out is not sys.stdout:
                out.close()
            if inp is not sys.stdin.buffer:
                inp.close()
            return fail("solve", e)
    if args.input == "-" and sys.stdin.isatty() and sys.stderr.isatty():
        print(
            "graspguide solve: reading JSON requests, one per line (Ctrl-D to end, "
            "--help for the format)",
            file=sys.stderr,
        )
    from graspguide.core.requests import run_solve

    try:
        run_solve(
            inp, out, args.scalar or "double", args.decomposition, args.max_iterations, engine
        )
    except LinkError as e:
        return fail("solve", e)
    except KeyboardInterrupt:
        try:
            out.flush()
        except Exception:
            pass
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_FAILURE
    finally:
        if out is not sys.stdout:
            out.close()
        if inp is not sys.stdin.buffer:
            inp.close()
        if transport is not None:
            transport.close()
    return EXIT_OK
