"""``ekf``'s compiled step on a vector space and its plain update in one Python call (issue 39).

:class:`FastPath` is :meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.step` for a
:class:`Robot` whose configuration space is a vector space, without joint friction,
``nv ≤`` :data:`~pinobs.observers.linalg.KERNEL_MAX_NV` (a UR5, a Panda, a cartpole): four
compiled calls around Pinocchio's four (:mod:`pinobs.observers.fused`).

:func:`update_fused` is a plain :meth:`~pinobs.observers.base.Observer.update` of such a
filter without the offset state (its default), done whole, as ``kf``'s ``"auto"`` is
(:mod:`pinobs.observers.kf_fused`).  In a loop paced at 1 kHz an update's every Python call,
attribute look-up and temporary array runs with the caches cold after the wait (on the UR5
the base's glue was measured at 25–30 µs an update, ``_inputs`` 9.7 and ``_make_estimate``
6.1; what this path saves, measured: 6.8–8.2 µs an update, 14–16 %, the ``ekf`` module
docstring).  Here, in one Python call (``update`` → ``_update_fused``: 2 in all,
12 before), the step's Pinocchio calls on bound functions and the filter's own ``pin.Data``,
its kernels without numba's dispatcher, and two kernels (:func:`finish_update_loops`,
:func:`coast_update_loops`) that end the step as the step's own kernels do (called as they are,
compiled: the same bits) and do the base's checks of the sample and the torque, the outlier
gate's decision (:func:`~pinobs.observers.gating.gate_loops`: ``GateState.measured``'s), the
estimate's copy and its finiteness check as the base does them.  Anything else (a bad input, a
pause, a latency, σ being learnt, the sample rejected by the gate, a NIS the kernel leaves to
:meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.correct`, a non-finite estimate, the offset
state) returns ``None``, nothing changed: the base's own path then does and says what it always
did.

:func:`update_blocks` is the same offer for a filter whose step is
:class:`~pinobs.observers.blockstep.BlockStep`'s (Lie-group joints, ``nv > KERNEL_MAX_NV``: go1,
talos; no offset state), with a sample: the base's checks of the sample and the torque in one
compiled call (:func:`inputs_loops`; the unit-norm blocks by ``Robot.normalized_units`` as the
base's), the one-BLAS-thread limit of :func:`~pinobs.observers.blas.one_blas_thread` inline (its
wrapper and look-up were three Python calls), the filter's own block step (under its
``np.errstate``), the estimate's copy and finiteness check compiled (:func:`copy_out_loops`)
and the base's commit.  A talos update: 15 → 11 Python-level calls (65 → 49 with C calls),
the glue around the step (thread CPU time of the update less its step's, same updates)
25.4 → 12.9 µs, 2.0 → 1.05 ``pin.aba``; in-process A/B against the base's path (20-update
chunks alternated, thread CPU, 40 rounds): 22.04 → 21.16 ``pin.aba``, 11.6 µs less an update
(paired median, IQR 2.7–20.2; load 2.8), go1 19.31 → 18.52, 3.7 µs less; the same bits.
Issue 39's 19× on a talos is not reached: the step itself is most of the update (each part
timed alone, warm, in warm ``pin.aba``: Pinocchio's four calls 7.0, the RKMK4's work between
them 0.7, the five BLAS products 4.9, the six compiled kernels 2.8).
"""

from __future__ import annotations

import copy
import math
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from pinobs.model import Robot
from pinobs.model.integrators import dynamics_calls
from pinobs.observers.base import Vector
from pinobs.observers.blas import found_libraries
from pinobs.observers.ekf_state import EKFState
from pinobs.observers.fused import (
    compiled_vector_space,
    ekf_coast_kernel,
    ekf_coast_loops,
    ekf_finish_kernel,
    ekf_finish_loops,
    ekf_predict_kernel,
    loaded,
    rk4_stage_kernel,
    torque_in_kernel,
)
from pinobs.observers.gating import GateState, gate_loops
from pinobs.observers.linalg import LazyKernel, identity
from pinobs.observers.results import Estimate
from pinobs.tolerances import TIME_EPS

