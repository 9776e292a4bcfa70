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

   (``T`` = ``window``; a sample the ``kf``'s outlier gate rejects is not scored; one the
   model-based observer's gate rejects is: a lost model rejects the samples).
   The measurement noise ``n_{k+1}`` enters both ``eᵢ`` alike and is independent of both
   predictions (made before it).  These one-step scores decide when the model is **lost**
   (below); the weights come from the velocity scores (**Velocity score**).

   **Velocity score.**  A one-step error barely sees a velocity error: the ``kf``'s
   ``δv ≈ 5e-3`` rad/s at 1 kHz moves its prediction by ``h δv = 5e-6`` rad,
   ``(h δv)² = 2.5e-11`` against ``σ² = 1e-8``, while the position estimates' own errors (a
   fraction of σ) enter in full: the one-step scores rank the position estimates.  Weighted
   by them (a window log-likelihood ratio, below, from the one-step scores) an exact
   ``riemannian`` on a Panda, whose positions follow the noise more than the ``kf``'s but
   whose velocities are ~10× better, had that ratio down to −1000 against it (σ = 1e-3 rad,
   1 kHz) and the blend was 7.8× the family alone (mean of 10 seeds; 3.7× for an exact
   ``riemannian`` and 1.5× for an exact ``ekf`` on a UR5: ``benchmarks/never_behind_exact.md``).
   So each predictor is judged by its velocity over a span ``H`` (:data:`VELOCITY_HORIZON`,
   10 ms): its estimate at ``t_{a−1}`` predicts the displacement from the next sample
   ``q_a`` to a later one ``q_k`` (the oldest waiting prediction with
   ``Δ = t_k − t_a ≥ 0.9 H``, or the oldest of :data:`RING_SIZE`),

       εᵢ = (q_k ⊖ q_a) − (Δ v̂ᵢ + ½ ((Δ + h₀)² − h₀²) â),    h₀ = t_a − t_{a−1},

   ``â`` the blend's acceleration at ``t_{a−1}`` (common to both).  Both samples come after
   the estimate, so their noise ``n_k − n_a`` (variance ``2σ²``) is independent of both
   predictions and the same in both; the position estimates do not enter; a velocity error
   enters as ``Δ δv``, growing with the span while the noise stays: ``(Δ δv)² = 2.5e-9``
   against ``2σ² = 2e-8`` for the ``kf`` above (``Δ = 10`` ms), 100× the one-step ratio
   (the k-step-ahead prediction errors of multiple-model testing, Bar-Shalom, Li &
   Kirubarajan 2001 §11.6, on a span rather than one step).  Scored like the one-step
   errors, ``uᵢ ← uᵢ + λ(εᵢ² − uᵢ)``, ``c_v ← c_v + λ(1 − c_v)``, ``λ = min(1, h/T)``.  The
   weights are the posterior probabilities of the two predictors given the window's
   velocity innovations, Gaussian with a common variance ``S = max(min(u_m, u_kf)/c_v, 2σ²)``
   (the multiple-model weights of Magill 1965; Bar-Shalom, Li & Kirubarajan 2001, §11.6.2,
   with a forgetting window), each innovation's log-likelihood ratio censored at ``±C``
   (:data:`EVIDENCE_CLIP` = 5; Huber 1965's censored probability-ratio test: a start
   transient, where a ``kf`` 1 rad/s off is 2500 S off, must not outweigh a window of later
   evidence), counted once and decayed by its age (on an irregular grid too):

       d ← (1 − λ) d + clip((ε²_kf − ε²_m) / (2S), ±C),    ℓ = clip(κ d + ℓ_p, ±ℓ₀),
       w = 1 / (1 + e^{−ℓ}).

   **Persistent prior** ``ℓ_p`` (:data:`MODEL_PRIOR` = 10).  An exact model's weight must
   stay close to 1: the ``kf``'s velocity is up to ~200× worse (σ = 1e-4 rad, 1 kHz, UR5:
   5e-3 against 2.6e-5 rad/s), so ``1 − w`` of 1e-3 already costs ``(1 − w) δv_kf = 5e-6``
   rad/s, a fifth of the model's own error.  The window's log-likelihood ratio between two
   good predictors wanders around zero (consecutive velocity errors are correlated, so its
   ~200 terms are fewer independent ones); the prior keeps ``1 − w ≤ e^{−10} = 4.5e-5``
   while it does.  The evidence needed to drop the model: ``d < −ℓ_p``, i.e. (uncensored)
   ``N Δ² (δv_m² − δv_kf²) / (4σ²) > ℓ_p`` (``N = T/h``): at 1 kHz, σ = 1e-4 rad,
   ``Δ = 9`` ms, ``δv_m² > δv_kf² + 2.5e-5``, a model worse than 7.1e-3 rad/s against the
   ``kf``'s 5e-3 (a model between the two may be kept, partly).  A lost model (below)
   starts at the most evidence a window holds against it, ``d = −C/λ``, ``c_v = 1``; a
   restart after a pause keeps ``d``, ``u``, ``c_v`` and the weights (a model the data
   rejected stays rejected, as ``kf``'s bank keeps its likelihoods).  Measured
   (``benchmarks/never_behind_exact.md``): on exact models at most 1.004× the family alone
   (240 runs; the one-step weights: up to 10×); the mismatch rows of
   ``never_behind_sim.py`` 1.00× ``kf``; but on the real UR10e logs with the identified
   model 1.01–1.56× ``kf`` (the one-step weights: 1.00×), and +1.3–1.6 ``pin.aba`` per
   update: not adopted.

   ``κ`` (``sharpness``) scales the evidence (before any velocity is scored the model is
   trusted, ``w = 1``); and the output

       v̂ = w v̂_m + (1 − w) v̂_kf,    q̂ = q̂_kf ⊕ w · difference(q̂_kf, q̂_m).

   With an exact model the model-based predictor wins every window (``w → 1``: its
   accuracy is kept); with a useless one the ``kf`` wins (``w → 0``: the tuned
   model-free accuracy).  **Lost**: when the model-based estimate stops being finite, its
   step raises, or its score exceeds ``lost_ratio²`` times the ``kf``'s on some joint, it
   is re-seeded from the blend (its family's initial state at the ``kf``'s ``(q̂, v̂)`` of
   that sample, the blend's with ``w = 0``; its score set to ``lost_ratio`` times the
   ``kf``'s, its velocity scores alike, its evidence as above and its waiting predictions
   dropped) and :attr:`NeverBehind.reseeds` counts it.  It is lost too when
   its velocity jumps away from the ``kf``'s by more than ``FAR_GATE`` = 10 times the
   ``kf``'s own RMS one-step error as a velocity, ``h |v̂_m − v̂_kf| > 10 √s_kf``: the
   windowed scores lag such a jump (on a UR10e log an ``ekf+auto`` 1.7 rad/s RMS off in
   bursts kept a mean weight 0.1–0.27 and made the blend 1.2× the ``kf``).  Where ``ℓ``
   reaches its bound ``−50``, ``w = 0`` exactly: a model 1e20 rad/s off cannot leak
   through ``w = 2e-22``.  The arithmetic between the two observers' steps is compiled
   (numba: :func:`score_loops`, :func:`velocity_loops` with :func:`log_odds_loops`,
   :func:`weigh_loops`; Pinocchio's
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

from collections.abc import Callable
from typing import Any, NamedTuple, cast

import numpy as np

from pinobs.errors import GainError, ObserverDiverged, OptionError
from pinobs.model import Robot
from pinobs.model.sampling import UNIFORM_TOL
from pinobs.observers.base import Observer, Vector, observer_class, positive
from pinobs.observers.linalg import LazyKernel

__all__ = ["NeverBehind", "match_density"]

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
    psd: Vector, e: Vector, s: Vector, dt: float, *, window: float, bounds: Vector
) -> Vector:
    """One step of module docstring item 2: the densities ``ψ`` updated.

    Args:
        psd: the densities ``ψ`` per coordinate (any unit; returned in it).
        e: this sample's innovation per coordinate.
        s: its predicted variance per coordinate (``Sᵢᵢ``), > 0.
        dt: the step [s].
        window: ``T`` [s], the time constant of ``log ψ``.
        bounds: ``(2, n)`` or ``(2,)``: ``ψ_min``, ``ψ_max``.
    """
    lam = min(1.0, dt / window)
    with np.errstate(divide="ignore"):  # e = 0: log 0 = −∞, clipped
        step = np.clip(np.log(e * e / s), *LOG_BOUNDS) - LOG_CHI2_MEAN
    return np.clip(psd * np.exp(lam * step), bounds[0], bounds[1])  # type: ignore[no-any-return]


#: Bound of the blend's log-odds ``ℓ`` (``1 − w`` or ``w`` ≥ 2e-22) and its prior (docstring).
_LOG_ODDS = 50.0
_TINY = 1e-300  # the smallest score the log-odds divide by
#: A model-based velocity this many kf one-step errors (as velocities) from the kf's is lost.
FAR_GATE = 10.0
#: ``H`` [s]: the span of the velocity score's predictions (module docstring, **Velocity score**).
VELOCITY_HORIZON = 0.01
#: ``ℓ_p``: the persistent prior log-odds of the model (module docstring, **Velocity score**).
MODEL_PRIOR = 10.0
#: The most predictions waiting for their span (above: the oldest is scored early).
RING_SIZE = 32
#: ``C``: the bound of one velocity innovation's log-likelihood ratio (module docstring).
EVIDENCE_CLIP = 5.0


def log_odds_loops(cv: float, sharpness: float, prior: float, out: Vector) -> None:
    """``out[2] = −ℓ`` per coordinate from the velocity evidence ``d = out[7]`` and the weight
    ``c_v`` its window has gathered (module docstring, item 1, **Velocity score**; compiled
    by numba): ``ℓ = clip(κ d + ℓ_p, ±ℓ₀)``, ``ℓ_p = prior``; NaN kept as NumPy keeps it."""
    for i in range(out.shape[1]):
        ell = sharpness * out[7, i] + prior
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
    c: float,
    window: float,
    lost_ratio2: float,
    out: Vector,
) -> tuple[float, bool]:
    """:meth:`NeverBehind.step`'s one-step scores and lost tests (module docstring, item 1;
    compiled by numba): lost if ``raised`` or ``(q_m, v_m)`` sums to a non-finite value;
    if ``scored`` (and not lost) the one-step errors (``flat``: here,
    ``eᵢ = q_{k+1} − (q̂ᵢ + h v̂ᵢ + ½ h² â)``, else given in ``out[5:7]``), the scores
    ``sᵢ ← sᵢ + λ(eᵢ² − sᵢ)`` into ``out[0:2]``, ``c ← c + λ(1 − c)``, ``λ = min(1, h/T)``,
    lost if ``s_m > lost_ratio² s_kf`` somewhere once ``c > ½``; if ``measured``, lost if
    ``h |v̂_m − v̂_kf| > FAR_GATE √(s_kf / c)`` somewhere.  Returns ``(c, lost)``."""
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
        c = c + lam * (1.0 - c)
        if c > 0.5:
            for i in range(nv):
                lost = lost or out[0, i] > lost_ratio2 * out[1, i]
    if not lost and c > 0.0 and measured:
        for i in range(nv):  # far (step's comment)
            lost = lost or dt * abs(v_m[i] - v_kf[i]) > FAR_GATE * np.sqrt(out[1, i] / c)
    return c, lost


