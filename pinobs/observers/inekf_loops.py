"""The invariant EKF's propagation and correction in compiled loops (numba).

:mod:`pinobs.observers.inekf`'s module docstring is the specification; this
module evaluates its equations with their block structure, where NumPy spent an
update (331 µs on go1, 59 ``pin.aba``) dispatching some 150 small array
operations:

* propagation, eqs. (1)-(3): the mean (1); ``Φ_ε``'s 15 × 15 Taylor series
  (scaling and squaring, the degree and scaling of :func:`expm_degree`) with its
  bias rows ``[0, I]`` skipped and, in its Horner products, ``F_ε``'s exact zeros
  (the sums over the other terms in the same order: the same bits); eq. (9)'s slip
  term added to ``Q_c`` in the same call; then, with ``T = diag(Ad_X̂, I₆)``,
  ``P⁺ = Φ P Φᵀ + Q`` as ::

      P_ε = T(X̂)⁻¹ P T(X̂)⁻ᵀ + ½ h Q_c,   P⁺ = T(X̂⁺) (Φ_ε P_ε Φ_εᵀ + ½ h Q_c) T(X̂⁺)ᵀ

  (the same expression as ``Φ = T(X̂⁺) Φ_ε T(X̂)⁻¹``,
  ``Q = T(X̂⁺) ½ (Φ_ε Q_c Φ_εᵀ + Q_c) h T(X̂⁺)ᵀ``), each factor applied by
  blocks: ``Ad_X`` rows ``(R M_0, x_i^ R M_0 + R M_i)``, ``Ad_X⁻¹`` rows
  ``(Rᵀ M_0, Rᵀ (M_i − x_i^ M_0))``, ``Φ_ε`` its 9 × 15 core and a 3 × 3 block
  per foot;
* correction, eqs. (4)-(5): ``r``, ``H P`` (rows of ``P``), ``S``, its Cholesky
  factor and ``S⁻¹ [H P, r]``, ``exp(−δ_ξ)`` and the Joseph form, in one call;
* the foot gate's NIS of each foot alone, eq. (8), by the 3 × 3 adjugate.

The results equal NumPy's to rounding (the products are summed in another
order).  The 3 × 3 matrix products (and the scaled series' 15 × 15 squares) are loops,
:func:`_matmul` and :func:`_matvec3`, not numba's ``@``: that calls SciPy's BLAS, whose
first call imports ``scipy.linalg`` (issue 39: 0.15–0.2 s of CPU in ``make_observer``,
and OpenBLAS's worker thread spinning on the other core).  Their fused multiply-adds are
in the order of OpenBLAS's ``gemm`` and ``gemv`` kernels on these sizes: the bits the
``@`` gave (checked on stored outputs).  :func:`load_kernels` compiles them
(``cache=True``: once per installation); ``import pinobs`` imports no numba.
"""

from __future__ import annotations

import math

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.linalg import LazyKernel
from pinobs.tolerances import SERIES_ANGLE

__all__ = [
    "base_kernel",
    "correct_kernel",
    "expm_degree",
    "finite_kernel",
    "foot_nis_kernel",
    "gamma_coefficients",
    "load_kernels",
    "load_leg_kernels",
    "propagate_kernel",
    "slip_kernel",
    "velocity_kernel",
]


def gamma_coefficients(t2: float) -> tuple[float, float, float, float, float, float]:
    """``(a0, b0, a1, b1, a2, b2)`` of ``Γ_m = I/m! + a_m φ^ + b_m (φ^)²`` at ``θ² = |φ|²``
    (:func:`pinobs.observers.inekf.gammas`: closed forms above ``SERIES_ANGLE``, else the
    series ``c_j = Σ_{k<5} (−θ²)^k/(2k+j)!``)."""
    if t2 < SERIES_ANGLE**2:
        c = [0.0] * 6
        for j in range(6):
            s, p, fact = 0.0, 1.0, 1.0  # fact = (2k + j)!
            for q in range(2, j + 1):
                fact *= q
            for k in range(5):
                s += ((-1.0) ** k / fact) * p
                p *= t2
                fact *= (2 * k + j + 1) * (2 * k + j + 2)
            c[j] = s
        return c[1], c[2], c[2], c[3], c[3], c[4]
    t = math.sqrt(t2)
    s, co = math.sin(t), math.cos(t)
    b0 = (1.0 - co) / t2
    b1 = (t - s) / (t2 * t)
    return s / t, b0, b0, b1, b1, (t2 + 2.0 * co - 2.0) / (2.0 * t2 * t2)


def _fma(a: float, b: float, c: float) -> float:
    """``a·b + c`` (compiled on its own with ``contract``: one fused multiply-add)."""
    return a * b + c


