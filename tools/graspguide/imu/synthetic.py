"""Synthetic 6-axis IMU streams from the virtual participant's hand (SIMULATED).

The hand's orientation comes from the virtual participant (study/participant.py) guided in
closed loop by the core, trial after trial of the paper's protocol, each trial starting
where the previous one ended, after a rest. The IMU on the back of the hand then reads:

* gyroscope: the body angular velocity that turns one pose into the next (exact over each
  sample interval), plus a constant bias and white noise;
* accelerometer: specific force ``R^T (a - g)`` with the hand's linear acceleration ``a``:
  the IMU sits ``LEVER_ARM_M`` from the wrist, about which the hand turns (tangential and
  centripetal terms), and the whole arm moves (a smooth random translation), plus white
  noise.

Every figure below is a stated assumption of this model, named with its unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from graspguide.core import _core
from graspguide.participant.model import VirtualParticipant
from graspguide.protocol.study_protocol import Protocol, draw_wrenches, load_protocol

STANDARD_GRAVITY_MPS2 = 9.80665
#: Noise densities of a common low-cost 6-axis part (InvenSense MPU-6050 datasheet:
#: gyro 0.005 deg/s/sqrt(Hz), accelerometer 400 ug/sqrt(Hz)); newer parts are quieter.
GYRO_NOISE_DPS_RTHZ = 0.005
ACCEL_NOISE_UG_RTHZ = 400.0
#: A gyro bias left after a start-up calibration (deg/s per axis): MPU-6050-class parts
#: drift by about a degree per second with temperature.
GYRO_BIAS_DPS = (0.6, -0.8, 0.4)
#: Where the IMU is from the wrist, in the hand frame [m]: the back of the hand, 8 cm out.
LEVER_ARM_M = (0.0, 0.08, 0.0)
#: The arm's own movement: a smooth random translation whose acceleration has this RMS per
#: axis [m/s^2] (a 0.2 m minimum-jerk reach in 1 s peaks at 1.15 m/s^2), in this band [Hz].
TRANSLATION_ACCEL_RMS_MPS2 = 0.5
TRANSLATION_BAND_HZ = (0.2, 2.0)
#: Rest before the first trial [s]: the host-less device waits for the button with the hand
#: still; an estimator may learn its bias here. Scored only after it.
REST_S = 10.0


@dataclass(frozen=True)
class ImuNoise:
    gyro_noise_dps_rthz: float = GYRO_NOISE_DPS_RTHZ
    accel_noise_ug_rthz: float = ACCEL_NOISE_UG_RTHZ
    gyro_bias_dps: tuple[float, float, float] = GYRO_BIAS_DPS
    translation_accel_rms_mps2: float = TRANSLATION_ACCEL_RMS_MPS2
    lever_arm_m: tuple[float, float, float] = LEVER_ARM_M


@dataclass
class ImuStream:
    """One stream: ``n`` samples at ``rate_hz``; gravity_true is unit, hand frame, down."""

    name: str
    rate_hz: float
    accel_mps2: np.ndarray  # n x 3, specific force
    gyro_radps: np.ndarray  # n x 3
    gravity_true: np.ndarray  # n x 3
    scored: np.ndarray  # n bools: the guidance motion (after the rest)
    noise: ImuNoise = field(default_factory=ImuNoise)
    SIMULATED = True

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """R(q) for unit [w, x, y, z] rows (n x 3 x 3), hand -> world."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - w * z)
    r[:, 0, 2] = 2 * (x * z + w * y)
    r[:, 1, 0] = 2 * (x * y + w * z)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - w * x)
    r[:, 2, 0] = 2 * (x * z - w * y)
    r[:, 2, 1] = 2 * (y * z + w * x)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def interval_rates(rot_from: np.ndarray, rot_to: np.ndarray, dt_s: float) -> np.ndarray:
    """The constant body angular velocity (n x 3, rad/s, body axes) that turns each
    ``rot_from`` into its ``rot_to`` in ``dt_s`` (exact over the interval)."""
    rel = np.einsum("nji,njk->nik", rot_from, rot_to)  # R_a^T R_b
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    angle = np.arccos(cos)
    vee = np.stack(
        [rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]],
        axis=1,
    )
    s = np.sin(angle)
    scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, 2 * s, 1.0), 0.5)
    return vee * scale[:, None] / dt_s


