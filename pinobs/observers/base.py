"""What every observer shares: the sampled-data contract, input checks, the registry.

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

import copy
import functools
import inspect
import itertools
import math
import numbers
import warnings
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any, ClassVar, Generic, NamedTuple, Protocol, TypeVar, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import (
    GainError,
    NoiseWarning,
    NonFiniteError,
    NotResetError,
    ObserverDiverged,
    OptionError,
    TimestampError,
    UnknownNameError,
)
from pinobs.model import Robot
from pinobs.model.robot import read_only
from pinobs.observers.blas import one_blas_thread
from pinobs.observers.noise import estimate_noise_std
from pinobs.tolerances import (
    ABSURD_LIMIT_FACTOR,
    ABSURD_VALUE,
    GAP_PERIODS,
    MAX_GAP_PERIODS,
    MAX_PLAUSIBLE_PERIOD,
    MIN_PLAUSIBLE_PERIOD,
    PAUSE_RESTART,
    TIME_EPS,
)

__all__ = [
    "NOISE_FLOOR",
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
    "register",
    "steady_innovation_variance",
    "time_unit_warning",
]

Vector = NDArray[np.floating[Any]]
State = TypeVar("State")

#: Seconds of samples (and at least :data:`NOISE_MIN_SAMPLES`) from which an
#: observer built without ``noise_std`` estimates σ (:class:`Observer`).
NOISE_WINDOW = 1.0
NOISE_MIN_SAMPLES = 200

#: The sample rates [Hz] and position noise levels [rad or m] an observer accepts.
RATE_RANGE = (1e-3, 1e7)
NOISE_STD_RANGE = (1e-12, 1e3)

#: Without ``rate``, the sample period is the median of this many first intervals.
_PERIOD_INTERVALS = 5
#: [rad or m] The σ of noise-free data: the σ a family assumes when built without
#: ``noise_std`` (or with 0), and a σ̂ at or below it is taken for noise-free data
#: (nothing is retuned: the family keeps that default).
NOISE_FLOOR = 1e-6


@dataclass(frozen=True)
class Estimate:
    """An observer's estimate at one time.

    Attributes:
        t: time [s].
        q: estimated configuration, shape ``(nq,)`` (read-only).
        v: estimated velocity, shape ``(nv,)`` (read-only), Pinocchio's tangent frame.
        nis: normalized innovation squared ``eᵀ S⁻¹ e`` of this sample's
            measurement (``S`` the predicted innovation covariance; χ² with
            ``nv`` degrees of freedom when the model and noise level are
            right), or ``None`` (no covariance, or no measurement).
        gated: the measurement was rejected as an outlier (the estimate is the prediction).
    """

    t: float
    q: Vector
    v: Vector
    nis: float | None = None
    gated: bool = False


@dataclass(frozen=True)
class Consistency:
    """Does the model explain the data?  A windowed test of the normalized innovation squared.

    Over the last ``samples`` measurements the mean NIS of a consistent filter
    is χ²(n·nv)/n: expectation ``expected`` (= nv), standard deviation
    ``√(2 nv / n)``.  ``verdict`` is ``"consistent"`` below ``bound`` (the
    expectation plus five standard deviations, plus 50 %: filters are tuned,
    not exact), ``"inconsistent"`` above it, ``"unknown"`` without a covariance
    or with fewer than 50 samples.

    Attributes:
        samples: measurements in the window.
        mean_nis: their mean NIS (NaN if none).
        expected: its expectation for a consistent filter (``nv``).
        bound: the threshold of the verdict.
        verdict: ``"consistent"``, ``"inconsistent"`` or ``"unknown"``.
        gated: measurements rejected as outliers since the reset.
        causes: what usually makes a model-based filter inconsistent (when it is).
        details: family-specific diagnostics (an adaptive observer's learning).
    """

    samples: int
    mean_nis: float
    expected: float
    bound: float
    verdict: str
    gated: int = 0
    causes: tuple[str, ...] = ()
    details: dict[str, Any] = field(default_factory=dict)

    def messages(self, name: str) -> list[str]:
        """What to tell of observer ``name``: a ``warning:`` line when the model does not
        explain the data, a ``note:`` line when outlier samples were rejected."""
        out = []
        if self.verdict == "inconsistent":
            out.append(
                f"warning: {name}: the model does not explain the data (mean NIS "
                f"{self.mean_nis:.3g} over the last {self.samples} samples, expected "
                f"{self.expected:g}); check " + "; ".join(self.causes)
            )
        if self.gated:
            out.append(f"note: {name} rejected {self.gated} outlier sample(s)")
        return out

    def as_dict(self) -> dict[str, Any]:
        """Plain values, for JSON."""
        return {
            "samples": self.samples,
            "mean_nis": self.mean_nis,
            "expected": self.expected,
            "bound": self.bound,
            "verdict": self.verdict,
            "gated": self.gated,
            "causes": list(self.causes),
            **self.details,
        }


#: What to check when a model-based filter's innovations are too large (Consistency.causes).
LIKELY_CAUSES = (
    "link masses or inertias (a payload, CAD values): try `pinobs identify` or the adaptive observer",
    "joint friction not in the model (URDF <dynamics>, load(..., friction=True))",
    "torque units or scale (gear ratios, motor constants, N·m vs mN·m), or a torque offset",
    "a measurement latency (give latency= if it is known)",
    "the noise level (noise_std smaller than the sensor's)",
)

#: Measurements in the consistency window.
CONSISTENCY_WINDOW = 1000

#: Consecutive measurements the outlier gate may reject before it accepts one whatever its NIS.
MAX_GATE_RUN = 1

#: Weight of each accepted NIS in the running mean that scales the gate.
NIS_AVERAGING = 0.01


def chi2_quantile(dof: int, p: float) -> float:
    """The χ² quantile with upper tail ``p`` by Wilson-Hilferty (above the exact one: +4 % at dof 6, +15 % at dof 1, p = 1e-6).

    ``χ²_k(1 − p) ≈ k (1 − 2/(9k) + z √(2/(9k)))³``, ``z`` the normal quantile
    (Wilson & Hilferty 1931); the standard library's ``NormalDist`` keeps
    ``scipy.stats`` out of the import.
    """
    z = NormalDist().inv_cdf(1.0 - p)
    c = 2.0 / (9.0 * dof)
    return float(dof * (1.0 - c + z * math.sqrt(c)) ** 3)


def gate_threshold(outlier_probability: float | None, dof: int) -> tuple[float | None, float]:
    """Validate the ``outlier_probability`` option: ``(p, χ²_dof(1 − p))``; ``(None, inf)`` switches
    the gate off.

    Raises:
        GainError: ``p`` not a number in (0, 0.5).
    """
    p = positive("outlier_probability", outlier_probability, allow_none=True)
    if p is None:
        return None, math.inf
    if p >= 0.5:
        raise GainError(f"outlier_probability={p!r} must be in (0, 0.5) (or None: no gate)")
    return p, chi2_quantile(dof, p)


def gate_nis(threshold: float, level: float | None, dof: int) -> float:
    """The NIS above which :func:`outlier_gate` rejects a measurement at ``level``
    (``threshold · max(1, NIS̄ / dof)``; ``level`` ``None``: ``dof``)."""
    return threshold * max(1.0, (float(dof) if level is None else level) / dof)


def outlier_gate(
    nis: float, level: float | None, run: int, threshold: float, dof: int
) -> tuple[bool, float]:
    """The outlier gate of the filters with an innovation covariance: ``(reject, new level)``.

    A measurement whose NIS exceeds ``threshold · max(1, NIS̄ / dof)`` is
    rejected (``NIS̄`` = ``level``, a running mean of accepted NIS, so a filter
    whose model is off does not reject everything), unless :data:`MAX_GATE_RUN`
    were rejected in a row (``run``): then it is accepted whatever its NIS (a
    real jump, or a prediction gone wrong, not a spike) and the level raised
    to it.  Measured: with ten allowed rejections, a Panda whose model has
    stiff Coulomb friction lost track (prediction errors near v = 0 were
    gated while the prediction drifted); with one it does not.
    """
    lvl = float(dof) if level is None else level
    if nis > gate_nis(threshold, lvl, dof) and run < MAX_GATE_RUN:
        return True, lvl
    if run >= MAX_GATE_RUN:  # the prediction was off, not the sample: adapt the gate
        lvl = max(lvl, nis * dof / threshold)
    return False, lvl + NIS_AVERAGING * (min(nis, 100.0 * lvl) - lvl)


class GateState(NamedTuple):
    """The outlier gate's bookkeeping, carried in the state of every family with an innovation.

    One definition for every filter (``ekf``, ``kf``, ``kalman``, ``riemannian``,
    ``liegroup``, ``ii``; ``adaptive`` through its ``ekf``): a family computes its NIS
    ``eᵀ S⁻¹ e`` (its own ``e`` and ``S``) and calls :meth:`measured`, or :meth:`predicted`
    at a step without a sample; the base reads ``nis`` and ``gated`` of the committed
    state (:meth:`Observer.innovation`: :attr:`Estimate.nis`, :meth:`Observer.consistency`).

    Attributes:
        nis: normalized innovation squared of the last measurement (``None``: none).
        gated: that measurement was rejected as an outlier (the state is the prediction).
        run: measurements rejected in a row.
        level: running mean of accepted NIS (scales the gate; ``None``: none yet, ``dof``).
    """

    nis: float | None = None
    gated: bool = False
    run: int = 0
    level: float | None = None

    def measured(self, nis: float, threshold: float, dof: int) -> GateState:
        """After a measurement of normalized innovation squared ``nis``: the gate's decision
        (:func:`outlier_gate`, ``threshold`` from :func:`gate_threshold`, ``dof`` degrees of
        freedom) and its bookkeeping.  ``gated``: the family must not use the measurement."""
        reject, level = outlier_gate(nis, self.level, self.run, threshold, dof)
        return GateState(nis, reject, self.run + 1 if reject else 0, level)

    def predicted(self) -> GateState:
        """After a step without a measurement: no NIS, not gated, the run and level kept."""
        return GateState(None, False, self.run, self.level)

    def limit(self, threshold: float, dof: int) -> float:
        """The NIS above which the gate rejects at this level (:func:`gate_nis`)."""
        return gate_nis(threshold, self.level, dof)


@functools.lru_cache(maxsize=64)
def steady_innovation_variance(k1: float, k2: float, h: float, meas_var: float) -> float:
    """Innovation variance of a fixed-gain observer of a double integrator, noise-driven, at steady state.

    One tangent direction, error ``e = (δq, δv)``, a sample every ``h`` [s] with
    noise of variance ``meas_var`` [rad²], the correction ``e⁺ = e⁻ − K (δq⁻ − n)``
    with the observer's own gains ``K = (k1, k2)`` [1, 1/s], the prediction
    ``e⁻ = D e``, ``D = [[1, h], [0, 1]]`` (no process noise: an exact model)::

        P = A P Aᵀ + meas_var K Kᵀ,   A = (I − K H) D,   H = [1 0]      (discrete Lyapunov)
        S = (D P Dᵀ)₀₀ + meas_var

    (solved as ``(I − A ⊗ A) vec P = meas_var vec(K Kᵀ)``).  The innovation
    ``δq⁻ − n`` is then Gaussian with variance ``S``, so ``|e|²/S`` over ``nv``
    such directions is χ²(nv).  ``inf`` if ``A`` is not stable (no steady state).
    """
    D = np.array([[1.0, h], [0.0, 1.0]])
    K = np.array([[k1], [k2]])
    A = (np.eye(2) - K @ np.array([[1.0, 0.0]])) @ D
    if not float(np.max(np.abs(np.linalg.eigvals(A)))) < 1.0:
        return math.inf
    vec_p = np.linalg.solve(np.eye(4) - np.kron(A, A), meas_var * (K @ K.T).ravel())
    P = vec_p.reshape(2, 2)
    return float((D @ P @ D.T)[0, 0] + meas_var)


def gap_substeps(dt: float, period: float | None, *, span: float = math.inf) -> int:
    """Steps of at most one sample ``period`` [s] over an interval ``dt`` [s]: the pause rule
    of the live observer (:meth:`Observer.update`) and of the log reader
    (:class:`pinobs.io.LogEstimator`).

    ``1`` (one step) unless ``dt`` is longer than :data:`~pinobs.tolerances.GAP_PERIODS`
    periods; then ``⌈min(dt, span) / period⌉`` (``span`` [s]: the most of a pause
    propagated in steps of one period; the steps are ``dt / n`` long).  ``period`` ``None``
    (not known yet): ``1``.
    """
    if period is None or not dt > GAP_PERIODS * period:
        return 1
    return math.ceil(min(dt, span) / period - 1e-9)


def positive(
    name: str, value: float | None, *, allow_none: bool = False, allow_zero: bool = False
) -> float | None:
    """Validate a gain or option: a finite real number > 0 (or >= 0), or ``None`` if allowed.

    Raises:
        GainError: naming the option, the value and the accepted range.
    """
    if value is None:
        if allow_none:
            return None
        raise GainError(f"{name} is required: give a finite number > 0")
    if isinstance(value, (str, bytes, bool)) or not isinstance(value, numbers.Real):
        # a string would pass float() here and crash the first update (issue 17)
        raise GainError(f"{name}={value!r} is not a number; give a finite number > 0")
    x = float(value)
    ok = math.isfinite(x) and (x >= 0 if allow_zero else x > 0)
    if not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise GainError(f"{name}={value!r} is out of range; give a finite number {bound}")
    return x


class GaussianFilter(Protocol):
    """An error-state Gaussian filter, predicted and corrected apart (what a smoother runs).

    The filter's step is ``correct ∘ predict`` (filterpy's ``KalmanFilter.predict`` /
    ``update``), both pure functions of an immutable state carrying the mean ``q, v``
    (and more: a torque offset ``d``, …) and the error covariance ``P``:

    * ``predict(state, dt, tau) -> (state⁻, Φ)`` propagates over ``dt`` [s] with ``tau``
      [N·m or N] held and returns the transition Jacobian ``Φ`` of the error state
      (Rauch-Tung-Striebel needs it);
    * ``predict_flow(state, dt, tau) -> (state⁻, Φ, F)`` also returns ``F``, the Jacobian
      of the mean's step, of which ``Φ`` is only the filter's approximation (a filter
      without a better one returns ``Φ`` as ``F``);
    * ``correct(state⁻, q_meas) -> state⁺`` fuses one measured configuration; a filter with
      an outlier gate keeps its bookkeeping in the state's ``gate`` (:class:`GateState`),
      and ``gate_limit(state⁺)`` is the NIS above which it rejected that measurement.

    Attributes:
        robot: the process model (its configuration space is the filter's).
        gains: the family's frozen gains; ``gains.meas_std`` is the position noise σ
            [rad or m], and the process density is ``gains.accel_psd`` [rad²/s³] (a
            model-based filter) or ``gains.jerk_psd`` [rad²/s⁵] (white jerk).
        disturbance_psd: the density of a random-walk torque offset, or ``None``.
        options: the filter's resolved options (reported with a smoothed result).
    """

    robot: Robot

    @property
    def gains(self) -> Any: ...
    @property
    def disturbance_psd(self) -> float | None: ...
    @property
    def options(self) -> dict[str, Any]: ...
    def initial_state(self, q0: Vector, v0: Vector) -> Any: ...
    def predict(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector]: ...
    def predict_flow(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector, Vector]: ...
    def correct(self, state: Any, q_meas: Vector) -> Any: ...
    def gate_limit(self, state: Any) -> float: ...


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

    **Pauses** (MATH §7 holds the torque over a step; a loop that stalls makes one step
    long).  The sample period ``T`` is ``1/rate``, or without ``rate`` the median of the
    first :data:`_PERIOD_INTERVALS` intervals after :meth:`reset`.  A step longer than
    :data:`~pinobs.tolerances.GAP_PERIODS` ``T`` is propagated in sub-steps of at most
    ``T`` with the held torque (as an update without a sample at every period); a pause
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
    _init_args: tuple[tuple[Any, ...], dict[str, Any]]  # set by __new__

    def __new__(cls, *args: Any, **kwargs: Any) -> Observer[Any]:
        self = super().__new__(cls)
        self._init_args = (args, kwargs)  # to rebuild with σ from the data (_learn_noise)
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
        self._reset_args: tuple[Any, ...] = ()
        self._diverged = False  # the latest update diverged (its state was not kept)
        self._intervals: list[float] = []  # the first intervals after the reset (the period)
        self._tau_floor = float(np.min(self.robot.absurd_torque)) if self.robot.nv else 0.0
        self._period_s = None if self.rate is None else 1.0 / self.rate  # (_sample_period)
        self._restart_due = False  # a pause without a sample: restart at the next one
        self._pauses: list[tuple[float, float]] = []

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.robot.name!r})"

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
        self._period_s = None if self.rate is None else 1.0 / self.rate
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
    @one_blas_thread
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
        """
        if self._state is None:
            raise NotResetError(f"{self!r}: call reset(t0, q0) before update()")
        t_new = self._check_time(t, previous=self._t)
        q = None if q_meas is None else self.robot.check_configuration(q_meas, what="q_meas")
        tau_new = self._check_tau(tau, what="tau")
        ts_before = self._ts
        dt = t_new - self._t
        period = self._sample_period(dt)
        if period is not None and dt > max(PAUSE_RESTART, MAX_GAP_PERIODS * period):
            self._restart_due = True
        if self._restart_due and q is not None:
            state, t_state, estimate = self._after_pause(t_new, q, dt)
        elif self.latency > 0.0:
            state, t_state, estimate = self._delayed(t_new, q)
        else:
            # MATH §7: propagate with the torque held since the previous call, then correct.
            state = self._stepped(self._state, dt, q, self._tau)
            t_state = t_new
            estimate = self._make_estimate(t_new, state)
        if not (
            math.isfinite(sum(estimate.q.tolist())) and math.isfinite(sum(estimate.v.tolist()))
        ):
            # (a sum overflowing to inf also lands here: then check entry by entry)
            if not (np.all(np.isfinite(estimate.q)) and np.all(np.isfinite(estimate.v))):
                self._diverged = True
                why = (
                    f"predicted through a pause of {dt:.6g} s without a sample (the next sample "
                    "restarts it)"
                    if self._restart_due
                    else "check the model and the torques (or the gains); reset(t, q) starts "
                    "it afresh"
                )
                raise ObserverDiverged(
                    f"{self!r} diverged at t = {t_new:.6g} s (non-finite estimate); "
                    f"the last finite estimate is at t = {self._t:.6g} s, kept: {why}.",
                    t=t_new,
                    last_estimate=self._last,
                )
        self._diverged = False
        self._state, self._t, self._tau, self._last = state, t_new, tau_new, estimate
        self._ts = t_state
        if self.latency > 0.0:  # the torques applied since the state's time, for the next steps
            self._torques = [
                x
                for i, x in enumerate(self._torques)
                if i + 1 == len(self._torques) or self._torques[i + 1][0] > t_state
            ] + [(t_new, tau_new)]
            held = next(x for tk, x in reversed(self._torques) if tk <= t_state + TIME_EPS)
        else:  # the state is at t_new: only the torque applied from t_new on matters
            self._torques, held = [(t_new, tau_new)], tau_new
        used = q if t_state > ts_before + TIME_EPS and not estimate.gated else None
        self._state = self.after_commit(state, t_state, used, held)
        if estimate.nis is not None:
            self._nis.append(estimate.nis)
            self._gated += estimate.gated
        if self._noise_samples is not None and self._learn_noise(t_new, q, tau_new):
            return self.estimate  # rebuilt with σ from the data, replayed up to t_new
        return estimate

    def _sample_period(self, dt: float) -> float | None:
        """The sample period [s]: ``1/rate``, or (none given) the median of the first
        :data:`_PERIOD_INTERVALS` intervals after the reset (``None`` until three are in)."""
        if self.rate is None and len(self._intervals) < _PERIOD_INTERVALS:
            self._intervals.append(dt)
            if len(self._intervals) >= 3:  # computed five times at most, not at every update
                self._period_s = float(np.median(self._intervals))
        return self._period_s

    def _stepped(self, state: State, dt: float, q: Vector | None, tau: Vector) -> State:
        """:meth:`step` over ``dt``, in sub-steps of at most one period when ``dt`` is longer
        than :data:`GAP_PERIODS` periods (at most ``PAUSE_RESTART`` worth of them: a longer
        step without a sample is a prediction in the dark, restarted at the next sample;
        :func:`gap_substeps`, the log reader's count too).
        One step of 10 s returned 1e74 rad/s from ``ekf`` and every update after it raised;
        one of 1 s left ``riemannian`` 500 rad/s off for seconds (a sweep)."""
        period = self._period_s
        span = math.inf if period is None else max(PAUSE_RESTART, MAX_GAP_PERIODS * period)
        n = gap_substeps(dt, period, span=span)
        if n == 1:
            return self.step(state, dt, q, tau)
        for _ in range(n - 1):
            state = self.step(state, dt / n, None, tau)
        return self.step(state, dt / n, q, tau)

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
            self._torques = [(self._t, self._tau)]  # the torque held through the pause
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

    def _delayed(self, t_new: float, q: Vector | None) -> tuple[State, float, Estimate]:
        """One update under a known latency (:meth:`set_latency`): ``(state, its time, estimate at t_new)``."""
        assert self._state is not None
        s = t_new - self.latency
        if s > self._ts + TIME_EPS:
            state, t_state = self._advance(self._state, self._ts, s, q), s
        else:  # the sample predates the state: keep the state
            state, t_state = self._state, self._ts
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

    def _learn_noise(self, t: float, q: Vector | None, tau: Vector) -> bool:
        """Keep the update until :data:`NOISE_WINDOW` s (and :data:`NOISE_MIN_SAMPLES`
        samples) are in; then σ̂ from them (class docstring) and, if it is above the floor
        and changes the gains, rebuild with it and replay the kept updates (warned once).
        Returns whether the observer was rebuilt (its latest estimate is then the replay's)."""
        assert self._noise_samples is not None
        self._noise_samples.append((t, q, tau))
        ts = [x[0] for x in self._noise_samples if x[1] is not None]
        if len(ts) < NOISE_MIN_SAMPLES or ts[-1] - ts[0] < NOISE_WINDOW:
            return False
        kept, self._noise_samples = self._noise_samples, None
        qs = np.array([x[1] for x in kept if x[1] is not None])
        sigma_joint = estimate_noise_std(np.array(ts), qs, self.robot, window=NOISE_WINDOW)
        if sigma_joint is None or not float(np.median(sigma_joint)) > NOISE_FLOOR:
            return False
        sigma = float(np.median(sigma_joint))
        fresh = self._with_noise_std(sigma)
        if fresh is None:
            return False  # its gains were given: σ changes nothing
        fresh.reset(*self._reset_args)
        fresh.set_latency(self.latency)  # after its reset: a copy (twin) has had updates
        for tk, qk, tauk in kept:  # the same updates, as if σ̂ had been given from the start
            fresh.update(tk, qk, tauk)
        self.__dict__ = fresh.__dict__
        warnings.warn(
            NoiseWarning(
                f"{self.name}: built without noise_std; estimated σ = {sigma:.3g} from its "
                f"first {ts[-1] - ts[0]:.3g} s of samples (median over joints; per joint "
                f"{np.array2string(sigma_joint, precision=3)}), rebuilt with it and replayed "
                "them; pass noise_std to set it yourself"
            ),
            stacklevel=3,
        )
        return True

    def _with_noise_std(self, sigma: float) -> Observer[Any] | None:
        """This observer built with ``noise_std = sigma`` (not reset), or ``None`` if that
        changes none of its options.  Families whose gains ignore σ
        (``noise_in_gains = False``) use it only in ``_sigma2``, the measurement
        variance of their NIS: a copy with that replaced (no costly rebuild)."""
        if not self.noise_in_gains:
            twin = copy.copy(self)
            twin.noise_std = sigma
            twin.__dict__["_sigma2"] = sigma**2  # the family's NIS measurement variance
            return twin
        args, kwargs = self._init_args
        fresh = type(self)(*args, **{**kwargs, "noise_std": sigma})
        options = {k: v for k, v in fresh.options.items() if k != "noise_std"}
        return (
            None
            if options == {k: v for k, v in self.options.items() if k != "noise_std"}
            else fresh
        )

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

        Must return a new state and leave ``state`` untouched.
        """

    @abstractmethod
    def output(self, state: State) -> tuple[Vector, Vector]:
        """``(q̂, v̂)`` of a state."""

    def after_commit(self, state: State, t: float, q: Vector | None, tau: Vector) -> State:
        """Called once a state is committed: ``t`` its time, ``q`` the sample it used (``None``
        if none or gated), ``tau`` the torque applied from ``t`` on.  Families that learn from
        the data do it here (never in :meth:`step`, which also runs for predictions that are
        not kept); may return a replacement state.  Default: the state unchanged."""
        return state

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
        q, v = self.output(state)
        nis, gated = self.innovation(state)
        return Estimate(t=t, q=read_only(q), v=read_only(v), nis=nis, gated=gated)

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


# ------------------------------------------------------------------ registry
_REGISTRY: dict[str, type[Observer[Any]]] = {}

ObserverType = TypeVar("ObserverType", bound=type[Observer[Any]])


def register(cls: ObserverType) -> ObserverType:
    """Class decorator: add an observer family to the registry under ``cls.name``."""
    if not cls.name or cls.name in _REGISTRY:
        raise ValueError(f"observer name {cls.name!r} is empty or already registered")
    _REGISTRY[cls.name] = cls
    return cls


def observer_names() -> list[str]:
    """Registered observer names, sorted."""
    return sorted(_REGISTRY)


def observer_class(name: str) -> type[Observer[Any]]:
    """The class registered under ``name``.

    Raises:
        UnknownNameError: listing the registered names.
    """
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownNameError(
            f"unknown observer {name!r}; available: {', '.join(observer_names())}"
        ) from None


@one_blas_thread  # a family's gains (scipy's DARE...): a woken BLAS thread spins ~50 ms after
def make_observer(name: str, robot: Robot, **options: Any) -> Observer[Any]:
    """Build the observer registered as ``name`` on ``robot``.

    Options are the keyword arguments of the family's constructor (every
    family accepts ``rate`` [Hz] and ``noise_std`` [rad or m]), and
    ``latency`` [s] for every family (:meth:`Observer.set_latency`), and
    ``never_behind=True`` for a model-based family: the family blended per joint with
    the model-free ``kf`` (:class:`pinobs.observers.neverbehind.NeverBehind`; its
    ``window``, ``sharpness``, ``lost_ratio``, ``reference_options`` then accepted too).

    Raises:
        UnknownNameError: unknown ``name``.
        OptionError: an option the family does not accept (the message lists them).
        GainError: an option out of range.
    """
    cls = observer_class(name)
    latency = options.pop("latency", None)
    never_behind = bool(options.pop("never_behind", False))
    blend = {k: options.pop(k) for k in _BLEND_OPTIONS if never_behind and k in options}
    accepted = [
        p.name
        for p in inspect.signature(cls.__init__).parameters.values()
        if p.kind is inspect.Parameter.KEYWORD_ONLY
    ]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise OptionError(
            f"observer {name!r} does not accept option(s) {unknown}; accepted: {accepted}"
            + ("" if never_behind else ", and never_behind (model-based families)")
        )
    if never_behind:  # the family blended with kf (pinobs.observers.neverbehind)
        from pinobs.observers.neverbehind import NeverBehind

        given = {k: options.pop(k) for k in ("rate", "noise_std") if k in options}
        observer: Observer[Any] = NeverBehind(
            robot, observer=name, options=options, **blend, **given
        )
    else:
        observer = cls(robot, **options)
    if latency is not None:
        observer.set_latency(latency)
    return observer


#: Options of :class:`pinobs.observers.neverbehind.NeverBehind` that ``make_observer`` passes
#: to it with ``never_behind=True``.
_BLEND_OPTIONS = ("window", "sharpness", "lost_ratio", "reference_options")


def time_unit_warning(period: float | None) -> str | None:
    """What to say of a log whose median sample period [s] is implausible (``None``: nothing).

    A log timed in milliseconds or nanoseconds reads as seconds 1000x or 1e9x too long:
    its velocities come out that many times too small (a sweep found a kf median |v| of
    6.7e-4 rad/s for 0.67, and ekf re-initialised at every row of a ns log).
    """
    if period is None or MIN_PLAUSIBLE_PERIOD < period < MAX_PLAUSIBLE_PERIOD:
        return None
    if period >= MAX_PLAUSIBLE_PERIOD:
        unit = "milliseconds, microseconds or nanoseconds (t / 1000, t * 1e-6, t * 1e-9)"
    else:
        unit = "a unit larger than seconds"
    return (
        f"the median sample period is {period:.6g} s ({1 / period:.6g} Hz): is t in {unit}? "
        "give t in seconds: velocities are per second of t, so they are off by the same factor"
    )


def median_period(t: Vector) -> float | None:
    """The median of a log's positive sample intervals [s] (finite times), or ``None``."""
    d = np.diff(t[np.isfinite(t)])
    d = d[d > 0]
    return float(np.median(d)) if d.size else None
