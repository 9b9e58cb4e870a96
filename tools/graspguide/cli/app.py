"""The ``graspguide`` command line.

``graspguide solve`` reads JSON Lines (one request per line) and writes exactly one JSON
line per request, in order, flushed after each line, so it can be driven through a pipe
one request at a time; with ``--engine device --port PORT|sim`` a device answers instead
of the core. ``graspguide ports`` lists serial ports (and ``sim``), ``graspguide info``
identifies a device, ``graspguide stream`` runs one trial, ``graspguide trial`` runs a
participant's trials of a study protocol (graspguide.study.runner, docs/study.md). See
``graspguide COMMAND --help``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import signal
import sys
import time
from collections.abc import Iterator
from typing import Any, BinaryIO, TextIO

from graspguide import __version__
from graspguide.link.transport import DEFAULT_BAUDRATE, SIM_PORT, LinkError

# A request is a few hundred bytes; a longer line is answered with bad_json without
# being parsed (the rest of it is read and dropped, so the stream goes on).
MAX_LINE_BYTES = 1 << 20

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130

_BOM = b"\xef\xbb\xbf"

SOLVE_DESCRIPTION = """\
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
and QR route): per request SET_SCENE, START_TRIAL, one POSE, its TELEMETRY, STOP.
Its answers have the keys the wire carries: ok, pwm, constraints_used, error_deg,
iterations, alpha (levels, lambda, relevant and fallback_mask are not on the wire).
Bad requests get the same codes and messages; compare with --scalar float.

Exit status: 0 when the input ends (even if some requests were bad), 2 for a usage
error, 130 when interrupted (Ctrl-C, SIGTERM or SIGHUP; every answer so far is
flushed, and a device is sent STOP), 1 when the reader closes the output pipe, or
when the link to the device fails (that request is answered with error "link_error"
and the reason goes to stderr).
"""

SOLVE_EPILOG = """\
examples:
  echo '{"contacts": [[0.045,0.045,0.035], [0.015,0.095,0.04], [-0.01,0.1,0.04]],
  "wrench": [0.3,-1.2,-0.8,0,0,0]}' | tr -d '\\n' | graspguide solve
  graspguide solve --scalar float --input tools/examples/solve_requests.jsonl
  graspguide solve --engine device --port sim --input tools/examples/solve_requests.jsonl
