"""A virtual participant: a seeded model of a person following the vibrotactile cues.

SIMULATED. Everything this module produces is the output of a model; it is never human
data and must be labelled as simulated wherever it is stored or shown
(:attr:`VirtualParticipant.SIMULATED` is True for that purpose).

The model (docs/participant.md explains it with every parameter and its source):

1. **Motors (ERM lag).** The PWM of each motor (0..255, the latest telemetry) drives a
   first-order lag with time constant ``erm_tau_s``: the motor speed (in PWM units)
   approaches the commanded PWM as ``1 - exp(-t / tau)``. A motor is *felt* when its
   speed reaches half of the lowest "on" level (PWM 70, the paper's 0.9 V minimum).
2. **Delay.** Every decision uses what the motors did ``reaction_time_s`` earlier (a
   delay line on the motor states). The first movement starts ``3 erm_tau_s +
   reaction_time_s`` after the first felt cue (relative strengths can be judged once the
   motors are near their steady speed, 95 % at 3 tau), so nothing moves before the cue
   plus the reaction time; after every submovement the participant again waits
   ``3 erm_tau_s + reaction_time_s`` to feel its result (mode V).
3. **Where does the weight pull (the grasping metaphor).** Motor ``i`` vibrates with the
   contact force at contact ``i``. The thimbles that vibrate are the ones that *hold*
   the virtual object, so the weight hangs on the opposite side. The participant
   estimates the weight direction in its hand frame as

       d = -sum_i p_i * y_i / |...|,    y_i = unit(C_i - centroid)

   with ``p_i`` the perceived strength of motor ``i`` above the weakest vibration
   (``speed_i - 70``), relative to the strongest motor (so only *relative* strengths
   matter), and ``C_i`` its own contact positions. Perceived strengths carry
   multiplicative noise from the vibrotactile Weber fraction.
4. **How far (mode V only).** In mode V the overall strength above the weakest
   vibration, ``L = |speed - 70| / 185``, is ``sin(error / 2)`` on the device; the
   participant reads its distance as ``2 asin(L)`` with the noise of the Weber fraction
   applied to the whole vibration (a faint vibration cannot be told from the weakest
   one). In mode C it never uses magnitude: its decisions depend only on which motors
   vibrate and their relative strengths, so scaling every PWM above 70 by a common
   factor changes nothing.
5. **Moving.** The hand moves in discrete submovements, each a minimum-jerk rotation
   (Flash & Hogan 1985) whose duration makes its peak angular speed at most
   ``peak_speed_deg_s``; its amplitude and axis carry signal-dependent noise
   (``motor_noise_frac`` of the amplitude). Physiological tremor
   (``tremor_amplitude_deg`` at ``tremor_frequency_hz``) is added on top.
6. **Strategy.**
   * First submovement (both modes): rotate so that the estimated weight direction,
     mapped to the world through the current orientation (proprioception), points down.
     Its amplitude is the angle this implies; in mode V it is the felt distance instead.
   * Mode V, while the cue persists: a compass ("warmer/colder") search. From the best
     pose known (the base) tilt by the felt distance about a horizontal axis; if the
     vibration got weaker that pose is the new base and it tilts on the same way,
     otherwise it goes back to the base, feels it again (readings there are averaged)
     and tries the next direction (+90, -90, 180 degrees); after four failures in a row
     the step halves. At a base as faint as can be told from the weakest vibration
     (one Weber step of the motor speed at PWM 70) it holds still for ``probe_dwell_s``.
   * Mode C, while the cue persists: the pattern is constant during the whole trial (it
     depends only on the grasp, not on the orientation; paper Sec. III-A), so the only
     new information is that the cue has not stopped yet. The participant searches the
     directions around its estimate systematically, most likely first, over a hexagonal
     grid of candidate weight directions (hand frame) centred on its first estimate,
     spacing sqrt(3) * 2/3 * ``task_threshold_deg``. Each time it moves to the candidate
     not yet ruled out that is nearest to its current estimate (the mean of all its
     readings of the pattern, so the Weber noise averages out) and holds it for
     ``task_hold_s + 3 erm_tau_s + reaction_time_s`` (the hold the task needs, then the
     time to feel that the cue did not stop). A held pose rules out the candidates
     within a third of the threshold of where the hand actually pointed (their whole
     cells lie inside the threshold cone just tried); a candidate missed by motor noise
     is aimed at again. It never uses magnitude.

What it does NOT use: the device's error angle, ``alpha`` or the wrench. The wrench
passed to :meth:`VirtualParticipant.begin_trial` is validated (so a broken caller is
caught) and then discarded: the decisions depend only on the PWM felt, the participant's
own contact geometry and its own orientation.
"""