if TYPE_CHECKING:
    from pinobs.observers.ekf import ExtendedKalmanFilter

__all__ = [
    "FastPath",
    "coast_update_kernel",
    "estimate_out",
    "finish_update_kernel",
    "held_torque",
    "inputs_kernel",
    "update_blocks",
    "update_fused",
]

_new_tuple = tuple.__new__  # a NamedTuple made without its __new__ (the fast paths' EKFState)
_new_object = object.__new__  # an Estimate without its __init__ (as Observer._make_estimate)
_F64 = np.dtype(np.float64)
_EMPTY = np.zeros(0)  # no torque given (zero held): the kernels' empty τ


def held_torque(tau: Vector, bounds: Vector, held: Vector) -> bool:
    """The base's check of an update's torque (``Observer._inputs``, ``Observer._check_tau``):
    every ``|τ_i| ≤ bounds_i`` (the absurd-torque bound; NaN is not ``≤``), then ``held = τ``
    (``tau`` empty: none given, ``held = 0``).  False: refused (``held`` half written)."""
    for i in range(held.shape[0]):
        ti = tau[i] if tau.shape[0] else 0.0
        if not abs(ti) <= bounds[i]:
            return False
        held[i] = ti
    return True


def finish_update_loops(
    w: Vector, acc: Vector, h: float, q_meas: Vector, P: Vector, r: float, ex: Vector,
    P_new: Vector, q_new: Vector, v_new: Vector, d: Vector, d_new: Vector, tau: Vector,
    bounds: Vector, out: Vector, held: Vector, run: int, level: float, threshold: float,
) -> tuple[float, float]:  # fmt: skip
    """A plain update's end with a sample: the base's checks (every ``q_meas_i`` finite, the
    torque by :func:`held_torque`), the step's end (:func:`~pinobs.observers.fused.ekf_finish_loops`,
    its compiled code called as it is: the same bits), the gate (:func:`~pinobs.observers.gating.gate_loops`) and the
    estimate ``out = (q̂, v̂)``, every entry finite (the base's check).  Returns the NIS and the
    gate's new level; NaN: not taken (a check failed, the gate rejected the sample, or the
    correction takes another way; the outputs half written)."""
    for i in range(q_meas.shape[0]):
        if not math.isfinite(q_meas[i]):
            return math.nan, math.nan
    if not held_torque(tau, bounds, held):
        return math.nan, math.nan
    nis = _finish_kernel(w, acc, h, q_meas, P, r, ex, P_new, q_new, v_new, d, d_new)
    if nis != nis:
        return nis, nis
    gated, _, new_level, _, _ = gate_loops(nis, run, level, False, 0.0, True, threshold, q_new.size)
    return nis, estimate_out(q_new, v_new, out, math.nan if gated else new_level)


def estimate_out(q: Vector, v: Vector, out: Vector, level: float) -> float:
    """``out = (q, v)`` if every entry is finite (the base's check of an estimate) and the
    gate let the sample through (``level`` not NaN): ``level``; else NaN (not taken)."""
    nv = q.shape[0]
    for i in range(nv if level == level else 0):
        if not (math.isfinite(q[i]) and math.isfinite(v[i])):
            return math.nan
        out[i] = q[i]
        out[nv + i] = v[i]
    return level


def coast_update_loops(
    w: Vector, acc: Vector, h: float, P: Vector, P_out: Vector, q_new: Vector, v_new: Vector,
    tau: Vector, bounds: Vector, out: Vector, held: Vector,
) -> bool:  # fmt: skip
    """A plain update's end without a sample: the torque's check (:func:`held_torque`), the
    step's end (:func:`~pinobs.observers.fused.ekf_coast_loops`, called as it is), its
    ``(q_s, v_s)`` copied into ``(q_new, v_new)`` and into the estimate ``out``, every entry
    finite.  False: not taken."""
    if not held_torque(tau, bounds, held):
        return False
    _coast_kernel(w, acc, h, P, P_out)
    nv = q_new.shape[0]
    for i in range(nv):
        qi, vi = w[6, i], w[7, i]
        if not (math.isfinite(qi) and math.isfinite(vi)):
            return False
        q_new[i] = qi
        v_new[i] = vi
        out[i] = qi
        out[nv + i] = vi
    return True


