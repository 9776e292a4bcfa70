"""Accuracy and cost of each observer in a :class:`~pinobs.simulation.Result`.

Definitions (used by every table pinobs prints):

* velocity error ``e_k = v̂_k − v_k`` in Pinocchio's tangent frame;
* **rms_v_error** [rad/s]: ``sqrt(mean over samples t_k ≥ transient and joints of e²)``;
* **max_v_error** [rad/s]: the largest ``|e_k|_∞`` after the transient;
* **rms_q_error** [rad]: the same RMS for ``difference(q_k, q̂_k)``;
* **convergence_time** [s]: the first time after which the moving RMS of
  ``|e|₂`` (window of 20 samples) stays below
  ``max(3 × its value over the last half of the run, 1 % of its maximum)``;
  0 when it never leaves that band;
* **time_per_update** [s]: mean wall time of one ``update`` call, the slowest
  1 % of calls left out (a preempted process, not the observer).  A mean,
  not a median, so work an observer does every k-th sample (``riemannian``'s
  Jacobi operator, every 10th) is counted at its amortised share.

``transient`` defaults to a quarter of the run.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from pinobs.errors import GainError
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.simulation import Result

__all__ = ["Metrics", "convergence_time", "evaluate", "trimmed_mean"]

_WINDOW = 20


@dataclass(frozen=True)
class Metrics:
    """Accuracy and cost of one observer on one run (definitions in the module docstring)."""

    observer: str
    rms_v_error: float
    max_v_error: float
    rms_q_error: float
    convergence_time: float
    time_per_update: float
    diverged_at: float | None

    def as_dict(self) -> dict[str, Any]:
        """Plain dict for JSON."""
        return asdict(self)


def trimmed_mean(times: Vector, *, drop: float = 0.01) -> float:
    """Mean of ``times`` without its slowest ``drop`` fraction (preemptions), at least one kept."""
    x = np.sort(np.asarray(times, dtype=float))
    keep = max(1, math.ceil(x.size * (1.0 - drop)))
    return float(np.mean(x[:keep]))


def convergence_time(t: Vector, err: Vector) -> float:
    """First time after which the moving RMS of ``err`` stays in its final band (module docstring)."""
    if len(err) < 2 * _WINDOW or not np.all(np.isfinite(err)):
        return math.inf
    kernel = np.ones(_WINDOW) / _WINDOW
    smooth = np.sqrt(
        np.convolve(err**2, kernel, mode="full")[: len(err)]
        / np.minimum(np.arange(1, len(err) + 1), _WINDOW)
        * _WINDOW
    )
    tail = smooth[len(smooth) // 2 :]
    band = max(3.0 * float(np.sqrt(np.mean(tail**2))), 0.01 * float(smooth.max()))
    above = np.flatnonzero(smooth > band)
    if above.size == 0:
        return 0.0
    last = int(above[-1])
    return float(t[last + 1]) if last + 1 < len(t) else math.inf


def evaluate(result: Result, robot: Robot, *, transient: float | None = None) -> list[Metrics]:
    """Metrics of every observer in ``result`` (``robot`` supplies the configuration difference).

    Raises:
        GainError: ``transient`` [s] not finite, negative, or not shorter than the run.
    """
    t = result.t
    span = float(t[-1] - t[0])
    if transient is not None and not (
        isinstance(transient, int | float) and math.isfinite(transient) and 0 <= transient < span
    ):
        raise GainError(
            f"transient={transient!r} is out of range; give a time [s] >= 0 and shorter than "
            f"the run ({span:g} s)"
        )
    t_tr = 0.25 * span if transient is None else transient
    after = t >= t[0] + t_tr
    out = []
    for tr in result.traces:
        e_v = tr.v - result.v
        finite = np.all(np.isfinite(tr.v)) and np.all(np.isfinite(tr.q))
        if finite:
            e_q = np.array([robot.difference(q, qh) for q, qh in zip(result.q, tr.q, strict=True)])
            rms_v = float(np.sqrt(np.mean(e_v[after] ** 2)))
            max_v = float(np.max(np.abs(e_v[after])))
            rms_q = float(np.sqrt(np.mean(e_q[after] ** 2)))
            t_conv = convergence_time(t, np.linalg.norm(e_v, axis=1))
        else:
            rms_v = max_v = rms_q = t_conv = math.inf
        times = tr.update_time[1:]
        times = times[np.isfinite(times)]
        out.append(
            Metrics(
                observer=tr.name,
                rms_v_error=rms_v,
                max_v_error=max_v,
                rms_q_error=rms_q,
                convergence_time=t_conv,
                time_per_update=trimmed_mean(times) if times.size else math.nan,
                diverged_at=tr.diverged_at,
            )
        )
    return out
