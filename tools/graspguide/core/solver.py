"""Algorithm 1 from the C++ core, with the validation of Python inputs.

:func:`solve` runs one scene through ``graspguide::Guidance<T>`` (T = double or float);
:class:`Guidance` is the stateful double-precision object the firmware uses frame by
frame. Both return the result dict documented in :func:`solve`.

Types are checked here, in Python (a bool is not a number, a string is not a list,
policy/mode/constraint names are exact); values are not: NaN, infinities and
out-of-range numbers go to the core, which answers with a status such as
``non_finite_input``. :func:`parse_request` does the same for one JSON request of the
command line and raises :class:`RequestError` with a machine-readable code.

Every check has a fast path for the plain types nearly every caller passes (a list or
tuple of float and int, a numpy float64 array, a str name): it only accepts, and sends
anything else to the thorough checks, which alone refuse and write the messages. So a
fast path never changes what is accepted or what an error says. :func:`solve` takes its
fast path in the binding (``_core.solve_plain``).
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping, Sequence
from typing import Any

from graspguide.core import _core
from graspguide.core.suggest import unknown_name
from graspguide.core.vocabulary import CONSTRAINT_MODELS, MODES, POLICIES

STATUS_NAMES: tuple[str, ...] = tuple(_core.STATUS_NAMES)
DECOMPOSITIONS: tuple[str, ...] = tuple(_core.DECOMPOSITIONS)
SCALARS: tuple[str, ...] = tuple(_core.SCALARS)
TOLERANCES: dict[str, dict[str, float]] = dict(_core.TOLERANCES)
PWM_SPAN: int = _core.kPwmSpan
MAX_CONTACTS: int = _core.kMaxContacts
DEFAULT_MAX_ITERATIONS: int = _core.kDefaultMaxIterations
# The binding lists its default route first.
DEFAULT_DECOMPOSITION: str = DECOMPOSITIONS[0]

DEFAULT_ORIENTATION = (1.0, 0.0, 0.0, 0.0)
DEFAULT_Y_AXIS = (0.0, 1.0, 0.0)

# Fields of one command-line request and their defaults (None: required).
REQUEST_FIELDS: dict[str, Any] = {
    "contacts": None,
    "wrench": None,
    "policy": "F",
    "mode": "C",
    "constraints": "paper",
    "orientation": list(DEFAULT_ORIENTATION),
    "y_axis": list(DEFAULT_Y_AXIS),
}

_FIELDS_KEYS = REQUEST_FIELDS.keys()
_REQUIRED = frozenset(key for key, default in REQUEST_FIELDS.items() if default is None)

# Cap on the contact count handed to the core (anything but 3 or 4 is
# bad_contact_count there); keeps a huge list from costing more than its parsing.
_MAX_FORWARDED_CONTACTS = 64


def status_message(status: str) -> str:
    """What a status means and how to fix it (``status_message`` of status.h)."""
    return _core.status_message(status)


class RequestError(ValueError):
    """An invalid request: ``code`` is ``"bad_json"`` or ``"bad_request"``."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


# --------------------------------------------------------------------------------------
# Type checks
# --------------------------------------------------------------------------------------
def _type_name(x: Any) -> str:
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "boolean"
    if isinstance(x, str):
        return "string"
    if isinstance(x, numbers.Number):
        return "number"
    if isinstance(x, Mapping):
        return "object"
    if isinstance(x, (list, tuple)):
        return "array"
    return type(x).__name__


def _show(x: Any, limit: int = 40) -> str:
    """A short, ASCII rendering of a (possibly huge) offending value."""
    try:
        if isinstance(x, (str, bool, int, float, list, dict)) or x is None:
            text = json.dumps(x, ensure_ascii=True, allow_nan=True)
        else:
            text = repr(x)
    except Exception:  # too deep, exotic objects
        text = f"<{type(x).__name__}>"
    text = text.encode("ascii", "backslashreplace").decode("ascii")
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _got(x: Any) -> str:
    """'got <type> <value>' for messages."""
    shown = _show(x)
    name = _type_name(x)
    return f"got {name}" if shown == name else f"got {name} {shown}"


def _is_number(x: Any) -> bool:
    if isinstance(x, bool) or type(x).__name__ == "bool_":  # bool / numpy.bool_
        return False
    return isinstance(x, numbers.Real)


def _to_float(x: Any) -> float:
    try:
        return float(x)
    except OverflowError:  # an int beyond the double range, like 1e400: infinite
        return math.inf if x > 0 else -math.inf


