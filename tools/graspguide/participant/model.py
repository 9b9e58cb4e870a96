"""A virtual participant: a seeded model of a person following the vibrotactile cues.

SIMULATED. Everything this module produces is the output of a model; it is never human
data and must be labelled as simulated wherever it is stored or shown
(:attr:`VirtualParticipant.SIMULATED` is True for that purpose).

The model (docs/participant.md explains it with every parameter, its distribution across
participants and its source):

1. **Motors (ERM lag).** The PWM of each motor (0..255, the latest telemetry) drives a
   first-order lag with time constant ``erm_tau_s``.
2. **Delay.** Every decision uses what the motors did ``reaction_time_s`` earlier (a
   delay line). The first movement starts ``3 erm_tau_s + reaction_time_s`` after the
   first felt cue (the motors near their steady speed, 95 % at 3 tau, then a reaction).
3. **Perception** (:mod:`graspguide.participant.perception`): which motors are felt,
   with counting errors when three or more vibrate; their levels with the amplitude
   Weber noise and the participant's own per-finger gains.
4. **Reading** (:mod:`graspguide.participant.bayes_reading`): a posterior over weight
   directions (hand frame) given the percept, from Algorithm 1 known in full
   (``reading="full"``) or learned from a few familiarisation trials
   (``reading="learned"``), with a uniform prior and no moment in the participant's
   picture of the task.
5. **Proprioception.** The participant believes its hand is at ``exp(E) q`` when it is at
   ``q``: ``E`` is its own constant bias, plus a per-trial variable error, plus a drift
   proportional to each movement. It plans with the belief; the hand moves from ``q``.
6. **Moving.** Minimum-jerk submovements (Flash & Hogan 1985), peak angular speed at most
   ``peak_speed_deg_s``, signal-dependent motor noise, physiological tremor on top.
7. **Strategy.**
   * Mode C: the pattern never changes during a trial, so after the one reading the only
     news is that the cue has not stopped. The participant visits the directions in the
     order of posterior mass covered per second: each time the grid point maximising
     (the not-yet-covered posterior mass within the threshold of it) / (hold + travel
     time), moving there continuously and holding it for the hold the task needs (with
     its own timing noise); a hold covers the grid points within the threshold of where it
     *believes* the hand pointed, never visited again.
   * Mode V: the first move turns the most probable direction down by the felt distance;
     then a compass ("warmer/colder") search with the felt distance, each pose felt after
     ``3 erm_tau_s + reaction_time_s``; at a pose as faint as it can tell from the weakest
     vibration it holds for the hold the task needs.
8. **Between participants** (:mod:`graspguide.participant.population`): ``from_spec``
   draws the participant's parameters from their stated distributions, seeded by its
   seed; an explicit ``key=value`` fixes one (``vary=0``: every parameter at its median).

What it does NOT use: the device's error angle, ``alpha`` or the wrench. The wrench
passed to :meth:`VirtualParticipant.begin_trial` is validated (so a broken caller is
caught) and then used only to seed the trial's noise: the decisions depend only on the PWM
felt, the participant's own contact geometry and its belief about its own orientation.
"""

from __future__ import annotations

import hashlib
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from graspguide.core.rotations import (
    Vec3,
    cross3,
    dot3,
    norm3,
    qconj,
    qexp,
    qmul,
    qnormalize,
    rotate,
    rotvec_from_quat,
    scale3,
)
from graspguide.core.rotations import (
    quat_angle_deg as quaternion_angle_deg,  # re-exported: tests, analysis
)
from graspguide.core.vocabulary import MODES, POLICIES
from graspguide.participant import bayes_reading, perception, population
from graspguide.participant.perception import PWM_FLOOR, PWM_RANGE

# Every number a pose depends on is computed on plain Python floats with `math`, in a
# fixed order. numpy's linear algebra (norm, dot, @) runs in OpenBLAS, whose kernel -- and
# so the last bit of a sum -- is chosen by the CPU (OPENBLAS_CORETYPE), and numpy's SIMD
# sin/cos/exp/hypot depend on the CPU's features; a closed loop turns one last-bit
# difference into a different trajectory, so a seeded study would not reproduce on
# another machine. numpy stays only for checking inputs, for the seeded random streams
# (PCG64 draws do not depend on the CPU) and for elementwise operations on the reading
# grid (+, -, *, /, sqrt and comparisons are IEEE-exact per element; no reductions, no
# SIMD transcendentals: graspguide.participant.bayes_reading). Left: the last bit of
# libm's sin/cos/exp/log/atan2 (glibc has an FMA code path).
# tools/tests/participant/test_participant.py checks both: the same bits under another
# OpenBLAS kernel, and a golden record within a tolerance stated there.

PWM_MAX = 255
GRAVITY: Vec3 = (0.0, 0.0, -1.0)
READINGS = ("full", "learned")
V_SEARCHES = ("bayes", "compass")
_STR_FIELDS = {"reading": READINGS, "v_search": V_SEARCHES}