def inputs_loops(q: Vector, tau: Vector, bounds: Vector, held: Vector) -> bool:
    """The base's checks of a plain update's inputs (``Observer._inputs``): every ``q_i``
    finite, the torque by :func:`held_torque` (``held = τ``).  False: refused."""
    for i in range(q.shape[0]):
        if not math.isfinite(q[i]):
            return False
    return held_torque(tau, bounds, held)


def copy_out_loops(q: Vector, v: Vector, out: Vector) -> bool:
    """``out = (q, v)`` (``q`` of any length: ``nq``) if every entry is finite (the base's
    check of an estimate); False: not taken (``out`` half written)."""
    nq = q.shape[0]
    for i in range(nq):
        if not math.isfinite(q[i]):
            return False
        out[i] = q[i]
    for i in range(v.shape[0]):
        if not math.isfinite(v[i]):
            return False
        out[nq + i] = v[i]
    return True


def _one() -> Vector:
    return np.zeros(1)


#: :func:`finish_update_loops` compiled (loaded by :class:`FastPath`).
finish_update_kernel = LazyKernel(
    finish_update_loops,
    np.zeros((8, 1)), _one(), 1e-3, _one(), np.eye(2), 1.0, np.zeros(3), np.zeros((2, 2)),
    _one(), _one(), np.zeros(0), np.zeros(0), _one(), np.ones(1), np.zeros(2), _one(), 0, 1.0,
    10.0, helpers=(held_torque, gate_loops, estimate_out),
    linked=(("_finish_kernel", ekf_finish_kernel),),
)  # fmt: skip
#: :func:`coast_update_loops` compiled (loaded by :class:`FastPath`).
coast_update_kernel = LazyKernel(
    coast_update_loops,
    np.zeros((8, 1)), _one(), 1e-3, np.eye(2), np.zeros((2, 2)), _one(), _one(), _one(),
    np.ones(1), np.zeros(2), _one(),
    helpers=(held_torque,),
    linked=(("_coast_kernel", ekf_coast_kernel),),
)  # fmt: skip
#: :func:`inputs_loops` compiled (loaded by :class:`~pinobs.observers.blockstep.BlockStep`'s
#: filter: :func:`update_blocks`).
inputs_kernel = LazyKernel(inputs_loops, _one(), _one(), np.ones(1), _one(), helpers=(held_torque,))
#: :func:`copy_out_loops` compiled (:func:`update_blocks`).
copy_out_kernel = LazyKernel(copy_out_loops, _one(), _one(), np.zeros(2))
#: The step's kernels :func:`finish_update_loops` and :func:`coast_update_loops` call: the
#: compiled ones once those are loaded, the Python ones before.
_finish_kernel = ekf_finish_loops
_coast_kernel = ekf_coast_loops