from __future__ import annotations

import functools
import hashlib
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, fields
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

# Every number a pose depends on is computed on plain Python floats with `math`, in a
# fixed order. numpy's linear algebra (norm, dot, @) runs in OpenBLAS, whose kernel -- and
# so the last bit of a sum -- is chosen by the CPU (OPENBLAS_CORETYPE), and numpy's SIMD
# sin/cos/hypot depend on the CPU's features; a closed loop turns one last-bit difference
# into a different trajectory, so a seeded study would not reproduce on another machine.
# numpy stays only for checking inputs and for the seeded random streams (PCG64 draws do
# not depend on the CPU). Left: the last bit of libm's sin/cos/exp/atan2 (glibc has an FMA
# code path). tools/tests/test_participant.py checks both: the same bits under another
# OpenBLAS kernel, and a golden record within a tolerance stated there.

PWM_FLOOR = 70  # lowest "on" PWM of the device (paper: 0.9 V), docs/algorithm.md step 6
PWM_RANGE = 185  # PWM span above the floor, docs/algorithm.md step 6
PWM_MAX = 255
GRAVITY: Vec3 = (0.0, 0.0, -1.0)


@dataclass(frozen=True)
class ParticipantParams:
    """Parameters of the virtual participant. Sources: docs/participant.md.

    Every field carries its unit in its name (``_s``, ``_deg``, ``_deg_s``, ``_hz``;
    ``_frac`` is a dimensionless fraction).
    """

    #: Pose rate the participant runs at [Hz]: a motion-capture tracking rate (the paper
    #: tracked the hand with a Vicon system; 100 Hz is a usual Vicon rate). Convention.
    #: The study runner calls step() every 1 / rate_hz s.
    rate_hz: float = 100.0
    #: ERM motor time constant [s]. Precision Microdrives' step-response test of an ERM
    #: (305-000 at rated voltage) reaches its maximum amplitude ~180 ms after turn-on;
    #: for a first-order lag that is ~3 tau, so tau ~ 60 ms (PMD, "New testing for the
    #: Precision Haptic ERMs"). The thimbles' 310-103 datasheet rise/stop times were not
    #: retrieved: replace this when read.
    erm_tau_s: float = 0.06
    #: Simple reaction time to a vibrotactile cue on the hand [s]: control values of
    #: 200-220 ms (variability 10-20 ms) for a fingertip vibrotactile reaction-time test
    #: with sub-millisecond timing (J Sci Med, josam.org/josam/article/view/31, the
    #: concussion study with the Brain Gauge); 0.21 s is the middle. Bao et al. 2019
    #: (PLOS ONE 14(8):e0219737) show stimulus factors add 20-300 ms (location 20-120 ms,
    #: a secondary task > 130 ms): raise it to model a loaded participant.
    reaction_time_s: float = 0.21
    #: Peak angular speed of a hand reorientation [deg/s]: a deliberate, comfortable
    #: wrist/forearm speed. Wrist/forearm movement in daily living is mostly slow, the
    #: likelihood of a speed falling exponentially with it (Anderton et al. 2023, J Hand
    #: Ther 36(3):580-592); maximal voluntary wrist speeds are several hundred deg/s.
    #: 90 deg/s is the standard isokinetic test speed of forearm pronation/supination
    #: (30 deg/s slow, up to ~190 deg/s achievable but hard to maintain; isokinetics.net,
    #: "Pronation and Supination"): a comfortable voluntary rotation, fixed before any
    #: study, not fitted to the paper.
    peak_speed_deg_s: float = 90.0
    #: Physiological tremor amplitude [deg]: the modal postural hand tremor is 0.01 g
    #: peak at ~7 Hz ("A normative study of postural tremor of the hand", Arch Neurol
    #: 1982;39:358-362, doi:10.1001/archneur.1982.00510180036009), i.e.
    #: 0.01 * 9.81 / (2 pi 7)^2 = 0.05 mm; over a 0.1 m wrist-to-fingertip lever that
    #: is 0.03 deg.
    tremor_amplitude_deg: float = 0.03
    #: Physiological tremor frequency [Hz]: modal ~7 Hz (Arch Neurol 1982, above), inside the
    #: 6-12 Hz peak of physiological hand tremor (Lakie et al. 2015, J Physiol
    #: 593:4411-4422).
    tremor_frequency_hz: float = 7.0
    #: Signal-dependent motor noise [fraction of the submovement amplitude, SD]: motor
    #: output noise grows in proportion to the command (Harris & Wolpert 1998, Nature
    #: 394:780-784; van Beers, Haggard & Wolpert 2004, J Neurophysiol 91:1050-1063):
    #: that form is verified (abstracts). The size, 10 % of the amplitude, was quoted
    #: from memory and no source read gives it: unverified, assumption.
    motor_noise_frac: float = 0.10
    #: Weber fraction of vibrotactile amplitude discrimination [fraction]: median
    #: difference thresholds of 0.20 (thenar eminence, 125 Hz, 10 dB above threshold) to
    #: 0.58 across conditions ("Vibrotactile difference thresholds: effects of vibration
    #: frequency, vibration magnitude, contact area, and body location"; figures and title
    #: verified, authors/year not: docs/participant.md); 0.20 is the Pacinian, ERM-like
    #: (125 Hz) case
    #: and the most favourable one. An ERM's vibration amplitude grows with the square
    #: of its speed, so the noise (SD) on the perceived motor speed is half of it.
    weber_frac: float = 0.20
    #: How long the participant holds a faint-vibration pose in mode V waiting for the
    #: cue to stop [s]. Model convention, fixed before any simulated study and not tuned
    #: toward the paper's tables (unverified, assumption).
    probe_dwell_s: float = 1.0
    #: What the participant knows of the task from its instructions and familiarization:
    #: the alignment threshold [deg] (paper Sec. IV: 3 deg) ...
    task_threshold_deg: float = 3.0
    #: ... and how long it must be held for the cue to stop [s] (paper Sec. IV: 0.5 s).
    #: Mode C uses both: candidate spacing sqrt(3) * 2/3 * task_threshold_deg (see
    #: _C_AIM_TOL) and a hold per candidate of
    #: task_hold_s + 3 erm_tau_s + reaction_time_s. Set them to the protocol's values.
    task_hold_s: float = 0.5


