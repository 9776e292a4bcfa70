"""Compiled steps around Pinocchio's calls: the per-update arithmetic of ``ekf`` and ``riemannian``.

Issue 39 (item 4): an update of ``ekf`` on a UR5 cost about 25 ``pin.aba`` calls for a
floor of about 3 (one ``computeABADerivatives``, three ``aba``): the rest was Python,
a hundred calls per update dispatching small NumPy operations.  Here the arithmetic
between Pinocchio's calls is fused into a few numba kernels (:class:`LazyKernel`,
``error_model="numpy"``, ``cache=True``), for robots whose configuration space is a
vector space (``⊕`` is ``+``) with ``nv ≤`` :data:`~pinobs.observers.linalg.KERNEL_MAX_NV`:

* the RK4 step of ``q̇ = v``, ``v̇ = a(q, v, τ)`` (:func:`pinobs.model.dynamics_rk4`'s
  stacked form, module docstring of :mod:`pinobs.model.integrators`) in a work array
  ``w`` of rows ``(q, v, a₁, a₂, a₃, a₄, q_s, v_s)``: each kernel stores the stage's
  ``v̇`` and writes the next stage's point ``(q_s, v_s)`` (after the fourth: the step's
  result);
* the EKF's covariance prediction ``P⁻ = Φ P Φᵀ + Q_d`` (``Φ`` by
  :func:`~pinobs.observers.linalg.transition_matrix`'s loops) with the RK4's first stage;
* the EKF's correction: the innovation, the Joseph update
  (:func:`~pinobs.observers.linalg.joseph_update`'s loops) and the NIS.

With Lie-group or continuous joints (no friction, any ``nv``; issue 39):

* the RKMK4 step's stages (:func:`rkmk4_stage_loops`; the step:
  :class:`~pinobs.observers.fused_lie.LieRK4`, with ``riemannian``'s whole step there);
* ``riemannian``'s correction but its bracket (:func:`lie_correction_loops`), its
  vector-space correction with the Riccati schedule's gains (:func:`riccati_correction_loops`)
  and its Jacobi operator's products (:mod:`pinobs.observers.fused_jacobi`), so that its
  update makes no BLAS call.

The equations are those of :mod:`pinobs.observers.ekf` and :mod:`pinobs.model.integrators`;
the compiled steps equal the NumPy ones to rounding (the tests compare them).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from pinobs.model import Robot
from pinobs.model.integrators import DynamicsCalls, dynamics_calls
from pinobs.observers.base import Vector
from pinobs.observers.linalg import KERNEL_MAX_NV, LazyKernel, joseph_kernel

__all__ = [
    "RiccatiStep",
    "compiled_vector_space",
    "ekf_coast_kernel",
    "ekf_correct_kernel",
    "ekf_finish_kernel",
    "ekf_predict_kernel",
    "lie_correction_kernel",
    "loaded",
    "riccati_correction_kernel",
    "rk4_calls",
    "rk4_last_kernel",
    "rk4_stage_kernel",
    "rk4_start_kernel",
    "rkmk4_stage_kernel",
    "torque_in_kernel",
    "vector_correction_kernel",
]

_new_tuple = tuple.__new__  # a NamedTuple made without its __new__ (RiccatiStep)


def compiled_vector_space(robot: object) -> bool:
    """Whether a compiled vector-space step applies to ``robot``: a :class:`Robot` whose
    configuration space is a vector space, without joint friction, ``nv ≤ KERNEL_MAX_NV``
    (``ekf``'s and ``kalman``'s steps)."""
    return (
        isinstance(robot, Robot)
        and robot.is_vector_space
        and not robot.has_friction
        and robot.nv <= KERNEL_MAX_NV
    )


# the linalg loop, under its own name (LazyKernel's helpers are found by name here)
_joseph_loops = joseph_kernel.fn


def rk4_start_loops(w: Vector, q: Vector, v: Vector, acc: Vector, h: float) -> None:
    """The RK4 step's start: ``w[0:3] = (q, v, a₁)``, ``(q_s, v_s) = (q + h/2 v, v + h/2 a₁)``."""
    hh = 0.5 * h
    for i in range(q.shape[0]):
        w[0, i] = q[i]
        w[1, i] = v[i]
        w[2, i] = acc[i]
        w[6, i] = q[i] + hh * v[i]
        w[7, i] = v[i] + hh * acc[i]