"""


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------
class _LineTooLong:
    def __init__(self, size: int):
        self.size = size


def _read_lines(stream: BinaryIO, limit: int = MAX_LINE_BYTES) -> Iterator[bytes | _LineTooLong]:
    """Lines of a binary stream (the last one may lack its newline). A line longer than
    ``limit`` bytes is read to its end and yielded as _LineTooLong."""
    while True:
        line = stream.readline(limit + 1)
        if not line:
            return
        if len(line) > limit and not line.endswith(b"\n"):
            size = len(line)
            while True:
                chunk = stream.readline(1 << 16)
                size += len(chunk)
                if not chunk or chunk.endswith(b"\n"):
                    break
            yield _LineTooLong(size)
            continue
        yield line


def _parse_int(text: str) -> int | float:
    try:
        return int(text)
    except ValueError:  # beyond Python's int-string digit limit: a float (inf)
        return float(text)


class _DuplicateField(ValueError):
    pass


def _no_duplicates(pairs):
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateField(key)
        out[key] = value
    return out


def _decode(line: bytes, number: int):
    """The JSON value of one line, or raise RequestError."""
    from graspguide.core.solver import RequestError

    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError as e:
        raise RequestError(
            "bad_json",
            f"line {number} is not valid UTF-8 (byte 0x{line[e.start]:02x} at "
            f"byte offset {e.start}); send UTF-8 encoded JSON",
        ) from None
    try:
        return json.loads(text, parse_int=_parse_int, object_pairs_hook=_no_duplicates)
    except _DuplicateField as e:
        raise RequestError(
            "bad_request",
            f"line {number}: field {json.dumps(str(e))} is given more than "
            "once; give each field once",
        ) from None
    except json.JSONDecodeError as e:
        hint = ""
        if e.msg == "Extra data":
            hint = " (exactly one JSON object per line)"
        elif text.lstrip().startswith("{") and "'" in text and '"' not in text:
            hint = " (JSON strings use double quotes)"
        raise RequestError(
            "bad_json", f"line {number} is not valid JSON: {e.msg} at column {e.colno}{hint}"
        ) from None
    except RecursionError:
        raise RequestError(
            "bad_json",
            f"line {number}: JSON nested too deeply; a request is a flat object of arrays",
        ) from None
    except ValueError as e:  # e.g. a number the float parser cannot handle
        raise RequestError("bad_json", f"line {number} is not valid JSON: {e}") from None


# --------------------------------------------------------------------------------------
# Answering
# --------------------------------------------------------------------------------------
def _finite_or_none(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _success(res: dict[str, Any]) -> dict[str, Any]:
    return {
        "ok": True,
        "pwm": list(res["pwm"]),
        "levels": [_finite_or_none(v) for v in res["levels"]],
        "lambda": [_finite_or_none(v) for v in res["lambda"]],
        "constraints_used": res["constraints_used"],
        "relevant": list(res["relevant"]),
        "error_deg": _finite_or_none(res["error_deg"]),
        "iterations": res["iterations"],
        "alpha": _finite_or_none(res["alpha"]),
        "fallback_mask": res["fallback_mask"],
    }


def _error(code: str, message: str) -> dict[str, Any]:
    return {"ok": False, "error": code, "message": message}


def answer(
    line: bytes | _LineTooLong,
    number: int,
    scalar: str = "double",
    decomposition: str = "qr",
    max_iterations: int | None = None,
    engine: DeviceEngine | None = None,
) -> dict[str, Any] | None:
    """The response to one input line, or None for a blank line. With ``engine`` (a
    :class:`DeviceEngine`) the device answers instead of the core."""
    from graspguide.core import solver

    if isinstance(line, _LineTooLong):
        return _error(
            "bad_json",
            f"line {number} is {line.size} bytes long, over the limit of "
            f"{MAX_LINE_BYTES}; a request is one short JSON object per line",
        )
    if number == 1 and line.startswith(_BOM):
        line = line[len(_BOM) :]
    if not line.strip():
        return None
    try:
        obj = _decode(line, number)
        obj, units = _pop_units(obj)
        kwargs = _in_metres(solver.parse_request(obj), units)
    except solver.RequestError as e:
        message = e.message
        if not message.startswith("line "):
            message = f"line {number}: {message}"
        return _error(e.code, message)
    if engine is not None:
        return engine.answer(kwargs)
    try:
        res = solver.solve(
            scalar=scalar,
            decomposition=decomposition,
            max_iterations=(
                solver.DEFAULT_MAX_ITERATIONS if max_iterations is None else max_iterations
            ),
            **kwargs,
        )
    except Exception as e:  # never expected: the request was checked above
        return _error(
            "internal_error",
            f"line {number}: unexpected {type(e).__name__}: {e}; please report this request",
        )
    if res["status"] != "ok":
        return _error(res["status"], solver.status_message(res["status"]))
    return _success(res)


REQUEST_UNITS = ("m", "mm", "any")


def _pop_units(obj: Any) -> tuple[Any, str]:
    """The request without its "units" field, and that field ("m" by default)."""
    from graspguide.core.solver import RequestError

    if not isinstance(obj, dict) or "units" not in obj:
        return obj, "m"
    obj = dict(obj)
    units = obj.pop("units")
    if not isinstance(units, str) or units not in REQUEST_UNITS:
        raise RequestError(
            "bad_request",
            f'field "units" must be "m" (the default), "mm" or "any", got {json.dumps(units)}',
        )
    return obj, units


def _solve_unit_fix(sym: str | None) -> str:
    if sym == "mm":
        return 'give metres (divide by 1000), or add "units": "mm" (moments in N mm then)'
    if sym == "cm":
        return "give metres (divide by 100)"
    if sym == "m":
        return 'drop "units": "mm" (metres are the default)'
    return 'give the contacts in metres, or in millimetres with "units": "mm"'


def _in_metres(kw: dict[str, Any], units: str) -> dict[str, Any]:
    """The request's solve() arguments with contacts in metres and moments in N m; a hand
    that does not span like one in the stated unit, or a moment in another length unit
    than the contacts, is a bad_request naming the likely unit. Requests the core would
    refuse anyway (a contact count other than 3 or 4, a non-finite number, all contacts
    at one point) go on to the core's own answer; "units": "any" skips the checks (the
    core uses only ratios: synthetic geometry such as its scale tests)."""
    from graspguide.core.solver import RequestError
    from graspguide.study.scene_file import hand_span, hand_span_problem, moment_unit_problem

    contacts, wrench = kw["contacts"], kw["wrench"]
    if (
        units == "any"
        or len(contacts) not in (3, 4)
        or not all(math.isfinite(x) for x in [*(v for c in contacts for v in c), *wrench])
    ):
        return kw
    if hand_span(contacts) > 0.0:
        problem = hand_span_problem(contacts, units, _solve_unit_fix)
        if problem:
            raise RequestError("bad_request", problem)
    if units == "mm":
        contacts = [[v / 1000.0 for v in c] for c in contacts]
        wrench = list(wrench[:3]) + [v / 1000.0 for v in wrench[3:]]
        kw = {**kw, "contacts": contacts, "wrench": wrench}
    problem = moment_unit_problem(contacts, wrench)
    if problem:
        raise RequestError("bad_request", problem)
    return kw


def _dumps(obj: dict[str, Any]) -> str:
    # ASCII only, and strict JSON (no NaN): any consumer can read it.
    return json.dumps(obj, ensure_ascii=True, allow_nan=False, separators=(", ", ": "))


def run_solve(
    inp: BinaryIO,
    out: TextIO,
    scalar: str = "double",
    decomposition: str = "qr",
    max_iterations: int | None = None,
    engine: DeviceEngine | None = None,
) -> int:
    """Answer every line of ``inp`` on ``out``; returns the number of answers."""
    count = 0
    for number, line in enumerate(_read_lines(inp), start=1):
        try:
            response = answer(line, number, scalar, decomposition, max_iterations, engine)
        except LinkError as e:
            # The link failed (only with --engine device): this request gets its error
            # line, every earlier answer is already out, and the command stops.
            out.write(_dumps(_error("link_error", f"line {number}: {e}")) + "\n")
            out.flush()
            raise
        if response is None:
            continue
        out.write(_dumps(response) + "\n")
        out.flush()
        count += 1
    return count


# --------------------------------------------------------------------------------------
# The device as the solve engine
# --------------------------------------------------------------------------------------
class DeviceEngine:
    """Answers `graspguide solve` requests with a device (--engine device): per request
    SET_SCENE (contacts, y_axis, constraints, policy, mode), START_TRIAL (wrench), one
    POSE (orientation), its TELEMETRY, then STOP (motors off).

    The answer has the core's keys that the wire carries: ok, pwm, constraints_used,
    error_deg, iterations, alpha. ``levels``, ``lambda``, ``relevant`` and
    ``fallback_mask`` are not in TELEMETRY and are left out. Bad requests are answered by
    the same checks as the core engine (bad_json, bad_request) on the host; the device's
    refusals and TELEMETRY.solver_status come back with the core's code and message.
    """

    def __init__(self, client) -> None:
        self.client = client
        self._trial_id = 0
        client.stop()  # a trial left running by an earlier session would refuse SET_SCENE

    def answer(self, kw: dict[str, Any]) -> dict[str, Any]:
        from graspguide.core import solver
        from graspguide.link.client import DeviceError

        client = self.client
        self._trial_id = (self._trial_id + 1) & 0xFFFF
        k = len(kw["contacts"])
        try:
            try:
                client.set_scene(
                    kw["contacts"],
                    y_axis=kw["y_axis"],
                    constraints=kw["constraints"],
                    policy=kw["policy"],
                    mode=kw["mode"],
                )
                client.start_trial(self._trial_id, kw["wrench"])
                tel = client.pose(quat=kw["orientation"])
            finally:
                client.stop()
        except DeviceError as e:
            return self._device_error(e, solver)
        status = int(tel.solver_status)
        if status != 0:
            return self._device_error(
                DeviceError("POSE", None, status, 0, source="TELEMETRY"), solver
            )
        return {
            "ok": True,
            "pwm": [int(p) for p in tel.pwm[:k]],
            "constraints_used": tel.constraints_used.name.lower(),
            "error_deg": _finite_or_none(float(tel.error_deg)),
            "iterations": int(tel.iterations),
            "alpha": _finite_or_none(float(tel.alpha)),
        }

    @staticmethod
    def _device_error(e, solver) -> dict[str, Any]:
        if e.code_name in solver.STATUS_NAMES:  # a core status: the core's message
            return _error(e.code_name, solver.status_message(e.code_name))
        return _error(e.code_name, str(e))


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------
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


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 1 <= value <= 1_000_000:
        raise argparse.ArgumentTypeError(f"must be between 1 and 1000000, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="graspguide",
        description="GraspGuide host tools: hand guidance by a grasping metaphor "
        "(Algorithm 1 from the C++ core in lib/graspguide).",
        epilog="Run 'graspguide COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    solve = sub.add_parser(
        "solve",
        help="answer JSON Lines requests (contacts, wrench -> PWM) with the C++ core",
        description=SOLVE_DESCRIPTION,
        epilog=SOLVE_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    solve.add_argument(
        "--scalar",
        choices=("double", "float"),
        default=None,
        help="precision of the core: double (default, the host) or float "
        "(what a microcontroller with a single-precision FPU runs; "
        "compare --engine device with this)",
    )
    solve.add_argument(
        "--decomposition",
        choices=("qr", "svd"),
        default="qr",
        help="equilibrium route: column-pivoting QR (default, the firmware's) "
        "or Jacobi SVD (reference route)",
    )
    solve.add_argument(
        "--max-iterations",
        type=_positive_int,
        default=None,
        metavar="N",
        help="cap on the QP's active-set changes (default: the core's "
        "kDefaultMaxIterations, 64); hitting it is the error "
        "qp_iteration_limit",
    )
    solve.add_argument(
        "--input",
        "-i",
        metavar="FILE",
        default="-",
        help="read requests from FILE instead of stdin ('-': stdin)",
    )
    solve.add_argument(
        "--output",
        "-o",
        metavar="FILE",
        default="-",
        help="write responses to FILE instead of stdout ('-': stdout)",
    )
    solve.add_argument(
        "--engine",
        choices=("core", "device"),
        default="core",
        help="who answers: core (default, the C++ core in this process) or "
        "device (the board or simulated device on --port: SET_SCENE, "
        "START_TRIAL, one POSE, TELEMETRY, STOP per request; answers "
        "carry ok, pwm, constraints_used, error_deg, iterations, alpha)",
    )
    _add_port_arguments(solve, required=False)
    solve.set_defaults(handler=_cmd_solve, command_parser=solve)

    ports = sub.add_parser(
        "ports",
        help="list serial ports (and the simulated device 'sim')",
        description="List the serial ports pyserial finds, plus the pseudo-port 'sim' (the "
        "simulated device, started on demand by --port sim).",
    )
    ports.add_argument("--json", action="store_true", help="one JSON object per line")
    ports.set_defaults(handler=_cmd_ports, command_parser=ports)

    info = sub.add_parser(
        "info",
        help="identify a device: HELLO_REPLY and STATUS",
        description="Ask a device who it is (HELLO -> HELLO_REPLY: protocol and firmware "
        "version, board, scalar, contacts, build id) and how it is (GET_STATUS "
        "-> STATUS: state, frames received, bad frames, stale events, last "
        "error).",
        epilog="examples:\n  graspguide info --port sim\n"
        "  graspguide info --port /dev/ttyACM0 --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_port_arguments(info, required=True)
    info.add_argument("--json", action="store_true", help="print one JSON object")
    info.set_defaults(handler=_cmd_info, command_parser=info)
    _add_stream_parser(sub)
    _add_bench_parser(sub)
    _add_trial_parser(sub)
    from graspguide.study import analysis as _analysis
    from graspguide.study import demo as _demo
    from graspguide.study import sweep as _sweep

    _analysis.register(sub)  # `graspguide analyze`: Tables I-III, statistics, Figure 4
    _demo.add_parser(sub)  # `graspguide demo`: the paper's study end to end, simulated
    _sweep.register(sub)  # `graspguide sweep`: threshold and pose rate vs time/success
    return parser


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 < value <= 3600:
        raise argparse.ArgumentTypeError(f"must be in (0, 3600] seconds, got {value}")
    return value


def _add_port_arguments(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument(
        "--port",
        "-p",
        metavar="PORT",
        required=required,
        help="serial port of the device (e.g. /dev/ttyACM0, COM3; "
        "`graspguide ports` lists them), or 'sim' to start the simulated "
        "device (.pio/build/sim/program, or $GRASPGUIDE_SIM)",
    )
    p.add_argument(
        "--baud",
        type=_positive_int,
        default=DEFAULT_BAUDRATE,
        metavar="RATE",
        help=f"baud rate (default {DEFAULT_BAUDRATE})",
    )
    p.add_argument(
        "--timeout",
        type=_positive_float,
        default=1.0,
        metavar="S",
        help="seconds to wait for each answer of the device (default 1)",
    )


@contextlib.contextmanager
def signals_interrupt():
    """SIGTERM and SIGHUP (a `kill`, a closed terminal, a supervisor stopping the run)
    raise KeyboardInterrupt in the main thread, as Ctrl-C does, so every command leaves
    through the same path: STOP sent, logs closed, exit status 130. Only the first one
    interrupts: a second signal must not cut the STOP on the way out short."""
    fired = []

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


def _connect(args):
    """(transport, client) for --port, or raise LinkError."""
    from graspguide.link.client import DeviceClient
    from graspguide.link.transport import open_port

    transport = open_port(args.port, baudrate=args.baud)
    try:
        client = DeviceClient(transport, timeout=args.timeout)
        client.hello()
    except BaseException:
        transport.close()
        raise
    return transport, client


def _fail(command: str, e: BaseException) -> int:
    print(f"graspguide {command}: error: {e}", file=sys.stderr)
    return EXIT_FAILURE


def _cmd_ports(args) -> int:
    from graspguide.link.transport import (
        LinkError as _LinkError,
    )
    from graspguide.link.transport import (
        find_sim_binary,
        list_serial_ports,
    )

    try:
        ports = list_serial_ports()
    except _LinkError as e:
        return _fail("ports", e)
    try:
        sim = {"device": SIM_PORT, "description": "simulated device", "hwid": find_sim_binary()}
    except _LinkError as e:
        sim = {
            "device": SIM_PORT,
            "description": "simulated device (not available)",
            "hwid": str(e).replace("\n", " "),
        }
    rows = ports + [sim]
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


def _cmd_info(args) -> int:
    from graspguide.link.messages import PROTOCOL_VERSION

    try:
        transport, client = _connect(args)
    except LinkError as e:
        return _fail("info", e)
    try:
        hello = client.hello()
        status = client.status()
    except LinkError as e:
        return _fail("info", e)
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
        ("state", data["state"]),
        ("frames received", str(status.frames_received)),
        ("bad frames", f"{status.bad_frames} (device), {client.host_bad_frames} (host)"),
        ("stale events", str(status.stale_events)),
        ("last error", data["last_error"]),
    ]
    for key, value in rows:
        print(f"{key + ':':<17}{value}")
    return EXIT_OK


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
    if args.decomposition != "qr":
        parser.error("--engine device uses the firmware's QR route; drop --decomposition")
    if args.max_iterations is not None:
        parser.error("--engine device uses the firmware's QP iteration cap; drop --max-iterations")


@signals_interrupt()  # with --engine device: a request in flight still ends with STOP
def _cmd_solve(args) -> int:
    _check_engine_options(args)
    inp, out = _open_streams(args.command_parser, args)
    engine = None
    transport = None
    if args.engine == "device":
        try:
            transport, client = _connect(args)
            engine = DeviceEngine(client)
        except LinkError as e:
            if transport is not None:
                transport.close()
            if out is not sys.stdout:
                out.close()
            if inp is not sys.stdin.buffer:
                inp.close()
            return _fail("solve", e)
    if args.input == "-" and sys.stdin.isatty() and sys.stderr.isatty():
        print(
            "graspguide solve: reading JSON requests, one per line (Ctrl-D to end, "
            "--help for the format)",
            file=sys.stderr,
        )
    try:
        run_solve(
            inp, out, args.scalar or "double", args.decomposition, args.max_iterations, engine
        )
    except LinkError as e:
        return _fail("solve", e)
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


# --------------------------------------------------------------------------------------
# graspguide stream
# --------------------------------------------------------------------------------------
STREAM_DESCRIPTION = """\
Run one trial on a device: HELLO, SET_SCENE (from --scene), START_TRIAL (--wrench), then
stream the poses of --source at the source's rate (real time; with --port sim
--virtual-clock as fast as the link allows, the device's clock following the poses'
times) while showing the guidance error, the motors' PWM, the rate and dropped frames.
Stops at the TRIAL_RESULT or at the end of the source, and always sends STOP on the way
out (also on Ctrl-C, SIGTERM, SIGHUP or an error).

