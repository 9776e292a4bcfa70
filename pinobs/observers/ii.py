"""Immersion & Invariance reduced-order momentum observer (Sarras, Venkatraman, Ortega, van der Schaft).

Revolute, prismatic and continuous joints: I&I lives in coordinates.  A
continuous joint (``q = (cos θ, sin θ)``) is run in its angle chart
(:class:`pinobs.model.chart.AngleChart`: the same robot with a revolute joint,
identical ``M``, ``c``, ``g`` at ``θ``), ``θ`` unwrapped along the measured
path: each measurement's ``atan2(sin, cos)`` is taken on the ``2π``-branch
nearest the step's prediction, so the chart never jumps while the joint
turns less than ``π`` per sample.  Lie-group joints belong to the
``liegroup`` / ``riemannian`` observers.  (MATH §5)

Coordinates.  ``M⁻¹(q) = T(q) T(q)ᵀ`` (Sarras et al. eq. 16) with ``T`` a
Cholesky factor taken in a joint ordering ``p``: ``L`` is the lower Cholesky
factor of ``M⁻¹`` with rows and columns permuted by ``p``, and
``T[p_i, p_j] = L[i, j]``.  The momenta ``P = Tᵀ p = T⁻¹ v`` satisfy
``|P|² = 2 × kinetic energy`` and (eq. 9, with an input torque)::

    q̇ = T P,    Ṗ = Tᵀ(τ − ∂V/∂q) + D_T(q, P),
    D_T(q, P) = {P, P}_J P,   {P_i, P_j} = −pᵀ [T_i, T_j]          (eqs. 18-19)

with ``[T_i, T_j] = (∂T_j/∂q) T_i − (∂T_i/∂q) T_j`` the Lie bracket of the
columns of ``T``.  Writing ``[T_i, T_j] = Σ_l c_ij^l T_l`` gives
``D_T,i = −Σ_{j,l} c_ij^l P_j P_l``: Assumption 1 (``D_T ≡ 0``) holds iff the
symmetric part of every ``(c_ij^l)_{j,l}`` vanishes, which
:func:`check_assumption1` measures over sampled configurations and orderings.

Observer (Proposition 5 with an input torque; the paper's eq. 30 is the case
``τ = 0``, ``M̄ = I``)::

    η̇ = 𝒫(q) T(q) (β(q) − η) − T(q)ᵀ(τ − ∂V/∂q),    P̂ = β(q) − η,    v̂ = T(q) P̂,
    𝒫 = ∂β/∂q                                                        (eq. 31)

so ``z = P̂ − P`` obeys ``ż = −𝒫 T z − D_T`` (proof of Prop. 5, eq. 33) and,
under Assumption 2 (``𝒫T + (𝒫T)ᵀ ≥ εI``, eq. 27),
``|P̂(t) − P(t)|² ≤ e^{−εt} |P̂(0) − P(0)|²``.

Constructive β (two cases, chosen automatically):

* ``"potential"`` — the columns of T commute (always the case when ``n ≤ 2``
  and Assumption 1 holds).  Then ``T⁻¹`` is a Jacobian (Fact 1, eq. 20):
  ``∂Q/∂q = T⁻¹``, and ``β = k Q`` gives ``𝒫T = kI``, ``ε = 2k``: the error
  ``|z|`` decays at exactly the rate ``k``.  ``Q`` is the path integral of
  ``T⁻¹ dq``, computed by Gauss-Legendre quadrature along straight segments
  (path independence is what Fact 1 guarantees and what the tests check).
  The observer carries ``β`` along the measured path, one short segment per
  sample, so the quadrature never spans a long excursion.
* ``"homotopy"`` — otherwise (the columns do not commute, or Assumption 1
  fails and the caller opted in with ``unguaranteed=True``).  β is the
  Poincaré homotopy of the rows of ``T⁻¹`` from a reference ``q_r`` (the
  configuration at reset), discretised by an N-point Gauss-Legendre rule::

      β(q) = k Σ_m w_m T⁻¹(q_r + s_m Δ) Δ,    Δ = q − q_r,
      𝒫(q) = k Σ_m w_m [T⁻¹(γ_m) + s_m Σ_j (∂_j T⁻¹)(γ_m) Δ e_jᵀ]

  ``𝒫`` is the exact Jacobian of this β (the rule is differentiated, not the
  integral), so the manifold ``η = β − P`` stays invariant exactly; ``𝒫T``
  equals ``kI`` when the columns commute and differs from it by
  ``O(k |Δ| |[T_i, T_j]|)`` otherwise, so Assumption 2 holds near ``q_r``
  only.  ε is checked on sampled configurations in ``q_r + [−region, region]ⁿ``
  at every reset and reported in :attr:`IIObserver.options`.

Sampled data (MATH §7).  η's ODE needs ``q(t)`` between samples, which is not
measured.  Each step (1) predicts the plant over the interval with the model
from the current estimate ``(q_k, v̂_k)`` and the held torque (RK4, ``substeps``
steps), (2) builds the path ``q̃(s) = H(s) + (s/h)(q_{k+1} − H(h))`` where ``H``
is the cubic Hermite interpolant of the prediction, so the path starts and ends
on the measurements, and (3) integrates η along it with RK4.  Started on the
truth, the prediction *is* the truth (up to RK4 error) and the correction
vanishes: the estimate stays on the truth.  From an error ``z``, the path
differs from the true one by ``O(h² k |T z|)`` inside the interval, a
perturbation of the decay rate of relative order ``(kh)²`` at most.  Without a
sample, the predicted path is used and ``q̂`` is the prediction.  Measured on
the cart-pole and two variants (PD tracking, 1 kHz, k = 10 /s, kh = 0.01):
started on the truth, ``|v̂ − v| ≤ 1.0e-10`` rad/s over 1 s; from a perturbed
velocity, the fitted decay rate of ``|z|`` is k to within 7e-8 relative and
``|z_k|`` exceeds the bound ``e^{−kt}|z₀|`` by at most 5e-10 (the invariance
floor).  ``tests/observers/test_ii.py``, ``examples/ii_cartpole.py``.

Consistency and outliers.  The observer has no covariance; the innovation
``e = q_meas − q̂⁻`` (the sample against the step's prediction ``q̂⁻``, which
starts from the previous sample) gets a variance from the observer's own
error dynamics.  Per joint, flat case, white noise ``n`` of variance σ²
(σ = ``noise_std``, 1e-6 if not given): ``e = n_{k+1} − n_k − h(v̂ − v) + O(h²)``,
and ``P̂ = β(q_meas) − η`` carries the noise into the velocity as
``v̂ − v ≈ k(n_k − n̄_k) + T z`` (``n̄`` the noise low-passed at ``k``, ``z`` the
momentum error of eq. 33), so to first order in ``kh``::

    S = σ² (2 + 2kh) + h² v0_std² e^{−ε t}

the last term the start-up error, ``|v̂(0) − v(0)|`` of standard deviation
``v0_std`` per joint decaying as the I&I bound guarantees (``ε`` of
Assumption 2, ``2k`` for the potential construction; ``2k`` assumed where
nothing is guaranteed).  ``NIS = |e|²/S`` is then χ²(nv) to that order, with
an exact model (a model error adds ``h Δa/k`` to ``e``: the velocity bias it
causes).  Successive innovations share ``n_k`` (correlation ≈ −½), which
does not change the mean NIS but widens its spread over a window by about
√1.5.  A sample the gate rejects (:func:`pinobs.observers.base.outlier_gate`)
is not used: the path and ``q̂`` are the prediction, as without a sample.

Unguaranteed mode (``unguaranteed=True``, Assumption 1 fails).  The observer
then adds the certainty-equivalent term ``−D_T(q, P̂)`` to η̇, so that
``ż = −𝒫Tz − (D_T(q, P) − D_T(q, P̂))``: the manifold stays invariant (started
on the truth it stays there) and the error contracts locally when ``k``
dominates ``|c| |P|``, but no global bound holds.  Where Assumption 1 holds
the term is identically zero and is not computed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pinobs.errors import GainError, UnsupportedRobotError
from pinobs.model import Robot, dynamics_rk4
from pinobs.model.chart import AngleChart
from pinobs.observers.base import (
    GateState,
    Observer,
    Vector,
    gate_threshold,
    positive,
    register,
)

# the factor, β and the assumptions' checks live in their own modules; their public names
# are this module's too (pinobs.observers.ii is where users and the docs find them)
from pinobs.observers.ii_assumptions import (
    Assumption1Report,
    Assumption2Report,
    OrderingResult,
    check_assumption1,
    check_assumption2,
)
from pinobs.observers.ii_assumptions import require_vector_joints as _require_vector_joints
from pinobs.observers.ii_factor import (
    CholeskyFactor,
    CustomFactor,
    Factor,
    momentum_residual,
    structure_functions,
)
from pinobs.observers.ii_potential import Homotopy as _Homotopy
from pinobs.observers.ii_potential import potential
from pinobs.observers.ii_potential import segment_integral as _segment_integral

__all__ = [
    "Assumption1Report",
    "Assumption2Report",
    "CholeskyFactor",
    "CustomFactor",
    "Factor",
    "IIGains",
    "IIObserver",
    "OrderingResult",
    "check_assumption1",
    "check_assumption2",
    "momentum_residual",
    "potential",
    "structure_functions",
]

_STEP_KH = 0.25  # sub-steps so that k·h_sub <= 0.25 (RK4 factor within (kh)⁵/120 = 8e-6 of e^{−kh})


# ================================================================ observer
@dataclass(frozen=True)
class IIGains:
    """Validated options of :class:`IIObserver`.

    Attributes:
        gain: ``k`` in ``β = k Q`` [1/s], > 0: the error decays as ``e^{−kt}``
            (potential construction).
        nodes: Gauss-Legendre nodes of the homotopy β, >= 1.
        region: half-width of the box where Assumption 2 is checked [rad or m], > 0.
    """

    gain: float
    nodes: int
    region: float

    def __post_init__(self) -> None:
        positive("gain", self.gain)
        positive("nodes", self.nodes)
        positive("region", self.region)
        if int(self.nodes) != self.nodes:
            raise GainError(f"nodes={self.nodes!r} must be a positive integer")


class _Stage(NamedTuple):
    t: Vector  # T(q)
    beta: Vector  # β(q)
    pt: Vector  # 𝒫(q) T(q)
    g: Vector  # ∂V/∂q
    c: Vector | None  # structure functions (D_T compensation), or None


class _State(NamedTuple):
    q: Vector  # last measured (or predicted) configuration
    eta: Vector  # η
    beta: Vector  # β(q)
    q_ref: Vector  # homotopy reference (the configuration at reset)
    age: float = 0.0  # [s] since the reset (the prior's decay in the NIS)
    gate: GateState = GateState()  # the outlier gate's bookkeeping (NIS of the last sample)


@register
class IIObserver(Observer[_State]):
    """I&I reduced-order observer of Sarras et al. (Proposition 5), with input torques.

    Args:
        robot: a robot with vector joints only (revolute, prismatic), or an
            :class:`~pinobs.model.AnalyticMetric`.
        gain: ``k`` [1/s]; the momentum error decays as ``e^{−kt}`` when the
            columns of ``T`` commute.
        ordering: Cholesky ordering (joint indices or names); ``None``
            searches the orderings with :func:`check_assumption1`.
        factor: a :class:`Factor` to use instead of a Cholesky factor (must
            satisfy ``T Tᵀ = M⁻¹``; checked).
        unguaranteed: run even when Assumption 1 fails (no convergence
            guarantee; labelled in :attr:`options`).
        check_samples: configurations sampled by the Assumption 1 check.
        seed: seed of the checks' samplers.
        nodes: Gauss-Legendre nodes of the homotopy β.
        region: half-width of the box around the reset configuration where
            Assumption 2 is checked [rad or m] (homotopy β only).
        substeps: RK4 steps per sample interval; ``None``: enough that
            ``k·h ≤ 0.25`` per step.
        v0_std: standard deviation of the initial velocity error [rad/s or m/s],
            for the NIS only (module docstring).
        outlier_probability: false-alarm probability ``p`` of the outlier gate
            (module docstring); ``None`` switches the gate off.
        rate: sample rate hint [Hz] (unused: the observer uses the actual intervals).
        noise_std: position noise standard deviation [rad or m]: the observer ignores
            it, the NIS divides by it (1e-6 if not given, as the filters').

    Raises:
        UnsupportedRobotError: Lie-group joints, or Assumption 1 fails and
            ``unguaranteed`` is false (the message gives the residual).
    """

    name = "ii"
    uses_noise_std = True
    noise_in_gains = False  # σ only in the NIS (_sigma2)
    summary = (
        "Immersion & Invariance reduced-order observer, Cholesky factor of M⁻¹ (Sarras et al.)"
    )

    def __init__(
        self,
        robot: Robot,
        *,
        gain: float = 20.0,
        ordering: Sequence[int | str] | None = None,
        factor: Factor | None = None,
        unguaranteed: bool = False,
        check_samples: int = 6,
        seed: int = 0,
        nodes: int = 6,
        region: float = 0.5,
        substeps: int | None = None,
        v0_std: float = 1.0,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        _require_vector_joints(robot)
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.outlier_probability, self._gate = gate_threshold(outlier_probability, robot.nv)
        self.v0_std = float(positive("v0_std", v0_std) or 0.0)
        # continuous joints: the observer runs in the angle chart, unwrapped along the path
        self.chart: AngleChart | None = None
        self.plant = self.robot
        if isinstance(self.robot, Robot) and any(b.kind == "circle" for b in self.robot.joints):
            self.chart = AngleChart(self.robot)
            self.plant = self.chart.chart
        self.gains = IIGains(gain=gain, nodes=nodes, region=region)
        self.substeps = None if substeps is None else int(positive("substeps", substeps) or 1)
        self.seed = int(seed)
        n = self.robot.nv
        if factor is not None and ordering is not None:
            raise GainError("give either ordering= or factor=, not both")
        if factor is not None:
            if factor.n != n:
                raise GainError(f"factor has dimension {factor.n}, the robot {n}")
            self._check_custom_factor(factor)
            report = check_assumption1(self.plant, samples=check_samples, seed=seed, factor=factor)
        else:
            orderings = None if ordering is None else [self._resolve_ordering(ordering)]
            report = check_assumption1(
                self.plant, samples=check_samples, seed=seed, orderings=orderings
            )
            factor = CholeskyFactor(self.plant, report.best.ordering or tuple(range(n)))
        self.report = report
        best = report.best
        if not best.holds and not unguaranteed:
            raise UnsupportedRobotError(
                f"Assumption 1 of Sarras et al. (D_T = {{P, P}}_J P ≡ 0) fails on {self.robot.name!r}: "
                f"best factor ({best.label}) has relative residual {best.residual:.3g} "
                f"(tolerance {report.tol:.1e}; max |D_T| = {best.abs_residual:.3g} for |P|² = 1 J, "
                f"at q = [{', '.join(f'{x:.3g}' for x in best.worst_q)}]; {report.search}). "
                "Pass unguaranteed=True to run it anyway without a convergence guarantee, "
                "or use the 'liegroup' or 'riemannian' observer."
            )
        self.guaranteed = best.holds
        self.compensate = not best.holds
        self.factor = factor
        self.construction = (
            "potential" if best.holds and best.commutator <= report.tol else "homotopy"
        )
        self._homotopy = _Homotopy(factor, self.gains.gain, self.gains.nodes)
        self.assumption2: Assumption2Report | None = None
        if self.construction == "potential":
            self.assumption2 = Assumption2Report(2.0 * self.gains.gain, True, math.inf, 0, ())

    def __repr__(self) -> str:
        tag = "" if self.guaranteed else ", unguaranteed"
        return f"{type(self).__name__}({self.robot.name!r}{tag})"

    @property
    def label(self) -> str:
        """What is guaranteed: ``"guaranteed ..."`` or ``"UNGUARANTEED (...)"``, with the numbers."""
        a2 = self.assumption2
        if not self.guaranteed:
            return (
                f"UNGUARANTEED (Assumption 1 fails: relative residual "
                f"{self.report.best.residual:.3g})"
            )
        if a2 is None:
            return "Assumption 1 holds; Assumption 2 is checked at reset"
        if a2.epsilon <= 0.0:
            return (
                f"UNGUARANTEED (Assumption 2 fails within ±{a2.region:g} of the reset "
                f"configuration: ε = {a2.epsilon:.3g} /s)"
            )
        how = (
            "exact, everywhere"
            if a2.exact
            else f"sampled; holds while q stays within ±{a2.region:g} of the reset configuration"
        )
        return f"guaranteed: |P̂ − P|² ≤ e^(−εt)|P̂(0) − P(0)|², ε = {a2.epsilon:.4g} /s ({how})"

    @property
    def options(self) -> dict[str, object]:
        a2 = self.assumption2
        return {
            **super().options,
            "gain": self.gains.gain,
            "factor": self.factor.label,
            "construction": self.construction,
            "assumption1_residual": self.report.best.residual,
            "guaranteed": self.guaranteed,
            "label": self.label,
            "assumption2_epsilon": None if a2 is None else a2.epsilon,
            "nodes": self.gains.nodes,
            "region": self.gains.region,
            "substeps": self.substeps,
            "v0_std": self.v0_std,
            "outlier_probability": self.outlier_probability,
        }

    # ------------------------------------------------------------- helpers
    def _resolve_ordering(self, ordering: Sequence[int | str]) -> tuple[int, ...]:
        names = self.robot.joint_names
        out = []
        for o in ordering:
            if isinstance(o, str):
                if o not in names:
                    raise GainError(f"ordering names unknown joint {o!r}; joints: {list(names)}")
                out.append(names.index(o))
            else:
                out.append(int(o))
        if sorted(out) != list(range(self.robot.nv)):
            raise GainError(
                f"ordering={list(ordering)!r} is not a permutation of the joints {list(names)}"
            )
        return tuple(out)

    def _check_custom_factor(self, factor: Factor) -> None:
        rng = np.random.default_rng(self.seed)
        for _ in range(3):
            q = self.plant.random_configuration(rng)
            t = factor.frame(q)
            minv = np.linalg.inv(self.plant.mass_matrix(q))
            err = float(np.abs(t @ t.T - minv).max() / np.abs(minv).max())
            if not err < 1e-8:
                raise GainError(
                    f"factor {factor.label!r} does not satisfy T Tᵀ = M⁻¹ (relative error {err:.3g})"
                )

    def beta_and_jacobian(self, q: Vector, state: _State) -> tuple[Vector, Vector]:
        """``(β(q), 𝒫(q) T(q))`` for the current construction; β relative to ``state``.

        ``potential``: ``β(q) = β(q_k) + k ∫_{q_k}^{q} T⁻¹ dq`` (one straight
        segment, exact by path independence) and ``𝒫T = kI``.
        """
        k = self.gains.gain
        if self.construction == "potential":
            return state.beta + k * _segment_integral(self.factor, state.q, q), k * np.eye(
                q.shape[0]
            )
        beta, jac = self._homotopy.beta_and_jacobian(q, state.q_ref)
        return beta, jac @ self.factor.frame(q)

    def vector_field(
        self, q: Vector, eta: Vector, tau: Vector, *, beta: Vector, pt: Vector
    ) -> Vector:
        """``η̇ = 𝒫T (β − η) − Tᵀ(τ − ∂V/∂q) [− D_T(q, P̂)]`` at measured ``q``.

        Sarras et al. eq. (30) with an input torque.  The bracketed
        certainty-equivalent term is added only when Assumption 1 fails
        (``unguaranteed``); where it holds ``D_T ≡ 0`` and the term vanishes.

        Args:
            q: configuration [rad or m].
            eta: observer state η.
            tau: torque [N·m or N].
            beta: ``β(q)`` (see :meth:`beta_and_jacobian`).
            pt: ``𝒫(q) T(q)`` [1/s].
        """
        return self._eta_dot(self._stage(q, beta, pt), eta, tau)

    def _stage(self, q: Vector, beta: Vector, pt: Vector) -> _Stage:
        if self.compensate:
            t, dts = self.factor.columns_jet(q)
            c: Vector | None = structure_functions(t, dts)[0]
        else:
            t, c = self.factor.frame(q), None
        return _Stage(t, beta, pt, self.plant.gravity(q), c)

    def _eta_dot(self, st: _Stage, eta: Vector, tau: Vector) -> Vector:
        p_hat = st.beta - eta
        if self.plant.has_friction:  # the model's joint friction, a known torque at v̂ = T P̂
            tau = tau + self.plant.friction_torque(st.t @ p_hat)
        out = st.pt @ p_hat - st.t.T @ (tau - st.g)  # Sarras et al. eq. (30), input τ added
        if st.c is not None:
            out -= momentum_residual(
                st.c, p_hat
            )  # certainty equivalence: ż = −𝒫Tz − (D_T(P) − D_T(P̂))
        return out

    def momentum(self, q: Vector, v: Vector) -> Vector:
        """``P = T(q)⁻¹ v`` (``|P|² = 2 × kinetic energy`` [J]); ``q`` the robot's (``nq``)."""
        x = q if self.chart is None else self.chart.to_chart(q)
        return self._momentum(x, v)

    def _momentum(self, x: Vector, v: Vector) -> Vector:
        """``P = T(x)⁻¹ v`` at chart coordinates ``x``."""
        return np.asarray(np.linalg.solve(self.factor.frame(x), v))

    # ------------------------------------------------------ family interface
    # The state lives in the chart (θ unwrapped for continuous joints); q in and out is the robot's.
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        if self.chart is not None:
            q0 = self.chart.to_chart(q0)
        q_ref = q0.copy()
        if self.construction == "potential":
            beta = np.zeros_like(q0)
        else:
            beta, _ = self._homotopy.beta_and_jacobian(q0, q_ref)
            self.assumption2 = check_assumption2(
                self.factor,
                self.gains.gain,
                q_ref,
                region=self.gains.region,
                seed=self.seed,
                nodes=self.gains.nodes,
            )
        eta = beta - self._momentum(q0, v0)  # P̂(0) = β − η = T⁻¹ v0
        return _State(q0.copy(), eta, beta, q_ref)

    def output(self, state: _State) -> tuple[Vector, Vector]:
        v_hat = self.factor.frame(state.q) @ (state.beta - state.eta)
        if self.chart is not None:
            return self.chart.from_chart(state.q), v_hat
        return state.q, v_hat

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        robot = self.plant
        n_sub = self.substeps or max(1, math.ceil(self.gains.gain * dt / _STEP_KH))
        h = dt / n_sub

        # (1) predict the plant from the estimate, torque held (MATH §7)
        v_hat = self.factor.frame(state.q) @ (state.beta - state.eta)
        nodes_q: list[Vector] = [state.q]
        nodes_v: list[Vector] = [v_hat]
        for _ in range(n_sub):
            qn, vn = dynamics_rk4(robot, nodes_q[-1], nodes_v[-1], tau, h)
            nodes_q.append(qn)
            nodes_v.append(vn)
        gate = state.gate.predicted()
        if q_meas is None:
            q_end = nodes_q[-1]
        elif self.chart is not None:  # θ unwrapped: the 2π-branch nearest the prediction
            q_end = self.chart.to_chart(q_meas, near=nodes_q[-1])
        else:
            q_end = q_meas
        if q_meas is not None:  # the innovation, its NIS and the filters' outlier gate
            e = q_end - nodes_q[-1]
            nis = float(e.dot(e)) / self.innovation_variance(state.age, dt)
            gate = state.gate.measured(nis, self._gate, e.size)
            if gate.gated:  # not used: the path and q̂ are the prediction's
                q_end = nodes_q[-1]
        shift = q_end - nodes_q[-1]

        # (2) the path: Hermite interpolant of the prediction, corrected to end on q_meas
        def path(j: int, frac: float) -> Vector:
            q0, q1, v0, v1 = nodes_q[j], nodes_q[j + 1], nodes_v[j], nodes_v[j + 1]
            s = frac
            h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
            h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
            herm = h00 * q0 + h10 * h * v0 + h01 * q1 + h11 * h * v1
            return herm + ((j + frac) / n_sub) * shift

        # (3) RK4 on η along the path; β carried along it (potential) or evaluated (homotopy)
        eta = state.eta
        cur = state
        sa = self._stage(state.q, *self.beta_and_jacobian(state.q, state))
        for j in range(n_sub):
            qm, qb = path(j, 0.5), path(j, 1.0)
            sm = self._stage(qm, *self.beta_and_jacobian(qm, cur))
            sb = self._stage(qb, *self.beta_and_jacobian(qb, cur))
            k1 = self._eta_dot(sa, eta, tau)
            k2 = self._eta_dot(sm, eta + 0.5 * h * k1, tau)
            k3 = self._eta_dot(sm, eta + 0.5 * h * k2, tau)
            k4 = self._eta_dot(sb, eta + h * k3, tau)
            eta = eta + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            cur = _State(qb, eta, sb.beta, state.q_ref)
            sa = sb
        return _State(q_end.copy(), eta, cur.beta, state.q_ref, state.age + dt, gate)

    def innovation_variance(self, age: float, h: float) -> float:
        """``S`` [rad² or m²] per joint of the innovation ``q_meas − q̂⁻`` after ``age`` [s]
        since the reset, over an interval ``h`` [s] (module docstring, "Consistency")::

            S = σ² (2 + 2kh) + h² v0_std² e^{−ε age}
        """
        a2 = self.assumption2
        eps = a2.epsilon if a2 is not None and a2.epsilon > 0.0 else 2.0 * self.gains.gain
        k = self.gains.gain
        return self._sigma2 * (2.0 + 2.0 * k * h) + (h * self.v0_std) ** 2 * math.exp(-eps * age)
