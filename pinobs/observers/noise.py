"""The position noise level of recorded samples, estimated from the samples themselves.

Third differences of the positions in the tangent coordinates
``difference(q_0, q_k)`` (so that quaternions and (cos, sin) pairs count as
angles), robustly (:func:`pinobs.model.noise.third_difference_std`: Gasser,
Sroka & Jennen-Steinmetz 1986; only runs of four consecutive, evenly spaced rows).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from pinobs.model import Robot
from pinobs.model.noise import third_difference_std
from pinobs.model.robot import Vector

__all__ = [
    "NOISE_MIN_SAMPLES",
    "NOISE_WINDOW",
    "STILL_STD",
    "estimate_noise_std",
    "joint_noise_std",
    "moving_median",
    "noise_from_log",
    "quantisation_std",
    "still_noise_std",
    "stillest_rows",
    "window_times",
]

#: Fewest usable rows for an estimate.
_MIN_ROWS = 12

#: Seconds of samples (and at least :data:`NOISE_MIN_SAMPLES` rows) σ is estimated from: a
#: log's first second (:func:`estimate_noise_std`), an observer's first second after its
#: reset (:class:`pinobs.observers.base.Observer`).
NOISE_WINDOW = 1.0
NOISE_MIN_SAMPLES = 200

#: [rad or m] A joint whose σ̂ is at most this tells nothing of the noise: its printed
#: position never changes (its third differences are rounding, σ̂ ~ 1e-17).
STILL_STD = 1e-12


def window_times(kept: Sequence[tuple[float, Any, Any]]) -> list[float] | None:
    """The times of the updates ``kept`` (``(t, q, τ)``, ``t`` increasing) that have a sample
    ``q``, once they are :data:`NOISE_MIN_SAMPLES` or more spanning :data:`NOISE_WINDOW` s or
    more (an observer's σ̂ window, :class:`pinobs.observers.base.Observer`); else ``None``.
    Listed only once all of ``kept`` are as many and span as long (those with ``q`` are no
    more and, ``t`` increasing, span no longer): an observer asks at every update."""
    if len(kept) < NOISE_MIN_SAMPLES or kept[-1][0] - kept[0][0] < NOISE_WINDOW:
        return None
    ts = [x[0] for x in kept if x[1] is not None]
    if len(ts) < NOISE_MIN_SAMPLES or ts[-1] - ts[0] < NOISE_WINDOW:
        return None
    return ts


def estimate_noise_std(
    t: Vector,
    q: Vector,
    robot: Robot,
    *,
    window: float = NOISE_WINDOW,
    min_rows: int = NOISE_MIN_SAMPLES,
) -> Vector | None:
    """σ per velocity coordinate [rad or m] from the first ``window`` seconds of a log.

    Args:
        t: times [s], shape ``(N,)`` (NaN rows are skipped).
        q: configurations, shape ``(N, nq)`` (rows with NaN are skipped).
        robot: the robot of the log.
        window: length of the stretch used [s], from the first usable row.
        min_rows: use at least this many rows when the window holds fewer.

    Returns:
        σ̂ per joint velocity coordinate, shape ``(nv,)``, or ``None`` with fewer
        than 12 usable rows or 9 runs of four consecutive evenly spaced ones.
    """
    q = np.asarray(q, dtype=float)
    idx = _rows(t, q, window, min_rows)
    if idx is None:
        return None
    if robot.is_vector_space:
        x = q[idx]
    else:
        ref = robot.normalize(q[idx[0]])
        x = np.array([robot.difference(ref, robot.normalize(q[i])) for i in idx])
    return third_difference_std(x, np.asarray(t, dtype=float)[idx], idx, min_runs=_MIN_ROWS - 3)


def still_noise_std(
    t: Vector, q: Vector, robot: Robot, *, window: float = NOISE_WINDOW
) -> Vector | None:
    """σ per velocity coordinate [rad or m] from the log's stillest ``window`` seconds, each at
    least the rounding of its printed positions::

        w* = argmin_w max_j (max_{k∈w} x_kj − min_{k∈w} x_kj)        (the stillest window)
        σ_j = max(√(mean_{k∈w*} d_kj² / 20),  δ_j/√12)

    ``x`` the positions in tangent coordinates, ``w`` the windows of ``window`` s of finite
    rows (starting every ``window/2`` s; the whole log when shorter), ``d`` the third
    differences over four consecutive, evenly spaced rows (Gasser, Sroka & Jennen-Steinmetz
    1986: variance ``20 σ²`` for white noise; the mean form,
    :func:`pinobs.model.noise.third_difference_std` with ``robust=False``, since a quantised
    reading's ``d`` take a few multiples of its step) and ``δ_j/√12``
    :func:`quantisation_std` (Widrow & Kollár 2008, §4.1; a joint whose reading repeats
    while still shows no third differences there).

    Why the stillest window and not the first second (:func:`estimate_noise_std`): a robot
    moving at the start (the real Go1 log settles on its legs in its first second) adds its
    motion's third differences ``h³ x⃛`` to the noise's; a window is chosen by how far its
    joints move, which the noise hardly changes, so σ is not measured where it happened to
    be low.  On a robot that never stands still the stillest window still holds motion, and
    σ comes out high (the first second's rule has the same bias).

    Returns ``None`` with fewer than 12 finite rows or 9 usable third differences in the
    window.
    """
    rows = stillest_rows(t, q, robot, window=window)
    if rows is None:
        return None
    x = _tangent(np.asarray(q, dtype=float), rows, robot)
    tt = np.asarray(t, dtype=float)[rows]
    sigma = third_difference_std(x, tt, rows, min_runs=_MIN_ROWS - 3, robust=False)
    return None if sigma is None else np.maximum(sigma, quantisation_std(q, robot))


def stillest_rows(
    t: Vector, q: Vector, robot: Robot, *, window: float = NOISE_WINDOW
) -> NDArray[np.intp] | None:
    """The finite rows of the log's stillest ``window`` seconds (:func:`still_noise_std`:
    the window whose joints' largest range is smallest), or ``None`` with fewer than 12."""
    q = np.asarray(q, dtype=float)
    t = np.asarray(t, dtype=float)
    idx = np.flatnonzero(np.isfinite(t) & np.isfinite(q).all(axis=1))
    if idx.size < _MIN_ROWS:
        return None
    x, tt = _tangent(q, idx, robot), t[idx]
    starts = np.arange(tt[0], max(tt[-1] - window, tt[0]) + 0.5 * window, 0.5 * window)
    best, motion = None, np.inf
    for s in starts:
        inside = (tt >= s) & (tt < s + window)
        if np.count_nonzero(inside) < _MIN_ROWS:
            continue
        moved = float(np.max(np.ptp(x[inside], axis=0)))
        if moved < motion:
            best, motion = idx[inside], moved
    return best


def _tangent(q: np.ndarray, rows: NDArray[np.intp], robot: Robot) -> np.ndarray:
    """The rows' positions in tangent coordinates (``difference`` from the first)."""
    if robot.is_vector_space:
        return q[rows]
    ref = robot.normalize(q[rows[0]])
    return np.array([robot.difference(ref, robot.normalize(q[i])) for i in rows])


def quantisation_std(q: Vector, robot: Robot) -> Vector:
    """Per velocity coordinate, the noise of rounding the positions to their printed step:
    ``δ/√12``, ``δ`` the smallest nonzero change between consecutive rows of ``q`` (vector
    joints; 0 for the others and for a coordinate that never changes).  A floor for σ̂: a
    still robot's printed positions repeat exactly, so their third differences are 0."""
    q = np.asarray(q, dtype=float)
    out = np.zeros(robot.nv)
    if q.shape[0] < 2:
        return out
    d = np.abs(np.diff(q, axis=0))
    for b in robot.joints:
        if b.kind != "vector":
            continue
        for k in range(b.nv):
            x = d[:, b.idx_q + k]
            x = x[np.isfinite(x) & (x > 0)]
            if x.size:
                out[b.idx_v + k] = float(x.min()) / np.sqrt(12.0)
    return out


def _rows(t: Vector, q: Vector, window: float, min_rows: int) -> NDArray[np.intp] | None:
    """The rows :func:`estimate_noise_std` uses: the finite ones within ``window`` s of the
    first finite one (at least ``min_rows``), or ``None`` when fewer than 12."""
    t = np.asarray(t, dtype=float)
    ok = np.isfinite(t) & np.isfinite(q).all(axis=1)
    idx = np.flatnonzero(ok)
    if idx.size < _MIN_ROWS:
        return None
    inside = idx[t[idx] <= t[idx[0]] + window]
    idx = inside if inside.size >= min_rows else idx[:min_rows]
    return idx if idx.size >= _MIN_ROWS else None


def noise_from_log(
    t: Vector, q: Vector, robot: Robot, *, floor: float = 0.0
) -> tuple[float, Vector, str] | None:
    """The one σ [rad or m] an observer takes when none is given: ``(σ̂, σ̂ per joint, a
    sentence reporting them)``, or ``None`` when the log has fewer than 12 usable rows.

    ``σ̂`` is the median over the joints that move of :func:`estimate_noise_std` (the
    log's first second), each joint's at least the rounding of its printed positions
    (:func:`quantisation_std`, over all the rows given: a robot still at the start of a
    real log repeats its printed positions exactly), and at least ``floor`` (a
    noise-free log: the sentence says so); the sentence also says how to give σ instead.
    """
    found = joint_noise_std(t, q, robot)
    if found is None:
        return None
    sigma_joint, floored = found
    sigma, told = moving_median(sigma_joint)
    used = cast(
        NDArray[np.intp], _rows(t, np.asarray(q, dtype=float), NOISE_WINDOW, NOISE_MIN_SAMPLES)
    )
    joints = np.array2string(sigma_joint, formatter={"float_kind": "{:.2e}".format})
    # the rows' times: the first second of finite rows need not be the log's (a sweep found
    # the sentence saying "first second" of a log whose first second was NaN)
    said = (
        f"no noise level given: estimated σ = {sigma:.3g} (median over the joints that move"
        f"{'' if told.all() else f' ({int(told.sum())} of {told.size})'}; per joint "
        f"{joints}) from the log's first "
        + (
            "second of finite rows"
            if t[used[-1]] <= t[used[0]] + NOISE_WINDOW
            else f"{NOISE_MIN_SAMPLES} finite rows (its first second has fewer)"
        )
        + f" ({used.size} rows, t = {t[used[0]]:.6g} to {t[used[-1]]:.6g} s)"
    )
    if floored.any():
        # (real logs starting at rest: third differences of repeated printed values are
        # 0; a UR10e log gave σ = 3.7e-17 on joints 1-3, refused by make_observer)
        said += (
            f"; on {int(floored.sum())} joints at least the rounding of their printed "
            "positions (step/√12)"
        )
    if sigma < floor:
        said += f" (below {floor:g}: taken as noise-free, σ = {floor:g} used)"
    return max(sigma, floor), sigma_joint, said + "; pass noise_std (--noise) to override"


def joint_noise_std(
    t: Vector, q: Vector, robot: Robot, *, rest_over_all_rows: bool = False
) -> tuple[Vector, NDArray[np.bool_]] | None:
    """σ̂ per velocity coordinate [rad or m], each at least the rounding of its printed
    positions, and where that rounding floored it: ``(max(σ̂_j, δ_j/√12), σ̂_j < δ_j/√12)``
    (:func:`estimate_noise_std` over the log's first second, :func:`quantisation_std` over
    all the rows given), or ``None`` with too few usable rows.

    ``rest_over_all_rows``: a joint at rest in the first second (``σ̂_j ≤ δ_j/√12``: its
    third differences there are only the rounding) is measured over all the rows instead
    (``pinobs.identify``'s σ: :mod:`pinobs.calibration`)."""
    first = estimate_noise_std(t, q, robot)
    if first is None:
        return None
    quantum = quantisation_std(q, robot)
    floored = first < quantum
    if rest_over_all_rows:
        rest = first <= quantum
        if rest.any():
            whole = estimate_noise_std(t, q, robot, window=math.inf)
            first = first if whole is None else np.where(rest, whole, first)
    return np.maximum(first, quantum), floored


def moving_median(sigma_joint: Vector) -> tuple[float, NDArray[np.bool_]]:
    """The one σ of a log: the median of ``sigma_joint`` over the joints that move (σ̂ above
    :data:`STILL_STD`; over all of them when none does), and which moved."""
    told = sigma_joint > STILL_STD
    return float(np.median(sigma_joint[told] if told.any() else sigma_joint)), told