@dataclass(frozen=True)
class ParticipantParams:
    """Parameters of the virtual participant. Sources and the distributions across
    participants: docs/participant.md ("Parameters"). The defaults are the population's
    medians; :meth:`VirtualParticipant.from_spec` draws a participant's own values.

    Every field carries its unit in its name (``_s``, ``_deg``, ``_deg_s``, ``_hz``;
    ``_frac``/``_cv``/``_sd`` are dimensionless).
    """

    #: Pose rate [Hz]: a motion-capture rate (the paper tracked the hand with a Vicon
    #: system). Convention; the runner calls step() every 1 / rate_hz s.
    rate_hz: float = 100.0
    #: ERM time constant [s]: ~180 ms to full amplitude for a PMD 305-000 ERM = 3 tau.
    erm_tau_s: float = 0.06
    #: Simple reaction time to a fingertip vibration [s]: 200-220 ms (Brain Gauge
    #: controls); it includes the tactile afferent latency. Drawn across participants.
    reaction_time_s: float = 0.21
    #: Peak angular speed of a hand reorientation [deg/s]: the standard isokinetic test
    #: speed of forearm rotation. Drawn across participants.
    peak_speed_deg_s: float = 90.0
    #: Physiological tremor amplitude [deg] (0.01 g at ~7 Hz over a 0.1 m lever).
    tremor_amplitude_deg: float = 0.03
    #: Physiological tremor frequency [Hz].
    tremor_frequency_hz: float = 7.0
    #: Signal-dependent motor noise [SD / amplitude] (form: Harris & Wolpert 1998; size
    #: assumed). Drawn across participants.
    motor_noise_frac: float = 0.10
    #: Amplitude Weber fraction of a fingertip vibration with other fingers vibrating:
    #: 3.6-3.7 dB average threshold with masking stimuli (Israr, Tan & Reed 2006, J Acoust
    #: Soc Am 120(5):2789-2800) = 10^(3.67/20) - 1 = 0.53. Drawn across participants.
    weber_frac: float = 0.53
    #: Spread of the per-finger gains [SD of ln gain] (assumption); each participant's
    #: gains are drawn from its seed and unknown to it.
    finger_gain_sd: float = 0.2
    #: Counting errors: the weakest of n >= 3 simultaneous vibrations is missed with
    #: probability miss_per_extra * (n - 2) (form: Gallace, Tan & Spence 2006; size
    #: assumed).
    miss_per_extra: float = 0.1
    #: Proprioceptive bias [deg, per axis SD across participants]: sqrt(E^2 - VE^2) =
    #: sqrt(6.83^2 - 4.59^2) of wrist position matching (Front Hum Neurosci 10:316, 2016).
    prop_bias_sd_deg: float = 5.06
    #: Proprioceptive variable error [deg, per axis SD, drawn per trial]: VE 4.59 (same).
    prop_trial_sd_deg: float = 4.59
    #: Proprioceptive drift [SD / movement amplitude, per axis]: a Weber fraction of about
    #: 0.09 for wrist movements (Cappello et al. 2016; not re-checked).
    prop_drift_frac: float = 0.09
    #: Timing noise of a held interval [CV]: scalar timing (assumption ~0.1). The
    #: participant aims at task_hold_s (1 + 2 hold_cv) so that ~98 % of its holds are long
    #: enough. Drawn across participants.
    hold_cv: float = 0.10
    #: What the participant knows of the task from its instructions and familiarization:
    #: the alignment threshold [deg] (paper Sec. IV: 3 deg) ...
    task_threshold_deg: float = 3.0
    #: ... and how long it must be held for the cue to stop [s] (paper Sec. IV: 0.5 s).
    task_hold_s: float = 0.5
    #: How it reads the pattern: "full" (Algorithm 1 known in full) or "learned" (only
    #: from familiar_examples trials of its familiarisation, a kernel estimate).
    reading: str = "full"
    #: Learned reading: familiarisation trials per hand and policy (the protocol's 4
    #: familiarisation trials, one per modality: 2 per policy) ...
    familiar_examples: float = 2
    #: ... and the kernel width [deg] around each learned direction (assumption).
    kernel_deg: float = 20.0
    #: Mode V search: "bayes" (the posterior over directions from the pattern, updated
    #: with every felt distance; the hand turned to its most probable direction) or
    #: "compass" (warmer/colder from the best pose known, started from the reading).
    v_search: str = "bayes"
    #: 1: from_spec draws the parameters across participants; 0: every parameter at its
    #: median (the defaults above). Only from_spec reads it.
    vary: float = 1


_NONNEG_FIELDS = (
    "tremor_amplitude_deg",
    "weber_frac",
    "motor_noise_frac",
    "finger_gain_sd",
    "miss_per_extra",
    "prop_bias_sd_deg",
    "prop_trial_sd_deg",
    "prop_drift_frac",
    "hold_cv",
    "vary",
)
_FRAC_FIELDS = ("motor_noise_frac", "weber_frac", "miss_per_extra", "hold_cv")


def _validate_params(p: ParticipantParams) -> None:
    for f in fields(p):
        v = getattr(p, f.name)
        if f.name in _STR_FIELDS:
            if v not in _STR_FIELDS[f.name]:
                raise ValueError(
                    f"participant parameter {f.name} must be one of {_STR_FIELDS[f.name]}, "
                    f"got {v!r}"
                )
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"participant parameter {f.name} must be a finite number, got {v!r}")
        if f.name in _NONNEG_FIELDS:
            if v < 0:
                raise ValueError(f"participant parameter {f.name} must be >= 0, got {v!r}")
        elif not v > 0:
            raise ValueError(f"participant parameter {f.name} must be > 0, got {v!r}")
        if f.name in _FRAC_FIELDS and v >= 1:
            raise ValueError(
                f"participant parameter {f.name} is a fraction and must be < 1, got {v!r}"
            )
    if p.familiar_examples != int(p.familiar_examples):
        raise ValueError(
            "participant parameter familiar_examples must be a whole number, "
            f"got {p.familiar_examples!r}"
        )


class FeelLagError(RuntimeError):
    """act() was called further ahead of feel() than the model's delay allows (its pose
    could depend on a PWM not felt yet); see :meth:`VirtualParticipant.act`."""


def _check_time(t_s: Any) -> float:
    if type(t_s) is float and t_s - t_s == 0.0:  # the common case: finite (inf - inf is NaN)
        return t_s
    if (
        isinstance(t_s, bool)
        or not isinstance(t_s, (int, float, np.floating, np.integer))
        or not math.isfinite(float(t_s))
    ):
        raise ValueError(f"t_s must be a finite number of seconds, got {t_s!r}")
    return float(t_s)


