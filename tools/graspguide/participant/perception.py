"""What the virtual participant perceives of the vibrating thimbles. SIMULATED: a model.

One reading of the motors (their ERM speeds in PWM units, as the delay line gives them)
becomes a :class:`graspguide.participant.bayes_reading.Percept`: which motors are felt,
after counting errors, and for each felt motor an estimate of its level |m_i| with the SD
of its logarithm. Every number is stated in docs/participant.md with its source:

* **Felt.** A motor is felt when its speed reaches half of the lowest "on" level (PWM 70,
  the paper's 0.9 V), or, with the calibration's per-finger model, its finger's threshold.
* **Intensity noise.** An ERM's vibration amplitude grows with the square of its speed;
  the amplitude is perceived with multiplicative noise whose log-SD is ``ln(1 + W)``, W the
  amplitude Weber fraction, so the perceived speed carries half of it.
* **Per-finger gain.** Each finger feels the same vibration with its own gain (a
  between-participant draw, unknown to the participant); the level is the perceived speed
  above the floor times that gain, on the scale 185.
* **Counting errors.** With ``n >= 3`` motors on at once, the weakest felt one is missed
  with probability ``miss_per_extra * (n - 2)``.

Plain-Python ``math`` only (see the reproducibility note of graspguide.participant.model).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from graspguide.participant.bayes_reading import Percept

PWM_FLOOR = 70  # lowest "on" PWM of the device (paper: 0.9 V), docs/algorithm.md step 6
PWM_RANGE = 185  # PWM span above the floor, docs/algorithm.md step 6


def ln_amplitude_sd(weber_frac: float) -> float:
    """SD of the log of a perceived vibration amplitude for a Weber fraction W: ln(1 + W)
    (the difference threshold taken as one SD of the internal noise)."""
    return math.log1p(weber_frac)


def miss_probabilities(miss_per_extra: float, k: int) -> tuple[float, ...]:
    """Index n: the probability that the weakest of n simultaneous vibrations is missed."""
    return tuple(min(1.0, miss_per_extra * (n - 2)) if n >= 3 else 0.0 for n in range(k + 1))


def perceive(
    speeds: Sequence[float],
    normals: Sequence[float],
    u_miss: float,
    gains: Sequence[float],
    weber_frac: float,
    gain_sd: float,
    miss_prob: Sequence[float],
    thresholds: Sequence[float] | None = None,
) -> Percept | None:
    """One reading of the motor speeds (None: nothing felt).

    ``normals``: one standard normal draw per motor (the intensity noise); ``u_miss``: a
    uniform draw in [0, 1) for the counting error; ``gains``: the fingers' gains;
    ``thresholds``: per-finger felt thresholds and floors (the calibration's per-finger
    model), else the uniform rule (felt from 35, floor 70). The SD reported for each
    level is what the participant assumes: its intensity noise (by the delta method on
    the level above the floor) and the spread of finger gains."""
    s = [float(v) for v in speeds]
    k = len(s)
    if thresholds is None:
        felt = [v >= 0.5 * PWM_FLOOR for v in s]
        floors = [float(PWM_FLOOR)] * k
    else:
        felt = [v > thr for v, thr in zip(s, thresholds)]
        floors = [float(t) for t in thresholds]
    if not any(felt):
        return None
    half = 0.5 * ln_amplitude_sd(weber_frac)
    level = [0.0] * k
    sd = [math.inf] * k
    strength = [0.0] * k
    for i in range(k):
        if not felt[i]:
            continue
        sp = s[i] * math.exp(half * float(normals[i]))
        above = max(sp - floors[i], 1.0)  # at least one count: a felt motor has a level
        strength[i] = float(gains[i]) * above
        level[i] = math.log(strength[i] / PWM_RANGE)
        rel = half * sp / above
        # (at least 1e-3: a noise-free reader still weighs its motors finitely)
        sd[i] = max(1e-3, math.sqrt(rel * rel + gain_sd * gain_sd))
    n = sum(felt)
    if n >= 3 and u_miss < miss_prob[n]:
        weakest = min((i for i in range(k) if felt[i]), key=lambda i: strength[i])
        felt[weakest] = False
        level[weakest] = 0.0
        sd[weakest] = math.inf
    return Percept(tuple(felt), tuple(level), tuple(sd))


__all__ = ["PWM_FLOOR", "PWM_RANGE", "ln_amplitude_sd", "miss_probabilities", "perceive"]