def rk4_stage_loops(w: Vector, acc: Vector, stage: int, h: float) -> None:
    """Stage ``stage`` (2, 3 or 4) of the RK4 step: ``a_stage = acc`` and the next point,
    after the fourth the step's result ``(q⁺, v⁺)``, into ``(q_s, v_s)`` (module docstring)."""
    hh, h2 = 0.5 * h, h * h
    for i in range(w.shape[1]):
        w[1 + stage, i] = acc[i]
        q, v = w[0, i], w[1, i]
        if stage == 2:  # (q₃, v₃)
            w[6, i] = q + hh * v + 0.25 * h2 * w[2, i]
            w[7, i] = v + hh * acc[i]
        elif stage == 3:  # (q₄, v₄)
            w[6, i] = q + h * v + 0.5 * h2 * w[3, i]
            w[7, i] = v + h * acc[i]
        else:  # (q⁺, v⁺)
            c6 = h2 / 6.0  # the terms in the order of rk4_stage_matrices' rows
            w[6, i] = q + h * v + c6 * w[2, i] + c6 * w[3, i] + c6 * w[4, i]
            w[7, i] = (
                v + h / 6.0 * w[2, i] + h / 3.0 * w[3, i] + h / 3.0 * w[4, i] + h / 6.0 * acc[i]
            )


def _transition_into(A: Vector, h: float, nv: int, work: Vector, Phi: Vector) -> None:  # noqa: C901, PLR0912 -- numba kernel: loops over blocks
    """``Φ = I + Ah(I + Ah/2 (I + Ah/3))`` into ``Phi`` (:func:`ekf_predict_loops`, its
    docstring's exact zeros skipped), ``work[0]`` and ``work[3]`` its scratch."""
    n = A.shape[0]
    mid, inner = work[0], work[3]
    row = work[3, nv]  # (a row after inner's: n ≥ 2nv)
    for i in range(nv):  # I + Ah/3's velocity rows
        for j in range(n):
            inner[i, j] = A[nv + i, j] * h / 3.0 + (1.0 if nv + i == j else 0.0)
    h3 = 1.0 * h / 3.0 + 0.0  # I + Ah/3 at (k, nv + k), k < nv (A's 1 there)
    c = 0.5 * h
    for i in range(nv):  # mid's position rows: (h/2) (I + Ah/3)'s velocity rows + I
        for j in range(n):
            mid[i, j] = c * inner[i, j] + (1.0 if i == j else 0.0)
    for i in range(nv, 2 * nv):  # its velocity rows: A's times I + Ah/3
        for j in range(n):
            row[j] = 0.0
        for k in range(nv):  # the position rows [I, (h/3) I, 0]: two terms each
            a = A[i, k]
            row[k] += a
            row[nv + k] += a * h3
        for k in range(nv, 2 * nv):
            a = A[i, k]
            for j in range(n):
                row[j] += a * inner[k - nv, j]
        for k in range(2 * nv, n):  # the offset rows [0, 0, I]
            row[k] += A[i, k]
        for j in range(n):
            mid[i, j] = c * row[j] + (1.0 if i == j else 0.0)
    for i in range(2 * nv, n):  # its offset rows: I's (A's are zero)
        for j in range(n):
            mid[i, j] = c * 0.0 + (1.0 if i == j else 0.0)
    for i in range(nv):  # Φ = I + h A mid: position rows, h mid's velocity rows + I
        for j in range(n):
            Phi[i, j] = h * mid[nv + i, j] + (1.0 if i == j else 0.0)
    for i in range(nv, 2 * nv):
        for j in range(n):
            row[j] = 0.0
        for k in range(2 * nv):
            a = A[i, k]
            for j in range(n):
                row[j] += a * mid[k, j]
        for k in range(2 * nv, n):  # mid's offset rows [0, 0, I]
            row[k] += A[i, k]
        for j in range(n):
            Phi[i, j] = h * row[j] + (1.0 if i == j else 0.0)
    for i in range(2 * nv, n):
        for j in range(n):
            Phi[i, j] = h * 0.0 + (1.0 if i == j else 0.0)


