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

The equations are those of :mod:`pinobs.observers.ekf` and :mod:`pinobs.model.integrators`;
the compiled steps equal the NumPy ones to rounding (the tests compare them).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.linalg import LazyKernel, joseph_kernel

__all__ = [
    "ekf_correct_kernel",
    "ekf_predict_kernel",
    "loaded",
    "rk4_stage_kernel",
    "rk4_start_kernel",
]

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


def _times_a(A: Vector, X: Vector, nv: int, c: float, out: Vector) -> None:
    """``out = I + c A X`` for the EKF's ``A`` (rows ``[0 I 0]``, ``[∂a/∂q ∂a/∂v M⁻¹]``, ``0``):
    the products with its constant rows are copies (the same numbers as the full sums, whose
    other terms are exact zeros)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            if i < nv:
                t = X[nv + i, j]
            elif i < 2 * nv:
                t = 0.0
                for k in range(n):
                    t += A[i, k] * X[k, j]
            else:
                t = 0.0
            out[i, j] = c * t + (1.0 if i == j else 0.0)


def ekf_predict_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
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
    inner = np.empty((n, n))  # I + Ah/3
    for i in range(n):
        for j in range(n):
            inner[i, j] = A[i, j] * h / 3.0 + (1.0 if i == j else 0.0)
    mid = np.empty((n, n))
    _times_a(A, inner, nv, 0.5 * h, mid)  # I + (Ah/2)(I + Ah/3)
    _times_a(A, mid, nv, h, Phi)
    T = np.zeros((n, n))  # Φ P, row by row (each sum in the order of k: vector loops over j)
    for i in range(n):
        for k in range(n):
            c = Phi[i, k]
            for j in range(n):
                T[i, j] += c * P[k, j]
    Phi_t = Phi.T.copy()
    out[:, :] = 0.0  # (Φ P) Φᵀ, its upper triangle
    for i in range(n):
        for k in range(n):
            c = T[i, k]
            for j in range(i, n):
                out[i, j] += c * Phi_t[k, j]
        for j in range(i + 1, n):
            out[j, i] = out[i, j]
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
    ekf_predict_loops, *_warm_predict(), helpers=(rk4_start_loops, _times_a), contract=True
)
#: :func:`ekf_correct_loops` compiled: returns the NIS (NaN: take the NumPy way).
ekf_correct_kernel = LazyKernel(
    ekf_correct_loops,
    np.zeros((8, 1)), np.zeros(1), np.eye(2), 1.0, np.zeros(1), np.zeros(2), np.zeros((2, 2)),
    np.zeros(1), np.zeros(1),
    helpers=(_joseph_loops,),
)  # fmt: skip


def loaded(kernel: LazyKernel) -> Callable[..., Any]:
    """``kernel``'s compiled function, loaded (or compiled once) now if it is not yet."""
    kernel.load()
    assert kernel.compiled is not None  # (load sets it)
    return kernel.compiled
