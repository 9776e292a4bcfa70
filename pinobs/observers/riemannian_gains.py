"""The ``riemannian`` observer's gains: the rule from the noise to ``(α, β)``, the sampled gains,
and the validated gains (:class:`RiemannianGains`, with Anisi–Hamberg's state-dependent ones).

**Sampled gains** (:func:`discrete_gains`; :mod:`pinobs.observers.riemannian`'s module
docstring, MATH §7).  The prediction maps the linearised error ``(ζ, ε)`` by
``D = [[1, h], [0, 1]]``, the correction by ``I − K [1 0]``, ``K = (k₁, k₂)``; the gains whose
``(I − K[1 0]) D`` has the eigenvalues ``e^{s₁h}, e^{s₂h}`` of ``s² + 2αs + β = 0`` are

    k₁ = 1 − e^{−2αh},     k₂ = (1 + e^{−2αh} − tr e^{Ah}) / h

(determinant ``1 − k₁ = e^{−2αh}``, trace ``2 − k₁ − k₂h = tr e^{Ah}``,
``A = [[−2α, 1], [−β, 0]]`` the continuous error dynamics).

**The rule** (:func:`steady_gains`).  The steady-state Kalman gain ``K`` of one double
integrator per tangent direction, white acceleration of density ψ = ``accel_psd``
[rad²/s³], position noise σ = ``noise_std``, at ``h = 1/rate`` (the DARE), converted to
``(α, β)`` through its error poles ``λ = e^{sh}``: ``α = −½ Re(s₁ + s₂)``, ``β = Re(s₁s₂)``.

**Its reach.**  With ``d = 1 − k₁ = e^{−2αh} ∈ (0, 1)`` and ``t = 2 − k₁ − k₂h``, the
poles ``e^{sh}`` of the paper form are a positive pair or a conjugate pair
``√d e^{±iθ}``, ``θ = ωh``, ``ω = √(β − α²)``: ``t = 2√d cos θ ≥ −2√d``, i.e.

    k₂ h ≤ (1 + √(1 − k₁))²,

reached at ``θ = π`` (the double pole ``−√d``).  When ψh³/σ² is large (TIAGo's identified
28.1 rad²/s³ at σ = 5.2e-6 rad, 100 Hz: about 1e6) the DARE's poles are two distinct negative
reals, ``t < −2√d``: no ``(α, β)`` has that gain.  The rule then takes the reachable gain
nearest it: the same ``k₁`` (the same ``α``, the same pole product ``d``), the largest ``k₂``
the form reaches — the two poles moved along the negative axis to their geometric mean
``−√d``::

    α = −ln(1 − k₁) / (2h),     β = α² + (π/h)²     (clipped: ``SteadyGains.clipped``)

Continuous with the unclipped rule at the boundary (``θ → π``); it exists for every ψ > 0
(``1 − k₁ = σ²/(P⁻₀₀ + σ²)`` computed as such, never rounded to 0).  The riemannian observer's
default Riccati schedule runs the Kalman gains themselves, clipped or not; the clipped
``(α, β)`` are run by ``gain_schedule="steady"`` (which then warns), by the continuous
:meth:`~pinobs.observers.riemannian.RiemannianObserver.vector_field` and reported.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pinobs.errors import GainError, PinobsWarning
from pinobs.observers.checks import positive
from pinobs.observers.gain_cache import solve_discrete_are

__all__ = [
    "DEFAULT_ALPHA",
    "DEFAULT_BETA",
    "GainFunction",
    "RiemannianGains",
    "SteadyGains",
    "anisi_hamberg_curvature_gain",
    "check_schedule",
    "checked_gain",
    "clipped_message",
    "discrete_gains",
    "gains_from_noise",
    "steady_gains",
    "warn_clipped",
]

#: ``(S, speed) -> gain``: ``S = ½ dist(q̂, q)²`` [kg·m²·rad², the metric's units],
#: ``speed = |v̂|_g`` [√(kg·m²)·rad/s].  Anisi–Hamberg's state-dependent gains.
GainFunction = Callable[[float, float], float]

DEFAULT_ALPHA = 60.0  # [1/s]
DEFAULT_BETA = 900.0  # [1/s²]


@dataclass(frozen=True)
class RiemannianGains:
    """Validated gains of :class:`~pinobs.observers.riemannian.RiemannianObserver`.

    Attributes:
        alpha: position gain α [1/s] (``A = 2α``), > 0.
        beta: velocity gain β [1/s²] (``B``), > 0.
        curvature_gain: ``C`` (dimensionless, any finite number; −1 cancels the
            curvature in the linearised error dynamics, :mod:`pinobs.observers.riemannian`'s
            module docstring).
        gain_a, gain_b, gain_c: optional Anisi–Hamberg gains ``A(S, speed)``
            [1/s], ``B(S, speed)`` [1/s²], ``C(S, speed)``; when given they
            replace ``2α``, ``β``, ``curvature_gain``.
    """

    alpha: float
    beta: float
    curvature_gain: float = -1.0
    gain_a: GainFunction | None = None
    gain_b: GainFunction | None = None
    gain_c: GainFunction | None = None

    def __post_init__(self) -> None:
        positive("alpha", self.alpha)
        positive("beta", self.beta)
        c = self.curvature_gain
        if not isinstance(c, (int, float)) or not math.isfinite(c):
            raise GainError(f"curvature_gain={c!r} is not a finite number")
        for label in ("gain_a", "gain_b", "gain_c"):
            fn = getattr(self, label)
            if fn is not None and not callable(fn):
                raise GainError(
                    f"{label}={fn!r} is not callable; give a function (S, speed) -> gain"
                )

    @property
    def state_dependent(self) -> bool:
        """True when some gain is a function of the state."""
        return not (self.gain_a is None and self.gain_b is None and self.gain_c is None)

    def at(self, s: float, speed: float) -> tuple[float, float, float]:
        """``(α, β, C)`` at ``S`` and ``|v̂|_g``.

        Raises:
            GainError: a gain function returned a non-finite value, or ``A, B ≤ 0``.
        """
        alpha, beta, c = self.alpha, self.beta, self.curvature_gain
        if self.gain_a is not None:
            alpha = 0.5 * checked_gain(
                "gain_a", self.gain_a(s, speed), s, speed, positive_only=True
            )
        if self.gain_b is not None:
            beta = checked_gain("gain_b", self.gain_b(s, speed), s, speed, positive_only=True)
        if self.gain_c is not None:
            c = checked_gain("gain_c", self.gain_c(s, speed), s, speed, positive_only=False)
        return alpha, beta, c


def check_schedule(curvature_every: int, *gains: GainFunction | None) -> None:
    """Refuse a ``curvature_every`` that is not an integer ≥ 1, or a gain function
    (``gain_a``, ``gain_b``, ``gain_c``) that is not callable."""
    if (
        isinstance(curvature_every, bool)
        or not isinstance(curvature_every, int)
        or curvature_every < 1
    ):
        raise GainError(f"curvature_every={curvature_every!r}; give an integer >= 1")
    for label, fn in zip(("gain_a", "gain_b", "gain_c"), gains, strict=True):
        if fn is not None and not callable(fn):
            raise GainError(f"{label}={fn!r} is not callable; give a function (S, speed) -> gain")


def checked_gain(label: str, value: float, s: float, speed: float, *, positive_only: bool) -> float:
    x = float(value)
    if not math.isfinite(x) or (positive_only and x <= 0.0):
        bound = "finite and > 0" if positive_only else "finite"
        raise GainError(f"{label}(S={s:.3g}, speed={speed:.3g}) = {value!r}; it must be {bound}")
    return x


def anisi_hamberg_curvature_gain(kappa: float) -> GainFunction:
    """Anisi–Hamberg §4.4: ``C(S) = −2κ⁻¹Υ(S)``, ``Υ(S) = κ tan(½√(2κS)) / √(2κS)``.

    For a space of constant sectional curvature ``kappa`` (≠ 0) [1/(metric
    units)]; ``C → −1`` as ``S → 0``; κ < 0 uses the analytic continuation
    (``tanh``).  Valid while ``√(2κS) < π`` (the cut locus).
    """
    k = float(kappa)
    if not math.isfinite(k) or k == 0.0:
        raise GainError(f"kappa={kappa!r}: give a finite nonzero curvature")

    def gain(s: float, speed: float) -> float:
        r = math.sqrt(2.0 * abs(k) * max(s, 0.0))
        if r < 1e-4:
            ratio = 0.5 + (r * r / 24.0 if k > 0 else -r * r / 24.0)  # tan(r/2)/r
        else:
            ratio = math.tan(0.5 * r) / r if k > 0 else math.tanh(0.5 * r) / r
        return -2.0 * ratio  # −2κ⁻¹ · κ·ratio

    return gain


class SteadyGains(NamedTuple):
    """The gain rule's result (module docstring).

    Attributes:
        alpha: α [1/s].
        beta: β [1/s²].
        kalman: the steady-state Kalman gain ``(k₁, k₂)`` at ``h = 1/rate`` (``k₂`` [1/s]).
        clipped: True when the Kalman gain's error poles are out of the paper form's reach
            and ``(alpha, beta)`` are the nearest reachable gains (``discrete_gains(alpha,
            beta, h)`` then has ``kalman``'s ``k₁`` and a smaller ``k₂``).
        rate, noise_std, accel_psd: the rule's rate [Hz], σ [rad or m] and ψ [rad²/s³].
    """

    alpha: float
    beta: float
    kalman: tuple[float, float]
    clipped: bool
    rate: float
    noise_std: float
    accel_psd: float


def discrete_gains(alpha: float, beta: float, h: float) -> tuple[float, float]:
    """``(k₁, k₂)``: correction gains whose discrete error poles are ``e^{s_i h}`` (module docstring).

    ``alpha`` [1/s], ``beta`` [1/s²], ``h`` [s].  ``k₁`` is dimensionless,
    ``k₂`` [1/s].
    """
    a = math.exp(-2.0 * alpha * h)
    disc = alpha * alpha - beta
    if disc >= 0.0:
        r = math.sqrt(disc) * h
        trace = math.exp(-alpha * h + r) + math.exp(-alpha * h - r)
    else:
        trace = 2.0 * math.exp(-alpha * h) * math.cos(math.sqrt(-disc) * h)
    return 1.0 - a, (1.0 + a - trace) / h


def steady_gains(rate: float, noise_std: float, accel_psd: float) -> SteadyGains:
    """``(α, β)`` of the steady-state Kalman gain of the error dynamics, clipped to the paper
    form's reach when it is out of it (module docstring).

    Per tangent direction: ``x = (ζ, ε)``, ``x⁺ = [[1, h], [0, 1]] x + w``,
    ``E[wwᵀ] = accel_psd·[[h³/3, h²/2], [h²/2, h]]``, measured ``ζ + n``,
    ``E[n²] = noise_std²``, ``h = 1/rate``.

    Args:
        rate: sample rate [Hz].
        noise_std: position noise standard deviation [rad or m], > 0.
        accel_psd: white-acceleration density [rad²/s³], > 0.
    """
    h = 1.0 / rate
    F = np.array([[1.0, h], [0.0, 1.0]])
    Q = accel_psd * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]])
    Hm = np.array([[1.0, 0.0]])
    r2 = noise_std**2
    P = solve_discrete_are(F.T, Hm.T, Q, np.array([[r2]]))  # (cached: gain_cache)
    K = P[:, 0] / (P[0, 0] + r2)  # gain on the predicted error
    kalman = (float(K[0]), float(K[1]))
    closed = (np.eye(2) - np.outer(K, [1.0, 0.0])) @ F
    lam = np.linalg.eigvals(closed).astype(complex)
    if np.any((np.abs(lam.imag) <= 1e-12 * np.abs(lam)) & (lam.real <= 0.0)):
        # negative real poles: the same k₁, the double pole −√(1 − k₁) (module docstring)
        alpha = -0.5 * math.log(r2 / (P[0, 0] + r2)) / h  # 1 − k₁ = σ²/(P⁻₀₀ + σ²)
        beta = alpha * alpha + (math.pi / h) ** 2
        return SteadyGains(alpha, beta, kalman, True, rate, noise_std, accel_psd)
    s = np.log(lam) / h
    alpha = -0.5 * float(np.real(s[0] + s[1]))
    beta = float(np.real(s[0] * s[1]))
    return SteadyGains(alpha, beta, kalman, False, rate, noise_std, accel_psd)


def gains_from_noise(rate: float, noise_std: float, accel_psd: float) -> tuple[float, float]:
    """``(α, β)`` of :func:`steady_gains`: the steady-state Kalman gain's, or the nearest the
    paper form reaches (module docstring).  ``rate`` [Hz], ``noise_std`` [rad or m],
    ``accel_psd`` [rad²/s³]."""
    rule = steady_gains(rate, noise_std, accel_psd)
    return rule.alpha, rule.beta


def clipped_message(rule: SteadyGains) -> str:
    """What the observer says when it runs clipped steady gains."""
    rate = rule.rate
    h = 1.0 / rate
    k1, k2 = rule.kalman
    run = discrete_gains(rule.alpha, rule.beta, h)[1]
    return (
        f"riemannian: accel_psd={rule.accel_psd:.3g} with noise_std={rule.noise_std:.3g} at "
        f"{rate:.4g} Hz asks for a Kalman gain (k1={k1:.6g}, k2={k2:.6g} /s) whose error poles "
        "lie on the negative real axis, out of (alpha, beta)'s reach: the steady gains are the "
        f"nearest it reaches, the same k1 and k2={run:.6g} /s (alpha={rule.alpha:.4g}, "
        f"beta={rule.beta:.4g}); gain_schedule='riccati' (the default) runs the Kalman gains"
    )


#: The package's directory: frames there are pinobs's own, not the user's (:func:`warn_clipped`).
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep


def warn_clipped(rule: SteadyGains) -> None:
    """Warn (:class:`~pinobs.errors.PinobsWarning`, :func:`clipped_message`) at the user's
    call: the first frame outside the package (``make_observer``'s caller, or the caller of
    the observer's class; the warning's ``stacklevel`` counted, not fixed)."""
    frame, level = sys._getframe(1), 2  # (level 1: this function)
    while frame.f_back is not None and frame.f_code.co_filename.startswith(_PACKAGE):
        frame, level = frame.f_back, level + 1
    warnings.warn(PinobsWarning(clipped_message(rule)), stacklevel=level)
