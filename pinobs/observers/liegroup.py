"""Intrinsic observer on a Lie group with left-invariant kinetic energy (Maithripala–Berg–Dayawansa).

A single rigid body on a spherical joint (G = SO(3)) or a free-flyer (G = SE(3)):
configuration ``g ∈ G`` (Pinocchio's quaternion / ``XYZQUAT``), body velocity
``ζ ∈ 𝒢`` (Pinocchio's ``v``: ``[linear; angular]`` on se(3)), constant inertia
``I`` (Pinocchio's mass matrix, the same at every ``q``).  Everything is written
with a basis ``{e_i}`` of the Lie algebra and no coordinates on the group
(Maithripala et al., §II–III):

    [e_i, e_j] = C^k_ij e_k                                                  structure constants
    ω^k_ij = ½ (C^k_ij − I^{ks}(I_ir C^r_js + I_jr C^r_is))                  eq. (2)
    R^k_jab = −ω^k_rj C^r_ab + 2 ω^k_ar ω^r_bj                               eq. (7)
    R(ζ, η)Ω = ½ R^k_jab Ω^j (ζ^a η^b − ζ^b η^a) e_k                         eq. (8), see below
    exp(ζ_e) = g⁻¹ g̃                                                        local error, §II-C
    Γ(S, ζ_e) = S − ω(ζ_e, S)                                                eq. (19), see below
    g̃̇ = g̃ · (ζ̃ − 2α ζ_e)                                                 eq. (20)
    ζ̃̇ = −ω(ζ̃ − 2α ζ_e, ζ̃) + Γ(S, ζ_e) + c·R(ζ̃, ζ_e) ζ̃ − β ζ_e            eq. (21)

with ``ω(x, y) = ω^k_ij x^i y^j e_k`` and ``S = I⁻¹(f^c + Σ u_i f^i)`` the force
per unit metric, here ``S(g, τ) = M⁻¹(τ − g(q))`` from the Pinocchio model
(gravity and the applied torques/forces), evaluated at the *measured* ``g``.
Expanding ``−ω(ζ̃ − 2αζ_e, ζ̃)`` with eq. (3) gives the paper's printed form
``I⁻¹(ad*_ζ̃ Iζ̃ − α(ad*_{ζ_e} Iζ̃ + ad*_ζ̃ Iζ_e)) + α[ζ_e, ζ̃]``; on SO(3) that is
eq. (29), on SE(3) eqs. (42)–(43) (angular first there).

Four places where the printed paper is not used as printed (each re-derived
and checked numerically, see ``tests/observers/test_liegroup.py``):

* eq. (21): the bracket term is ``α[ζ_e, ζ̃]`` (as in eq. 29), not ``[ζ_e, ζ̃]``
  (MATH §4).
* eq. (19): the paper contracts ``ω^k_ij S^i ζ_e^j = ω(S, ζ_e)``.  Parallel
  transport of ``S`` from ``g`` to ``g̃`` along ``g·exp(tζ_e)`` solves
  ``ẏ = −ω(ζ_e, y)`` (the first slot of ω is the direction of motion, eq. 1),
  so to first order ``S∥ = S − ω(ζ_e, S)``.  The two differ by
  ``[ζ_e, S] = O(|ζ_e|)``: the printed order is only zeroth-order accurate
  (measured: error 1.3e-3 vs 2.8e-7 against the exact transport at
  ``|ζ_e| = 1.7e-3`` on a generic SO(3) body).
* eq. (8): with eq. (7) the curvature is the Cartan 2-form
  ``θ^k_j(ζ, η) Ω^j = ½ R^k_jab Ω^j (ζ^a η^b − ζ^b η^a)`` (sum over all a, b);
  the printed extra term ``−ω^k_ij C^i_ab ζ^a η^b Ω^j`` counts ``∇_[ζ,η]``
  twice (it is already in ``−ω^k_rj C^r_ab``).  The contraction used here
  equals the model layer's :meth:`pinobs.Robot.curvature` to 1e-14; the
  printed one does not (relative error O(1)).
* eqs. (18), (21): the curvature term enters with ``c = curvature_gain``,
  default ``−1``; the paper prints ``+R(ζ̃, ζ_e)ζ̃`` (``c = +1``) with the
  convention of its eq. (5), ``R(X,Y) = ∇_X∇_Y − ∇_Y∇_X − ∇_[X,Y]``.
  Linearising along the true motion (error ``J ≈ ζ_e``, transported velocity
  error ``ε``) gives ``D_t J = ε − 2αJ``, ``D_t ε = −βJ + (1 + c) R(ζ, J) ζ``:
  ``c = −1`` leaves the flat ``J̈ + 2αJ̇ + βJ = 0``, ``c = +1`` doubles the
  Jacobi term (Aghannan–Rouchon's ``+`` belongs to do Carmo's opposite
  convention; Anisi–Hamberg's ``C = −2κ⁻¹Υ(S) → −1``; the ``riemannian``
  observer derives the same).  Measured: the heavy top spun at 30 rad/s about
  a transverse axis (sectional curvature −16 /(kg·m²) in the plane of the
  error) is lost from a 0.05 rad error with ``c = +1`` and converges with
  ``c = −1`` or ``0``.  ``curvature_gain=1.0`` reproduces the printed paper.

The log and its cut locus.  ``ζ_e = log(g⁻¹g̃)`` is ``Robot.difference(q, q̃)``,
which for these joints is exactly ``pin.log3`` / ``pin.log6`` of ``g⁻¹g̃``
(checked in the tests; MATH §4: eqs. (44)–(45) of the paper are inconsistent,
so the closed forms are not used).  Its rotation angle ψ lies in ``[0, π]``.
At ψ = π the rotation ``g⁻¹g̃`` has two minimal logs ``±π n``; Pinocchio
returns the one selected by the sign of the (w = 0) relative quaternion,
i.e. by the signs of the stored quaternions.  The result is finite, of norm
π, and a deterministic function of the two input vectors; either choice makes
the correction move ``g̃`` along a minimising geodesic towards ``g``.  Just
below π the error is the unique minimal log; ``ζ_e`` jumps from ``π n`` to
``−π n`` as the estimate crosses the cut locus (the distance ``|ζ_e|`` stays
continuous).  The observer's convergence is local (Aghannan–Rouchon): from
errors near π it is not guaranteed, only well defined.

Sampled data (MATH §7).  Between samples ``g`` is unknown, so the observer is
split into the model flow (eqs. 15–16 at the estimate: ``g̃̇ = g̃ζ̃``,
``ζ̃̇ = −ω(ζ̃, ζ̃) + S(g̃, τ)``), integrated by one RKMK4 step
(:func:`pinobs.model.lie_rk4`), and the correction, applied at the sample
instant with ``ζ_e`` from the new sample, ``h`` the time since the last
correction (one interval, or more after dropped samples):

    g̃⁺ = g̃⁻ · exp(−ℓ₁ ζ_e)                      (= g · exp((1 − ℓ₁) ζ_e) exactly)
    ζ̃⁺ = ζ̃⁻ + ℓ₁ ω(ζ_e, ζ̃⁻) + τ_v (Γ(S(g), ζ_e) − S(g̃⁻) + c·R(ζ̃⁻, ζ_e) ζ̃⁻ − β ζ_e)

with ``ℓ₁ = 1 − e^{−2αh}`` and ``τ_v = (1 − e^{λ₁h})(1 − e^{λ₂h}) / (βh)``,
``λ₁,₂ = −α ± √(α² − β)`` the roots of ``s² + 2αs + β``.  The first line is
the exact flow of ``g̃̇ = −2α g̃ζ_e`` with ``g`` held (``ζ_e`` then decays as
``e^{−2αt}`` because ``J_r(ζ)ζ = ζ``); ``ℓ₁ω(ζ_e, ζ̃)`` is eq. (21)'s
``2α ω(ζ_e, ζ̃)`` over that flow (transport of ``ζ̃`` along the jump);
``τ_v → h`` as ``h → 0``.  On a flat space the error then obeys
``e⁺ = [[1−ℓ₁, (1−ℓ₁)h], [−βτ_v, 1−βτ_v h]] e``, whose eigenvalues are
exactly ``e^{λ₁h}, e^{λ₂h}``: the samples of the continuous observer's error
dynamics, inside the unit circle for every ``α, β > 0`` and every ``h``
(stable for large gains, e.g. ``αh ≫ 1``).  Started on the truth without noise,
``ζ_e`` is the RK4 error of one step, so the estimate stays on the truth.

Consistency and outliers.  The observer has no covariance; its innovation
covariance is derived from the same flat error map, per tangent direction,
driven by the sensor noise ``n ~ N(0, σ² I)`` (σ = ``noise_std``, 1e-6 if not
given) and nothing else (an exact model has no process noise): ``ζ_e = δg̃⁻ − n``,
``e⁺ = (I − K H) D e + K n`` with ``K = (ℓ₁, βτ_v)``, ``D = [[1, h], [0, 1]]``,
whose steady-state covariance solves a 2 × 2 discrete Lyapunov equation
(:func:`pinobs.observers.base.steady_innovation_variance`), giving
``S = (D P Dᵀ)₀₀ + σ²`` (``1.010 σ²`` for the default gains at 1 kHz: the
noise-driven error is small beside the noise).  ``NIS = |ζ_e|²/S`` is then
χ²(nv) to first order in ``ζ_e`` while the estimate is converged and the
model exact; the neglected couplings (the force-error stiffness, Coriolis and
curvature terms) change ``S`` by ``O(αh)`` only.  It is a *steady-state*
approximation: during a transient from a wrong start the NIS is large (the
verdict says so until the estimate has converged).  So the first sample after
a reset is accepted whatever its NIS and sets the gate's level, as a sample
after a rejection does (:func:`pinobs.observers.base.outlier_gate`): the
level, a running mean of the NIS, then follows the transient down.
A sample the gate rejects is not used (the estimate is the prediction; the
next correction spans the gap, as after a dropout).

Every term linear in ``ζ_e`` that acts as a stiffness (``−βζ_e``, the force
error ``Γ(S(g), ζ_e) − S(g̃⁻)`` of the prediction, the curvature term) gets
the same weight ``τ_v``.  This matters for the curvature term at high spin:
on the linearised isotropic top (spin ``w`` about the symmetry axis, error
⊥ spin, c = −1, α = β = 10, h = 1 ms) the slow pole of the sampled error map
is 0.5138 1/s with weight ``τ_v`` (continuous: 0.5132) and 0.396 1/s with
weight ``h`` at w = 30 rad/s; at w = 60 rad/s, 0.518 against 0.054.  The
two weights differ by ``O(αh)`` only, but with c = −1 the curvature term
(``w²/4`` per unit error there) must cancel the Jacobi term of the prediction
to within a fraction of β, and ``w²/4 ≫ β``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pinobs.errors import GainError, UnsupportedRobotError
from pinobs.model import Robot, lie_rk4
from pinobs.observers.base import (
    MAX_GATE_RUN,
    GateState,
    Observer,
    Vector,
    gate_threshold,
    positive,
    register,
    steady_innovation_variance,
)
from pinobs.tolerances import LEFT_INVARIANT_INERTIA_TOL

__all__ = [
    "LieAlgebraGeometry",
    "LieGroupGains",
    "LieGroupObserver",
    "connection_coefficients",
    "correction_weights",
    "curvature_coefficients",
    "se3_basis",
    "so3_basis",
    "structure_constants",
]

_DEFAULT_ALPHA = 10.0  # [1/s]   Maithripala et al. §IV-A
_DEFAULT_BETA = 10.0  # [1/s²]  Maithripala et al. §IV-A


# ----------------------------------------------------------------- Lie algebra
def _hat(w: Vector) -> Vector:
    """``ŵ``: the so(3) matrix of ``w ∈ R³`` (Maithripala et al. eq. 22)."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def so3_basis() -> Vector:
    """The basis ``ê₁, ê₂, ê₃`` of so(3) as 3×3 matrices, shape ``(3, 3, 3)`` (eq. 22)."""
    return np.array([_hat(e) for e in np.eye(3)])


