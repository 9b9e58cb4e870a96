"""The physical world of a simulated host-less study, as a stream: the hand's orientation
at each sample time in, the reading of the IMU on the back of the hand out. SIMULATED:
a model, never a measurement.

The physics is graspguide.imu.synthetic's (the streams the estimator was compared on),
evaluated one sample at a time:

* gyroscope: the constant body rate that turns the previous orientation into this one
  over the sample interval, plus the stated bias and white noise;
* accelerometer: specific force ``R^T (a - g)`` (at rest it reads +9.80665 m/s^2 up),
  with the arm's smooth random translation and the IMU's lever arm about the wrist, plus
  white noise.

The noise figures are :class:`graspguide.imu.synthetic.ImuNoise`'s (MPU-6050-like by
default), drawn from a seeded generator. The IMU's own axes differ from the hand's by
the mounting ``imu_to_hand_wxyz`` (the rotation taking IMU axes to hand axes, as the plan
declares it): ``v_imu = R(imu_to_hand)^T v_hand``. Bias and noise live in the IMU's axes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from graspguide.imu.synthetic import (
    ArmTranslation,
    ImuNoise,
    accel_noise_sigma_mps2,
    gyro_noise_sigma_radps,
    interval_rates,
    lever_arm_accel,
    rotation_matrices,
    specific_force_hand,
)

#: A quaternion further than this from unit length is refused rather than normalised: it
#: is a wrong value, not a rounding error.
UNIT_QUAT_TOLERANCE = 1e-3


def unit_quaternion(q: Sequence[float], what: str) -> np.ndarray:
    """``q`` (w, x, y, z) as a unit numpy vector; ValueError naming ``what`` when it is not
    four finite numbers of length 1 (within UNIT_QUAT_TOLERANCE)."""
    try:
        w, x, y, z = (float(c) for c in q)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be four numbers (w, x, y, z), got {q!r}") from None
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not math.isfinite(n):
        raise ValueError(f"{what} must be four finite numbers (w, x, y, z), got {q!r}")
    if abs(n - 1.0) > UNIT_QUAT_TOLERANCE:
        raise ValueError(f"{what} must be a unit quaternion (w, x, y, z), got length {n:.6g}")
    return np.array([w / n, x / n, y / n, z / n])


@dataclass(frozen=True)
class ImuSample:
    """One IMU reading in the IMU's axes. SIMULATED."""

    time_s: float
    accel_mps2: tuple[float, float, float]
    gyro_radps: tuple[float, float, float]


class ImuWorld:
    """The IMU on a simulated hand, sampled at ``rate_hz`` (which sets the noise per
    sample). Call :meth:`sample` once per sample time, in increasing time, with the hand's
    orientation (hand -> world, w, x, y, z) at that time. The first sample has no
    predecessor: it reads no rotation."""

    SIMULATED = True

    def __init__(
        self,
        rate_hz: float,
        seed: int,
        noise: ImuNoise | None = None,
        imu_to_hand_wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    ):
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(
                f"rate_hz must be a positive number of samples per second, got {rate_hz!r}"
            )
        self.rate_hz = float(rate_hz)
        self.noise = noise or ImuNoise()
        # White noise of the part's bandwidth at its sample rate (rate / 2).
        self._accel_sigma_mps2 = accel_noise_sigma_mps2(self.noise, self.rate_hz)
        self._gyro_sigma_radps = gyro_noise_sigma_radps(self.noise, self.rate_hz)
        mount = unit_quaternion(imu_to_hand_wxyz, "imu_to_hand_wxyz")
        self._to_imu = rotation_matrices(mount[None])[0].T  # hand axes -> IMU axes
        self._rng = np.random.default_rng(seed)
        self._arm = ArmTranslation.draw(self._rng, self.noise.translation_accel_rms_mps2)
        self._gyro_bias_radps = np.radians(np.asarray(self.noise.gyro_bias_dps, dtype=float))
        self._t_prev: float | None = None
        self._rot_prev: np.ndarray | None = None
        self._omega_prev = np.zeros((1, 3))

    def sample(self, t_s: float, quat_wxyz: Sequence[float]) -> ImuSample:
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"sample time must be finite, got {t_s!r}")
        rot = rotation_matrices(unit_quaternion(quat_wxyz, "hand orientation")[None])
        if self._t_prev is None or self._rot_prev is None:
            dt = 0.0
            omega = np.zeros((1, 3))
        else:
            dt = t - self._t_prev
            if not dt > 0:
                raise ValueError(f"sample times must increase: {t!r} s after {self._t_prev!r} s")
            omega = interval_rates(self._rot_prev, rot, dt)
        alpha = (omega - self._omega_prev) / dt if dt > 0 else np.zeros((1, 3))
        accel_hand = specific_force_hand(
            rot, self._arm.accel_world_mps2(np.array([t]))
        ) + lever_arm_accel(omega, alpha, self.noise)
        accel = self._to_imu @ accel_hand[0] + self._rng.normal(0.0, self._accel_sigma_mps2, 3)
        gyro = (
            self._to_imu @ omega[0]
            + self._gyro_bias_radps
            + self._rng.normal(0.0, self._gyro_sigma_radps, 3)
        )
        self._t_prev, self._rot_prev, self._omega_prev = t, rot, omega
        return ImuSample(
            t,
            (float(accel[0]), float(accel[1]), float(accel[2])),
            (float(gyro[0]), float(gyro[1]), float(gyro[2])),
        )


#: No noise, bias, translation or lever arm: the ideal IMU (for checks of the geometry).
IDEAL_IMU = ImuNoise(
    gyro_noise_dps_rthz=0.0,
    accel_noise_ug_rthz=0.0,
    gyro_bias_dps=(0.0, 0.0, 0.0),
    translation_accel_rms_mps2=0.0,
    lever_arm_m=(0.0, 0.0, 0.0),
)

__all__ = ["ImuWorld", "ImuSample", "IDEAL_IMU", "unit_quaternion"]
