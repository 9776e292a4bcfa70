"""Slow, independent reference geometry: for tests and accuracy reports only.

Built from finite differences of ``M(q)`` along ``integrate`` and the frame
bracket alone: no ABA call, no Christoffel formula from the fast path.

* Koszul formula for frame-constant fields X, Y, Z::

      2⟨∇_X Y, Z⟩ = X⟨Y,Z⟩ + Y⟨X,Z⟩ − Z⟨X,Y⟩ + ⟨[X,Y],Z⟩ − ⟨[X,Z],Y⟩ − ⟨[Y,Z],X⟩

* curvature from that connection by central differences (MATH §3)::

      R(X,Y)Z = D_X ω(Y,Z) − D_Y ω(X,Z) + ω(X, ω(Y,Z)) − ω(Y, ω(X,Z)) − ω([X,Y], Z)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pinobs.model.robot import Robot, Vector

__all__ = ["fd_curvature", "koszul_connection", "mass_matrix_derivative_fd"]


def mass_matrix_derivative_fd(robot: Robot, q: Vector, x: Vector, eps: float = 1e-5) -> Vector:
    """``D_x M(q)`` by central differences along ``integrate``."""
    return (
        robot.mass_matrix(robot.integrate(q, eps * x))
        - robot.mass_matrix(robot.integrate(q, -eps * x))
    ) / (2 * eps)


def koszul_connection(robot: Robot, q: Vector, x: Vector, y: Vector, eps: float = 1e-5) -> Vector:
    """``∇_X Y`` for frame-constant X, Y from the Koszul formula (module docstring)."""
    n = robot.nv
    m = robot.mass_matrix(q)
    dmx = mass_matrix_derivative_fd(robot, q, x, eps)
    dmy = mass_matrix_derivative_fd(robot, q, y, eps)
    bxy = robot.bracket(x, y)
    rhs = np.empty(n)
    for k in range(n):
        e = np.zeros(n)
        e[k] = 1.0
        rhs[k] = 0.5 * (
            y @ dmx @ e
            + x @ dmy @ e
            - x @ mass_matrix_derivative_fd(robot, q, e, eps) @ y
            + bxy @ m @ e
            - robot.bracket(x, e) @ m @ y
            - robot.bracket(y, e) @ m @ x
        )
    return np.linalg.solve(m, rhs)


def fd_curvature(
    robot: Robot, q: Vector, x: Vector, y: Vector, z: Vector, h: float = 1e-4
) -> Vector:
    """``R(x, y) z`` from :func:`koszul_connection` and central differences (module docstring)."""

    def w(qq: Vector, a: Vector, b: Vector) -> Vector:
        return koszul_connection(robot, qq, a, b)

    def d(a: Vector, f: Callable[[Vector], Vector]) -> Vector:
        return (f(robot.integrate(q, h * a)) - f(robot.integrate(q, -h * a))) / (2 * h)

    return (
        d(x, lambda qq: w(qq, y, z))
        - d(y, lambda qq: w(qq, x, z))
        + w(q, x, w(q, y, z))
        - w(q, y, w(q, x, z))
        - w(q, robot.bracket(x, y), z)
    )
