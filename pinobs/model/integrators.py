"""One explicit Runge-Kutta step on ``configuration space × Rᵐ``.

State ``(q, x)`` with ``q̇ = q · u(q, x)`` (``u`` in Pinocchio's tangent frame)
and ``ẋ = f(q, x)``.  Runge-Kutta-Munthe-Kaas, order 4: write
``q(t) = q₀ ⊕ ξ(t)``; then ``ξ̇ = J_r(ξ)⁻¹ u`` with ``J_r`` the right Jacobian
of the exponential (:meth:`Robot.integrate_jacobian`), and classical RK4 runs
on ``(ξ, x)`` in a vector space.  For vector and continuous joints ``J_r = I``
and this is plain RK4.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pinobs.model.robot import Robot, Vector

__all__ = ["lie_rk4"]

Rhs = Callable[[Vector, Vector], tuple[Vector, Vector]]


def lie_rk4(robot: Robot, q: Vector, x: Vector, h: float, rhs: Rhs) -> tuple[Vector, Vector]:
    """Advance ``(q, x)`` by ``h`` [s] under ``rhs(q, x) -> (u, ẋ)`` (RKMK4, module docstring)."""
    if robot.is_vector_space:  # ⊕ is +: classical RK4, without the group bookkeeping
        u1, f1 = rhs(q, x)
        u2, f2 = rhs(q + (0.5 * h) * u1, x + (0.5 * h) * f1)
        u3, f3 = rhs(q + (0.5 * h) * u2, x + (0.5 * h) * f2)
        u4, f4 = rhs(q + h * u3, x + h * f3)
        return q + (h / 6.0) * (u1 + 2.0 * (u2 + u3) + u4), x + (h / 6.0) * (
            f1 + 2.0 * (f2 + f3) + f4
        )
    exact_frame = not robot.has_lie_group_joints

    def xi_dot(xi: Vector, u: Vector) -> Vector:
        if exact_frame or not np.any(xi):
            return u
        return np.linalg.solve(robot.integrate_jacobian(q, xi), u)

    zero = np.zeros(robot.nv)
    u1, f1 = rhs(q, x)
    k1 = xi_dot(zero, u1)
    xi2 = 0.5 * h * k1
    u2, f2 = rhs(robot.integrate(q, xi2), x + 0.5 * h * f1)
    k2 = xi_dot(xi2, u2)
    xi3 = 0.5 * h * k2
    u3, f3 = rhs(robot.integrate(q, xi3), x + 0.5 * h * f2)
    k3 = xi_dot(xi3, u3)
    xi4 = h * k3
    u4, f4 = rhs(robot.integrate(q, xi4), x + h * f3)
    k4 = xi_dot(xi4, u4)
    xi = (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    x_new = x + (h / 6.0) * (f1 + 2.0 * f2 + 2.0 * f3 + f4)
    return robot.normalize(robot.integrate(q, xi)), x_new
