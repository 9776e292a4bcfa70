"""Model-free differentiators of Ibrir (§2): the dynamic-gain and the sliding-mode observer.

Both run per tangent direction of the configuration (one scalar chain per
joint velocity), on a chain of order ``n``: state ``x̂ = (x̂₁, …, x̂ₙ)`` where
``x̂₁`` estimates the position and ``x̂_{j}`` its ``(j−1)``-th derivative.
``A`` is the integrator chain ``A_ij = δ_{i,j−1}`` and ``C = (1, 0, …, 0)``.
On Lie-group joints ``x̂₁`` is the configuration ``q̂`` itself, the higher
derivatives are body-frame tangent vectors, and every place the paper writes
``y − x̂₁`` uses the group error ``e = difference(q̂, y)`` (the log of
``q̂⁻¹ y``), never raw quaternion numbers; ``x̂₁`` moves by ``q̂ ← q̂ ⊕ (…)``.

``highgain`` — Theorem 2.1 (eqs. 7–8)::

    x̂̇ = A x̂ + L(t)⁻¹ Cᵀ (y − C x̂)                                   (7)
    L̇ = −γ L − Aᵀ L − L A + Cᵀ C                                       (8)

``L(t)`` tends to ``L∞`` (eq. 9), whose gain ``L∞⁻¹ Cᵀ`` is
``(C(n,1)γ, C(n,2)γ², …, γⁿ)`` (Remark 2.1: the Esfandiari–Khalil
high-gain observer with ε = 1/γ), and the transfer functions are eq. (13)::

    X̂_j(s)/Y(s) = Σ_{k=j}^{n} C(n,k) γ^k s^{n−k+j−1} / (s + γ)^n.

(Remark 2.1 as printed has ``ẋ_{n−1} = x_{n−1} + …``; the chain is
``ẋ_j = x_{j+1} + α_j/εʲ (y − x₁)``.)  Sampled data: ``(q̂, x̂₂…x̂ₙ, L)`` are
integrated together by one RKMK4 step per sample interval, with ``y(t)``
interpolated on the group between the two samples that bound it
(``y(t) = y_{k−1} ⊕ s·difference(y_{k−1}, y_k)``): the classical
first-order-hold discretisation of a continuous-time filter, order 4 in
the step, and causal at the sample instants where the estimate is read.
Once ``L(t)`` equals ``L∞`` to rounding, on robots whose configuration is
a vector space, the step is the exact discretisation of the now LTI eq. (7)
with that piecewise-linear ``y`` (the first-order hold: Franklin, Powell &
Workman, *Digital Control of Dynamic Systems*, 3rd ed., §6.3.2)::

    (x̂, y, ẏ)(t + dt) = exp(M dt) (x̂, y, ẏ)(t),   M = [[A − k C, k, 0], [0, 0, 1], [0, 0, 0]]

(``k = L∞⁻¹Cᵀ``), 10× cheaper than RK4 and exactly eq. 13 at the sample instants.
``exp(M h)`` at the nominal interval ``h = 1/rate`` is SciPy's ``expm``, computed when the
observer is made and kept on disk (:mod:`pinobs.observers.gain_cache`: a later process makes
it without ``scipy.linalg``).  At any other interval (``k·h`` or ``t += h`` in floating point,
which differ from ``h`` in their last bits; a live loop's jittered stamps; a dropped sample),
no ``expm`` (issue 39: every jittered interval was new, an ``expm`` an
update, the median update 4–7× slower)::

    exp(M dt) = exp(M h)^m · Σ_{j=0}^{K} (M r)^j / j!,   m = round(dt/h),  r = dt − m h

(the exponential's semigroup property, ``exp(M h)`` from the cache, ``|r| ≤ h/2``; Moler &
Van Loan, "Nineteen dubious ways to compute the exponential of a matrix, twenty-five years
later", SIAM Review 45 (2003), methods 1 and 3), ``K`` the first with
``(ρ|r|)^{K+1}/(K+1)! · e^{ρ|r|} ≤ 2⁻⁵³`` (the series' remainder below the unit roundoff),
``ρ = ‖D⁻¹ M D‖₁`` in the chain's scaling ``D = diag(1, γ, …, γ^{n−1}, 1, γ)`` where ``M``'s
entries are ``O(γ)`` (ρ = 15γ at order 4: ``K = 7`` at ±50 µs off 1 kHz), in Horner's form;
``exp(M h)^m`` by squaring.  Against ``expm`` (UR5; orders 2–6, γ = 20–200 /s, 200 and
1000 Hz; entries scaled by ``γ^{i−j}``): within 1.1e-15 for ``|dt − h| ≤ h/2`` and 1.9e-14
for ``dt`` = 1.5–10.5 ``h``; at ``dt = 400 h`` (order 6) ``expm`` itself is 2.9e-11 off a
50-digit exponential and this 4.9e-14.  Estimates over 3 s at ±50 µs jitter (four option
sets): at most 9.3e-16 (``q̂``) and 7.9e-14 (``v̂``) of their largest value off the
``expm`` path.  On such robots the steps are one compiled call each (issue 39:
:mod:`pinobs.observers.chain_kernels`; 8 Python calls an update at most, 7 for the hold at
the interval ``h`` and 9 at another, was 135 while ``L(t)`` converges and 28 after; no BLAS
call), the same bits.
``L(0) = L∞(γ/κ)`` with κ = ``gain_ramp``: the observer starts κ times slower
and speeds up to γ within a few ``1/γ`` (the "nice transient" of Ibrir §5);
``L(t) ⪰ L∞ ≻ 0`` all along, since ``L∞(γ)`` decreases with γ.

``sliding`` — Theorem 2.2::

    x̂̇_ℓ = −β_ℓ (x̂₁ − y) + x̂_{ℓ+1} − k_ℓ sign(x̂₁ − y),   ℓ = 1…n  (x̂_{n+1} ≡ 0)
    k₁ = γ,  k_ℓ = C(n−1, ℓ−1) γ^ℓ  (ℓ ≥ 2)

(the paper's row ``n−1`` omits ``+ x̂ₙ``; without it ``x̂ₙ`` would not feed
the chain, so it is a typo like Remark 2.1's.)  In sliding (``x̂₁ ≡ y``) the
equivalent value of ``sign`` is ``(x̂₂ − ẏ)/k₁`` and the reduced chain
``(x̂₂ … x̂ₙ)`` has characteristic polynomial ``(s + γ)^{n−1}``: γ is the
bandwidth of the sliding differentiator.  ``β_ℓ = C(n,ℓ) λ^ℓ`` (the high-gain
chain with poles at ``−λ``) drives the reaching phase.

Discretisation (semi-implicit, Acary & Brogliato 2010): the drift ``A x̂`` is
transported exactly over the interval (a Taylor polynomial, exact for the
chain), then the output injection is taken *implicitly* at the sample::

    x̂⁺ = x̃ − h β σ⁺ − h k s⁺,   σ⁺ = x̂₁⁺ − y_k,   s⁺ ∈ Sgn(σ⁺)

whose first row ``(1 + hβ₁) σ⁺ + h k₁ s⁺ = r`` (``r = x̃₁ − y_k``) has the
unique solution ``σ⁺ = 0, s⁺ = r / (h k₁)`` if ``|r| ≤ h k₁`` and
``σ⁺ = (r − h k₁ sign r)/(1 + hβ₁), s⁺ = sign r`` otherwise.  Why: an explicit
``sign`` makes ``x̂₁ − y`` jump across zero by up to ``h k₁`` every sample
and feeds a ±``h k_ℓ`` square wave into the derivatives (numerical
chattering, for any step size); the implicit multiplier ``s⁺`` lands on the
discrete sliding surface exactly and is the discrete equivalent control, so
at 1 kHz the estimate is as smooth as the data allow.  ``discretization=
"explicit"`` keeps the chattering version for comparison.  On a vector space the step is
one compiled call (issue 39: :mod:`pinobs.observers.chain_kernels`, 7 Python calls an
update, was 24, no BLAS call), equal to the NumPy step to rounding.

Defaults from ``rate`` (1/h) and ``noise_std`` σ, for a motion with
``|y^{(n)}| ≤ B`` (``B`` = ``deriv_bound``, default ``0.5 πⁿ``: a 0.5 rad,
0.5 Hz motion), capped (the cap is used when σ = 0) at ``0.2·rate`` for
``highgain`` (its RK4 step reproduces eq. 13 within 10 % for γh ≤ 0.2 up to
order 4; at γh = 0.5 and order 4 the error is 35× the continuous lag) and
``0.5·rate`` for ``sliding`` (exact transport, implicit injection).

* ``highgain``: with steady gains the velocity estimate has noise variance
  ``c_n σ² h γ³`` (the H₂ norm of eq. 13, ``c₂ = 1/4``, ``c₃ = 7/4``) and a lag
  ``n B / γ^{n−1}``; their squared sum is least at
  ``γ^{2n+1} = 2 (n − 1) n² B² / (3 c_n σ² h)``.
* ``sliding``: once sliding, ``x̂₁ = y_k`` exactly and the reduced chain of
  order ``m = n − 1`` is driven by the raw differences of ``y``; the velocity
  takes a fraction ``m γ h`` of each backward difference (noise std
  ``≈ m γ σ``) and lags by ``B / γ^{n−1}``; the sum is least at
  ``γ^{2n} = B² / ((n − 1) σ²)``; ``λ = γ``.

Measured on a UR5 tracking the ``pd`` reference at 1 kHz, σ = 1e-4 rad
(velocity RMS after 0.5 s of a 2 s run; the best per-joint ``kf``,
``jerk_psd`` = 10, scores 5.2e-3): ``highgain`` order 4 with the default
γ = 48 /s 4.2e-3 (γ = 60: 3.9e-3, 88: 6.2e-3; order 3 at its best γ ≈ 110:
6.6e-3; order 2 at γ = 500: 1.9e-2); ``sliding`` order 4 with the default
γ = 23 /s 1.0e-2 (order 3/4/5 at their best γ = 50/30/25: 1.2e-2 / 9.7e-3 /
1.0e-2; explicit discretisation at γ = 30: 1.4 rad/s of chattering).  The sliding
differentiator cannot filter the position (it sets ``x̂₁ = y``), so it stays
about 2× behind the linear filters on noisy data; its use is noise-free or
quantised data and finite-time convergence.  Default order 4 for both.

Why about 2×, whatever γ (same run, 4 s, ``kf`` at its best ``jerk_psd`` =
10: 5.50e-3 rad/s).  The implicit step projects ``x̂₁`` onto ``y_k`` whenever
the miss ``|r|`` is within the sign's reach ``h k₁ = hγ``; the noise makes
``|r| ≈ σ``, so there are two regimes.  Sliding (``hγ ≫ σ``): ``x̂₁ = y_k``
every sample, the velocity is the reduced chain (bandwidth γ) driven by raw
backward differences, noise ``≈ (n − 1)γσ`` against lag ``B/γ^{n−1}``: 1.06e-2
at the default γ = 23 (1.93×), and γ = 0.1–3 /s (slower chain) 0.07–1.1
rad/s.  Not sliding (``hγ < σ``): the sign term is smaller than the noise,
the linear part β does the filtering and the observer is the high-gain chain
with a negligible discontinuous term; γ = 0.03, λ = 70: 5.70e-3 (1.04×).  A
differentiator that actually slides pays the projection; the default stays a
sliding one (reproduce with the grid in ``tests/observers/test_differentiators.py``
``test_sliding_regimes``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pinobs.errors import GainError
from pinobs.model import Robot, lie_rk4
from pinobs.observers.base import Observer, Vector, positive, register
from pinobs.observers.chain_kernels import (
    chain_rk4_kernel,
    hold_between_kernel,
    hold_kernel,
    sliding_kernel,
)
from pinobs.observers.fused import loaded
from pinobs.observers.gain_cache import expm_at, solve_continuous_lyapunov

__all__ = [
    "DifferentiatorGains",
    "HighGainDifferentiator",
    "SlidingDifferentiator",
    "chain_matrix",
    "default_bandwidth",
    "gain_riccati_rhs",
    "steady_gain_matrix",
    "steady_gains",
    "transfer_function",
]

_DEFAULT_RATE = 1000.0  # [Hz] assumed for default gains when no rate is given
_STEADY_TOL = 1e-13  # relative distance of L(t) to L∞ below which the gain is held fixed
_new_tuple = tuple.__new__  # a state NamedTuple without its __new__ (a Python call less)


def _compiled(robot: Robot) -> bool:
    """Whether the compiled steps run on ``robot``: a :class:`Robot` whose configuration is a
    vector space (:mod:`pinobs.observers.chain_kernels`)."""
    return isinstance(robot, Robot) and robot.is_vector_space


NDComplex = np.ndarray  # complex array (eq. 13 values)


# ------------------------------------------------------------------ algebra
def chain_matrix(n: int) -> Vector:
    """The integrator chain ``A_ij = δ_{i,j−1}`` (n × n)."""
    return np.eye(n, k=1)


def gain_riccati_rhs(L: Vector, gamma: float) -> Vector:
    """``L̇ = −γL − AᵀL − LA + CᵀC``, Ibrir eq. (8)."""
    n = L.shape[0]
    A = chain_matrix(n)
    CtC = np.zeros((n, n))
    CtC[0, 0] = 1.0
    return -gamma * L - A.T @ L - L @ A + CtC  # Ibrir eq. (8)


def steady_gain_matrix(n: int, gamma: float) -> Vector:
    """``L∞``: the solution of ``−γα − Aᵀα − αA + CᵀC = 0`` (Ibrir eq. 9).

    Closed form ``(L∞)_ij = (−1)^{i+j} C(i+j−2, i−1) / γ^{i+j−1}`` (1-based).
    """
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = (-1) ** (i + j) * math.comb(i + j, i) / gamma ** (i + j + 1)
    return out


def steady_gains(n: int, gamma: float) -> Vector:
    """``L∞⁻¹ Cᵀ = (C(n,1)γ, …, γⁿ)`` (Ibrir Remark 2.1)."""
    return np.array([math.comb(n, k) * gamma**k for k in range(1, n + 1)], dtype=float)


def transfer_function(n: int, gamma: float, s: complex) -> NDComplex:
    """``X̂_j(s)/Y(s)``, j = 1…n, of the steady observer: Ibrir eq. (13)."""
    den = sum(math.comb(n, k) * gamma**k * s ** (n - k) for k in range(n + 1))
    return np.array(
        [
            sum(math.comb(n, k) * gamma**k * s ** (n - k + j - 1) for k in range(j, n + 1)) / den
            for j in range(1, n + 1)
        ]
    )


def _velocity_noise_coefficient(n: int) -> float:
    """``c_n``: variance of x̂₂ per unit white-noise density on y, at γ = 1 (H₂ norm of eq. 13)."""
    A = chain_matrix(n)
    g = steady_gains(n, 1.0)
    F = A - np.outer(g, np.eye(n)[0])
    X = solve_continuous_lyapunov(F, -np.outer(g, g))  # (SciPy's, cached: gain_cache)
    return float(X[1, 1])


def default_bandwidth(
    n: int, rate: float, noise_std: float | None, deriv_bound: float, *, sliding: bool = False
) -> float:
    """γ [1/s] minimising noise plus lag of the velocity estimate (module docstring)."""
    cap = (0.5 if sliding else 0.2) * rate
    if not noise_std:
        return cap
    if sliding:
        g = (deriv_bound**2 / ((n - 1) * noise_std**2)) ** (1.0 / (2 * n))
        return min(g, cap)
    h = 1.0 / rate
    c = _velocity_noise_coefficient(n)
    g = (2.0 * (n - 1) * n**2 * deriv_bound**2 / (3.0 * c * noise_std**2 * h)) ** (
        1.0 / (2 * n + 1)
    )
    return min(g, cap)


# -------------------------------------------------------------------- gains
@dataclass(frozen=True)
class DifferentiatorGains:
    """Validated options of the differentiators.

    Attributes:
        order: chain order n >= 2 (states: position and n − 1 derivatives).
        gamma: bandwidth γ [1/s], > 0 (Theorem 2.1 / 2.2).
        aux: ``gain_ramp`` κ >= 1 (highgain) or λ [1/s] > 0 (sliding).
    """

    order: int
    gamma: float
    aux: float

    def __post_init__(self) -> None:
        if not isinstance(self.order, int) or self.order < 2:
            raise GainError(f"order={self.order!r} is out of range; give an integer >= 2")
        positive("gamma", self.gamma)
        positive("aux", self.aux)


def _resolve_gamma(
    order: int,
    gamma: float | None,
    rate: float | None,
    noise_std: float | None,
    deriv_bound: float | None,
    *,
    sliding: bool,
) -> float:
    if not isinstance(order, int) or order < 2:
        raise GainError(f"order={order!r} is out of range; give an integer >= 2")
    if gamma is not None:
        return float(positive("gamma", gamma))  # type: ignore[arg-type]
    b = positive("deriv_bound", deriv_bound, allow_none=True)
    bound = b if b is not None else 0.5 * math.pi**order
    return default_bandwidth(order, rate or _DEFAULT_RATE, noise_std, bound, sliding=sliding)


def _taylor_transport(robot: Robot, q: Vector, X: Vector, h: float) -> tuple[Vector, Vector]:
    """Exact flow of the chain ``x̂̇ = A x̂`` over ``h``: ``x̂_j ← Σ_m x̂_{j+m} h^m / m!``."""
    n1 = X.shape[0]
    coef = np.array([h ** (m + 1) / math.factorial(m + 1) for m in range(n1)])
    q_new = robot.integrate(q, coef @ X)
    X_new = np.empty_like(X)
    for j in range(n1):
        c = np.array([h**m / math.factorial(m) for m in range(n1 - j)])
        X_new[j] = c @ X[j:]
    return q_new, X_new


# ----------------------------------------------------------------- highgain
class _HGState(NamedTuple):
    q: Vector  # x̂₁ on the group
    X: Vector  # (n − 1, nv): x̂₂ … x̂ₙ
    L: Vector  # (n, n) dynamic gain matrix, eq. (8)
    y_prev: Vector | None  # last received sample
    since: float  # time since it [s]


@register
class HighGainDifferentiator(Observer[_HGState]):
    """Ibrir's dynamic-gain differentiator (Theorem 2.1), per joint, of order ``order``.

    Args:
        robot: the robot (only its Lie-group operations are used).
        order: chain order n >= 2 (2: position and velocity; 3 adds acceleration).
        gamma: bandwidth γ [1/s]; default from ``rate``/``noise_std`` (module docstring).
        gain_ramp: κ >= 1, ``L(0) = L∞(γ/κ)`` (1: start at the steady gain).
        deriv_bound: bound B on ``|y^{(n)}|`` [rad/sⁿ] for the default γ.
        rate: sample rate hint [Hz]; ``1/rate`` (1 ms without it) is the nominal interval ``h``
            of the exact hold (module docstring): other intervals take :meth:`hold_between`
            (within rounding of ``expm``, not its bits).
        noise_std: position noise hint [rad or m].
    """

    name = "highgain"
    uses_torque = False  # model-free: the torque is not used
    summary = "Ibrir's dynamic-gain differentiator, Thm 2.1 (model-free)"
    uses_noise_std = True

    def __init__(
        self,
        robot: Robot,
        *,
        order: int = 4,
        gamma: float | None = None,
        gain_ramp: float = 10.0,
        deriv_bound: float | None = None,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        g = _resolve_gamma(order, gamma, self.rate, self.noise_std, deriv_bound, sliding=False)
        if not gain_ramp >= 1.0:
            raise GainError(f"gain_ramp={gain_ramp!r} is out of range; give a number >= 1")
        self.gains = DifferentiatorGains(order=order, gamma=g, aux=float(gain_ramp))
        self._c = np.eye(order)[:, 0]
        self._L_inf = steady_gain_matrix(order, g)
        self._L_scale = float(np.max(np.abs(self._L_inf)))
        self._k_inf = np.linalg.solve(self._L_inf, self._c)
        self._build_holds(1.0 / (self.rate or _DEFAULT_RATE))
        # the steps compiled on a vector space (pinobs.observers.chain_kernels): no BLAS
        compiled = _compiled(self.robot)
        self._hold = loaded(hold_kernel) if compiled else None
        self._rk4 = loaded(chain_rk4_kernel) if compiled else None
        self._between = loaded(hold_between_kernel) if compiled else None
        self._tol = _STEADY_TOL * self._L_scale
        self.uses_blas = not compiled

    def _build_holds(self, h: float) -> None:
        """The exact hold ``exp(M·h)`` at the nominal interval ``h`` [s] (SciPy's ``expm``,
        cached on disk: gain_cache), and what :meth:`hold_between` needs for any other
        interval (module docstring)."""
        n = self.gains.order
        M = np.zeros((n + 2, n + 2))  # d/dt (x̂, y, ẏ) for the steady eq. (7), y linear
        M[:n, :n] = chain_matrix(n) - np.outer(self._k_inf, self._c)
        M[:n, n] = self._k_inf
        M[n, n + 1] = 1.0
        E = expm_at(M, np.array([h]))[0]  # expm(M·h), the bits expm gives
        # contiguous copies (the same numbers): the compiled step's loaded signature
        self._foh_cache = {h: (E[:n, :n].copy(), E[:n, n].copy(), E[:n, n + 1].copy())}
        self._M, self._h, self._E_h = M, h, E
        scale = self.gains.gamma ** np.r_[np.arange(n), 0.0, 1.0]  # x̂_j ~ γ^{j−1}, y ~ 1, ẏ ~ γ
        self._rho = float(np.max(np.sum(np.abs(M * scale / scale[:, None]), axis=0)))
        self._between_out = (np.empty((n, n)), np.empty(n), np.empty(n))

    @property
    def options(self) -> dict[str, object]:
        g = self.gains
        return {**super().options, "order": g.order, "gamma": g.gamma, "gain_ramp": g.aux}

    def gain(self) -> Vector:
        """The current injection gain ``L(t)⁻¹ Cᵀ`` (n,)."""
        if self._state is None:
            return np.full(self.gains.order, np.nan)
        return np.linalg.solve(self._state.L, np.eye(self.gains.order)[:, 0])

    def derivatives(self) -> Vector:
        """The current ``(x̂₂, …, x̂ₙ)``, shape ``(n − 1, nv)``: velocity, acceleration, … (a copy)."""
        if self._state is None:
            return np.full((self.gains.order - 1, self.robot.nv), np.nan)
        return np.array(self._state.X)

    def gain_matrix(self) -> Vector:
        """The current ``L(t)`` (a copy)."""
        if self._state is None:
            return np.full((self.gains.order, self.gains.order), np.nan)
        return np.array(self._state.L)

    def vector_field(
        self, q_hat: Vector, X: Vector, L: Vector, y: Vector | None
    ) -> tuple[Vector, Vector, Vector]:
        """Ibrir eqs. (7)–(8): ``(q̂̇ as a body velocity, Ẋ, L̇)`` for the measurement ``y``.

        ``y = None`` means no measurement (no injection; ``L`` still evolves).
        """
        k = np.linalg.solve(L, self._c)  # L⁻¹ Cᵀ, eq. (7)
        u, X_dot = self._chain_field(q_hat, X, k, y)
        return u, X_dot, gain_riccati_rhs(L, self.gains.gamma)

    def _chain_field(
        self, q_hat: Vector, X: Vector, k: Vector, y: Vector | None
    ) -> tuple[Vector, Vector]:
        """Eq. (7) for the gain ``k = L⁻¹Cᵀ``: ``ẋ_j = x_{j+1} + k_j (y − x₁)``."""
        X_dot = np.zeros_like(X)
        X_dot[:-1] = X[1:]
        if y is None:
            return X[0].copy(), X_dot
        e = self.robot.difference(q_hat, y)  # the group error, y − x₁
        return X[0] + k[0] * e, X_dot + np.outer(k[1:], e)

    def initial_state(self, q0: Vector, v0: Vector) -> _HGState:
        n, g = self.gains.order, self.gains
        X = np.zeros((n - 1, self.robot.nv))
        X[0] = v0
        L0 = steady_gain_matrix(n, g.gamma / g.aux)
        return _HGState(q0.copy(), X, L0, None, 0.0)

    def step(self, state: _HGState, dt: float, q_meas: Vector | None, tau: Vector) -> _HGState:
        since = state.since + dt
        rk4 = self._rk4
        if rk4 is None:
            return self._step(state, dt, q_meas, since)
        # the steps of _step in one compiled call (pinobs.observers.chain_kernels)
        y_prev, L_inf = state.y_prev, self._L_inf
        mode = 0 if q_meas is None else (1 if y_prev is None else 2)
        y, q, X = (
            y_prev if mode == 2 else state.q,
            np.empty(state.q.shape[0]),
            np.empty(state.X.shape),
        )
        m = state.q if q_meas is None else q_meas
        ratio, share = state.since / since, dt / since
        steady = state.L is L_inf
        if not steady:  # L(t) still converging (eq. 8), unless it is within rounding of L∞
            L = np.empty(L_inf.shape)
            if not rk4(state.q, state.X, state.L, L_inf, self._tol, self.gains.gamma,
                       self._k_inf, True, mode, y, m, ratio, share, dt, q, X, L):  # fmt: skip
                return self._committed(q, X, L, q_meas, state, since)
        if mode == 2:  # steady, a sample after a sample: the exact first-order hold
            assert self._hold is not None and self._between is not None and y is not None
            assert q_meas is not None
            holds = self._foh_cache.get(dt)  # (_first_order_hold, a Python call less)
            if holds is None:  # (hold_between's compiled path inline, a Python call less)
                holds = self._between_out
                self._between(self._E_h, self._M, self._h, dt, self._rho, *holds)
            Phi, psi0, psi1 = holds
            Z = np.empty((self.gains.order, y.shape[0]))
            self._hold(state.q, state.X, y, q_meas, ratio, share, dt, Phi, psi0, psi1, Z)
            return _new_tuple(_HGState, (Z[0], Z[1:], L_inf, m.copy(), 0.0))
        if mode == 1:  # (the first sample, its gain steady: rare)
            return self._step(state, dt, q_meas, since)
        rk4(state.q, state.X, L_inf, L_inf, 0.0, self.gains.gamma, self._k_inf, False, 0, y, m,
            ratio, share, dt, q, X, L_inf)  # fmt: skip
        return self._committed(q, X, L_inf, q_meas, state, since)

    @staticmethod
    def _committed(
        q: Vector, X: Vector, L: Vector, q_meas: Vector | None, state: _HGState, since: float
    ) -> _HGState:
        """The state after a step (``since``: the time since the last sample)."""
        if q_meas is None:
            return _new_tuple(_HGState, (q, X, L, state.y_prev, since))
        return _new_tuple(_HGState, (q, X, L, q_meas.copy(), 0.0))

    def _step(self, state: _HGState, dt: float, q_meas: Vector | None, since: float) -> _HGState:
        """:meth:`step` in NumPy (``since``: the time since the last sample, this step's
        included)."""
        n, nv = self.gains.order, self.robot.nv
        y0: Vector | None = None  # no sample: no injection
        d = np.zeros(nv)
        if q_meas is not None and state.y_prev is None:
            y0 = q_meas  # first sample: held over the first interval
        elif q_meas is not None and state.y_prev is not None:
            d_full = self.robot.difference(state.y_prev, q_meas)
            y0 = self.robot.integrate(state.y_prev, (state.since / since) * d_full)
            d = np.asarray((dt / since) * d_full, dtype=float)  # y(t₀ + s) = y0 ⊕ (s/dt) d
        n_x = (n - 1) * nv
        steady = np.max(np.abs(state.L - self._L_inf)) <= _STEADY_TOL * self._L_scale
        if steady and y0 is not None and self.robot.is_vector_space:
            # L(t) = L∞ to rounding and q ∈ Rⁿ: eq. (7) is LTI with a linear y(t) on the
            # interval, so its exact first-order-hold discretisation replaces RK4
            Phi, psi0, psi1 = self._first_order_hold(dt)
            Z = Phi @ np.vstack([state.q, state.X]) + np.outer(psi0, y0) + np.outer(psi1, d / dt)
            q, X, L = Z[0], Z[1:], self._L_inf
        elif steady:
            # L(t) has reached L∞ (eq. 9) to rounding: a fixed gain, no L dynamics
            def rhs_steady(q: Vector, x: Vector) -> tuple[Vector, Vector]:
                X = x[:n_x].reshape(n - 1, nv)
                y = None if y0 is None else self.robot.integrate(y0, (x[-1] / dt) * d)
                u, X_dot = self._chain_field(q, X, self._k_inf, y)
                return u, np.concatenate([X_dot.ravel(), [1.0]])

            x0 = np.concatenate([state.X.ravel(), [0.0]])
            q, x = lie_rk4(self.robot, state.q, x0, dt, rhs_steady)
            X, L = x[:n_x].reshape(n - 1, nv), self._L_inf
        else:

            def rhs(q: Vector, x: Vector) -> tuple[Vector, Vector]:
                X = x[:n_x].reshape(n - 1, nv)
                L = x[n_x:-1].reshape(n, n)
                y = None if y0 is None else self.robot.integrate(y0, (x[-1] / dt) * d)
                u, X_dot, L_dot = self.vector_field(q, X, L, y)
                return u, np.concatenate([X_dot.ravel(), L_dot.ravel(), [1.0]])

            x0 = np.concatenate([state.X.ravel(), state.L.ravel(), [0.0]])
            q, x = lie_rk4(self.robot, state.q, x0, dt, rhs)
            X = x[:n_x].reshape(n - 1, nv)
            L = x[n_x:-1].reshape(n, n)
            L = 0.5 * (L + L.T)
        if q_meas is None:
            return _HGState(q, X, L, state.y_prev, since)
        return _HGState(q, X, L, q_meas.copy(), 0.0)

    def _first_order_hold(self, dt: float) -> tuple[Vector, Vector, Vector]:
        """``(Φ, ψ₀, ψ₁)`` with ``x̂(dt) = Φ x̂(0) + ψ₀ y(0) + ψ₁ ẏ`` for the steady eq. (7), y linear:
        SciPy's ``expm`` at the nominal interval, :meth:`hold_between` otherwise."""
        cached = self._foh_cache.get(dt)
        if cached is None:
            return self.hold_between(dt)
        return cached

    def hold_between(self, dt: float) -> tuple[Vector, Vector, Vector]:
        """``(Φ, ψ₀, ψ₁)`` at any interval ``dt`` [s] without ``expm``:
        ``exp(M dt) = exp(M h)^m exp(M r)``, ``m = round(dt/h)``, ``r = dt − m h``, the second
        factor by its Taylor series truncated below rounding (module docstring).  The arrays
        are this observer's buffers, overwritten by the next call."""
        Phi, psi0, psi1 = self._between_out
        if self._between is not None:  # (pinobs.observers.chain_kernels.hold_between_loops)
            self._between(self._E_h, self._M, self._h, dt, self._rho, Phi, psi0, psi1)
            return Phi, psi0, psi1
        M, h, n = self._M, self._h, self.gains.order
        m = math.floor(dt / h + 0.5)
        r = dt - m * h
        x = abs(r) * self._rho
        K, term, bound = 0, 1.0, math.exp(x)
        while term * x / (K + 1) * bound > 2.0**-53:  # Taylor's remainder below rounding
            K += 1
            term *= x / K
        eye = np.eye(n + 2)
        T = eye
        for j in range(K, 0, -1):  # Horner: T ← I + (M r / j) T
            T = eye + (r / j) * (M @ T)
        E = np.linalg.matrix_power(self._E_h, m) @ T
        Phi[:], psi0[:], psi1[:] = E[:n, :n], E[:n, n], E[:n, n + 1]
        return Phi, psi0, psi1

    def output(self, state: _HGState) -> tuple[Vector, Vector]:
        return state.q, state.X[0]


