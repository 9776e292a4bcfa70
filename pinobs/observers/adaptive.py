"""Adaptive EKF: learns the robot's dynamics online and never falls behind a model-free filter.

Three parts, each on code shared with the rest of pinobs:

1. **The filter** is an :class:`~pinobs.observers.ekf.ExtendedKalmanFilter`
   (``AdaptiveEKF.core``, held, not inherited: driven through its public
   ``initial_state``, ``step`` and ``replace_robot``) with
   its joint-torque offset state ``d`` (``disturbance_psd``), run on the
   current learned model ``θ̂`` and the learned torque offset ``b̂``::

       v̇ = M_θ̂⁻¹(q)(τ + b̂ + d + τ_f,θ̂(v) − c_θ̂(q, v) − g_θ̂(q)),   ḋ = w_d.

   The two noise densities (white acceleration ``q_w``, offset ``q_d``, the
   latter scaled per joint by ``M̄ᵢᵢ²`` as in ``ekf``) follow three regimes:

   * ``warmup`` until the first solve: ``warmup_accel_psd`` = 1e-2 and
     ``disturbance_psd`` = 1 (the nominal model is not trusted yet);
   * ``nominal`` when a solve finds nothing better than the nominal model
     (model selection, below): the exact-model densities of ``ekf``
     (``validated_*`` = 1e-8);
   * ``learned`` once a learned model is installed: ``accel_psd`` = 1e-6 and
     ``learned_disturbance_psd`` = 1e-4 (a learned model is good, not exact).

   These defaults were chosen on UR5, cart-pole and planar_3r runs
   (``benchmarks/learning.py`` reports Panda and z1 as well).

   Learned friction goes where it costs least.  A joint friction that cannot
   make the prediction stiff, ``λᵢ h ≤ 0.1`` with ``λᵢ = max (M_θ̂⁻¹)ᵢᵢ
   |∂τ_f,ᵢ/∂v|`` over the configurations the consistency check sampled (the
   slope peaks at ``v = 0``), is a torque held over each step, evaluated at
   the mid-step velocity extrapolated from the last step,
   ``τ_f,θ̂(v̂ + (h/2)(v̂ − v̂₋)/h₋)`` (second order; for a linear friction a
   two-step Adams–Bashforth step, stable for ``λh < 1``), and left out of the
   filter's model; stiffer friction stays in the model, where ``ekf``'s
   stiff-friction path (substeps, ``exp(Ah)`` by squaring) handles it at
   about 17 ``pin.aba`` calls more per update on a UR5 (measured on a loaded
   machine: ``ekf`` with the offset state, 45 against 28).  The covariance of a
   held friction misses its slope ``−M⁻¹ ∂τ_f/∂v``, at most ``0.1/h`` [1/s].

2. **The identification** (:mod:`pinobs.model.identification`, the same
   machinery as ``pinobs identify``): every committed sample joins a buffer;
   each ``window`` seconds of data (plus the half-width of the zero-phase
   smoother, so velocities are centred fits) give ``nv`` momentum-form rows

       [Y_M(q₂,v₂) − Y_M(q₁,v₁) − ∫Y_G dt] π + D∫v + F_c∫tanh(v/v_s) − b Δt = ∫τ dt     (MATH §9)

   kept for the last ``horizon`` seconds (the integrals by trapezoids of
   4 ms; the smoother's edge fits are skipped: only samples ``half_window``
   inside what it smooths are kept).  Every ``resolve_every`` seconds
   the rows are solved (nominal prior, robust reweighting; identifiable
   base parameters by pivoted QR, the regressor's condition number
   reported).  A friction coefficient within 3σ of its nominal value (zero
   for a URDF without friction) is kept nominal: friction the data do not
   show would cost every prediction (above).  A solve is installed only if the learned masses are positive
   and ``M_θ̂(q) ≻ 0`` at configurations sampled from the buffer (otherwise
   the last model is kept and :meth:`consistency` says so), and only if it
   explains the rows better than the current model by more than fitting
   noise would: the robust (Huber) loss must drop by more than
   ``r + 3√r`` (``r`` the number of identifiable combinations; the expected
   drop from fitting pure noise is ``r/2``), and only if the filter's
   innovations say the current model does not explain the data (running
   mean NIS above twice its expectation; a model that explains the data is
   not replaced: velocities smoothed from the samples carry a bias that a
   fit would otherwise chase).  Trust in the nominal model is revoked at
   once, between solves, when the running NIS exceeds ten times its
   expectation: the latest solve is installed (or the warm-up resumes).  When a model is
   installed the offset state ``d`` is set to zero (the new model explains
   what it was absorbing).  A trajectory that does not excite a parameter
   cannot teach it: such parameters stay at their nominal values
   (:meth:`parameters` marks them).

3. **Never behind** (and never lost: should the model-based filter's estimate
   or covariance stop being finite, it restarts on the model-free estimate
   in the warm-up regime, and :meth:`consistency` counts it; if the restarted
   filter is lost at once, the learned model itself does not hold and is
   dropped for the nominal one (said in ``rejected``); the blend then
   starts from ``s = v0_std²`` and blames the model fully until a solve
   replaces it): a bank of per-joint constant-acceleration Kalman filters
   (:class:`~pinobs.observers.kf.ConstantAccelerationKF`, white-jerk
   densities ``jerk_psd`` = 1e-2 … 1e5, :data:`JERK_PSD`: from a real arm logged at
   100 Hz through 4-digit encoders to a simulated one at 1 kHz)
   runs beside it; per velocity coordinate the one with the smallest running
   mean squared innovation (the one-step prediction error, which the best
   model minimises; averaged over ``blend_time``) is the model-free estimate
   ``v̂_kf``, and its covariance gives its variance ``P_kf``.  The
   model-based error variance is estimated from the recent disagreement
   ``e = v̂_model − v̂_kf``,
   ``s_i ← s_i + (h/T_b)(max(e_i² − P_kf, 0) − s_i)`` (``T_b`` = ``blend_time``),
   and the output is the inverse-variance blend

       v̂ = w v̂_model + (1 − w) v̂_kf,   w = P_kf / (P_kf + s),

   (``q̂`` likewise, in the tangent space at ``q̂_model``).  The ``kf``'s own
   variance understates its error (its white-jerk model is wrong too), so
   the disagreement is blamed on the model only as far as the model-based
   filter's innovations say it is inconsistent: the target of ``s`` is
   multiplied by ``clip((NIS̄/nv − 2)/2, 0, 1)`` (``NIS̄`` the running mean of
   the normalized innovation squared).  With an exact model ``w = 1``; with
   a wrong one the innovations grow and ``w → 0``.  On robots whose joints
   are all vector joints the bank and the blend are compiled loops (numba;
   in NumPy the bank alone cost about 15 ``pin.aba`` calls per update on a
   UR5),
   tested equal to the NumPy path that Lie-group robots take.

Learning happens only from samples the base class has committed
(:meth:`Observer.after_commit`), so a rejected update, a gated outlier or
a prediction that is not kept (under a known latency) teaches nothing.

4. **Off the loop** (``learning="background"``; issue 39).  Synchronous (the
   default, for offline replays: :func:`pinobs.estimate`, smoothing, the
   benchmarks), the rows of each window and each solve run inside the
   ``update`` that completes them: on a UR5 at 1 kHz 1.2–1.6 ms every 0.1 s
   (``smooth_path`` 0.3 ms, the regressor 0.7 ms) and 4–9 ms every 0.5 s
   (the solve), measured on a loaded 2-core machine.  In the background
   they run in a worker process (:class:`~pinobs.observers.worker.Worker`:
   not a thread, whose Python and Pinocchio calls hold the GIL the loop
   waits for — the window rows hold it nearly throughout; measured in that
   module's docstring).  The update only does the bookkeeping (the buffer,
   the interval, when to solve) and sends a window's samples or a solve's
   inputs (the current model, the configurations to check ``M(q) ≻ 0`` at);
   it never waits: a result is taken at the first update after it is done,
   in order, and changes the learner as it would have synchronously (a
   late solve is used late: installed then, compared with the model that
   was current when it was asked for).  One solve at a time: while one is
   out, the next is asked for when it is back.  Given the time to finish
   before each result is taken (the test hook ``_Learner.join``), the
   output equals the synchronous one (tested to 1e-12: it is bit-identical);
   fed as fast as it runs, a UR5 with a payload made the same number of
   solves or one fewer, its velocity RMS within ±10 % of the synchronous
   one.  The SciPy modules the learner uses are imported when the observer
   is made (the first window's update took 0.5 s importing them).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
from collections import deque
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import (
    GainError,
    IdentificationError,
    ObserverDiverged,
    OptionError,
    UnsupportedRobotError,
)
from pinobs.model import Robot
from pinobs.model.identification import (
    MAX_FILL,
    MomentumRegressor,
    ParameterSet,
    smooth_path,
    solve,
)
from pinobs.observers.base import (
    LIKELY_CAUSES,
    Consistency,
    Observer,
    Vector,
    positive,
    register,
)
from pinobs.observers.blas import blas_libraries, one_blas_thread
from pinobs.observers.ekf import EKFState, ExtendedKalmanFilter
from pinobs.observers.kf import BankState, KFBank
from pinobs.observers.linalg import LazyKernel
from pinobs.observers.worker import Worker
from pinobs.tolerances import TIME_EPS

__all__ = ["AdaptiveEKF", "ModelSnapshot"]


class ModelSnapshot(NamedTuple):
    """The model-based filter's model as it stands (for :func:`pinobs.smooth`, which freezes it).

    Attributes:
        robot: the learned model (the nominal one before any install), a copy.
        offset: the learned joint-torque offset added to ``tau`` [N·m or N].
        regime: ``"warmup"``, ``"nominal"`` or ``"learned"`` (module docstring).
        accel_psd: that regime's white-acceleration density [rad²/s³].
        disturbance_psd: that regime's offset density per joint, ``psd · M̄ᵢᵢ²`` [N²·m²/s].
    """

    robot: Robot
    offset: Vector
    regime: str
    accel_psd: float
    disturbance_psd: Vector


class _State(NamedTuple):
    ekf: EKFState
    kf: BankState  # one filter per white-jerk density of the bank
    score: Vector  # (filters, nv): running mean squared innovation of each kf per coordinate
    t: float
    s: Vector  # estimated model-based velocity error variance per coordinate [rad²/s²]
    q: Vector  # blended output
    v: Vector
    v_prev: Vector  # the EKF's v̂ at the start of the last step (held friction, _torque)
    dt_prev: float  # that step [s] (0: none yet)


class _Learner:
    """Sliding-window momentum-form identification fed one committed sample at a time.

    The bookkeeping (the buffer, the interval, when to solve, what a solve changes) runs on
    the loop; the rows of each window and the solves (:class:`_Identifier`) run on the loop
    too, or, given a ``worker``, in its process (``learning="background"``), their results
    taken at the first update after they are done (:meth:`collect`)."""

    #: Test hook: :meth:`collect` waits for every job asked for (background learning then
    #: gives what synchronous learning gives).
    join = False

    def __init__(
        self,
        robot: Robot,
        *,
        window: float,
        half_window: float,
        horizon: float,
        resolve_every: float,
        friction: bool,
        offset: bool,
        rate: float | None,
        worker: Worker | None = None,
    ) -> None:
        self.reg = MomentumRegressor(robot, friction=friction, offset=offset)
        self.nominal = self.reg.nominal()
        # the costly part: here (synchronous) or in the worker process (background)
        self.identifier = _Identifier(self.reg, max(1, round(horizon / window)))
        self.worker = worker  # None: synchronous (every job run in add)
        self.key = next(_KEYS)  # this learner's identifier in the worker process
        self.row_count = 0  # rows kept, as of the last window taken
        # the jobs asked for and not yet taken, in order: (job, (explained, current) of a solve)
        self.pending: deque[tuple[Any, tuple[bool, Vector] | None]] = deque()
        self.windows = 0  # windows of rows asked for (at most the rows kept)
        self.solving = False  # a solve is pending
        self.window, self.half_window = window, half_window
        self.rate_given = rate
        self.h = math.nan  # the sample interval: 1/rate, or the first one seen (_interval)
        if rate is not None:
            self._counts(1.0 / rate)
        self.buf: deque[tuple[float, Vector, Vector]] = deque()
        self.resolve_every = resolve_every
        # the first solve resolve_every after the reset, wherever the clock starts (:meth:`start`;
        # it was at t = resolve_every: a clock 100 s behind never solved, 3 s behind, 3.5 s late)
        self.next_solve = math.nan
        self._off_run: list[float] = []  # the latest consecutive update intervals off h
        self._t_last: float | None = None  # the latest update's time (committed or not)
        self.theta: Vector | None = None
        self.std: Vector | None = None
        self.excited: NDArray[np.bool_] | None = None
        self.condition = np.nan
        self.rank = 0
        self.solves = 0
        self.installs = 0
        self.validated = False  # a solve has checked the current model against the data
        self.last_drop = np.nan
        self.history: list[tuple[float, float]] = []
        self.candidate: Vector | None = None  # the latest consistent solve
        self.minv_max: Vector = np.zeros(robot.nv)  # its largest (M⁻¹)ᵢᵢ at the checked q
        self.rejected: deque[str] = deque(maxlen=_REJECTED_KEPT)  # the latest, said in details
        self.rejected_run = 0  # consecutive solves rejected (not physical, or failed)
        # (t, τ, gated) of the updates without a sample since the last one
        self._lost: list[tuple[float, Vector, bool]] = []

    def add(
        self,
        t: float,
        q: Vector | None,
        tau: Vector,
        *,
        explained: bool = False,
        gated: bool = False,
    ) -> bool:
        """Add the sample ``q`` taken at ``t`` and the torque ``tau`` applied from ``t`` on
        (``q`` None: no sample, nothing added); returns True when a new model was solved for.
        ``explained``: the filter's innovations say the current model explains the data
        (then a solve only validates it); ``gated``: ``q`` None because the filter's gate
        rejected the sample (not filled: :meth:`_fill`)."""
        if self._t_last is not None:  # the stream's interval, from every update's time
            dt = t - self._t_last  # (a gated or lost sample is not a slower stream)
            if math.isnan(self.h):
                self._counts(dt)  # no rate given: the stream's own interval
            elif abs(dt - self.h) > _GAP_FRACTION * self.h:
                self._off_run.append(dt)
                if len(self._off_run) == _INTERVAL_CHECK:
                    self._interval(self._off_run)
                    self._off_run = []
            else:
                self._off_run = []
        self._t_last = t
        if q is None:
            if self.buf:
                self._lost.append((t, tau, gated))
            return self.collect()  # a lost sample shows as a gap in the times below
        # a gap (a lost sample: 2h) or a doubled sample: windows never straddle one, unless
        # it is at most MAX_FILL lost samples, which are interpolated (_fill).  Jitter is not
        # a gap: the rows integrate over the samples' own times (MATH §9); at ±0.1 h this
        # test cleared the windows at every other sample and the learner never solved,
        # silently (a sweep found it, and a 500 Hz stream without rate)
        if self.buf and abs(t - self.buf[-1][0] - self.h) > _GAP_FRACTION * self.h:
            if not self._fill(t, q):
                self.buf.clear()
        self._lost = []
        self.buf.append((t, q, tau))
        if math.isnan(self.h):
            return self.collect()  # one sample: no interval yet
        need = self.win + 2 * self.hw + 1
        while len(self.buf) >= need:
            # (concatenated, not np.stack: 3× faster; still 0.2 ms a window on a UR5 in a
            # paced loop, its caches cold, and 0.12 ms to send it: the window's update cost)
            t_s, q_s, tau_s = zip(*list(self.buf)[:need], strict=True)
            t_arr = np.array(t_s)
            q_arr = np.concatenate(q_s).reshape(need, -1)
            tau_arr = np.concatenate(tau_s).reshape(need, -1)
            self._run(None, "add_window", t_arr, q_arr, tau_arr, self.hw, self.win, self.stride)
            self.windows = min(self.windows + 1, self.identifier.rows.maxlen or 0)
            for _ in range(self.win):
                self.buf.popleft()
        if (
            t >= self.next_solve - TIME_EPS  # (t₀ + kT: rounding)
            and self.windows >= 2
            and not self.solving  # one solve at a time: a late one is used late, not queued
        ):
            self.next_solve = t + self.resolve_every
            current = self.nominal if self.theta is None else self.theta
            qs = [x[1] for x in list(self.buf)[:: max(1, len(self.buf) // 4)]]
            self.solving = True
            self._run((explained, current), "solve", current, qs)
        return self.collect()

    def _run(self, solve: tuple[bool, Vector] | None, job: str, *args: Any) -> None:
        """Run the identifier's ``job(*args)`` now (synchronous) or queue it on the worker
        process (background); ``solve``: ``(explained, current model)`` of a solve, ``None``
        for a window."""
        if self.worker is None:
            self.pending.append((_Done(getattr(self.identifier, job)(*args)), solve))
        else:
            windows = self.identifier.rows.maxlen or 1
            self.pending.append((self.worker.submit(_remote, self.key, windows, job, *args), solve))

    def collect(self) -> bool:
        """Take the jobs that are done, in order (all of them, synchronous or with :attr:`join`),
        and apply a solve's result (:meth:`_apply`); True when it installs a new model.
        A job's exception is raised here, as the synchronous learner raises it in ``add``."""
        installed = False
        while self.pending and (self.join or self.pending[0][0].done()):
            job, solve = self.pending.popleft()
            result = job.result()
            if solve is None:
                self.row_count = result
            else:
                self.solving = False
                installed = self._apply(result, *solve) or installed
        return installed

    def _fill(self, t: float, q: Vector) -> bool:
        """Interpolate the ``k − 1`` samples lost between the last buffered one and ``q`` taken
        at ``t`` (``t − t_last ≈ k h``, ``k − 1 ≤`` :data:`~pinobs.model.identification.MAX_FILL`)
        linearly on the manifold, each with the torque of its own update (held from the last
        one given); False (nothing filled) for a longer or uneven gap, or one where the filter's
        gate rejected a sample (the model did not explain the data there: filled too, z1 with a
        payload went from 7.4e-4 to 1.22e-3 rad/s in ``benchmarks/learning.py``).  Cleared at every lost
        sample instead, the windows of ``win + 2 hw + 1`` consecutive samples never filled with
        2 % of the samples lost at random, and ``adaptive`` never learned (a sweep: UR5 with a
        payload, 5 % lost, 0 solves in 12 s, 1.19× kf, said "consistent").  The interpolation
        error, ``(k h)² |q̈| / 8``, is 2e-6 |q̈| rad at 1 kHz over 3 lost samples."""
        t0, q0, tau0 = self.buf[-1]
        k = round((t - t0) / self.h)
        if not 2 <= k <= MAX_FILL + 1 or abs(t - t0 - k * self.h) > _GAP_FRACTION * self.h:
            return False
        if any(g for *_, g in self._lost):  # gated, not lost: the model was not explaining the
            return False  # data there (filled, z1 with a payload went 7.4e-4 -> 1.22e-3 rad/s)
        robot = self.reg.robot
        for i in range(1, k):
            ti = t0 + i * (t - t0) / k
            held = tau0
            for t_lost, tau_lost, _ in self._lost:  # the torque applied from the lost update on
                if t_lost <= ti + _GAP_FRACTION * self.h:
                    held = tau_lost
            self.buf.append((ti, robot.interpolate(q0, q, i / k), held))
        return True

    def _counts(self, h: float) -> None:
        """The windows in samples for the interval ``h`` [s]."""
        self.h = h
        self.stride = max(1, round(0.004 / h))
        self.win = max(self.stride, round(self.window / h / self.stride) * self.stride)
        self.hw = max(2, round(self.half_window / h))

    def start(self, t0: float) -> None:
        """Begin at the reset time ``t0`` [s]: the first solve comes ``resolve_every`` after it."""
        self.next_solve = t0 + self.resolve_every

    def _interval(self, run: list[float]) -> None:
        """:data:`_INTERVAL_CHECK` consecutive intervals off ``h`` that agree among themselves:
        the stream is not at ``rate`` (or its first interval was not its own); their median
        becomes ``h``, said in ``rejected``.  A 500 Hz stream taken for 1 kHz (the default
        without ``rate``) never solved, silently."""
        h = float(np.median(run))
        if all(abs(d - h) <= _GAP_FRACTION * h for d in run):
            given = f"rate = {self.rate_given:g} Hz" if self.rate_given else "its first interval"
            self.rejected.append(
                f"the samples come every {h:.6g} s, not {self.h:.6g} s ({given}): the "
                "identification windows are counted on the samples' interval from here"
            )
            self._counts(h)
            self.buf.clear()  # spaced (or filled: _fill) at the interval taken before

    def _apply(self, sol: _Solution, explained: bool, current: Vector) -> bool:
        """Take the solve ``sol`` (:meth:`_Identifier.solve`, against ``current``, the model
        when it was asked for); True when it installs a new model.  Model selection: keep the
        current model unless the new one explains the rows better than fitting noise would
        (robust loss drop above rank + 3√rank, in units of ½χ²)."""
        if sol.failure is not None:
            self.rejected.append(f"solve failed: {sol.failure}")
            self.rejected_run += 1
            return False
        self.condition, self.rank = sol.condition, sol.rank
        if sol.unphysical is not None:
            self.rejected.append(f"{sol.unphysical} in solve {self.solves + 1}")
            self.rejected_run += 1
            return False
        assert sol.minv_max is not None and sol.theta is not None  # (a consistent solve)
        self.minv_max = sol.minv_max  # of the latest consistent solve (the candidate)
        self.candidate = sol.theta  # the latest consistent solve, installed or not
        drop = sol.loss_current - sol.loss_new
        self.history.append((sol.loss_current, sol.loss_new))
        self.solves += 1
        self.rejected_run = 0
        self.validated = True
        self.std, self.excited = sol.std, sol.excited
        self.last_drop = float(drop)
        if explained or drop <= sol.rank + 3.0 * np.sqrt(sol.rank):
            if self.theta is None:
                self.theta = current
            return False
        self.theta = sol.theta
        self.installs += 1
        return True


