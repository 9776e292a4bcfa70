"""Intrinsic Riemannian observer (Aghannan–Rouchon; Maithripala et al.; Anisi–Hamberg) on any robot.

Continuous time, in Pinocchio's tangent frame (MATH §2–4; Maithripala et al.
eqs. (17)–(18); Anisi–Hamberg eq. (6) with ``A = 2α``, ``B = β``)::

    q̂̇ = v̂ − 2α ζ
    v̂̇ = −ω(q̂̇, v̂) + S∥ − β ζ + C · R(v̂, ζ) v̂

* ``ζ = −log_q̂(q)`` is the gradient at ``q̂`` of ``½ dist(q̂, q)²``: the
  geodesic error, pointing from the measured ``q`` to ``q̂``.  Second order:
  ``ζ = −(δ + ½ Γs(q̂)(δ, δ))``, ``δ = difference(q̂, q)`` (exact for a
  bi-invariant metric, where ``Γs ≡ 0``).
* ``ω(x, y) = Γs(x, y) + ½[x, y]`` is the Levi-Civita connection in the frame
  (MATH §2), so ``v̂̇ + ω(q̂̇, v̂)`` is the covariant derivative of ``v̂``.
* ``S = M(q)⁻¹(τ − g(q))`` [rad/s²] is the force per unit metric at the
  measured ``q`` and ``S∥ = S − ω(ζ, S)`` its parallel transport to ``q̂``
  along the error geodesic, to first order (Maithripala et al. eq. (19), with
  the arguments of ω in the order of eq. (1): the direction of motion first;
  the printed ``ω(S, ζ)`` differs by ``[ζ, S]`` and is only zeroth-order
  accurate on Lie-group joints).  Derivation: along the geodesic from ``q`` to
  ``q̂``, of initial velocity ``≈ ζ``, a parallel field obeys
  ``ẏ = −ω(γ̇, y)``.  ``tests/observers/test_riemannian.py`` checks the
  error against a numerically integrated transport: O(|ζ|²).
* ``R(X, Y) = ∇_X∇_Y − ∇_Y∇_X − ∇_[X,Y]`` (Maithripala eq. (5), MATH §3).
  The curvature gain ``C`` defaults to ``−1``, not the ``+1`` printed in
  Maithripala et al. eq. (18) and MATH §4.  Re-derivation: linearising along
  the true motion, with ``J ≈ ζ`` the error and ``ε`` the transported
  velocity error, the symmetry lemma ``D_t D_s − D_s D_t = R(∂_t, ∂_s)`` gives

      D_t J = ε − 2α J,      D_t ε = −β J + (1 + C) R(v, J) v,

  so ``C = −1`` removes the curvature from the error dynamics (they become
  the flat ``ζ̈ + 2αζ̇ + βζ = 0``), ``C = 0`` leaves the Jacobi term of the
  geodesic deviation and ``C = +1`` doubles it.  Anisi–Hamberg §4.4 choose
  ``C = −2κ⁻¹Υ(S) → −1`` as ``S → 0`` and use ``C = −1`` in §5, consistent
  with this; ``+1`` is Aghannan–Rouchon's sign under the opposite curvature
  convention (do Carmo's).  The tests measure it.  Where the curvature is
  negative (a folded double pendulum, K = −207, spun at 20 rad/s with
  α = 10, β = 100) ``C = −1`` converges, ``C = 0`` stalls and ``C = +1``
  diverges.  On the unit S³ (K = 1) the slow decay rate of the error
  across the motion is ``α − √(α² − β − (1+C)K|v|²)`` for C = −1, 0, +1, as
  derived: positive curvature adds stiffness, so there dropping the term
  (or doubling it) is faster for overdamped gains; ``C = −1`` makes the
  rate independent of the curvature and of the speed.
* Anisi–Hamberg: ``A``, ``B``, ``C`` may depend on ``S = ½|ζ|²_g`` and the
  speed ``|v̂|_g`` (options ``gain_a``, ``gain_b``, ``gain_c``);
  :func:`anisi_hamberg_curvature_gain` is their ``C = −2κ⁻¹Υ(S)`` on a space
  of constant curvature κ.

Sampled data (MATH §7).  Between samples the observer follows the model:
one RKMK4 step (:func:`pinobs.model.dynamics_rk4`) of ``q̂̇ = v̂``,
``v̂̇ = M⁻¹(τ − c − g)`` over the interval ``H`` since the last correction
(4 ABA calls; under joint friction, stiff near ``v = 0``, in as many substeps as
:func:`~pinobs.model.integrators.friction_substeps` asks, as the ``ekf``'s).  At the sample instant the correction terms act, integrated
over ``H``; every one of them vanishes with ``ζ``, so a start on the truth
stays on it (measured in the tests: ≤ 1e-9 rad/s).  The linear part of the
correction is integrated exactly: with ``ζ⁻`` the predicted error,

    q̂⁺ = q̂⁻ ⊕ (−k₁ ζ⁻),
    v̂⁺ = v̂⁻ − k₂ ζ⁻ + ω(ζ⁻, k₁ v̂⁻ − H S) + H (S − S(q̂⁻)) + C H R(v̂⁻, ζ⁻) v̂⁻,
    k₁ = 1 − e^{−2αH},     k₂ = (1 + e^{−2αH} − 2 e^{−αH} cosh(H √(α² − β))) / H.

The prediction maps the linearised error ``(ζ, ε)`` by ``D = [[1, H], [0, 1]]``
and the correction by ``I − K [1 0]``, ``K = (k₁, k₂)``; these ``k₁, k₂`` are
the unique gains for which ``(I − K[1 0]) D`` has the eigenvalues
``e^{s₁H}, e^{s₂H}`` of the continuous error dynamics
(``s² + 2αs + β = 0``): determinant ``1 − k₁ = e^{−2αH}``, trace
``2 − k₁ − k₂H = tr e^{AH}``.  Hence the discrete error decays for every
``α, β > 0`` and every ``H``: at ``αH = 1`` the poles are
``e^{(−α ± √(α²−β))H}``, inside the unit circle, where an explicit Euler
correction (``k₁ = 2αH = 2``) would put one at ``−1``.  For ``αH → 0``,
``k₁ → 2αH`` and ``k₂ → βH``: the continuous observer.  The terms
``ω(ζ, k₁v̂)`` (transport of ``v̂`` along the jump of ``q̂``), ``H(S∥ − S(q̂))``
(the force error the prediction made) and the curvature term are the
geometric part of ``−ω(q̂̇, v̂) + S∥ + C R(v̂, ζ)v̂``, first order in ``ζ``.

Cost per update (counted in the tests): 4 ABA calls (the prediction) and one
ABA-derivatives call at ``(q̂⁻, δ, τ)``, which gives ``a = S(q̂) − Γs(δ, δ)``,
``∂a/∂q`` and ``∂a/∂v = −2Γs(δ, ·)``; hence ``Γs(δ, δ) = −½ (∂a/∂v) δ`` (for
ζ), every ``Γs(ζ, x) = ½ (∂a/∂v) x + O(δ²)``, ``S(q̂)`` and
``S(q) − S(q̂) = (∂a/∂q) δ + O(δ²)`` (first order is all the correction
needs; :func:`transport_first_order` is the exact-S version used by
:meth:`RiemannianObserver.vector_field`).  The curvature enters
through the Jacobi operator ``R(v̂, ·)v̂`` (:func:`jacobi_operator`, four
ABA-derivatives calls), recomputed every ``curvature_every`` samples (default
10: it moves with ``q̂, v̂``, not with the noise in ζ) and applied as a matrix
in between.  Around those calls the Python work is kept small: the RK4 prediction's stages
are compiled on the observer's own ``pin.Data`` (:mod:`pinobs.observers.fused`;
:class:`~pinobs.observers.fused_lie.LieRK4` with Lie-group or continuous joints); with the
Riccati schedule the whole step is one Python call around compiled ones
(:class:`~pinobs.observers.fused.RiccatiStep` where ``q ∈ Rⁿ``, else
:class:`~pinobs.observers.fused_lie.LieRiccatiStep`), otherwise the correction but its
bracket is one (:func:`~pinobs.observers.fused.lie_correction_loops`); all equal the
general :meth:`RiemannianObserver._correct` to rounding (tested).  The Jacobi operator's
calls share the correction's ``pin.Data`` (:class:`~pinobs.observers.fused_jacobi.JacobiCalls`,
compiled products, the same bits): with constant gains the update makes no BLAS call.  With
the Riccati schedule the whole plain update, the base's checks, copies and commit included, is
one Python call around compiled ones (:class:`~pinobs.observers.riemannian_fused.FusedUpdate`,
the observer's ``_update_fused``; the same bits as the base's path, which takes the rest).
:func:`pinobs.evaluation.measure_cost` reports ``time(update) / time(pin.aba)``
(chunks of updates, each followed by as many ``pin.aba`` calls; the Jacobi
operator counted at its amortised share).  Measured on a UR5 at 1 kHz:
see the benchmark's scaling table (README).

Default gains (rule, :mod:`pinobs.observers.riemannian_gains`).  Given ``alpha`` and
``beta``: used as given.  Else, with ``rate`` given, the gains are those of the steady-state
Kalman filter of the linearised error dynamics, one double integrator per tangent direction
with white acceleration of density ``accel_psd`` [rad²/s³] (model error) and position noise
σ = ``noise_std`` (1e-6 rad if not given): the DARE gain ``(k₁, k₂)`` at ``H = 1/rate`` is
inverted through the formulas above (:func:`steady_gains`), so the discrete observer
reproduces that filter's gain exactly at the nominal rate.  Where the DARE's error poles are
two negative reals (``ψH³/σ² ≫ 1``: no ``(α, β)`` has them) the rule takes the nearest gain
the form reaches, the same ``k₁`` and ``k₂H = (1 + √(1 − k₁))²``: ``β = α² + (π/H)²``
(``gain_rule`` ``"kalman-clipped"``; the Riccati schedule below still runs the Kalman gains
themselves, ``"steady"`` runs the clipped ones and warns).  ``accel_psd`` defaults to the
robot's own model error (:attr:`pinobs.Robot.model_error_psd`, measured by ``pinobs.identify``,
as ``ekf``'s), else 1e-8 rad²/s³ (trust an exact model); at 1 kHz and σ = 1e-4 rad that gives
α = 4.0 /s, β = 31.6 /s² (slow transients, lowest noise); raise it when the model is uncertain
or transients matter (1e-4: α = 40, β = 3162).  Else ``alpha = 60``, ``beta = 900``.

Gain schedule (``gain_schedule``, with the Kalman rule).  ``"riccati"``
(default): the same double-integrator filter run in time, not only at its
steady state: a 2×2 covariance ``P``, shared by every tangent direction (as
in ``kf``), starts at ``diag(q0_std², v0_std²)`` (defaults 0.1 rad, 1 rad/s,
as the ``ekf``'s) and follows ``P⁻ = F P Fᵀ + Q``, ``K = P⁻[:, 0] / (P⁻₀₀ + σ²)``,
Joseph update, over the interval since the last correction; the correction
uses ``k₁ = K₀``, ``k₂ = K₁``.  Large gains while the estimate is uncertain,
the steady-state gains above once it has converged: fast transients without
giving up the noise level.  Started on the truth, ζ ≡ 0 and the gains do not
matter.  ``"steady"``: the constant steady-state gains.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from pinobs.errors import GainError
from pinobs.model import Robot, dynamics_rk4
from pinobs.model.integrators import dynamics_calls, friction_rk4
from pinobs.observers.base import GateState, Observer, Vector, gate_threshold, positive, register
from pinobs.observers.checks import model_accel_psd
from pinobs.observers.fused import (
    RiccatiStep,
    lie_correction_kernel,
    loaded,
    riccati_correction_kernel,
    riccati_gains,
    rk4_calls,
    vector_correction_kernel,
)
from pinobs.observers.fused_jacobi import JacobiCalls, jacobi_kernel
from pinobs.observers.fused_lie import LieRiccatiStep, LieRK4
from pinobs.observers.riemannian_fused import FusedUpdate
from pinobs.observers.riemannian_gains import (
    DEFAULT_ALPHA,
    DEFAULT_BETA,
    GainFunction,
    RiemannianGains,
    anisi_hamberg_curvature_gain,
    check_schedule,
    checked_gain,
    discrete_gains,
    gains_from_noise,
    steady_gains,
    warn_clipped,
)
from pinobs.tolerances import JACOBI_FD_STEP

__all__ = [
    "GainFunction",
    "RiemannianGains",
    "RiemannianObserver",
    "anisi_hamberg_curvature_gain",
    "discrete_gains",
    "gains_from_noise",
    "jacobi_operator",
    "jacobi_term",
    "steady_gains",
    "transport_first_order",
]


# --------------------------------------------------------------- geometry
def jacobi_term(
    robot: Robot,
    q: Vector,
    v: Vector,
    z: Vector,
    *,
    at_z: tuple[Vector, Vector, Vector] | None = None,
) -> Vector:
    """``R(v, z) v`` at ``q``, the curvature contraction of the observer, shape ``(nv,)``.

    MATH §3 with ``X = Z = v``, ``Y = z`` (frame-constant fields)::

        R(v,z)v = D_v Γs(z,v) − D_z Γs(v,v) + ω(v, ω(z,v)) − ω(z, Γs(v,v)) − ω([v,z], v)

    from three ABA-derivatives calls, at ``(q, v)``, ``(q, z)`` and
    ``(q, v + z)``: each gives ``Γs(x,x)``, ``∂_q Γs(x,x)`` (so
    ``D_y Γs(x,x)`` for every y) and ``2Γs(x, ·)``; the mixed term comes by
    polarisation, ``D_v Γs(z,v) = ½ (D_v Γs(v+z) − D_v Γs(v) − D_v Γs(z))``.
    ``at_z`` passes the call at ``(q, z)`` when the caller already has it.
    Equals :meth:`Robot.curvature` ``(q, v, z, v)`` to rounding (tests).
    """
    g_vv, p_v, b_v = robot.spray_jacobians(q, v)
    _, p_z, b_z = at_z if at_z is not None else robot.spray_jacobians(q, z)
    _, p_vz, _ = robot.spray_jacobians(q, v + z)
    br = robot.bracket
    dv_gzv = 0.5 * ((p_vz - p_v - p_z) @ v)  # D_v Γs(z, v)
    dz_gvv = p_v @ z  # D_z Γs(v, v)
    w_zv = 0.5 * (b_v @ z) + 0.5 * br(z, v)  # ω(z, v)
    w_v_wzv = 0.5 * (b_v @ w_zv) + 0.5 * br(v, w_zv)  # ω(v, ω(z, v))
    w_z_gvv = 0.5 * (b_z @ g_vv) + 0.5 * br(z, g_vv)  # ω(z, Γs(v, v))
    vz = br(v, z)
    w_vz_v = 0.5 * (b_v @ vz) + 0.5 * br(vz, v)  # ω([v, z], v)
    return dv_gzv - dz_gvv + w_v_wzv - w_z_gvv - w_vz_v  # type: ignore[no-any-return]


def _ad_matrix(robot: Robot, x: Vector) -> Vector:
    """``ad_x`` as a matrix: column j is ``[x, E_j]`` (used where there are Lie-group joints)."""
    if isinstance(robot, Robot):
        return robot.bracket_matrix(x)  # block by block, no loop over the columns
    return np.column_stack([robot.bracket(x, e) for e in np.eye(robot.nv)])


def jacobi_operator(robot: Robot, q: Vector, v: Vector) -> Vector:
    """The matrix ``J`` with ``J z = R(v, z) v`` at ``q`` (the Jacobi operator), shape ``(nv, nv)``.

    Same formula as :func:`jacobi_term`, with ``ad_x y = [x, y]`` and the
    matrices ``B_x = ∂_x Γs(x, x) = 2Γs(x, ·)``, ``P_x = ∂_q Γs(x, x)``::

        J = ½ D_v B_v − P_v + (½B_v + ½ad_v)(½B_v − ½ad_v) − (½B_g − ½ad_g) − (½B_v − ½ad_v) ad_v

    with ``g = Γs(v, v)``.  Four ABA-derivatives calls: at ``(q, v)``,
    ``(q, g)`` and at ``q ⊕ ±εv`` for the central difference ``D_v B_v``
    (step ``ε|v| =`` :data:`pinobs.tolerances.JACOBI_FD_STEP`; error ~1e-9
    relative).  The observer caches it for ``curvature_every`` samples.  Once the observer
    has loaded :data:`~pinobs.observers.fused_jacobi.jacobi_kernel`, the sums run compiled
    (no BLAS; equal to the NumPy products to rounding, tested).
    """
    n = robot.nv
    speed = float(np.linalg.norm(v))
    if speed == 0.0:
        return np.zeros((n, n))
    g_vv, p_v, b_v = robot.spray_jacobians(q, v)
    _, _, b_g = robot.spray_jacobians(q, g_vv)
    eps = JACOBI_FD_STEP / speed
    _, _, b_plus = robot.spray_jacobians(robot.integrate(q, eps * v), v)
    _, _, b_minus = robot.spray_jacobians(robot.integrate(q, -eps * v), v)
    lie = robot.has_lie_group_joints
    ad_v = _ad_matrix(robot, v) if lie else None
    ad_g = _ad_matrix(robot, g_vv) if lie else None
    if jacobi_kernel.compiled is not None:  # the same sums in loops, no BLAS (fused_jacobi)
        out = np.empty((n, n))
        zero = np.zeros((n, n))
        jacobi_kernel.compiled(
            b_plus, b_minus, eps, p_v, b_v, b_g,
            zero if ad_v is None else ad_v, zero if ad_g is None else ad_g, 1.0, out,
        )  # fmt: skip
        return out
    dv_bv = (b_plus - b_minus) / (2.0 * eps)
    if ad_v is None or ad_g is None:  # ad ≡ 0: the same formula without the brackets
        return 0.5 * dv_bv - p_v + 0.25 * b_v.dot(b_v) - 0.5 * b_g  # type: ignore[no-any-return]
    left = 0.5 * (b_v - ad_v)  # z -> ω(z, v)
    right = 0.5 * (b_v + ad_v)  # a -> ω(v, a)
    return 0.5 * dv_bv - p_v + right @ left - 0.5 * (b_g - ad_g) - left @ ad_v  # type: ignore[no-any-return]


def geodesic_error(robot: Robot, q_hat: Vector, q: Vector) -> Vector:
    """``ζ = −(δ + ½ Γs(q̂)(δ, δ))``, ``δ = difference(q̂, q)``: ``−log_q̂(q)`` to second order."""
    delta = robot.difference(q_hat, q)
    return -(delta + 0.5 * robot.geodesic_spray(q_hat, delta))


def transport_first_order(robot: Robot, q_hat: Vector, zeta: Vector, s: Vector) -> Vector:
    """``S∥ = S − ω(ζ, S)``: ``S`` at ``q`` carried to ``q̂`` along the geodesic (error O(|ζ|²)).

    ``ζ = −log_q̂(q)``; Maithripala et al. eq. (19) with ω's arguments in the
    order of their eq. (1) (module docstring).
    """
    return s - robot.connection(q_hat, zeta, s)


# ---------------------------------------------------------------- observer
_new_tuple = tuple.__new__  # a NamedTuple made without its __new__ (the corrections)


class _State(NamedTuple):
    q: Vector
    v: Vector
    elapsed: float  # [s] since the last correction
    jacobi: Vector | None  # cached R(v̂, ·)v̂ (nv × nv), or None
    age: int  # corrections since the cache was computed
    P: tuple[float, float, float] | None = None  # (P₀₀, P₀₁, P₁₁) of the gain schedule, or None
    gate: GateState = GateState()  # the outlier gate's bookkeeping (Riccati schedule)


@register
class RiemannianObserver(Observer[_State]):
    """Intrinsic Riemannian observer (module docstring has the equations and the discrete scheme).

    Args:
        robot: any robot :func:`pinobs.load` accepts.
        alpha: position gain α [1/s] (Anisi–Hamberg ``A = 2α``).
        beta: velocity gain β [1/s²] (Anisi–Hamberg ``B``).
        curvature_gain: ``C`` in ``C·R(v̂, ζ)v̂``; −1 (default) cancels the
            curvature of the linearised error dynamics, 0 drops the term.
        curvature_every: recompute the Jacobi operator ``R(v̂, ·)v̂``
            (:func:`jacobi_operator`, 4 ABA-derivatives calls) every this
            many samples and reuse it in between (1 = every sample).
        gain_a: Anisi–Hamberg state-dependent gain ``(S, speed) -> A`` [1/s];
            replaces the constant ``A = 2·alpha``.
        gain_b: the same for ``B`` [1/s²]; replaces ``beta``.
        gain_c: the same for ``C``; replaces ``curvature_gain``.
        accel_psd: white-acceleration density [rad²/s³] of the gain rule used
            when ``alpha``/``beta`` are not given and ``rate`` is; ``None``: the robot's
            :attr:`~pinobs.Robot.model_error_psd`, else 1e-8.
        gain_schedule: ``"riccati"`` (time-varying Kalman gains from the rule's
            double-integrator model) or ``"steady"`` (its steady state); only
            with the rule (module docstring).
        q0_std: initial configuration standard deviation of the schedule [rad].
        v0_std: initial velocity standard deviation of the schedule [rad/s].
        rate: sample rate [Hz] (gain rule).
        noise_std: position noise standard deviation [rad or m] (gain rule).

    Raises:
        GainError: a gain out of range, or only one of ``alpha``, ``beta`` given.
    """

    name = "riemannian"
    uses_noise_std = True
    summary = "intrinsic Riemannian observer with curvature term (Aghannan–Rouchon, Anisi–Hamberg)"

    def __init__(
        self,
        robot: Robot,
        *,
        alpha: float | None = None,
        beta: float | None = None,
        curvature_gain: float = -1.0,
        gain_a: GainFunction | None = None,
        gain_b: GainFunction | None = None,
        gain_c: GainFunction | None = None,
        curvature_every: int = 10,
        accel_psd: float | None = None,
        gain_schedule: str = "riccati",
        q0_std: float = 0.1,
        v0_std: float = 1.0,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.outlier_probability, self._gate = gate_threshold(outlier_probability, robot.nv)
        self.accel_psd = model_accel_psd(robot, accel_psd)  # (as ekf's: module docstring)
        if gain_schedule not in ("riccati", "steady"):
            raise GainError(f"gain_schedule={gain_schedule!r}; give 'riccati' or 'steady'")
        positive("q0_std", q0_std)
        positive("v0_std", v0_std)
        self._p0 = np.diag([float(q0_std) ** 2, float(v0_std) ** 2])
        check_schedule(curvature_every, gain_a, gain_b, gain_c)
        self.curvature_every = curvature_every
        # An Anisi–Hamberg gain function stands in for the constant it replaces;
        # the constant is then its value at zero error and speed (for reports).
        if alpha is None and gain_a is not None:
            alpha = 0.5 * checked_gain("gain_a", gain_a(0.0, 0.0), 0.0, 0.0, positive_only=True)
        if beta is None and gain_b is not None:
            beta = checked_gain("gain_b", gain_b(0.0, 0.0), 0.0, 0.0, positive_only=True)
        if (alpha is None) != (beta is None):
            raise GainError(
                f"give both alpha and beta or neither (got alpha={alpha!r}, beta={beta!r}); "
                "with neither they follow from rate and noise_std"
            )
        if alpha is None or beta is None:
            if self.rate is not None:
                rule = steady_gains(self.rate, self.noise_std_used, self.accel_psd)
                alpha, beta = rule.alpha, rule.beta
                self.gain_rule = "kalman-clipped" if rule.clipped else "kalman"
            else:
                alpha, beta = DEFAULT_ALPHA, DEFAULT_BETA
                self.gain_rule = "default"
        else:
            self.gain_rule = "given"
        self.gains = RiemannianGains(
            alpha=alpha,
            beta=beta,
            curvature_gain=curvature_gain,
            gain_a=gain_a,
            gain_b=gain_b,
            gain_c=gain_c,
        )
        self._zero_nn = np.zeros((self.robot.nv, self.robot.nv))  # J when C = 0
        self._lie = not self.robot.is_vector_space  # brackets or unit-norm blocks to keep
        # the Riccati schedule replaces (α, β) only when they came from the Kalman rule
        self.gain_schedule = (
            gain_schedule
            if self.gain_rule.startswith("kalman") and not self.gains.state_dependent
            else "steady"
        )
        if self.gain_rule == "kalman-clipped" and self.gain_schedule == "steady":
            warn_clipped(rule)  # (at the user's call: make_observer's caller, or this one's)
        self._set_compiled_steps()

    @property
    def options(self) -> dict[str, Any]:
        g = self.gains
        return {
            **super().options,
            "alpha": g.alpha,
            "beta": g.beta,
            "curvature_gain": g.curvature_gain,
            "state_dependent_gains": g.state_dependent,
            "curvature_every": self.curvature_every,
            "accel_psd": self.accel_psd,
            "gain_rule": self.gain_rule,
            "gain_schedule": self.gain_schedule,
            "outlier_probability": self.outlier_probability,
        }

    def _set_compiled_steps(self) -> None:
        """The compiled steps (issue 39, :mod:`pinobs.observers.fused`; numba loaded now, not
        in an update) and their Pinocchio calls on the observer's own ``pin.Data``.  On a
        :class:`Robot` with constant gains the step makes no BLAS call, the Jacobi operator
        included (:attr:`Observer.uses_blas`)."""
        robot = self.robot
        self._scratch_calls = rk4_calls(robot)  # vector space: the RK4's stages
        self._scratch_lie = lie = LieRK4.build(robot)  # Lie-group joints: the RKMK4's
        # the correction's derivatives call (any Robot)
        calls = dynamics_calls(robot) if isinstance(robot, Robot) else None
        self._scratch_derivatives = calls
        self._correction = None if self._lie else loaded(vector_correction_kernel)
        compiled = isinstance(robot, Robot) and not self.gains.state_dependent
        # the vector-space correction with the schedule's gains: one compiled call
        riccati = not self._lie and self.gain_schedule == "riccati"
        self._riccati_correction = loaded(riccati_correction_kernel) if riccati else None
        # Lie-group joints: with the schedule the whole step (fused_lie.LieRiccatiStep), else
        # the correction but its bracket in one compiled call
        lie_fast = compiled and self.gain_schedule == "riccati" and lie is not None and lie.solves
        lie_compiled = compiled and self._lie and not lie_fast
        self._lie_correction = loaded(lie_correction_kernel) if lie_compiled else None
        # the Jacobi operator (the same bits), its calls on the correction's pin.Data
        self._scratch_jacobi = JacobiCalls(robot, calls.data) if compiled and calls else None
        self.uses_blas = not compiled or robot.has_friction  # (friction: dynamics_rk4's, inv)
        fast = riccati and compiled and self._scratch_calls is not None  # (fused.RiccatiStep)
        step = RiccatiStep if fast else LieRiccatiStep if lie_fast else None
        self._scratch_fast: Any = None if step is None else step(self, _State)
        # the plain update with that step in one Python call (riemannian_fused, issue 39):
        # Observer.update offers it to _update_fused first, an instance attribute here
        plain = step is not None and not (self._commits or self._own_innovation)
        fused = FusedUpdate(self, _State) if plain else None
        self._fused_path = fused is not None
        if fused is not None:
            vars(self)["_update_fused"] = fused.update

    # ------------------------------------------------------ continuous time
    def vector_field(
        self, q_hat: Vector, v_hat: Vector, q_meas: Vector, tau: Vector
    ) -> tuple[Vector, Vector]:
        """``(q̂̇, v̂̇)`` of the continuous-time observer (module docstring), in the frame at ``q̂``.

        ``q̂̇`` is a tangent vector [rad/s] (integrate with ``Robot.integrate``),
        ``v̂̇`` [rad/s²].  Gains evaluated at the current ``S`` and ``|v̂|_g``.
        """
        r = self.robot
        zeta = geodesic_error(r, q_hat, q_meas)
        alpha, beta, c = self._gains_at(q_hat, zeta, v_hat)
        tau = tau + r.friction_torque(v_hat)  # the model's joint friction (zero if none), at v̂
        s_par = transport_first_order(r, q_hat, zeta, r.force_per_metric(q_meas, tau))
        q_dot = v_hat - 2.0 * alpha * zeta  # Maithripala et al. eq. (17)
        v_dot = -r.connection(q_hat, q_dot, v_hat) + s_par - beta * zeta  # eq. (18)
        if c != 0.0:
            v_dot = v_dot + c * jacobi_term(r, q_hat, v_hat, zeta)  # Anisi–Hamberg eq. (6)
        return q_dot, v_dot

    # ------------------------------------------------------------ sampled
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        p0 = (self._p0[0, 0], 0.0, self._p0[1, 1]) if self.gain_schedule == "riccati" else None
        return _State(q0.copy(), v0.copy(), 0.0, None, 0, p0)

    def _predicted(self, state: _State, dt: float, tau: Vector) -> tuple[Vector, Vector, bool]:
        """The prediction (MATH §7), one RKMK4 step of the model over ``dt`` [s]: ``(q, v,
        work)``, ``work`` True where ``(q, v)`` are rows of the compiled step's work array
        (read them before the next step; copy what a state keeps)."""
        if self._scratch_lie is not None:  # Lie-group joints: compiled between the calls
            return (*self._scratch_lie.step(state.q, state.v, tau, dt), False)
        if self._scratch_calls is None:
            return (*self._model_step(state.q, state.v, tau, dt), False)
        # the same RK4 step (the same bits), compiled around the four ABA calls
        (aba, _, _), w, start, stage = self._scratch_calls
        start(w, state.q, state.v, aba(state.q, state.v, tau), dt)
        q, v = w[6], w[7]
        for k in (2, 3, 4):
            stage(w, aba(q, v, tau), k, dt)
        return q, v, True

    def _model_step(self, q: Vector, v: Vector, tau: Vector, dt: float) -> tuple[Vector, Vector]:
        """:func:`~pinobs.model.dynamics_rk4` over ``dt`` [s]; under joint friction (stiff near
        ``v = 0``) in :func:`~pinobs.model.integrators.friction_substeps` substeps, as the
        ``ekf``'s prediction: one RK4 step is stable only for ``λh < 2.785``."""
        r = self.robot
        if not (isinstance(r, Robot) and r.has_friction):
            return dynamics_rk4(r, q, v, tau, dt)
        acc = r.forward_dynamics(q, v, tau)  # (the first stage's, the same bits)
        return friction_rk4(r, q, v, tau, dt, acc, np.diag(np.linalg.inv(r.mass_matrix(q))))

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        fast = self._scratch_fast  # the same in one call (a vector space's: with a sample)
        if fast is not None and (q_meas is not None or self._lie):
            return fast.step(self, state, dt, q_meas, tau)
        q, v, work = self._predicted(state, dt, tau)
        elapsed = state.elapsed + dt
        if q_meas is None:
            if work:
                q, v = q.copy(), v.copy()
            return state._replace(q=q, v=v, elapsed=elapsed, gate=state.gate.predicted())
        gate, delta = state.gate, None
        if state.P is not None:
            # the schedule's innovation variance per joint, S = P⁻₀₀ + σ² (same for every
            # joint): NIS = |e|² / S and the outlier gate of the filters (base.GateState)
            p00, p01, p11 = state.P
            h = elapsed
            s_inn = p00 + h * (2.0 * p01 + h * p11 + self.accel_psd * h * h / 3.0) + self._sigma2
            # e = δ, the correction's (difference is − on a vector space)
            delta = self.robot.difference(q, q_meas) if self._lie else q_meas - q
            gate = gate.measured(float(delta.dot(delta)) / s_inn, self._gate, delta.size)
            if gate.gated:  # the estimate is the prediction; the next correction spans the gap
                if work:
                    q, v = q.copy(), v.copy()
                return state._replace(q=q, v=v, elapsed=elapsed, gate=gate)
        if not self._lie:
            return self._correct_vector_space(state, q, v, q_meas, tau, elapsed, delta, gate)
        if self._lie_correction is not None:
            return self._correct_compiled(state, q, v, q_meas, tau, elapsed, delta, gate)
        return self._correct(state._replace(gate=gate), q, v, q_meas, tau, elapsed)

    def _correction_gains(
        self, state: _State, q: Vector, zeta: Vector | None, v: Vector, h: float
    ) -> tuple[float, float, float, tuple[float, float, float] | None]:
        """``(k₁, k₂, C, P⁺)`` for a correction after ``h`` [s] (module docstring).

        ``zeta`` may be ``None`` unless the gains are state-dependent.
        """
        P = state.P
        if P is None:
            alpha, beta, c = self._gains_at(q, zeta, v)
            k1, k2 = discrete_gains(alpha, beta, h)
            return k1, k2, c, None
        # Riccati schedule of the double-integrator error model (module docstring);
        # constant gains here, so C is the constant one
        p00, p01, p11 = P  # 2×2 symmetric, in scalars: this runs every sample
        k1, k2, p00, p01, p11 = riccati_gains(p00, p01, p11, self.accel_psd, self._sigma2, h)
        return k1, k2, self.gains.curvature_gain, (p00, p01, p11)

    def _jacobi(self, state: _State, q: Vector, v: Vector, c: float) -> tuple[Vector | None, int]:
        """The cached ``R(v̂, ·)v̂``, recomputed every ``curvature_every`` corrections (with
        ``C ≠ 0``).  Before :meth:`_jacobians`: they share a ``pin.Data`` (JacobiCalls)."""
        jac, age = state.jacobi, state.age + 1
        if c != 0.0 and (jac is None or age >= self.curvature_every):
            fast = self._scratch_jacobi
            jac, age = (jacobi_operator(self.robot, q, v) if fast is None else fast(q, v)), 0
        return jac, age

    def _jacobians(self, q: Vector, x: Vector, tau: Vector) -> tuple[Vector, Vector, Vector]:
        """:meth:`Robot.forward_dynamics_jacobians`; on a :class:`Robot`, the same call on the
        observer's own ``pin.Data``, its arrays read in place (views, valid until the next
        call, the Jacobi operator's included)."""
        calls = self._scratch_derivatives
        if calls is None:
            return self.robot.forward_dynamics_jacobians(q, x, tau)
        calls.derivatives(q, x, tau)
        data = calls.data
        return data.ddq, data.ddq_dq, data.ddq_dv

    def _correct(
        self, state: _State, q: Vector, v: Vector, q_meas: Vector, tau: Vector, h: float
    ) -> _State:
        """The correction at a sample instant, integrated over ``h`` [s] (module docstring).

        Any robot; :meth:`_correct_vector_space` is the same where ``q ∈ Rⁿ``.
        """
        r = self.robot
        delta = r.difference(q, q_meas)
        # One analytic call at (q̂⁻, δ, τ): a = S(q̂) − Γs(δ,δ), ∂a/∂q, ∂a/∂v = −2Γs(δ, ·).
        acc, a_q, a_v = self._jacobians(q, delta, tau)
        g_dd = -0.5 * (a_v @ delta)  # Γs(δ, δ)
        zeta = -(delta + 0.5 * g_dd)  # second-order −log_q̂(q) (MATH §4)
        k1, k2, c, P = self._correction_gains(state, q, zeta, v, h)
        ds = a_q @ delta  # S(q) − S(q̂) + O(δ²): ∂_q Γs(δ,δ) is O(δ²)
        s_meas = acc + g_dd + ds  # S = M⁻¹(τ − g) at q, to first order
        w = k1 * v - h * s_meas
        # ω(ζ, w) with Γs(ζ, ·) = −Γs(δ, ·) + O(δ²) = ½ ∂a/∂v: transports v̂ along the
        # jump −k₁ζ and S to q̂ (Maithripala et al. eq. (19)).
        dv = 0.5 * (a_v @ w) - k2 * zeta + h * ds + 0.5 * r.bracket(zeta, w)
        jac, age = self._jacobi(state, q, v, c)  # (after the last read of a_q, a_v)
        if jac is not None and c != 0.0:
            dv = dv + (c * h) * (jac @ zeta)  # Anisi–Hamberg eq. (6): C·R(v̂, ζ)v̂
        q_new = r.normalize(r.integrate(q, -k1 * zeta))
        return state._replace(q=q_new, v=v + dv, elapsed=0.0, jacobi=jac, age=age, P=P)

    def _correct_compiled(
        self, state: _State, q: Vector, v: Vector, q_meas: Vector, tau: Vector, h: float,
        delta: Vector | None, gate: GateState,
    ) -> _State:  # fmt: skip
        """:meth:`_correct` with constant gains, its arithmetic but the bracket in one
        compiled call (:func:`~pinobs.observers.fused.lie_correction_loops`); the same
        formulas, equal to it to rounding (tested).  ``delta``: ``difference(q, q_meas)``
        if the caller has it; ``gate``: the new state's."""
        r = self.robot
        if delta is None:
            delta = r.difference(q, q_meas)
        jac, age = self._jacobi(state, q, v, self.gains.curvature_gain)  # (constant gains)
        acc, a_q, a_v = self._jacobians(q, delta, tau)
        k1, k2, c, P = self._correction_gains(state, q, None, v, h)
        n = v.shape[0]  # (r.nv asks Pinocchio: a Python call more)
        zeta, w, dv, jump = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        self._lie_correction(  # type: ignore[misc]
            v, acc, a_q, a_v, delta, self._zero_nn if jac is None else jac, k1, k2, h, c * h,
            zeta, w, dv, jump,
        )  # fmt: skip
        dv += 0.5 * r.bracket(zeta, w)  # ω(ζ, w)'s bracket (Maithripala et al. eq. (19))
        q_new = r.normalize(r.integrate(q, jump))
        return _new_tuple(_State, (q_new, v + dv, 0.0, jac, age, P, gate))

    def _correct_vector_space(
        self, state: _State, q: Vector, v: Vector, q_meas: Vector, tau: Vector, h: float,
        delta: Vector | None, gate: GateState,
    ) -> _State:  # fmt: skip
        """:meth:`_correct` where ``q ∈ Rⁿ`` (``⊕`` is ``+``, no bracket), compiled.

        The same formulas (the tests check it equals :meth:`_correct`); the
        arithmetic is one call of :func:`~pinobs.observers.fused.vector_correction_loops`
        (with the Riccati schedule's gains: :func:`~pinobs.observers.fused.riccati_correction_loops`).  ``delta``:
        ``q_meas − q`` if the caller has it; ``gate``: the new state's.
        """
        if delta is None:
            delta = q_meas - q
        constant = not self.gains.state_dependent  # (the schedule's gains are)
        if constant:
            jac, age = self._jacobi(state, q, v, self.gains.curvature_gain)
        acc, a_q, a_v = self._jacobians(q, delta, tau)
        if state.P is not None and self._riccati_correction is not None:
            c = self.gains.curvature_gain
            q_new, v_new = np.empty(q.shape[0]), np.empty(q.shape[0])
            P = self._riccati_correction(
                q, v, acc, a_q, a_v, delta, self._zero_nn if jac is None else jac, *state.P,
                self.accel_psd, self._sigma2, h, c, q_new, v_new,
            )  # fmt: skip
            # by tuple.__new__: the NamedTuple's own __new__ is a Python call more (issue 39)
            return _new_tuple(_State, (q_new, v_new, 0.0, jac, age, P, gate))
        # ζ is needed before the kernel only by state-dependent gains
        zeta = 0.25 * a_v.dot(delta) - delta if self.gains.state_dependent else None
        k1, k2, c, P = self._correction_gains(state, q, zeta, v, h)
        if not constant:
            jac, age = self._jacobi(state, q, v, c)
        q_new, v_new = self._correction(  # type: ignore[misc]
            q, v, acc, a_q, a_v, delta, self._zero_nn if jac is None else jac, k1, k2, h, c * h
        )
        return _State(q_new, v_new, 0.0, jac, age, P, gate)

    def _gains_at(self, q: Vector, zeta: Vector | None, v: Vector) -> tuple[float, float, float]:
        g = self.gains
        if not g.state_dependent:
            return g.alpha, g.beta, g.curvature_gain
        assert zeta is not None  # callers pass ζ when the gains are state-dependent
        m = self.robot.mass_matrix(q)
        s = 0.5 * float(zeta @ m @ zeta)
        speed = math.sqrt(max(float(v @ m @ v), 0.0))
        return g.at(s, speed)

    def output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q, state.v
