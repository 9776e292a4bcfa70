"""``adaptive``'s plain update in one Python call (issue 39: a paced loop's update).

In a loop paced at 1 kHz every Python call, attribute look-up and temporary array of an
update runs with the caches cold after the wait; on a UR5 ``adaptive`` made 17 Python calls
and 39 C calls an update (the base's checks and estimate, its step around ``ekf``'s compiled
step with the offset state, the bank's and blend's kernel, the learner's bookkeeping), half
its cost beyond its model-based filter.  :func:`update_fused` is a plain
:meth:`~pinobs.observers.base.Observer.update` of it (vector joints, the compiled bank and
blend, the filter's compiled step, a sample the gate lets through) done whole:

1. the torque the filter predicts with, ``τ + b̂ + d`` (:func:`torque_sum_loops`: NumPy's
   ``(tau + offset) + d`` entry by entry, as :meth:`~pinobs.observers.adaptive.AdaptiveEKF.step`
   then :meth:`~pinobs.observers.ekf_fused.FastPath.step` add them; a held friction's torque
   as that step computes it);
2. :meth:`~pinobs.observers.ekf_fused.FastPath.step`'s Pinocchio calls and kernels on the
   filter's own buffers, the RK4's last stage, the correction, the base's checks of the sample
   and torque and the gate (:data:`~pinobs.observers.ekf_fused.finish_update_kernel`, called as
   it is), then the bank and the blend
   (:data:`~pinobs.observers.adaptive_blend.bank_blend_kernel`, called as it is, after the
   blame :meth:`~pinobs.observers.adaptive.AdaptiveEKF.step` computes), the estimate copied and
   checked finite, the sample's row written where the learner's buffer takes it next: one
   compiled call, :func:`adaptive_finish_loops` (each part the compiled code it is alone: the
   same bits);
3. the base's commit, and the learner's bookkeeping of a sample on the interval that
   completes no window and asks for no solve, with no background job's result to take
   (``Learner.add``'s usual case: its row already written; then nothing else of
   ``after_commit`` applies), else :meth:`~pinobs.observers.adaptive.AdaptiveEKF.after_commit`
   itself.  (Before that last condition, a live loop learning in the background took
   ``after_commit`` at 1747 of 5000 updates, a window's job out; 132 with it.)

Anything else (a bad input, a pause, a latency, σ being learnt, no sample, the sample gated,
the filter lost, a NIS its compiled correction leaves to NumPy, a non-finite estimate, a
Lie-group robot, learned friction in the filter's model) returns ``None`` with nothing
changed but working memory: the base's path then does and says what it always did.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from pinobs.errors import ObserverDiverged
from pinobs.observers.adaptive_blend import (
    NIS_TRUSTED,
    REJECTED_RUN,
    bank_blend_kernel,
    blend_layout,
)
from pinobs.observers.adaptive_learner import GAP_FRACTION
from pinobs.observers.adaptive_state import AdaptiveState
from pinobs.observers.base import Vector
from pinobs.observers.ekf_fused import finish_update_kernel
from pinobs.observers.ekf_state import EKFState
from pinobs.observers.fused import torque_in_kernel
from pinobs.observers.gating import GateState
from pinobs.observers.linalg import LazyKernel
from pinobs.observers.results import Estimate
from pinobs.tolerances import TIME_EPS

if TYPE_CHECKING:
    from pinobs.observers.adaptive import AdaptiveEKF
    from pinobs.observers.ekf_fused import FastPath

__all__ = [
    "NIS_REVOKED",
    "VECTOR_TABLE",
    "FusedParts",
    "adaptive_finish_kernel",
    "adaptive_finish_loops",
    "blame_of",
    "fused_step",
    "torque_sum_kernel",
    "torque_sum_loops",
    "update_fused",
]

_new_tuple = tuple.__new__  # a NamedTuple made without its __new__ (as ekf_fused's)
_new_object = object.__new__  # an Estimate without its __init__ (as Observer._make_estimate)
_F64 = np.dtype(np.float64)
_EMPTY = np.zeros(0)  # no torque given (zero held): the kernels' empty τ
#: The joints of a vector space, as the compiled bank takes them (kf_kernels.joint_table).
VECTOR_TABLE = np.zeros((0, 4), dtype=np.int64)

#: Mean NIS per degree of freedom above which the nominal model's trust is revoked at once
#: (:meth:`~pinobs.observers.adaptive.AdaptiveEKF.after_commit`).
NIS_REVOKED = 10.0


def torque_sum_loops(tau: Vector, offset: Vector, d: Vector, out: Vector) -> None:
    """``out = (τ + b̂) + d``: the torque ``adaptive``'s filter predicts with (NumPy's
    ``tau + offset``, then ``FastPath.step``'s ``+ d``, entry by entry: the same bits)."""
    for i in range(out.shape[0]):
        out[i] = (tau[i] + offset[i]) + d[i]