def body_rates(rot: np.ndarray, dt_s: float) -> np.ndarray:
    """The constant body angular velocity taking R_k to R_{k+1} (last row repeated)."""
    w = interval_rates(rot[:-1], rot[1:], dt_s)
    return np.vstack([w, w[-1:]])


def lever_arm_accel(omega: np.ndarray, alpha: np.ndarray, noise: ImuNoise) -> np.ndarray:
    """The IMU's acceleration from turning about the wrist (n x 3, hand frame, m/s^2):
    alpha x r + omega x (omega x r), r = ``noise.lever_arm_m``."""
    r = np.asarray(noise.lever_arm_m, dtype=float)
    return _cross(alpha, r) + _cross(omega, _cross(omega, r))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b for n x 3 rows (b may be one 3-vector): np.cross's arithmetic
    without its per-call axis handling, which dominates a one-sample stream."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


#: Sinusoids per axis in the arm's random translation.
TRANSLATION_TONES = 8


@dataclass(frozen=True)
class ArmTranslation:
    """The arm's smooth random translation: its world-frame acceleration is a sum of
    TRANSLATION_TONES sinusoids per axis across TRANSLATION_BAND_HZ, scaled to the stated
    RMS per axis. Draws its frequencies and phases (in that order) from ``rng``."""

    freqs_hz: np.ndarray  # 3 x TRANSLATION_TONES
    phases: np.ndarray  # 3 x TRANSLATION_TONES
    rms_mps2: float

    @classmethod
    def draw(cls, rng: np.random.Generator, rms_mps2: float) -> ArmTranslation:
        lo, hi = TRANSLATION_BAND_HZ
        freqs = rng.uniform(lo, hi, size=(3, TRANSLATION_TONES))
        phases = rng.uniform(0, 2 * math.pi, size=(3, TRANSLATION_TONES))
        return cls(freqs, phases, float(rms_mps2))

    def accel_world_mps2(self, t_s: np.ndarray) -> np.ndarray:
        """Acceleration at the times ``t_s`` (n) -> n x 3, world frame."""
        t = np.asarray(t_s, dtype=float).reshape(-1)
        a = np.sin(2 * math.pi * self.freqs_hz[None] * t[:, None, None] + self.phases[None]).sum(
            axis=2
        )
        return a * (self.rms_mps2 / math.sqrt(TRANSLATION_TONES / 2))


GRAVITY_WORLD_MPS2 = np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2])


def specific_force_hand(rot: np.ndarray, accel_world_mps2: np.ndarray) -> np.ndarray:
    """What an ideal accelerometer on the hand reads (n x 3, hand frame): R^T (a - g)."""
    return np.einsum("nji,nj->ni", rot, accel_world_mps2 - GRAVITY_WORLD_MPS2)


def accel_noise_sigma_mps2(noise: ImuNoise, rate_hz: float) -> float:
    """White accelerometer noise per sample at ``rate_hz`` (bandwidth rate / 2)."""
    return noise.accel_noise_ug_rthz * 1e-6 * STANDARD_GRAVITY_MPS2 * math.sqrt(rate_hz / 2)


def gyro_noise_sigma_radps(noise: ImuNoise, rate_hz: float) -> float:
    """White gyroscope noise per sample at ``rate_hz`` (bandwidth rate / 2)."""
    return math.radians(noise.gyro_noise_dps_rthz) * math.sqrt(rate_hz / 2)


