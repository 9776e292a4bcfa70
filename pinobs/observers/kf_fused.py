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

Its arguments are few (issue 39: numba's entry unboxes each, about 0.3 µs a scalar and 0.5 µs
an array in a paced loop): the bank's constants in one array (:func:`fused_constants`), the
gate's state as four numbers; it returns the count and the gate's state after the step as
:class:`~pinobs.observers.base.GateState`'s fields, ``None`` where that has none.
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
    "fused_constants",
    "gated_kernel",
    "gated_step_loops",
    "update_kernel",
]

#: Where :func:`fused_constants` puts each constant (the torque bounds after them).
_SPLIT, _SPAN, _VAR, _FORGET, _THRESHOLD, _DOF, _SAMPLES, _NQ, _BOUNDS = range(9)


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
    x: Vector, x1: Vector, out: Vector, jerk: Vector, q_meas: Vector, tau: Vector,
    consts: Vector, t_prev: float, t: float, n: float, level: float, run: int, drift: float,
) -> tuple[bool, float, tuple[float | None, bool, int, float | None, float | None]]:  # fmt: skip
    """A plain update at ``t`` (the state's time ``t_prev``) with the sample ``q_meas`` (empty:
    none, a prediction) and the torque ``tau`` (empty: none, zero), or nothing.  Plain:
    ``t_prev + TIME_EPS < t``, the step ``h = t − t_prev`` below the base's sub-step limit and
    at most its pause limit (``consts``: :func:`fused_constants`), the grid set (``jerk``),
    every ``q_meas_i`` finite, every ``|τ_i| ≤ bound_i`` (finite; the base's absurd-torque
    test, joint by joint), and the estimate finite.  Then :func:`gated_step_loops` (on a copy
    of the sample; the gate's ``n``, ``level``, ``run``, ``drift`` as it takes them) writes the
    new state into ``x1``, and ``out`` (``nq + 2 nv``) gets the estimate ``(q̂, v̂)`` and the
    torque held from ``t`` on.  Returns ``(taken, N, gate)``: :func:`gated_step_loops`'s two
    after ``taken``; not taken, nothing is to be used (``x1`` and ``out`` half written)."""
    nq, nv = int(consts[_NQ]), consts.size - _BOUNDS
    h = t - t_prev
    measured = q_meas.size > 0
    no = (None, False, run, None, None)  # (not taken: not used)
    if not (t_prev + TIME_EPS < t and h < consts[_SPLIT] and h <= consts[_SPAN] and jerk.size > 0):
        return False, n, no
    q = np.zeros(nq)  # (C-contiguous, as the step's one signature takes it; unread if none)
    table = np.empty((0, 4), dtype=np.int64)  # vector joints (a global array: read-only typed)
    for i in range(nq if measured else 0):
        q[i] = q_meas[i]
        if not math.isfinite(q_meas[i]):
            return False, n, no
    for i in range(nv):
        ti = tau[i] if tau.size else 0.0
        if not abs(ti) <= consts[_BOUNDS + i]:  # (NaN: not ≤)
            return False, n, no
        out[nq + nv + i] = ti
    n1, gate = _gated_step(
        x, x1, jerk, q, table, h, consts[_VAR], consts[_FORGET], consts[_THRESHOLD],
        consts[_DOF], consts[_SAMPLES], nq, measured, n, level, run, drift,
    )  # fmt: skip
    o_mix = x1.size - nq - nv
    for i in range(nq + nv):
        m = x1[o_mix + i]
        if not math.isfinite(m):
            return False, n, no
        out[i] = m
    return True, n1, gate


def fused_constants(
    split: float, span: float, meas_var: float, forget: float, threshold: float, dof: float,
    gate_samples: float, nq: int, bounds: Vector,
) -> Vector:  # fmt: skip
    """:func:`auto_update_loops`'s constants in one array: the base's sub-step and pause
    limits, σ₀², γ, the gate's threshold and degrees of freedom, the samples before it acts,
    ``nq``, then each joint's absurd-torque bound."""
    head = [split, span, meas_var, forget, threshold, dof, gate_samples, float(nq)]
    return np.concatenate([np.array(head), np.asarray(bounds, dtype=np.float64)])


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
    """Arguments of :data:`update_kernel`'s one signature: the state of
    :data:`~pinobs.observers.kf_kernels.auto_kernel`'s warm arguments (float64 C arrays; two
    filters, one joint), the sample and torque any 1-D float64 arrays (``A`` layout)."""
    nf, nq, nv = 2, 1, 1
    o = auto_layout(nf, nq, nv)
    x = np.zeros(o[-1])
    x[o[6] :] = 1.0  # (P = ones: S > 0)
    strided = np.zeros(4)[::2]  # (two entries: one alone would be typed C-contiguous)
    consts = fused_constants(1.0, 1.0, 1.0, 0.99, math.inf, 1.0, 20.0, nq, np.ones(nv))
    return (
        x, np.empty(o[-1]), np.empty(nq + 2 * nv), np.ones(nf), strided, strided, consts, 0.0,
        1e-3, 30.0, 1.0, 0, 0.0,
    )  # fmt: skip


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
