"""The calibration's stimuli on a device: one thimble buzzed at a PWM for a while
(graspguide.link.motor_drive.drive_motors: SET_MOTORS kept inside the watchdog, always
zeros at the end). SET_MOTORS is a raw drive, never calibrated, so the PWM presented is
the PWM measured."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from graspguide.core.motor_calibration import FINGER_NAMES, MOTORS
from graspguide.link.motor_drive import drive_motors

#: With the virtual participant nobody feels the stimulus, so it need not last: each one
#: is still sent to the device (and shows in its trace), for this long.
SIMULATED_STIMULUS_S = 0.01


class DeviceStimulator:
    """``stimulus_s``: how long each stimulus lasts; ``gap_s``: the pause between the two
    of a matching pair. A catch trial (PWM 0) waits as long as a stimulus would, so the
    timing does not give it away."""

    def __init__(
        self,
        client: Any,
        stimulus_s: float,
        gap_s: float,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.client = client
        self.stimulus_s = stimulus_s
        self.gap_s = gap_s
        self.sleep = sleep
        self.sent = 0  # stimuli driven

    def _buzz(self, finger: str, pwm: int) -> None:
        duty = [0] * MOTORS
        duty[FINGER_NAMES.index(finger)] = pwm
        drive_motors(self.client, duty, self.stimulus_s)
        self.sent += 1

    def detection(self, finger: str, pwm: int) -> None:
        if pwm > 0:
            self._buzz(finger, pwm)
        else:
            self.sleep(self.stimulus_s)

    def pair(self, first: tuple[str, int], second: tuple[str, int]) -> None:
        self._buzz(*first)
        self.sleep(self.gap_s)
        self._buzz(*second)


__all__ = ["DeviceStimulator", "SIMULATED_STIMULUS_S"]
