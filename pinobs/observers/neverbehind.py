"""Never behind a model-free filter: a model-based observer blended per joint with ``kf``.

Two shared pieces (issue 36, item 2), used by every model-based family:

1. **The blend** (:class:`NeverBehind`, ``make_observer(name, robot, never_behind=True)``):
   the family's observer and a model-free :class:`~pinobs.observers.kf.ConstantAccelerationKF`
   run side by side on the same samples (composition: the wrapper holds both observers
   and their states, and steps each through its own family interface).  Each is scored
   per coordinate by its one-step prediction of the next sample: with ``(q̂ᵢ, v̂ᵢ)`` its
   estimate at ``t_k`` and ``â`` the blend's acceleration (finite difference of its last
   two velocities, common to both),

       eᵢ = difference(q̂ᵢ ⊕ (h v̂ᵢ + ½ h² â), q_{k+1}),    sᵢ ← sᵢ + (h/T)(eᵢ² − sᵢ),

   (``T`` = ``window``; a sample the ``kf``'s outlier gate rejects is not scored, nor the
   next one (**Gated**); one the model-based observer's gate rejects is: a lost model
   rejects the samples).
   The measurement noise ``n_{k+1}`` enters both ``eᵢ`` alike and is independent of both
   predictions (made before it), so the difference of the scores measures the difference
   of the predictors' errors, not the noise.  The weights are the posterior probabilities
   of the two predictors given the window's innovations, Gaussian with a common variance
   ``S = max(min(s_m, s_kf), σ²)`` (the multiple-model weights of Magill 1965; Bar-Shalom,
   Li & Kirubarajan 2001, §11.6.2, with a forgetting window instead of a growing one):

       ℓ = κ (N/2) (s_kf − s_m) / S,    N = T/h,    w = 1 / (1 + e^{−ℓ}),

   (the scores are exponential means started at zero: until the window has filled,
   ``sᵢ`` is divided by the weight gathered so far, ``c = 1 − (1 − h/T)^k``, and ``N`` is
   ``c T/h``; the log-odds start from a prior ``ℓ₀ = 50`` for the model that fades as the
   window fills to the persistent prior ``ℓ_p``, ``ℓ += ℓ_p + (1 − c)(ℓ₀ − ℓ_p)``: the
   model is trusted until the data disagree).
   **Prior.**  ``ℓ_p`` is the prior log-odds of the model against the ``kf``: the
   posterior log-odds are the prior's plus the window's log-likelihood ratio (Bayes' rule;
   the prior probabilities ``μⱼ(0)`` of Bar-Shalom, Li & Kirubarajan 2001, §11.6.2),
   ``w ≥ 1/(1 + e^{−ℓ_p − ℓ_data})``.  On an exact model the one-step data are weak: the
   predictions differ by ``h δv``, far below the noise (UR5, 1 kHz, σ = 1e-3 rad, seed 5:
   0.035 nats a sample, ~7 a window, standard deviation ~3.7; ``ℓ`` wandered to −0.6,
   ``w`` = 0.36, where the ``kf``'s velocity is 440× worse: the blend 4.0× ``ekf`` alone,
   still far below the ``kf``).  A fixed prior of 5 holds the weight there (every one of
   ``benchmarks/never_behind_exact.py``'s 120 exact ``ekf`` runs within 1.004×, against up
   to 4.2× without), but a model whose positions predict nearly as well as the ``kf``'s
   while its velocities are worse gives data log-odds of only a few nats against it, which
   such a prior outweighs: ``ekf`` with the learned disturbance blended on the identified
   UR10e model (``benchmarks/real_logs.py``) went from 0.93–1.1× the ``kf`` to 0.98–1.24×
   (behind it).  So by default (``prior_log_odds="consistent"``) the model earns the prior
   by its own consistency, the time-average NIS test (Bar-Shalom, Li & Kirubarajan 2001,
   §5.4.2) over the window::

       ν̄ ← ν̄ + λ (min(εₖ/m, 100) − ν̄),   ν̄₀ = 1,   λ = min(1, h/T),
       ℓ_p = TRUSTED_PRIOR  if  χ²_n(α)/n ≤ ν̄ ≤ χ²_n(1 − α)/n  [and ψᵢ h²/20 ≤ q_a/3 ∀i]
                                 {and P_m,vv,ii ≤ P_kf,vv,ii ∀i},
       ℓ_p = 0              otherwise,

   ``εₖ`` the model-based observer's NIS over ``m`` = ``nv`` coordinates, ``n = m (2 − λ)/λ``
   (an exponential mean of ``χ²_m / m`` samples has the variance of ``χ²_n / n``: the
   window's equivalent count ``(2 − λ)/λ``), ``α`` = :data:`CONSISTENCY_ALPHA` (Wilson–Hilferty
   quantiles, :func:`~pinobs.observers.gating.chi2_quantile`); the bracket for ``ekf``'s
   ``disturbance_psd="auto"`` only: the learned random-walk disturbance adds less to the
   one-step prediction variance (``ψ h⁵/20``, ``ψ`` per unit inertia) than the white
   acceleration the filter already carries (``q_a h³/3``, ``accel_psd``): the model error it
   learned is within the noise it assumes; the braces for a family that keeps an error
   covariance (``ekf``, ``kalman``): the velocity variance it claims (``P_m,vv``, the ``δv``
   block's diagonal, :func:`model_velocity_variance`) at most the ``kf``'s own
   (:func:`kf_velocity_variance`, its mixture's); ``riemannian`` under its Riccati gain
   schedule claims its schedule's ``P₁₁`` in every tangent direction (the double integrator
   its gains come from, with its ``accel_psd`` and σ: module docstring of
   :mod:`pinobs.observers.riemannian`), at most the ``kf``'s smallest.  The NIS test says the model's covariance
   describes its errors, not that they are small: of two estimators whose covariances
   describe their errors, the one with the smaller variance is the better under squared
   loss, so a model consistent only because it claims large errors earns no prior.
   Measured (``benchmarks/never_behind_weights.md``): the identified UR10e model, which
   carries its identification's error density as ``accel_psd``, passed the NIS test on
   38–83 % of the steps of the 40–50 s logs while claiming 11–16× the ``kf``'s velocity
   variance; with the prior its weight flipped between ~0 and ~1 (mean 0.08–0.17,
   ``E[w²]`` 0.05–0.12), uncorrelated with which velocity was better, and ``ekf+nb+id``
   was 1.007–1.063× the ``kf`` on 15 of 19 UR10e logs; without it 0.94–1.00× on 18 (the
   19th 1.008×: one sample at a stop).  An exact ``ekf`` claims ~1e-3 of the ``kf``'s
   after ~10 samples: its runs are unchanged bit for bit.  Measured before the braces
   (``benchmarks/never_behind_exact.md``,
   "Common-position velocity score", helper branch ``nbvel``): an exact ``ekf``'s windowed
   NIS/m is 1.00–1.08 (its learned density 1e-9 to 3e-6 rad²/s⁵), the identified UR10e
   model's 1e3–1e5 (with ``auto`` its density 3–100): the 120 exact ``ekf`` runs within
   1.004× of ``ekf`` alone, no re-seed; the mismatch rows of ``never_behind_sim.py`` and
   every real UR10e cell of ``never_behind_real.py`` as with ``ℓ_p`` = 0 (one
   ``ekf+auto+nb@id`` cell +3e-4 relative).  ``riemannian`` and ``kalman`` on an exact Panda
   are not consistent (NIS/m 1.2–4.5: their ``S`` does not describe their errors) and keep
   ``ℓ_p`` = 0 and its losses (up to 8.7× alone); on the UR5, where they are, they gain
   (100 Hz, σ = 1e-4: 2.4 → 1.00×).  A number (``prior_log_odds=x`` in ``[0, 50]``) fixes
   ``ℓ_p``: 0 is the data alone, as before this test (:data:`PRIOR`), and
   :data:`TRUSTED_PRIOR` a model you trust whatever its NIS.  A wrong model gives data
   log-odds of hundreds against it and is re-seeded whatever the prior (mismatch runs of
   ``never_behind_sim.py`` 1.00× the ``kf`` with 0, 5 and 10).
   **Irregular steps.**  The log-likelihood ratio counts each innovation once, decayed by
   its age: ``ℓ = κ Σⱼ Dⱼ (e²_kf,j − e²_m,j) / (2S)``, ``Dⱼ = Π_{i>j} (1 − hᵢ/T)``.  On a
   regular grid that is the form above (``sᵢ = Σⱼ (h/T) Dⱼ e²ᵢ,ⱼ``, so the sum is
   ``(T/h)(s_kf − s_m)``); on an irregular one ``(N/2)(s_kf − s_m)`` weighs sample ``j`` by
   ``hⱼ/h_k`` and rescales the whole window by the current step (a step of ``h/2`` doubles
   ``ℓ``, one of ``2h`` halves it).  So the count-decayed sum is kept,
   ``d ← (1 − h/T) d + (e²_kf − e²_m)``, and a step more than ``UNIFORM_TOL`` (10 %) off the
   sample period takes ``ℓ = κ c d / (2 max(min(s_m, s_kf), c σ²))`` instead (a step on the
   grid keeps the form above, to the bit).  Measured on an exact-model UR5 log stamped at
   intervals uniform in 0.5–1.5 ms (PD input, σ = 1e-4 rad, seed 2): the blend 3.5× ``ekf``
   alone (9.9e-5 against 2.8e-5 rad/s, weights down to 0.22), with ``d`` 1.43× (4.0e-5; the
   same log on a regular 1 ms grid: 1.27×, 3.6e-5: what the one-step scores can tell).
   **Gated.**  A sample the ``kf`` rejects leaves it at its prediction, so at the next
   sample its error is a two-step prediction's while the model's, corrected by the rejected
   sample, is a one-step one: not the same predictor, and never to the ``kf``'s credit.  That
   sample is not scored either (the far gate still reads it).  Measured on the UR10e log
   ``ur-19_10_01-13_51_41`` (``ekf`` with ``auto`` on the identified model,
   ``benchmarks/never_behind_gated.py``): the robot stops at t = 5.66 s; the ``kf`` rejects
   that sample, the ``ekf`` does not (NIS 222) and at the next its elbow velocity is
   0.193 rad/s (the robot's −0.014).  Scored, the ``kf``'s two-step error (1.07e-3 rad
   against the model's 0.71e-3) took ``ℓ`` from 1.2 to 9.8 on the elbow (``w`` ≥ 0.9998 on
   all six joints) and ``s_kf`` out of the far gate's reach (``h |v̂_m − v̂_kf|`` = 2.05e-3
   < 10 √(6.7e-8) = 2.6e-3 rad): that one sample made the blend 1.17× the ``kf`` over the
   log (elbow 0.0111 against 0.0074 rad/s).  Unscored, the far gate (10 √(1.0e-8) =
   1.0e-3) re-seeds the model there: 0.97× (elbow 0.0070).

   ``κ`` (``sharpness``) scales the count ``N`` of innovations in the window (before any
   sample is scored the model is trusted, ``w = 1``); and the output

       v̂ = w v̂_m + (1 − w) v̂_kf,    q̂ = q̂_kf ⊕ w · difference(q̂_kf, q̂_m).

   With an exact model the model-based predictor wins every window (``w → 1``: its
   accuracy is kept); with a useless one the ``kf`` wins (``w → 0``: the tuned
   model-free accuracy).  **Lost**: when the model-based estimate stops being finite, its
   step raises, or its score exceeds ``lost_ratio²`` times the ``kf``'s on some joint, it
   is re-seeded from the blend (its family's initial state at the ``kf``'s ``(q̂, v̂)`` of
   that sample, the blend's with ``w = 0``; its score set to ``lost_ratio`` times the
   ``kf``'s, so its weight stays near zero until its predictions have beaten the
   ``kf``'s over a window) and :attr:`NeverBehind.reseeds` counts it.  It is lost too when
   its velocity jumps away from the ``kf``'s by more than ``FAR_GATE`` = 10 times the
   ``kf``'s own RMS one-step error as a velocity, ``h |v̂_m − v̂_kf| > 10 √s_kf``, once the
   window has gathered half its weight (``c > ½``, as the ratio test: at the first sample
   ``√(s_kf/c)`` is one innovation, ``|q₁ − q₀|``, near zero on a joint at rest, and the
   gate re-seeded an exact Panda at 100 Hz, σ = 1e-3, seed 7: ``w`` ≈ 0 for ~1 s, 8.1×): the
   windowed scores lag such a jump (on a UR10e log an ``ekf+auto`` 1.7 rad/s RMS off in
   bursts kept a mean weight 0.1–0.27 and made the blend 1.2× the ``kf``).  Where ``ℓ``
   reaches its bound ``−50``, ``w = 0`` exactly: a model 1e20 rad/s off cannot leak
   through ``w = 2e-22``.  The arithmetic between the two observers' steps is compiled
   (numba: :func:`score_loops`, :func:`log_odds_loops`, :func:`weigh_loops`; Pinocchio's
   ``integrate``/``difference`` on Lie-group joints, NumPy's ``exp``, whose last bit
   numba's ``exp`` does not always give) and equals the NumPy form bit for bit.

2. **The disturbance density learned from the innovations** (:func:`match_density`,
   ``ekf``'s ``disturbance_psd="auto"``): a per-joint random-walk density ``ψᵢ``
   matched to the innovations, covariance matching (Mehra 1972 §IV; Myers & Tapley
   1976: the innovations of a filter whose noise densities are right have the
   covariance it predicts, ``E[e eᵀ] = S``) done joint by joint, in the log domain and
   at every sample:

       log ψᵢ ← log ψᵢ + (h/T) (clip(log(eᵢ² / Sᵢᵢ), −8, 5) − m),

   a stochastic approximation (Robbins & Monro 1951) whose fixed point is
   ``E[clip(log(eᵢ²/Sᵢᵢ))] = m``, ``m`` the mean of the clipped ``log χ²₁``
   (−1.24; −(γ + log 2) = −1.27 unclipped): ``eᵢ ~ N(0, Sᵢᵢ)``.
   ψ grows while the model under-predicts the innovations (model error it does not
   carry) and shrinks while the filter over-predicts them.  Per sample rather than
   from a windowed ratio: a windowed ratio lags the density it steers, and on a UR5
   with a payload it wound up to the density's bound (velocity RMS 0.12 rad/s against
   0.0093 per sample).  Tried and dropped: the innovations' lag-one correlation
   (Mehra 1970), whose target, white innovations, a motion-dependent model error never
   gives (it drove the density up to 7e5 rad²/s⁵, 0.17 rad/s).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any, NamedTuple, cast

import numpy as np

from pinobs.errors import GainError, ObserverDiverged, OptionError
from pinobs.model import Robot
from pinobs.model.sampling import UNIFORM_TOL
from pinobs.observers.base import Observer, Vector, observer_class, positive
from pinobs.observers.gating import chi2_quantile
from pinobs.observers.kf_bank import AutoState
from pinobs.observers.kf_kernels import auto_layout
from pinobs.observers.linalg import LazyKernel

__all__ = ["CONSISTENT", "NeverBehind", "match_density"]

#: The bounds of one sample's ``log(e²/S)`` in :func:`match_density` (an outlier moves ψ by at
#: most ``e^{5h/T}``; an innovation of zero by ``e^{−8h/T}``).
LOG_BOUNDS = (-8.0, 5.0)


def clipped_log_chi2_mean(lo: float, hi: float) -> float:
    """``E[clip(log u, lo, hi)]`` for ``u ~ χ²₁`` (``−(γ + log 2) = −1.2704`` unclipped): the
    density of ``y = log u`` is ``exp(y/2 − eʸ/2)/√(2π)``, integrated by the trapezoid rule."""
    y = np.linspace(-60.0, 8.0, 200001)
    f = np.exp(0.5 * y - 0.5 * np.exp(y)) / np.sqrt(2.0 * np.pi)
    return float(np.trapezoid(np.clip(y, lo, hi) * f, y) / np.trapezoid(f, y))


#: The mean the clipped ``log(e²/S)`` has when ``e ~ N(0, S)``: the fixed point,
#: ``clipped_log_chi2_mean(*LOG_BOUNDS)`` written out (its 200 001-point integral cost 5–9 ms
#: of every ``make_observer`` at import: issue 39; the test recomputes it).
LOG_CHI2_MEAN = -1.241135859180433


def match_density(
    psd: Vector,
    e: Vector,
    s: Vector,
    dt: float,
    *,
    window: float,
    bounds: Vector,
    weight: Vector | float = 1.0,
) -> Vector:
    """One step of module docstring item 2: the densities ``ψ`` updated.

    Args:
        psd: the densities ``ψ`` per coordinate (any unit; returned in it).
        e: this sample's innovation per coordinate.
        s: its predicted variance per coordinate (``Sᵢᵢ``), > 0.
        dt: the step [s].
        window: ``T`` [s], the time constant of ``log ψ``.
        bounds: ``(2, n)`` or ``(2,)``: ``ψ_min``, ``ψ_max``.
        weight: per coordinate, a factor in [0, 1] on the step ``h/T`` (1, default: the
            step above, to the bit; the invariant EKF's ``adapt_noise`` gives the share of
            ``Sᵢᵢ`` that ``ψ`` sets: :mod:`pinobs.observers.legged_adapt`).
    """
    lam = min(1.0, dt / window) * weight
    with np.errstate(divide="ignore"):  # e = 0: log 0 = −∞, clipped
        step = np.clip(np.log(e * e / s), *LOG_BOUNDS) - LOG_CHI2_MEAN
    return np.clip(psd * np.exp(lam * step), bounds[0], bounds[1])  # type: ignore[no-any-return]


#: Bound of the blend's log-odds ``ℓ`` (``1 − w`` or ``w`` ≥ 2e-22) and its prior (docstring).
_LOG_ODDS = 50.0
_TINY = 1e-300  # the smallest score the log-odds divide by
#: A model-based velocity this many kf one-step errors (as velocities) from the kf's is lost.
FAR_GATE = 10.0
#: The persistent prior log-odds ``ℓ_p`` of a model that has not earned it: the data alone
#: decide (module docstring: **Prior**).
PRIOR = 0.0
#: ``ℓ_p`` for a model you trust (an exact or calibrated one), and the one a consistent model
#: earns by default (module docstring: **Prior**).
TRUSTED_PRIOR = 5.0
#: ``prior_log_odds``'s default: ``ℓ_p`` from the model's own NIS test (module docstring).
CONSISTENT = "consistent"
#: The time-average NIS test's level ``α`` on each side (module docstring: **Prior**).
CONSISTENCY_ALPHA = 1e-3
#: The largest ``εₖ/m`` one sample brings into ``ν̄`` (an outlier's NIS of 1e300 would hold
#: ``ν̄`` out of the band for minutes; 100 is out of it for about a window).
NIS_CAP = 100.0


@functools.lru_cache(maxsize=64)
def nis_band(m: int, lam: float) -> tuple[float, float]:
    """The time-average NIS test's two-sided band for ``ν̄`` (module docstring, **Prior**):
    ``χ²_n(α)/n``, ``χ²_n(1 − α)/n``, ``n = m (2 − λ)/λ``, ``α`` = :data:`CONSISTENCY_ALPHA`
    (computed once per ``(m, λ)``: a step's length, not the observer's state)."""
    n = max(1, round(m * (2.0 - lam) / lam))
    alpha = CONSISTENCY_ALPHA
    return chi2_quantile(n, 1.0 - alpha) / n, chi2_quantile(n, alpha) / n


def kf_velocity_variance_loops(x: Vector, nf: int, nq: int, nv: int, n: float, out: Vector) -> None:
    """The ``kf``'s own velocity error variance per joint into ``out`` (module docstring,
    **Prior**; compiled by numba), from its ``jerk_psd="auto"`` buffer ``x``
    (:func:`~pinobs.observers.kf_kernels.auto_layout`): the mixture's

        Pᵥᵢ = Σ_f w_fi (ĉ_fi P_f,vv + (v̂_fi − v̂ᵢ)²),   ĉ_fi = A_fi / N,   v̂ᵢ = Σ_f w_fi v̂_fi,

    each filter's covariance (computed for σ₀²) scaled by its profiled noise scale ``ĉ``
    (:mod:`pinobs.observers.kf`), plus the spread of the filters' velocities about the
    mixture's (the covariance of a Gaussian mixture)."""
    o_v = nf * nq
    o_A = o_v + 2 * nf * nv
    o_w = o_A + nf * nv
    o_P = o_w + 2 * nf * nv
    for i in range(nv):
        vbar = 0.0
        for f in range(nf):
            vbar += x[o_w + f * nv + i] * x[o_v + f * nv + i]
        acc = 0.0
        for f in range(nf):
            c = x[o_A + f * nv + i] / n
            if c < _TINY:
                c = _TINY
            dv = x[o_v + f * nv + i] - vbar
            acc += x[o_w + f * nv + i] * (c * x[o_P + 9 * f + 4] + dv * dv)
        out[i] = acc