class FastPath:
    """:meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.step` in four compiled calls around Pinocchio's four
    (issue 39; :mod:`pinobs.observers.fused`).  For a :class:`Robot` whose configuration
    space is a vector space, without joint friction, ``nv ≤ KERNEL_MAX_NV``; the same
    equations as :meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.predict` then
    :meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.corrected`, to rounding (tested), which it falls back on
    where :meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.correct` takes another way (a NaN NIS, see
    :func:`~pinobs.observers.fused.ekf_correct_loops`).  It owns its ``pin.Data``; its
    buffers are working memory (``_scratch``: overwritten by every step, never read across
    steps)."""

    def __init__(self, ekf: ExtendedKalmanFilter) -> None:
        robot, nv = ekf.robot, ekf.robot.nv
        n = (2 if ekf.disturbance_psd is None else 3) * nv
        self.calls = dynamics_calls(robot)
        data = self.calls.data
        # a, ∂a/∂q, ∂a/∂v, M⁻¹ of the derivatives call: views Pinocchio writes in place
        self._scratch_data = (data.ddq, data.ddq_dq, data.ddq_dv, data.Minv)
        self._scratch_work = np.zeros((8, nv))  # the RK4's rows (pinobs.observers.fused)
        # the next stage's (q, v)
        self._scratch_point = (self._scratch_work[6], self._scratch_work[7])
        self._scratch_A = np.zeros((n, n))
        self._scratch_A[:nv, nv : 2 * nv] = identity(nv)
        self._scratch_Phi = np.empty((n, n))
        self._scratch_P = np.empty((n, n))  # P⁻ (a state keeps a copy, never this)
        self._scratch_ex = np.empty(nv + n)  # the correction's (e, dx)
        self._shape = (n, n)
        self.no_psd = np.zeros(nv)
        self.no_d = np.zeros(0)  # the finish kernel's offset arguments without one
        self._stride = (_F64.itemsize,)  # a contiguous q_meas's strides
        self._scratch_tau = np.empty(nv)  # τ + d (torque_in)
        self.torque_in = loaded(torque_in_kernel)
        self.predict, self.finish = loaded(ekf_predict_kernel), loaded(ekf_finish_kernel)
        # without numba's dispatcher (LazyKernel.unchecked): the stages and the coast on the
        # step's own buffers and aba's output; predict and finish where the state's arrays are
        # the (q, v, P) this path returned last (_layout_cache: a memo of the layout check, by
        # identity; the bits are the dispatcher's either way) and q_meas a float64 array of
        # unit stride (issue 39: in a paced 1 kHz loop 1–1.5 µs less on predict alone)
        self.stage, self.coast = rk4_stage_kernel.unchecked(), ekf_coast_kernel.unchecked()
        views = all(x.dtype == _F64 and x.flags.c_contiguous for x in self._scratch_data)
        self._own_predict = ekf_predict_kernel.unchecked() if views else self.predict
        self._own_finish = ekf_finish_kernel.unchecked()
        self._layout_cache: tuple[Vector, Vector, Vector] | None = None
        # update_fused's: its two kernels (unchecked: every array theirs or made C-contiguous
        # float64 first), the torque's bounds (Robot.absurd_torque), the shapes it takes
        self._update_finish = finish_update_kernel.unchecked()
        self._update_coast = coast_update_kernel.unchecked()
        self.bounds = np.array(robot.absurd_torque, dtype=float)
        self.nv, self.shapes = nv, ((robot.nq,), (nv,))

    @classmethod
    def build(cls, ekf: ExtendedKalmanFilter) -> FastPath | None:
        """The fast path of ``ekf``, or ``None`` where its robot does not qualify."""
        return cls(ekf) if compiled_vector_space(ekf.robot) else None

    def rebound(self, robot: Robot) -> FastPath:
        """This fast path on ``robot``, a model of the same tree as its own (its
        :meth:`Robot.with_inertials`: ``replace_robot``): the calls bound to the new model,
        on the same ``pin.Data`` (which depends only on the model's structure: Pinocchio
        overwrites what it reads), the buffers and kernels shared (working memory: one
        step at a time, as ``adaptive``'s copies of a filter).  A UR5 filter copied and its
        robot replaced: 15–18 → 3–6 ``pin.aba``."""
        fast = copy.copy(self)
        fast.calls = dynamics_calls(robot, data=self.calls.data)
        return fast

    def step(
        self, ekf: ExtendedKalmanFilter, state: EKFState, dt: float, q_meas: Vector | None,
        tau: Vector,
    ) -> EKFState:  # fmt: skip
        """:meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.step` (class docstring): four compiled calls around
        Pinocchio's four, the last (:func:`~pinobs.observers.fused.ekf_finish_loops`) the RK4's
        last stage and the correction (with the offset state's); ``P⁻`` and ``(e, dx)`` in the
        scratch buffers.  No NumPy floating-point warning (a lost filter's overflows): its
        NumPy arithmetic is compiled or under ``np.errstate`` (``compiled_step``)."""
        d = state.d
        if d is None:
            tau_in = tau
        else:  # τ + d, compiled: no overflow warning where a lost filter's d overflows
            tau_in = self._scratch_tau
            self.torque_in(tau, d, tau_in)
        calls, w, (qs, vs) = self.calls, self._scratch_work, self._scratch_point
        q0, v0, P0 = state.q, state.v, state.P
        calls.derivatives(q0, v0, tau_in)
        psd = self.no_psd if state.d_psd is None else state.d_psd
        P = self._scratch_P
        accel_psd = ekf.gains.accel_psd  # (read at every step: a smoother's replay sets it)
        ddq, ddq_dq, ddq_dv, minv = self._scratch_data
        made = self._layout_cache  # the state's arrays this path's own (__init__)
        own = made is not None and P0 is made[2] and q0 is made[0] and v0 is made[1]
        own = own and psd is self.no_psd
        predict = self._own_predict if own else self.predict
        predict(w, q0, v0, ddq, ddq_dq, ddq_dv, minv, P0, dt, accel_psd, psd, self._scratch_A,
                self._scratch_Phi, P)  # fmt: skip
        aba, stage = calls.aba, self.stage
        stage(w, aba(qs, vs, tau_in), 2, dt)  # RKMK4 (dynamics_rk4), its first stage the
        stage(w, aba(qs, vs, tau_in), 3, dt)  # derivatives call's v̇
        if q_meas is None:  # the fourth stage and P⁻ symmetrised, 0.5 * (P + P.T)
            P = np.empty(self._shape)
            self.coast(w, aba(qs, vs, tau_in), dt, self._scratch_P, P)
            gate, q, v = state.gate.predicted(), qs.copy(), vs.copy()
            self._layout_cache = (q, v, P)
            return _new_tuple(EKFState, (q, v, P, d, state.d_psd, gate, state.auto,
                                         state.psd_scale))  # fmt: skip
        # the fourth stage and the correction (ExtendedKalmanFilter.corrected)
        nv, ex, r = qs.shape[0], self._scratch_ex, ekf.gains.meas_std**2
        q, v, P_new = np.empty(nv), np.empty(nv), np.empty(self._shape)
        d_new = self.no_d if d is None else np.empty(nv)  # (d + dx_d: the kernel's)
        plain = d is None and q_meas.dtype is _F64 and q_meas.strides == self._stride
        finish = self._own_finish if plain else self.finish
        nis = finish(w, aba(qs, vs, tau_in), dt, q_meas, P, r, ex, P_new, q, v,
                     self.no_d if d is None else d, d_new)  # fmt: skip
        if nis != nis:  # NaN: ekf.correct's other ways
            pred = state.moved(qs.copy(), vs.copy(), P, state.gate, d, state.d_psd)
            with np.errstate(over="ignore", invalid="ignore"):
                return ekf.corrected(pred, q_meas, dt)
        gate = state.gate.measured(nis, ekf._gate, nv)
        if gate.gated:
            with np.errstate(over="ignore", invalid="ignore"):
                P = 0.5 * (P + P.T)
                return state.moved(qs.copy(), vs.copy(), P, gate, d, state.d_psd)
        d_psd = state.d_psd
        if d is not None:
            d = d_new  # d + dx[2nv:], the offset's part (dx = ex[nv:]), by the kernel
            if state.auto and d_psd is not None:  # as ekf.corrected
                with np.errstate(over="ignore", invalid="ignore"):
                    s = P.diagonal()[:nv] + r  # Sᵢᵢ = P⁻_qq,ii + σ²
                    d_psd = ekf.matched_density(state, ex[:nv], s, dt)
        self._layout_cache = (q, v, P_new)
        # state.moved's tuple, built here (a Python call less)
        return _new_tuple(EKFState, (q, v, P_new, d, d_psd, gate, state.auto, state.psd_scale))


