"""The compiled loops of ``kf``'s filter banks (:mod:`pinobs.observers.kf_bank`).

Two numba kernels, each loaded on first use
(:class:`~pinobs.observers.linalg.LazyKernel`: ``import pinobs`` does not import numba):
:func:`bank_rows_loops`, a bank of white-jerk filters over the rows of a log
(:meth:`~pinobs.observers.kf_bank.KFBank.run` and ``KFBank.step``), and
:func:`auto_step_loops`, one step of ``jerk_psd="auto"``
(:class:`~pinobs.observers.kf_bank.AutoBank`).  Their equations are those of the
:mod:`pinobs.observers.kf` module docstring ("module docstring" below); both are tested
equal to the NumPy paths.  On vector joints ``q ⊕ δ = q + δ``; on Lie-group joints
(continuous, spherical, free-flyer: :func:`joint_table`) Pinocchio's ``integrate`` and
``difference`` per joint, in loops (:func:`integrate_joints`, :func:`difference_joints`),
so that the filters' tangent-space algebra and the group's steps run in one compiled call.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import as_strided
from numpy.typing import NDArray

from pinobs.model import JointBlock
from pinobs.observers.base import MAX_GATE_RUN, NIS_AVERAGING, Vector
from pinobs.observers.gating import MAX_SPIKE_RUN, SPIKE_ALPHA
from pinobs.observers.linalg import LazyKernel

__all__ = [
    "JOINT_KINDS",
    "LIE_HELPERS",
    "auto_kernel",
    "auto_layout",
    "auto_rows_loops",
    "auto_step_loops",
    "bank_kernel",
    "bank_rows_loops",
    "copy_into",
    "covariances_view",
    "difference_joints",
    "innovations_into",
    "integrate_joints",
    "joint_table",
    "kalman_correct",
    "predict_covariance",
    "predict_mean",
    "rows_kernel",
    "rows_view",
    "transition_into",
]


# The kernels' steps: small functions compiled with them and inlined into them by numba
# (:class:`~pinobs.observers.linalg.LazyKernel`'s ``helpers``, ``inline="always"``: as fast
# as the loops written in place, and bit-identical to them on every kf and adaptive estimate
# of UR5, Panda and go1 runs with dropouts and outliers).  Public: ``adaptive``'s compiled
# bank and blend (:mod:`pinobs.observers.adaptive_blend`) are made of them too.


def transition_into(h: float, F: Vector, Q1: Vector) -> None:
    """``F(h)`` and ``Q₁(h)`` (``Q`` at unit density) into ``F`` (its unit diagonal and zeros
    already there) and ``Q1`` (the module docstring)."""
    F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h
    Q1[0, 0], Q1[0, 1], Q1[0, 2] = h**5 / 20, h**4 / 8, h**3 / 6
    Q1[1, 1], Q1[1, 2], Q1[2, 2] = h**3 / 3, h**2 / 2, h
    Q1[1, 0], Q1[2, 0], Q1[2, 1] = Q1[0, 1], Q1[0, 2], Q1[1, 2]


def copy_into(src: Vector, dst: Vector) -> None:
    """``dst[:] = src`` (2-D, in loops)."""
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


def predict_covariance(
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


def _predict_covariance_ca(
    h: float, c: float, jerk: float, Q1: Vector, P: Vector, out: Vector
) -> None:
    """:func:`predict_covariance` with ``F = [[1, h, c], [0, 1, h], [0, 0, 1]]`` written out
    (``c = h²/2``, computed as :func:`transition_into` does): its products by 1 and 0 and
    its sums of 0 left out, the rest in the same order (the same finite results, to the sign
    of an exact zero: ``0 + x`` is ``+0`` where ``x`` is ``−0``; tested equal)."""
    for j in range(3):  # F P, row by row
        p0, p1, p2 = P[0, j], P[1, j], P[2, j]
        out[0, j], out[1, j], out[2, j] = (p0 + h * p1) + c * p2, p1 + h * p2, p2
    for i in range(3):  # (F P) Fᵀ + jerk · Q₁
        f0, f1, f2 = out[i, 0], out[i, 1], out[i, 2]
        out[i, 0] = ((f0 + f1 * h) + f2 * c) + jerk * Q1[i, 0]
        out[i, 1] = (f1 + f2 * h) + jerk * Q1[i, 1]
        out[i, 2] = f2 + jerk * Q1[i, 2]


def kalman_correct(  # noqa: C901 -- numba kernel: its branches are loops over small matrices
    Pp: Vector, s: float, meas_var: float, e: Vector, q: Vector, v: Vector, a: Vector,
    K: Vector, C: Vector, Pn: Vector, out: Vector, table: NDArray[np.int64], d: Vector,
) -> None:  # fmt: skip
    """One filter's Kalman correction by its innovations ``e`` (per joint): the gain
    ``K = P⁻[:, 0] / s`` (``s = P⁻₀₀ + σ²``), ``q ← q ⊕ K₀ e`` (:func:`integrate_joints` on
    Lie-group joints, ``d`` its scratch), ``v, a`` += ``K₁ e, K₂ e`` in place, and
    the Joseph form ``C = (I − K e₀ᵀ) P⁻``, ``Pn = C (I − K e₀ᵀ)ᵀ + σ² K Kᵀ``,
    ``out = (Pn + Pnᵀ) / 2`` (``Pn`` and ``out`` may be ``Pp``: it is read before)."""
    for i in range(3):
        K[i] = Pp[i, 0] / s
    if table.shape[0] == 0:
        for i in range(e.size):
            ei = e[i]
            q[i] += K[0] * ei
            v[i] += K[1] * ei
            a[i] += K[2] * ei
    else:
        for i in range(e.size):
            ei = e[i]
            d[i] = K[0] * ei
            v[i] += K[1] * ei
            a[i] += K[2] * ei
        integrate_joints(q, d, table, q)
    for i in range(3):  # C = (I − K e₀ᵀ) P⁻
        for j in range(3):
            C[i, j] = Pp[i, j] - K[i] * Pp[0, j]
    for i in range(3):  # C (I − K e₀ᵀ)ᵀ + σ² K Kᵀ
        for j in range(3):
            Pn[i, j] = C[i, j] - C[i, 0] * K[j] + meas_var * K[i] * K[j]
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.5 * (Pn[i, j] + Pn[j, i])


def innovations_into(q_meas: Vector, q: Vector, table: NDArray[np.int64], e: Vector) -> float:
    """One filter's innovations ``e = difference(q⁻, q_meas)`` (``q_meas − q⁻`` on a vector
    space) into ``e``; returns ``Σ e_i²``."""
    if table.shape[0] > 0:
        difference_joints(q, q_meas, table, e)
    sq = 0.0
    for i in range(e.size):
        ei = e[i] if table.shape[0] > 0 else q_meas[i] - q[i]
        e[i] = ei
        sq += ei * ei
    return sq


def predict_mean(
    q: Vector, v: Vector, a: Vector, h: float, table: NDArray[np.int64], d: Vector,
    q1: Vector, v1: Vector,
) -> None:  # fmt: skip
    """``q1 = q ⊕ (v h + a h²/2)``, ``v1 = v + a h`` (the module docstring; ``q1`` may be ``q``,
    ``v1`` ``v``): on a vector space ``q + v h + a h²/2``, else :func:`integrate_joints`
    (``d`` its scratch)."""
    if table.shape[0] == 0:
        for i in range(v.size):
            q1[i] = q[i] + v[i] * h + 0.5 * h * h * a[i]
            v1[i] = v[i] + h * a[i]
        return
    for i in range(v.size):
        d[i] = v[i] * h + 0.5 * h * h * a[i]
        v1[i] = v[i] + h * a[i]
    integrate_joints(q, d, table, q1)


def _outlier_gate(
    nis: float, threshold: float, level: float, nv: int, run: int, drift: float
) -> tuple[bool, float, float]:
    """:func:`pinobs.observers.base.outlier_gate` in loops (tested equal to
    :meth:`~pinobs.observers.base.GateState.measured`, ``drift`` its ``drift``, 0 for
    ``None``): ``(rejected, the level after, the drift after)``."""
    limit = threshold * max(1.0, level / nv)
    ref = limit if run <= MAX_GATE_RUN else max(limit, drift)
    spike = run < MAX_GATE_RUN + MAX_SPIKE_RUN and nis > SPIKE_ALPHA * ref  # (past the run)
    if nis > limit and (run < MAX_GATE_RUN or spike):
        return True, level, (nis if nis <= SPIKE_ALPHA * limit else drift)
    if run >= MAX_GATE_RUN:
        level = max(level, nis * nv / threshold)
    return False, level + NIS_AVERAGING * (min(nis, 100.0 * level) - level), 0.0


def _innovations(
    q_meas: Vector, q1: Vector, S: Vector, w: Vector, A: Vector, n: float, gate_on: bool,
    table: NDArray[np.int64], e1: Vector, A1: Vector, meas_var: float,
) -> float:  # fmt: skip
    """:func:`auto_step_loops`'s innovations ``e_f = difference(q⁻_f, q_meas)`` (``q_meas −
    q⁻_f`` on a vector space; into ``e1``), ``z_fi = e_fi² / S_f`` (into ``A1``) and the gate's
    NIS, ``Σ w_fi z_fi / max(A_fi / N, σ₀² / S_f)`` (``gate_on``; ``meas_var`` = σ₀²) or
    ``Σ w_fi z_fi``, in order (:mod:`pinobs.observers.kf`: the scale's floor)."""
    nf, nv = e1.shape
    lie = table.shape[0] > 0
    nis = 0.0
    for f in range(nf):
        if lie:
            difference_joints(q1[f], q_meas, table, e1[f])
        floor = meas_var / S[f]  # ĉ S_f ≥ σ₀² (kf module docstring)
        for i in range(nv):
            ei = e1[f, i] if lie else q_meas[i] - q1[f, i]
            e1[f, i] = ei
            z = ei * ei / S[f]
            A1[f, i] = z  # z for now: the sums below
            if gate_on:
                nis += w[f, i] * z / max(A[f, i] / n, floor)
            else:
                nis += w[f, i] * z
    return nis


def _corrected_into(
    P1: Vector, S: Vector, alpha: float, meas_var: float, e1: Vector, q1: Vector, v1: Vector,
    a1: Vector, table: NDArray[np.int64], d: Vector,
) -> None:  # fmt: skip
    """Each filter's Kalman correction (:func:`kalman_correct`, in place) by its innovations
    ``e1[f]`` with the innovation variance ``α S_f``: the gain ``K / α`` (``α = 1``: the plain
    correction, to the bit; ``α > 1``: the soft gate, Chang 2014)."""
    K, C, Pn = np.empty(3), np.empty((3, 3)), np.empty((3, 3))
    for f in range(S.size):  # correct: K = P⁻[:, 0] / (α S), the Joseph form
        kalman_correct(
            P1[f], S[f] * alpha, meas_var, e1[f], q1[f], v1[f], a1[f], K, C, Pn, P1[f], table, d
        )


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


def _mixture_into(  # noqa: C901 -- numba kernel: its branches are loops over small matrices
    w1: Vector, q1: Vector, v1: Vector, table: NDArray[np.int64], d: Vector, mix: Vector
) -> None:
    """The mixture ``(Σ_f w_fi q_fi, Σ_f w_fi v_fi)`` into ``mix`` (``nq + nv``: ``q`` then
    ``v``), summed over ``f`` in order; on Lie-group joints the configurations mixed in the
    tangent space of the filter ``r`` of largest total weight, ``q_r ⊕ Σ_f w_f
    difference(q_r, q_f)`` (as :meth:`~pinobs.observers.kf_bank.AutoBank.output`; ``d``: two
    rows of ``nv`` scratch)."""
    nf, nv = w1.shape
    nq = mix.size - nv
    for i in range(nv):
        mv = w1[0, i] * v1[0, i]
        for f in range(1, nf):
            mv += w1[f, i] * v1[f, i]
        mix[nq + i] = mv
    if table.shape[0] == 0:
        for i in range(nv):
            mq = w1[0, i] * q1[0, i]
            for f in range(1, nf):
                mq += w1[f, i] * q1[f, i]
            mix[i] = mq
        return
    ref, best = 0, -math.inf
    for f in range(nf):  # the first of the largest (np.argmax)
        total = 0.0
        for i in range(nv):
            total += w1[f, i]
        if total > best:
            ref, best = f, total
    for f in range(nf):
        difference_joints(q1[ref], q1[f], table, d[0])
        for i in range(nv):
            d[1, i] = w1[f, i] * d[0, i] if f == 0 else d[1, i] + w1[f, i] * d[0, i]
    integrate_joints(q1[ref], d[1], table, mix[:nq])


# Lie-group joints (:func:`joint_table`): Pinocchio 3/4's ``integrate`` and ``difference``
# per joint, the same formulas and branches in loops (``pinocchio/src/spatial/
# explog-quaternion.hxx``, ``log.hxx``, ``multibody/liegroup/special-orthogonal.hxx`` and
# ``special-euclidean.hxx``; the maps are those of Sola, Deray & Atchuthan 2018, "A micro Lie
# theory", App. B (SO(3) as unit quaternions) and D (SE(3), its ``V(θ)``)); tested equal to
# ``pin.integrate``/``difference``.
_EPS = 2.220446049250313e-16  # the float64 machine epsilon (Pinocchio's eps)
_TAYLOR2 = _EPS ** (1.0 / 3.0)  # TaylorSeriesExpansion<double>::precision<2>()
_TAYLOR3 = _EPS ** (1.0 / 4.0)  # TaylorSeriesExpansion<double>::precision<3>()
#: :func:`joint_table`'s kinds: ``pinobs.model.JointBlock.kind`` → code.
JOINT_KINDS = {"vector": 0, "circle": 1, "so3": 2, "se3": 3}


def joint_table(joints: tuple[JointBlock, ...], nq: int, nv: int) -> NDArray[np.int64] | None:
    """The kernels' description of a robot's joints: rows ``(kind, idx_q, idx_v, nv)``
    (:data:`JOINT_KINDS`), empty on a vector space (every joint a vector joint, ``nq = nv``:
    the kernels' plain ``q + δ``), ``None`` if a joint's group is not compiled (planar) or the
    joints do not cover ``q`` and ``v``."""
    if all(b.kind == "vector" for b in joints) and nq == nv:
        return np.zeros((0, 4), dtype=np.int64)
    if any(b.kind not in JOINT_KINDS for b in joints):
        return None
    if sum(b.nq for b in joints) != nq or sum(b.nv for b in joints) != nv:
        return None
    rows = [(JOINT_KINDS[b.kind], b.idx_q, b.idx_v, b.nv) for b in joints]
    return np.array(rows, dtype=np.int64).reshape(-1, 4)


def _quat_mul(
    ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
) -> tuple[float, float, float, float]:
    """The Hamilton product ``a b`` of ``(x, y, z, w)`` quaternions (Eigen's order of terms)."""
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by + ay * bw + az * bx - ax * bz,
        aw * bz + az * bw + ax * by - ay * bx,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _quat_rotate(
    x: float, y: float, z: float, w: float, p0: float, p1: float, p2: float
) -> tuple[float, float, float]:
    """``q p q*`` as Eigen's ``_transformVector``: ``u = 2 (q⃗ × p)``, ``p + w u + q⃗ × u``."""
    u0, u1, u2 = y * p2 - z * p1, z * p0 - x * p2, x * p1 - y * p0
    u0, u1, u2 = u0 + u0, u1 + u1, u2 + u2
    return (
        p0 + w * u0 + (y * u2 - z * u1),
        p1 + w * u1 + (z * u0 - x * u2),
        p2 + w * u2 + (x * u1 - y * u0),
    )


def _exp3(w0: float, w1: float, w2: float) -> tuple[float, float, float, float]:
    """``Exp(ω)`` as a unit quaternion ``(sin(θ/2) ω/θ, cos(θ/2))``, ``θ = |ω|`` (Sola et al.
    App. B); below ``θ² = ε^¼`` their Taylor series to ``θ⁴`` (``quaternion::exp3``)."""
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    if t2 > _TAYLOR3:
        t = math.sqrt(t2 + _EPS * _EPS)
        s, c = math.sin(0.5 * t), math.cos(0.5 * t)
        return s * (w0 / t), s * (w1 / t), s * (w2 / t), c
    h2 = t2 / 4.0  # (θ/2)²
    k = 0.5 * (1.0 - h2 / 6.0 + h2 * h2 / 120.0)
    return k * w0, k * w1, k * w2, 1.0 - h2 / 2.0 + h2 * h2 / 24.0


def _log3(x: float, y: float, z: float, w: float) -> tuple[float, float, float, float]:
    """``(θ, Log(q))``: ``Log(q) = θ u`` with ``θ = 2 atan2(|q⃗|, |w|)`` on the quaternion of
    ``w ≥ 0`` (Sola et al. App. B); below ``|q⃗|² = ε^⅓`` the Taylor series
    (``quaternion::log3``)."""
    n2 = x * x + y * y + z * z
    norm = math.sqrt(n2 + _EPS * _EPS)
    sign = 1.0 if w >= 0.0 else -1.0
    wp = sign * w
    if n2 < _TAYLOR2:
        theta = 2.0 * (1.0 - n2 / (wp * wp) / 3.0) * (norm / wp)
        h2 = theta * theta / 4.0
        k = 2.0 * (1.0 + h2 / 6.0 + 7.0 / 360.0 * h2 * h2)
    else:
        half = math.atan2(norm, wp)
        theta = 2.0 * half
        k = theta / math.sin(half)
    return theta, k * (sign * x), k * (sign * y), k * (sign * z)


def _normalize_first_order(x: float, y: float, z: float, w: float, out: Vector, i: int) -> None:
    """``q (3 − |q|²) / 2`` into ``out[i:i + 4]`` (Pinocchio's ``firstOrderNormalize``)."""
    k = (3.0 - (x * x + y * y + z * z + w * w)) / 2.0
    out[i], out[i + 1], out[i + 2], out[i + 3] = x * k, y * k, z * k, w * k


def _integrate_se3(q: Vector, d: Vector, iq: int, iv: int, out: Vector) -> None:
    """A free-flyer's ``q ⊕ δ``: ``(p + R V(ω) ν, q Exp(ω))`` with ``V(ω) = I + (1 − cos θ)/θ²
    ω^ + (θ − sin θ)/θ³ ω^²`` (Sola et al. App. D), the quaternion's sign kept near
    ``q``'s, normalised to first order (``SpecialEuclideanOperationTpl<3>::integrate``)."""
    n0, n1, n2 = d[iv], d[iv + 1], d[iv + 2]
    w0, w1, w2 = d[iv + 3], d[iv + 4], d[iv + 5]
    x, y, z, w = q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]
    t2 = w0 * w0 + w1 * w1 + w2 * w2 + _EPS * _EPS
    t = math.sqrt(t2)
    if t < _TAYLOR3:
        a, b = 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0
    else:
        a, b = (1.0 - math.cos(t)) * (1.0 / t2), (t - math.sin(t)) * (1.0 / t2) / t
    c0, c1, c2 = w1 * n2 - w2 * n1, w2 * n0 - w0 * n2, w0 * n1 - w1 * n0  # ω × ν
    cc0, cc1, cc2 = w1 * c2 - w2 * c1, w2 * c0 - w0 * c2, w0 * c1 - w1 * c0  # ω × (ω × ν)
    r0, r1, r2 = _quat_rotate(
        x, y, z, w, n0 + a * c0 + b * cc0, n1 + a * c1 + b * cc1, n2 + a * c2 + b * cc2
    )
    out[iq], out[iq + 1], out[iq + 2] = r0 + q[iq], r1 + q[iq + 1], r2 + q[iq + 2]
    ex, ey, ez, ew = _exp3(w0, w1, w2)
    rx, ry, rz, rw = _quat_mul(x, y, z, w, ex, ey, ez, ew)
    if rx * x + ry * y + rz * z + rw * w < 0.0:
        rx, ry, rz, rw = -rx, -ry, -rz, -rw
    _normalize_first_order(rx, ry, rz, rw, out, iq + 3)