def blame_of(level: float, nv: int, full: bool) -> float:
    """The blend's blame on the model (``adaptive_blend.blend_inputs``, as
    :meth:`~pinobs.observers.adaptive.AdaptiveEKF.step` computes it inline):
    ``min(1, max(0, (level/nv − 2)/2))`` with Python's ``min``/``max`` (the first argument
    unless the second is strictly beyond it), 1 if ``full`` (restarted, or no model fits) or
    ``level`` not finite."""
    b = (level / nv - NIS_TRUSTED) / NIS_TRUSTED
    b = b if b > 0.0 else 0.0
    b = b if b < 1.0 else 1.0
    if full or not math.isfinite(level):
        b = 1.0
    return b


def adaptive_finish_loops(
    w: Vector, acc: Vector, h: float, q_meas: Vector, P: Vector, r: float, P_new: Vector,
    q_new: Vector, v_new: Vector, d: Vector, d_new: Vector, tau: Vector, held: Vector, run: int,
    level: float, threshold: float, x: Vector, x1: Vector, lam: float, full: bool, est: Vector,
    rows: Vector, row: int, t: float, c: Vector, torque: Vector,
) -> tuple[float, float]:  # fmt: skip
    """A plain update's end with a sample (module docstring, 2): the filter's
    (:data:`~pinobs.observers.ekf_fused.finish_update_kernel`: its checks, the RK4's last stage,
    the correction with the offset state, the gate), then, the sample let through, the bank and
    the blend (:data:`~pinobs.observers.adaptive_blend.bank_blend_kernel` on the buffer ``x``
    into ``x1``, the filter checked not lost first, the blame :func:`blame_of` the gate's new
    level), the estimate ``est = (q̂, v̂)`` every entry finite, the row ``[t, q_meas, held]``
    written at ``rows[row]`` (if inside: the learner's buffer's next row, kept only if the
    learner takes it), and the next step's torque ``torque[nv:] = (held + b̂) + d_new``
    (:func:`torque_sum_loops`; ``b̂ = torque[:nv]``).  The constants ``c``
    (:meth:`FusedParts.constants`): the bank's ``σ²``, ``nq``, where ``(q̂, v̂)`` lies in ``x``,
    the bank's size ``nf``, its densities, the torque's bounds.  Returns the NIS and the gate's
    new level; a NaN level: not taken (the outputs half written)."""
    nq, nf, nv = int(c[1]), int(c[3]), v_new.shape[0]
    jerk, bounds = c[4 : 4 + nf], c[4 + nf : 4 + nf + nv]
    out, ex = np.empty(2 * nv), np.empty(nv + P.shape[0])  # (the filter's: scratch)
    nis, lvl = _finish_update(w, acc, h, q_meas, P, r, ex, P_new, q_new, v_new, d, d_new, tau,
                              bounds, out, held, run, level, threshold)  # fmt: skip
    if lvl != lvl:
        return nis, lvl
    blame = blame_of(lvl, nv, full)
    table = np.zeros((0, 4), dtype=np.int64)  # (vector joints)
    if not _bank_blend(x, x1, nq, h, q_meas, True, jerk, c[0], q_new, v_new, P_new, lam, blame,
                       True, table):  # fmt: skip
        return nis, math.nan  # lost: the base's path restarts it
    o_est = int(c[2])
    for i in range(est.shape[0]):
        e = x1[o_est + i]
        if not math.isfinite(e):
            return nis, math.nan
        est[i] = e
    if row < rows.shape[0]:
        rows[row, 0] = t
        for i in range(nq):
            rows[row, 1 + i] = q_meas[i]
        for i in range(nv):
            rows[row, 1 + nq + i] = held[i]
    for i in range(nv):
        torque[nv + i] = (held[i] + torque[i]) + d_new[i]
    return nis, lvl


