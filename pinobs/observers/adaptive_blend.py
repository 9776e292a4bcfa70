"""``adaptive``'s bank of ``kf`` filters and its blend (:mod:`pinobs.observers.adaptive` module
docstring, 3): their state in one float64 buffer (:func:`blend_layout`), and on vector joints
one compiled step of both (:func:`bank_blend_loops`: the bank's step, the blend, and first
whether the model-based filter is lost); :meth:`~pinobs.observers.adaptive.AdaptiveEKF.step`
runs it, or :class:`~pinobs.observers.kf_bank.KFBank`'s step and :func:`numpy_blend` on
Lie-group joints (tested equal); :func:`lost_filter`: when the model-based filter is lost.
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pinobs.observers.base import Vector
from pinobs.observers.ekf import EKFState
from pinobs.observers.kf_bank import BankState
from pinobs.observers.kf_kernels import (
    copy_into,
    covariances_view,
    innovations_into,
    kalman_correct,
    predict_covariance,
    predict_mean,
    rows_view,
    transition_into,
)
from pinobs.observers.linalg import LazyKernel

if TYPE_CHECKING:
    from pinobs.observers.adaptive_state import AdaptiveModel

__all__ = [
    "JERK_PSD",
    "NIS_TRUSTED",
    "REJECTED_RUN",
    "BankBlend",
    "bank_blend_kernel",
    "bank_blend_loops",
    "blend_inputs",
    "blend_layout",
    "blend_state",
    "buffer_part",
    "lost_filter",
    "model_free",
    "numpy_blend",
    "offsets",
    "packed",
]

#: The bank's white-jerk densities [rad²/s⁵] (:mod:`pinobs.observers.adaptive` module
#: docstring, 3).  1e1 … 1e5 until the UR10e logs (~95 Hz, positions printed to 1e-4 rad, ``benchmarks/real_logs.py``), where
#: the best fixed ``kf`` density is 1e-2 … 1: with the bank's floor at 1e1 the blend's
#: model-free side alone was 3.0× the ``kf``'s RMS (0.027 against 0.0092 rad/s on
#: ur-19_09_27-11_32_02, its model-based filter lost and restarted all along, weight 0),
#: with 1e-2 … 1e5 1.13× (0.0104); the simulated learning table is unchanged.
JERK_PSD: tuple[float, ...] = tuple(float(10.0**k) for k in range(-2, 6))


def lost_filter(ekf: EKFState) -> bool:
    """Whether a model-based filter state's estimate or covariance holds NaN or ±inf, or its
    velocity's square overflows: the blend squares it (a UR10e log, a filter at 1e207 rad/s:
    the blend's ``s`` became ``inf − inf``, the estimate NaN, and :func:`pinobs.estimate`
    re-initialised the whole observer mid-log)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return not math.isfinite(float(ekf.v @ ekf.v) + ekf.P.sum())


#: Consecutive rejected solves (no physical model fits the rows) after which
#: :meth:`~pinobs.observers.adaptive.AdaptiveEKF.consistency` says ``"inconsistent"`` whatever
#: the NIS: measured, exact-model and the README's model-error logs (UR5, Panda, double
#: pendulum, 12 s, seeds 0-1) reject at most one solve, the second; a UR5 whose wrist_2 torque
#: is logged with the wrong sign rejected every one for 30 s, stayed in its warm-up (1.18× kf)
#: and read "consistent" (the offset state absorbs the wrong torque below the NIS bound).
REJECTED_RUN = 4

#: Mean NIS per degree of freedom up to which the model-based filter is trusted outright by the
#: blend (twice the consistent value); the blame on the model ramps up to full at twice this.
NIS_TRUSTED = 2.0