class _Solution(NamedTuple):
    """One solve of :class:`_Identifier` (``failure`` or ``unphysical`` said why it is not one)."""

    failure: str | None = None  # the solve raised
    unphysical: str | None = None  # a non-positive mass, or M(q) not positive definite
    condition: float = math.nan
    rank: int = 0
    theta: Vector | None = None  # friction clipped and kept nominal where the data do not show it
    std: Vector | None = None
    excited: NDArray[np.bool_] | None = None
    minv_max: Vector | None = None  # the largest (M⁻¹)ᵢᵢ at the checked configurations
    loss_current: float = math.nan  # the robust loss of the current model on the rows
    loss_new: float = math.nan  # the same of the solve


class _Identifier:
    """The learner's costly part: the rows of each window and the solves, run in order on the
    loop (synchronous) or in the worker process (background), on its own regressor."""

    def __init__(self, reg: MomentumRegressor, windows: int) -> None:
        self.reg = reg
        self.nominal = reg.nominal()
        self.rows: deque[tuple[Vector, Vector]] = deque(maxlen=windows)

    def add_window(self, t: Vector, q: Vector, tau: Vector, hw: int, win: int, stride: int) -> int:
        """The ``nv`` rows of one window (module docstring, MATH §9) from the samples ``q``
        [rad] taken at ``t`` [s] with the torques ``tau`` (``win + 2 hw + 1`` of them: the
        smoother's half-width ``hw`` on both sides); returns the rows kept."""
        q_s, v = smooth_path(self.reg.robot, t, q, half_window=hw, edges=False)
        k = slice(hw, hw + win + 1)
        A, y = self.reg.system(t[k], q_s[k], v[k], tau[k], window=win, stride=stride)
        self.rows.append((A, y))
        return sum(r[0].shape[0] for r in self.rows)

    def solve(self, current: Vector, qs: list[Vector]) -> _Solution:
        """Solve the rows; check the masses and ``M(q) ≻ 0`` at the configurations ``qs``;
        the robust losses of ``current`` and of the solve (for :meth:`_Learner._apply`)."""
        A = np.vstack([r[0] for r in self.rows])
        y = np.concatenate([r[1] for r in self.rows])
        try:
            sol = solve(self.reg, A, y, consistent=False)
        except (IdentificationError, np.linalg.LinAlgError) as exc:
            return _Solution(failure=str(exc))
        theta = sol.theta
        n = self.reg.n_inertial
        masses = theta[0:n:10]
        if np.any(masses <= 0):
            return _Solution(None, "non-positive mass", sol.condition, sol.rank)
        if self.reg.friction:
            theta = theta.copy()
            f = slice(n, n + 2 * self.reg.n_joint)
            theta[f] = np.maximum(theta[f], 0.0)  # friction never feeds energy in
            # friction the data do not show (within _FRICTION_SIGMAS σ of nominal) stays nominal:
            # a learned friction makes every prediction pay for it (ekf's stiff path)
            nominal = self.nominal[f]
            weak = np.abs(theta[f] - nominal) <= _FRICTION_SIGMAS * sol.std[f]
            theta[f] = np.where(weak, nominal, theta[f])
        robot = self.reg.with_parameters(theta)
        minv_max = np.zeros(robot.nv)
        for q in qs:
            m = robot.mass_matrix(q)
            if np.linalg.eigvalsh(m)[0] <= 0:
                return _Solution(None, "M(q) not positive definite", sol.condition, sol.rank)
            minv_max = np.maximum(minv_max, np.diag(np.linalg.inv(m)))
        loss_cur = _huber_loss(A @ current - y, sol.sigma)
        loss_new = _huber_loss(A @ theta - y, sol.sigma)
        return _Solution(
            None, None, sol.condition, sol.rank, theta, sol.std, sol.excited, minv_max,
            loss_cur, loss_new,
        )  # fmt: skip


