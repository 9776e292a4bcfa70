"""The noise band: the covariance of the smoothed estimate's error driven by the measurement
noise alone (``band="noise"``; :mod:`pinobs.smoothing`, "The noise band"), forward and
backward, with compiled loops where numba is installed."""

from __future__ import annotations

from typing import Any

import numpy as np

from pinobs.observers.base import (
    Vector,
)
from pinobs.observers.linalg import LazyKernel

__all__ = [
    "NOISE_KERNEL_MAX",
    "noise_backward",
    "noise_backward_kernel",
    "noise_forward",
    "noise_forward_kernel",
    "noise_step",
    "was_gated",
]


def was_gated(state: Any) -> bool:
    """Whether the filter's outlier gate rejected ``state``'s measurement (its ``gate``,
    :class:`~pinobs.observers.base.GateState`; a filter without a gate: never)."""
    gate = getattr(state, "gate", None)
    return gate is not None and bool(gate.gated)


def noise_step(
    prev: tuple[Vector, Vector | None] | None,
    pred: Any,
    F: Any,
    state: Any,
    nv: int,
    meas_var: float,
) -> tuple[Vector, Vector | None]:
    """``(Pⁿ⁺_k, K_k)``: the filter's error covariance driven by the measurement noise alone.

    The filter's estimate is linear in the measurements (to first order); its
    error, under the model's own dynamics with no process noise, obeys (the
    actual covariance of a filter whose gains were designed for another noise
    model: Gelb, *Applied Optimal Estimation*, 1974, §7.2)::

        Pⁿ⁺_k = (I − K_k H) F_{k−1} Pⁿ⁺_{k−1} F_{k−1}ᵀ (I − K_k H)ᵀ + σ² K_k K_kᵀ

    with ``F_{k−1}`` the Jacobian of the mean's step, by which the error
    propagates (the filter's ``Φ`` only approximates it; ``F = Φ`` for a
    filter without ``predict_flow``), ``K_k = P⁻_k Hᵀ (H P⁻_k Hᵀ + σ² I)⁻¹ =
    P⁺_k Hᵀ / σ²`` the filter's own gain (``H = [I 0]``; the second form, free,
    holds for the Kalman gain: ``P⁺Hᵀ = P⁻Hᵀ − K (S − σ² I) = σ² K``;
    ``K = None`` at a dropped or gated sample, where ``Pⁿ⁺_k = F Pⁿ⁺_{k−1} Fᵀ``)
    and ``Pⁿ⁺_0 = P⁺_0`` (the start's uncertainty is kept).  Evaluated as
    ``Y = X − K X_q·``, ``Pⁿ⁺ = Y − (Y_·q − σ² K) Kᵀ`` with ``X = F Pⁿ⁺ Fᵀ``
    (as :func:`pinobs.observers.linalg.joseph_update`).
    """
    if prev is None:
        return state.P.copy(), None
    if state is pred or was_gated(state):  # predicted over, not corrected
        return noise_forward(prev[0], F, None, meas_var), None
    K = state.P[:, :nv] / meas_var
    return noise_forward(prev[0], F, K, meas_var), K


def _noise_forward_loops(Pn: Vector, Phi: Vector, K: Vector, r: float, out: Vector) -> None:  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    """:func:`noise_forward` in loops (compiled by numba for small matrices); ``K`` with no
    columns: no correction."""
    m, nv = Pn.shape[0], K.shape[1]
    T = np.zeros((m, m))  # Φ Pn (Φ is sparse: its zeros skipped)
    for i in range(m):
        for k in range(m):
            a = Phi[i, k]
            if a != 0.0:
                for j in range(m):
                    T[i, j] += a * Pn[k, j]
    X = np.zeros((m, m))  # T Φᵀ
    for j in range(m):
        for k in range(m):
            a = Phi[j, k]
            if a != 0.0:
                for i in range(m):
                    X[i, j] += T[i, k] * a
    for i in range(m):  # Y = X − K X_q·, then out = Y − (Y_·q − r K) Kᵀ
        for j in range(m):
            t = X[i, j]
            for k in range(nv):
                t -= K[i, k] * X[k, j]
            T[i, j] = t
    for i in range(m):
        for j in range(m):
            t = T[i, j]
            for k in range(nv):
                t -= (T[i, k] - r * K[i, k]) * K[j, k]
            out[i, j] = t