def velocity_loops(
    flat: bool,
    scored: bool,
    age: float,
    h0: float,
    dt_prev: float,
    vm0: Vector,
    vk0: Vector,
    v: Vector,
    v_prev: Vector,
    q_anchor: Vector,
    q_meas: Vector,
    lam: float,
    u: Vector,
    d: Vector,
    cv: float,
    sharpness: float,
    nvar: float,
    prior: float,
    out: Vector,
) -> float:
    """The velocity scores (module docstring, item 1, **Velocity score**; compiled by numba):
    if ``scored``, one prediction's errors over the span ``age = t_k − t_a`` (``flat``: the
    displacement ``q_k − q_a`` here, else given in ``q_meas``),

        εᵢ = (q_k ⊖ q_a) − (age v̂ᵢ + ½ ((age + h₀)² − h₀²) â),    â = (v − v₋)/h₋,

    into ``out[10:12]``; the evidence ``d ← (1 − λ) d + clip((ε²_kf − ε²_m) / (2S), ±C)``,
    ``S = max(min(u_m, u_kf)/c_v, 2σ², 10⁻³⁰⁰)`` (``0`` for the mean while ``c_v = 0``), into
    ``out[7]``; ``uᵢ ← uᵢ + λ(εᵢ² − uᵢ)`` into ``out[8:10]``; ``c_v ← c_v + λ(1 − c_v)``
    (returned); else ``u``, ``d`` copied; then, if ``c_v > 0``, :func:`log_odds_loops`."""
    nv = out.shape[1]
    for i in range(nv):
        out[8, i] = u[0, i]
        out[9, i] = u[1, i]
        out[7, i] = d[i]
    floor = 2.0 * nvar
    if _TINY > floor:
        floor = _TINY
    ahead = 0.0 if dt_prev <= 0 else 0.5 * ((age + h0) * (age + h0) - h0 * h0) / dt_prev
    for i in range(nv if scored else 0):
        disp = q_meas[i] - q_anchor[i] if flat else q_meas[i]
        step_a = ahead * (v[i] - v_prev[i])
        e_m = disp - (age * vm0[i] + step_a)
        e_k = disp - (age * vk0[i] + step_a)
        out[10, i] = e_m
        out[11, i] = e_k
        u_m, u_k = u[0, i], u[1, i]
        low = u_m if u_m <= u_k else (u_k if u_k < u_m else u_m + u_k)  # np.minimum (NaN: NaN)
        mean = low / cv if cv > 0.0 else 0.0
        big = mean if mean >= floor else (floor if floor > mean else mean + floor)  # np.maximum
        # Huber 1965: each innovation's log-likelihood ratio, censored at ±C
        term = (e_k * e_k - e_m * e_m) / (2.0 * big)
        if term < -EVIDENCE_CLIP:
            term = -EVIDENCE_CLIP
        elif term > EVIDENCE_CLIP:
            term = EVIDENCE_CLIP
        out[7, i] = (1.0 - lam) * d[i] + term
        out[8, i] = u_m + lam * (e_m * e_m - u_m)
        out[9, i] = u_k + lam * (e_k * e_k - u_k)
    if scored:
        cv = cv + lam * (1.0 - cv)
    if cv > 0.0:
        log_odds_loops(cv, sharpness, prior, out)
    return cv


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
_ROWS = np.zeros((12, 1))
#: :func:`score_loops`, :func:`velocity_loops`, :func:`log_odds_loops` and :func:`weigh_loops`
#: compiled (loaded when a blend is made).
score_kernel = LazyKernel(
    score_loops, True, True, True, False, *(_ONE,) * 7, 1e-3, 1e-3, *(_ONE,) * 3,
    np.zeros((2, 1)), 0.5, 0.2, 1e4, _ROWS.copy(),
)  # fmt: skip
velocity_kernel = LazyKernel(
    velocity_loops, True, True, 1e-2, 1e-3, 1e-3, *(_ONE,) * 6, 5e-3, np.zeros((2, 1)), _ONE,
    0.5, 1.0, 1e-8, 10.0, _ROWS.copy(), helpers=(log_odds_loops,),
)  # fmt: skip
weigh_kernel = LazyKernel(weigh_loops, True, True, *(_ONE,) * 4, _ROWS.copy())


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
    d: Vector  # (nv,): Σⱼ Dⱼ (ε²_kf − ε²_m), each velocity innovation once
    u: Vector  # (2, nv): windowed mean squared velocity-score error, model then kf
    cv: float  # the weight the velocity window has gathered
    ring: tuple[Any, ...]  # predictions waiting for their span (t_a, h₀, h₋, v̂_m, v̂_kf, v, v₋, q_a)
    clock: float  # time since the reset [s]


