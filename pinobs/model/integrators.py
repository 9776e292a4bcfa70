"""One explicit Runge-Kutta step on ``configuration space × Rᵐ``.

State ``(q, x)`` with ``q̇ = q · u(q, x)`` (``u`` in Pinocchio's tangent frame)
and ``ẋ = f(q, x)``.  Runge-Kutta-Munthe-Kaas, order 4: write
``q(t) = q₀ ⊕ ξ(t)``; then ``ξ̇ = J_r(ξ)⁻¹ u`` with ``J_r`` the right Jacobian
of the exponential (:meth:`Robot.integrate_jacobian`), and classical RK4 runs
on ``(ξ, x)`` in a vector space.  For vector and continuous joints ``J_r = I``
and this is plain RK4.

:func:`dynamics_rk4` is the step every user of the model's dynamics takes
(``q̇ = v``, ``v̇ = M⁻¹(τ − c − g)``, τ held): the truth in the simulator
and the prediction of the model-based observers.  On a vector space its four
stages are linear combinations of ``(q, v, a₁, a₂, a₃, a₄)``, ``a_i`` the
stage accelerations::

    q₂ = q + ½h v,          v₂ = v + ½h a₁
    q₃ = q + ½h v + ¼h² a₁, v₃ = v + ½h a₂
    q₄ = q + h v + ½h² a₂,  v₄ = v + h a₃
    q⁺ = q + h v + ⅙h² (a₁ + a₂ + a₃),  v⁺ = v + ⅙h (a₁ + 2a₂ + 2a₃ + a₄)

(classical RK4 with ``k_q = v_i``, ``k_v = a_i``), each pair one product of a
2 × k coefficient matrix with the stacked vectors: six NumPy calls instead
of two dozen, so the four ABA calls dominate the step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache, partial
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from pinobs.model.robot import Robot, Vector

__all__ = [
    "RK4_STIFFNESS",
    "DynamicsCalls",
    "MassCoriolisCalls",
    "difference_call",
    "dynamics_calls",
    "dynamics_rk4",
    "friction_rk4",
    "friction_substeps",
    "integrate_call",
    "jexp_blocks",
    "lie_rk4",
    "mass_coriolis_calls",
    "rk4_stage_matrices",
    "unit_slices",
]

#: ``λ h`` kept below classical RK4's stability limit on the negative real axis, 2.785
#: (:func:`friction_substeps`).
RK4_STIFFNESS = 2.5

Rhs = Callable[[Vector, Vector], tuple[Vector, Vector]]


class DynamicsCalls(NamedTuple):
    """Pinocchio's two dynamics calls bound to a model and a ``pin.Data`` of the caller's own.

    ``aba(q, v, τ)`` returns ``v̇`` (a view into ``data``: copy it or use it before the next
    call); ``derivatives(q, v, τ)`` runs ``pin.computeABADerivatives`` and leaves ``v̇``,
    ``∂v̇/∂q``, ``∂v̇/∂v`` and ``M⁻¹`` (upper triangle) in ``data.ddq``, ``data.ddq_dq``,
    ``data.ddq_dv`` and ``data.Minv``.  No checks and no friction: for the compiled
    steps of the observers (:mod:`pinobs.observers.fused`), which read ``data``'s arrays in place.
    """

    aba: Callable[[Vector, Vector, Vector], Vector]
    derivatives: Callable[[Vector, Vector, Vector], object]
    data: Any


def dynamics_calls(robot: Robot, *, gravity: bool = True, data: Any = None) -> DynamicsCalls:
    """:class:`DynamicsCalls` of ``robot``'s model on a new ``pin.Data`` (every consumer owns
    its data: the filter's calls do not overwrite the robot's), or on ``data``, a
    ``pin.Data`` of ``robot``'s model that the caller's other calls use too (so that they
    find it in the cache).  ``gravity=False``: on a copy of the model without gravity, whose
    ``derivatives(q, x, 0)`` leaves ``−Γs(x, x)``, ``−∂_q Γs(x, x)`` and ``−∂_x Γs(x, x)``,
    the negated :meth:`Robot.spray_jacobians`, to the bit (the same model parameters; a
    ``pin.Data`` depends only on the model's structure)."""
    model = robot.model
    if not gravity:
        model = model.copy()
        model.gravity.setZero()
    if data is None:
        data = model.createData()
    return DynamicsCalls(
        partial(pin.aba, model, data), partial(pin.computeABADerivatives, model, data), data
    )


class MassCoriolisCalls(NamedTuple):
    """``pin.crba`` and ``pin.computeCoriolisMatrix`` bound to a model and a ``pin.Data`` of
    the caller's own each, with the arrays they write: ``crba(q)`` leaves ``M(q)`` in ``M``
    (its upper triangle at least: Pinocchio < 4 fills only that), ``coriolis(q, v)`` leaves
    ``C(q, v)`` in ``C`` (views, written in place).  No checks: for ``kalman``'s compiled step
    (:mod:`pinobs.observers.kalman_step`)."""

    crba: Callable[[Vector], object]
    coriolis: Callable[[Vector, Vector], object]
    M: Vector
    C: Vector


def mass_coriolis_calls(robot: Robot) -> MassCoriolisCalls:
    """:class:`MassCoriolisCalls` of ``robot``'s model on two new ``pin.Data``."""
    model = robot.model
    data_m, data_c = model.createData(), model.createData()
    return MassCoriolisCalls(
        partial(pin.crba, model, data_m),
        partial(pin.computeCoriolisMatrix, model, data_c),
        data_m.M,
        data_c.C,
    )


def integrate_call(robot: Robot) -> Callable[[Vector, Vector], Vector]:
    """``robot.integrate`` without its Python call: ``pin.integrate`` bound to the model
    (the float64 array :meth:`Robot.integrate` returns as it is), for a compiled step's
    loop (:class:`pinobs.observers.fused_lie.LieRK4`); the method itself where a subclass
    overrides it."""
    if type(robot).integrate is Robot.integrate:
        return partial(pin.integrate, robot.model)
    return robot.integrate


def difference_call(robot: Robot) -> Callable[[Vector, Vector], Vector]:
    """``robot.difference`` without its Python call: ``pin.difference`` bound to the model (the
    float64 array :meth:`Robot.difference` returns as it is), as :func:`integrate_call`; the
    method itself where a subclass overrides it."""
    if type(robot).difference is Robot.difference:
        return partial(pin.difference, robot.model)
    return robot.difference


def jexp_blocks(robot: Robot) -> tuple[tuple[Callable[[Vector], Vector], slice], ...] | None:
    """The blocks of :meth:`Robot.integrate_jacobian_solve`: per spherical or free-flyer joint,
    Pinocchio's ``Jexp3`` or ``Jexp6`` and the joint's slice of ``v`` (the solve of each block
    is the caller's: :class:`pinobs.observers.fused_lie.LieRK4`); ``None`` with a planar joint
    (its block is ``dIntegrate``'s) or where a subclass overrides the method."""
    if type(robot).integrate_jacobian_solve is not Robot.integrate_jacobian_solve:
        return None
    jexp = {"so3": pin.Jexp3, "se3": pin.Jexp6}
    kinds = [b.kind for b in robot.joints if b.kind in ("so3", "se3", "se2")]
    if "se2" in kinds:
        return None
    return tuple(
        (jexp[b.kind], slice(b.idx_v, b.idx_v + b.nv)) for b in robot.joints if b.kind in jexp
    )


def unit_slices(robot: Robot) -> tuple[slice, ...] | None:
    """The unit-norm blocks of ``q`` (quaternions, ``(cos, sin)`` pairs) that
    :meth:`Robot.normalize` divides by their norms, for a caller that normalises
    :func:`integrate_call`'s fresh array in place with its arithmetic (``block /=
    √(block·block)``); ``None`` where a subclass overrides either method."""
    cls = type(robot)
    if cls.normalize is not Robot.normalize or cls.integrate is not Robot.integrate:
        return None
    return robot._unit_slices


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
        if exact_frame or not xi.any():
            return u
        if isinstance(robot, Robot):  # joint by joint, closed forms
            return robot.integrate_jacobian_solve(q, xi, u)
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


@lru_cache(maxsize=16)
def rk4_stage_matrices(h: float) -> tuple[Vector, Vector, Vector, Vector]:
    """Rows ``(q_i, v_i)`` of the stages in the basis ``(q, v, a₁, a₂, a₃, a₄)`` (module docstring)."""
    hh, h2 = 0.5 * h, h * h
    out = (
        np.array([[1.0, hh, 0.0], [0.0, 1.0, hh]]),  # (q₂, v₂)
        np.array([[1.0, hh, 0.25 * h2, 0.0], [0.0, 1.0, 0.0, hh]]),  # (q₃, v₃)
        np.array([[1.0, h, 0.0, 0.5 * h2, 0.0], [0.0, 1.0, 0.0, 0.0, h]]),  # (q₄, v₄)
        np.array(
            [
                [1.0, h, h2 / 6.0, h2 / 6.0, h2 / 6.0, 0.0],
                [0.0, 1.0, h / 6.0, h / 3.0, h / 3.0, h / 6.0],
            ]
        ),  # (q⁺, v⁺)
    )
    for m in out:
        m.setflags(write=False)
    return out


def dynamics_rk4(
    robot: Robot, q: Vector, v: Vector, tau: Vector, h: float, *, acc0: Vector | None = None
) -> tuple[Vector, Vector]:
    """One RKMK4 step of ``q̇ = v``, ``v̇ = robot.forward_dynamics(q, v, tau)`` over ``h`` [s], τ held.

    Same result as :func:`lie_rk4` with that right-hand side (to rounding);
    on a vector space, the stacked form of the module docstring.  ``acc0``:
    the first stage's ``v̇`` at ``(q, v)`` if the caller has it already (an
    EKF gets it with its Jacobians), saving one ABA call; read before any
    other dynamics call, so it may be a view into the robot's ``pin.Data``.
    """
    fd: Callable[[Vector, Vector, Vector], Vector] = robot.forward_dynamics
    if isinstance(robot, Robot) and robot.has_lie_group_joints:
        return _dynamics_rkmk4(robot, q, v, tau, h, acc0)
    if not robot.is_vector_space:
        first = [] if acc0 is None else [np.array(acc0)]  # a copy: acc0 may be a view

        def rhs(qq: Vector, vv: Vector) -> tuple[Vector, Vector]:
            return vv, (first.pop() if first else fd(qq, vv, tau))

        return lie_rk4(robot, q, v, h, rhs)
    if isinstance(robot, Robot):  # the call, without the method
        aba = partial(pin.aba, robot.model, robot._data)  # the robot's own data (same layer)
        fd = aba if not robot.has_friction else _with_friction(aba, robot.friction_torque)
    c2, c3, c4, c_out = rk4_stage_matrices(float(h))
    b = np.empty((6, q.shape[0]))
    b[0], b[1] = q, v
    b[2] = fd(q, v, tau) if acc0 is None else acc0
    s = c2.dot(b[:3])
    b[3] = fd(s[0], s[1], tau)
    s = c3.dot(b[:4])
    b[4] = fd(s[0], s[1], tau)
    s = c4.dot(b[:5])
    b[5] = fd(s[0], s[1], tau)
    out = c_out.dot(b)
    return out[0], out[1]


def friction_substeps(robot: Robot, v: Vector, acc: Vector, minv_diag: Vector, dt: float) -> int:
    """RK4 substeps over ``dt`` [s] keeping ``λ h_sub ≤ 2.5`` under joint friction.

    Smoothed Coulomb friction (:meth:`Robot.friction_torque`) makes ``v̇`` stiff near
    ``v = 0``: its slope ``F_c / v_s`` enters ``∂v̇/∂v`` as ``−M⁻¹ F_c / v_s`` (λh reaches 55
    on a Panda's wrist at 1 kHz with 2 N·m), and one RK4 step is stable only for
    ``λ h < 2.785`` (on the negative real axis).  ``λ = maxᵢ (M⁻¹)ᵢᵢ |∂τ_f,ᵢ/∂v|`` at the
    velocity nearest zero that joint ``i`` can reach in the step, ``max(|vᵢ| − |aᵢ| dt, 0)``
    (the URDF's slope peaks at ``v = 0``; other laws' largest slope beyond it:
    :meth:`Robot.friction_stiffness`); ``acc`` [rad/s²] the acceleration at the start,
    ``minv_diag`` the diagonal of ``M⁻¹``.  The step of the simulator's plant and of the
    model-based observers' prediction (:mod:`pinobs.observers.ekf` measures it).
    """
    v_near = np.maximum(np.abs(v) - np.abs(acc) * dt, 0.0)
    lam = float(np.max(minv_diag * robot.friction_stiffness(v_near)))
    if not math.isfinite(lam):  # a lost filter's state: one step, its NaN reported by the caller
        return 1
    return max(1, math.ceil(lam * dt / RK4_STIFFNESS))


def friction_rk4(
    robot: Robot,
    q: Vector,
    v: Vector,
    tau: Vector,
    dt: float,
    acc: Vector | None,
    minv_diag: Vector | None,
) -> tuple[Vector, Vector]:
    """:func:`dynamics_rk4` over ``dt`` [s] in :func:`friction_substeps` substeps (joint
    friction is stiff near ``v = 0``): ``acc`` [rad/s²] the acceleration at ``(q, v)``, the
    first substep's first stage, ``minv_diag`` the diagonal of ``M⁻¹(q)``; ``acc`` ``None``:
    one step.  The model-based observers' prediction under friction (``ekf``, ``riemannian``)."""
    n = 1 if acc is None or minv_diag is None else friction_substeps(robot, v, acc, minv_diag, dt)
    q, v = dynamics_rk4(robot, q, v, tau, dt / n, acc0=acc)
    for _ in range(n - 1):
        q, v = dynamics_rk4(robot, q, v, tau, dt / n)
    return q, v


def _with_friction(
    aba: Callable[[Vector, Vector, Vector], Vector], friction: Callable[[Vector], Vector]
) -> Callable[[Vector, Vector, Vector], Vector]:
    """``(q, v, τ) ↦ aba(q, v, τ + τ_f(v))``: :meth:`Robot.forward_dynamics` without its checks."""

    def fd(q: Vector, v: Vector, tau: Vector) -> Vector:
        return aba(q, v, tau + friction(v))

    return fd


def _dynamics_rkmk4(
    robot: Robot, q: Vector, v: Vector, tau: Vector, h: float, acc0: Vector | None
) -> tuple[Vector, Vector]:
    """:func:`lie_rk4` of ``q̇ = v``, ``v̇ = M⁻¹(τ − c − g)``, written out (the same
    operations in the same order, so the same bits) where there are Lie-group joints.

    Stage ``i`` at ``q ⊕ ξᵢ``: ``ξ₁ = 0`` (``J_r(0) = I``, so ``k₁ = v``),
    ``ξ₂ = ½h k₁``, ``ξ₃ = ½h k₂``, ``ξ₄ = h k₃`` with ``kᵢ = J_r(ξᵢ)⁻¹ vᵢ``
    (:meth:`Robot.integrate_jacobian_solve`); ``v₂ = v + ½h a₁``, ``v₃ = v + ½h a₂``,
    ``v₄ = v + h a₃``, ``aᵢ`` the stage accelerations; then
    ``q⁺ = q ⊕ ⅙h (k₁ + 2k₂ + 2k₃ + k₄)``, ``v⁺ = v + ⅙h (a₁ + 2a₂ + 2a₃ + a₄)``
    (Munthe-Kaas, module docstring).  Without :func:`lie_rk4`'s closure and
    its per-stage zero tests.
    """
    fd, solve, integrate = robot.forward_dynamics, robot.integrate_jacobian_solve, robot.integrate
    if not robot.has_friction:  # the call, without the method (its result is the same)
        fd = partial(pin.aba, robot.model, robot._data)
    hh = 0.5 * h
    a1 = fd(q, v, tau) if acc0 is None else np.array(acc0)  # a copy: acc0 may be a view
    xi2 = hh * v
    v2 = v + hh * a1
    a2 = fd(integrate(q, xi2), v2, tau)
    k2 = solve(q, xi2, v2)
    xi3 = hh * k2
    v3 = v + hh * a2
    a3 = fd(integrate(q, xi3), v3, tau)
    k3 = solve(q, xi3, v3)
    xi4 = h * k3
    v4 = v + h * a3
    a4 = fd(integrate(q, xi4), v4, tau)
    k4 = solve(q, xi4, v4)
    xi = (h / 6.0) * (v + 2.0 * k2 + 2.0 * k3 + k4)
    v_new = v + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return robot.normalize(integrate(q, xi)), v_new