def se3_basis() -> Vector:
    """A basis of se(3) as 4×4 matrices, shape ``(6, 4, 4)``, in Pinocchio's order.

    ``e₀, e₁, e₂`` are the translations (``[[0, e_i], [0, 0]]``), ``e₃, e₄, e₅``
    the rotations (``[[ê_i, 0], [0, 0]]``): ``ζ = (v, Ω)``, linear first
    (Maithripala et al. eq. 35 writes ``(Ω, v)``).
    """
    basis = np.zeros((6, 4, 4))
    for i in range(3):
        basis[i, i, 3] = 1.0
        basis[3 + i, :3, :3] = _hat(np.eye(3)[i])
    return basis


def structure_constants(basis: Vector) -> Vector:
    """``C[k, i, j] = C^k_ij`` with ``[e_i, e_j] = e_i e_j − e_j e_i = C^k_ij e_k`` (§II-A).

    Args:
        basis: the basis as matrices, shape ``(n, d, d)``, linearly independent.

    Raises:
        ValueError: the commutators do not lie in the span of the basis (not a Lie algebra).
    """
    n = basis.shape[0]
    flat = basis.reshape(n, -1).T
    gram = flat.T @ flat  # diagonal for so3_basis / se3_basis: exact coefficients
    C = np.zeros((n, n, n))
    for i in range(n):
        for j in range(n):
            comm = (basis[i] @ basis[j] - basis[j] @ basis[i]).ravel()
            coef = np.linalg.solve(gram, flat.T @ comm)
            if np.linalg.norm(flat @ coef - comm) > 1e-12 * (1.0 + np.linalg.norm(comm)):
                raise ValueError(f"[e_{i}, e_{j}] is not in the span of the basis")
            C[:, i, j] = coef
    return C