def blend_inputs(
    ekf: EKFState, model: AdaptiveModel, q_meas: Vector | None
) -> tuple[Vector | None, float]:
    """The bank's sample and the blame on the model (module docstring, 3): ``q_meas`` unless
    the model-based filter's gate rejected it (not a lost filter's: restarted, not replaced
    since); the disagreement is the model's fault only when its innovations say so
    (``NIS̄ > 2 nv``), wholly when it was lost and not replaced since, or none fits.
    The fused update computes the blame in its kernel
    (:func:`~pinobs.observers.adaptive_fused.blame_of`): keep the two equal."""
    meas = None if ekf.gate.gated and not model.restarted else q_meas
    nv = ekf.v.size
    level = float(nv) if ekf.gate.level is None else ekf.gate.level
    blame = min(1.0, max(0.0, (level / nv - NIS_TRUSTED) / NIS_TRUSTED))
    if model.restarted or model.rejected_run >= REJECTED_RUN or not math.isfinite(level):
        blame = 1.0  # the model was lost and not replaced since, or none fits (or a NaN)
    return meas, blame


def blend_layout(nf: int, nq: int, nv: int) -> tuple[int, ...]:
    """Where the bank's and the blend's state lies in its one float64 buffer (issue 39: one
    array to pass and allocate a step, as ``kf``'s :func:`~pinobs.observers.kf_kernels.auto_layout`):
    the offsets of the ``nf`` filters' ``q`` (``nf × nq``), ``v``, ``a`` (``nf × nv`` each),
    ``P`` (``nf × 3 × 3``), the innovations ``e`` and the scores (``nf × nv`` each), ``s``
    (``nv``), the estimate ``q̂`` (``nq``) and ``v̂`` (``nv``, after it) and the end."""
    o_v = nf * nq
    o_a = o_v + nf * nv
    o_P = o_a + nf * nv
    o_e = o_P + 9 * nf
    o_score = o_e + nf * nv
    o_s = o_score + nf * nv
    o_q = o_s + nv
    return 0, o_v, o_a, o_P, o_e, o_score, o_s, o_q, o_q + nq, o_q + nq + nv


#: :func:`blend_layout` for Python's callers, memoised (the module's name is the compiled
#: kernel's inlined helper once :data:`bank_blend_kernel` is loaded).
offsets = functools.cache(blend_layout)


def packed(
    shape: tuple[int, int, int], bank: BankState, score: Vector, s: Vector, q: Vector, v: Vector
) -> Vector:
    """The buffer (:func:`blend_layout`) of these arrays (no innovations: zeros)."""
    o = offsets(*shape)
    x = np.zeros(o[-1])
    e = np.zeros_like(bank.v) if bank.innovation is None else bank.innovation
    for i, part in enumerate((bank.q, bank.v, bank.a, bank.P, e, score, s, q, v)):
        x[o[i] : o[i + 1]] = np.ravel(part)
    return x


class BankBlend(NamedTuple):
    """The bank's and the blend's arrays where they are stepped in NumPy (Lie-group joints:
    :class:`~pinobs.observers.kf_bank.KFBank`'s step and
    :func:`~pinobs.observers.adaptive_blend.numpy_blend`, whose arrays are kept as they are)."""

    kf: BankState  # one kf per white-jerk density
    score: Vector  # (filters, nv): running mean squared innovation of each kf per coordinate
    s: Vector  # estimated model-based velocity error variance per coordinate [rad²/s²]
    q: Vector  # the blended estimate
    v: Vector


def blend_state(
    shape: tuple[int, int, int], kf: BankState, score: Vector, s: Vector, q: Vector, v: Vector,
    *, buffer: bool,
) -> Vector | BankBlend:  # fmt: skip
    """The bank's and the blend's state of these arrays: in a buffer (:func:`packed`) for the
    compiled step (``buffer``), else a :class:`BankBlend` (``s``, ``q``, ``v`` copied)."""
    if buffer:
        return packed(shape, kf, score, s, q, v)
    return BankBlend(kf, score, s.copy(), q.copy(), v.copy())


def buffer_part(x: Vector, shape: tuple[int, int, int], i: int) -> Vector:
    """Part ``i`` of the buffer ``x`` (:func:`blend_layout`), shaped, read-only."""
    nf, nq, nv = shape
    o = offsets(nf, nq, nv)
    dims = ((nf, nq), (nf, nv), (nf, nv), (nf, 3, 3), (nf, nv), (nf, nv), (nv,), (nq,), (nv,))
    out = x[o[i] : o[i + 1]].reshape(dims[i])
    out.setflags(write=False)
    return out


