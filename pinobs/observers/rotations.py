"""Unit quaternions ``(x, y, z, w)`` and rotation matrices, converted both ways in scalar
arithmetic (the contact-aided filters' estimates, every sample; re-exported by
:mod:`pinobs.observers.legs`)."""

from __future__ import annotations

import math

import numpy as np

from pinobs.observers.base import Vector

__all__ = ["quaternion_to_rotation", "rotation_to_quaternion"]


def rotation_to_quaternion(R: Vector) -> Vector:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix, ``w ≥ 0`` (SciPy's convention).

    Shepperd's method (J. Guidance Control 1978): from the largest of ``4w² = 1 + tr R``
    and ``4x² = 1 + 2R₀₀ − tr R`` (…), so no division by a small number; 20× cheaper
    than SciPy's ``Rotation.from_matrix`` per call (which cost 40 % of an update)."""
    r = R.tolist()
    (a, b, c), (d, e, f), (g, h, i) = r
    tr = a + e + i
    if tr >= a and tr >= e and tr >= i:
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        k = 0.25 / w
        q = [(h - f) * k, (c - g) * k, (d - b) * k, w]
    elif a >= e and a >= i:
        x = 0.5 * math.sqrt(max(1.0 + a - e - i, 0.0))
        k = 0.25 / x
        q = [x, (b + d) * k, (c + g) * k, (h - f) * k]
    elif e >= i:
        y = 0.5 * math.sqrt(max(1.0 - a + e - i, 0.0))
        k = 0.25 / y
        q = [(b + d) * k, y, (f + h) * k, (c - g) * k]
    else:
        z = 0.5 * math.sqrt(max(1.0 - a - e + i, 0.0))
        k = 0.25 / z
        q = [(c + g) * k, (f + h) * k, z, (d - b) * k]
    out = np.array(q)
    out /= math.sqrt(float(out @ out))
    return -out if out[3] < 0 else out


def quaternion_to_rotation(quat: Vector) -> Vector:
    """Rotation matrix of a quaternion ``(x, y, z, w)``, normalised first: with
    ``x² + y² + z² + w² = 1``,

        R = [[x²−y²−z²+w², 2(xy−zw), 2(xz+yw)],
             [2(xy+zw), −x²+y²−z²+w², 2(yz−xw)],
             [2(xz−yw), 2(yz+xw), −x²−y²+z²+w²]]

    (the Hamilton convention, Pinocchio's: Solà, *Quaternion kinematics for the error-state
    Kalman filter*, the rotation matrix of a quaternion), in the order of SciPy's
    ``Rotation.from_quat(quat).as_matrix()``: the same bits (tested), without importing
    ``scipy.spatial`` (0.1–0.4 s CPU: ``inekf``'s reset, issue 39)."""
    x, y, z, w = (float(c) for c in quat)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return np.array(
        [
            [x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
            [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
            [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2],
        ]
    )
