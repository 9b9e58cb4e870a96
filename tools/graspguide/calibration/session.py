"""The calibration procedure: a detection threshold on every finger, then each other
finger matched to the reference; every stimulus and answer recorded. It talks to the
participant through a responder (the operator typing a person's answers, or the virtual
observer) and to the thimbles through a stimulator (graspguide.calibration.stimuli), so
the same procedure runs on a device, on the simulator, or with no device in the tests."""

from __future__ import annotations

import dataclasses
import math
import random
import time
from collections.abc import Callable
from typing import Any, Protocol

from graspguide.calibration.detection import Detection
from graspguide.calibration.matching import Matching, MatchingSettings, matching_gain
from graspguide.calibration.staircase import StaircaseSettings, target_probability
from graspguide.core.motor_calibration import (
    FINGER_NAMES,
    FLOOR_RANGE,
    GAIN_RANGE,
    MOTORS,
    MotorCalibration,
)
from graspguide.core.reference import PWM_BASE, PWM_RANGE

#: The paper's motors start turning at PWM 70: a floor below the start PWM is a motor
#: that does not turn, so the floor is never set below it (``--min-floor``).
DEFAULT_MIN_FLOOR = PWM_BASE
#: The middle of the paper's duty range (70 + 185 / 2).
DEFAULT_REFERENCE_PWM = PWM_BASE + PWM_RANGE // 2
DEFAULT_FINGERS = ("thumb", "index", "middle")
DEFAULT_REFERENCE = "index"
DEFAULT_STIMULUS_S = 0.5
DEFAULT_GAP_S = 0.5
DEFAULT_CATCH_RATE = 0.2
#: Above this false-alarm rate the participant says "yes" to nothing too often for the
#: thresholds to mean much (a yes-sayer).
FALSE_ALARM_WARN = 0.2


class CalibrationAborted(Exception):
    """The operator quit (q or end of input): nothing is written."""


class CalibrationFailed(Exception):
    """The procedure could not measure something (e.g. a thimble never felt)."""


class Responder(Protocol):
    simulated: bool

    def detect(self, finger: str, pwm: int, n: int) -> bool: ...

    def compare(
        self, finger: str, first: tuple[str, int], second: tuple[str, int], n: int
    ) -> int: ...


class Stimulator(Protocol):
    def detection(self, finger: str, pwm: int) -> None: ...

    def pair(self, first: tuple[str, int], second: tuple[str, int]) -> None: ...


@dataclasses.dataclass(frozen=True)
class CalibrationSettings:
    fingers: tuple[str, ...] = DEFAULT_FINGERS
    reference: str = DEFAULT_REFERENCE
    reference_pwm: int = DEFAULT_REFERENCE_PWM
    min_floor: int = DEFAULT_MIN_FLOOR
    detection: StaircaseSettings = StaircaseSettings(start=150)
    catch_rate: float = DEFAULT_CATCH_RATE
    matching: MatchingSettings = MatchingSettings()
    stimulus_s: float = DEFAULT_STIMULUS_S
    gap_s: float = DEFAULT_GAP_S
    seed: int = 0
    # Scale every gain (the reference's too) so that no finger's strongest duty,
    # floor + gain * 185, passes 255: a clipped finger would distort the relative strengths
    # that mode C renders (docs/calibration.md, "Headroom").
    headroom: bool = True

    def __post_init__(self) -> None:
        if not self.fingers:
            raise ValueError("--fingers: name at least one finger")
        for f in self.fingers:
            if f not in FINGER_NAMES:
                raise ValueError(
                    f"--fingers: unknown finger {f!r}; use names of {', '.join(FINGER_NAMES)}"
                )
        if len(set(self.fingers)) != len(self.fingers):
            raise ValueError(f"--fingers: a finger is named twice: {','.join(self.fingers)}")
        if self.reference not in self.fingers:
            raise ValueError(
                f"--reference {self.reference}: must be one of --fingers "
                f"({','.join(self.fingers)}): its floor is measured too"
            )
        if not FLOOR_RANGE[0] <= self.min_floor <= FLOOR_RANGE[1]:
            raise ValueError(
                f"--min-floor must be in {FLOOR_RANGE[0]}..{FLOOR_RANGE[1]}, got {self.min_floor}"
            )
        if not self.min_floor < self.reference_pwm <= 255:
            raise ValueError(
                f"--reference-pwm must be above --min-floor ({self.min_floor}) and at most "
                f"255, got {self.reference_pwm}"
            )

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["fingers"] = list(self.fingers)
        d["detection_target_p"] = self.detection.target
        d["detection_rule"] = f"1-up-{self.detection.down}-down"
        d["matching_rule"] = "two interleaved 1-up-1-down (from above, from below)"
        return d