class _Done:
    """A job run on the loop (synchronous learning): its result, as a done future."""

    def __init__(self, result: Any) -> None:
        self._result = result

    def done(self) -> bool:
        return True

    def result(self) -> Any:
        return self._result


#: Learner keys (:attr:`_Learner.key`): which learner a job in the worker process is for.
_KEYS = itertools.count()


def _worker_start(robot: Robot, friction: bool, offset: bool) -> dict[str, Any]:
    """The worker process's state (:class:`~pinobs.observers.worker.Worker`): its regressor
    (its own ``pin.Data``) and the identifier of the latest learner that sent a job."""
    _load_learning()
    # off the loop's scheduling: its own session (so its own group where Linux groups tasks
    # by session, autogroup: the loop's share is not spent on it) at the lowest priority.
    # UR5 live_loop at load 9-11, updates over 1 ms in 10 s: 62-77 in the loop's session,
    # 21-41 in its own (synchronous learning: 141-168)
    with contextlib.suppress(AttributeError, OSError):
        os.setsid()
    with contextlib.suppress(AttributeError, OSError):
        os.nice(19)
    return {"reg": MomentumRegressor(robot, friction=friction, offset=offset), "key": None}


@one_blas_thread  # small matrices (and the loop is on the other core)
def _remote(state: dict[str, Any], key: int, windows: int, job: str, *args: Any) -> Any:
    """In the worker process: the job ``job(*args)`` of the identifier of learner ``key``
    (made afresh, keeping ``windows`` windows of rows, at that learner's first job: a reset)."""
    if state["key"] != key:
        state["key"], state["identifier"] = key, _Identifier(state["reg"], windows)
    return getattr(state["identifier"], job)(*args)


