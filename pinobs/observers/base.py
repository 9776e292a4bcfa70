"""What every observer shares: the sampled-data contract and the :class:`Observer` base.

The helpers of the protocol live in modules of their own and are re-exported here:
:mod:`pinobs.observers.checks` (option checks, the pause rule), :mod:`pinobs.observers.gating`
(the outlier gate and NIS), :mod:`pinobs.observers.gaussian` (:class:`GaussianFilter`, what a
smoother runs), :mod:`pinobs.observers.registry` (families by name) and
:mod:`pinobs.observers.results` (:class:`Estimate`, :class:`Consistency`).

The contract (``docs/theory/math.md`` §7).  Samples arrive at times ``t_k``.
The torque passed with ``update(t_k, q_k, τ_k)`` is the one applied *from*
``t_k`` on, held until the next sample (zero-order hold).  So the step to
``t_k`` propagates with the torque stored at the previous call, then corrects
with ``q_k``, then stores ``τ_k``.  ``reset(t0, q0, v0=None, tau0=None)``
stores the first torque (zero if not given).

A family implements only its mathematics, as pure functions of an immutable
state: :meth:`Observer.initial_state`, :meth:`Observer.step` and
:meth:`Observer.output` (optionally :meth:`Observer.restart_state`,
:meth:`Observer.after_commit`, :meth:`Observer.innovation`).  The base validates
every input before anything changes, checks the new estimate is finite, and
commits the new state only then, so a rejected call leaves the observer exactly
as it was.  Those methods are public: a family is driven through them by the
base, by another family (the never-behind blend) and by the smoother, which also
reads what a family declares of itself (:attr:`Observer.smoothable`,
:attr:`Observer.model_free`, :attr:`Observer.learns_model`,
:attr:`Observer.process_density`) and runs the Gaussian filter a smoothable
family gives (:meth:`Observer.smoothing_filter`, a :class:`GaussianFilter`: its
``predict`` and ``correct`` apart, as filterpy's ``KalmanFilter``).
"""

from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod
from collections import deque
from operator import le as _le
from typing import Any, ClassVar, Generic, TypeVar, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import (
    GainError,
    NonFiniteError,
    NotResetError,
    ObserverDiverged,
    OptionError,
    TimestampError,
)
from pinobs.model import Robot
from pinobs.model.robot import read_only
from pinobs.model.sampling import MISSING_PERIODS
from pinobs.observers.blas import one_blas_thread
from pinobs.observers.checks import (
    gap_substeps,
    interval_substeps,
    lost_torque,
    median_period,
    positive,
    propagate_gap,
    time_unit_warning,
)
from pinobs.observers.gating import (
    MAX_GATE_RUN,
    NIS_AVERAGING,
    GateState,
    chi2_quantile,
    gate_nis,
    gate_threshold,
    outlier_gate,
    steady_innovation_variance,
)
from pinobs.observers.gaussian import GaussianFilter
from pinobs.observers.noise import NOISE_MIN_SAMPLES, NOISE_WINDOW
from pinobs.observers.noise_live import learn_noise
from pinobs.observers.registry import make_observer, observer_class, observer_names, register
from pinobs.observers.results import CONSISTENCY_WINDOW, LIKELY_CAUSES, Consistency, Estimate
from pinobs.tolerances import (
    ABSURD_LIMIT_FACTOR,
    ABSURD_VALUE,
    GAP_PERIODS,
    MAX_GAP_PERIODS,
    PAUSE_RESTART,
    TIME_EPS,
)

# (the protocol's helpers live in their own modules and are re-exported here, where they
# were first defined: pinobs.observers.checks, .gating, .gaussian, .noise, .registry, .results)
__all__ = [
    "CONSISTENCY_WINDOW",
    "LIKELY_CAUSES",
    "MAX_GATE_RUN",
    "NIS_AVERAGING",
    "NOISE_FLOOR",
    "NOISE_MIN_SAMPLES",
    "NOISE_WINDOW",
    "Consistency",
    "Estimate",
    "GateState",
    "GaussianFilter",
    "Observer",
    "chi2_quantile",
    "gap_substeps",
    "gate_nis",
    "gate_threshold",
    "make_observer",
    "median_period",
    "observer_class",
    "observer_names",
    "outlier_gate",
    "positive",
    "propagate_gap",
    "register",
    "steady_innovation_variance",
    "time_unit_warning",
]

Vector = NDArray[np.floating[Any]]
State = TypeVar("State")

#: The sample rates [Hz] and position noise levels [rad or m] an observer accepts.
RATE_RANGE = (1e-3, 1e7)
NOISE_STD_RANGE = (1e-12, 1e3)

#: Without ``rate``, the sample period is the median of this many first intervals.
_PERIOD_INTERVALS = 5
#: [rad or m] The σ of noise-free data: the σ a family assumes when built without
#: ``noise_std`` (or with 0), and a σ̂ at or below it is taken for noise-free data
#: (nothing is retuned: the family keeps that default).
NOISE_FLOOR = 1e-6

