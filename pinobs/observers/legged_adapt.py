"""The feet's contact density matched to their innovations online: the invariant EKF's
``adapt_noise`` (:class:`pinobs.observers.inekf.InvariantEKF`, its eq. 12).

Covariance matching (Mehra 1972 §IV; Myers & Tapley 1976): a filter whose noise densities
are right has innovations whose covariance is the one it predicts, ``E[r rᵀ] = S``.  Here the
density scaled is the feet's, ``Q_c,dj`` (the contact density with the ``slip_speed`` and
landing terms: what sets ``S`` while walking), by one factor ``α_a`` per axis ``a`` of the
IMU frame (the feet's error ``ε_dj`` in ``Q_c`` is in that frame)::

    Q_c,dj ← diag(α) Q_c,dj                                                           (A1)

and ``α`` follows each measured foot's innovation in the IMU frame, ``e = R̂ᵀ r_j``,
``s = diag(R̂ᵀ S_jj R̂)`` (eqs. 4 and 8 of :mod:`~pinobs.observers.inekf`, before the update),
by :func:`pinobs.observers.neverbehind.match_density`'s log-domain stochastic approximation
(Robbins & Monro 1951) with its step weighted::

    log α_a ← log α_a + (h / (T K)) f_a (clip(log(e_a² / s_a), −8, 5) − m),
    f_a = min(1, α_a q_a h / s_a)                                                     (A2)

``K`` the feet measured (each foot one innovation: ``T`` is a time, whatever ``K``), ``m`` the
clipped ``log χ²₁``'s mean (−1.24), ``q_a h`` the foot's own density over the last step
(after (A1)).  ``f_a`` is the share of ``s_a`` that ``α_a`` sets: after an update the
combination ``ξ_p − ξ_dj`` is pinned to about ``N_j``, so the next ``S_jj`` is that, the step's
foot density ``q h`` and the base's (``P_vv h²`` and the IMU's).  It is ``∂ log s/∂ log α``,
the sensitivity the matching needs: where ``α`` sets the innovation's variance (walking: the
slip term, ``f`` ≈ 1) it learns at ``h/T``; where something else does (standing: the IMU's
densities through ``P``, ``f`` ≪ 1) the innovations say nothing of ``α``, and it is left
alone instead of being driven to its bound.

Only ``α`` is matched.  A scale on the IMU's densities matched from the same innovations is
not identifiable beside it: per axis the feet's zero-lag innovations give one number, their
variance, to which the gyro's, the accelerometer's and the feet's densities all add (Mehra
1972: from ``E[r rᵀ]`` alone at most as many noise parameters as the innovation has
independent entries; the rest only through the innovations' time correlation); the two are
separable only where their shares ``f`` differ (the IMU's where standing, the feet's while
walking), and a process-noise scale learned while standing (the real Go1 log wants ~0.03)
would carry its over-trust into the walking that follows (the real log's ``IMU densities ÷
10`` row: walking rows above their interval 7.7 → 18.5 %; ``benchmarks/legged_real_innovations.md``).
Tried in ``benchmarks/legged_adapt_noise.py`` (a variant there, not here): with the
simulation's own IMU densities the scale ran to its bound 0.01 and the velocity's NEES/3 to
12-19 (``benchmarks/legged_adapt_noise.md``).
"""

from __future__ import annotations

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.neverbehind import match_density

__all__ = ["ADAPT_BOUNDS", "match_foot_scale", "scaled_densities"]

#: The bounds of ``α`` (A2): a hundredth to a hundred times the feet's density.
ADAPT_BOUNDS = np.array([1e-2, 1e2])


def scaled_densities(qc: Vector, scale: Vector, n_feet: int) -> Vector:
    """(A1): ``Q_c`` (filter order ``R, v, p, d_1 … d_K, b_g, b_a``) with each foot's block
    multiplied by ``scale`` (3,), read-only."""
    out = np.array(qc, dtype=float)
    out[9 : 9 + 3 * n_feet] *= np.tile(scale, n_feet)
    out.setflags(write=False)
    return out


def match_foot_scale(
    scale: Vector, e: Vector, s: Vector, q_h: Vector, dt: float, window: float
) -> Vector:
    """(A2) for one sample: ``scale`` ``α`` (3,) after the feet's innovations ``e`` (K, 3) and
    predicted variances ``s`` (K, 3) in the IMU frame, ``q_h`` (K, 3) each foot's density
    times the step (after (A1)), ``dt`` the step [s], ``window`` ``T`` [s]."""
    k = e.shape[0]
    share = np.minimum(q_h / np.maximum(s, 1e-300), 1.0) / k
    for i in range(k):
        scale = match_density(
            scale, e[i], s[i], dt, window=window, bounds=ADAPT_BOUNDS, weight=share[i]
        )
    return scale