def _one() -> Vector:
    return np.zeros(1)


def _warm_args() -> tuple[object, ...]:
    """Arguments of :data:`adaptive_finish_kernel`'s one signature (nq = nv = 1, two filters,
    no offset state): float64 C arrays."""
    o = blend_layout(2, 1, 1)
    x = np.zeros(o[-1])
    x[o[3] : o[4]] = 1.0  # (the bank's P = ones: S > 0)
    c = np.array([1.0, 1.0, o[7], 2.0, 1.0, 1.0, 1.0])  # (FusedParts.constants)
    return (
        np.zeros((8, 1)), _one(), 1e-3, _one(), np.eye(2), 1.0, np.zeros((2, 2)), _one(),
        _one(), np.zeros(0), np.zeros(0), _one(), _one(), 0, 1.0, 10.0, x, np.empty(x.size),
        0.5, False, np.zeros(2), np.zeros((2, 3)), 0, 0.0, c, np.zeros(2),
    )  # fmt: skip


#: :func:`adaptive_finish_loops` compiled (loaded with a blending ``adaptive`` on vector joints).
adaptive_finish_kernel = LazyKernel(
    adaptive_finish_loops,
    *_warm_args(),
    helpers=(blame_of,),
    linked=(("_finish_update", finish_update_kernel), ("_bank_blend", bank_blend_kernel)),
)
#: :func:`torque_sum_loops` compiled.
torque_sum_kernel = LazyKernel(torque_sum_loops, _one(), _one(), _one(), _one())
#: The kernels :func:`adaptive_finish_loops` calls: the compiled ones once it is loaded.
_finish_update = finish_update_kernel.fn
_bank_blend = bank_blend_kernel.fn


class FusedParts:
    """What :func:`update_fused` needs beyond the observer: its kernels' unchecked entries
    (:meth:`~pinobs.observers.linalg.LazyKernel.unchecked`: every array theirs or checked
    C-contiguous float64 first), where the estimate lies in the bank's buffer, and ``made``:
    the state's arrays the last fused update made or checked (by identity: a memo of the
    layout check)."""

    __slots__ = (
        "c", "est_size", "est_start", "fast", "finish", "made", "offset", "torque", "torque_in", "torque_next",
        "torque_sum",
    )  # fmt: skip

    def __init__(self, est: slice, nv: int) -> None:
        self.finish = adaptive_finish_kernel.unchecked()
        self.torque_sum = torque_sum_kernel.unchecked()
        self.torque_in = torque_in_kernel.unchecked()
        self.est_start, self.est_size = est.start, est.stop - est.start
        self.c = np.zeros(0)  # the kernel's constants (constants), of the FastPath `fast`
        self.fast: Any = None
        #: ``[b̂, τ + b̂ + d]``: the offset of the model stepped last, and the torque the next
        #: step predicts with, written by the kernel (valid where ``made`` says so)
        self.torque = np.zeros(2 * nv)
        self.offset, self.torque_next = self.torque[:nv], self.torque[nv:]
        self.made: tuple[Any, ...] | None = None

    def constants(self, fast: Any, bank: Any, nq: int) -> Vector:
        """:func:`adaptive_finish_loops`' constants: the ``bank``'s ``σ²``, ``nq``, where
        ``(q̂, v̂)`` lies in its buffer, its size, its densities, then ``fast``'s torque
        bounds (kept until ``fast``, the filter's ``FastPath``, changes)."""
        if fast is not self.fast:
            head = [bank.meas_var, nq, self.est_start, bank.jerk.size]
            self.c = np.concatenate([head, bank.jerk, fast.bounds]).astype(float)
            self.fast = fast
        return self.c

    @classmethod
    def build(cls, est: slice, nv: int, *, blend: bool) -> FusedParts | None:
        """The parts of a blending ``adaptive`` whose bank and blend are compiled (vector
        joints: :data:`~pinobs.observers.adaptive_blend.bank_blend_kernel` loaded), whose
        estimate is ``x[est]``; ``None`` elsewhere (no fused update)."""
        if not blend or bank_blend_kernel.compiled is None:
            return None
        return cls(est, nv)


