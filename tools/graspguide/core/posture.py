"""One posture's per-posture result, as a board that does only the per-frame work receives
it (SET_POSTURE, a MicroPython plan's levels): Algorithm 1's motor levels from the C++ core
and the force direction f-hat, both rounded to the float32 a board stores."""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

MAX_MOTORS = 4
_F32 = struct.Struct("<f")


def f32(x: float) -> float:
    """x rounded to the nearest float32, as a float."""
    return _F32.unpack(_F32.pack(float(x)))[0]


@dataclass(frozen=True)
class Posture:
    status: str  # the core's status name; "ok" or why it cannot be solved
    k: int
    levels: tuple[float, float, float, float]  # float32, slots >= k zero
    force_unit: tuple[float, float, float]  # float32 f-hat in the hand frame


def solve_posture(
    contacts: Sequence[Sequence[float]],
    wrench: Sequence[float],
    policy: str,
    mode: str,
    constraints: str,
    y_axis: Sequence[float],
) -> Posture:
    """The core's levels for these contacts (k = len(contacts)) and wrench, and f-hat as
    grasp_solution.h forms it (the wrench's force over its norm). A status other than "ok"
    comes with zero levels and f-hat."""
    from graspguide.core import solver

    k = len(contacts)
    res = solver.solve(
        [list(c) for c in contacts],
        list(wrench),
        policy=policy,
        mode=mode,
        constraints=constraints,
        y_axis=list(y_axis),
    )
    if res["status"] != "ok":
        return Posture(res["status"], k, (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    force = [float(f) for f in wrench[:3]]
    norm = math.sqrt(sum(f * f for f in force))  # > 0: the core refuses a zero force
    f_hat = (f32(force[0] / norm), f32(force[1] / norm), f32(force[2] / norm))
    lv = [f32(v) for v in res["levels"][:k]] + [0.0] * (MAX_MOTORS - k)
    return Posture("ok", k, (lv[0], lv[1], lv[2], lv[3]), f_hat)


__all__ = ["MAX_MOTORS", "Posture", "f32", "solve_posture"]