sources: replay:FILE.csv (columns t_s,qw,qx,qy,qz[,thumb_x,...]; with --tracker the
         values are a tracker's raw export and are converted),
         synthetic[:rate=240,duration=10,seed=0] (a scripted hand that turns to align the
         scene's force with gravity),
         plugin:MODULE:CLASS[:ARG] (a live tracker: a graspguide.study.sources.TrackerAdapter
         subclass that reads the lab's tracker SDK)."""

STREAM_EPILOG = """\
examples:
  graspguide stream --port sim --virtual-clock --scene tools/examples/scene_paper_3.toml \\
      --wrench 0.3,-1.2,-0.8 --source synthetic --log runs/s1
  graspguide stream --port /dev/ttyACM0 --scene my_scene.toml --wrench -1,0,-2 \\
      --source replay:poses.csv --trial-id 3

exit status: 0 when the trial ended (success or failure) or the source ended, 1 on a link
error, 2 on a usage error (bad scene, wrench or source), 130 on Ctrl-C, SIGTERM or SIGHUP
(STOP is sent and the log's end record written first)."""


def _wrench(text: str):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--wrench must be fx,fy,fz or fx,fy,fz,mx,my,mz (numbers), got {text!r}"
        ) from None
    if len(values) not in (3, 6) or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(
            f"--wrench must be 3 or 6 finite numbers (fx,fy,fz[,mx,my,mz]), got {text!r}"
        )
    return values + [0.0] * (6 - len(values))


def _add_stream_parser(sub) -> None:
    p = sub.add_parser(
        "stream",
        help="run a trial: stream poses from a source to a device",
        description=STREAM_DESCRIPTION,
        epilog=STREAM_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_port_arguments(p, required=True)
    p.add_argument(
        "--scene",
        required=True,
        metavar="SCENE.toml",
        help="scene file (tools/examples/scene_paper_3.toml shows the format)",
    )
    p.add_argument(
        "--wrench",
        required=True,
        type=_wrench,
        metavar="FX,FY,FZ[,MX,MY,MZ]",
        help="the virtual object's wrench in the object frame: force in N, "
        "moment about the contacts' centroid in N m; negative values as "
        "they are: --wrench -1,0,0 (a moment of more than 10 hand spans "
        "times the force is refused: it looks like N mm)",
    )
    p.add_argument(
        "--source",
        required=True,
        metavar="SOURCE",
        help="replay:FILE.csv, synthetic[:rate=240,duration=10,seed=0] or "
        "plugin:MODULE:CLASS[:ARG]",
    )
    p.add_argument(
        "--tracker",
        metavar="NAME",
        default=None,
        help="the replay file is a raw tracker export in this convention: "
        "vicon, optitrack, leap, world, or UNITS/UP/HANDEDNESS/ORDER such "
        "as mm/y/right/xyzw (default: already in this project's world)",
    )
    p.add_argument(
        "--log",
        metavar="DIR",
        default=None,
        help="write the session folder DIR (scene.json, device.json, "
        "config.json, poses.csv, telemetry.csv, results.jsonl)",
    )
    p.add_argument(
        "--trial-id",
        type=int,
        default=1,
        metavar="N",
        help="START_TRIAL trial id, 0..65535 (default 1)",
    )
    p.add_argument(
        "--virtual-clock",
        action="store_true",
        help="with --port sim: the device's clock follows the poses' times, so "
        "the trial runs as fast as possible",
    )
    p.set_defaults(handler=_cmd_stream, command_parser=p)


def _add_bench_parser(sub) -> None:
    # Arguments only: graspguide.bench (numpy, the peer solvers) is imported when the
    # command runs, so the other commands do not pay for it at start-up.
    p = sub.add_parser(
        "bench",
        help="host benchmark: full frame and QP alone vs DAQP, quadprog, OSQP, "
        "scipy, with accuracy against the float64 reference",
        description="Time this project's full frame (in C++ and per Python call) and its QP "
        "alone next to DAQP, quadprog, OSQP and scipy on the same instances, "
        "judge every answer against the float64 reference, print a table. "
        "Columns: tools/README.md, 'graspguide bench'.",
    )
    p.add_argument(
        "--instances",
        type=int,
        default=None,
        metavar="N",
        help="random hands per k, 0..100000 (default 200, --quick 20); each runs "
        "with the paper and the normal model, next to the paper's hand scenes",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=1,
        metavar="S",
        help="seed of the random hands, >= 0 (default 1)",
    )
    p.add_argument(
        "--k", choices=("3", "4", "both"), default="both", help="contact counts (default both)"
    )
    p.add_argument(
        "--quick", action="store_true", help="fewer instances, repetitions and passes (a smoke run)"
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        default=None,
        help="also write the full report (every figure, every failure) as JSON",
    )
    p.add_argument(
        "--solvers",
        default="daqp,quadprog,osqp,scipy-slsqp",
        metavar="LIST",
        help="peer solvers, comma-separated (default: daqp,quadprog,osqp,scipy-slsqp)",
    )
    p.add_argument(
        "--max-passes",
        type=int,
        default=None,
        metavar="N",
        help="cap on the passes of a noisy series, >= 1 (default 8, --quick 4)",
    )

    def handler(args) -> int:
        from graspguide.bench import host_bench as bench

        return bench.main_args(args)

    p.set_defaults(handler=handler, command_parser=p)


class _StatusView:
    """Live status: a rich panel on a terminal, plain periodic lines otherwise."""

    def __init__(self, k: int, out: TextIO = None, period_s: float = 1.0):
        self.out = out or sys.stdout
        self.k = k
        self.period_s = period_s
        self.next_t = 0.0
        self.live = None
        self.last_draw = 0.0
        if self.out.isatty():
            try:
                from rich.live import Live

                self.live = Live(self._render({}), refresh_per_second=10, transient=False)
                self.live.start()
            except ImportError:  # pragma: no cover - rich is a dependency
                self.live = None

    def _render(self, s):
        from rich.table import Table

        table = Table(title="graspguide stream", show_header=False, expand=False)
        table.add_row("time", f"{s.get('t_s', 0.0):7.2f} s")
        table.add_row("error", f"{s.get('error_deg', float('nan')):7.2f} deg")
        for i, pwm in enumerate(s.get("pwm", [0] * self.k)[: self.k]):
            bar = "#" * (pwm * 30 // 255)
            table.add_row(f"motor {i + 1}", f"{pwm:3d} [green]{bar:<30}[/green]")
        table.add_row("rate", f"{s.get('rate_hz', 0.0):7.1f} poses/s")
        table.add_row("sent / telemetry", f"{s.get('sent', 0)} / {s.get('received', 0)}")
        table.add_row("dropped", str(s.get("dropped", 0)))
        return table

    def update(self, s, force: bool = False) -> None:
        if self.live is not None:
            now = time.monotonic()
            if force or now - self.last_draw >= 0.1:
                self.live.update(self._render(s))
                self.last_draw = now
            return
        if force or s["t_s"] >= self.next_t:
            self.next_t = s["t_s"] + self.period_s
            pwm = " ".join(f"{p:3d}" for p in s["pwm"][: self.k])
            print(
                f"t={s['t_s']:7.2f}s error={s['error_deg']:7.2f}deg pwm=[{pwm}] "
                f"rate={s['rate_hz']:.1f}/s sent={s['sent']} dropped={s['dropped']}",
                file=self.out,
                flush=True,
            )

    def close(self) -> None:
        if self.live is not None:
            self.live.stop()
            self.live = None


def run_stream(
    client,
    scene,
    wrench,
    source,
    trial_id: int = 1,
    virtual_clock: bool = False,
    log=None,
    view=None,
) -> dict[str, Any]:
    """One trial on ``client`` (after HELLO): SET_SCENE, START_TRIAL, the source's poses
    (paced in real time unless ``virtual_clock``), until TRIAL_RESULT or the end of the
    source. Returns a summary dict; raises LinkError. STOP is the caller's job."""
    from graspguide.link.client import DeviceError, LinkTimeout, host_time_us
    from graspguide.link.messages import TELEMETRY_FLAG_TRIAL_RUNNING, ErrorCode

    client.set_scene(**scene.set_scene_kwargs())
    client.start_trial(trial_id, wrench)
    client.trial_results.clear()
    period = 1.0 / source.rate_hz if source.rate_hz else 0.0
    sent = received = dropped = 0
    last_tel = None
    result = None
    ended = False
    t_wall0 = time.monotonic()
    status = {
        "t_s": 0.0,
        "error_deg": float("nan"),
        "pwm": [0] * 4,
        "rate_hz": 0.0,
        "sent": 0,
        "received": 0,
        "dropped": 0,
    }
    for t_s, quat, contacts in source:
        if not virtual_clock:
            wait = t_wall0 + t_s - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            elif period and -wait > 2 * period:
                dropped += 1  # too late for this sample: skip it, keep the pace
                continue
            t_us = host_time_us()
        else:
            t_us = int(round(t_s * 1e6)) & 0xFFFFFFFF
        if log is not None:
            log.pose(t_us, t_s, quat, contacts is not None)
        try:
            tel = client.pose(t_us, quat, contacts)
        except DeviceError as e:
            client.drain(0.05)
            if e.code == ErrorCode.NOT_ALLOWED_IN_STATE and client.trial_results:
                sent += 1
                break
            raise
        sent += 1
        received += 1
        last_tel = tel
        if log is not None:
            log.telemetry(tel)
        if not client.trial_results and not int(tel.flags) & TELEMETRY_FLAG_TRIAL_RUNNING:
            # this pose ended the trial: its TRIAL_RESULT follows the TELEMETRY
            try:
                client.trial_results.appendleft(client.wait_trial_result(client.timeout))
            except LinkTimeout:
                pass
            ended = True
        elapsed = max(time.monotonic() - t_wall0, 1e-9)
        status.update(
            t_s=t_s,
            error_deg=tel.error_deg,
            pwm=list(tel.pwm),
            rate_hz=sent / elapsed,
            sent=sent,
            received=received,
            dropped=dropped + client.device_frames_lost + client.host_bad_frames,
        )
        if view is not None:
            view.update(status)
        if client.trial_results or ended:
            break
    if not client.trial_results:
        client.drain(0.05)
    if client.trial_results:
        result = client.trial_results.popleft()
        if log is not None:
            log.result(result)
    if view is not None:
        view.update(status, force=True)
    elapsed = time.monotonic() - t_wall0
    return {
        "trial_result": result,
        "sent": sent,
        "received": received,
        "dropped": status["dropped"] if sent else dropped,
        "late_skipped": dropped,
        "elapsed_s": elapsed,
        "last_error_deg": None if last_tel is None else last_tel.error_deg,
    }


@signals_interrupt()  # SIGTERM and SIGHUP end the trial like Ctrl-C: STOP, end record
def _cmd_stream(args) -> int:
    from graspguide.link.transport import SIM_PORT as _SIM
    from graspguide.link.transport import open_port
    from graspguide.study.records import SessionLog
    from graspguide.study.scene_file import (
        SceneError,
        config_hash,
        load_scene,
        moment_unit_problem,
    )
    from graspguide.study.sources import SourceError, SyntheticSource, open_source

    parser = args.command_parser
    if args.virtual_clock and args.port != _SIM:
        parser.error("--virtual-clock is for --port sim (a board's clock is its own)")
    if not 0 <= args.trial_id <= 0xFFFF:
        parser.error(f"--trial-id must be in 0..65535, got {args.trial_id}")
    try:
        scene = load_scene(args.scene)
        problem = moment_unit_problem(scene.contacts, args.wrench)
        if problem:
            raise SceneError(f"--wrench with {args.scene}: {problem}")
        source = open_source(args.source, tracker=args.tracker)
        if isinstance(source, SyntheticSource):
            source.aim(scene.contacts, args.wrench, scene.policy, scene.constraints, scene.y_axis)
    except (SceneError, SourceError) as e:
        print(f"graspguide stream: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    kwargs = {"virtual_clock": True} if args.virtual_clock else {}
    try:
        transport = open_port(args.port, baudrate=args.baud, **kwargs)
    except LinkError as e:
        return _fail("stream", e)
    from graspguide.link.client import DeviceClient

    client = DeviceClient(transport, timeout=args.timeout)
    log = view = None
    code = EXIT_OK
    summary = None
    stop_acked = False
    log_failed = False
    try:
        hello = client.hello()
        config = {"scene": scene.to_dict(), "wrench": args.wrench}
        config["config_hash"] = config_hash(config)
        config.update(
            source=source.describe(),
            source_spec=args.source,
            port=args.port,
            trial_id=args.trial_id,
            virtual_clock=args.virtual_clock,
            scene_file=args.scene,
        )
        if args.log:
            log = SessionLog(args.log)
            log.scene(scene.to_dict())
            log.device(hello)
            log.config(config)
        view = _StatusView(scene.k)
        summary = run_stream(
            client, scene, args.wrench, source, args.trial_id, args.virtual_clock, log, view
        )
    except (LinkError, OSError) as e:  # OSError: the session log's disk (RecordWriteError)
        code = EXIT_FAILURE
        print(f"graspguide stream: error: {e}", file=sys.stderr)
        log_failed = isinstance(e, OSError) and not isinstance(e, LinkError)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        print("graspguide stream: interrupted", file=sys.stderr)
    finally:
        if view is not None:
            view.close()
        try:
            client.stop()
            stop_acked = True
        except LinkError as e:
            print(f"graspguide stream: STOP failed: {e}", file=sys.stderr)
            code = code or EXIT_FAILURE
        except KeyboardInterrupt:
            pass
        transport.close()
        if log is not None:
            end = {"event": "end", "exit_code": code, "stop_acknowledged": stop_acked}
            if summary is not None:
                end.update({k: v for k, v in summary.items() if k != "trial_result"})
            try:
                log.result(end)
                log.close()
            except OSError as e:  # the records before stay whole (session_log)
                if not log_failed:
                    print(f"graspguide stream: error: {e}", file=sys.stderr)
                code = code or EXIT_FAILURE
    if summary is not None:
        r = summary["trial_result"]
        if r is None:
            print(
                f"no trial result: the source ended first ({summary['sent']} poses sent, "
                f"last error {summary['last_error_deg']})"
            )
        else:
            print(
                f"trial {r.trial_id}: {'success' if r.success else 'failure'} "
                f"completion_s={r.completion_s:.3f} first_entry_s={r.first_entry_s:.3f} "
                f"final_error_deg={r.final_error_deg:.3f} ({summary['sent']} poses, "
                f"{summary['dropped']} dropped)"
            )
    return code


# --------------------------------------------------------------------------------------
# graspguide trial (the study runner, graspguide.study.runner)
# --------------------------------------------------------------------------------------
TRIAL_DESCRIPTION = """\
Run one participant's trials of a study protocol (docs/study.md) on a device: the plan
(familiarization, then one session per contact count x modality, in the participant's
counterbalanced order) is derived from --protocol and --participant; each trial is
SET_SCENE (when the condition changes), START_TRIAL, poses streamed from --source until
the TRIAL_RESULT. Progress: trial n of N, the condition and the live error (plain lines
when stdout is not a terminal). After each session the six NASA-TLX scales (MD, TD, PD,
PE, EF, FR; integers 1-21) are asked on stdin, or read from --tlx, or -- for a simulated
source without --tlx -- recorded as absent (null), never invented.

Writes OUT/study.json, OUT/PID/trials.jsonl (one fsync'ed line per completed trial),
OUT/PID/tlx.jsonl, OUT/PID/frames/trial-NNNN.csv, OUT/PID/plan.json, OUT/PID/runs.jsonl.
Run the same command again after a crash or Ctrl-C: completed trials are skipped, none
is lost or repeated. STOP is sent on every way out.

sources: participant[:PARAMS] (the virtual participant, closed loop), synthetic[:...] and
         replay:FILE.csv (open loop; the last pose is held until the device ends the
         trial), plugin:MODULE:CLASS[:ARG] (a sources.TrackerAdapter -- a live tracker, a
         person -- or a closed-loop class with begin_trial/step).
With --port sim the simulated device runs on its virtual clock for simulated sources (a
90 s trial takes about a second).

--tlx FILE: JSON Lines, one object per session, e.g.
  {"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": 3}
  (optional "participant", "modality", "k" are checked against the plan)."""

TRIAL_EPILOG = """\
examples:
  graspguide trial --protocol protocols/paper.toml --participant U1 --port sim \\
      --source participant --out runs/pilot
  graspguide trial --protocol protocols/paper.toml --participant U3 --port /dev/ttyACM0 \\
      --source plugin:my_lab.vicon:ViconHand --out runs/study --tlx u3_tlx.jsonl

exit status: 0 when every trial and questionnaire is done, 1 on a link or run error, 2 on
a usage error (bad protocol, participant, source or TLX file), 130 on Ctrl-C (run the
same command again to resume)."""


def _add_trial_parser(sub) -> None:
    p = sub.add_parser(
        "trial",
        help="run a participant's trials of a study protocol "
        "(resumable; NASA-TLX after each session)",
        description=TRIAL_DESCRIPTION,
        epilog=TRIAL_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--protocol",
        required=True,
        metavar="FILE",
        help="study protocol (protocols/paper.toml; format in docs/study.md)",
    )
    p.add_argument(
        "--participant",
        required=True,
        metavar="PID",
        help="participant id ending in a number (U1, U2, ...): picks the counterbalanced order",
    )
    _add_port_arguments(p, required=True)
    p.add_argument(
        "--source",
        required=True,
        metavar="SOURCE",
        help="participant[:PARAMS], synthetic[:...], replay:FILE.csv or plugin:MODULE:CLASS[:ARG]",
    )
    p.add_argument(
        "--out",
        default="study",
        metavar="DIR",
        help="study folder (default ./study); the participant's files go to DIR/PID/",
    )
    p.add_argument(
        "--tlx",
        metavar="FILE",
        default=None,
        help="NASA-TLX answers, JSON Lines, one object per session (see above)",
    )
    p.set_defaults(handler=_cmd_trial, command_parser=p)


@signals_interrupt()  # SIGTERM and SIGHUP end the run like Ctrl-C: STOP; trials are kept
def _cmd_trial(args) -> int:
    from graspguide.link.transport import SIM_PORT as _SIM
    from graspguide.link.transport import open_port
    from graspguide.study.runner import (
        Progress,
        RunnerError,
        StudyRunner,
        load_tlx_file,
        open_runner_source,
        summary_lines,
    )
    from graspguide.study.study_protocol import (
        ProtocolFileError,
        load_protocol,
        participant_number,
    )

    def usage(message: str) -> int:
        print(f"graspguide trial: error: {message}", file=sys.stderr)
        return EXIT_USAGE

    try:
        protocol = load_protocol(args.protocol)
        participant_number(args.participant)
        source = open_runner_source(args.source, protocol, args.participant)
        runner_tlx = None
        if args.tlx is not None:
            from graspguide.study.study_protocol import session_order

            runner_tlx = load_tlx_file(
                args.tlx, args.participant, session_order(protocol, args.participant)
            )
    except ProtocolFileError as e:
        return usage(str(e))
    except RunnerError as e:
        return usage(str(e))
    virtual_clock = args.port == _SIM and source.simulated and not source.live
    kwargs = {"virtual_clock": True} if virtual_clock else {}

    transport = None
    code = EXIT_OK
    runner = None
    try:
        try:
            transport = open_port(args.port, baudrate=args.baud, **kwargs)
        except LinkError as e:
            return _fail("trial", e)
        from graspguide.link.client import DeviceClient

        client = DeviceClient(transport, timeout=args.timeout)
        try:
            runner = StudyRunner(
                protocol,
                args.participant,
                args.out,
                source,
                client,
                virtual_clock,
                tlx=runner_tlx,
                progress=Progress(),
                protocol_file=args.protocol,
                port=args.port,
            )
            result = runner.run()
            print(
                f"{args.participant}: all {result['planned']} trials done ({result['ran']} "
                f"run now, {result['skipped']} from earlier runs); "
                f"{os.path.join(args.out, args.participant)}"
            )
            for line in summary_lines(args.out, args.participant):
                print(line)
        except ProtocolFileError as e:
            code = usage(str(e))
        except RunnerError as e:
            print(f"graspguide trial: error: {e}", file=sys.stderr)
            code = EXIT_USAGE if e.usage else EXIT_FAILURE
        except LinkError as e:
            print(f"graspguide trial: error: {e}", file=sys.stderr)
            code = EXIT_FAILURE
        except KeyboardInterrupt:
            code = EXIT_INTERRUPTED
            done = "" if runner is None else f" after {runner.ran} trials"
            print(
                f"\ngraspguide trial: interrupted{done}; completed trials are saved: run "
                "the same command again to resume",
                file=sys.stderr,
            )
        finally:
            try:
                client.stop()
            except (LinkError, OSError) as e:
                print(f"graspguide trial: STOP failed: {e}", file=sys.stderr)
                code = code or EXIT_FAILURE
            except KeyboardInterrupt:
                pass
    finally:
        if transport is not None:
            transport.close()
    return code


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help(sys.stderr)
            return EXIT_USAGE
        return args.handler(args)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