def _difference_se3(q0: Vector, q1: Vector, iq: int, iv: int, out: Vector) -> None:
    """A free-flyer's ``Log(q0⁻¹ q1)``: ``ω = Log(q0* q1)`` (:func:`_log3`) and ``ν = V(ω)⁻¹
    R0ᵀ (p1 − p0)``, ``V⁻¹ = I − ω^/2 + β ω^²`` (Sola et al. App. D, inverted; ``β`` of
    J. L. Blanco's eq. (9.26), Pinocchio's ``log6`` of a quaternion)."""
    x, y, z, w = q0[iq + 3], q0[iq + 4], q0[iq + 5], q0[iq + 6]
    p0, p1, p2 = _quat_rotate(
        -x, -y, -z, w, q1[iq] - q0[iq], q1[iq + 1] - q0[iq + 1], q1[iq + 2] - q0[iq + 2]
    )
    rx, ry, rz, rw = _quat_mul(-x, -y, -z, w, q1[iq + 3], q1[iq + 4], q1[iq + 5], q1[iq + 6])
    theta, w0, w1, w2 = _log3(rx, ry, rz, rw)
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    ct = (1.0 if rw >= 0.0 else -1.0) * rw
    cot = ct / math.sqrt(rx * rx + ry * ry + rz * rz + _EPS * _EPS)  # cot(θ/2)
    if theta <= _TAYLOR3:
        beta = (1.0 / 3.0 - t2 / 4.0 / 45.0) / 4.0
    else:
        beta = 1.0 / t2 - cot * 0.5 / theta
    c0, c1, c2 = w1 * p2 - w2 * p1, w2 * p0 - w0 * p2, w0 * p1 - w1 * p0  # ω × p
    cc0, cc1, cc2 = w1 * c2 - w2 * c1, w2 * c0 - w0 * c2, w0 * c1 - w1 * c0
    out[iv], out[iv + 1], out[iv + 2] = (
        p0 - 0.5 * c0 + beta * cc0, p1 - 0.5 * c1 + beta * cc1, p2 - 0.5 * c2 + beta * cc2
    )  # fmt: skip
    out[iv + 3], out[iv + 4], out[iv + 5] = w0, w1, w2


