"""The compiled loops of ``kf``'s filter banks (:mod:`pinobs.observers.kf_bank`).

Two numba kernels on vector joints, each loaded on first use
(:class:`~pinobs.observers.linalg.LazyKernel`: ``import pinobs`` does not import numba):
:func:`bank_rows_loops`, a bank of white-jerk filters over the rows of a log
(:meth:`~pinobs.observers.kf_bank.KFBank.run` and ``KFBank.step``), and
:func:`auto_step_loops`, one step of ``jerk_psd="auto"``
(:class:`~pinobs.observers.kf_bank.AutoBank`).  Their equations are those of the
:mod:`pinobs.observers.kf` module docstring ("module docstring" below); both are tested
equal to the NumPy paths.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pinobs.observers.base import MAX_GATE_RUN, NIS_AVERAGING, Vector
from pinobs.observers.linalg import LazyKernel

__all__ = ["auto_kernel", "auto_step_loops", "bank_kernel", "bank_rows_loops"]


# The kernels' steps: small functions compiled with them and inlined into them by numba
# (:class:`~pinobs.observers.linalg.LazyKernel`'s ``helpers``, ``inline="always"``: as fast
# as the loops written in place, and bit-identical to them on every kf and adaptive estimate
# of UR5, Panda and go1 runs with dropouts and outliers).


def _transition_into(h: float, F: Vector, Q1: Vector) -> None:
    """``F(h)`` and ``Q₁(h)`` (``Q`` at unit density) into ``F`` (its unit diagonal and zeros
    already there) and ``Q1`` (the module docstring)."""
    F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h
    Q1[0, 0], Q1[0, 1], Q1[0, 2] = h**5 / 20, h**4 / 8, h**3 / 6
    Q1[1, 1], Q1[1, 2], Q1[2, 2] = h**3 / 3, h**2 / 2, h
    Q1[1, 0], Q1[2, 0], Q1[2, 1] = Q1[0, 1], Q1[0, 2], Q1[1, 2]


def _copy_into(src: Vector, dst: Vector) -> None:
    """``dst[:] = src`` (2-D, in loops)."""
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


def _predict_covariance(
    F: Vector, Q1: Vector, jerk: float, P: Vector, FP: Vector, out: Vector
) -> None:
    """``out = F P Fᵀ + jerk · Q₁`` (3×3; ``FP`` receives ``F P``)."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += F[i, m] * P[m, j]
            FP[i, j] = s
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += FP[i, m] * F[j, m]
            out[i, j] = s + jerk * Q1[i, j]


def _correct(
    Pp: Vector, s: float, meas_var: float, e: Vector, q: Vector, v: Vector, a: Vector,
    K: Vector, C: Vector, Pn: Vector, out: Vector,
) -> None:  # fmt: skip
    """One filter's Kalman correction by its innovations ``e`` (per joint): the gain
    ``K = P⁻[:, 0] / s`` (``s = P⁻₀₀ + σ²``), ``q, v, a`` += ``K₀ e, K₁ e, K₂ e`` in place, and
    the Joseph form ``C = (I − K e₀ᵀ) P⁻``, ``Pn = C (I − K e₀ᵀ)ᵀ + σ² K Kᵀ``,
    ``out = (Pn + Pnᵀ) / 2`` (``Pn`` and ``out`` may be ``Pp``: it is read before)."""
    for i in range(3):
        K[i] = Pp[i, 0] / s
    for i in range(e.size):
        ei = e[i]
        q[i] += K[0] * ei
        v[i] += K[1] * ei
        a[i] += K[2] * ei
    for i in range(3):  # C = (I − K e₀ᵀ) P⁻
        for j in range(3):
            C[i, j] = Pp[i, j] - K[i] * Pp[0, j]
    for i in range(3):  # C (I − K e₀ᵀ)ᵀ + σ² K Kᵀ
        for j in range(3):
            Pn[i, j] = C[i, j] - C[i, 0] * K[j] + meas_var * K[i] * K[j]
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.5 * (Pn[i, j] + Pn[j, i])


def _innovations_into(q_meas: Vector, q: Vector, e: Vector) -> float:
    """One filter's innovations ``e_i = q_meas_i − q⁻_i`` into ``e``; returns ``Σ e_i²``."""
    sq = 0.0
    for i in range(e.size):
        ei = q_meas[i] - q[i]
        e[i] = ei
        sq += ei * ei
    return sq


