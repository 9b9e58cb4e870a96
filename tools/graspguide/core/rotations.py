"""Quaternions [w, x, y, z] (Hamilton product, active rotations, hand -> world as in
POSE), written once for the whole package.

Two layers with the same arithmetic: plain-float tuples (:func:`qmul`, :func:`qexp`,
:func:`rotate`, ...) for the virtual participant's per-step path, where numpy's call
overhead would dominate, and numpy arrays (:func:`quat_mul`, :func:`quat_to_matrix`,
:func:`slerp`, ...) for the sources, the reference and the generators. The golden closed
loops and the known answers depend on the exact operation order here: change none of it
without regenerating them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

Quat = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]


# --------------------------------------------------------------------------------------
# Plain floats
# --------------------------------------------------------------------------------------
def qmul(a: Sequence[float], b: Sequence[float]) -> Quat:
    """The Hamilton product a b."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def qexp(x: float, y: float, z: float) -> Quat:
    """Unit quaternion of the rotation vector (x, y, z) [rad]."""
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        n = math.sqrt(1.0 + 0.25 * angle * angle)
        return (1.0 / n, 0.5 * x / n, 0.5 * y / n, 0.5 * z / n)
    s = math.sin(0.5 * angle) / angle
    return (math.cos(0.5 * angle), x * s, y * s, z * s)


def qnormalize(q: Sequence[float]) -> Quat:
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def qconj(q: Sequence[float]) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def dot3(a: Sequence[float], b: Sequence[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def norm3(a: Sequence[float]) -> float:
    return math.sqrt(dot3(a, a))


def cross3(a: Sequence[float], b: Sequence[float]) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def scale3(a: Sequence[float], c: float) -> Vec3:
    return (a[0] * c, a[1] * c, a[2] * c)


def rotvec_from_quat(q: Sequence[float]) -> Vec3:
    """The rotation vector [rad] of q (the shorter way round)."""
    q = qnormalize(q)
    if q[0] < 0:
        q = (-q[0], -q[1], -q[2], -q[3])
    v = q[1:]
    s = norm3(v)
    if s < 1e-15:
        return scale3(v, 2.0)
    return scale3(v, 2.0 * math.atan2(s, q[0]) / s)


def rotate(q: Sequence[float], v: Sequence[float]) -> Vec3:
    """q (hand -> world, unit) applied to the hand-frame vector v."""
    w, u = q[0], q[1:]
    t = scale3(cross3(u, v), 2.0)
    c = cross3(u, t)
    return (v[0] + w * t[0] + c[0], v[1] + w * t[1] + c[1], v[2] + w * t[2] + c[2])


# --------------------------------------------------------------------------------------
# numpy
# --------------------------------------------------------------------------------------
def quat_mul(a, b) -> np.ndarray:
    """The Hamilton product a b as an array."""
    return np.array(qmul(a, b))


def quat_from_axis_angle(axis, angle_rad: float) -> np.ndarray:
    """The rotation by ``angle_rad`` about ``axis`` (any length; zero: the identity)."""
    axis = np.asarray(axis, dtype=float)
    n = np.linalg.norm(axis)
    if n < 1e-15:
        return np.array([1.0, 0.0, 0.0, 0.0])
    axis = axis / n
    return np.concatenate([[math.cos(angle_rad / 2)], math.sin(angle_rad / 2) * axis])


def quat_to_matrix(q) -> np.ndarray:
    """The rotation matrix of q (normalised here)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(m) -> np.ndarray:
    """The unit quaternion (w >= 0) of a rotation matrix."""
    m = np.asarray(m, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.array(q)
    out /= np.linalg.norm(out)
    return out if out[0] >= 0 else -out


def quat_angle_deg(a, b) -> float:
    """The rotation angle between two orientations, in degrees."""
    d = abs(float(np.dot(np.asarray(a) / np.linalg.norm(a), np.asarray(b) / np.linalg.norm(b))))
    return math.degrees(2 * math.acos(min(1.0, d)))


def slerp(a, b, u: float) -> np.ndarray:
    """The orientation a fraction ``u`` of the way from a to b (the shorter way)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 0.9995:
        q = a + u * (b - a)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - u) * th) * a + math.sin(u * th) * b) / math.sin(th)


__all__ = [
    "Quat",
    "Vec3",
    "qmul",
    "qexp",
    "qnormalize",
    "qconj",
    "dot3",
    "norm3",
    "cross3",
    "scale3",
    "rotvec_from_quat",
    "rotate",
    "quat_mul",
    "quat_from_axis_angle",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_angle_deg",
    "slerp",
]
