"""``kf``'s plain ``"auto"`` update in one compiled call (issue 39: a paced loop's update).

In a loop paced at 1 kHz every NumPy call, attribute look-up and temporary array of an
update runs with the caches cold after the wait: on the UR5 its checks, copies and estimate
took more than its compiled step.  :func:`auto_update_loops` is the whole of a plain
:meth:`~pinobs.observers.base.Observer.update` of ``jerk_psd="auto"`` (on vector joints,
where the sample needs no normalising): the base's checks of the inputs, the step
(:func:`~pinobs.observers.kf_kernels.auto_step_loops`, its compiled code called as it is:
the same bits) and the estimate's copy and finiteness check, each done as the base does it;
:meth:`~pinobs.observers.kf.ConstantAccelerationKF._update_fused` calls it and commits.
Anything else (a bad input, a pause, a latency, σ being learnt, a non-finite estimate) is
left to the base's own path, which then does and says what it always did.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pinobs.observers.base import Vector
from pinobs.observers.kf_kernels import auto_kernel, auto_layout, auto_step_loops
from pinobs.observers.linalg import LazyKernel
from pinobs.tolerances import TIME_EPS

__all__ = ["auto_update_loops", "update_kernel"]


def auto_update_loops(
    x: Vector, x1: Vector, out: Vector, jerk: Vector, q_meas: Vector, tau: Vector,
    measured: bool, t_prev: float, t: float, split: float, span: float, gate_on: bool, n: float, n_new: float,
    level: float, run: int, drift: float, bounds: Vector, table: NDArray[np.int64],
    meas_var: float, forget: float, threshold: float, nq: int,
) -> tuple[bool, float, bool, float, float]:  # fmt: skip
    """A plain update at ``t`` (the state's time ``t_prev``) with the sample ``q_meas`` (if
    ``measured``; else none, a prediction) and the torque ``tau`` (empty: none, zero), or
    nothing.  Plain: ``t_prev + TIME_EPS < t``, the step
    ``h = t − t_prev`` below ``split`` and at most ``span`` (the base's sub-step and pause
    limits), the grid set (``jerk``), every ``q_meas_i`` finite, every ``|τ_i| ≤ bounds_i``
    (finite; the base's absurd-torque test, joint by joint), and the estimate finite.  Then
    the step (:func:`~pinobs.observers.kf_kernels.auto_step_loops` on a copy of the sample,
    the arguments as :meth:`~pinobs.observers.kf_bank.AutoBank.step` gives them) writes the
    new state into ``x1``, and ``out`` (``nq + 2 nv``) gets the estimate ``(q̂, v̂)`` and the
    torque held from ``t`` on.  Returns ``(taken, nis, rejected, level, drift)``: the step's
    four after ``taken``; not taken, nothing is to be used (``x1`` and ``out`` half written)."""
    nv = bounds.size
    h = t - t_prev
    if not (t_prev + TIME_EPS < t and h < split and h <= span and jerk.size > 0):
        return False, math.nan, False, level, drift
    q = np.zeros(nq)  # (C-contiguous, as the step's one signature takes it; unread if none)
    for i in range(nq if measured else 0):
        q[i] = q_meas[i]
        if not math.isfinite(q_meas[i]):
            return False, math.nan, False, level, drift
    for i in range(nv):
        ti = tau[i] if tau.size else 0.0
        if not abs(ti) <= bounds[i]:  # (NaN: not ≤)
            return False, math.nan, False, level, drift
        out[nq + nv + i] = ti
    nis, rejected, level1, drift1 = _step_kernel(
        x, x1, jerk, q, table, h, meas_var, measured, gate_on, n, n_new, forget, threshold, level,
        run, drift, nq,
    )  # fmt: skip
    o_mix = x1.size - nq - nv
    for i in range(nq + nv):
        m = x1[o_mix + i]
        if not math.isfinite(m):
            return False, math.nan, False, level, drift
        out[i] = m
    return True, nis, rejected, level1, drift1


def _update_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`update_kernel`'s one signature: the state of
    :data:`~pinobs.observers.kf_kernels.auto_kernel`'s warm arguments (float64 C arrays; two
    filters, one joint), the sample and torque any 1-D float64 arrays (``A`` layout)."""
    nf, nq, nv = 2, 1, 1
    o = auto_layout(nf, nq, nv)
    x = np.zeros(o[-1])
    x[o[6] :] = 1.0  # (P = ones: S > 0)
    strided = np.zeros(4)[::2]  # (two entries: one alone would be typed C-contiguous)
    return (
        x, np.empty(o[-1]), np.empty(nq + 2 * nv), np.ones(nf), strided, strided, True, 0.0, 1e-3,
        1.0, 1.0, True, 30.0, 30.0, 1.0, 0, 0.0, np.ones(nv), np.zeros((0, 4), dtype=np.int64),
        1.0, 0.99, math.inf, nq,
    )  # fmt: skip


#: :func:`auto_update_loops` compiled (loaded when a ``kf`` whose update it runs is made).
update_kernel = LazyKernel(
    auto_update_loops,
    *_update_warm_args(),
    linked=(("_step_kernel", auto_kernel),),
)
#: The step :func:`auto_update_loops` calls: :data:`~pinobs.observers.kf_kernels.auto_kernel`'s
#: compiled function once :data:`update_kernel` is loaded, the Python one before.
_step_kernel = auto_step_loops