def update_fused(  # noqa: C901, PLR0912 -- one Python call: the base's tests inline
    obs: ExtendedKalmanFilter, t: Any, q_meas: Any, tau: Any
) -> Estimate | None:
    """A plain :meth:`~pinobs.observers.base.Observer.update` whole, or ``None`` (nothing changed),
    ``ekf``'s ``_update_fused`` (module docstring; by blocks: :func:`update_blocks`).  Taken: no
    offset state, the base's plain case (a float time past the last, no sub-step, pause, latency
    or σ to learn; float64 ``q_meas`` ``(nq,)``, ``tau`` ``(nv,)`` or ``None``, copied unless
    writable of unit stride), the kernels' checks; then ``Observer._update``'s commit."""
    fast, state = obs._fast, obs._state
    if fast is None:
        return update_blocks(obs, t, q_meas, tau)  # (a large robot's: _fused_path)
    if not (
        (type(t) is float or type(t) is np.float64)
        and state is not None
        and state.d is None
        and obs._noise_samples is None
        and not obs._intervals_due
        and not obs._restart_due
        and obs.latency == 0.0
    ):
        return None
    sq, st = fast.shapes
    if q_meas is not None:
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
    # FastPath.step, d None: the same calls on the same arrays (its comments there)
    calls, w, (qs, vs) = fast.calls, fast._scratch_work, fast._scratch_point
    q0, v0, P0, tau_in = state.q, state.v, state.P, obs._tau
    calls.derivatives(q0, v0, tau_in)
    P = fast._scratch_P
    ddq, ddq_dq, ddq_dv, minv = fast._scratch_data
    made = fast._layout_cache
    own = made is not None and P0 is made[2] and q0 is made[0] and v0 is made[1]
    predict = fast._own_predict if own and state.d_psd is None else fast.predict
    predict(w, q0, v0, ddq, ddq_dq, ddq_dv, minv, P0, dt, obs.gains.accel_psd, fast.no_psd,
            fast._scratch_A, fast._scratch_Phi, P)  # fmt: skip
    aba, stage = calls.aba, fast.stage
    stage(w, aba(qs, vs, tau_in), 2, dt)
    stage(w, aba(qs, vs, tau_in), 3, dt)
    nv, gate = fast.nv, state.gate
    q, v, P_new = np.empty(nv), np.empty(nv), np.empty(fast._shape)
    out, held = np.empty(2 * nv), np.empty(nv)
    if q_meas is None:
        if not fast._update_coast(w, aba(qs, vs, tau_in), dt, P, P_new, q, v, tau, fast.bounds,
                                  out, held):  # fmt: skip
            return None
        nis, gate = None, _new_tuple(GateState, (None, False, gate.run, gate.level, gate.drift))
    else:
        nis, lvl = fast._update_finish(w, aba(qs, vs, tau_in), dt, q_meas, P,
                                       obs.gains.meas_std**2, fast._scratch_ex, P_new, q, v,
                                       fast.no_d, fast.no_d, tau, fast.bounds, out, held,
                                       gate.run, float(nv) if gate.level is None else gate.level,
                                       obs._gate)  # fmt: skip
        if lvl != lvl:  # not taken: the base's checks, the gate, or ekf.correct's other ways
            return None
        gate = _new_tuple(GateState, (nis, False, 0, lvl, None))  # (GateState.measured's)
    fast._layout_cache = (q, v, P_new)
    out.setflags(write=False)  # (its views below read-only with it)
    estimate = _new_object(Estimate)  # as Observer._make_estimate
    e = estimate.__dict__
    e["t"], e["q"], e["v"], e["nis"], e["gated"] = x, out[:nv], out[nv:], nis, False
    # the base's commit (Observer._update: no after_commit, σ known, no latency)
    obs._state = _new_tuple(EKFState, (q, v, P_new, None, state.d_psd, gate, state.auto,
                                       state.psd_scale))  # fmt: skip
    obs._t, obs._ts, obs._tau, obs._last, obs._diverged = x, x, held, estimate, False
    if nis is not None:
        obs._nis.append(nis)
    return estimate