def noise_forward(Pn: Vector, Phi: Vector, K: Vector | None, r: float) -> Vector:
    """``(I − K H) Φ Pn Φᵀ (I − K H)ᵀ + r K Kᵀ`` (``K = None``: ``Φ Pn Φᵀ``), evaluated as
    ``X = Φ Pn Φᵀ``, ``Y = X − K X_q·``, ``Y − (Y_·q − r K) Kᵀ`` (as
    :func:`pinobs.observers.linalg.joseph_update`)."""
    m = Pn.shape[0]
    if m <= NOISE_KERNEL_MAX and noise_forward_kernel.compiled is not None:
        out = np.empty((m, m))
        k = _NO_GAIN if K is None else K
        noise_forward_kernel.compiled(Pn, np.ascontiguousarray(Phi), k, r, out)
        return out
    X = Phi @ Pn @ Phi.T
    if K is None:
        return X
    nv = K.shape[1]
    Y = X - K @ X[:nv]
    return Y - (Y[:, :nv] - r * K) @ K.T


def _noise_backward_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    B: Vector, U: Vector, G: Vector, Phi: Vector, K: Vector, Pn: Vector, r: float, var: Vector
) -> None:
    """:func:`noise_backward` in loops, ``B`` and ``U`` updated in place (compiled by numba
    for small matrices); ``K`` with no columns: no correction at the later sample."""
    m, nk, nv = B.shape[0], K.shape[1], var.shape[0]
    D = np.zeros((m, m))  # B Φ − Φ, then − (B K) Φ_q·
    for i in range(m):
        for k in range(m):
            a = B[i, k]
            if a != 0.0:
                for j in range(m):
                    D[i, j] += a * Phi[k, j]
    D -= Phi
    if nk > 0:
        BK = np.zeros((m, nk))
        for i in range(m):
            for k in range(m):
                a = B[i, k]
                for j in range(nk):
                    BK[i, j] += a * K[k, j]
        for i in range(m):
            for k in range(nk):
                a = BK[i, k]
                for j in range(m):
                    D[i, j] -= a * Phi[k, j]
        for i in range(m):
            for j in range(m):
                t = 0.0
                for k in range(nk):
                    t += BK[i, k] * BK[j, k]
                U[i, j] += r * t
    T = np.zeros((m, m))  # U ← G U Gᵀ
    for i in range(m):
        for k in range(m):
            a = G[i, k]
            for j in range(m):
                T[i, j] += a * U[k, j]
    for i in range(m):
        for j in range(m):
            t = 0.0
            for k in range(m):
                t += T[i, k] * G[j, k]
            U[i, j] = t
    for i in range(m):  # B ← G D + I
        for j in range(m):
            t = 1.0 if i == j else 0.0
            for k in range(m):
                t += G[i, k] * D[k, j]
            B[i, j] = t
    for i in range(nv):  # (B Pn Bᵀ + U) at the velocity rows nv..2nv
        row = nv + i
        t = U[row, row]
        for j in range(m):
            a = 0.0
            for k in range(m):
                a += Pn[j, k] * B[row, k]
            t += B[row, j] * a
        var[i] = t


def noise_backward(
    B: Vector, U: Vector, G: Vector, Phi: Vector, K: Vector | None, Pn: Vector, r: float, nv: int
) -> tuple[Vector, Vector, Vector]:
    """One step of :func:`_backward`'s ``B, U`` recursion: ``(B_k, U_k, var)`` from
    ``B_{k+1}, U_{k+1}`` (``K = K_{k+1}``, ``Pn = Pⁿ⁺_k``), ``var`` the velocity entries of
    ``B_k Pn B_kᵀ + U_k``."""
    m = B.shape[0]
    if m <= NOISE_KERNEL_MAX and noise_backward_kernel.compiled is not None:
        B, U, var = B.copy(), U.copy(), np.empty(nv)
        k = _NO_GAIN if K is None else K
        noise_backward_kernel.compiled(
            B, U, np.ascontiguousarray(G), np.ascontiguousarray(Phi), k, Pn, r, var
        )
        return B, U, var
    BAPhi = B @ Phi
    if K is not None:
        BK = B @ K
        BAPhi -= BK @ Phi[:nv]  # B (I − K H) Φ, H Φ = Φ's first nv rows
        U = U + r * (BK @ BK.T)
    U = G @ U @ G.T
    B = G @ (BAPhi - Phi)
    B.flat[:: m + 1] += 1.0
    Bv = B[nv : 2 * nv]
    return B, U, np.einsum("ij,ij->i", Bv @ Pn, Bv) + U.diagonal()[nv : 2 * nv]


NOISE_KERNEL_MAX = 20  # states: above, NumPy's BLAS products win (crossover measured at 21)


_NO_GAIN = np.empty((0, 0))


noise_forward_kernel = LazyKernel(
    _noise_forward_loops, np.eye(2), np.eye(2), np.zeros((2, 1)), 1.0, np.zeros((2, 2))
)


noise_backward_kernel = LazyKernel(
    _noise_backward_loops,
    np.eye(2),
    np.eye(2),
    np.eye(2),
    np.eye(2),
    np.zeros((2, 1)),
    np.eye(2),
    1.0,
    np.zeros(1),
)
