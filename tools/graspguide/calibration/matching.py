"""Intensity matching of one finger to the reference finger: the reference at a fixed
PWM and the comparison finger, in random order, and "which felt stronger?". Two 1-up-1-down
staircases on the comparison's PWM, one starting above and one below the expected match,
interleaved at random, each converge on the 50 % point, the point of subjective equality
(PSE; Gescheider 1997; Levitt 1971). Starting from both sides cancels the bias of
where a track starts; the PSE is the mean of the two."""

from __future__ import annotations

import dataclasses
import math
import random

from graspguide.calibration.staircase import Staircase, StaircaseSettings

STAIRCASES = ("from_above", "from_below")


@dataclasses.dataclass(frozen=True)
class MatchingSettings:
    """``offset``: how far above and below the expected match the two tracks start."""

    offset: int = 40
    initial_step: int = 16
    min_step: int = 2
    reversals: int = 10
    use_last: int = 8
    max_trials: int = 60


@dataclasses.dataclass(frozen=True)
class MatchingTrial:
    staircase: str
    comparison_pwm: int
    comparison_first: bool


class Matching:
    """One comparison finger against the reference. ``floor``: the comparison finger's
    floor (its track never goes below it: under the threshold it is not felt at all);
    ``expected``: where the tracks centre (the match if the fingers were alike)."""

    def __init__(
        self, settings: MatchingSettings, floor: int, expected: float, rng: random.Random
    ) -> None:
        self.settings = settings
        self.rng = rng
        lo, hi = max(0, min(floor, 254)), 255
        centre = min(hi, max(lo, round(expected)))
        starts = {
            "from_above": min(hi, centre + settings.offset),
            "from_below": max(lo, centre - settings.offset),
        }
        self.staircases = {
            name: Staircase(
                StaircaseSettings(
                    start=starts[name],
                    down=1,
                    initial_step=settings.initial_step,
                    min_step=settings.min_step,
                    reversals=settings.reversals,
                    use_last=settings.use_last,
                    lo=lo,
                    hi=hi,
                    max_trials=settings.max_trials,
                ),
                name,
            )
            for name in STAIRCASES
        }
        self._pending: MatchingTrial | None = None

    @property
    def done(self) -> bool:
        return all(s.done for s in self.staircases.values())

    def next_trial(self) -> MatchingTrial:
        if self._pending is not None:
            return self._pending
        open_tracks = [n for n in STAIRCASES if not self.staircases[n].done]
        if not open_tracks:
            raise RuntimeError("matching is done: no more trials")
        name = self.rng.choice(open_tracks)
        self._pending = MatchingTrial(name, self.staircases[name].level, self.rng.random() < 0.5)
        return self._pending

    def answer(self, comparison_stronger: bool) -> None:
        trial = self._pending
        if trial is None:
            raise RuntimeError("answer() before next_trial()")
        self._pending = None
        self.staircases[trial.staircase].answer(comparison_stronger)

    @property
    def converged(self) -> bool:
        return all(s.converged for s in self.staircases.values())

    def pse(self) -> float:
        """Mean of the two tracks' estimates (NaN if either has none)."""
        estimates = [s.estimate() for s in self.staircases.values()]
        if any(math.isnan(e) for e in estimates):
            return math.nan
        return sum(estimates) / len(estimates)


def matching_gain(pse: float, floor: float, reference_pwm: float, reference_floor: float) -> float:
    """gain_i = (PSE_i - floor_i) / (reference_pwm - floor_ref): with
    duty_i = floor_i + gain_i * G * |m|, the duty that drives the reference finger at
    ``reference_pwm`` drives this finger at its PSE, i.e. they feel alike."""
    span = reference_pwm - reference_floor
    if span <= 0:
        raise ValueError(
            f"the reference level (PWM {reference_pwm:g}) is not above the reference "
            f"finger's floor (PWM {reference_floor:g}): raise --reference-pwm"
        )
    return (pse - floor) / span


__all__ = ["Matching", "MatchingSettings", "MatchingTrial", "STAIRCASES", "matching_gain"]