def model_free(robot: Any, bank: BankState, score: Vector, q: Vector) -> tuple[Vector, ...]:
    """Per coordinate, the bank's ``kf`` with the smallest running innovation ``score``:
    ``(its v, its velocity variance, its tangent offset from the model-based q̂ = q)``."""
    best = np.argmin(score, axis=0)
    cols = np.arange(robot.nv)
    v = bank.v[best, cols]
    p = bank.P[best, 1, 1]
    if robot.is_vector_space:
        dq = bank.q[best, cols] - q
    else:
        dq = np.array([robot.difference(q, x) for x in bank.q])[best, cols]
    return v, p, dq


def numpy_blend(
    robot: Any, kf: BankState, score: Vector, s: Vector, ekf: EKFState, lam: float, blame: float
) -> tuple[Vector, Vector, Vector, Vector]:
    """The blend in NumPy, on any joints, after the bank's step ``kf``: ``(score, s, q̂, v̂)``.

    Per coordinate ``i``: the scores ``score ← score + λ(e² − score)`` (after a measurement),
    the filter ``b`` of the least score, ``v_kf = v_b``, ``P_kf = P_b,11``,
    ``s ← s + λ(blame · max((v − v_kf)² − P_kf, 0) − s)``, ``w = P_kf / (P_kf + s)``,
    ``v̂ = w v + (1 − w) v_kf``, ``q̂ = q ⊕ (1 − w) difference(q, q_b)`` (``q, v``: the
    model-based filter's; :mod:`pinobs.observers.adaptive` module docstring, 3)."""
    if kf.innovation is not None:
        score = score + lam * (kf.innovation**2 - score)
    v_kf, p_kf, dq_kf = model_free(robot, kf, score, ekf.q)
    d = ekf.v - v_kf
    s = s + lam * (blame * np.maximum(d * d - p_kf, 0.0) - s)
    w = p_kf / (p_kf + s + 1e-300)
    v = w * ekf.v + (1.0 - w) * v_kf
    q = robot.integrate(ekf.q, (1.0 - w) * dq_kf)
    return score, s, q, v