def integrate_joints(q: Vector, d: Vector, table: NDArray[np.int64], out: Vector) -> None:
    """``out = q ⊕ d`` joint by joint (``table``: :func:`joint_table`; ``out`` may be ``q``):
    vector ``q + d``; continuous ``(cos, sin)`` turned by ``d`` and normalised to first order;
    spherical ``q Exp(d)`` normalised to first order; free-flyer :func:`_integrate_se3`."""
    for j in range(table.shape[0]):
        kind, iq, iv, n = table[j, 0], table[j, 1], table[j, 2], table[j, 3]
        if kind == 0:
            for i in range(n):
                out[iq + i] = q[iq + i] + d[iv + i]
        elif kind == 1:
            ca, sa = q[iq], q[iq + 1]
            s, c = math.sin(d[iv]), math.cos(d[iv])
            o0, o1 = c * ca - s * sa, s * ca + c * sa
            k = (3.0 - (o0 * o0 + o1 * o1)) / 2.0
            out[iq], out[iq + 1] = o0 * k, o1 * k
        elif kind == 2:
            ex, ey, ez, ew = _exp3(d[iv], d[iv + 1], d[iv + 2])
            rx, ry, rz, rw = _quat_mul(q[iq], q[iq + 1], q[iq + 2], q[iq + 3], ex, ey, ez, ew)
            _normalize_first_order(rx, ry, rz, rw, out, iq)
        else:
            _integrate_se3(q, d, iq, iv, out)