def _is_sequence(x: Any) -> bool:
    if isinstance(x, (str, bytes, bytearray, Mapping)):
        return False
    return isinstance(x, Sequence) or hasattr(x, "__array__")


_PLAIN_NUMBERS = frozenset((float, int))
_INT_MAX = 2**31 - 1


def _plain_numbers(x: Any, n: int) -> list[float] | None:
    """``x`` as n floats if it is a list or tuple of exactly n floats and ints (what JSON
    and most callers give), else None. Exact types: bool, a subclass of int, is not
    plain. The thorough path gives the same floats for such an ``x``."""
    if (type(x) is list or type(x) is tuple) and len(x) == n:
        types = set(map(type, x))
        if types <= _PLAIN_NUMBERS:
            if int not in types:
                return list(x)
            try:
                return list(map(float, x))
            except OverflowError:  # beyond the double range: the thorough path's inf
                return None
    return None


def _float64_array(x: Any) -> bool:
    """Is ``x`` a numpy float64 array (not a subclass)? numpy is not imported for it."""
    t = type(x)
    return t.__name__ == "ndarray" and t.__module__ == "numpy" and x.dtype.char == "d"


def _number_list(x: Any, n: int, field: str, what: str) -> list[float]:
    fast = _plain_numbers(x, n)
    if fast is not None:
        return fast
    if _float64_array(x) and x.shape == (n,):
        return x.tolist()
    if not _is_sequence(x):
        raise RequestError(
            "bad_request", f"{field} must be an array of {n} numbers ({what}), {_got(x)}"
        )
    try:
        items = list(x)
    except TypeError:
        raise RequestError(
            "bad_request", f"{field} must be an array of {n} numbers ({what}), {_got(x)}"
        ) from None
    if len(items) != n:
        raise RequestError(
            "bad_request", f"{field} must have exactly {n} numbers ({what}), got {len(items)}"
        )
    out = []
    for i, v in enumerate(items):
        if not _is_number(v):
            raise RequestError(
                "bad_request",
                f"{field}[{i}] must be a number, {_got(v)}"
                " (NaN and Infinity are accepted as numbers; booleans and "
                "strings are not)",
            )
        out.append(_to_float(v))
    return out


def _contacts(x: Any, field: str = "contacts") -> list[list[float]]:
    """A list of [x, y, z] triples. The count is not checked here: anything but 3 or 4
    goes to the core, which answers bad_contact_count."""
    if (type(x) is list or type(x) is tuple) and len(x) <= _MAX_FORWARDED_CONTACTS:
        rows = [_plain_numbers(row, 3) for row in x]
        if None not in rows:
            return rows  # type: ignore[return-value]
    elif _float64_array(x) and x.ndim == 2 and x.shape[1] == 3:
        if x.shape[0] <= _MAX_FORWARDED_CONTACTS:
            return x.tolist()
    if not _is_sequence(x):
        raise RequestError(
            "bad_request",
            f"{field} must be an array of 3 or 4 [x, y, z] triples "
            f"(thumb, index, middle, optional palm), {_got(x)}",
        )
    try:
        rows = list(x)
    except TypeError:
        raise RequestError(
            "bad_request", f"{field} must be an array of [x, y, z] triples, {_got(x)}"
        ) from None
    out = []
    for i, row in enumerate(rows):
        if not _is_sequence(row):
            raise RequestError(
                "bad_request", f"{field}[{i}] must be an [x, y, z] triple, {_got(row)}"
            )
        out.append(_number_list(row, 3, f"{field}[{i}]", "x, y, z of one contact"))
    # Only the count of any extra contacts matters to the core.
    del out[_MAX_FORWARDED_CONTACTS:]
    return out


def _choice(x: Any, field: str, accepted: Sequence[str]) -> str:
    if type(x) is str and x in accepted:
        return x
    listed = ", ".join(f'"{a}"' for a in accepted)
    if not isinstance(x, str):
        raise RequestError("bad_request", f"{field} must be a string, one of {listed}; {_got(x)}")
    if x not in accepted:
        hint = ""
        close = [a for a in accepted if a.lower() == x.lower()]
        if close:
            hint = f' (names are case-sensitive: did you mean "{close[0]}"?)'
        raise RequestError("bad_request", f"unknown {field} {_show(x)}; accepted: {listed}{hint}")
    return x


def _option(x: Any, what: str, accepted: Sequence[str]) -> None:
    """A ValueError (not a RequestError: a caller's mistake) for an unknown option."""
    if x not in accepted:
        raise ValueError(f"unknown {what} {_show(x)}; accepted: {', '.join(accepted)}")


