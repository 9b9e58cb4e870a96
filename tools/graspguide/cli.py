"""The ``graspguide`` command line.

``graspguide solve`` reads JSON Lines (one request per line) and writes exactly one JSON
line per request, in order, flushed after each line, so it can be driven through a pipe
one request at a time; with ``--engine device --port PORT|sim`` a device answers instead
of the core. ``graspguide ports`` lists serial ports (and ``sim``), ``graspguide info``
identifies a device. See ``graspguide COMMAND --help``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Any, BinaryIO, Dict, Iterator, Optional, TextIO, Tuple, Union

from . import __version__
from .transport import DEFAULT_BAUDRATE, SIM_PORT, LinkError

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
                         (, palm); any length unit, only differences matter
  wrench       required  [fx, fy, fz, mx, my, mz] in the object frame (moment about
                         the contacts' centroid, force x the contacts' length unit)
  policy       "F" (default) | "Fperp"
  mode         "C" (default) | "V"
  constraints  "paper" (default) | "normal" | "none"
  orientation  [w, x, y, z] hand -> world; default [1, 0, 0, 0] (identity)
  y_axis       the object axis y_O in the hand frame; default [0, 1, 0]
Numbers may also be the JSON extensions NaN, Infinity and -Infinity, and a number
beyond the double range (1e400) is infinite: they reach the core, which answers
non_finite_input. Booleans and strings are never numbers. A contact count other
than 3 or 4 is the core's bad_contact_count.

Success:
  {"ok": true, "pwm": [k ints 0..255], "levels": [k], "lambda": [3k],
   "constraints_used": "paper"|"normal"|"none", "relevant": [k bools],
   "error_deg": float, "iterations": int, "alpha": float, "fallback_mask": int}
Error:
  {"ok": false, "error": CODE, "message": "what is wrong and how to fix it"}
  CODE: "bad_json"     the line is not a JSON object (or not UTF-8, or too long)
        "bad_request"  a missing or unknown field, a wrong type or length, an
                       unknown policy/mode/constraints name
        otherwise the core's status, e.g. "non_finite_input", "bad_contact_count",
        "coincident_contacts", "rank_deficient", "zero_force", "bad_quaternion"

With --engine device --port PORT|sim a device answers instead (the firmware's float
and QR route): per request SET_SCENE, START_TRIAL, one POSE, its TELEMETRY, STOP.
Its answers have the keys the wire carries: ok, pwm, constraints_used, error_deg,
iterations, alpha (levels, lambda, relevant and fallback_mask are not on the wire).
Bad requests get the same codes and messages; compare with --scalar float.

Exit status: 0 when the input ends (even if some requests were bad), 2 for a usage
error, 130 when interrupted (Ctrl-C; every answer so far is flushed), 1 when the
reader closes the output pipe, or when the link to the device fails (that request
is answered with error "link_error" and the reason goes to stderr).
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


def _read_lines(stream: BinaryIO, limit: int = MAX_LINE_BYTES
                ) -> Iterator[Union[bytes, _LineTooLong]]:
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


def _parse_int(text: str) -> Union[int, float]:
    try:
        return int(text)
    except ValueError:  # beyond Python's int-string digit limit: a float (inf)
        return float(text)


class _DuplicateField(ValueError):
    pass


def _no_duplicates(pairs):
    out: Dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateField(key)
        out[key] = value
    return out


def _decode(line: bytes, number: int):
    """The JSON value of one line, or raise RequestError."""
    from .solver import RequestError

    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError as e:
        raise RequestError("bad_json",
                           f"line {number} is not valid UTF-8 (byte 0x{line[e.start]:02x} at "
                           f"byte offset {e.start}); send UTF-8 encoded JSON") from None
    try:
        return json.loads(text, parse_int=_parse_int, object_pairs_hook=_no_duplicates)
    except _DuplicateField as e:
        raise RequestError("bad_request",
                           f"line {number}: field {json.dumps(str(e))} is given more than "
                           "once; give each field once") from None
    except json.JSONDecodeError as e:
        hint = ""
        if e.msg == "Extra data":
            hint = " (exactly one JSON object per line)"
        elif text.lstrip().startswith("{") and "'" in text and '"' not in text:
            hint = " (JSON strings use double quotes)"
        raise RequestError("bad_json",
                           f"line {number} is not valid JSON: {e.msg} at column {e.colno}"
                           f"{hint}") from None
    except RecursionError:
        raise RequestError("bad_json",
                           f"line {number}: JSON nested too deeply; a request is a flat "
                           "object of arrays") from None
    except ValueError as e:  # e.g. a number the float parser cannot handle
        raise RequestError("bad_json", f"line {number} is not valid JSON: {e}") from None


# --------------------------------------------------------------------------------------
# Answering
# --------------------------------------------------------------------------------------
def _finite_or_none(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _success(res: Dict[str, Any]) -> Dict[str, Any]:
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


def _error(code: str, message: str) -> Dict[str, Any]:
    return {"ok": False, "error": code, "message": message}


def answer(line: Union[bytes, _LineTooLong], number: int, scalar: str = "double",
           decomposition: str = "qr", max_iterations: Optional[int] = None,
           engine: Optional["DeviceEngine"] = None) -> Optional[Dict[str, Any]]:
    """The response to one input line, or None for a blank line. With ``engine`` (a
    :class:`DeviceEngine`) the device answers instead of the core."""
    from . import solver

    if isinstance(line, _LineTooLong):
        return _error("bad_json",
                      f"line {number} is {line.size} bytes long, over the limit of "
                      f"{MAX_LINE_BYTES}; a request is one short JSON object per line")
    if number == 1 and line.startswith(_BOM):
        line = line[len(_BOM):]
    if not line.strip():
        return None
    try:
        kwargs = solver.parse_request(_decode(line, number))
    except solver.RequestError as e:
        message = e.message
        if not message.startswith("line "):
            message = f"line {number}: {message}"
        return _error(e.code, message)
    if engine is not None:
        return engine.answer(kwargs)
    try:
        res = solver.solve(scalar=scalar, decomposition=decomposition,
                           max_iterations=(solver.DEFAULT_MAX_ITERATIONS
                                           if max_iterations is None else max_iterations),
                           **kwargs)
    except Exception as e:  # never expected: the request was checked above
        return _error("internal_error",
                      f"line {number}: unexpected {type(e).__name__}: {e}; please report "
                      "this request")
    if res["status"] != "ok":
        return _error(res["status"], solver.status_message(res["status"]))
    return _success(res)


def _dumps(obj: Dict[str, Any]) -> str:
    # ASCII only, and strict JSON (no NaN): any consumer can read it.
    return json.dumps(obj, ensure_ascii=True, allow_nan=False, separators=(", ", ": "))


def run_solve(inp: BinaryIO, out: TextIO, scalar: str = "double", decomposition: str = "qr",
              max_iterations: Optional[int] = None,
              engine: Optional["DeviceEngine"] = None) -> int:
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

    def answer(self, kw: Dict[str, Any]) -> Dict[str, Any]:
        from . import solver
        from .device import DeviceError

        client = self.client
        self._trial_id = (self._trial_id + 1) & 0xFFFF
        k = len(kw["contacts"])
        try:
            try:
                client.set_scene(kw["contacts"], y_axis=kw["y_axis"],
                                 constraints=kw["constraints"], policy=kw["policy"],
                                 mode=kw["mode"])
                client.start_trial(self._trial_id, kw["wrench"])
                tel = client.pose(quat=kw["orientation"])
            finally:
                client.stop()
        except DeviceError as e:
            return self._device_error(e, solver)
        status = int(tel.solver_status)
        if status != 0:
            return self._device_error(DeviceError("POSE", None, status, 0, source="TELEMETRY"),
                                      solver)
        return {
            "ok": True,
            "pwm": [int(p) for p in tel.pwm[:k]],
            "constraints_used": tel.constraints_used.name.lower(),
            "error_deg": _finite_or_none(float(tel.error_deg)),
            "iterations": int(tel.iterations),
            "alpha": _finite_or_none(float(tel.alpha)),
        }

    @staticmethod
    def _device_error(e, solver) -> Dict[str, Any]:
        if e.code_name in solver.STATUS_NAMES:  # a core status: the core's message
            return _error(e.code_name, solver.status_message(e.code_name))
        return _error(e.code_name, str(e))


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------
def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 1 <= value <= 1_000_000:
        raise argparse.ArgumentTypeError(f"must be between 1 and 1000000, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="graspguide",
        description="GraspGuide host tools: hand guidance by a grasping metaphor "
                    "(Algorithm 1 from the C++ core in lib/graspguide).",
        epilog="Run 'graspguide COMMAND --help' for a command's options.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    solve = sub.add_parser(
        "solve", help="answer JSON Lines requests (contacts, wrench -> PWM) with the C++ core",
        description=SOLVE_DESCRIPTION, epilog=SOLVE_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    solve.add_argument("--scalar", choices=("double", "float"), default=None,
                       help="precision of the core: double (default, the host) or float "
                            "(what a microcontroller with a single-precision FPU runs; "
                            "compare --engine device with this)")
    solve.add_argument("--decomposition", choices=("qr", "svd"), default="qr",
                       help="equilibrium route: column-pivoting QR (default, the firmware's) "
                            "or Jacobi SVD (reference route)")
    solve.add_argument("--max-iterations", type=_positive_int, default=None, metavar="N",
                       help="cap on the QP's active-set changes (default: the core's "
                            "kDefaultMaxIterations, 64); hitting it is the error "
                            "qp_iteration_limit")
    solve.add_argument("--input", "-i", metavar="FILE", default="-",
                       help="read requests from FILE instead of stdin ('-': stdin)")
    solve.add_argument("--output", "-o", metavar="FILE", default="-",
                       help="write responses to FILE instead of stdout ('-': stdout)")
    solve.add_argument("--engine", choices=("core", "device"), default="core",
                       help="who answers: core (default, the C++ core in this process) or "
                            "device (the board or simulated device on --port: SET_SCENE, "
                            "START_TRIAL, one POSE, TELEMETRY, STOP per request; answers "
                            "carry ok, pwm, constraints_used, error_deg, iterations, alpha)")
    _add_port_arguments(solve, required=False)
    solve.set_defaults(handler=_cmd_solve, command_parser=solve)

    ports = sub.add_parser(
        "ports", help="list serial ports (and the simulated device 'sim')",
        description="List the serial ports pyserial finds, plus the pseudo-port 'sim' (the "
                    "simulated device, started on demand by --port sim).")
    ports.add_argument("--json", action="store_true", help="one JSON object per line")
    ports.set_defaults(handler=_cmd_ports, command_parser=ports)

    info = sub.add_parser(
        "info", help="identify a device: HELLO_REPLY and STATUS",
        description="Ask a device who it is (HELLO -> HELLO_REPLY: protocol and firmware "
                    "version, board, scalar, contacts, build id) and how it is (GET_STATUS "
                    "-> STATUS: state, frames received, bad frames, stale events, last "
                    "error).",
        epilog="examples:\n  graspguide info --port sim\n"
               "  graspguide info --port /dev/ttyACM0 --json",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_port_arguments(info, required=True)
    info.add_argument("--json", action="store_true", help="print one JSON object")
    info.set_defaults(handler=_cmd_info, command_parser=info)
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
    p.add_argument("--port", "-p", metavar="PORT", required=required,
                   help="serial port of the device (e.g. /dev/ttyACM0, COM3; "
                        "`graspguide ports` lists them), or 'sim' to start the simulated "
                        "device (.pio/build/sim/program, or $GRASPGUIDE_SIM)")
    p.add_argument("--baud", type=_positive_int, default=DEFAULT_BAUDRATE, metavar="RATE",
                   help=f"baud rate (default {DEFAULT_BAUDRATE})")
    p.add_argument("--timeout", type=_positive_float, default=1.0, metavar="S",
                   help="seconds to wait for each answer of the device (default 1)")


def _connect(args):
    """(transport, client) for --port, or raise LinkError."""
    from .device import DeviceClient
    from .transport import open_port

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
    from .transport import LinkError as _LinkError, find_sim_binary, list_serial_ports

    try:
        ports = list_serial_ports()
    except _LinkError as e:
        return _fail("ports", e)
    try:
        sim = {"device": SIM_PORT, "description": "simulated device",
               "hwid": find_sim_binary()}
    except _LinkError as e:
        sim = {"device": SIM_PORT, "description": "simulated device (not available)",
               "hwid": str(e).replace("\n", " ")}
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
    from .protocol.messages import PROTOCOL_VERSION

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


def _open_streams(parser: argparse.ArgumentParser, args) -> Tuple[BinaryIO, TextIO]:
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
            parser.error("--port is for --engine device (the core engine runs in this "
                         "process); add --engine device")
        return
    if args.port is None:
        parser.error("--engine device needs --port PORT (see `graspguide ports`) or "
                     "--port sim")
    if args.scalar == "double":
        parser.error("--engine device computes in the firmware's float; drop --scalar "
                     "double (compare with --engine core --scalar float)")
    if args.decomposition != "qr":
        parser.error("--engine device uses the firmware's QR route; drop --decomposition")
    if args.max_iterations is not None:
        parser.error("--engine device uses the firmware's QP iteration cap; drop "
                     "--max-iterations")


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
        print("graspguide solve: reading JSON requests, one per line (Ctrl-D to end, "
              "--help for the format)", file=sys.stderr)
    try:
        run_solve(inp, out, args.scalar or "double", args.decomposition, args.max_iterations,
                  engine)
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