def difference_joints(q0: Vector, q1: Vector, table: NDArray[np.int64], out: Vector) -> None:
    """``out = difference(q0, q1)`` joint by joint (``table``: :func:`joint_table`): vector
    ``q1 − q0``; continuous the angle of ``R0ᵀ R1`` (Pinocchio's SO(2) ``log``: ``asin`` near
    0, ``acos`` elsewhere); spherical ``Log(q0* q1)``; free-flyer :func:`_difference_se3`."""
    for j in range(table.shape[0]):
        kind, iq, iv, n = table[j, 0], table[j, 1], table[j, 2], table[j, 3]
        if kind == 0:
            for i in range(n):
                out[iv + i] = q1[iq + i] - q0[iq + i]
        elif kind == 1:
            c = q0[iq] * q1[iq] + q0[iq + 1] * q1[iq + 1]
            s = q0[iq] * q1[iq + 1] - q0[iq + 1] * q1[iq]
            tr = c + c
            if tr > 2.0:
                out[iv] = 0.0
            elif tr < -2.0:
                out[iv] = math.pi if s >= 0.0 else -math.pi
            elif tr > 2.0 - 1e-2:
                out[iv] = math.asin((s - -s) / 2.0)
            else:
                out[iv] = math.acos(tr / 2.0) if s >= 0.0 else -math.acos(tr / 2.0)
        elif kind == 2:
            x, y, z, w = q0[iq], q0[iq + 1], q0[iq + 2], q0[iq + 3]
            r = _quat_mul(-x, -y, -z, w, q1[iq], q1[iq + 1], q1[iq + 2], q1[iq + 3])
            _, out[iv], out[iv + 1], out[iv + 2] = _log3(r[0], r[1], r[2], r[3])
        else:
            _difference_se3(q0, q1, iq, iv, out)