def claim_within_loops(
    x: Vector, nf: int, nq: int, nv: int, n: float, P: Vector, out: Vector
) -> bool:
    """Whether every velocity variance the model claims, ``P[nv + i, nv + i]``, is at most
    the ``kf``'s own (:func:`kf_velocity_variance_loops`, into ``out``; compiled by numba:
    one call a step while the NIS test passes)."""
    kf_velocity_variance_loops(x, nf, nq, nv, n, out)
    for i in range(nv):
        if not P[nv + i, nv + i] <= out[i]:
            return False
    return True


def claims_within_kf(m: Any, kf: Any, nv: int) -> bool:
    """The prior's velocity clause (module docstring, **Prior**): ``P_m,vv,ii ≤ P_kf,vv,ii``
    for every coordinate, the model's :func:`model_velocity_variance` against the ``kf``'s
    :func:`kf_velocity_variance`; true for a family that keeps no covariance and before the
    ``kf``'s first measured sample (nothing to compare: the NIS test alone)."""
    P = getattr(m, "P", None)
    if isinstance(P, tuple) and len(P) == 3:  # riemannian's schedule (P₀₀, P₀₁, P₁₁)
        kf_vv = kf_velocity_variance(kf)
        return kf_vv is None or bool(P[2] <= kf_vv.min())
    if not isinstance(P, np.ndarray) or P.ndim != 2 or P.shape[0] < 2 * nv:
        return True
    if isinstance(kf, AutoState):
        if kf.n <= 0.0:
            return True
        nf, nq, _ = kf.shape
        claim = cast(_Kernel, claim_kernel.compiled)
        return bool(claim(kf.x, nf, nq, nv, kf.n, P, np.empty(nv)))
    return bool(np.all(np.diagonal(P)[nv : 2 * nv] <= kf.P[1, 1]))