def connection_coefficients(C: Vector, inertia: Vector) -> Vector:
    """``ω[k, i, j] = ω^k_ij``, the Levi-Civita connection of the left-invariant metric.

    Maithripala et al. eq. (2)::

        ω^k_ij = ½ (C^k_ij − I^{ks} (I_ir C^r_js + I_jr C^r_is))

    so that ``∇_{E_i} E_j = ω^k_ij E_k``.

    Args:
        C: structure constants ``C[k, i, j]``, shape ``(n, n, n)``.
        inertia: the metric ``I_ij`` (symmetric positive definite), shape ``(n, n)``
            [kg·m² on rotations, kg on translations].
    """
    inv = np.linalg.inv(inertia)
    sym = np.einsum("ks,ir,rjs->kij", inv, inertia, C) + np.einsum(
        "ks,jr,ris->kij", inv, inertia, C
    )
    return 0.5 * (C - sym)  # Maithripala et al. eq. (2)


def curvature_coefficients(C: Vector, omega: Vector) -> Vector:
    """``R[k, j, a, b] = R^k_jab = −ω^k_rj C^r_ab + 2 ω^k_ar ω^r_bj`` (Maithripala et al. eq. 7).

    Not antisymmetric in ``(a, b)`` as printed; only its antisymmetric part
    enters the contraction :meth:`LieAlgebraGeometry.curvature`.
    """
    return -np.einsum("krj,rab->kjab", omega, C) + 2.0 * np.einsum(
        "kar,rbj->kjab", omega, omega
    )  # Maithripala et al. eq. (7)