def participant_poses(
    protocol: Protocol, seed: int, rate_hz: float, duration_s: float, modality: str, k: int
) -> np.ndarray:
    """Hand orientations [w, x, y, z] at ``rate_hz`` for ``duration_s``: a rest, then the
    virtual participant guided by the core through the protocol's wrenches, in one
    modality, each trial starting where the last ended."""
    policy, mode = modality.split("+")
    vp = VirtualParticipant.from_spec(f"participant:rate_hz={rate_hz}", seed)
    contacts = [list(c) for c in protocol.hands[k]]
    guide = _core.Guidance()
    status = guide.set_scene(contacts, policy=policy, mode=mode, y_axis=list(protocol.y_axis))
    if status != "ok":
        raise ValueError(f"the protocol's k={k} hand is refused by the core: {status}")
    wrenches = [w.wrench for w in draw_wrenches(protocol)]
    n = int(round(duration_s * rate_hz))
    n_rest = int(round(REST_S * rate_hz))
    q = np.array(protocol.start_quat, dtype=float)
    poses = [q] * min(n_rest, n)
    trial = 0
    while len(poses) < n:
        wrench = list(wrenches[trial % len(wrenches)])
        trial += 1
        if guide.set_wrench(wrench) != "ok":
            continue
        vp.begin_trial(
            contacts=contacts,
            y_axis=list(protocol.y_axis),
            wrench=wrench,
            policy=policy,
            mode=mode,
            start_quat=list(q),
            noise_seed=seed * 1000 + trial,
        )
        held_from = None
        for i in range(int(protocol.timeout_s * rate_hz)):
            res = guide.update(list(q))
            t = i / rate_hz
            if res["status"] == "ok" and res["error_deg"] <= protocol.threshold_deg:
                held_from = t if held_from is None else held_from
                if t - held_from >= protocol.hold_s:
                    break
            else:
                held_from = None
            q = np.array(vp.step(t, res["pwm"]))
            poses.append(q)
            if len(poses) >= n:
                break
    out = np.array(poses[:n])
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def sweep_poses(rate_hz: float, duration_s: float, peak_dps: float = 90.0) -> np.ndarray:
    """A harder reference motion than guidance: after the rest, the hand swings back and
    forth between 0 and 120 deg about a tilted axis with a peak speed of ``peak_dps``, for the whole
    stream."""
    n = int(round(duration_s * rate_hz))
    t = np.arange(n) / rate_hz
    amp = math.radians(60.0)
    freq = math.radians(peak_dps) / (2 * math.pi * amp)
    moving = np.clip(t - REST_S, 0.0, None)
    # 1 - cos: the swing starts from rest, so the first step is no infinite acceleration.
    angle = amp * (1.0 - np.cos(2 * math.pi * freq * moving))
    angle[t < REST_S] = 0.0
    axis = np.array([1.0, 0.5, 0.3]) / np.linalg.norm([1.0, 0.5, 0.3])
    return np.column_stack([np.cos(angle / 2), np.outer(np.sin(angle / 2), axis)])


def imu_from_poses(
    name: str, poses: np.ndarray, rate_hz: float, seed: int, noise: ImuNoise | None = None
) -> ImuStream:
    """The IMU readings for ``poses`` (n x 4, [w, x, y, z], hand -> world) at ``rate_hz``."""
    noise = noise or ImuNoise()
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    n = len(poses)
    rot = rotation_matrices(poses)
    omega = body_rates(rot, dt)
    alpha = np.gradient(omega, dt, axis=0)
    t = np.arange(n) * dt
    arm = ArmTranslation.draw(rng, noise.translation_accel_rms_mps2)
    accel = specific_force_hand(rot, arm.accel_world_mps2(t)) + lever_arm_accel(omega, alpha, noise)
    accel += rng.normal(0.0, accel_noise_sigma_mps2(noise, rate_hz), (n, 3))
    gyro = omega + np.radians(noise.gyro_bias_dps)
    gyro += rng.normal(0.0, gyro_noise_sigma_radps(noise, rate_hz), (n, 3))
    g_true = -rot[:, 2, :]  # R^T (0, 0, -1)
    scored = t >= REST_S
    return ImuStream(name, rate_hz, accel, gyro, g_true, scored, noise)


#: The streams of the comparison: (name, source, rate_hz, modality, k).
STREAMS = (
    ("participant-F+V-k4-100Hz", "participant", 100.0, "F+V", 4),
    ("participant-Fperp+C-k3-100Hz", "participant", 100.0, "Fperp+C", 3),
    ("participant-F+V-k4-200Hz", "participant", 200.0, "F+V", 4),
    ("sweep-90dps-100Hz", "sweep", 100.0, "", 0),
)
DURATION_S = 60.0


def make_streams(
    protocol_path: str = "protocols/paper.toml",
    seed: int = 1,
    duration_s: float = DURATION_S,
    noise: ImuNoise | None = None,
) -> list[ImuStream]:
    protocol = load_protocol(protocol_path)
    out = []
    for i, (name, source, rate, modality, k) in enumerate(STREAMS):
        if source == "participant":
            poses = participant_poses(protocol, seed + i, rate, duration_s, modality, k)
        else:
            poses = sweep_poses(rate, duration_s)
        out.append(imu_from_poses(name, poses, rate, seed * 100 + i, noise))
    return out