# The Lie-group helpers, in the order they are compiled (each before its callers).
LIE_HELPERS = (
    _quat_mul, _quat_rotate, _exp3, _log3, _normalize_first_order, _integrate_se3,
    _difference_se3, integrate_joints, difference_joints,
)  # fmt: skip


def bank_rows_loops(
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
    table: NDArray[np.int64],
) -> None:
    """A bank of filters over rows ``1..`` of ``(t, q_meas, measured)``, from
    its state at ``t[0]``, in loops (compiled by numba); the state arrays updated in place.

    The equations of the module docstring per filter ``f`` (row) and row ``k``, with
    ``h = t[k] − t[k−1]``: predict with ``F(h)`` and ``Q(h) = jerk[f] · Q₁(h)``, then, if
    ``measured[k]``, the gain ``K = P⁻[:, 0] / S`` with ``S = P⁻₀₀ + σ²``, the innovation
    ``e = difference(q⁻, q_meas[k])``, the Joseph form
    ``P = (I − K e₀ᵀ) P⁻ (I − K e₀ᵀ)ᵀ + σ² K Kᵀ`` (symmetrised), and
    ``ll[f] += log N(e; 0, S I)`` (the prediction-error decomposition, Schweppe 1965); the
    outlier gate first (:func:`pinobs.observers.base.outlier_gate`: ``gate`` its threshold,
    ``inf`` for none; ``level`` and ``run`` each filter's, updated): a rejected measurement
    leaves the prediction and counts in ``ll`` at the gate (as
    :func:`pinobs.smoothing.rts.forward_pass`).  ``e`` receives the innovations of the last
    row, when it is measured.  When ``X`` has rows, ``X[k] = (q, v, a)``, ``PX[k] = P`` and
    ``used[k]`` (corrected with its measurement) of filter 0 at every row ``k`` (row 0
    included: not corrected; needs ``nq = nv``).  ``table``: the joints (:func:`joint_table`;
    empty on a vector space).
    """
    nf, nv = v.shape
    store = X.shape[0] > 0
    F, Q1 = np.eye(3), np.zeros((3, 3))
    FP, Pp, C = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    K, d = np.empty(3), np.empty(nv)
    drift = np.zeros(nf)  # each filter's GateState.drift (0: none)
    h_prev = math.nan
    for k in range(t.size):
        if k > 0:
            h = t[k] - t[k - 1]
            if h != h_prev:
                transition_into(h, F, Q1)
                h_prev = h
            for f in range(nf):
                predict_covariance(F, Q1, jerk[f], P[f], FP, Pp)  # P⁻ = F P Fᵀ + Q
                predict_mean(q[f], v[f], a[f], h, table, d, q[f], v[f])
                if not measured[k]:
                    copy_into(Pp, P[f])
                    continue
                s = Pp[0, 0] + meas_var
                nis = innovations_into(q_meas[k], q[f], table, e[f]) / s
                g = gate * max(1.0, level[f] / nv)  # the limit before the sample
                reject, level[f], drift[f] = _outlier_gate(
                    nis, gate, level[f], nv, run[f], drift[f]
                )
                if reject:  # GateState.measured (base.outlier_gate), in loops: tested equal
                    run[f] += 1
                    ll[f] -= 0.5 * (g + nv * math.log(2.0 * math.pi * s))
                    copy_into(Pp, P[f])
                    continue
                run[f] = 0
                if f == 0 and store:
                    used[k] = True
                ll[f] -= 0.5 * (nis + nv * math.log(2.0 * math.pi * s))
                kalman_correct(Pp, s, meas_var, e[f], q[f], v[f], a[f], K, C, Pp, P[f], table, d)
        if store:  # filter 0's state
            for i in range(nv):
                X[k, 0, i], X[k, 1, i], X[k, 2, i] = q[0, i], v[0, i], a[0, i]
            copy_into(P[0], PX[k])


