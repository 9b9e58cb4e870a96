"""`graspguide solve` as a library: JSON Lines requests in, one JSON line per request out,
in order, flushed after each (so it can be driven through a pipe one request at a time).

A request is checked here (:func:`graspguide.core.solver.parse_request`, its units by
:mod:`graspguide.core.units`) and answered by the C++ core, or by an engine (a device:
:class:`graspguide.link.device_solver.DeviceEngine`). The request and answer formats are
the command's help (graspguide.cli.solve)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from itertools import chain
from typing import Any, BinaryIO, Protocol, TextIO

from graspguide.core import solver
from graspguide.core.solver import RequestError
from graspguide.core.units import hand_span, hand_span_problem, moment_unit_problem

# A request is a few hundred bytes; a longer line is answered with bad_json without
# being parsed (the rest of it is read and dropped, so the stream goes on).
MAX_LINE_BYTES = 1 << 20

_BOM = b"\xef\xbb\xbf"


class Engine(Protocol):
    """Who answers instead of the core: ``answer(solve arguments) -> answer dict``;
    ``errors``: the exceptions that mean it cannot answer any more (the request gets an
    error line, then the exception goes on to the caller)."""

    errors: tuple[type[BaseException], ...]

    def answer(self, kw: dict[str, Any]) -> dict[str, Any]: ...


class _LineTooLong:
    def __init__(self, size: int):
        self.size = size


def read_lines(stream: BinaryIO, limit: int = MAX_LINE_BYTES) -> Iterator[bytes | _LineTooLong]:
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
    out = dict(pairs)
    if len(out) == len(pairs):
        return out
    seen: set[str] = set()
    for key, _ in pairs:  # the first key given again, as a reader scanning the line meets it
        if key in seen:
            raise _DuplicateField(key)
        seen.add(key)
    raise AssertionError("unreachable: a shorter dict has a repeated key")


# One decoder for every line (json.loads would build one per call).
_DECODER = json.JSONDecoder(parse_int=_parse_int, object_pairs_hook=_no_duplicates)


def _decode(line: bytes, number: int):
    """The JSON value of one line, or raise RequestError."""
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError as e:
        raise RequestError(
            "bad_json",
            f"line {number} is not valid UTF-8 (byte 0x{line[e.start]:02x} at "
            f"byte offset {e.start}); send UTF-8 encoded JSON",
        ) from None
    try:
        if text.startswith("\ufeff"):  # json.loads refuses it so; the decoder alone would not
            raise json.JSONDecodeError("Unexpected UTF-8 BOM (decode using utf-8-sig)", text, 0)
        return _DECODER.decode(text)
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


def finite_or_none(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _finite_list(xs: list[Any]) -> list[Any]:
    if all(map(math.isfinite, xs)):  # always, for an ok answer: a copy is all it takes
        return list(xs)
    return [finite_or_none(v) for v in xs]


def success_answer(res: dict[str, Any]) -> dict[str, Any]:
    return {
        "ok": True,
        "pwm": list(res["pwm"]),
        "levels": _finite_list(res["levels"]),
        "lambda": _finite_list(res["lambda"]),
        "constraints_used": res["constraints_used"],
        "relevant": list(res["relevant"]),
        "error_deg": finite_or_none(res["error_deg"]),
        "iterations": res["iterations"],
        "alpha": finite_or_none(res["alpha"]),
        "fallback_mask": res["fallback_mask"],
    }


def error_answer(code: str, message: str) -> dict[str, Any]:
    return {"ok": False, "error": code, "message": message}


class Answerer:
    """The response to each input line, with the solve options checked once for all of
    them. With ``engine`` (a device) the engine answers instead of the core."""

    def __init__(
        self,
        scalar: str = "double",
        decomposition: str | None = None,
        max_iterations: int | None = None,
        engine: Engine | None = None,
    ):
        self.engine = engine
        self.options: tuple[str, str, int] | None = None
        self.options_error: Exception | None = None
        try:
            self.options = solver.check_options(
                scalar,
                solver.DEFAULT_DECOMPOSITION if decomposition is None else decomposition,
                solver.DEFAULT_MAX_ITERATIONS if max_iterations is None else max_iterations,
            )
        except (TypeError, ValueError) as e:
            # A caller's bad option (the command's parser never lets one through): every
            # request that reaches the core is answered internal_error with it.
            self.options_error = e

    def __call__(self, line: bytes | _LineTooLong, number: int) -> dict[str, Any] | None:
        """The response to one input line, or None for a blank line."""
        if isinstance(line, _LineTooLong):
            return error_answer(
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
            obj, units = pop_units(obj)
            kwargs = in_metres(solver.parse_request(obj, _POPPED_FIELDS), units)
        except RequestError as e:
            message = e.message
            if not message.startswith("line "):
                message = f"line {number}: {message}"
            return error_answer(e.code, message)
        if self.engine is not None:
            return self.engine.answer(kwargs)
        try:
            if self.options is None:
                raise self.options_error  # type: ignore[misc]
            res = solver.solve_checked(kwargs, *self.options)
        except Exception as e:  # never expected: the request was checked above
            return error_answer(
                "internal_error",
                f"line {number}: unexpected {type(e).__name__}: {e}; please report this request",
            )
        if res["status"] != "ok":
            return error_answer(res["status"], solver.status_message(res["status"]))
        return success_answer(res)


REQUEST_UNITS = ("m", "mm", "any")
# The fields taken out of a request before solver.parse_request checks the rest.
_POPPED_FIELDS = ("units",)


def pop_units(obj: Any) -> tuple[Any, str]:
    """The request without its "units" field, and that field ("m" by default)."""
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


def in_metres(kw: dict[str, Any], units: str) -> dict[str, Any]:
    """The request's solve() arguments with contacts in metres and moments in N m; a hand
    that does not span like one in the stated unit, or a moment in another length unit
    than the contacts, is a bad_request naming the likely unit. Requests the core would
    refuse anyway (a contact count other than 3 or 4, a non-finite number, all contacts
    at one point) go on to the core's own answer; "units": "any" skips the checks (the
    core uses only ratios: synthetic geometry such as its scale tests)."""
    contacts, wrench = kw["contacts"], kw["wrench"]
    if (
        units == "any"
        or len(contacts) not in (3, 4)
        or not all(map(math.isfinite, chain(*contacts, wrench)))
    ):
        return kw
    span = hand_span(contacts)
    if span > 0.0:
        problem = hand_span_problem(contacts, units, _solve_unit_fix, span)
        if problem:
            raise RequestError("bad_request", problem)
    if units == "mm":
        contacts = [[v / 1000.0 for v in c] for c in contacts]
        wrench = list(wrench[:3]) + [v / 1000.0 for v in wrench[3:]]
        kw = {**kw, "contacts": contacts, "wrench": wrench}
        span = hand_span(contacts)  # of the metres, as rounded
    problem = moment_unit_problem(contacts, wrench, span)
    if problem:
        raise RequestError("bad_request", problem)
    return kw


# ASCII only, and strict JSON (no NaN): any consumer can read it. One encoder for every
# answer (json.dumps would build one per call).
_ENCODER = json.JSONEncoder(ensure_ascii=True, allow_nan=False, separators=(", ", ": "))


def dumps(obj: dict[str, Any]) -> str:
    return _ENCODER.encode(obj)


def run_solve(
    inp: BinaryIO,
    out: TextIO,
    scalar: str = "double",
    decomposition: str | None = None,
    max_iterations: int | None = None,
    engine: Engine | None = None,
) -> int:
    """Answer every line of ``inp`` on ``out``; returns the number of answers.
    ``decomposition`` and ``max_iterations`` default to the core's."""
    count = 0
    answer = Answerer(scalar, decomposition, max_iterations, engine)
    engine_errors = engine.errors if engine is not None else ()
    for number, line in enumerate(read_lines(inp), start=1):
        try:
            response = answer(line, number)
        except engine_errors as e:
            # The engine failed (a device's link): this request gets its error line,
            # every earlier answer is already out, and the command stops.
            out.write(dumps(error_answer("link_error", f"line {number}: {e}")) + "\n")
            out.flush()
            raise
        if response is None:
            continue
        out.write(dumps(response) + "\n")
        out.flush()
        count += 1
    return count
