"""Is a hand in the unit it claims? The core uses only ratios of positions, so it cannot
tell metres from millimetres; these checks catch a hand or a moment given in another
unit than stated, for the scene and protocol files and `graspguide solve`."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from itertools import combinations, starmap

UNITS = {"m": 1.0, "mm": 1000.0}  # divisor to metres (x / 1000 is correctly rounded)

# A human hand: its two farthest contacts are 5 mm to 0.5 m apart. Outside that the
# numbers are almost surely in another unit than the one stated (85 "m" are 85 mm);
# the core cannot tell, since it uses only ratios of positions.
HAND_SPAN_M = (0.005, 0.5)
_TYPICAL_SPAN_M = 0.08
_LENGTH_UNITS = (("millimetres", "mm", 1e-3), ("centimetres", "cm", 1e-2), ("metres", "m", 1.0))
# A moment's lever arm |m| / |f| of more than this many hand spans is no hand's: with
# the contacts known to be in metres, such a moment is almost surely in N mm (1000 times
# too large). The paper's wrenches have |m| / |f| <= 5 mm, 1/16 of a span.
MAX_LEVER_SPANS = 10.0


def hand_span(contacts: Sequence[Sequence[float]]) -> float:
    """The largest distance between two contacts."""
    return max(starmap(math.dist, combinations(contacts, 2)), default=0.0)


def hand_span_problem(
    contacts: Sequence[Sequence[float]],
    unit: str,
    fix: Callable[[str | None], str],
    span: float | None = None,
) -> str | None:
    """None when ``contacts`` (in ``unit``, "m" or "mm") span like a hand
    (:data:`HAND_SPAN_M`); else what is wrong, the likely unit and ``fix(symbol)`` (the
    likely unit's symbol, "mm", "cm" or "m", or None when no unit makes it a hand).
    ``span``: their :func:`hand_span`, if the caller has it already."""
    raw = hand_span(contacts) if span is None else span
    lo, hi = HAND_SPAN_M
    if lo <= raw / UNITS[unit] <= hi:
        return None
    fits = [
        (abs(math.log(raw * scale / _TYPICAL_SPAN_M)), name, sym)
        for name, sym, scale in _LENGTH_UNITS
        if raw > 0 and lo <= raw * scale <= hi
    ]
    head = (
        f"contacts span {raw:g} {unit} (the two farthest apart), but a hand spans "
        f"{lo * 1000:g} mm to {hi:g} m"
    )
    if not fits:
        return f"{head}: check the contact positions and their unit; {fix(None)}"
    _, name, sym = min(fits)
    return f"{head}: looks like {name}; {fix(sym)}"


def moment_unit_problem(
    contacts_m: Sequence[Sequence[float]], wrench: Sequence[float], span: float | None = None
) -> str | None:
    """None unless the wrench's moment is implausibly large for its force and the hand
    (contacts in metres): a lever arm |m| / |f| over :data:`MAX_LEVER_SPANS` hand spans,
    which is what a moment in N mm given as N m looks like. A zero force is left to the
    core (zero_force). ``span``: the contacts' :func:`hand_span`, if the caller has it."""
    # x * x, not x ** 2: a float power raises OverflowError where a product is infinite.
    f = math.sqrt(sum([x * x for x in map(float, wrench[:3])]))
    m = math.sqrt(sum([x * x for x in map(float, wrench[3:6])]))
    if span is None:
        span = hand_span(contacts_m)
    if not (f > 0 and span > 0 and math.isfinite(f) and math.isfinite(m)):
        return None
    lever = m / f
    if lever <= MAX_LEVER_SPANS * span:
        return None
    text = (
        f"the moment |m| = {m:g} with the force |f| = {f:g} N is a lever arm of "
        f"{lever:g} m, {lever / span:.0f} times the hand's span ({span * 1000:.0f} mm; "
        f"at most {MAX_LEVER_SPANS:g} spans are accepted)"
    )
    if lever / 1000 <= MAX_LEVER_SPANS * span:
        return (
            f"{text}: the moment looks like N mm while the contacts are metres; give it "
            "in N m (divide by 1000)"
        )
    return f"{text}: check the moment and its unit (N m, about the contacts' centroid)"