#: :func:`bank_rows_loops` compiled (loaded when a
#: :class:`~pinobs.observers.kf_bank.KFBank` whose joints it runs is made).
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
    np.zeros((0, 4), dtype=np.int64),
    helpers=(
        *LIE_HELPERS, transition_into, copy_into, predict_covariance, innovations_into,
        predict_mean, kalman_correct, _outlier_gate,
    ),
)  # fmt: skip


def auto_layout(nf: int, nq: int, nv: int) -> tuple[int, ...]:
    """Where ``jerk_psd="auto"``'s state lies in its one float64 buffer (issue 39: one array
    to pass and allocate a step, not nine): the offsets of ``q`` (``nf × nq``), ``v``, ``a``,
    ``A``, ``w``, ``e`` (``nf × nv`` each), ``P`` (``nf × 3 × 3``), ``B`` (``nf``), the
    mixture (``nq + nv``: ``q`` then ``v``) and the end (the buffer's size), in that order."""
    o_v = nf * nq
    o_a = o_v + nf * nv
    o_A = o_a + nf * nv
    o_w = o_A + nf * nv
    o_e = o_w + nf * nv
    o_P = o_e + nf * nv
    o_B = o_P + 9 * nf
    o_mix = o_B + nf
    return 0, o_v, o_a, o_A, o_w, o_e, o_P, o_B, o_mix, o_mix + nq + nv


def rows_view(x: Vector, start: int, rows: int, cols: int) -> Vector:
    """``x[start : start + rows·cols]`` as a ``rows × cols`` array (a view: numba's
    ``reshape`` of a slice cost 13 ns each, 0.2 µs a step)."""
    return as_strided(x[start:], shape=(rows, cols), strides=(cols * x.itemsize, x.itemsize))


def covariances_view(x: Vector, start: int, nf: int) -> Vector:
    """``x[start : start + 9 nf]`` as ``nf`` 3×3 matrices (a view, as :func:`rows_view`)."""
    k = x.itemsize
    return as_strided(x[start:], shape=(nf, 3, 3), strides=(9 * k, 3 * k, k))


