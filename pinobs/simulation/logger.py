"""A lab logger: a simulated run turned into the log a recorder would have written.

A :class:`Logger` records a :class:`~pinobs.simulation.Result` the way a logger
beside the robot records its controller: it loses ticks, stamps rows with its
own clock, reads a state twice, prints a few digits.  The log it returns, a
:class:`RecordedLog`, keeps for every row the tick of the run it came from, so
tests and benchmarks can run the log readers and observers against a known truth.

The model (``P``: the run's sample period [s]; ``t_n = n·P``: the run's times):

1. **Ticks.**  The robot's loop produces one sample per tick ``n = 0 .. N-1``:
   the measured configuration ``q_meas[n]`` (the run's sensor noise, quantization
   and delay already in it; a NaN row, the sensor's own lost sample, stays NaN,
   as does tick 0, which the simulated sensor never measures) and the torque
   ``tau[n]``.
2. **Drops.**  A tick is lost with probability ``drop``, in bursts of mean length
   ``burst`` ticks: lost ticks come in runs of geometric length (mean ``burst``;
   ``burst = 1``: every run is one tick), kept ticks in runs of geometric length
   of mean ``burst·(1 - drop)/drop``, so that a fraction ``drop`` of the ticks is
   lost in the long run (a two-state Gilbert chain, started in its stationary
   distribution).  Runs of lost ticks are separated by at least one kept tick,
   so ``drop <= burst / (1 + burst)``.
3. **Stamps.**  Every kept tick ``n`` gives one row, stamped by a second clock
   ``stamp = offset + (1 + drift)·t_n + e`` with ``offset`` [s], ``drift``
   [dimensionless, e.g. 50e-6 for 50 ppm] and ``e`` uniform in
   ``[-jitter, jitter]`` [s], independent from row to row.  A jitter of half the
   row spacing or more could put a stamp at or before the previous one: such a
   stamp is drawn again, uniformly between the previous stamp and its own upper
   bound ``offset + (1 + drift)·t_n + jitter``, so the stamps stay within
   ``±jitter`` of their nominal value and strictly increase (the errors are
   then no longer independent).
4. **Stale rows.**  After each kept row, with probability ``stale``, the logger
   reads the same state again: a duplicate row with that row's ``q`` and ``tau``
   exactly (and its ``tick``) is inserted, stamped uniformly between that row's
   stamp and the next row's (after the last row: within one period ``(1 + drift)·P``
   after it).  A fraction ``stale / (1 + stale)`` of the rows is then stale (fewer
   with a coarse ``resolution``: 5).
5. **Printing.**  ``q`` and ``tau`` are rounded to ``digits`` significant digits
   (``None``: not rounded); the stamps to the nearest multiple of ``resolution``
   [s] (``None``: not rounded), which must be finer than the row spacing
   ``(1 + drift)·P``.  The stamps still strictly increase: a kept row's stamp
   that rounding makes equal to (or puts before) the previous one, which a jitter
   near half the spacing can do, is moved to the next multiple after the previous
   stamp (one more ``resolution`` of error for that row, and perhaps the next);
   a stale row takes the multiple nearest its draw strictly between its
   neighbours' stamps, and where there is none (neighbours one step apart) it is
   not written.

With the defaults the log is the run's samples: ``t``, ``q_meas`` and ``tau``,
every tick, exactly.

Two real logs, measured (``benchmarks/real_data.py``): FIGAROH's TIAGo log has
one row per 10 ms, its stamps on that grid with an error of standard deviation
0.41 ms (-0.6 to +2.0 ms), no repeated row while the arm moves (3 and 4 above);
the UR10e logs of Mamedov et al. step by 10 ms (67 % of rows) or 12 ms (31 %)
on 1 ms stamps, one tick in 5 or 6 of the robot's 500 Hz loop it seems, and
print 4 decimals, with repeated rows only at rest: a regular decimation, which
random drops (2) do not reproduce.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import DimensionError, GainError, TimestampError
from pinobs.model import Robot
from pinobs.model.robot import Vector, read_only
from pinobs.simulation.result import Result

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Logger", "RecordedLog"]

_INSTALL_IO = 'pip install "pinobs[io]"'


def _real(name: str, value: object, what: str) -> float:
    """``value`` as a finite float, or a :class:`GainError` naming it and ``what`` is accepted."""
    if isinstance(value, (str, bytes, bool)) or not isinstance(value, numbers.Real):
        raise GainError(f"{name}={value!r} is not a number; give {what}")
    x = float(value)
    if not math.isfinite(x):
        raise GainError(f"{name}={value!r} is not finite; give {what}")
    return x


def _probability(name: str, value: object) -> float:
    x = _real(name, value, "a probability in [0, 1)")
    if not 0.0 <= x < 1.0:
        raise GainError(f"{name}={value!r} is out of range; give a probability in [0, 1)")
    return x


@dataclass(frozen=True)
class Logger:
    """How a lab logger records a run (module docstring: the model).

    Attributes:
        drop: long-run fraction of ticks lost, in ``[0, 1)`` and at most
            ``burst / (1 + burst)``.
        burst: mean length of a run of lost ticks [ticks], >= 1 (1: single drops).
        jitter: half-width of the uniform stamp error [s], >= 0 (half the row
            spacing or more is allowed: the stamps still increase).
        offset: the logger clock's reading at the run's time 0 [s].
        drift: the logger clock's rate error [dimensionless], > -1 (50e-6: 50 ppm fast).
        stale: probability that a row is followed by a stale duplicate, in ``[0, 1)``.
        digits: significant digits of ``q`` and ``tau``, an integer in 1..17, or
            ``None`` (not rounded).
        resolution: the stamps' resolution [s], > 0, or ``None`` (not rounded);
            it must be finer than the row spacing ``(1 + drift)·P`` of the run
            recorded.

    Raises:
        GainError: a value out of its range (the message names it and the range).
    """

    drop: float = 0.0
    burst: float = 1.0
    jitter: float = 0.0
    offset: float = 0.0
    drift: float = 0.0
    stale: float = 0.0
    digits: int | None = None
    resolution: float | None = None

    def __post_init__(self) -> None:
        _probability("drop", self.drop)
        _probability("stale", self.stale)
        if _real("burst", self.burst, "a mean burst length >= 1 [ticks]") < 1.0:
            raise GainError(
                f"burst={self.burst!r} is out of range; give a mean burst length >= 1 [ticks]"
            )
        if self.drop > self.burst / (1.0 + self.burst):
            raise GainError(
                f"drop={self.drop!r} with burst={self.burst!r}: bursts of mean length "
                f"{self.burst:g} separated by at least one kept tick lose at most "
                f"burst / (1 + burst) = {self.burst / (1.0 + self.burst):.6g} of the ticks; "
                "lower drop or raise burst"
            )
        if _real("jitter", self.jitter, "a half-width >= 0 [s]") < 0.0:
            raise GainError(f"jitter={self.jitter!r} is negative; give a half-width >= 0 [s]")
        _real("offset", self.offset, "a clock offset [s]")
        if _real("drift", self.drift, "a clock rate error > -1 (e.g. 50e-6)") <= -1.0:
            raise GainError(
                f"drift={self.drift!r} would stop or reverse the logger's clock; "
                "give a rate error > -1 (e.g. 50e-6)"
            )
        if self.digits is not None and (
            not isinstance(self.digits, numbers.Integral)
            or isinstance(self.digits, bool)
            or not 1 <= self.digits <= 17
        ):
            raise GainError(
                f"digits={self.digits!r}: give an integer number of significant digits "
                "in 1..17, or None (not rounded)"
            )
        if self.resolution is not None:
            res = _real("resolution", self.resolution, "a stamp resolution > 0 [s] or None")
            if res <= 0.0:
                raise GainError(
                    f"resolution={self.resolution!r} is out of range; give a stamp "
                    "resolution > 0 [s] or None (not rounded)"
                )

    def record(self, result: Result, rng: np.random.Generator | int) -> RecordedLog:
        """The log this logger would have written of ``result``'s run.

        Args:
            result: a simulated run (its ``t``, ``q_meas`` and ``tau``).
            rng: the generator of the drops, jitter and stale rows (an int seeds one).

        Raises:
            GainError: ``resolution`` not finer than the run's row spacing.
            DimensionError: the result has no sample.
        """
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        t = np.asarray(result.t, dtype=float)
        n = t.size
        if n == 0:
            raise DimensionError("the result has no sample to record")
        period = _period(result)
        scale = 1.0 + float(self.drift)
        spacing = scale * period
        if self.resolution is not None and self.resolution >= spacing:
            raise GainError(
                f"resolution={self.resolution!r} s is not finer than the row spacing "
                f"(1 + drift)·P = {spacing:.6g} s: the stamps could not increase; give a "
                "finer resolution"
            )
        ticks = np.flatnonzero(self._kept(n, gen))
        if ticks.size == 0:  # every tick lost
            return RecordedLog(
                t=np.empty(0),
                q=np.empty((0, result.q_meas.shape[1])),
                tau=np.empty((0, result.tau.shape[1])),
                tick=np.empty(0, dtype=np.intp),
                stale=np.empty(0, dtype=bool),
                period=period,
                robot=result.robot,
            )
        nominal = float(self.offset) + scale * t[ticks]
        stamps = self._jittered(nominal, gen)
        res = None if self.resolution is None else float(self.resolution)
        grid = None if res is None else _grid_steps(stamps, res)
        if grid is not None and res is not None:
            stamps = _from_steps(grid, res)
        k = np.flatnonzero(gen.random(ticks.size) < self.stale) if self.stale else np.empty(0, int)
        k, between = _stale_stamps(stamps, k, spacing, grid, res, gen)
        row_tick, is_stale, t_rows = _rows(ticks, stamps, k, between)
        q = np.asarray(result.q_meas, dtype=float)[row_tick]
        tau = np.asarray(result.tau, dtype=float)[row_tick]
        if self.digits is not None:
            q = _significant(q, int(self.digits))
            tau = _significant(tau, int(self.digits))
        return RecordedLog(
            t=t_rows,
            q=q,
            tau=tau,
            tick=row_tick,
            stale=is_stale,
            period=period,
            robot=result.robot,
        )

    def _kept(self, n: int, gen: np.random.Generator) -> NDArray[np.bool_]:
        """Which of ``n`` ticks are kept: alternating geometric runs (module docstring, 2)."""
        if not self.drop:
            return np.ones(n, dtype=bool)
        p_end_burst = 1.0 / float(self.burst)  # a lost run ends after each lost tick
        p_start_burst = float(self.drop) / (float(self.burst) * (1.0 - float(self.drop)))
        if p_start_burst <= 0.0:  # a subnormal drop underflows to no drop (found by hypothesis)
            return np.ones(n, dtype=bool)
        dropping = bool(gen.random() < self.drop)  # stationary start
        p_first, p_second = (
            (p_end_burst, p_start_burst) if dropping else (p_start_burst, p_end_burst)
        )
        runs: list[NDArray[np.int64]] = []
        total = 0
        while total < n:  # pairs of runs (first state, other state) until n ticks are covered
            pairs = max(16, int(n * p_start_burst) + 16)
            lengths = np.column_stack(
                [gen.geometric(p_first, pairs), gen.geometric(p_second, pairs)]
            ).ravel()
            np.minimum(lengths, n, out=lengths)  # (a tiny drop: runs of 2**63 - 1 ticks)
            runs.append(lengths)
            total += int(lengths.sum())
        lengths = np.concatenate(runs)
        ends = np.cumsum(lengths)
        last = int(np.searchsorted(ends, n))  # the run that reaches tick n - 1
        lengths = lengths[: last + 1].copy()
        lengths[last] -= int(ends[last]) - n
        lost = np.zeros(lengths.size, dtype=bool)
        lost[0 if dropping else 1 :: 2] = True
        return ~np.repeat(lost, lengths)

    def _jittered(self, nominal: Vector, gen: np.random.Generator) -> Vector:
        """Nominal stamps plus uniform jitter, redrawn where it would not increase (3)."""
        if not self.jitter:
            return nominal.copy()
        j = float(self.jitter)
        stamps = nominal + gen.uniform(-j, j, nominal.size)
        if nominal.size < 2 or np.all(np.diff(stamps) > 0.0):
            return stamps
        first = int(np.flatnonzero(np.diff(stamps) <= 0.0)[0]) + 1
        for k in range(first, nominal.size):
            if stamps[k] > stamps[k - 1]:
                continue
            lo = np.nextafter(stamps[k - 1], np.inf)
            hi = nominal[k] + j
            stamps[k] = min(lo + gen.random() * (hi - lo), hi)
        return stamps


def _period(result: Result) -> float:
    """The run's sample period [s]: ``1 / meta["rate"]``, else the step of its times."""
    rate = result.meta.get("rate") if isinstance(result.meta, dict) else None
    if isinstance(rate, numbers.Real) and not isinstance(rate, bool) and float(rate) > 0:
        return 1.0 / float(rate)
    if result.t.size < 2:
        raise DimensionError(
            "the result has one sample and no meta['rate']: its sample period is unknown"
        )
    return float(result.t[1] - result.t[0])


