"""Compiled steps on robots with Lie-group or continuous joints: the RKMK4 step and ``riemannian``'s.

Issue 39: an update of ``riemannian`` on a go1 (free-flyer, nv = 18) made 29 Python calls
with a sample (42 when its Jacobi operator was due) around Pinocchio's five dynamics calls:
the RKMK4's three block solves (``Robot.integrate_jacobian_solve``: a Python method and
LAPACK's ``dgesv`` through SciPy's wrapper), two ``normalize``, the bracket (a Python method
building two ``pin.Motion``), the correction's five methods.  Here:

* :class:`LieRK4`, :func:`pinobs.model.dynamics_rk4` on Lie-group joints: four ``aba`` and
  four ``integrate`` (bound to the model), and between them compiled stages
  (:func:`~pinobs.observers.fused.rkmk4_stage_loops`), whose stages 2–4 also solve
  ``J_r(ξ) k = v_s`` block by block (:func:`rkmk4_solve_loops`: Pinocchio's ``Jexp3`` /
  ``Jexp6`` matrices, the LU solve of ``np.linalg.solve`` in numba, which calls the same
  LAPACK ``dgesv`` as SciPy's wrapper on the same matrix: the same bits); ``normalize``
  in place, its arithmetic;
* :class:`LieRiccatiStep`, ``riemannian``'s whole step with the Riccati schedule: the RKMK4,
  ``difference`` bound, the NIS and the gate, the Jacobi operator when due, the derivatives
  call, and one compiled correction (:func:`lie_riccati_correction_loops`: the schedule's
  gains, :func:`~pinobs.observers.fused.lie_correction_loops`, the bracket by
  :func:`bracket_loops` and ``v̂⁺``).

The same operations in the same order as the paths they replace (no fused multiply-adds),
so the same bits (tested, and on stored runs of go1, talos, a spherical top and a
continuous-joint pendulum).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pinobs.model import Robot
from pinobs.model.integrators import (
    DynamicsCalls,
    difference_call,
    dynamics_calls,
    integrate_call,
    jexp_blocks,
    unit_slices,
)
from pinobs.observers.base import Vector
from pinobs.observers.fused import (
    lie_correction_loops,
    loaded,
    riccati_gains,
    rkmk4_stage_kernel,
    rkmk4_stage_loops,
)
from pinobs.observers.fused_jacobi import bracket_table
from pinobs.observers.linalg import LazyKernel

__all__ = [
    "LieRK4",
    "LieRiccatiStep",
    "bracket_kernel",
    "lie_riccati_correction_kernel",
    "rkmk4_solve_kernel",
]

_new_tuple = tuple.__new__  # a NamedTuple made without its __new__


def rkmk4_solve_loops(
    w: Vector, acc: Vector, jexp: Vector, blocks: Any, k: Vector, stage: int, h: float
) -> None:
    """Stage ``stage`` (2 to 4) of the RKMK4 step with its solve: ``k = J_r(ξ)⁻¹ v_s``, ``v_s =
    w[9]``, equal to ``v_s`` but on the blocks (rows ``(size, first index)`` of ``blocks``),
    where ``jexp[b]`` holds ``J_r(ξ)``'s block (:meth:`~pinobs.model.Robot.integrate_jacobian_solve`:
    LU with partial pivoting, NaN where it fails), then
    :func:`~pinobs.observers.fused.rkmk4_stage_loops` with ``k``."""
    n = w.shape[1]
    for i in range(n):
        k[i] = w[9, i]
    for b in range(blocks.shape[0]):
        d, i0 = blocks[b, 0], blocks[b, 1]
        try:
            x = np.linalg.solve(jexp[b, :d, :d], w[9, i0 : i0 + d])
            for j in range(d):
                k[i0 + j] = x[j]
        except Exception:  # singular (|ξ| at 2π) or not finite: NaN, as the method's
            for j in range(d):
                k[i0 + j] = np.nan
    rkmk4_stage_loops(w, acc, k, stage, h)


class LieRK4:
    """:func:`pinobs.model.dynamics_rk4` on Lie-group joints (RKMK4, without friction), its
    arithmetic between the calls compiled: four ``aba`` on ``calls``' own data, and the model's
    ``integrate`` (four), ``integrate_jacobian_solve`` (three) and ``normalize``, as
    :func:`pinobs.model.dynamics_rk4` calls them.  Where the robot's blocks allow
    (:func:`~pinobs.model.integrators.jexp_blocks`: no planar joint) the solves are compiled
    with the stages (:func:`rkmk4_solve_loops`) and ``normalize`` runs in place on
    ``integrate``'s fresh array (:func:`~pinobs.model.integrators.unit_slices`).  Equal to
    :func:`pinobs.model.dynamics_rk4` to the bit (tested).  ``_scratch*`` are overwritten by
    every step."""

    def __init__(self, robot: Robot, calls: DynamicsCalls) -> None:
        self.robot, self.calls = robot, calls
        self.integrate = integrate_call(robot)  # (pin.integrate: a Python call less, four)
        self._scratch_work = np.zeros((10, robot.nv))
        self._scratch_point = (self._scratch_work[8], self._scratch_work[9])  # (ξ, v_s), made once
        self.stage = loaded(rkmk4_stage_kernel)
        jexp, units = jexp_blocks(robot), unit_slices(robot)
        self.solves = jexp is not None and units is not None
        self.units: tuple[slice, ...] = units or ()
        n = len(jexp or ())  # the blocks' J_r(ξ), written by Pinocchio's Jexp3 / Jexp6
        self._scratch_jexp = np.zeros((max(n, 1), 6, 6))
        self._scratch_blocks = tuple(
            (self._scratch_jexp[b, : s.stop - s.start, : s.stop - s.start], fn, s)
            for b, (fn, s) in enumerate(jexp or ())
        )
        rows = [(s.stop - s.start, s.start) for _, s in jexp or ()]
        self.table = np.array(rows, dtype=np.int64).reshape(-1, 2)
        self._scratch_k = np.empty(robot.nv)
        # (its arguments the step's own buffers and aba's output: LazyKernel.unchecked)
        self.solve_stage = rkmk4_solve_kernel.unchecked() if self.solves else None
        self._first_stage = rkmk4_stage_kernel.unchecked()  # (the same, for stage 1)
        self._scratch_ddq = calls.data.ddq  # aba's output, a view made once (BlockStep's acc0)

    @classmethod
    def build(cls, robot: Robot) -> LieRK4 | None:
        """The step on a new ``pin.Data`` of ``robot``'s, for a :class:`Robot` with
        Lie-group or continuous joints and no joint friction; ``None`` elsewhere."""
        if not isinstance(robot, Robot) or robot.is_vector_space or robot.has_friction:
            return None
        zero = np.zeros(robot.nv)  # the solves' LAPACK (dgesv) imported now, not in the first
        robot.integrate_jacobian_solve(robot.neutral(), zero, zero)  # step (0.16-0.34 s; issue 39)
        return cls(robot, dynamics_calls(robot))

    def step(
        self, q: Vector, v: Vector, tau: Vector, h: float, acc0: Vector | None = None
    ) -> tuple[Vector, Vector]:
        """``(q⁺, v⁺)`` after ``h`` [s] with ``tau`` held from ``(q, v)``; ``acc0``: the first
        stage's ``v̇`` if the caller has it (read before any call)."""
        if self.solve_stage is None:
            return self._step_solving(q, v, tau, h, acc0)
        q_new, v_new = self.predict(q, v, tau, h, acc0)
        return q_new, v_new.copy()

    def predict(
        self, q: Vector, v: Vector, tau: Vector, h: float, acc0: Vector | None = None
    ) -> tuple[Vector, Vector]:
        """:meth:`step` with the compiled solves, ``v⁺`` a row of the work array (read it
        before the next step)."""
        aba, w, integrate, solve_stage = (
            self.calls.aba,
            self._scratch_work,
            self.integrate,
            self.solve_stage,
        )
        xi, vs = self._scratch_point
        jexp, table, k = self._scratch_jexp, self.table, self._scratch_k
        w[0] = v
        if acc0 is None or acc0 is self._scratch_ddq:  # own buffers (stage 1 reads no k)
            self._first_stage(w, aba(q, v, tau) if acc0 is None else acc0, k, 1, h)
        else:
            self.stage(w, acc0, v, 1, h)  # (k₁ = v)
        for stage in (2, 3, 4):
            acc = aba(integrate(q, xi), vs, tau)
            for (
                block,
                fn,
                s,
            ) in self._scratch_blocks:  # J_r(ξ)'s blocks (Robot.integrate_jacobian_solve)
                block[...] = fn(xi[s])
            solve_stage(w, acc, jexp, table, k, stage, h)  # type: ignore[misc]
        q_new = integrate(q, xi)
        for s in self.units:  # Robot.normalize, in place on the fresh array
            b = q_new[s]
            b /= math.sqrt(b.dot(b))
        return q_new, vs

    def _step_solving(
        self, q: Vector, v: Vector, tau: Vector, h: float, acc0: Vector | None
    ) -> tuple[Vector, Vector]:
        """:meth:`step` with the model's ``integrate_jacobian_solve`` and ``normalize``."""
        r, aba, stage, w = self.robot, self.calls.aba, self.stage, self._scratch_work
        integrate, solve = self.integrate, r.integrate_jacobian_solve
        xi, vs = self._scratch_point
        w[0] = v
        stage(w, aba(q, v, tau) if acc0 is None else acc0, v, 1, h)
        for k in (2, 3, 4):
            acc = aba(integrate(q, xi), vs, tau)
            stage(w, acc, solve(q, xi, vs), k, h)
        return r.normalize(integrate(q, xi)), vs.copy()