#: A sample interval further than this fraction of ``h`` from it is a gap for the learner
#: (a lost sample is ``2h``): its windows restart after it.
_GAP_FRACTION = 0.5

#: Consecutive rejected solves (no physical model fits the rows) after which :meth:`AdaptiveEKF.
#: consistency` says ``"inconsistent"`` whatever the NIS: measured, exact-model and the
#: README's model-error logs (UR5, Panda, double pendulum, 12 s, seeds 0-1) reject at most one
#: solve, the second; a UR5 whose wrist_2 torque is logged with the wrong sign rejected every
#: one for 30 s, stayed in its warm-up (1.18× kf) and read "consistent" (the offset state
#: absorbs the wrong torque below the NIS bound).
_REJECTED_RUN = 4

#: The latest rejections kept in ``details["rejected"]`` (it grew without bound, two a second).
_REJECTED_KEPT = 100

#: Consecutive off-interval samples after which the learner takes their median as ``h``.
_INTERVAL_CHECK = 10

#: Friction parameters within this many standard deviations of their nominal values are kept
#: nominal (the significance of a learned viscous or Coulomb coefficient).
_FRICTION_SIGMAS = 3.0


#: ``λ h`` up to which a learned joint friction is a held input of the filter rather than part
#: of its model (``λ = (M⁻¹)ᵢᵢ |∂τ_f,ᵢ/∂v|``, largest over the configurations the learner
#: checked): the friction held at the extrapolated mid-step velocity (:meth:`AdaptiveEKF._torque`)
#: is, for a linear friction, a two-step Adams–Bashforth step, stable for ``λh < 1``; the 10×
#: margin covers configurations the check did not sample.  Stiffer friction stays in the
#: model (``ekf``'s stiff-friction path, which costs its substeps and ``exp(Ah)`` by squaring).
_HELD_FRICTION_STIFFNESS = 0.1


