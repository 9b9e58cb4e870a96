"""A simulated participant for the calibration procedure: per finger, a detection
psychometric function and a perceived-magnitude slope, all seeded. It is a model, never
human data: everything it answers is labelled simulated.

Detection (yes/no): P(yes | pwm) = fa + (1 - fa - lapse) * L((pwm - threshold) / spread)
with L the logistic function; a catch trial (no stimulus) gets "yes" with probability fa
(the false-alarm rate, a yes-sayer's tendency). Perceived magnitude above threshold grows
linearly, psi(pwm) = magnitude * (pwm - threshold), so two fingers feel alike when
magnitude_i (d_i - threshold_i) = magnitude_ref (d_ref - threshold_ref): the gain that
equalises them is magnitude_ref / magnitude_i (docs/calibration.md). Comparing two
stimuli, each magnitude carries Gaussian noise of sd weber * psi(reference).
"""

from __future__ import annotations

import dataclasses
import math
import random
from collections.abc import Iterable, Mapping

from graspguide.core.motor_calibration import FINGER_NAMES

# Where a fresh observer's parameters are drawn from (uniform): thresholds above the
# paper's motor start (PWM 70), slopes that give gains of about 0.6..1.6.
THRESHOLD_RANGE_PWM = (74.0, 104.0)
SPREAD_RANGE_PWM = (3.0, 7.0)
MAGNITUDE_RANGE = (0.65, 1.5)
DEFAULT_FALSE_ALARM = 0.03
DEFAULT_LAPSE = 0.02
DEFAULT_WEBER = 0.10


@dataclasses.dataclass(frozen=True)
class FingerSensitivity:
    """One finger: ``threshold_pwm`` where the detection function L is 1/2 and perceived
    magnitude starts; ``spread_pwm`` the logistic's scale (counts); ``magnitude`` the
    perceived magnitude per count above threshold."""

    threshold_pwm: float
    spread_pwm: float
    magnitude: float


def draw_finger_sensitivities(seed: int) -> dict[str, FingerSensitivity]:
    """The per-finger sensitivities of the simulated person ``seed`` (every finger of
    FINGER_NAMES). Drawn from the seed alone, so the same seed is the same person whatever
    fingers a run calibrates -- and the same fingers the trials' virtual participant feels
    with (``--source participant:fingers=N``, graspguide.participant.model)."""
    draw = random.Random(f"graspguide-virtual-observer-params:{int(seed)}")
    return {
        name: FingerSensitivity(
            draw.uniform(*THRESHOLD_RANGE_PWM),
            draw.uniform(*SPREAD_RANGE_PWM),
            draw.uniform(*MAGNITUDE_RANGE),
        )
        for name in FINGER_NAMES
    }


