"""The differentiators' steps compiled, on robots whose configuration is a vector space (issue 39).

``sliding`` (:class:`~pinobs.observers.differentiators.SlidingDifferentiator`): the exact
drift of the chain and the implicit (or explicit) injection in one call
(:func:`sliding_loops`), where a step was 24 Python calls (its Taylor coefficients rebuilt
by list comprehensions at every step, the products by BLAS: the one-BLAS-thread limit
around every update).  ``highgain`` (:class:`~pinobs.observers.differentiators.HighGainDifferentiator`)
once its gain is steady: the first-order-hold step ``Z = Φ [q; X] + ψ₀ y₀ + ψ₁ ẏ`` in one
call (:func:`hold_loops`), ``Φ [q; X]`` with ``contract`` (OpenBLAS's ``gemm`` sums in the
order of ``k`` with fused multiply-adds: the same bits, tested), the rest without; its
``(Φ, ψ₀, ψ₁)`` at an interval other than the nominal one (jittered stamps) in one call too
(:func:`hold_between_loops`: ``exp(M h)^m`` times a Taylor series, module docstring of
:mod:`pinobs.observers.differentiators`; the products in loops, no BLAS).

``⊕`` is ``+`` and ``⊖`` is ``−`` there (Pinocchio's ``integrate`` and ``difference`` of a
revolute or prismatic joint).  ``sliding``'s drift ``Σ_m x̂_{j+m} h^m/m!`` was NumPy's
vector–matrix product (``gemv``, whose order of summation depends on the CPU's kernel): here
the sum in the order of ``m``, equal to it to rounding (tested to 1e-12); its coefficients
``h^m/m!`` are computed as Python did (``pow``, the factorial exact).
"""

from __future__ import annotations

import math

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.linalg import LazyKernel

__all__ = ["chain_rk4_kernel", "hold_between_kernel", "hold_kernel", "sliding_kernel"]