def _max_iterations(x: Any) -> int:
    if type(x) is not int and (isinstance(x, bool) or not isinstance(x, numbers.Integral)):
        raise TypeError(f"max_iterations must be an int, {_got(x)}")
    # The core answers bad_config below 1; the binding takes a C int.
    return int(max(-1, min(int(x), _INT_MAX)))


def _check_kwargs(
    contacts, wrench, policy, mode, constraints, orientation, y_axis
) -> dict[str, Any]:
    plain = _core.plain_numbers(contacts, wrench, orientation, y_axis)
    if (
        plain is not None
        and type(policy) is str
        and policy in POLICIES
        and type(mode) is str
        and mode in MODES
        and type(constraints) is str
        and constraints in CONSTRAINT_MODELS
    ):
        c, w, q, y = plain
        return dict(
            contacts=c,
            wrench=w,
            policy=policy,
            mode=mode,
            constraints=constraints,
            orientation=q,
            y_axis=y,
        )
    return dict(
        contacts=_contacts(contacts),
        wrench=_number_list(wrench, 6, "wrench", "fx, fy, fz, mx, my, mz"),
        policy=_choice(policy, "policy", POLICIES),
        mode=_choice(mode, "mode", MODES),
        constraints=_choice(constraints, "constraints", CONSTRAINT_MODELS),
        orientation=_number_list(orientation, 4, "orientation", "quaternion w, x, y, z"),
        y_axis=_number_list(y_axis, 3, "y_axis", "x, y, z"),
    )