def _outlier_gate(
    nis: float, threshold: float, level: float, nv: int, run: int
) -> tuple[bool, float]:
    """:func:`pinobs.observers.base.outlier_gate` in loops (tested equal to
    :meth:`~pinobs.observers.base.GateState.measured`): ``(rejected, the level after)``."""
    if nis > threshold * max(1.0, level / nv) and run < MAX_GATE_RUN:
        return True, level
    if run >= MAX_GATE_RUN:
        level = max(level, nis * nv / threshold)
    return False, level + NIS_AVERAGING * (min(nis, 100.0 * level) - level)


def _innovations(
    q_meas: Vector, q1: Vector, S: Vector, w: Vector, A: Vector, n: float, gate_on: bool,
    e1: Vector, A1: Vector,
) -> float:  # fmt: skip
    """:func:`auto_step_loops`'s innovations ``e_fi = q_meas_i − q⁻_fi`` (into ``e1``),
    ``z_fi = e_fi² / S_f`` (into ``A1``) and the gate's NIS, ``Σ w_fi z_fi / max(A_fi / N,
    1e-300)`` (``gate_on``) or ``Σ w_fi z_fi``, summed in order."""
    nf, nv = e1.shape
    nis = 0.0
    for f in range(nf):
        for i in range(nv):
            ei = q_meas[i] - q1[f, i]
            e1[f, i] = ei
            z = ei * ei / S[f]
            A1[f, i] = z  # z for now: the sums below
            if gate_on:
                nis += w[f, i] * z / max(A[f, i] / n, 1e-300)
            else:
                nis += w[f, i] * z
    return nis


def _weights_into(n_new: float, A1: Vector, B1: Vector, w1: Vector) -> None:
    """The mixture's weights ``w_fi ∝ exp(−(L_fi − min_f L_fi) / 2)``, ``L_fi = N log(max(A_fi,
    1e-300) / N) + B_f`` (Mehra 1970's profile likelihood; ``N`` = ``n_new``) into ``w1``."""
    nf, nv = w1.shape
    for f in range(nf):  # L_fi (into w1), the profile likelihood (Mehra 1970)
        for i in range(nv):
            w1[f, i] = n_new * math.log(max(A1[f, i], 1e-300) / n_new) + B1[f]
    for i in range(nv):  # w_fi ∝ exp(−(L_fi − min_f L_fi) / 2), summed over f in order
        low = w1[0, i]
        for f in range(1, nf):
            low = min(low, w1[f, i])
        for f in range(nf):  # exp(x) = 0 exactly below −745.2: not called there
            x = -0.5 * (w1[f, i] - low)
            w1[f, i] = math.exp(x) if x > -746.0 else 0.0
        total = w1[0, i]
        for f in range(1, nf):
            total += w1[f, i]
        for f in range(nf):
            w1[f, i] = w1[f, i] / total


def _mixture_into(w1: Vector, q1: Vector, v1: Vector, mix: Vector) -> None:
    """The mixture ``(Σ_f w_fi q_fi, Σ_f w_fi v_fi)`` into ``mix`` (2, nv), summed over ``f``
    in order."""
    nf, nv = w1.shape
    for i in range(nv):
        mq = w1[0, i] * q1[0, i]
        mv = w1[0, i] * v1[0, i]
        for f in range(1, nf):
            mq += w1[f, i] * q1[f, i]
            mv += w1[f, i] * v1[f, i]
        mix[0, i], mix[1, i] = mq, mv


