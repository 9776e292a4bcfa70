"""Foot contacts from measured normal forces: a threshold with hysteresis (issue 38, item 2).

A foot is in contact from the first sample whose normal force reaches ``on`` until the
first one that falls to ``off`` (``off < on``): a Schmitt trigger per foot,

    c_k = 1 if f_k ≥ on,    c_k = 0 if f_k ≤ off,    c_k = c_{k−1} otherwise,

so a force that hovers near one threshold does not make the contact chatter (each change
adds or removes a foot in :class:`pinobs.observers.inekf.InvariantEKF`'s state).  A
missing force (NaN) keeps the foot's previous state.  Before the first decisive sample a
foot is out of contact (``initial``).

Defaults scale with the robot's weight ``W = m g`` (:func:`default_thresholds`):
``on = 0.15 W``, ``off = 0.075 W`` (20 N is the legged benchmark's threshold for a 12.7 kg
Go1, whose ``0.15 W`` is 18.7 N; a foot of a trotting quadruped carries about ``W/2``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import DimensionError, GainError
from pinobs.model import Robot

#: ``on`` and ``off`` as fractions of the robot's weight (module docstring).
ON_FRACTION, OFF_FRACTION = 0.15, 0.075
#: Standard gravity [m/s²].
G = 9.80665


def default_thresholds(robot: Robot) -> tuple[float, float]:
    """``(on, off)`` [N]: :data:`ON_FRACTION` and :data:`OFF_FRACTION` of the robot's weight."""
    weight = G * robot.total_mass()
    return ON_FRACTION * weight, OFF_FRACTION * weight


def contacts_from_forces(
    force: ArrayLike, on: float, off: float | None = None, *, initial: ArrayLike | None = None
) -> NDArray[np.bool_]:
    """Contact flags ``(N, feet)`` from normal forces ``(N, feet)`` [N] (module docstring).

    Args:
        force: normal force per sample and foot [N]; NaN where not measured.
        on: force at or above which a foot touches [N].
        off: force at or below which it leaves [N], ``< on`` (default ``on / 2``).
        initial: each foot's state before the first sample (default: out of contact).

    Raises:
        DimensionError: ``force`` not two-dimensional, ``initial`` of another length.
        GainError: thresholds not finite, or ``off ≥ on``.
    """
    f = np.asarray(force, dtype=float)
    if f.ndim != 2:
        raise DimensionError(f"force must have shape (samples, feet), got shape {f.shape}")
    off = 0.5 * on if off is None else off
    if not (math.isfinite(on) and math.isfinite(off)) or off >= on:
        raise GainError(
            f"contact thresholds on={on!r}, off={off!r} [N]: give finite ones with off < on"
        )
    start = np.zeros(f.shape[1]) if initial is None else np.asarray(initial, dtype=float)
    if start.shape != (f.shape[1],):
        raise DimensionError(f"initial must have one flag per foot ({f.shape[1]})")
    decided = np.where(f >= on, 1.0, np.where(f <= off, 0.0, np.nan))  # NaN: keep
    rows = np.vstack([start[None, :], decided])
    # forward fill along time: each row takes the last decided row at or before it
    index = np.where(np.isnan(rows), 0, np.arange(rows.shape[0])[:, None])
    last = np.maximum.accumulate(index, axis=0)
    return np.take_along_axis(rows, last, axis=0)[1:] > 0.5