def _grid_steps(t: Vector, resolution: float) -> NDArray[np.int64]:
    """``t`` in whole steps of ``resolution``, rounded, each above the previous (module
    docstring, 5): ``k[i] = max(round(t[i] / resolution), k[i-1] + 1)``."""
    k = np.rint(t / resolution).astype(np.int64)
    idx = np.arange(k.size, dtype=np.int64)
    return np.maximum.accumulate(k - idx) + idx


def _from_steps(k: NDArray[np.int64], resolution: float) -> Vector:
    """Stamps [s] of whole steps ``k`` of ``resolution``."""
    per_second = 1.0 / resolution
    if per_second == round(per_second):  # 1e-3 s: k / 1000, which prints as its decimal
        return k / round(per_second)
    return k * resolution


def _significant(x: Vector, digits: int) -> Vector:
    """``x`` rounded to ``digits`` significant digits (NaN, ±inf and 0 kept).

    Each finite value becomes the float nearest to a decimal of ``digits``
    significant digits (what ``float(f"{x:.{digits}g}")`` reads): the integer of
    the digits and the power of ten are exact floats (``digits <= 15``,
    ``10**k`` with ``|k| <= 22``) and one correctly rounded product or quotient
    joins them; other values take the (slower) way through text.
    """
    x = np.asarray(x, dtype=float)
    out = x.copy()
    if digits >= 17:  # every float is its own 17-digit decimal
        return out
    nonzero = np.isfinite(x) & (x != 0.0)
    if not nonzero.any():
        return out
    v = x[nonzero]
    exp = np.floor(np.log10(np.abs(v))).astype(np.int64)
    shift = digits - 1 - exp  # decimals kept (negative: tens, hundreds, ...)
    res = np.full_like(v, np.nan)
    fast = (np.abs(shift) <= 22) & (digits <= 15)
    up = fast & (shift >= 0)
    down = fast & (shift < 0)
    scale = np.ones_like(v)
    scale[fast] = 10.0 ** np.abs(shift[fast]).astype(float)
    res[up] = np.rint(v[up] * scale[up]) / scale[up]
    res[down] = np.rint(v[down] / scale[down]) * scale[down]
    slow = ~fast
    res[slow] = [float(f"{a:.{digits}g}") for a in v[slow]]
    out[nonzero] = res
    return out


