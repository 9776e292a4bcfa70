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
(:func:`retimed`): each sample at the time it was taken, ``t − d``, each torque
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
compiled passes over those factors (:func:`white_jerk_smooth`, tested equal
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
noise alone, ``Pⁿˢ`` (:func:`noise_step` forward, :func:`_backward`'s
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

The layer's modules, each one concern (all built on the observers' public protocol,
:class:`pinobs.observers.base.GaussianFilter` and the families' class attributes):
:mod:`~pinobs.smoothing.rts` (the forward pass and the RTS backward pass, :class:`Smoother`),
:mod:`~pinobs.smoothing.band` (the noise band), :mod:`~pinobs.smoothing.jerk` (the compiled
white-jerk smoother of ``kf``), :mod:`~pinobs.smoothing.windows` (chunks, overlaps),
:mod:`~pinobs.smoothing.logs` (a log's arrays, re-timing), :mod:`~pinobs.smoothing.replay`
(``adaptive``'s learning replay, its models frozen per window),
:mod:`~pinobs.smoothing.filters` (the filter smoothed), :mod:`~pinobs.smoothing.densities`
(``accel_psd="auto"``), :mod:`~pinobs.smoothing.latency` (the latency search),
:mod:`~pinobs.smoothing.api` (:func:`smooth`, :func:`streaming_smoother`),
:mod:`~pinobs.smoothing.pipeline` (:func:`smooth_quietly`, step by step), :mod:`~pinobs.smoothing.constants`.
"""

from __future__ import annotations

from pinobs.smoothing.api import (
    smooth,
    smoothing_warnings,
    streaming_smoother,
)
from pinobs.smoothing.constants import (
    AUTO_WHITE_SCALE,
    BANDS,
    CHUNK_TOL,
    COST_WARN,
    DEFAULT_ACCEL_PSD,
    DEFAULT_GRID,
    JERK_GRID,
    LIKELIHOOD_MARGIN,
    OFFSET_SCALE_RANGE,
    OVERLAP_CONFIGURATIONS,
    RHO_WARN,
)
from pinobs.smoothing.densities import consistent_offset_scale, select_accel_psd
from pinobs.smoothing.latency import LATENCY_INTERVALS, latency_note, select_latency
from pinobs.smoothing.logs import LogLike, log_noise_std
from pinobs.smoothing.pipeline import smooth_quietly
from pinobs.smoothing.rts import Smoothed, Smoother
from pinobs.smoothing.windows import default_overlap

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
    "OVERLAP_CONFIGURATIONS",
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
