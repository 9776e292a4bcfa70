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
is one compiled step on vector joints; 4.9× the fixed one on go1's free-flyer, the NumPy
path): ``benchmarks/kf_auto.py``.

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
The outlier gate sees ``NIS = Σ_i Σ_f w_fi e_fi² / (ĉ_fi S_f)`` (the weights and
scales before the sample), once :data:`AUTO_GATE_SAMPLES` samples are in.  Cost per
update ``O(n_f · nv)``.  σ₀ changes nothing but the start (``P₀``) and the scale's
units: the noise level is learnt per joint with the density.

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

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import GainError, NotResetError
from pinobs.model import Robot
from pinobs.observers.base import (
    MAX_GATE_RUN,
    NIS_AVERAGING,
    NOISE_FLOOR,
    Consistency,
    GateState,
    Observer,
    Vector,
    gate_threshold,
    positive,
    register,
)
from pinobs.observers.linalg import LazyKernel

__all__ = [
    "AUTO_LAMBDAS",
    "KF_CAUSES",
    "SMOOTHING_JERK_PSD",
    "BankState",
    "ConstantAccelerationKF",
    "ErrorState",
    "KFBank",
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


class _State(NamedTuple):
    q: Vector
    v: Vector
    a: Vector
    P: Vector  # 3×3 covariance shared by every direction
    gate: GateState = GateState()  # the outlier gate's bookkeeping (NIS of the last measurement)


def transition(h: float, jerk_psd: float) -> tuple[Vector, Vector]:
    """``(F(h), Q(h))`` of the white-jerk model (module docstring)."""
    F = np.array([[1.0, h, 0.5 * h * h], [0.0, 1.0, h], [0.0, 0.0, 1.0]])
    Q = jerk_psd * np.array(
        [
            [h**5 / 20, h**4 / 8, h**3 / 6],
            [h**4 / 8, h**3 / 3, h**2 / 2],
            [h**3 / 6, h**2 / 2, h],
        ]
    )
    return F, Q


def _predicted(
    robot: Robot, q: Vector, v: Vector, a: Vector, P: Vector, F: Vector, Q: Vector, h: float
) -> tuple[Vector, Vector, Vector, Vector]:
    """The prediction over ``h``: ``q ⊕ (v h + a h²/2)``, ``v + a h``, ``a``, ``F P Fᵀ + Q``."""
    return robot.integrate(q, v * h + 0.5 * h * h * a), v + h * a, a, F @ P @ F.T + Q


def _corrected(
    robot: Robot,
    q: Vector,
    v: Vector,
    a: Vector,
    P: Vector,
    gate: GateState,
    r: float,
    threshold: float,
    q_meas: Vector,
) -> _State:
    """The update of the prediction ``q, v, a, P`` (``P`` its 3×3 covariance; ``gate`` the
    gate's state) with ``q_meas``: the innovation ``e = difference(q, q_meas)``,
    ``S = P₀₀ + r``, the outlier gate on ``NIS = |e|² / S``
    (:meth:`pinobs.observers.base.GateState.measured`, ``threshold``: a rejected measurement
    leaves the prediction), else per direction the shared gain ``K = P[:, 0] / S`` and ``P`` in
    the Joseph form; ``P`` symmetrised."""
    s = P[0, 0] + r
    e = robot.difference(q, q_meas)
    gate = gate.measured(float(e.dot(e)) / s, threshold, e.size)
    if gate.gated:
        return _State(q, v, a, 0.5 * (P + P.T), gate)
    K = P[:, 0] / s
    IKH = np.eye(3) - np.outer(K, [1.0, 0.0, 0.0])
    P = IKH @ P @ IKH.T + r * np.outer(K, K)
    q = robot.integrate(q, K[0] * e)
    return _State(q, v + K[1] * e, a + K[2] * e, 0.5 * (P + P.T), gate)


#: ``jerk_psd="auto"``: the bank's dimensionless densities ``λ = (j / σ²) T⁵`` (module
#: docstring), every decade from 1e-14 (a bandwidth of about 0.005 / T) to 1e2 (about the
#: raw difference).
AUTO_LAMBDAS: tuple[float, ...] = tuple(float(10.0**e) for e in range(-14, 3))

#: ``jerk_psd="auto"``: measured samples (effective count ``N``) before the outlier gate acts.
AUTO_GATE_SAMPLES = 20.0

#: ``jerk_psd="auto"``: the likelihoods' default memory [measured samples].  In samples, not
#: seconds: the grid's filters remember from about 1 (λ = 1e2) to 200 samples (λ = 1e-14,
#: ``λ^(−1/6)`` periods), and the likelihood needs many such spans.  Measured (velocity RMS
#: over the best fixed density on the run): 1 kHz simulations (ur5, start error 0.05 rad,
#: 0.5 rad/s) 0.97–0.98× at 100 samples, 1.14–1.15× at 300, 1.3–1.7× at 500 to 2000 (the
#: start's transient, remembered, holds the density up); UR10e and TIAGo logs (~100 Hz)
#: within 5 % of each other from 50 to 1000 samples.
AUTO_MEMORY = 100.0

#: The density [rad²/s⁵] of :meth:`ConstantAccelerationKF.smoothing_filter` (and of its
#: :class:`KFGains`) with ``jerk_psd="auto"``: the fixed default before ``"auto"`` (an arm
#: tracking smooth references at 1 kHz).
SMOOTHING_JERK_PSD = 1e3


class _AutoState(NamedTuple):
    """``jerk_psd="auto"``'s state: a bank of ``n_f`` filters and their likelihoods."""

    bank: BankState  # the filters' states, rows (KFBank; defined below, a forward reference)
    jerk: Vector  # (n_f,): ρ_f σ₀² [rad²/s⁵] (empty until the period is known)
    n: float  # N: the forgotten count of measured samples
    A: Vector  # (n_f, nv): forgotten sums of e² / S
    B: Vector  # (n_f,): forgotten sums of log S
    w: Vector  # (n_f, nv): the mixture's weights
    gate: GateState = GateState()
    mix: Vector | None = None  # (2, nv): the estimate (Σ_f w q_f, Σ_f w v_f), if computed


def _auto_weights(n: float, A: Vector, B: Vector) -> Vector:
    """The mixture's weights ``w_fi ∝ exp(−(L_fi − min_f L_fi) / 2)``, ``L_fi = N log(A_fi /
    N) + B_f`` (module docstring; uniform before any sample)."""
    if n <= 0.0:
        return np.full(A.shape, 1.0 / A.shape[0])
    L = n * np.log(np.maximum(A, 1e-300) / n) + B[:, None]  # profile likelihood (Mehra 1970)
    w = np.exp(-0.5 * (L - L.min(axis=0)))
    return cast(Vector, w / w.sum(axis=0))


@register
class ConstantAccelerationKF(Observer["_State | _AutoState"]):
    """Per-joint Kalman filter on a constant-acceleration (white-jerk) model.

    Args:
        robot: the robot (only its Lie-group operations are used).
        jerk_psd: white-jerk spectral density [rad²/s⁵], or ``"auto"``: each joint's
            density (and noise level) from the data as it comes, by a bank of filters and
            their innovations' likelihoods (module docstring; :attr:`densities`).
        v0_std: initial velocity standard deviation [rad/s] when ``v0`` is not given.
        outlier_probability: false-alarm probability of the outlier gate (as in ``ekf``; a
            rejected measurement leaves the prediction), or ``None``: no gate.
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
            self.noise_std or NOISE_FLOOR,
            outlier_probability,
        )
        self._gate = gate_threshold(outlier_probability, robot.nv)[1]
        self._bank_cache: KFBank | None = None
        # "auto" on vector joints: its compiled step loaded now, not at the first update
        self._forget = math.exp(-1.0 / self.auto_memory)  # γ (module docstring)
        self._bank_var = float(self.gains.meas_std) ** 2  # as KFBank's meas_var
        self._no_sample = np.zeros(robot.nv)
        self._dof = float(robot.nv)  # the gate's level before any (outlier_gate)
        if self.auto and robot.is_vector_space:
            _auto_kernel.load()

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
        if not isinstance(state, _AutoState):
            return np.full(self.robot.nv, self.gains.jerk_psd)
        if state.n <= 0.0 or not state.jerk.size:
            return np.full(self.robot.nv, math.nan)
        scale = np.maximum(state.A / state.n, 1e-300)
        return cast(Vector, np.exp(np.sum(state.w * np.log(state.jerk[:, None] * scale), axis=0)))

    @property
    def noise_stds(self) -> Vector:
        """Each joint's measurement noise σ [rad or m]: ``noise_std``, or with ``"auto"`` the
        bank's ``√exp Σ_f w_fi log(ĉ_fi σ₀²)`` (module docstring; ``nan`` before a sample)."""
        state = self._state
        if state is None:
            raise NotResetError(f"{self!r}: call reset(t0, q0) first")
        if not isinstance(state, _AutoState):
            return np.full(self.robot.nv, self.gains.meas_std)
        if state.n <= 0.0:
            return np.full(self.robot.nv, math.nan)
        scale = np.maximum(state.A / state.n, 1e-300) * self.gains.meas_std**2
        return cast(Vector, np.sqrt(np.exp(np.sum(state.w * np.log(scale), axis=0))))

    def _initial_p(self) -> Vector:
        return np.diag(
            np.array([self.gains.meas_std**2, self.v0_std**2, (10.0 * self.v0_std) ** 2])
        )

    def initial_state(self, q0: Vector, v0: Vector) -> _State | _AutoState:
        P = self._initial_p()
        if not self.auto:
            return _State(q0.copy(), v0.copy(), np.zeros_like(v0), P)
        n_f, nv = len(AUTO_LAMBDAS), v0.size
        jerk = np.empty(0) if self.rate is None else self._grid(1.0 / self.rate)
        bank = BankState(
            np.tile(q0, (n_f, 1)), np.tile(v0, (n_f, 1)), np.zeros((n_f, nv)),
            np.tile(P, (n_f, 1, 1)), None,
        )  # fmt: skip
        w = np.full((n_f, nv), 1.0 / n_f)
        return _AutoState(bank, jerk, 0.0, np.zeros((n_f, nv)), np.zeros(n_f), w)

    def restart_state(self, state: _State | _AutoState, q: Vector) -> _State | _AutoState:
        """After a pause: afresh, but ``"auto"`` keeps its likelihoods (what it learned)."""
        fresh = self.initial_state(q, np.zeros(self.robot.nv))
        if isinstance(state, _AutoState) and isinstance(fresh, _AutoState):
            return fresh._replace(jerk=state.jerk, n=state.n, A=state.A, B=state.B, w=state.w)
        return fresh

    def _grid(self, period: float) -> Vector:
        """The bank's densities ``ρ_f σ₀² = λ_f σ₀² / T⁵`` [rad²/s⁵] (module docstring)."""
        return np.array(AUTO_LAMBDAS) * self.gains.meas_std**2 / period**5

    def step(
        self, state: _State | _AutoState, dt: float, q_meas: Vector | None, tau: Vector
    ) -> _State | _AutoState:
        if isinstance(state, _AutoState):
            return self._auto_step(state, dt, q_meas)
        F, Q = transition(dt, self.gains.jerk_psd)
        q, v, a, P = _predicted(self.robot, state.q, state.v, state.a, state.P, F, Q, dt)
        if q_meas is None:
            return _State(q, v, a, 0.5 * (P + P.T), state.gate.predicted())
        r = self.gains.meas_std**2
        return _corrected(self.robot, q, v, a, P, state.gate, r, self._gate, q_meas)

    def _bank(self, jerk: Vector) -> KFBank:
        """The :class:`KFBank` stepping the filters of densities ``jerk`` (built once)."""
        if self._bank_cache is None or not np.array_equal(self._bank_cache.jerk, jerk):
            self._bank_cache = KFBank(self.robot, tuple(jerk.tolist()), self.gains.meas_std)
        return self._bank_cache

    def _auto_step(self, state: _AutoState, h: float, q_meas: Vector | None) -> _AutoState:
        """One step of the bank (module docstring, ``jerk_psd="auto"``): each filter's
        prediction and correction (:meth:`KFBank.step`: the equations of :meth:`step`),
        the forgotten likelihood sums, the mixture's weights.  On vector joints one compiled
        call (:func:`_auto_step_loops`) into arrays allocated here (the state before is kept
        as it was); otherwise NumPy, the configurations filter by filter."""
        jerk = state.jerk if state.jerk.size else self._grid(h)
        kernel = _auto_kernel.compiled
        if kernel is not None and self.robot.is_vector_space:
            return self._auto_step_compiled(kernel, state, jerk, h, q_meas)
        bank = self._bank(jerk)
        if q_meas is None:
            return state._replace(
                bank=bank.step(state.bank, h, None), jerk=jerk, gate=state.gate.predicted()
            )
        new = bank.step(state.bank, h, q_meas)
        e = cast(Vector, new.innovation)  # (n_f, nv): difference(q⁻_f, q_meas)
        f0 = np.array([1.0, h, 0.5 * h * h])  # F's first row: S = (F P Fᵀ)₀₀ + j h⁵/20 + σ₀²
        S = np.einsum("i,fij,j->f", f0, state.bank.P, f0) + jerk * h**5 / 20 + bank.meas_var
        z = e * e / S[:, None]
        if state.n >= AUTO_GATE_SAMPLES:  # the scales ĉ and weights before this sample
            nis = float(np.sum(state.w * z / np.maximum(state.A / state.n, 1e-300)))
            gate = state.gate.measured(nis, self._gate, self.robot.nv)
        else:  # too few samples for a scale: reported (with σ₀), not gated
            gate = GateState(float(np.sum(state.w * z)))
        if gate.gated:  # the prediction (its likelihoods unchanged)
            return state._replace(bank=bank.step(state.bank, h, None), jerk=jerk, gate=gate)
        forget = math.exp(-1.0 / self.auto_memory)  # γ (module docstring)
        n = forget * state.n + 1.0  # the forgotten sums (module docstring)
        A, B = forget * state.A + z, forget * state.B + np.log(S)
        return _AutoState(new, jerk, n, A, B, _auto_weights(n, A, B), gate)

    def _auto_step_compiled(
        self,
        kernel: Callable[..., tuple[float, bool, float]],
        state: _AutoState,
        jerk: Vector,
        h: float,
        q_meas: Vector | None,
    ) -> _AutoState:
        """:meth:`_auto_step` on vector joints: :func:`_auto_step_loops` (the same equations,
        tested equal to the NumPy ones to 1e-12)."""
        b, gate = state.bank, state.gate
        gate_on = state.n >= AUTO_GATE_SAMPLES  # the scales ĉ and weights before this sample
        n_new = self._forget * state.n + 1.0  # the forgotten count (module docstring)
        new = (
            np.empty_like(b.v), np.empty_like(b.v), np.empty_like(b.v), np.empty_like(b.P),
            np.empty_like(b.v), np.empty_like(state.A), np.empty_like(state.B),
            np.empty_like(state.w), np.empty((2, b.v.shape[1])),
        )  # fmt: skip
        nis, rejected, level = kernel(
            b.q, b.v, b.a, b.P, state.A, state.B, state.w, jerk, h, self._bank_var,
            self._no_sample if q_meas is None else q_meas, q_meas is not None, gate_on,
            state.n, n_new, self._forget, self._gate,
            self._dof if gate.level is None else gate.level, gate.run, *new,
        )  # fmt: skip
        q, v, a, P, e, A, B, w, mix = new
        if q_meas is None:  # the prediction (its likelihoods unchanged)
            return _AutoState(
                BankState(q, v, a, P, None), jerk, state.n, A, B, w, gate.predicted(), mix
            )
        if not gate_on:  # too few samples for a scale: reported (with σ₀), not gated
            after = GateState(nis)
        else:  # GateState.measured, decided in the kernel
            after = GateState(nis, rejected, gate.run + 1 if rejected else 0, level)
        if rejected:  # the prediction (its likelihoods unchanged)
            return _AutoState(BankState(q, v, a, P, None), jerk, state.n, A, B, w, after, mix)
        return _AutoState(BankState(q, v, a, P, e), jerk, n_new, A, B, w, after, mix)

    def consistency(self) -> Consistency:
        """The NIS test of the base class; its causes are a model-free filter's.  With
        ``"auto"`` the NIS is scaled by each joint's learnt noise level: about ``nv`` by
        construction (the test then checks only the shape of the innovations)."""
        base = super().consistency()
        return replace(base, causes=KF_CAUSES) if base.causes else base

    def output(self, state: _State | _AutoState) -> tuple[Vector, Vector]:
        if not isinstance(state, _AutoState):
            return state.q, state.v
        if state.mix is not None:  # computed by the compiled step
            return state.mix[0], state.mix[1]
        w, b = state.w, state.bank
        v = np.sum(w * b.v, axis=0)
        if self.robot.is_vector_space:
            return np.sum(w * b.q, axis=0), v
        ref = int(np.argmax(w.sum(axis=1)))  # the mixture in the tangent space of one filter
        d = np.array([self.robot.difference(b.q[ref], x) for x in b.q])
        return self.robot.integrate(b.q[ref], np.sum(w * d, axis=0)), v

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
        q, v, a, P3 = _predicted(self.robot, state.q, state.v, state.d, state.P3, F, Q, dt)
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
        new = _corrected(
            self.robot, q, v, a, P3, state.gate, self.gains.meas_std**2, self._gate, q_meas
        )
        if new.gate.gated:  # the prediction, as it is
            return state._replace(gate=new.gate)
        return self._full(*new)

    def gate_limit(self, state: ErrorState) -> float:
        """The NIS above which :meth:`correct` rejected ``state``'s measurement."""
        return state.gate.limit(self._gate, self.robot.nv)


class BankState(NamedTuple):
    """States of a bank of ``F`` per-joint filters (:class:`KFBank`): rows are filters."""

    q: Vector  # (F, nq)
    v: Vector  # (F, nv)
    a: Vector  # (F, nv)
    P: Vector  # (F, 3, 3)
    innovation: Vector | None  # (F, nv): each filter's innovation at the last sample


def _bank_rows_loops(
    q: Vector,
    v: Vector,
    a: Vector,
    P: Vector,
    t: Vector,
    q_meas: Vector,
    measured: NDArray[np.bool_],
    jerk: Vector,
    meas_var: float,
    gate: float,
    level: Vector,
    run: NDArray[np.int64],
    ll: Vector,
    e: Vector,
    X: Vector,
    PX: Vector,
    used: NDArray[np.bool_],
) -> None:
    """A bank of filters on vector joints over rows ``1..`` of ``(t, q_meas, measured)``, from
    its state at ``t[0]``, in loops (compiled by numba); the state arrays updated in place.

    The equations of the module docstring per filter ``f`` (row) and row ``k``, with
    ``h = t[k] − t[k−1]``: predict with ``F(h)`` and ``Q(h) = jerk[f] · Q₁(h)``, then, if
    ``measured[k]``, the gain ``K = P⁻[:, 0] / S`` with ``S = P⁻₀₀ + σ²``, the innovation
    ``e = q_meas[k] − q⁻`` per joint, the Joseph form
    ``P = (I − K e₀ᵀ) P⁻ (I − K e₀ᵀ)ᵀ + σ² K Kᵀ`` (symmetrised), and
    ``ll[f] += log N(e; 0, S I)`` (the prediction-error decomposition, Schweppe 1965); the
    outlier gate first (:func:`pinobs.observers.base.outlier_gate`: ``gate`` its threshold,
    ``inf`` for none; ``level`` and ``run`` each filter's, updated): a rejected measurement
    leaves the prediction and counts in ``ll`` at the gate (as
    :func:`pinobs.observers.smoothing._forward`).  ``e`` receives the innovations of the last
    row, when it is measured.  When ``X`` has rows, ``X[k] = (q, v, a)``, ``PX[k] = P`` and
    ``used[k]`` (corrected with its measurement) of filter 0 at every row ``k`` (row 0
    included: not corrected).
    """
    nf, nv = v.shape
    store = X.shape[0] > 0
    F = np.eye(3)
    Q1 = np.zeros((3, 3))
    FP = np.empty((3, 3))
    Pp = np.empty((3, 3))
    C = np.empty((3, 3))
    K = np.empty(3)
    h_prev = math.nan
    for k in range(t.size):
        if k > 0:
            h = t[k] - t[k - 1]
            if h != h_prev:
                F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h
                Q1[0, 0], Q1[0, 1], Q1[0, 2] = h**5 / 20, h**4 / 8, h**3 / 6
                Q1[1, 1], Q1[1, 2], Q1[2, 2] = h**3 / 3, h**2 / 2, h
                Q1[1, 0], Q1[2, 0], Q1[2, 1] = Q1[0, 1], Q1[0, 2], Q1[1, 2]
                h_prev = h
            for f in range(nf):
                for i in range(3):  # FP = F P
                    for j in range(3):
                        s = 0.0
                        for m in range(3):
                            s += F[i, m] * P[f, m, j]
                        FP[i, j] = s
                for i in range(3):  # P⁻ = F P Fᵀ + Q
                    for j in range(3):
                        s = 0.0
                        for m in range(3):
                            s += FP[i, m] * F[j, m]
                        Pp[i, j] = s + jerk[f] * Q1[i, j]
                for i in range(nv):
                    q[f, i] = q[f, i] + v[f, i] * h + 0.5 * h * h * a[f, i]
                    v[f, i] = v[f, i] + h * a[f, i]
                if not measured[k]:
                    for i in range(3):
                        for j in range(3):
                            P[f, i, j] = Pp[i, j]
                    continue
                s = Pp[0, 0] + meas_var
                sq = 0.0
                for i in range(nv):
                    ei = q_meas[k, i] - q[f, i]
                    e[f, i] = ei
                    sq += ei * ei
                nis = sq / s
                # GateState.measured (base.outlier_gate), in loops: tested equal
                g = gate * max(1.0, level[f] / nv)
                if nis > g and run[f] < MAX_GATE_RUN:
                    run[f] += 1
                    ll[f] -= 0.5 * (g + nv * math.log(2.0 * math.pi * s))
                    for i in range(3):
                        for j in range(3):
                            P[f, i, j] = Pp[i, j]
                    continue
                if run[f] >= MAX_GATE_RUN:
                    level[f] = max(level[f], nis * nv / gate)
                level[f] += NIS_AVERAGING * (min(nis, 100.0 * level[f]) - level[f])
                run[f] = 0
                if f == 0 and store:
                    used[k] = True
                ll[f] -= 0.5 * (nis + nv * math.log(2.0 * math.pi * s))
                for i in range(3):
                    K[i] = Pp[i, 0] / s
                for i in range(nv):
                    ei = e[f, i]
                    q[f, i] += K[0] * ei
                    v[f, i] += K[1] * ei
                    a[f, i] += K[2] * ei
                for i in range(3):  # C = (I − K e₀ᵀ) P⁻
                    for j in range(3):
                        C[i, j] = Pp[i, j] - K[i] * Pp[0, j]
                for i in range(3):  # C (I − K e₀ᵀ)ᵀ + σ² K Kᵀ
                    for j in range(3):
                        Pp[i, j] = C[i, j] - C[i, 0] * K[j] + meas_var * K[i] * K[j]
                for i in range(3):
                    for j in range(3):
                        P[f, i, j] = 0.5 * (Pp[i, j] + Pp[j, i])
        if store:
            for i in range(nv):
                X[k, 0, i], X[k, 1, i], X[k, 2, i] = q[0, i], v[0, i], a[0, i]
            for i in range(3):
                for j in range(3):
                    PX[k, i, j] = P[0, i, j]


_NO_STORE = np.empty((0, 3, 0))
_NO_PX = np.empty((0, 3, 3))
_ROW_MEASURED = (np.array([False, False]), np.array([False, True]))  # KFBank.step's rows
_bank_kernel = LazyKernel(
    _bank_rows_loops,
    np.zeros((1, 1)),
    np.zeros((1, 1)),
    np.zeros((1, 1)),
    np.tile(np.eye(3), (1, 1, 1)),
    np.array([0.0, 1e-3]),
    np.zeros((2, 1)),
    np.array([False, True]),
    np.ones(1),
    1.0,
    math.inf,
    np.ones(1),
    np.zeros(1, dtype=np.int64),
    np.zeros(1),
    np.zeros((1, 1)),
    np.zeros((2, 3, 1)),
    np.zeros((2, 3, 3)),
    np.zeros(2, dtype=bool),
)
_NO_USED = np.zeros(0, dtype=bool)


def _auto_step_loops(
    q: Vector,
    v: Vector,
    a: Vector,
    P: Vector,
    A: Vector,
    B: Vector,
    w: Vector,
    jerk: Vector,
    h: float,
    meas_var: float,
    q_meas: Vector,
    measured: bool,
    gate_on: bool,
    n: float,
    n_new: float,
    forget: float,
    threshold: float,
    level: float,
    run: int,
    q1: Vector,
    v1: Vector,
    a1: Vector,
    P1: Vector,
    e1: Vector,
    A1: Vector,
    B1: Vector,
    w1: Vector,
    mix: Vector,
) -> tuple[float, bool, float]:
    """One step of ``jerk_psd="auto"`` on vector joints (module docstring), in loops compiled
    by numba: the bank's prediction and correction (:func:`_bank_rows_loops`'s arithmetic, one
    row), the outlier gate, the forgotten likelihood sums, the weights and the mixture.

    Reads the state ``(q, v, a, P, A, B, w)`` (``n`` its count, ``n_new = γ n + 1``), writes
    the next one into ``(q1, v1, a1, P1, A1, B1, w1)`` (all preallocated by the caller: the
    state before is left as it was), the innovations ``e_fi = q_meas_i − q⁻_fi`` into ``e1``
    and the mixture ``(Σ_f w_fi q_fi, Σ_f w_fi v_fi)`` into ``mix`` (2, nv).  With
    ``measured``: ``S_f = P⁻_f,00 + σ₀²``, ``z_fi = e_fi² / S_f``, the gate's NIS
    ``Σ w_fi z_fi / max(A_fi / N, 1e-300)`` (``gate_on``) or ``Σ w_fi z_fi`` (too few
    samples: not gated), :func:`pinobs.observers.base.outlier_gate` on it (``threshold``,
    ``level`` the gate's, ``nv`` its degrees of freedom, ``run`` its rejections in a row: in
    loops, tested equal to :meth:`GateState.measured`); a rejected measurement leaves the
    prediction and the sums; else the Kalman correction (Joseph form, symmetrised),
    ``A ← γ A + z``, ``B ← γ B + log S`` and ``w_fi ∝ exp(−(L_fi − min_f L_fi) / 2)``,
    ``L_fi = N log(max(A_fi, 1e-300) / N) + B_f`` (Mehra 1970's profile likelihood).
    Returns ``(nis, rejected, level after)`` (``nis`` NaN without a measurement).
    """
    nf, nv = v.shape
    F = np.eye(3)
    F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h
    Q1 = np.zeros((3, 3))
    Q1[0, 0], Q1[0, 1], Q1[0, 2] = h**5 / 20, h**4 / 8, h**3 / 6
    Q1[1, 1], Q1[1, 2], Q1[2, 2] = h**3 / 3, h**2 / 2, h
    Q1[1, 0], Q1[2, 0], Q1[2, 1] = Q1[0, 1], Q1[0, 2], Q1[1, 2]
    FP = np.empty((3, 3))
    S = np.empty(nf)
    for f in range(nf):  # predict: x ← F x, P⁻ = F P Fᵀ + j_f Q₁(h)
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += F[i, m] * P[f, m, j]
                FP[i, j] = s
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += FP[i, m] * F[j, m]
                P1[f, i, j] = s + jerk[f] * Q1[i, j]
        for i in range(nv):
            q1[f, i] = q[f, i] + v[f, i] * h + 0.5 * h * h * a[f, i]
            v1[f, i] = v[f, i] + h * a[f, i]
            a1[f, i] = a[f, i]
        S[f] = P1[f, 0, 0] + meas_var
    nis = math.nan
    reject = False
    accept = measured
    if measured:
        nis = 0.0
        for f in range(nf):
            for i in range(nv):
                ei = q_meas[i] - q1[f, i]
                e1[f, i] = ei
                z = ei * ei / S[f]
                A1[f, i] = z  # z for now: the sums below
                if gate_on:
                    nis += w[f, i] * z / max(A[f, i] / n, 1e-300)
                else:
                    nis += w[f, i] * z
        if gate_on:  # base.outlier_gate, in loops
            if nis > threshold * max(1.0, level / nv) and run < MAX_GATE_RUN:
                reject = True
            else:
                if run >= MAX_GATE_RUN:
                    level = max(level, nis * nv / threshold)
                level = level + NIS_AVERAGING * (min(nis, 100.0 * level) - level)
        accept = not reject
    if accept:
        K = np.empty(3)
        C = np.empty((3, 3))
        Pn = np.empty((3, 3))
        for f in range(nf):  # correct: K = P⁻[:, 0] / S, the Joseph form
            s = S[f]
            for i in range(3):
                K[i] = P1[f, i, 0] / s
            for i in range(nv):
                ei = e1[f, i]
                q1[f, i] += K[0] * ei
                v1[f, i] += K[1] * ei
                a1[f, i] += K[2] * ei
            for i in range(3):  # C = (I − K e₀ᵀ) P⁻
                for j in range(3):
                    C[i, j] = P1[f, i, j] - K[i] * P1[f, 0, j]
            for i in range(3):  # C (I − K e₀ᵀ)ᵀ + σ² K Kᵀ
                for j in range(3):
                    Pn[i, j] = C[i, j] - C[i, 0] * K[j] + meas_var * K[i] * K[j]
            for i in range(3):
                for j in range(3):
                    P1[f, i, j] = 0.5 * (Pn[i, j] + Pn[j, i])
            B1[f] = forget * B[f] + math.log(s)  # the forgotten sums (module docstring)
            for i in range(nv):
                A1[f, i] = forget * A[f, i] + A1[f, i]
        for f in range(nf):  # L_fi (into w1), the profile likelihood (Mehra 1970)
            for i in range(nv):
                w1[f, i] = n_new * math.log(max(A1[f, i], 1e-300) / n_new) + B1[f]
        for i in range(nv):  # w_fi ∝ exp(−(L_fi − min_f L_fi) / 2), summed over f in order
            low = w1[0, i]
            for f in range(1, nf):
                low = min(low, w1[f, i])
            for f in range(nf):  # exp(x) = 0 exactly below −745.2: not called there
                x = -0.5 * (w1[f, i] - low)
                w1[f, i] = math.exp(x) if x > -746.0 else 0.0
            total = w1[0, i]
            for f in range(1, nf):
                total += w1[f, i]
            for f in range(nf):
                w1[f, i] = w1[f, i] / total
    else:  # no measurement, or rejected: the sums and weights as they were
        for f in range(nf):
            B1[f] = B[f]
            for i in range(nv):
                A1[f, i] = A[f, i]
                w1[f, i] = w[f, i]
    for i in range(nv):  # the mixture, summed over f in order
        mq = w1[0, i] * q1[0, i]
        mv = w1[0, i] * v1[0, i]
        for f in range(1, nf):
            mq += w1[f, i] * q1[f, i]
            mv += w1[f, i] * v1[f, i]
        mix[0, i], mix[1, i] = mq, mv
    return nis, reject, level


def _auto_warm_args() -> tuple[object, ...]:
    """Arguments of :data:`_auto_kernel`'s one signature (float64 C arrays, as the step gives)."""
    nf, nv = 2, 1
    z2, P = np.zeros((nf, nv)), np.tile(np.eye(3), (nf, 1, 1))
    return (
        z2, z2.copy(), z2.copy(), P, np.ones((nf, nv)), np.zeros(nf), np.full((nf, nv), 0.5),
        np.ones(nf), 1e-3, 1.0, np.zeros(nv), True, True, 30.0, 30.0, 0.99, math.inf, 1.0, 0,
        *(np.empty((nf, nv)) for _ in range(3)), np.empty((nf, 3, 3)), np.empty((nf, nv)),
        np.empty((nf, nv)), np.empty(nf), np.empty((nf, nv)), np.empty((2, nv)),
    )  # fmt: skip


#: :func:`_auto_step_loops` compiled (loaded when a vector-joint ``kf`` with ``"auto"`` is made).
_auto_kernel = LazyKernel(_auto_step_loops, *_auto_warm_args())


class KFBank:
    """Several :class:`ConstantAccelerationKF` filters with different ``jerk_psd``, stepped together.

    The same equations as the family (module docstring), one filter per row
    of the arrays.  On robots whose joints are all vector joints a step is one
    compiled loop (:func:`_bank_rows_loops`, numba; a NumPy step cost about 15 ``pin.aba``
    calls on a UR5, mostly in dispatching small-array operations); otherwise NumPy
    arrays, the configuration part filter by filter through ``integrate``/``difference``.
    Both paths are tested equal to separate :class:`ConstantAccelerationKF` filters.
    Each step also returns every filter's innovation ``e = difference(q̂⁻, q_meas)``,
    which the adaptive observer uses to pick the best filter per joint; :meth:`step` has no
    outlier gate (the adaptive observer gives it only the samples its own gate keeps),
    :meth:`run` over a log has the filters' (``outlier_probability``).
    """

    def __init__(
        self,
        robot: Robot,
        jerk_psd: tuple[float, ...],
        meas_std: float,
        outlier_probability: float | None = None,
    ) -> None:
        self.robot = robot
        self.jerk = np.array([float(positive("jerk_psd", j) or 0.0) for j in jerk_psd])
        self.meas_var = float(positive("meas_std", meas_std) or 0.0) ** 2
        self.gate = gate_threshold(outlier_probability, robot.nv)[1]
        self._cache: tuple[float, Vector, Vector] | None = None
        n = self.jerk.size  # step's scratch (its likelihood and gate are not kept)
        self._ll, self._level, self._run = np.zeros(n), np.ones(n), np.zeros(n, dtype=np.int64)
        if robot.is_vector_space:
            _bank_kernel.load()

    def initial(self, q0: Vector, v0: Vector, v0_std: float) -> BankState:
        n = self.jerk.size
        P = np.diag([self.meas_var, v0_std**2, (10.0 * v0_std) ** 2])
        return BankState(
            np.tile(q0, (n, 1)), np.tile(v0, (n, 1)), np.zeros((n, v0.size)),
            np.tile(P, (n, 1, 1)), None,
        )  # fmt: skip

    def log_likelihoods(self, t: Vector, q: Vector, good: Vector, v0_std: float) -> Vector:
        """Each filter's innovation log-likelihood over a log, in one pass: ``Σ_k log N(e_k;
        0, S_k I)`` over the measured samples ``k ≥ 1`` (``good[k]``), ``S_k = P⁻₀₀ + σ²``
        (the prediction-error decomposition, Schweppe 1965; a sample the gate rejects counted
        at the gate), started at ``q[0]`` with ``v = 0`` (:meth:`initial`); what
        :func:`pinobs.observers.smoothing.select_accel_psd` computes for ``kf`` filter by
        filter (tested equal)."""
        return self.run(t, q, good, v0_std, store=False)[0]

    def run(
        self, t: Vector, q: Vector, good: Vector, v0_std: float, *, store: bool = True
    ) -> tuple[Vector, Vector, Vector, Vector]:
        """The bank over a log from :meth:`initial` at ``q[0]`` with ``v = 0``, with the outlier
        gate: each filter's innovation log-likelihood (:meth:`log_likelihoods`) and, with
        ``store``, the first filter's state at every row, ``X[k] = (q, v, a)`` of shape
        ``(3, nv)``, its 3×3 covariance ``PX[k]`` and whether it was corrected with the row's
        measurement, ``used[k]`` (all three empty without; ``store`` needs ``nq = nv``).  On
        vector joints one compiled pass (:func:`_bank_rows_loops`), otherwise each filter in
        turn as :class:`ConstantAccelerationKF` steps."""
        nv, n_f = self.robot.nv, self.jerk.size
        n = t.size if store else 0
        X, PX, used = np.empty((n, 3, nv)), np.empty((n, 3, 3)), np.zeros(n, dtype=bool)
        ll = np.zeros(n_f)
        state = self.initial(q[0], np.zeros(nv), v0_std)
        if self.robot.is_vector_space and _bank_kernel.compiled is not None:
            q_meas = np.ascontiguousarray(np.where(good[:, None], q, 0.0), dtype=float)
            _bank_kernel.compiled(
                *(np.array(x) for x in state[:4]), np.ascontiguousarray(t, dtype=float), q_meas,
                np.ascontiguousarray(good, dtype=bool), self.jerk, self.meas_var, self.gate,
                np.full(n_f, float(nv)), np.zeros(n_f, dtype=np.int64), ll,
                np.empty((n_f, nv)), X if store else _NO_STORE, PX, used if store else _NO_USED,
            )  # fmt: skip
            return ll, X, PX, used
        for f in range(n_f):  # the causal filter's own steps, the likelihood as _forward's
            one = _State(state.q[f], state.v[f], state.a[f], state.P[f])
            for k in range(t.size):
                if k > 0:
                    h = float(t[k] - t[k - 1])
                    F, Q = transition(h, float(self.jerk[f]))
                    qk, vk, ak, Pk = _predicted(self.robot, one.q, one.v, one.a, one.P, F, Q, h)
                    one = _State(qk, vk, ak, Pk, one.gate.predicted())
                    if good[k]:
                        s = Pk[0, 0] + self.meas_var
                        one = _corrected(
                            self.robot, qk, vk, ak, Pk, one.gate, self.meas_var, self.gate, q[k]
                        )
                        cap = one.gate.limit(self.gate, nv) if one.gate.gated else math.inf
                        nis = min(cast(float, one.gate.nis), cap)
                        ll[f] -= 0.5 * (nis + nv * math.log(2.0 * math.pi * s))
                if store and f == 0:
                    X[k], PX[k], used[k] = (
                        (one.q, one.v, one.a),
                        one.P,
                        k > 0 and one.gate.nis is not None and not one.gate.gated,
                    )
        return ll, X, PX, used

    def step(self, state: BankState, dt: float, q_meas: Vector | None) -> BankState:
        r = self.robot
        if r.is_vector_space and _bank_kernel.compiled is not None:
            measured = q_meas is not None
            q, v, a, P = state.q.copy(), state.v.copy(), state.a.copy(), state.P.copy()
            e = np.empty_like(v)
            rows = np.empty((2, v.shape[1]))
            if measured:
                rows[1] = q_meas
            _bank_kernel.compiled(
                q, v, a, P, np.array([0.0, dt]), rows, _ROW_MEASURED[measured], self.jerk,
                self.meas_var, math.inf, self._level, self._run, self._ll, e, _NO_STORE, _NO_PX,
                _NO_USED,
            )  # fmt: skip
            return BankState(q, v, a, P, e if measured else None)
        if self._cache is None or self._cache[0] != dt:
            F, Q = transition(dt, 1.0)
            self._cache = (dt, F, self.jerk[:, None, None] * Q)
        _, F, Q = self._cache
        step = state.v * dt + 0.5 * dt * dt * state.a
        q = np.array([r.integrate(x, s) for x, s in zip(state.q, step, strict=True)])
        v = state.v + dt * state.a
        a = state.a
        P = F @ state.P @ F.T + Q
        if q_meas is None:
            return BankState(q, v, a, P, None)
        e = np.array([r.difference(x, q_meas) for x in q])
        K = P[:, :, 0] / (P[:, 0, 0] + self.meas_var)[:, None]  # (F, 3)
        q = np.array([r.integrate(x, k * y) for x, k, y in zip(q, K[:, 0], e, strict=True)])
        v = v + K[:, 1:2] * e
        a = a + K[:, 2:3] * e
        IKH = np.eye(3) - K[:, :, None] * np.array([1.0, 0.0, 0.0])  # Joseph form, per filter
        P = IKH @ P @ IKH.transpose(0, 2, 1) + self.meas_var * K[:, :, None] * K[:, None, :]
        return BankState(q, v, a, 0.5 * (P + P.transpose(0, 2, 1)), e)
