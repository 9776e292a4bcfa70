"""``ekf``'s whole update on a large robot with Lie-group joints, by blocks (issue 39).

For ``nv >`` :data:`~pinobs.observers.linalg.KERNEL_MAX_NV` (go1, nv = 18; talos, nv = 38)
without joint friction or the offset state, :class:`BlockStep` runs
:meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.step` (``n = 2nv``, ``D = −ad_v̂``,
``A_q = ∂a/∂q``, ``A_v = ∂a/∂v``, ``G = [A_q A_v]``)::

    A = [[D, I], [A_q, A_v]],   Φ = I + hA + (h²/2) A² + (h³/6) A³

by block rows: for any ``X = [X_q X_v]``, ``X A = X_v G + [X_q D, X_q]`` (``A``'s first block
row is ``[D, I]``), and ``(A Y)₁. = D Y₁. + Y₂.``, ``(A Y)₂. = G Y``, so::

    G A  = A_v G + [A_q D, A_q],          G A² = (G A)_v G + [(G A)_q D, (G A)_q]
    Φ₂.  = [0 I] + h G + (h²/2) G A + (h³/6) G A²
    Φ₁.  = [I hI] + (h²/2) G + (h³/6) G A + h D M₁.,   M₁. = [I 0] + (h/2)([D, I] + (h/3)([D², D] + G))

two ``nv × nv × 2nv`` products (``A_v G``, ``(G A)_v G``; before, ``Φ = I + hA·M`` took
``G M``, ``nv × 2nv × 2nv``, in place of the second), ``D`` nonzero on the bracket rows only
(six on a talos).  Then ``P⁻ = (Φ P) Φᵀ + Q_d`` (two BLAS products) and, with ``H = [I 0]``,
``S = P⁻_qq + R = Uᵀ U`` (Cholesky, compiled) and ``Z = U⁻ᵀ P⁻_q·`` (one triangular solve)::

    K = P⁻_·q S⁻¹ = Zᵀ U⁻ᵀ,   dx = K e = Zᵀ w,   w = U⁻ᵀ e,   NIS = eᵀ S⁻¹ e = wᵀ w,
    P⁺ = P⁻ − K S Kᵀ = P⁻ − Zᵀ Z        (Bar-Shalom, Li & Kirubarajan 2001, §5.2.3)

(one ``2nv × nv × 2nv`` product, symmetrised), equal to the Joseph form
``(I − KH) P⁻ (I − KH)ᵀ + K R Kᵀ`` for this ``K`` (Joseph's form also holds for other
gains, which is why it costs the two correction products this one drops).  Its rounding:
``P⁺_qq = P⁻_qq S⁻¹ R ≈ R`` comes out of ``P⁻_qq − Z_qᵀ Z_q`` to about ``ε P⁻_qq,ii / R`` of
itself, so above :data:`MOST_RATIO` (the first samples from a wide start) :meth:`BlockStep.correct`
reports NaN and the filter takes its Joseph form; at 1 kHz ``P⁻_qq,ii / R`` is 0.01–0.14 in
steady state (talos, go1).  Measured (talos, 60 s at 1 kHz, 5 % of the samples dropped,
seed 11): against the Joseph block step, estimates within 1.0e-14 (σ = 1e-4) of each signal's
largest value, ``P⁺`` exactly symmetric and positive definite at every check (1200, smallest
eigenvalue 2.1e-14).  The mean by :class:`~pinobs.observers.fused_lie.LieRK4` (compiled RKMK4
between Pinocchio's calls).  The arithmetic between the BLAS calls is compiled (numba, loaded
by the filter's constructor), so that an update makes a few dozen Python-level calls; the same
equations as ``predict`` then ``correct``, equal to them to rounding (tested).  The products
are ``ndarray.dot`` (``np.dot``'s C function without its Python dispatcher, the same BLAS call
and bits), Pinocchio's output views are made once (about 1 µs an attribute) and
``difference`` is ``pin.difference`` bound to the model.

Cost (talos, one BLAS thread, CPU time, in-process A/B against the Joseph block step):
the covariance algebra 1.54 → 1.32 M BLAS multiply-adds and 119 k → 64 k compiled ones;
the correction 65 → 36 µs (gain 23 → 15, the Joseph form's four products 32 → ZᵀZ's 14),
``Φ`` 25 → 20 µs (``Φᵀ`` no longer copied: 2.8 µs, for 0.8 µs more in its product); the
covariance algebra 13.0 → 10.0 ``pin.aba`` (load 3.4), 11.3 → 9.0 (load 6; 43 µs less, paired
median), ``measure_cost`` 34.9 → 30.7 (load 5.3, paired); go1 10.4 → 7.8 (16 µs less).

Why not compiled products, without BLAS (issue 39, measured on this project's 2-core AMD EPYC
(Zen 4), one BLAS thread, CPU time): the ``76 × 76 × 76`` product takes OpenBLAS 17–19 µs
(23–26 G multiply-adds/s), numba's best loops here 45–55 µs (8–10 G/s; numba's loop
vectorizer does emit 512-bit FMAs, but with its SLP vectorizer off a register tile stays
scalar), so the five products' 1.3 M multiply-adds would take 120–160 µs against
OpenBLAS's ~60: far more than the one-thread limit (~7 µs a call in a paced loop) and the
Python calls they would save.

Where a talos update goes (issue 39; 1 kHz, σ = 1e-4, ``make_observer`` as
``benchmarks/speed.py``, one BLAS thread, thread CPU time per section inside the update, 6000
updates, in units of a ``pin.aba`` timed after each update; 2-core Xeon, OpenBLAS SkylakeX
kernels, load 1.3; the same shares at load 6.7): the update 20.5, of which the derivatives call
4.05, the RKMK4 mean 4.34 (its three ``aba`` and what lies between them), ``Φ`` 2.29 (the two
products ``A_v G``, ``(G A)_v G`` 0.98, the three kernels 1.31), ``(Φ P) Φᵀ`` 2.55 (``Φ P``
1.02, the second product, with ``Φᵀ`` a strided view, 1.53), ``Q_d`` 0.21, the correction 3.02
(factor and solve 1.25, ``Zᵀ Z`` 1.05, ``P⁺`` and ``dx`` 0.56, two allocations 0.16) and the
Python around them 4.0 (the input checks 1.3 of it). ``measure_cost`` (its ``pin.aba`` warm,
twenty in a row) was 24–25 in the same session. Tried and not adopted (A/B against this step,
same inputs, alternated, 800 pairs, load 5): ``Φᵀ`` written by the kernel (both products then
OpenBLAS's fast transposition cases), ``(Φ P) Φᵀ``'s velocity rows and ``qq`` block only (its
``qv`` block mirrored: ¾ of its multiply-adds) and ``Zᵀ Z`` by ``dsyrk``: talos 5 µs less (p10
303 → 298 µs, 1–2 %), go1 6 µs more (p10 106 → 112), estimates off by up to 1.8e-13 of the
largest velocity: not worth the bits. Then (issue 39, same bits: 48 stored
``ekf`` runs on talos, go1, UR5 and Panda ``array_equal``) the kernels whose arguments are
all the step's own buffers (``start``, on ``v`` copied into :class:`LieRK4`'s first work row,
``square``, ``phi``, ``noise``, ``update``, and :class:`LieRK4`'s four stages) are called
without numba's dispatcher (:meth:`~pinobs.observers.linalg.LazyKernel.unchecked`: 0.6–1 µs
a call less) and the update's torque test joint by joint in plain Python (about 1 µs less):
the fastest tenth of a talos's 20-update chunks 390 → 374, 396 → 381, 394 → 373 µs, the
medians 27.3 → 24.8, 25.7 → 26.1, 27.9 → 25.5 ``pin.aba`` (in-process A/B, old and new
alternated, 40 rounds of 400 updates each, thread CPU, load 7–8: every time inflated; at load
4.5: 391 → 378 and 382 → 367 µs, 14 µs less in paired chunks, go1 7.7 µs less). Not
reached: issue 39's 20× (what is left beside Pinocchio's calls and the products is the kernels'
and products' own calls, about 20 from Python). Pinocchio's four calls are the floor of this step (the
derivatives call's ``ddq`` is the first RK4 stage already); ``aba`` with ``Convention.WORLD``
is 15 % faster on a talos (18.3 → 15.6 µs; 8 % on a UR5) and differs from the default's ``ddq``
by 2.6e-14 relative, so it would change every :func:`pinobs.model.dynamics_rk4` user's bits.
Then (issue 39, the same bits: 24 stored ``ekf`` runs on talos, go1 (10 s each), UR5 and Panda
``array_equal``) two kernels whose time went to short dependent chains: the Cholesky of
:func:`_factor_loops` left-looking, in the forward substitution's pass (its trailing updates
were loops of 1–37 entries, 9.6 µs for a talos's 9 k multiply-adds) and the bracket runs'
sums of :func:`_phi_loops` along rows (each a chain of six additions before): the factor
27.3 → 21.0 µs, ``Φ`` 13.4 → 10.2 µs (talos, paired on the step's buffers, load 4; go1 0.7
and 1.4 µs less); the talos update 325.8 → 319.4 µs, 21.01 → 20.63 ``pin.aba`` (in-process
A/B, old and new alternated, 60 rounds of 400 updates, thread CPU, load 2.7–3.0; paired
6.3 µs less, IQR 3.5–7.8).  Then :func:`_phi_loops` writes ``Φᵀ`` (its entries transposed), so
that ``Φ P`` is OpenBLAS's "TN" case and ``(Φ P) Φᵀ`` its "NN" (the "NT" of a strided ``Φᵀ``
took 25.8 against 18.5 µs, warm; the first of the three changes tried above, alone): talos
7.9 µs less an update (paired median, IQR 0.1–16.3; 22.07 → 21.59 ``pin.aba``, 60 rounds,
load 4.5; 8.6 µs, IQR 2.7–13.7, at load 3.4), go1 0.8 µs (IQR −4.3–2.8: none).  Not the same
bits (another summation order inside BLAS): over 10 s at 1 kHz (σ = 1e-4, seeds 0 and 11, 5 %
dropped samples in the second) the estimates move by at most 1.0e-13 rad/s on a talos (3.4e-15
of the largest velocity; 6.5e-10 of the filter's RMS error, unchanged to ten digits), 1.8e-15
rad in ``q``; go1 1.2e-14 rad/s.  Then (issue 39, the same bits: 60 stored runs of ``ekf``,
``kalman``, ``adaptive`` and ``ekf`` with the offset on cartpole, UR5, Panda, go1, talos
``array_equal``) ``v⁺ = v⁻ + dx_v`` in :func:`_update_loops` (``v⁻`` left in the RKMK4's work
row: no copy, no NumPy addition), :func:`_factor_loops` without the dispatcher on the step's
own ``P⁻``, the views and the derivatives call made once, and the step's ``np.errstate`` a
decorator (two Python calls less than a ``with``): talos 9.6 µs less an update (22.37 →
21.71 ``pin.aba``), go1 6.7 µs (in-process A/B, 20-update chunks alternated, thread CPU,
paired medians, load 6.7–7.0).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pinobs.model import Robot
from pinobs.model.integrators import difference_call
from pinobs.observers.base import Vector
from pinobs.observers.blocks import bracket_rows
from pinobs.observers.ekf_fused import copy_out_kernel, inputs_kernel
from pinobs.observers.fused import loaded
from pinobs.observers.fused_jacobi import bracket_table
from pinobs.observers.fused_lie import LieRK4
from pinobs.observers.linalg import LazyKernel

__all__ = ["MOST_RATIO", "BlockStep", "bracket_table", "joseph_kernels", "transition_kernels"]

#: Largest ``P⁻_qq,ii / R`` where :meth:`BlockStep.correct` takes ``P⁺ = P⁻ − Zᵀ Z``: its
#: ``P⁺_qq ≈ R`` is computed to about ``ε · P⁻_qq,ii / R`` of itself, 2e-12 here; above (the
#: first samples from a wide start) the filter's Joseph form.
MOST_RATIO = 1e4
_F64 = np.dtype(np.float64)


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


def _square_loops(G: Vector, W: Vector, D: Vector, runs: Any, GA: Vector) -> None:
    """``G A = A_v G + [A_q D, A_q]`` (``(X A) = X_v G + [X_q D, X_q]`` for any ``X``, from
    ``A``'s first block row ``[D, I]``) from ``G = [A_q A_v]`` and ``W = A_v G``; ``D`` read on
    the bracket runs ``runs`` (``(k, 2)``: first, end row)."""
    nv = G.shape[0]
    for i in range(nv):
        for j in range(nv):
            GA[i, j] = W[i, j]
            GA[i, nv + j] = W[i, nv + j] + G[i, j]
    for r in range(runs.shape[0]):
        s0, s1 = runs[r, 0], runs[r, 1]
        for i in range(nv):  # A_q D: D's columns s0:s1 meet A_q's columns s0:s1
            for j in range(s0, s1):
                t = 0.0
                for k in range(s0, s1):
                    t += G[i, k] * D[k, j]
                GA[i, j] += t


def _phi_loops(  # noqa: C901, PLR0912 -- numba kernel: loops over blocks
    G: Vector, GA: Vector, V: Vector, D: Vector, runs: Any, h: float, phi: Vector
) -> None:
    """``Φᵀ`` into ``phi``, ``Φ = I + hA + (h²/2)A² + (h³/6)A³`` by block rows (module
    docstring) from ``G``, ``G A`` and ``V = (G A)_v G`` (so ``G A² = V + [(G A)_q D, (G A)_q]``):
    ``Φ``'s entries, written transposed, so that both products of ``Φ P Φᵀ`` are OpenBLAS's
    fast cases (:meth:`BlockStep.predict`)."""
    nv, n = G.shape
    b, c = 0.5 * h * h, h * h * h / 6.0
    for i in range(nv):
        for j in range(n):
            g2 = V[i, j]  # (G A²)ᵢⱼ, its [·, (G A)_q] part
            if j >= nv:
                g2 += GA[i, j - nv]
            phi[j, nv + i] = h * G[i, j] + b * GA[i, j] + c * g2
            phi[j, i] = b * G[i, j] + c * GA[i, j]
        phi[nv + i, nv + i] += 1.0
        phi[i, i] += 1.0
        phi[nv + i, i] += h
    t = np.empty(n)  # the sums of a row, each in the order of a dot product (k ascending)
    for r in range(runs.shape[0]):  # (vectorised along the row, not a latency-bound chain)
        s0, s1 = runs[r, 0], runs[r, 1]
        for i in range(nv):  # G A²'s (G A)_q D on the run's columns
            for j in range(s0, s1):
                t[j] = 0.0
            for k in range(s0, s1):
                g = GA[i, k]
                for j in range(s0, s1):
                    t[j] += g * D[k, j]
            for j in range(s0, s1):
                phi[j, nv + i] += c * t[j]
        m = s1 - s0  # the run's rows of M₁. = [I 0] + (h/2)([D, I] + (h/3)([D², D] + G))
        M1 = np.empty((m, n))
        for k in range(m):
            for j in range(n):
                M1[k, j] = (0.5 * h * h / 3.0) * G[s0 + k, j]
            M1[k, s0 + k] += 1.0
            M1[k, nv + s0 + k] += 0.5 * h
            for j in range(s0, s1):
                u = 0.0
                for a in range(s0, s1):
                    u += D[s0 + k, a] * D[a, j]
                M1[k, j] += 0.5 * h * D[s0 + k, j] + (0.5 * h * h / 3.0) * u
                M1[k, nv + j] += (0.5 * h * h / 3.0) * D[s0 + k, j]
        for i in range(s0, s1):  # Φ₁. += h D M₁. on the run's rows
            for j in range(n):
                t[j] = 0.0
            for k in range(m):
                d = D[i, s0 + k]
                for j in range(n):
                    t[j] += d * M1[k, j]
            for j in range(n):
                phi[j, i] += h * t[j]


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


def _factor_loops(  # noqa: C901, PLR0912 -- numba kernel: loops over rows
    P: Vector, U: Vector, e: Vector, Z: Vector, w: Vector, most: float, r: float
) -> float:
    """``Z = U⁻ᵀ P_q·`` into ``Z`` (``nv × n``) and ``w = U⁻ᵀ e`` with ``U`` holding ``S``
    (upper triangle): ``S = Uᵀ U`` (Cholesky, ``U`` overwritten) and ``Uᵀ Z = P_q·``, row by row
    in one pass, left-looking: ``[U Z w]``'s row ``i`` takes its terms from the finished rows
    ``j < i``, in that order, four at a time, each inner loop along a row (then the row divided
    by ``U_ii``): each entry's operations in the order of the right-looking Cholesky and the
    forward substitution (the same bits), vectorised where that Cholesky's short trailing
    updates were not.  Returns the NIS ``eᵀ S⁻¹ e = wᵀ w``, or NaN (``Z`` undefined) when
    ``S`` is not positive definite or a diagonal of ``S`` exceeds ``most`` (there
    ``P⁺_qq ≈ R`` would lose its digits in ``P − Zᵀ Z``: Joseph's form), or where
    ``NIS · r < 10⁻⁶ eᵀe`` (``K_q ≈ I``, ``r`` the measurement variance: ``ekf``'s
    ``correct`` computes that NIS directly; its test, here without ``e @ e``'s Python call)."""
    nv, n = Z.shape
    for j in range(nv):
        if not U[j, j] <= most:  # (or NaN)
            return math.nan
    for i in range(nv):
        for c in range(n):
            Z[i, c] = P[i, c]
        w[i] = e[i]
    for i in range(nv):  # row i: S_i· − Σ_j U_ji U_j· (k ≥ i), P_i· − Σ_j U_ji Z_j·, j < i
        j = 0
        while j + 4 <= i:
            u0, u1, u2, u3 = U[j, i], U[j + 1, i], U[j + 2, i], U[j + 3, i]
            for k in range(i, nv):
                x = U[i, k] - u0 * U[j, k]
                x -= u1 * U[j + 1, k]
                x -= u2 * U[j + 2, k]
                U[i, k] = x - u3 * U[j + 3, k]
            for c in range(n):
                x = Z[i, c] - u0 * Z[j, c]
                x -= u1 * Z[j + 1, c]
                x -= u2 * Z[j + 2, c]
                Z[i, c] = x - u3 * Z[j + 3, c]
            w[i] -= u0 * w[j] + u1 * w[j + 1] + u2 * w[j + 2] + u3 * w[j + 3]
            j += 4
        for k in range(j, i):
            u = U[k, i]
            for c in range(i, nv):
                U[i, c] -= u * U[k, c]
            for c in range(n):
                Z[i, c] -= u * Z[k, c]
            w[i] -= u * w[k]
        d = U[i, i]
        if not d > 0.0:
            return math.nan
        d = math.sqrt(d)
        for k in range(i, nv):
            U[i, k] /= d
        d = U[i, i]
        for c in range(n):
            Z[i, c] /= d
        w[i] /= d
    nis, ee = 0.0, 0.0
    for i in range(nv):
        nis += w[i] * w[i]
        ee += e[i] * e[i]
    if not nis * r >= 1e-6 * ee:  # K_q ≈ I (or NaN): e − K_q e has lost its digits
        return math.nan
    return nis


def _update_loops(
    P: Vector, ZZ: Vector, Z: Vector, w: Vector, out: Vector, dx: Vector, v: Vector, v_new: Vector
) -> None:
    """``P⁺ = P − Zᵀ Z`` (``ZZ = Zᵀ Z``; both symmetrised) into ``out``, ``dx = Zᵀ w`` and
    ``v⁺ = v + dx_v`` into ``v_new`` (NumPy's ``v + dx[nv:]``, entry by entry: the same bits)."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1):
            a = 0.5 * ((P[i, j] + P[j, i]) - (ZZ[i, j] + ZZ[j, i]))
            out[i, j] = a
            out[j, i] = a
    nv = Z.shape[0]
    for i in range(n):
        dx[i] = 0.0
    for k in range(nv):
        c = w[k]
        for i in range(n):
            dx[i] += Z[k, i] * c
    for i in range(nv):
        v_new[i] = v[i] + dx[nv + i]


def _warm(nv: int) -> tuple[Any, ...]:
    n = 2 * nv
    m, s, g = np.zeros((n, n)), np.zeros((nv, nv)), np.zeros((nv, n))
    runs = np.zeros((1, 2), dtype=np.int64)
    return m, s, g, runs


_m, _s, _g, _runs = _warm(1)
#: :func:`_start_loops`, :func:`_square_loops` and :func:`_phi_loops` compiled.
transition_kernels = (
    LazyKernel(_start_loops, _s, _s, np.zeros(1), np.zeros((0, 2), dtype=np.int64), _g, _s),
    LazyKernel(_square_loops, _g, _g, _s, _runs, _g),
    LazyKernel(_phi_loops, _g, _g, _g, _s, _runs, 1e-3, _m),
)
#: :func:`_noise_loops`, :func:`_factor_loops` and :func:`_update_loops` compiled.
joseph_kernels = (
    LazyKernel(_noise_loops, _m, 0.0, 0.0, 0.0, 1.0, _s),
    LazyKernel(_factor_loops, _m, _s, np.zeros(1), _g, np.zeros(1), 1.0, 1.0, contract=True),
    LazyKernel(_update_loops, _m, _m, _g, np.zeros(1), _m, np.zeros(2), np.zeros(1), np.zeros(1)),
)


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
        self._scratch_data = (rk4._scratch_ddq, data.ddq_dq, data.ddq_dv)  # (~1 µs an attribute)
        self.runs = np.array([[s.start, s.stop] for s in bracket_rows(robot)], dtype=np.int64)
        self.table = bracket_table(robot)
        self._scratch_D = np.zeros((nv, nv))
        self._scratch_G = np.empty((nv, n))
        self._scratch_W = np.empty((nv, n))
        self._scratch_GA = np.empty((nv, n))
        self._scratch_T = np.empty((n, n))
        self._scratch_PhiT = np.empty((n, n))  # Φᵀ
        self._scratch_P = np.empty((n, n))  # P⁻
        self._scratch_S = np.empty((nv, nv))
        self._scratch_Z = np.empty((nv, n))
        self._scratch_w = np.empty(nv)
        self._scratch_ZZ = np.empty((n, n))
        self.factor, self.update = (loaded(k) for k in joseph_kernels[1:])  # (a caller's arrays)
        # on the step's own buffers only: without numba's dispatcher (LazyKernel.unchecked);
        # v in LieRK4's first work row, which its step writes the same
        self.start, self.square, self.phi = (k.unchecked() for k in transition_kernels)
        self._scratch_v = rk4._scratch_work[0]
        self.noise, self._own_update = joseph_kernels[0].unchecked(), joseph_kernels[2].unchecked()
        # the factor's too where P⁻ is predict's and e a float64 array of unit stride (correct)
        self._own_factor, self._stride = joseph_kernels[1].unchecked(), (_F64.itemsize,)
        # made once (issue 39): the derivatives call, the views the products take, and v⁻ (the
        # RKMK4's work row that predict returns, where LieRK4.predict applies)
        self.derivatives = rk4.calls.derivatives
        self._scratch_GAv = self._scratch_GA[:, nv:]  # (G A)_v
        self._scratch_Phi = self._scratch_PhiT.T  # Φ, a view of Φᵀ
        self._scratch_ZT = self._scratch_Z.T
        self._scratch_vs = rk4._scratch_point[1] if rk4.solve_stage is not None else None
        # what predict and correct read, in two tuples (issue 39: one attribute look-up each,
        # not twenty; about 0.1 µs each in a paced loop); dx is correct's working memory
        self._scratch_dx = np.empty(n)
        self._predict_calls = (self.derivatives, self.start, self.square, self.phi, self.noise)
        self._scratch_predict = (
            self._scratch_data, self._scratch_G, self._scratch_W, self._scratch_GA,
            self._scratch_GAv, self._scratch_PhiT, self._scratch_Phi, self._scratch_D,
            self._scratch_T, self._scratch_P, self._scratch_S, self._scratch_v, self.runs,
            self.table,
        )  # fmt: skip
        # ekf_fused.update_blocks': its checks' kernels and what they take
        # (the inputs' on arrays it made or checked: float64, unit stride; the estimate's
        # through numba's dispatcher: arrays of the step's fallbacks too)
        self.inputs, self.copy_out = inputs_kernel.unchecked(), loaded(copy_out_kernel)
        self.bounds = np.array(robot.absurd_torque, dtype=float)
        self.shapes, self.stride = ((robot.nq,), (nv,)), (_F64.itemsize,)
        self._scratch_correct = (
            self._scratch_Z, self._scratch_w, self._scratch_ZZ, self._scratch_ZT, self._scratch_S,
            self._scratch_P, self._scratch_dx, self._scratch_vs,
        )  # fmt: skip

    def predict(
        self, q: Vector, v: Vector, tau: Vector, h: float, P: Vector, psd: float, r: float
    ) -> tuple[Vector, Vector, Vector]:
        """``(q⁻, v⁻, P⁻)`` after ``h`` [s] from ``(q, v, P)`` with ``tau`` held (``psd``: the
        white-acceleration density, ``r`` the measurement variance, for :meth:`correct`'s
        ``S``); ``v⁻`` and ``P⁻`` are working memory (the RKMK4's work row, where
        :meth:`LieRK4.predict` applies, and a buffer): read them before the next step."""
        derivatives, start, square, phi, noise = self._predict_calls
        (a_q_v, G, W, GA, GAv, PhiT, Phi, D, T, P_new, S, v0, runs, table) = self._scratch_predict
        derivatives(q, v, tau)
        acc, a_q, a_v = a_q_v
        v0[...] = v
        start(a_q, a_v, v0, table, G, D)
        a_v.dot(G, out=W)  # A_v G (ndarray.dot: np.dot less its Python dispatcher)
        square(G, W, D, runs, GA)  # G A
        GAv.dot(G, out=W)  # (G A)_v G
        phi(G, GA, W, D, runs, h, PhiT)
        Phi.dot(P, out=T)  # Φ P (BLAS's "TN" case, as fast as "NN")
        T.dot(PhiT, out=P_new)  # (Φ P) Φᵀ ("NN": 7 µs less than "NT" on a talos)
        noise(P_new, psd * h**3 / 3.0, psd * h**2 / 2.0, psd * h, r, S)
        if self._scratch_vs is None:
            q_new, v_new = self.rk4.step(q, v, tau, h, acc0=acc)
            return q_new, v_new, P_new
        q_new, v_new = self.rk4.predict(q, v, tau, h, acc)  # (v⁻: its work row, not copied)
        return q_new, v_new, P_new

    def correct(
        self, P: Vector, e: Vector, r: float, v: Vector
    ) -> tuple[Vector, Vector, float, Vector]:
        """``(dx, P⁺, NIS, v⁺)`` from :meth:`predict`'s ``P⁻`` and ``v⁻`` (``v``) and the
        innovation ``e`` (``r`` the measurement variance; ``v⁺ = v⁻ + dx_v``; ``dx`` working
        memory: read it before the next step); NaN NIS where
        ``S`` is not positive definite, ``P⁻_qq`` exceeds ``MOST_RATIO · r`` on its diagonal
        or ``K_q ≈ I`` (:func:`_factor_loops`; the caller's Joseph form then)."""
        Z, w, ZZ, ZT, S, own_P, dx, v_own = self._scratch_correct
        out, v_new = np.empty(P.shape), np.empty(self.nv)
        own = P is own_P  # (its arrays the step's own: no dispatcher, __init__)
        plain = own and e.dtype is _F64 and e.strides == self._stride
        factor = self._own_factor if plain else self.factor
        nis = factor(P, S, e, Z, w, MOST_RATIO * r + r, r)
        if nis != nis:  # NaN
            return dx, out, nis, v_new
        ZT.dot(Z, out=ZZ)
        update = self._own_update if own and v is v_own else self.update
        update(P, ZZ, Z, w, out, dx, v, v_new)
        return dx, out, nis, v_new
