"""Contact-aided invariant EKF for a floating-base robot with an IMU and leg kinematics.

Hartley, Ghaffari, Eustice, Grizzle, *Contact-aided invariant extended Kalman
filtering for robot state estimation*, IJRR 39(4), 2020 (arXiv:1904.09251),
written from the equations (no code taken from the authors' ``invariant-ekf``).
References below name the paper's sections by their subject (the equation
numbers of the printed version could not be checked against a copy here);
the numbers (1)-(6) are this docstring's, cited as ``eq. (n)`` in the code.

State (the paper's "contact-inertial" state on the matrix Lie group SE_{2+K}(3))::

    X = [[R, v, p, d_1, …, d_K],          R: world from base (IMU) rotation
         [0,      I_{2+K}      ]]         v, p: base velocity and position in the world [m/s, m]
                                          d_j: world position of foot j in contact [m]
    θ = (b_g, b_a)                        gyro [rad/s] and accelerometer [m/s²] biases

"Base" in the filter is the IMU's frame: the free-flyer root joint's frame, or
with ``imu_frame`` a frame fixed to it (go1's ``imu_link``, 7 cm off the root),
whose placement ``(R_bi, r_bi)`` in the root frame converts the outputs back
to the root joint (Pinocchio's ``q[0:7]``, ``v[0:6]``), or one that moves with
other joints (TALOS's ``imu_link``, on the torso: :mod:`pinobs.observers.imu_link`,
the placement and the joints' velocities at each sample).  The biases
are a Euclidean augmentation outside the group: the paper's "imperfect IEKF"
(its section on IMU biases), whose bias columns depend on the estimate.

Process model (the paper's contact-inertial dynamics), IMU readings ω̃, ã
(ã the specific force in the base frame), white noises w::

    Ṙ = R (ω̃ − b_g − w_g)^,   v̇ = R (ã − b_a − w_a) + g,   ṗ = v,
    ḋ_j = R h_R(q) w_c,        ḃ_g = w_bg,   ḃ_a = w_ba,       g = (0, 0, −9.81) m/s²

**Error: right-invariant**, ``η = X̂ X⁻¹ = exp(ξ)``, ``ξ = (ξ_R, ξ_v, ξ_p, ξ_d1 … ξ_dK) ∈ R^{9+3K}``,
and ``ζ = θ̂ − θ``; the covariance ``P`` is that of ``e = (ξ, ζ)``, in this order
(``9 + 3K + 6`` entries).  ``exp`` of SE_{2+K}(3)::

    exp(φ, ρ_1, …, ρ_n) = [[Γ_0(φ), Γ_1(φ)ρ_1, …, Γ_1(φ)ρ_n], [0, I]],
    Γ_m(φ) = Σ_{k≥0} (φ^)^k / (k + m)!      (Γ_0 = Exp of SO(3), Γ_1 its left Jacobian)

Group-affine dynamics.  Writing ``U = (ω, a)^`` (the bias-corrected readings)
and ``N`` the matrix unit that copies the v column into the p column,
``Ẋ = X (U + N) + (G − N) X`` with ``G`` the gravity column: a sum of a
left- and a right-multiplication, so for inputs held over a step ``h``::

    X(h) = exp((G − N) h) · X(0) · exp((U + N) h)                                  (1)
         ⇔ R⁺ = R Γ_0(ωh),  v⁺ = v + R Γ_1(ωh) a h + g h,
           p⁺ = p + v h + R Γ_2(ωh) a h² + ½ g h²,  d⁺ = d       (the paper's discrete propagation)

(exact for readings held constant over the step).  The right-invariant error
then obeys ``η̇ = [G − N, η]``: autonomous and *independent of the trajectory*
(Barrau–Bonnabel; the paper's theorem on the log-linear error).  Linearised,
``ξ̇ = A ξ``, the same matrix along every trajectory and for every input::

    A = [[0,  0, 0, 0],      rows/cols: ξ_R, ξ_v, ξ_p, ξ_d (each foot's block like ξ_d)
         [g^, 0, 0, 0],      expm(A h) = I + A h + ½ A² h² (A³ = 0)                   (2)
         [0,  I, 0, 0],
         [0,  0, 0, 0]]

With noises and the bias error (the "imperfect" part, which is where the
estimate enters)::

    ė = [[A, −Ad_X̂ B], [0, 0]] e + [[Ad_X̂, 0], [0, I]] w,   B = [[I, 0], [0, I], [0, 0], …]   (3)

``Ad_X`` the adjoint of SE_{2+K}(3): ``[[R, 0], [x_i^ R, R]]`` for the columns ``x_i ∈ {v, p, d_j}``.

Discretisation, exact for held inputs.  In the body-frame error
``ε = Ad_X̂⁻¹ ξ`` (the left-invariant one) the system (3) has constant
coefficients, ``ε̇ = −ad(U + N) ε − B ζ + w``::

    ε̇_R = −ω^ ε_R − ζ_g,   ε̇_v = −ω^ ε_v − a^ ε_R − ζ_a,   ε̇_p = −ω^ ε_p + ε_v,   ε̇_dj = −ω^ ε_dj

so its transition ``Φ_ε = expm(F_ε h)`` is computed once per step (a 15 × 15
Taylor series for the R, v, p, bias blocks; ``Γ_0(ωh)ᵀ`` for each foot), and
``Φ = T(X̂⁺) Φ_ε T(X̂)⁻¹`` with ``T = diag(Ad_X̂, I₆)``.  Its ξ-block is exactly
``expm(A h)`` of (2) (a test checks it).  The process noise is
``Q = T(X̂⁺) · ½ (Φ_ε Q_c Φ_εᵀ + Q_c) h · T(X̂⁺)ᵀ`` (trapezoid; exact for the
feet), ``Q_c = diag(σ_g², σ_a², 0, σ_c² …, σ_bg², σ_ba²)`` (densities; the contact
noise is isotropic, so the foot's orientation ``h_R(q)`` drops out of ``R h_R Σ_c h_Rᵀ Rᵀ``).

Measurement (the paper's forward-kinematics measurement, a right-invariant
observation ``Y = X⁻¹ b + V``).  For each foot j in contact, with ``h_j(q)``
its position in the base frame from the measured joint angles q
(:class:`pinobs.model.FootKinematics`; rolling spheres, ``foot_radius``: :mod:`~.rolling`)::

    Y = (h_j(q̃), 0, 1, −1_j)ᵀ = X⁻¹ (0, 0, 1, −1_j)ᵀ + noise,    h_j(q) = Rᵀ (d_j − p)
    r_j = Π (X̂ Y − b) = R̂ h_j(q̃) − (d̂_j − p̂)  ≈  ξ_p − ξ_dj + R̂ J_j w_q            (4)
    H_j = [0, 0, I, 0 … −I (at d_j) … 0 | 0],   N_j = R̂ (J_j Σ_q J_jᵀ + σ_k² I) R̂ᵀ

with ``J_j = ∂h_j/∂q`` (Pinocchio's frame Jacobian), ``Σ_q = σ_q² I`` the
joint-encoder noise and ``σ_k`` a kinematic-model error.  ``H`` does not
depend on the estimate.  All feet in contact are stacked; then::

    S = H P Hᵀ + N,  K = P Hᵀ S⁻¹,  δ = K r,
    X̂⁺ = exp(−δ_ξ) X̂,  θ̂⁺ = θ̂ − δ_θ,  P⁺ = (I − KH) P (I − KH)ᵀ + K N Kᵀ      (5)

(``X̂ = exp(ξ) X``, so the estimated error is removed on the left: the
paper's right-invariant update ``X̂⁺ = exp(K r) X̂`` with its innovation sign.)

Contacts (the paper's section on adding and removing contact points).  A foot
whose contact ends is removed: its rows and columns of ``P`` are deleted (the
Gaussian marginal).  A foot whose contact begins is added *after* the update
of the others, from the updated estimate: ``d̂_j = p̂ + R̂ h_j(q̃)``, whose error
is ``ξ_dj = ξ_p + R̂ J_j w_q``::

    P ← F P Fᵀ + G N_j Gᵀ,   F: the new rows copy ξ_p's,   G: the new block.    (6)

A slipping foot (the paper's contact model assumes none beyond the white ``w_c``) is caught
with ``foot_gate=p``: before (5) each foot in the state is tested alone, its marginal
innovation ``r_j`` (eq. 4) against its own block of ``S``::

    NIS_j = r_jᵀ S_jj⁻¹ r_j,   S_jj = P_pp − P_pdj − P_djp + P_djdj + N_j   (χ² with 3 dof)

by the shared outlier gate (:mod:`pinobs.observers.gating`, threshold ``χ²₃(1 − p)``).  A
rejected foot does not correct the base: it is removed (its marginal) and re-anchored
where the legs now put it, by (6), as a foot that lands (its next innovation starts from
zero, so a run of rejections cannot leave the filter without feet).                    (8)

The foot's noise.  ``Σ_q`` in (4) is ``σ_q² I`` (``gains.joint``) or, with ``joint_std``,
``diag(σ_q,i²)`` per joint: the form of Hartley et al.'s forward-kinematics noise (SEROW's
contact position noise is likewise ``J`` of ``joint_position_variance``); ``σ_k`` is then a
floor for model error.  With ``slip_speed`` the contact density covers the foot's predicted
motion: the model says ``ḋ_j = 0``, the foot's velocity ``ṗ̂_j`` (:meth:`foot_velocities`,
at the previous update) says by how much that fails, and its displacement over the step,
``|ṗ̂_j| h``, is taken as the σ of that step of the foot's random walk::

    Q_c,dj = (σ_c² + |ṗ̂_j|² h) I                                                        (9)

(at lift-off and touch-down it is large: one white ``σ_c`` cannot fit both).  Standing,
``ṗ̂_j`` is mostly the readings' noise: the held gyro reading's (variance ``σ_g²/T`` per
axis, period ``T``) adds ``2 |h_j|² σ_g²/T`` to ``E|ṗ̂_j|²`` (go1, 400 Hz: 0.02 m/s), so with
``slip_gyro = σ_g`` (9) takes (:func:`~pinobs.observers.legs.slip_speeds`)::

    |ṗ_j|² ≈ max(|ṗ̂_j|² − 2 |h_j|² σ_g²/T, 0)                                            (10)

A foot still settling after its contact flag rose (a sphere sinking into a soft floor,
short bounces) moves most in its first milliseconds; with ``InEKFGains.landing`` ``σ_l``
and ``landing_time`` ``τ_l`` its density over that window is raised (both families;
:func:`~pinobs.observers.legged_filter.landing_densities`), ``t_j`` the time it landed
(was added by (6))::

    Q_c,dj = (σ_c² + σ_l² · |[t, t + h] ∩ [t_j, t_j + τ_l]| / h) I                     (11)

so that ``σ_c`` is the stance's own density, not one that spreads the landing over every
stance (MuJoCo's go1 trotting: 0.0136 m/s/√Hz over the first 20 ms, 0.0023 after;
``benchmarks/legged_truth.md``).  ``σ_l = 0`` (default) leaves the filter as it was.

With ``adapt_noise=T`` the feet's density (9)-(11) is scaled per axis of the IMU frame by ``α``
matched to the feet's innovations online (covariance matching, Mehra 1972; Myers & Tapley
1976; :mod:`~pinobs.observers.legged_adapt`, which says why the IMU's densities are not)::

    Q_c,dj ← diag(α) Q_c,dj,   log α_a ← log α_a + (h/(T K)) f_a (clip(log(e_a²/s_a)) − m)    (12)

``e = R̂ᵀ r_j``, ``s = diag(R̂ᵀ S_jj R̂)`` (8), ``f_a`` the share of ``s_a`` the foot's own
step density makes, ``α = 1`` at ``reset``; ``None`` (default): no scale.  Off by default: on
the MuJoCo go1 it lowers α (0.03-0.6) and costs velocity (``legged_run``'s trot 0.0082 →
0.0094 m/s) and ±2σ coverage (``benchmarks/legged_adapt_noise.md``).

Prior (at ``reset``, before any foot is added).  :class:`InEKFPrior` gives independent
errors of the attitude ``ξ_R``, of the velocity in the base frame ``v_b`` (as ``reset``
takes it), and of the world position: ``ξ_v = R̂ (v̂_b − v_b)`` exactly, and to first
order ``ξ_p = δp + p̂^ ξ_R`` (``δp = p̂ − p``, the p column of ``X̂ X⁻¹``), so::

    P₀ = T diag(σ_θ², σ_v², σ_p², σ_bg², σ_ba²) Tᵀ,   T = [[I, 0, 0], [0, I, 0], [p̂^, 0, I]] ⊕ I₆   (7)

A translation of the world by ``c`` maps ξ by ``Ad`` (``ξ_p, ξ_d += c^ ξ_R``), under
which (2)-(6) are equivariant; (7) is too, so the whole filter is the same wherever
the world's origin is (a diagonal ``P₀`` on ξ would give the base a position error
``p̂ × ξ_R`` growing with the distance from the origin).  Feet added by (6) then start
from the base's position, as in Hartley et al.

Sampled data (``docs/theory/math.md`` §7, as for torques): the IMU reading
passed with ``update(t_k, …)`` is held from ``t_k`` to ``t_{k+1}``, so the step
to ``t_k`` propagates with the reading stored at the previous call, then
corrects with ``q_k`` and the contacts at ``t_k``, then stores the new reading.
``reset`` stores the first reading (``gyro``/``acc``); without one, the first
step uses the reading of the first update.  Readings sampled from a smooth
motion are not constant between samples: holding them errs by O(period)
(measured: tilt 8.2e-4 rad, body velocity 1.1e-3 m/s at 200 Hz, half at
400 Hz); ``imu_hold="average"`` propagates with the mean of the two readings
that bound the step, O(period²).

Observability: yaw and the position are not observable from an IMU and leg
kinematics (their covariance grows); roll, pitch and the velocity are, and the
biases as far as the motion excites them.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import GainError
from pinobs.model import Robot
from pinobs.observers.base import Vector
from pinobs.observers.checks import positive
from pinobs.observers.gating import GateState, gate_threshold
from pinobs.observers.inekf_loops import (
    correct_kernel,
    expm_degree,
    foot_nis_kernel,
    gamma_coefficients,
    load_kernels,
    propagate_kernel,
    slip_kernel,
    velocity_kernel,
)
from pinobs.observers.legged_adapt import match_foot_scale, scaled_densities
from pinobs.observers.legged_filter import LeggedFilter
from pinobs.observers.legs import (
    GRAVITY,
    ContactKinematics,
    InEKFEstimate,
    InEKFGains,
    InEKFPrior,
    LegState,
    ResetInputs,
    UpdateInputs,
    check_contacts,
    check_joint_std,
    check_time,
    contact_kinematics,
    foot_noise,
    noise_densities,
    remove_feet,
    replace_state,
    rotation_to_quaternion,
    slip_speeds,
)
from pinobs.observers.linalg import cholesky_solve

__all__ = [
    "GRAVITY",
    "ContactKinematics",
    "InEKFEstimate",
    "InEKFGains",
    "InEKFPrior",
    "InEKFState",
    "InvariantEKF",
    "adjoint",
    "check_contacts",
    "check_time",
    "contact_kinematics",
    "error_transition",
    "gammas",
    "imu_step",
    "imu_vector_field",
    "prior_covariance",
    "propagate_mean",
    "right_invariant_error_matrix",
    "rotation_to_quaternion",
    "sek3_exp",
    "skew",
]

#: The invariant EKF's state (:class:`pinobs.observers.legs.LegState`; ``P`` is the
#: covariance of ``(ξ_R, ξ_v, ξ_p, ξ_d1 … ξ_dK, ζ_g, ζ_a)``).
InEKFState = LegState


_I3 = np.eye(3)
#: ``ndarray.sum``'s reduction, without its Python wrapper
_sum = np.add.reduce
_NO_SPEED: Vector = np.zeros(0)  # the propagation kernel's "no eq. (9) term": no speeds,
_NO_FEET: NDArray[np.intp] = np.zeros(0, dtype=np.intp)  # no feet


# ------------------------------------------------------------------- SO(3), SE_K(3)
def skew(w: ArrayLike) -> Vector:
    """``w^``: the 3 × 3 matrix with ``w^ x = w × x``."""
    x, y, z = np.asarray(w, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def gammas(phi: Vector) -> tuple[Vector, Vector, Vector]:
    """``(Γ_0, Γ_1, Γ_2)(φ)``, ``Γ_m(φ) = Σ_k (φ^)^k/(k+m)!`` (Hartley et al., discrete propagation).

    ``Γ_0`` is the SO(3) exponential, ``Γ_1`` its left Jacobian.  With
    ``θ = |φ|`` and ``(φ^)³ = −θ² φ^``, ``Γ_m = I/m! + c₁ φ^ + c₂ (φ^)²``,
    ``c₁ = Σ_k (−θ²)^k/(2k+1+m)!``, ``c₂ = Σ_k (−θ²)^k/(2k+2+m)!``: closed forms
    above :data:`pinobs.tolerances.SERIES_ANGLE`, the series (to θ⁸) below.
    """
    W = skew(phi)
    W2 = W @ W
    a0, b0, a1, b1, a2, b2 = gamma_coefficients(float(phi @ phi))
    return (
        _I3 + a0 * W + b0 * W2,
        _I3 + a1 * W + b1 * W2,
        0.5 * _I3 + a2 * W + b2 * W2,
    )


def sek3_exp(xi: Vector) -> tuple[Vector, Vector]:
    """``exp`` of SE_K(3): ``(R, x)`` with ``R = Γ_0(φ)``, ``x[i] = Γ_1(φ) ρ_i`` for
    ``ξ = (φ, ρ_1, …, ρ_n)``, shape ``(3 + 3n,)`` → ``(3, 3)``, ``(n, 3)``."""
    G0, G1, _ = gammas(xi[:3])
    return G0, xi[3:].reshape(-1, 3) @ G1.T


def adjoint(R: Vector, x: Vector) -> Vector:
    """``Ad_X`` of ``X = [[R, x_1 … x_n], [0, I]]``, ``(3 + 3n)`` square: ``[[R, 0], [x_i^ R, R]]``."""
    n = x.shape[0]
    out = np.zeros((3 + 3 * n, 3 + 3 * n))
    out[:3, :3] = R
    hats = np.zeros((n, 3, 3))  # x_i^ for every i at once
    hats[:, 0, 1], hats[:, 0, 2], hats[:, 1, 2] = -x[:, 2], x[:, 1], -x[:, 0]
    hats[:, 1, 0], hats[:, 2, 0], hats[:, 2, 1] = x[:, 2], -x[:, 1], x[:, 0]
    out[3:, :3] = (hats @ R).reshape(3 * n, 3)
    for i in range(n):
        out[3 + 3 * i : 6 + 3 * i, 3 + 3 * i : 6 + 3 * i] = R
    return out


# -------------------------------------------------------------------- dynamics
def imu_vector_field(
    R: Vector, v: Vector, omega: Vector, acc: Vector, gravity: ArrayLike = GRAVITY
) -> tuple[Vector, Vector, Vector]:
    """The continuous model ``(Ṙ, v̇, ṗ) = (R ω^, R a + g, v)`` (bias-corrected readings)."""
    return R @ skew(omega), R @ acc + np.asarray(gravity, dtype=float), np.array(v, dtype=float)


def propagate_mean(
    R: Vector,
    v: Vector,
    p: Vector,
    omega: Vector,
    acc: Vector,
    h: float,
    gravity: ArrayLike = GRAVITY,
) -> tuple[Vector, Vector, Vector]:
    """Eq. (1): the exact flow of :func:`imu_vector_field` over ``h`` [s] with ``ω`` [rad/s]
    and ``a`` [m/s²] (bias-corrected) held; returns ``(R⁺, v⁺, p⁺)``."""
    g = np.asarray(gravity, dtype=float)
    G0, G1, G2 = gammas(np.asarray(omega, dtype=float) * h)
    return (
        R @ G0,
        v + (R @ (G1 @ acc)) * h + g * h,
        p + v * h + (R @ (G2 @ acc)) * (h * h) + 0.5 * g * (h * h),
    )


def imu_step(
    R: Vector, x: Vector, omega: Vector, acc: Vector, h: float, gravity: ArrayLike = GRAVITY
) -> tuple[Vector, Vector]:
    """Eq. (1) on a state ``(R, x)`` (rows ``v, p, d_j``): ``(R⁺, x⁺)``, ``R⁺`` brought back
    onto SO(3) to first order (``R (3I − RᵀR)/2``: rounding only), the feet unchanged."""
    R1, v1, p1 = propagate_mean(R, x[0], x[1], omega, acc, h, gravity)
    R1 = R1 @ (1.5 * _I3 - 0.5 * (R1.T @ R1))
    x1 = x.copy()
    x1[0], x1[1] = v1, p1
    return R1, x1


def right_invariant_error_matrix(n_contacts: int, gravity: ArrayLike = GRAVITY) -> Vector:
    """Eq. (2): ``A`` of ``ξ̇ = A ξ`` (without biases), ``(9 + 3K)`` square; no state enters it."""
    n = 9 + 3 * n_contacts
    A = np.zeros((n, n))
    A[3:6, 0:3] = skew(gravity)
    A[6:9, 3:6] = _I3
    return A


def _expm_taylor(M: Vector) -> Vector:
    """``exp(M)`` by scaling (to ``‖M‖∞ ≤ 1/8``), a Taylor series and squaring; the degree d
    is the least with ``‖M‖^{d+1}/(d+1)! < 1e-17`` (6 at ‖M‖ = 0.01, 10 at 1/8)."""
    s, degree = expm_degree(float(np.abs(M).sum(axis=1).max()))
    A = M / (2.0**s)
    n = M.shape[0]
    eye = np.eye(n)
    out = eye + A / degree
    for k in range(degree - 1, 0, -1):
        out = A @ out
        out /= k
        out += eye
    for _ in range(s):
        out = out @ out
    return out


@functools.cache
def _indices(n_contacts: int) -> tuple[Any, Any]:
    """Index arrays for K feet: ξ_d's rows and ξ_p's (repeated) as ``H`` picks them (read-only)."""
    out = (np.arange(9, 9 + 3 * n_contacts), np.tile(np.arange(6, 9), n_contacts))
    for a in out:
        a.setflags(write=False)
    return out


def _body_transition(w: Vector, a: Vector, h: float, n_contacts: int) -> Vector:
    """``Φ_ε``: the transition over ``h`` of the body-frame error ``ε = Ad_X̂⁻¹ ξ`` and ``ζ``
    (module docstring), ``15 + 3K`` square, for bias-corrected readings ``w``, ``a`` held."""
    F = np.zeros((15, 15))  # (ε_R, ε_v, ε_p, ζ_g, ζ_a)
    W = skew(w)
    F[0:3, 0:3] = -W
    F[3:6, 0:3] = -skew(a)
    F[3:6, 3:6] = -W
    F[6:9, 3:6] = _I3
    F[6:9, 6:9] = -W
    F[0:3, 9:12] = -_I3
    F[3:6, 12:15] = -_I3
    core = _expm_taylor(F * h)  # its bias rows are exactly [0, I]
    n = 15 + 3 * n_contacts
    out = np.zeros((n, n))
    out[:9, :9] = core[:9, :9]
    out[:9, n - 6 :] = core[:9, 9:]
    out[n - 6 :, n - 6 :] = np.eye(6)
    foot = core[0:3, 0:3]  # ε̇_d = −ω^ ε_d, as ε_R without the bias: exp(−ω^ h)
    for j in range(n_contacts):
        s = slice(9 + 3 * j, 12 + 3 * j)
        out[s, s] = foot
    return out


def _inverse_frame(R: Vector, x: Vector) -> Vector:
    """``diag(Ad_X⁻¹, I₆)``: ``Ad_{X⁻¹}`` with ``X⁻¹ = (Rᵀ, −Rᵀ x_i)``."""
    n = 3 + 3 * x.shape[0] + 6
    out = np.eye(n)
    out[: n - 6, : n - 6] = adjoint(R.T, -(x @ R))
    return out


def error_transition(
    R: Vector, x: Vector, omega: Vector, acc: Vector, h: float, gravity: ArrayLike = GRAVITY
) -> Vector:
    """``Φ`` of eq. (3) over ``h`` [s] from the state ``(R, x)`` (rows ``v, p, d_j``) with the
    bias-corrected readings held: ``(9 + 3K + 6)`` square, error ``(ξ, ζ)``.  Its ξ-block is
    ``expm(A h)`` (eq. 2) whatever the state and readings."""
    K = x.shape[0] - 2
    R1, v1, p1 = propagate_mean(R, x[0], x[1], omega, acc, h, gravity)
    x1 = x.copy()
    x1[0], x1[1] = v1, p1
    n = 15 + 3 * K
    T1 = np.eye(n)
    T1[: n - 6, : n - 6] = adjoint(R1, x1)
    return T1 @ _body_transition(omega, acc, h, K) @ _inverse_frame(R, x)


def prior_covariance(prior: InEKFPrior, x: Vector) -> Vector:
    """Eq. (7): the prior of the right-invariant error ``(ξ, ζ)`` (no feet) from the
    :class:`InEKFPrior` of ``(ξ_R, R̂ δv_b, δp, ζ)`` (independent) at the estimate's
    position ``x[1] = p̂`` (module docstring): ``T diag(σ²) Tᵀ``, ``T``'s ``(ξ_p, ξ_R)``
    block ``p̂^``, so that the prior is the same wherever the world's origin is."""
    T = np.eye(15)
    T[6:9, 0:3] = skew(x[1])
    return T @ prior.covariance() @ T.T


