"""``kf``'s plain ``"auto"`` update in one compiled call (issue 39: a paced loop's update).

In a loop paced at 1 kHz every NumPy call, attribute look-up and temporary array of an
update runs with the caches cold after the wait: on the UR5 its checks, copies and estimate
took more than its compiled step.  :func:`auto_update_loops` is the whole of a plain
:meth:`~pinobs.observers.base.Observer.update` of ``jerk_psd="auto"`` (on vector joints,
where the sample needs no normalising): the base's checks of the inputs, the step and the
gate's bookkeeping after it (:func:`gated_step_loops`: the step,
:func:`~pinobs.observers.kf_kernels.auto_step_loops`, its compiled code called as it is, the
same bits) and the estimate's copy and finiteness check, each done as the base does it;
:meth:`~pinobs.observers.kf.ConstantAccelerationKF._update_fused` calls it and commits.
Anything else (a bad input, a pause, a latency, σ being learnt, a non-finite estimate) is
left to the base's own path, which then does and says what it always did.

Its arguments are five (issue 39: numba's entry unboxes each, about 0.3 µs a scalar and
0.5 µs an array in a paced loop): the filter's own array (:func:`fused_work`), which holds the
state (in one of two buffers: the step writes the other, which then becomes the state's),
its time, count and gate, the torque held and the constants, all updated in place by the
kernel (no state, gate or torque object made per update: the observer builds its
:class:`~pinobs.observers.kf_bank.AutoState` from the array only when asked for it,
:func:`work_state`), the estimate's new array (the caller's: users keep estimates; made by
NumPy, as numba's boxing of an array it allocates is a Python call), the sample, the torque
and the time; it returns whether it took the update, the NIS and the gate's decision.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pinobs.observers.base import Vector
from pinobs.observers.kf_kernels import auto_kernel, auto_layout, auto_step_loops
from pinobs.observers.linalg import LazyKernel
from pinobs.tolerances import TIME_EPS

__all__ = [
    "auto_update_loops",
    "fused_work",
    "gated_kernel",
    "gated_step_loops",
    "held_torque",
    "load_work",
    "set_limits",
    "update_kernel",
    "work_state",
]

#: Where :func:`fused_work` puts each number: the state's (time, count, gate, the buffer it is
#: in), then the constants; the arrays from ``_HEAD`` on.
(_T, _N, _LEVEL, _RUN, _DRIFT, _NIS, _MEASURED, _GATED, _CUR) = range(9)
(_SPLIT, _SPAN, _VAR, _FORGET, _THRESHOLD, _DOF, _SAMPLES, _NQ, _NV, _NF, _SIZE) = range(9, 20)
_GRID, _HEAD = 20, 21


def gated_step_loops(
    x: Vector, x1: Vector, jerk: Vector, q_meas: Vector, table: NDArray[np.int64], h: float,
    meas_var: float, forget: float, threshold: float, dof: float, gate_samples: float, nq: int,
    measured: bool, n: float, level: float, run: int, drift: float,
) -> tuple[float, tuple[float | None, bool, int, float | None, float | None]]:  # fmt: skip
    """One step of the ``"auto"`` bank and the gate's bookkeeping after it: the count ``N`` and
    the :class:`~pinobs.observers.base.GateState` fields ``(nis, gated, run, level, drift)``
    (``None`` where the state has none), as :meth:`~pinobs.observers.kf_bank.AutoBank.step`
    and the fused update both commit them.

    The step is :func:`~pinobs.observers.kf_kernels.auto_step_loops` (``x`` into ``x1``, the
    gate's ``level``: negative for none, then ``dof``; ``drift`` 0 for none), with the scales
    and weights before the sample (``gate_on = N ≥ gate_samples``, ``N' = γ N + 1``,
    :mod:`pinobs.observers.kf`).  Then (:meth:`~pinobs.observers.base.GateState.measured`,
    decided in the step): no sample, ``N`` kept and the gate's run, level and drift as they
    were (``GateState.predicted``); too few samples for a scale, ``N'`` and the NIS reported
    (with σ₀), not gated; else ``N'`` (``N`` if rejected: the likelihoods unchanged), the run
    ``run + 1`` if rejected else 0, the step's level and drift (0: none)."""
    gate_on = n >= gate_samples  # the scales ĉ and weights before this sample
    n_new = forget * n + 1.0  # the forgotten count (:mod:`pinobs.observers.kf`)
    known = not level < 0.0  # (a negative level: none yet)
    nis, rejected, level1, drift1 = _step_kernel(
        x, x1, jerk, q_meas, table, h, meas_var, measured, gate_on, n, n_new, forget,
        threshold, level if known else dof, run, drift, nq,
    )  # fmt: skip
    if not measured:  # the prediction (its likelihoods unchanged): GateState.predicted
        return n, (None, False, run, level if known else None, drift if drift != 0.0 else None)
    if not gate_on:  # too few samples for a scale: reported (with σ₀), not gated
        return n_new, (nis, False, 0, None, None)
    return (n if rejected else n_new), (
        nis, rejected, run + 1 if rejected else 0, level1, drift1 if drift1 != 0.0 else None,
    )  # fmt: skip


def auto_update_loops(
    work: Vector, out: Vector, q_meas: Vector, tau: Vector, t: float
) -> tuple[bool, float, bool]:
    """A plain update at ``t`` with the sample ``q_meas`` (empty: none, a prediction) and the
    torque ``tau`` (empty: none, zero) on the filter's own array ``work``
    (:func:`fused_work`: the state, its time, count and gate, the torque held, the
    constants), updated in place, the estimate ``(q̂, v̂)`` into ``out`` (``nq + nv``), or
    nothing.  Plain: ``t_prev + TIME_EPS < t`` (``t_prev``
    the state's time), the step ``h = t − t_prev`` below the base's sub-step limit and at most
    its pause limit, the grid set, every ``q_meas_i`` finite, every ``|τ_i| ≤ bound_i``
    (finite; the base's absurd-torque test, joint by joint), and the estimate finite.  Then
    :func:`gated_step_loops` (on a copy of the sample; the gate's ``n``, ``level``, ``run``,
    ``drift`` as it takes them) writes the new state into the buffer that is not the state's,
    which becomes the state's, and the time, count, gate and torque held are written over
    the old ones.  Returns ``(taken, nis, rejected)``: the step's NIS (NaN without a sample)
    and decision; not taken, ``work`` as it was (``out`` half written, not to be used)."""
    nq, nv, nf, size = int(work[_NQ]), int(work[_NV]), int(work[_NF]), int(work[_SIZE])
    t_prev = work[_T]
    h = t - t_prev
    measured = q_meas.size > 0
    if not (t_prev + TIME_EPS < t and h < work[_SPLIT] and h <= work[_SPAN] and work[_GRID]):
        return False, math.nan, False
    o_jerk = _HEAD + 2 * nv
    o_q = o_jerk + nf + 2 * size
    q = work[o_q : o_q + nq]  # (C-contiguous, as the step's one signature takes it; unread if none)
    table = np.empty((0, 4), dtype=np.int64)  # vector joints (a global array: read-only typed)
    for i in range(nq if measured else 0):
        q[i] = q_meas[i]
        if not math.isfinite(q_meas[i]):
            return False, math.nan, False
    for i in range(nv):
        if not abs(tau[i] if tau.size else 0.0) <= work[_HEAD + nv + i]:  # (NaN: not ≤)
            return False, math.nan, False
    cur = int(work[_CUR])  # the state's buffer; the step writes the other
    o_x, o_x1 = o_jerk + nf + cur * size, o_jerk + nf + (1 - cur) * size
    x1 = work[o_x1 : o_x1 + size]
    n1, gate = _gated_step(
        work[o_x : o_x + size], x1, work[o_jerk : o_jerk + nf], q, table, h, work[_VAR],
        work[_FORGET], work[_THRESHOLD], work[_DOF], work[_SAMPLES], nq, measured, work[_N],
        work[_LEVEL], int(work[_RUN]), work[_DRIFT],
    )  # fmt: skip
    o_mix = size - nq - nv
    for i in range(nq + nv):
        m = x1[o_mix + i]
        if not math.isfinite(m):
            return False, math.nan, False
        out[i] = m
    nis, rejected, run, level, drift = gate  # the commit: the state, its time, count and gate
    work[_T], work[_N], work[_CUR], work[_RUN] = t, n1, 1 - cur, run
    work[_LEVEL] = -1.0 if level is None else level
    work[_DRIFT] = 0.0 if drift is None else drift
    work[_NIS] = math.nan if nis is None else nis
    work[_MEASURED], work[_GATED] = measured, rejected
    for i in range(nv):  # the torque held from t on
        work[_HEAD + i] = tau[i] if tau.size else 0.0
    return True, work[_NIS], rejected


def fused_work(
    split: float, span: float, meas_var: float, forget: float, threshold: float, dof: float,
    gate_samples: float, nq: int, bounds: Vector, nf: int, size: int,
) -> Vector:  # fmt: skip
    """:func:`auto_update_loops`'s array, the state not yet in it (:func:`load_work`): the
    state's time, count, gate (level, run, drift; the last NIS, whether measured, whether
    rejected) and buffer index, then the base's sub-step and pause limits, σ₀², γ, the gate's
    threshold and degrees of freedom, the samples before it acts, ``nq``, ``nv``, the
    filters ``nf``, the state's size, whether the grid is set; then the torque held
    (``nv``), each joint's absurd-torque bound (``nv``), the grid (``nf``), the state's two
    buffers (``size`` each: the state in one, the next step written into the other) and the
    sample's copy (``nq``)."""
    nv = len(bounds)
    work = np.zeros(_HEAD + 2 * nv + nf + 2 * size + nq)
    head = (split, span, meas_var, forget, threshold, dof, gate_samples, nq, nv, nf, size)
    work[_SPLIT:_GRID] = head
    work[_HEAD + nv : _HEAD + 2 * nv] = bounds
    return work


def load_work(
    work: Vector, x: Vector, jerk: Vector, t: float, n: float, level: float | None, run: int,
    drift: float | None, tau: Vector,
) -> None:  # fmt: skip
    """A state into :func:`fused_work`'s array: its buffer ``x`` (into the first), grid
    ``jerk`` (empty: not set), time ``t``, count ``n``, the gate's ``level``, ``run`` and
    ``drift`` (``None``: none), and the torque held ``tau``."""
    nv, nf, size = int(work[_NV]), int(work[_NF]), int(work[_SIZE])
    work[_T], work[_N], work[_RUN], work[_CUR] = t, n, run, 0
    work[_LEVEL] = -1.0 if level is None else level
    work[_DRIFT] = 0.0 if drift is None else drift
    work[_GRID] = jerk.size == nf
    o_jerk = _HEAD + 2 * nv
    if jerk.size == nf:
        work[o_jerk : o_jerk + nf] = jerk
    work[o_jerk + nf : o_jerk + nf + size] = x
    work[_HEAD : _HEAD + nv] = tau


def work_state(work: Vector) -> tuple[Vector, float, tuple[float | None, bool, int, float | None, float | None]]:  # fmt: skip
    """The state in :func:`fused_work`'s array: a copy of its buffer, its count and its
    :class:`~pinobs.observers.base.GateState` fields ``(nis, gated, run, level, drift)``
    (``None`` where it has none; after an update without a sample, none and not gated)."""
    nv, nf, size = int(work[_NV]), int(work[_NF]), int(work[_SIZE])
    o_x = _HEAD + 2 * nv + nf + int(work[_CUR]) * size
    level, drift, measured = float(work[_LEVEL]), float(work[_DRIFT]), work[_MEASURED] != 0
    gate = (
        float(work[_NIS]) if measured else None, bool(measured and work[_GATED]),
        int(work[_RUN]), None if level < 0.0 else level, None if drift == 0.0 else drift,
    )  # fmt: skip
    return work[o_x : o_x + size].copy(), float(work[_N]), gate


def set_limits(work: Vector, split: float, span: float) -> None:
    """The base's sub-step and pause limits [s] in :func:`fused_work`'s array (the period
    learnt: :meth:`~pinobs.observers.base.Observer._set_period`)."""
    work[_SPLIT], work[_SPAN] = split, span


def held_torque(work: Vector) -> Vector:
    """The torque held in :func:`fused_work`'s array (a view: updated in place)."""
    return work[_HEAD : _HEAD + int(work[_NV])]


def _gated_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`gated_kernel`'s one signature (float64 C arrays, as the step gives;
    those of :data:`~pinobs.observers.kf_kernels.auto_kernel`'s warm step, then the gate's)."""
    nf, nq, nv = 2, 1, 1
    o = auto_layout(nf, nq, nv)
    x = np.zeros(o[-1])
    x[o[6] :] = 1.0  # (P = ones: S > 0)
    return (
        x, np.empty(o[-1]), np.ones(nf), np.zeros(nv), np.zeros((0, 4), dtype=np.int64), 1e-3,
        1.0, 0.99, math.inf, 1.0, 20.0, nq, True, 30.0, 1.0, 0, 0.0,
    )  # fmt: skip


def _update_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`update_kernel`'s one signature: the array of a bank of two
    filters on one joint, its state :data:`~pinobs.observers.kf_kernels.auto_kernel`'s warm
    one (float64 C arrays), the sample and torque any 1-D float64 arrays (``A`` layout)."""
    nf, nq, nv = 2, 1, 1
    o = auto_layout(nf, nq, nv)
    x = np.zeros(o[-1])
    x[o[6] :] = 1.0  # (P = ones: S > 0)
    strided = np.zeros(4)[::2]  # (two entries: one alone would be typed C-contiguous)
    work = fused_work(1.0, 1.0, 1.0, 0.99, math.inf, 1.0, 20.0, nq, np.ones(nv), nf, x.size)
    load_work(work, x, np.ones(nf), 0.0, 30.0, 1.0, 0, None, np.zeros(nv))
    return work, np.empty(nq + nv), strided, strided, 1e-3


#: :func:`gated_step_loops` compiled (:meth:`~pinobs.observers.kf_bank.AutoBank.step`'s, and
#: the fused update's step).
gated_kernel = LazyKernel(
    gated_step_loops, *_gated_warm_args(), linked=(("_step_kernel", auto_kernel),)
)
#: :func:`auto_update_loops` compiled (loaded when a ``kf`` whose update it runs is made).
update_kernel = LazyKernel(
    auto_update_loops,
    *_update_warm_args(),
    linked=(("_gated_step", gated_kernel),),
)
#: The step :func:`gated_step_loops` calls: :data:`~pinobs.observers.kf_kernels.auto_kernel`'s
#: compiled function once :data:`gated_kernel` is loaded, the Python one before.
_step_kernel = auto_step_loops
#: :func:`gated_step_loops` as :func:`auto_update_loops` calls it (compiled once
#: :data:`update_kernel` is loaded).
_gated_step = gated_step_loops
