"""What the stamps' order and the motion say about a log's ticks (:mod:`pinobs.io.clock`).

- :func:`in_order`: the rows of the longest strictly increasing run of stamps (the fewest
  rows left out for the stamps to increase); the rows left out are outliers, placed by
  :func:`place_between` (module docstring of :mod:`pinobs.io.clock`, step 2).
- :func:`resolve_by_motion` (step 3) and :func:`place_between`: a tick chosen by linear
  interpolation of the position between the neighbouring rows.
- :func:`interp_error` (step 4): how smooth the motion is under a clock.
- :func:`successive_ratio` (step 4): whether the stamps' residuals about a line are the
  independent delays of a logger on a loop, or wander.
"""

from __future__ import annotations

from bisect import bisect_left
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "in_order",
    "interp_error",
    "monotone",
    "place_between",
    "resolve_by_motion",
    "successive_ratio",
]

Bool = NDArray[np.bool_]
Floats = NDArray[np.floating[Any]]
Idx = NDArray[np.intp]


def monotone(n: Floats) -> Floats:
    """The smallest strictly increasing sequence ≥ ``n`` elementwise."""
    k = np.arange(n.size, dtype=float)
    return np.maximum.accumulate(n - k) + k


def in_order(t: Floats, reach: int = 4, rounds: int = 8) -> Bool:
    """The rows whose stamps ``t`` (finite) increase once the outliers are left out.

    Where two successive rows are out of order, the one farther from its neighbours'
    prediction leaves, ``d_k = |t_k − median_{0<|o|≤reach} (t_{k+o} − o·h)|``, ``h`` the
    median interval (a row stamped far ahead or behind, a glitch, leaves alone, not the
    rows after it, which a running maximum left out); ``rounds`` times, then what is still
    out of order by a longest increasing subsequence (patience sorting, ``O(N log N)``:
    Fredman 1975, "On computing the length of longest increasing subsequences", Discrete
    Math. 11: 29–35).  Stamps already increasing: every row, nothing computed.
    """
    n = t.size
    keep = np.ones(n, dtype=bool)
    if n < 2 or bool(np.all(np.diff(t) > 0)):
        return keep
    h = float(np.median(np.diff(t)))
    pad = np.r_[np.full(reach, np.nan), t, np.full(reach, np.nan)]
    pred = [pad[reach + o : reach + o + n] - o * h for o in range(-reach, reach + 1) if o]
    dev = np.abs(t - np.nanmedian(np.vstack(pred), axis=0))
    for _ in range(rounds):
        k = np.flatnonzero(keep)
        bad = np.flatnonzero(np.diff(t[k]) <= 0)
        if bad.size == 0:
            return keep
        a, b = k[bad], k[bad + 1]
        keep[np.where(dev[a] >= dev[b], a, b)] = False
    k = np.flatnonzero(keep)
    keep[k[~_increasing(t[k])]] = False
    return keep


def _increasing(t: Floats) -> Bool:
    """The rows of a longest strictly increasing subsequence of ``t`` (patience sorting:
    ``tails[j]`` the smallest last stamp of an increasing run of length ``j + 1``)."""
    n = t.size
    tails: list[float] = []
    ends: list[int] = []
    prev = np.full(n, -1, dtype=np.intp)
    for i, x in enumerate(t.tolist()):
        j = bisect_left(tails, x)
        prev[i] = ends[j - 1] if j else -1
        if j == len(tails):
            tails.append(x)
            ends.append(i)
        else:
            tails[j] = x
            ends[j] = i
    keep = np.zeros(n, dtype=bool)
    i = ends[-1] if ends else -1
    while i >= 0:
        keep[i] = True
        i = int(prev[i])
    return keep


def _predicted(qa: Floats, qb: Floats, frac: Floats) -> Floats:
    return qa + (qb - qa) * frac[:, None]