#: Mean NIS per degree of freedom up to which the model-based filter is trusted outright by the
#: blend (twice the consistent value); the blame on the model ramps up to full at twice this.
_NIS_TRUSTED = 2.0


#: Mean NIS per degree of freedom above which the nominal model's trust is revoked at once.
_NIS_REVOKED = 10.0


#: The bank's white-jerk densities [rad²/s⁵] (module docstring, 3).  1e1 … 1e5 until the
#: UR10e logs (~95 Hz, positions printed to 1e-4 rad, ``benchmarks/real_logs.py``), where
#: the best fixed ``kf`` density is 1e-2 … 1: with the bank's floor at 1e1 the blend's
#: model-free side alone was 3.0× the ``kf``'s RMS (0.027 against 0.0092 rad/s on
#: ur-19_09_27-11_32_02, its model-based filter lost and restarted all along, weight 0),
#: with 1e-2 … 1e5 1.13× (0.0104); the simulated learning table is unchanged.
JERK_PSD: tuple[float, ...] = tuple(float(10.0**k) for k in range(-2, 6))


def _lost(ekf: EKFState) -> bool:
    """Whether a model-based filter state's estimate or covariance holds NaN or ±inf."""
    return not math.isfinite(ekf.v.sum() + ekf.P.sum())


def _blend_loops(
    score: Vector,
    innovation: Vector,
    measured: bool,
    lam: float,
    bank_q: Vector,
    bank_v: Vector,
    bank_P: Vector,
    q: Vector,
    v: Vector,
    s: Vector,
    blame: float,
) -> tuple[Vector, Vector, Vector, Vector]:
    """The blend of :meth:`AdaptiveEKF.step` on vector joints, in loops (compiled by numba).

    Per coordinate ``i``: the scores ``score ← score + λ(e² − score)`` (if ``measured``),
    the filter ``b`` of the least score, ``v_kf = v_b``, ``P_kf = P_b,11``,
    ``s ← s + λ(blame · max((v − v_kf)² − P_kf, 0) − s)``, ``w = P_kf / (P_kf + s)``,
    ``v̂ = w v + (1 − w) v_kf``, ``q̂ = q + (1 − w)(q_b − q)`` (module docstring).
    Returns new arrays ``(score, s, q̂, v̂)``.
    """
    nf, nv = score.shape
    score_out = score.copy()
    if measured:
        for f in range(nf):
            for i in range(nv):
                score_out[f, i] = score[f, i] + lam * (innovation[f, i] ** 2 - score[f, i])
    s_out = np.empty(nv)
    q_out = np.empty(nv)
    v_out = np.empty(nv)
    for i in range(nv):
        b = 0
        for f in range(1, nf):
            if score_out[f, i] < score_out[b, i]:
                b = f
        p_kf = bank_P[b, 1, 1]
        d = v[i] - bank_v[b, i]
        s_out[i] = s[i] + lam * (blame * max(d * d - p_kf, 0.0) - s[i])
        w = p_kf / (p_kf + s_out[i] + 1e-300)
        v_out[i] = w * v[i] + (1.0 - w) * bank_v[b, i]
        q_out[i] = q[i] + (1.0 - w) * (bank_q[b, i] - q[i])
    return score_out, s_out, q_out, v_out


_blend_kernel = LazyKernel(
    _blend_loops,
    np.zeros((1, 1)), np.zeros((1, 1)), True, 0.5, np.zeros((1, 1)), np.zeros((1, 1)),
    np.tile(np.eye(3), (1, 1, 1)), np.zeros(1), np.zeros(1), np.zeros(1), 0.5,
)  # fmt: skip


#: What the worker processes' fork server imports once (:class:`~pinobs.observers.worker.Worker`).
_PRELOAD = ("pinobs.observers.adaptive", "scipy.signal", "scipy.ndimage", "scipy.linalg")

#: Where the learner's windows and solves run (:class:`AdaptiveEKF`, ``learning``).
_LEARNING = ("sync", "background")


def _load_learning() -> None:
    """Import what the learner imports when it first runs (SciPy's smoothing and QR: about
    0.5 s, the first window's update took 494 ms on a UR5) and scan the BLAS libraries
    with ``scipy.linalg`` loaded (:func:`~pinobs.observers.blas.blas_libraries`): now, at
    construction, not in the loop."""
    import scipy.linalg
    import scipy.ndimage
    import scipy.signal  # noqa: F401

    blas_libraries()


def _huber_loss(r: Vector, sigma: float, c: float = 1.345) -> float:
    """``Σ ρ(rᵢ/σ)`` with Huber's ρ (½z² inside ``c``, ``c|z| − ½c²`` outside)."""
    z = np.abs(r) / sigma
    return float(np.sum(np.where(z <= c, 0.5 * z * z, c * z - 0.5 * c * c)))