def kf_velocity_variance(state: Any) -> Vector | None:
    """The ``kf``'s own velocity error variance per coordinate [(rad/s)²] (module docstring,
    **Prior**): ``P_vv`` of a fixed density (shared by every direction), the mixture's of
    ``jerk_psd="auto"`` (:func:`kf_velocity_variance_loops`); ``None`` before the auto bank's
    first measured sample (no scale yet)."""
    if isinstance(state, AutoState):
        nf, nq, nv = state.shape
        if state.n <= 0.0:
            return None
        out = np.empty(nv)
        kf_variance_kernel.load()  # (loaded by the blend's constructor; tests call it bare)
        cast(_Kernel, kf_variance_kernel.compiled)(state.x, nf, nq, nv, state.n, out)
        return out
    return np.full(state.v.shape[0], state.P[1, 1])


def model_velocity_variance(state: Any, nv: int) -> Vector | None:
    """The model-based observer's own velocity error variance per coordinate: the ``δv``
    block's diagonal of its error covariance ``P`` (``(δq, δv)`` or ``(δq, δv, δd)``:
    ``ekf``, ``kalman``), ``None`` for a family that keeps none (``riemannian``, ``ii``,
    ``adaptive``'s own state)."""
    P = getattr(state, "P", None)
    if not isinstance(P, np.ndarray) or P.ndim != 2 or P.shape[0] < 2 * nv:
        return None
    return cast(Vector, np.diagonal(P)[nv : 2 * nv])


