"""Between-participant variability: each virtual participant draws its own parameters.
SIMULATED: a model of a population, never human data.

``draw(seed, fixed)`` gives the scalar parameters of the participant with that seed: every
field in :data:`DISTRIBUTIONS` is drawn from its stated distribution (docs/participant.md,
"Parameters"), in a fixed order from a stream seeded by the participant's seed alone, so a
participant is the same person on every run and fixing one parameter changes no other
draw. A key in ``fixed`` (an explicit ``key=value`` of the spec) is not drawn.
``person_constants`` draws what is not a scalar parameter: the per-finger gains and the
proprioceptive bias. numpy is used only for the seeded draws (PCG64 streams do not depend
on the CPU); the transforms are ``math`` on plain floats.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

#: field -> (kind, a, b, lo, hi). Kinds: "normal" (mean a, SD b), "lognormal" (median a,
#: SD b of the log), "weber_db" (a difference threshold in dB, mean a, SD b, turned into
#: the Weber fraction 10^(dB/20) - 1). Draws are clipped to [lo, hi]. The order is the
#: draw order: append, never reorder (a reordering changes every participant).
DISTRIBUTIONS: dict[str, tuple[str, float, float, float, float]] = {
    "reaction_time_s": ("normal", 0.21, 0.02, 0.15, 0.35),
    "peak_speed_deg_s": ("lognormal", 90.0, 0.25, 30.0, 270.0),
    "motor_noise_frac": ("lognormal", 0.10, 0.30, 0.02, 0.4),
    "weber_frac": ("weber_db", 3.67, 0.5, 0.15, 0.99),
    "hold_cv": ("lognormal", 0.10, 0.30, 0.02, 0.4),
}

_STREAM = 0x706F70756C6174  # "populat": the population's stream of a participant seed
_CONSTANTS = 0x706572736F6E  # "person": its per-finger gains and proprioceptive bias


def draw(seed: int, fixed: Mapping[str, float]) -> dict[str, float]:
    """The drawn parameters of participant ``seed``, without the keys in ``fixed``."""
    rng = np.random.default_rng([seed & (2**64 - 1), _STREAM])
    z = rng.standard_normal(len(DISTRIBUTIONS)).tolist()
    out: dict[str, float] = {}
    for (name, (kind, a, b, lo, hi)), e in zip(DISTRIBUTIONS.items(), z, strict=True):
        if name in fixed:
            continue
        if kind == "normal":
            v = a + b * e
        elif kind == "lognormal":
            v = a * math.exp(b * e)
        elif kind == "weber_db":
            v = 10.0 ** ((a + b * e) / 20.0) - 1.0
        else:  # pragma: no cover - the table above
            raise ValueError(f"unknown distribution {kind!r}")
        out[name] = min(hi, max(lo, v))
    return out


def person_constants(
    seed: int, k: int, finger_gain_sd: float, prop_bias_sd_deg: float
) -> tuple[tuple[float, ...], tuple[float, float, float]]:
    """Participant ``seed``'s finger gains (k, log-normal with log-SD ``finger_gain_sd``)
    and its proprioceptive bias (a world rotation vector [rad], per axis SD
    ``prop_bias_sd_deg``): the same in every trial of that participant."""
    rng = np.random.default_rng([seed & (2**64 - 1), _CONSTANTS])
    z = rng.standard_normal(4 + 3).tolist()
    gains = tuple(math.exp(finger_gain_sd * e) for e in z[:k])
    s = math.radians(prop_bias_sd_deg)
    bias = (s * z[4], s * z[5], s * z[6])
    return gains, bias


__all__ = ["DISTRIBUTIONS", "draw", "person_constants"]
