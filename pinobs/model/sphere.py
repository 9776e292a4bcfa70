"""The unit 3-sphere as a Pinocchio robot (Anisi–Hamberg §5).

Realisation.  A unit quaternion *is* a point of S³ ⊂ R⁴, and Pinocchio's
spherical joint stores its configuration as one (``x, y, z, w``) and moves it
by ``q ⊕ ω = q ⊗ exp(ω/2)`` without ever flipping its sign.  Along a motion
``q̇ = ½ q ⊗ (ω, 0)``, so ``|q̇|_{R⁴} = |ω| / 2``: a rigid body with isotropic
inertia ``c·1`` has kinetic metric ``c|ω|²``, which equals the round metric
``|q̇|²`` of the unit S³ for ``c = ¼``.  That metric is bi-invariant
(sectional curvature ``1/(4c) = 1``, MATH §3), Pinocchio's group log is then
the Riemannian log (``Γs ≡ 0``), and the whole observer stack runs unchanged
on a ``pin.Model`` with one ``JointModelSpherical`` and zero gravity.  This
was chosen over an analytic-metric protocol because it is exact (no chart:
Anisi–Hamberg's hyperspherical coordinates are singular at ``x₁, x₂ ∈ {0,
π}``) and needs no second code path in the observers.

Caveat (distances double).  SO(3) = S³/±1.  ``Robot.difference`` is the log of
the *rotation* ``R(q₀)ᵀR(q₁)``, whose angle θ ∈ [0, π] is twice the S³ arc
between ``q₀`` and the nearer of ``±q₁``.  With ``c = ¼`` the metric norm of
the log is ``θ/2``, the S³ distance, as long as ``⟨q₀, q₁⟩ > 0``
(``dist < π/2``); the observer's error stays far below that in §5.  Tested.

Hyperspherical coordinates (Anisi–Hamberg §5): ``x₁, x₂ ∈ [0, π]``,
``x₃ ∈ [0, 2π)``, metric ``diag(1, sin²x₁, sin²x₁ sin²x₂)``, point
``p = (cos x₁, sin x₁ cos x₂, sin x₁ sin x₂ cos x₃, sin x₁ sin x₂ sin x₃)``,
identified with the quaternion ``w + x i + y j + z k = p₀ + p₁ i + p₂ j + p₃ k``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pinobs.model.robot import Robot, Vector

__all__ = [
    "anisi_hamberg_potential",
    "anisi_hamberg_torque",
    "body_velocity",
    "coordinate_velocity",
    "hyperspherical",
    "quaternion",
    "unit_three_sphere",
]

_INERTIA = 0.25  # [kg·m²] c = ¼: the round metric of the unit S³


def unit_three_sphere() -> Robot:
    """A ``Robot`` whose configuration manifold is the unit S³ with its round metric (module docstring)."""
    model = pin.Model()
    model.name = "s3"
    joint = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "s3")
    inertia = pin.Inertia(1.0, np.zeros(3), _INERTIA * np.eye(3))
    model.appendBodyToJoint(joint, inertia, pin.SE3.Identity())
    model.gravity.setZero()
    return Robot(model, name="s3", source="pinobs.model.sphere")


def _qmul(a: Vector, b: Vector) -> Vector:
    """Quaternion product, ``x, y, z, w`` order."""
    va, wa, vb, wb = a[:3], a[3], b[:3], b[3]
    return np.concatenate([wa * vb + wb * va + np.cross(va, vb), [wa * wb - va @ vb]])


def _point(x: Vector) -> Vector:
    s1, s2 = np.sin(x[0]), np.sin(x[1])
    return np.array(
        [
            np.cos(x[0]),
            s1 * np.cos(x[1]),
            s1 * s2 * np.cos(x[2]),
            s1 * s2 * np.sin(x[2]),
        ]
    )


def _point_jacobian(x: Vector) -> Vector:
    c1, s1, c2, s2, c3, s3 = (
        np.cos(x[0]),
        np.sin(x[0]),
        np.cos(x[1]),
        np.sin(x[1]),
        np.cos(x[2]),
        np.sin(x[2]),
    )
    return np.array(
        [
            [-s1, 0.0, 0.0],
            [c1 * c2, -s1 * s2, 0.0],
            [c1 * s2 * c3, s1 * c2 * c3, -s1 * s2 * s3],
            [c1 * s2 * s3, s1 * c2 * s3, s1 * s2 * c3],
        ]
    )


def _to_quat(p: Vector) -> Vector:
    return np.array([p[1], p[2], p[3], p[0]])


def _to_point(q: Vector) -> Vector:
    return np.array([q[3], q[0], q[1], q[2]])


def quaternion(x: Vector) -> Vector:
    """Pinocchio configuration (``x, y, z, w``) of the point with hyperspherical coordinates ``x``."""
    return _to_quat(_point(np.asarray(x, dtype=float)))


def hyperspherical(q: Vector) -> Vector:
    """Hyperspherical coordinates ``(x₁, x₂, x₃)`` [rad] of the configuration ``q`` (``x₃ ∈ [0, 2π)``)."""
    p = _to_point(np.asarray(q, dtype=float))
    x1 = np.arctan2(np.linalg.norm(p[1:]), p[0])
    x2 = np.arctan2(np.linalg.norm(p[2:]), p[1])
    x3 = np.mod(np.arctan2(p[3], p[2]), 2.0 * np.pi)
    return np.array([x1, x2, x3])


def body_velocity(x: Vector, xdot: Vector) -> Vector:
    """Pinocchio velocity ω [rad/s] at ``quaternion(x)`` of the coordinate velocity ``ẋ``: ``ω = 2 q* ⊗ q̇``."""
    q = quaternion(x)
    qdot = _to_quat(_point_jacobian(np.asarray(x, dtype=float)) @ np.asarray(xdot, dtype=float))
    conj = np.array([-q[0], -q[1], -q[2], q[3]])
    return 2.0 * _qmul(conj, qdot)[:3]


def coordinate_velocity(q: Vector, omega: Vector) -> Vector:
    """Coordinate velocity ``ẋ`` of the Pinocchio velocity ``ω`` at ``q`` (inverse of :func:`body_velocity`)."""
    x = hyperspherical(q)
    qdot = 0.5 * _qmul(np.asarray(q, dtype=float), np.concatenate([omega, [0.0]]))
    jac = _point_jacobian(x)
    return np.asarray(np.linalg.lstsq(jac, _to_point(qdot), rcond=None)[0])


def anisi_hamberg_potential(q: Vector) -> float:
    """Anisi–Hamberg §5: ``W = sin x₁ cos x₂ cos x₃ = p₁ p₂ / √(p₂² + p₃²)`` (undefined where ``p₂ = p₃ = 0``)."""
    p = _to_point(np.asarray(q, dtype=float))
    return float(p[1] * p[2] / np.hypot(p[2], p[3]))


def anisi_hamberg_torque(q: Vector) -> Vector:
    """The generalised force of ``−grad W`` at ``q``: ``τ_i = −D_{E_i} W`` [N·m], so ``M⁻¹τ = −grad W``.

    ``D_{E_i} W = ∇_p W · ṗ_i`` with ``q̇_i = ½ q ⊗ (e_i, 0)`` (module docstring).
    """
    q = np.asarray(q, dtype=float)
    p = _to_point(q)
    rho = np.hypot(p[2], p[3])
    grad = np.array(
        [0.0, p[2] / rho, p[1] * p[3] ** 2 / rho**3, -p[1] * p[2] * p[3] / rho**3]
    )  # ∇_p W in R⁴
    out = np.empty(3)
    for i in range(3):
        e = np.zeros(4)
        e[i] = 1.0
        out[i] = -grad @ _to_point(0.5 * _qmul(q, e))
    return out