def _sign(x: float) -> float:
    """``np.sign``: −1, 0 or 1, NaN for NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x  # ±0 or NaN


def sliding_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small arrays
    q: Vector, X: Vector, q_meas: Vector, measured: bool, h: float, k: Vector, beta: Vector,
    implicit: bool, q_out: Vector, X_out: Vector,
) -> None:  # fmt: skip
    """One step of the sliding differentiator (:meth:`SlidingDifferentiator.step`): the drift
    ``x̂_j ← Σ_m x̂_{j+m} h^m/m!`` (``q ← q + Σ_m x̂_{m+2} h^{m+1}/(m+1)!``), then with a sample
    the injection at ``r = x̃₁ − y_k`` (module docstring of
    :mod:`pinobs.observers.differentiators`), into ``(q_out, X_out)``."""
    n1, nv = X.shape
    coef = np.empty(n1 + 1)  # h^m / m!, as Python's h ** m / math.factorial(m)
    fact = 1.0
    for m in range(n1 + 1):
        if m > 0:
            fact *= m
        coef[m] = math.pow(h, float(m)) / fact
    for i in range(nv):
        t = 0.0
        for m in range(n1):
            t += coef[m + 1] * X[m, i]
        q_out[i] = q[i] + t
        for j in range(n1):
            t = 0.0
            for m in range(n1 - j):
                t += coef[m] * X[j + m, i]
            X_out[j, i] = t
    if not measured:
        return
    hk1, hb1 = h * k[0], h * beta[0]
    for i in range(nv):
        r = -(q_meas[i] - q_out[i])  # x̃₁ − y_k = −difference(x̃₁, y_k)
        if implicit:
            if abs(r) <= hk1:
                s, sigma = r / hk1, 0.0
            else:
                sg = _sign(r)
                s, sigma = sg, (r - hk1 * sg) / (1.0 + hb1)
            dq = sigma - r
        else:
            s = _sign(r)
            sigma = r
            dq = -(hb1 * r + hk1 * s)
        q_out[i] = q_out[i] + dq
        for j in range(n1):
            X_out[j, i] = X_out[j, i] - h * (beta[j + 1] * sigma + k[j + 1] * s)


def _product_fma(Phi: Vector, q: Vector, X: Vector, out: Vector) -> None:
    """``out = Φ [q; X]`` (compiled on its own with ``contract``: ``gemm``'s bits)."""
    n = Phi.shape[0]
    for i in range(n):
        for j in range(q.shape[0]):
            t = 0.0
            for k in range(n):
                t += Phi[i, k] * (q[j] if k == 0 else X[k - 1, j])
            out[i, j] = t


def hold_loops(
    q: Vector, X: Vector, y_prev: Vector, q_meas: Vector, ratio: float, share: float, h: float,
    Phi: Vector, psi0: Vector, psi1: Vector, Z: Vector,
) -> None:  # fmt: skip
    """``highgain``'s steady step with a sample after a sample
    (:meth:`HighGainDifferentiator.step`): ``d = y_k − y_prev``, ``y₀ = y_prev + ratio·d``,
    ``ẏ = (share·d)/h`` and ``Z = Φ [q; X] + ψ₀ y₀ + ψ₁ ẏ`` (rows ``(q, X)``)."""
    _product_fma(Phi, q, X, Z)
    for j in range(q.shape[0]):
        d = q_meas[j] - y_prev[j]
        y0 = y_prev[j] + ratio * d
        yd = (share * d) / h
        for i in range(Z.shape[0]):
            Z[i, j] = Z[i, j] + psi0[i] * y0 + psi1[i] * yd


def _matmul(a: Vector, b: Vector, out: Vector) -> None:
    """``out = a b`` (square matrices; ``out`` another array)."""
    n = a.shape[0]
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += a[i, k] * b[k, j]
            out[i, j] = t


def hold_between_loops(
    E_h: Vector, M: Vector, h: float, dt: float, rho: float, Phi: Vector, psi0: Vector,
    psi1: Vector,
) -> None:  # fmt: skip
    """``highgain``'s first-order hold at an interval ``dt`` other than its nominal ``h``
    (:meth:`HighGainDifferentiator.hold_between`): ``exp(M dt) = exp(M h)^m exp(M r)``,
    ``m = round(dt/h)``, ``r = dt − m h``, the second factor by its Taylor series to the first
    term whose bound ``(ρ|r|)^{K+1}/(K+1)! e^{ρ|r|}`` is below the unit roundoff, in
    Horner's form; ``(Φ, ψ₀, ψ₁)``: the first ``n`` rows of its last three blocks."""
    N = M.shape[0]
    n = N - 2
    m = math.floor(dt / h + 0.5)
    r = dt - m * h
    x = abs(r) * rho
    bound = math.exp(x)
    K, term = 0, 1.0
    while term * x / (K + 1) * bound > 2.0**-53:
        K += 1
        term *= x / K
    T, W = np.eye(N), np.empty((N, N))
    for j in range(K, 0, -1):  # T ← I + (M r / j) T
        _matmul(M, T, W)
        c = r / j
        for a in range(N):
            for b in range(N):
                T[a, b] = (1.0 if a == b else 0.0) + c * W[a, b]
    P, B = np.eye(N), E_h.copy()
    while m > 0:  # P = exp(M h)^m by squaring
        if m & 1:
            _matmul(P, B, W)
            P[:, :] = W
        m >>= 1
        if m > 0:
            _matmul(B, B, W)
            B[:, :] = W
    _matmul(P, T, W)
    for a in range(n):
        for b in range(n):
            Phi[a, b] = W[a, b]
        psi0[a] = W[a, n]
        psi1[a] = W[a, n + 1]


def _fma(a: float, b: float, c: float) -> float:
    """``a·b + c`` (compiled on its own with ``contract``: one fused multiply-add)."""
    return a * b + c


def _first_gain(L: Vector, k: Vector) -> None:  # noqa: C901, PLR0912 -- numba kernel's helper
    """``k = L⁻¹ Cᵀ`` (``C = (1, 0, …, 0)``): ``np.linalg.solve``'s LAPACK ``gesv`` as
    OpenBLAS runs it on a small matrix, its operations in its order (``getf2``: left-looking
    LU with partial pivoting, dot products and ``gemv`` by fused multiply-adds, the
    multipliers scaled by the pivot's reciprocal; ``getrs``: row swaps, then the unit lower
    and the upper triangular solves by ``axpy``), so the same bits (tested against
    ``np.linalg.solve``)."""
    n = L.shape[0]
    A = L.copy()
    piv = np.empty(n, np.int64)
    for j in range(n):
        for i in range(j):  # the previous rows' swaps, on column j
            p = piv[i]
            if p != i:
                A[i, j], A[p, j] = A[p, j], A[i, j]
        for i in range(1, j):  # U's column: b_i −= L[i, :i]·b[:i]
            t = 0.0
            for m in range(i):
                t = _fma(A[i, m], A[m, j], t)
            A[i, j] = A[i, j] - t
        for r in range(j, n):  # the rest: b[j:] −= A[j:, :j] b[:j]
            t = 0.0
            for m in range(j):
                t = _fma(A[r, m], A[m, j], t)
            A[r, j] = _fma(-1.0, t, A[r, j])
        jp = j
        for r in range(j + 1, n):
            if abs(A[r, j]) > abs(A[jp, j]):
                jp = r
        piv[j] = jp
        if A[jp, j] != 0.0:
            if jp != j:
                for c in range(j + 1):
                    A[j, c], A[jp, c] = A[jp, c], A[j, c]
            inv = 1.0 / A[j, j]
            for r in range(j + 1, n):
                A[r, j] = A[r, j] * inv
    for i in range(n):
        k[i] = 1.0 if i == 0 else 0.0
    for i in range(n):
        p = piv[i]
        if p != i:
            k[i], k[p] = k[p], k[i]
    for i in range(n):  # L y = P Cᵀ (unit diagonal)
        for r in range(i + 1, n):
            k[r] = _fma(-k[i], A[r, i], k[r])
    for i in range(n - 1, -1, -1):  # U k = y
        k[i] = k[i] / A[i, i]
        for r in range(i):
            k[r] = _fma(-k[i], A[r, i], k[r])


def _chain_rhs(
    q: Vector, X: Vector, L: Vector, gamma: float, k_fixed: Vector, evolve: bool, t: float,
    mode: int, y0: Vector, d: Vector, h: float, k: Vector, u: Vector, Xd: Vector, Ld: Vector,
) -> None:  # fmt: skip
    """``highgain``'s vector field at one RK4 stage (Ibrir eqs. 7–8,
    :meth:`HighGainDifferentiator.vector_field`): ``u = x̂₂ + k₁ e``, ``Ẋ = shift(X) + k e``,
    ``e = y(t) − q``, ``y(t) = y0 + (t/h) d`` (no injection when ``mode`` is 0), ``k = L⁻¹Cᵀ``
    (``k_fixed`` when the gain does not ``evolve``) and ``L̇ = −γL − AᵀL − LA + CᵀC`` (the
    products with the chain ``A`` are shifts: the same numbers as the matrix products)."""
    n1, nv = X.shape
    if evolve:
        _first_gain(L, k)
        n = L.shape[0]
        for i in range(n):
            for j in range(n):
                v = -gamma * L[i, j]
                v = v - (L[i - 1, j] if i >= 1 else 0.0)  # (AᵀL)ᵢⱼ
                v = v - (L[i, j - 1] if j >= 1 else 0.0)  # (LA)ᵢⱼ
                Ld[i, j] = v + (1.0 if i == 0 and j == 0 else 0.0)
    else:
        for i in range(k.shape[0]):
            k[i] = k_fixed[i]
    s = t / h
    for i in range(nv):
        for j in range(n1 - 1):
            Xd[j, i] = X[j + 1, i]
        Xd[n1 - 1, i] = 0.0
        if mode == 0:
            u[i] = X[0, i]
        else:
            e = (y0[i] + s * d[i]) - q[i]
            u[i] = X[0, i] + k[0] * e
            for j in range(n1):
                Xd[j, i] = Xd[j, i] + k[j + 1] * e


def chain_rk4_loops(  # noqa: C901, PLR0912 -- numba kernel: loops over small arrays
    q: Vector, X: Vector, L: Vector, L_inf: Vector, tol: float, gamma: float,
    k_fixed: Vector, check: bool, mode: int, y_prev: Vector, q_meas: Vector, ratio: float,
    share: float, h: float, q_out: Vector, X_out: Vector, L_out: Vector,
) -> bool:  # fmt: skip
    """``highgain``'s RK4 step on a vector space (:meth:`HighGainDifferentiator.step`: the
    classical RK4 of :func:`~pinobs.model.lie_rk4` on ``(q, X, L, t)``, its operations in its
    order): with ``L`` evolving and ``L ← ½(L + Lᵀ)`` after, or with the fixed gain ``k_fixed``
    when ``check`` is false.  ``mode``: 0 no sample, 1 the first (``y = q_meas``), 2 after
    another (``y(t) = y_prev ⊕ ratio·d ⊕ (t/h)·share·d``, ``d = q_meas ⊖ y_prev``).  With
    ``check``, returns True and writes nothing when ``L`` is within ``tol`` of ``L∞`` (the
    caller takes the steady step)."""
    n1, nv = X.shape
    n = L.shape[0]
    if check:
        worst = 0.0
        for i in range(n):
            for j in range(n):
                a = abs(L[i, j] - L_inf[i, j])
                if a > worst or a != a:
                    worst = a
        if worst <= tol:
            return True
    evolve = check
    y0 = np.empty(nv)
    d = np.zeros(nv)
    for i in range(nv):
        if mode == 1:
            y0[i] = q_meas[i]
        elif mode == 2:
            dd = q_meas[i] - y_prev[i]
            y0[i] = y_prev[i] + ratio * dd
            d[i] = share * dd
    k = np.empty(n)
    us = np.empty((4, nv))
    Xs = np.empty((4, n1, nv))
    Ls = np.empty((4, n, n))
    ts = np.empty(4)
    qa = np.empty(nv)
    Xa = np.empty((n1, nv))
    La = np.empty((n, n))
    hh = 0.5 * h
    for stage in range(4):
        if stage == 0:
            c, ta = 0.0, 0.0
            qa[:] = q
            Xa[:, :] = X
            La[:, :] = L
        else:
            c = h if stage == 3 else hh
            p = stage - 1
            for i in range(nv):
                qa[i] = q[i] + c * us[p, i]
                for j in range(n1):
                    Xa[j, i] = X[j, i] + c * Xs[p, j, i]
            if evolve:
                for i in range(n):
                    for j in range(n):
                        La[i, j] = L[i, j] + c * Ls[p, i, j]
            ta = 0.0 + c * 1.0
        ts[stage] = ta
        _chain_rhs(qa, Xa, La, gamma, k_fixed, evolve, ta, mode, y0, d, h, k, us[stage],
                   Xs[stage], Ls[stage])  # fmt: skip
    c6 = h / 6.0
    for i in range(nv):
        q_out[i] = q[i] + c6 * (us[0, i] + 2.0 * (us[1, i] + us[2, i]) + us[3, i])
        for j in range(n1):
            X_out[j, i] = X[j, i] + c6 * (
                Xs[0, j, i] + 2.0 * (Xs[1, j, i] + Xs[2, j, i]) + Xs[3, j, i]
            )
    if evolve:
        for i in range(n):
            for j in range(n):
                La[i, j] = L[i, j] + c6 * (
                    Ls[0, i, j] + 2.0 * (Ls[1, i, j] + Ls[2, i, j]) + Ls[3, i, j]
                )
        for i in range(n):
            for j in range(n):
                L_out[i, j] = 0.5 * (La[i, j] + La[j, i])
    return False


#: :func:`sliding_loops` compiled.
sliding_kernel = LazyKernel(
    sliding_loops, np.zeros(2), np.zeros((3, 2)), np.zeros(2), True, 1e-3, np.ones(4),
    np.ones(4), True, np.zeros(2), np.zeros((3, 2)), helpers=(_sign,),
)  # fmt: skip
#: :func:`hold_loops` compiled (its product with ``contract``).
hold_kernel = LazyKernel(
    hold_loops, np.zeros(2), np.zeros((3, 2)), np.zeros(2), np.zeros(2), 0.5, 0.5, 1e-3,
    np.eye(4), np.zeros(4), np.zeros(4), np.zeros((4, 2)), contracted=("_product_fma",),
)  # fmt: skip
#: :func:`hold_between_loops` compiled.
hold_between_kernel = LazyKernel(
    hold_between_loops, np.eye(6), np.zeros((6, 6)), 1e-3, 1e-3, 1.0, np.zeros((4, 4)),
    np.zeros(4), np.zeros(4), helpers=(_matmul,),
)  # fmt: skip
#: :func:`chain_rk4_loops` compiled.
chain_rk4_kernel = LazyKernel(
    chain_rk4_loops, np.zeros(2), np.zeros((3, 2)), np.eye(4), np.eye(4), 0.0, 1.0,
    np.ones(4), True, 2, np.zeros(2), np.zeros(2), 0.5, 0.5, 1e-3, np.zeros(2),
    np.zeros((3, 2)), np.zeros((4, 4)), helpers=(_first_gain, _chain_rhs),
    contracted=("_fma",),
)  # fmt: skip