@dataclass(frozen=True)
class LieAlgebraGeometry:
    """The constant coefficients of a left-invariant metric on SO(3) or SE(3).

    Attributes:
        group: ``"so3"`` or ``"se3"``.
        inertia: ``I_ij``, shape ``(n, n)``.
        inertia_inv: ``I^{ij}``.
        C: structure constants ``C^k_ij``, shape ``(n, n, n)``.
        omega: connection coefficients ``ω^k_ij`` (eq. 2).
        riemann: curvature coefficients ``R^k_jab`` (eq. 7), shape ``(n, n, n, n)``.
    """

    group: str
    inertia: Vector
    inertia_inv: Vector
    C: Vector
    omega: Vector
    riemann: Vector

    @classmethod
    def build(cls, group: str, inertia: Vector) -> LieAlgebraGeometry:
        """The coefficients for ``group`` (``"so3"`` or ``"se3"``) and the metric ``inertia``."""
        basis = {"so3": so3_basis, "se3": se3_basis}[group]()
        C = structure_constants(basis)
        inertia = 0.5 * (inertia + inertia.T)
        omega = connection_coefficients(C, inertia)
        return cls(
            group=group,
            inertia=inertia,
            inertia_inv=np.linalg.inv(inertia),
            C=C,
            omega=omega,
            riemann=curvature_coefficients(C, omega),
        )

    @property
    def dim(self) -> int:
        """Dimension of the Lie algebra (3 or 6)."""
        return int(self.C.shape[0])

    def bracket(self, x: Vector, y: Vector) -> Vector:
        """``[x, y]_𝒢 = C^k_ij x^i y^j e_k``."""
        return np.einsum("kij,i,j->k", self.C, x, y)

    def connection(self, x: Vector, y: Vector) -> Vector:
        """``ω(x, y) = ω^k_ij x^i y^j e_k = ∇_x y`` for left-invariant ``x, y`` (eq. 1)."""
        return np.einsum("kij,i,j->k", self.omega, x, y)

    def curvature(self, x: Vector, y: Vector, z: Vector) -> Vector:
        """``R(x, y) z = ½ R^k_jab z^j (x^a y^b − x^b y^a) e_k`` (eqs. 7–8, module docstring).

        Convention of eq. (5): ``R(X, Y) = ∇_X∇_Y − ∇_Y∇_X − ∇_[X,Y]``.
        """
        t = np.einsum("kjab,j->kab", self.riemann, z)
        return 0.5 * (np.einsum("kab,a,b->k", t, x, y) - np.einsum("kab,a,b->k", t, y, x))

    def transport(self, s: Vector, zeta_e: Vector) -> Vector:
        """``Γ(S, ζ_e) = S − ω(ζ_e, S)``: ``S`` at ``g`` transported to ``g·exp(ζ_e)`` (eq. 19, corrected).

        First order in ``ζ_e`` (module docstring: the printed index order is
        zeroth-order accurate).
        """
        return s - self.connection(zeta_e, s)  # Maithripala et al. eq. (19), slots as in eq. (1)

    def euler(self, zeta: Vector) -> Vector:
        """``−ω(ζ, ζ) = I⁻¹ ad*_ζ Iζ``: the free motion's acceleration (eq. 16 with no force)."""
        return -self.connection(zeta, zeta)