def bank_rows_loops(  # noqa: C901 -- numba kernel: its branches are loops over small matrices
    q: Vector,
    v: Vector,
    a: Vector,
    P: Vector,
    t: Vector,
    q_meas: Vector,
    measured: NDArray[np.bool_],
    jerk: Vector,
    meas_var: float,
    gate: float,
    level: Vector,
    run: NDArray[np.int64],
    ll: Vector,
    e: Vector,
    X: Vector,
    PX: Vector,
    used: NDArray[np.bool_],
) -> None:
    """A bank of filters on vector joints over rows ``1..`` of ``(t, q_meas, measured)``, from
    its state at ``t[0]``, in loops (compiled by numba); the state arrays updated in place.

    The equations of the module docstring per filter ``f`` (row) and row ``k``, with
    ``h = t[k] − t[k−1]``: predict with ``F(h)`` and ``Q(h) = jerk[f] · Q₁(h)``, then, if
    ``measured[k]``, the gain ``K = P⁻[:, 0] / S`` with ``S = P⁻₀₀ + σ²``, the innovation
    ``e = q_meas[k] − q⁻`` per joint, the Joseph form
    ``P = (I − K e₀ᵀ) P⁻ (I − K e₀ᵀ)ᵀ + σ² K Kᵀ`` (symmetrised), and
    ``ll[f] += log N(e; 0, S I)`` (the prediction-error decomposition, Schweppe 1965); the
    outlier gate first (:func:`pinobs.observers.base.outlier_gate`: ``gate`` its threshold,
    ``inf`` for none; ``level`` and ``run`` each filter's, updated): a rejected measurement
    leaves the prediction and counts in ``ll`` at the gate (as
    :func:`pinobs.smoothing.rts.forward_pass`).  ``e`` receives the innovations of the last
    row, when it is measured.  When ``X`` has rows, ``X[k] = (q, v, a)``, ``PX[k] = P`` and
    ``used[k]`` (corrected with its measurement) of filter 0 at every row ``k`` (row 0
    included: not corrected).
    """
    nf, nv = v.shape
    store = X.shape[0] > 0
    F, Q1 = np.eye(3), np.zeros((3, 3))
    FP, Pp, C = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    K = np.empty(3)
    h_prev = math.nan
    for k in range(t.size):
        if k > 0:
            h = t[k] - t[k - 1]
            if h != h_prev:
                _transition_into(h, F, Q1)
                h_prev = h
            for f in range(nf):
                _predict_covariance(F, Q1, jerk[f], P[f], FP, Pp)  # P⁻ = F P Fᵀ + Q
                for i in range(nv):
                    q[f, i] = q[f, i] + v[f, i] * h + 0.5 * h * h * a[f, i]
                    v[f, i] = v[f, i] + h * a[f, i]
                if not measured[k]:
                    _copy_into(Pp, P[f])
                    continue
                s = Pp[0, 0] + meas_var
                nis = _innovations_into(q_meas[k], q[f], e[f]) / s
                # GateState.measured (base.outlier_gate), in loops: tested equal
                g = gate * max(1.0, level[f] / nv)
                if nis > g and run[f] < MAX_GATE_RUN:
                    run[f] += 1
                    ll[f] -= 0.5 * (g + nv * math.log(2.0 * math.pi * s))
                    _copy_into(Pp, P[f])
                    continue
                if run[f] >= MAX_GATE_RUN:
                    level[f] = max(level[f], nis * nv / gate)
                level[f] += NIS_AVERAGING * (min(nis, 100.0 * level[f]) - level[f])
                run[f] = 0
                if f == 0 and store:
                    used[k] = True
                ll[f] -= 0.5 * (nis + nv * math.log(2.0 * math.pi * s))
                _correct(Pp, s, meas_var, e[f], q[f], v[f], a[f], K, C, Pp, P[f])
        if store:  # filter 0's state
            for i in range(nv):
                X[k, 0, i], X[k, 1, i], X[k, 2, i] = q[0, i], v[0, i], a[0, i]
            _copy_into(P[0], PX[k])


#: :func:`bank_rows_loops` compiled (loaded when a vector-joint
#: :class:`~pinobs.observers.kf_bank.KFBank` is made).
bank_kernel = LazyKernel(
    bank_rows_loops,
    np.zeros((1, 1)),
    np.zeros((1, 1)),
    np.zeros((1, 1)),
    np.tile(np.eye(3), (1, 1, 1)),
    np.array([0.0, 1e-3]),
    np.zeros((2, 1)),
    np.array([False, True]),
    np.ones(1),
    1.0,
    math.inf,
    np.ones(1),
    np.zeros(1, dtype=np.int64),
    np.zeros(1),
    np.zeros((1, 1)),
    np.zeros((2, 3, 1)),
    np.zeros((2, 3, 3)),
    np.zeros(2, dtype=bool),
    helpers=(_transition_into, _copy_into, _predict_covariance, _innovations_into, _correct),
)


