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
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pinobs.model.integrators import dynamics_calls, mass_coriolis_calls
from pinobs.observers.base import Vector
from pinobs.observers.blas import one_blas_thread
from pinobs.observers.fused import (
    compiled_vector_space,
    loaded,
    rk4_stage_kernel,
    rk4_stage_loops,
    rk4_start_loops,
)
from pinobs.observers.linalg import LazyKernel, joseph_kernel, transition_kernel

__all__ = ["KalmanStep", "coast_kernel", "fused_kernel"]

_new_tuple = tuple.__new__  # the state NamedTuple without its __new__ (a Python call less)
_F64 = np.dtype(np.float64)

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
