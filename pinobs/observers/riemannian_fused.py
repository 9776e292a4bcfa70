"""``riemannian``'s plain update in one Python call (issue 39: a paced loop's update).

In a loop paced at 1 kHz every Python call, attribute look-up and temporary array of an
update runs with the caches cold after the wait: on a UR5 ``riemannian``'s update was 13
Python calls around Pinocchio's five (the base's ``update``, ``_update``, ``_inputs``,
``_make_estimate``, the family's ``step`` and ``output``, the step's own and five numba
dispatchers, each typing its arguments), 28× one ``pin.aba`` call where its Pinocchio calls
are about 8.  Here a plain :meth:`~pinobs.observers.base.Observer.update` with the Riccati
schedule (``gain_schedule="riccati"``, constant gains, a :class:`~pinobs.model.Robot` without
joint friction: where :class:`~pinobs.observers.fused.RiccatiStep` or
:class:`~pinobs.observers.fused_lie.LieRiccatiStep` is the step) is one Python call,
:meth:`FusedUpdate.update`, the observer's ``_update_fused`` (3 with the base's ``update`` and
the step it picks): the base's input checks and copies with the RK4's start
(:func:`vector_start_loops`; the RKMK4's first stage: :func:`lie_start_loops`), the step's
operations in the same order on the same buffers, its compiled parts called by their
machine code (:meth:`~pinobs.observers.linalg.LazyKernel.unchecked`: the same code, so the
same bits), the NIS, the outlier gate (:func:`gate_loops`, ``GateState.measured``'s rule),
the correction and the estimate's copy and finiteness check in one kernel
(:func:`vector_finish_loops`; :func:`lie_finish_loops` then ``integrate`` and
:func:`estimate_loops`), and the base's commit.  The gate is decided after the derivatives
call, so a gated sample pays for that call (and a Jacobi operator due) it does not use: the
working memory only, the state is the prediction's as before.  Anything else (a bad input, a
pause, a latency, σ being learnt, a non-finite estimate) is left to the base's own path,
which then does and says what it always did: nothing of the observer changes before the
commit (only working memory).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pinobs.observers.base import GateState, Vector
from pinobs.observers.fused import (
    riccati_correction_kernel,
    riccati_correction_loops,
    rk4_last_kernel,
    rk4_stage_kernel,
    rk4_start_loops,
    rkmk4_stage_loops,
)
from pinobs.observers.fused_lie import (
    lie_riccati_correction_kernel,
    lie_riccati_correction_loops,
    rkmk4_solve_kernel,
)
from pinobs.observers.gating import gate_loops
from pinobs.observers.linalg import LazyKernel
from pinobs.observers.results import Estimate
from pinobs.tolerances import QUATERNION_NORM_TOL, TIME_EPS

__all__ = ["FusedUpdate", "estimate_kernel", "lie_kernels", "vector_kernels"]

_F64 = np.dtype(np.float64)
_new_tuple = tuple.__new__  # a NamedTuple made without its __new__
_new_object = object.__new__  # an Estimate without its __init__ (Observer._make_estimate's)


def inputs_loops(
    q_meas: Vector, measured: bool, tau: Vector, has_tau: bool, bounds: Vector, q_in: Vector,
    tau_out: Vector,
) -> bool:  # fmt: skip
    """The base's checks of an update's inputs (:meth:`~pinobs.observers.base.Observer._inputs`)
    and its copies: ``q_in = q_meas`` (if ``measured``) with every entry finite, ``tau_out = τ``
    (zero without: ``has_tau`` False) with every ``|τ_i| ≤ bounds_i`` (finite; the
    absurd-torque test, joint by joint, as :meth:`~pinobs.observers.base.Observer._check_tau`).
    ``q_meas`` and ``tau`` any 1-D float64 arrays (strided, read-only: only read)."""
    ok = True
    for i in range(q_in.shape[0] if measured else 0):
        x = q_meas[i]
        q_in[i] = x
        ok = ok and math.isfinite(x)
    for i in range(tau_out.shape[0]):
        x = tau[i] if has_tau else 0.0
        tau_out[i] = x
        ok = ok and abs(x) <= bounds[i]  # (NaN: not ≤)
    return ok


def estimate_loops(q: Vector, v: Vector, est: Vector) -> bool:
    """``est = (q, v)`` (the estimate's copy, :meth:`~pinobs.observers.base.Observer._make_estimate`),
    and whether every entry is finite (:meth:`~pinobs.observers.base.Observer._update`'s test)."""
    nq = q.shape[0]
    ok = True
    for i in range(nq):
        est[i] = q[i]
        ok = ok and math.isfinite(q[i])
    for i in range(v.shape[0]):
        est[nq + i] = v[i]
        ok = ok and math.isfinite(v[i])
    return ok


def vector_start_loops(
    q_meas: Vector, measured: bool, tau: Vector, has_tau: bool, bounds: Vector, q_in: Vector,
    tau_out: Vector, w: Vector, q: Vector, v: Vector, acc: Vector, h: float,
) -> bool:  # fmt: skip
    """:func:`inputs_loops`, then (inputs taken) the RK4 step's start
    (:func:`~pinobs.observers.fused.rk4_start_loops`, with ``contract``: its bits)."""
    ok = inputs_loops(q_meas, measured, tau, has_tau, bounds, q_in, tau_out)
    if ok:
        _rk4_start_fma(w, q, v, acc, h)
    return ok


def lie_start_loops(
    q_meas: Vector, measured: bool, tau: Vector, has_tau: bool, bounds: Vector, q_in: Vector,
    tau_out: Vector, w: Vector, v: Vector, acc: Vector, k: Vector, h: float,
) -> bool:  # fmt: skip
    """:func:`inputs_loops`, then (inputs taken) the RKMK4 step's first stage
    (:meth:`~pinobs.observers.fused_lie.LieRK4.predict`: ``w[0] = v``,
    :func:`~pinobs.observers.fused.rkmk4_stage_loops` at stage 1)."""
    ok = inputs_loops(q_meas, measured, tau, has_tau, bounds, q_in, tau_out)
    if ok:
        for i in range(v.shape[0]):
            w[0, i] = v[i]
        rkmk4_stage_loops(w, acc, k, 1, h)
    return ok


def _gate(
    measured: bool, ee: float, p00: float, p01: float, p11: float, qa: float, r2: float,
    h: float, run: int, level: float, level_none: bool, drift: float, drift_none: bool,
    threshold: float, dof: int,
) -> tuple[float, bool, int, float, float, bool]:  # fmt: skip
    """The step's NIS ``|δ|²/S``, ``S = P⁻₀₀ + σ²`` of the schedule (``ee = |δ|²``, NumPy's
    ``delta.dot(delta)``: the caller's), and :func:`gate_loops`; without a sample
    (``measured`` False) NaN and the state's gate (:meth:`~pinobs.observers.gating.GateState.predicted`)."""
    if not measured:
        return math.nan, False, run, level, drift, drift_none
    s_inn = p00 + h * (2.0 * p01 + h * p11 + qa * h * h / 3.0) + r2
    nis = ee / s_inn
    gated, run, level, drift, drift_none = gate_loops(
        nis, run, level, level_none, drift, drift_none, threshold, dof
    )
    return nis, gated, run, level, drift, drift_none


def vector_finish_loops(
    w: Vector, delta: Vector, ee: float, measured: bool, p00: float, p01: float, p11: float,
    qa: float, r2: float, h: float, c: float, run: int, level: float, level_none: bool,
    drift: float, drift_none: bool, threshold: float, acc: Vector, a_q: Vector, a_v: Vector,
    jac: Vector, q_new: Vector, v_new: Vector, est: Vector,
) -> tuple[bool, float, bool, int, float, float, bool, float, float, float]:  # fmt: skip
    """After the RK4's last stage (``(q⁻, v⁻) = (w[6], w[7])``, ``δ = q_meas − q⁻``): the NIS
    and the gate (:func:`_gate`), then the prediction copied into ``(q_new, v_new)`` (no
    sample, or gated) or :func:`~pinobs.observers.fused.riccati_correction_loops` (its
    compiled code, called as it is: the same bits), and the estimate's copy into ``est``
    (:func:`estimate_loops`): ``(finite, nis, gated, run, level, drift, drift is None, P⁺₀₀,
    P⁺₀₁, P⁺₁₁)`` (``P`` as given where not corrected)."""
    nis, gated, run, level, drift, drift_none = _gate(
        measured, ee, p00, p01, p11, qa, r2, h, run, level, level_none, drift, drift_none,
        threshold, delta.shape[0],
    )  # fmt: skip
    if measured and not gated:
        p00, p01, p11 = _riccati_correction(
            w[6], w[7], acc, a_q, a_v, delta, jac, p00, p01, p11, qa, r2, h, c, q_new, v_new
        )
    else:
        for i in range(q_new.shape[0]):
            q_new[i] = w[6, i]
            v_new[i] = w[7, i]
    ok = _estimate(q_new, v_new, est)
    return ok, nis, gated, run, level, drift, drift_none, p00, p01, p11


def lie_finish_loops(
    w: Vector, delta: Vector, ee: float, measured: bool, p00: float, p01: float, p11: float,
    qa: float, r2: float, h: float, c: float, run: int, level: float, level_none: bool,
    drift: float, drift_none: bool, threshold: float, acc: Vector, a_q: Vector, a_v: Vector,
    jac: Vector, table: Any, work: Vector, v_new: Vector,
) -> tuple[float, bool, int, float, float, bool, float, float, float]:  # fmt: skip
    """After the RKMK4 (``v⁻ = w[9]``, ``δ = difference(q⁻, q_meas)``): the NIS and the gate
    (:func:`_gate`), then ``v_new = v⁻`` (no sample, or gated) or
    :func:`~pinobs.observers.fused_lie.lie_riccati_correction_loops` (its compiled code: the
    same bits; the step ``−k₁ζ`` in ``work[3]``, for the caller's ``integrate``): ``(nis,
    gated, run, level, drift, drift is None, P⁺₀₀, P⁺₀₁, P⁺₁₁)``."""
    nis, gated, run, level, drift, drift_none = _gate(
        measured, ee, p00, p01, p11, qa, r2, h, run, level, level_none, drift, drift_none,
        threshold, delta.shape[0],
    )  # fmt: skip
    if measured and not gated:
        p00, p01, p11 = _lie_correction(
            w[9], acc, a_q, a_v, delta, jac, p00, p01, p11, qa, r2, h, c, table, work, v_new
        )
    else:
        for i in range(v_new.shape[0]):
            v_new[i] = w[9, i]
    return nis, gated, run, level, drift, drift_none, p00, p01, p11


class FusedUpdate:
    """A ``riemannian`` observer's plain update with the Riccati schedule in one Python call
    (module docstring): :meth:`update` is its ``_update_fused``.  Built where its step is
    :class:`~pinobs.observers.fused.RiccatiStep` or
    :class:`~pinobs.observers.fused_lie.LieRiccatiStep`, on that step's calls, work rows and
    ``pin.Data``; ``_scratch*`` are overwritten by every update."""

    def __init__(self, obs: Any, state_type: type) -> None:
        step, robot = obs._scratch_fast, obs.robot
        self.obs, self.state_type, self.lie = obs, state_type, bool(obs._lie)
        self.nq, self.nv = nq, nv = robot.nq, robot.nv
        self.shapes = ((nq,), (nv,))
        self.bounds = np.array(robot.absurd_torque, dtype=float)
        self.units = tuple(robot._unit_slices) if self.lie else ()
        self._scratch_q, self._scratch_zero = np.zeros(nq), np.zeros(nv)  # the sample's copy
        self.ddq, self.ddq_dq, self.ddq_dv = step.ddq, step.ddq_dq, step.ddq_dv
        self.derivatives, self.threshold, self.zero = step.derivatives, obs._gate, obs._zero_nn
        self.c, self.every = obs.gains.curvature_gain, obs.curvature_every
        if self.lie:  # LieRiccatiStep's parts (its LieRK4's)
            rk = step.rk4
            self.aba, self.integrate, self.difference = rk.calls.aba, rk.integrate, step.difference
            self.w, self.point, self.jexp = rk._scratch_work, rk._scratch_point, rk._scratch_jexp
            self.blocks, self.table, self.k = rk._scratch_blocks, rk.table, rk._scratch_k
            self.rk_units, self.solve = rk.units, rkmk4_solve_kernel.unchecked()
            self.bracket_table, self._scratch_work = step.table, step._scratch_work
            self.start, self.finish = (kernel.unchecked() for kernel in lie_kernels)
            self.estimate = estimate_kernel.unchecked()
        else:  # RiccatiStep's
            self.aba, self.w, self.point = step.aba, step.w, step.point
            self.stage, self.last = rk4_stage_kernel.unchecked(), rk4_last_kernel.unchecked()
            self._scratch_delta = step._scratch_delta
            self.start, self.finish = (kernel.unchecked() for kernel in vector_kernels)
        self.step = self._lie_step if self.lie else self._vector_step  # (bound once)

    def update(self, t: float, q_meas: Any, tau: Any) -> Estimate | None:
        """:meth:`~pinobs.observers.base.Observer.update` of the observer, or ``None`` (nothing
        changed: the base's own path takes it).  Taken: ``t`` a ``float`` (or NumPy's) after
        the previous time by more than ``TIME_EPS`` and before the sub-step and pause limits,
        ``q_meas`` ``None`` or a float64 array of shape ``(nq,)`` (any strides), ``tau`` ``None``
        or a float64 ``(nv,)``, σ known, the period known, no latency, no pause due, a state
        with the schedule's ``P``, and what :func:`inputs_loops` and the finiteness checks
        ask."""
        obs = self.obs
        state = obs._state
        if not (
            (type(t) is float or type(t) is np.float64)
            and (
                q_meas is None
                or (
                    type(q_meas) is np.ndarray
                    and q_meas.dtype is _F64
                    and q_meas.shape == self.shapes[0]
                )
            )
            and (
                tau is None
                or (type(tau) is np.ndarray and tau.dtype is _F64 and tau.shape == self.shapes[1])
            )
            and state is not None
            and state.P is not None
            and obs._noise_samples is None
            and not obs._intervals_due
            and not obs._restart_due
            and obs.latency == 0.0
        ):
            return None
        x, t_prev = float(t), obs._t
        dt = x - t_prev
        if not (t_prev + TIME_EPS < x and dt < obs._split and dt <= obs._span):
            return None
        made = self.step(obs, state, dt, q_meas, tau)
        if made is None:  # a bad input or a non-finite estimate: the base's path says so
            return None
        new, est, tau_new = made  # the base's commit (Observer._update: no after_commit)
        gate = new[6]
        est.setflags(write=False)
        estimate = _new_object(Estimate)  # as Observer._make_estimate
        d = estimate.__dict__
        nq = self.nq
        d["t"], d["q"], d["v"], d["nis"], d["gated"] = x, est[:nq], est[nq:], gate.nis, gate.gated
        obs._state = _new_tuple(self.state_type, new)
        obs._t, obs._ts, obs._tau, obs._last, obs._diverged = x, x, tau_new, estimate, False
        if gate.nis is not None:
            obs._nis.append(gate.nis)
            obs._gated += gate.gated
        return estimate

    def _vector_step(
        self, obs: Any, state: Any, dt: float, q_meas: Any, tau: Any
    ) -> tuple[tuple[Any, ...], Vector, Vector] | None:
        """:class:`~pinobs.observers.fused.RiccatiStep`'s step (with a sample) or the base
        step's prediction (without), the inputs checked and copied first: the new state's
        fields, the estimate ``(q̂, v̂)`` and the torque held from now, or ``None``."""
        aba, w, stage, tau_old, nv = self.aba, self.w, self.stage, obs._tau, self.nv
        q, v = self.point
        q_in, delta, measured = self._scratch_q, self._scratch_delta, q_meas is not None
        tau_new = np.empty(nv)
        if not self.start(
            q_meas if measured else q_in, measured, tau_new if tau is None else tau,
            tau is not None, self.bounds, q_in, tau_new, w, state.q, state.v,
            aba(state.q, state.v, tau_old), dt,
        ):  # fmt: skip
            return None
        stage(w, aba(q, v, tau_old), 2, dt)
        stage(w, aba(q, v, tau_old), 3, dt)
        h, g, jac, age = state.elapsed + dt, state.gate, state.jacobi, state.age
        if measured:
            self.last(w, aba(q, v, tau_old), dt, q_in, delta)
            ee = float(delta.dot(delta))  # (NumPy's, as the step's)
            c, age = self.c, age + 1
            if c != 0.0 and (jac is None or age >= self.every):  # due (RiemannianObserver._jacobi)
                calls = obs._scratch_jacobi  # (computed if gated too: not kept then)
                jac, age = obs._jacobi(state, q, v, c) if calls is None else (calls(q, v), 0)
            self.derivatives(q, delta, tau_old)  # (RiemannianObserver._jacobians)
        else:
            stage(w, aba(q, v, tau_old), 4, dt)
            ee = 0.0
        level, drift = g.level, g.drift
        q_new, v_new, est = np.empty(nv), np.empty(nv), np.empty(2 * nv)
        ok, nis, gated, run, level1, drift1, drift_none, p00, p01, p11 = self.finish(
            w, delta, ee, measured, *state.P, obs.accel_psd, obs._sigma2, h, self.c, g.run,
            0.0 if level is None else level, level is None, 0.0 if drift is None else drift,
            drift is None, self.threshold, self.ddq, self.ddq_dq, self.ddq_dv,
            self.zero if jac is None else jac, q_new, v_new, est,
        )  # fmt: skip
        if not ok:
            return None
        if not measured:  # GateState.predicted()
            gate = _new_tuple(GateState, (None, False, g.run, level, drift))
            return (q_new, v_new, h, state.jacobi, state.age, state.P, gate), est, tau_new
        gate = _new_tuple(GateState, (nis, gated, run, level1, None if drift_none else drift1))
        if gated:
            return (q_new, v_new, h, state.jacobi, state.age, state.P, gate), est, tau_new
        return (q_new, v_new, 0.0, jac, age, (p00, p01, p11), gate), est, tau_new

    def _lie_step(  # noqa: C901, PLR0912 -- the whole step inline: one Python call (issue 39)
        self, obs: Any, state: Any, dt: float, q_meas: Any, tau: Any
    ) -> tuple[tuple[Any, ...], Vector, Vector] | None:
        """:class:`~pinobs.observers.fused_lie.LieRiccatiStep`'s step (its RKMK4,
        :meth:`~pinobs.observers.fused_lie.LieRK4.predict`, inline), the inputs checked,
        copied and normalised first (:meth:`~pinobs.model.Robot.normalized_units`, as the
        base's): the new state's fields, the estimate ``(q̂, v̂)`` and the torque held from now,
        or ``None``."""
        aba, w, integrate, solve, tau_old = self.aba, self.w, self.integrate, self.solve, obs._tau
        jexp, table, k, nv = self.jexp, self.table, self.k, self.nv
        xi, vs = self.point
        q0, q_in, measured = state.q, self._scratch_q, q_meas is not None
        tau_new = np.empty(nv)
        if not self.start(
            q_meas if measured else q_in, measured, tau_new if tau is None else tau,
            tau is not None, self.bounds, q_in, tau_new, w, state.v,
            aba(q0, state.v, tau_old), k, dt,
        ):  # fmt: skip
            return None
        for s in self.units if measured else ():  # Robot.normalized_units, as the base's _inputs
            b = q_in[s]
            norm = math.sqrt(float(b.dot(b)))
            if abs(norm - 1.0) > QUATERNION_NORM_TOL:
                return None
            b /= norm
        for i in (2, 3, 4):
            acc = aba(integrate(q0, xi), vs, tau_old)
            for block, fn, s in self.blocks:  # J_r(ξ)'s blocks (Robot.integrate_jacobian_solve)
                block[...] = fn(xi[s])
            solve(w, acc, jexp, table, k, i, dt)
        q = integrate(q0, xi)
        for s in self.rk_units:  # Robot.normalize, in place on the fresh array
            b = q[s]
            b /= math.sqrt(b.dot(b))
        h, g, jac, age, ee, delta = (
            state.elapsed + dt,
            state.gate,
            state.jacobi,
            state.age,
            0.0,
            self._scratch_zero,
        )
        if measured:
            delta = self.difference(q, q_in)
            ee = float(delta.dot(delta))  # (NumPy's, as the step's)
            c, age = self.c, age + 1
            if c != 0.0 and (jac is None or age >= self.every):  # due (RiemannianObserver._jacobi)
                calls = obs._scratch_jacobi  # (computed if gated too: not kept then)
                jac, age = obs._jacobi(state, q, vs, c) if calls is None else (calls(q, vs), 0)
            self.derivatives(q, delta, tau_old)  # (RiemannianObserver._jacobians)
        level, drift, work, v_new = g.level, g.drift, self._scratch_work, np.empty(nv)
        nis, gated, run, level1, drift1, drift_none, p00, p01, p11 = self.finish(
            w, delta, ee, measured, *state.P, obs.accel_psd, obs._sigma2, h, self.c, g.run,
            0.0 if level is None else level, level is None, 0.0 if drift is None else drift,
            drift is None, self.threshold, self.ddq, self.ddq_dq, self.ddq_dv,
            self.zero if jac is None else jac, self.bracket_table, work, v_new,
        )  # fmt: skip
        corrected = measured and not gated
        if corrected:  # q̂⁻ ⊕ (−k₁ζ), normalised in place
            q = integrate(q, work[3])
            for s in self.rk_units:
                b = q[s]
                b /= math.sqrt(b.dot(b))
        est = np.empty(self.nq + nv)
        if not self.estimate(q, v_new, est):
            return None
        if not measured:  # GateState.predicted()
            gate = _new_tuple(GateState, (None, False, g.run, level, drift))
        else:
            gate = _new_tuple(GateState, (nis, gated, run, level1, None if drift_none else drift1))
        if not corrected:
            return (q, v_new, h, state.jacobi, state.age, state.P, gate), est, tau_new
        return (q, v_new, 0.0, jac, age, (p00, p01, p11), gate), est, tau_new


def _warm_start(lie: bool) -> tuple[object, ...]:
    """The start kernels' arguments: the sample and torque any 1-D float64 arrays (``A``
    layout: strided), the rest the step's own C arrays."""
    one, strided = np.zeros(1), np.zeros(4)[::2]
    rows = np.zeros((10, 1)) if lie else np.zeros((8, 1))
    inputs = (strided, True, strided, True, np.ones(1), np.zeros(2), np.zeros(1), rows)
    return (*inputs, one, one, one, 1e-3)  # (q, v, a₁ or v, a₁, k; h)


def _warm_finish(lie: bool) -> tuple[object, ...]:
    one, two = np.zeros(1), np.zeros((1, 1))
    scalars = (0.0, True, *(1.0,) * 7, 0, 1.0, True, 0.0, True, 1.0)
    if lie:
        table = np.zeros((0, 2), dtype=np.int64)
        return (np.zeros((10, 1)), one, *scalars, one, two, two, two, table, np.zeros((5, 1)), one)
    return (np.zeros((8, 1)), one, *scalars, one, two, two, two, one, one, np.zeros(2))


#: :func:`estimate_loops` compiled: ``(q, v, est) -> finite``.
estimate_kernel = LazyKernel(estimate_loops, np.zeros(1), np.zeros(1), np.zeros(2))
#: :func:`vector_start_loops` and :func:`vector_finish_loops` compiled (the RK4's start with
#: ``contract``, on its own; :data:`~pinobs.observers.fused.riccati_correction_kernel`'s code
#: called as it is).
vector_kernels = (
    LazyKernel(
        vector_start_loops, *_warm_start(False), helpers=(inputs_loops,),
        contracted=("_rk4_start_fma",),
    ),
    LazyKernel(
        vector_finish_loops, *_warm_finish(False), helpers=(gate_loops, _gate),
        linked=(("_riccati_correction", riccati_correction_kernel), ("_estimate", estimate_kernel)),
    ),
)  # fmt: skip
#: :func:`lie_start_loops` and :func:`lie_finish_loops` compiled (no contraction: the RKMK4's
#: bits; :data:`~pinobs.observers.fused_lie.lie_riccati_correction_kernel`'s code called as it is).
lie_kernels = (
    LazyKernel(lie_start_loops, *_warm_start(True), helpers=(inputs_loops, rkmk4_stage_loops)),
    LazyKernel(
        lie_finish_loops, *_warm_finish(True), helpers=(gate_loops, _gate),
        linked=(("_lie_correction", lie_riccati_correction_kernel),),
    ),
)  # fmt: skip
#: The functions the kernels call, under the names they call them by: compiled ones once they
#: load (``LazyKernel``'s ``helpers``, ``contracted`` and ``linked``).
_rk4_start_fma = rk4_start_loops
_riccati_correction = riccati_correction_loops
_lie_correction = lie_riccati_correction_loops
_estimate = estimate_loops