#: The time types :meth:`Observer.update`'s fast path takes as they are (else ``float(t)``).
_FLOATS = (float, np.float64)
_F64 = np.dtype(np.float64)
_new_object = object.__new__  # an instance without its __init__ (_make_estimate)


class Observer(ABC, Generic[State]):
    """Base class of every observer.

    Args:
        robot: the model the observer uses (copied: the observer owns its ``pin.Data``).
        rate: sensor sample rate [Hz], a hint for default gains.
        noise_std: standard deviation of the position noise [rad or m], a hint
            for default gains.

    Class attributes set by each family:
        name: registry name.
        summary: one line for ``pinobs list`` and the README table.
        uses_torque: whether the observer uses the torque (model-based) or not.
        uses_noise_std: whether it uses ``noise_std`` (gains or NIS).
        noise_in_gains: whether its gains depend on it (else only its NIS).
        smoothable, model_free, learns_model, process_density: what a smoother needs
            to know of the family (each documented below; :meth:`smoothing_filter`).

    **σ from the data, live.**  Built without ``noise_std`` (``None``; ``0``
    means noise-free and is kept), an observer whose gains depend on it starts
    from its family's default σ and keeps its updates for the first
    :data:`NOISE_WINDOW` seconds after :meth:`reset`.  Then it estimates σ
    from those samples (the robust third-difference estimator of
    :func:`pinobs.observers.noise.estimate_noise_std`, median over joints),
    rebuilds itself with ``noise_std = σ̂`` and the same arguments, replays the
    kept updates, and warns once (:class:`~pinobs.errors.NoiseWarning`): from
    then on its estimates are those it would give had σ̂ been passed at
    construction.  Nothing changes when σ̂ ≤ :data:`NOISE_FLOOR` (noise-free
    data) or when its gains were given explicitly.  The replay costs the first
    second's updates once more.  The estimator sees ``h³ x⃛`` too: at low
    rates and fast motions it overestimates σ (noise-free samples of a top
    spinning at 30 rad/s at 100 Hz give 2e-4 rad); pass ``noise_std`` there.

    **Pauses** (MATH §7 holds the torque over a step; a loop that stalls or a dropped row
    makes one step long).  The sample period ``T`` is ``1/rate``, or without ``rate`` the
    median of the first :data:`_PERIOD_INTERVALS` intervals after :meth:`reset`.  A step
    longer than :data:`~pinobs.tolerances.GAP_PERIODS` ``T`` (a model-based one: 1.75 ``T``)
    is propagated in sub-steps of about ``T``, lost torques on the line (:meth:`_stepped`); a pause
    longer than :data:`~pinobs.tolerances.PAUSE_RESTART` s and
    :data:`~pinobs.tolerances.MAX_GAP_PERIODS` ``T`` restarts the state at the next sample
    (:meth:`restart_state`: measured position, zero velocity, what the family learned
    kept), listed in :attr:`pauses`: the log reader's policy (:mod:`pinobs.io.stream`),
    with a restart threshold in seconds, because restarting from zero velocity costs more
    than it saves below ~0.1 s (:meth:`_after_pause`).
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    #: False for model-free observers, which ignore the torque.
    uses_torque: ClassVar[bool] = True
    #: Whether it uses ``noise_std`` at all (σ is then learnt from the data if not given) ...
    uses_noise_std: ClassVar[bool] = False
    #: ... and whether in its gains (else only in ``_sigma2``, its NIS's measurement variance).
    noise_in_gains: ClassVar[bool] = True
    #: Whether a smoother can run it: it keeps an error-state covariance and gives a
    #: :class:`GaussianFilter` (:meth:`smoothing_filter`), or it ``learns_model``.
    smoothable: ClassVar[bool] = False
    #: Whether its process model is kinematic (white jerk: no torque, no robot dynamics).
    model_free: ClassVar[bool] = False
    #: Whether it learns its dynamic model from the data (``adaptive``): a smoother first
    #: runs it causally and then replays its learned models frozen.
    learns_model: ClassVar[bool] = False
    #: The option naming the process-noise density a smoother tunes (``accel_psd="auto"``):
    #: ``"accel_psd"`` [rad²/s³] (white acceleration) or ``"jerk_psd"`` [rad²/s⁵] (white jerk).
    process_density: ClassVar[str] = "accel_psd"
    #: Whether its :meth:`step`, :meth:`output` and :meth:`after_commit` may call a BLAS
    #: (NumPy's or SciPy's matrix algebra): :meth:`update` then runs on one BLAS thread
    #: (:func:`~pinobs.observers.blas.one_blas_thread`, 11–12 µs a call in a paced loop).
    #: A family whose step makes no BLAS call (elementwise NumPy, Pinocchio, a compiled
    #: kernel) sets it ``False`` (a class default; an instance may set its own, as a family
    #: whose step is compiled only on some robots): the limit is not entered and costs
    #: nothing per update.
    uses_blas: bool = True
    #: Whether :meth:`output` returns new float64 arrays at every call, no view of the state:
    #: the estimate keeps them read-only, uncopied (issue 39; ``kf`` with ``"auto"``).
    fresh_output: bool = False
    #: Whether :meth:`update` first offers the call to :meth:`_update_fused` (a family's plain
    #: update in one compiled call: ``kf``'s ``"auto"``, issue 39); a class default.
    _fused_path: bool = False
    _init_args: tuple[tuple[Any, ...], dict[str, Any]]  # set by __new__

    def __new__(cls, *args: Any, **kwargs: Any) -> Observer[Any]:
        self = super().__new__(cls)
        self._init_args = (args, kwargs)  # to rebuild with σ from the data (learn_noise)
        return self

    def __init__(
        self, robot: Robot, *, rate: float | None = None, noise_std: float | None = None
    ) -> None:
        self.robot = robot.copy()
        self.rate = positive("rate", rate, allow_none=True)
        self.noise_std = positive("noise_std", noise_std, allow_none=True, allow_zero=True)
        # beyond these the default gains overflow or divide by zero (raw ZeroDivisionError,
        # OverflowError or LinAlgError deep in a family's gains, a sweep found)
        if self.rate is not None and not RATE_RANGE[0] <= self.rate <= RATE_RANGE[1]:
            raise GainError(
                f"rate={rate!r} Hz is outside [{RATE_RANGE[0]:g}, {RATE_RANGE[1]:g}]: a sensor "
                "sample rate in Hz"
            )
        if self.noise_std and not NOISE_STD_RANGE[0] <= self.noise_std <= NOISE_STD_RANGE[1]:
            raise GainError(
                f"noise_std={noise_std!r} is outside [{NOISE_STD_RANGE[0]:g}, "
                f"{NOISE_STD_RANGE[1]:g}] (or 0, noise-free): a position noise in rad or m"
            )
        self._state: State | None = None
        self._t = -math.inf
        self._tau: Vector = np.zeros(self.robot.nv)
        self._last: Estimate | None = None
        self._nis: deque[float] = deque(maxlen=CONSISTENCY_WINDOW)
        self._gated = 0
        self.latency = 0.0  # [s]; set_latency()
        self._ts = -math.inf  # time of the state (t − latency once delayed samples arrive)
        self._torques: list[tuple[float, Vector]] = []  # (applied from [s], τ), for latency
        # updates (t, q, τ) kept while σ is unknown, for σ from the data; then None
        self._noise_samples: list[tuple[float, Vector | None, Vector]] | None = (
            [] if noise_std is None and self.uses_noise_std else None
        )
        #: the measurement variance σ² [rad² or m²] of a family's NIS (:attr:`noise_std_used`)
        self._sigma2 = self.noise_std_used**2
        self._reset_args: tuple[Any, ...] = ()
        self._diverged = False  # the latest update diverged (its state was not kept)
        self._intervals: list[float] = []  # the first intervals after the reset (the period)
        self._tau_floor = float(np.min(self.robot.absurd_torque)) if self.robot.nv else 0.0
        # the shapes update's fast path takes (Robot.nq/nv ask Pinocchio): q's on a vector
        # space or a Robot (its unit-norm blocks then normalised), neither when empty
        nq, nv = self.robot.nq, self.robot.nv
        self._units = isinstance(self.robot, Robot) and not self.robot.is_vector_space
        fast_q = (self.robot.is_vector_space or self._units) and nq
        self._shapes = ((nq if fast_q else -1,), (nv if nv else -1,))
        self._set_period(None if self.rate is None else 1.0 / self.rate)  # (_sample_period)
        self._intervals_due = self.rate is None
        self._restart_due = False  # a pause without a sample: restart at the next one
        self._pauses: list[tuple[float, float]] = []
        # whether the family overrides after_commit / innovation: else update skips the
        # call (the default returns the state) / reads the state's gate inline (issue 39)
        family = type(self)
        self._commits = family.after_commit is not Observer.after_commit
        self._own_innovation = family.innovation is not Observer.innovation

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.robot.name!r})"

    @property
    def noise_std_used(self) -> float:
        """The position noise σ [rad or m] a family's gains and NIS take: ``noise_std``, or
        :data:`NOISE_FLOOR` when it was not given or is 0 (noise-free)."""
        return self.noise_std or NOISE_FLOOR

    # ----------------------------------------------------------- public API
    @final
    @one_blas_thread  # small matrices: threads only contend (observers/blas.py)
    def reset(
        self,
        t0: float,
        q0: ArrayLike,
        v0: ArrayLike | None = None,
        tau0: ArrayLike | None = None,
    ) -> Estimate:
        """Start (or restart) the observer at time ``t0`` [s] from ``q0`` (and ``v0``, zero if not given).

        ``tau0`` is the torque applied from ``t0`` on (zero if not given).
        """
        t = self._check_time(t0, previous=None)
        q = self.robot.check_configuration(q0, what="q0")
        v = (
            np.zeros(self.robot.nv)
            if v0 is None
            else self.robot.check_vector(v0, self.robot.nv, what="v0")
        )
        tau = self._check_tau(tau0, what="tau0")
        state = self.initial_state(q, v)
        estimate = self._make_estimate(t, state)
        self._state, self._t, self._tau, self._last = state, t, tau, estimate
        self._ts, self._torques = t, [(t, tau)]
        self._nis.clear()
        self._gated = 0
        self._diverged = False
        self._intervals, self._restart_due, self._pauses = [], False, []
        self._set_period(None if self.rate is None else 1.0 / self.rate)
        self._intervals_due = self.rate is None
        # copies: a loop that reuses its buffers must not change what σ's replay starts from
        # (a sweep found adaptive 0.12 rad/s off after a replay from a reused v0 buffer)
        self._reset_args = (
            t,
            q.copy(),
            None if v0 is None else v.copy(),
            None if tau0 is None else tau.copy(),
        )
        if self._noise_samples is not None:
            self._noise_samples = []  # σ from the samples after this reset
        return estimate

    @final
    def update(self, t: float, q_meas: ArrayLike | None, tau: ArrayLike | None = None) -> Estimate:
        """Advance to time ``t`` [s] and correct with the measured configuration.

        Args:
            t: sample time [s], strictly after the previous one.
            q_meas: measured configuration, shape ``(nq,)``; ``None`` means no
                sample this tick (the observer only propagates).
            tau: joint torque [N·m or N] applied from ``t`` on (zero-order
                hold), shape ``(nv,)``; ``None`` means zero.

        **A pause** (class docstring, **Pauses**): a step longer than :data:`GAP_PERIODS` sample
        periods is propagated in sub-steps of at most one period; after one longer than
        :data:`PAUSE_RESTART` s (and :data:`MAX_GAP_PERIODS` periods) the state restarts at
        the sample (:meth:`pauses`).

        Raises:
            NotResetError: ``reset`` was never called.
            TimestampError: ``t`` is not finite or not after the previous time.
            DimensionError, NonFiniteError, ConfigurationError: bad ``q_meas`` or ``tau``
                (a torque beyond :data:`ABSURD_LIMIT_FACTOR` times the effort limit included).
            ObserverDiverged: the estimate became non-finite (state kept as it was).

        On one BLAS thread for the call if the family :attr:`uses_blas` (the caller's
        thread counts restored after), else straight; first, where the family has one, its
        fused path (:meth:`_update_fused`).
        """
        if self._fused_path and (estimate := self._update_fused(t, q_meas, tau)) is not None:
            return estimate
        if self.uses_blas:
            return self._update_on_one_thread(t, q_meas, tau)
        return self._update(t, q_meas, tau)

    def _update_fused(
        self, t: float, q_meas: ArrayLike | None, tau: ArrayLike | None
    ) -> Estimate | None:
        """:meth:`update` done whole by the family (where :attr:`_fused_path`), or ``None``: then
        nothing changed and :meth:`update` goes its own way.  The family's fast path must give
        what that way gives, to the bit, and leave to it every update it does not take."""
        return None

    def _update(self, t: float, q_meas: ArrayLike | None, tau: ArrayLike | None) -> Estimate:
        """:meth:`update` (its docstring), on the caller's BLAS threads."""
        if self._state is None:
            raise NotResetError(f"{self!r}: call reset(t0, q0) before update()")
        t_new, q, tau_new = self._inputs(t, q_meas, tau)
        ts_before = self._ts
        dt = t_new - self._t
        if self._intervals_due:
            self._sample_period(dt)
        if dt > self._span:  # a pause (class docstring): restart at the next sample
            self._restart_due = True
        if self._restart_due and q is not None:
            state, t_state, estimate = self._after_pause(t_new, q, dt)
        elif self.latency > 0.0:
            state, t_state, estimate = self._delayed(t_new, q, tau_new)
        else:
            # MATH §7: propagate with the torque held since the previous call, then correct
            # (in sub-steps over dropped samples or past GAP_PERIODS periods: _stepped)
            if dt >= self._split:
                state = self._stepped(self._state, dt, q, self._tau, tau_new)
            else:
                state = self.step(self._state, dt, q, self._tau)
            t_state = t_new
            estimate = self._make_estimate(t_new, state)
        s = sum(estimate.q.tolist()) + sum(estimate.v.tolist())
        if not s - s == 0.0:  # not finite (as math.isfinite: a call less)
            self._check_finite(estimate, t_new, dt)  # entry by entry: a sum can overflow to inf
        self._diverged = False
        self._state, self._t, self._tau, self._last = state, t_new, tau_new, estimate
        self._ts = t_state
        # without a latency the state is at t_new and only tau_new matters from there on
        # (_delayed rebuilds _torques from _t and _tau when the state is at _t)
        held = self._keep_torques(t_state, t_new, tau_new) if self.latency > 0.0 else tau_new
        used = q if t_state > ts_before + TIME_EPS and not estimate.gated else None
        self._state = self.after_commit(state, t_state, used, held) if self._commits else state
        if estimate.nis is not None:
            self._nis.append(estimate.nis)
            self._gated += estimate.gated
        if self._noise_samples is not None and learn_noise(self, t_new, q, tau_new, NOISE_FLOOR):
            return self.estimate  # rebuilt with σ from the data, replayed up to t_new
        return estimate

    def _keep_torques(self, t_state: float, t_new: float, tau_new: Vector) -> Vector:
        """Under a latency: keep the torques applied since the state's time ``t_state`` (for
        the next steps) with ``tau_new`` applied from ``t_new``; the torque held at ``t_state``."""
        self._torques = [
            x
            for i, x in enumerate(self._torques)
            if i + 1 == len(self._torques) or self._torques[i + 1][0] > t_state
        ] + [(t_new, tau_new)]
        return next(x for tk, x in reversed(self._torques) if tk <= t_state + TIME_EPS)

    def _inputs(
        self, t: float, q_meas: ArrayLike | None, tau: ArrayLike | None
    ) -> tuple[float, Vector | None, Vector]:
        """:meth:`update`'s inputs checked: ``(t, q or None, τ)``, fresh arrays.

        One test for the usual call (issue 39: the checks cost 3× one ``pin.aba`` an update on a
        UR5): a ``float`` time after the previous one, ``q`` and ``τ`` float64 arrays of the right
        shapes (or ``None``) whose Python sum with the time is finite (then every entry is), τ
        within ``±`` the smallest joint's bound (or each joint's own, in plain Python: 1 against
        2 µs on a talos): copied, ``q``'s unit-norm blocks normalised (``Robot.normalized_units``,
        on a :class:`Robot`).  Else :meth:`_check_time`, ``Robot.check_configuration``, :meth:`_check_tau`."""
        sq, st = self._shapes
        if (
            type(t) in _FLOATS
            and (tau is None or (type(tau) is np.ndarray and tau.dtype is _F64 and tau.shape == st))
            and (q_meas is None or (type(q_meas) is np.ndarray and q_meas.dtype is _F64))
            and (q_meas is None or q_meas.shape == sq)
        ):
            x = float(t)  # (before comparing: a np.float64 compares through NumPy's scalars)
            lst = () if tau is None else tau.tolist()
            s = x + sum(lst) + (0.0 if q_meas is None else sum(q_meas.tolist()))
            f = self._tau_floor
            if (
                s - s == 0.0  # finite
                and self._t + TIME_EPS < x
                and (
                    tau is None
                    or (-f <= min(lst) and max(lst) <= f)
                    # joint by joint (a free-flyer's weight is past a wrist's bound): 2 against 7 µs
                    or all(map(_le, map(abs, lst), self.robot.absurd_torque_list))
                )
            ):
                q = None if q_meas is None else q_meas.copy()
                if q is not None and self._units:  # (check_configuration's last step only)
                    q = self.robot.normalized_units(q, what="q_meas")
                return x, q, self._check_tau(None, what="tau") if tau is None else tau.copy()
        t_new = self._check_time(t, previous=self._t)
        q = None if q_meas is None else self.robot.check_configuration(q_meas, what="q_meas")
        return t_new, q, self._check_tau(tau, what="tau")

    def _check_finite(self, estimate: Estimate, t_new: float, dt: float) -> None:
        """:class:`ObserverDiverged` if ``estimate`` (at ``t_new``, ``dt`` after the previous
        one) has a non-finite entry, checked entry by entry (the sums :meth:`_update` checks
        first can overflow to inf on a finite estimate)."""
        if not (np.all(np.isfinite(estimate.q)) and np.all(np.isfinite(estimate.v))):
            self._diverged = True
            why = (
                f"predicted through a pause of {dt:.6g} s without a sample (the next sample "
                "restarts it)"
                if self._restart_due
                else "check the model and the torques (or the gains); reset(t, q) starts it afresh"
            )
            raise ObserverDiverged(
                f"{self!r} diverged at t = {t_new:.6g} s (non-finite estimate); "
                f"the last finite estimate is at t = {self._t:.6g} s, kept: {why}.",
                t=t_new,
                last_estimate=self._last,
            )

    _update_on_one_thread = one_blas_thread(_update)  # small matrices: threads only contend

    def _sample_period(self, dt: float) -> float | None:
        """The sample period [s]: ``1/rate``, or (none given) the median of the first
        :data:`_PERIOD_INTERVALS` intervals after the reset (``None`` until three are in)."""
        if self.rate is None and len(self._intervals) < _PERIOD_INTERVALS:
            self._intervals.append(dt)
            if len(self._intervals) >= 3:  # computed five times at most, not at every update
                self._set_period(float(np.median(self._intervals)))
        self._intervals_due = self.rate is None and len(self._intervals) < _PERIOD_INTERVALS
        return self._period_s

    def _set_period(self, period: float | None) -> None:
        """The sample period [s] (``None``: not known yet) and what follows from it, computed
        once: the longest step propagated in sub-steps before a restart (:meth:`_stepped`)."""
        self._period_s = period
        self._span = math.inf if period is None else max(PAUSE_RESTART, MAX_GAP_PERIODS * period)
        self._gap = math.inf if period is None else GAP_PERIODS * period  # sub-steps beyond
        missing = MISSING_PERIODS * (period or math.inf) if self.uses_torque else math.inf
        self._split = min(self._gap, missing)  # sub-steps from (and over dropped samples)

    def _stepped(
        self, state: State, dt: float, q: Vector | None, tau: Vector, tau_b: Vector | None = None
    ) -> State:
        """:meth:`step` over ``dt`` in sub-steps: of at most one period past :data:`GAP_PERIODS`
        periods (a step of 10 s gave 1e74 rad/s from ``ekf``; past ``PAUSE_RESTART``: restarted)
        and, for a model-based family given ``tau_b`` (the torque ending the interval), one per
        dropped sample (MATH §7, **Dropped samples**: :func:`interval_substeps`), with the lost
        torques on the line from ``tau`` to ``tau_b`` (:func:`lost_torque`), else ``tau`` held."""
        n = self._substeps(dt, tau_b)
        if n == 1:
            return self.step(state, dt, q, tau)
        b = tau if tau_b is None else tau_b
        for j in range(n - 1):
            state = self.step(state, dt / n, None, lost_torque(tau, b, j, n))
        return self.step(state, dt / n, q, lost_torque(tau, b, n - 1, n))

    def _substeps(self, dt: float, tau_b: Vector | None) -> int:
        """The sub-steps of a step of ``dt`` [s]: one per sample the loop dropped for a
        model-based family given the torque ``tau_b`` ending it (:func:`interval_substeps`),
        else the pause rule (:func:`gap_substeps`)."""
        sub = interval_substeps if tau_b is not None and self.uses_torque else gap_substeps
        return sub(dt, self._period_s, span=self._span)

    def _after_pause(self, t_new: float, q: Vector, dt: float) -> tuple[State, float, Estimate]:
        """After a pause: the state afresh at the sample (its position, zero velocity; what the
        family learned is kept: :meth:`restart_state`), ``(state, its time, estimate at
        t_new)``.  Measured on a UR5 log (1 kHz, σ = 1e-4 rad, PD input), ``ekf``'s error at
        the first sample / 50 ms / RMS over 1 s after a pause: 0.2 s: 0.54 / 0.44 / 0.2
        rad/s propagated, 0.88 / 1.3e-3 / 0.04 restarted; 1 s: 16 / 12 / 5.5 against 1.2 /
        1.4e-3 / 0.056; after 12–50 ms, propagating is as good or better (0.002–0.033 at the
        first sample against 1.2–1.3), hence the restart only beyond ``PAUSE_RESTART``."""
        assert self._state is not None
        t_state = t_new - self.latency
        state = self.restart_state(self._state, q)
        self._restart_due = False
        self._pauses.append((t_new, dt))
        if t_state < t_new - TIME_EPS:  # a latency: the estimate at t_new, predicted ahead
            self._torques = [(min(self._t, t_state), self._tau)]  # held through the pause
            ahead = self._advance(state, t_state, t_new, None)
        else:
            t_state, ahead = t_new, state
        q_hat, v_hat = self.output(ahead)
        return state, t_state, Estimate(t=t_new, q=read_only(q_hat), v=read_only(v_hat))

    @property
    def pauses(self) -> list[tuple[float, float]]:
        """``(t, pause [s])`` of each update since the reset at which the state restarted
        after a pause (:meth:`update`)."""
        return list(self._pauses)

    @property
    def estimate(self) -> Estimate:
        """The latest estimate."""
        if self._last is None:
            raise NotResetError(f"{self!r}: call reset(t0, q0) first")
        return self._last

    def set_latency(self, latency: float) -> None:
        """Declare a known measurement latency [s]: the sample given at ``t`` was taken at ``t − latency``.

        The state is then kept at the measurement time: each update propagates
        it from the previous measurement time to ``t − latency`` with the
        torques that were applied over that interval (their own stamps, zero-
        order hold), corrects it with the sample, and delivers the estimate at
        ``t`` by predicting it ``latency`` ahead with the torques applied since
        (a prediction that is not kept).  Up to three model steps per update.
        A sample taken before the state's time is not used.  Must be called
        before the first :meth:`update` after a reset (refused after: changed mid-run, 3 → 0
        ms, it gave a ``kf`` a 0.70 rad/s transient, against 0.02 for a fresh observer).
        """
        positive("latency", latency, allow_zero=True)
        if self._state is not None and self._t != self._reset_args[0]:
            raise OptionError(
                f"{self!r}: set_latency({latency!r}) after updates; call it before the first "
                "update (reset(t, q) first to start again with it)"
            )
        self.latency = float(latency)

    def _advance(self, state: State, t_from: float, t_to: float, q: Vector | None) -> State:
        """Propagate ``state`` from ``t_from`` to ``t_to`` through the torque history, correcting with ``q`` at the end."""
        cuts = [
            t_from,
            *(tk for tk, _ in self._torques if t_from + TIME_EPS < tk < t_to - TIME_EPS),
        ]
        cuts.append(t_to)
        for i, (a, b) in enumerate(itertools.pairwise(cuts)):
            tau = next(tk_tau for tk, tk_tau in reversed(self._torques) if tk <= a + TIME_EPS)
            last = i == len(cuts) - 2
            state = self._stepped(state, b - a, q if last else None, tau)
        return state

    def _delayed(
        self, t_new: float, q: Vector | None, tau_new: Vector
    ) -> tuple[State, float, Estimate]:
        """One update under a known latency (:meth:`set_latency`): ``(state, its time, estimate
        at t_new)``.  Over dropped samples (MATH §7, **Dropped samples**; :meth:`_substeps`) a
        model-based family predicts through each lost tick ``t_j`` as an update without a
        sample would: to ``t_j − latency``, then its torque (:func:`lost_torque`) from ``t_j``."""
        assert self._state is not None
        if self._ts >= self._t - TIME_EPS:  # the state at the last sample (after a reset, or
            self._torques = [(self._t, self._tau)]  # updates without a latency): its torque
        s = t_new - self.latency
        state, t_state, dt = self._state, self._ts, t_new - self._t
        n = self._substeps(dt, tau_new) if self.uses_torque and dt >= self._split else 1
        for j in range(1, n):  # the lost ticks, as updates without a sample
            t_j = self._t + (j / n) * dt
            if t_j - self.latency > t_state + TIME_EPS:
                state = self._advance(state, t_state, t_j - self.latency, None)
                t_state = t_j - self.latency
            self._torques.append((t_j, lost_torque(self._tau, tau_new, j, n)))
        if s > t_state + TIME_EPS:
            state, t_state = self._advance(state, t_state, s, q), s
        # (else the sample predates the state: the state kept)
        ahead = self._advance(state, t_state, t_new, None) if t_new > t_state + TIME_EPS else state
        q_hat, v_hat = self.output(ahead)
        nis, gated = (
            self.innovation(state) if s > self._ts + TIME_EPS and q is not None else (None, False)
        )
        estimate = Estimate(t=t_new, q=read_only(q_hat), v=read_only(v_hat), nis=nis, gated=gated)
        return state, t_state, estimate

    def consistency(self) -> Consistency:
        """Whether the model explains the recent data (see :class:`Consistency`)."""
        n = len(self._nis)
        dof = float(self.robot.nv)
        bound = 1.5 * (dof + 5.0 * math.sqrt(2.0 * dof / max(n, 1)))
        if n == 0:
            return Consistency(0, math.nan, dof, bound, "unknown", self._gated)
        mean = float(np.mean(self._nis))
        if n < 50:
            verdict = "unknown"
        else:  # a NIS that is not finite or below 0 is a filter being lost, not a small one
            sane = math.isfinite(mean) and min(self._nis) >= 0.0
            verdict = "consistent" if sane and mean <= bound else "inconsistent"
        causes = LIKELY_CAUSES if verdict == "inconsistent" else ()
        return Consistency(n, mean, dof, bound, verdict, self._gated, causes)

    @property
    def options(self) -> dict[str, Any]:
        """The resolved options (gains chosen from ``rate``/``noise_std`` included), for reports."""
        return {"rate": self.rate, "noise_std": self.noise_std}

    # ------------------------------------------------------ family interface
    # The protocol every family implements (module docstring): pure functions of an
    # immutable state, called by :meth:`update`, by another family (the never-behind blend)
    # and by the smoother.
    @abstractmethod
    def initial_state(self, q0: Vector, v0: Vector) -> State:
        """The state at reset, ``q0`` [nq] and ``v0`` [nv].  Must not keep references to
        mutable inputs."""

    def restart_state(self, state: State, q: Vector) -> State:
        """The state restarted at ``q`` with zero velocity after a pause (:meth:`update`);
        a family that learns (``adaptive``) keeps what it learned."""
        return self.initial_state(q, np.zeros(self.robot.nv))

    @abstractmethod
    def step(self, state: State, dt: float, q_meas: Vector | None, tau: Vector) -> State:
        """Propagate ``state`` over ``dt`` [s] with torque ``tau`` held, then correct with ``q_meas``.

        Must return a new state and leave ``state`` and the observer untouched: what it
        learns or counts (a restart) goes into the new state, read from :attr:`_state`, the
        latest committed one; only working memory (``pin.Data``, ``_scratch*`` buffers, memo
        caches) may change (``tests/observers/test_purity.py``).
        """

    @abstractmethod
    def output(self, state: State) -> tuple[Vector, Vector]:
        """``(q̂, v̂)`` of a state."""

    def after_commit(self, state: State, t: float, q: Vector | None, tau: Vector) -> State:
        """Called once a state is committed: ``t`` its time, ``q`` the sample it used (``None``
        if none or gated), ``tau`` the torque applied from ``t`` on.  Families that learn from
        the data do it here (never in :meth:`step`, which also runs for predictions that are
        not kept); may return a replacement state.  Default: the state unchanged (and
        :meth:`update` then skips the call: override it in the class)."""
        return state

    def adopt(self, state: State) -> None:
        """Hold ``state`` as this observer's committed state, when a wrapper steps it (as
        :class:`~pinobs.observers.neverbehind.NeverBehind` does): what is read of the
        observer (its covariance, what it learned) then comes from that state."""
        self._state = state

    def innovation(self, state: State) -> tuple[float | None, bool]:
        """``(NIS, gated)`` of the measurement that made ``state``: its :class:`GateState`
        ``gate`` (families with an innovation), else ``(None, False)``."""
        gate: GateState | None = getattr(state, "gate", None)
        return (None, False) if gate is None else (gate.nis, gate.gated)

    def smoothing_filter(self) -> GaussianFilter:
        """The Gaussian filter a smoother runs for this family (:class:`GaussianFilter`),
        for a :attr:`smoothable` family that does not :attr:`learns_model`.

        Raises:
            OptionError: the family keeps no error-state covariance to smooth.
        """
        raise OptionError(
            f"observer {self.name!r} keeps no error-state covariance to smooth; smoothable: "
            f"{[n for n in observer_names() if observer_class(n).smoothable]}"
        )

    # -------------------------------------------------------------- helpers
    def _make_estimate(self, t: float, state: State) -> Estimate:
        """The estimate of ``state`` at ``t``: :meth:`output` copied read-only (as
        ``read_only``; a float64 array by its own ``copy``, cheaper; not copied if the family's
        output is :attr:`fresh_output`) and :meth:`innovation`."""
        q, v = self.output(state)
        if self._own_innovation:
            nis, gated = self.innovation(state)
        else:  # Observer.innovation, inline (issue 39: a call less at every update)
            gate: GateState | None = getattr(state, "gate", None)
            nis, gated = (None, False) if gate is None else (gate.nis, gate.gated)
        if not self.fresh_output:
            q = q.copy() if type(q) is np.ndarray and q.dtype is _F64 else np.array(q, dtype=float)
            v = v.copy() if type(v) is np.ndarray and v.dtype is _F64 else np.array(v, dtype=float)
        q.setflags(write=False)
        v.setflags(write=False)
        # Estimate(t, q, v, nis, gated) without its __init__'s call: the fields written into
        # the instance's dict, as that __init__ does (tests/observers/test_update_path.py)
        estimate = _new_object(Estimate)
        d = estimate.__dict__
        d["t"], d["q"], d["v"], d["nis"], d["gated"] = t, q, v, nis, gated
        return estimate

    def _check_tau(self, tau: ArrayLike | None, *, what: str) -> Vector:
        if tau is None:
            return np.zeros(self.robot.nv)
        arr = self.robot.check_vector(tau, self.robot.nv, what=what)
        bound = self.robot.absurd_torque
        # as the log reader's screening (a 1e9 spike sent ekf to 1e23 rad/s, then diverged);
        # a plain-Python test of the largest |τ| against the smallest bound first (cheap)
        if max(map(abs, arr.tolist())) > self._tau_floor and np.any(np.abs(arr) > bound):
            i = int(np.argmax(np.abs(arr) > bound))
            raise NonFiniteError(
                f"{what}[{i}] = {arr[i]:.6g} is beyond {ABSURD_LIMIT_FACTOR:g}× the effort "
                f"limit ({bound[i] / ABSURD_LIMIT_FACTOR:.6g}; {ABSURD_VALUE:g} without one): "
                "absurd, refused (the observer is unchanged)"
            )
        return arr

    @staticmethod
    def _check_time(t: float, *, previous: float | None) -> float:
        try:
            x = float(t)
        except (TypeError, ValueError) as exc:
            raise TimestampError(f"time {t!r} is not a number") from exc
        if not math.isfinite(x):
            raise TimestampError(f"time {t!r} is not finite")
        if previous is not None and not x > previous + TIME_EPS:
            raise TimestampError(
                f"time t = {x!r} s is not after the previous sample at t = {previous!r} s; "
                "timestamps must be strictly increasing"
            )
        return x