def _sandwich_into(Phi: Vector, P: Vector, m: int, work: Vector, out: Vector) -> None:  # noqa: C901, PLR0912 -- numba kernel: loops over blocks
    """``out = (Φ P) Φᵀ`` (:func:`ekf_predict_loops`; ``Φ``'s rows from ``m`` unit rows),
    ``work[1]`` and ``work[2]`` its scratch: ``Φ P`` row by row (each sum in the order of k:
    vector loops over j; the offset's rows are P's, issue 39: a third of the products at
    n = 3nv, the same numbers as the full sums), then ``(Φ P) Φᵀ`` by whole rows and its
    upper triangle mirrored."""
    n = P.shape[0]
    Phi_t, T = work[1], work[2]
    for i in range(m):
        for j in range(n):
            T[i, j] = 0.0
        for k in range(n):
            a = Phi[i, k]
            for j in range(n):
                T[i, j] += a * P[k, j]
    for i in range(m, n):
        for j in range(n):
            T[i, j] = P[i, j]
    for k in range(n):
        for j in range(n):
            Phi_t[k, j] = Phi[j, k]
    for i in range(m):
        for j in range(m):
            out[i, j] = 0.0
        for k in range(n):
            a = T[i, k]
            for j in range(m):
                out[i, j] += a * Phi_t[k, j]
        for j in range(m, n):  # (Φ's offset rows: (Φ P)'s columns)
            out[i, j] = T[i, j]
    for i in range(m, n):
        for j in range(i, n):
            out[i, j] = T[i, j]
    for i in range(n):
        for j in range(i + 1, n):
            out[j, i] = out[i, j]


def ekf_predict_loops(
    w: Vector, q: Vector, v: Vector, acc: Vector, dq: Vector, dv: Vector, minv: Vector,
    P: Vector, h: float, psd: float, d_psd: Vector, A: Vector, Phi: Vector, out: Vector,
) -> None:  # fmt: skip
    """The EKF's prediction but for the RK4's later stages, after ``computeABADerivatives``.

    ``A = [[0, I, 0], [∂a/∂q, ∂a/∂v, M⁻¹], [0, 0, 0]]`` (the caller's buffer, its
    constant blocks written once; ``M⁻¹`` from its upper triangle, the offset's block
    only when ``P`` is ``3nv × 3nv``), ``Φ = I + Ah(I + Ah/2 (I + Ah/3))`` into ``Phi``
    (:func:`~pinobs.observers.linalg.transition_matrix`), ``out = Φ P Φᵀ + Q_d`` with
    ``Q_d = psd [[h³/3 I, h²/2 I], [h²/2 I, h I]]`` and ``diag(d_psd h)`` on the offset
    (:mod:`pinobs.observers.ekf`, module docstring; ``out`` made symmetric: its upper
    triangle is computed), and the RK4's start (``acc = a₁``).

    Each product is the full sum over ``k`` in ascending order (``t += a · x``, an FMA with
    ``contract``), less the terms whose ``x`` is an exact 0 of ``A``'s constant blocks (issue
    39): ``I + Ah/3``'s position rows are ``[I, (h/3) I, 0]`` and its offset rows ``[0, 0, I]``,
    ``I + (Ah/2)(…)``'s offset rows ``[0, 0, I]``, so those terms are ``a`` (× 1) or ``a · h/3``
    on a sum still at ``+0`` (the first nonzero term of its entry), else nothing.  Adding
    ``a · 0`` to a sum leaves it as it is (a sum that starts at ``+0`` and adds products is
    never ``−0`` in round-to-nearest; ``a`` finite), so the bits are the full sums' (tested
    against the full loops, ``tests/observers/test_fused.py``).  ``(Φ P) Φᵀ`` by whole rows
    (the upper triangle's entries as before; the lower, overwritten by the mirror, make the
    loops whole vectors: faster than the triangle's ragged rows), the scratch in one array.
    """
    rk4_start_loops(w, q, v, acc, h)
    nv, n = q.shape[0], P.shape[0]
    with_d = n == 3 * nv
    for i in range(nv):
        for j in range(nv):
            A[nv + i, j] = dq[i, j]
            A[nv + i, nv + j] = dv[i, j]
            if with_d:
                A[nv + i, 2 * nv + j] = minv[i, j] if i <= j else minv[j, i]
    work = np.empty((4, n, n))  # the scratch of both: one allocation
    _transition_into(A, h, nv, work, Phi)
    # Φ's rows past 2nv (the offset's) are unit rows (A's are zero)
    _sandwich_into(Phi, P, 2 * nv if with_d else n, work, out)
    q3, q2, q1 = psd * (h**3 / 3.0), psd * (h**2 / 2.0), psd * h
    for i in range(nv):
        out[i, i] += q3
        out[i, nv + i] += q2
        out[nv + i, i] += q2
        out[nv + i, nv + i] += q1
        if with_d:
            out[2 * nv + i, 2 * nv + i] += d_psd[i] * h


