"""``kalman``'s step in compiled calls around Pinocchio's (issue 39).

:class:`~pinobs.observers.ibrir_kalman.IbrirKalman` on a vector space without joint
friction, ``nv ≤`` :data:`~pinobs.observers.linalg.KERNEL_MAX_NV`, with its default
``velocity_source="estimate"``, ``schedule="measured"`` and no ``viscous`` (the case of its
module docstring's RK4 without :func:`~pinobs.model.lie_rk4`'s bookkeeping): a step was 29
Python calls, its RK4's stacked products and its covariance without a sample NumPy's (BLAS:
the one-BLAS-thread limit around every update, about 7 µs a call in a paced loop), and the
RK4's stage matrices and ``Q_d`` built once per new sample interval (LRU caches on ``dt``: a
clock's timestamps give a new interval at every sample).  Here (:class:`KalmanStep`):

* the RK4 of ``(q, v)`` with ``v̇ = aba(y(s), v, τ)`` on the measured schedule ``y(s)``:
  :func:`~pinobs.observers.fused.rk4_start_loops` and
  :func:`~pinobs.observers.fused.rk4_stage_loops` (the stacked products of
  :func:`pinobs.model.dynamics_rk4`, with ``contract``) between four ``aba`` calls;
  :func:`start_loops` also writes ``y(½)`` and ``y(1)``, :func:`finish_loops` the midpoint's
  ``ẏ = ½(v + v⁺)`` and the innovation;
* ``M`` and ``C`` at the midpoint by Pinocchio (:func:`pinobs.model.integrators.mass_coriolis_calls`);
* the covariance and the correction (:func:`fused_loops`: ``F``, ``Φ``, ``P⁻ = Φ P Φᵀ +
  Q_d``, the Joseph update and the NIS) or, without a sample, the covariance alone
  (:func:`coast_loops`), ``Q_d`` from three numbers.

Six compiled calls around Pinocchio's six, no BLAS call: the observer's ``uses_blas`` is
false.  The same equations; the bits of the RK4 are those of the stacked ``c.dot(b)``
products (OpenBLAS's ``gemm``, as :func:`~pinobs.model.dynamics_rk4` and ``ekf``) where the
NumPy step took ``c[1].dot(b)`` (``gemv``, whose order of summation depends on the CPU's
kernel), and the step without a sample takes ``F`` by the kernel's Cholesky loops where it
took LAPACK's: equal to the NumPy step to rounding (tested to 1e-12).  The kernels are called
without numba's dispatcher (:meth:`~pinobs.observers.linalg.LazyKernel.unchecked`) where their
arrays are the step's own: the stages always, the others where the state is the one the step
returned last (its arrays, by identity) and the sample a float64 array of unit stride (the
same bits, tested; UR5 in a paced 1 kHz loop 4.3 µs less an update, in-process A/B, load 6.4).

A plain update whole in one Python call (:func:`update_fused`, as ``ekf``'s,
:mod:`pinobs.observers.ekf_fused`; 13 → 2 Python calls an update): the step's calls, and two
kernels (:func:`correct_update_loops`, :func:`coast_update_loops`) that end it as
:func:`correct_loops` and :func:`coast_loops` do (called as they are: the same bits) with the
base's checks of the sample and the torque, the gate and the estimate.  UR5 72.5 → 63.3 µs
(16.1 → 14.1 warm ``pin.aba``) in a paced 1 kHz loop (in-process A/B, load 7.0), the same bits.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pinobs.model.integrators import dynamics_calls, mass_coriolis_calls
from pinobs.observers.base import Vector
from pinobs.observers.blas import one_blas_thread
from pinobs.observers.ekf_fused import estimate_out, held_torque
from pinobs.observers.fused import (
    compiled_vector_space,
    loaded,
    rk4_stage_kernel,
    rk4_stage_loops,
    rk4_start_loops,
)
from pinobs.observers.gating import GateState, gate_loops
from pinobs.observers.linalg import LazyKernel, joseph_kernel, transition_kernel
from pinobs.observers.results import Estimate
from pinobs.tolerances import TIME_EPS

__all__ = [
    "KalmanStep",
    "coast_kernel",
    "coast_update_kernel",
    "correct_update_kernel",
    "fused_kernel",
    "update_fused",
]

_new_tuple = tuple.__new__  # the state NamedTuple without its __new__ (a Python call less)
_F64 = np.dtype(np.float64)
_new_object = object.__new__  # an Estimate without its __init__ (as Observer._make_estimate)
_EMPTY = np.zeros(0)  # no torque given (zero held): the kernels' empty τ

# the linalg loops under their own names (LazyKernel's helpers are found by name here)
_joseph_loops = joseph_kernel.fn
_transition_loops = transition_kernel.fn
# the RK4's loops under the names start_loops and finish_loops call them by: compiled on
# their own with contract (LazyKernel's contracted), the bits of fused's kernels
_rk4_start_fma = rk4_start_loops
_rk4_stage_fma = rk4_stage_loops


def covariance_loops(  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    M: Vector, CD: Vector, h: float, P: Vector, q3: float, q2: float, q1: float, Pm: Vector
) -> bool:
    """``F = [[0, I], [0, −M⁻¹ CD]]`` (Ibrir eq. 3, ``CD = C + C_f``, ``M`` read from its upper
    triangle, by Cholesky), ``Φ = transition_matrix(F, h)`` and ``P⁻ = Φ P Φᵀ + Q_d`` into
    ``Pm``, ``Q_d = [[q3 I, q2 I], [q2 I, q1 I]]``.  False (``Pm`` undefined) when ``M`` is
    not positive definite."""
    nv = M.shape[0]
    n = 2 * nv
    L = np.zeros((nv, nv))  # M = L Lᵀ
    for j in range(nv):
        d = M[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, nv):
            t = M[j, i]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]
    F = np.zeros((n, n))
    for c in range(nv):  # column c of M⁻¹ CD: L y = CD[:, c], then Lᵀ x = y
        x = np.empty(nv)
        for i in range(nv):
            t = CD[i, c]
            for k in range(i):
                t -= L[i, k] * x[k]
            x[i] = t / L[i, i]
        for i in range(nv - 1, -1, -1):
            t = x[i]
            for k in range(i + 1, nv):
                t -= L[k, i] * x[k]
            x[i] = t / L[i, i]
        for i in range(nv):
            F[nv + i, nv + c] = -x[i]  # Ibrir eq. (3)
        F[c, nv + c] = 1.0
    Phi = np.empty((n, n))
    _transition_loops(F, h, Phi)
    PhiP = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += Phi[i, k] * P[k, j]
            PhiP[i, j] = t
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += PhiP[i, k] * Phi[j, k]
            q = 0.0
            if i == j:
                q = q3 if i < nv else q1
            elif j == i + nv or i == j + nv:
                q = q2
            Pm[i, j] = t + q
    return True


def fused_loops(
    M: Vector, CD: Vector, h: float, P: Vector, q3: float, q2: float, q1: float, e: Vector,
    r: float, dx: Vector, out: Vector,
) -> float:  # fmt: skip
    """One covariance step of a vector-space robot in one compiled call: :func:`covariance_loops`,
    then ``joseph_update(P⁻, e, r)`` into ``(dx, out)``.  Returns the NIS ``eᵀ S⁻¹ e``, or NaN
    (outputs undefined) when ``M`` or ``S`` is not positive definite."""
    nv = M.shape[0]
    Pm = np.empty((2 * nv, 2 * nv))
    if not covariance_loops(M, CD, h, P, q3, q2, q1, Pm):
        return np.nan
    if not _joseph_loops(Pm, e, r, dx, out):
        return np.nan
    nis = 0.0  # S⁻¹ e = (e − K_q e) / r (ExtendedKalmanFilter.correct)
    for i in range(nv):
        nis += e[i] * (e[i] - dx[i])
    return nis / r


def coast_loops(
    M: Vector, CD: Vector, h: float, P: Vector, q3: float, q2: float, q1: float, out: Vector
) -> bool:
    """A step without a sample: :func:`covariance_loops`, then ``out = ½(P⁻ + P⁻ᵀ)``."""
    n = P.shape[0]
    Pm = np.empty((n, n))
    if not covariance_loops(M, CD, h, P, q3, q2, q1, Pm):
        return False
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.5 * (Pm[i, j] + Pm[j, i])
    return True


def start_loops(
    w: Vector, ys: Vector, q: Vector, v: Vector, acc: Vector, h: float, y0: Vector,
    y_end: Vector, measured: bool,
) -> None:  # fmt: skip
    """The RK4's start (:func:`~pinobs.observers.fused.rk4_start_loops`, ``acc = a₁`` at
    ``y(0) = y0``) and the schedule ``y(s) = y0 + s·dy`` at ``s = ½, 1`` into ``ys[0], ys[1]``:
    ``dy = y_end − y0`` (a sample), else ``h v`` (the prediction's own path)."""
    _rk4_start_fma(w, q, v, acc, h)
    for i in range(q.shape[0]):
        dy = y_end[i] - y0[i] if measured else h * v[i]
        ys[0, i] = y0[i] + 0.5 * dy
        ys[1, i] = y0[i] + dy


def finish_loops(
    w: Vector, ys: Vector, acc: Vector, h: float, v: Vector, q_meas: Vector, measured: bool
) -> None:
    """The RK4's fourth stage (``(q⁻, v⁻)`` into ``w[6], w[7]``), the midpoint's
    ``ẏ = ½(v + v⁻)`` into ``ys[2]`` and, with a sample, ``e = q_meas − q⁻`` into ``ys[3]``."""
    _rk4_stage_fma(w, acc, 4, h)
    for i in range(v.shape[0]):
        ys[2, i] = 0.5 * (v[i] + w[7, i])
        if measured:
            ys[3, i] = q_meas[i] - w[6, i]


def correct_loops(
    M: Vector, CD: Vector, h: float, P: Vector, q3: float, q2: float, q1: float, w: Vector,
    ys: Vector, r: float, dx: Vector, P_new: Vector, q_new: Vector, v_new: Vector,
) -> float:  # fmt: skip
    """:func:`fused_loops` with the innovation ``ys[3]``, then ``q⁺ = q⁻ + dx_q``,
    ``v⁺ = v⁻ + dx_v``; returns the NIS (NaN: the caller takes the NumPy step)."""
    nis = fused_loops(M, CD, h, P, q3, q2, q1, ys[3], r, dx, P_new)
    nv = q_new.shape[0]
    for i in range(nv):
        q_new[i] = w[6, i] + dx[i]
        v_new[i] = w[7, i] + dx[nv + i]
    return nis


def _warm(*shapes: Any) -> tuple[Any, ...]:
    return tuple(np.zeros(s) if isinstance(s, tuple) else s for s in shapes)


_HELPERS = (_transition_loops, _joseph_loops)
# the signatures of the calls (nv = 2 here): M and C as Pinocchio's data holds them, Eigen's
# column-major (Fortran) order, so that the first update finds them loaded
_FORTRAN = np.asfortranarray(np.eye(2)), np.asfortranarray(np.zeros((2, 2)))
_COV = (*_FORTRAN, 1e-3, np.eye(4), 0.0, 0.0, 0.0)
#: :func:`fused_loops` compiled (the general step's, for a vector-space robot).
fused_kernel = LazyKernel(
    fused_loops, *_COV, np.zeros(2), 1.0, np.zeros(4), np.zeros((4, 4)),
    helpers=(*_HELPERS, covariance_loops),
)  # fmt: skip
#: :func:`coast_loops` compiled.
coast_kernel = LazyKernel(
    coast_loops, *_COV, np.zeros((4, 4)), helpers=(*_HELPERS, covariance_loops)
)
#: :func:`correct_loops` compiled.
correct_kernel = LazyKernel(
    correct_loops, *_COV, *_warm((8, 2), (4, 2)), 1.0, *_warm((4,), (4, 4), (2,), (2,)),
    helpers=(*_HELPERS, covariance_loops, fused_loops),
)  # fmt: skip
#: :func:`start_loops` compiled (the RK4's start with ``contract``, the schedule without).
start_kernel = LazyKernel(
    start_loops, *_warm((8, 1), (4, 1), (1,), (1,), (1,)), 1e-3, *_warm((1,), (1,)), True,
    contracted=("_rk4_start_fma",),
)  # fmt: skip
#: :func:`finish_loops` compiled (the RK4's stage with ``contract``, the rest without).
finish_kernel = LazyKernel(
    finish_loops, *_warm((8, 1), (4, 1), (1,)), 1e-3, *_warm((1,), (1,)), True,
    contracted=("_rk4_stage_fma",),
)  # fmt: skip


def correct_update_loops(
    M: Vector, CD: Vector, h: float, P: Vector, q3: float, q2: float, q1: float, w: Vector,
    ys: Vector, r: float, dx: Vector, P_new: Vector, q_new: Vector, v_new: Vector,
    q_meas: Vector, tau: Vector, bounds: Vector, out: Vector, held: Vector, run: int,
    level: float, threshold: float,
) -> tuple[float, float]:  # fmt: skip
    """A plain update's end with a sample (:func:`update_fused`): the base's checks (every
    ``q_meas_i`` finite, the torque by :func:`~pinobs.observers.ekf_fused.held_torque`), the
    step's correction (:func:`correct_loops`, its compiled code called as it is: the same bits),
    the gate (:func:`~pinobs.observers.gating.gate_loops`) and the estimate ``out = (q̂, v̂)``,
    every entry finite (:func:`~pinobs.observers.ekf_fused.estimate_out`).  Returns the NIS and
    the gate's new level; NaN: not taken."""
    for i in range(q_meas.shape[0]):
        if not math.isfinite(q_meas[i]):
            return math.nan, math.nan
    if not held_torque(tau, bounds, held):
        return math.nan, math.nan
    nis = _correct_kernel(M, CD, h, P, q3, q2, q1, w, ys, r, dx, P_new, q_new, v_new)
    if nis != nis:
        return nis, nis
    gated, _, new_level, _, _ = gate_loops(nis, run, level, False, 0.0, True, threshold, q_new.size)
    return nis, estimate_out(q_new, v_new, out, math.nan if gated else new_level)


def coast_update_loops(
    M: Vector, CD: Vector, h: float, P: Vector, q3: float, q2: float, q1: float, P_out: Vector,
    w: Vector, q_new: Vector, v_new: Vector, tau: Vector, bounds: Vector, out: Vector,
    held: Vector,
) -> bool:  # fmt: skip
    """A plain update's end without a sample: the torque's check, the step's covariance
    (:func:`coast_loops`, called as it is), the predicted ``(q⁻, v⁻)`` of ``w`` copied into
    ``(q_new, v_new)`` and the estimate ``out``, every entry finite.  False: not taken."""
    if not held_torque(tau, bounds, held):
        return False
    if not _coast_kernel(M, CD, h, P, q3, q2, q1, P_out):
        return False
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


#: The arguments after the step's: ``q_meas``, ``τ``, the bounds, ``out``, ``held`` (nv = 2).
_TAIL = (np.zeros(2), np.zeros(2), np.ones(2), np.zeros(4), np.zeros(2))
#: :func:`correct_update_loops` compiled (nv = 2, M and C Fortran-ordered as Pinocchio's:
#: ``_COV``; a 1 × 1 array would be typed C-ordered, and the unchecked call read M transposed).
correct_update_kernel = LazyKernel(
    correct_update_loops, *_COV, *_warm((8, 2), (4, 2)), 1.0, *_warm((4,), (4, 4), (2,), (2,)),
    *_TAIL, 0, 1.0, 10.0, helpers=(held_torque, gate_loops, estimate_out),
    linked=(("_correct_kernel", correct_kernel),),
)  # fmt: skip
#: :func:`coast_update_loops` compiled.
coast_update_kernel = LazyKernel(
    coast_update_loops, *_COV, *_warm((4, 4), (8, 2), (2,), (2,)), *_TAIL[1:],
    helpers=(held_torque,), linked=(("_coast_kernel", coast_kernel),),
)  # fmt: skip
#: The step's kernels the update's call: the compiled ones once those are loaded.
_correct_kernel = correct_loops
_coast_kernel = coast_loops


class KalmanStep:
    """:meth:`~pinobs.observers.ibrir_kalman.IbrirKalman.step` in six compiled calls around
    Pinocchio's six (module docstring), on its own ``pin.Data``; the NumPy step (on one BLAS
    thread) where a kernel finds ``M`` or ``S`` not positive definite (a lost filter).  Its
    buffers (``_scratch``) are overwritten by every step, never read across steps."""

    def __init__(self, observer: Any, state_type: type) -> None:
        robot, nv = observer.robot, observer.robot.nv
        self.aba = dynamics_calls(robot).aba
        self._scratch_mc = mass_coriolis_calls(robot)  # (M and C written by every step)
        self._scratch_work = np.zeros((8, nv))  # the RK4's rows (pinobs.observers.fused)
        self._scratch_ys = np.zeros((4, nv))  # y(½), y(1), ẏ at the midpoint, e
        self._scratch_dx = np.empty(2 * nv)
        self._shape = (2 * nv, 2 * nv)
        self.start, self.finish = loaded(start_kernel), loaded(finish_kernel)
        self.correct, self.coast = loaded(correct_kernel), loaded(coast_kernel)
        self._checked = (self.start, self.finish, self.correct, self.coast)
        # without numba's dispatcher (LazyKernel.unchecked; issue 39): the stages on the
        # work rows and aba's output, the others where the state's arrays are this step's own
        # (_layout_cache: the (q, v, P, y_prev) it returned last, y_prev None unless a float64
        # copy; a memo of the layout check, by identity: the bits are the dispatcher's either way)
        # and the sample a float64 array of unit stride; M and C: Pinocchio's views, checked
        self.stage = rk4_stage_kernel.unchecked()
        mc = self._scratch_mc
        views = all(x.dtype == _F64 and x.flags.f_contiguous for x in (mc.M, mc.C))
        kernels = (start_kernel, finish_kernel, correct_kernel, coast_kernel)
        own = tuple(k.unchecked() for k in kernels)
        self._own = own if views else (self.start, self.finish, self.correct, self.coast)
        self._layout_cache: tuple[Any, ...] = (None, None, None, None)
        self._stride = (_F64.itemsize,)  # a contiguous sample's strides
        self.state_type = state_type
        self.general = one_blas_thread(type(observer).general_step)
        # update_fused's: its kernels (unchecked where M and C are as the warm arguments' and
        # the state the step's own, as the others),
        # the torque's bounds (Robot.absurd_torque), the shapes it takes
        self._update_checked = (loaded(correct_update_kernel), loaded(coast_update_kernel))
        own_update = (correct_update_kernel.unchecked(), coast_update_kernel.unchecked())
        self._update_own = own_update if views else self._update_checked
        self.bounds = np.array(robot.absurd_torque, dtype=float)
        self.nv, self.shapes = nv, ((robot.nq,), (nv,))

    @classmethod
    def build(cls, observer: Any, state_type: type) -> KalmanStep | None:
        """The compiled step of ``observer``, or ``None`` where it does not apply (module
        docstring)."""
        r = observer.robot
        if not (
            compiled_vector_space(r)
            and observer.velocity_source == "estimate"
            and observer.schedule == "measured"
            and not observer._viscous
        ):
            return None
        return cls(observer, state_type)

    def step(self, kf: Any, state: Any, dt: float, q_meas: Vector | None, tau: Vector) -> Any:
        """:meth:`~pinobs.observers.ibrir_kalman.IbrirKalman.step` (class docstring)."""
        aba, w, ys, stage = self.aba, self._scratch_work, self._scratch_ys, self.stage
        measured = q_meas is not None
        q0, v0, P0 = state.q, state.v, state.P
        y0 = q0 if not measured or state.y_prev is None else state.y_prev
        y_end = q_meas if measured else y0
        made = self._layout_cache  # the arrays the unchecked kernels may take (__init__)
        own = P0 is made[2] and q0 is made[0] and v0 is made[1] and (y0 is q0 or y0 is made[3])
        plain = q_meas is None or (q_meas.dtype is _F64 and q_meas.strides == self._stride)
        start, finish, correct, coast = self._own if own and plain else self._checked
        vs = w[7]
        start(w, ys, q0, v0, aba(y0, v0, tau), dt, y0, y_end, measured)
        stage(w, aba(ys[0], vs, tau), 2, dt)
        stage(w, aba(ys[0], vs, tau), 3, dt)
        finish(w, ys, aba(ys[1], vs, tau), dt, v0, y_end, measured)
        mc = self._scratch_mc
        mc.crba(ys[0])
        mc.coriolis(ys[0], ys[2])
        g = kf.gains
        psd = g.accel_psd if g.form == "practical" else 0.0  # (IbrirKalman._noise)
        q3, q2, q1 = psd * (dt**3 / 3), psd * (dt**2 / 2), psd * dt
        P = np.empty(self._shape)
        if not measured:
            if not coast(mc.M, mc.C, dt, P0, q3, q2, q1, P):
                return self.general(kf, state, dt, q_meas, tau)
            gate, q, v = state.gate.predicted(), w[6].copy(), vs.copy()
            self._layout_cache = (q, v, P, None)
            return _new_tuple(self.state_type, (q, v, P, None, None, gate))
        nv = ys.shape[1]
        q, v = np.empty(nv), np.empty(nv)
        meas_var = 1.0 / (g.output_weight * dt)
        nis = correct(mc.M, mc.C, dt, P0, q3, q2, q1, w, ys, meas_var, self._scratch_dx, P, q, v)
        if math.isnan(nis):
            return self.general(kf, state, dt, q_meas, tau)
        gate = state.gate.measured(nis, kf._gate, nv)
        if gate.gated:  # used nowhere: the step without it (IbrirKalman.step)
            return self.step(kf, state, dt, None, tau)._replace(gate=gate)
        assert q_meas is not None  # (measured)
        y = q_meas.copy()
        self._layout_cache = (q, v, P, y if plain else None)
        return _new_tuple(self.state_type, (q, v, P, None, y, gate))


def update_fused(  # noqa: C901, PLR0912, PLR0915 -- one Python call: the base's tests inline
    obs: Any, t: Any, q_meas: Any, tau: Any
) -> Estimate | None:
    """A plain :meth:`~pinobs.observers.base.Observer.update` whole, or ``None``, ``kalman``'s
    ``_update_fused``: as ``ekf``'s (:func:`pinobs.observers.ekf_fused.update_fused`, its
    conditions), by :meth:`KalmanStep.step`'s calls on the same arrays."""
    fast, state = obs._fast, obs._state
    if not (
        (type(t) is float or type(t) is np.float64)
        and fast is not None
        and state is not None
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
            q_meas = q_meas.copy()  # (C-contiguous: the unchecked kernels' layout)
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
    # KalmanStep.step: the same calls on the same arrays (its comments there)
    aba, w, ys, stage, tau_in = fast.aba, fast._scratch_work, fast._scratch_ys, fast.stage, obs._tau
    measured = q_meas is not None
    q0, v0, P0 = state.q, state.v, state.P
    y0 = q0 if not measured or state.y_prev is None else state.y_prev
    y_end = q_meas if measured else y0
    made = fast._layout_cache
    own = P0 is made[2] and q0 is made[0] and v0 is made[1] and (y0 is q0 or y0 is made[3])
    (start, finish, _, _), vs = fast._own if own else fast._checked, w[7]
    start(w, ys, q0, v0, aba(y0, v0, tau_in), dt, y0, y_end, measured)
    stage(w, aba(ys[0], vs, tau_in), 2, dt)
    stage(w, aba(ys[0], vs, tau_in), 3, dt)
    finish(w, ys, aba(ys[1], vs, tau_in), dt, v0, y_end, measured)
    mc = fast._scratch_mc
    mc.crba(ys[0])
    mc.coriolis(ys[0], ys[2])
    g, nv, gate = obs.gains, fast.nv, state.gate
    psd = g.accel_psd if g.form == "practical" else 0.0  # (IbrirKalman._noise)
    q3, q2, q1 = psd * (dt**3 / 3), psd * (dt**2 / 2), psd * dt
    q, v, P = np.empty(nv), np.empty(nv), np.empty(fast._shape)
    out, held = np.empty(2 * nv), np.empty(nv)
    correct, coast = fast._update_own if own else fast._update_checked  # (P0: the state's)
    if not measured:
        if not coast(mc.M, mc.C, dt, P0, q3, q2, q1, P, w, q, v, tau, fast.bounds, out, held):
            return None
        nis, y = None, None
        gate = _new_tuple(GateState, (None, False, gate.run, gate.level, gate.drift))
    else:
        nis, lvl = correct(mc.M, mc.C, dt, P0, q3, q2, q1, w, ys, 1.0 / (g.output_weight * dt),
                           fast._scratch_dx, P, q, v, q_meas, tau, fast.bounds, out, held,
                           gate.run, float(nv) if gate.level is None else gate.level,
                           obs._gate)  # fmt: skip
        if lvl != lvl:  # not taken: the base's checks, the gate, or the NumPy step's way
            return None
        gate = _new_tuple(GateState, (nis, False, 0, lvl, None))  # (GateState.measured's)
        y = q_meas.copy()
    fast._layout_cache = (q, v, P, y)
    out.setflags(write=False)  # (its views below read-only with it)
    estimate = _new_object(Estimate)  # as Observer._make_estimate
    e = estimate.__dict__
    e["t"], e["q"], e["v"], e["nis"], e["gated"] = x, out[:nv], out[nv:], nis, False
    # the base's commit (Observer._update: no after_commit, σ known, no latency)
    obs._state = _new_tuple(fast.state_type, (q, v, P, None, y, gate))
    obs._t, obs._ts, obs._tau, obs._last, obs._diverged = x, x, held, estimate, False
    if nis is not None:
        obs._nis.append(nis)
    return estimate
