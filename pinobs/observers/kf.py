"""Per-joint constant-acceleration Kalman filter: the strongest model-free baseline.

Each tangent direction i carries ``x_i = (δq_i, v_i, a_i)`` with white jerk of
spectral density ``jerk_psd`` [rad²/s⁵] and measurement noise variance σ²:

    F(h) = [[1, h, h²/2], [0, 1, h], [0, 0, 1]],
    Q(h) = j · [[h⁵/20, h⁴/8, h³/6], [h⁴/8, h³/3, h²/2], [h³/6, h²/2, h]],   R = σ².

All directions share F, Q and R, so they share one 3×3 covariance: the cost
is O(nv).  On Lie-group joints the position part lives in the tangent space:
predict ``q ← q ⊕ (v h + a h²/2)``, correct with the innovation
``e = difference(q̂, q_meas)`` and ``q ← q ⊕ K₀ e``.

The outlier gate of the EKF family (:func:`pinobs.observers.base.outlier_gate`) on
``NIS = |e|² / S``, ``S = P⁻₀₀ + σ²`` (``nv`` degrees of freedom): a rejected measurement
leaves the prediction.  Without it one sample 1 rad off moved the causal estimate by
75 rad/s and widened the smoothed band 65× over a whole 2 s log (the consistency ρ it is
scaled by went from 0.77 to 4.3e3); on the learning benchmark's model-error logs it changes
the estimates by nothing visible (four logs: the same RMS to four digits).

Defaults: σ = ``noise_std`` (1e-6 if not given, so the filter trusts the
encoder), ``jerk_psd`` = ``"auto"`` (below), ``outlier_probability`` = 1e-6.
The fixed default before it, 1e3 rad²/s⁵ (:data:`SMOOTHING_JERK_PSD`), was about right
for an arm tracking smooth references at 1 kHz and 1.6–10× over the best fixed density on
the UR10e and TIAGo logs of ``benchmarks/real_logs.py``; ``"auto"`` is within 0.89–1.21× of
that best on every one of them (TX40 at 1 kHz: 0.98×), 0.85–1.03× on ``pinobs bench``'s
simulations (1 kHz; the fixed 1e3: 1.4–2.3×) and 0.87–1.00× on ``benchmarks/learning.py``'s
runs, at half the cost of a fixed density on a UR5 (8.5 ``pin.aba`` calls against 18: the bank
is one compiled step, on Lie-group joints too; go1's free-flyer 7.2 against 10.5, where the
NumPy path of the bank cost 52): ``benchmarks/kf_auto.py``.

**``jerk_psd="auto"``: the density of each joint from the data, causally** (a
multiple-model filter, Magill 1965 / Bar-Shalom, Li & Kirubarajan 2001 §11.6, with
each model's noise scale profiled out as in Mehra 1970's adaptive filtering).  The
gain of the filter above depends only on the ratio ``ρ = j / σ²`` and ``h``; so a bank
of ``n_f`` filters runs on a log-spaced grid ``ρ_f = λ_f / T⁵`` (:data:`AUTO_LAMBDAS`:
the dimensionless ``λ = ρ T⁵``, ``T`` the sample period, ``1/rate`` or the first
interval), each with ``R = σ₀²`` (σ₀ the ``noise_std``) and ``Q = ρ_f σ₀² Q₁(h)``: one
3×3 covariance per filter, shared by the joints.  The filter ``f`` is exact for joint
``i`` if its noise variance is ``c_fi σ₀²`` and its density ``ρ_f c_fi σ₀²``; its
innovations ``e_fi`` then have variance ``c_fi S_f``, ``S_f = P⁻_f,00 + σ₀²``.  With
the exponentially forgotten sums (``γ = exp(−1 / auto_memory)``, at each measured
sample: a memory of about ``auto_memory`` samples, :data:`AUTO_MEMORY`)::

    N ← γ N + 1,   A_fi ← γ A_fi + e_fi² / S_f,   B_f ← γ B_f + log S_f,

the scale's maximum-likelihood value is ``ĉ_fi = A_fi / N`` and the concentrated
(profile) negative log-likelihood, up to a constant,
``L_fi = N log(A_fi / N) + B_f`` (the prediction-error decomposition, Schweppe 1965,
with ``c`` maximised out).  Each joint's estimate is the likelihood-weighted mixture
``w_fi ∝ exp(−(L_fi − min_f L_fi) / 2)`` of the bank's (a posterior over the grid with
a flat prior: a switch between two filters passes through equal weights, no jump);
its density and noise are read as ``j_i = exp Σ_f w_fi log(ρ_f ĉ_fi σ₀²)`` and
``σ_i² = exp Σ_f w_fi log(ĉ_fi σ₀²)`` (:attr:`ConstantAccelerationKF.densities`).
The outlier gate sees ``NIS = Σ_i Σ_f w_fi e_fi² / max(ĉ_fi S_f, σ₀²)`` (the weights and
scales before the sample), once :data:`AUTO_GATE_SAMPLES` samples are in: the scale is
floored where the gate reads it, the innovation variance never below the sensor's σ₀².  On
a joint at rest whose quantised readings repeat exactly, ``ĉ`` goes to 0, and the first
step of one quantum when it starts to move read as an outlier of NIS ~1e300 (a UR10e
validation log, ``ur-20_01_17-p1``, σ₀ from the log: 28 of its 918 samples rejected, the
mean NIS 1e299 and "the model does not explain the data"; floored: 1 rejected, mean NIS
4.6 for 6 joints); on white-noise simulations the velocities are unchanged to the bit
(UR5, Panda, go1; 1 kHz to 100 Hz), only the NIS values below the floor move.  Cost per
update ``O(n_f · nv)``.  σ₀ changes nothing but the start (``P₀``) and the scale's
units: the noise level is learnt per joint with the density.

**``"auto"``'s gate is soft.**  Where it fires (``NIS > limit``, the limit
``χ²_nv(1 − p) · max(1, NIS̄ / nv)`` of :meth:`~pinobs.observers.base.GateState.measured`,
``p`` = ``outlier_probability``) the sample still corrects every filter of the bank, its
innovation variance inflated so that its NIS equals the limit::

    α = NIS / limit,   S_f ← α S_f,   K_f = P⁻_f[:, 0] / (α S_f)   (Joseph form, R = σ₀²)

(as Chang 2014, J. Geodesy 88:391, inflates the noise covariance until the Mahalanobis
distance is its χ² quantile; here the whole innovation covariance, so ``α`` in closed form:
the gain ``K / α``, a redescending variant of the Huber weight of Karlgaard & Schaub 2007,
whose ``α = √(NIS / limit)`` caps the correction at the limit's: here ``K e / α = K S limit /
e`` falls as ``1/e``), the likelihood sums and count left as they were.  A glitch's influence
vanishes (1 rad off: NIS ~1e9, α ~2e7); a maneuver keeps ``1/α`` of its correction.  Why: on
the 17 moving UR10e logs (``benchmarks/kf_gate.py``) the hard gate (the prediction kept) fired
71 times, 2–9 a log, NIS 41–618 (median 81), on true maneuvers (e.g. ``ur-19_10_01-14_04_13``
row 620, the arm stopping from 0.1 rad/s within one 12 ms sample): the velocity RMS against
the robot's own was 0.907–1.002× the hard gate's without a gate, 0.961–1.001× (geometric mean
0.990) with the soft one; TIAGo 0.998× (both).  With five glitches injected per log (0.01 to
1 rad) the soft gate moved ``v`` as little as the hard one (0.014 against 0.015 rad/s, median
of the largest changes; no gate: 1.2 to 130).  Not taken (same file): a gate per joint (a
stop on one joint is gated as a glitch is: up to 1.14×); rejecting only what no filter of the
bank explains (the multiple-model union of gates: the low-density filters' learnt scales are
wide, the smallest glitch rejected 2.1 rad, median, against 5.6e-4); Huber's
``α = √(NIS / limit)`` (0.954–0.999×, but glitches moved ``v`` by 0.079 rad/s, median).  On
simulations the gate does not fire (``pinobs bench``'s runs, 1 kHz and 100 Hz): the same bits.
The fixed density's gate, and the smoother's (a gated sample is not
corrected: :func:`pinobs.smoothing.band.was_gated`), stay hard.

Why profiled, per joint, and forgotten per sample (where a filter matching its NIS to its
expectation failed in simulation and on TIAGo): (1) the NIS needs σ, and the logs do not
give it: the third-difference estimator finds 0 to 1e-4 rad per joint on the UR10e logs
(quantised encoders, repeated rows) and 0 to 9e-6 on TIAGo, while the innovations say
5e-6 to 9e-5 (:attr:`~ConstantAccelerationKF.noise_stds`); profiled out, σ cannot bias
the density.  (2) A memory in seconds remembers the start: on ``pinobs bench``'s UR5
(1 kHz, a 0.05 rad / 0.5 rad/s start error) 2 s of memory gave 1.7–1.8× the best fixed
density's RMS and 10 s more (the low-density filters' long transient keeps their
likelihood down), 100 samples 0.97–0.98×.  (3) One density cannot fit every joint: the
UR5 run's joints settle from 1.2 to 44 rad²/s⁵, TIAGo's from 0 (the torso, at rest) to
0.8.  What remains on TIAGo (1.21× its best fixed density, 1e-6, the grid's bottom) is
the reference's: its recorded velocity matches the positions' Savitzky–Golay derivative
best 10 to 20 samples late (RMS 4.5e-3 rad/s against 6.7e-3 at no delay), so a filter
that lags scores better against it; the likelihood sees only the positions.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Literal, NamedTuple, cast

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import GainError, NotResetError
from pinobs.model import Robot
from pinobs.observers.base import (
    Consistency,
    Estimate,
    GateState,
    Observer,
    Vector,
    gate_threshold,
    positive,
    register,
)
from pinobs.observers.kf_bank import AUTO_GATE_SAMPLES as AUTO_GATE_SAMPLES  # re-exported
from pinobs.observers.kf_bank import AUTO_LAMBDAS as AUTO_LAMBDAS  # re-exported
from pinobs.observers.kf_bank import (
    AUTO_MEMORY,
    AutoBank,
    AutoState,
    KFState,
    corrected,
    predicted,
    transition,
)
from pinobs.observers.kf_bank import BankState as BankState  # re-exported
from pinobs.observers.kf_bank import KFBank as KFBank  # re-exported
from pinobs.observers.kf_fused import held_torque, load_work, set_limits, work_state
from pinobs.tolerances import TIME_EPS

_F64 = np.dtype(np.float64)
_EMPTY = np.empty(0)  # (the fused update's no sample, or tau None: zero)
_new_tuple = tuple.__new__  # (NamedTuples and the Estimate made as AutoBank.step and
_new_object = object.__new__  # Observer._make_estimate make them)

__all__ = [
    "KF_CAUSES",
    "SMOOTHING_JERK_PSD",
    "ConstantAccelerationKF",
    "ErrorState",
    "KFGains",
    "WhiteJerkFilter",
]


#: What makes ``kf``'s innovations inconsistent (:meth:`ConstantAccelerationKF.consistency`).
KF_CAUSES = (
    "jerk_psd too small for this motion (raise it, or let pinobs.smooth choose it: "
    "accel_psd='auto')",
    "the noise level (noise_std smaller than the sensor's)",
)


@dataclass(frozen=True)
class KFGains:
    """Validated options of :class:`ConstantAccelerationKF`.

    Attributes:
        jerk_psd: white-jerk spectral density [rad²/s⁵], > 0.
        meas_std: measurement noise standard deviation [rad], > 0.
        outlier_probability: false-alarm probability ``p`` of the outlier gate
            (:func:`pinobs.observers.base.outlier_gate`, on ``NIS = |e|² / S`` with ``nv``
            degrees of freedom, as the EKF's), in (0, 0.5), or ``None``: no gate.
    """

    jerk_psd: float
    meas_std: float
    outlier_probability: float | None = 1e-6

    def __post_init__(self) -> None:
        positive("jerk_psd", self.jerk_psd)
        positive("meas_std", self.meas_std)
        gate_threshold(self.outlier_probability, 1)


#: The density [rad²/s⁵] of :meth:`ConstantAccelerationKF.smoothing_filter` (and of its
#: :class:`KFGains`) with ``jerk_psd="auto"``: the fixed default before ``"auto"`` (an arm
#: tracking smooth references at 1 kHz).
SMOOTHING_JERK_PSD = 1e3


@register
class ConstantAccelerationKF(Observer["KFState | AutoState"]):
    """Per-joint Kalman filter on a constant-acceleration (white-jerk) model.

    Args:
        robot: the robot (only its Lie-group operations are used).
        jerk_psd: white-jerk spectral density [rad²/s⁵], or ``"auto"``: each joint's
            density (and noise level) from the data as it comes, by a bank of filters and
            their innovations' likelihoods (module docstring; :attr:`densities`).
        v0_std: initial velocity standard deviation [rad/s] when ``v0`` is not given.
        outlier_probability: false-alarm probability of the outlier gate (as in ``ekf``; a
            rejected measurement leaves the prediction; with ``"auto"`` the gate is soft: the
            gain divided by ``NIS / limit``, module docstring), or ``None``: no gate.
        rate: sample rate hint [Hz] (not needed: the filter uses the actual intervals;
            with ``"auto"`` it sets the grid's period ``T``, else the first interval does).
        noise_std: position noise standard deviation [rad or m], the measurement noise.
        auto_memory: with ``"auto"``, the likelihoods' memory [measured samples] (module
            docstring: ``γ = exp(−1 / auto_memory)``).
    """

    name = "kf"
    summary = "per-joint constant-acceleration Kalman filter (model-free baseline)"
    uses_torque = False
    uses_noise_std = True
    #: :func:`pinobs.smooth` can run its backward pass over this filter (through
    #: :meth:`smoothing_filter`: the model-free smoother).
    smoothable = True
    model_free = True
    process_density = "jerk_psd"

    def __init__(
        self,
        robot: Robot,
        *,
        jerk_psd: float | Literal["auto"] = "auto",
        v0_std: float = 1.0,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
        auto_memory: float = AUTO_MEMORY,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        positive("v0_std", v0_std)
        positive("auto_memory", auto_memory)
        self.v0_std = float(v0_std)
        if isinstance(jerk_psd, str) and jerk_psd != "auto":
            raise GainError(f"jerk_psd={jerk_psd!r}: give a number > 0 [rad²/s⁵] or 'auto'")
        self.auto = jerk_psd == "auto"
        self.auto_memory = float(auto_memory)
        # with "auto" the gains' density is only the smoother's: the bank's are ρ_f σ₀²
        self.gains = KFGains(
            SMOOTHING_JERK_PSD if self.auto else cast(float, jerk_psd),
            self.noise_std_used,
            outlier_probability,
        )
        self._gate = gate_threshold(outlier_probability, robot.nv)[1]
        #: ``"auto"``'s bank (:class:`~pinobs.observers.kf_bank.AutoBank`; its compiled step
        #: loaded now on vector joints, not at the first update), else ``None``.
        self.auto_bank = (
            AutoBank(robot, self.gains.meas_std, self.auto_memory, self._gate)
            if self.auto
            else None
        )
        # the compiled bank's step (its joints compiled) makes no BLAS call: no thread limit to
        # enter per update (Observer.uses_blas); the fixed density's NumPy step does
        self.uses_blas = not (self.auto_bank is not None and self.auto_bank.compiled)
        # output's: "auto"'s estimate copied out of the state's buffer, its own
        self.fresh_output = self.auto_bank is not None
        self._mixture = None if self.auto_bank is None else self.auto_bank.mixture
        self._nq, self._nv = robot.nq, robot.nv  # (Robot.nq/nv ask Pinocchio)
        # "auto"'s plain update in one compiled call (Observer._update_fused; vector joints) on
        # an array of its own: the state, its time, count, gate and torque held, updated in
        # place (kf_fused.fused_work; the limits kept by _set_period; the state put in it by
        # _load_work, read back by the _state property)
        self._fused_path = self.auto_bank is not None and self.auto_bank.fused is not None
        self._work = (
            None if self.auto_bank is None else self.auto_bank.work(self._split, self._span)
        )
        self._est_size = self._nq + self._nv  # (the estimate's array)
        self._fused: Any = None  # (the bank's compiled update, set by _load_work)

    # The committed state: ``_held``, or where the fused updates have run since it was set
    # (``_stale``) the one in ``_work``, an AutoState built from it when asked for (once).  Set
    # by the base (an update of its own, a reset), ``_work`` no longer has it (``_live``).
    _held: KFState | AutoState | None
    _stale: bool
    _live: bool

    @property  # type: ignore[override]
    def _state(self) -> KFState | AutoState | None:
        if self._stale:
            held = cast(AutoState, self._held)
            x, n, gate = work_state(cast(Vector, self._work))
            self._held = _new_tuple(
                AutoState, (x, held.shape, held.jerk, n, _new_tuple(GateState, gate))
            )
            self._stale = False
        return self._held

    @_state.setter
    def _state(self, state: KFState | AutoState | None) -> None:
        self._held, self._stale, self._live = state, False, False

    def __getstate__(self) -> dict[str, object]:
        """Pickled with its state built (:attr:`_state`) and ``_work`` to be loaded again (a
        view of it, the torque held, is pickled as a copy; the compiled code is not)."""
        state = self._state
        return {**self.__dict__, "_held": state, "_stale": False, "_live": False, "_fused": None}

    def _load_work(self) -> bool:
        """The committed state (and time, torque held) into ``_work`` for the fused update
        (``_tau`` then a view of it), and the compiled update for it; ``False`` if the state
        is not the compiled bank's."""
        state, work, bank = self._held, self._work, self.auto_bank
        if not isinstance(state, AutoState) or work is None or bank is None or bank.fused is None:
            return False  # (not reset: the base says so)
        gate = state.gate
        load_work(
            work, state.x, state.jerk, self._t, state.n, gate.level, gate.run, gate.drift,
            self._tau,
        )  # fmt: skip
        self._tau, self._live, self._fused = held_torque(work), True, bank.fused
        return True

    def _set_period(self, period: float | None) -> None:
        """The base's, and the fused update's copy of its sub-step and pause limits."""
        super()._set_period(period)
        work = getattr(self, "_work", None)  # (None: from the base's __init__, or no bank)
        if work is not None:
            set_limits(work, self._split, self._span)

    @property
    def options(self) -> dict[str, object]:
        out = {**super().options, **_gain_options(self.gains)}
        if self.auto:
            out.update(jerk_psd="auto", auto_memory=self.auto_memory)
        return out

    @property
    def densities(self) -> Vector:
        """Each joint's white-jerk density [rad²/s⁵]: ``jerk_psd``, or with ``"auto"`` the
        bank's current estimate ``exp Σ_f w_fi log(ρ_f ĉ_fi σ₀²)`` (module docstring;
        ``nan`` before the first measured sample)."""
        state = self._state
        if state is None:
            raise NotResetError(f"{self!r}: call reset(t0, q0) first")
        if not isinstance(state, AutoState):
            return np.full(self.robot.nv, self.gains.jerk_psd)
        return self._auto().densities(state)

    @property
    def noise_stds(self) -> Vector:
        """Each joint's measurement noise σ [rad or m]: ``noise_std``, or with ``"auto"`` the
        bank's ``√exp Σ_f w_fi log(ĉ_fi σ₀²)`` (module docstring; ``nan`` before a sample)."""
        state = self._state
        if state is None:
            raise NotResetError(f"{self!r}: call reset(t0, q0) first")
        if not isinstance(state, AutoState):
            return np.full(self.robot.nv, self.gains.meas_std)
        return self._auto().noise_stds(state)

    def _auto(self) -> AutoBank:
        """The ``"auto"`` bank (an :class:`~pinobs.observers.kf_bank.AutoState` comes only
        from it)."""
        return cast(AutoBank, self.auto_bank)

    def _initial_p(self) -> Vector:
        return np.diag(
            np.array([self.gains.meas_std**2, self.v0_std**2, (10.0 * self.v0_std) ** 2])
        )

    def initial_state(self, q0: Vector, v0: Vector) -> KFState | AutoState:
        P = self._initial_p()
        if self.auto_bank is None:
            return KFState(q0.copy(), v0.copy(), np.zeros_like(v0), P)
        return self.auto_bank.initial(q0, v0, P, self.rate)

    def restart_state(self, state: KFState | AutoState, q: Vector) -> KFState | AutoState:
        """After a pause: afresh, but ``"auto"`` keeps its likelihoods (what it learned)."""
        fresh = self.initial_state(q, np.zeros(self.robot.nv))
        if isinstance(state, AutoState) and isinstance(fresh, AutoState):
            return self._auto().restart(state, fresh)
        return fresh

    def step(
        self, state: KFState | AutoState, dt: float, q_meas: Vector | None, tau: Vector
    ) -> KFState | AutoState:
        if isinstance(state, AutoState):  # (an AutoState comes only from the auto bank; not
            # through _auto: its call and cast's, every update)
            return self.auto_bank.step(state, dt, q_meas)  # type: ignore[union-attr]
        F, Q = transition(dt, self.gains.jerk_psd)
        q, v, a, P = predicted(self.robot, state.q, state.v, state.a, state.P, F, Q, dt)
        if q_meas is None:
            return KFState(q, v, a, 0.5 * (P + P.T), state.gate.predicted())
        r = self.gains.meas_std**2
        return corrected(self.robot, q, v, a, P, state.gate, r, self._gate, q_meas)

    def _update_fused(
        self, t: float, q_meas: ArrayLike | None, tau: ArrayLike | None
    ) -> Estimate | None:
        """A plain update of ``"auto"`` in one compiled call, or ``None`` (nothing changed: the
        base's own path takes it).  Issue 39: in a paced 1 kHz loop the base's checks, copies
        and estimate cost more than the step; here they are done in
        :func:`~pinobs.observers.kf_fused.auto_update_loops` as the base does them, and what
        the base commits is committed, to the bit: the state, its count and gate, and the
        torque held in place in the filter's array (``_work``; the state built from it only
        when read, :attr:`_state`), the time, the estimate, the NIS here.  Taken: ``t`` a
        ``float`` (or NumPy's), ``q_meas`` ``None`` or a float64 array of shape ``(nq,)``,
        ``tau`` ``None`` or a float64 ``(nv,)``, σ known, the period known, no latency, no
        pause due, and whatever the kernel checks.  The estimate's ``q̂`` and ``v̂`` are views
        of one new read-only array (``nq + nv``), not written again."""
        if not (
            (type(t) is float or type(t) is np.float64)
            and (
                q_meas is None
                or (
                    type(q_meas) is np.ndarray
                    and q_meas.dtype is _F64
                    and q_meas.shape == self._shapes[0]
                )
            )
            and (
                tau is None
                or (type(tau) is np.ndarray and tau.dtype is _F64 and tau.shape == self._shapes[1])
            )
            and self._noise_samples is None
            and not self._intervals_due
            and not self._restart_due
            and self.latency == 0.0
            and (self._live or self._load_work())
        ):
            return None
        x, out = float(t), np.empty(self._est_size)
        taken, nis, rejected = self._fused(
            self._work, out, _EMPTY if q_meas is None else q_meas, _EMPTY if tau is None else tau, x
        )
        if not taken:
            return None  # (a bad input or a non-finite estimate: the base's path says so)
        out.setflags(write=False)  # (its views below read-only with it)
        estimate = _new_object(Estimate)  # as Observer._make_estimate
        d, nq = estimate.__dict__, self._nq
        if q_meas is None:  # the prediction: no NIS (GateState.predicted)
            nis = None
        else:
            self._nis.append(nis)
            self._gated += rejected
        d["t"], d["q"], d["v"], d["nis"], d["gated"] = x, out[:nq], out[nq:], nis, rejected
        # the base's commit (Observer._update: no after_commit, σ known; the state in _work)
        self._t = self._ts = x
        self._last, self._diverged, self._stale = estimate, False, True
        return estimate

    def update_rows(self, t: Vector, q: Vector, v_max: Vector) -> tuple[Vector, Vector]:
        """:meth:`update` at ``t[k]`` with ``q[k]`` for ``k = 0, 1, …`` in turn, as far as
        each is a plain step of ``"auto"``'s compiled bank, in one compiled call
        (:meth:`~pinobs.observers.kf_bank.AutoBank.rows`: the same bits as the updates, for a
        caller that runs a whole log: :class:`pinobs.io.LogEstimator`).  A plain step: σ known
        (given, or learnt and replayed), the period known, no latency, no pause due, ``t[k]``
        after the previous time by more than ``TIME_EPS`` and before the sub-step and pause
        limits, ``q[k]`` finite (the caller's check), an estimate finite with every
        ``|v̂_i| ≤ v_max_i``; the rows from the first that is not are left to :meth:`update`.
        Returns the estimates ``(q̂, v̂)`` of the rows taken (``(rows, nq)``, ``(rows, nv)``)."""
        state, nq = self._state, self._nq
        taken = 0
        if (
            isinstance(state, AutoState)
            and self._noise_samples is None
            and not self._intervals_due
            and self.latency == 0.0
            and not self._restart_due
            and not self._units  # (update normalises unit-norm blocks: not here)
        ):
            before = np.concatenate([[self._t], t[:-1]])
            dt = t - before
            plain = (t > before + TIME_EPS) & (dt < self._split) & (dt <= self._span)
            taken = t.size if plain.all() else int(np.argmin(plain))
        if not taken or not isinstance(state, AutoState):
            return np.empty((0, nq)), np.empty((0, self.robot.nv))
        bank = self._auto()
        state, mixes, nis, gated = bank.rows(state, self._t, t[:taken], q[:taken], v_max)
        if mixes.shape[0]:  # the base's bookkeeping after its last update (Observer.update)
            self._state, self._t = state, float(t[mixes.shape[0] - 1])
            self._ts, self._diverged = self._t, False
            self._last = self._make_estimate(self._t, state)
            self._nis.extend(nis.tolist())
            self._gated += int(gated.sum())
        return mixes[:, :nq], mixes[:, nq:]

    def consistency(self) -> Consistency:
        """The NIS test of the base class; its causes are a model-free filter's.  With
        ``"auto"`` the NIS is scaled by each joint's learnt noise level: about ``nv`` by
        construction (the test then checks only the shape of the innovations)."""
        base = super().consistency()
        if base.causes:
            base = replace(base, causes=KF_CAUSES)
        if isinstance(self._state, AutoState) and base.gated:  # (its gate soft: down-weighted)
            base = replace(base, details={**base.details, "soft_gate": True})
        return base

    def output(self, state: KFState | AutoState) -> tuple[Vector, Vector]:
        """With ``"auto"``: the bank's mixture ``(Σ_f w_f q_f, Σ_f w_f v_f)`` (module docstring;
        computed by the step, in the state's buffer:
        :attr:`~pinobs.observers.kf_bank.AutoBank.mixture`), copied out once (:attr:`fresh_output`;
        writable, as the kernels that take it expect; here, not through the bank: a call less
        every update)."""
        if isinstance(state, AutoState):
            mix = state.x[self._mixture].copy()
            return mix[: self._nq], mix[self._nq :]
        return state.q, state.v

    def smoothing_filter(self) -> WhiteJerkFilter:
        """This filter as :func:`pinobs.smooth` runs it (:class:`WhiteJerkFilter`): one
        density, ``jerk_psd``; with ``"auto"`` :data:`SMOOTHING_JERK_PSD` (the causal bank's
        densities change along the log; ``pinobs.smooth(accel_psd="auto")`` chooses one from
        the whole log)."""
        return WhiteJerkFilter(self.robot, self.gains, self.v0_std)


def _gain_options(gains: KFGains) -> dict[str, object]:
    return {
        "jerk_psd": gains.jerk_psd,
        "meas_std": gains.meas_std,
        "outlier_probability": gains.outlier_probability,
    }


def _kron_eye(A: Vector, eye: Vector) -> Vector:
    """``A ⊗ I`` (a broadcast product: ``np.kron`` costs 10× more at these sizes)."""
    n = A.shape[0] * eye.shape[0]
    return (A[:, None, :, None] * eye[:, None]).reshape(n, n)


class ErrorState(NamedTuple):
    """:class:`WhiteJerkFilter`'s state: the mean, and the covariance of the error state
    ``(δq, δv, δa)`` (each block ``nv`` long)."""

    q: Vector
    v: Vector
    d: Vector  # the acceleration a, named as the smoother's further vector part (the EKF's d)
    P: Vector  # (3nv, 3nv): P₃ ⊗ I, the directions' shared 3×3 covariance
    P3: Vector  # that 3×3 covariance
    gate: GateState = GateState()  # as ConstantAccelerationKF's state


class WhiteJerkFilter:
    """:class:`ConstantAccelerationKF` with its predict and correct apart, for the RTS
    smoother (a :class:`pinobs.observers.base.GaussianFilter`): the model-free smoother.

    The same equations (module docstring), stated for the whole error state
    ``x = (δq, δv, δa)`` of ``3 nv`` coordinates: every direction has the same
    ``F(h)``, ``Q(h)`` and ``R``, and the measurement ``H = [I 0 0]``, so the covariance is
    ``P = P₃ ⊗ I`` and the transition ``Φ = F(h) ⊗ I`` (the Kronecker product keeps the
    ``δq, δv, δa`` blocks in that order); the filter runs on ``P₃`` as the causal one does,
    and its states carry ``P`` for the smoother's backward pass.  ``a`` is the state's
    ``d``, the part after ``v`` that the smoother treats as a vector.  Takes no torque.
    """

    def __init__(self, robot: Robot, gains: KFGains, v0_std: float) -> None:
        self.robot, self.gains, self.v0_std = robot, gains, float(v0_std)
        self._gate = gate_threshold(gains.outlier_probability, robot.nv)[1]
        self._cache: tuple[float, Vector, Vector, Vector] | None = None
        self._eye = np.eye(robot.nv)

    #: No torque offset: white jerk takes no torque.
    disturbance_psd: float | None = None

    @property
    def options(self) -> dict[str, object]:
        return _gain_options(self.gains)

    def _full(self, q: Vector, v: Vector, a: Vector, P3: Vector, gate: GateState) -> ErrorState:
        return ErrorState(q, v, a, _kron_eye(P3, self._eye), P3, gate)

    def initial_state(self, q0: Vector, v0: Vector) -> ErrorState:
        """As :meth:`ConstantAccelerationKF.initial_state`."""
        P3 = np.diag([self.gains.meas_std**2, self.v0_std**2, (10.0 * self.v0_std) ** 2])
        return self._full(q0.copy(), v0.copy(), np.zeros_like(v0), P3, GateState())

    def predict(self, state: ErrorState, dt: float, tau: Vector) -> tuple[ErrorState, Vector]:
        """``(state⁻, Φ)`` (``tau`` is not used)."""
        if self._cache is None or self._cache[0] != dt:
            F, Q = transition(dt, self.gains.jerk_psd)
            self._cache = (dt, F, Q, _kron_eye(F, self._eye))
        _, F, Q, Phi = self._cache
        q, v, a, P3 = predicted(self.robot, state.q, state.v, state.d, state.P3, F, Q, dt)
        return self._full(q, v, a, P3, state.gate.predicted()), Phi.copy()

    def predict_flow(
        self, state: ErrorState, dt: float, tau: Vector
    ) -> tuple[ErrorState, Vector, Vector]:
        """:meth:`predict` and the Jacobian of its mean's step: ``Φ`` itself (the step is
        linear in the error state)."""
        pred, Phi = self.predict(state, dt, tau)
        return pred, Phi, Phi

    def correct(self, state: ErrorState, q_meas: Vector) -> ErrorState:
        q, v, a, P3 = (*state[:3], state.P3)
        new = corrected(
            self.robot, q, v, a, P3, state.gate, self.gains.meas_std**2, self._gate, q_meas
        )
        if new.gate.gated:  # the prediction, as it is
            return state._replace(gate=new.gate)
        return self._full(*new)

    def gate_limit(self, state: ErrorState) -> float:
        """The NIS above which :meth:`correct` rejected ``state``'s measurement."""
        return state.gate.limit(self._gate, self.robot.nv)