def _finite_vector(x: Any, n: int | None, what: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be numbers, got {x!r}") from None
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        raise ValueError(f"{what} must be {n} numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} must be finite, got {x!r}")
    return a


class VirtualParticipant:
    """A seeded virtual participant (see the module docstring). SIMULATED, never human data.

    Use: ``begin_trial(...)`` once per trial, then ``step(t_s, pwm)`` every
    ``1 / rate_hz`` s of virtual time with the PWM of the latest telemetry; each call
    returns the next hand orientation ``(w, x, y, z)`` (hand -> world).

    Or, pipelined, feeling apart from acting: ``act(t_s)`` gives the pose at ``t_s``
    and ``feel(t_s, pwm)`` takes that pose's telemetry PWM when it arrives (late, in
    order); act() may run up to :meth:`max_lead` poses ahead of feel() and gives
    exactly what ``step`` gives (see :meth:`act` for the guarantee, checked at run
    time). ``step(t, pwm)`` is ``feel(t_prev, pwm)`` then ``act(t)``.
    """

    SIMULATED = True

    def __init__(self, params: ParticipantParams, seed: int, fingers: int | None = None):
        if not isinstance(params, ParticipantParams):
            raise TypeError(f"params must be a ParticipantParams, got {type(params).__name__}")
        _validate_params(params)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(f"seed must be an integer, got {seed!r}")
        self.params = params
        self.seed = int(seed)
        self.rate_hz = float(params.rate_hz)
        self._rng = np.random.default_rng(self.seed)
        self._trial = False
        # Opt-in per-finger sensitivities (None: every motor felt alike, the default).
        self.fingers_seed: int | None = None
        self._sens: tuple[tuple[float, float], ...] | None = None
        self._mag_ref = 1.0
        self._thr_ref = float(PWM_FLOOR)
        if fingers is not None:
            self._set_fingers(fingers)
        # The person's constants: per-finger gains (unknown to it) and proprioceptive bias.
        self._gains, self._prop_bias = population.person_constants(
            self.seed, 4, params.finger_gain_sd, params.prop_bias_sd_deg
        )

    def _set_fingers(self, fingers: Any) -> None:
        """Feel with the fingers of the calibration's simulated person ``fingers``
        (graspguide.calibration.virtual_observer.draw_finger_sensitivities): motor i is
        FINGER_NAMES[i]; its perceived strength is magnitude_i * max(0, speed_i -
        threshold_i), and distances are read on the reference finger's scale
        (magnitude_ref * PWM_RANGE; the reference is calibrate's default, index)."""
        if isinstance(fingers, bool) or not isinstance(fingers, (int, np.integer)):
            raise ValueError(f"fingers must be an integer seed (fingers=3), got {fingers!r}")
        from graspguide.calibration.session import DEFAULT_REFERENCE
        from graspguide.calibration.virtual_observer import draw_finger_sensitivities
        from graspguide.core.motor_calibration import FINGER_NAMES

        sens = draw_finger_sensitivities(int(fingers))
        self.fingers_seed = int(fingers)
        self._sens = tuple((sens[n].threshold_pwm, sens[n].magnitude) for n in FINGER_NAMES)
        self._mag_ref = sens[DEFAULT_REFERENCE].magnitude
        self._thr_ref = sens[DEFAULT_REFERENCE].threshold_pwm

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_spec(cls, spec: str, seed: int) -> VirtualParticipant:
        """``participant`` or ``participant:key=val,key=val`` (keys: ParticipantParams
        fields); also just the part after ``participant:`` (``""`` for the defaults).

        The participant's parameters are drawn from their distributions across
        participants, seeded by ``seed`` (:mod:`graspguide.participant.population`); a
        key given in the spec is fixed to its value, and ``vary=0`` draws none."""
        params, fingers, given = _parse_spec_keys(spec)
        if params.vary and not (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))):
            drawn = population.draw(int(seed), given)
            if drawn:
                params = replace(params, **drawn)  # type: ignore[arg-type]
        return cls(params, seed, fingers=fingers)

    # ------------------------------------------------------------------ trial
    def begin_trial(
        self,
        *,
        contacts,
        y_axis,
        wrench,
        policy: str,
        mode: str,
        start_quat,
        noise_seed: int | None = None,
    ) -> None:
        """Start a trial. ``wrench`` never enters a decision (see the module doc).

        The trial's random stream (perception and motor noise, tremor phases, search
        directions) is seeded from the participant's seed and, unless ``noise_seed`` is
        given, a hash of this call's arguments: the same trial gives the same trajectory
        whatever ran before it (a resumed study reproduces an uninterrupted one). This
        seeding is the wrench's only use.
        """
        try:
            c = np.asarray(contacts, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"contacts must be k x 3 numbers, got {contacts!r}") from None
        if c.ndim != 2 or c.shape[1] != 3 or c.shape[0] not in (3, 4):
            raise ValueError(f"contacts must be 3 or 4 points [x, y, z], got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("contacts must be finite")
        y = _finite_vector(y_axis, 3, "y_axis")
        if not norm3(y.tolist()) > 0:
            raise ValueError("y_axis must be non-zero")
        w = _finite_vector(wrench, 6, "wrench")  # never used for a decision (seed only)
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        q = _finite_vector(start_quat, 4, "start_quat (w, x, y, z)")
        q0 = tuple(q.tolist())
        if not math.sqrt(dot3(q0[1:], q0[1:]) + q0[0] * q0[0]) > 1e-6:
            raise ValueError("start_quat must be a non-zero quaternion")

        points = c.tolist()
        centroid = [sum(p[a] for p in points) / len(points) for a in range(3)]
        r = [(p[0] - centroid[0], p[1] - centroid[1], p[2] - centroid[2]) for p in points]
        norms = [norm3(v) for v in r]
        if not all(n > 1e-9 * max(1.0, max(norms)) for n in norms):
            raise ValueError("contacts must not coincide with their centroid")
        if noise_seed is None:
            digest = hashlib.sha256(
                b"|".join(
                    [
                        c.tobytes(),
                        y.tobytes(),
                        w.tobytes(),
                        policy.encode(),
                        mode.encode(),
                        q.tobytes(),
                    ]
                )
            ).digest()
            trial_key = int.from_bytes(digest[:8], "little")
        else:
            if isinstance(noise_seed, bool) or not isinstance(noise_seed, (int, np.integer)):
                raise ValueError(f"noise_seed must be an integer, got {noise_seed!r}")
            trial_key = int(noise_seed)
        self._rng = np.random.default_rng([self.seed & (2**64 - 1), trial_key & (2**64 - 1)])

        # own hand geometry: y_i (hand frame)
        self._radial = [(v[0] / n, v[1] / n, v[2] / n) for v, n in zip(r, norms)]
        self._k = c.shape[0]
        self.policy = policy
        self.mode = mode
        self._qt = qnormalize(q0)  # the hand's orientation (before tremor)
        self._contacts = tuple(tuple(float(x) for x in row) for row in points)
        self._y_axis = tuple(float(x) for x in y.tolist())
        self._motor = [0.0] * self._k  # ERM speeds, PWM units
        self._history: deque[tuple[float, list[float]]] = deque()
        self._t_prev: float | None = None  # time of the last motor update
        self._t_last: float | None = None  # time of the last act/step
        self._unfelt: deque[float] = deque()  # act times whose telemetry is not felt yet
        self._keys: deque[float] = deque()  # act times whose motor update waits for PWM
        # Felt PWM waiting for its motor update; the first pose's: nothing felt (zeros).
        self._inputs: deque[list[float]] = deque([[0.0] * self._k])
        self._cue_onset: float | None = None
        self._move: dict[str, Any] | None = None
        self._next_decision: float | None = None
        self._plans = 0
        self._search: dict[str, Any] = {}
        p = self.params
        # Tremor: two independent horizontal components with random phases.
        self._tremor_phase = self._rng.uniform(0.0, 2.0 * math.pi, size=2).tolist()
        self._tremor_amp = math.radians(p.tremor_amplitude_deg)
        # Proprioception: the belief error E (world rotation vector, rad) is the person's
        # bias plus this trial's variable error; each movement adds a drift.
        v = math.radians(p.prop_trial_sd_deg)
        e = self._rng.standard_normal(3).tolist()
        b = self._prop_bias
        self._prop_err = (b[0] + v * e[0], b[1] + v * e[1], b[2] + v * e[2])
        self._trial = True

    # ------------------------------------------------------------------ perception
    def perceived(
        self, speeds: Sequence[float], noise: Sequence[float] | None = None
    ) -> list[float]:
        """Per-finger model only: the perceived strength of each motor,
        ``magnitude_i * max(0, speed_i - threshold_i)``; with ``noise`` (standard normal
        draws, one per motor) the speed carries the Weber noise of the distance reading
        (SD ``ln(1 + weber_frac) / 2`` of the whole speed)."""
        if self._sens is None:
            raise RuntimeError("perceived() needs the per-finger model (fingers=N)")
        s = [float(v) for v in speeds]
        if noise is not None:
            g = self._speed_sd()
            s = [v * (1.0 + g * float(e)) for v, e in zip(s, noise)]
        return [m * max(0.0, v - thr) for v, (thr, m) in zip(s, self._sens)]

    def _speed_sd(self) -> float:
        """SD of the perceived motor speed relative to the speed: half the log-SD of the
        amplitude (an ERM's amplitude grows with the square of its speed)."""
        return 0.5 * perception.ln_amplitude_sd(self.params.weber_frac)

    def _felt(self, speeds: Sequence[float]) -> list[bool]:
        if self._sens is None:
            return [float(v) >= 0.5 * PWM_FLOOR for v in speeds]
        return [float(v) > thr for v, (thr, _) in zip(speeds, self._sens)]

    def percept(self, speeds: Sequence[float]) -> bayes_reading.Percept | None:
        """One reading of the motor speeds (fresh noise from the trial's stream): which
        motors are felt and their levels (graspguide.participant.perception)."""
        p = self.params
        k = self._k
        normals: list[float] = self._rng.standard_normal(k).tolist()  # type: ignore[assignment]
        u = float(self._rng.uniform())
        if self._sens is None:
            gains: Sequence[float] = self._gains[:k]
            thresholds = None
        else:
            gains = [m / self._mag_ref for _, m in self._sens[:k]]
            thresholds = [thr for thr, _ in self._sens[:k]]
        return perception.perceive(
            speeds,
            normals,
            u,
            gains,
            p.weber_frac,
            p.finger_gain_sd,
            perception.miss_probabilities(p.miss_per_extra, k),
            thresholds,
        )

    def posterior(self, percept: bayes_reading.Percept) -> np.ndarray:
        """Posterior weights over the reading grid (bayes_reading.direction_grid) given
        a percept: the participant's reading of the pattern (maximum 1)."""
        p = self.params
        miss = perception.miss_probabilities(p.miss_per_extra, self._k)
        if p.reading == "learned":
            return bayes_reading.posterior_learned(
                self._contacts,
                self._y_axis,
                self.policy,
                percept,
                miss,
                int(p.familiar_examples),
                p.kernel_deg,
                self.seed,
            )
        pm = bayes_reading.pattern_map(self._contacts, self._y_axis, self.policy)
        return bayes_reading.posterior_full(pm, percept, miss)

    def felt_distance_deg(
        self, speeds: Sequence[float] | None = None, noise: Sequence[float] | None = None
    ) -> float | None:
        """Distance to the target the participant reads from the intensity [deg]; None in
        mode C (no magnitude information) or when no motor is felt."""
        self._need_trial()
        if self.mode != "V":
            return None
        s = [float(v) for v in (self._motor if speeds is None else speeds)]
        felt = self._felt(s)
        if not any(felt):
            return None
        if self._sens is not None:
            # Read on the reference finger's scale: calibrated, every finger's strength
            # is magnitude_ref * alpha * |m_i|, so L = alpha |m| / PWM_RANGE as in the
            # uniform model.
            p = [a if f else 0.0 for a, f in zip(self.perceived(s, noise), felt)]
            level = min(1.0, math.sqrt(sum(a * a for a in p)) / (self._mag_ref * PWM_RANGE))
            return math.degrees(2.0 * math.asin(level))
        if noise is not None:
            g = self._speed_sd()
            s = [v * (1.0 + g * float(e)) for v, e in zip(s, noise)]
        above = [max(v - PWM_FLOOR, 0.0) if f else 0.0 for v, f in zip(s, felt)]
        level = min(1.0, math.sqrt(sum(a * a for a in above)) / PWM_RANGE)
        return math.degrees(2.0 * math.asin(level))

    def resolution_deg(self) -> float:
        """The smallest distance a V participant can tell from the weakest vibration
        [deg]: one Weber step of the motor speed at the floor."""
        # Per-finger model: one Weber step of the speed at the reference's threshold.
        base = PWM_FLOOR if self._sens is None else self._thr_ref
        step = self._speed_sd() * base
        return math.degrees(2.0 * math.asin(min(1.0, step / PWM_RANGE)))

    def hold_s(self) -> float:
        """How long the participant means to hold a pose for the cue to stop [s]: the
        task's hold, lengthened by two SDs of its own timing noise."""
        p = self.params
        return p.task_hold_s * (1.0 + 2.0 * p.hold_cv)

    def believed_quat(self) -> tuple[float, float, float, float]:
        """Where the participant believes its hand is (proprioception, before tremor)."""
        self._need_trial()
        return qnormalize(qmul(qexp(*self._prop_err), self._qt))

    # ------------------------------------------------------------------ the loop
    def step(self, t_s: float, pwm: Sequence[int]) -> tuple[float, float, float, float]:
        """Lockstep: advance to virtual time ``t_s`` having felt ``pwm`` (the PWM of the
        previous pose's telemetry; at the first pose of a trial the PWM of the interval
        before it, normally zeros); return the pose (w, x, y, z) at ``t_s``.

        The same as ``feel(t_prev, pwm)`` followed by ``act(t_s)`` (``t_prev``: the
        previous pose's time). Mixing is allowed when every earlier act() but the last
        has been felt."""
        self._need_trial()
        t = _check_time(t_s)
        u = self._check_pwm(pwm)
        if self._t_last is not None and t < self._t_last:
            raise ValueError(f"time went backwards: {t} after {self._t_last}")
        if self._unfelt:
            if len(self._unfelt) > 1:
                raise RuntimeError(
                    "step() after act() with poses not yet felt: call feel() "
                    "for them (or use feel/act throughout)"
                )
            self._unfelt.popleft()
            self._inputs.append(u)
        elif self._t_last is None and len(self._inputs) == 1:
            self._inputs[0] = u  # the first pose: the input before it
        else:
            raise RuntimeError("step() after the last pose was already felt: call act()")
        return self._act(t)

    def feel(self, t_s: float, pwm: Sequence[int]) -> None:
        """Feel ``pwm``, the PWM of the telemetry of the pose act() gave at ``t_s``.

        Telemetry arrives late and in order: ``t_s`` must be the oldest act() time not yet
        felt. The motors see this PWM from ``t_s`` until the next pose's time (what
        ``step`` does with the PWM it is given). Validated here, once per telemetry
        (``pwm`` must be k numbers 0..255: NaN, a wrong length or a non-number raise
        ValueError)."""
        if not self._trial:
            self._need_trial()
        t = t_s if type(t_s) is float and t_s - t_s == 0.0 else _check_time(t_s)
        u = self._check_pwm(pwm)
        if not self._unfelt or t != self._unfelt[0]:
            expected = self._unfelt[0] if self._unfelt else None
            raise ValueError(
                f"feel({t}) is not for the oldest pose not yet felt "
                f"(expected t_s = {expected}); feel the poses act() gave, in "
                "order, once each"
            )
        self._unfelt.popleft()
        self._inputs.append(u)

    def act(self, t_s: float) -> tuple[float, float, float, float]:
        """The pose (w, x, y, z) at virtual time ``t_s`` (after the previous act/step time).

        **Guarantee** (docs/participant.md, "feel and act"): the pose depends on a felt
        PWM only through the motor state it produced, and a decision at ``t`` reads the
        motor state of ``t - reaction_time_s`` (the delay line) or the first-cue time
        (which moves nothing for ``3 erm_tau_s + reaction_time_s``). So act(t) depends
        only on feel() samples of poses whose *next* pose time ``s`` has
        ``s <= t - reaction_time_s`` (in particular only on samples with time
        ``< t - reaction_time_s``), and at a fixed pose rate act() may run
        :meth:`max_lead` poses ahead of the last felt pose. The result is then bit for
        bit what lockstep ``step`` gives. This is checked, not assumed: an act() whose
        result could depend on a PWM not yet felt raises :class:`FeelLagError`."""
        if not self._trial:
            self._need_trial()
        t = t_s if type(t_s) is float and t_s - t_s == 0.0 else _check_time(t_s)
        if self._t_last is not None and t < self._t_last:
            raise ValueError(f"time went backwards: {t} after {self._t_last}")
        return self._act(t)

    def max_lead(self, pose_rate_hz: float) -> int:
        """How many poses act() may run ahead of feel() at ``pose_rate_hz``: act(t_j) may
        be called once the poses up to j - max_lead have been felt. The exact bound is
        about reaction_time_s * rate + 1; this keeps two poses of margin for the rounding
        of ``t - reaction_time_s`` (floor(reaction_time_s * rate) - 1, at least 1:
        20 at 0.21 s and 100 Hz)."""
        n = int(math.floor(self.params.reaction_time_s * float(pose_rate_hz) + 1e-9)) - 1
        return max(1, n)

    def _act(self, t: float) -> tuple[float, float, float, float]:
        """act() without the argument checks (t is a float, not before the last one)."""
        self._t_last = t
        self._unfelt.append(t)
        keys, inputs = self._keys, self._inputs
        keys.append(t)
        while keys and inputs:
            self._advance(keys.popleft(), inputs.popleft())
        if keys:
            # The oldest motor update still waiting for its PWM: it must not be one this
            # pose could depend on (see act()).
            s = keys[0]
            p = self.params
            if s <= t - p.reaction_time_s or s + 3.0 * p.erm_tau_s + p.reaction_time_s <= t:
                raise FeelLagError(
                    f"act({t}) is too far ahead of feel(): the PWM of the pose before "
                    f"{s} is not felt yet and the pose at {t} could depend on it (act may "
                    f"run at most reaction_time_s = {p.reaction_time_s} s ahead)"
                )

        # 2. Decide (with the percept of reaction_time_s ago) when the last movement and
        #    its pause are over.
        if self._next_decision is not None and t >= self._next_decision and self._move is None:
            self._plan(t)

        # 3. Execute the current submovement (minimum jerk).
        if self._move is not None:
            m = self._move
            tau = min(1.0, (t - m["t0"]) / m["T"]) if m["T"] > 0 else 1.0
            s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
            rx, ry, rz = m["rotvec_t"]
            self._qt = qmul(qexp(rx * s, ry * s, rz * s), m["q0_t"])
            if tau >= 1.0:
                self._move = None
                self._next_decision = t + m["pause"]
                self._qt = qnormalize(self._qt)

        # 4. Tremor on top of the commanded orientation.
        q = self._qt
        if self._tremor_amp > 0:
            w = 2.0 * math.pi * self.params.tremor_frequency_hz * t
            q = qmul(
                qexp(
                    self._tremor_amp * math.sin(w + self._tremor_phase[0]),
                    self._tremor_amp * math.sin(w + self._tremor_phase[1]),
                    0.0,
                ),
                q,
            )
        return qnormalize(q)

    def _advance(self, t: float, u: list[float]) -> None:
        """The motors from the previous motor time to ``t`` with the PWM ``u`` held (the
        delay line gets the state at ``t``); the first felt cue starts the clock of the
        first decision."""
        dt = 1.0 / self.rate_hz if self._t_prev is None else t - self._t_prev
        self._t_prev = t

        # 1. ERM lag (exact discretisation of the first-order lag over dt).
        gain = 1.0 - math.exp(-dt / self.params.erm_tau_s)
        motor = [x + (v - x) * gain for x, v in zip(self._motor, u)]
        self._motor = motor
        self._history.append((t, motor))
        if self._cue_onset is None:
            while len(self._history) > 1 and self._history[1][0] <= t - self.params.reaction_time_s:
                self._history.popleft()
            if max(motor) >= 0.5 * PWM_FLOOR if self._sens is None else any(self._felt(motor)):
                # First felt cue. Relative strengths can be judged once the motors have
                # (nearly) reached their steady speed (3 tau: 95 %); the first movement
                # starts a reaction time after that percept.
                self._cue_onset = t
                self._next_decision = t + 3.0 * self.params.erm_tau_s + self.params.reaction_time_s

    def _check_pwm(self, pwm: Any) -> list[float]:
        # Fast paths: a list or tuple of k ints (TELEMETRY's) in 0..255, or of k
        # ints/floats in 0..255 (NaN fails the range test).
        if type(pwm) in (list, tuple) and len(pwm) == self._k:
            u = [float(v) for v in pwm if type(v) is int and 0 <= v <= 255]
            if len(u) == self._k:
                return u
            try:
                u = [float(v) for v in pwm if type(v) is int or type(v) is float]
            except OverflowError:
                u = []
            if len(u) == self._k and all(0.0 <= x <= 255.0 for x in u):
                return u
        return self._check_pwm_slow(pwm)

    def _check_pwm_slow(self, pwm: Any) -> list[float]:
        what = f"pwm must be {self._k} numbers 0..255"
        if isinstance(pwm, (str, bytes)) or not hasattr(pwm, "__iter__"):
            raise ValueError(f"{what}, got {pwm!r}")
        u = list(pwm)
        if len(u) != self._k:
            raise ValueError(f"pwm must have {self._k} values (one per contact), got {len(u)}")
        out = []
        for v in u:
            if isinstance(v, (bool, np.bool_)) or not isinstance(
                v, (int, float, np.integer, np.floating)
            ):
                raise ValueError(f"{what}, got {u!r}")
            x = float(v)
            if not math.isfinite(x):
                raise ValueError(f"pwm must be finite, got {u!r}")
            if not 0.0 <= x <= PWM_MAX:
                raise ValueError(f"pwm values must be in 0..255, got {u!r}")
            out.append(x)
        return out

    # ------------------------------------------------------------------ internals
    def _need_trial(self) -> None:
        if not self._trial:
            raise RuntimeError("call begin_trial() first")

    def _delayed_speeds(self, t: float) -> list[float]:
        """Motor speeds as they were reaction_time_s before t (the delay line)."""
        horizon = t - self.params.reaction_time_s
        while len(self._history) > 1 and self._history[1][0] <= horizon:
            self._history.popleft()
        return self._history[0][1]

    def _noise(self) -> list[float]:
        return self._rng.standard_normal(self._k).tolist()

    def _start_move(self, t: float, rotvec: Vec3, pause: float) -> None:
        p = self.params
        amp = norm3(rotvec)
        if amp > 0 and p.motor_noise_frac > 0:
            e = scale3(self._rng.standard_normal(3).tolist(), p.motor_noise_frac * amp)
            rotvec = (rotvec[0] + e[0], rotvec[1] + e[1], rotvec[2] + e[2])
            amp = norm3(rotvec)
        if amp > 0 and p.prop_drift_frac > 0:
            # Proprioceptive drift: the belief error grows with each movement.
            d = scale3(self._rng.standard_normal(3).tolist(), p.prop_drift_frac * amp)
            e0 = self._prop_err
            self._prop_err = (e0[0] + d[0], e0[1] + d[1], e0[2] + d[2])
        # Minimum jerk: peak speed 1.875 * amp / T <= peak_speed.
        T = 1.875 * amp / math.radians(p.peak_speed_deg_s)
        self._move = {"t0": t, "T": T, "rotvec_t": rotvec, "q0_t": self._qt, "pause": pause}

    def _hold(self, t: float, duration: float) -> None:
        self._next_decision = t + duration

    def _held_s(self) -> float:
        """One hold as the participant produces it: hold_s() with its timing noise."""
        p = self.params
        e = float(self._rng.standard_normal())
        return max(0.0, p.task_hold_s * (1.0 + 2.0 * p.hold_cv) * (1.0 + p.hold_cv * e))

    def _believed_down(self) -> Vec3:
        """Gravity in the hand frame as the participant believes it."""
        return rotate(qconj(self.believed_quat()), GRAVITY)

    def _tilt_to_align(self, d_hand: Vec3) -> tuple[Vec3, float]:
        """World rotation vector bringing the hand direction d_hand to gravity (as the
        participant believes its hand is), and its angle."""
        u = rotate(self.believed_quat(), d_hand)
        axis = cross3(u, GRAVITY)
        s = norm3(axis)
        angle = math.atan2(s, dot3(u, GRAVITY))
        if s < 1e-12:
            if angle < 1e-6:
                return (0.0, 0.0, 0.0), 0.0
            axis = (1.0, 0.0, 0.0)  # antiparallel: any horizontal axis
            s = 1.0
        return (axis[0] / s * angle, axis[1] / s * angle, axis[2] / s * angle), angle

    def _plan(self, t: float) -> None:
        p = self.params
        speeds = self._delayed_speeds(t)
        if not any(self._felt(speeds)):  # nothing felt (cue over): stay
            self._hold(t, p.reaction_time_s)
            return
        first = self._plans == 0
        self._plans += 1
        if first:
            percept = self.percept(speeds)
            if percept is None:  # cannot happen: a motor is felt
                self._hold(t, p.reaction_time_s)
                return
            w = self.posterior(percept)
            if self.mode == "C":
                self._begin_search(w)
                self._plan_candidate(t)
                return
            if p.v_search == "bayes":
                self._begin_v(w)
                self._plan_v(t, speeds)
                return
            gx, gy, gz = bayes_reading.direction_grid()
            i = int(np.argmax(w))  # the most probable direction (first on ties)
            direction = (float(gx[i]), float(gy[i]), float(gz[i]))
            rotvec, angle = self._tilt_to_align(direction)
            distance = self.felt_distance_deg(speeds, self._noise())
            if distance is not None and angle > 0:
                rotvec = scale3(rotvec, math.radians(distance) / angle)
            self._start_move(t, rotvec, p.reaction_time_s + 3.0 * p.erm_tau_s)
            return
        if self.mode == "C":
            self._plan_candidate(t)
        elif p.v_search == "bayes":
            self._plan_v(t, speeds)
        else:
            distance = self.felt_distance_deg(speeds, self._noise())
            self._plan_compass(t, float(distance) if distance is not None else 0.0)

    def _random_horizontal(self) -> Vec3:
        phi = float(self._rng.uniform(0.0, 2.0 * math.pi))
        return (math.cos(phi), math.sin(phi), 0.0)

    # ------------------------------------------------------------------ mode C search
    def _begin_search(self, w: np.ndarray) -> None:
        """Mode C: the posterior weights ``w`` of the grid points and, per point, the
        posterior mass a hold there would cover (the points within the threshold)."""
        nbrs = bayes_reading.cap_neighbours(self.params.task_threshold_deg)
        wl = w.tolist()
        gain = [0.0] * len(wl)
        for i, idx in enumerate(nbrs):
            acc = 0.0
            for j in idx.tolist():
                acc += wl[j]
            gain[i] = acc
        self._search = {
            "w": wl,
            "gain": np.array(gain),
            "covered": np.zeros(len(wl), dtype=bool),
            "nbrs": nbrs,
            "phase": "start",
            "holds": 0,
        }

    def _plan_candidate(self, t: float) -> None:
        """Mode C. After a hold: the grid points within the threshold of where the
        participant believes the hand pointed are covered (their mass leaves every
        neighbour's gain). Then the next pose: the point with the most uncovered posterior
        mass per second of hold and travel (travel: minimum-jerk time over the chord from
        the believed current direction, a small-angle stand-in for the angle); a
        movement there, then a hold. After a movement: the hold."""
        st = self._search
        p = self.params
        if st["phase"] == "moving":
            # The movement is over: hold (the device ends the trial itself on success).
            st["phase"] = "holding"
            st["holds"] += 1
            self._hold(t, self._held_s())
            return
        if st["phase"] == "holding":
            self._cover(self._believed_down())
        gx, gy, gz = bayes_reading.direction_grid()
        d = self._believed_down()
        cx, cy, cz = gx - d[0], gy - d[1], gz - d[2]
        chord = np.sqrt(cx * cx + cy * cy + cz * cz)
        cost = self.hold_s() + chord * (1.875 / math.radians(p.peak_speed_deg_s))
        gain = st["gain"]
        score = np.where(gain > 1e-12, gain, 0.0) / cost
        i = int(np.argmax(score))  # first on ties
        if not score[i] > 0:  # everything covered: start over
            self._begin_search(np.array(st["w"]))
            self._search["holds"] = st["holds"]
            i = int(np.argmax(self._search["gain"] / cost))
        rotvec, _ = self._tilt_to_align((float(gx[i]), float(gy[i]), float(gz[i])))
        self._search["phase"] = "moving"
        self._start_move(t, rotvec, 0.0)

    def _cover(self, d: Vec3) -> None:
        st = self._search
        gx, gy, gz = bayes_reading.direction_grid()
        c = math.cos(math.radians(self.params.task_threshold_deg))
        inside = (gx * d[0] + gy * d[1] + gz * d[2] >= c) & ~st["covered"]
        new = np.nonzero(inside)[0].tolist()
        st["covered"][new] = True
        gain, w, nbrs = st["gain"], st["w"], st["nbrs"]
        for q in new:
            idx = nbrs[q]
            gain[idx] = gain[idx] - w[q]

    # ------------------------------------------------------------------ mode V search
    def _begin_v(self, w: np.ndarray) -> None:
        """Mode V (bayes): the log-posterior over the grid, from the pattern's reading."""
        self._search = {
            "logpost": np.array([math.log(x) if x > 0 else -math.inf for x in w.tolist()]),
            "holding": False,
        }

    def _best_cap(self) -> int:
        """Mode V (bayes): the grid point whose threshold cap holds the most posterior
        mass (the posterior within 20 nats of its maximum; ties: the lowest index)."""
        st = self._search
        lp = st["logpost"]
        top = float(lp.max())
        if not top > -math.inf:  # everything ruled out: start over, the prior alone
            st["logpost"] = lp = np.zeros(len(lp))
            top = 0.0
        idx = np.nonzero(lp > top - 20.0)[0]
        w = np.zeros(len(lp))
        # math.exp, not np.exp: numpy's SIMD exp may differ in the last bit between CPUs.
        w[idx] = [math.exp(v - top) for v in lp[idx].tolist()]
        # The caps are symmetric (j covers c iff c covers j): cap c holds the sum of w
        # over its own neighbours; argmax takes the lowest index among ties.
        mass = bayes_reading.cap_matrix(self.params.task_threshold_deg) @ w
        return int(np.argmax(mass))

    def _plan_v(self, t: float, speeds: Sequence[float]) -> None:
        """Mode V (bayes). Each decision: read the overall intensity at the pose the
        participant believes it holds, ``L = |speed - 70| / 185`` (= sin(error / 2) on the
        device, with the Weber noise on the speeds), and add its log-likelihood to the
        posterior: for a target t the predicted level is sin(angle / 2) = |u - t| / 2, u
        the believed down direction (hand frame), with SD the speed noise at that level,
        ``h (70 + 185 L) / 185``. After a hold that did not stop the cue the targets within
        the threshold of u are ruled out (as in mode C). Then the grid point whose
        threshold cap holds the most posterior mass: if it is within the threshold of u,
        hold; if it is nearer than the felt distance, turn it down and hold it on arrival;
        else turn toward it by the felt distance and feel again after
        ``3 erm_tau_s + reaction_time_s``."""
        p = self.params
        st = self._search
        if st.get("arrived"):
            # At the point chosen, reached in full: hold it (the hold is the test).
            st["arrived"] = False
            st["holding"] = True
            self._hold(t, self._held_s())
            return
        gx, gy, gz = bayes_reading.direction_grid()
        u = self._believed_down()
        cx, cy, cz = gx - u[0], gy - u[1], gz - u[2]
        half_chord = 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
        if st["holding"]:
            c = math.cos(math.radians(p.task_threshold_deg))
            st["logpost"] = np.where(
                gx * u[0] + gy * u[1] + gz * u[2] >= c, -math.inf, st["logpost"]
            )
            st["holding"] = False
        distance = self.felt_distance_deg(speeds, self._noise())
        if distance is not None:
            level = math.sin(math.radians(distance) / 2.0)
            sd = self._speed_sd() * (PWM_FLOOR + PWM_RANGE * level) / PWM_RANGE
            r = (half_chord - level) / max(sd, 1e-3)
            st["logpost"] = st["logpost"] - 0.5 * (r * r)
        i = self._best_cap()
        if float(half_chord[i]) <= math.sin(math.radians(p.task_threshold_deg) / 2.0):
            st["holding"] = True
            self._hold(t, self._held_s())
            return
        rotvec, angle = self._tilt_to_align((float(gx[i]), float(gy[i]), float(gz[i])))
        if distance is not None and angle > math.radians(distance) > 0:
            # Toward it, as far as the felt distance: the target lies about that far away.
            rotvec = scale3(rotvec, math.radians(distance) / angle)
            self._start_move(t, rotvec, p.reaction_time_s + 3.0 * p.erm_tau_s)
            return
        st["arrived"] = True
        self._start_move(t, rotvec, 0.0)

    def _plan_compass(self, t: float, distance: float) -> None:
        """Mode V: warmer/colder compass search with the felt distance.

        From the best pose known (the base, as the participant believes it) the
        participant tilts by ``step`` about a horizontal axis. Warmer (the vibration is
        weaker than at the base): that pose becomes the base and it tilts on the same
        way. Colder: it goes back to the base, feels it again (readings at the base are
        averaged) and tries the next direction (+90, -90, 180 degrees from the last good
        one); after four failures in a row the step halves. At a base as faint as it can
        tell from the weakest vibration it holds for the hold the task needs.
        """
        p = self.params
        st = self._search
        res = self.resolution_deg()
        pause = p.reaction_time_s + 3.0 * p.erm_tau_s
        qb = self.believed_quat()
        if "base_q" not in st:
            # Right after the first move: this pose is the first base.
            st.update(
                base_q=qb,
                base_sum=distance,
                base_n=1,
                axis=self._random_horizontal(),
                tries=0,
                step=max(distance, res),
                at_base=True,
                held=False,
            )
        elif st["at_base"]:
            st["base_sum"] += distance  # felt the base again
            st["base_n"] += 1
        else:
            base_val = st["base_sum"] / st["base_n"]
            if distance < base_val:  # warmer: new base, same direction
                st.update(
                    base_q=qb,
                    base_sum=distance,
                    base_n=1,
                    tries=0,
                    step=max(distance, res),
                    held=False,
                )
            else:  # colder: back to the base
                st["tries"] += 1
                turn = (0.5 * math.pi, math.pi, -0.5 * math.pi, math.pi)[(st["tries"] - 1) % 4]
                a = st["axis"]
                c, s = math.cos(turn), math.sin(turn)
                st["axis"] = (c * a[0] - s * a[1], s * a[0] + c * a[1], 0.0)
                if st["tries"] % 4 == 0:
                    st["step"] = max(0.5 * st["step"], 0.5 * res)
                st["at_base"] = True
                delta = rotvec_from_quat(qmul(st["base_q"], qconj(qb)))
                self._start_move(t, delta, pause)
                return
        base_val = st["base_sum"] / st["base_n"]
        if st["at_base"] and base_val <= res and not st["held"]:
            # As faint as it can tell from the weakest vibration: hold for the cue to stop.
            st["held"] = True
            self._hold(t, self._held_s())
            return
        target = qmul(qexp(*scale3(st["axis"], math.radians(st["step"]))), st["base_q"])
        delta = rotvec_from_quat(qmul(target, qconj(qb)))
        st["at_base"] = False
        self._start_move(t, delta, pause)


# --------------------------------------------------------------------------------------
# --source participant[:key=val,...]
# --------------------------------------------------------------------------------------
def parse_spec(spec: str) -> ParticipantParams:
    """ParticipantParams from ``participant``, ``participant:key=val,key=val`` or the part
    after ``participant:`` alone (``""``: the defaults). ``fingers=N`` is not a parameter
    of the movement model: :meth:`VirtualParticipant.from_spec` takes it."""
    params, fingers = _parse_spec(spec)
    if fingers is not None:
        raise ValueError(
            "participant spec key 'fingers' selects the per-finger model; "
            "use VirtualParticipant.from_spec for it"
        )
    return params


def _parse_spec(spec: str) -> tuple[ParticipantParams, int | None]:
    """(ParticipantParams, the fingers=N seed or None) from a participant spec."""
    params, fingers, _ = _parse_spec_keys(spec)
    return params, fingers


def _parse_spec_keys(spec: str) -> tuple[ParticipantParams, int | None, dict[str, Any]]:
    """(ParticipantParams, the fingers=N seed or None, the keys given) from a spec."""
    names = [f.name for f in fields(ParticipantParams)]
    usage = (
        "expected 'participant' or 'participant:key=value,...' with keys "
        + ", ".join(names)
        + ", fingers (an integer seed: the calibration's simulated person)"
    )
    if not isinstance(spec, str):
        raise ValueError(f"participant spec must be a string; {usage}")
    head, sep, rest = spec.partition(":")
    if head.strip() != "participant":
        # Also accepted: what follows 'participant:' alone ('' = the defaults).
        head, sep, rest = "participant", (":" if spec.strip() else ""), spec
    values: dict[str, Any] = {}
    fingers: int | None = None
    if sep:
        if not rest.strip():
            raise ValueError(f"participant spec {spec!r} has ':' but no key=value; {usage}")
        for item in rest.split(","):
            key, eq, val = item.partition("=")
            key = key.strip()
            if not eq:
                raise ValueError(f"participant spec item {item!r} is not key=value; {usage}")
            if key == "fingers":
                if fingers is not None:
                    raise ValueError("participant parameter 'fingers' given twice")
                try:
                    fingers = int(val.strip())
                except ValueError:
                    raise ValueError(
                        f"participant parameter fingers={val.strip()!r} must be an integer "
                        "seed (the N of calibrate --source participant:seed=N)"
                    ) from None
                continue
            if key not in names:
                raise ValueError(
                    f"unknown participant parameter {key!r}; known: "
                    + ", ".join(names)
                    + ", fingers"
                )
            if key in values:
                raise ValueError(f"participant parameter {key!r} given twice")
            if key in _STR_FIELDS:
                values[key] = val.strip()
                continue
            try:
                x = float(val)
            except ValueError:
                raise ValueError(
                    f"participant parameter {key}={val.strip()!r} is not a number"
                ) from None
            values[key] = x
    params = ParticipantParams(**values)
    _validate_params(params)
    return params, fingers, values


__all__ = [
    "ParticipantParams",
    "VirtualParticipant",
    "FeelLagError",
    "parse_spec",
    "quaternion_angle_deg",
    "PWM_FLOOR",
    "PWM_RANGE",
]
