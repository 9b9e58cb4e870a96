"""`graspguide solve` inside the interpreter: one JSON request line on stdin, one JSON
answer line on stdout, flushed, in order; blank lines get no answer and a bad line gets
an error answer while the stream goes on (tools/graspguide/cli/solve.py's format).

Run: micropython solve_server.py   (from this folder, so graspguide_mp is importable)

The interpreter's json reads no NaN or Infinity, so a non-finite number may be spelled as
the string "nan", "inf" or "-inf" (test/data/known_answers.json's spelling); it then
reaches the solver, which answers non_finite_input. The unit checks of
`graspguide solve` (a hand in mm given as m) are the host's: `graspguide solve --engine
micropython` makes them before a request gets here, so here "units" only scales.
"""

import json
import sys

from graspguide_mp import status as st
from graspguide_mp.solver import solve

_FIELDS = ("contacts", "wrench", "units", "policy", "mode", "constraints", "orientation", "y_axis")
_NAMES = {
    "policy": ("F", "Fperp"),
    "mode": ("C", "V"),
    "constraints": ("paper", "normal", "none"),
    "units": ("m", "mm", "any"),
}
_NON_FINITE = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}


class BadRequest(Exception):
    def __init__(self, code, message):
        super().__init__(message)
        self.code = code
        self.message = message


def _number(x, field):
    if isinstance(x, bool):
        raise BadRequest("bad_request", 'field "%s": booleans are not numbers' % field)
    if isinstance(x, (int, float)):
        return float(x)
    if isinstance(x, str) and x in _NON_FINITE:
        return _NON_FINITE[x]
    raise BadRequest("bad_request", 'field "%s" must hold numbers, got %s' % (field, json.dumps(x)))


def _vector(x, field, n):
    if not isinstance(x, list) or len(x) != n:
        raise BadRequest(
            "bad_request",
            'field "%s" must be an array of %d numbers, got %s' % (field, n, json.dumps(x)),
        )
    return [_number(v, field) for v in x]


def parse(obj):
    """The solve() arguments of one decoded request, or raise BadRequest."""
    if not isinstance(obj, dict):
        raise BadRequest("bad_request", "a request is a JSON object, got %s" % json.dumps(obj))
    for key in obj:
        if key not in _FIELDS:
            raise BadRequest(
                "bad_request", 'unknown field "%s"; the fields are %s' % (key, ", ".join(_FIELDS))
            )
    for key in ("contacts", "wrench"):
        if key not in obj:
            raise BadRequest("bad_request", 'field "%s" is required' % key)
    contacts = obj["contacts"]
    if not isinstance(contacts, list) or not contacts:
        raise BadRequest("bad_request", 'field "contacts" must be an array of [x, y, z] arrays')
    contacts = [_vector(c, "contacts", 3) for c in contacts]
    kw = {"contacts": contacts, "wrench": _vector(obj["wrench"], "wrench", 6)}
    for key in ("orientation", "y_axis"):
        if key in obj:
            kw[key] = _vector(obj[key], key, 4 if key == "orientation" else 3)
    for key, names in _NAMES.items():
        if key in obj and obj[key] not in names:
            raise BadRequest(
                "bad_request",
                'field "%s" must be one of %s, got %s'
                % (key, ", ".join(names), json.dumps(obj[key])),
            )
        if key in obj and key != "units":
            kw[key] = obj[key]
    if obj.get("units") == "mm":  # metres and N m inside; only ratios matter anyway
        kw["contacts"] = [[v / 1000.0 for v in c] for c in contacts]
        wr = kw["wrench"]
        kw["wrench"] = wr[:3] + [v / 1000.0 for v in wr[3:]]
    return kw


def _num(x):
    """JSON for a float: null when not finite (strict JSON, as the host's answers)."""
    if x - x != 0.0:
        return "null"
    return json.dumps(x)


def answer_line(res):
    if res.status != st.OK:
        return error_line(st.name(res.status), st.message(res.status))
    parts = [
        '"ok": true',
        '"pwm": ' + json.dumps(res.pwm),
        '"levels": [' + ", ".join(_num(v) for v in res.levels) + "]",
        '"lambda": [' + ", ".join(_num(v) for v in res.lam) + "]",
        '"constraints_used": ' + json.dumps(res.used),
        '"relevant": ' + json.dumps(res.relevant),
        '"error_deg": ' + _num(res.error_deg),
        '"iterations": %d' % res.iterations,
        '"alpha": ' + _num(res.alpha),
        '"fallback_mask": %d' % res.fallback_mask,
    ]
    return "{" + ", ".join(parts) + "}"


def error_line(code, message):
    return '{"ok": false, "error": %s, "message": %s}' % (json.dumps(code), json.dumps(message))


def respond(line, number):
    """The answer line to one input line, or None for a blank one."""
    if not line.strip():
        return None
    try:
        obj = json.loads(line)
    except ValueError:
        return error_line("bad_json", "line %d is not valid JSON" % number)
    try:
        kw = parse(obj)
    except BadRequest as e:
        return error_line(e.code, "line %d: %s" % (number, e.message))
    try:
        return answer_line(solve(**kw))
    except Exception as e:  # never expected: motors stay off and the stream goes on
        return error_line(
            "internal_error",
            "line %d: unexpected %s: %s; please report this request"
            % (number, type(e).__name__, e),
        )


def main():
    number = 0
    out = sys.stdout
    while True:
        line = sys.stdin.readline()
        if not line:
            return
        number += 1
        text = respond(line, number)
        if text is None:
            continue
        out.write(text + "\n")
        if hasattr(out, "flush"):
            out.flush()


if __name__ == "__main__":
    main()
