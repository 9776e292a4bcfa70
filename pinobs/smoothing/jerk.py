"""The compiled smoother of the model-free white-jerk filter (``kf`` on a vector-space robot):
its forward pass is the filter bank's, its backward pass (and noise band) per joint in numba
kernels (:func:`white_jerk_smooth`)."""

from __future__ import annotations

import functools
import math
from typing import Any, cast

import numpy as np

from pinobs.observers.base import (
    Vector,
)
from pinobs.observers.kf import KFBank, WhiteJerkFilter
from pinobs.observers.linalg import LazyKernel

__all__ = ["white_jerk_smooth"]


def _jerk_noise_loops(PX: Vector, t: Vector, measured: Vector, r: float, Pn: Vector) -> None:  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    """:func:`noise_step` for the white-jerk filter on its 3×3 factor (``P = P₃ ⊗ I``, so
    ``Pⁿ = Pⁿ₃ ⊗ I``), every row: ``Pⁿ₀ = P⁺₀``, then ``X = F Pⁿ_{k−1} Fᵀ`` and, at a row
    corrected with its measurement (``measured``: neither dropped nor gated), ``K = P⁺_k[:, 0] /
    σ²``, ``Y = X − K X₀·``, ``Pⁿ_k = Y − (Y·₀ − σ² K) Kᵀ``."""
    F, T, X, K = np.eye(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    for i in range(3):
        for j in range(3):
            Pn[0, i, j] = PX[0, i, j]
    for k in range(1, t.size):
        h = t[k] - t[k - 1]
        F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h  # F(h) (pinobs.observers.kf.transition)
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += F[i, m] * Pn[k - 1, m, j]
                T[i, j] = s
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += T[i, m] * F[j, m]
                X[i, j] = s
        if not measured[k]:
            for i in range(3):
                for j in range(3):
                    Pn[k, i, j] = X[i, j]
            continue
        for i in range(3):
            K[i] = PX[k, i, 0] / r
        for i in range(3):
            for j in range(3):
                T[i, j] = X[i, j] - K[i] * X[0, j]
        for i in range(3):
            for j in range(3):
                Pn[k, i, j] = T[i, j] - (T[i, 0] - r * K[i]) * K[j]


def _jerk_gain_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    PX: Vector,
    k: int,
    h: float,
    jerk: float,
    F: Vector,
    Q: Vector,
    W: Vector,
    Pp: Vector,
    L: Vector,
    G: Vector,
) -> None:
    """The step ``k → k+1`` of :func:`_jerk_backward_loops`: ``F(h)``, ``Q(h)``
    (:func:`pinobs.observers.kf.transition`), ``W = F P⁺_k``, ``P⁻_{k+1} = W Fᵀ + Q = L Lᵀ``
    and the smoother gain ``Gᵀ = (P⁻_{k+1})⁻¹ W`` (3×3 factors), into the arrays given."""
    F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h
    Q[0, 0], Q[0, 1], Q[0, 2] = jerk * h**5 / 20, jerk * h**4 / 8, jerk * h**3 / 6
    Q[1, 1], Q[1, 2], Q[2, 2] = jerk * h**3 / 3, jerk * h**2 / 2, jerk * h
    Q[1, 0], Q[2, 0], Q[2, 1] = Q[0, 1], Q[0, 2], Q[1, 2]
    for i in range(3):  # W = F P⁺_k, P⁻_{k+1} = W Fᵀ + Q
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += F[i, m] * PX[k, m, j]
            W[i, j] = s
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += W[i, m] * F[j, m]
            Pp[i, j] = s + Q[i, j]
    for j in range(3):  # P⁻ = L Lᵀ
        s = Pp[j, j]
        for m in range(j):
            s -= L[j, m] * L[j, m]
        L[j, j] = math.sqrt(s) if s > 0.0 else math.nan  # lost: NaN, reported by smooth()
        for i in range(j + 1, 3):
            s = Pp[i, j]
            for m in range(j):
                s -= L[i, m] * L[j, m]
            L[i, j] = s / L[j, j]
    for c in range(3):  # Gᵀ = (P⁻)⁻¹ W, column by column  [Särkkä 2013, Thm 8.2]
        for i in range(3):
            s = W[i, c]
            for m in range(i):
                s -= L[i, m] * G[c, m]
            G[c, i] = s / L[i, i]
        for i in range(2, -1, -1):
            s = G[c, i]
            for m in range(i + 1, 3):
                s -= L[m, i] * G[c, m]
            G[c, i] = s / L[i, i]