def ekf_correct_loops(
    w: Vector, q_meas: Vector, P: Vector, r: float, e: Vector, dx: Vector, P_new: Vector,
    q_new: Vector, v_new: Vector,
) -> float:  # fmt: skip
    """The EKF's correction of the predicted ``(q_s, v_s)`` of ``w`` and ``P`` by ``q_meas``.

    ``e = q_meas − q⁻`` (``difference`` on a vector space), ``(dx, P_new)`` by the Joseph
    update, ``q_new = q⁻ + dx_q``, ``v_new = v⁻ + dx_v`` (the offset's part of ``dx`` is
    the caller's), and returns the NIS ``eᵀS⁻¹e = eᵀ(e − K_q e)/r``
    (:meth:`pinobs.observers.ekf.ExtendedKalmanFilter.correct`), or NaN where that
    method takes another way (``S`` not positive definite, or ``K_q ≈ I``).
    """
    nv = q_meas.shape[0]
    for i in range(nv):
        e[i] = q_meas[i] - w[6, i]
    if not _joseph_loops(P, e, r, dx, P_new):
        return math.nan
    ee, nis = 0.0, 0.0
    for i in range(nv):
        ee += e[i] * e[i]
        nis += e[i] * (e[i] - dx[i])
    if not nis >= 1e-6 * ee:  # e − K_q e lost its digits (ekf.correct): solved there
        return math.nan
    for i in range(nv):
        q_new[i] = w[6, i] + dx[i]
        v_new[i] = w[7, i] + dx[nv + i]
    return nis / r


#: :func:`rk4_stage_loops` under the name the fused kernels call it by: compiled on its own with
#: ``contract`` when they load (``LazyKernel``'s ``contracted``), its bits those of
#: :data:`rk4_stage_kernel`'s.
_rk4_stage_fma = rk4_stage_loops


def ekf_finish_loops(
    w: Vector, acc: Vector, h: float, q_meas: Vector, P: Vector, r: float, ex: Vector,
    P_new: Vector, q_new: Vector, v_new: Vector, d: Vector, d_new: Vector,
) -> float:  # fmt: skip
    """The RK4's fourth stage (:func:`rk4_stage_loops`, ``acc = a₄``: the predicted
    ``(q_s, v_s)``) and the EKF's correction (:func:`ekf_correct_loops`, ``e`` and ``dx`` in
    ``ex = (e, dx)``) in one call: each part's operations as it does them alone (the stage
    with ``contract``, the correction without), so the same bits.  With the offset state
    (``d`` of ``nv`` entries; empty without), its correction ``d_new = d + dx_d`` too
    (NumPy's ``d + dx[2nv:]``, entry by entry: the same bits, without NumPy's overflow
    warning to silence; issue 39).  Returns the NIS (NaN: the caller takes
    :func:`ekf_correct_loops`' other ways, ``d_new`` unwritten)."""
    _rk4_stage_fma(w, acc, 4, h)
    nv = q_meas.shape[0]
    nis = ekf_correct_loops(w, q_meas, P, r, ex[:nv], ex[nv:], P_new, q_new, v_new)
    if nis == nis:
        for i in range(d.shape[0]):
            d_new[i] = d[i] + ex[3 * nv + i]
    return nis


def torque_in_loops(tau: Vector, d: Vector, out: Vector) -> None:
    """The torque an ``ekf`` with the offset state predicts with, ``out = τ + d`` (NumPy's
    ``tau + d``, entry by entry: the same bits, without NumPy's overflow warning to silence
    where a lost filter's ``d`` overflows; issue 39)."""
    for i in range(tau.shape[0]):
        out[i] = tau[i] + d[i]


def ekf_coast_loops(w: Vector, acc: Vector, h: float, P: Vector, out: Vector) -> None:
    """The RK4's fourth stage (:func:`rk4_stage_loops`, ``contract``: its bits) and, for a
    step without a sample, ``out = ½(P + Pᵀ)`` (NumPy's ``0.5 * (P + P.T)``, entry by entry:
    the same bits, without NumPy's overflow warning to silence) in one call."""
    _rk4_stage_fma(w, acc, 4, h)
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.5 * (P[i, j] + P[j, i])