def resolve_by_motion(
    n: Floats, frac: Floats, q: Floats, scale: Floats, ambiguous: float
) -> Floats:
    """Stamps farther than ``ambiguous`` periods from their tick placed by the motion: of
    the two ticks the stamp falls between, the one where linear interpolation between the
    neighbouring rows predicts the row's position best."""
    k = np.flatnonzero(np.abs(frac) > ambiguous)
    k = k[(k > 0) & (k < n.size - 1)]
    if k.size == 0:
        return n
    na, nb = n[k - 1], n[k + 1]
    low = n[k] - (frac[k] < 0)  # the two ticks the stamp falls between: low, low + 1
    span = np.where(nb > na, nb - na, 1.0)
    errs = []
    for c in (low, low + 1.0):
        pred = _predicted(q[k - 1], q[k + 1], (c - na) / span)
        e = np.nansum(((q[k] - pred) / scale) ** 2, axis=1)
        errs.append(np.where((na < c) & (c < nb), e, np.inf))
    choice = np.where(errs[1] < errs[0], low + 1.0, low)
    ok = np.isfinite(np.minimum(errs[0], errs[1]))
    out = n.copy()
    out[k[ok]] = choice[ok]
    return monotone(out)


def place_between(ticks: Floats, rows: Idx, q: Floats, scale: Floats) -> Floats:
    """Ticks for the outlier ``rows`` (their stamps out of order), in increasing order:
    between the ticks ``na < nb`` of the nearest placed rows before and after (``ticks``
    finite there, an outlier placed before counting), the free tick ``na < c < nb`` where
    linear interpolation of the position between those rows predicts the row's best.
    Without a free tick, or a placed row on either side, the row stays unplaced (NaN)."""
    out = ticks.copy()
    for k in np.sort(rows):
        placed = np.flatnonzero(np.isfinite(out))
        j = int(np.searchsorted(placed, k))
        if j == 0 or j == placed.size:
            continue
        a, b = int(placed[j - 1]), int(placed[j])
        na, nb = float(out[a]), float(out[b])
        if nb - na < 2 or not np.isfinite(q[[a, b, k]]).all():
            continue
        c = np.arange(na + 1.0, nb)
        pred = q[a] + np.outer((c - na) / (nb - na), q[b] - q[a])
        out[k] = c[int(np.argmin((((q[k] - pred) / scale) ** 2).sum(axis=1)))]
    return out


def interp_error(t: Floats, q: Floats, scale: Floats) -> tuple[float, int]:
    """Σ over moving interior rows of the squared error of predicting each row by linear
    interpolation between its neighbours, per joint in units of ``scale``; and the count."""
    if t.size < 3:
        return 0.0, 0
    ta, tk, tb = t[:-2], t[1:-1], t[2:]
    qa, qk, qb = q[:-2], q[1:-1], q[2:]
    with np.errstate(invalid="ignore", divide="ignore"):
        w = ((tk - ta) / (tb - ta))[:, None]
        e = (qk - (qa + (qb - qa) * w)) / scale
    moving = (np.abs(qb - qa) > 4 * scale * 1e-3).any(axis=1)
    ok = np.isfinite(e).all(axis=1) & moving & (tb > ta)
    return float(np.sum(e[ok] ** 2)), int(ok.sum())


def successive_ratio(r: Floats) -> float:
    """von Neumann's ratio ``η = Σ (r_k − r_{k−1})² / Σ (r_k − r̄)²`` of residuals ``r``.

    Independent residuals give ``η ≈ 2`` (mean ``2N/(N−1)``, s.d. ``≈ 2/√N``); residuals
    that wander (each carrying the previous one's error, a random walk) give ``η → 0``
    (von Neumann 1941, "Distribution of the ratio of the mean square successive difference
    to the variance", Ann. Math. Statist. 12(4): 367–395).  ``η = 2(1 − ρ₁)`` for
    stationary residuals of lag-one autocorrelation ``ρ₁``.  No spread: 2 (nothing wanders).
    """
    r = r - r.mean()
    ss = float(np.sum(r**2))
    if r.size < 3 or ss == 0.0:
        return 2.0
    return float(np.sum(np.diff(r) ** 2) / ss)