def _jerk_covariance_loops(
    PX: Vector, k: int, G: Vector, Pp: Vector, Ps: Vector, T: Vector, W: Vector
) -> None:
    """``P^s_k = P⁺_k + G (P^s_{k+1} − P⁻_{k+1}) Gᵀ`` (symmetrised) into ``Ps``, which holds
    ``P^s_{k+1}`` on entry [Särkkä 2013, Thm 8.2]; ``T`` and ``W`` are scratch."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += G[i, m] * (Ps[m, j] - Pp[m, j])
            T[i, j] = s
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += T[i, m] * G[j, m]
            W[i, j] = PX[k, i, j] + s
    for i in range(3):
        for j in range(3):
            Ps[i, j] = 0.5 * (W[i, j] + W[j, i])


def _jerk_band_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    PX: Vector,
    k: int,
    measured: Vector,
    r: float,
    F: Vector,
    G: Vector,
    B: Vector,
    U: Vector,
    D: Vector,
    T: Vector,
    W: Vector,
    BK: Vector,
) -> None:
    """:func:`noise_backward`'s ``B, U`` recursion from ``k+1`` to ``k`` on the 3×3 factors
    (``K = K_{k+1} = P⁺_{k+1}[:, 0] / σ²`` where row ``k+1`` was corrected):
    ``D = B F − F − (B K) Hᵢ F``, ``U ← G (U + σ² (B K)(B K)ᵀ) Gᵀ``, ``B ← G D + I``;
    ``D``, ``T``, ``W``, ``BK`` are scratch."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += B[i, m] * F[m, j]
            D[i, j] = s - F[i, j]
    if measured[k + 1]:
        for i in range(3):
            s = 0.0
            for m in range(3):
                s += B[i, m] * PX[k + 1, m, 0]
            BK[i] = s / r
        for i in range(3):
            for j in range(3):
                D[i, j] -= BK[i] * F[0, j]
                U[i, j] += r * BK[i] * BK[j]
    for i in range(3):  # U ← G U Gᵀ
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += G[i, m] * U[m, j]
            T[i, j] = s
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += T[i, m] * G[j, m]
            W[i, j] = s
    for i in range(3):  # B ← G D + I
        for j in range(3):
            U[i, j] = W[i, j]
            s = 1.0 if i == j else 0.0
            for m in range(3):
                s += G[i, m] * D[m, j]
            T[i, j] = s
    for i in range(3):
        for j in range(3):
            B[i, j] = T[i, j]


#: The steps :func:`_jerk_backward_loops` calls: these Python functions, replaced by their
#: compiled forms (:func:`_backward_kernel`) before it is compiled (numba calls only compiled
#: functions from compiled code).
_gain_step: Any = _jerk_gain_loops
_covariance_step: Any = _jerk_covariance_loops
_band_step: Any = _jerk_band_loops


def _jerk_backward_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    X: Vector,
    PX: Vector,
    Pn: Vector,
    t: Vector,
    measured: Vector,
    jerk: float,
    r: float,
    start: int,
    stop: int,
    keep: int,
    noise: bool,
    qs: Vector,
    vs: Vector,
    var: Vector,
    rho: Vector,
) -> None:
    """:func:`_backward` (and :class:`Smoother`'s ``ρ`` terms) for the white-jerk filter on the
    rows ``start..stop−1``, from the filtered state at ``stop − 1``, in loops (compiled by
    numba).  Every direction shares ``F``, ``Q`` and ``H``, so the gain is ``G₃ ⊗ I`` with
    ``G₃ = P⁺₃ Fᵀ (P⁻₃)⁻¹`` (3×3: :func:`_jerk_gain_loops`) and the means move joint by joint;
    the covariances (``P^s``, the noise band's ``B, U``) are their 3×3 factors.  Writes the
    rows ``start..start+keep−1``: ``qs``, ``vs`` and ``var`` (the velocity variance of the
    model band, or of the noise band with ``noise``; one per row, every direction's), and adds
    ``ρ``'s sum and count to ``rho``.  ``X[k] = (q, v, a)`` and ``PX[k]`` the filter's (from
    :meth:`pinobs.observers.kf.KFBank.run`, ``measured`` its rows corrected), ``Pn``
    :func:`_jerk_noise_loops`'."""
    nv = X.shape[2]
    F, B, L, U = np.eye(3), np.eye(3), np.zeros((3, 3)), np.zeros((3, 3))
    Q, W, Pp = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))  # scratch, set before use
    G, T, D = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    xs, xp, BK, Ps = np.empty((3, nv)), np.empty(3), np.empty(3), np.empty((3, 3))
    last = stop - 1
    for i in range(3):
        for j in range(nv):
            xs[i, j] = X[last, i, j]
        for j in range(3):
            Ps[i, j] = PX[last, i, j]
    if last - start < keep:  # the smoother is the filter there: no ρ term
        for j in range(nv):
            qs[last, j], vs[last, j] = xs[0, j], xs[1, j]
        var[last] = Pn[last, 1, 1] if noise else Ps[1, 1]
    for k in range(last - 1, start - 1, -1):
        h = t[k + 1] - t[k]
        _gain_step(PX, k, h, jerk, F, Q, W, Pp, L, G)
        for j in range(nv):  # x^s_k = x⁺_k + G (x^s_{k+1} − x⁻_{k+1}), joint by joint
            q, v, a = X[k, 0, j], X[k, 1, j], X[k, 2, j]
            xp[0], xp[1], xp[2] = q + v * h + 0.5 * h * h * a, v + h * a, a
            d0, d1, d2 = xs[0, j] - xp[0], xs[1, j] - xp[1], xs[2, j] - xp[2]
            for i in range(3):
                xs[i, j] = X[k, i, j] + G[i, 0] * d0 + G[i, 1] * d1 + G[i, 2] * d2
        _covariance_step(PX, k, G, Pp, Ps, T, W)
        if noise:  # noise_backward's B, U recursion, K = K_{k+1}
            _band_step(PX, k, measured, r, F, G, B, U, D, T, W, BK)
        if k - start >= keep:
            continue
        for j in range(nv):
            qs[k, j], vs[k, j] = xs[0, j], xs[1, j]
        if noise:  # (B Pⁿ_k Bᵀ + U)₁₁
            s = U[1, 1]
            for i in range(3):
                for j in range(3):
                    s += B[1, i] * Pn[k, i, j] * B[1, j]
            var[k] = s
        else:
            var[k] = Ps[1, 1]
        dvar = PX[k, 1, 1] - Ps[1, 1]
        if dvar > 1e-9 * PX[k, 1, 1]:  # as Smoother: not where the smoother is the filter
            for j in range(nv):
                rho[0] += (xs[1, j] - X[k, 1, j]) ** 2 / dvar
            rho[1] += nv