_NONNEG_FIELDS = ("tremor_amplitude_deg", "motor_noise_frac", "weber_frac")
_FRAC_FIELDS = ("motor_noise_frac", "weber_frac")


def _validate_params(p: ParticipantParams) -> None:
    for f in fields(p):
        v = getattr(p, f.name)
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
        fields); also just the part after ``participant:`` (``""`` for the defaults)."""
        params, fingers = _parse_spec(spec)
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
        self._qt = qnormalize(q0)  # commanded (proprioceptive) orientation
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
        self._trial = True

    # ------------------------------------------------------------------ perception
    def perceived(
        self, speeds: Sequence[float], noise: Sequence[float] | None = None
    ) -> list[float]:
        """Per-finger model only: the perceived strength of each motor,
        ``magnitude_i * max(0, speed_i - threshold_i)``; with ``noise`` (standard normal
        draws, one per motor) the speed carries the Weber noise of the uniform model's
        distance reading, SD ``weber_frac / 2`` of the whole speed."""
        if self._sens is None:
            raise RuntimeError("perceived() needs the per-finger model (fingers=N)")
        s = [float(v) for v in speeds]
        if noise is not None:
            g = 0.5 * self.params.weber_frac
            s = [v * (1.0 + g * float(e)) for v, e in zip(s, noise)]
        return [m * max(0.0, v - thr) for v, (thr, m) in zip(s, self._sens)]

    def _felt(self, speeds: Sequence[float]) -> list[bool]:
        if self._sens is None:
            return [float(v) >= 0.5 * PWM_FLOOR for v in speeds]
        return [float(v) > thr for v, (thr, _) in zip(speeds, self._sens)]

    def _direction(self, speeds: Sequence[float], noise: Sequence[float] | None) -> Vec3 | None:
        s = [float(v) for v in speeds]
        felt = self._felt(s)
        if not any(felt):
            return None
        if self._sens is None:
            above = [max(v - PWM_FLOOR, 0.0) if f else 0.0 for v, f in zip(s, felt)]
        else:
            above = self.perceived(s)
        if noise is not None:
            g = 0.5 * self.params.weber_frac
            above = [max(a * (1.0 + g * float(e)), 0.0) for a, e in zip(above, noise)]
        top = max(above)
        # Relative strength of each felt motor; all felt motors equal if none is above
        # the weakest vibration.
        w = [a / top for a in above] if top > 0 else [float(f) for f in felt]
        d = [0.0, 0.0, 0.0]
        for wi, y in zip(w, self._radial):
            d = [d[0] + wi * y[0], d[1] + wi * y[1], d[2] + wi * y[2]]
        d = [-d[0], -d[1], -d[2]]
        n = norm3(d)
        if n < 1e-9:
            return None
        return (d[0] / n, d[1] / n, d[2] / n)

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
            g = 0.5 * self.params.weber_frac
            s = [v * (1.0 + g * float(e)) for v, e in zip(s, noise)]
        above = [max(v - PWM_FLOOR, 0.0) if f else 0.0 for v, f in zip(s, felt)]
        level = min(1.0, math.sqrt(sum(a * a for a in above)) / PWM_RANGE)
        return math.degrees(2.0 * math.asin(level))

    def resolution_deg(self) -> float:
        """The smallest distance a V participant can tell from the weakest vibration
        [deg]: one Weber step of the motor speed at the floor."""
        # Per-finger model: one Weber step of the speed at the reference's threshold.
        base = PWM_FLOOR if self._sens is None else self._thr_ref
        step = 0.5 * self.params.weber_frac * base
        return math.degrees(2.0 * math.asin(min(1.0, step / PWM_RANGE)))

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
        # Minimum jerk: peak speed 1.875 * amp / T <= peak_speed.
        T = 1.875 * amp / math.radians(p.peak_speed_deg_s)
        self._move = {"t0": t, "T": T, "rotvec_t": rotvec, "q0_t": self._qt, "pause": pause}

    def _hold(self, t: float, duration: float) -> None:
        self._next_decision = t + duration

    def _tilt_to_align(self, d_hand: Vec3) -> tuple[Vec3, float]:
        """World rotation vector bringing the hand direction d_hand to gravity, and its angle."""
        u = rotate(self._qt, d_hand)
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
        direction = self._direction(speeds, self._noise())
        if direction is None:  # nothing felt (cue over): stay
            self._hold(t, p.reaction_time_s)
            return
        distance = self.felt_distance_deg(speeds, self._noise())  # None in mode C
        first = self._plans == 0
        self._plans += 1
        if first:
            rotvec, angle = self._tilt_to_align(direction)
            if distance is not None and angle > 0:
                rotvec = tuple(v / angle * math.radians(distance) for v in rotvec)
            if self.mode == "C":
                # The first candidate is the first estimate itself (the centre of the
                # candidate grid); wait there for the cue to stop.
                grid = _hex_directions(direction, _C_SPACING * p.task_threshold_deg)
                self._search = {
                    "grid": grid,
                    "readings": direction,
                    "n_readings": 1,
                    "tried": np.zeros(len(grid[0]), dtype=bool),
                }
                self._start_move(t, rotvec, self.c_dwell_s())
            else:
                self._start_move(t, rotvec, p.reaction_time_s + 3.0 * p.erm_tau_s)
            return
        if self.mode == "C":
            self._plan_candidate(t, direction)
        else:
            self._plan_compass(t, float(distance))

    def _random_horizontal(self) -> Vec3:
        phi = float(self._rng.uniform(0.0, 2.0 * math.pi))
        return (math.cos(phi), math.sin(phi), 0.0)

    def c_dwell_s(self) -> float:
        """Mode C: how long each candidate pose is held [s]: the task's hold, then the
        time to feel that the cue did not stop (ERM spin-down to 5 %, reaction time)."""
        p = self.params
        return p.task_hold_s + 3.0 * p.erm_tau_s + p.reaction_time_s

    def _plan_candidate(self, t: float, direction: Vec3) -> None:
        """Mode C: the cue did not stop, so the pose just held was wrong. Rule out the
        candidates it covered, average the new reading of the (constant) pattern into the
        estimate and move to the candidate not yet ruled out that is nearest to it (most
        likely first); the search widens as the near candidates are used up and never
        returns to a ruled-out one."""
        st = self._search
        r = st["readings"]
        r = st["readings"] = (r[0] + direction[0], r[1] + direction[1], r[2] + direction[2])
        st["n_readings"] += 1
        n = norm3(r)
        centre = (r[0] / n, r[1] / n, r[2] / n)
        grid, tried = st["grid"], st["tried"]
        # The pose just held rules out the candidates within the aim tolerance (a third
        # of the threshold) of where the hand actually pointed (proprioception): with the
        # grid's spacing their whole cells are then inside the threshold cone just tried.
        # A candidate missed by more than that (motor noise) stays untried and is aimed
        # at again, with a small, precise correction.
        down = rotate(qconj(self._qt), GRAVITY)
        tol = math.radians(_C_AIM_TOL * self.params.task_threshold_deg)
        gx, gy, gz = grid  # elementwise only: _hex_directions says why
        tried |= gx * down[0] + gy * down[1] + gz * down[2] >= math.cos(tol)
        if tried.all():  # the whole sphere tried: start over
            tried[:] = False
        cosines = np.where(tried, -np.inf, gx * centre[0] + gy * centre[1] + gz * centre[2])
        i = int(np.argmax(cosines))  # the nearest untried candidate (first on ties)
        rotvec, _ = self._tilt_to_align((float(gx[i]), float(gy[i]), float(gz[i])))
        self._start_move(t, rotvec, self.c_dwell_s())

    def _plan_compass(self, t: float, distance: float) -> None:
        """Mode V: warmer/colder compass search with the felt distance.

        From the best pose known (the base) the participant tilts by ``step`` about a
        horizontal axis. Warmer (the vibration is weaker than at the base): that pose
        becomes the base and it tilts on the same way. Colder: it goes back to the base,
        feels it again (readings at the base are averaged) and tries the next direction
        (+90, -90, 180 degrees from the last good one); after four failures in a row
        the step halves. At a base as faint as can be told from the weakest vibration
        it holds still for probe_dwell_s, waiting for the cue to stop.
        """
        p = self.params
        st = self._search
        res = self.resolution_deg()
        pause = p.reaction_time_s + 3.0 * p.erm_tau_s
        if "base_q" not in st:
            # Right after the first (metaphor) move: this pose is the first base.
            st.update(
                base_q=self._qt,
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
                    base_q=self._qt,
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
                delta = rotvec_from_quat(qmul(st["base_q"], qconj(self._qt)))
                self._start_move(t, delta, pause)
                return
        base_val = st["base_sum"] / st["base_n"]
        if st["at_base"] and base_val <= res and not st["held"]:
            # As faint as can be told from the weakest vibration: wait for it to stop.
            st["held"] = True
            self._hold(t, p.probe_dwell_s)
            return
        target = qmul(qexp(*scale3(st["axis"], math.radians(st["step"]))), st["base_q"])
        delta = rotvec_from_quat(qmul(target, qconj(self._qt)))
        st["at_base"] = False
        self._start_move(t, delta, pause)


#: Mode C, in units of the task threshold r. A held pose within the aim tolerance e of a
#: candidate rules the candidate out; a hexagonal lattice of spacing s has cells of
#: covering radius s / sqrt(3), so a cell lies wholly inside the cone of radius r around
#: the pose when s / sqrt(3) + e <= r: s = sqrt(3) (r - e). e = r / 3 (1 deg for 3 deg)
#: is about two SDs of the aiming error of a correction of one spacing with the motor
#: noise (0.1 x 3.5 deg x sqrt(2) = 0.5 deg), so most candidates are held on the first
#: aim. Fixed from that geometry, before any simulated study.
_C_AIM_TOL = 1.0 / 3.0
_C_SPACING = math.sqrt(3.0) * (1.0 - _C_AIM_TOL)


def _hex_directions(centre: Vec3, spacing_deg: float) -> tuple[np.ndarray, ...]:
    """Unit directions on a hexagonal lattice of the given spacing in the tangent plane at
    ``centre`` (mapped onto the sphere by the exponential map), sorted by their angle to
    the centre (the centre first), out to 180 degrees; as three arrays (x, y, z).

    The lattice and its sines and cosines (:func:`_hex_lattice`) are built with ``math``
    on plain floats: numpy's sin/cos depend on the CPU. Here they are only combined
    elementwise (+, *, /, sqrt), which is IEEE-exact per element, as are the search's own
    uses of the arrays (+, *, compare), so the search gives the same bits on every CPU."""
    n0 = norm3(centre)
    c = (centre[0] / n0, centre[1] / n0, centre[2] / n0)
    e1 = cross3(c, (1.0, 0.0, 0.0) if abs(c[0]) < 0.9 else (0.0, 1.0, 0.0))
    m = norm3(e1)
    e1 = (e1[0] / m, e1[1] / m, e1[2] / m)
    e2 = cross3(c, e1)
    a, b, cr, sr = _hex_lattice(spacing_deg)
    # Point p at the angle r from the centre: d = cos(r) c + sin(r) (a e1 + b e2), then
    # normalised; the centre itself (r = 0, the first point) is c.
    d = [cr * c[i] + sr * (a * e1[i] + b * e2[i]) for i in range(3)]
    for i in range(3):
        d[i][0] = c[i]
    m = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    return tuple(v / m for v in d)


@functools.lru_cache(maxsize=4)
def _hex_lattice(spacing_deg: float) -> tuple[np.ndarray, ...]:
    """The centre-independent part of :func:`_hex_directions` (every mode C trial uses the
    same spacing): the lattice points within 180 degrees in their order, as the unit
    tangent direction (a, b) of each and cos(r), sin(r) of its angle r (the centre first,
    with a = b = 0). Read-only arrays: they are shared."""
    s = math.radians(spacing_deg)
    n = int(math.ceil(math.pi / s / 0.8)) + 1
    h = math.sqrt(3.0) / 2.0
    # Point (i, j) lies at (i + j/2, j sqrt(3)/2) s, at the distance sqrt(i^2 + i j + j^2) s:
    # sorting by that integer orders the rings exactly, then by angle within a ring.
    points = sorted(
        (k, math.atan2(y, x), x, y, math.sqrt(k) * s)
        for i in range(-n, n + 1)
        for j in range(-n, n + 1)
        for k, x, y in ((i * i + i * j + j * j, (i + 0.5 * j) * s, j * h * s),)
        if math.sqrt(k) * s <= math.pi + 1e-12
    )
    rows = [
        (x / r, y / r, math.cos(r), math.sin(r)) if r > 0 else (0.0, 0.0, 1.0, 0.0)
        for _, _, x, y, r in points
    ]
    out = tuple(np.array(v, dtype=np.float64) for v in zip(*rows))
    for v in out:
        v.flags.writeable = False
    return out


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
    values: dict[str, float] = {}
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
            try:
                x = float(val)
            except ValueError:
                raise ValueError(
                    f"participant parameter {key}={val.strip()!r} is not a number"
                ) from None
            values[key] = x
    params = ParticipantParams(**values)
    _validate_params(params)
    return params, fingers


__all__ = [
    "ParticipantParams",
    "VirtualParticipant",
    "FeelLagError",
    "parse_spec",
    "quaternion_angle_deg",
    "PWM_FLOOR",
    "PWM_RANGE",
]