def rkmk4_stage_loops(w: Vector, acc: Vector, k: Vector, stage: int, h: float) -> None:
    """Stage ``stage`` (1 to 4) of the RKMK4 step on a Lie group, work rows ``w`` =
    ``(v, a₁, a₂, a₃, a₄, k₂, k₃, k₄, ξ, v_s)``: stores ``a_stage = acc`` and
    ``k_stage = k`` (``J_r(ξ)⁻¹ v_s``, the caller's solve; unused at stage 1, where it is
    ``v``), then the next stage's ``(ξ, v_s)`` (``ξ₂ = ½h v``, ``ξ₃ = ½h k₂``, ``ξ₄ = h k₃``;
    ``v_{i+1} = v + c h a_i``), after the fourth ``ξ = ⅙h (v + 2k₂ + 2k₃ + k₄)`` and ``v⁺``
    (:func:`pinobs.model.dynamics_rk4` on Lie-group joints: the same operations in the
    same order, without fused multiply-adds, so the same bits)."""
    hh, h6 = 0.5 * h, h / 6.0
    for i in range(w.shape[1]):
        v = w[0, i]
        w[stage, i] = acc[i]
        if stage > 1:
            w[3 + stage, i] = k[i]
        if stage == 1:
            w[8, i] = hh * v
            w[9, i] = v + hh * acc[i]
        elif stage == 2:
            w[8, i] = hh * k[i]
            w[9, i] = v + hh * acc[i]
        elif stage == 3:
            w[8, i] = h * k[i]
            w[9, i] = v + h * acc[i]
        else:
            w[8, i] = h6 * (v + 2.0 * w[5, i] + 2.0 * w[6, i] + k[i])
            w[9, i] = v + h6 * (w[1, i] + 2.0 * w[2, i] + 2.0 * w[3, i] + acc[i])


def lie_correction_loops(
    v: Vector, acc: Vector, a_q: Vector, a_v: Vector, delta: Vector, jac: Vector, k1: float,
    k2: float, h: float, ch: float, zeta: Vector, w: Vector, dv: Vector, step: Vector,
) -> None:  # fmt: skip
    """The riemannian correction's arithmetic on any robot but its bracket (module
    docstring of :mod:`pinobs.observers.riemannian`), with ``a, ∂a/∂q, ∂a/∂v`` the ABA
    derivatives at ``(q̂⁻, δ, τ)`` and ``Γs(δ,δ) = −½(∂a/∂v)δ``::

        ζ = −(δ + ½Γs(δ,δ))                          (second-order −log_q̂(q), MATH §4)
        w = k₁ v̂ − h (a + Γs(δ,δ) + (∂a/∂q)δ)
        dv = ½(∂a/∂v) w − k₂ ζ + h (∂a/∂q)δ + C h J ζ,     step = −k₁ ζ

    (``½(∂a/∂v)w = Γs(ζ, w)`` to first order, Maithripala et al. eq. (19); ``J ζ =
    R(v̂, ζ)v̂``, Anisi–Hamberg eq. (6)); the caller adds ``½[ζ, w]`` to ``dv``."""
    n = v.shape[0]
    ds = np.empty(n)
    for i in range(n):
        u = 0.0
        d = 0.0
        for j in range(n):
            u += a_v[i, j] * delta[j]
            d += a_q[i, j] * delta[j]
        ds[i] = d
        g = -0.5 * u
        zeta[i] = -(delta[i] + 0.5 * g)
        w[i] = k1 * v[i] - h * (acc[i] + g + d)
    for i in range(n):
        t = 0.0
        c = 0.0
        for j in range(n):
            t += a_v[i, j] * w[j]
            c += jac[i, j] * zeta[j]
        dv[i] = 0.5 * t - k2 * zeta[i] + h * ds[i] + ch * c
        step[i] = -k1 * zeta[i]