def _contiguous(*arrays: Any) -> bool:
    """Every one a float64 C-contiguous array (what the kernels' unchecked entries take)."""
    return all(type(a) is np.ndarray and a.dtype is _F64 and a.flags.c_contiguous for a in arrays)


def update_fused(  # noqa: C901 -- one Python call: the base's tests inline
    obs: AdaptiveEKF, t: Any, q_meas: Any, tau: Any
) -> Estimate | None:
    """A plain :meth:`~pinobs.observers.base.Observer.update` whole, or ``None`` (nothing
    changed but working memory: the base's path takes it), ``adaptive``'s ``_update_fused``
    (module docstring).  Taken: the base's plain case (a float time past the last, no sub-step,
    pause, latency or σ to learn; float64 ``q_meas`` ``(nq,)`` and ``tau`` ``(nv,)`` or
    ``None``, copied unless writable of unit stride) and :func:`fused_step`'s; then the base's
    commit and the learner's usual bookkeeping (module docstring, 3)."""
    state, parts = obs._state, obs._fused_parts
    if not (
        (type(t) is float or type(t) is np.float64)
        and parts is not None
        and q_meas is not None
        and state is not None
        and obs._noise_samples is None
        and not obs._intervals_due
        and not obs._restart_due
        and obs.latency == 0.0
    ):
        return None
    fast = state.model.core._fast
    if fast is None:
        return None
    sq, st = fast.shapes
    if not (type(q_meas) is np.ndarray and q_meas.dtype is _F64 and q_meas.shape == sq):
        return None
    if q_meas.strides != fast._stride or not q_meas.flags.writeable:
        q_meas = q_meas.copy()  # (C-contiguous: the unchecked kernel's layout)
    if tau is None:
        tau = _EMPTY
    elif not (type(tau) is np.ndarray and tau.dtype is _F64 and tau.shape == st):
        return None
    elif tau.strides != fast._stride or not tau.flags.writeable:
        tau = tau.copy()
    x = float(t)
    dt = x - obs._t
    if not (obs._t + TIME_EPS < x and dt < obs._split and dt <= obs._span):
        return None
    step = fused_step(obs, state, parts, fast, dt, q_meas, tau, x)
    if step is None:
        return None
    new, est, held, nis, lvl = step
    nq = sq[0]
    estimate = _new_object(Estimate)  # as Observer._make_estimate
    e = estimate.__dict__
    e["t"], e["q"], e["v"], e["nis"], e["gated"] = x, est[:nq], est[nq:], nis, False
    # the base's commit (Observer._update: no latency, σ known), then after_commit's usual case
    obs._state, obs._t, obs._tau, obs._last, obs._diverged = new, x, held, estimate, False
    obs._ts = x
    lr, model = state.learner, state.model
    buf, regime = lr.buf, model.regime
    h, t_last, end = lr.h, lr._t_last, buf.end
    if (
        t_last is not None
        and abs(x - t_last - h) <= GAP_FRACTION * h  # (h NaN: False)
        and not lr._off_run
        and not lr._lost
        and lr.rejected_run == model.rejected_run
        and (end == buf.start or abs(x - buf.last_t - h) <= GAP_FRACTION * h)
        and end < buf.rows.shape[0]
        and end + 1 - buf.start < lr._need
        and not (x >= lr.next_solve - TIME_EPS and lr.windows >= 2 and not lr.solving)
        and lr.next_solve == lr.next_solve  # (NaN: not started)
        and not (regime == "nominal" and lvl > NIS_REVOKED * held.shape[0])
        and not (lr.validated and regime == "warmup" and not model.restarted)
        # no job out, or the first not done (Learner.collect then takes none: the same poll)
        and (not lr.pending or not (lr.join or lr.pending[0][0].done()))
    ):  # Learner.add: on the interval, no gap, its row written (fused_step), nothing else to do
        lr._t_last = x
        buf.end, buf.last_t = end + 1, x
    else:
        obs._state = obs.after_commit(new, x, q_meas, held)
    obs._nis.append(nis)
    return estimate


