"""White-noise levels measured on samples of a smooth signal.

For samples ``y_k = x(t_k) + e_k`` of a smooth motion ``x`` with white noise
``e_k ~ N(0, σ²)``, the third difference

    d_k = y_{k+3} - 3 y_{k+2} + 3 y_{k+1} - y_k

is ``h³ x⃛ + O(h⁴)`` plus noise of variance ``(1 + 9 + 9 + 1) σ² = 20 σ²``: it
is the residual of the exact quadratic fit through four samples, and the
factor 20 is that fit's degrees-of-freedom correction (the difference-based
variance estimator of Gasser, Sroka & Jennen-Steinmetz 1986, Biometrika 73(3),
eq. (2), with the binomial weights of order 3).  At 1 kHz the motion term is
~1e-9·|x⃛| rad, far below any realistic noise.  A glitch or an outlier must
not inflate σ, so the robust form is used:

    σ̂² = median(d_k²) / (20 · 0.4549)

(0.4549 is the median of a χ²₁ variable).  On four rows evenly spaced in time
(each interval within :data:`EVEN_TOL` of the median ``h``) that is the
binomial difference above.  On uneven ones (a dropped sample between them, or
irregular sampling) the binomial weights do not annihilate a straight line: a
motion at 1 rad/s sampled at intervals of ``h (1 ± 0.5)`` leaves ~``h·0.5`` rad,
above the noise (with 30 % of the samples dropped σ̂ was 2.0× σ, with 5 %
1.17×).  There ``d_k`` is the third divided difference instead, the
combination ``Σ wᵢ yᵢ``, ``wᵢ = 1 / Πⱼ≠ᵢ (tᵢ − tⱼ)``, that annihilates every
quadratic whatever the times, scaled to the same noise variance ``20 σ²``
(``d_k · √(20 / Σ wᵢ²)``; on even times it is the binomial difference).  Its
motion term grows as ``x⃛ H³`` with the four rows' span ``H``: four rows
spanning more than :data:`MAX_SPAN` median intervals are not used.

Used on positions by the observers (:mod:`pinobs.observers.noise`) and on
positions and torques by the identification (:mod:`pinobs.model.identification`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.model.robot import Vector

__all__ = ["CHI2_1_MEDIAN", "robust_rms", "third_difference_std"]

#: Median of a χ² variable with one degree of freedom: ``median(x²) / CHI2_1_MEDIAN`` is the
#: variance of zero-mean Gaussian ``x``, robustly (a few outlying rows do not move it).
CHI2_1_MEDIAN = 0.454936423119572
#: Σ binomial(3, k)²: the variance gain of the third difference.
_THIRD_DIFF_GAIN = 20.0

#: Four rows whose intervals are each within this fraction of the median are evenly
#: spaced (the binomial third difference); others use the divided difference.
EVEN_TOL = 0.01

#: Four rows spanning more than this many median intervals make no difference (module
#: docstring: the motion term grows as the span cubed; 5: one dropped sample between them).
MAX_SPAN = 5.0


def robust_rms(x: Vector) -> Vector:
    """Per column, ``√(median(x²) / median(χ²₁))``: the RMS of zero-mean Gaussian columns,
    unmoved by a few outlying rows."""
    return np.sqrt(np.median(x**2, axis=0) / CHI2_1_MEDIAN)


def third_difference_std(
    x: Vector,
    t: ArrayLike | None = None,
    idx: ArrayLike | None = None,
    *,
    min_runs: int = 1,
    robust: bool = True,
) -> Vector | None:
    """σ̂ per column of ``x`` (rows are samples; module docstring), or ``None`` with fewer
    than ``min_runs`` usable third differences.

    ``robust=False``: ``σ̂² = mean(d_k²) / 20`` instead of the median form, for samples
    known to hold no motion: a quantised reading's ``d_k`` take a few multiples of the step,
    whose squares' median is not ``0.4549`` times their mean (on a still joint of the real
    Go1 log, steps of 6e-5 rad, the median form gives 0, 2.0e-5 or 4.0e-5 and nothing between).

    Args:
        x: samples, shape ``(N, n)``; a difference with a non-finite entry is skipped.
        t: the rows' times [s], shape ``(N,)``: four rows evenly spaced make the
            binomial difference, unevenly spaced ones (within :data:`MAX_SPAN` median
            intervals) the scaled divided difference (module docstring).
            ``None``: the rows are taken as evenly spaced.
        idx: the rows' indices in the log they were taken from, shape ``(N,)``: a
            difference is used only over four consecutive indices (none dropped between).
        min_runs: fewest usable differences for an estimate.
    """
    x = np.asarray(x, dtype=float)
    d = x[3:] - 3.0 * x[2:-1] + 3.0 * x[1:-2] - x[:-3]  # Gasser et al. (1986), order 3
    even = np.ones(max(x.shape[0] - 1, 0), dtype=bool)  # row j to j+1: the next sample
    if idx is not None:
        even &= np.diff(np.asarray(idx)) == 1
    uneven = np.zeros(max(x.shape[0] - 3, 0), dtype=bool)
    if t is not None and even.size:
        tt = np.asarray(t, dtype=float)
        dt = np.diff(tt)
        h = float(np.median(dt))
        close = np.abs(dt - h) <= EVEN_TOL * h
        linked = even & (dt > 0)
        even &= close
        if d.shape[0] and not np.all(close):
            span = tt[3:] - tt[:-3]
            uneven = linked[:-2] & linked[1:-1] & linked[2:] & (span <= MAX_SPAN * h)
            uneven &= ~(even[:-2] & even[1:-1] & even[2:])
            if uneven.any():
                four = np.stack([tt[:-3], tt[1:-2], tt[2:-1], tt[3:]], axis=1)[uneven]
                diff = four[:, :, None] - four[:, None, :]
                np.einsum("kii->ki", diff)[...] = 1.0
                w = 1.0 / np.prod(diff, axis=2)  # the third divided difference's weights
                scale = np.sqrt(_THIRD_DIFF_GAIN / np.sum(w**2, axis=1))
                rows = np.flatnonzero(uneven)
                d = d.copy()
                d[rows] = np.einsum(
                    "ki,kij->kj", w * scale[:, None], x[rows[:, None] + np.arange(4)]
                )
    whole: NDArray[np.bool_] = (even[:-2] & even[1:-1] & even[2:]) | uneven  # d_k's four rows
    whole &= np.all(np.isfinite(d), axis=1)
    if np.count_nonzero(whole) < max(min_runs, 1):
        return None
    if not robust:
        return np.sqrt(np.mean(d[whole] ** 2, axis=0) / _THIRD_DIFF_GAIN)
    return np.sqrt(np.median(d[whole] ** 2, axis=0) / (_THIRD_DIFF_GAIN * CHI2_1_MEDIAN))
