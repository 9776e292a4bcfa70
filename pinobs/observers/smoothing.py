"""Offline smoothing of a recorded log: the Rauch–Tung–Striebel smoother on the manifold.

A causal filter estimates ``x_k`` from the samples up to ``t_k``; a log has the
later samples too.  The fixed-interval smoother runs the filter forward
(:class:`pinobs.observers.ekf.ExtendedKalmanFilter`, whose ``predict`` and
``correct`` it calls), stores at every sample the filtered mean and
covariance ``(x⁺_k, P⁺_k)``, the predicted ones ``(x⁻_{k+1}, P⁻_{k+1})`` and
the transition Jacobian ``Φ_k`` of the error state, then runs backward
(Rauch, Tung, Striebel 1965; Särkkä, *Bayesian Filtering and Smoothing*, 2013,
Theorem 8.2, and its extended form in Ch. 9)::

    G_k   = P⁺_k Φ_kᵀ (P⁻_{k+1})⁻¹                          smoother gain
    δ_k   = G_k · (x^s_{k+1} ⊖ x⁻_{k+1})                      error-state correction
    x^s_k = x⁺_k ⊕ δ_k
    P^s_k = P⁺_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ

started from the filter at the last sample, ``x^s_N = x⁺_N``, ``P^s_N = P⁺_N``.
On the manifold ``x ⊖ y`` and ``x ⊕ δ`` are the error-state maps of the EKF:
``difference(q⁻, q^s)`` and ``integrate(q⁺, δq)`` for the configuration
(``q^s = q⁻ ⊕ e`` ⇔ ``e = difference(q⁻, q^s)``), plain differences and sums
for the velocity (and the EKF's torque offset ``d`` when it has one).

What is approximated: the covariances ``P⁺_k`` (in the tangent space at
``q⁺_k``), ``P⁻_{k+1}`` and ``P^s_{k+1}`` (at ``q⁻_{k+1}`` and ``q^s_{k+1}``) are
combined as if those tangent spaces were one, i.e. the transport of the
covariance between them (``J_r`` of the differences, identity + ``O(|δq|)``)
is neglected, as the EKF neglects it at its reset.  On robots whose joints
are all revolute or prismatic (UR5, Panda) ``⊕``/``⊖`` are sums and
differences and the smoother is the exact extended RTS smoother of the EKF's
linearisation.

Process noise, and what "calibrated" asks of it.  The smoother's ``v_std``
is honest only if ``accel_psd`` matches the model error.  With the same
``accel_psd`` in both, the steady-state smoother of a position-measured
double integrator has a velocity standard deviation 2.0× below the filter's
(the variance ratio is 4; computed from the discrete Riccati equations at
1 kHz for ``q_w/σ²`` from 1e-2 to 1e4 s⁻³: 1.98–2.00).  A log of an exact
model has no process noise at all; the EKF's default ``accel_psd`` (1e-8)
then overstates it and the band is too wide.  :func:`select_accel_psd`
picks ``accel_psd`` from the log alone (no truth): the largest value whose
innovation likelihood is within 1.92 nats of the best on a decade grid.
Measured on 3 s logs (``benchmarks/smoothing.py``, README): it picks
1e-10 to 1e-8 on a UR5 and 1e-11 to 1e-9 on a Panda (σ = 1e-4 and 1e-3),
and the ±2σ band then covers the truth at 95–98 % of samples on the seed-0
logs, 88–100 % on seeds 1–3 (one log holds few independent values of a
slowly varying error; README: on 3 s at σ = 1e-3 the likelihood cannot
resolve densities below 1e-8, on 10 s logs it picks 1e-11); at the default 1e-8 it covers 98.5 % (UR5, σ = 1e-4,
seed 0) with an RMS 1.9× larger.  On short logs the choice is larger, so
conservative (0.7 s, UR5, σ = 1e-4: 1e-7).

Memory: the whole-log smoother stores ``3 m²`` numbers per sample (``m`` = 2nv, or
3nv with the torque offset; ``band="noise"``: ``m² + m nv`` more, ``Pⁿ⁺`` and ``K``;
the compiled ``kf`` smoother below ``3 nv + 9``, and 9 more, for the whole log
even in chunks: of the order of the result's own ``nq + 2 nv``).  With
``chunk`` the forward pass still runs once, but the backward pass runs on
windows of ``chunk + overlap`` seconds started from the *filtered* estimate at
the window's end (the best available without later data) and keeps only the
first ``chunk`` seconds; the error this makes decays backward at the rate of
the filter's slowest pole, so an overlap of a few of its time constants
reproduces the whole-log smoother (:func:`default_overlap`: aimed at 1e-6 of
``v_std``, measured 1.7e-6 to 1.8e-6, tested below 1e-5).  The smaller
``accel_psd``, the longer the memory: 11 s at ``accel_psd`` = 1e-10 and
σ = 1e-4 rad.  A torque offset (``disturbance_psd``, ``adaptive``) acts
through ``M(q)⁻¹``, whose coupling leaves it a slow real pole in some
directions: overlaps of 0.5–10 s where an offset of the same density on
every joint alone would need 0.4–1.4 s.
``lag`` is the near-real-time form: chunks of ``lag`` with an overlap of
``lag``, so every estimate uses at least ``lag`` seconds of later samples and
is available at most ``2 lag`` after its sample; a lag shorter than the
memory gives a result between the filter's and the whole-log smoother's.
:class:`Smoother` is the same loop fed one sample at a time (finished
samples out as each window closes; :func:`streaming_smoother` builds one), so
a log read as it goes (:func:`pinobs.io.smoothing.smooth_log`) never needs
more than ``chunk + overlap`` samples' states.

A log with dropped samples (rows missing from a fixed-rate loop's log: an interval of
``m ≥ 2`` median intervals) is smoothed on the grid of its ticks, each missing sample
predicted over with its torque on the line between its neighbours'
(:func:`pinobs.model.sampling.on_ticks`), the estimate given at the log's rows.  Fed
the log as it is, the filter would hold the torque before each gap across it: on a
4 s UR5 log of the exact model (σ = 1e-4) with 8 % of its rows dropped (runs of 1 and
3–9) the velocity error was then 33× the clean log's, on the ticks 1.24× (1.04× with
the missing samples' true torques: the rest is their interpolation).  An irregular
log (intervals within 1.5 median intervals) is smoothed at its own times.

A known measurement latency (``filter_options={"latency": d}``) re-times the log
(:func:`_retimed`): each sample at the time it was taken, ``t − d``, each torque
switching at its stamped time, the estimates read at the stamped times; it is then
an ordinary log with dropped samples, which the filter predicts over.  An unknown
one (``"latency": "auto"``) is the likeliest on the log (:func:`select_latency`: the
innovation likelihood over whole sample intervals, then a parabola's vertex).  With no
latency given, a log the model does not explain as stamped (``ρ`` above :data:`RHO_WARN`)
is searched the same way, and the latency found is used if the log smoothed under it is
explained (``ρ`` at most :data:`RHO_WARN`), which :func:`smooth` says
(:class:`~pinobs.errors.LatencyWarning`).  A model error of another kind can pass that
test only if a latency happens to explain it (on the UR5 payload log of the tests none of up
to three intervals did); a latency so adopted is said all the same.  ``{"latency": 0}``
smooths the log as stamped.  With ``accel_psd="auto"`` over ``ekf``, ``ρ`` is about 1 on
any log (the density absorbs what the model misses), so the search runs when the density
chosen is above the filter's own; the latency found is adopted if it explains the log at
the filter's own density and, smoothed under it with ``"auto"`` again, raises the
likelihood by :data:`LIKELIHOOD_MARGIN` (a UR5 log 2 ms late, 3 s, σ = 1e-4: ``"auto"``
took 1e-2 rad²/s³ as stamped, RMS 9.45e-3 rad/s; 2 ms found, 1e-10 rad²/s³, RMS 7.05e-6).

The observers that can be smoothed are those that keep an error-state
Gaussian: ``ekf``, ``adaptive`` through its model-based filter, and the
model-free ``kf`` (:class:`pinobs.observers.kf.WhiteJerkFilter`: its per-joint
white-jerk filter as one error state ``(δq, δv, δa)`` with ``P = P₃ ⊗ I``, the
acceleration smoothed as the EKF's ``d``).  Another family qualifies by declaring
itself :attr:`~pinobs.observers.base.Observer.smoothable` and giving, from its
:meth:`~pinobs.observers.base.Observer.smoothing_filter`, a
:class:`~pinobs.observers.base.GaussianFilter` (``initial_state``, ``predict``
returning ``Φ``, ``correct``) whose states carry ``q``, ``v``, ``P`` (and
optionally ``d``).

The model-free smoother is the floor where the model is wrong.  Over ``ekf``
with a wrong model, ``accel_psd="auto"`` ends at white acceleration
(:func:`smoothing_warnings`), a poorer prior for a robot's motion than white
jerk: on a 4 s UR5 log under an unmodelled payload (seed 1, σ = 1e-4) the
smoother over ``ekf`` has an RMS of 1.22e-2 rad/s, the causal ``kf`` at its best
density chosen on the truth 5.39e-3, the smoother over ``kf`` with ``"auto"``
2.16e-3 (tested; ``benchmarks/smoothing_model_free.py`` for 12 s logs).  Its
density is ``jerk_psd`` [rad²/s⁵] (``filter_options``; a number for
``accel_psd`` is refused), ``"auto"`` chooses it by the likelihood rule of
:func:`select_accel_psd` on :data:`JERK_GRID` and then once more with the
half-decades either side of that choice added (a white-jerk model is never
exact for a robot, so the likelihood has an interior maximum, and the decade
grid is coarse around it: on that log, 1e3 on the decades, 316 refined, RMS
2.91e-3 and 2.16e-3).  The likelihood is not the velocity's error: lower
densities smooth more and err less on these logs (9.5e-4 at 10), but the
innovations then say the model is wrong (``ρ`` 28), and no rule without the
truth picks them.  The band is the inflated noise band by default: the model
band, ``P^s`` under white jerk, covered 99.1–99.7 % of the truth on 12 s
logs of a UR5 and a Panda, the noise band 94.8–95.7 %.  On a robot whose
joints are all vector joints every covariance is a 3×3 factor times ``I``
(``P^s``, ``G``, the noise band's ``B, U``), so the whole smoother runs in
compiled passes over those factors (:func:`_white_jerk_smooth`, tested equal
to :class:`Smoother`): a few hundredths of the causal ``kf``'s time, instead
of 4–7× through :class:`Smoother`'s ``3 nv`` state.

``adaptive`` learns its model online, so its causal steps are not one model's
filter.  The smoother runs it causally once over the log (the learning pass,
unchanged but for the blend's model-free bank, which the models learned do not
depend on: it is left out, and the pass is rerun with it only should the
model-based filter be lost, which the bank restarts), keeps the model it holds
at the end of each ``model_window`` (default its ``horizon``, 10 s:
:meth:`AdaptiveEKF.snapshot`: learned dynamics, torque offset, the regime's
two densities), then smooths the EKF
with the offset state (``δq, δv, δd``) in which each window's samples are
predicted with *that window's end model*.  Chosen over the model the causal
pass held at each step because a window's end model was fitted on the
window's own samples (the learner keeps the last ``horizon`` seconds of
rows), so it is the best model the log offers for them, and the early
samples the causal pass ran with the nominal model (or in its warm-up) get
the learned one; within a window the model is one, so the backward pass is
that model's exact extended RTS smoother, and at a window boundary ``d``
absorbs the switch.  The blend with the model-free ``kf`` is not smoothed
(the output is the model-based smoother's).  ``accel_psd`` given replaces
every window's density and scales the offset's with it; ``None`` keeps the
regimes' densities; ``"auto"`` sets them from the log by the consistency rule
below (the learning pass runs once).

Consistency without the truth.  Under the filter's model ``x⁺ − x^s`` has
covariance ``P⁺ − P^s`` (the smoothed error is uncorrelated with the data),
so ``ρ``, the mean of ``(v^s − v⁺)ᵢ² / (P⁺ − P^s)_{vᵢvᵢ}``
(:attr:`Smoother.consistency`, :attr:`Smoothed.consistency`), is about 1
when the densities explain the log (tested on double integrators: 0.99–1.02
with the true density, 57–61 with 100× less, 0.45 with 100× more).  Over
``adaptive`` the regimes' densities (white acceleration 1e-6 rad²/s³, offset
1e-4 rad²/s⁵ once learned) are what the likelihood keeps on the learning
benchmark's 12 s model-error logs, yet the band covers 98.1–100 % of
samples (target 90–98 %).  A sweep of the two densities apart
(``benchmarks/smoothing_densities.py``) shows why: the learned model's
residual error is smooth in time, not white; the likelihood still keeps
the white acceleration, which helps the causal filter follow it, and while
``ρ`` follows the *filter's* calibration (``ρ`` ≈ its ``z²``, the mean squared
error over the claimed variance), the smoother's ``z²`` is only 0.2–0.7 of
the filter's when white acceleration carries the model error (the regimes'
white density, an offset density at or below theirs), because the forward
and backward filters lag the smooth error in opposite directions and their
errors cancel in the smoother.  Carried by the offset state instead (white
acceleration at 1e-2 or 1e-3 of the regimes', offset 0.1–10× theirs) the
smoother's ``z²`` is 0.6–1.1 of the filter's.  So ``"auto"`` over ``adaptive`` keeps the white
acceleration small and sets the offset density so that ``ρ = 1``
(:func:`consistent_offset_scale`, secant, 3–7 smoother passes): on the
learning benchmark's six scenarios at seeds 1 and 2 the band then covers
96.5–99.5 % of samples, within 90–98 % on 7 of 12 logs (regimes' densities:
98.1–100 %), with an RMS 0.80–1.11× the regimes' (README).  Designed on three of those
logs (UR5 payload and Panda friction at seed 1, UR5 torque scale at seed 2);
still conservative where the smoother gains more than its model says.

Three bands (``band``).  ``"model"``: ``v_std = sqrt(diag P^s)``, the posterior
under the filter's noise model, honest when the densities describe the
error (an exact model with ``accel_psd`` chosen by likelihood).  ``"noise"``:
the covariance of the *same* estimate's error driven by the measurement
noise alone, ``Pⁿˢ`` (:func:`_noise_step` forward, :func:`_backward`'s
``B, U`` recursion backward; on a linear model it equals the batch
estimate's ``(I − W C) T₀ P₀ T₀ᵀ (I − W C)ᵀ + σ² W Wᵀ``, tested): the error
a model error adds is left out, because a smooth one cancels between the
forward and backward passes (above; for a double integrator the filter's
velocity lags a slowly varying acceleration error ``w`` by about
``√2 w/ω`` and the smoother's by ``ẇ/ω²``, at the filter's bandwidth
``ω``).  The error moves by the Jacobian ``F`` of the filter's mean step,
which the filter's ``Φ`` (``A`` at the step's start) only approximates:
``F = exp(h Ā)``, ``Ā`` the mean of ``A`` at the step's two ends
(:meth:`~pinobs.observers.ekf.ExtendedKalmanFilter.predict_flow`, one
derivatives call more per sample; ``O(h³)``, 670× closer than ``Φ`` on a Panda
at 1 kHz).  With ``Φ`` in its place the band was too narrow on the Panda's
exact-model logs: over 20 noise draws on one 10 s log (seed 3, density
1e-12) the mean squared error was 1.31 of the band's variance (1.53–1.71 on
joints 1–3), 0.94 with ``F`` (tested on a linear model with ``F ≠ Φ``, where
the band equals the error covariance computed directly).  Over ``adaptive``
the error is propagated with ``Φ``: its regimes' densities give the filter a
short memory (bandwidth ``(q_w / σ² h)^{1/4}``: 18 rad/s learned, 5.6
nominal, at σ = 1e-4 and 1 kHz; 0.56 rad/s at the exact-model density
1e-12), over which ``Φ``'s error does not build up; with ``F`` the coverage
of the benchmark's 12 model-error logs of seeds 1 and 2 was the same to 0.1 %, and the
smoother cost 2.13–2.93× the causal run (medians of 5 pairs, three logs)
instead of 1.85–2.37×.  The band costs a few more products per sample (and over
``ekf`` that derivatives call).  A model error the smoother does not cancel
(learned friction's residual, a model learned badly) adds to the error, and
the noise band is then too narrow.  ``"inflated"`` widens it by the log's own
consistency, ``v_std = √max(1, ρ) · sqrt(diag Pⁿˢ)``: ``ρ`` is the mean
squared filter–smoother difference over the variance the model gives it, the
a-posteriori variance factor of least squares (``σ̂₀²``, Koch 1999,
*Parameter Estimation and Hypothesis Testing in Linear Models*, §3.2.2),
which scales a covariance whose noise levels are all off by one factor;
``ρ > 1`` says the log holds more error than the densities explain.  It is
floored at 1 because the noise band is the error the measurement noise alone
drives, which no model error takes away.  It is the default over
``adaptive`` with its regimes' densities, which are tuned for the causal
filter's tracking, not fitted to the log.  Found on the learning benchmark's
logs of seeds 1 and 2 (where ρ ordered the noise band's coverage: 88.1 and
88.8 % at ρ = 1.81 and 1.85, 92.1–96.7 % at ρ ≤ 1.01) and checked on seeds 3
and 4, held out (README): the noise band covered 75.1–96.4 %, within
90–98 % on 8 of 12 logs; inflated, 89.8–96.4 %, on 11 of 12.
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal, NamedTuple, Protocol, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import (
    ChunkWarning,
    ConfigurationError,
    ConsistencyWarning,
    CostWarning,
    DimensionError,
    GainError,
    LatencyWarning,
    NoiseWarning,
    NonFiniteError,
    ObserverDiverged,
    OptionError,
    TimestampError,
    TimestampWarning,
)
from pinobs.model import Robot
from pinobs.model.robot import read_only
from pinobs.model.sampling import on_ticks
from pinobs.observers.adaptive import AdaptiveEKF, ModelSnapshot
from pinobs.observers.base import (
    NOISE_FLOOR,
    GaussianFilter,
    Observer,
    Vector,
    make_observer,
    median_period,
    observer_class,
    observer_names,
    positive,
    time_unit_warning,
)
from pinobs.observers.ekf import ExtendedKalmanFilter
from pinobs.observers.kf import KFBank, KFGains, WhiteJerkFilter
from pinobs.observers.linalg import LazyKernel, cholesky_solve, lapack_posv
from pinobs.observers.noise import noise_from_log
from pinobs.tolerances import QUATERNION_NORM_TOL, TIME_EPS

__all__ = [
    "AUTO_WHITE_SCALE",
    "BANDS",
    "CHUNK_TOL",
    "COST_WARN",
    "DEFAULT_ACCEL_PSD",
    "DEFAULT_GRID",
    "JERK_GRID",
    "LATENCY_INTERVALS",
    "LIKELIHOOD_MARGIN",
    "OFFSET_SCALE_RANGE",
    "RHO_WARN",
    "LogLike",
    "Smoothed",
    "Smoother",
    "consistent_offset_scale",
    "default_overlap",
    "latency_note",
    "log_noise_std",
    "select_accel_psd",
    "select_latency",
    "smooth",
    "smooth_quietly",
    "smoothing_warnings",
    "streaming_smoother",
]

#: Default white-acceleration density of the smoothed filter [rad²/s³] (module docstring).
DEFAULT_ACCEL_PSD = 1e-8

#: Candidates of :func:`select_accel_psd` [rad²/s³]: every decade from 1e-14 to 1.
DEFAULT_GRID: tuple[float, ...] = tuple(float(10.0**e) for e in range(-14, 1))

#: Candidates of :func:`select_accel_psd` for the model-free ``kf`` (its white-jerk density
#: ``jerk_psd`` [rad²/s⁵]): every decade from 1e-4 to 1e8.
JERK_GRID: tuple[float, ...] = tuple(float(10.0**e) for e in range(-4, 9))

#: :func:`smooth` warns (:class:`~pinobs.errors.CostWarning`) when the overlap is more than this
#: many chunks: the backward pass then runs more than ``COST_WARN + 1`` times over each sample.
COST_WARN = 10

#: Log-likelihood margin [nats] of :func:`select_accel_psd`: χ²₁(0.95)/2.
LIKELIHOOD_MARGIN = 1.92

#: ``adaptive`` with ``accel_psd="auto"``: the white-acceleration density, as a fraction of each
#: window's regime's (the offset's is then set by :func:`consistent_offset_scale`).
AUTO_WHITE_SCALE = 1e-2

#: The range searched by :func:`consistent_offset_scale` (factors of the regimes' offset density).
OFFSET_SCALE_RANGE = (1e-3, 1e2)

#: What ``v_std`` states (:func:`smooth`'s ``band``): the smoother's posterior covariance under the
#: filter's noise model, the covariance of its error driven by the measurement noise alone, or
#: that noise band scaled by the log's consistency, ``√max(1, ρ)`` (:func:`smooth`).
BANDS = ("model", "noise", "inflated")

#: ``ρ`` (:attr:`Smoother.consistency`) above which :func:`smooth` says the model does not
#: explain the log (:func:`smoothing_warnings`).  Chosen between what was measured (README)
#: where the estimate and its band held, 0.68–1.17 on exact-model logs with
#: ``accel_psd="auto"`` and 0.48–5.05 over ``adaptive`` under the learning benchmark's model
#: errors (a known latency and a stale model included), and where they did not, 8.65–131
#: over ``adaptive`` under an unknown 1 ms latency (band coverage 13–37 %) and 95 to 3e9 over
#: ``ekf`` under those model errors: about the geometric mean of 5.05 and 8.65, a thin
#: margin on both sides (ρ is one number per log).
RHO_WARN = 6.5

#: Relative agreement the default overlap aims at: ``|v_chunked − v_whole| ≤ CHUNK_TOL · v_std``.
CHUNK_TOL = 1e-6

#: How many of a log's configurations (evenly spaced, the first sample's first) the default
#: overlap takes the inertia at, with a torque offset (:func:`default_overlap`).
OVERLAP_CONFIGURATIONS = 32


_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Smoothed:
    """Smoothed estimates, one row per log sample (read-only arrays).

    Attributes:
        t: sample times [s], shape ``(N,)``.
        q: smoothed configurations, shape ``(N, nq)``.
        v: smoothed velocities [rad/s or m/s], shape ``(N, nv)``.
        v_std: their standard deviations ``sqrt(diag P^s)`` [rad/s or m/s], shape ``(N, nv)``.
        log_likelihood: ``log p(q_1..q_N)`` of the measurements under the filter's
            model, the sum of the innovations' Gaussian log densities [nats]
            (for choosing ``accel_psd``: :func:`select_accel_psd`).
        consistency: the filter–smoother velocity consistency ``ρ``
            (:attr:`Smoother.consistency`, no ground truth): about 1 when the
            densities explain the log, ≫ 1 when they are too small (the band is
            too narrow), < 1 when too large; NaN with nothing to compare.
        options: the filter's resolved options and the smoother's (chunk, overlap, lag).
    """

    t: Vector
    q: Vector
    v: Vector
    v_std: Vector
    log_likelihood: float
    consistency: float
    options: dict[str, Any]

    def __post_init__(self) -> None:
        for k in ("t", "q", "v", "v_std"):
            object.__setattr__(self, k, read_only(getattr(self, k)))


class _Step(NamedTuple):
    """What the backward pass keeps of one sample."""

    filt: Any  # x⁺_k (a filter state: q, v, P[, d])
    pred: Any  # x⁻_{k+1} (None at the last sample seen so far)
    Phi: Any  # Φ_k (None likewise)
    noise: Any = None  # band="noise": (Pⁿ_k, K_k or None), the noise-driven covariance and gain
    F: Any = None  # band="noise": F_k, the Jacobian of the mean's step (None likewise)


def _gated(state: Any) -> bool:
    """Whether the filter's outlier gate rejected ``state``'s measurement (its ``gate``,
    :class:`~pinobs.observers.base.GateState`; a filter without a gate: never)."""
    gate = getattr(state, "gate", None)
    return gate is not None and bool(gate.gated)


def _noise_step(
    prev: tuple[Vector, Vector | None] | None,
    pred: Any,
    F: Any,
    state: Any,
    nv: int,
    meas_var: float,
) -> tuple[Vector, Vector | None]:
    """``(Pⁿ⁺_k, K_k)``: the filter's error covariance driven by the measurement noise alone.

    The filter's estimate is linear in the measurements (to first order); its
    error, under the model's own dynamics with no process noise, obeys (the
    actual covariance of a filter whose gains were designed for another noise
    model: Gelb, *Applied Optimal Estimation*, 1974, §7.2)::

        Pⁿ⁺_k = (I − K_k H) F_{k−1} Pⁿ⁺_{k−1} F_{k−1}ᵀ (I − K_k H)ᵀ + σ² K_k K_kᵀ

    with ``F_{k−1}`` the Jacobian of the mean's step, by which the error
    propagates (the filter's ``Φ`` only approximates it; ``F = Φ`` for a
    filter without ``predict_flow``), ``K_k = P⁻_k Hᵀ (H P⁻_k Hᵀ + σ² I)⁻¹ =
    P⁺_k Hᵀ / σ²`` the filter's own gain (``H = [I 0]``; the second form, free,
    holds for the Kalman gain: ``P⁺Hᵀ = P⁻Hᵀ − K (S − σ² I) = σ² K``;
    ``K = None`` at a dropped or gated sample, where ``Pⁿ⁺_k = F Pⁿ⁺_{k−1} Fᵀ``)
    and ``Pⁿ⁺_0 = P⁺_0`` (the start's uncertainty is kept).  Evaluated as
    ``Y = X − K X_q·``, ``Pⁿ⁺ = Y − (Y_·q − σ² K) Kᵀ`` with ``X = F Pⁿ⁺ Fᵀ``
    (as :func:`pinobs.observers.linalg.joseph_update`).
    """
    if prev is None:
        return state.P.copy(), None
    if state is pred or _gated(state):  # predicted over, not corrected
        return _noise_forward(prev[0], F, None, meas_var), None
    K = state.P[:, :nv] / meas_var
    return _noise_forward(prev[0], F, K, meas_var), K


def _noise_forward_loops(Pn: Vector, Phi: Vector, K: Vector, r: float, out: Vector) -> None:
    """:func:`_noise_forward` in loops (compiled by numba for small matrices); ``K`` with no
    columns: no correction."""
    m, nv = Pn.shape[0], K.shape[1]
    T = np.zeros((m, m))  # Φ Pn (Φ is sparse: its zeros skipped)
    for i in range(m):
        for k in range(m):
            a = Phi[i, k]
            if a != 0.0:
                for j in range(m):
                    T[i, j] += a * Pn[k, j]
    X = np.zeros((m, m))  # T Φᵀ
    for j in range(m):
        for k in range(m):
            a = Phi[j, k]
            if a != 0.0:
                for i in range(m):
                    X[i, j] += T[i, k] * a
    for i in range(m):  # Y = X − K X_q·, then out = Y − (Y_·q − r K) Kᵀ
        for j in range(m):
            t = X[i, j]
            for k in range(nv):
                t -= K[i, k] * X[k, j]
            T[i, j] = t
    for i in range(m):
        for j in range(m):
            t = T[i, j]
            for k in range(nv):
                t -= (T[i, k] - r * K[i, k]) * K[j, k]
            out[i, j] = t


def _noise_forward(Pn: Vector, Phi: Vector, K: Vector | None, r: float) -> Vector:
    """``(I − K H) Φ Pn Φᵀ (I − K H)ᵀ + r K Kᵀ`` (``K = None``: ``Φ Pn Φᵀ``), evaluated as
    ``X = Φ Pn Φᵀ``, ``Y = X − K X_q·``, ``Y − (Y_·q − r K) Kᵀ`` (as
    :func:`pinobs.observers.linalg.joseph_update`)."""
    m = Pn.shape[0]
    if m <= _NOISE_KERNEL_MAX and _noise_forward_kernel.compiled is not None:
        out = np.empty((m, m))
        k = _NO_GAIN if K is None else K
        _noise_forward_kernel.compiled(Pn, np.ascontiguousarray(Phi), k, r, out)
        return out
    X = Phi @ Pn @ Phi.T
    if K is None:
        return X
    nv = K.shape[1]
    Y = X - K @ X[:nv]
    return Y - (Y[:, :nv] - r * K) @ K.T


def _noise_backward_loops(
    B: Vector, U: Vector, G: Vector, Phi: Vector, K: Vector, Pn: Vector, r: float, var: Vector
) -> None:
    """:func:`_noise_backward` in loops, ``B`` and ``U`` updated in place (compiled by numba
    for small matrices); ``K`` with no columns: no correction at the later sample."""
    m, nk, nv = B.shape[0], K.shape[1], var.shape[0]
    D = np.zeros((m, m))  # B Φ − Φ, then − (B K) Φ_q·
    for i in range(m):
        for k in range(m):
            a = B[i, k]
            if a != 0.0:
                for j in range(m):
                    D[i, j] += a * Phi[k, j]
    D -= Phi
    if nk > 0:
        BK = np.zeros((m, nk))
        for i in range(m):
            for k in range(m):
                a = B[i, k]
                for j in range(nk):
                    BK[i, j] += a * K[k, j]
        for i in range(m):
            for k in range(nk):
                a = BK[i, k]
                for j in range(m):
                    D[i, j] -= a * Phi[k, j]
        for i in range(m):
            for j in range(m):
                t = 0.0
                for k in range(nk):
                    t += BK[i, k] * BK[j, k]
                U[i, j] += r * t
    T = np.zeros((m, m))  # U ← G U Gᵀ
    for i in range(m):
        for k in range(m):
            a = G[i, k]
            for j in range(m):
                T[i, j] += a * U[k, j]
    for i in range(m):
        for j in range(m):
            t = 0.0
            for k in range(m):
                t += T[i, k] * G[j, k]
            U[i, j] = t
    for i in range(m):  # B ← G D + I
        for j in range(m):
            t = 1.0 if i == j else 0.0
            for k in range(m):
                t += G[i, k] * D[k, j]
            B[i, j] = t
    for i in range(nv):  # (B Pn Bᵀ + U) at the velocity rows nv..2nv
        row = nv + i
        t = U[row, row]
        for j in range(m):
            a = 0.0
            for k in range(m):
                a += Pn[j, k] * B[row, k]
            t += B[row, j] * a
        var[i] = t


def _noise_backward(
    B: Vector, U: Vector, G: Vector, Phi: Vector, K: Vector | None, Pn: Vector, r: float, nv: int
) -> tuple[Vector, Vector, Vector]:
    """One step of :func:`_backward`'s ``B, U`` recursion: ``(B_k, U_k, var)`` from
    ``B_{k+1}, U_{k+1}`` (``K = K_{k+1}``, ``Pn = Pⁿ⁺_k``), ``var`` the velocity entries of
    ``B_k Pn B_kᵀ + U_k``."""
    m = B.shape[0]
    if m <= _NOISE_KERNEL_MAX and _noise_backward_kernel.compiled is not None:
        B, U, var = B.copy(), U.copy(), np.empty(nv)
        k = _NO_GAIN if K is None else K
        _noise_backward_kernel.compiled(
            B, U, np.ascontiguousarray(G), np.ascontiguousarray(Phi), k, Pn, r, var
        )
        return B, U, var
    BAPhi = B @ Phi
    if K is not None:
        BK = B @ K
        BAPhi -= BK @ Phi[:nv]  # B (I − K H) Φ, H Φ = Φ's first nv rows
        U = U + r * (BK @ BK.T)
    U = G @ U @ G.T
    B = G @ (BAPhi - Phi)
    B.flat[:: m + 1] += 1.0
    Bv = B[nv : 2 * nv]
    return B, U, np.einsum("ij,ij->i", Bv @ Pn, Bv) + U.diagonal()[nv : 2 * nv]


_NOISE_KERNEL_MAX = 20  # states: above, NumPy's BLAS products win (crossover measured at 21)
_NO_GAIN = np.empty((0, 0))
_noise_forward_kernel = LazyKernel(
    _noise_forward_loops, np.eye(2), np.eye(2), np.zeros((2, 1)), 1.0, np.zeros((2, 2))
)
_noise_backward_kernel = LazyKernel(
    _noise_backward_loops,
    np.eye(2),
    np.eye(2),
    np.eye(2),
    np.eye(2),
    np.zeros((2, 1)),
    np.eye(2),
    1.0,
    np.zeros(1),
)


def _forward(
    filt: GaussianFilter,
    rows: Iterator[tuple[float, Vector | None, Vector]],
    k0: int,
    flow: bool = False,
) -> Iterator[tuple[int, Any | None, Vector | None, Any, float, Vector | None]]:
    """The filter over a log's rows ``(t, q or None, tau)`` from its first good sample
    (``k0`` in the caller's numbering); pulls one row per value yielded.

    Yields ``(k, x⁻_k, Φ_{k−1}, x⁺_k, log N(e_k; 0, S_k), F_{k−1})`` (``None, None,
    ·, 0, None`` at ``k = 0``; ``x⁺_k = x⁻_k`` and 0 at a dropped sample; ``F`` the
    Jacobian of the mean's step with ``flow`` (:class:`GaussianFilter`), else
    ``None``), where
    ``e_k = q_k ⊖ q⁻_k`` and ``S_k = P⁻_qq + σ² I`` are the innovation and its
    covariance (the prediction-error decomposition of the likelihood,
    Schweppe 1965, "Evaluation of likelihood functions for Gaussian signals").
    A sample the filter's outlier gate rejects (``NIS = eᵀ S⁻¹ e`` above the gate's ``g``)
    counts as at the gate, ``NIS`` replaced by ``g``: the log-density of the contaminated
    Gaussian ``(1 − ε) N(e; 0, S) + ε u`` (Huber 1964, "Robust estimation of a location
    parameter") by its larger component, ``u`` level with ``N`` at the gate, so that one
    glitch does not decide a density or a latency (it did: one sample 1 rad off moved
    ``"auto"`` from 1e-9 to 1 on a 2 s UR5 log, the RMS from 1.4e-5 to 1.3e-2 rad/s).
    """
    model = filt.robot
    nv = model.nv
    meas_var = filt.gains.meas_std**2
    t_prev, q0, tau_prev = next(rows)
    if q0 is None:
        raise NonFiniteError(f"sample {k0} has no configuration; the smoother starts on one")
    state = filt.initial_state(model.check_configuration(q0, what=f"q[{k0}]"), np.zeros(nv))
    yield 0, None, None, state, 0.0, None
    for k, (t, q, tau) in enumerate(rows, start=1):
        F: Vector | None = None
        if flow:
            pred, Phi, F = filt.predict_flow(state, float(t - t_prev), tau_prev)
        else:
            pred, Phi = filt.predict(state, float(t - t_prev), tau_prev)
        ll = 0.0
        if q is not None:
            q_meas = model.check_configuration(q, what=f"q[{k0 + k}]")
            e = model.difference(pred.q, q_meas)
            # S = U'U (LAPACK dposv: the factor and S⁻¹e at once); log det S = 2 Σ log Uᵢᵢ
            chol, s_inv_e, info = lapack_posv()(pred.P[:nv, :nv] + meas_var * np.eye(nv), e)
            if info != 0:
                raise NonFiniteError(
                    f"sample {k0 + k} (t = {t:.6g} s): the filter is lost (its innovation "
                    "covariance is not positive definite): the model does not explain the log "
                    "at these densities; check the model and the torques, or smooth with "
                    "accel_psd='auto' or observer='adaptive'"
                )
            nis = float(e @ s_inv_e)
            state = filt.correct(pred, q_meas)
            if _gated(state):  # rejected by the filter's outlier gate
                nis = min(nis, filt.gate_limit(state))
            ll = -(0.5 * nis + np.log(np.diagonal(chol)).sum() + 0.5 * nv * _LOG_2PI)
        else:
            state = pred
        t_prev, tau_prev = t, tau
        yield k, pred, Phi, state, ll, F


def _rows(
    t: Vector, q: Vector, tau: Vector, good: Vector
) -> Iterator[tuple[float, Vector | None, Vector]]:
    return ((float(t[k]), q[k] if good[k] else None, tau[k]) for k in range(t.size))


class _Fed:
    """An iterator over a queue the caller fills before each pull (push-driven :func:`_forward`)."""

    def __init__(self) -> None:
        self.queue: deque[tuple[float, Vector | None, Vector]] = deque()

    def __iter__(self) -> _Fed:
        return self

    def __next__(self) -> tuple[float, Vector | None, Vector]:
        if not self.queue:
            raise StopIteration
        return self.queue.popleft()


class Smoother:
    """The smoother fed one sample at a time (what :func:`smooth` runs on arrays).

    :meth:`push` runs the filter one step and, each time ``chunk`` samples and
    after them ``overlap`` measured ones are buffered (a sample without a
    measurement does not contract the backward pass's error: a gap in the overlap
    would shorten it), the backward pass over them, returning the first
    ``chunk`` samples smoothed; :meth:`close` smooths the rest.  Memory: the
    buffered samples' states.  Samples are numbered from 0 (the first pushed,
    which must carry a configuration); each result is
    ``(k, q^s_k, v^s_k, var v^s_k)``, in order.

    Attributes:
        log_likelihood: the innovations' summed log densities so far [nats].
        consistency: ``ρ``, the mean over the samples smoothed so far and their
            velocity coordinates of ``(v^s_k − v⁺_k)ᵢ² / (P⁺_k − P^s_k)_{vᵢvᵢ}``
            (NaN before any).  Under the filter's model the smoothed error
            ``x^s − x`` is uncorrelated with every measurement, hence with
            ``x⁺ − x^s`` (a function of them), so ``P⁺ = Cov(x⁺ − x^s) + P^s``:
            ``x⁺ − x^s`` has covariance ``P⁺ − P^s`` and ``E[ρ] = 1``, a check of the
            densities from the log alone (tested on a linear Gaussian model).  ``ρ ≫ 1``: the model
            error is larger than the densities say (bands too narrow); ``ρ < 1``:
            smaller.  It tests the filter's covariance, which the smoother's
            inherits; measured under a learned model's smooth residual error
            (module docstring) the smoother's band is wider than ``ρ`` says.

    Args:
        filt: the filter (a :class:`GaussianFilter`).
        chunk: samples smoothed per backward pass (``None``: everything at :meth:`close`).
        overlap: measured samples after a chunk that its backward pass starts from.
    """

    def __init__(
        self, filt: GaussianFilter, chunk: int | None, overlap: int, band: str = "model"
    ) -> None:
        if band not in BANDS[:2]:  # "inflated" needs the whole log's ρ: smooth() scales at the end
            raise OptionError(f"band={band!r}: a Smoother gives one of {list(BANDS[:2])}")
        self._fed = _Fed()
        self._gen = _forward(filt, self._fed, 0, flow=band == "noise")
        self._model = filt.robot
        self._chunk, self._over = chunk, overlap
        self._meas_var = float(filt.gains.meas_std**2)
        self._noise: tuple[Vector, Vector | None] | None = None  # band="noise": (Pⁿ⁺, K) last
        if band == "noise" and 2 * self._model.nv <= _NOISE_KERNEL_MAX:
            _noise_forward_kernel.load()
            _noise_backward_kernel.load()
        self._band = band
        self._buf: list[_Step] = []
        self._measured: list[bool] = []  # each buffered sample's: had a configuration
        self._tail = 0  # how many of the buffered samples after the first chunk were measured
        self._start = 0
        self.log_likelihood = 0.0
        self._rho_sum, self._rho_n = 0.0, 0

    @property
    def consistency(self) -> float:
        """``ρ`` over the samples smoothed so far (class docstring); NaN before any."""
        return self._rho_sum / self._rho_n if self._rho_n else math.nan

    @property
    def consistency_terms(self) -> int:
        """How many (sample, joint) terms :attr:`consistency` averages (to pool logs' ``ρ``)."""
        return self._rho_n

    def push(
        self, t: float, q: Vector | None, tau: Vector
    ) -> list[tuple[int, Vector, Vector, Vector]]:
        """One sample: ``t`` [s], measured ``q`` (``None``: dropped), ``tau`` held from ``t``."""
        self._fed.queue.append((t, q, tau))
        _, pred, Phi, state, ll, F = next(self._gen)
        self.log_likelihood += ll
        if self._band == "noise":
            nv = self._model.nv
            self._noise = _noise_step(self._noise, pred, F, state, nv, self._meas_var)
        if pred is not None:
            self._buf[-1] = self._buf[-1]._replace(pred=pred, Phi=Phi, F=F)
        self._buf.append(_Step(state, None, None, self._noise))
        self._measured.append(q is not None)
        if self._chunk is None:
            return []
        if len(self._buf) > self._chunk:
            self._tail += q is not None
        if len(self._buf) >= self._chunk + self._over and self._tail >= self._over:
            done = self._back(self._chunk)
            self._tail = sum(self._measured[self._chunk :])
            return done
        return []

    def close(self) -> list[tuple[int, Vector, Vector, Vector]]:
        """Smooth the samples still buffered (the log's end: no later samples)."""
        return self._back(len(self._buf)) if self._buf else []

    def _back(self, keep: int) -> list[tuple[int, Vector, Vector, Vector]]:
        nv = self._model.nv
        out: list[tuple[int, Vector, Vector, Vector]] = []

        var_s: list[Vector] = []  # diag P^s, for ρ

        def emit(i: int, qs: Vector, vs: Vector, var: Vector, var_n: Vector | None) -> None:
            if i < keep:
                band = var if var_n is None else var_n
                out.append((self._start + i, qs, vs, band[nv : 2 * nv]))
                var_s.append(var[nv : 2 * nv])

        _backward(self._model, self._buf, emit, self._meas_var)
        if out:  # ρ's terms (v^s − v⁺)² / (P⁺ − P^s)_vv, where that variance is not ~0
            filt = [step.filt for step in reversed(self._buf[:keep])]  # out's order: last first
            var_f = np.array([f.P.diagonal()[nv : 2 * nv] for f in filt])
            dvar = var_f - np.array(var_s)
            diff = np.array([o[2] for o in out]) - np.array([f.v for f in filt])
            ok = dvar > 1e-9 * var_f  # not at the last sample (the smoother is the filter there)
            self._rho_sum += float(np.sum(diff[ok] ** 2 / dvar[ok]))
            self._rho_n += int(np.count_nonzero(ok))
        del self._buf[:keep], self._measured[:keep]
        self._start += keep
        out.reverse()
        return out


def _plain(state: Any) -> Vector:
    """The vector-space part of the error state: ``v`` (and the torque offset ``d``)."""
    d = getattr(state, "d", None)
    return state.v if d is None else np.concatenate([state.v, d])


def _backward(
    robot: Robot,
    steps: Sequence[_Step],
    emit: Callable[[int, Vector, Vector, Vector, Vector | None], None],
    meas_var: float = 0.0,
) -> None:
    """RTS backward pass over ``steps`` (module docstring), from the last one's filtered state.

    Calls ``emit(i, q^s_i, v^s_i, diag P^s_i, diag Pⁿˢ_i)`` for every index, last
    first; ``Pⁿˢ`` (``None`` unless the steps carry :func:`_noise_step`'s
    covariances; its velocity entries only, the others NaN) is the smoothed
    error's covariance driven by the measurement noise alone.  The smoothed error obeys
    ``e^s_k = e⁺_k + G_k (e^s_{k+1} − F_k e⁺_k)`` with
    ``e⁺_{k+1} = A_{k+1} F_k e⁺_k + K_{k+1} n_{k+1}`` (``A = I − K H``, no process
    noise; ``F_k`` the Jacobian of the mean's step, :func:`_noise_step`, while
    ``G_k`` is the smoother's, from ``Φ_k``), so ``e^s_k = B_k e⁺_k + u_k`` with
    ``u_k`` independent of ``e⁺_k``::

        B_k = I + G_k (B_{k+1} A_{k+1} F_k − F_k)                 B_N = I
        U_k = G_k (σ² B_{k+1} K_{k+1} K_{k+1}ᵀ B_{k+1}ᵀ + U_{k+1}) G_kᵀ   U_N = 0
        Pⁿˢ_k = B_k Pⁿ⁺_k B_kᵀ + U_k

    (at the window's end the smoother is the filter: ``B = I``, ``U = 0``).
    """
    nv = robot.nv
    last = steps[-1]
    q_s, x_s, P_s = last.filt.q, _plain(last.filt), last.filt.P
    noise = last.noise is not None
    if noise:
        m = P_s.shape[0]
        B: Vector = np.eye(m)
        U: Vector = np.zeros((m, m))
    var_n = None
    if noise:
        var_n = np.full(m, np.nan)
        var_n[nv : 2 * nv] = last.noise[0].diagonal()[nv : 2 * nv]
    emit(len(steps) - 1, q_s, x_s[:nv], np.diag(P_s), var_n)
    for i in range(len(steps) - 2, -1, -1):
        filt, pred, Phi, pn_k, F = steps[i]
        # G_k = P⁺_k Φ_kᵀ (P⁻_{k+1})⁻¹, as (P⁻⁻¹ Φ P⁺)ᵀ (P symmetric)  [Särkkä 2013, Thm 8.2]
        G = cholesky_solve(pred.P, Phi @ filt.P)[0].T
        # δ_k = G_k (x^s_{k+1} ⊖ x⁻_{k+1}); x^s_k = x⁺_k ⊕ δ_k  [ibid., mean on the manifold]
        delta = G @ np.concatenate([robot.difference(pred.q, q_s), x_s - _plain(pred)])
        q_s = robot.integrate(filt.q, delta[:nv])
        x_s = _plain(filt) + delta[nv:]
        # P^s_k = P⁺_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ  [ibid.]
        P_s = filt.P + G @ (P_s - pred.P) @ G.T
        P_s = 0.5 * (P_s + P_s.T)
        var_n = None
        if noise:  # the docstring's B, U recursion
            var_n = np.full(m, np.nan)  # the velocity entries: all that v_std needs
            B, U, var_n[nv : 2 * nv] = _noise_backward(
                B, U, G, F, steps[i + 1].noise[1], pn_k[0], meas_var, nv
            )
        emit(i, q_s, x_s[:nv], np.diag(P_s), var_n)


def _jerk_noise_loops(PX: Vector, t: Vector, measured: Vector, r: float, Pn: Vector) -> None:
    """:func:`_noise_step` for the white-jerk filter on its 3×3 factor (``P = P₃ ⊗ I``, so
    ``Pⁿ = Pⁿ₃ ⊗ I``), every row: ``Pⁿ₀ = P⁺₀``, then ``X = F Pⁿ_{k−1} Fᵀ`` and, at a row
    corrected with its measurement (``measured``: neither dropped nor gated), ``K = P⁺_k[:, 0] /
    σ²``, ``Y = X − K X₀·``, ``Pⁿ_k = Y − (Y·₀ − σ² K) Kᵀ``."""
    F, T, X, K = np.eye(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    for i in range(3):
        for j in range(3):
            Pn[0, i, j] = PX[0, i, j]
    for k in range(1, t.size):
        h = t[k] - t[k - 1]
        F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h  # F(h) (pinobs.observers.kf.transition)
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += F[i, m] * Pn[k - 1, m, j]
                T[i, j] = s
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += T[i, m] * F[j, m]
                X[i, j] = s
        if not measured[k]:
            for i in range(3):
                for j in range(3):
                    Pn[k, i, j] = X[i, j]
            continue
        for i in range(3):
            K[i] = PX[k, i, 0] / r
        for i in range(3):
            for j in range(3):
                T[i, j] = X[i, j] - K[i] * X[0, j]
        for i in range(3):
            for j in range(3):
                Pn[k, i, j] = T[i, j] - (T[i, 0] - r * K[i]) * K[j]


def _jerk_backward_loops(
    X: Vector,
    PX: Vector,
    Pn: Vector,
    t: Vector,
    measured: Vector,
    jerk: float,
    r: float,
    start: int,
    stop: int,
    keep: int,
    noise: bool,
    qs: Vector,
    vs: Vector,
    var: Vector,
    rho: Vector,
) -> None:
    """:func:`_backward` (and :class:`Smoother`'s ``ρ`` terms) for the white-jerk filter on the
    rows ``start..stop−1``, from the filtered state at ``stop − 1``, in loops (compiled by
    numba).  Every direction shares ``F``, ``Q`` and ``H``, so the gain is ``G₃ ⊗ I`` with
    ``G₃ = P⁺₃ Fᵀ (P⁻₃)⁻¹`` (3×3) and the means move joint by joint; the covariances
    (``P^s``, the noise band's ``B, U``) are their 3×3 factors.  Writes the rows
    ``start..start+keep−1``: ``qs``, ``vs`` and ``var`` (the velocity variance of the model band,
    or of the noise band with ``noise``; one per row, every direction's), and adds ``ρ``'s sum
    and count to ``rho``.  ``X[k] = (q, v, a)`` and ``PX[k]`` the filter's (from
    :meth:`pinobs.observers.kf.KFBank.run`, ``measured`` its rows corrected), ``Pn``
    :func:`_jerk_noise_loops`'."""
    nv = X.shape[2]
    F, Q, W, Pp, L = (
        np.eye(3),
        np.empty((3, 3)),
        np.empty((3, 3)),
        np.empty((3, 3)),
        np.zeros((3, 3)),
    )
    G, T, D, B, U = (
        np.empty((3, 3)),
        np.empty((3, 3)),
        np.empty((3, 3)),
        np.eye(3),
        np.zeros((3, 3)),
    )
    xs, xp, BK = np.empty((3, nv)), np.empty(3), np.empty(3)
    Ps = np.empty((3, 3))
    last = stop - 1
    for i in range(3):
        for j in range(nv):
            xs[i, j] = X[last, i, j]
        for j in range(3):
            Ps[i, j] = PX[last, i, j]
    if last - start < keep:  # the smoother is the filter there: no ρ term
        for j in range(nv):
            qs[last, j], vs[last, j] = xs[0, j], xs[1, j]
        var[last] = Pn[last, 1, 1] if noise else Ps[1, 1]
    for k in range(last - 1, start - 1, -1):
        h = t[k + 1] - t[k]  # F(h), Q(h) (pinobs.observers.kf.transition)
        F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h
        Q[0, 0], Q[0, 1], Q[0, 2] = jerk * h**5 / 20, jerk * h**4 / 8, jerk * h**3 / 6
        Q[1, 1], Q[1, 2], Q[2, 2] = jerk * h**3 / 3, jerk * h**2 / 2, jerk * h
        Q[1, 0], Q[2, 0], Q[2, 1] = Q[0, 1], Q[0, 2], Q[1, 2]
        for i in range(3):  # W = F P⁺_k, P⁻_{k+1} = W Fᵀ + Q
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += F[i, m] * PX[k, m, j]
                W[i, j] = s
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += W[i, m] * F[j, m]
                Pp[i, j] = s + Q[i, j]
        for j in range(3):  # P⁻ = L Lᵀ
            s = Pp[j, j]
            for m in range(j):
                s -= L[j, m] * L[j, m]
            L[j, j] = math.sqrt(s) if s > 0.0 else math.nan  # lost: NaN, reported by smooth()
            for i in range(j + 1, 3):
                s = Pp[i, j]
                for m in range(j):
                    s -= L[i, m] * L[j, m]
                L[i, j] = s / L[j, j]
        for c in range(3):  # Gᵀ = (P⁻)⁻¹ W, column by column  [Särkkä 2013, Thm 8.2]
            for i in range(3):
                s = W[i, c]
                for m in range(i):
                    s -= L[i, m] * G[c, m]
                G[c, i] = s / L[i, i]
            for i in range(2, -1, -1):
                s = G[c, i]
                for m in range(i + 1, 3):
                    s -= L[m, i] * G[c, m]
                G[c, i] = s / L[i, i]
        for j in range(nv):  # x^s_k = x⁺_k + G (x^s_{k+1} − x⁻_{k+1}), joint by joint
            q, v, a = X[k, 0, j], X[k, 1, j], X[k, 2, j]
            xp[0], xp[1], xp[2] = q + v * h + 0.5 * h * h * a, v + h * a, a
            d0, d1, d2 = xs[0, j] - xp[0], xs[1, j] - xp[1], xs[2, j] - xp[2]
            for i in range(3):
                xs[i, j] = X[k, i, j] + G[i, 0] * d0 + G[i, 1] * d1 + G[i, 2] * d2
        for i in range(3):  # P^s_k = P⁺_k + G (P^s_{k+1} − P⁻_{k+1}) Gᵀ
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += G[i, m] * (Ps[m, j] - Pp[m, j])
                T[i, j] = s
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(3):
                    s += T[i, m] * G[j, m]
                W[i, j] = PX[k, i, j] + s
        for i in range(3):
            for j in range(3):
                Ps[i, j] = 0.5 * (W[i, j] + W[j, i])
        if noise:  # _noise_backward's B, U recursion, K = K_{k+1}
            for i in range(3):
                for j in range(3):
                    s = 0.0
                    for m in range(3):
                        s += B[i, m] * F[m, j]
                    D[i, j] = s - F[i, j]
            if measured[k + 1]:
                for i in range(3):
                    s = 0.0
                    for m in range(3):
                        s += B[i, m] * PX[k + 1, m, 0]
                    BK[i] = s / r
                for i in range(3):
                    for j in range(3):
                        D[i, j] -= BK[i] * F[0, j]
                        U[i, j] += r * BK[i] * BK[j]
            for i in range(3):  # U ← G U Gᵀ
                for j in range(3):
                    s = 0.0
                    for m in range(3):
                        s += G[i, m] * U[m, j]
                    T[i, j] = s
            for i in range(3):
                for j in range(3):
                    s = 0.0
                    for m in range(3):
                        s += T[i, m] * G[j, m]
                    W[i, j] = s
            for i in range(3):  # B ← G D + I
                for j in range(3):
                    U[i, j] = W[i, j]
                    s = 1.0 if i == j else 0.0
                    for m in range(3):
                        s += G[i, m] * D[m, j]
                    T[i, j] = s
            for i in range(3):
                for j in range(3):
                    B[i, j] = T[i, j]
        if k - start >= keep:
            continue
        for j in range(nv):
            qs[k, j], vs[k, j] = xs[0, j], xs[1, j]
        if noise:  # (B Pⁿ_k Bᵀ + U)₁₁
            s = U[1, 1]
            for i in range(3):
                for j in range(3):
                    s += B[1, i] * Pn[k, i, j] * B[1, j]
            var[k] = s
        else:
            var[k] = Ps[1, 1]
        dvar = PX[k, 1, 1] - Ps[1, 1]
        if dvar > 1e-9 * PX[k, 1, 1]:  # as Smoother: not where the smoother is the filter
            for j in range(nv):
                rho[0] += (xs[1, j] - X[k, 1, j]) ** 2 / dvar
            rho[1] += nv


_jerk_noise_kernel = LazyKernel(
    _jerk_noise_loops, np.tile(np.eye(3), (2, 1, 1)), np.array([0.0, 1e-3]),
    np.array([False, True]), 1.0, np.zeros((2, 3, 3)),
)  # fmt: skip
_jerk_backward_kernel = LazyKernel(
    _jerk_backward_loops, np.zeros((2, 3, 1)), np.tile(np.eye(3), (2, 1, 1)),
    np.tile(np.eye(3), (2, 1, 1)), np.array([0.0, 1e-3]), np.array([False, True]), 1.0, 1.0,
    0, 2, 2, True, np.zeros((2, 1)), np.zeros((2, 1)), np.zeros(2), np.zeros(2),
)  # fmt: skip


def _white_jerk_smooth(
    filt: WhiteJerkFilter,
    arrays: tuple[Vector, Vector, Vector, Vector],
    chunk: int | None,
    overlap: int,
    band: str,
) -> tuple[Vector, Vector, Vector, float, float, int]:
    """What :class:`Smoother` gives over ``filt`` (pushed ``arrays``' rows, ``chunk`` and
    ``overlap`` as there), on a robot whose joints are all vector joints, in compiled passes:
    the forward one (:meth:`pinobs.observers.kf.KFBank.run`, its states stored: ``3 nv + 9``
    numbers a row, and ``9`` more for the noise band), then the backward one per window
    (:func:`_jerk_backward_loops`).  Returns ``q^s``, ``v^s``, the band's velocity variance
    (every direction's), ``log_likelihood``, ``ρ``'s sum and count; tested equal to
    :class:`Smoother` (which costs about 4–7× the causal ``kf``)."""
    t, q, _, good = arrays
    gains = filt.gains
    bank = KFBank(filt.robot, (gains.jerk_psd,), gains.meas_std, gains.outlier_probability)
    ll, X, PX, used = bank.run(t, q, good, filt.v0_std)  # used: corrected (measured, not gated)
    t = np.ascontiguousarray(t, dtype=float)
    r, n, nv = gains.meas_std**2, t.size, filt.robot.nv
    noise = band == "noise"
    _jerk_backward_kernel.load()
    Pn = PX
    if noise:
        _jerk_noise_kernel.load()
        Pn = np.empty_like(PX)
        cast(Any, _jerk_noise_kernel.compiled)(PX, t, used, r, Pn)
    qs, vs, var, rho = np.empty((n, nv)), np.empty((n, nv)), np.empty(n), np.zeros(2)
    chunk = n if chunk is None else chunk
    windows, start = [], 0
    measured = np.concatenate([[0], np.cumsum(good)])  # measured rows before each row
    while overlap and start + chunk + overlap <= n:  # overlap: measured rows (as Smoother)
        stop = max(
            start + chunk + overlap,
            int(np.searchsorted(measured, measured[start + chunk] + overlap)),
        )
        if stop > n:
            break
        windows.append((start, stop, chunk))
        start += chunk
    if start < n:
        windows.append((start, n, n - start))
    for start, stop, keep in windows:
        cast(Any, _jerk_backward_kernel.compiled)(
            X, PX, Pn, t, used, gains.jerk_psd, r, start, stop, keep, noise, qs, vs, var, rho
        )
    return qs, vs, np.repeat(var[:, None], nv, axis=1), float(ll[0]), float(rho[0]), int(rho[1])


def default_overlap(
    accel_psd: float,
    meas_std: float,
    dt: float,
    tol: float = CHUNK_TOL,
    *,
    disturbance_psd: float | None = None,
    mass_matrices: Sequence[Vector] | None = None,
) -> float:
    """The overlap [s] after which a window's start-up error has decayed to ``tol`` of ``v_std``.

    The backward pass forgets its end condition at the rate of the steady-state
    filter's slowest pole (the smoother's backward dynamics has the mirror
    poles), hence ``overlap = ln(1/tol) / min |Re s|``.  The filter of a double
    integrator with white acceleration ``q_w`` [rad²/s³] measured with noise
    ``σ`` [rad] every ``h`` [s] (a noise density ``r = σ² h``) has the poles
    ``ω e^{±3iπ/4}``, ``ω = (q_w / r)^{1/4}``: ``overlap = √2 ln(1/tol) / ω``.

    With the EKF's torque-offset state (``disturbance_psd`` ``j`` [rad²/s⁵], a
    random walk converted per joint as ``j M̄ᵢᵢ²`` [N²·m²/s] with ``M̄`` the
    inertia at the filter's first sample, acting through ``M(q)⁻¹``) the
    offset's acceleration density is ``S = M⁻¹ diag(j M̄ᵢᵢ²) M⁻¹``.  In the
    eigenbasis of ``S`` (orthogonal, so the measurement and the white
    acceleration stay isotropic) each direction is a double integrator plus an
    acceleration bias of density ``λ`` (an eigenvalue of ``S``), the measured
    position's spectrum ``r + q_w/ω⁴ + λ/ω⁶``; the filter's poles are the
    left-half-plane roots of ``r s⁶ + q_w s² − λ = 0`` (its spectral factor).
    With ``u = s²`` the cubic ``r u³ + q_w u − λ`` has one positive root ``u₊``
    (a real pole, ``√u₊``, the offset's memory) and ``−u₊/2 ± i b`` with
    ``|u|² = λ / (r u₊)`` (the bandwidth's pair, ``Re s = √((|u| − u₊/2)/2)``).
    ``λ → 0``: the first case; ``q_w = 0``: third-order Butterworth poles,
    ``overlap = 2 ln(1/tol) / (λ/r)^{1/6}``.  The coupling of ``M`` matters: on
    a UR5 or a Panda the smallest ``λ`` is 0.07–0.1 ``j``, on the planar 3R
    0.02 ``j``, and the real pole ``≈ √(λ/q_w)`` then sets overlaps of 4–10 s
    where the isotropic ``λ = j`` gives 1.4 s (measured on a planar 3R's
    adaptive smoothing: 0.41 s of overlap left 3.2e-3 of ``v_std`` between the
    chunked and whole-log results, 9.45 s 5.5e-9).

    Args:
        mass_matrices: ``M(q)`` at configurations the log visits, the first at
            its first sample (``M̄``); ``None``: ``S = j I`` (the model-free
            ``kf``, white jerk ``jerk_psd``: ``accel_psd = 0``,
            ``disturbance_psd = jerk_psd``).  The overlap is the longest over
            them: the poles move with ``q`` and the time-varying filter is not
            the steady state of any of them (tested against the whole-log
            smoother, :mod:`tests.observers.test_smoothing`).
    """
    r = meas_std**2 * dt
    if accel_psd <= 0.0 and disturbance_psd is None:
        raise GainError(f"accel_psd={accel_psd!r} and no disturbance_psd: a filter without memory")
    if disturbance_psd is None:
        return math.sqrt(2.0) * math.log(1.0 / tol) / (accel_psd / r) ** 0.25
    if mass_matrices is None:
        densities = np.array([disturbance_psd])
    else:
        m_bar = np.diag(mass_matrices[0])
        densities = np.concatenate(
            [
                np.linalg.eigvalsh(_offset_density(m, disturbance_psd * m_bar**2))
                for m in mass_matrices
            ]
        )
    return math.log(1.0 / tol) / min(_slowest_pole(r, accel_psd, lam) for lam in densities)


def _offset_density(mass: Vector, torque_psd: Vector) -> Vector:
    """``M⁻¹ diag(torque_psd) M⁻¹``: a torque random walk's acceleration density."""
    m_inv = np.linalg.inv(mass)
    return (m_inv * torque_psd) @ m_inv


def _slowest_pole(r: float, q_w: float, lam: float) -> float:
    """``min |Re s|`` over the left-half-plane roots of ``r s⁶ + q_w s² − λ`` (:func:`default_overlap`)."""
    if lam <= 0.0:
        return 0.0  # an offset never driven: never forgotten
    if q_w <= 0.0:
        u = (lam / r) ** (1.0 / 3.0)
    else:  # the real root of u³ + p u − λ/r, p = q_w/r > 0 (trigonometric form: no cancellation)
        p = q_w / r
        u = (
            2.0
            * math.sqrt(p / 3.0)
            * math.sinh(math.asinh(1.5 * lam / (r * p) * math.sqrt(3.0 / p)) / 3.0)
        )
    pair = math.sqrt(lam / (r * u))  # |u| of the complex pair
    return min(math.sqrt(u), math.sqrt(max(pair - 0.5 * u, 0.0) / 2.0))


def _spread(rows: Vector) -> Vector:
    """At most :data:`OVERLAP_CONFIGURATIONS` of ``rows``, evenly spaced, the first kept."""
    pick = np.linspace(0, len(rows) - 1, min(len(rows), OVERLAP_CONFIGURATIONS)).astype(int)
    return rows[np.unique(pick)]


def _samples(seconds: float, dt: float, what: str) -> int:
    positive(what, seconds)
    return max(1, math.ceil(seconds / dt - 1e-9))


class LogLike(Protocol):
    """Anything with a log's arrays ``t``, ``q`` (measured), ``tau``: :class:`pinobs.io.Log`.

    An object that also has ``q_meas`` (a :class:`pinobs.Result`, whose ``q`` is
    the truth) is read through ``q_meas``.
    """

    @property
    def t(self) -> Vector: ...
    @property
    def q(self) -> Vector: ...
    @property
    def tau(self) -> Vector | None: ...


def _log_arrays(
    robot: Robot, log: LogLike | Sequence[ArrayLike] | Mapping[str, ArrayLike]
) -> tuple[Vector, Vector, Vector]:
    """``(t, q, tau)`` of a log, checked (``tau`` zero when the log has none)."""
    if isinstance(log, (tuple, list)):
        if len(log) not in (2, 3):
            raise DimensionError(f"log is a tuple of {len(log)} arrays; give (t, q) or (t, q, tau)")
        t, q, tau = (*log, None)[:3]
    elif isinstance(log, Mapping):
        if not {"t", "q"} <= set(log):
            raise DimensionError(f"log has the keys {sorted(log)}; give 't', 'q' (and 'tau')")
        t, q, tau = log["t"], log["q"], log.get("tau")
    elif hasattr(log, "t") and hasattr(log, "q"):
        # a Result's q is the truth: its measurements are q_meas
        t, q, tau = log.t, getattr(log, "q_meas", log.q), getattr(log, "tau", None)
    else:
        raise DimensionError(
            f"log is a {type(log).__name__}; give a pinobs.io.Log, a pinobs.Result, (t, q) or "
            "(t, q, tau) arrays, or a mapping with 't', 'q' (and 'tau')"
        )
    t_arr = np.asarray(t, dtype=float)
    q_arr = np.asarray(q, dtype=float)
    if t_arr.ndim != 1 or t_arr.size < 2:
        raise DimensionError(f"t has shape {t_arr.shape}; give a 1-D array of at least 2 times [s]")
    n = t_arr.size
    if q_arr.shape != (n, robot.nq):
        raise DimensionError(
            f"q has shape {q_arr.shape}; robot {robot.name!r} with {n} times needs ({n}, {robot.nq})"
        )
    if not np.all(np.isfinite(t_arr)):
        bad = int(np.flatnonzero(~np.isfinite(t_arr))[0])
        raise TimestampError(f"t[{bad}] = {t_arr[bad]!r} is not finite; every time must be")
    steps = np.diff(t_arr)
    if np.any(steps <= 0):
        bad = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise TimestampError(
            f"t[{bad}] = {t_arr[bad]!r} s is not after t[{bad - 1}] = {t_arr[bad - 1]!r} s; "
            "timestamps must be strictly increasing"
        )
    off = np.flatnonzero(robot.off_unit_rows(q_arr))
    if off.size:  # refused before the passes, not at the row, after minutes (a sweep found it)
        rows = ", ".join(map(str, off[:5])) + (", …" if off.size > 5 else "")
        raise ConfigurationError(
            f"{off.size} rows of q have a quaternion or (cos, sin) pair off unit norm by more "
            f"than {QUATERNION_NORM_TOL:g} (rows {rows}; row {off[0]}: {q_arr[off[0]].tolist()}); "
            "set such rows to NaN to smooth over them as dropped samples"
        )
    if tau is None:
        tau_arr = np.zeros((n, robot.nv))
    else:
        tau_arr = np.asarray(tau, dtype=float)
        if tau_arr.shape != (n, robot.nv):
            raise DimensionError(
                f"tau has shape {tau_arr.shape}; robot {robot.name!r} with {n} times needs ({n}, {robot.nv})"
            )
        if not np.all(np.isfinite(tau_arr)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(tau_arr), axis=1))[0])
            raise NonFiniteError(f"tau[{bad}] = {tau_arr[bad].tolist()} is not finite")
    return t_arr, q_arr, tau_arr


class _FrozenModels:
    """``adaptive``'s model-based filter replayed with its learned model frozen per window.

    ``snapshots[j]`` is the model (:class:`~pinobs.observers.adaptive.ModelSnapshot`)
    the causal pass held at the end of window ``j``; the prediction from sample
    ``k`` uses ``snapshots[which[k]]``: its dynamics, its torque offset (added to
    ``tau``) and its regime's densities (``accel_psd`` replaced by the smoother's
    when given, the offset's scaled with it; with ``offset_scale``, the white
    acceleration at :data:`AUTO_WHITE_SCALE` of the regime's and the offset's
    at ``offset_scale`` times the regime's: :func:`consistent_offset_scale`).
    The torque-offset state ``d`` carries over a model switch (it is a random
    walk, so the backward pass sees the switch as a step it absorbs).
    """

    def __init__(
        self,
        ekf: ExtendedKalmanFilter,
        snapshots: Sequence[ModelSnapshot],
        which: Vector,
        accel_psd: float | None,
        offset_scale: float | None = None,
    ) -> None:
        self._ekf, self._snaps, self._which, self._accel = ekf, snapshots, which, accel_psd
        self._offset_scale = offset_scale
        self._k, self._j = 0, -1
        self.robot = ekf.robot

    @property
    def gains(self) -> Any:
        return self._ekf.gains

    @property
    def options(self) -> dict[str, Any]:
        return self._ekf.options

    @property
    def disturbance_psd(self) -> float | None:
        """The offset density given at construction (each window's regime sets its own)."""
        return self._ekf.disturbance_psd

    def _use(self, state: Any, j: int) -> Any:
        snap = self._snaps[j]
        self._ekf.replace_robot(snap.robot)
        scale = 1.0 if self._accel is None else self._accel / snap.accel_psd
        d_scale = scale
        if self._offset_scale is not None:
            scale, d_scale = AUTO_WHITE_SCALE, self._offset_scale
        self._ekf.gains = replace(self._ekf.gains, accel_psd=scale * snap.accel_psd)
        self._j, self.robot = j, snap.robot
        return state._replace(d_psd=d_scale * snap.disturbance_psd)

    def initial_state(self, q0: Vector, v0: Vector) -> Any:
        self._k, self._j = 0, -1
        state = self._ekf.initial_state(q0, v0)
        return self._use(state, int(self._which[0]))

    def predict(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector]:
        j = int(self._which[self._k])
        if j != self._j:
            state = self._use(state, j)
        self._k += 1
        return self._ekf.predict(state, dt, tau + self._snaps[j].offset)

    def predict_flow(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector, Vector]:
        """:meth:`predict` with ``Φ`` as the mean's Jacobian: the noise band propagates the
        error with ``Φ`` here (module docstring, "Two bands")."""
        pred, Phi = self.predict(state, dt, tau)
        return pred, Phi, Phi

    def correct(self, state: Any, q_meas: Vector) -> Any:
        return self._ekf.correct(state, q_meas)

    def gate_limit(self, state: Any) -> float:
        return self._ekf.gate_limit(state)


def _learn(
    robot: Robot,
    t: Vector,
    q: Vector,
    tau: Vector,
    good: Vector,
    noise_std: float | None,
    options: Mapping[str, Any],
    model_window: float | None,
    frozen_t: Vector | None = None,
) -> tuple[Callable[..., _FrozenModels], dict[str, Any]]:
    """The causal ``adaptive`` over the log (from its first good sample), its model kept per window.

    ``frozen_t``: the times of the rows the frozen-model filter runs over, when they are not
    ``t`` (a known latency: :func:`_retimed`); each row takes the window of the latest ``t``
    at or before it.

    Returns a maker of the frozen-model filter (given an ``accel_psd`` or ``None``:
    each window's regime density; and optionally an ``offset_scale``) and the
    options to report.
    """
    dt = float(np.median(np.diff(t)))

    def observer(blend: bool) -> AdaptiveEKF:
        opts = {**options, "blend": blend}
        obs = make_observer("adaptive", robot, noise_std=noise_std, rate=1.0 / dt, **opts)
        return cast(AdaptiveEKF, obs)

    # The snapshots depend on the model-based filter alone (its innovations decide the
    # regimes; the learner takes the committed samples), not on the blend's model-free bank,
    # except through a restart of a lost filter, which needs the bank: the pass runs without
    # it and, should the filter be lost, again with it (tested: the same snapshots).  It
    # costs about 10 % less.
    obs = observer(False)
    window = float(obs.options["horizon"] if model_window is None else model_window)
    positive("model_window", window)
    if window < dt:
        raise OptionError(
            f"model_window={window!r} s is shorter than the log's sample interval ({dt:.3g} s): "
            f"give at least one interval (default the learner's horizon, "
            f"{obs.options['horizon']:g} s)"
        )
    # windows (t₀ + jW, t₀ + (j+1)W]: each ends on the sample where the learner's solve
    # falls when W is a multiple of its resolve_every (both count from the reset at t₀), so
    # the window's model includes it.  Half-open the other way, a solve landing on a window's
    # first sample was left out of the window before it: a payload log smoothed with its
    # first window frozen in the nominal regime, ρ = 72.
    which = np.maximum(np.ceil((t - t[0]) / window - 1e-6).astype(int) - 1, 0)
    which[0] = which[1]  # sample 0 is never a window of its own (nothing learned before it)
    which = np.unique(which, return_inverse=True)[1].astype(float)  # empty windows (gaps) dropped
    frozen = which
    if frozen_t is not None:
        latest = np.searchsorted(t, frozen_t + TIME_EPS, side="right") - 1
        frozen = which[np.maximum(latest, 0)]

    def learn(obs: AdaptiveEKF) -> list[ModelSnapshot] | None:
        """The snapshots at the windows' ends; ``None`` if a filter run without the bank the
        user asked for is lost."""
        give_up = not obs.blend and bool(options.get("blend", True))
        snapshots: list[ModelSnapshot] = []
        obs.reset(float(t[0]), q[0], None, tau[0])
        for k in range(1, t.size):
            try:
                obs.update(float(t[k]), q[k] if good[k] else None, tau[k])
            except ObserverDiverged:
                if give_up:
                    return None
                raise
            if give_up and obs.lost():
                return None
            if k == t.size - 1 or which[k + 1] != which[k]:
                snapshots.append(obs.snapshot())  # the model held at the window's last sample
        return snapshots

    snapshots = learn(obs)
    if snapshots is None:  # lost: the pass with the bank, which restarts the filter
        obs = observer(True)
        snapshots = cast(list[ModelSnapshot], learn(obs))
    opts = {**obs.options, "blend": options.get("blend", True)}
    ekf = ExtendedKalmanFilter(
        snapshots[0].robot,
        accel_psd=snapshots[0].accel_psd,
        q0_std=opts["q0_std"],
        v0_std=opts["v0_std"],
        disturbance_psd=1.0,  # the state gets each window's own density (_FrozenModels._use)
        d0_std=obs.core.d0_std,
        outlier_probability=opts["outlier_probability"],
        noise_std=noise_std,
    )
    densities = {
        "warmup": opts["disturbance_psd"],
        "nominal": opts["validated_disturbance_psd"],
        "learned": opts["learned_disturbance_psd"],
    }
    report = {
        **opts,
        "model_window": window,
        "model_regimes": [s.regime for s in snapshots],
        "model_accel_psd": [s.accel_psd for s in snapshots],
        # (accel_psd [rad²/s³], offset density [rad²/s⁵]) of each window's regime
        "model_densities": [(s.accel_psd, densities[s.regime]) for s in snapshots],
    }

    def make(accel_psd: float | None, offset_scale: float | None = None) -> _FrozenModels:
        return _FrozenModels(ekf, snapshots, frozen, accel_psd, offset_scale)

    return make, report


def _first_good(q: Vector) -> tuple[int, Vector]:
    """Index of the first finite row of ``q`` and the finite-row mask from there on."""
    good = np.all(np.isfinite(q), axis=1)
    if not np.any(good):
        raise NonFiniteError("no row of q is finite: nothing to smooth")
    k0 = int(np.argmax(good))  # the filter starts at the first good sample
    return k0, good[k0:]


def _retimed(
    t: Vector, q: Vector, tau: Vector, latency: float
) -> tuple[Vector, Vector, Vector, NDArray[np.intp]]:
    """The log on the times its samples were taken, for a known measurement latency ``d`` [s].

    The sample stamped ``t_k`` was taken at ``s_k = t_k − d``; the torque ``τ_k`` is applied
    from ``t_k`` (MATH §7: only the measurement is late).  The rows returned are the union of
    the ``s_k`` (each with its ``q_k``) and the ``t_k`` (no measurement: predicted over), in
    time order, times closer than 1e-6 of the median interval merged (a latency of whole
    sample intervals puts each ``s_k`` on an earlier ``t_j``); each row's torque is the one
    in effect from it on, ``τ_j`` of the latest ``t_j`` at or before it (``τ_0`` before
    ``t_0``).  The filter over these rows is the causal observer under ``latency=d``
    (:meth:`pinobs.observers.base.Observer.set_latency`: the state at ``t − d``, predicted
    to ``t`` with the torques applied since), and the estimate at ``t_k`` is the row at
    ``t_k``.  Returns ``(times, q or NaN, τ, the row of each t_k)``.
    """
    n = t.size
    times = np.concatenate([t - latency, t])
    order = np.argsort(times, kind="stable")
    # merged below 1e-6 of an interval, or a few float64 steps of the times (about 2e-7 s at
    # Unix times, 1.7e9 s: 1e-6 of a 1 ms interval would merge nothing there)
    eps = max(1e-6 * float(np.median(np.diff(t))) if n > 1 else 0.0, 4.0 * _spacing(t))
    new = np.concatenate([[True], np.diff(times[order]) > eps])
    group = np.cumsum(new) - 1  # the row of each sorted time
    row_of = np.empty(2 * n, dtype=np.intp)
    row_of[order] = group
    first = order[new]  # each row's earliest time
    rows_t = times[first]
    rows_q = np.full((rows_t.size, q.shape[1]), np.nan)
    rows_q[row_of[:n]] = q
    rows_t[row_of[n:]] = t  # a row with a stamped time keeps it exactly (the output rows)
    latest = np.searchsorted(t, rows_t + eps, side="right") - 1
    return rows_t, rows_q, tau[np.maximum(latest, 0)], row_of[n:]


def _spacing(t: Vector) -> float:
    """The float64 step at the log's largest time magnitude [s]."""
    return float(np.spacing(np.abs(t).max())) if t.size else 0.0


def _latency(filter_options: Mapping[str, Any] | None) -> tuple[float, dict[str, Any]]:
    """``filter_options``' ``latency`` [s] (0 if none) and the other options."""
    options = dict(filter_options or {})
    latency = options.pop("latency", None)
    if isinstance(latency, str):
        raise OptionError(
            f"latency={latency!r}: give a number >= 0 [s] (pinobs.smooth alone takes 'auto': "
            "select_latency over the whole log)"
        )
    positive("latency", latency, allow_zero=True, allow_none=True)
    return float(latency or 0.0), options


#: :func:`select_latency`'s range: latencies up to this many sample intervals.
LATENCY_INTERVALS = 3


def select_latency(
    robot: Robot,
    log: LogLike | tuple[ArrayLike, ...],
    *,
    noise_std: float,
    observer: str = "ekf",
    accel_psd: float | None = None,
    disturbance_psd: float | None = None,
    filter_options: Mapping[str, Any] | None = None,
    model_window: float | None = None,
    intervals: int = LATENCY_INTERVALS,
) -> tuple[float, list[tuple[float, float]]]:
    """The measurement latency [s] under which the log's innovations are most likely.

    For a candidate ``d`` the filter runs over the log re-timed by ``d``
    (:func:`_retimed`; ``adaptive``: its learning pass under ``latency=d``, then
    the frozen-model filter) and sums the innovation log densities,
    ``ℓ(d) = Σ_k log N(e_k; 0, S_k)`` (as :func:`select_accel_psd`; every
    candidate has the same measurements, so the sums compare).  The search: whole
    sample intervals ``h`` (the median) from 0, 1 and 2, further up to
    ``intervals · h`` while ``ℓ`` still rises; then the vertex of the parabola through
    the best whole interval and its two neighbours, rounded to ``h/4`` (``ℓ`` is
    quadratic in ``d`` near its peak: on the UR5 logs of the tests, 0.5, 0.75 and 1 ms
    late at 1 kHz, the vertex fell within 0.002 ``h`` of the latency); should the
    parabola not open downward (a lost filter among its points), two halvings around
    the best, ``±h/2`` and ``±h/4``, as before.  3–4 passes on those logs (8 before);
    a latency is a delay, so never below 0.  The maximiser, not an interval's end
    (unlike ``accel_psd``, a latency has no side to err on).  A candidate at which
    the filter is lost is rejected.  Uses no ground truth.  Returns ``d`` and every
    ``(candidate, ℓ)`` evaluated, in the order tried.

    Raises:
        GainError: ``intervals`` < 0.
        NonFiniteError: the filter is lost at every candidate.
    """
    if intervals < 0:
        raise GainError(f"intervals={intervals!r}: give a whole number of sample intervals >= 0")
    return _select_latency(
        robot,
        _log_arrays(robot, log),
        noise_std,
        observer,
        accel_psd,
        disturbance_psd,
        filter_options,
        model_window,
        intervals,
    )


def _select_latency(
    robot: Robot,
    log: tuple[Vector, Vector, Vector],
    noise_std: float,
    observer: str,
    accel_psd: float | None,
    disturbance_psd: float | None,
    filter_options: Mapping[str, Any] | None,
    model_window: float | None,
    intervals: int = LATENCY_INTERVALS,
    prepared: dict[float, Any] | None = None,
    tried: dict[float, float] | None = None,
) -> tuple[float, list[tuple[float, float]]]:
    """:func:`select_latency` on checked arrays; ``prepared`` (latency → :func:`_prepare`'s
    result) and ``tried`` (latency → ``ℓ``) are read and filled, so that a caller that has
    run a candidate (:func:`smooth_quietly`: the log as stamped, the latency then smoothed under)
    does not run it twice: ``adaptive``'s learning pass costs about the causal run."""
    t, q, tau = log
    h = float(np.median(np.diff(t)))
    prepared = {} if prepared is None else prepared
    tried = {} if tried is None else tried

    def ll(d: float) -> float:
        d = round(d, 12)  # k·h/4 without its float noise (2e-3, not 0.0020000000000000018)
        if d not in tried and d >= t[-1] - t[0]:  # no sample taken within the log
            tried[d] = -math.inf
        if d not in tried:
            opts = {**dict(filter_options or {}), "latency": d}
            try:  # adaptive's learning pass can be lost too: the candidate is then rejected
                if d not in prepared:
                    prepared[d] = _prepare(
                        robot, t, q, tau, observer, noise_std, disturbance_psd, opts, model_window
                    )
            except (NonFiniteError, ObserverDiverged, np.linalg.LinAlgError):
                tried[d] = -math.inf
            else:
                arrays, k0, _, make, _ = prepared[d]
                tried[d] = _log_likelihood(make(accel_psd), arrays, k0)
        return tried[d]

    _latency_search(ll, h, intervals)
    best = max(tried, key=tried.__getitem__)
    if not math.isfinite(tried[best]):
        raise NonFiniteError(
            f"the filter is lost on this log at every latency tried (0 to "
            f"{max(tried):g} s); check the model, the torques and noise_std"
        )
    return best, list(tried.items())


def _latency_search(ll: Callable[[float], float], h: float, intervals: int) -> None:
    """:func:`select_latency`'s search: calls ``ll(d)`` (which records and caches) on whole
    intervals ``k h`` from 0 (0, 1, 2, further up to ``intervals`` while ``ℓ`` rises), then
    on the vertex of the parabola through the best and its neighbours rounded to ``h/4``,
    or, should it not open downward, on two halvings around the best."""
    top = 0  # the whole intervals tried: 0..top
    for k in range(intervals + 1):
        if k >= 3 and ll((k - 1) * h) < ll((k - 2) * h):  # past the peak
            break
        ll(k * h)
        top = k
    best = max((k * h for k in range(top + 1)), key=ll)
    c = min(max(round(best / h), 1), top - 1)  # the parabola's middle interval
    l0, l1, l2 = (ll((c + i) * h) for i in (-1, 0, 1)) if top >= 2 else (math.nan,) * 3
    curve = l0 - 2.0 * l1 + l2
    if math.isfinite(curve) and curve < 0.0:  # ℓ ≈ l1 + (l2 − l0) x/2 + curve x²/2
        x = c + 0.5 * (l0 - l2) / curve
        ll(min(max(round(4.0 * x) / 4.0, 0.0), float(top)) * h)
        return
    for step in (h / 2, h / 4):
        best = max([best, *(d for d in (best - step, best + step) if d >= 0.0)], key=ll)


def _prepare(
    robot: Robot,
    t: Vector,
    q: Vector,
    tau: Vector,
    observer: str,
    noise_std: float | None,
    disturbance_psd: float | None,
    filter_options: Mapping[str, Any] | None,
    model_window: float | None,
) -> tuple[tuple[Vector, Vector, Vector, Vector], int, NDArray[np.intp], Any, dict[str, Any]]:
    """The rows the filter runs over (from the first good one), its first index, the row of
    each log sample, and :func:`_filter_maker`'s maker and options.  With a ``latency`` in
    ``filter_options`` the rows are the log re-timed (:func:`_retimed`); ``adaptive``'s
    learning pass then runs on the log as stamped, with the latency (its own handling), and
    its windows' models are mapped onto the re-timed rows."""
    latency, options = _latency(filter_options)
    if latency >= t[-1] - t[0]:
        raise GainError(
            f"latency={latency!r} s is not shorter than the log ({t[-1] - t[0]:.6g} s): no sample "
            "would have been taken within it; give the measurement latency in seconds"
        )
    rows = np.arange(t.size)
    run_t, run_q, run_tau = t, q, tau
    if latency > 0.0:
        run_t, run_q, run_tau, rows = _retimed(t, q, tau, latency)
    k0, good = _first_good(run_q)
    arrays = (run_t[k0:], run_q[k0:], run_tau[k0:], good)
    learn = None
    if latency > 0.0:
        j0, good_j = _first_good(q)
        learn = ((t[j0:], q[j0:], tau[j0:], good_j), {**options, "latency": latency})
    make, extra = _filter_maker(
        robot, observer, arrays, noise_std, disturbance_psd, options, model_window, learn
    )
    if latency > 0.0:
        extra = {**extra, "latency": latency}
    return arrays, k0, rows, make, extra


def select_accel_psd(
    robot: Robot,
    log: LogLike | tuple[ArrayLike, ...],
    *,
    noise_std: float,
    grid: Sequence[float] | None = None,
    threshold: float = LIKELIHOOD_MARGIN,
    observer: str = "ekf",
    disturbance_psd: float | None = None,
    filter_options: Mapping[str, Any] | None = None,
    model_window: float | None = None,
) -> float:
    """The largest ``accel_psd`` [rad²/s³] of ``grid`` the log does not reject (``kf``: its
    ``jerk_psd`` [rad²/s⁵]; ``grid`` default :data:`DEFAULT_GRID`, ``kf``'s :data:`JERK_GRID`).

    For each candidate the filter runs forward once and sums the innovation
    log densities, ``ℓ(psd) = Σ_k log N(e_k; 0, S_k)`` (the
    prediction-error decomposition, Schweppe 1965); the choice is the largest candidate with
    ``ℓ ≥ max ℓ − threshold``, the upper end of the profile-likelihood
    interval (``threshold`` = 1.92 = χ²₁(0.95)/2: a 95 % interval).  Not the
    maximum itself: with an exact model the truth has no process noise and
    ``ℓ`` keeps rising, ever more slowly, as ``accel_psd → 0`` (a smoother
    that claims a perfect model is overconfident), so the maximiser is the
    grid's lower end and says nothing.  Uses no ground truth.  Costs one
    forward pass per candidate (no backward pass).  For ``adaptive`` the
    candidate replaces every window's ``accel_psd`` of the frozen-model
    filter (:func:`smooth`; the learning pass runs once).  For ``kf`` every
    candidate's ``ℓ`` comes from one pass of a bank of filters
    (:meth:`~pinobs.observers.kf.KFBank.log_likelihoods`), and the rule is applied
    once more with the half-decades either side of its choice added (module docstring).

    Raises:
        GainError: an empty grid, a non-positive candidate or threshold.
    """
    arrays, k0, _, make, _ = _prepare(
        robot,
        *_log_arrays(robot, log),
        observer,
        noise_std,
        disturbance_psd,
        filter_options,
        model_window,
    )
    model_free = observer_class(observer).model_free
    if grid is None:
        grid = JERK_GRID if model_free else DEFAULT_GRID
    return _select(make, arrays, k0, grid, threshold, model_free)


def consistent_offset_scale(
    robot: Robot,
    log: LogLike | tuple[ArrayLike, ...],
    *,
    noise_std: float,
    tol: float = 0.02,
    max_passes: int = 8,
    filter_options: Mapping[str, Any] | None = None,
    model_window: float | None = None,
) -> float:
    """The offset-density factor at which the smoother over ``adaptive`` has ``ρ = 1``.

    With the white acceleration at :data:`AUTO_WHITE_SCALE` of each window's
    regime density, the torque-offset density is ``s`` times the regime's, and
    ``s`` solves ``ρ(s) = 1`` (:attr:`Smoother.consistency`, whose expectation is
    1 when the densities explain the log).  ``ρ`` falls as ``s`` grows, about as
    a power of it (exponent −0.5 to −0.75 in ``benchmarks/smoothing_densities.md``),
    so the root of ``f(x) = log ρ(10ˣ)`` is found by the secant method from
    ``x = 0`` (the regimes' density) and a first step of slope −0.6, kept
    inside the bracket once the sign has changed (Illinois' false position)
    and inside :data:`OFFSET_SCALE_RANGE`; it stops at ``|log ρ| ≤ tol`` or
    after ``max_passes`` smoother passes and returns the best ``s`` seen (1, the
    regimes' density, when the log is too short to give a ``ρ``).
    A method of moments, not the likelihood: the learned model's residual
    error lies outside the filter's noise family, where the likelihood keeps a
    white acceleration that widens the smoother's band (module docstring).
    Uses no ground truth; costs one learning pass and 3–7 smoother passes
    (measured on the README's twelve model-error logs of seeds 1 and 2).

    Raises:
        GainError: ``tol`` ≤ 0, ``max_passes`` < 1, or a bad filter option.
    """
    positive("tol", tol)
    if max_passes < 1:
        raise GainError(f"max_passes={max_passes!r}: give at least 1 smoother pass")
    arrays, _, _, make, _ = _prepare(
        robot,
        *_log_arrays(robot, log),
        "adaptive",
        noise_std,
        None,
        filter_options,
        model_window,
    )
    return _consistent(make, arrays, tol, max_passes)


def _consistent(
    make: Callable[..., GaussianFilter],
    arrays: tuple[Vector, Vector, Vector, Vector],
    tol: float = 0.02,
    max_passes: int = 8,
) -> float:
    """:func:`consistent_offset_scale` on checked arrays and ``adaptive``'s frozen-model maker."""
    lo, hi = (math.log10(b) for b in OFFSET_SCALE_RANGE)

    def f(x: float) -> float:  # log ρ at s = 10ˣ: one smoother pass
        smoother = Smoother(make(None, 10.0**x), None, 0)
        for row in _rows(*arrays):
            smoother.push(*row)
        smoother.close()
        rho = smoother.consistency
        return math.log(rho) if math.isfinite(rho) and rho > 0 else 0.0  # nothing to test: as is

    seen = [(0.0, f(0.0))]
    x = min(max(seen[0][1] / 0.6, lo), hi)  # a first step along ρ ∝ s^−0.6
    below: tuple[float, float] | None = None  # the bracket's ends: f > 0 (x too small)...
    above: tuple[float, float] | None = None  # ... and f < 0
    for _ in range(max_passes - 1):
        if min(abs(p[1]) for p in seen) <= tol:
            break
        seen.append((x, f(x)))
        for p in seen[-2:]:
            if p[1] > 0 and (below is None or p[0] > below[0]):
                below = p
            if p[1] <= 0 and (above is None or p[0] < above[0]):
                above = p
        (x0, f0), (x1, f1) = seen[-2], seen[-1]
        x = x1 - f1 * (x1 - x0) / (f1 - f0) if f1 != f0 else x1 + (1.0 if f1 > 0 else -1.0)
        if below is not None and above is not None and not below[0] < x < above[0]:
            x = below[0] - below[1] * (above[0] - below[0]) / (above[1] - below[1])
        x = min(max(x, lo), hi)
    return float(10.0 ** min(seen, key=lambda p: abs(p[1]))[0])


def _select(
    make: Callable[[float | None], GaussianFilter],
    arrays: tuple[Vector, Vector, Vector, Vector],
    k0: int,
    grid: Sequence[float],
    threshold: float,
    model_free: bool = False,
) -> float:
    """:func:`select_accel_psd` on checked arrays (from the first good sample) and a filter
    maker.  ``model_free`` (``kf``): every candidate's ``ℓ`` in one pass of a bank of filters
    (:meth:`~pinobs.observers.kf.KFBank.log_likelihoods`), and the rule applied again with
    the geometric midpoints either side of its first choice added (a decade grid: the
    half-decades)."""
    candidates = sorted(float(positive("grid value", g) or 0.0) for g in grid)
    if not candidates:
        raise GainError("grid is empty; give accel_psd candidates > 0 [rad²/s³]")
    positive("threshold", threshold)

    def score(psds: list[float]) -> list[float]:
        if not model_free:
            return [_log_likelihood(make(psd), arrays, k0) for psd in psds]
        filt = cast(WhiteJerkFilter, make(None))
        gains = filt.gains
        bank = KFBank(filt.robot, tuple(psds), gains.meas_std, gains.outlier_probability)
        with np.errstate(over="ignore", invalid="ignore"):
            lls = bank.log_likelihoods(arrays[0], arrays[1], arrays[3], filt.v0_std)
        return [float(ll) if math.isfinite(ll) else -math.inf for ll in lls]

    lls = dict(zip(candidates, score(candidates), strict=True))
    best = max(lls.values())
    if not math.isfinite(best):
        raise NonFiniteError(
            f"the filter is lost on this log at every accel_psd of the grid ({candidates[0]:g} to "
            f"{candidates[-1]:g} rad²/s³); check the model, the torques and noise_std"
        )
    choice = max(p for p, ll in lls.items() if ll >= best - threshold)
    if model_free:
        i = candidates.index(choice)
        mids = [
            math.sqrt(choice * candidates[j]) for j in (i - 1, i + 1) if 0 <= j < len(candidates)
        ]
        lls.update(zip(mids, score(mids), strict=True))
        best = max(lls.values())
        choice = max(p for p, ll in lls.items() if ll >= best - threshold)
    return choice


def _log_likelihood(
    filt: GaussianFilter, arrays: tuple[Vector, Vector, Vector, Vector], k0: int
) -> float:
    """``ℓ`` of :func:`select_accel_psd` for one filter; ``−∞`` if the filter is lost on the log
    (its covariance or estimate stops being finite: under a model error a small density
    makes the filter overconfident until it diverges), which rejects the candidate."""
    with np.errstate(over="ignore", invalid="ignore"):
        try:
            ll = sum(ll for *_, ll, _ in _forward(filt, _rows(*arrays), k0))
        except (NonFiniteError, ObserverDiverged, np.linalg.LinAlgError):
            return -math.inf
    return ll if math.isfinite(ll) else -math.inf


def _smoothable_class(observer: str) -> type[Observer[Any]]:
    """The class of ``observer``, if a smoother can run it (its
    :attr:`~pinobs.observers.base.Observer.smoothable`; else :class:`OptionError`)."""
    cls = observer_class(observer)
    if not cls.smoothable:
        smoothable = [n for n in observer_names() if observer_class(n).smoothable]
        raise OptionError(
            f"observer {observer!r} keeps no error-state covariance to smooth; "
            f"smoothable: {smoothable}"
        )
    return cls


def _filter_maker(
    robot: Robot,
    observer: str,
    arrays: tuple[Vector, Vector, Vector, Vector],
    noise_std: float | None,
    disturbance_psd: float | None,
    filter_options: Mapping[str, Any] | None,
    model_window: float | None,
    learn: tuple[tuple[Vector, Vector, Vector, Vector], Mapping[str, Any]] | None = None,
) -> tuple[Callable[..., GaussianFilter], dict[str, Any]]:
    """``make(accel_psd)`` -> the filter the smoother runs over ``arrays`` (``None``: the
    observer's own density), and the options to report beyond the filter's (``adaptive``:
    after its learning pass, over ``learn``'s arrays with its options when given: a known
    latency, :func:`_prepare`)."""
    cls = _smoothable_class(observer)
    if cls.learns_model:
        if disturbance_psd is not None:
            raise OptionError(
                f"disturbance_psd={disturbance_psd!r}: adaptive's densities are its regimes' "
                "(give them in filter_options: disturbance_psd, learned_disturbance_psd, ...)"
            )
        if learn is None:
            return _learn(robot, *arrays, noise_std, dict(filter_options or {}), model_window)
        return _learn(robot, *learn[0], noise_std, learn[1], model_window, frozen_t=arrays[0])
    if model_window is not None:
        raise OptionError(
            f"model_window={model_window!r} is for a filter that learns its model (adaptive), "
            f"not {observer!r}"
        )

    density = cls.process_density  # the process density make() sets
    options = dict(filter_options or {})
    if disturbance_psd is not None:
        options["disturbance_psd"] = disturbance_psd

    def make(psd: float | None) -> GaussianFilter:
        extra = {} if psd is None else {density: psd}
        filt = make_observer(observer, robot, noise_std=noise_std, **{**options, **extra})
        return filt.smoothing_filter()  # kf: its predict and correct apart (WhiteJerkFilter)

    return make, {}


def _windows(
    filt: GaussianFilter,
    extra: Mapping[str, Any],
    accel_psd: float | str | None,
    chunk: float | None,
    overlap: float | None,
    lag: float | None,
    dt: float,
    meas_dt: float | None = None,
    *,
    robot: Robot,
    configurations: Vector,
    rows: int | None = None,
) -> tuple[int | None, int]:
    """``(chunk, overlap)`` in samples of ``dt`` [s] (``(None, 0)``: the whole log at once);
    the default overlap from the measurement interval ``meas_dt`` (default ``dt``; a re-timed
    log has rows between its measurements: :func:`_retimed`) and, with a torque offset,
    ``robot``'s inertia at ``configurations`` (rows of ``q``, the first the filter's first:
    :func:`default_overlap`; ``adaptive``: the nominal model's inertia); ``rows``: the log's
    (``None``: streamed, not known), for the cost warning."""
    if lag is not None and (chunk is not None or overlap is not None):
        raise OptionError(
            f"lag={lag!r} sets the chunk and the overlap; give lag alone, or chunk and overlap"
        )
    if lag is not None:
        n = _samples(lag, dt, "lag")
        return n, n
    if chunk is None:
        if overlap is not None:
            raise OptionError(
                f"overlap={overlap!r} without chunk: the whole log is smoothed at once; give "
                "chunk too (or lag)"
            )
        return None, 0
    given = overlap
    # the longest memory: the smallest densities (adaptive: any window's)
    gains = filt.gains
    if isinstance(gains, KFGains):  # white jerk: the triple integrator alone
        pairs = [(0.0, gains.jerk_psd)]
    else:
        pairs = extra.get("model_densities") or [(gains.accel_psd, filt.disturbance_psd)]
    if isinstance(accel_psd, float) and not isinstance(gains, KFGains):
        # it replaces each window's, the offset's scaled
        pairs = [(accel_psd, None if d is None else d * accel_psd / a) for a, d in pairs]
    h = dt if meas_dt is None else meas_dt
    masses = None
    if not isinstance(gains, KFGains) and any(d is not None for _, d in pairs):
        masses = [robot.mass_matrix(q) for q in configurations]
    needed = max(
        default_overlap(a, gains.meas_std, h, disturbance_psd=d, mass_matrices=masses)
        for a, d in pairs
    )
    overlap = needed if given is None else given
    if overlap < needed:  # the backward error decays as exp(−rate·overlap): CHUNK_TOL at needed
        warnings.warn(
            ChunkWarning(
                f"overlap={overlap!r} s is shorter than the {needed:.3g} s over which the "
                f"filter's slowest mode decays to CHUNK_TOL = {CHUNK_TOL:g} (default_overlap): "
                f"chunked estimates can differ from the whole log's by the order of "
                f"{CHUNK_TOL ** (overlap / needed):.2g} of v_std at each chunk's end; give a "
                "longer overlap, or none (the default)"
            ),
            stacklevel=4,
        )
    n_chunk, n_over = _samples(chunk, dt, "chunk"), _samples(overlap, dt, "overlap")
    # every window's backward pass runs over its overlap (once over a log within one window)
    if n_over > COST_WARN * n_chunk and (rows is None or rows > n_chunk + n_over):
        warnings.warn(
            CostWarning(
                f"chunk={chunk!r} s with an overlap of {n_over * dt:.3g} s: the backward pass runs "
                f"{(n_chunk + n_over) / n_chunk:.0f}× over each sample, and the memory is set by "
                f"chunk + overlap anyway (a chunk as long as the overlap: 2×, at most twice the "
                "memory); give a longer chunk, or lag"
            ),
            stacklevel=4,
        )
    return n_chunk, n_over


def streaming_smoother(
    robot: Robot,
    *,
    dt: float,
    observer: str = "ekf",
    noise_std: float | None = None,
    accel_psd: float | None = None,
    disturbance_psd: float | None = None,
    chunk: float | None = None,
    overlap: float | None = None,
    lag: float | None = None,
    filter_options: Mapping[str, Any] | None = None,
    band: str = "model",
    configurations: ArrayLike | None = None,
) -> tuple[Callable[[], Smoother], dict[str, Any]]:
    """A maker of :class:`Smoother` for a log read as it goes (memory bounded by ``chunk`` or
    ``lag``), and the options to report; the arguments as :func:`smooth`, ``dt`` the
    nominal sample period [s] (the chunks are counted in samples of it), ``configurations``
    rows of ``q`` the log visits, its first sample first (with a torque offset the default
    overlap depends on the inertia along them, :func:`default_overlap`; default the robot's
    neutral configuration and :data:`OVERLAP_CONFIGURATIONS` − 1 random ones, seed 0).

    Not for ``accel_psd="auto"`` or ``adaptive``: both pass over the log more than once.
    ``noise_std`` is required: a stream has no log to estimate it from
    (:func:`pinobs.io.smoothing.smooth_log` estimates it from the log's first chunk).

    Raises:
        OptionError: those two, or neither ``chunk`` nor ``lag`` (the whole log is not a stream).
        GainError: no ``noise_std``.
    """
    cls = observer_class(observer)
    if accel_psd == "auto" or cls.learns_model or (chunk is None and lag is None):
        raise OptionError(
            f"a streamed smoother needs chunk or lag, a given accel_psd and a filter with one "
            f"model (got observer={observer!r}, accel_psd={accel_psd!r}, chunk={chunk!r}, "
            f"lag={lag!r}); use smooth() on the whole log"
        )
    if band not in BANDS[:2]:
        raise OptionError(
            f"band={band!r}: a streamed smoother gives one of {list(BANDS[:2])} ('inflated' "
            "scales by the whole log's ρ: use smooth() on the whole log)"
        )
    if _latency(filter_options)[0] > 0.0:
        raise OptionError(
            "a known latency re-times the whole log (its samples on the times they were "
            "taken): use smooth() on the whole log"
        )
    positive("dt", dt)
    if noise_std is None:  # the filter's default σ would be used, silently
        raise GainError(
            "a streamed smoother needs noise_std [rad or m]: it has no log to estimate it from"
        )
    empty = np.empty(0)
    make, extra = _filter_maker(
        robot,
        observer,
        (empty, empty, empty, empty),
        noise_std,
        disturbance_psd,
        filter_options,
        None,
    )
    filt = make(accel_psd)
    if configurations is None:
        rng = np.random.default_rng(0)
        configs = np.array(
            [robot.neutral()]
            + [robot.random_configuration(rng) for _ in range(OVERLAP_CONFIGURATIONS - 1)]
        )
    else:
        configs = np.asarray(configurations, dtype=float).reshape(-1, robot.nq)
        configs = _spread(configs[np.all(np.isfinite(configs), axis=1)])
        if not len(configs):
            raise DimensionError("configurations has no finite row of q")
    n_chunk, n_over = _windows(
        filt, extra, accel_psd, chunk, overlap, lag, dt, robot=robot, configurations=configs
    )
    opts = {
        **filt.options,
        "observer": observer,
        "chunk": None if n_chunk is None else n_chunk * dt,
        "overlap": n_over * dt if n_over else None,
        "lag": lag,
        "band": band,
    }
    return (lambda: Smoother(make(accel_psd), n_chunk, n_over, band)), opts


def smoothing_warnings(consistency: float, options: Mapping[str, Any]) -> list[str]:
    """What :func:`smooth` warns of its result (:class:`~pinobs.errors.ConsistencyWarning`),
    from its ``consistency`` ``ρ`` and ``options`` (``accel_psd_from_log``: ``"auto"`` was asked):

    * ``ρ`` above :data:`RHO_WARN`: the model does not explain the log, so the estimate
      follows a model error, and a band that ``ρ`` does not scale is too narrow;
    * ``"auto"`` over ``ekf`` chose the grid's largest density: the likelihood still rises
      there, so the model explains the log no better than white acceleration does, and the
      smoother is model-free (measured on the learning benchmark's six model-error logs of
      seed 1, 12 s: ``"auto"`` chose 1 rad²/s³ on every one, RMS 1.24e-2 to 1.26e-2 rad/s,
      98–126× the smoother over ``adaptive``'s; at the default 1e-8, 0.25–2.4 rad/s with
      ``ρ`` 3e8 to 3e9 and a model band that covers none of the truth).
    """
    said = []
    band = options.get("band")
    if options.get("accel_psd_from_log") and options.get("accel_psd") == DEFAULT_GRID[-1]:
        said.append(
            f"accel_psd='auto' chose {DEFAULT_GRID[-1]:g} rad²/s³, the largest it tries: the "
            "model explains the log no better than white acceleration does (the smoother is "
            "model-free, and white acceleration is a poorer prior than the model-free kf's white "
            "jerk); check the model and the torques, or smooth with observer='adaptive' (learns "
            "the model) or observer='kf' with accel_psd='auto' (model-free)"
        )
    if math.isfinite(consistency) and consistency > RHO_WARN:
        scale = math.sqrt(consistency)
        widened = (
            f"the band is widened by √ρ = {scale:.3g}"
            if band == "inflated"
            else f"the {band} band is too narrow, by about √ρ = {scale:.3g} (band='inflated' "
            "scales it)"
        )
        latency = (
            f"no measurement latency of up to {LATENCY_INTERVALS} sample intervals explains it "
            "(searched); check the model, the torques"
            if options.get("latency_searched")
            else "check the model, the torques, a measurement latency (filter_options="
            "{'latency': 'auto'} finds one)"
        )
        check = (
            f"{latency} and noise_std, or smooth with accel_psd='auto', "
            "observer='adaptive' (learns the model) or observer='kf' (model-free)"
        )
        if options.get("observer") == "kf":  # no model: its white jerk is too small
            check = (
                "the motion has more jerk than jerk_psd says: smooth with accel_psd='auto' "
                "(chosen from the log), or check noise_std"
            )
        said.append(
            f"the model does not explain the log: filter–smoother consistency ρ = "
            f"{consistency:.3g} (about 1 when it does; above {RHO_WARN:g}, the estimate follows "
            f"a model error); {widened}; {check}"
        )
    return said


def latency_note(options: Mapping[str, Any]) -> str | None:
    """What :func:`smooth` says (:class:`~pinobs.errors.LatencyWarning`) when it smoothed under
    a latency it found because the log, as stamped, was not explained (``options`` of its
    result), else ``None``."""
    if not (options.get("latency_searched") and options.get("latency_from_log")):
        return None
    d = options["latency"]
    without = options.get("accel_psd_without_latency")
    found = (
        f"accel_psd='auto' took {without:g} rad²/s³ without it, {options['accel_psd']:g} with it"
        if without is not None
        else f"ρ = {options['consistency_without_latency']:.3g} without it"
    )
    return (
        f"the model explains the log only with a measurement latency: its positions are "
        f"{1e3 * d:.3g} ms late (found from the log: {found}), so it was smoothed with "
        f"them at the times they were taken and the estimates given at the stamped times; give "
        f"filter_options={{'latency': {d:.6g}}} (estimate --latency) if that is right, or "
        "{'latency': 0} to smooth the log as stamped"
    )


def log_noise_std(robot: Robot, t: Vector, q: Vector) -> tuple[float, Vector, str]:
    """The σ [rad or m] the smoother takes when none is given: ``(σ̂, σ̂ per joint, a sentence
    reporting them)`` from :func:`pinobs.observers.noise.noise_from_log` (the median over
    joints, the log's first second), at least :data:`~pinobs.observers.base.NOISE_FLOOR`
    (the filters' default σ).

    Raises:
        GainError: fewer than 12 finite rows to estimate it from.
    """
    found = noise_from_log(t, q, robot, floor=NOISE_FLOOR)
    if found is None:
        raise GainError("the log has too few finite rows to estimate its noise; give noise_std")
    return found


def smooth(
    robot: Robot,
    log: LogLike | tuple[ArrayLike, ...],
    *,
    observer: str = "ekf",
    noise_std: float | None = None,
    accel_psd: float | Literal["auto"] | None = None,
    disturbance_psd: float | None = None,
    chunk: float | None = None,
    overlap: float | None = None,
    lag: float | None = None,
    model_window: float | None = None,
    filter_options: Mapping[str, Any] | None = None,
    band: str | None = None,
) -> Smoothed:
    """Fixed-interval RTS smoothing of a log on the manifold (module docstring for the equations).

    Args:
        robot: the model (the filter's process model; ``adaptive``'s nominal model).
        log: ``(t, q)`` or ``(t, q, tau)`` arrays (a tuple or a list, or a mapping with
            those keys), or an object with ``t``, ``q``, ``tau`` attributes
            (:class:`pinobs.io.Log`; a
            :class:`pinobs.Result` is read through its ``q_meas``): times [s] ``(N,)`` strictly
            increasing, at any intervals (an interval of ``m ≥ 2`` median intervals holds
            ``m − 1`` samples the log lost: they are predicted over at their ticks, each
            with its torque on the line between its neighbours',
            :func:`pinobs.model.sampling.on_ticks`; ``options["missing_samples"]``);
            measured configurations ``(N, nq)``, a row with a non-finite entry
            being a dropped sample (predicted over, not corrected with; rows
            before the first good one get NaN); torques applied from each
            sample on [N·m or N] ``(N, nv)`` (zero-order hold, MATH §7;
            ``None``: zero).
        observer: the filter smoothed: ``"ekf"``, ``"adaptive"`` (its learned
            model frozen per ``model_window``: module docstring), or the model-free
            ``"kf"`` (white jerk, no torque: the floor where the model is wrong).
        noise_std: position noise standard deviation [rad or m]; ``None``: the
            median over joints of its estimate from the log's first second
            (:func:`pinobs.observers.noise.noise_from_log`; at least
            :data:`~pinobs.observers.base.NOISE_FLOOR`), warned
            (:class:`~pinobs.errors.NoiseWarning`) and reported in ``options``
            (``noise_std``, ``noise_std_from_log``).
        accel_psd: white-acceleration density of the filter [rad²/s³];
            ``None``: the observer's own (``ekf``: :data:`DEFAULT_ACCEL_PSD`;
            ``adaptive``: each window's regime's; ``kf`` takes no number: its
            density is ``jerk_psd`` in ``filter_options``, default (and with ``"auto"``,
            the causal filter's default) 1e3 rad²/s⁵);
            ``"auto"``: chosen from this log, for ``ekf`` by
            :func:`select_accel_psd` (one forward pass per grid value), for
            ``kf`` its ``jerk_psd`` likewise (:data:`JERK_GRID`, then the
            half-decades either side), for ``adaptive`` by
            :func:`consistent_offset_scale` (``ρ = 1``; 3–7 smoother
            passes); module docstring.  Reported in ``options`` (``accel_psd``,
            ``accel_psd_from_log``).
        disturbance_psd: the EKF's joint-torque offset density [rad²/s⁵], or ``None``
            (not for ``adaptive``: its regimes set it).
        chunk: memory bound: the backward pass runs on windows of ``chunk``
            seconds (``None``: the whole log at once).
        overlap: seconds of later samples each window's backward pass starts
            from (default :func:`default_overlap`: agreement with the whole-log
            smoother to :data:`CHUNK_TOL` of ``v_std``).
        lag: fixed-lag mode [s]: chunks of ``lag`` with ``lag`` of overlap
            (exclusive with ``chunk`` and ``overlap``).
        model_window: ``adaptive`` only: the window [s] over which its learned model
            is frozen (default: its ``horizon``, 10 s: module docstring).
        filter_options: further options of the filter (``q0_std``, ``v0_std``, ...;
            for ``adaptive``, those of its causal learning pass).  ``latency`` [s], a
            known measurement latency (the sample stamped ``t`` was taken at
            ``t − latency``, as :meth:`pinobs.observers.base.Observer.set_latency`):
            the log is smoothed on the times its samples were taken, the torque
            switching at the stamped times, and the estimate given at the stamped
            times (:func:`_retimed`; reported in ``options["latency"]``);
            ``"auto"``: the likeliest latency from the log (:func:`select_latency`,
            at ``accel_psd`` if a number is given, else the observer's own density;
            ``options["latency_from_log"]``).  Not given: 0, unless the model does not
            explain the log as stamped (``ρ`` > :data:`RHO_WARN`), which is then searched
            as with ``"auto"`` and smoothed under the latency found if that explains it
            (``ρ`` ≤ :data:`RHO_WARN`; ``options["latency_searched"]``,
            ``"consistency_without_latency"``; module docstring), or ``accel_psd="auto"``
            chose a density above ``ekf``'s own (``"accel_psd_without_latency"``); ``0``:
            as stamped.
        band: what ``v_std`` states (:data:`BANDS`): ``"model"``, the smoother's
            covariance ``P^s`` under the filter's noise model (white acceleration
            and offset as modelled); ``"noise"``, the covariance of the same
            estimate's error driven by the measurement noise alone
            (:func:`_backward`), for a model error that is smooth in time, which
            the forward and backward passes lag in opposite directions and the
            smoother cancels (module docstring); ``"inflated"``, the noise band
            scaled by ``√max(1, ρ)`` (``ρ`` = :attr:`Smoothed.consistency` of this
            log; module docstring: a model error the densities do not explain
            widens it, never below the noise's own); ``None``: ``"inflated"`` over
            ``adaptive`` with its regimes' densities (tuned for the causal
            filter's tracking, not fitted to the log) and over ``kf`` (a robot's
            motion is not white jerk: module docstring), ``"model"`` otherwise
            (``ekf``; densities given or chosen from the log).

    Raises:
        UnknownNameError, OptionError: ``observer`` is unknown or cannot be smoothed,
            or an option it does not take; ``overlap`` without ``chunk``; ``filter_options``
            not a mapping, or with ``noise_std`` or ``rate`` (given to :func:`smooth` or set
            by the log).
        GainError: a non-positive ``noise_std``, ``chunk``, ``overlap``, ``lag`` or
            ``model_window``, a latency not shorter than the log, a bad filter option, or no
            ``noise_std`` and too few finite rows to estimate it.
        DimensionError, TimestampError, NonFiniteError: malformed log arrays.
        ConfigurationError: rows with a quaternion or ``(cos, sin)`` pair off unit norm
            (before any pass; NaN such rows to smooth over them).

    Warns:
        NoiseWarning: ``noise_std`` not given (σ estimated from the log).
        CostWarning: a ``chunk`` more than :data:`COST_WARN` times shorter than its overlap.
        ChunkWarning: an ``overlap`` given shorter than :func:`default_overlap`'s.
        TimestampWarning: a median sample period of 0.1 s or more, or 1 µs or less
            (``t`` in ms, µs or ns?).
        LatencyWarning: no latency given, and the log explained only with one found in it
            (:func:`latency_note`).
        ConsistencyWarning: ``ρ`` (:attr:`Smoothed.consistency`) above :data:`RHO_WARN`,
            or ``"auto"`` at the grid's largest density: the model does not explain the
            log (:func:`smoothing_warnings`).
    """
    try:  # a log timed in ms reads as 1000× too slow: the filter is lost, or v 1000× too small
        times = log[0] if isinstance(log, tuple) else log.t
        unit = time_unit_warning(median_period(np.asarray(times, dtype=float).ravel()))
    except (AttributeError, TypeError, ValueError, IndexError):
        unit = None  # smooth_quietly says what is wrong with the log
    if unit is not None:
        warnings.warn(TimestampWarning(unit), stacklevel=2)
    result = smooth_quietly(
        robot,
        log,
        observer=observer,
        noise_std=noise_std,
        accel_psd=accel_psd,
        disturbance_psd=disturbance_psd,
        chunk=chunk,
        overlap=overlap,
        lag=lag,
        model_window=model_window,
        filter_options=filter_options,
        band=band,
        find_latency=True,
    )
    note = latency_note(result.options)
    if note is not None:
        warnings.warn(LatencyWarning(note), stacklevel=2)
    for said in smoothing_warnings(result.consistency, result.options):
        warnings.warn(ConsistencyWarning(said), stacklevel=2)
    return result


def _filter_options(options: Any) -> dict[str, Any]:
    """``filter_options`` as a dict, or :class:`OptionError` (not a mapping, or an option
    :func:`smooth` takes itself)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise OptionError(
            f"filter_options is a {type(options).__name__}; give a mapping of option names to "
            "values, e.g. {'latency': 0.001}"
        )
    for name, why in (
        ("noise_std", "give noise_std= to smooth()"),
        ("rate", "the log's times set it"),
    ):
        if name in options:
            raise OptionError(f"filter_options[{name!r}]: not a filter option here ({why})")
    return dict(options)


def smooth_quietly(
    robot: Robot,
    log: LogLike | tuple[ArrayLike, ...],
    *,
    observer: str = "ekf",
    noise_std: float | None = None,
    accel_psd: float | Literal["auto"] | None = None,
    disturbance_psd: float | None = None,
    chunk: float | None = None,
    overlap: float | None = None,
    lag: float | None = None,
    model_window: float | None = None,
    filter_options: Mapping[str, Any] | None = None,
    band: str | None = None,
    find_latency: bool = False,
    _prepared: dict[float, Any] | None = None,
) -> Smoothed:
    """:func:`smooth` without its warnings (the same arguments and result), for callers that
    report the consistency their own way (a log file's run, the identification's refinement).

    ``find_latency``: a log the model does not explain, with no latency given, is searched
    for one (:func:`smooth` sets it).  ``_prepared`` is internal: :func:`_prepare`'s results
    by latency, shared with the latency search's own calls."""
    if accel_psd is not None and not isinstance(accel_psd, str):  # a float from here on
        accel_psd = positive("accel_psd", accel_psd)
    positive("noise_std", noise_std, allow_none=True)  # (a filter would floor 0 to NOISE_FLOOR)
    filter_options = _filter_options(filter_options)
    asked_psd = accel_psd
    prepared: dict[float, Any] = {} if _prepared is None else _prepared
    if lag is not None and (chunk is not None or overlap is not None):
        raise OptionError(
            f"lag={lag!r} sets the chunk and the overlap; give lag alone, or chunk and overlap"
        )
    if isinstance(accel_psd, str) and accel_psd != "auto":
        raise GainError(f"accel_psd={accel_psd!r}: give a number > 0 [rad²/s³] or 'auto'")
    for name, seconds in (("chunk", chunk), ("overlap", overlap), ("lag", lag)):
        positive(name, seconds, allow_none=True)  # before any pass over the log
    cls = _smoothable_class(observer)
    adaptive, model_free = cls.learns_model, cls.model_free
    if model_free and accel_psd is not None and accel_psd != "auto":
        raise OptionError(
            f"accel_psd={accel_psd!r}: {observer!r} has no white acceleration; its process "
            f"density is its white jerk: give filter_options={{'jerk_psd': {accel_psd!r}}} "
            "[rad²/s⁵], or accel_psd='auto' to choose it from the log"
        )
    if band is None:  # the noise band where the densities are adaptive's causal regimes'
        band = "inflated" if (adaptive and accel_psd is None) or model_free else "model"
    if band not in BANDS:
        raise OptionError(f"band={band!r}: give one of {list(BANDS)}")
    t_all, q_all, tau_all = _log_arrays(robot, log)
    # dropped samples: smoothed on the grid of ticks, each missing one predicted over with
    # its torque on the line between its neighbours' (pinobs.model.sampling), and the
    # estimate given at the log's own rows (given_rows; None: nothing was missing)
    t_given = t_all
    t_all, q_all, tau_all, given_rows = on_ticks(t_all, q_all, tau_all)
    noise_from_data = noise_std is None
    if noise_std is None:
        noise_std, _, said = log_noise_std(robot, t_all, q_all)
        warnings.warn(NoiseWarning(said), stacklevel=3)  # the caller of smooth()

    def find(options: Mapping[str, Any] | None, tried: dict[float, float] | None = None) -> float:
        """:func:`select_latency` on this log, its passes shared through ``prepared``."""
        return _select_latency(
            robot,
            (t_all, q_all, tau_all),
            cast(float, noise_std),
            observer,
            asked_psd if isinstance(asked_psd, float) else None,
            disturbance_psd,
            options,
            model_window,
            prepared=prepared,
            tried=tried,
        )[0]

    latency_from_log = (filter_options or {}).get("latency") == "auto"
    if latency_from_log and model_free:
        raise OptionError(
            f"latency='auto' with {observer!r}: without a model a late log is as likely as one "
            "on time, so the log cannot tell its latency; give it in seconds, or smooth with "
            "ekf or adaptive to find it"
        )
    if latency_from_log:  # the likeliest latency (select_latency), then smoothed under it
        rest = {k: v for k, v in dict(filter_options or {}).items() if k != "latency"}
        filter_options = {**rest, "latency": find(rest)}
    latency = _latency(filter_options)[0]
    if latency not in prepared:  # (adaptive: the learning pass)
        prepared[latency] = _prepare(
            robot,
            t_all,
            q_all,
            tau_all,
            observer,
            noise_std,
            disturbance_psd,
            filter_options,
            model_window,
        )
    arrays, k0, rows, make, extra = prepared[latency]
    offset_scale = None
    accel_from_log = accel_psd == "auto"
    if accel_psd == "auto" and adaptive:
        offset_scale = _consistent(make, arrays)  # ρ = 1 (consistent_offset_scale)
        extra = {
            **extra,
            "offset_scale": offset_scale,
            "model_accel_psd": [AUTO_WHITE_SCALE * a for a in extra["model_accel_psd"]],
            "model_densities": [
                (AUTO_WHITE_SCALE * a, offset_scale * d) for a, d in extra["model_densities"]
            ],
        }
        filt = make(None, offset_scale)
    else:
        if accel_psd == "auto":
            grid = JERK_GRID if model_free else DEFAULT_GRID  # kf: its jerk_psd
            accel_psd = _select(make, arrays, k0, grid, LIKELIHOOD_MARGIN, model_free)
        filt = make(None if isinstance(accel_psd, str) else accel_psd)
    model = filt.robot
    nv = model.nv
    run_t = arrays[0]
    n_run = k0 + run_t.size  # the rows the filter runs over (the log's, or re-timed: _prepare)
    dt = meas_dt = float(np.median(np.diff(t_all)))
    if "latency" in extra and run_t.size > 1:  # re-timed rows: their mean interval
        dt = float(run_t[-1] - run_t[0]) / (run_t.size - 1)
    configs = _spread(arrays[1][arrays[3]])  # the rows measured, from the filter's first
    n_chunk, n_over = _windows(
        filt,
        extra,
        accel_psd,
        chunk,
        overlap,
        lag,
        dt,
        meas_dt,
        robot=robot,
        configurations=configs,
        rows=n_run,
    )
    n_chunk = n_run if n_chunk is None else n_chunk
    out_q = np.full((n_run, model.nq), np.nan)
    out_v = np.full((n_run, nv), np.nan)
    out_var = np.full((n_run, nv), np.nan)
    inner = "noise" if band == "inflated" else band  # scaled below, once ρ is known
    window = None if n_over == 0 else n_chunk
    if model_free and model.is_vector_space:  # the same in compiled passes
        jerk = cast(WhiteJerkFilter, filt)
        out_q[k0:], out_v[k0:], out_var[k0:], loglik, rho_sum, terms = _white_jerk_smooth(
            jerk, arrays, window, n_over, inner
        )
        rho = rho_sum / terms if terms else math.nan
    else:
        smoother = Smoother(filt, window, n_over, inner)

        def keep(done: list[tuple[int, Vector, Vector, Vector]]) -> None:
            for k, qs, vs, var in done:
                out_q[k0 + k], out_v[k0 + k], out_var[k0 + k] = qs, vs, var

        for row in _rows(*arrays):
            keep(smoother.push(*row))
        keep(smoother.close())
        loglik, rho, terms = (
            smoother.log_likelihood,
            smoother.consistency,
            smoother.consistency_terms,
        )
    # "inflated": the a-posteriori variance factor of least squares (σ̂₀², Koch 1999, §3.2.2),
    # ρ, scales the noise band where the log's filter–smoother differences exceed the model's
    scale = math.sqrt(max(1.0, rho)) if band == "inflated" and math.isfinite(rho) else 1.0
    out_var *= scale**2
    if not (np.all(np.isfinite(out_v[k0:])) and np.all(np.isfinite(out_var[k0:]))):
        raise NonFiniteError(
            "the smoothed estimate is not finite (the filter is lost): check the model, the "
            "torques and noise_std, or smooth with accel_psd='auto' or observer='adaptive'"
        )
    # kf: none (its jerk_psd, chosen or given, is among the filter's options); adaptive
    # without a given density: each window's regime's (extra["model_accel_psd"])
    reported_psd = None
    if not model_free and (isinstance(accel_psd, float) or not adaptive):
        reported_psd = accel_psd if isinstance(accel_psd, float) else filt.gains.accel_psd
    opts = {
        **filt.options,
        **extra,
        "accel_psd": reported_psd,
        "observer": observer,
        "chunk": None if chunk is None and lag is None else n_chunk * dt,
        "overlap": n_over * dt if n_over else None,
        "lag": lag,
        "band": band,
        "band_scale": scale,
        "consistency_terms": terms,
        "noise_std": noise_std,
        "noise_std_from_log": noise_from_data,
        "accel_psd_from_log": accel_from_log,
        "latency": float(extra.get("latency", 0.0)),
        "latency_from_log": latency_from_log,
        "latency_searched": False,
        "missing_samples": t_all.size - t_given.size,
    }
    result = Smoothed(
        t=t_all,
        q=out_q[rows],  # each log sample's row (re-timed under a latency: _retimed)
        v=out_v[rows],
        v_std=np.sqrt(np.maximum(out_var[rows], 0.0)),
        log_likelihood=loglik,
        consistency=rho,
        options=opts,
    )
    # "auto" over ekf makes ρ about 1 whatever the log: a density above the filter's default
    # says the model does not explain the log at its own density, which a latency might (a
    # UR5 log 2 ms late: "auto" took 1e-2 rad²/s³, ρ 0.605, RMS 9.45e-3 rad/s; 1.8e-5 under
    # the latency)
    hidden = (
        accel_from_log
        and not adaptive
        and not model_free
        and isinstance(accel_psd, float)
        and accel_psd > make(None).gains.accel_psd
    )
    if not (
        find_latency
        and "latency" not in dict(filter_options or {})
        and not model_free  # without a model a late log is as likely: nothing to find
        and math.isfinite(rho)
        and (rho > RHO_WARN or hidden)
    ):
        return _at_rows(result, given_rows, t_given)
    # The model does not explain the log: a measurement latency might (module docstring).
    # Adopted only if the log smoothed under it is consistent (ρ ≤ RHO_WARN) and, where
    # "auto" chose the density, likelier by LIKELIHOOD_MARGIN (each at its own chosen density)
    found = 0.0
    # the log as stamped is the search's first candidate: its learning pass is done, and so
    # is its likelihood when the density is the one the search takes (not chosen by "auto")
    tried = {} if accel_from_log else {0.0: loglik}
    try:
        found = find(filter_options, tried)
    except (NonFiniteError, ObserverDiverged):
        pass  # lost at every latency: nothing found
    searched = {
        "latency_searched": True,
        "consistency_without_latency": rho,
        "accel_psd_without_latency": accel_psd if hidden else None,
        "latency_found": found,
    }

    def under(d: float, psd: Any) -> Smoothed:
        return smooth_quietly(
            robot,
            (t_all, q_all, tau_all),
            observer=observer,
            noise_std=noise_std,
            accel_psd=psd,
            disturbance_psd=disturbance_psd,
            chunk=chunk,
            overlap=overlap,
            lag=lag,
            model_window=model_window,
            filter_options={**dict(filter_options or {}), "latency": d},
            band=band,
            _prepared=prepared,
        )

    # "auto": the latency must first explain the log at the filter's own density (one pass;
    # the 20 % inertia/payload logs of UR5 and Panda found 0.5–3 ms there, ρ far above)
    if found > 0.0 and (not hidden or under(found, None).consistency <= RHO_WARN):
        retry = under(found, asked_psd)
        likelier = retry.log_likelihood > loglik + LIKELIHOOD_MARGIN
        if retry.consistency <= RHO_WARN and (likelier or not hidden):
            return _at_rows(
                replace(
                    retry,
                    options={
                        **retry.options,
                        **searched,
                        "latency_from_log": True,
                        "noise_std_from_log": noise_from_data,
                        "missing_samples": t_all.size - t_given.size,
                    },
                ),
                given_rows,
                t_given,
            )
    return _at_rows(replace(result, options={**result.options, **searched}), given_rows, t_given)


def _at_rows(result: Smoothed, rows: NDArray[np.intp] | None, t: Vector) -> Smoothed:
    """``result`` (of a log on the grid of its ticks: :func:`~pinobs.model.sampling.on_ticks`)
    at the given log's rows ``rows``, its times ``t``; as it is with ``rows`` None."""
    if rows is None:
        return result
    return replace(result, t=t, q=result.q[rows], v=result.v[rows], v_std=result.v_std[rows])