def fused_step(
    obs: AdaptiveEKF, state: AdaptiveState, parts: FusedParts, fast: FastPath, dt: float,
    q_meas: Vector, tau: Vector, t: float,
) -> tuple[AdaptiveState, Vector, Vector, float, float] | None:  # fmt: skip
    """:meth:`~pinobs.observers.adaptive.AdaptiveEKF.step` of ``state`` over ``dt`` [s] to the
    sample ``q_meas`` taken at ``t`` [s], the torque held ``obs._tau``, ``tau`` the one given
    from ``t`` on (checked: :data:`adaptive_finish_kernel`), ``fast`` the filter's
    :class:`~pinobs.observers.ekf_fused.FastPath`: one compiled call around Pinocchio's (module
    docstring, 1–2).  Returns ``(state, estimate (q̂, v̂) read-only, the torque held from
    ``t``, NIS, the gate's level)``, or ``None`` where the step takes another way (the sample
    gated, the filter lost, a NIS its compiled correction leaves to NumPy, a non-finite
    estimate, the NumPy bank, an update's pending message, arrays not float64 C-contiguous)."""
    model, ekf = state.model, state.ekf
    core, xs, d = model.core, state.x, ekf.d
    if d is None or ekf.auto or model.said or type(xs) is not np.ndarray:
        return None
    q0, v0, P0, d_psd, tau_prev, offset = ekf.q, ekf.v, ekf.P, ekf.d_psd, obs._tau, model.offset
    made = parts.made  # what the last step here made or checked (by identity: a memo)
    hit = made is not None and ekf is made[0] and tau_prev is made[1] and offset is made[2]
    if not hit:
        if not _contiguous(q0, v0, P0, d, d_psd, tau_prev, offset):
            return None
        parts.offset[:] = offset
    # AdaptiveEKF.step's torque, then FastPath.step with the offset state: the same calls
    tau_in = parts.torque_next  # (τ + b̂) + d: the last kernel's where it made the state
    if model.held is not None:  # a learned friction held as an input (AdaptiveEKF._torque)
        parts.torque_in(obs._torque(state, dt, tau_prev), d, tau_in)
    elif not hit:
        parts.torque_sum(tau_prev, offset, d, tau_in)
    calls, w, (qs, vs) = fast.calls, fast._scratch_work, fast._scratch_point
    nv, gate, buf = fast.nv, ekf.gate, state.learner.buf
    q, v, P_new, d_new = np.empty(nv), np.empty(nv), np.empty(fast._shape), np.empty(nv)
    held, est, x1 = np.empty(nv), np.empty(parts.est_size), np.empty(xs.size)
    c = parts.c if fast is parts.fast else parts.constants(fast, obs._bank, q0.shape[0])
    try:
        calls.derivatives(q0, v0, tau_in)
        P = fast._scratch_P
        ddq, ddq_dq, ddq_dv, minv = fast._scratch_data
        fast._own_predict(w, q0, v0, ddq, ddq_dq, ddq_dv, minv, P0, dt, core.gains.accel_psd,
                          d_psd, fast._scratch_A, fast._scratch_Phi, P)  # fmt: skip
        aba, stage = calls.aba, fast.stage
        stage(w, aba(qs, vs, tau_in), 2, dt)
        stage(w, aba(qs, vs, tau_in), 3, dt)
        nis, lvl = parts.finish(
            w, aba(qs, vs, tau_in), dt, q_meas, P, core.gains.meas_std**2, P_new, q, v, d,
            d_new, tau, held, gate.run, float(nv) if gate.level is None else gate.level,
            core._gate, xs, x1, min(1.0, dt / obs.blend_time),
            model.restarted or model.rejected_run >= REJECTED_RUN, est, buf.rows, buf.end, t, c,
            parts.torque,
        )  # fmt: skip
    except (ObserverDiverged, np.linalg.LinAlgError, ArithmeticError):
        return None  # (AdaptiveEKF.step catches them: its way)
    if lvl != lvl:  # not taken: the base's checks, the gate, a lost filter, ekf.correct's ways
        return None
    # AdaptiveEKF.step's state: FastPath.step's EKFState (GateState.measured's gate), the blend's
    new_ekf = _new_tuple(EKFState, (q, v, P_new, d_new, d_psd, _new_tuple(GateState, (
        nis, False, 0, lvl, None)), False, ekf.psd_scale))  # fmt: skip
    new = _new_tuple(AdaptiveState, (new_ekf, x1, state.shape, state.t + dt, v0, dt, model,
                                     state.learner))  # fmt: skip
    parts.made = (new_ekf, held, offset)
    est.setflags(write=False)  # (the estimate's views read-only with it)
    return new, est, held, nis, lvl