def update_blocks(  # noqa: C901, PLR0912 -- one Python call: the base's tests inline
    obs: ExtendedKalmanFilter, t: Any, q_meas: Any, tau: Any
) -> Estimate | None:
    """A plain :meth:`~pinobs.observers.base.Observer.update` with a sample, whole, of a filter
    whose step is :class:`~pinobs.observers.blockstep.BlockStep`'s (Lie-group joints,
    ``nv > KERNEL_MAX_NV``, no offset state), or ``None`` (nothing changed: the base's path
    takes it): the base's plain case (as :func:`update_fused`; a sample, float64 ``(nq,)``,
    any strides), its checks (:func:`inputs_loops`, ``Robot.normalized_units`` on ``q``'s
    copy), the step (the filter's own, under ``np.errstate`` as the base's) on one BLAS thread
    (:func:`~pinobs.observers.blas.one_blas_thread`'s rule, inline: only where the libraries
    are found and all OpenBLAS's own pools), the estimate (:func:`copy_out_loops`) and the
    commit (``Observer._update``'s, no ``after_commit``).  A talos: 15 → 9 Python calls."""
    lie, state = obs._lie_fast, obs._state
    if not (
        (type(t) is float or type(t) is np.float64)
        and type(q_meas) is np.ndarray
        and lie is not None
        and state is not None
        and state.d is None
        and obs._noise_samples is None
        and not obs._intervals_due
        and not obs._restart_due
        and obs.latency == 0.0
    ):
        return None
    b, libs = lie.blocks, found_libraries("scipy.linalg" in sys.modules)
    if b is None or libs is None or libs.others is not None:
        return None
    sq, st = b.shapes
    if not (q_meas.dtype is _F64 and q_meas.shape == sq):
        return None
    if tau is None:
        tau = _EMPTY
    elif not (type(tau) is np.ndarray and tau.dtype is _F64 and tau.shape == st):
        return None
    elif tau.strides != b.stride:
        tau = tau.copy()
    x = float(t)
    dt = x - obs._t
    if not (obs._t + TIME_EPS < x and dt < obs._split and dt <= obs._span):
        return None
    q, held = q_meas.copy(), np.empty(b.nv)  # (the base's copies: C-contiguous)
    if not b.inputs(q, tau, b.bounds, held):
        return None
    if obs._units:  # (check_configuration's last step, as the base's)
        obs.robot.normalized_units(q, what="q_meas")
    lowered = []
    for pool in libs.openblas:  # one_blas_thread, inline
        n = pool.get_threads()
        if n != 1:
            pool.set_threads(1)
            lowered.append((pool, n))
    try:
        new = lie.step(obs, state, dt, q, obs._tau)
    finally:
        for pool, n in lowered:
            pool.set_threads(n)
    nq = sq[0]
    out = np.empty(nq + b.nv)
    if not b.copy_out(new.q, new.v, out):  # a non-finite estimate: the base's path says so
        return None
    out.setflags(write=False)  # (its views below read-only with it)
    gate = new.gate
    estimate = _new_object(Estimate)  # as Observer._make_estimate
    e = estimate.__dict__
    e["t"], e["q"], e["v"], e["nis"], e["gated"] = x, out[:nq], out[nq:], gate.nis, gate.gated
    obs._state = new  # the base's commit (Observer._update: no after_commit)
    obs._t, obs._ts, obs._tau, obs._last, obs._diverged = x, x, held, estimate, False
    if gate.nis is not None:
        obs._nis.append(gate.nis)
        obs._gated += gate.gated
    return estimate