class RiccatiStep:
    """``riemannian``'s step with a sample, on a vector space with the Riccati schedule and a
    :class:`Robot` (issue 39): the RK4 prediction (:func:`rk4_start_loops`, two
    :func:`rk4_stage_loops`, then :func:`rk4_last_loops`, which also writes ``δ = q_meas −
    q⁻``), the NIS and the outlier gate, the Jacobi operator when due, the correction's
    derivatives call (its arrays read as views) and :func:`riccati_correction_loops` into two
    new arrays: the operations of
    :meth:`~pinobs.observers.riemannian.RiemannianObserver.step` in the same order, in one
    Python call and five compiled ones around Pinocchio's five (the same bits, tested).  The
    observer's calls, work rows and ``pin.Data``; ``_scratch_delta`` is overwritten by every
    step.  ``state_type``: the observer's state (a NamedTuple, built by ``tuple.__new__``)."""

    def __init__(self, observer: Any, state_type: type) -> None:
        rk4 = observer._scratch_calls
        assert rk4 is not None and observer._scratch_derivatives is not None
        (self.aba, _, _), self.w, self.start, self.stage = rk4
        self.point = (self.w[6], self.w[7])
        calls = observer._scratch_derivatives
        self.derivatives, data = calls.derivatives, calls.data
        self.ddq, self.ddq_dq, self.ddq_dv = data.ddq, data.ddq_dq, data.ddq_dv
        self.last, self.correction = loaded(rk4_last_kernel), loaded(riccati_correction_kernel)
        self._scratch_delta = np.empty(observer.robot.nv)
        self.state_type = state_type

    def step(self, obs: Any, state: Any, dt: float, q_meas: Vector, tau: Vector) -> Any:
        """:meth:`~pinobs.observers.riemannian.RiemannianObserver.step` with ``q_meas``, from a
        ``state`` with the schedule's ``P``."""
        aba, w, stage, delta = self.aba, self.w, self.stage, self._scratch_delta
        q, v = self.point
        self.start(w, state.q, state.v, aba(state.q, state.v, tau), dt)
        stage(w, aba(q, v, tau), 2, dt)
        stage(w, aba(q, v, tau), 3, dt)
        self.last(w, aba(q, v, tau), dt, q_meas, delta)
        h = state.elapsed + dt
        p00, p01, p11 = state.P  # the schedule's innovation variance and the gate (step)
        s_inn = p00 + h * (2.0 * p01 + h * p11 + obs.accel_psd * h * h / 3.0) + obs._sigma2
        gate = state.gate.measured(float(delta.dot(delta)) / s_inn, obs._gate, delta.size)
        if gate.gated:
            return state._replace(q=q.copy(), v=v.copy(), elapsed=h, gate=gate)
        c = obs.gains.curvature_gain
        jac, age = state.jacobi, state.age + 1
        if c != 0.0 and (jac is None or age >= obs.curvature_every):  # due (obs._jacobi)
            calls = obs._scratch_jacobi
            jac, age = obs._jacobi(state, q, v, c) if calls is None else (calls(q, v), 0)
        self.derivatives(q, delta, tau)  # (RiemannianObserver._jacobians)
        q_new, v_new = np.empty(delta.size), np.empty(delta.size)
        P = self.correction(q, v, self.ddq, self.ddq_dq, self.ddq_dv, delta,
                            obs._zero_nn if jac is None else jac, p00, p01, p11,
                            obs.accel_psd, obs._sigma2, h, c, q_new, v_new)  # fmt: skip
        return _new_tuple(self.state_type, (q_new, v_new, 0.0, jac, age, P, gate))


def vector_correction_into(
    q: Vector, v: Vector, acc: Vector, a_q: Vector, a_v: Vector, delta: Vector, jac: Vector,
    k1: float, k2: float, h: float, ch: float, q_new: Vector, v_new: Vector,
) -> None:  # fmt: skip
    """The correction's arithmetic on a vector space: ``(q̂⁺, v̂⁺)`` into ``(q_new, v_new)``.

    With ``a, ∂a/∂q, ∂a/∂v`` the ABA derivatives at ``(q̂⁻, δ, τ)``,
    ``u = (∂a/∂v)δ = −2Γs(δ, δ)``, ``d = (∂a/∂q)δ``::

        ζ = −δ + ¼u                              (second-order log, MATH §4)
        w = k₁ v̂ − h (a − ½u + d)                (S at q = a + Γs(δ,δ) + d)
        q̂⁺ = q̂ − k₁ ζ
        v̂⁺ = v̂ + ½(∂a/∂v) w − k₂ ζ + h d + C h J ζ

    (``½(∂a/∂v)w = ω(ζ, w)`` to first order: Maithripala et al. eq. (19);
    ``J ζ = R(v̂, ζ)v̂``: Anisi–Hamberg eq. (6)).  For six joints NumPy would
    spend more time dispatching a dozen tiny operations than computing them.
    """
    n = q.shape[0]
    zeta = np.empty(n)
    d = np.empty(n)
    half_w = np.empty(n)
    for i in range(n):
        u_i = 0.0
        d_i = 0.0
        for j in range(n):
            u_i += a_v[i, j] * delta[j]
            d_i += a_q[i, j] * delta[j]
        d[i] = d_i
        zeta[i] = 0.25 * u_i - delta[i]
        half_w[i] = 0.5 * (k1 * v[i] - h * (acc[i] - 0.5 * u_i + d_i))
    for i in range(n):
        transport = 0.0
        curvature = 0.0
        for j in range(n):
            transport += a_v[i, j] * half_w[j]
            curvature += jac[i, j] * zeta[j]
        v_new[i] = v[i] + transport - k2 * zeta[i] + h * d[i] + ch * curvature
        q_new[i] = q[i] - k1 * zeta[i]