def _geometry_of(robot: Robot) -> LieAlgebraGeometry:
    """The robot's Lie-algebra geometry, or :class:`UnsupportedRobotError`."""
    kinds = [b.kind for b in robot.joints]
    hint = (
        "the 'liegroup' observer needs a single rigid body on a spherical joint (SO(3)) "
        "or a free-flyer (SE(3)) with left-invariant kinetic energy; use 'riemannian', "
        "which runs on every robot"
    )
    if len(kinds) != 1 or kinds[0] not in ("so3", "se3"):
        raise UnsupportedRobotError(
            f"robot {robot.name!r} has joints {list(zip(robot.joint_names, kinds, strict=True))}; {hint}"
        )
    # Left-invariance: M(q) must not depend on q.  Deterministic sample of configurations.
    q0 = robot.neutral()
    m0 = robot.mass_matrix(q0)
    probe = np.array([0.3, -0.7, 1.1, -1.9, 2.3, -0.4])[: robot.nv]
    for scale in (0.5, 1.0, 2.7):
        m = robot.mass_matrix(robot.integrate(q0, scale * probe))
        if np.max(np.abs(m - m0)) > LEFT_INVARIANT_INERTIA_TOL * np.max(np.abs(m0)):
            raise UnsupportedRobotError(
                f"robot {robot.name!r}: the mass matrix depends on the configuration, "
                f"so the kinetic energy is not left-invariant; {hint}"
            )
    return LieAlgebraGeometry.build(kinds[0], m0)


def correction_weights(alpha: float, beta: float, h: float) -> tuple[float, float]:
    """``(ℓ₁, τ_v)`` of the sampled correction (module docstring).

    ``ℓ₁ = 1 − e^{−2αh}`` and ``τ_v = (1 − e^{λ₁h})(1 − e^{λ₂h}) / (βh)`` with
    ``λ₁,₂`` the roots of ``s² + 2αs + β``: the flat error map then has the
    eigenvalues ``e^{λ₁h}, e^{λ₂h}``.

    Args:
        alpha: gain [1/s].
        beta: gain [1/s²].
        h: time since the previous sample [s].
    """
    l1 = -math.expm1(-2.0 * alpha * h)
    root = np.emath.sqrt(alpha * alpha - beta)
    lam = np.array([-alpha + root, -alpha - root], dtype=complex) * h
    prod = np.expm1(lam[0]) * np.expm1(lam[1])  # (1 − e^{λ₁h})(1 − e^{λ₂h}), real
    return l1, float(prod.real) / (beta * h)