@dataclass(frozen=True)
class RecordedLog:
    """A log written by a :class:`Logger`, with the truth of every row.

    Attributes:
        t: stamps [s], shape ``(M,)``, strictly increasing.
        q: configurations as recorded, shape ``(M, nq)`` (NaN rows: samples the sensor lost).
        tau: torques as recorded [N·m or N], shape ``(M, nv)``.
        tick: the run's sample each row recorded, shape ``(M,)`` (ints): the truth of
            row ``i`` is ``result.q[tick[i]]``, ``result.v[tick[i]]`` at ``result.t[tick[i]]``.
        stale: whether each row is a stale duplicate of the row before it, shape ``(M,)``.
        period: the run's sample period ``P`` [s].
        robot: the run's robot name.
    """

    t: Vector
    q: Vector
    tau: Vector
    tick: NDArray[np.intp]
    stale: NDArray[np.bool_]
    period: float
    robot: str = ""

    def __post_init__(self) -> None:
        for k in ("t", "q", "tau"):
            object.__setattr__(self, k, read_only(getattr(self, k)))
        for k, dtype in (("tick", np.intp), ("stale", np.bool_)):
            arr = np.array(getattr(self, k), dtype=dtype)
            arr.setflags(write=False)
            object.__setattr__(self, k, arr)
        m = self.t.shape[0]
        if any(a.shape[0] != m for a in (self.q, self.tau, self.tick, self.stale)):
            raise DimensionError(
                f"a recorded log needs one q, tau, tick and stale row per stamp ({m}); got "
                f"{self.q.shape[0]}, {self.tau.shape[0]}, {self.tick.shape[0]}, "
                f"{self.stale.shape[0]}"
            )

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def columns(self, robot: Robot | None = None) -> list[str]:
        """Column names: ``t``, then ``q.<joint>`` and ``tau.<joint>`` (``.<k>`` for each
        coordinate of a joint with several) with ``robot``, else ``q0 ..`` and ``tau0 ..``."""
        nq, nv = self.q.shape[1], self.tau.shape[1]
        if robot is None:
            return ["t", *(f"q{i}" for i in range(nq)), *(f"tau{i}" for i in range(nv))]
        if (robot.nq, robot.nv) != (nq, nv):
            raise DimensionError(
                f"robot {robot.name!r} has nq = {robot.nq}, nv = {robot.nv}; this log of "
                f"{self.robot or 'a robot'!r} has nq = {nq}, nv = {nv}: give its own robot"
            )
        qcols = [
            f"q.{b.name}" if b.nq == 1 else f"q.{b.name}.{k}"
            for b in robot.joints
            for k in range(b.nq)
        ]
        taucols = [
            f"tau.{b.name}" if b.nv == 1 else f"tau.{b.name}.{k}"
            for b in robot.joints
            for k in range(b.nv)
        ]
        return ["t", *qcols, *taucols]

    def to_frame(self, robot: Robot | None = None) -> pd.DataFrame:
        """The log as a DataFrame that :func:`pinobs.io.read_log` reads (columns: :meth:`columns`).

        Raises:
            DimensionError: ``robot`` has other dimensions than the log.
        """
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - pandas is in the io and test extras
            raise ModuleNotFoundError(f"a log as a DataFrame needs pandas: {_INSTALL_IO}") from exc
        names = self.columns(robot)
        data = np.column_stack([self.t, self.q, self.tau])
        return pd.DataFrame(data, columns=names)

    def to_csv(self, path: str | Path, robot: Robot | None = None) -> Path:
        """Write the log as CSV (a header, then one row per stamp; floats in their shortest
        round-trip form, so :func:`pinobs.io.read_log` reads back the same numbers; NaN as an
        empty cell).  Overwrites ``path``; creates its folder."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        frame: Any = self.to_frame(robot)
        frame.to_csv(path, index=False, lineterminator="\n")
        return path


def _stale_stamps(
    stamps: Vector,
    k: NDArray[np.intp],
    spacing: float,
    grid: NDArray[np.int64] | None,
    res: float | None,
    gen: np.random.Generator,
) -> tuple[NDArray[np.intp], Vector]:
    """The stale rows that are written (of those after kept rows ``k``) and their stamps
    (module docstring, 4 and 5): uniformly between their row's stamp and the next row's
    (one row spacing after the last), on a free multiple of ``res`` between them when
    the stamps are rounded (a row without one is not written)."""
    lo = stamps[k]
    hi = np.append(stamps[1:], stamps[-1] + spacing)[k]
    between: Vector = lo + gen.random(k.size) * (hi - lo)
    if grid is not None and res is not None:  # on a free multiple of res between them
        g_lo = grid[k]
        g_hi = np.append(grid[1:], np.rint((stamps[-1] + spacing) / res))[k]
        room = g_hi - g_lo >= 2
        k, between = k[room], between[room]
        steps = np.clip(np.rint(between / res), g_lo[room] + 1, g_hi[room] - 1)
        between = _from_steps(steps.astype(np.int64), res)
    else:
        outside = (between <= lo) | (between >= hi)
        between[outside] = 0.5 * (lo[outside] + hi[outside])
    return k, between


def _rows(
    ticks: NDArray[np.intp],
    stamps: Vector,
    k: NDArray[np.intp],
    between: Vector,
) -> tuple[NDArray[np.intp], NDArray[np.bool_], Vector]:
    """The log's rows, each kept tick then its stale duplicate if any: each row's tick,
    whether it is stale, and its stamp [s] (``stamps`` of the kept rows, ``between`` of
    the stale rows after kept rows ``k``)."""
    rows_per_tick = np.ones(ticks.size, dtype=np.intp)
    rows_per_tick[k] = 2
    row_tick = np.repeat(ticks, rows_per_tick)
    first_row = np.cumsum(rows_per_tick) - rows_per_tick  # row of each kept tick
    is_stale = np.zeros(row_tick.size, dtype=bool)
    is_stale[first_row[k] + 1] = True
    t_rows = np.empty(row_tick.size)
    t_rows[first_row] = stamps
    t_rows[first_row[k] + 1] = between
    if t_rows.size > 1 and not np.all(np.diff(t_rows) > 0.0):  # pragma: no cover
        bad = int(np.flatnonzero(np.diff(t_rows) <= 0.0)[0]) + 1
        raise TimestampError(
            f"row {bad}: stamp {t_rows[bad]!r} s does not follow {t_rows[bad - 1]!r} s "
            "(the rows are too close for float stamps)"
        )
    return row_tick, is_stale, t_rows