def vector_correction_loops(
    q: Vector, v: Vector, acc: Vector, a_q: Vector, a_v: Vector, delta: Vector, jac: Vector,
    k1: float, k2: float, h: float, ch: float,
) -> tuple[Vector, Vector]:  # fmt: skip
    """:func:`vector_correction_into`, compiled (one call), ``(q̂⁺, v̂⁺)`` new arrays."""
    q_new = np.empty(q.shape[0])
    v_new = np.empty(q.shape[0])
    vector_correction_into(q, v, acc, a_q, a_v, delta, jac, k1, k2, h, ch, q_new, v_new)
    return q_new, v_new


def riccati_gains(
    p00: float, p01: float, p11: float, qa: float, r2: float, h: float
) -> tuple[float, float, float, float, float]:
    """The Riccati schedule's step (:mod:`pinobs.observers.riemannian`'s module docstring):
    ``P⁻ = F P Fᵀ + Q``, ``(k₁, k₂) = K = P⁻Hᵀ/(P⁻₀₀ + σ²)``, and the Joseph update;
    returns ``(k₁, k₂, P⁺₀₀, P⁺₀₁, P⁺₁₁)`` (``qa`` the acceleration density [rad²/s³],
    ``r2 = σ²``, ``h`` [s]).  Plain Python for the NumPy path, inlined in the kernel."""
    p00 += h * (2.0 * p01 + h * p11 + qa * h * h / 3.0)  # P⁻ = F P Fᵀ + Q
    p01 += h * (p11 + 0.5 * qa * h)
    p11 += qa * h
    s = 1.0 / (p00 + r2)
    k1, k2 = p00 * s, p01 * s  # K = P⁻Hᵀ (H P⁻Hᵀ + σ²)⁻¹
    m = 1.0 - k1
    return (  # Joseph form (I − KH) P⁻ (I − KH)ᵀ + K σ² Kᵀ
        k1,
        k2,
        m * m * p00 + r2 * k1 * k1,
        m * (p01 - k2 * p00) + r2 * k1 * k2,
        k2 * k2 * (p00 + r2) - 2.0 * k2 * p01 + p11,
    )


def riccati_correction_loops(
    q: Vector, v: Vector, acc: Vector, a_q: Vector, a_v: Vector, delta: Vector, jac: Vector,
    p00: float, p01: float, p11: float, qa: float, r2: float, h: float, c: float,
    q_new: Vector, v_new: Vector,
) -> tuple[float, float, float]:  # fmt: skip
    """:func:`vector_correction_into` with the gains of :func:`riccati_gains` (the Riccati
    schedule of :meth:`pinobs.observers.riemannian.RiemannianObserver._correction_gains`):
    ``(q̂⁺, v̂⁺)`` into ``(q_new, v_new)`` (the caller's: arrays a numba kernel returns cost
    two Python calls more to box), returns ``(P⁺₀₀, P⁺₀₁, P⁺₁₁)`` (``c`` the curvature gain)."""
    k1, k2, p00, p01, p11 = riccati_gains(p00, p01, p11, qa, r2, h)
    vector_correction_into(q, v, acc, a_q, a_v, delta, jac, k1, k2, h, c * h, q_new, v_new)
    return p00, p01, p11


def rk4_last_loops(w: Vector, acc: Vector, h: float, q_meas: Vector, delta: Vector) -> None:
    """The RK4's fourth stage (:func:`rk4_stage_loops`, with ``contract``: its bits) and
    ``δ = q_meas − q⁻`` (``difference`` on a vector space) in one call."""
    _rk4_stage_fma(w, acc, 4, h)
    for i in range(delta.shape[0]):
        delta[i] = q_meas[i] - w[6, i]


def _warm_predict() -> tuple[object, ...]:
    one, two = np.zeros((1, 1)), np.zeros((2, 2))
    return (np.zeros((8, 1)), np.zeros(1), np.zeros(1), np.zeros(1), one, one, one, np.eye(2),
            1e-3, 1.0, np.zeros(1), np.zeros((2, 2)), np.zeros((2, 2)), two)  # fmt: skip