_jerk_noise_kernel = LazyKernel(
    _jerk_noise_loops, np.tile(np.eye(3), (2, 1, 1)), np.array([0.0, 1e-3]),
    np.array([False, True]), 1.0, np.zeros((2, 3, 3)),
)  # fmt: skip


@functools.cache
def _backward_kernel() -> Any:
    """:func:`_jerk_backward_loops` compiled (numba, ``cache=True``), its steps compiled
    first (as :mod:`pinobs.observers.ibrir_kalman`'s fused kernel)."""
    global _gain_step, _covariance_step, _band_step
    import numba  # lazy: start-up time

    _gain_step = numba.njit(cache=True)(_jerk_gain_loops)
    _covariance_step = numba.njit(cache=True)(_jerk_covariance_loops)
    _band_step = numba.njit(cache=True)(_jerk_band_loops)
    kernel = numba.njit(cache=True)(_jerk_backward_loops)
    kernel(
        np.zeros((2, 3, 1)), np.tile(np.eye(3), (2, 1, 1)), np.tile(np.eye(3), (2, 1, 1)),
        np.array([0.0, 1e-3]), np.array([False, True]), 1.0, 1.0, 0, 2, 2, True,
        np.zeros((2, 1)), np.zeros((2, 1)), np.zeros(2), np.zeros(2),
    )  # fmt: skip
    return kernel


def white_jerk_smooth(
    filt: WhiteJerkFilter,
    arrays: tuple[Vector, Vector, Vector, Vector],
    chunk: int | None,
    overlap: int,
    band: str,
) -> tuple[Vector, Vector, Vector, float, float, int]:
    """What :class:`Smoother` gives over ``filt`` (pushed ``arrays``' rows, ``chunk`` and
    ``overlap`` as there), on a robot whose joints are all vector joints, in compiled passes:
    the forward one (:meth:`pinobs.observers.kf.KFBank.run`, its states stored: ``3 nv + 9``
    numbers a row, and ``9`` more for the noise band), then the backward one per window
    (:func:`_jerk_backward_loops`).  Returns ``q^s``, ``v^s``, the band's velocity variance
    (every direction's), ``log_likelihood``, ``ρ``'s sum and count; tested equal to
    :class:`Smoother` (which costs about 4–7× the causal ``kf``)."""
    t, q, _, good = arrays
    gains = filt.gains
    bank = KFBank(filt.robot, (gains.jerk_psd,), gains.meas_std, gains.outlier_probability)
    ll, X, PX, used = bank.run(t, q, good, filt.v0_std)  # used: corrected (measured, not gated)
    t = np.ascontiguousarray(t, dtype=float)
    r, n, nv = gains.meas_std**2, t.size, filt.robot.nv
    noise = band == "noise"
    backward = _backward_kernel()
    Pn = PX
    if noise:
        _jerk_noise_kernel.load()
        Pn = np.empty_like(PX)
        cast(Any, _jerk_noise_kernel.compiled)(PX, t, used, r, Pn)
    qs, vs, var, rho = np.empty((n, nv)), np.empty((n, nv)), np.empty(n), np.zeros(2)
    chunk = n if chunk is None else chunk
    windows, start = [], 0
    measured = np.concatenate([[0], np.cumsum(good)])  # measured rows before each row
    while overlap and start + chunk + overlap <= n:  # overlap: measured rows (as Smoother)
        stop = max(
            start + chunk + overlap,
            int(np.searchsorted(measured, measured[start + chunk] + overlap)),
        )
        if stop > n:
            break
        windows.append((start, stop, chunk))
        start += chunk
    if start < n:
        windows.append((start, n, n - start))
    for start, stop, keep in windows:
        backward(X, PX, Pn, t, used, gains.jerk_psd, r, start, stop, keep, noise, qs, vs, var, rho)
    return qs, vs, np.repeat(var[:, None], nv, axis=1), float(ll[0]), float(rho[0]), int(rho[1])