def log_odds_loops(
    c: float,
    dt: float,
    window: float,
    sharpness: float,
    nvar: float,
    prior: float,
    out: Vector,
    fair: bool,
) -> None:
    """``out[2] = −ℓ`` per coordinate from the scores ``out[0:2]`` (model, kf) and the weight
    ``c`` the window has gathered (module docstring, item 1; compiled by numba):

        ℓ = clip(κ (N/2)(s_kf − s_m) / max(min(s_m, s_kf), max(c σ², 10⁻³⁰⁰)) + ℓ_p
                 + (1 − c)(ℓ₀ − ℓ_p), ±ℓ₀),

    ``N = c T/h`` (the scores are sums ``c`` times their means); ``fair`` (a step off the
    grid: **Irregular steps**) ``c d`` for ``N (s_kf − s_m)``, ``d = out[7]``; ``ℓ_p`` =
    ``prior``; NaN kept as NumPy keeps it."""
    floor = c * nvar
    if _TINY > floor:
        floor = _TINY
    k = sharpness * 0.5 * (c * window / dt)
    start = prior + (1.0 - c) * (_LOG_ODDS - prior)  # ℓ_p + (1 − c)(ℓ₀ − ℓ_p)
    for i in range(out.shape[1]):
        s_m, s_k = out[0, i], out[1, i]
        low = s_m if s_m <= s_k else (s_k if s_k < s_m else s_m + s_k)  # np.minimum (NaN: NaN)
        den = low if low >= floor else (floor if floor > low else low + floor)  # np.maximum
        # Bar-Shalom, Li & Kirubarajan 2001 §11.6.2 (each innovation counted once if fair)
        ell = (sharpness * 0.5 * c * out[7, i] if fair else k * (s_k - s_m)) / den + start
        if ell < -_LOG_ODDS:
            ell = -_LOG_ODDS
        elif ell > _LOG_ODDS:
            ell = _LOG_ODDS
        out[2, i] = -ell


