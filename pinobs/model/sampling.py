"""Logs off a uniform grid: dropped samples and irregular intervals.

A real robot's log comes from a control loop of fixed period ``P`` that drops
samples: the interval between two rows is ``2P``, ``3P``, … (a repaired clock
puts every row on a tick ``k·P``, some ticks missing).  Other logs are truly
irregular but correctly stamped (intervals anywhere in ``0.5P–1.5P``).  The
offline tools (identification, smoothing) use the true intervals; what they
share is here:

* the **period** ``P`` is the median interval (dropped samples are a minority of
  the intervals);
* an interval of ``Δ ≥`` :data:`MISSING_PERIODS` ``· P`` holds ``m − 1`` **missing
  samples**, ``m = round(Δ/P)`` (:func:`missing_samples`); a truly irregular log (every
  interval below ``1.5 P``) has none.  Not from ``1.5 P`` on: on a UR5 log sampled at
  intervals uniform in 0.5–1.5 ms (a control loop holding each torque over its own
  interval), taking the 78 intervals just above ``1.5 P`` (``P`` the median, a little
  under 1 ms) as a lost sample each made the smoother's velocity error 1.70× that of a
  clean 1 kHz log (seed 1);
* the **torque** of a missing sample is unknown: a zero-order hold (MATH §7) held
  ``τ_a`` over the first tick, then values the log lost; they are taken on the line
  from ``τ_a`` to ``τ_b``, so over the interval (:func:`held_torque_integral`)::

      ∫ τ dt = Δ τ_a + (τ_b − τ_a) Δ (m − 1) / (2m)

  (the hold's exact integral when ``m = 1``; for a torque varying at ``τ̇`` the
  interpolation errs by ``O(τ̈ Δ³)``, where holding ``τ_a`` over the whole gap errs by
  ``τ̇ Δ² (m − 1)/(2m)``: on a UR5 log with 8 % of its rows dropped, smoothing
  with ``τ_a`` held across each gap made the velocity error 33× that of the clean
  log, with the line 1.3×);
* a gap longer than :data:`SPLIT_GAP_PERIODS` periods splits the log (its two sides
  are smoothed and integrated apart): a broken log, not a dropped sample.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pinobs.model.robot import Vector

__all__ = [
    "MISSING_PERIODS",
    "SPLIT_GAP_PERIODS",
    "UNIFORM_TOL",
    "held_torque_integral",
    "is_uniform",
    "missing_samples",
    "on_ticks",
    "period",
]

#: A gap between two finite rows longer than this many periods splits a log into
#: stretches (identification, :func:`pinobs.model.identification.segments`).  Dropped
#: runs of up to 9 samples (intervals of 10 periods) are inside it with a margin; a
#: Savitzky–Golay fit over ±50 ms and a window of 100 ms still hold a 16 ms gap.
SPLIT_GAP_PERIODS = 16.0

#: An interval of at least this many periods has lost samples (module docstring): between
#: the 1.5 periods an irregular log's interval may reach and the 2 of one dropped sample.
MISSING_PERIODS = 1.75

#: Every interval within this fraction of the median: the log is on a uniform grid (the
#: uniform-grid code paths, unchanged for such logs, are taken).
UNIFORM_TOL = 0.1


def period(t: Vector) -> float:
    """The median interval of increasing times ``t`` [s] (NaN with fewer than two)."""
    return float(np.median(np.diff(t))) if t.shape[0] > 1 else float("nan")


def is_uniform(t: Vector, h: float | None = None) -> bool:
    """Whether every interval of ``t`` is within :data:`UNIFORM_TOL` of the median ``h``."""
    if t.shape[0] < 2:
        return True
    h = period(t) if h is None else h
    return bool(np.all(np.abs(np.diff(t) - h) <= UNIFORM_TOL * h))


def missing_samples(t: Vector, h: float | None = None) -> NDArray[np.intp]:
    """Per interval ``Δ`` of ``t``, the samples it lost: ``round(Δ/h) − 1`` from
    :data:`MISSING_PERIODS` periods on, else 0 (``h``: the period, default the median
    interval)."""
    h = period(t) if h is None else h
    if t.shape[0] < 2:
        return np.zeros(0, dtype=np.intp)
    ratio = np.diff(t) / h
    return np.where(ratio >= MISSING_PERIODS, np.rint(ratio).astype(np.intp) - 1, 0)


def held_torque_integral(t: Vector, tau: Vector, h: float | None = None) -> Vector:
    """``∫_{t_0}^{t_k} τ dt`` at every row, for a zero-order-hold torque with the missing
    samples' torques on the line between their neighbours (module docstring).

    Args:
        t: row times [s], increasing, shape ``(N,)``.
        tau: torques held from each row on, shape ``(N, n)``.
        h: the period [s] (default: the median interval).
    """
    out = np.zeros_like(tau)
    if t.shape[0] < 2:
        return out
    dt = np.diff(t)
    inc = tau[:-1] * dt[:, None]
    lost = missing_samples(t, h)
    gap = lost > 0
    if gap.any():
        m = lost[gap] + 1.0
        inc[gap] += (tau[1:][gap] - tau[:-1][gap]) * (dt[gap] * (m - 1.0) / (2.0 * m))[:, None]
    out[1:] = np.cumsum(inc, axis=0)
    return out


def on_ticks(
    t: Vector, q: Vector, tau: Vector, h: float | None = None
) -> tuple[Vector, Vector, Vector, NDArray[np.intp] | None]:
    """The log on the grid of its ticks: ``(t, q, tau, rows)``, each missing sample
    (:func:`missing_samples`) a row at its tick (spread evenly over its interval) with NaN
    positions and the torque on the line between its neighbours; ``rows`` the indices of
    the given rows in the result (``None``: nothing was missing, the arrays are the given
    ones).

    A filter fed this predicts over each missing sample with its torque (MATH §7), where
    fed the log itself it would hold ``τ_a`` over the whole gap (module docstring).
    """
    lost = missing_samples(t, h)
    if not lost.any():
        return t, q, tau, None
    n_out = t.shape[0] + int(lost.sum())
    rows = np.arange(t.shape[0]) + np.concatenate([[0], np.cumsum(lost)])
    t_out = np.empty(n_out)
    q_out = np.full((n_out, q.shape[1]), np.nan)
    tau_out = np.empty((n_out, tau.shape[1]))
    t_out[rows], q_out[rows], tau_out[rows] = t, q, tau
    for k in np.flatnonzero(lost):
        m = int(lost[k]) + 1
        s = np.arange(1, m) / m  # the missing ticks' places along the interval
        r = rows[k] + np.arange(1, m)
        t_out[r] = t[k] + s * (t[k + 1] - t[k])
        tau_out[r] = tau[k] + s[:, None] * (tau[k + 1] - tau[k])
    return t_out, q_out, tau_out, rows