def auto_step_loops(
    x: Vector, x1: Vector, jerk: Vector, q_meas: Vector, table: NDArray[np.int64], h: float,
    meas_var: float, measured: bool, gate_on: bool, n: float, n_new: float, forget: float,
    threshold: float, level: float, run: int, drift: float, nq: int,
) -> tuple[float, bool, float, float]:  # fmt: skip
    """One step of ``jerk_psd="auto"`` (module docstring), in loops compiled by numba: the
    bank's prediction and correction (:func:`bank_rows_loops`'s arithmetic, one row), the
    outlier gate, the forgotten likelihood sums, the weights and the mixture.

    Reads the state ``(q, v, a, P, A, B, w)`` from the buffer ``x`` (:func:`auto_layout`,
    ``nf`` = ``jerk.size`` filters, ``nq`` given, ``nv`` from the size; ``n`` its count,
    ``n_new = γ n + 1``), writes the next one into the buffer ``x1`` (allocated by the caller:
    the state before is left as it was), the innovations ``e_f = difference(q⁻_f, q_meas)``
    and the mixture (:func:`_mixture_into`) there too (``table``: the joints,
    :func:`joint_table`).  With ``measured``: ``S_f = P⁻_f,00 + σ₀²``, ``z_fi = e_fi² / S_f``,
    the gate's NIS ``Σ w_fi z_fi / max(A_fi / N, σ₀² / S_f)`` (``gate_on``) or ``Σ w_fi z_fi``
    (too few samples: not gated), :func:`pinobs.observers.base.outlier_gate` on it
    (``threshold``, ``level`` the gate's, ``nv`` its degrees of freedom, ``run`` its
    rejections in a row, ``drift`` its drift, 0 for none: in loops, tested equal to
    :meth:`GateState.measured`); the Kalman correction (Joseph form, symmetrised), where the
    gate fired with each ``S_f`` inflated by ``α = NIS / limit`` (the soft gate: the gain
    ``K / α``) and the sums left; else
    ``A ← γ A + z``, ``B ← γ B + log S`` and ``w_fi ∝ exp(−(L_fi − min_f L_fi)
    / 2)``, ``L_fi = N log(max(A_fi, 1e-300) / N) + B_f`` (Mehra 1970's profile likelihood).
    Returns ``(nis, rejected, level after, drift after)`` (``nis`` NaN without a measurement).
    """
    nf = jerk.size
    nv = (x.size - nq * (nf + 1) - 10 * nf) // (5 * nf + 1)
    o = auto_layout(nf, nq, nv)
    q, q1 = rows_view(x, o[0], nf, nq), rows_view(x1, o[0], nf, nq)
    v, v1 = rows_view(x, o[1], nf, nv), rows_view(x1, o[1], nf, nv)
    a, a1 = rows_view(x, o[2], nf, nv), rows_view(x1, o[2], nf, nv)
    A, A1 = rows_view(x, o[3], nf, nv), rows_view(x1, o[3], nf, nv)
    w, w1 = rows_view(x, o[4], nf, nv), rows_view(x1, o[4], nf, nv)
    e1 = rows_view(x1, o[5], nf, nv)
    P, P1 = covariances_view(x, o[6], nf), covariances_view(x1, o[6], nf)
    B, B1 = x[o[7] : o[8]], x1[o[7] : o[8]]
    mix = x1[o[8] : o[9]]
    F, Q1 = np.eye(3), np.zeros((3, 3))
    transition_into(h, F, Q1)
    d, S = np.empty((2, nv)), np.empty(nf)
    for f in range(nf):  # predict: x ← F x, P⁻ = F P Fᵀ + j_f Q₁(h)
        _predict_covariance_ca(h, F[0, 2], jerk[f], Q1, P[f], P1[f])
        predict_mean(q[f], v[f], a[f], h, table, d[0], q1[f], v1[f])
        for i in range(nv):
            a1[f, i] = a[f, i]
        S[f] = P1[f, 0, 0] + meas_var
    nis, reject = math.nan, False
    if measured:
        nis = _innovations(q_meas, q1, S, w, A, n, gate_on, table, e1, A1, meas_var)
        if gate_on:  # base.outlier_gate, in loops
            reject, level, drift = _outlier_gate(nis, threshold, level, nv, run, drift)
        # the soft gate: S inflated by α = NIS / limit where it fired (kf module docstring)
        alpha = nis / (threshold * max(1.0, level / nv)) if reject else 1.0
        _corrected_into(P1, S, alpha, meas_var, e1, q1, v1, a1, table, d[0])
    else:  # (no innovation: the buffer's entries defined all the same)
        e1[:] = 0.0
    if measured and not reject:
        for f in range(nf):  # the forgotten sums (module docstring)
            B1[f] = forget * B[f] + math.log(S[f])
            for i in range(nv):
                A1[f, i] = forget * A[f, i] + A1[f, i]
        _weights_into(n_new, A1, B1, w1)
    else:  # no measurement, or gated: the sums and weights as they were
        B1[:] = B
        copy_into(A, A1)
        copy_into(w, w1)
    _mixture_into(w1, q1, v1, table, d, mix)
    return nis, reject, level, drift


