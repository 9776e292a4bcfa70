"""The smoothing layer's defaults and thresholds (:mod:`pinobs.smoothing` for what each means)."""

from __future__ import annotations

__all__ = [
    "AUTO_WHITE_SCALE",
    "BANDS",
    "CHUNK_TOL",
    "COST_WARN",
    "DEFAULT_ACCEL_PSD",
    "DEFAULT_GRID",
    "JERK_GRID",
    "LIKELIHOOD_MARGIN",
    "OFFSET_SCALE_RANGE",
    "OVERLAP_CONFIGURATIONS",
    "RHO_WARN",
]

#: Default white-acceleration density of the smoothed filter [rad²/s³] (:mod:`pinobs.smoothing`).
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
