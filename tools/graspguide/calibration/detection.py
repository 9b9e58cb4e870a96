"""The detection threshold of one thimble: a transformed up-down staircase on the PWM
(yes/no answers), with catch trials (no stimulus) mixed in at random to measure the
false-alarm rate: a participant who says "yes" to nothing pulls the staircase down, and
only catch trials show it (Gescheider 1997)."""

from __future__ import annotations

import dataclasses
import random

from graspguide.calibration.staircase import Staircase, StaircaseSettings


@dataclasses.dataclass(frozen=True)
class DetectionTrial:
    catch: bool
    pwm: int  # 0 on a catch trial
    staircase_level: int  # the staircase's level (what a non-catch trial presents)


class Detection:
    """One finger's staircase plus catch trials. :meth:`next_trial`, then
    :meth:`answer` with the participant's yes/no, until :attr:`done`."""

    def __init__(self, settings: StaircaseSettings, catch_rate: float, rng: random.Random):
        if not 0.0 <= catch_rate <= 0.5:
            raise ValueError(f"catch_rate must be in 0..0.5, got {catch_rate!r}")
        self.staircase = Staircase(settings, "detection")
        self.catch_rate = float(catch_rate)
        self.rng = rng
        self.catch_trials = 0
        self.false_alarms = 0
        self._pending: DetectionTrial | None = None

    @property
    def done(self) -> bool:
        return self.staircase.done

    def next_trial(self) -> DetectionTrial:
        if self._pending is not None:
            return self._pending
        catch = self.rng.random() < self.catch_rate
        level = self.staircase.level
        self._pending = DetectionTrial(catch, 0 if catch else level, level)
        return self._pending

    def answer(self, yes: bool) -> None:
        trial = self._pending
        if trial is None:
            raise RuntimeError("answer() before next_trial()")
        self._pending = None
        if trial.catch:
            self.catch_trials += 1
            self.false_alarms += bool(yes)
        else:
            self.staircase.answer(yes)

    @property
    def false_alarm_rate(self) -> float | None:
        return self.false_alarms / self.catch_trials if self.catch_trials else None

    def threshold(self) -> float:
        return self.staircase.estimate()


__all__ = ["Detection", "DetectionTrial"]
