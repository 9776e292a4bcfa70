"""The measurement latency from the log: the likeliest on a grid refined by golden sections
(:func:`select_latency`), and the note :func:`pinobs.smooth` gives when one was found."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import (
    GainError,
    NonFiniteError,
    ObserverDiverged,
)
from pinobs.model import Robot
from pinobs.observers.base import (
    Vector,
)
from pinobs.smoothing.densities import forward_log_likelihood
from pinobs.smoothing.filters import prepare_log
from pinobs.smoothing.logs import LogLike, smoothing_arrays

__all__ = ["LATENCY_INTERVALS", "latency_note", "likeliest_latency", "select_latency"]

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
    (:func:`retimed`; ``adaptive``: its learning pass under ``latency=d``, then
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
    return likeliest_latency(
        robot,
        smoothing_arrays(robot, log),
        noise_std,
        observer,
        accel_psd,
        disturbance_psd,
        filter_options,
        model_window,
        intervals,
    )


def likeliest_latency(
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
    """:func:`select_latency` on checked arrays; ``prepared`` (latency → :func:`prepare_log`'s
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
                    prepared[d] = prepare_log(
                        robot, t, q, tau, observer, noise_std, disturbance_psd, opts, model_window
                    )
            except (NonFiniteError, ObserverDiverged, np.linalg.LinAlgError):
                tried[d] = -math.inf
            else:
                arrays, k0, _, make, _ = prepared[d]
                tried[d] = forward_log_likelihood(make(accel_psd), arrays, k0)
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
