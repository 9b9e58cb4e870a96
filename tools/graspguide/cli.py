"""The ``graspguide`` command line.

``graspguide solve`` reads JSON Lines (one request per line) and writes exactly one JSON
line per request, in order, flushed after each line, so it can be driven through a pipe
one request at a time. See ``graspguide solve --help``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Any, BinaryIO, Dict, Iterator, Optional, TextIO, Tuple, Union

from . import __version__

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

Exit status: 0 when the input ends (even if some requests were bad), 2 for a usage
error, 130 when interrupted (Ctrl-C; every answer so far is flushed), 1 when the
reader closes the output pipe.
"""

SOLVE_EPILOG = """\
examples:
  echo '{"contacts": [[0.045,0.045,0.035], [0.015,0.095,0.04], [-0.01,0.1,0.04]],
  "wrench": [0.3,-1.2,-0.8,0,0,0]}' | tr -d '\\n' | graspguide solve
  graspguide solve --scalar float --input tools/examples/solve_requests.jsonl
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
           decomposition: str = "qr", max_iterations: Optional[int] = None
           ) -> Optional[Dict[str, Any]]:
    """The response to one input line, or None for a blank line."""
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
              max_iterations: Optional[int] = None) -> int:
    """Answer every line of ``inp`` on ``out``; returns the number of answers."""
    count = 0
    for number, line in enumerate(_read_lines(inp), start=1):
        response = answer(line, number, scalar, decomposition, max_iterations)
        if response is None:
            continue
        out.write(_dumps(response) + "\n")
        out.flush()
        count += 1
    return count


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
    solve.add_argument("--scalar", choices=("double", "float"), default="double",
                       help="precision of the core: double (default, the host) or float "
                            "(what a microcontroller with a single-precision FPU runs)")
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
    solve.set_defaults(handler=_cmd_solve, command_parser=solve)
    return parser


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


def _cmd_solve(args) -> int:
    inp, out = _open_streams(args.command_parser, args)
    if args.input == "-" and sys.stdin.isatty() and sys.stderr.isatty():
        print("graspguide solve: reading JSON requests, one per line (Ctrl-D to end, "
              "--help for the format)", file=sys.stderr)
    try:
        run_solve(inp, out, args.scalar, args.decomposition, args.max_iterations)
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