@register
class AdaptiveEKF(Observer["_State"]):
    """EKF that identifies its model online and blends with a model-free filter (module docstring).

    A composition: ``core``, an :class:`~pinobs.observers.ekf.ExtendedKalmanFilter` whose
    model and densities the learner sets (its ``replace_robot`` and ``gains``), driven
    through its public ``initial_state`` and ``step``; the learner; the blend with a bank
    of model-free ``kf`` (:class:`~pinobs.observers.kf.KFBank`).

    Args:
        robot: the nominal model (the identification's prior).
        window: identification window [s] (one block of ``nv`` rows each).
        half_window: half-width of the zero-phase smoother of the measured path [s].
        horizon: rows kept for the solve [s] (a sliding window).
        resolve_every: time between solves [s].
        friction: learn joint friction.
        offset: learn a torque offset.
        accel_psd: white-acceleration density once a model is learned [rad²/s³].
        warmup_accel_psd: the same before the first solve.
        disturbance_psd: density of the torque-offset state (as in ``ekf``) before the first solve [rad²/s⁵].
        learned_disturbance_psd: the same once a model is learned.
        validated_accel_psd: ``accel_psd`` while a solve finds nothing better than
            the nominal model (the exact-model regime of ``ekf``).
        validated_disturbance_psd: ``disturbance_psd`` in that regime.
        blend: blend with the model-free ``kf`` (never behind it).
        blend_time: averaging time of the disagreement [s].
        jerk_psd: the white-jerk densities of the ``kf`` bank [rad²/s⁵] (module docstring).
        q0_std: initial configuration standard deviation [rad] (as in ``ekf``).
        v0_std: initial velocity standard deviation [rad/s] (as in ``ekf``).
        d0_std: initial standard deviation of the torque offset [N·m or N] (as in ``ekf``).
        outlier_probability: the outlier gate (as in ``ekf``; the ``kf`` skips what it rejects).
        rate: sample rate [Hz]: the identification windows are counted in samples of
            ``1/rate``; not given, of the stream's first interval.  Either way, ten
            consecutive intervals off it by more than half (that agree among themselves)
            replace it, said in ``consistency().details["rejected"]``.  Jitter within
            ±h/2 is not a gap.
        noise_std: position noise standard deviation [rad or m].
        learning: ``"sync"``: the identification runs inside ``update`` (offline replays:
            the results do not depend on the machine's pace); ``"background"``: in a worker
            process, its results taken when they are done (a live loop: no update waits for
            it; module docstring, 4).  The observer then owns a process (started from
            multiprocessing's fork server: a script that makes one guards its top-level
            code with ``if __name__ == "__main__":``), which ends when it is dropped.
    """

    name = "adaptive"
    uses_noise_std = True
    #: :func:`pinobs.smooth` smooths its model-based filter, the learned model frozen per window
    smoothable = True
    learns_model = True
    summary = "EKF that identifies its model online, blended with kf: never behind it (model-based)"

    def __init__(
        self,
        robot: Robot,
        *,
        window: float = 0.1,
        half_window: float = 0.05,
        horizon: float = 10.0,
        resolve_every: float = 0.5,
        friction: bool = True,
        offset: bool = True,
        accel_psd: float = 1e-6,
        warmup_accel_psd: float = 1e-2,
        disturbance_psd: float = 1.0,
        learned_disturbance_psd: float = 1e-4,
        validated_accel_psd: float = 1e-8,
        validated_disturbance_psd: float = 1e-8,
        blend: bool = True,
        blend_time: float = 0.2,
        jerk_psd: tuple[float, ...] = JERK_PSD,
        q0_std: float = 0.1,
        v0_std: float = 1.0,
        d0_std: float = 1.0,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
        learning: str = "sync",
    ) -> None:
        if learning not in _LEARNING:
            raise GainError(f"learning={learning!r} must be one of {', '.join(_LEARNING)}")
        super().__init__(robot, rate=rate, noise_std=noise_std)
        #: The model-based filter (class docstring).
        self.core = ExtendedKalmanFilter(
            robot,
            accel_psd=warmup_accel_psd,
            q0_std=q0_std,
            v0_std=v0_std,
            disturbance_psd=disturbance_psd,
            d0_std=d0_std,
            outlier_probability=outlier_probability,
            rate=rate,
            noise_std=noise_std,
        )
        for key, val in (
            ("window", window),
            ("half_window", half_window),
            ("horizon", horizon),
            ("resolve_every", resolve_every),
            ("accel_psd", accel_psd),
            ("blend_time", blend_time),
            ("learned_disturbance_psd", learned_disturbance_psd),
            ("validated_accel_psd", validated_accel_psd),
            ("validated_disturbance_psd", validated_disturbance_psd),
        ):
            positive(key, val)
        if horizon < 2 * window:
            positive("horizon - 2 window", horizon - 2 * window)
        self._nominal = self.core.robot
        self._learn_options = dict(
            window=float(window),
            half_window=float(half_window),
            horizon=float(horizon),
            resolve_every=float(resolve_every),
            friction=bool(friction),
            offset=bool(offset),
            rate=None if self.rate is None else float(self.rate),
        )
        self.learning = learning
        _load_learning()
        # background: one worker process, started now (not in the loop); it ends when the
        # observer is dropped (its jobs hold no observer)
        self._worker: Worker | None = None
        if learning == "background":
            self._worker = Worker(
                _worker_start, self._nominal, bool(friction), bool(offset), preload=_PRELOAD
            )
        self._learner = _Learner(self._nominal, **self._learn_options, worker=self._worker)  # type: ignore[arg-type]
        if self._learner.reg.size == 0:
            raise UnsupportedRobotError(f"robot {robot.name!r} has no dynamic parameter to learn")
        self.blend = bool(blend)
        self.blend_time = float(blend_time)
        try:
            jerks = tuple(float(positive("jerk_psd", j) or 0.0) for j in jerk_psd)
        except TypeError:
            raise GainError(f"jerk_psd={jerk_psd!r} must be a sequence of numbers > 0") from None
        if not jerks:
            raise GainError("jerk_psd needs at least one density")
        self._bank = KFBank(self.robot, jerks, self.core.gains.meas_std)
        if self.blend and self.robot.is_vector_space:
            _blend_kernel.load()
        self._offset: Vector = np.zeros(self.robot.nv)
        self._learned = self._nominal  # the learned model, all its friction included
        self._held_friction: Vector | None = None  # 1 where it is a held input (_install)
        self._regimes = {  # (accel_psd, disturbance density) per regime
            "warmup": (float(warmup_accel_psd), float(disturbance_psd)),
            "nominal": (float(validated_accel_psd), float(validated_disturbance_psd)),
            "learned": (float(accel_psd), float(learned_disturbance_psd)),
        }
        self.regime = "warmup"
        self.restarts = 0  # times the model-based filter was lost and restarted
        self._restarted = False
        self._m_bar2: Vector = np.zeros(self.robot.nv)

    @property
    def options(self) -> dict[str, Any]:
        return {
            **self.core.options,
            **self._learn_options,
            "accel_psd": self._regimes["learned"][0],
            "warmup_accel_psd": self._regimes["warmup"][0],
            "learned_disturbance_psd": self._regimes["learned"][1],
            "validated_accel_psd": self._regimes["nominal"][0],
            "validated_disturbance_psd": self._regimes["nominal"][1],
            "blend": self.blend,
            "blend_time": self.blend_time,
            "jerk_psd": self._bank.jerk.tolist(),
            "learning": self.learning,
        }

    # ---------------------------------------------------------------- learning
    def learned_robot(self) -> Robot:
        """A :class:`Robot` carrying the current estimate (friction included; the nominal one before the first solve)."""
        return self._learned.copy()

    def snapshot(self) -> ModelSnapshot:
        """The learned model, offset and regime densities now (read only: the filter is unchanged).

        The model is the filter's, with the learned friction it takes as a held input
        (:meth:`_install`) put back: the learned model whole."""
        accel, dist = self._regimes[self.regime]
        robot = self.core.robot if self._held_friction is None else self._learned
        return ModelSnapshot(
            robot.copy(), self._offset.copy(), self.regime, accel, dist * self._m_bar2
        )

    def lost(self) -> bool:
        """Whether the model-based filter's estimate or covariance is not finite, or its
        latest update diverged (with the blend, the next update restarts it; without, it
        stays lost: every update raises ``ObserverDiverged`` until :meth:`reset`).  A
        diverged update keeps the last finite state, so this said ``False`` then (a sweep)."""
        if self._state is None:
            return False
        return self._diverged or _lost(self._state.ekf)

    def parameters(self) -> ParameterSet:
        """The learned parameters with names and standard deviations (nominal before the first solve)."""
        lr = self._learner
        reg = lr.reg
        nominal = reg.nominal()
        if lr.theta is None or lr.std is None or lr.excited is None:
            prior = reg.prior_std()
            return ParameterSet(reg.names, nominal, prior, nominal, np.zeros(reg.size, bool))
        return ParameterSet(reg.names, lr.theta.copy(), lr.std.copy(), nominal, lr.excited.copy())

    def consistency(self) -> Consistency:
        """The NIS test of the base class, with what the learner did in ``details``:
        solves, the regressor's condition number and rank, rejected solves (a
        failed re-solve keeps the last model and is listed here: the latest
        :data:`_REJECTED_KEPT`), the blend weights.  ``"inconsistent"`` whatever the
        NIS after :data:`_REJECTED_RUN` rejected solves in a row (no physical model
        fits the data)."""
        lr = self._learner
        base = super().consistency()
        if lr.rejected_run >= _REJECTED_RUN:  # no physical model fits: the NIS cannot see it
            last = lr.rejected[-1] if lr.rejected else ""
            base = replace(
                base,
                verdict="inconsistent",
                causes=(
                    f"no physical model fits the data: the last {lr.rejected_run} solves were "
                    f"rejected ({last}); check the torques' signs, scales and column order",
                    *LIKELY_CAUSES,
                ),
            )
        details = {
            "solves": lr.solves,
            "installs": lr.installs,
            "last_loss_drop": lr.last_drop,
            "condition": float(lr.condition),
            "rank": lr.rank,
            "n_parameters": lr.reg.size,
            "rows": lr.row_count,
            "rejected": list(lr.rejected),
            "warming_up": lr.theta is None,
            "regime": self.regime,
            "restarts": self.restarts,
            "blend_weight": None if self._state is None else self._weights(self._state).tolist(),
        }
        return replace(base, details=details)

    def _set_regime(self, state: EKFState, regime: str) -> EKFState:
        """Switch the process noise: ``warmup`` (nominal model not trusted yet), ``nominal``
        (a solve found nothing better: the exact-model densities), ``learned`` (a learned model)."""
        self.regime = regime
        accel, dist = self._regimes[regime]
        self.core.gains = replace(self.core.gains, accel_psd=accel)
        if state.d_psd is None:
            return state
        return state._replace(d_psd=dist * self._m_bar2)  # per joint, as ekf: psd · M̄ᵢᵢ²

    def _install(self, state: EKFState) -> EKFState:
        """Install the learner's model: friction that cannot be stiff (``λᵢ h ≤``
        :data:`_HELD_FRICTION_STIFFNESS`) as a held input, the rest in the filter's model."""
        lr = self._learner
        assert lr.theta is not None
        name = f"{self._nominal.name}~learned"
        self._learned = lr.reg.with_parameters(lr.theta, name=name)
        theta = lr.theta
        self._held_friction = None
        if lr.reg.friction and self._learned.has_friction:
            # λᵢ = max (M⁻¹)ᵢᵢ |∂τ_f,ᵢ/∂v| (its largest slope is at v = 0)
            lam = lr.minv_max * np.abs(self._learned.friction_derivative(np.zeros(self.robot.nv)))
            held = lam * lr.h <= _HELD_FRICTION_STIFFNESS
            if np.any(held & (lam > 0)):
                n, nj = lr.reg.n_inertial, lr.reg.n_joint
                cols = held[list(lr.reg.actuated)]
                theta = theta.copy()
                theta[n : n + nj][cols] = 0.0
                theta[n + nj : n + 2 * nj][cols] = 0.0
                self._held_friction = held.astype(float)
        self.core.replace_robot(lr.reg.with_parameters(theta, name=name))
        self._offset = lr.reg.offsets(lr.theta)
        state = self._set_regime(state, "learned")
        if state.d is None:
            return state
        return state._replace(d=np.zeros_like(state.d))  # the new model explains what d absorbed

    # ------------------------------------------------------------------ filter
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        # a reset starts learning afresh from the nominal model
        self.core.replace_robot(self._nominal.copy())
        self._learned = self._nominal
        self._held_friction = None
        self._learner = _Learner(self._nominal, **self._learn_options, worker=self._worker)  # type: ignore[arg-type]
        self._offset = np.zeros(self.robot.nv)
        self.core.gains = replace(self.core.gains, accel_psd=self._regimes["warmup"][0])
        self.regime = "warmup"
        self.restarts, self._restarted = 0, False
        self._m_bar2 = np.diag(self._nominal.mass_matrix(q0)) ** 2
        ekf = self.core.initial_state(q0, v0)
        kf = self._bank.initial(q0, v0, self.core.gains.v0_std)
        score = np.zeros((self._bank.jerk.size, self.robot.nv))
        s = np.zeros(self.robot.nv)  # the model is trusted until the data disagree
        state = _State(ekf, kf, score, 0.0, s, q0.copy(), v0.copy(), ekf.v, 0.0)
        self._warm(state, q0)
        return state

    def _warm(self, state: _State, q0: Vector) -> None:
        """One step from ``state`` to ``q0``, thrown away: the first ``update`` then runs
        on paths already taken (NumPy's and the filters' first calls, their caches: the
        kernels are compiled or loaded when the observer is made, SciPy imported then too).
        UR5 in a loop paced at 1 kHz, first update 820–1065 µs without it, 295–406 µs with it
        (median update 200 µs).  ``step`` leaves ``state`` as it is; what a lost filter's
        restart would change here is put back."""
        kept = (self.restarts, self._restarted, list(self._learner.rejected), self.regime)
        h = 1.0 / self.rate if self.rate else 1e-3
        with np.errstate(all="ignore"):
            self.step(state, h, q0, np.zeros(self.robot.nv))
        self.restarts, self._restarted, rejected, regime = kept
        self._learner.rejected = deque(rejected, maxlen=_REJECTED_KEPT)
        if regime != self.regime:
            self._set_regime(state.ekf, regime)

    def restart_state(self, state: _State, q: Vector) -> _State:
        """After a pause: the filter and the bank afresh at ``q`` (zero velocity), in the
        current regime; the learned model, offset and learner kept (a reset would relearn)."""
        zero = np.zeros(self.robot.nv)
        ekf = self._set_regime(self.core.initial_state(q, zero), self.regime)
        kf = self._bank.initial(q, zero, self.core.gains.v0_std)
        score = np.zeros((self._bank.jerk.size, self.robot.nv))
        return _State(ekf, kf, score, state.t, zero.copy(), q.copy(), zero.copy(), ekf.v, 0.0)

    def _model_free(self, state: _State) -> tuple[Vector, Vector, Vector]:
        """Per coordinate, the bank's ``kf`` with the smallest running innovation:
        ``(its v, its velocity variance, its tangent offset from the EKF's q̂)``."""
        best = np.argmin(state.score, axis=0)
        cols = np.arange(self.robot.nv)
        bank = state.kf
        v = bank.v[best, cols]
        p = bank.P[best, 1, 1]
        if self.robot.is_vector_space:
            dq = bank.q[best, cols] - state.ekf.q
        else:
            dq = np.array([self.robot.difference(state.ekf.q, x) for x in bank.q])[best, cols]
        return v, p, dq

    def _weights(self, state: _State) -> Vector:
        if not self.blend:
            return np.ones(self.robot.nv)
        p_kf = self._model_free(state)[1]
        return p_kf / (p_kf + state.s + 1e-300)

    def _torque(self, state: _State, dt: float, tau: Vector) -> Vector:
        """The torque the filter's model is given over the next step of ``dt`` [s]: ``τ + b̂``,
        plus, on the joints where it is an input (:meth:`_install`), the learned friction at
        the mid-step velocity extrapolated from the last step, ``τ_f,θ̂(v̂ + (h/2)(v̂ − v̂₋)/h₋)``
        (``v̂₋``, ``h₋``: :attr:`_State.v_prev`, :attr:`_State.dt_prev`; no extrapolation before
        a first step).  Held at ``v̂`` alone, its error would be first order,
        ``h |∂τ_f/∂v| |a| h/2`` per step (7e-4 rad/s on a UR5 started on a noise-free truth);
        extrapolated, second order (tested)."""
        if self._held_friction is None:
            return tau + self._offset
        v = state.ekf.v
        v_mid = v + (0.5 * dt / state.dt_prev) * (v - state.v_prev) if state.dt_prev > 0 else v
        return tau + self._offset + self._held_friction * self._learned.friction_torque(v_mid)

    def _core_step(self, ekf: EKFState, dt: float, q_meas: Vector | None, tau: Vector) -> EKFState:
        """The model-based filter's step; a filter whose covariance overflowed to a singular
        innovation covariance, or that its family says diverged, comes back with a NaN
        velocity (lost: restarted by :meth:`step`).  On UR10e logs at ~95 Hz the warm-up
        filter's velocity variance reached 6e10 before ``solve`` raised ``LinAlgError``, which
        escaped the restart and left the re-initialisation to :func:`pinobs.estimate`."""
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a lost filter: handled by step
                return self.core.step(ekf, dt, q_meas, tau)
        except (ObserverDiverged, np.linalg.LinAlgError, ArithmeticError):
            return ekf._replace(v=np.full_like(ekf.v, np.nan))

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        ekf = self._core_step(state.ekf, dt, q_meas, self._torque(state, dt, tau))
        t = state.t + dt
        if self.blend and _lost(ekf):
            # the model-based filter is lost (a learned model that does not hold): restart it
            # on the model-free estimate, in the warm-up regime, rather than fail
            v_kf, _, dq_kf = self._model_free(state)
            restart = self.core.initial_state(self.robot.integrate(state.ekf.q, dq_kf), v_kf)
            restart = self._set_regime(restart, "warmup")
            state = state._replace(ekf=restart, dt_prev=0.0)
            ekf = self._core_step(restart, dt, q_meas, self._torque(state, dt, tau))
            if _lost(ekf) and self._learned is not self._nominal:
                # lost again at once: the learned model itself does not hold (a mass matrix
                # not positive definite away from the configurations its solve checked, held
                # friction stiff there: solo12 with friction, a Panda at hard stops raised
                # ObserverDiverged); back to the nominal model, which the learner may replace
                self.core.replace_robot(self._nominal.copy())
                self._learned, self._held_friction = self._nominal, None
                self._offset = np.zeros(self.robot.nv)
                self._learner.rejected.append(
                    f"learned model dropped at t = {t:.6g} s (the filter restarted on it was "
                    "lost at once): back to the nominal model"
                )
                ekf = self.core.step(restart, dt, q_meas, self._torque(state, dt, tau))
            self._learner.rejected.append(f"model-based filter restarted at t = {t:.6g} s")
            self.restarts += 1
            # the blend's error variance of the lost filter overflowed with it: the restarted
            # one starts with its initial velocity variance (the blend follows the kf first)
            state = state._replace(s=np.full(self.robot.nv, self.core.gains.v0_std**2))
            self._restarted = True  # the next solve must beat the current model to end it
        if not self.blend:
            return state._replace(ekf=ekf, t=t, q=ekf.q, v=ekf.v, v_prev=state.ekf.v, dt_prev=dt)
        meas = None if ekf.gate.gated else q_meas  # one gate for every filter
        kf = self._bank.step(state.kf, dt, meas)
        lam = min(1.0, dt / self.blend_time)
        # disagreement is the model's fault only when its innovations say so (NIS̄ > 2 nv)
        nv = self.robot.nv
        level = float(nv) if ekf.gate.level is None else ekf.gate.level
        blame = min(1.0, max(0.0, (level / nv - _NIS_TRUSTED) / _NIS_TRUSTED))
        if self._restarted or self._learner.rejected_run >= _REJECTED_RUN:
            blame = 1.0  # the model was lost and not replaced since, or none fits: to blame
        if self.robot.is_vector_space and _blend_kernel.compiled is not None:
            score, s, q, v = _blend_kernel.compiled(
                state.score, kf.v if kf.innovation is None else kf.innovation,
                kf.innovation is not None, lam, kf.q, kf.v, kf.P, ekf.q, ekf.v, state.s, blame,
            )  # fmt: skip
            return _State(ekf, kf, score, t, s, q, v, state.ekf.v, dt)
        score = state.score
        if kf.innovation is not None:
            score = score + lam * (kf.innovation**2 - score)
        new = _State(ekf, kf, score, t, state.s, ekf.q, ekf.v, state.ekf.v, dt)
        v_kf, p_kf, dq_kf = self._model_free(new)
        d = ekf.v - v_kf
        s = state.s + lam * (blame * np.maximum(d * d - p_kf, 0.0) - state.s)
        w = p_kf / (p_kf + s + 1e-300)
        v = w * ekf.v + (1.0 - w) * v_kf
        q = self.robot.integrate(ekf.q, (1.0 - w) * dq_kf)
        return new._replace(s=s, q=q, v=v)

    def after_commit(self, state: _State, t: float, q: Vector | None, tau: Vector) -> _State:
        """Teach the learner the committed sample (with the torque held from it on, MATH §7);
        install a new model or leave the warm-up when a solve says so."""
        ekf = state.ekf
        level = float(self.robot.nv) if ekf.gate.level is None else ekf.gate.level
        # the first solve only ends the warm-up: the nominal model gets its chance with the
        # exact-model densities, and its innovations decide at the next solve
        # (a learned model is refined at every solve; only the nominal one is protected)
        explained = (self.regime == "warmup" and not self._restarted) or (
            self.regime == "nominal" and level <= _NIS_TRUSTED * self.robot.nv
        )
        lr = self._learner
        if math.isnan(lr.next_solve):
            # the reset time; inside never_behind (which is the one reset) the first sample's
            lr.start(float(self._reset_args[0]) if self._reset_args else t)
        if lr.add(t, q, tau, explained=explained, gated=q is None and bool(state.ekf.gate.gated)):
            ekf = self._install(ekf)
            self._restarted = False
        elif self.regime == "nominal" and level > _NIS_REVOKED * self.robot.nv:
            # the nominal model stopped explaining the data between solves: do not wait
            if lr.candidate is not None:
                lr.theta = lr.candidate
                lr.installs += 1
                ekf = self._install(ekf)
            else:
                ekf = self._set_regime(ekf, "warmup")
        elif self._learner.validated and self.regime == "warmup" and not self._restarted:
            # the nominal model explains the data (a learned one, after a restart)
            ekf = self._set_regime(ekf, "learned" if lr.installs else "nominal")
        return state if ekf is state.ekf else state._replace(ekf=ekf)

    def innovation(self, state: _State) -> tuple[float | None, bool]:
        return state.ekf.gate.nis, state.ekf.gate.gated

    def output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q, state.v

    def smoothing_filter(self) -> ExtendedKalmanFilter:
        """None: a smoother runs it causally and replays its learned models frozen
        (:attr:`learns_model`; :func:`pinobs.smooth`).

        Raises:
            OptionError: always.
        """
        raise OptionError(
            "adaptive learns its model: pinobs.smooth runs it causally, then replays its "
            "learned models frozen per window (model_window)"
        )

    @property
    def disturbance(self) -> Vector | None:
        """The EKF's estimated joint-torque offset ``d`` beyond the learned offset [N·m or N]."""
        if self._state is None or self._state.ekf.d is None:
            return None
        return np.array(self._state.ekf.d)

    def covariance(self) -> Vector:
        """The EKF's covariance of ``(δq, δv, δd)`` (before the blend), a copy."""
        if self._state is None:
            return self.core.covariance()  # NaN: not reset
        return np.array(self._state.ekf.P)