def _cross(
    a0: float, a1: float, a2: float, b0: float, b1: float, b2: float
) -> tuple[float, float, float]:
    """``a × b`` (``np.cross``'s and Eigen's products and differences)."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


def bracket_loops(table: Any, x: Vector, y: Vector, out: Vector) -> None:
    """``[x, y]`` (:meth:`~pinobs.model.Robot.bracket`) into ``out``: zero but on the blocks of
    ``table`` (:func:`~pinobs.observers.fused_jacobi.bracket_table`): ``x × y`` in a spherical joint
    (``np.cross``), ``(ω₁ × v₂ + v₁ × ω₂, ω₁ × ω₂)`` in a free-flyer (``pin.Motion``'s
    ``cross``, ``x = (v₁, ω₁)``), the se(2) bracket in a planar joint: the same products and
    sums in the same order (the same bits, tested)."""
    for i in range(out.shape[0]):
        out[i] = 0.0
    for r in range(table.shape[0]):
        kind, i = table[r, 0], table[r, 1]
        if kind == 0:
            out[i], out[i + 1], out[i + 2] = _cross(
                x[i], x[i + 1], x[i + 2], y[i], y[i + 1], y[i + 2]
            )
        elif kind == 1:
            c = _cross(x[i + 3], x[i + 4], x[i + 5], y[i], y[i + 1], y[i + 2])  # ω₁ × v₂
            d = _cross(x[i], x[i + 1], x[i + 2], y[i + 3], y[i + 4], y[i + 5])  # v₁ × ω₂
            out[i], out[i + 1], out[i + 2] = c[0] + d[0], c[1] + d[1], c[2] + d[2]
            out[i + 3], out[i + 4], out[i + 5] = _cross(
                x[i + 3], x[i + 4], x[i + 5], y[i + 3], y[i + 4], y[i + 5]
            )
        else:  # se2, (vx, vy, w): Robot.bracket's expressions
            ax, ay = x[i + 2], y[i + 2]
            out[i] = -ax * y[i + 1] + ay * x[i + 1]
            out[i + 1] = ax * y[i] - ay * x[i]


def lie_riccati_correction_loops(
    v: Vector, acc: Vector, a_q: Vector, a_v: Vector, delta: Vector, jac: Vector, p00: float,
    p01: float, p11: float, qa: float, r2: float, h: float, c: float, table: Any,
    work: Vector, v_new: Vector,
) -> tuple[float, float, float]:  # fmt: skip
    """``riemannian``'s correction on any robot with the Riccati schedule's gains
    (:func:`~pinobs.observers.fused.riccati_gains`): ``ζ, w, dv`` and the step ``−k₁ζ`` into the
    rows 0–3 of ``work`` (:func:`~pinobs.observers.fused.lie_correction_loops`), ``[ζ, w]`` into
    row 4 (:func:`bracket_loops`), ``v̂⁺ = v̂ + (dv + ½[ζ, w])`` into ``v_new`` (the NumPy
    path's ``dv += 0.5 * bracket``, then ``v + dv``); returns ``(P⁺₀₀, P⁺₀₁, P⁺₁₁)``."""
    k1, k2, p00, p01, p11 = riccati_gains(p00, p01, p11, qa, r2, h)
    zeta, w, dv, step, br = work[0], work[1], work[2], work[3], work[4]
    lie_correction_loops(v, acc, a_q, a_v, delta, jac, k1, k2, h, c * h, zeta, w, dv, step)
    bracket_loops(table, zeta, w, br)
    for i in range(v.shape[0]):
        v_new[i] = v[i] + (dv[i] + 0.5 * br[i])
    return p00, p01, p11


class LieRiccatiStep:
    """``riemannian``'s step on a :class:`Robot` with Lie-group or continuous joints, constant
    gains and the Riccati schedule (issue 39), with a sample or without: the RKMK4 prediction
    (:meth:`LieRK4.predict`), ``δ = difference(q̂⁻, q)`` (bound), the NIS and the outlier gate,
    the Jacobi operator when due, the correction's derivatives call (its arrays read as views)
    and :func:`lie_riccati_correction_loops`, then ``q̂⁻ ⊕ (−k₁ζ)`` normalised in place: the
    operations of :meth:`~pinobs.observers.riemannian.RiemannianObserver.step` in the same
    order (the same bits, tested).  The observer's RKMK4, calls and ``pin.Data``;
    ``_scratch_work`` is overwritten by every step.  ``state_type``: the observer's state (a
    NamedTuple, built by ``tuple.__new__``)."""

    def __init__(self, observer: Any, state_type: type) -> None:
        rk4, calls = observer._scratch_lie, observer._scratch_derivatives
        assert rk4 is not None and rk4.solves and calls is not None
        robot = observer.robot
        self.rk4, self.integrate, self.units = rk4, rk4.integrate, rk4.units
        self.difference = difference_call(robot)
        self.derivatives, data = calls.derivatives, calls.data
        self.ddq, self.ddq_dq, self.ddq_dv = data.ddq, data.ddq_dq, data.ddq_dv  # views, once
        self.correction = loaded(lie_riccati_correction_kernel)
        self.table = bracket_table(robot)
        self._scratch_work = np.empty((5, robot.nv))  # ζ, w, dv, −k₁ζ, [ζ, w]
        self.state_type = state_type

    def step(self, obs: Any, state: Any, dt: float, q_meas: Vector | None, tau: Vector) -> Any:
        """:meth:`~pinobs.observers.riemannian.RiemannianObserver.step` from a ``state`` with
        the schedule's ``P``."""
        q, v = self.rk4.predict(state.q, state.v, tau, dt)
        h = state.elapsed + dt
        if q_meas is None:
            gate = state.gate.predicted()
            return _new_tuple(self.state_type, (q, v.copy(), h, state.jacobi, state.age, state.P, gate))  # fmt: skip
        delta = self.difference(q, q_meas)
        p00, p01, p11 = state.P  # the schedule's innovation variance and the gate (step)
        s_inn = p00 + h * (2.0 * p01 + h * p11 + obs.accel_psd * h * h / 3.0) + obs._sigma2
        gate = state.gate.measured(float(delta.dot(delta)) / s_inn, obs._gate, delta.size)
        if gate.gated:
            return _new_tuple(self.state_type, (q, v.copy(), h, state.jacobi, state.age, state.P, gate))  # fmt: skip
        c = obs.gains.curvature_gain
        jac, age = state.jacobi, state.age + 1
        if c != 0.0 and (jac is None or age >= obs.curvature_every):  # due (obs._jacobi)
            calls = obs._scratch_jacobi
            jac, age = obs._jacobi(state, q, v, c) if calls is None else (calls(q, v), 0)
        self.derivatives(q, delta, tau)  # (RiemannianObserver._jacobians)
        work, v_new = self._scratch_work, np.empty(delta.size)
        P = self.correction(v, self.ddq, self.ddq_dq, self.ddq_dv, delta,
                            obs._zero_nn if jac is None else jac, p00, p01, p11, obs.accel_psd,
                            obs._sigma2, h, c, self.table, work, v_new)  # fmt: skip
        q_new = self.integrate(q, work[3])
        for s in self.units:  # Robot.normalize, in place on the fresh array
            b = q_new[s]
            b /= math.sqrt(b.dot(b))
        return _new_tuple(self.state_type, (q_new, v_new, 0.0, jac, age, P, gate))


#: :func:`rkmk4_solve_loops` compiled: ``(w, a, J, blocks, k, stage, h)`` (no contraction:
#: :func:`~pinobs.observers.fused.rkmk4_stage_loops`' bits).
rkmk4_solve_kernel = LazyKernel(
    rkmk4_solve_loops, np.zeros((10, 1)), np.zeros(1), np.zeros((1, 6, 6)),
    np.zeros((0, 2), dtype=np.int64), np.zeros(1), 2, 1e-3,
    helpers=(rkmk4_stage_loops,),
)  # fmt: skip
#: :func:`bracket_loops` compiled: ``(table, x, y, out)``.
bracket_kernel = LazyKernel(
    bracket_loops, np.zeros((0, 2), dtype=np.int64), np.zeros(1), np.zeros(1), np.zeros(1),
    helpers=(_cross,),
)  # fmt: skip
#: :func:`lie_riccati_correction_loops` compiled.
lie_riccati_correction_kernel = LazyKernel(
    lie_riccati_correction_loops, *(np.zeros(1),) * 2, *(np.zeros((1, 1)),) * 2, np.zeros(1),
    np.zeros((1, 1)), *(1.0,) * 6, 0.0, np.zeros((0, 2), dtype=np.int64), np.zeros((5, 1)),
    np.zeros(1),
    helpers=(riccati_gains, lie_correction_loops, bracket_loops, _cross),
)  # fmt: skip
