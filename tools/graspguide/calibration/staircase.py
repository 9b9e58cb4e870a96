"""The transformed up-down staircase (Levitt 1971): the level goes down after ``down``
positive answers in a row and up after each negative one, so it settles where the chance
of ``down`` positives in a row is one half, i.e. where P(positive) = 0.5 ** (1 / down):
1-up-1-down tracks 50 %, 1-up-2-down 70.7 %, 1-up-3-down 79.4 %. The step halves at
every reversal down to ``min_step`` (large steps find the region fast, small ones settle
in it) and doubles again, up to ``initial_step``, after ``double_after`` steps in the same
direction (as PEST does, Taylor & Creelman 1967): without that, one lapse early on (a "no"
to a clear stimulus) shrinks the step far from the threshold and the track then creeps
towards it for dozens of trials. The step sizes change where the track settles, not
which point it tracks; the estimate is the mean of the last reversal levels."""

from __future__ import annotations

import dataclasses
import math


def target_probability(down: int) -> float:
    """The point of the psychometric function a 1-up-``down``-down staircase converges
    to (Levitt 1971, Table I): 0.5 ** (1 / down)."""
    return 0.5 ** (1.0 / down)


@dataclasses.dataclass(frozen=True)
class StaircaseSettings:
    """``start``: first level; ``down``: positives in a row for a step down (1, 2 or 3);
    ``initial_step``/``min_step``: step sizes in counts (halved at each reversal);
    ``double_after``: same-direction steps after which the step doubles (0: never);
    ``reversals``: stop after this many; ``use_last``: the estimate averages that many
    last reversal levels; ``lo``/``hi``: the level's range; ``max_trials``: a staircase
    that has not reversed often enough by then stops, not converged."""

    start: int
    down: int = 2
    initial_step: int = 32
    min_step: int = 2
    double_after: int = 3
    reversals: int = 12
    use_last: int = 8
    lo: int = 0
    hi: int = 255
    max_trials: int = 120

    def __post_init__(self) -> None:
        def need(ok: bool, field: str, what: str, value: object) -> None:
            if not ok:
                raise ValueError(f"staircase {field} must be {what}, got {value!r}")

        for name in (
            "start",
            "down",
            "initial_step",
            "min_step",
            "double_after",
            "reversals",
            "use_last",
        ):
            v = getattr(self, name)
            need(isinstance(v, int) and not isinstance(v, bool), name, "an integer", v)
        need(self.down in (1, 2, 3), "down", "1, 2 or 3 (1-up-N-down)", self.down)
        need(0 <= self.lo < self.hi <= 255, "lo/hi", "0 <= lo < hi <= 255", (self.lo, self.hi))
        need(self.lo <= self.start <= self.hi, "start", f"in {self.lo}..{self.hi}", self.start)
        need(self.min_step >= 1, "min_step", ">= 1 count", self.min_step)
        need(self.initial_step >= self.min_step, "initial_step", ">= min_step", self.initial_step)
        need(self.double_after >= 0, "double_after", ">= 0", self.double_after)
        need(self.reversals >= 2, "reversals", ">= 2", self.reversals)
        need(
            2 <= self.use_last <= self.reversals,
            "use_last",
            f"in 2..reversals ({self.reversals})",
            self.use_last,
        )
        need(self.max_trials >= 1, "max_trials", ">= 1", self.max_trials)

    @property
    def target(self) -> float:
        return target_probability(self.down)


class Staircase:
    """One staircase. :attr:`level` is the next trial's level; :meth:`answer` takes that
    trial's answer (True: detected / the comparison felt stronger, which moves the level
    down); :attr:`done` once enough reversals or ``max_trials`` came."""

    def __init__(self, settings: StaircaseSettings, name: str = "") -> None:
        self.settings = settings
        self.name = name
        self.level = settings.start
        self.step = settings.initial_step
        self.trials: list[tuple[int, bool]] = []
        self.reversal_levels: list[int] = []
        self._run = 0  # positives in a row since the last step
        self._direction = 0  # -1 down, +1 up, 0 no step yet
        self._same = 0  # steps in the current direction since the last reversal

    @property
    def converged(self) -> bool:
        return len(self.reversal_levels) >= self.settings.reversals

    @property
    def done(self) -> bool:
        return self.converged or len(self.trials) >= self.settings.max_trials

    def answer(self, positive: bool) -> None:
        if self.done:
            raise RuntimeError(f"staircase {self.name or ''} is done: no more trials")
        s = self.settings
        self.trials.append((self.level, bool(positive)))
        if positive:
            self._run += 1
            if self._run < s.down:
                return
            move = -1
        else:
            move = +1
        self._run = 0
        if self._direction and move != self._direction:
            # The level just tested is where the track turned: a reversal.
            self.reversal_levels.append(self.level)
            self.step = max(s.min_step, self.step // 2)
            self._same = 0
        self._same += 1
        if s.double_after and self._same > s.double_after:
            self.step = min(s.initial_step, self.step * 2)
        self._direction = move
        self.level = min(s.hi, max(s.lo, self.level + move * self.step))

    def estimate(self) -> float:
        """Mean of the last ``use_last`` reversal levels (of all there are, at least 2,
        when the staircase stopped before converging); NaN with fewer than 2."""
        levels = self.reversal_levels[-self.settings.use_last :]
        if len(levels) < 2:
            return math.nan
        return sum(levels) / len(levels)


__all__ = ["Staircase", "StaircaseSettings", "target_probability"]