def bank_blend_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    x: Vector, x1: Vector, nq: int, dt: float, q_meas: Vector, measured: bool, jerk: Vector,
    meas_var: float, ekf_q: Vector, ekf_v: Vector, ekf_P: Vector, lam: float, blame: float,
    check: bool, table: NDArray[np.int64],
) -> bool:  # fmt: skip
    """One step of the bank and the blend on vector joints (``table`` empty), in loops
    compiled by numba: reads the buffer ``x`` (:func:`blend_layout`; ``nf`` = ``jerk.size``,
    ``nv`` = ``ekf_v.size``), writes the next state into ``x1`` (allocated by the caller: the
    state before is left as it was).  With ``check``, first whether the model-based filter
    ``(ekf_v, ekf_P)`` is lost (:func:`lost_filter`: ``Σ v_i² + Σ P_ij`` not finite, summed
    in order): then returns False at once, ``x1`` unwritten.

    The bank: :func:`~pinobs.observers.kf_kernels.bank_rows_loops`' arithmetic over one row
    (``[0, dt]``, ``measured`` with ``q_meas``), without its gate (``KFBank.step``'s is off):
    each filter predicted, and corrected by its innovation ``e = q_meas − q⁻`` (kept, zeros
    without a measurement).  The blend: :func:`numpy_blend`'s equations on the new bank, the
    model-based ``(ekf_q, ekf_v)``, ``lam`` and ``blame`` (``q̂ = q + (1 − w)(q_b − q)``); ``q̂,
    v̂`` written at the buffer's end."""
    nf, nv = jerk.size, ekf_v.size
    if check:
        sq, sp = 0.0, 0.0
        for i in range(nv):
            sq += ekf_v[i] * ekf_v[i]
        for i in range(ekf_P.shape[0]):
            for j in range(ekf_P.shape[1]):
                sp += ekf_P[i, j]
        if not math.isfinite(sq + sp):
            return False
    o = blend_layout(nf, nq, nv)
    q, q1 = rows_view(x, o[0], nf, nq), rows_view(x1, o[0], nf, nq)
    v, v1 = rows_view(x, o[1], nf, nv), rows_view(x1, o[1], nf, nv)
    a, a1 = rows_view(x, o[2], nf, nv), rows_view(x1, o[2], nf, nv)
    P, P1 = covariances_view(x, o[3], nf), covariances_view(x1, o[3], nf)
    e1 = rows_view(x1, o[4], nf, nv)
    score, score1 = rows_view(x, o[5], nf, nv), rows_view(x1, o[5], nf, nv)
    F, Q1 = np.eye(3), np.zeros((3, 3))
    FP, Pp, C = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    K, d = np.empty(3), np.empty(nv)
    transition_into(dt, F, Q1)
    for f in range(nf):  # KFBank.step (bank_rows_loops, one row, no gate)
        predict_covariance(F, Q1, jerk[f], P[f], FP, Pp)  # P⁻ = F P Fᵀ + Q
        predict_mean(q[f], v[f], a[f], dt, table, d, q1[f], v1[f])
        for i in range(nv):
            a1[f, i] = a[f, i]
        if not measured:
            copy_into(Pp, P1[f])
            for i in range(nv):
                e1[f, i] = 0.0
            continue
        s = Pp[0, 0] + meas_var
        innovations_into(q_meas, q1[f], table, e1[f])
        kalman_correct(Pp, s, meas_var, e1[f], q1[f], v1[f], a1[f], K, C, Pp, P1[f], table, d)
    for f in range(nf):  # the blend (numpy_blend)
        for i in range(nv):
            if measured:
                score1[f, i] = score[f, i] + lam * (e1[f, i] ** 2 - score[f, i])
            else:
                score1[f, i] = score[f, i]
    for i in range(nv):
        b = 0
        for f in range(1, nf):
            if score1[f, i] < score1[b, i]:
                b = f
        p_kf = P1[b, 1, 1]
        dv = ekf_v[i] - v1[b, i]
        s_i = x[o[6] + i] + lam * (blame * max(dv * dv - p_kf, 0.0) - x[o[6] + i])
        x1[o[6] + i] = s_i
        w = p_kf / (p_kf + s_i + 1e-300)
        x1[o[8] + i] = w * ekf_v[i] + (1.0 - w) * v1[b, i]
        x1[o[7] + i] = ekf_q[i] + (1.0 - w) * (q1[b, i] - ekf_q[i])
    return True


def _bank_blend_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`bank_blend_kernel`'s one signature (float64 C arrays)."""
    nf, nq, nv = 2, 1, 1
    x = np.zeros(blend_layout(nf, nq, nv)[-1])
    x[blend_layout(nf, nq, nv)[3] : blend_layout(nf, nq, nv)[4]] = 1.0  # (P = ones: S > 0)
    return (
        x, np.empty(x.size), nq, 1e-3, np.zeros(nv), True, np.ones(nf), 1.0, np.zeros(nv),
        np.zeros(nv), np.eye(2), 0.5, 0.5, True, np.zeros((0, 4), dtype=np.int64),
    )  # fmt: skip


#: :func:`bank_blend_loops` compiled (loaded when a blending ``adaptive`` on vector joints is
#: made, after :data:`~pinobs.observers.kf_kernels.bank_kernel`, whose module's compiled
#: Lie-group helpers its own helpers call).
bank_blend_kernel = LazyKernel(
    bank_blend_loops,
    *_bank_blend_warm_args(),
    helpers=(
        transition_into, copy_into, predict_covariance, innovations_into, predict_mean,
        kalman_correct, blend_layout, rows_view, covariances_view,
    ),
)  # fmt: skip
