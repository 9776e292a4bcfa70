"""A log's sample counter (a ``tick`` column, ROS 1 ``header.seq``), as the clock repair
(:mod:`pinobs.io.clock`) reads it: unwrapped where it wraps, followed chunk by chunk."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import TimestampError

__all__ = ["CounterTrack", "unwrap_counter"]

Bool = NDArray[np.bool_]
Floats = NDArray[np.floating[Any]]


def unwrap_counter(tick: Floats) -> Floats:
    """A sample counter as a non-decreasing sequence (:mod:`pinobs.io.clock`'s docstring, step 5)."""
    c = np.asarray(tick, dtype=float)
    if not np.isfinite(c).all():
        bad = int(np.flatnonzero(~np.isfinite(c))[0])
        raise TimestampError(f"the sample counter is unreadable at row {bad}: {c[bad]!r}")
    if np.any(c != np.rint(c)):
        bad = int(np.flatnonzero(c != np.rint(c))[0])
        raise TimestampError(f"the sample counter is not an integer at row {bad}: {c[bad]!r}")
    d = np.diff(c)
    back = np.flatnonzero(d < 0)
    if back.size == 0:
        return c
    top = float(c.max())
    modulus = 2.0 ** math.ceil(math.log2(top + 1)) if top > 0 else 1.0
    out = c.copy()
    shift = 0.0
    for k in back.tolist():
        # a wrap: from near the top of the counter's range to near its bottom
        if c[k] > 0.9 * modulus - 1 and c[k + 1] < 0.1 * modulus:
            shift += modulus
            out[k + 1 :] = c[k + 1 :] + shift
        else:
            raise TimestampError(
                f"the sample counter goes back from {c[k]:.0f} to {c[k + 1]:.0f} at row {k + 1} "
                f"(not a wrap of a {modulus:.0f} counter): is it the log's sample counter?"
            )
    return out


@dataclass
class CounterTrack:
    """A sample counter followed chunk by chunk (:mod:`pinobs.io.clock`'s docstring, step 5): its last raw
    value, that value unwrapped, and the unwrapped value of tick 0 of the fit."""

    raw: float
    unwrapped: float
    origin: float

    @classmethod
    def after(cls, tick: Floats, fit_tick: NDArray[np.int64], k: int) -> CounterTrack:
        """The track after the first window's rows ``:k`` (its ticks ``fit_tick``)."""
        c = unwrap_counter(np.asarray(tick[:k], dtype=float))
        placed = np.flatnonzero(np.asarray(fit_tick[:k]) >= 0)
        j = int(placed[-1]) if placed.size else 0
        return cls(float(tick[k - 1]), float(c[-1]), float(c[j] - max(fit_tick[j], 0)))

    def follow(self, tick: Floats) -> tuple[Floats, Bool]:
        """The ticks of a chunk's rows on the fit's scale, and which rows repeat the
        counter's previous value (the previous chunk's last row included)."""
        seg = np.r_[self.raw, np.asarray(tick, dtype=float)]
        u = unwrap_counter(seg)  # a wrap, or an error naming the row (of this chunk + 1)
        unwrapped = u[1:] - u[0] + self.unwrapped
        if seg.size > 1:
            self.raw, self.unwrapped = float(seg[-1]), float(unwrapped[-1])
        return unwrapped - self.origin, np.diff(seg) == 0