@dataclasses.dataclass
class FingerResult:
    finger: str
    motor: int  # 1..4
    threshold_pwm: float
    detection_converged: bool
    detection_reversals: list[int]
    catch_trials: int
    false_alarms: int
    pwm_floor: int = 0
    floor_clamped: bool = False
    pse_pwm: float | None = None
    matching_converged: bool | None = None
    matching_reversals: dict[str, list[int]] | None = None
    gain_raw: float | None = None
    gain: float = 1.0
    gain_clipped: bool = False
    gain_scale: float = 1.0  # the headroom factor applied to every finger's gain

    @property
    def false_alarm_rate(self) -> float | None:
        return self.false_alarms / self.catch_trials if self.catch_trials else None

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["false_alarm_rate"] = self.false_alarm_rate
        return d


@dataclasses.dataclass
class CalibrationResult:
    settings: CalibrationSettings
    fingers: dict[str, FingerResult]
    trials: list[dict[str, Any]]
    calibration: MotorCalibration
    warnings: list[str]

    @property
    def catch_trials(self) -> int:
        return sum(f.catch_trials for f in self.fingers.values())

    @property
    def false_alarm_rate(self) -> float | None:
        n = self.catch_trials
        return sum(f.false_alarms for f in self.fingers.values()) / n if n else None


def motor_of(finger: str) -> int:
    """0-based motor slot of a finger (SET_MOTORS, MotorCalibration)."""
    return FINGER_NAMES.index(finger)