# ---------------------------------------------------------------------- filter
class InvariantEKF(LeggedFilter):
    """Contact-aided invariant EKF (right-invariant error, bias-augmented; module docstring).

    Args:
        robot: a free-flyer robot (``pinobs.load("go1")``) or a
            :class:`ContactKinematics` (then ``feet`` is taken from it).
        feet: the foot frame names, with a robot.
        gains: noise levels (:class:`InEKFGains`).
        gravity: gravity in the world frame [m/s²].
        imu_frame: with a robot, the frame of the IMU if it is not the root joint's (fixed to
            the base, go1's ``"imu_link"``, or moving with joints, TALOS's: then the root's
            twist needs ``update``'s ``joint_velocities``; :mod:`~pinobs.observers.imu_link`).
        imu_hold: the reading used over ``[t_k, t_{k+1}]``: ``"previous"`` (the one at
            ``t_k``, held: MATH §7's convention, exact for readings that are held) or
            ``"average"`` (the mean of the readings at ``t_k`` and ``t_{k+1}``: second
            order in the period for readings sampled from a smooth motion, where
            ``"previous"`` is first order).
        foot_gate: the outlier probability ``p`` of the foot gate (module docstring, eq. 8):
            a foot whose own NIS exceeds ``χ²₃(1 − p)`` is re-anchored instead of measured;
            ``None`` (default): every foot in contact is measured.
        joint_std: the encoders' σ per joint [rad] (``nv − 6`` entries): eq. (4)'s ``Σ_q``,
            instead of ``gains.joint`` for every joint.
        slip_speed: eq. (9), each foot's contact noise from its speed predicted at the
            previous update (updates without ``joint_velocities``: ``gains.contact`` alone).
        slip_gyro: eq. (10), the gyro's white noise density [rad/s/√Hz] taken out of those
            speeds (the gyro's own, measured; 0, default: none taken out).
        foot_radius: the feet's sphere radius [m] (go1: 0.02): each foot measured at its point
            that touched the ground, which rolling leaves still (:mod:`pinobs.observers.rolling`,
            eq. R4); 0 (default): at its frame.
        rolling_lift: with ``foot_radius``, that point's cycloid lift removed (rolling.py's
            eq. R5: exact for a sphere rolling on the plane; ``True``, default; ``False``: R4
            alone, the default before).  Nothing without ``foot_radius``.
        adapt_noise: eq. (12), the window ``T`` [s] of the feet's density scale ``α`` per
            IMU axis matched to their innovations (:attr:`noise_scale`); ``None``
            (default): off.

    Raises:
        GainError: an ``imu_hold`` that is neither; a ``foot_gate`` not in (0, 0.5); a
            negative ``joint_std`` (non-finite: NonFiniteError), or one all 0 with
            ``gains.kinematics`` 0.
        UnknownNameError: a foot frame that is not in the model (names the frames).
        UnsupportedRobotError: a robot without a free-flyer root joint.
    """

    def __init__(
        self,
        robot: Robot | ContactKinematics,
        feet: Sequence[str] | None = None,
        *,
        gains: InEKFGains | None = None,
        gravity: ArrayLike = GRAVITY,
        imu_hold: str = "previous",
        imu_frame: str | None = None,
        foot_gate: float | None = None,
        joint_std: ArrayLike | None = None,
        slip_speed: bool = False,
        slip_gyro: float = 0.0,
        foot_radius: float = 0.0,
        rolling_lift: bool = True,
        adapt_noise: float | None = None,
    ) -> None:
        super().__init__(
            robot,
            feet,
            gains=gains,
            gravity=gravity,
            imu_hold=imu_hold,
            imu_frame=imu_frame,
            foot_radius=foot_radius,
            rolling_lift=rolling_lift,
        )
        s = self.setup
        self._gravity = np.array(self.gravity, dtype=float)  # writable: the kernel's signature
        #: the foot gate's outlier probability (``None``: off) and its χ²₃ threshold
        try:
            self.foot_gate, self._gate_nis = gate_threshold(foot_gate, 3)
        except GainError as exc:
            raise GainError(f"foot_gate: {exc}") from exc
        #: σ_q per joint [rad] (``None``: ``gains.joint`` for every joint), eq. (4)'s ``Σ_q``
        self.joint_std = None if joint_std is None else check_joint_std(joint_std, s.nv_joints)
        self._joint_var = 1.0 if self.joint_std is not None else self.gains.joint**2
        if self.joint_std is not None and not self.joint_std.any() and not self.gains.kinematics:
            raise GainError(
                "joint_std is all 0 and InEKFGains.kinematics is 0: the foot measurement would "
                "be exact and its innovation covariance singular; make one > 0"
            )
        #: eq. (9): each foot's contact density grows with its predicted speed
        self.slip_speed = bool(slip_speed)
        self.slip_gyro = positive("slip_gyro", slip_gyro, allow_zero=True) or 0.0
        self._speed: Vector | None = None  # |ṗ_j| of every foot at the last sample [m/s]
        #: the feet's positions and unscaled Jacobians of the last :meth:`_legs` call
        self._kinematics: tuple[Vector, Vector] = (np.empty((0, 3)), np.empty((0, 3, 0)))
        #: ``Q_c`` per number of feet, of these gains (:meth:`_noise_densities`)
        self._densities: tuple[InEKFGains | None, dict[int, Vector]] = (None, {})
        #: eq. (12): the window ``T`` [s] (``None``: off), the scale ``α`` per IMU axis, and
        #: each state foot's density times the last step ``h`` (after the scale), (K, 3)
        self.adapt_noise = None if adapt_noise is None else positive("adapt_noise", adapt_noise)
        self.noise_scale: Vector = np.ones(3)
        self._foot_q: tuple[float, Vector] = (0.0, np.empty((0, 3)))
        #: index arrays of the feet tuples seen (:meth:`_rows`)
        self._feet_rows: dict[tuple[int, ...], NDArray[np.intp]] = {}
        load_kernels()  # compiled (or loaded from numba's cache) now, not at the first update

    def error_matrix(self) -> Vector:
        """Eq. (2) for the current contacts: ``A`` of the right-invariant error, without biases."""
        return right_invariant_error_matrix(len(self.state.feet), self.gravity)

    def foot_velocities(self, q: ArrayLike, joint_velocities: ArrayLike, gyro: ArrayLike) -> Vector:
        """Each foot's velocity in the world [m/s], ``(K, 3)`` in the order of ``feet``, from
        the current state and the joint angles ``q`` (``nq − 7``), their velocities and the gyro
        reading (IMU frame, [rad/s])::

            ṗ_j = v̂ + R̂ ((ω̃ − b̂_g) × h_j(q) + J_j(q) q̇)      (zero for a foot that stands)

        (what :class:`pinobs.observers.contacts.ContactProbability` takes as the foot's speed).
        """
        h, jac = self.setup.legs(Robot.check_vector(q, self.setup.nq_joints, what="q"))
        dq = Robot.check_vector(joint_velocities, self.setup.nv_joints, what="joint_velocities")
        return self._velocities(h, jac, dq, Robot.check_vector(gyro, 3, what="gyro"))

    def foot_speeds_checked(
        self, q_joints: Vector, joint_velocities: Vector, gyro: Vector
    ) -> Vector:
        """``|ṗ_j|`` of :meth:`foot_velocities` (``(K,)`` [m/s]; the bits of
        ``np.linalg.norm(…, axis=1)``, ``((x² + y²) + z²)`` then ``√``) without its checks: for
        a caller that has checked its rows (:func:`pinobs.io.legged_run.legged_run`): finite
        C-contiguous float arrays of sizes ``nq − 7``, ``nv − 6`` and at least 3 (the gyro's
        first)."""
        h, jac = self.setup.legs(q_joints)
        return self._speeds(h, jac, joint_velocities, gyro)[1]

    def _velocities(self, h: Vector, jac: Vector, dq: Vector, gyro: Vector) -> Vector:
        """:meth:`foot_velocities` from the feet's positions ``h`` (K, 3) and unscaled Jacobians
        ``jac`` (K, 3, nv_j) in the IMU frame: ``v̂ + R̂ ((ω̃ − b̂_g) × h_j + J_j q̇)``."""
        return self._speeds(h, jac, dq, gyro)[0]

    def _speeds(self, h: Vector, jac: Vector, dq: Vector, gyro: Vector) -> tuple[Vector, Vector]:
        """:meth:`_velocities` and their norms ``|ṗ̂_j|``: ``J_j q̇`` by NumPy's ``@``, the rest
        compiled (:data:`pinobs.observers.inekf_loops.velocity_kernel`: the same bits as the
        cross product written out by columns and ``local @ R̂ᵀ`` it replaces)."""
        state = self.state
        out, speed = np.empty((h.shape[0], 3)), np.empty(h.shape[0])
        kernel = velocity_kernel.compiled
        assert kernel is not None  # loaded by the constructor
        # (ω = ω̃ − b̂_g from the first three entries of each, in the kernel)
        kernel(gyro, state.bias, np.ascontiguousarray(h), jac @ dq, state.R, state.x[0], out, speed)
        return out, speed

    # ------------------------------------------------------------- the steps
    def _initial_covariance(self, a: ResetInputs) -> Vector:
        """Eq. (7) (:func:`prior_covariance`)."""
        return prior_covariance(a.prior, a.x)

    def _propagate(self, state: InEKFState, imu: Vector, dt: float, t: float) -> InEKFState:
        """Eqs. (1)-(3): mean and covariance over ``dt`` with the reading ``imu`` held, as
        ``P⁺ = T(X̂⁺) (Φ_ε (T(X̂)⁻¹ P T(X̂)⁻ᵀ + ½ h Q_c) Φ_εᵀ + ½ h Q_c) T(X̂⁺)ᵀ`` (the module
        docstring's ``Φ P Φᵀ + Q``) in compiled loops (:mod:`pinobs.observers.inekf_loops`)."""
        x, P = state.x, state.P
        R1, x1, P1 = np.empty((3, 3)), np.empty_like(x), np.empty_like(P)
        qc = self._noise_densities(x.shape[0] - 2)
        speed, feet = _NO_SPEED, _NO_FEET  # eq. (9) in the propagation's kernel, or none
        if self._speed is not None and state.feet:
            speed, feet = self._speed, self._rows(state.feet)
        g = self.gains
        if self.adapt_noise is not None or (g.landing != 0.0 and g.landing_time != 0.0):
            if speed.shape[0]:  # eq. (9) first, then eqs. (11)-(12): slip_densities, compiled
                slip = np.empty(qc.shape[0])
                kernel = slip_kernel.compiled
                assert kernel is not None  # loaded by the constructor
                kernel(qc, speed, dt, feet, slip)
                slip.setflags(write=False)  # (the propagation's signature: Q_c read-only)
                qc, speed = slip, _NO_SPEED
            qc = self._landing(qc, state, dt)  # eq. (11)
            if self.adapt_noise is not None:  # eq. (12)'s scale
                k = len(state.feet)
                qc = scaled_densities(qc, self.noise_scale, k)
                self._foot_q = (dt, qc[9 : 9 + 3 * k].reshape(k, 3) * dt)
        kernel = propagate_kernel.compiled
        assert kernel is not None  # loaded by the constructor
        kernel(state.R, x, state.bias, imu, dt, self._gravity, qc, speed, feet, P, R1, x1, P1)
        return replace_state(state, t=t, R=R1, x=x1, P=P1)

    def _noise_densities(self, n_contacts: int) -> Vector:
        """:func:`~pinobs.observers.legs.noise_densities` of ``self.gains``, kept per number of
        feet for as long as ``gains`` is the same object (its hash, every sample, cost more)."""
        if self._densities[0] is not self.gains:
            self._densities = (self.gains, {})
        cache = self._densities[1]
        qc = cache.get(n_contacts)
        if qc is None:
            qc = cache[n_contacts] = noise_densities(self.gains, n_contacts)
        return qc

    def _gate(
        self, state: InEKFState, h: Vector, jac: Vector
    ) -> tuple[InEKFState, tuple[int, ...]]:
        """Eq. (8), with the foot gate: the feet whose own NIS exceeds its threshold removed
        (re-anchored by :meth:`_correct`, eq. 6), and their indices into ``feet``."""
        if not state.feet or self.foot_gate is None:
            return state, ()
        nis_j = self.foot_nis(state, h, jac)
        gated = [
            s for s, z in enumerate(nis_j) if GateState().measured(z, self._gate_nis, 3).gated
        ]  # the shared gate, fresh for each foot: a rejected one is re-anchored (eq. 8)
        if not gated:
            return state, ()
        return remove_feet(state, gated), tuple(state.feet[s] for s in gated)

    def _remember(self, u: UpdateInputs | None, h: Vector, dt: float = 0.0) -> None:
        """Eq. (9): with ``slip_speed``, the feet's speeds for the next step's contact noise
        (none after ``reset`` or an update without ``joint_velocities``); at ``reset`` eq.
        (12)'s scale back to 1."""
        if u is None:
            self.noise_scale = np.ones(3)
        if u is None or u.joint_velocities is None or not self.slip_speed:
            self._speed = None
        else:  # the update's own legs (:meth:`_legs`, at u.q_joints): not computed again
            h_now, jac = self._kinematics
            velocities, speed = self._speeds(h_now, jac, u.joint_velocities, u.reading)
            if self.slip_gyro == 0.0 and math.isfinite(float(_sum(speed, None))):
                self._speed = speed  # eq. (10) without its noise term: √max(|ṗ̂_j|², 0)
            else:
                self._speed = slip_speeds(velocities, h, self.slip_gyro, dt)  # eq. (10)

    def foot_nis(self, state: InEKFState, h: Vector, jac: Vector) -> Vector:
        """Eq. (8): each foot's own ``NIS_j = r_jᵀ S_jj⁻¹ r_j`` (3 dof) in the state's order,
        with ``h``, ``jac`` the feet's positions and Jacobians (:meth:`LeggedSetup.legs`), in
        a compiled loop (:data:`pinobs.observers.inekf_loops.foot_nis_kernel`)."""
        feet = list(state.feet)
        out = np.empty(len(feet))
        kernel = foot_nis_kernel.compiled
        assert kernel is not None  # loaded by the constructor
        g = self.gains
        rows = self._rows(feet)
        kernel(
            state.R,
            state.x,
            state.P,
            h.take(rows, 0),
            jac.take(rows, 0),
            self._joint_var,
            g.kinematics**2,
            out,
        )
        return out

    def _rows(self, feet: Sequence[int]) -> NDArray[np.intp]:
        """``feet`` (indices into ``feet``, in state order) as an index array, kept per tuple:
        ``h.take(rows, 0)`` gives the rows of ``h[feet]`` without converting the list each
        sample."""
        key = tuple(feet)
        rows = self._feet_rows.get(key)
        if rows is None:
            rows = self._feet_rows[key] = np.array(key, dtype=np.intp)
        return rows

    def _legs(self, q_joints: Vector, R: Any = None, flags: Any = None) -> tuple[Vector, Vector]:
        """The feet's positions and Jacobians (:meth:`LeggedSetup.legs`), the columns scaled by
        ``joint_std`` if given (``J diag(σ_q)``: eq. (4)'s ``J Σ_q Jᵀ`` with unit variance)."""
        h, jac = self.setup.legs(q_joints, R, flags)
        self._kinematics = (h, jac)  # unscaled, for the slip speeds (:meth:`_remember`)
        return (h, jac) if self.joint_std is None else (h, jac * self.joint_std)

    def _foot_noise(self, R: Vector, jac: Vector) -> Vector:
        """``N_j = R (J_j Σ_q J_jᵀ + σ_k² I) Rᵀ`` (eq. 4), for one ``J`` (3, n) or a stack (m, 3, n)."""
        return R @ foot_noise(self.gains, jac, self._joint_var) @ R.T

    def _update(
        self, state: InEKFState, measured: list[int], h: Vector, jac: Vector
    ) -> tuple[InEKFState, float]:
        """Eqs. (4)-(5) in compiled loops (:mod:`pinobs.observers.inekf_loops`); with NumPy
        (:meth:`_update_solve`) if ``S`` is not positive definite."""
        R, x, P = state.R, state.x, state.P
        window = self.adapt_noise
        if window is not None and self._foot_q[1].shape[0] == len(measured):
            self._match_scale(state, measured, h, jac, window)  # eq. (12), before the update
        R1, x1, theta, P1 = np.empty((3, 3)), np.empty_like(x), np.empty(6), np.empty_like(P)
        kernel = correct_kernel.compiled
        assert kernel is not None  # loaded by the constructor
        rows = self._rows(measured)  # (h[measured], jac[measured]: indexed in the kernel)
        g = self.gains
        nis = kernel(
            R, x, state.bias, P, h, jac, rows, self._joint_var, g.kinematics**2, R1, x1, theta, P1
        )
        if nis < 0.0:
            return self._update_solve(state, measured, h, jac)
        return replace_state(state, R=R1, x=x1, bias=theta, P=P1), float(nis)

    def _match_scale(
        self, state: InEKFState, measured: list[int], h: Vector, jac: Vector, window: float
    ) -> None:
        """Eq. (12): :attr:`noise_scale` after the measured feet's innovations
        (:meth:`foot_innovations`), ``window`` ``T`` [s]."""
        e, s, _ = self.foot_innovations(state, measured, h, jac)
        dt, q_h = self._foot_q
        self.noise_scale = match_foot_scale(self.noise_scale, e, s, q_h, dt, window)

    def foot_innovations(
        self, state: InEKFState, measured: list[int], h: Vector, jac: Vector
    ) -> tuple[Vector, Vector, Vector]:
        """The measured feet's innovations in the IMU frame ``R̂ᵀ r_j`` (eq. 4), their predicted
        variances ``diag(R̂ᵀ S_jj R̂)`` (eq. 8's blocks) and those of ``N_j`` alone, each
        ``(K, 3)``, before the update; ``h``, ``jac`` as :meth:`_update` takes them."""
        R, x, P = state.R, state.x, state.P
        k = len(measured)
        e = h[measured] - (x[2:] - x[1]) @ R  # R̂ᵀ (R̂ h_j − (d̂_j − p̂)), eq. (4)
        n_b = np.diagonal(foot_noise(self.gains, jac[measured], self._joint_var), 0, 1, 2)
        s = np.empty((k, 3))
        for i in range(k):
            d = slice(9 + 3 * i, 12 + 3 * i)
            S = P[6:9, 6:9] - P[6:9, d] - P[d, 6:9] + P[d, d]
            s[i] = np.einsum("ij,ik,kj->j", R, S, R) + n_b[i]  # diag(R̂ᵀ S R̂)
        return e, s, n_b

    def _update_solve(
        self, state: InEKFState, measured: list[int], h: Vector, jac: Vector
    ) -> tuple[InEKFState, float]:
        """Eqs. (4)-(5) with ``H``'s structure: ``H P`` is rows of P subtracted (ξ_p's minus ξ_dj's)."""
        R, x, P = state.R, state.x, state.P
        n = P.shape[0]
        k = len(measured)  # the feet in the state, all measured, in state order
        m = 3 * k
        d_idx, p_idx = _indices(k)
        r = (h[measured] @ R.T - (x[2:] - x[1])).reshape(-1)  # eq. (4)
        blocks = self._foot_noise(R, jac[measured])
        HP = P[p_idx] - P[d_idx]  # H = [0, 0, I, −I_j]
        S = HP[:, p_idx] - HP[:, d_idx]
        for i in range(k):
            S[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += blocks[i]
        rhs = np.empty((m, n + 1))
        rhs[:, :n] = HP
        rhs[:, n] = r
        sol, _ = cholesky_solve(S, rhs)  # S⁻¹ [H P, r]
        Kt = sol[:, :n]  # Kᵀ = S⁻¹ H P
        nis = float(r @ sol[:, n])
        delta = HP.T @ sol[:, n]  # K r
        dR, dx = sek3_exp(-delta[: n - 6])  # eq. (5): X̂⁺ = exp(−δ_ξ) X̂
        R1 = dR @ R
        x1 = x @ dR.T + dx
        theta = state.bias - delta[n - 6 :]
        # Joseph form, (I − KH) P (I − KH)ᵀ + K N Kᵀ = C − (C Hᵀ − K N) Kᵀ with C = P − K H P
        K = Kt.T
        C = P - K @ HP
        Y = C[:, p_idx] - C[:, d_idx]
        for i in range(k):
            Y[:, 3 * i : 3 * i + 3] -= K[:, 3 * i : 3 * i + 3] @ blocks[i]
        P1 = C - Y @ Kt
        P1 = 0.5 * (P1 + P1.T)
        return replace_state(state, R=R1, x=x1, bias=theta, P=P1), nis