def score_loops(  # noqa: C901 -- numba kernel: its branches are loops over small vectors
    flat: bool,
    scored: bool,
    measured: bool,
    raised: bool,
    q_meas: Vector,
    qm0: Vector,
    vm0: Vector,
    qk0: Vector,
    vk0: Vector,
    v: Vector,
    v_prev: Vector,
    dt: float,
    dt_prev: float,
    q_m: Vector,
    v_m: Vector,
    v_kf: Vector,
    s: Vector,
    d: Vector,
    fair: bool,
    c: float,
    window: float,
    lost_ratio2: float,
    sharpness: float,
    nvar: float,
    prior: float,
    out: Vector,
) -> tuple[float, bool]:
    """:meth:`NeverBehind.step`'s arithmetic up to the weights (module docstring, item 1;
    compiled by numba): lost if ``raised`` or ``(q_m, v_m)`` sums to a non-finite value;
    if ``scored`` (and not lost) the one-step errors (``flat``: here,
    ``eᵢ = q_{k+1} − (q̂ᵢ + h v̂ᵢ + ½ h² â)``, else given in ``out[5:7]``), the scores
    ``sᵢ ← sᵢ + λ(eᵢ² − sᵢ)`` into ``out[0:2]``, ``d ← (1 − λ) d + e²_kf − e²_m`` into
    ``out[7]`` (``d`` itself if not scored), ``c ← c + λ(1 − c)``, ``λ = min(1, h/T)``,
    lost if ``s_m > lost_ratio² s_kf`` somewhere once ``c > ½``; if ``measured``, lost if
    ``h |v̂_m − v̂_kf| > FAR_GATE √(s_kf / c)`` somewhere once ``c > ½``; if not lost and ``c > 0``,
    :func:`log_odds_loops`.  Returns ``(c, lost)``."""
    nv = out.shape[1]
    total_q = 0.0
    for i in range(q_m.shape[0]):  # (a sum overflowing to inf says lost too: that far off)
        total_q += q_m[i]
    total_v = 0.0
    for i in range(nv):
        total_v += v_m[i]
    lost = raised or not np.isfinite(total_q + total_v)
    for i in range(nv):
        out[0, i] = s[0, i]
        out[1, i] = s[1, i]
        out[7, i] = d[i]
    if not lost and scored:
        lam = min(1.0, dt / window)
        ahead = 0.0 if dt_prev <= 0 else 0.5 * dt * dt / dt_prev
        for i in range(nv):
            if flat:
                step_a = ahead * (v[i] - v_prev[i])  # ½ h² â, â = Δv̂ / h₋ (the blend's)
                out[5, i] = q_meas[i] - (qm0[i] + dt * vm0[i] + step_a)
                out[6, i] = q_meas[i] - (qk0[i] + dt * vk0[i] + step_a)
            e_m, e_k = out[5, i], out[6, i]
            out[0, i] = s[0, i] + lam * (e_m * e_m - s[0, i])
            out[1, i] = s[1, i] + lam * (e_k * e_k - s[1, i])
            out[7, i] = (1.0 - lam) * d[i] + (e_k * e_k - e_m * e_m)  # (**Irregular steps**)
        c = c + lam * (1.0 - c)
        if c > 0.5:
            for i in range(nv):
                lost = lost or out[0, i] > lost_ratio2 * out[1, i]
    if not lost and c > 0.5 and measured:
        for i in range(nv):  # far (step's comment)
            lost = lost or dt * abs(v_m[i] - v_kf[i]) > FAR_GATE * np.sqrt(out[1, i] / c)
    if not lost and c > 0.0:
        log_odds_loops(c, dt, window, sharpness, nvar, prior, out, fair)
    return c, lost