def _queued(
    ring: tuple[Any, ...],
    clock: float,
    dt: float,
    state: _State,
    vm0: Vector,
    vk0: Vector,
    q_meas: Vector,
) -> tuple[tuple[Any, ...], tuple[Any, ...], bool]:
    """This sample's prediction queued (module docstring, **Velocity score**: made at the
    previous one, anchored here) and the oldest taken out if its span is due."""
    a = (state.dt_prev, vm0, vk0, state.v, state.v_prev, q_meas.copy())
    ring = (*ring, (clock, dt, *a))
    old = ring[0]
    due = len(ring) > RING_SIZE or clock - old[0] >= (1 - UNIFORM_TOL) * VELOCITY_HORIZON
    return (ring[1:] if due else ring), old, due


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
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.window = float(positive("window", window) or 0.0)
        self.sharpness = float(positive("sharpness", sharpness) or 0.0)
        self.lost_ratio = float(positive("lost_ratio", lost_ratio) or 0.0)
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
        #: the kernels' gains: T, lost_ratio², κ, σ² (a σ learnt from the data rebuilds the blend)
        self._gains = (
            self.window,
            self.lost_ratio**2,
            self.sharpness,
            (self.noise_std or 0.0) ** 2,
        )
        for kernel in (score_kernel, velocity_kernel, weigh_kernel):
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
        z = np.zeros((5, nv))  # (the scores, d, the velocity scores)
        w = np.ones(nv)
        return _State(
            m, k, z[:2], 0.0, w, q0.copy(), v0.copy(), v0, 0.0, 0, z[2], z[3:], 0.0, (), 0.0
        )

    def restart_state(self, state: _State, q: Vector) -> _State:
        """After a pause: both observers restarted, the one-step scores afresh; the velocity
        evidence (``d``, the scores ``u``, ``c_v``) and the weights kept: a model the data
        rejected stays rejected over a pause, as ``kf``'s bank keeps its likelihoods
        (module docstring, **Velocity score**)."""
        zero = np.zeros(self.robot.nv)
        m = self.model.restart_state(state.model, q)
        k = self.reference.restart_state(state.kf, q)
        s = np.zeros((2, self.robot.nv))
        return _State(
            m, k, s, 0.0, state.w, q.copy(), zero, zero, 0.0, state.reseeds, state.d, state.u,
            state.cv, (), 0.0,
        )  # fmt: skip

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
        # scored (module docstring), unless the kf's gate took the sample for an outlier
        scored = measured and not self.reference.innovation(kf)[1]
        qm0, vm0 = self.model.output(state.model)
        qk0, vk0 = self.reference.output(state.kf)
        # the new state's rows: s (model, kf), w, v, q (flat), the one-step errors (model, kf),
        # d, u (model, kf), the velocity errors (model, kf)
        out = np.empty((12, r.nv))
        if q_meas is not None and scored and not flat and not raised:  # on Lie groups: Pinocchio
            ahead = 0.0 if state.dt_prev <= 0 else 0.5 * dt * dt / state.dt_prev
            step_a = ahead * (state.v - state.v_prev)  # ½ h² â, â = Δv̂ / h₋ (the blend's)
            out[5] = r.difference(r.integrate(qm0, dt * vm0 + step_a), q_meas)
            out[6] = r.difference(r.integrate(qk0, dt * vk0 + step_a), q_meas)
        gains = self._gains
        c, lost = cast(_Kernel, score_kernel.compiled)(  # one-step scores, lost tests
            flat, scored and not raised, measured, raised, q_meas if measured else q_kf,
            qm0, vm0, qk0, vk0, state.v, state.v_prev, dt, state.dt_prev, q_m, v_m, v_kf,
            state.s, state.c, gains[0], gains[1], out,
        )  # fmt: skip
        reseeds, clock, ring, u, d = state.reseeds, state.clock + dt, state.ring, state.u, state.d
        cv = state.cv
        lam = min(1.0, dt / gains[0])
        old: tuple[Any, ...] = (0.0, 0.0, 0.0, vm0, vk0, state.v, state.v_prev, q_kf)
        due = False
        if lost:  # re-seeded (module docstring) at the kf's estimate, the blend's when w = 0
            reseeds += 1
            m = self.model.initial_state(q_kf, v_kf)
            q_m, v_m = self.model.output(m)
            np.multiply(self.lost_ratio, out[1], out=out[0])  # to prove itself: w ≈ 0 until it has
            u = np.array([self.lost_ratio * u[1], u[1]])  # (its velocity scores too)
            d = np.full(r.nv, -EVIDENCE_CLIP / lam)  # (the most evidence a window holds:
            cv = 1.0  # a full window's, weighed even before any prediction was)
            ring = ()  # (the lost model's predictions)
        elif q_meas is not None and scored and not raised:  # a prediction made, one scored
            ring, old, due = _queued(ring, clock, dt, state, vm0, vk0, q_meas)
        q_a, q_k = old[7], q_kf
        if due and q_meas is not None:  # the displacement (on Lie groups: tangent at q_a)
            q_k = q_meas if flat else r.difference(q_a, q_meas)
        cv = cast(_Kernel, velocity_kernel.compiled)(  # velocity scores, log-odds
            flat, due, clock - old[0], *old[1:7], q_a, q_k, lam, u, d, cv, gains[2],
            gains[3], MODEL_PRIOR, out,
        )  # fmt: skip
        if cv > 0.0:
            np.exp(out[2], out=out[5])  # NumPy's exp (out[2] = −ℓ): the NumPy form's bits
        cast(_Kernel, weigh_kernel.compiled)(cv > 0.0, flat, q_kf, v_kf, q_m, v_m, out)
        q = out[4] if flat else r.integrate(q_kf, out[2] * r.difference(q_kf, q_m))
        return _State(
            m, kf, out[:2], c, out[2], q, out[3], state.v, dt, reseeds, out[7], out[8:10], cv,
            ring, clock,
        )  # fmt: skip

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