#: :func:`rk4_start_loops` compiled: ``(w, q, v, a₁, h)``.
rk4_start_kernel = LazyKernel(
    rk4_start_loops, np.zeros((8, 1)), np.zeros(1), np.zeros(1), np.zeros(1), 1e-3, contract=True
)
#: :func:`rk4_stage_loops` compiled: ``(w, a, stage, h)``.
rk4_stage_kernel = LazyKernel(
    rk4_stage_loops, np.zeros((8, 1)), np.zeros(1), 2, 1e-3, contract=True
)
#: :func:`ekf_predict_loops` compiled.
ekf_predict_kernel = LazyKernel(
    ekf_predict_loops,
    *_warm_predict(),
    helpers=(rk4_start_loops, _transition_into, _sandwich_into),
    contract=True,
)
#: :func:`ekf_correct_loops` compiled: returns the NIS (NaN: take the NumPy way).
ekf_correct_kernel = LazyKernel(
    ekf_correct_loops,
    np.zeros((8, 1)), np.zeros(1), np.eye(2), 1.0, np.zeros(1), np.zeros(2), np.zeros((2, 2)),
    np.zeros(1), np.zeros(1),
    helpers=(_joseph_loops,),
)  # fmt: skip

#: :func:`ekf_finish_loops` compiled.
ekf_finish_kernel = LazyKernel(
    ekf_finish_loops,
    np.zeros((8, 1)), np.zeros(1), 1e-3, np.zeros(1), np.eye(2), 1.0, np.zeros(3),
    np.zeros((2, 2)), np.zeros(1), np.zeros(1), np.zeros(0), np.zeros(0),
    helpers=(_joseph_loops, ekf_correct_loops),
    contracted=("_rk4_stage_fma",),
)  # fmt: skip
#: :func:`torque_in_loops` compiled.
torque_in_kernel = LazyKernel(torque_in_loops, np.zeros(1), np.zeros(1), np.zeros(1))

#: :func:`ekf_coast_loops` compiled.
ekf_coast_kernel = LazyKernel(
    ekf_coast_loops, np.zeros((8, 1)), np.zeros(1), 1e-3, np.eye(2), np.zeros((2, 2)),
    contracted=("_rk4_stage_fma",),
)  # fmt: skip


#: :func:`rkmk4_stage_loops` compiled: ``(w, a, k, stage, h)`` (no contraction: the bits of
#: NumPy's separate products and sums).
rkmk4_stage_kernel = LazyKernel(
    rkmk4_stage_loops, np.zeros((10, 1)), np.zeros(1), np.zeros(1), 1, 1e-3
)
#: :func:`lie_correction_loops` compiled.
lie_correction_kernel = LazyKernel(
    lie_correction_loops,
    *(np.zeros(1), np.zeros(1), np.zeros((1, 1)), np.zeros((1, 1)), np.zeros(1)),
    np.zeros((1, 1)),
    0.5,
    0.5,
    1e-3,
    0.0,
    *(np.zeros(1),) * 4,
)
#: :func:`vector_correction_loops` compiled.
vector_correction_kernel = LazyKernel(
    vector_correction_loops, *(np.zeros(1),) * 3, np.zeros((1, 1)), np.zeros((1, 1)),
    np.zeros(1), np.zeros((1, 1)), 0.0, 0.0, 0.0, 0.0,
    helpers=(vector_correction_into,),
)  # fmt: skip
#: :func:`riccati_correction_loops` compiled.
riccati_correction_kernel = LazyKernel(
    riccati_correction_loops, *(np.zeros(1),) * 3, np.zeros((1, 1)), np.zeros((1, 1)),
    np.zeros(1), np.zeros((1, 1)), *(1.0,) * 7, np.zeros(1), np.zeros(1),
    helpers=(vector_correction_into, riccati_gains),
)  # fmt: skip
#: :func:`rk4_last_loops` compiled.
rk4_last_kernel = LazyKernel(
    rk4_last_loops, np.zeros((8, 1)), np.zeros(1), 1e-3, np.zeros(1), np.zeros(1),
    contracted=("_rk4_stage_fma",),
)  # fmt: skip


def rk4_calls(
    robot: Robot,
) -> tuple[DynamicsCalls, Vector, Callable[..., Any], Callable[..., Any]] | None:
    """Pinocchio's calls on a new ``pin.Data`` (the observer's own), the work rows of the
    compiled RK4 step and its two kernels: for a :class:`Robot` on a vector space without
    joint friction; ``None`` elsewhere (:func:`pinobs.model.dynamics_rk4`)."""
    if not (isinstance(robot, Robot) and robot.is_vector_space and not robot.has_friction):
        return None
    w = np.zeros((8, robot.nv))
    return dynamics_calls(robot), w, loaded(rk4_start_kernel), loaded(rk4_stage_kernel)


def loaded(kernel: LazyKernel) -> Callable[..., Any]:
    """``kernel``'s compiled function, loaded (or compiled once) now if it is not yet."""
    kernel.load()
    assert kernel.compiled is not None  # (load sets it)
    return kernel.compiled