def weigh_loops(
    weigh: bool, flat: bool, q_kf: Vector, v_kf: Vector, q_m: Vector, v_m: Vector, out: Vector
) -> None:
    """The blend (module docstring, item 1; compiled by numba): ``w = 1/(1 + e^{−ℓ})``
    (``out[2] = −ℓ``, ``out[5] = e^{−ℓ}``), ``0`` where ``ℓ = −ℓ₀`` (a far-off model must
    not leak through), ``1`` unless ``weigh``, into ``out[2]``; ``v̂ = v̂_kf + w (v̂_m − v̂_kf)``
    into ``out[3]``; if ``flat`` ``q̂ = q̂_kf + w (q̂_m − q̂_kf)`` into ``out[4]``."""
    for i in range(out.shape[1]):
        w = 1.0
        if weigh:
            w = 0.0 if out[2, i] >= _LOG_ODDS else 1.0 / (1.0 + out[5, i])
        out[2, i] = w
        out[3, i] = v_kf[i] + w * (v_m[i] - v_kf[i])
        if flat:
            out[4, i] = q_kf[i] + w * (q_m[i] - q_kf[i])


_Kernel = Callable[..., Any]
_ONE = np.ones(1)
_ROWS = np.zeros((8, 1))
#: :func:`score_loops`, :func:`log_odds_loops` and :func:`weigh_loops` compiled (loaded when
#: a blend is made).
score_kernel = LazyKernel(
    score_loops, True, True, True, False, *(_ONE,) * 7, 1e-3, 1e-3, *(_ONE,) * 3,
    np.zeros((2, 1)), _ONE, False, 0.5, 0.2, 1e4, 1.0, 1e-8, 10.0, _ROWS.copy(),
    helpers=(log_odds_loops,),
)  # fmt: skip
log_odds_kernel = LazyKernel(log_odds_loops, 0.5, 1e-3, 0.2, 1.0, 1e-8, 10.0, _ROWS.copy(), False)
weigh_kernel = LazyKernel(weigh_loops, True, True, *(_ONE,) * 4, _ROWS.copy())
kf_variance_kernel = LazyKernel(
    kf_velocity_variance_loops, np.zeros(auto_layout(1, 1, 1)[-1]), 1, 1, 1, 1.0, _ONE.copy()
)
claim_kernel = LazyKernel(
    claim_within_loops, np.zeros(auto_layout(1, 1, 1)[-1]), 1, 1, 1, 1.0, np.eye(2), _ONE.copy(),
    helpers=(kf_velocity_variance_loops,),
)  # fmt: skip


class _State(NamedTuple):
    model: Any  # the model-based observer's state
    kf: Any  # the kf's state
    s: Vector  # (2, nv): windowed mean squared one-step prediction error, model then kf
    c: float  # the weight the window has gathered so far, 1 − (1 − h/T)^k (s / c: the mean)
    w: Vector  # the model-based weight per coordinate
    q: Vector  # the blend
    v: Vector
    v_prev: Vector  # the blend's v̂ one step before (â)
    dt_prev: float  # that step [s] (0: none yet)
    reseeds: int  # times the model-based observer was re-seeded since the reset
    d: Vector  # (nv,): Σⱼ Dⱼ (e²_kf − e²_m), each innovation once (**Irregular steps**)
    nis: float = 1.0  # ν̄: the model's windowed NIS over nv (**Prior**)


