"""Process densities from the log (``accel_psd="auto"``): the likeliest on a grid
(:func:`select_accel_psd`) and, for ``adaptive``, the offset scale that makes the smoother
consistent (:func:`consistent_offset_scale`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import (
    GainError,
    NonFiniteError,
    ObserverDiverged,
)
from pinobs.model import Robot
from pinobs.observers.base import (
    GaussianFilter,
    Vector,
    observer_class,
    positive,
)
from pinobs.observers.kf import KFBank, WhiteJerkFilter
from pinobs.smoothing.constants import (
    DEFAULT_GRID,
    JERK_GRID,
    LIKELIHOOD_MARGIN,
    OFFSET_SCALE_RANGE,
)
from pinobs.smoothing.filters import prepare_log
from pinobs.smoothing.logs import LogLike, smoothing_arrays
from pinobs.smoothing.rts import Smoother, forward_pass, log_rows

__all__ = [
    "consistent_offset_scale",
    "consistent_scale",
    "forward_log_likelihood",
    "select_accel_psd",
    "select_density",
]


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
    once more with the half-decades either side of its choice added (:mod:`pinobs.smoothing`).

    Raises:
        GainError: an empty grid, a non-positive candidate or threshold.
    """
    arrays, k0, _, make, _ = prepare_log(
        robot,
        *smoothing_arrays(robot, log),
        observer,
        noise_std,
        disturbance_psd,
        filter_options,
        model_window,
    )
    model_free = observer_class(observer).model_free
    if grid is None:
        grid = JERK_GRID if model_free else DEFAULT_GRID
    return select_density(make, arrays, k0, grid, threshold, model_free)


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
    white acceleration that widens the smoother's band (:mod:`pinobs.smoothing`).
    Uses no ground truth; costs one learning pass and 3–7 smoother passes
    (measured on the README's twelve model-error logs of seeds 1 and 2).

    Raises:
        GainError: ``tol`` ≤ 0, ``max_passes`` < 1, or a bad filter option.
    """
    positive("tol", tol)
    if max_passes < 1:
        raise GainError(f"max_passes={max_passes!r}: give at least 1 smoother pass")
    arrays, _, _, make, _ = prepare_log(
        robot,
        *smoothing_arrays(robot, log),
        "adaptive",
        noise_std,
        None,
        filter_options,
        model_window,
    )
    return consistent_scale(make, arrays, tol, max_passes)


def consistent_scale(
    make: Callable[..., GaussianFilter],
    arrays: tuple[Vector, Vector, Vector, Vector],
    tol: float = 0.02,
    max_passes: int = 8,
) -> float:
    """:func:`consistent_offset_scale` on checked arrays and ``adaptive``'s frozen-model maker."""
    lo, hi = (math.log10(b) for b in OFFSET_SCALE_RANGE)

    def f(x: float) -> float:  # log ρ at s = 10ˣ: one smoother pass
        smoother = Smoother(make(None, 10.0**x), None, 0)
        for row in log_rows(*arrays):
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


def select_density(
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
            return [forward_log_likelihood(make(psd), arrays, k0) for psd in psds]
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


def forward_log_likelihood(
    filt: GaussianFilter, arrays: tuple[Vector, Vector, Vector, Vector], k0: int
) -> float:
    """``ℓ`` of :func:`select_accel_psd` for one filter; ``−∞`` if the filter is lost on the log
    (its covariance or estimate stops being finite: under a model error a small density
    makes the filter overconfident until it diverges), which rejects the candidate."""
    with np.errstate(over="ignore", invalid="ignore"):
        try:
            ll = sum(ll for *_, ll, _ in forward_pass(filt, log_rows(*arrays), k0))
        except (NonFiniteError, ObserverDiverged, np.linalg.LinAlgError):
            return -math.inf
    return ll if math.isfinite(ll) else -math.inf
