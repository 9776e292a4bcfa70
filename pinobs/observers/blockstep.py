"""``ekf``'s whole update on a large robot with Lie-group joints, by blocks (issue 39).

For ``nv ≥`` :data:`~pinobs.observers.blocks.MIN_NV` (a talos, nv = 38) without joint friction
or the offset state, :class:`BlockStep` runs :meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.step`
(``n = 2nv``, ``D = −ad_v̂``, ``A_q = ∂a/∂q``, ``A_v = ∂a/∂v``, ``G = [A_q A_v]``)::

    A = [[D, I], [A_q, A_v]],   Φ = I + hA·M,   M = I + (h/2) A (I + (h/3) A)

with ``A (I + (h/3)A)`` written by blocks, since ``I + (h/3)A``'s first block row is
``[I + (h/3)D, (h/3)I]``::

    (A (I + (h/3)A))₁. = [D, I] + (h/3) ([D², D] + G)
    (A (I + (h/3)A))₂. = G + (h/3) (A_v G + [A_q D, A_q])

so ``M`` costs one ``nv × nv × 2nv`` product (``A_v G``) and ``Φ``'s dynamics rows one
``nv × 2nv × 2nv`` (``G M``); its first block row is ``[I 0] + h (M₂. + D M₁.)``, ``D`` nonzero
on the bracket rows only (six on a talos).  Then ``P⁻ = (Φ P) Φᵀ + Q_d`` (two BLAS products)
and the Joseph update with ``H = [I 0]``, ``S = P⁻_qq + R = L Lᵀ`` (LAPACK ``dpotrf``),
``K = P⁻_·q S⁻¹`` (two ``dtrsm``) and only the lower block triangle::

    C_·q = P⁻_·q − K P⁻_qq,   Y = C_·q − R K,   P⁺_·q = C_·q − Y K_qᵀ,
    P⁺_vv = P⁻_vv − K_v P⁻_qv − Y_v K_vᵀ,     P⁺_qv = (P⁺_vq)ᵀ

(:func:`pinobs.observers.linalg.joseph_update`'s ``C − (C_·q − R K) Kᵀ`` with ``C = P − K H P``,
its upper block right not computed; the diagonal blocks symmetrised).  The mean by
:class:`~pinobs.observers.fused_lie.LieRK4` (compiled RKMK4 between Pinocchio's calls).  The
arithmetic between the BLAS and LAPACK calls is compiled (numba, loaded by the filter's
constructor), so that an update makes a few dozen Python-level calls; the same equations as
``predict`` then ``correct``, equal to them to rounding (tested).  The products are
``ndarray.dot`` (``np.dot``'s C function without its Python dispatcher: eight Python calls an
update less, the same BLAS call and bits), Pinocchio's output views are made once (about 1 µs
an attribute) and ``difference`` is ``pin.difference`` bound to the model.

Why not compiled products, without BLAS (issue 39, measured on this project's 2-core AMD EPYC
(Zen 4), one BLAS thread, CPU time): the ``76 × 76 × 76`` product takes OpenBLAS 17–19 µs
(23–26 G multiply-adds/s), numba's best loops here 45–55 µs (8–10 G/s; numba's loop
vectorizer does emit 512-bit FMAs, but with its SLP vectorizer off a register tile stays
scalar), so the eight products' 1.3–1.5 M multiply-adds (1.3 with only ``P⁻``'s upper
triangle) would take 130–190 µs against OpenBLAS's ~70: far more than the one-thread limit
(~7 µs a call in a paced loop) and the Python calls they would save.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pinobs.model import Robot
from pinobs.model.integrators import difference_call
from pinobs.observers.base import Vector
from pinobs.observers.blocks import bracket_rows
from pinobs.observers.fused import bracket_table, loaded
from pinobs.observers.fused_lie import LieRK4
from pinobs.observers.linalg import LazyKernel

__all__ = ["BlockStep", "bracket_table", "joseph_kernels", "transition_kernels"]


def _start_loops(a_q: Vector, a_v: Vector, v: Vector, table: Any, G: Vector, D: Vector) -> None:  # noqa: C901 -- numba kernel: one branch per joint kind
    """``G = [A_q A_v]`` and ``D = −ad_v`` on the bracket blocks (``table`` rows: kind, first
    row; :meth:`pinobs.model.Robot.bracket_matrix`: ``skew(ω)`` in a spherical joint, se(3)'s
    ``[[skew(ω), skew(v)], [0, skew(ω)]]`` in a free-flyer (``x = (v, ω)``), the se(2)
    bracket in a planar joint); ``D`` elsewhere is not read."""
    nv = a_q.shape[0]
    for i in range(nv):
        for j in range(nv):
            G[i, j] = a_q[i, j]
            G[i, nv + j] = a_v[i, j]
    for r in range(table.shape[0]):
        kind, i = table[r, 0], table[r, 1]
        if kind == 2:  # se2, x = (vx, vy, w)
            for a in range(3):
                for b in range(3):
                    D[i + a, i + b] = 0.0
            D[i, i + 1], D[i, i + 2] = v[i + 2], -v[i + 1]
            D[i + 1, i], D[i + 1, i + 2] = -v[i + 2], v[i]
            continue
        w = i + 3 if kind == 1 else i  # ω's first index
        for o in range(0, 6 if kind == 1 else 3, 3):  # the diagonal blocks: −skew(ω)
            D[i + o, i + o], D[i + o, i + o + 1], D[i + o, i + o + 2] = 0.0, v[w + 2], -v[w + 1]
            D[i + o + 1, i + o], D[i + o + 1, i + o + 1] = -v[w + 2], 0.0
            D[i + o + 1, i + o + 2] = v[w]
            D[i + o + 2, i + o], D[i + o + 2, i + o + 1], D[i + o + 2, i + o + 2] = (
                v[w + 1], -v[w], 0.0,
            )  # fmt: skip
        if kind == 1:  # −skew(v) above, zero below
            D[i, i + 3], D[i, i + 4], D[i, i + 5] = 0.0, v[i + 2], -v[i + 1]
            D[i + 1, i + 3], D[i + 1, i + 4], D[i + 1, i + 5] = -v[i + 2], 0.0, v[i]
            D[i + 2, i + 3], D[i + 2, i + 4], D[i + 2, i + 5] = v[i + 1], -v[i], 0.0
            for a in range(3):
                for b in range(3):
                    D[i + 3 + a, i + b] = 0.0


def _mid_loops(G: Vector, W: Vector, D: Vector, runs: Any, h: float, mid: Vector) -> None:  # noqa: C901 -- numba kernel: loops over blocks
    """``M = I + (h/2) A (I + (h/3) A)`` (module docstring) from ``G = [A_q A_v]`` and
    ``W = A_v G``; ``D`` read on the bracket runs ``runs`` (``(k, 2)``: first, end row)."""
    nv, n = G.shape
    b, c = 0.5 * h, h / 3.0
    for i in range(nv):
        for j in range(n):  # (A(I + cA))₂. = G + c (W + [A_q D, A_q]), A_q D below
            x = W[i, j]
            if j >= nv:
                x += G[i, j - nv]
            mid[nv + i, j] = b * (G[i, j] + c * x)
            mid[i, j] = (b * c) * G[i, j]  # (A(I + cA))₁. = [D, I] + c([D², D] + G)
        mid[nv + i, nv + i] += 1.0
        mid[i, i] += 1.0
        mid[i, nv + i] += b
    for r in range(runs.shape[0]):
        s0, s1 = runs[r, 0], runs[r, 1]
        for i in range(nv):  # A_q D: D's columns s0:s1 meet A_q's columns s0:s1
            for j in range(s0, s1):
                t = 0.0
                for k in range(s0, s1):
                    t += G[i, k] * D[k, j]
                mid[nv + i, j] += (b * c) * t
        for i in range(s0, s1):  # D, D² on the run's block
            for j in range(s0, s1):
                t = 0.0
                for k in range(s0, s1):
                    t += D[i, k] * D[k, j]
                mid[i, j] += b * D[i, j] + (b * c) * t
                mid[i, nv + j] += (b * c) * D[i, j]


def _phi_loops(mid: Vector, D: Vector, runs: Any, h: float, phi: Vector, phi_t: Vector) -> None:
    """``Φ`` from ``M`` with ``phi``'s dynamics rows holding ``G M``: ``Φ₂. = [0 I] + h G M``,
    ``Φ₁. = [I 0] + h (M₂. + D M₁.)``; ``Φᵀ`` into ``phi_t`` (BLAS multiplies by it faster
    than by a transposed view: 17 against 23 µs for a talos)."""
    n = mid.shape[0]
    nv = n // 2
    for i in range(nv):
        for j in range(n):
            phi[nv + i, j] *= h
            phi[i, j] = h * mid[nv + i, j]
        phi[nv + i, nv + i] += 1.0
        phi[i, i] += 1.0
    for r in range(runs.shape[0]):
        s0, s1 = runs[r, 0], runs[r, 1]
        for i in range(s0, s1):
            for j in range(n):
                t = 0.0
                for k in range(s0, s1):
                    t += D[i, k] * mid[k, j]
                phi[i, j] += h * t
    for i in range(n):
        for j in range(n):
            phi_t[j, i] = phi[i, j]


def _noise_loops(P: Vector, q00: float, q01: float, q11: float, r: float, S: Vector) -> None:
    """``P += Q_d`` (its four diagonals) and ``S = P_qq + r I``."""
    nv = S.shape[0]
    for i in range(nv):
        P[i, i] += q00
        P[i, nv + i] += q01
        P[nv + i, i] += q01
        P[nv + i, nv + i] += q11
        for j in range(nv):
            S[i, j] = P[i, j]
        S[i, i] += r


def _gain_loops(P: Vector, U: Vector, Kt: Vector) -> bool:  # noqa: C901, PLR0912 -- numba kernel: loops over rows
    """``Kᵀ = S⁻¹ P_q·`` into ``Kt`` (``nv × n``) with ``U`` holding ``S`` (upper triangle):
    ``S = Uᵀ U`` (Cholesky, right-looking, ``U`` overwritten), then ``Uᵀ Z = P_q·`` and
    ``U Kᵀ = Z`` row by row (left-looking: row ``i`` takes its terms from the finished rows four
    at a time, each inner loop along a row; every entry's subtractions in the order of the
    right-looking solve's, one at a time, so its bits: 19 → 16 µs on a talos).  False
    (``Kt`` undefined) when ``S`` is not positive definite."""
    nv, n = Kt.shape
    for j in range(nv):
        d = U[j, j]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        for k in range(j, nv):
            U[j, k] /= d
        for i in range(j + 1, nv):  # the trailing block, upper triangle: S -= u uᵀ
            u = U[j, i]
            for k in range(i, nv):
                U[i, k] -= u * U[j, k]
    for i in range(nv):
        for c in range(n):
            Kt[i, c] = P[i, c]
    for i in range(nv):  # Uᵀ Z = P_q·: forward, Z in Kt; row i's terms j = 0 … i − 1
        j = 0
        while j + 4 <= i:
            u0, u1, u2, u3 = U[j, i], U[j + 1, i], U[j + 2, i], U[j + 3, i]
            for c in range(n):
                x = Kt[i, c] - u0 * Kt[j, c]
                x -= u1 * Kt[j + 1, c]
                x -= u2 * Kt[j + 2, c]
                Kt[i, c] = x - u3 * Kt[j + 3, c]
            j += 4
        for k in range(j, i):
            u = U[k, i]
            for c in range(n):
                Kt[i, c] -= u * Kt[k, c]
        d = U[i, i]
        for c in range(n):
            Kt[i, c] /= d
    for i in range(nv - 1, -1, -1):  # U Kᵀ = Z: backward; row i's terms j = nv − 1 … i + 1
        j = nv - 1
        while j - 4 >= i:
            u0, u1, u2, u3 = U[i, j], U[i, j - 1], U[i, j - 2], U[i, j - 3]
            for c in range(n):
                x = Kt[i, c] - u0 * Kt[j, c]
                x -= u1 * Kt[j - 1, c]
                x -= u2 * Kt[j - 2, c]
                Kt[i, c] = x - u3 * Kt[j - 3, c]
            j -= 4
        for k in range(j, i, -1):
            u = U[i, k]
            for c in range(n):
                Kt[i, c] -= u * Kt[k, c]
        d = U[i, i]
        for c in range(n):
            Kt[i, c] /= d
    return True


def _carry_loops(P: Vector, KP: Vector, K: Vector, r: float, Y: Vector) -> None:
    """``C_·q = P_·q − K P_qq`` into ``KP``, ``Y = C_·q − r K``."""
    n, nv = KP.shape
    for i in range(n):
        for j in range(nv):
            c = P[i, j] - KP[i, j]
            KP[i, j] = c
            Y[i, j] = c - r * K[i, j]


def _joseph_loops(
    P: Vector, C: Vector, YK: Vector, KP: Vector, YKv: Vector, K: Vector, e: Vector, r: float,
    out: Vector, dx: Vector,
) -> float:  # fmt: skip
    """``P⁺`` by its lower block triangle (module docstring; the diagonal blocks symmetrised,
    the upper right the lower left's transpose), ``dx = K e``; returns the NIS
    ``eᵀ (e − (K e)_q) / r``."""
    n, nv = C.shape
    for i in range(nv):
        for j in range(i + 1):
            a = 0.5 * ((C[i, j] - YK[i, j]) + (C[j, i] - YK[j, i]))
            out[i, j] = a
            out[j, i] = a
        for j in range(nv):
            a = C[nv + i, j] - YK[nv + i, j]
            out[nv + i, j] = a
            out[j, nv + i] = a
        for j in range(i + 1):
            a = 0.5 * (
                (P[nv + i, nv + j] - KP[i, j] - YKv[i, j])
                + (P[nv + j, nv + i] - KP[j, i] - YKv[j, i])
            )
            out[nv + i, nv + j] = a
            out[nv + j, nv + i] = a
    for i in range(n):
        t = 0.0
        for k in range(nv):
            t += K[i, k] * e[k]
        dx[i] = t
    nis = 0.0
    for i in range(nv):
        nis += e[i] * (e[i] - dx[i])
    return nis / r


def _warm(nv: int) -> tuple[Any, ...]:
    n = 2 * nv
    m, s, g = np.zeros((n, n)), np.zeros((nv, nv)), np.zeros((nv, n))
    runs = np.zeros((1, 2), dtype=np.int64)
    return m, s, g, runs


_m, _s, _g, _runs = _warm(1)
#: :func:`_start_loops`, :func:`_mid_loops` and :func:`_phi_loops` compiled.
transition_kernels = (
    LazyKernel(_start_loops, _s, _s, np.zeros(1), np.zeros((0, 2), dtype=np.int64), _g, _s),
    LazyKernel(_mid_loops, _g, _g, _s, _runs, 1e-3, _m),
    LazyKernel(_phi_loops, _m, _s, _runs, 1e-3, _m, _m),
)
#: :func:`_noise_loops`, :func:`_gain_loops`, :func:`_carry_loops` and :func:`_joseph_loops`
#: compiled (``K`` as ``Kᵀ``'s transpose: Fortran order, warmed so).
joseph_kernels = (
    LazyKernel(_noise_loops, _m, 0.0, 0.0, 0.0, 1.0, _s),
    LazyKernel(_gain_loops, _m, _s, np.zeros((1, 2)), contract=True),
    LazyKernel(_carry_loops, _m, np.zeros((2, 1)), np.zeros((2, 2)).T, 1.0, np.zeros((2, 1))),
    LazyKernel(
        _joseph_loops, _m, np.zeros((2, 1)), np.zeros((2, 1)), _s, _s, np.zeros((2, 2)).T,
        np.zeros(1), 1.0, _m, np.zeros(2),
    ),
)  # fmt: skip


class BlockStep:
    """``ekf``'s step by blocks (module docstring) for a :class:`Robot` with Lie-group joints,
    without friction, ``nv ≥ blocks.MIN_NV``; its own ``pin.Data`` (:class:`LieRK4`'s).
    Buffers (``_scratch*``) are working memory, overwritten by every step."""

    def __init__(self, robot: Robot) -> None:
        nv = robot.nv
        n = 2 * nv
        rk4 = LieRK4.build(robot)
        assert rk4 is not None  # (the caller checked the robot)
        self.robot, self.rk4, self.nv = robot, rk4, nv
        self.difference = difference_call(robot)  # (robot.difference, bound)
        data = rk4.calls.data  # a, ∂a/∂q, ∂a/∂v: views Pinocchio writes in place, made once
        self._scratch_data = (data.ddq, data.ddq_dq, data.ddq_dv)  # (~1 µs an attribute)
        self.runs = np.array([[s.start, s.stop] for s in bracket_rows(robot)], dtype=np.int64)
        self.table = bracket_table(robot)
        self._scratch_D = np.zeros((nv, nv))
        self._scratch_G = np.empty((nv, n))
        self._scratch_W = np.empty((nv, n))
        self._scratch_mid = np.empty((n, n))
        self._scratch_Phi = np.empty((n, n))
        self._scratch_PhiT = np.empty((n, n))
        self._scratch_P = np.empty((n, n))  # P⁻
        self._scratch_S = np.empty((nv, nv))
        self._scratch_KP = np.empty((n, nv))
        self._scratch_Y = np.empty((n, nv))
        self._scratch_YK = np.empty((n, nv))
        self._scratch_KPv = np.empty((nv, nv))
        self._scratch_YKv = np.empty((nv, nv))
        self.start, self.mid, self.phi = (loaded(k) for k in transition_kernels)
        self.noise, self.gain, self.carry, self.joseph = (loaded(k) for k in joseph_kernels)
        self._scratch_Kt = np.empty((nv, n))

    def predict(
        self, q: Vector, v: Vector, tau: Vector, h: float, P: Vector, psd: float, r: float
    ) -> tuple[Vector, Vector, Vector]:
        """``(q⁻, v⁻, P⁻)`` after ``h`` [s] from ``(q, v, P)`` with ``tau`` held (``psd``: the
        white-acceleration density, ``r`` the measurement variance, for :meth:`correct`'s
        ``S``); ``P⁻`` is working memory."""
        nv, runs = self.nv, self.runs
        self.rk4.calls.derivatives(q, v, tau)
        acc, a_q, a_v = self._scratch_data
        G, W, mid, Phi = self._scratch_G, self._scratch_W, self._scratch_mid, self._scratch_Phi
        D = self._scratch_D
        self.start(a_q, a_v, v, self.table, G, D)
        a_v.dot(G, out=W)  # A_v G (ndarray.dot: np.dot less its Python dispatcher)
        self.mid(G, W, D, runs, h, mid)
        G.dot(mid, out=Phi[nv:])  # G M
        self.phi(mid, D, runs, h, Phi, self._scratch_PhiT)
        T, P_new = mid, self._scratch_P  # (M is not needed any more)
        Phi.dot(P, out=T)
        T.dot(self._scratch_PhiT, out=P_new)
        self.noise(P_new, psd * h**3 / 3.0, psd * h**2 / 2.0, psd * h, r, self._scratch_S)
        q_new, v_new = self.rk4.step(q, v, tau, h, acc0=acc)
        return q_new, v_new, P_new

    def correct(self, P: Vector, e: Vector, r: float) -> tuple[Vector, Vector, float]:
        """``(dx, P⁺, NIS)`` from :meth:`predict`'s ``P⁻`` and the innovation ``e`` (``r``
        the measurement variance); NaN NIS where ``S`` is not positive definite."""
        nv, n = self.nv, P.shape[0]
        dx, out = np.empty(n), np.empty((n, n))
        Kt = self._scratch_Kt
        if not self.gain(P, self._scratch_S, Kt):
            return dx, out, float("nan")
        K = Kt.T
        KP, Y, YK = self._scratch_KP, self._scratch_Y, self._scratch_YK
        K.dot(P[:nv, :nv], out=KP)
        self.carry(P, KP, K, r, Y)  # KP ← C_·q
        Y.dot(Kt[:, :nv], out=YK)
        Kv = K[nv:]
        Kv.dot(P[:nv, nv:], out=self._scratch_KPv)
        Y[nv:].dot(Kt[:, nv:], out=self._scratch_YKv)
        nis = self.joseph(P, KP, YK, self._scratch_KPv, self._scratch_YKv, K, e, r, out, dx)
        return dx, out, nis