# --------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------
def solve(
    contacts,
    wrench,
    policy: str = "F",
    mode: str = "C",
    constraints: str = "paper",
    orientation=DEFAULT_ORIENTATION,
    y_axis=DEFAULT_Y_AXIS,
    scalar: str = "double",
    decomposition: str = DEFAULT_DECOMPOSITION,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> dict[str, Any]:
    """Run Algorithm 1 on one scene with ``graspguide::Guidance<double|float>``.

    contacts: 3 or 4 ``[x, y, z]`` in the hand frame (another count gives status
    ``bad_contact_count``); wrench: ``[fx, fy, fz, mx, my, mz]`` in the object frame;
    policy ``"F"``/``"Fperp"``; mode ``"C"``/``"V"``; constraints
    ``"paper"``/``"normal"``/``"none"``; orientation ``[w, x, y, z]`` hand -> world;
    y_axis: y_O in the hand frame; scalar ``"double"``/``"float"``; decomposition one of
    :data:`DECOMPOSITIONS` (default :data:`DEFAULT_DECOMPOSITION`).

    Returns a dict: ``status`` (``"ok"`` or a name from :data:`STATUS_NAMES`), ``pwm``
    (k ints, all 0 unless ok), ``levels`` (k), ``lambda`` (3k), ``constraints_used``,
    ``relevant`` (k bools), ``error_deg``, ``alpha``, ``fallback_mask``, ``iterations``,
    ``rank_ratio``, ``retried`` (a float solve that could not vouch for its answer ran
    again in double; docs/algorithm.md, step 5), ``recomputed``; levels, lambda,
    relevant, error_deg and alpha are None unless the status is ok.

    Raises :class:`RequestError` (a ValueError) for a wrong type, length or name, and
    ValueError for an unknown scalar or decomposition.
    """
    res = _core.solve_plain(
        contacts,
        wrench,
        policy,
        mode,
        constraints,
        orientation,
        y_axis,
        scalar,
        decomposition,
        max_iterations,
    )
    if res is not None:
        return res
    kw = _check_kwargs(contacts, wrench, policy, mode, constraints, orientation, y_axis)
    return solve_checked(kw, *check_options(scalar, decomposition, max_iterations))


def check_options(scalar: Any, decomposition: Any, max_iterations: Any) -> tuple[str, str, int]:
    """The options of :func:`solve` checked as it checks them, for :func:`solve_checked`:
    (scalar, decomposition, max_iterations clamped to what the binding takes)."""
    _option(scalar, "scalar", SCALARS)
    _option(decomposition, "decomposition", DECOMPOSITIONS)
    return scalar, decomposition, _max_iterations(max_iterations)


def solve_checked(
    kw: dict[str, Any], scalar: str, decomposition: str, max_iterations: int
) -> dict[str, Any]:
    """:func:`solve` on arguments already checked: ``kw`` from :func:`parse_request` (or
    changed only in its numbers), the options from :func:`check_options`. Nothing is
    checked again."""
    return _core.solve(
        kw["contacts"],
        kw["wrench"],
        kw["policy"],
        kw["mode"],
        kw["constraints"],
        kw["orientation"],
        kw["y_axis"],
        scalar,
        decomposition,
        max_iterations,
    )


class Guidance:
    """Stateful Algorithm 1 in double (``graspguide::Guidance<double>``).

    The grasp part (steps 1-6) is kept until the contacts (compared exactly), the wrench
    or the scene change; :meth:`update` with only a new orientation costs the error,
    alpha and the PWM mapping (its result has ``recomputed`` False). Setters return a
    status name: ``"ok"``, or the error, in which case nothing changed.
    """

    def __init__(self) -> None:
        self._g = _core.Guidance()

    @property
    def k(self) -> int:
        return self._g.k

    def set_scene(
        self,
        contacts,
        policy: str = "F",
        mode: str = "C",
        constraints: str = "paper",
        y_axis=DEFAULT_Y_AXIS,
        decomposition: str = DEFAULT_DECOMPOSITION,
        max_iterations: int = DEFAULT_MAX_ITERATIONS,
    ) -> str:
        _option(decomposition, "decomposition", DECOMPOSITIONS)
        return self._g.set_scene(
            _contacts(contacts),
            _choice(policy, "policy", POLICIES),
            _choice(mode, "mode", MODES),
            _choice(constraints, "constraints", CONSTRAINT_MODELS),
            _number_list(y_axis, 3, "y_axis", "x, y, z"),
            decomposition,
            _max_iterations(max_iterations),
        )

    def set_wrench(self, wrench) -> str:
        return self._g.set_wrench(_number_list(wrench, 6, "wrench", "fx, fy, fz, mx, my, mz"))

    def set_contacts(self, contacts) -> str:
        return self._g.set_contacts(_contacts(contacts))

    def update(self, orientation=DEFAULT_ORIENTATION) -> dict[str, Any]:
        return self._g.update(_number_list(orientation, 4, "orientation", "quaternion w, x, y, z"))


def _plain_fields(obj: Any) -> dict[str, Any] | None:
    """A request's fields, defaults filled in, if it is a dict with the required fields
    and no unknown one (the fast path of :func:`parse_request`); else None."""
    if type(obj) is dict and _FIELDS_KEYS >= obj.keys() >= _REQUIRED:
        return {**REQUEST_FIELDS, **obj}
    return None


def parse_request(obj: Any, also_accepted: Sequence[str] = ()) -> dict[str, Any]:
    """Check one decoded JSON request and return the keyword arguments of :func:`solve`
    (defaults filled in). Raises :class:`RequestError`. ``also_accepted``: the fields the
    caller takes out of the request before (such as "units"), so that the message for an
    unknown field lists every field a request may have and can suggest them too."""
    merged = _plain_fields(obj)
    if merged is not None:
        return _check_kwargs(**merged)
    if not isinstance(obj, Mapping):
        raise RequestError(
            "bad_json", f"a request must be a JSON object {{...}}, got {_type_name(obj)}"
        )
    unknown = [key for key in obj if key not in REQUEST_FIELDS]
    if unknown:
        accepted = [*REQUEST_FIELDS, *(f for f in also_accepted if f not in REQUEST_FIELDS)]
        raise RequestError("bad_request", unknown_name("field", unknown[0], accepted))
    missing = [key for key, default in REQUEST_FIELDS.items() if default is None and key not in obj]
    if missing:
        raise RequestError(
            "bad_request",
            "missing required field"
            + ("s " if len(missing) > 1 else " ")
            + ", ".join(f'"{m}"' for m in missing)
            + ' (a request needs at least "contacts": [[x, y, z], ...] and '
            '"wrench": [fx, fy, fz, mx, my, mz])',
        )
    merged = {key: obj.get(key, default) for key, default in REQUEST_FIELDS.items()}
    return _check_kwargs(**merged)


__all__ = [
    "solve",
    "Guidance",
    "parse_request",
    "RequestError",
    "status_message",
    "STATUS_NAMES",
    "POLICIES",
    "MODES",
    "CONSTRAINT_MODELS",
    "DECOMPOSITIONS",
    "SCALARS",
    "TOLERANCES",
    "PWM_SPAN",
    "MAX_CONTACTS",
    "DEFAULT_MAX_ITERATIONS",
    "DEFAULT_DECOMPOSITION",
    "REQUEST_FIELDS",
    "check_options",
    "solve_checked",
]