class NeverBehind(Observer[_State]):
    """A model-based observer blended per joint with ``kf`` (module docstring, item 1).

    Built by ``make_observer(name, robot, never_behind=True, ...)`` (or directly).

    Args:
        robot: the model.
        observer: the registered name of the model-based observer.
        options: its options (``rate`` and ``noise_std`` are passed to both observers).
        reference_options: options of the model-free ``kf``.
        window: ``T`` [s], the scores' averaging window.
        sharpness: ``κ``, the weight of the window's innovation count in the log-odds.
        lost_ratio: RMS prediction error ratio (model over kf) beyond which the
            model-based observer is re-seeded from the blend.
        prior_log_odds: ``ℓ_p``, the persistent prior log-odds of the model (module
            docstring, **Prior**): ``"consistent"`` (default, :data:`CONSISTENT`):
            :data:`TRUSTED_PRIOR` while the model's windowed NIS passes its test, else 0;
            or a number in ``[0, 50]``, fixed.
        rate: sample rate hint [Hz].
        noise_std: position noise standard deviation [rad or m].
    """

    name = "never_behind"  # not registered: the option never_behind=True of every family
    summary = "a model-based observer blended per joint with kf by their one-step predictions"
    uses_noise_std = True

    def __init__(
        self,
        robot: Robot,
        *,
        observer: str = "ekf",
        options: dict[str, Any] | None = None,
        reference_options: dict[str, Any] | None = None,
        window: float = 0.2,
        sharpness: float = 1.0,
        lost_ratio: float = 100.0,
        prior_log_odds: float | str = CONSISTENT,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.window = float(positive("window", window) or 0.0)
        self.sharpness = float(positive("sharpness", sharpness) or 0.0)
        self.lost_ratio = float(positive("lost_ratio", lost_ratio) or 0.0)
        self._self_test = isinstance(prior_log_odds, str)
        if self._self_test and prior_log_odds != CONSISTENT:
            raise GainError(
                f"prior_log_odds={prior_log_odds!r}: give {CONSISTENT!r} or a number in "
                f"[0, {_LOG_ODDS:g}]"
            )
        self.prior: float | str = prior_log_odds if self._self_test else float(prior_log_odds)
        if not self._self_test and not 0.0 <= float(self.prior) <= _LOG_ODDS:
            raise GainError(f"prior_log_odds={prior_log_odds!r}: give one in [0, {_LOG_ODDS:g}]")
        if self.lost_ratio <= 1.0:
            raise GainError(f"lost_ratio={lost_ratio!r}: give a ratio above 1")
        cls = observer_class(observer)
        if not cls.uses_torque:
            raise OptionError(
                f"never_behind blends a model-based observer with kf; {observer!r} is model-free"
            )
        if cls is NeverBehind:
            raise OptionError("never_behind cannot wrap itself")
        opts = dict(options or {})
        for k in ("rate", "noise_std"):
            if k in opts:
                raise OptionError(f"give {k} to never_behind, not in options (it passes it on)")
        given = {"rate": rate, "noise_std": noise_std}
        self.model = cls(robot, **opts, **given)
        self.reference = observer_class("kf")(robot, **dict(reference_options or {}), **given)
        #: the kernels' gains: T, lost_ratio², κ, σ², ℓ_p (a σ learnt from the data rebuilds the blend)
        self._gains = (
            self.window,
            self.lost_ratio**2,
            self.sharpness,
            (self.noise_std or 0.0) ** 2,
            PRIOR if self._self_test else float(self.prior),
        )
        for kernel in (
            score_kernel,
            log_odds_kernel,
            weigh_kernel,
            claim_kernel,
            kf_variance_kernel,
        ):
            kernel.load()  # (numba's cache: compiled once per installation)

    @property
    def options(self) -> dict[str, Any]:
        return {
            **super().options,
            "observer": self.model.name,
            "model_options": self.model.options,
            "reference_options": self.reference.options,
            "window": self.window,
            "sharpness": self.sharpness,
            "lost_ratio": self.lost_ratio,
            "prior_log_odds": self.prior,
        }

    def set_latency(self, latency: float) -> None:
        """Refused (but for 0): the blend steps both observers forward and cannot predict
        without committing (give the latency to a family observer instead)."""
        if latency:
            raise OptionError("never_behind takes no latency; give it to the observer alone")
        super().set_latency(latency)

    @property
    def reseeds(self) -> int:
        """Times the model-based observer was re-seeded since the reset (module docstring),
        read from the latest state (``step`` is pure: it counts them in the state)."""
        return 0 if self._state is None else self._state.reseeds

    @property
    def weights(self) -> Vector:
        """The current model-based weight ``w`` per coordinate (module docstring)."""
        if self._state is None:
            return np.full(self.robot.nv, np.nan)
        return np.array(self._state.w)

    # ---------------------------------------------------------------- states
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        nv = self.robot.nv
        m = self.model.initial_state(q0, v0)
        k = self.reference.initial_state(q0, v0)
        z = np.zeros((3, nv))  # (the scores, d)
        return _State(m, k, z[:2], 0.0, np.ones(nv), q0.copy(), v0.copy(), v0, 0.0, 0, z[2])

    def restart_state(self, state: _State, q: Vector) -> _State:
        nv = self.robot.nv
        zero = np.zeros(nv)
        m = self.model.restart_state(state.model, q)
        k = self.reference.restart_state(state.kf, q)
        w = np.ones(nv)
        z = np.zeros((3, nv))  # (the scores, d)
        return _State(m, k, z[:2], 0.0, w, q.copy(), zero, zero, 0.0, state.reseeds, z[2])

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        """Module docstring, item 1: both observers stepped, then :func:`score_loops`,
        NumPy's ``exp`` and :func:`weigh_loops` (issue 39: the blend's own arithmetic cost
        ~14 ``pin.aba`` per UR5 update in NumPy, ~3 compiled; the same bits, tested), into
        one new array whose rows the new state holds."""
        r = self.robot
        flat = r.is_vector_space  # q ⊕ x = q + x, difference(a, b) = b − a: plain arithmetic
        kf = self.reference.step(state.kf, dt, q_meas, tau)
        q_kf, v_kf = self.reference.output(kf)
        try:
            m = self.model.step(state.model, dt, q_meas, tau)
            q_m, v_m = self.model.output(m)
            raised = False
        except (ObserverDiverged, np.linalg.LinAlgError, ArithmeticError):
            q_m, v_m, raised = q_kf, v_kf, True
        measured = q_meas is not None
        # scored (module docstring), unless the kf's gate took this sample or the one before
        # for an outlier (then its prediction is two steps ahead, the model's one: **Gated**)
        scored = measured and not (
            self.reference.innovation(kf)[1] or self.reference.innovation(state.kf)[1]
        )
        qm0, vm0 = self.model.output(state.model)
        qk0, vk0 = self.reference.output(state.kf)
        # the new state's rows: s (model, kf), w, v, q (flat), the one-step errors (model, kf), d
        out = np.empty((8, r.nv))
        if q_meas is not None and scored and not flat and not raised:  # on Lie groups: Pinocchio
            ahead = 0.0 if state.dt_prev <= 0 else 0.5 * dt * dt / state.dt_prev
            step_a = ahead * (state.v - state.v_prev)  # ½ h² â, â = Δv̂ / h₋ (the blend's)
            out[5] = r.difference(r.integrate(qm0, dt * vm0 + step_a), q_meas)
            out[6] = r.difference(r.integrate(qk0, dt * vk0 + step_a), q_meas)
        gains, period = self._gains, self._period_s  # a step off the grid: fair (docstring)
        nis = state.nis
        if self._self_test and not raised:  # ℓ_p earned by the model's NIS test (**Prior**)
            nis, prior = self._earned_prior(nis, m, kf, dt)
            gains = (*gains[:4], prior)
        fair = period is not None and abs(dt - period) > UNIFORM_TOL * period
        c, lost = cast(_Kernel, score_kernel.compiled)(  # scores, lost tests, log-odds
            flat, scored and not raised, measured, raised, q_meas if measured else q_kf,
            qm0, vm0, qk0, vk0, state.v, state.v_prev, dt, state.dt_prev, q_m, v_m, v_kf,
            state.s, state.d, fair, state.c, *gains, out,
        )  # fmt: skip
        reseeds = state.reseeds
        if lost:  # re-seeded (module docstring) at the kf's estimate, the blend's when w = 0
            reseeds += 1
            m = self.model.initial_state(q_kf, v_kf)
            q_m, v_m = self.model.output(m)
            np.multiply(self.lost_ratio, out[1], out=out[0])  # to prove itself: w ≈ 0 until it has
            out[7] = (out[1] - out[0]) / min(1.0, dt / gains[0])  # (d as on the grid)
            if c > 0.0:
                g = (gains[0], gains[2], gains[3], gains[4])
                cast(_Kernel, log_odds_kernel.compiled)(c, dt, *g, out, fair)
        if c > 0.0:
            np.exp(out[2], out=out[5])  # NumPy's exp (out[2] = −ℓ): the NumPy form's bits
        cast(_Kernel, weigh_kernel.compiled)(c > 0.0, flat, q_kf, v_kf, q_m, v_m, out)
        q = out[4] if flat else r.integrate(q_kf, out[2] * r.difference(q_kf, q_m))
        return _State(m, kf, out[:2], c, out[2], q, out[3], state.v, dt, reseeds, out[7], nis)

    def _earned_prior(self, nis: float, m: Any, kf: Any, dt: float) -> tuple[float, float]:
        """``(ν̄, ℓ_p)`` after this step (module docstring, **Prior**): the model's windowed NIS
        over ``nv`` updated with its NIS at ``m`` (kept without one), and :data:`TRUSTED_PRIOR`
        if it is inside the test's two-sided band, (``ekf``'s ``disturbance_psd="auto"``)
        every learned density within ``q_a``'s share and (a family with a covariance) every
        velocity variance it claims at most the ``kf``'s own at ``kf``, else :data:`PRIOR`."""
        lam = min(1.0, dt / self.window)
        eps = self.model.innovation(m)[0]
        nv = self.robot.nv
        if eps is not None and math.isfinite(eps):  # (one sample's share capped: NIS_CAP)
            nis += lam * (min(eps / nv, NIS_CAP) - nis)
        low, high = nis_band(nv, lam)
        if not low <= nis <= high:
            return nis, PRIOR
        psd, scale = getattr(m, "d_psd", None), getattr(m, "psd_scale", None)
        gains = getattr(self.model, "gains", None)  # (ekf's: its accel_psd q_a)
        if psd is not None and scale is not None and gains is not None:  # ψ h⁵/20 ≤ q_a h³/3
            if not bool(np.all(psd / scale * (dt * dt / 20.0) <= gains.accel_psd / 3.0)):
                return nis, PRIOR
        if not claims_within_kf(m, kf, nv):  # consistent: its P_vv is its error's (**Prior**)
            return nis, PRIOR
        return nis, TRUSTED_PRIOR

    def after_commit(self, state: _State, t: float, q: Vector | None, tau: Vector) -> _State:
        """Each observer's own, on its part of the state; the model-based observer's committed
        part is then its latest state, for what is read of it (``adaptive``'s learned model,
        regime, restarts: :meth:`~pinobs.observers.adaptive.AdaptiveEKF.snapshot`)."""
        m = self.model.after_commit(state.model, t, q, tau)
        k = self.reference.after_commit(state.kf, t, q, tau)
        self.model.adopt(m)  # (the blend is the one reset: the wrapped observer never is)
        return state._replace(model=m, kf=k)

    def innovation(self, state: _State) -> tuple[float | None, bool]:
        """The model-based observer's NIS (the consistency test is of the model), and the
        ``kf``'s outlier decision (the one the scores use): a lost model gates every
        sample, and a sample reported gated is withheld from both observers' learning
        (:meth:`after_commit`)."""
        return self.model.innovation(state.model)[0], self.reference.innovation(state.kf)[1]

    def output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q, state.v