def run_procedure(
    settings: CalibrationSettings,
    responder: Responder,
    stimulator: Stimulator,
    on_trial: Callable[[dict[str, Any]], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> CalibrationResult:
    """Detection on every finger (in the order given), then matching of each other finger
    to the reference. Raises CalibrationAborted (operator quit) or CalibrationFailed."""
    rng = random.Random(f"graspguide-calibration:{settings.seed}")
    trials: list[dict[str, Any]] = []
    t0 = clock()

    def record(entry: dict[str, Any]) -> None:
        entry = {"n": len(trials) + 1, "t_s": round(clock() - t0, 3), **entry}
        trials.append(entry)
        if on_trial is not None:
            on_trial(entry)

    results: dict[str, FingerResult] = {}
    for finger in settings.fingers:
        results[finger] = _detect(finger, settings, responder, stimulator, rng, record)
    warnings = _set_floors(results, settings)
    ref = results[settings.reference]
    for finger in settings.fingers:
        if finger != settings.reference:
            _match(results[finger], ref, settings, responder, stimulator, rng, record)
    warnings += _set_gains(results, settings)
    calibration = _calibration(results)
    total_catch = sum(r.catch_trials for r in results.values())
    if total_catch:
        rate = sum(r.false_alarms for r in results.values()) / total_catch
        if rate > FALSE_ALARM_WARN:
            warnings.append(
                f"false-alarm rate {rate:.2f} on {total_catch} catch trials (above "
                f"{FALSE_ALARM_WARN:g}): the participant says yes without a stimulus, so "
                "the thresholds are too low; instruct again and repeat (--force)"
            )
    return CalibrationResult(settings, results, trials, calibration, warnings)


def _detect(
    finger: str,
    settings: CalibrationSettings,
    responder: Responder,
    stimulator: Stimulator,
    rng: random.Random,
    record: Callable[[dict[str, Any]], None],
) -> FingerResult:
    det = Detection(settings.detection, settings.catch_rate, rng)
    n = 0
    while not det.done:
        trial = det.next_trial()
        n += 1
        stimulator.detection(finger, trial.pwm)
        yes = responder.detect(finger, trial.pwm, n)
        det.answer(yes)
        record(
            {
                "phase": "detection",
                "finger": finger,
                "catch": trial.catch,
                "pwm": trial.pwm,
                "answer": "yes" if yes else "no",
            }
        )
    s = det.staircase
    threshold = det.threshold()
    if math.isnan(threshold):
        top = [lvl for lvl, ans in s.trials if lvl == settings.detection.hi]
        hint = (
            f"not felt even at PWM {settings.detection.hi}: check the thimble and its motor"
            if top and not any(ans for lvl, ans in s.trials if lvl == settings.detection.hi)
            else "the answers did not settle"
        )
        raise CalibrationFailed(
            f"{finger}: no detection threshold after {len(s.trials)} trials "
            f"({len(s.reversal_levels)} reversals): {hint}"
        )
    return FingerResult(
        finger=finger,
        motor=motor_of(finger) + 1,
        threshold_pwm=threshold,
        detection_converged=s.converged,
        detection_reversals=list(s.reversal_levels),
        catch_trials=det.catch_trials,
        false_alarms=det.false_alarms,
    )


def _set_floors(results: dict[str, FingerResult], settings: CalibrationSettings) -> list[str]:
    warnings = []
    for r in results.values():
        floor = round(r.threshold_pwm)
        if floor < settings.min_floor:
            warnings.append(
                f"{r.finger}: threshold PWM {r.threshold_pwm:.1f} is below the motor's start "
                f"PWM {settings.min_floor} (--min-floor): floor set to {settings.min_floor}"
            )
            floor, r.floor_clamped = settings.min_floor, True
        if floor > FLOOR_RANGE[1]:
            floor, r.floor_clamped = FLOOR_RANGE[1], True
        r.pwm_floor = floor
        if not r.detection_converged:
            warnings.append(
                f"{r.finger}: the detection staircase stopped at its trial limit with "
                f"{len(r.detection_reversals)} of {settings.detection.reversals} reversals: "
                "the threshold is rough"
            )
    return warnings


def _match(
    r: FingerResult,
    ref: FingerResult,
    settings: CalibrationSettings,
    responder: Responder,
    stimulator: Stimulator,
    rng: random.Random,
    record: Callable[[dict[str, Any]], None],
) -> None:
    expected = r.pwm_floor + (settings.reference_pwm - ref.pwm_floor)
    match = Matching(settings.matching, r.pwm_floor, expected, rng)
    reference = (ref.finger, settings.reference_pwm)
    n = 0
    while not match.done:
        trial = match.next_trial()
        n += 1
        comparison = (r.finger, trial.comparison_pwm)
        first, second = (
            (comparison, reference) if trial.comparison_first else (reference, comparison)
        )
        stimulator.pair(first, second)
        which = responder.compare(r.finger, first, second, n)
        stronger = (which == 1) == trial.comparison_first
        match.answer(stronger)
        record(
            {
                "phase": "matching",
                "finger": r.finger,
                "reference_finger": ref.finger,
                "reference_pwm": settings.reference_pwm,
                "staircase": trial.staircase,
                "comparison_pwm": trial.comparison_pwm,
                "order": "comparison_first" if trial.comparison_first else "reference_first",
                "answer": "first" if which == 1 else "second",
                "comparison_stronger": stronger,
            }
        )
    pse = match.pse()
    if math.isnan(pse):
        raise CalibrationFailed(
            f"{r.finger}: no point of subjective equality against {ref.finger} "
            "(a matching staircase never reversed): the answers did not settle"
        )
    r.pse_pwm = pse
    r.matching_converged = match.converged
    r.matching_reversals = {n: list(s.reversal_levels) for n, s in match.staircases.items()}


def _set_gains(results: dict[str, FingerResult], settings: CalibrationSettings) -> list[str]:
    warnings = []
    ref = results[settings.reference]
    for r in results.values():
        if r is ref:
            r.gain_raw, r.gain = 1.0, 1.0
            continue
        assert r.pse_pwm is not None
        raw = matching_gain(r.pse_pwm, r.pwm_floor, settings.reference_pwm, ref.pwm_floor)
        r.gain_raw = raw
        gain = min(GAIN_RANGE[1], max(GAIN_RANGE[0], raw))
        if gain != raw:
            r.gain_clipped = True
            warnings.append(
                f"{r.finger}: gain {raw:.3f} is outside {GAIN_RANGE[0]:g}..{GAIN_RANGE[1]:g}; "
                f"clipped to {gain:g} (check the thimble's fit and repeat)"
            )
        r.gain = round(gain, 4)
        if r.matching_converged is False:
            warnings.append(
                f"{r.finger}: a matching staircase stopped at its trial limit: the gain is rough"
            )
    if settings.headroom:
        warnings += _make_headroom(results)
    return warnings


def headroom_scale(floors: list[int], gains: list[float]) -> float:
    """The largest factor <= 1 by which every gain can be multiplied so that no finger's
    strongest duty, floor + gain * 185, passes 255."""
    scale = 1.0
    for floor, gain in zip(floors, gains, strict=True):
        top = floor + gain * PWM_RANGE
        if top > 255:
            scale = min(scale, (255 - floor) / (gain * PWM_RANGE))
    return scale


def _make_headroom(results: dict[str, FingerResult]) -> list[str]:
    """Every gain times one factor, so relative strengths stay matched and no finger
    saturates before |m| = 1; a gain pushed below the allowed range is clipped (and said)."""
    ordered = list(results.values())
    scale = headroom_scale([r.pwm_floor for r in ordered], [r.gain for r in ordered])
    if scale >= 1.0:
        return []
    # Rounded down, so the rounded gains still leave the headroom.
    scale = math.floor(scale * 1e4) / 1e4
    warnings = []
    for r in ordered:
        r.gain_scale = scale
        scaled = math.floor(r.gain * scale * 1e4) / 1e4
        if scaled < GAIN_RANGE[0]:
            r.gain_clipped = True
            warnings.append(
                f"{r.finger}: gain {scaled:.3f} after the headroom scaling is below "
                f"{GAIN_RANGE[0]:g}; clipped (its strongest cue is then stronger than the others')"
            )
            scaled = GAIN_RANGE[0]
        r.gain = scaled
    warnings.append(
        f"every gain scaled by {scale:.3f} so that no finger passes PWM 255 (relative "
        "strengths kept; --no-headroom keeps the matched gains and lets strong cues clip)"
    )
    return warnings


def _calibration(results: dict[str, FingerResult]) -> MotorCalibration:
    floor = [PWM_BASE] * MOTORS
    gain = [1.0] * MOTORS
    for r in results.values():
        floor[r.motor - 1] = r.pwm_floor
        gain[r.motor - 1] = r.gain
    return MotorCalibration(tuple(floor), tuple(gain))


__all__ = [
    "CalibrationAborted",
    "CalibrationFailed",
    "CalibrationResult",
    "CalibrationSettings",
    "FingerResult",
    "Responder",
    "Stimulator",
    "run_procedure",
    "motor_of",
    "target_probability",
    "DEFAULT_MIN_FLOOR",
    "DEFAULT_REFERENCE_PWM",
    "DEFAULT_FINGERS",
    "DEFAULT_REFERENCE",
    "DEFAULT_STIMULUS_S",
    "DEFAULT_CATCH_RATE",
    "FALSE_ALARM_WARN",
]
