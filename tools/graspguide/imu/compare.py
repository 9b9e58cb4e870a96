"""The device's gravity estimator against VQF (Laidig & Seel) and x-io Fusion on the same
synthetic IMU streams: the gravity-direction error (degrees) during guidance motion.

Each estimator starts from nothing at the stream's first sample and sees the same noisy,
biased samples; the error is the angle between its unit gravity (hand frame) and the true
one, over the samples after the rest (ImuStream.scored).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from graspguide.core import _core
from graspguide.imu.synthetic import STANDARD_GRAVITY_MPS2, ImuStream

#: The estimator's goal during guidance motion [deg].
GOAL_RMS_DEG = 1.0
GOAL_MAX_DEG = 3.0


def gravity_from_quaternions(q: np.ndarray) -> np.ndarray:
    """R(q)^T (0, 0, -1) for sensor -> earth quaternions [w, x, y, z] with z up (VQF's
    earth frame and Fusion's NWU): gravity in the sensor frame, pointing down."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return -np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])


def ours(
    stream: ImuStream,
    scalar: str = "float",
    gains: tuple[float, float, float] | None = None,
) -> np.ndarray:
    est = _core.GravityEstimator(scalar)
    if gains is not None:
        status = est.configure(*gains)
        if status != "ok":
            raise ValueError(f"gains {gains} refused: {status} (kp, ki >= 0, gate > 0)")
    return np.array(est.run(stream.accel_mps2.tolist(), stream.gyro_radps.tolist(), stream.dt_s))


def vqf_estimate(stream: ImuStream) -> np.ndarray:
    """VQF with its defaults (rest and motion bias estimation on), 6D (no magnetometer)."""
    from vqf import VQF  # type: ignore[import-untyped]

    f = VQF(stream.dt_s)
    out = f.updateBatch(
        np.ascontiguousarray(stream.gyro_radps), np.ascontiguousarray(stream.accel_mps2)
    )
    return gravity_from_quaternions(out["quat6D"])


def fusion_estimate(stream: ImuStream) -> np.ndarray:
    """x-io Fusion's AHRS with its defaults and its gyroscope bias (offset) correction, as
    its examples use them: gyro in deg/s, accelerometer in g."""
    import imufusion

    rate = float(stream.rate_hz)
    bias_settings = imufusion.BiasSettings()
    bias_settings.sample_rate = rate
    bias = imufusion.Bias()
    bias.set_settings(bias_settings)
    settings = imufusion.AhrsSettings()  # gain 0.5, NWU: Fusion's defaults
    settings.gyroscope_range = 2000.0
    settings.acceleration_rejection = 10.0
    settings.rejection_timeout = 5.0 * rate
    settings.sample_rate = rate
    ahrs = imufusion.Ahrs()
    ahrs.set_settings(settings)
    gyro_dps = np.degrees(stream.gyro_radps)
    accel_g = stream.accel_mps2 / STANDARD_GRAVITY_MPS2
    quats = np.empty((len(gyro_dps), 4))
    for i in range(len(gyro_dps)):
        ahrs.update_no_magnetometer(bias.update(gyro_dps[i]), accel_g[i])
        quats[i] = ahrs.get_quaternion()
    return gravity_from_quaternions(quats)


ESTIMATORS: dict[str, Callable[[ImuStream], np.ndarray]] = {
    "ours": ours,
    "vqf": vqf_estimate,
    "imufusion": fusion_estimate,
}


def errors_deg(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Angle between unit rows, accurate near 0 (atan2 of |cross| and dot)."""
    e = estimate / np.linalg.norm(estimate, axis=1, keepdims=True)
    cross = np.linalg.norm(np.cross(e, truth), axis=1)
    return np.degrees(np.arctan2(cross, np.einsum("ij,ij->i", e, truth)))


def score(stream: ImuStream, estimate: np.ndarray) -> dict[str, float]:
    err = errors_deg(estimate, stream.gravity_true)[stream.scored]
    return {
        "rms_deg": float(math.sqrt(float(np.mean(err**2)))),
        "max_deg": float(err.max()),
        "p99_deg": float(np.percentile(err, 99)),
    }


def compare(
    streams: Sequence[ImuStream], names: Sequence[str] = tuple(ESTIMATORS)
) -> dict[str, dict[str, dict[str, float]]]:
    """stream name -> estimator -> {rms_deg, max_deg, p99_deg}."""
    return {s.name: {n: score(s, ESTIMATORS[n](s)) for n in names} for s in streams}


def format_table(result: dict[str, dict[str, dict[str, float]]]) -> str:
    names = list(next(iter(result.values())))
    head = "| stream (SIMULATED) | " + " | ".join(f"{n} RMS / max [deg]" for n in names) + " |"
    lines = [head, "|---" * (len(names) + 1) + "|"]
    for stream, row in result.items():
        cells = [f"{row[n]['rms_deg']:.3f} / {row[n]['max_deg']:.3f}" for n in names]
        lines.append(f"| {stream} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def to_json(result: dict[str, Any], streams: Sequence[ImuStream]) -> str:
    meta = {
        s.name: {"rate_hz": s.rate_hz, "samples": len(s.scored), "noise": vars(s.noise)}
        for s in streams
    }
    return json.dumps(
        {
            "simulated": True,
            "goal": {"rms_deg": GOAL_RMS_DEG, "max_deg": GOAL_MAX_DEG},
            "streams": meta,
            "errors": result,
        },
        indent=2,
    )