def auto_step_loops(
    q: Vector,
    v: Vector,
    a: Vector,
    P: Vector,
    A: Vector,
    B: Vector,
    w: Vector,
    jerk: Vector,
    h: float,
    meas_var: float,
    q_meas: Vector,
    measured: bool,
    gate_on: bool,
    n: float,
    n_new: float,
    forget: float,
    threshold: float,
    level: float,
    run: int,
    q1: Vector,
    v1: Vector,
    a1: Vector,
    P1: Vector,
    e1: Vector,
    A1: Vector,
    B1: Vector,
    w1: Vector,
    mix: Vector,
) -> tuple[float, bool, float]:
    """One step of ``jerk_psd="auto"`` on vector joints (module docstring), in loops compiled
    by numba: the bank's prediction and correction (:func:`bank_rows_loops`'s arithmetic, one
    row), the outlier gate, the forgotten likelihood sums, the weights and the mixture.

    Reads the state ``(q, v, a, P, A, B, w)`` (``n`` its count, ``n_new = γ n + 1``), writes
    the next one into ``(q1, v1, a1, P1, A1, B1, w1)`` (all preallocated by the caller: the
    state before is left as it was), the innovations ``e_fi = q_meas_i − q⁻_fi`` into ``e1``
    and the mixture ``(Σ_f w_fi q_fi, Σ_f w_fi v_fi)`` into ``mix`` (2, nv).  With
    ``measured``: ``S_f = P⁻_f,00 + σ₀²``, ``z_fi = e_fi² / S_f``, the gate's NIS
    ``Σ w_fi z_fi / max(A_fi / N, 1e-300)`` (``gate_on``) or ``Σ w_fi z_fi`` (too few
    samples: not gated), :func:`pinobs.observers.base.outlier_gate` on it (``threshold``,
    ``level`` the gate's, ``nv`` its degrees of freedom, ``run`` its rejections in a row: in
    loops, tested equal to :meth:`GateState.measured`); a rejected measurement leaves the
    prediction and the sums; else the Kalman correction (Joseph form, symmetrised),
    ``A ← γ A + z``, ``B ← γ B + log S`` and ``w_fi ∝ exp(−(L_fi − min_f L_fi) / 2)``,
    ``L_fi = N log(max(A_fi, 1e-300) / N) + B_f`` (Mehra 1970's profile likelihood).
    Returns ``(nis, rejected, level after)`` (``nis`` NaN without a measurement).
    """
    nf, nv = v.shape
    F, Q1 = np.eye(3), np.zeros((3, 3))
    _transition_into(h, F, Q1)
    FP = np.empty((3, 3))
    S = np.empty(nf)
    for f in range(nf):  # predict: x ← F x, P⁻ = F P Fᵀ + j_f Q₁(h)
        _predict_covariance(F, Q1, jerk[f], P[f], FP, P1[f])
        for i in range(nv):
            q1[f, i] = q[f, i] + v[f, i] * h + 0.5 * h * h * a[f, i]
            v1[f, i] = v[f, i] + h * a[f, i]
            a1[f, i] = a[f, i]
        S[f] = P1[f, 0, 0] + meas_var
    nis, reject, accept = math.nan, False, measured
    if measured:
        nis = _innovations(q_meas, q1, S, w, A, n, gate_on, e1, A1)
        if gate_on:  # base.outlier_gate, in loops
            reject, level = _outlier_gate(nis, threshold, level, nv, run)
        accept = not reject
    if accept:
        K, C, Pn = np.empty(3), np.empty((3, 3)), np.empty((3, 3))
        for f in range(nf):  # correct: K = P⁻[:, 0] / S, the Joseph form
            _correct(P1[f], S[f], meas_var, e1[f], q1[f], v1[f], a1[f], K, C, Pn, P1[f])
            B1[f] = forget * B[f] + math.log(S[f])  # the forgotten sums (module docstring)
            for i in range(nv):
                A1[f, i] = forget * A[f, i] + A1[f, i]
        _weights_into(n_new, A1, B1, w1)
    else:  # no measurement, or rejected: the sums and weights as they were
        B1[:] = B
        _copy_into(A, A1)
        _copy_into(w, w1)
    _mixture_into(w1, q1, v1, mix)
    return nis, reject, level


def _auto_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`auto_kernel`'s one signature (float64 C arrays, as the step gives)."""
    nf, nv = 2, 1
    z2, P = np.zeros((nf, nv)), np.tile(np.eye(3), (nf, 1, 1))
    return (
        z2, z2.copy(), z2.copy(), P, np.ones((nf, nv)), np.zeros(nf), np.full((nf, nv), 0.5),
        np.ones(nf), 1e-3, 1.0, np.zeros(nv), True, True, 30.0, 30.0, 0.99, math.inf, 1.0, 0,
        *(np.empty((nf, nv)) for _ in range(3)), np.empty((nf, 3, 3)), np.empty((nf, nv)),
        np.empty((nf, nv)), np.empty(nf), np.empty((nf, nv)), np.empty((2, nv)),
    )  # fmt: skip


#: :func:`auto_step_loops` compiled (loaded when a vector-joint ``kf`` with ``"auto"`` is made).
auto_kernel = LazyKernel(
    auto_step_loops,
    *_auto_warm_args(),
    helpers=(
        _transition_into, _copy_into, _predict_covariance, _correct, _innovations,
        _outlier_gate, _weights_into, _mixture_into,
    ),
)  # fmt: skip