class VirtualObserver:
    """Seeded answers of a simulated participant (:meth:`detect`, :meth:`compare`)."""

    simulated = True

    def __init__(
        self,
        seed: int = 0,
        fingers: Mapping[str, FingerSensitivity] | None = None,
        false_alarm: float = DEFAULT_FALSE_ALARM,
        lapse: float = DEFAULT_LAPSE,
        weber: float = DEFAULT_WEBER,
    ) -> None:
        for name, v, hi in (("false_alarm", false_alarm, 0.9), ("lapse", lapse, 0.5)):
            if not 0.0 <= v <= hi:
                raise ValueError(f"virtual participant {name} must be in 0..{hi:g}, got {v!r}")
        if not 0.0 < weber <= 1.0:
            raise ValueError(f"virtual participant weber must be in (0, 1], got {weber!r}")
        if false_alarm + lapse >= 1.0:
            raise ValueError("virtual participant false_alarm + lapse must be below 1")
        self.seed = int(seed)
        self.false_alarm = float(false_alarm)
        self.lapse = float(lapse)
        self.weber = float(weber)
        self._rng = random.Random(f"graspguide-virtual-observer:{self.seed}")
        if fingers is None:
            fingers = draw_finger_sensitivities(self.seed)
        self.fingers = dict(fingers)

    def _finger(self, finger: str) -> FingerSensitivity:
        try:
            return self.fingers[finger]
        except KeyError:
            raise ValueError(f"the virtual participant has no finger {finger!r}") from None

    # ---- the truth (what the procedure should find)
    def p_yes(self, finger: str, pwm: float) -> float:
        """P("yes") for a stimulus at ``pwm`` (0: a catch trial, no stimulus)."""
        if pwm <= 0:
            return self.false_alarm
        f = self._finger(finger)
        z = (pwm - f.threshold_pwm) / f.spread_pwm
        return self.false_alarm + (1.0 - self.false_alarm - self.lapse) / (1.0 + math.exp(-z))

    def detection_point(self, finger: str, p: float) -> float:
        """The PWM where P(yes) = ``p`` (the inverse of :meth:`p_yes`)."""
        f = self._finger(finger)
        q = (p - self.false_alarm) / (1.0 - self.false_alarm - self.lapse)
        if not 0.0 < q < 1.0:
            raise ValueError(f"P(yes) = {p} is outside what this observer reaches")
        return f.threshold_pwm + f.spread_pwm * math.log(q / (1.0 - q))

    def true_gain(self, finger: str, reference: str) -> float:
        """The gain that makes ``finger`` feel like ``reference``."""
        return self._finger(reference).magnitude / self._finger(finger).magnitude

    def true_pse(self, finger: str, reference: str, reference_pwm: float) -> float:
        """The PWM on ``finger`` that feels like ``reference_pwm`` on ``reference``."""
        f, r = self._finger(finger), self._finger(reference)
        return f.threshold_pwm + r.magnitude * (reference_pwm - r.threshold_pwm) / f.magnitude

    def magnitude(self, finger: str, pwm: float) -> float:
        f = self._finger(finger)
        return f.magnitude * max(0.0, pwm - f.threshold_pwm)

    # ---- answers (the Responder interface of graspguide.calibration.session)
    def detect(self, finger: str, pwm: int, n: int = 0) -> bool:
        return self._rng.random() < self.p_yes(finger, pwm)

    def compare(
        self, finger: str, first: tuple[str, int], second: tuple[str, int], n: int = 0
    ) -> int:
        """Which of two stimuli (finger, pwm) felt stronger: 1 or 2. The noise scales
        with the reference's magnitude (the stimulus not on ``finger``): Weber's law."""
        if self._rng.random() < self.lapse:
            return self._rng.choice((1, 2))
        reference = second if first[0] == finger else first
        sd = max(1e-9, self.weber * self.magnitude(*reference))
        a = self.magnitude(*first) + self._rng.gauss(0.0, sd)
        b = self.magnitude(*second) + self._rng.gauss(0.0, sd)
        return 1 if a > b else 2

    def describe(self, names: Iterable[str]) -> dict[str, object]:
        """The parameters, for the calibration file of a simulated run."""
        return {
            "seed": self.seed,
            "false_alarm": self.false_alarm,
            "lapse": self.lapse,
            "weber": self.weber,
            "fingers": {n: dataclasses.asdict(self._finger(n)) for n in names},
        }


def parse_participant_source(spec: str) -> VirtualObserver | None:
    """``operator`` -> None (a person answers through the operator); ``participant`` or
    ``participant:seed=N,false_alarm=P,lapse=P,weber=W`` -> a VirtualObserver."""
    kind, _, rest = spec.partition(":")
    if kind == "operator" and not rest:
        return None
    if kind != "participant":
        raise ValueError(
            f"--source {spec!r}: use 'operator' (the operator types a person's answers) or "
            "'participant[:seed=N,false_alarm=P,lapse=P,weber=W]' (the virtual participant)"
        )
    conv = {"seed": int, "false_alarm": float, "lapse": float, "weber": float}
    kw: dict[str, float] = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or key not in conv:
            raise ValueError(
                f"--source participant: bad option {item!r}; options are "
                f"{', '.join(k + '=N' for k in conv)}"
            )
        try:
            kw[key] = conv[key](value)
        except ValueError:
            raise ValueError(
                f"--source participant: {key} must be a number, got {value!r}"
            ) from None
    return VirtualObserver(**kw)  # type: ignore[arg-type]


__all__ = [
    "FingerSensitivity",
    "VirtualObserver",
    "draw_finger_sensitivities",
    "parse_participant_source",
]
