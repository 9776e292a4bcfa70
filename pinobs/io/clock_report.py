"""What the log's clock repair (:mod:`pinobs.io.clock`) found: its report and fit."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["CREDIBLE_JITTER", "ClockFit", "ClockReport", "in_ms"]

#: A loop the stamps were kept against is named in the report only if they are this close
#: to it (RMS, in periods): a loop found, not the best fit of stamps without one.
CREDIBLE_JITTER = 0.1

Bool = NDArray[np.bool_]
Floats = NDArray[np.floating[Any]]
Ints = NDArray[np.int64]


@dataclass(frozen=True)
class ClockReport:
    """What :func:`fit_clock` found and did (module docstring).

    Attributes:
        mode: the mode asked (``"auto"``, ``"stamps"``, ``"loop"``).
        repaired: the loop's clock replaced the stamps.
        period: the loop's period [s] (``None``: no loop found).
        step: the median row step in loop periods (1: every sample logged).
        jitter: RMS of the stamps about the loop's clock [s].
        jitter_max: largest ``|stamp − loop time|`` of a non-stale row [s].
        stale: rows that repeat the previous sample while the robot moves.
        repeated_at_rest: rows equal to the previous one at rest (kept as samples).
        drops: loop samples missing between rows (when every sample is logged, ``step`` 1).
        largest_correction: largest ``|repaired time − stamp|`` [s] (0 when not repaired).
        rows: rows seen.
        counter: ticks came from a sample counter column.
        reason: why this clock (for ``auto``).
        outliers: fresh rows stamped out of order with the rows around them (the fewest
            for the stamps to increase), placed on the loop by the motion between their
            neighbours (0 when not repaired: the stamps' time rules report them).
        wander: von Neumann's ratio of the stamps' residuals about the loop (2: they
            jitter independently; towards 0: they wander, no loop; 2 without a loop).
    """

    mode: str
    repaired: bool
    period: float | None
    step: float
    jitter: float
    jitter_max: float
    stale: int
    repeated_at_rest: int
    drops: int
    largest_correction: float
    rows: int
    counter: bool = False
    reason: str = ""
    outliers: int = 0
    wander: float = 2.0

    def message(self) -> str:
        """One line for the run's warnings and the summary."""
        stale = (
            f"; {self.stale} rows repeat the previous sample while the robot moves (stale "
            "reads of the logger), measured as they are: clock='auto' or 'loop' skips them"
            if self.stale and not self.repaired
            else ""
        )
        if self.period is None or (
            not self.repaired and self.jitter > CREDIBLE_JITTER * self.period
        ):
            # (the best loop fitted to stamps this far off it is no finding: UR10e logs
            # stepping 10-12 ms gave "2.46 ms loops" with 0.5 ms RMS off them)
            return f"log clock: stamps kept ({self.reason}){stale}"
        loop = f"a {in_ms(self.period)} loop"
        if self.step > 1.5:
            loop += f" logged every {self.step:.3g} periods"
        found = (
            f"{loop}; stamps off it by {in_ms(self.jitter)} RMS (at most {in_ms(self.jitter_max)})"
        )
        if not self.repaired:
            return f"log clock: stamps kept ({self.reason}): {found}{stale}"
        parts = [
            f"{self.stale} stale rows (a repeat of the previous sample: skipped, "
            "output at that sample's time)",
            f"{self.drops} loop samples missing (propagated across)",
        ]
        if self.outliers:
            parts.append(
                f"{self.outliers} rows stamped out of order (outliers: placed by the motion "
                "between their neighbours)"
            )
        if self.repeated_at_rest:
            parts.append(f"{self.repeated_at_rest} repeated rows at rest kept as samples")
        how = "from its sample counter" if self.counter else self.reason
        return (
            f"log clock repaired ({how}): {found}; {'; '.join(parts)}; "
            f"largest correction {in_ms(self.largest_correction)} (clock='stamps' keeps the stamps)"
        )


def in_ms(x: float) -> str:
    """``x`` [s] in milliseconds, three significant digits."""
    return f"{1e3 * x:.3g} ms"


@dataclass(frozen=True)
class ClockFit:
    """A log's rows on the loop's clock.

    Attributes:
        t: the time of every row [s] (the stamps when not repaired; NaN where the stamp is).
        stale: rows that repeat the previous sample (no measurement).
        drops: per row, loop samples missing just before it (0 when not repaired).
        tick: per row, the loop's tick (``−1`` where unplaced; all ``−1`` when not repaired).
        report: what was found and done.
    """

    t: Floats
    stale: Bool
    drops: Ints
    tick: Ints
    report: ClockReport
    t0: float = 0.0
    period: float = 0.0
    outlier: Bool | None = None  # rows stamped out of order (placed by the motion or not)