# -------------------------------------------------------------------- observer
@dataclass(frozen=True)
class LieGroupGains:
    """Validated gains of :class:`LieGroupObserver`.

    Attributes:
        alpha: configuration gain α [1/s], > 0 (eq. 20).
        beta: velocity gain β [1/s²], > 0 (eq. 21).
        curvature_gain: ``c`` of the curvature term (dimensionless, finite);
            −1 cancels the curvature in the linearised error, +1 is the printed
            paper (module docstring).
    """

    alpha: float
    beta: float
    curvature_gain: float = -1.0

    def __post_init__(self) -> None:
        positive("alpha", self.alpha)
        positive("beta", self.beta)
        if not (
            isinstance(self.curvature_gain, (int, float)) and math.isfinite(self.curvature_gain)
        ):
            raise GainError(
                f"curvature_gain={self.curvature_gain!r} is not a finite number; "
                "give -1 (default, cancels the curvature), 0 (drops it) or +1 (as printed)"
            )


class _State(NamedTuple):
    q: Vector  # g̃, Pinocchio configuration (unit quaternion inside)
    v: Vector  # ζ̃, body velocity in the Lie-algebra basis
    elapsed: float  # [s] since the last correction (longer than one interval after dropouts)
    gate: GateState = GateState()  # the outlier gate's bookkeeping (NIS of the last sample)