def auto_rows_loops(
    x: Vector, t0: float, t: Vector, q: NDArray[np.float64], jerk: Vector,
    table: NDArray[np.int64], meas_var: float, forget: float, threshold: float, dof: float,
    n: float, level: float, level_known: bool, run: int, drift: float, nq: int,
    gate_samples: float, v_max: Vector, mixes: NDArray[np.float64], nis: Vector,
    gated: NDArray[np.bool_],
) -> tuple[int, float, float, bool, int, float]:  # fmt: skip
    """:func:`auto_step_loops` measured at each row ``k`` in turn (``q[k]`` at ``t[k]``, the step
    ``h = t[k] − t[k−1]``, ``t[−1] = t0``) with :meth:`~pinobs.observers.kf_bank.AutoBank.step`'s
    count and gate (``gate_on = n ≥ gate_samples``, ``n ← γ n + 1`` unless rejected, the
    gate's ``run``, ``drift`` and ``level``: ``dof`` while not ``level_known``): the same calls in the
    same order, without a Python call per row.  Row ``k``'s mixture ``(q̂, v̂)`` into
    ``mixes[k]``, its NIS and rejection into ``nis[k]``, ``gated[k]``.  Stops before a row whose
    mixture has a non-finite entry or a ``|v̂_i| > v_max_i`` (not taken: the state before it
    kept, for :meth:`Observer.update` to take it and say why).  The state after the last row
    taken is left in ``x``.  Returns ``(rows taken, n, level, level_known, run, drift)``."""
    size, nv = x.size, v_max.size
    o_mix = auto_layout(jerk.size, nq, nv)[8]
    bufs = np.empty((2, size))
    now = x
    done = 0
    measured = size > 0  # (True, typed bool: a literal True would compile the step again)
    for k in range(t.size):
        h = t[k] - (t0 if k == 0 else t[k - 1])
        gate_on = n >= gate_samples
        n_new = forget * n + 1.0
        nxt = bufs[k % 2]
        z, rejected, lvl, drift_new = _step_kernel(
            now, nxt, jerk, q[k], table, h, meas_var, measured, gate_on, n, n_new, forget,
            threshold, level if level_known else dof, run, drift, nq,
        )  # fmt: skip
        ok = True
        for i in range(nq + nv):
            m = nxt[o_mix + i]
            if not math.isfinite(m) or (i >= nq and abs(m) > v_max[i - nq]):
                ok = False
        if not ok:
            break
        if gate_on:  # GateState.measured, decided in the kernel
            run, level, level_known, drift = (run + 1 if rejected else 0), lvl, True, drift_new
            if rejected:
                n_new = n
        else:  # too few samples for a scale: reported, not gated
            run, level_known, rejected, drift = 0, False, False, 0.0
        n = n_new
        for i in range(nq + nv):
            mixes[k, i] = nxt[o_mix + i]
        nis[k], gated[k] = z, rejected
        now, done = nxt, k + 1
    if done:
        x[:] = now
    return done, n, level, level_known, run, drift


def _auto_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`auto_kernel`'s one signature (float64 C arrays, as the step gives)."""
    nf, nq, nv = 2, 1, 1
    size = auto_layout(nf, nq, nv)[-1]
    x = np.zeros(size)
    x[auto_layout(nf, nq, nv)[6] :] = 1.0  # (P = ones: S > 0)
    return (
        x, np.empty(size), np.ones(nf), np.zeros(nv), np.zeros((0, 4), dtype=np.int64), 1e-3,
        1.0, True, True, 30.0, 30.0, 0.99, math.inf, 1.0, 0, 0.0, nq,
    )  # fmt: skip


#: :func:`auto_step_loops` compiled (loaded when a ``kf`` with ``"auto"`` whose joints it runs
#: is made).
auto_kernel = LazyKernel(
    auto_step_loops,
    *_auto_warm_args(),
    helpers=(
        *LIE_HELPERS, transition_into, copy_into, predict_covariance, predict_mean, kalman_correct,
        _innovations, auto_layout, _predict_covariance_ca, rows_view, covariances_view,
        _outlier_gate, _corrected_into, _weights_into, _mixture_into,
    ),
)  # fmt: skip


def _rows_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`rows_kernel`'s one signature (float64 C arrays, as the bank gives;
    the state of :func:`_auto_warm_args`)."""
    x, jerk, table = _auto_warm_args()[0], np.ones(2), np.zeros((0, 4), dtype=np.int64)
    nq = nv = rows = 1
    return (
        x, 0.0, np.full(rows, 1e-3), np.zeros((rows, nq)), jerk, table, 1.0, 0.99, math.inf,
        1.0, 30.0, 1.0, True, 0, 0.0, nq, 20.0, np.full(nv, np.inf), np.empty((rows, nq + nv)),
        np.empty(rows), np.zeros(rows, dtype=np.bool_),
    )  # fmt: skip


#: :func:`auto_rows_loops` compiled (loaded by :meth:`~pinobs.observers.kf_bank.AutoBank.rows`
#: at its first call, after :data:`auto_kernel`: its helpers compiled).
rows_kernel = LazyKernel(
    auto_rows_loops,
    *_rows_warm_args(),
    helpers=auto_kernel.helpers,
    linked=(("_step_kernel", auto_kernel),),
)
#: The step :func:`auto_rows_loops` calls: :data:`auto_kernel`'s compiled function once
#: :data:`rows_kernel` is loaded (linked, not inlined: compiled once), the Python one before.
_step_kernel = auto_step_loops
