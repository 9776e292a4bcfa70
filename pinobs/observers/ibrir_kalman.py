"""Ibrir's Kalman observer on the state-affine form (Theorem 3.1).

With the output derivative injected, ``M(q) q̈ + C(q, q̇) q̇ + C_f q̇ + g(q) = τ``
is a linear time-varying system in ``x = (q, v)`` (Ibrir eqs. 3–6)::

    ẋ = F(y, ẏ) x + G(y, τ),   y = C x = q,
    F(y, ẏ) = [[0, I], [0, −M⁻¹(y)(C(y, ẏ) + C_f)]],   G(y, τ) = [0; M⁻¹(y)(τ − g(y))]

with ``ẏ`` from a dynamic-gain differentiator (Theorem 2.1; Theorem 3.1 uses
order 2, here ``diff_order``).  Theorem 3.1, with its ``A₂ₓ₂`` read as the
chain ``[[0,1],[0,0]]`` (MATH §6)::

    x̂̇ = F(y, ξ̂) x̂ + P Cᵀ R (y − C x̂) + G(y, τ)
    Ṗ  = F P + P Fᵀ − P Cᵀ R C P            (+ Q: the practical form)

``R`` [1/(rad²·s)] weights the output in continuous time; ``C(y, ẏ)`` is
Pinocchio's Coriolis matrix (``C ẏ = c``); ``C_f`` = ``viscous`` (diagonal)
plus the local damping of the robot's own joint friction at ``ẏ``, whose
remainder joins ``G`` (:meth:`IbrirKalman.friction_affine`).

Sampled data (MATH §7).  Over ``[t_{k−1}, t_k]`` the scheduling output
``y(t)`` is the measured one interpolated on the group,
``y_{k−1} ⊕ s·difference(y_{k−1}, y_k)`` (``schedule="measured"``, the
paper's ``F(y, ·)``, ``G(y, ·)``; ``"filtered"`` uses the differentiator's
``ŷ`` instead, also the fallback when a sample is missing).  The mean is
propagated by one RKMK4 step of ``x̂̇ = F(y(t), ẏ(t)) x̂ + G(y(t), τ)``, the
covariance with ``F`` frozen at the interval's midpoint::

    P⁻ = Φ P Φᵀ (+ Q_d),   Φ = exp(F h) (third-order series),

and the correction at the sample is the Kalman update with measurement
variance ``1/(R h)``: its gain ``P⁻ (P⁻ + 1/(Rh))⁻¹ → h P R`` is the paper's
continuous correction integrated over the interval, and the covariance
update is the sampled Riccati term ``−P Cᵀ R C P h``.  On Lie-group joints
``q̂ ← q̂ ⊕ (…)``, the innovation is ``difference(q̂, y)``, and the error
dynamics get ``δq̇ = −ad_ẏ δq + δv`` (zero on vector joints, where the
printed form is exact).

Where ``ẏ`` comes from (``velocity_source``):

* ``"differentiator"`` (the paper): ``ξ̂₂`` of the dynamic-gain
  differentiator, linearly interpolated over the interval.  Its error on
  ``ẏ`` (lag and noise) enters ``F`` as model error: on a UR5 at 1 kHz,
  σ = 1e-4 rad, the best process noise (1e-6) leaves 2.5e-4 rad/s RMS, 7×
  the exact-model EKF.
* ``"estimate"`` (certainty equivalence): the observer's own ``v̂(t)``
  inside the RK4 step, so the mean follows the exact model evaluated at the
  measured ``y``; 3.4e-5 rad/s on the same run, equal to the EKF.  The
  covariance still uses the state-affine ``F`` (no ``∂a/∂q``: the
  configuration dependence is injected through ``y``).

Which form to use:

* ``form="paper"`` (no process noise; ``ẏ`` from the differentiator by
  default): right when the model and ``ẏ`` are exact, the assumption behind
  "for γ → ∞": then ``P → 0`` is the right answer (the estimate averages all
  past data), e.g. the noise-free simulations of Ibrir §4.  With noisy data,
  a lagging ``ẏ`` or model error its gain fades and the estimate is left to
  a wrong model (on the §4 example its error settles near 1e-2).
* ``form="practical"`` (default; ``ẏ = v̂`` by default): adds a white
  acceleration process noise of density ``accel_psd`` [rad²/s³] standing
  for the model error, which keeps the gain alive.  Raise ``accel_psd``
  with the model's uncertainty exactly as for :mod:`pinobs.observers.ekf`.

Consistency and outliers (as :mod:`pinobs.observers.ekf`).  The innovation
``e = difference(q̂⁻, q_meas)`` has the predicted covariance
``S = P⁻_qq + 1/(R h)``; ``NIS = eᵀ S⁻¹ e`` (χ²(nv) when the model and the
noise level are right; the paper's form, whose ``P → 0``, is not) is on
``Estimate.nis`` and feeds :meth:`consistency`.  A sample whose NIS the
shared gate rejects (:func:`pinobs.observers.base.outlier_gate`, option
``outlier_probability``) is used nowhere: the step is redone without it (it
had entered the schedule ``y(t)`` and the differentiator too), and the
estimate is that prediction.

Implementation (issue 18).  On vector-space robots without joint friction
(``nv ≤ 12``), ``F`` at the midpoint, ``Φ``, ``P⁻ = Φ P Φᵀ + Q_d``, the Joseph
update and the NIS are one compiled call (numba, the ekf's two kernels
inside; compiled once per installation, loaded by the constructor), fed
with ``M`` and ``C + C_f``; ``⊕`` and ``⊖`` are NumPy's ``+`` and ``−`` there.
Outputs equal the dense pre-optimisation form to 2e-14 (tested to 1e-12).
Measured: 27.3 → 21.1 × ``pin.aba`` per update on the UR5 (medians of six
runs of :func:`pinobs.evaluation.measure_cost` each, in the same process,
ranges 26.6–28.8 and 20.9–21.6, on a loaded shared 2-core machine).
Issue 39: there, with ``velocity_source="estimate"``, ``schedule="measured"`` and no
``viscous`` (the defaults), the whole step is six compiled calls around Pinocchio's six
(:mod:`pinobs.observers.kalman_step`: 13 Python calls an update, was 29, then 2 with its plain
update in one call, :func:`~pinobs.observers.kalman_step.update_fused`; no BLAS call, so
no one-BLAS-thread limit; no cache on the sample interval), equal to the NumPy step to
rounding (3e-16 rad/s measured, tested to 1e-12).

Defaults: ``R = rate/σ²`` (so the sampled measurement variance is σ², with
σ = ``noise_std`` or 1e-6 rad), ``accel_psd`` = the robot's
model-error density when it has one, else 1e-8 rad²/s³ (as the EKF),
``q0_std`` = 0.1 rad, ``v0_std`` = 1 rad/s, the differentiator with
``highgain``'s defaults at ``diff_order`` = 4 (its lag enters ``F``; the
paper's order 2 lags 2ÿ/γ).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from pinobs.errors import GainError
from pinobs.model import Robot, lie_rk4
from pinobs.model.integrators import friction_substeps, rk4_stage_matrices
from pinobs.observers.base import (
    GateState,
    Observer,
    Vector,
    gate_threshold,
    positive,
    register,
)
from pinobs.observers.checks import model_accel_psd
from pinobs.observers.differentiators import HighGainDifferentiator
from pinobs.observers.ekf import ad_matrix, double_integrator_noise
from pinobs.observers.fused import loaded
from pinobs.observers.kalman_step import KalmanStep, fused_kernel, update_fused
from pinobs.observers.linalg import (
    cholesky_solve,
    joseph_update,
    stiff_transition_matrix,
    transition_matrix,
    warm_linear_algebra,
)

__all__ = ["IbrirKalman", "IbrirKalmanGains"]


@functools.cache
def _fused_kernel() -> Any:
    """:func:`pinobs.observers.kalman_step.fused_loops` compiled (numba, ``cache=True``; loaded
    by the constructor)."""
    warm_linear_algebra(1)  # both linalg kernels loaded
    return loaded(fused_kernel)


_DEFAULT_RATE = 1000.0  # [Hz] assumed for R when no rate is given
_FUSED_MAX_NV = 12  # as the ekf's kernels: above, NumPy (BLAS products) is faster than loops


@dataclass(frozen=True)
class IbrirKalmanGains:
    """Validated options of :class:`IbrirKalman`.

    Attributes:
        form: ``"paper"`` (no process noise) or ``"practical"``.
        output_weight: R [1/(rad²·s)], > 0.
        accel_psd: process noise density [rad²/s³] (practical form), > 0.
        q0_std: initial configuration standard deviation [rad], > 0.
        v0_std: initial velocity standard deviation [rad/s], > 0.
    """

    form: str
    output_weight: float
    accel_psd: float
    q0_std: float
    v0_std: float

    def __post_init__(self) -> None:
        if self.form not in ("paper", "practical"):
            raise GainError(f"form={self.form!r} is not accepted; use 'paper' or 'practical'")
        positive("output_weight", self.output_weight)
        positive("accel_psd", self.accel_psd)
        positive("q0_std", self.q0_std)
        positive("v0_std", self.v0_std)


class _State(NamedTuple):
    q: Vector
    v: Vector
    P: Vector  # (2nv, 2nv)
    diff: Any  # the differentiator's state (ξ̂ of Theorem 3.1), None when unused
    y_prev: Vector | None  # the sample of the previous call (None: there was none, or gated)
    gate: GateState = GateState()  # the outlier gate's bookkeeping (NIS of the last measurement)


@register
class IbrirKalman(Observer[_State]):
    """Ibrir's Theorem 3.1: a Kalman observer on the state-affine form built from the model.

    Args:
        robot: the model (``M``, ``C``, ``g`` from Pinocchio).
        form: ``"practical"`` (with process noise) or ``"paper"`` (as printed).
        output_weight: R [1/(rad²·s)]; default ``rate/σ²``.
        accel_psd: process noise density [rad²/s³] (practical form only); ``None``: the
            robot's :attr:`~pinobs.Robot.model_error_psd`, else 1e-8 (as ``ekf``).
        viscous: viscous friction ``C_f`` [N·m·s/rad], a number or one per velocity.
        q0_std: initial configuration standard deviation [rad] (``P(0)``).
        v0_std: initial velocity standard deviation [rad/s] (``P(0)``).
        diff_order: order of the differentiator giving ``ẏ``.
        diff_gamma: its bandwidth γ [1/s] (default: ``highgain``'s rule).  The
            differentiator enters the estimate only through ``velocity_source=
            "differentiator"``, ``schedule="filtered"`` or a missing sample's
            schedule: under the defaults (``"estimate"``, ``"measured"``) these two
            change nothing on a log without gaps.
        schedule: ``"measured"`` (the paper's y) or ``"filtered"`` (the differentiator's ŷ).
        velocity_source: ``"differentiator"`` (the paper's ẏ) or ``"estimate"`` (v̂);
            default: the former for ``form="paper"``, the latter otherwise.
        outlier_probability: false-alarm probability ``p`` of the outlier gate
            (module docstring); ``None`` switches the gate off.
        rate: sample rate hint [Hz].
        noise_std: position noise standard deviation [rad or m].
    """

    name = "kalman"
    uses_noise_std = True
    summary = "Ibrir's Kalman observer on the state-affine form, Thm 3.1 (model-based)"

    def __init__(
        self,
        robot: Robot,
        *,
        form: str = "practical",
        output_weight: float | None = None,
        accel_psd: float | None = None,
        viscous: float | Vector = 0.0,
        q0_std: float = 0.1,
        v0_std: float = 1.0,
        diff_order: int = 4,
        diff_gamma: float | None = None,
        schedule: str = "measured",
        velocity_source: str | None = None,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.outlier_probability, self._gate = gate_threshold(outlier_probability, robot.nv)
        sigma = self.noise_std_used
        R = output_weight
        if R is None:
            R = (self.rate or _DEFAULT_RATE) / sigma**2
        self.gains = IbrirKalmanGains(
            form=form,
            output_weight=R,
            accel_psd=model_accel_psd(robot, accel_psd),
            q0_std=q0_std,
            v0_std=v0_std,
        )
        cf = np.broadcast_to(np.asarray(viscous, dtype=float), (self.robot.nv,)).copy()
        if not np.all(np.isfinite(cf)) or np.any(cf < 0):
            raise GainError(f"viscous={viscous!r} must be finite and >= 0")
        self.viscous = cf
        self._viscous = bool(np.any(cf))  # (read every update: once here)
        self._damped = self._viscous or self.robot.has_friction  # C_f ≠ 0 somewhere
        self._vector_space = self.robot.is_vector_space
        if schedule not in ("filtered", "measured"):
            raise GainError(f"schedule={schedule!r} is not accepted; use 'filtered' or 'measured'")
        self.schedule = schedule
        if velocity_source is None:
            velocity_source = "differentiator" if form == "paper" else "estimate"
        if velocity_source not in ("differentiator", "estimate"):
            raise GainError(
                f"velocity_source={velocity_source!r} is not accepted; "
                "use 'differentiator' or 'estimate'"
            )
        self.velocity_source = velocity_source
        self._scratch_F: Vector | None = None  # F's buffer (_state_matrix)
        warm_linear_algebra(self.robot.nv)  # LAPACK and the compiled update, now
        # Φ, P⁻ and the update in one compiled call where the ekf's kernels run (small nv)
        # and Φ is the series (no friction: stiff_transition_matrix otherwise)
        n2 = 2 * self.robot.nv
        small = self.robot.nv <= _FUSED_MAX_NV and not self.robot.has_friction
        small = small and self._vector_space
        self._fused = _fused_kernel() if small else None
        self._no_noise = np.zeros((n2, n2))  # Q of the paper's form
        self.differentiator = HighGainDifferentiator(
            self.robot, order=diff_order, gamma=diff_gamma, rate=rate, noise_std=noise_std
        )
        # the whole step compiled where it applies (pinobs.observers.kalman_step): no BLAS
        self._fast = None if self._fused is None else KalmanStep.build(self, _State)
        self.uses_blas = self._fast is None
        # a plain update whole in one Python call (Observer._update_fused; kalman_step)
        self._fused_path = self._fast is not None and type(self) is IbrirKalman

    _update_fused = update_fused  # (Observer.update's first offer: kalman_step.update_fused)

    @property
    def options(self) -> dict[str, object]:
        g = self.gains
        d = self.differentiator.gains
        return {
            **super().options,
            "form": g.form,
            "output_weight": g.output_weight,
            "accel_psd": g.accel_psd if g.form == "practical" else 0.0,
            "q0_std": g.q0_std,
            "v0_std": g.v0_std,
            "diff_order": d.order,
            "diff_gamma": d.gamma,
            "outlier_probability": self.outlier_probability,
        }

    # ------------------------------------------------------- state-affine form
    def state_affine(self, y: Vector, y_dot: Vector, tau: Vector) -> tuple[Vector, Vector]:
        """``(F(y, ẏ), G(y, τ))`` of Ibrir eqs. (3)–(5), shapes (2nv, 2nv) and (2nv,).

        On Lie-group joints ``F``'s position block is ``−ad_ẏ`` (error dynamics).
        """
        r, nv = self.robot, self.robot.nv
        M = r.mass_matrix(y)
        damp, offset = self.friction_affine(y_dot)
        rhs = np.column_stack(
            [r.coriolis_matrix(y, y_dot) + np.diag(damp), tau - r.gravity(y) + offset]
        )
        sol, _ = cholesky_solve(M, rhs)  # M⁻¹ [C + C_f, τ − g (+ friction offset)]
        F = np.zeros((2 * nv, 2 * nv))
        F[:nv, :nv] = -ad_matrix(r, y_dot)
        F[:nv, nv:] = np.eye(nv)
        F[nv:, nv:] = -sol[:, :nv]  # Ibrir eq. (3)
        G = np.concatenate([np.zeros(nv), sol[:, nv]])  # Ibrir eq. (3), τ(q, u)
        return F, G

    def _state_matrix(self, y: Vector, y_dot: Vector) -> Vector:
        """``F(y, ẏ)`` of :meth:`state_affine` alone, in the filter's scratch buffer.

        ``F₂₂ = −M⁻¹(y)(C(y, ẏ) + C_f)`` by a Cholesky solve (``M`` symmetric
        positive definite); ``G`` (and so ``g(y)``) is not needed by the covariance.
        """
        r, nv = self.robot, self.robot.nv
        F = self._scratch_F
        if F is None:
            F = self._scratch_F = np.zeros((2 * nv, 2 * nv))
            F[:nv, nv:] = np.eye(nv)
        if r.has_lie_group_joints:
            np.negative(ad_matrix(r, y_dot), out=F[:nv, :nv])
        sol, _ = cholesky_solve(r.mass_matrix(y), self._damped_coriolis(y, y_dot))
        np.negative(sol, out=F[nv:, nv:])  # Ibrir eq. (3)
        return F

    def _damped_coriolis(self, y: Vector, y_dot: Vector) -> Vector:
        """``C(y, ẏ) + C_f`` (a new array), ``C_f`` of :meth:`friction_affine`."""
        cd = self.robot.coriolis_matrix(y, y_dot)
        if self._damped:
            cd.flat[:: self.robot.nv + 1] += self.friction_affine(y_dot)[0]
        return cd

    def friction_affine(self, y_dot: Vector) -> tuple[Vector, Vector]:
        """``(C_f, τ₀)`` with friction ``≈ −C_f v + τ₀`` near ``v = ẏ`` (diagonal ``C_f``).

        ``C_f`` = ``viscous`` plus the local damping ``−∂τ_f/∂v(ẏ)`` of the
        robot's own joint friction (URDF ``<dynamics>``), ``τ₀`` the rest, so
        ``F x + G`` equals the model exactly at ``v = ẏ``.
        """
        if not self.robot.has_friction:
            return self.viscous, np.zeros(self.robot.nv)
        d = -self.robot.friction_derivative(y_dot)
        return self.viscous + d, self.robot.friction_torque(y_dot) + d * y_dot

    def vector_field(
        self, q_hat: Vector, v_hat: Vector, y: Vector, y_dot: Vector, tau: Vector, P: Vector
    ) -> tuple[Vector, Vector]:
        """Theorem 3.1's ``x̂̇ = F x̂ + P Cᵀ R (y − C x̂) + G`` as ``(q̂̇ body velocity, v̂̇)``."""
        nv = self.robot.nv
        F, G = self.state_affine(y, y_dot, tau)
        corr = P[:, :nv] @ (self.gains.output_weight * self.robot.difference(q_hat, y))
        return v_hat + corr[:nv], F[nv:, nv:] @ v_hat + G[nv:] + corr[nv:]

    # ------------------------------------------------------------- the filter
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        nv = self.robot.nv
        std = np.concatenate([np.full(nv, self.gains.q0_std), np.full(nv, self.gains.v0_std)])
        uses_diff = self.velocity_source == "differentiator" or self.schedule == "filtered"
        diff = self.differentiator.initial_state(q0, v0) if uses_diff else None
        return _State(q0.copy(), v0.copy(), np.diag(std**2), diff, None)

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        """Prediction over ``dt`` [s] (scheduled on ``q_meas``), then the gated Kalman correction
        (:meth:`general_step`; compiled where :class:`~pinobs.observers.kalman_step.KalmanStep`
        applies)."""
        if self._fast is not None:
            return self._fast.step(self, state, dt, q_meas, tau)
        return self.general_step(state, dt, q_meas, tau)

    def general_step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        """:meth:`step` in NumPy (and the general compiled covariance step on small robots).

        ``NIS = eᵀ S⁻¹ e`` with ``S = P⁻_qq + 1/(R h)`` comes free from the update
        (``S⁻¹ e = (e − K_q e) R h``, as in :meth:`ExtendedKalmanFilter.correct`).  A
        measurement the gate rejects (:func:`pinobs.observers.base.outlier_gate`) is used
        nowhere: the step is redone as if there were no sample (the schedule ``y(t)`` and
        the differentiator had read it too), and the estimate is that prediction.
        """
        q, v, mid, d1 = self._predict(state, dt, q_meas, tau)
        if q_meas is None:
            P = self._covariance(self._state_matrix(*mid), dt, state.P)
            P = 0.5 * (P + P.T)  # (joseph_update symmetrises)
            return _State(q, v, P, d1, None, state.gate.predicted())
        r, nv = self.robot, self.robot.nv
        e = q_meas - q if self._vector_space else r.difference(q, q_meas)
        meas_var = 1.0 / (self.gains.output_weight * dt)
        nis = math.nan
        dx: Vector = np.empty(2 * nv)
        P = np.empty_like(state.P)
        if self._fused is not None:  # the general path below in one compiled call
            M, CD = r.mass_matrix(mid[0]), self._damped_coriolis(*mid)
            q3, q2, q1 = self._noise_terms(dt)
            nis = self._fused(M, CD, float(dt), state.P, q3, q2, q1, e, meas_var, dx, P)
        if math.isnan(nis):  # (or not positive definite in the kernel: the general path copes)
            P_pred = self._covariance(self._state_matrix(*mid), dt, state.P)
            dx, P = joseph_update(P_pred, e, meas_var)
            nis = float(e.dot(e - dx[:nv])) / meas_var
        dq = dx[:nv]
        gate = state.gate.measured(nis, self._gate, nv)
        if gate.gated:
            return self.step(state, dt, None, tau)._replace(gate=gate)
        q = q + dq if self._vector_space else r.integrate(q, dq)
        return _State(q, v + dx[nv:], P, d1, q_meas.copy(), gate)

    def _noise_terms(self, dt: float) -> tuple[float, float, float]:
        """``Q_d``'s blocks over ``dt`` [s]: ``Q_d = [[q3 I, q2 I], [q2 I, q1 I]]`` (:meth:`_noise`)."""
        g = self.gains
        psd = g.accel_psd if g.form == "practical" else 0.0
        return psd * (dt**3 / 3), psd * (dt**2 / 2), psd * dt

    def _noise(self, dt: float) -> Vector:
        """``Q_d`` over ``dt`` [s]: white acceleration (practical form) or none (the paper's)."""
        g = self.gains
        if g.form == "practical":
            return double_integrator_noise(self.robot.nv, dt, g.accel_psd)
        return self._no_noise

    def _covariance(self, F: Vector, dt: float, P: Vector) -> Vector:
        """``P⁻ = Φ P Φᵀ + Q_d``, ``Φ = exp(F dt)`` (module docstring), symmetric to rounding only."""
        if self.robot.has_friction:  # stiff near v = 0: scaling and squaring
            Phi = stiff_transition_matrix(F, dt)
        else:
            Phi = transition_matrix(F, dt)
        P_new = Phi.dot(P).dot(Phi.T)
        P_new += self._noise(dt)
        return P_new

    def _predict(
        self, state: _State, dt: float, q_meas: Vector | None, tau: Vector
    ) -> tuple[Vector, Vector, tuple[Vector, Vector], Any]:
        """``(q̂⁻, v̂⁻, (y, ẏ), ξ̂)`` over ``dt`` [s] with ``tau`` held, ``y(t)`` ending on
        ``q_meas`` (module docstring); ``(y, ẏ)`` at the interval's midpoint, where the
        covariance takes ``F``."""
        r, nv = self.robot, self.robot.nv
        d0 = state.diff
        d1 = None if d0 is None else self.differentiator.step(d0, dt, q_meas, tau)  # ξ̂
        vector_space = self._vector_space  # ⊕ is +, ⊖ is −: NumPy, not a Pinocchio call
        y0, dy = self._schedule(state, d0, d1, q_meas, dt)
        yd0 = yd1 = state.v
        if d0 is not None and d1 is not None:
            yd0, yd1 = d0.X[0], d1.X[0]
        use_estimate = self.velocity_source == "estimate"
        # y at the RK4 stages: s = 0, ½, ½, 1 (the stage times, exact in binary)
        if vector_space:
            y_at = {0.0: y0, 0.5: y0 + 0.5 * dy, 1.0: y0 + dy}
        else:
            y_at = {0.0: y0, 0.5: r.integrate(y0, 0.5 * dy), 1.0: r.integrate(y0, dy)}

        def rhs(q: Vector, x: Vector) -> tuple[Vector, Vector]:
            v, s = x[:nv], x[nv] / dt
            y = y_at[s] if s in y_at else r.integrate(y0, s * dy)
            if use_estimate:  # ẏ = v̂: C(y, v̂) v̂ = c(y, v̂), one ABA call
                a = r.forward_dynamics(y, v, tau - self.viscous * v)
            else:  # Ibrir eq. (3) with ẏ = ξ̂₂
                y_dot = yd0 + s * (yd1 - yd0)
                damp, offset = self.friction_affine(y_dot)
                rhs_ = tau - r.gravity(y) + offset - r.coriolis_matrix(y, y_dot) @ v - damp * v
                a = np.linalg.solve(r.mass_matrix(y), rhs_)
            return v, np.concatenate([a, [1.0]])

        q: Vector
        v: Vector
        n = 1
        if r.has_friction:  # stiff near v = 0 (smoothed Coulomb): substeps, as the EKF
            a0 = r.forward_dynamics(y0, state.v, tau - self.viscous * state.v)
            minv_diag = np.diag(np.linalg.inv(r.mass_matrix(y0)))
            n = friction_substeps(r, state.v, a0, minv_diag, dt)
        if n == 1 and use_estimate and vector_space:  # RK4 without lie_rk4's bookkeeping
            q, v = self._rk4(state, y_at, tau, dt)
        else:
            q, x = state.q, np.concatenate([state.v, [0.0]])
            for _ in range(n):  # x[nv] carries the time since the interval's start
                q, x = lie_rk4(r, q, x, dt / n, rhs)
            v = x[:nv]
        y_dot_mid = 0.5 * (state.v + v) if use_estimate else 0.5 * (yd0 + yd1)
        return q, v, (y_at[0.5], y_dot_mid), d1

    def _schedule(
        self, state: _State, d0: Any, d1: Any, q_meas: Vector | None, dt: float
    ) -> tuple[Vector, Vector]:
        """``(y0, dy)`` of the scheduling output on the interval, ``y(s) = y0 ⊕ (s/dt) dy``
        for ``s ∈ [0, dt]`` (module docstring; ``d0``, ``d1`` the differentiator's states at
        its ends, ``None`` without one)."""
        r = self.robot
        if self.schedule == "filtered" and d0 is not None and d1 is not None:
            return d0.q, r.difference(d0.q, d1.q)
        if q_meas is not None:  # the paper's y; from q̂ when no sample opened the interval
            y0 = state.q if state.y_prev is None else state.y_prev
            return y0, q_meas - y0 if self._vector_space else r.difference(y0, q_meas)
        return state.q, dt * state.v  # no sample at either end: the prediction's own path

    def _rk4(
        self, state: _State, y_at: dict[float, Vector], tau: Vector, dt: float
    ) -> tuple[Vector, Vector]:
        """One classical RK4 step of ``(q, v)`` on a vector space with ``ẏ = v̂`` (``y_at``:
        ``y`` at the stages' ``s = 0, ½, 1``), stacked as in ``dynamics_rk4``: rows ``(q, v,
        a₁, a₂, a₃, a₄)``, without :func:`lie_rk4`'s bookkeeping."""
        r, nv = self.robot, self.robot.nv
        c2, c3, c4, c_out = rk4_stage_matrices(float(dt))
        fd, b = r.forward_dynamics, np.empty((6, nv))
        b[0], b[1] = state.q, state.v
        y0, y_half = y_at[0.0], y_at[0.5]
        if not self._viscous:  # C_f v = 0: τ as it is (the same numbers)
            b[2] = fd(y0, b[1], tau)
            b[3] = fd(y_half, c2[1].dot(b[:3]), tau)
            b[4] = fd(y_half, c3[1].dot(b[:4]), tau)
            b[5] = fd(y_at[1.0], c4[1].dot(b[:5]), tau)
        else:
            visc = self.viscous
            for i, (y, c) in enumerate(((y0, None), (y_half, c2), (y_half, c3), (y_at[1.0], c4))):
                v_i = b[1] if c is None else c[1].dot(b[: i + 2])
                b[i + 2] = fd(y, v_i, tau - visc * v_i)
        q, v = c_out.dot(b)
        return q, v

    def output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q, state.v

    def covariance(self) -> Vector:
        """The current ``P`` of ``(δq, δv)``, shape ``(2nv, 2nv)`` (a copy)."""
        if self._state is None:
            return np.full((2 * self.robot.nv, 2 * self.robot.nv), np.nan)
        return np.array(self._state.P)