def _matmul(A: Vector, B: Vector, out: Vector) -> None:
    """``out = A B`` for small matrices, each entry ``Σ_k A_ik B_kj`` by fused multiply-adds
    in the order of ``k`` from 0: the bits of OpenBLAS's ``gemm`` on them (numba's ``@``)."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            t = 0.0
            for k in range(A.shape[1]):
                t = _fma(A[i, k], B[k, j], t)
            out[i, j] = t


def _matvec3(A: Vector, x: Vector, out: Vector) -> None:
    """``out = A x`` for a 3 × 3 ``A``, each entry ``(a_1 x_1 + a_0 x_0) + a_2 x_2`` by fused
    multiply-adds: the bits of OpenBLAS's ``gemv`` on a C-contiguous 3 × 3 (numba's ``@``)."""
    for i in range(3):
        out[i] = _fma(A[i, 2], x[2], _fma(A[i, 0], x[0], A[i, 1] * x[1]))


def _gammas(phi: Vector, out: Vector) -> None:
    """``out[m] = Γ_m(φ)`` for m = 0, 1, 2 (``out`` shape (3, 3, 3))."""
    W = np.zeros((3, 3))
    W[0, 1], W[0, 2], W[1, 2] = -phi[2], phi[1], -phi[0]
    W[1, 0], W[2, 0], W[2, 1] = phi[2], -phi[1], phi[0]
    W2 = np.empty((3, 3))
    _matmul(W, W, W2)
    a0, b0, a1, b1, a2, b2 = gamma_coefficients(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    for i in range(3):
        for j in range(3):
            d = 1.0 if i == j else 0.0
            out[0, i, j] = d + a0 * W[i, j] + b0 * W2[i, j]
            out[1, i, j] = d + a1 * W[i, j] + b1 * W2[i, j]
            out[2, i, j] = 0.5 * d + a2 * W[i, j] + b2 * W2[i, j]


def expm_degree(norm: float) -> tuple[int, int]:
    """``(s, d)`` of the Taylor ``exp``: scale by ``2^-s`` to ``‖M‖∞ ≤ 1/8``, then the least
    degree ``d`` (≤ 12) with ``‖M‖^{d+1}/(d+1)! < 1e-17``."""
    s = max(0, math.ceil(math.log2(norm * 8.0))) if norm > 0.125 else 0
    norm /= 2.0**s
    degree, term = 1, norm
    while degree < 12 and term * norm / (degree + 1) >= 1e-17:
        degree += 1
        term *= norm / degree
    return s, degree


def _body_core(w: Vector, a: Vector, h: float, core: Vector) -> None:  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    """``core = expm(F_ε h)`` (15 × 15: ε_R, ε_v, ε_p, ζ_g, ζ_a), the Horner form of the series
    on the 9 rows that move (the bias rows of ``F_ε`` are zero, of ``core`` ``[0, I]``).

    Each Horner product ``Σ_m F_im core_mj`` is summed over ``m`` in order, skipping the
    products whose factor is an exact 0 (``F_ε``'s zero entries: at most 5 of 15 on a row
    are not) or 1 (``core``'s bias rows ``[0, I]``: ``F_im`` itself at ``j = m``), the
    inner loop along ``j``: the bits of the dense sum, in a third of its operations."""
    F = np.zeros((15, 15))
    for i in range(3):
        F[i, 9 + i] = -h
        F[3 + i, 12 + i] = -h
        F[6 + i, 3 + i] = h
    for blk in range(3):  # −ω^ h on the three diagonal blocks
        o = 3 * blk
        F[o, o + 1], F[o, o + 2], F[o + 1, o + 2] = w[2] * h, -w[1] * h, w[0] * h
        F[o + 1, o], F[o + 2, o], F[o + 2, o + 1] = -w[2] * h, w[1] * h, -w[0] * h
    F[3, 1], F[3, 2], F[4, 2] = a[2] * h, -a[1] * h, a[0] * h  # −a^ h
    F[4, 0], F[5, 0], F[5, 1] = -a[2] * h, a[1] * h, -a[0] * h
    norm = 0.0
    for i in range(9):
        t = 0.0
        for j in range(15):
            t += abs(F[i, j])
        norm = max(norm, t)
    s, degree = expm_degree(norm)
    F /= 2.0**s
    nz = np.empty((9, 15), dtype=np.int64)  # each row's columns m < 9 with F_im ≠ 0, in order
    count = np.zeros(9, dtype=np.int64)
    for i in range(9):
        for m in range(9):
            if F[i, m] != 0.0:
                nz[i, count[i]] = m
                count[i] += 1
    core[:] = 0.0
    for i in range(15):
        core[i, i] = 1.0
    for i in range(9):
        for j in range(15):
            core[i, j] += F[i, j] / degree
    tmp = np.empty((9, 15))
    for k in range(degree - 1, 0, -1):
        for i in range(9):
            for j in range(15):
                tmp[i, j] = 0.0
            for e in range(count[i]):  # Σ_m F_im core_mj over the rows m < 9 that move
                m = nz[i, e]
                f = F[i, m]
                for j in range(15):
                    tmp[i, j] += f * core[m, j]
            for m in range(9, 15):  # the bias rows: core_mj = δ_mj
                if F[i, m] != 0.0:
                    tmp[i, m] += F[i, m]
        for i in range(9):
            for j in range(15):
                v = tmp[i, j]  # (0/k is v itself: the division skipped on exact zeros)
                core[i, j] = (v / k if v != 0.0 else v) + (1.0 if i == j else 0.0)
    for _ in range(s):
        C = core.copy()
        _matmul(C, C, core)


def _left_adjoint(R: Vector, x: Vector, M: Vector, out: Vector, inverse: bool) -> None:
    """``out = diag(Ad_X, I₆) M`` (or ``Ad_X⁻¹``) by blocks, ``X = (R, x_1 … x_n)``:
    rows ``R M_0``, ``x_i^ R M_0 + R M_i`` (``Rᵀ M_0``, ``Rᵀ (M_i − x_i^ M_0)``); ``M``
    C-contiguous, the inner loops along its rows."""
    n_blk, n = x.shape[0], M.shape[1]
    Rm = R.T.copy() if inverse else R.copy()
    for r in range(3):
        for j in range(n):
            out[r, j] = Rm[r, 0] * M[0, j] + Rm[r, 1] * M[1, j] + Rm[r, 2] * M[2, j]
    c = M[0:3] if inverse else out[0:3]  # x_i × M_0, or x_i × (R M_0)
    for i in range(n_blk):
        o = 3 + 3 * i
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        for j in range(n):
            cr0 = x1 * c[2, j] - x2 * c[1, j]
            cr1 = x2 * c[0, j] - x0 * c[2, j]
            cr2 = x0 * c[1, j] - x1 * c[0, j]
            if inverse:
                u0, u1, u2 = M[o, j] - cr0, M[o + 1, j] - cr1, M[o + 2, j] - cr2
                for r in range(3):
                    out[o + r, j] = Rm[r, 0] * u0 + Rm[r, 1] * u1 + Rm[r, 2] * u2
            else:
                u0, u1, u2 = M[o, j], M[o + 1, j], M[o + 2, j]
                out[o, j] = (Rm[0, 0] * u0 + Rm[0, 1] * u1 + Rm[0, 2] * u2) + cr0
                out[o + 1, j] = (Rm[1, 0] * u0 + Rm[1, 1] * u1 + Rm[1, 2] * u2) + cr1
                out[o + 2, j] = (Rm[2, 0] * u0 + Rm[2, 1] * u1 + Rm[2, 2] * u2) + cr2
    for r in range(3 + 3 * n_blk, M.shape[0]):
        for j in range(n):
            out[r, j] = M[r, j]


def _left_body(core: Vector, n_feet: int, M: Vector, out: Vector) -> None:  # noqa: C901 -- numba kernel: its branches are loops over small matrices
    """``out = Φ_ε M``: the core's 9 × 15 on rows ε_R, ε_v, ε_p (columns ε and ζ; its exact
    zeros skipped), its ``exp(−ω^ h)`` block on each foot, the bias rows copied (``M``
    C-contiguous)."""
    n, n_col = M.shape[0], M.shape[1]
    b = n - 6
    for i in range(9):
        for j in range(n_col):
            out[i, j] = 0.0
        for k in range(15):
            coef = core[i, k]
            if coef == 0.0:  # (core's zero blocks: ε_R on ε_v, ε_p, ζ_a; ε_v on ε_p)
                continue
            row = k if k < 9 else b + k - 9
            for j in range(n_col):
                out[i, j] += coef * M[row, j]
    for f in range(n_feet):
        o = 9 + 3 * f
        for i in range(3):
            c0, c1, c2 = core[i, 0], core[i, 1], core[i, 2]
            for j in range(n_col):
                out[o + i, j] = c0 * M[o, j] + c1 * M[o + 1, j] + c2 * M[o + 2, j]
    for i in range(b, n):
        for j in range(n_col):
            out[i, j] = M[i, j]


def _propagate_loops(
    R: Vector,
    x: Vector,
    theta: Vector,
    imu: Vector,
    h: float,
    g: Vector,
    qc: Vector,
    speed: Vector,
    feet: Vector,
    P: Vector,
    R1: Vector,
    x1: Vector,
    P1: Vector,
) -> None:
    """Eqs. (1)-(3) over ``h`` with the reading ``imu`` held: ``R1``, ``x1``, ``P1`` (module
    docstring; :meth:`pinobs.observers.inekf.InvariantEKF._propagate`'s arithmetic), ``Q_c``
    with eq. (9)'s slip term (:func:`_slip_loops`) if ``speed`` is not empty (the feet's
    speeds, ``feet`` their indices in state order)."""
    if speed.shape[0]:  # eq. (9), into a copy
        slipped = np.empty(qc.shape[0])
        _slip_loops(qc, speed, h, feet, slipped)
        qc = slipped
    w = imu[:3] - theta[:3]
    a = imu[3:] - theta[3:]
    G = np.empty((3, 3, 3))
    _gammas(w * h, G)  # eq. (1)
    Rg, RtR = np.empty((3, 3)), np.empty((3, 3))
    Ga, Ra1, Ra2 = np.empty(3), np.empty(3), np.empty(3)
    _matmul(R, G[0], Rg)
    _matvec3(G[1], a, Ga)
    _matvec3(R, Ga, Ra1)
    _matvec3(G[2], a, Ga)
    _matvec3(R, Ga, Ra2)
    _matmul(Rg.T, Rg, RtR)
    for i in range(3):  # 1.5 I − ½ RᵀR, entry by entry (NumPy's arithmetic)
        for j in range(3):
            RtR[i, j] = (1.5 if i == j else 0.0) - 0.5 * RtR[i, j]
    _matmul(Rg, RtR, R1)  # back onto SO(3) (rounding)
    x1[:] = x
    for c in range(3):
        x1[0, c] = x[0, c] + Ra1[c] * h + g[c] * h
        x1[1, c] = x[1, c] + x[0, c] * h + Ra2[c] * (h * h) + 0.5 * g[c] * (h * h)
    core = np.empty((15, 15))
    _body_core(w, a, h, core)  # Φ_ε (eq. 3 in the body frame)
    n = P.shape[0]
    A = np.empty((n, n))
    B = np.empty((n, n))
    _left_adjoint(R, x, P, A, True)  # T(X̂)⁻¹ P
    _left_adjoint(R, x, np.ascontiguousarray(A.T), B, True)  # P_ε = T(X̂)⁻¹ P T(X̂)⁻ᵀ
    for i in range(n):
        B[i, i] += 0.5 * h * qc[i]
    _left_body(core, x.shape[0] - 2, B, A)
    _left_body(core, x.shape[0] - 2, np.ascontiguousarray(A.T), B)  # Φ_ε (P_ε + ½ h Q_c) Φ_εᵀ
    for i in range(n):
        B[i, i] += 0.5 * h * qc[i]
    _left_adjoint(R1, x1, B, A, False)
    _left_adjoint(R1, x1, np.ascontiguousarray(A.T), B, False)  # T(X̂⁺) … T(X̂⁺)ᵀ
    for i in range(n):
        for j in range(i + 1):
            m = 0.5 * (B[i, j] + B[j, i])
            P1[i, j] = m
            P1[j, i] = m


def _foot_noise(
    R: Vector, jac: Vector, f: int, joint_var: float, kin_var: float, M: Vector
) -> Vector:
    """Eq. (4): foot ``f``'s measurement noise ``N_j = R̂ (J Σ_q Jᵀ + σ_k² I) R̂ᵀ`` (``M`` is
    scratch, ``3 × 3``)."""
    for c in range(3):
        for d in range(3):
            t = 0.0
            for q in range(jac.shape[2]):
                t += jac[f, c, q] * jac[f, d, q]
            M[c, d] = joint_var * t + (kin_var if c == d else 0.0)
    RM, out = np.empty((3, 3)), np.empty((3, 3))
    _matmul(R, M, RM)
    _matmul(RM, R.T, out)
    return out


def _correct_loops(
    R: Vector,
    x: Vector,
    theta: Vector,
    P: Vector,
    h: Vector,
    jac: Vector,
    rows: Vector,
    joint_var: float,
    kin_var: float,
    R1: Vector,
    x1: Vector,
    theta1: Vector,
    P1: Vector,
) -> float:
    """Eqs. (4)-(5) for every foot in the state (``h[rows[f]]`` the measured position of
    the foot at state position ``f``, ``jac[rows[f]]`` its Jacobian, ``σ_q²``, ``σ_k²``):
    ``R1``, ``x1``, ``theta1``, ``P1``; returns the NIS, or −1 (outputs undefined) when ``S``
    is not positive definite."""
    n, k = P.shape[0], x.shape[0] - 2
    m = 3 * k
    N = np.empty((k, 3, 3))
    HP = np.empty((m, n + 1))  # [H P, r]
    M = np.empty((3, 3))
    Rh = np.empty(3)
    for f in range(k):
        N[f] = _foot_noise(R, jac, rows[f], joint_var, kin_var, M)  # eq. (4): N_j
        _matvec3(R, h[rows[f]], Rh)
        for c in range(3):
            a = 3 * f + c
            HP[a, n] = Rh[c] - (x[2 + f, c] - x[1, c])  # r_j = R̂ h_j − (d̂_j − p̂)
            for j in range(n):
                HP[a, j] = P[6 + c, j] - P[9 + a, j]  # H = [0, 0, I, −I_j]
    sol = np.empty((m, n + 1))  # S⁻¹ [H P, r] = [Kᵀ, S⁻¹ r]
    if not _solve_innovation(HP, N, sol):
        return -1.0
    nis = 0.0
    for a in range(m):
        nis += HP[a, n] * sol[a, n]
    delta = np.zeros(n)  # δ = K r = (H P)ᵀ S⁻¹ r
    for j in range(n):
        for a in range(m):
            delta[j] += HP[a, j] * sol[a, n]
    _update_mean(R, x, theta, -delta, R1, x1, theta1)
    _joseph(P, HP, sol, N, P1)
    return nis


def _foot_nis_loops(
    R: Vector,
    x: Vector,
    P: Vector,
    h: Vector,
    jac: Vector,
    joint_var: float,
    kin_var: float,
    out: Vector,
) -> None:
    """Eq. (8): ``out[j] = r_jᵀ S_jj⁻¹ r_j`` for every foot in the state (``S_jj`` its own
    block of ``S``, inverted by its adjugate; ``inf`` if it is singular)."""
    S = np.empty((3, 3))
    M = np.empty((3, 3))
    r, Rh = np.empty(3), np.empty(3)
    for f in range(x.shape[0] - 2):
        N = _foot_noise(R, jac, f, joint_var, kin_var, M)  # eq. (4): N_j
        _matvec3(R, h[f], Rh)
        a = 9 + 3 * f
        for c in range(3):
            r[c] = Rh[c] - (x[2 + f, c] - x[1, c])  # eq. (4): r_j
            for d in range(3):  # S_jj = P_pp − P_pd − P_dp + P_dd + N_j
                S[c, d] = P[6 + c, 6 + d] - P[6 + c, a + d] - P[a + c, 6 + d] + P[a + c, a + d]
                S[c, d] += N[c, d]
        c00 = S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1]  # the adjugate's first column
        c10 = S[1, 2] * S[2, 0] - S[1, 0] * S[2, 2]
        c20 = S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]
        det = S[0, 0] * c00 + S[0, 1] * c10 + S[0, 2] * c20
        if not det > 0.0:
            out[f] = np.inf
            continue
        adj = np.empty((3, 3))
        adj[0, 0], adj[1, 0], adj[2, 0] = c00, c10, c20
        adj[0, 1] = S[0, 2] * S[2, 1] - S[0, 1] * S[2, 2]
        adj[1, 1] = S[0, 0] * S[2, 2] - S[0, 2] * S[2, 0]
        adj[2, 1] = S[0, 1] * S[2, 0] - S[0, 0] * S[2, 1]
        adj[0, 2] = S[0, 1] * S[1, 2] - S[0, 2] * S[1, 1]
        adj[1, 2] = S[0, 2] * S[1, 0] - S[0, 0] * S[1, 2]
        adj[2, 2] = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
        t = 0.0
        for c in range(3):
            for d in range(3):
                t += r[c] * adj[c, d] * r[d]
        out[f] = t / det


def _solve_innovation(HP: Vector, N: Vector, sol: Vector) -> bool:  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    """``sol = S⁻¹ [H P, r]`` with ``S = H P Hᵀ + N`` (eq. 5; ``HP = [H P, r]``, ``N`` the
    feet's 3 × 3 blocks) by Cholesky ``S = L Lᵀ``; False if ``S`` is not positive definite."""
    m, n = HP.shape[0], HP.shape[1] - 1
    L = np.zeros((m, m))  # S = H P Hᵀ + N, its Cholesky factor
    for i in range(m):
        for j in range(i + 1):
            s = HP[i, 6 + j % 3] - HP[i, 9 + j]
            if i // 3 == j // 3:
                s += N[i // 3, i % 3, j % 3]
            for q in range(j):
                s -= L[i, q] * L[j, q]
            if i == j:
                if not s > 0.0:
                    return False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    sol[:] = HP
    for i in range(m):  # L y = b, then Lᵀ x = y, on every column at once
        for q in range(i):
            for c in range(n + 1):
                sol[i, c] -= L[i, q] * sol[q, c]
        for c in range(n + 1):
            sol[i, c] /= L[i, i]
    for i in range(m - 1, -1, -1):
        for q in range(i + 1, m):
            for c in range(n + 1):
                sol[i, c] -= L[q, i] * sol[q, c]
        for c in range(n + 1):
            sol[i, c] /= L[i, i]
    return True


def _joseph(P: Vector, HP: Vector, sol: Vector, N: Vector, P1: Vector) -> None:  # noqa: C901 -- numba kernel: its branches are loops over small matrices
    """Eq. (5)'s Joseph form ``(I − KH) P (I − KH)ᵀ + K N Kᵀ = C − (C Hᵀ − K N) Kᵀ`` with
    ``C = P − K H P``, ``Kᵀ = sol[:, :n]``, symmetrised, into ``P1``."""
    n, m = P.shape[0], HP.shape[0]
    C = P.copy()
    for i in range(n):  # C[i, :] −= Σ_a K[i, a] (H P)[a, :], the inner loop contiguous
        for a in range(m):
            k = sol[a, i]
            for j in range(n):
                C[i, j] -= k * HP[a, j]
    Y = np.empty((n, m))
    for i in range(n):
        for a in range(m):
            f, c = a // 3, a % 3
            s = C[i, 6 + c] - C[i, 9 + a]
            for e in range(3):
                s -= sol[3 * f + e, i] * N[f, e, c]
            Y[i, a] = s
    for i in range(n):  # C − Y Kᵀ in place (C's entries are not read again), then symmetrised
        for a in range(m):
            y = Y[i, a]
            for j in range(n):
                C[i, j] -= y * sol[a, j]
    for i in range(n):
        for j in range(i + 1):
            P1[i, j] = 0.5 * (C[i, j] + C[j, i])
            P1[j, i] = P1[i, j]


def _update_mean(
    R: Vector, x: Vector, theta: Vector, e: Vector, R1: Vector, x1: Vector, theta1: Vector
) -> None:
    """Eq. (5): ``X̂⁺ = exp(e_ξ) X̂`` (``R1 = Γ_0 R``, rows ``x1_i = Γ_0 x_i + Γ_1 ρ_i``),
    ``θ̂⁺ = θ̂ + e_θ``, for ``e = −δ``."""
    n = e.shape[0]
    G = np.empty((3, 3, 3))
    _gammas(e[:3], G)
    _matmul(G[0], R, R1)
    u, w = np.empty(3), np.empty(3)
    for i in range(x.shape[0]):
        _matvec3(G[0], x[i], u)
        _matvec3(G[1], e[3 + 3 * i : 6 + 3 * i], w)
        for c in range(3):
            x1[i, c] = u[c] + w[c]
    for i in range(6):
        theta1[i] = theta[i] + e[n - 6 + i]


def _base_loops(
    R: Vector, x: Vector, imu: Vector, arm: Vector, bias: Vector, R_bi: Vector, r_bi: Vector,
    columns: bool, R_b: Vector, out: Vector, quat: Vector,
) -> None:  # fmt: skip
    """The estimate in the root joint's frame (:meth:`pinobs.observers.legs.LeggedSetup.estimate`,
    module docstring of :mod:`pinobs.observers.legs`): ``R_b = R R_biᵀ`` and the rows of
    ``out``: ``p_b = p − R_b r_bi``, ``ω_b = R_bi (ω̃ − b̂_g)``, ``v_b = R_bᵀ v − ω̄_b × r_bi``
    with ``ω̄_b = R_bi (ω̄ − b̂_g)``, ``ω̄`` the gyro reading ``arm`` (:mod:`~.imu_link`'s (M4):
    the low-passed one; ``imu`` itself for (M3), then ``ω̄_b = ω_b``), and ``R_b v_b``.  The products' fused multiply-adds in the order of OpenBLAS's on these
    sizes, the bits of NumPy's ``@`` (checked on stored outputs): a C-contiguous matrix times a
    vector, :func:`_matvec3`; a column-major one (``R_bᵀ v``; ``R_bi ω`` with ``columns``,
    ``R_bi`` as Pinocchio gives it), a sum over the columns from the first.  ``quat``:
    ``R_b``'s quaternion before its normalisation (:func:`_shepperd`)."""
    t = np.empty(3)
    _matmul(R, R_bi.T, R_b)
    _matvec3(R_b, r_bi, t)
    for i in range(3):
        out[0, i] = x[1, i] - t[i]
    _imu_to_root(R_bi, imu, bias, columns, t)
    out[1, 0], out[1, 1], out[1, 2] = t[0], t[1], t[2]
    _imu_to_root(R_bi, arm, bias, columns, t)  # (M4): ω̄_b (ω_b's bits again for arm = imu)
    c = (
        t[1] * r_bi[2] - t[2] * r_bi[1],
        t[2] * r_bi[0] - t[0] * r_bi[2],
        t[0] * r_bi[1] - t[1] * r_bi[0],
    )
    for i in range(3):
        s = 0.0
        for k in range(3):
            s = _fma(R_b[k, i], x[0, k], s)
        out[2, i] = s - c[i]
    _matvec3(R_b, out[2], t)
    out[3, 0], out[3, 1], out[3, 2] = t[0], t[1], t[2]
    _shepperd(R_b, quat)


def _imu_to_root(R_bi: Vector, reading: Vector, bias: Vector, columns: bool, out: Vector) -> None:
    """``out = R_bi (ω − b̂_g)`` from a gyro ``reading``'s first three entries: a column-major
    ``R_bi`` (``columns``) summed over its columns from the first, else :func:`_matvec3`."""
    omega = np.empty(3)
    for i in range(3):
        omega[i] = reading[i] - bias[i]
    if columns:
        for i in range(3):
            s = 0.0
            for k in range(3):
                s = _fma(R_bi[i, k], omega[k], s)
            out[i] = s
    else:
        _matvec3(R_bi, omega, out)


def _shepperd(R: Vector, q: Vector) -> None:
    """``q`` = the quaternion ``(x, y, z, w)`` of ``R`` before its normalisation, by
    :func:`pinobs.observers.rotations.rotation_to_quaternion`'s arithmetic (Shepperd's method)."""
    a, b, c = R[0, 0], R[0, 1], R[0, 2]
    d, e, f = R[1, 0], R[1, 1], R[1, 2]
    g, h, i = R[2, 0], R[2, 1], R[2, 2]
    tr = a + e + i
    if tr >= a and tr >= e and tr >= i:
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        k = 0.25 / w
        q[0], q[1], q[2], q[3] = (h - f) * k, (c - g) * k, (d - b) * k, w
    elif a >= e and a >= i:
        x = 0.5 * math.sqrt(max(1.0 + a - e - i, 0.0))
        k = 0.25 / x
        q[0], q[1], q[2], q[3] = x, (b + d) * k, (c + g) * k, (h - f) * k
    elif e >= i:
        y = 0.5 * math.sqrt(max(1.0 - a + e - i, 0.0))
        k = 0.25 / y
        q[0], q[1], q[2], q[3] = (b + d) * k, y, (f + h) * k, (c - g) * k
    else:
        z = 0.5 * math.sqrt(max(1.0 - a - e + i, 0.0))
        k = 0.25 / z
        q[0], q[1], q[2], q[3] = (c + g) * k, (f + h) * k, z, (d - b) * k


def _slip_loops(qc: Vector, speed: Vector, h: float, feet: Vector, out: Vector) -> None:
    """Eq. (9) of :mod:`pinobs.observers.inekf` into ``out``: ``qc`` with each foot's density
    raised by ``|ṗ_j|² h``, ``speed[feet[s]]`` for the foot at state position ``s``
    (:func:`pinobs.observers.legs.slip_densities`' arithmetic: ``q + (|ṗ_j|·|ṗ_j|)·h``)."""
    for o in range(qc.shape[0]):
        out[o] = qc[o]
    for s in range(feet.shape[0]):
        sp = speed[feet[s]]
        for o in range(9 + 3 * s, 12 + 3 * s):
            out[o] += sp * sp * h


def _finite_loops(R: Vector, x: Vector, P: Vector, bias: Vector) -> bool:
    """Whether a state is finite (:meth:`pinobs.observers.legs.LeggedSetup.finite`): the sum of
    every entry of ``R``, ``x``, ``P`` and ``bias``, row by row, is finite iff every entry is
    (or it overflowed: diverged as well)."""
    s = 0.0
    for i in range(3):
        for j in range(3):
            s += R[i, j]
    for i in range(x.shape[0]):
        for j in range(3):
            s += x[i, j]
    for i in range(P.shape[0]):
        for j in range(P.shape[1]):
            s += P[i, j]
    for i in range(bias.shape[0]):
        s += bias[i]
    return math.isfinite(s)


def _velocity_loops(
    gyro: Vector, bias: Vector, h: Vector, jdq: Vector, R: Vector, v: Vector, out: Vector,
    speed: Vector,
) -> None:  # fmt: skip
    """The feet's velocities ``ṗ̂_j = v̂ + R̂ (ω × h_j + J_j q̇)`` (``jdq`` the rows ``J_j q̇``;
    :meth:`pinobs.observers.inekf.InvariantEKF.foot_velocities`) and their speeds
    ``√max(|ṗ̂_j|², 0)``, the cross product and the sums in NumPy's order and ``(ω × h_j +
    J_j q̇) R̂ᵀ`` by fused multiply-adds in OpenBLAS's ``gemm`` order (its bits)."""
    w0, w1, w2 = gyro[0] - bias[0], gyro[1] - bias[1], gyro[2] - bias[2]  # ω = ω̃ − b̂_g
    for j in range(h.shape[0]):
        h0, h1, h2 = h[j, 0], h[j, 1], h[j, 2]
        l0 = (w1 * h2 - w2 * h1) + jdq[j, 0]
        l1 = (w2 * h0 - w0 * h2) + jdq[j, 1]
        l2 = (w0 * h1 - w1 * h0) + jdq[j, 2]
        for i in range(3):
            out[j, i] = v[i] + _fma(l2, R[i, 2], _fma(l1, R[i, 1], _fma(l0, R[i, 0], 0.0)))
        s2 = (out[j, 0] * out[j, 0] + out[j, 1] * out[j, 1]) + out[j, 2] * out[j, 2]
        speed[j] = math.sqrt(s2) if s2 > 0.0 else (0.0 if s2 <= 0.0 else s2)


def _readonly(a: Vector) -> Vector:
    """``a`` made read-only (a kernel's signature for an argument the filters pass so)."""
    a.setflags(write=False)
    return a


def _warm_propagate() -> tuple[object, ...]:
    """Arguments of :data:`propagate_kernel`'s one signature (``qc`` read-only, as cached)."""
    qc = np.ones(21)
    qc.setflags(write=False)
    n = 21
    return (np.eye(3), np.zeros((4, 3)), np.zeros(6), np.zeros(6), 1e-3, np.zeros(3), qc,
            np.zeros(4), np.zeros(2, dtype=np.intp), np.eye(n), np.empty((3, 3)),
            np.empty((4, 3)), np.empty((n, n)))  # fmt: skip


#: :func:`_propagate_loops` compiled: ``(R, x, θ, imu, h, g, Q_c, |ṗ_j|, feet, P, R1, x1, P1)``.
propagate_kernel = LazyKernel(_propagate_loops, *_warm_propagate(), contracted=("_fma",))
#: :func:`_correct_loops` compiled: ``(R, x, θ, P, h, J, rows, σ_q², σ_k², R1, x1, θ1, P1)
#: -> nis``.
correct_kernel = LazyKernel(
    _correct_loops,
    np.eye(3),
    np.zeros((3, 3)),
    np.zeros(6),
    np.eye(18),
    np.zeros((1, 3)),
    np.zeros((1, 3, 2)),
    np.zeros(1, dtype=np.intp),
    1.0,
    1.0,
    np.empty((3, 3)),
    np.empty((3, 3)),
    np.empty(6),
    np.empty((18, 18)),
    contracted=("_fma",),
)


#: :func:`_foot_nis_loops` compiled: ``(R, x, P, h, J, σ_q², σ_k², out)`` (the foot gate's).
foot_nis_kernel = LazyKernel(
    _foot_nis_loops,
    np.eye(3),
    np.zeros((3, 3)),
    np.eye(18),
    np.zeros((1, 3)),
    np.zeros((1, 3, 2)),
    1.0,
    1.0,
    np.empty(1),
    contracted=("_fma",),
)


#: :func:`_base_loops` compiled: ``(R, x, imu, ω̄, θ, R_bi, r_bi, columns, R_b, out, quat)``.
base_kernel = LazyKernel(
    _base_loops,
    np.eye(3),
    np.zeros((3, 3)),
    np.zeros(6),
    np.zeros(3),
    np.zeros(6),
    np.eye(3),
    np.zeros(3),
    False,
    np.empty((3, 3)),
    np.empty((4, 3)),
    np.empty(4),
    contracted=("_fma",),
)
#: :func:`_slip_loops` compiled: ``(Q_c (read-only), |ṗ_j|, h, feet, out)``.
slip_kernel = LazyKernel(
    _slip_loops, _readonly(np.ones(21)), np.zeros(4), 1e-3, np.zeros(2, dtype=np.intp), np.empty(21)
)
#: :func:`_finite_loops` compiled: ``(R, x, P, bias) -> finite``.
finite_kernel = LazyKernel(_finite_loops, np.eye(3), np.zeros((3, 3)), np.eye(15), np.zeros(6))
#: :func:`_velocity_loops` compiled: ``(ω̃ (≥ 3), b̂ (≥ 3), h, J q̇, R, v, out, speed)``.
velocity_kernel = LazyKernel(
    _velocity_loops,
    np.zeros(6),
    np.zeros(6),
    np.zeros((2, 3)),
    np.zeros((2, 3)),
    np.eye(3),
    np.zeros(3),
    np.empty((2, 3)),
    np.empty(2),
    contracted=("_fma",),
)


_registered = False


def _register_helpers() -> None:
    """The helpers the kernels call, made callable from compiled code (once)."""
    global _registered
    if not _registered:
        from numba.extending import register_jitable  # lazy: start-up time

        for helper in (
            _matmul,
            _matvec3,
            _slip_loops,
            gamma_coefficients,
            _gammas,
            expm_degree,
            _body_core,
            _left_adjoint,
            _left_body,
            _update_mean,
            _solve_innovation,
            _joseph,
            _foot_noise,
            _imu_to_root,
            _shepperd,
        ):
            register_jitable(helper)
        _registered = True


def load_kernels() -> None:
    """Compile (or load from numba's cache) the kernels; once."""
    if (
        propagate_kernel.compiled is None
        or correct_kernel.compiled is None
        or foot_nis_kernel.compiled is None
        or slip_kernel.compiled is None
    ):
        _register_helpers()
        propagate_kernel.load()
        correct_kernel.load()
        foot_nis_kernel.load()
        slip_kernel.load()
    load_leg_kernels()


def load_leg_kernels() -> None:
    """Compile (or load) :data:`base_kernel`, :data:`finite_kernel` and :data:`velocity_kernel`
    (every contact-aided filter's estimate; the invariant EKF's feet speeds); once."""
    if None in (base_kernel.compiled, velocity_kernel.compiled, finite_kernel.compiled):
        _register_helpers()
        base_kernel.load()
        velocity_kernel.load()
        finite_kernel.load()