# ------------------------------------------------------------------ sliding
class _SMState(NamedTuple):
    q: Vector  # x̂₁ on the group
    X: Vector  # (n − 1, nv): x̂₂ … x̂ₙ


@register
class SlidingDifferentiator(Observer[_SMState]):
    """Ibrir's sliding-mode differentiator (Theorem 2.2), semi-implicit, per joint.

    Args:
        robot: the robot (only its Lie-group operations are used).
        order: chain order n >= 2.
        gamma: sliding bandwidth γ [1/s] (``k₁ = γ``, ``k_ℓ = C(n−1,ℓ−1)γ^ℓ``);
            default from ``rate``/``noise_std`` (module docstring).
        lam: linear-part bandwidth λ [1/s] (``β_ℓ = C(n,ℓ)λ^ℓ``); default γ.
        deriv_bound: bound B on ``|y^{(n)}|`` [rad/sⁿ] for the default γ.
        discretization: ``"implicit"`` (default, no numerical chattering) or
            ``"explicit"`` (forward sign, chatters; for comparison).
        rate: sample rate hint [Hz].
        noise_std: position noise hint [rad or m].
    """

    name = "sliding"
    uses_torque = False  # model-free: the torque is not used
    summary = "Ibrir's sliding-mode differentiator, Thm 2.2, implicit (model-free)"
    uses_noise_std = True

    def __init__(
        self,
        robot: Robot,
        *,
        order: int = 4,
        gamma: float | None = None,
        lam: float | None = None,
        deriv_bound: float | None = None,
        discretization: str = "implicit",
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        g = _resolve_gamma(order, gamma, self.rate, self.noise_std, deriv_bound, sliding=True)
        lam_v = g if lam is None else positive("lam", lam)
        self.gains = DifferentiatorGains(order=order, gamma=g, aux=float(lam_v))  # type: ignore[arg-type]
        if discretization not in ("implicit", "explicit"):
            raise GainError(
                f"discretization={discretization!r} is not accepted; use 'implicit' or 'explicit'"
            )
        self.discretization = discretization
        n = order
        self.k = np.array([g] + [math.comb(n - 1, ell - 1) * g**ell for ell in range(2, n + 1)])
        self.beta = steady_gains(n, float(lam_v))  # type: ignore[arg-type]
        # the step compiled on a vector space (pinobs.observers.chain_kernels): no BLAS
        self._fast = loaded(sliding_kernel) if _compiled(self.robot) else None
        self.uses_blas = self._fast is None

    @property
    def options(self) -> dict[str, object]:
        g = self.gains
        return {
            **super().options,
            "order": g.order,
            "gamma": g.gamma,
            "lam": g.aux,
            "discretization": self.discretization,
        }

    def vector_field(self, q_hat: Vector, X: Vector, y: Vector) -> tuple[Vector, Vector]:
        """Ibrir Theorem 2.2: ``(q̂̇ as a body velocity, Ẋ)``; ``x̂₁ − y = −difference(q̂, y)``."""
        sigma = -self.robot.difference(q_hat, y)
        s = np.sign(sigma)
        X_ext = np.vstack([X, np.zeros((1, self.robot.nv))])
        u = X[0] - self.beta[0] * sigma - self.k[0] * s
        X_dot = X_ext[1:] - np.outer(self.beta[1:], sigma) - np.outer(self.k[1:], s)
        return u, X_dot

    def initial_state(self, q0: Vector, v0: Vector) -> _SMState:
        X = np.zeros((self.gains.order - 1, self.robot.nv))
        X[0] = v0
        return _SMState(q0.copy(), X)

    def step(self, state: _SMState, dt: float, q_meas: Vector | None, tau: Vector) -> _SMState:
        fast = self._fast
        if fast is not None:  # the steps below in one compiled call
            q_new, X_new = np.empty(state.q.shape[0]), np.empty(state.X.shape)
            measured = q_meas is not None
            fast(state.q, state.X, q_meas if measured else state.q, measured, dt, self.k,
                 self.beta, self.discretization == "implicit", q_new, X_new)  # fmt: skip
            return _new_tuple(_SMState, (q_new, X_new))
        q, X = _taylor_transport(self.robot, state.q, state.X, dt)  # drift, exact
        if q_meas is None:
            return _SMState(q, X)
        r = -self.robot.difference(q, q_meas)  # x̃₁ − y_k
        hk1, hb1 = dt * self.k[0], dt * self.beta[0]
        if self.discretization == "implicit":
            inside = np.abs(r) <= hk1
            s = np.where(inside, r / hk1, np.sign(r))  # s⁺ ∈ Sgn(σ⁺)
            sigma = np.where(inside, 0.0, (r - hk1 * np.sign(r)) / (1.0 + hb1))
        else:
            s = np.sign(r)
            sigma = r
        dq = (sigma - r) if self.discretization == "implicit" else -(hb1 * r + hk1 * s)
        q = self.robot.integrate(q, dq)
        X = X - dt * (np.outer(self.beta[1:], sigma) + np.outer(self.k[1:], s))
        return _SMState(q, X)

    def output(self, state: _SMState) -> tuple[Vector, Vector]:
        return state.q, state.X[0]