@register
class LieGroupObserver(Observer[_State]):
    """Maithripala–Berg–Dayawansa observer for one rigid body on SO(3) or SE(3).

    Args:
        robot: a single rigid body on a spherical joint or a free-flyer
            (``pinobs.load("top")``, ``pinobs.load("rigid_body")``).
        alpha: configuration gain α [1/s] (default 10, the paper's).
        beta: velocity gain β [1/s²] (default 10, the paper's).
        curvature_gain: ``c`` in ``c·R(ζ̃, ζ_e)ζ̃`` (default −1; +1 as printed,
            module docstring).
        outlier_probability: false-alarm probability ``p`` of the outlier gate
            (:meth:`step`); ``None`` switches the gate off.
        rate: sample rate hint [Hz] (unused: the gains are the paper's unless given).
        noise_std: position noise standard deviation [rad or m]: the gains ignore it,
            the NIS divides by it (1e-6 if not given, as the filters').

    Raises:
        UnsupportedRobotError: any other robot (use ``riemannian``).
        GainError: a gain that is not a finite number > 0.
    """

    name = "liegroup"
    uses_noise_std = True
    noise_in_gains = False  # σ only in the NIS (_sigma2)
    summary = "intrinsic observer on SO(3)/SE(3) from structure constants (Maithripala et al.)"

    def __init__(
        self,
        robot: Robot,
        *,
        alpha: float = _DEFAULT_ALPHA,
        beta: float = _DEFAULT_BETA,
        curvature_gain: float = -1.0,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.gains = LieGroupGains(alpha=alpha, beta=beta, curvature_gain=curvature_gain)
        self.outlier_probability, self._gate = gate_threshold(outlier_probability, robot.nv)
        self.geometry = _geometry_of(self.robot)
        # the RK4 stages' solves' LAPACK (dgesv) now: it was imported in the second update
        # (top: 0.19-0.2 s of CPU, 0.22-0.37 s of wall time; issue 39)
        zero = np.zeros(self.robot.nv)
        self.robot.integrate_jacobian_solve(self.robot.neutral(), zero, zero)

    @property
    def options(self) -> dict[str, object]:
        g = self.gains
        return {
            **super().options,
            "alpha": g.alpha,
            "beta": g.beta,
            "curvature_gain": g.curvature_gain,
            "outlier_probability": self.outlier_probability,
        }

    # ------------------------------------------------------------ the paper
    def error(self, q_meas: Vector, q_hat: Vector) -> Vector:
        """``ζ_e = log(g⁻¹ g̃)`` with ``g = q_meas``, ``g̃ = q_hat`` (§II-C; cut locus: module docstring)."""
        return self.robot.difference(q_meas, q_hat)

    def force(self, q: Vector, tau: Vector) -> Vector:
        """``S(g) = I⁻¹(f^c(g) + f(τ)) = M⁻¹(τ − g(q))`` [rad/s² or m/s²] (eq. 14)."""
        return self.robot.force_per_metric(q, tau)

    def vector_field(
        self, q_hat: Vector, v_hat: Vector, q_meas: Vector, tau: Vector
    ) -> tuple[Vector, Vector]:
        """The continuous-time observer, eqs. (20)–(21).

        Args:
            q_hat: estimate ``g̃`` (shape ``(nq,)``).
            v_hat: estimate ``ζ̃`` [rad/s, m/s] (shape ``(nv,)``).
            q_meas: measured ``g``.
            tau: applied torques/forces [N·m, N].

        Returns:
            ``(u, ζ̃̇)`` with ``g̃̇ = g̃ · u`` [rad/s, m/s] and ``ζ̃̇`` [rad/s², m/s²].
        """
        geo, g = self.geometry, self.gains
        zeta_e = self.error(q_meas, q_hat)
        tau = tau + self.robot.friction_torque(v_hat)  # the model's joint friction (zero if none)
        u = v_hat - 2.0 * g.alpha * zeta_e  # Maithripala et al. eq. (20)
        v_dot = (
            -geo.connection(u, v_hat)  # eq. (21): I⁻¹(ad*…) + α[ζ_e, ζ̃]
            + geo.transport(self.force(q_meas, tau), zeta_e)  # eq. (19)
            + g.curvature_gain * geo.curvature(v_hat, zeta_e, v_hat)  # eqs. (8), (21)
            - g.beta * zeta_e
        )
        return u, v_dot

    def model_vector_field(self, q: Vector, v: Vector, tau: Vector) -> tuple[Vector, Vector]:
        """The system itself, eqs. (15)–(16): ``(ζ, −ω(ζ, ζ) + S(g))``, joint friction included."""
        return v, self.geometry.euler(v) + self.force(q, tau + self.robot.friction_torque(v))

    # ------------------------------------------------------- sampled data
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        # the first sample is accepted whatever its NIS (a start-up transient, not a spike)
        return _State(q0.copy(), v0.copy(), 0.0, GateState(run=MAX_GATE_RUN))

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        q, v = lie_rk4(
            self.robot, state.q, state.v, dt, lambda qq, vv: self.model_vector_field(qq, vv, tau)
        )
        h = state.elapsed + dt
        if q_meas is None:
            return state._replace(q=q, v=v, elapsed=h, gate=state.gate.predicted())
        geo, g = self.geometry, self.gains
        l1, tau_v = correction_weights(g.alpha, g.beta, h)
        zeta_e = self.error(q_meas, q)
        # NIS of the flat, noise-driven error at steady state (module docstring) and the
        # filters' outlier gate (base.GateState)
        s_inn = steady_innovation_variance(l1, g.beta * tau_v, h, self._sigma2)
        gate = state.gate.measured(float(zeta_e.dot(zeta_e)) / s_inn, self._gate, zeta_e.size)
        if gate.gated:  # the estimate is the prediction; the next correction spans the gap
            return _State(q, v, h, gate)
        jump = -l1 * zeta_e  # exact flow of eq. (20)'s −2α ζ_e over h
        v_new = (
            v
            - geo.connection(jump, v)  # eq. (21)'s 2α ω(ζ_e, ζ̃) over the jump
            + tau_v
            * (
                geo.transport(self.force(q_meas, tau), zeta_e)  # eq. (19)
                - self.force(q, tau)  # already in the prediction
                + g.curvature_gain * geo.curvature(v, zeta_e, v)  # eqs. (8), (21)
                - g.beta * zeta_e  # poles matched
            )
        )
        q_new = self.robot.normalize(self.robot.integrate(q, jump))
        return _State(q_new, v_new, 0.0, gate)

    def output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q.copy(), state.v.copy()
