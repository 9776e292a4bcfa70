"""The log's clock: a fixed-rate loop seen through a logger's jittery stamps.

A robot's control loop samples at a fixed period ``P``; the computer that
logs it stamps each row with its own clock, when it reads it.  So a real log
has (issue 35, measured on a 1 kHz arm: intervals 0.7–1.6 ms, 6 % stale rows,
8 % of the loop's samples missing):

- **jitter**: ``t_k = T0 + P·n_k + e_k``, ``n_k`` the loop's tick of the
  sample, ``e_k`` the logger's delay (a fraction of ``P``);
- **stale rows**: the logger read the same sample twice; the row repeats the
  previous one exactly (``n_k = n_{k−1}``) but carries a later stamp;
- **drops**: the logger missed samples (``n_k − n_{k−1} ≥ 2``); the motion
  over such an interval is that of two (or more) periods.

Fed to an observer as stamped, the jitter is a velocity error ``v·e_k/P`` per
row and a stale row claims the robot stopped for a period (measured: 70–400×
worse estimates).  :func:`fit_clock` reconstructs the loop's clock:

1. **Stale rows**: a row equal to the previous one while the robot moves
   (its neighbours differ by more than two quantisation steps on some
   joint; for repeats that end the log, the sample they repeat and the row
   before it: the robot moved into the repeat).  A repeated row at rest is a
   genuine sample of a still robot, placed by its stamp.
2. **Period and ticks**: ``P`` and ``T0`` by least squares of the stamps on
   integer ticks, grown from the first rows (ticks by rounding the intervals)
   to the whole window (ticks by rounding ``(t − T0)/P``, then made strictly
   increasing), for ``P`` the median interval divided by ``m = 1..MAX_SUBDIVISION``
   (a loop faster than the logger: a UR's 2 ms loop logged every 10–12 ms); the
   ``m`` whose stamps keep the strongest phase, the slowest of those within ``TIED``
   of it.  (The first ``m`` above the noise floor was taken before: on the UR10e's
   ``14harm50sec`` log the ~10.5 ms mean interval's coherence 0.17 (floor 0.08), not
   the 2 ms loop's 0.94; as stamped, ``kf``'s gate rejected 140 of its rows, the
   5 % stamped 1 ms off the loop.)  **Outliers**: rows whose stamps are out of order
   with the rows around them (a glitch: a stamp far ahead or behind) are left out of
   the fit, the fewest of them (of two successive rows out of order, the one farther
   from its neighbours' stamps ``t_{k+o} − o·h``, ``h`` the median interval); each is
   placed by the motion at a free tick between its neighbours' (step 3) and counted
   in the report, or keeps its stamp when there is none.  (A row stamped 1 s ahead
   left every row stamped before it out of the fit, and five of them refused the
   repair of ``14harm50sec``.)
3. **Motion decides** a stamp within ``AMBIGUOUS`` of half a period from two
   ticks: the tick whose linear interpolation between the neighbouring rows
   best predicts the row's position ("a drop shows as twice the motion").
4. **Which clock** (``mode="auto"``): the one under which the motion is
   smoother.  For each hypothesis, every interior row's position is predicted
   by linear interpolation in time between its neighbours; the loop's clock is
   used when its summed squared prediction error (per joint, in units of the
   joint's typical step) is below ``CLEAR_RATIO`` times the stamps' over at
   least ``MIN_TRIPLES`` moving rows: clearly better, not by chance (the outliers left
   out of both).  Truly irregular but correct stamps (intervals 0.5–1.5 ms) are
   smoother as they are and left alone; so is a log without motion to judge by.
   And the stamps must jitter about the loop, not wander: their residuals
   ``r_k = t_k − T0 − P n_k`` have von Neumann's ratio

       η = Σ (r_k − r_{k−1})² / Σ (r_k − r̄)²  ≥ WANDER = 1

   (von Neumann 1941; independent delays give ``η ≈ 2``, a random walk ``η → 0``;
   ``η = 2(1 − ρ₁)``: below 1, more of a stamp's offset is its neighbour's than its
   own).  A logger that paces itself by sleeping (each interval's error carried into
   the next) reads a faster loop's latest sample: its mean interval is no loop, and a
   line through its stamps is farther from the samples' times than the stamps are.
   (The UR10e's ``ur-19_09_27-11_28_22``: stamps 10 and 11 ms apart about a 10.6 ms
   line, ``η = 0.088``, off it by up to 15.7 ms, while the robot's own velocity puts its
   samples 10 and 12 ms apart on its 2 ms loop; repaired on that line, ``kf`` against
   the robot's velocity 0.0129 rad/s, on the stamps 0.0104.  Simulated, the line's
   error to the samples' times 1.1–2.5 ms RMS, the stamps' 0.7.  Loops under jittered
   stamps: ``η`` 1.9–2.1.)
5. A **sample counter** (a ``tick`` column, ROS 1 ``header.seq``) gives the
   ticks directly (a fresh row is usable whatever its stamp's order: the stamps
   only fit the line); a counter that wraps is unwrapped at its modulus, and one
   that goes back otherwise is an error naming the row.

The repaired time of a row is ``T0 + P·n_k``; a stale row takes the time of
the sample it repeats (its estimate is the one at that time, and it corrects
nothing).  :class:`ClockRepair` applies it chunk by chunk with bounded memory:
the clock is fitted and chosen on the first window, then followed (the fit
refreshed over the last window of rows, so a slowly drifting logger clock is
tracked); a chunk's trailing repeats wait for the next chunk's fresh row, so the
stale rows are those of the whole log (but for a run of ``WINDOW_ROWS`` repeats or
more, judged as the log's last run to bound the memory).  A sample counter keeps
giving the ticks after the first window (unwrapped across chunks, a repeat of the
previous chunk's last value stale), as it does for the whole log.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import OptionError, TimestampError
from pinobs.io._clock_motion import (
    in_order,
    interp_error,
    monotone,
    place_between,
    resolve_by_motion,
    successive_ratio,
)
from pinobs.io._clock_period import fit_ticks, line
from pinobs.io.clock_report import ClockFit, ClockReport, in_ms
from pinobs.io.counter import CounterTrack, unwrap_counter

if TYPE_CHECKING:
    from pinobs.io.readers import Log

__all__ = [
    "CLOCK_MODES",
    "ClockFit",
    "ClockRepair",
    "ClockReport",
    "fit_clock",
    "repaired_chunks",
    "without_stale",
]

#: What ``clock=`` (CLI ``--clock``) accepts.
CLOCK_MODES = ("auto", "stamps", "loop")
#: The loop period is looked for as the median interval divided by 1 .. this.
MAX_SUBDIVISION = 8
#: A stamp this far (in periods) from its nearest tick is placed by the motion.
AMBIGUOUS = 0.3
#: ``auto`` repairs when the loop's clock leaves at most this fraction of the
#: stamps' interpolation error (module docstring, step 4).
CLEAR_RATIO = 0.7
#: Moving interior rows needed for ``auto`` to judge.
MIN_TRIPLES = 50
#: The stamps are a loop when their phase coherence about it is at least this many
#: times the ``1/√N`` of stamps without one.
COHERENT_SIGMAS = 5.0
#: A slower loop is kept over the most coherent one when its coherence is at least this
#: fraction of that one's (stamps on the ticks: 1 at P, P/2, ... alike).
TIED = 0.9
#: ``auto`` keeps the stamps when their residuals about the loop's line have a von Neumann
#: ratio below this (module docstring, step 4): they wander more than they jitter.
WANDER = 1.0
#: Rows of the first window the clock is chosen on, and the window its fit follows.
WINDOW_ROWS = 4000

Bool = NDArray[np.bool_]
Floats = NDArray[np.floating[Any]]
Ints = NDArray[np.int64]


# ------------------------------------------------------------------ pieces
def _repeats(q: Floats) -> Bool:
    """Rows equal to the previous row (every coordinate finite)."""
    rep = np.zeros(len(q), dtype=bool)
    if len(q) > 1:
        fin: Bool = np.asarray(np.isfinite(q).all(axis=1))
        rep[1:] = (q[1:] == q[:-1]).all(axis=1) & fin[1:] & fin[:-1]
    return rep


def _quantum(q: Floats) -> Floats:
    """Per coordinate: the smallest step the log resolves (1st percentile of nonzero steps)."""
    d = np.abs(np.diff(q, axis=0))
    out = np.zeros(q.shape[1])
    for j in range(q.shape[1]):
        x = d[:, j]
        x = x[np.isfinite(x) & (x > 0)]
        out[j] = float(np.percentile(x, 1)) if x.size else 0.0
    return out


def _stale(q: Floats, rep: Bool, quantum: Floats) -> Bool:
    """Repeated rows while the robot moves (module docstring, step 1).

    A run of repeats of the fresh row ``a`` is stale when the robot moves across it:
    ``|q_b − q_a| > 2·quantum`` on some coordinate, ``b`` the next fresh row; for the
    run that ends the rows (no ``b``), ``b = a − 1``: the robot moved into the repeat.
    """
    n = len(q)
    if not rep.any():
        return np.zeros(n, dtype=bool)
    idx = np.arange(n)
    prev = np.maximum.accumulate(np.where(~rep, idx, 0))  # the sample each row repeats
    fresh = np.flatnonzero(~rep)
    k = np.flatnonzero(rep)
    after = np.searchsorted(fresh, k, side="right")
    has_next = after < fresh.size
    a = prev[k]
    b = np.where(has_next, fresh[np.minimum(after, fresh.size - 1)], np.maximum(a - 1, 0))
    moved = (np.abs(q[b] - q[a]) > 2 * quantum).any(axis=1)  # (a NaN row: not moved)
    out = np.zeros(n, dtype=bool)
    out[k] = moved
    return out


def _decided(repeated: Bool, window: int) -> int:
    """How many leading rows of a chunk can be judged now: all but its trailing run of
    repeats (their next fresh row, in a later chunk, decides them), unless that run is
    ``window`` rows or longer (then judged as the log's last run, to bound memory)."""
    fresh = np.flatnonzero(~repeated)
    start = int(fresh[-1]) + 1 if fresh.size else 0
    return start if repeated.size - start < window else int(repeated.size)


# ------------------------------------------------------------------ the fit
@dataclass(frozen=True)
class _Rows:
    """A log's rows as the clock sees them (module docstring, step 1)."""

    t: Floats
    q: Floats
    repeated: Bool  # equal to the previous row
    stale: Bool  # repeated while moving (or the counter repeats)
    usable: Bool  # a new sample, its stamp in order with the other usable rows'
    ui: NDArray[np.intp]  # the usable rows
    scale: Floats  # per coordinate: the typical step between usable rows
    counter: Floats | None  # the unwrapped sample counter, or None
    outlier: Bool  # a new sample whose stamp is out of order (placed by the motion)

    @property
    def size(self) -> int:
        return int(self.t.size)


def _screen(t: Floats, q: Floats, tick: Floats | None) -> _Rows:
    n_rows = t.size
    rep = _repeats(q)
    quantum = _quantum(q) if n_rows > 2 else np.zeros(q.shape[1])
    stale = _stale(q, rep, quantum)
    counter = None
    if tick is not None:
        counter = unwrap_counter(np.asarray(tick, dtype=float))
        stale = stale | (np.r_[1.0, np.diff(counter)] == 0)
    usable = np.isfinite(t) & ~stale & np.isfinite(q).all(axis=1)
    # stamps must increase among the usable rows: the fewest rows left out (outliers,
    # step 2), unless a counter orders them (step 5: its ticks increase, the stamps fit
    # the line)
    ui = np.flatnonzero(usable)
    outlier = np.zeros(n_rows, dtype=bool)
    if ui.size and counter is None:
        keep = in_order(t[ui])
        outlier[ui[~keep]] = True
        usable[ui[~keep]] = False
        ui = ui[keep]
    scale = np.ones(q.shape[1])
    if ui.size >= 3:
        scale = np.maximum(np.median(np.abs(np.diff(q[ui], axis=0)), axis=0), quantum)
        scale = np.where(scale > 0, scale, 1.0)
    return _Rows(t, q, rep, stale, usable, ui, scale, counter, outlier)


def _find_loop(rows: _Rows) -> tuple[Floats, float, float] | None:
    """The loop's ticks of the usable rows and its line ``T0, P`` (module docstring,
    steps 2, 3 and 5), or ``None``."""
    tu, qu = rows.t[rows.ui], rows.q[rows.ui]
    h = float(np.median(np.diff(tu)))
    if rows.counter is not None:
        n = rows.counter[rows.ui] - rows.counter[rows.ui][0]
        t0, p = line(n, tu, h)
        return n, t0, p
    # the loop whose ticks the stamps keep most in phase; of loops within TIED of that, the
    # slowest (a loop of period P is one of period P/2 too, logged every 2 ticks)
    floor = COHERENT_SIGMAS / math.sqrt(tu.size)
    fits = [fit_ticks(tu, h / m) for m in range(1, MAX_SUBDIVISION + 1)]
    found = [f for m, f in enumerate(fits, 1) if 0.5 * h / m < f[2] < 2 * h / m and f[3] > floor]
    if not found:
        return None
    best = max(f[3] for f in found)
    n, t0, p, _ = next(f for f in found if f[3] >= TIED * best)
    n = resolve_by_motion(n, (tu - t0) / p - n, qu, rows.scale, AMBIGUOUS)
    t0, p = line(n, tu, p)
    return n, t0, p


def _verdict(
    rows: _Rows, mode: str, n: Floats, t0: float, p: float, stats: dict[str, float]
) -> tuple[bool, str]:
    """Whether to use the loop's clock, and why (module docstring, step 4)."""
    t, q = rows.t, rows.q
    if rows.counter is not None:
        jitter_max = stats["jitter_max"]
        if mode == "auto" and not rows.stale.any() and jitter_max < 0.01 * p:
            return False, f"the stamps agree with the sample counter to {in_ms(jitter_max)}"
        return True, "from its sample counter"
    if mode != "auto":
        return True, "clock='loop'"
    # the stamps as a plain reading would use them: every row with an increasing stamp,
    # but the outliers (left out of both clocks' errors: step 4)
    si = np.flatnonzero(np.isfinite(t) & np.isfinite(q).all(axis=1) & ~rows.outlier)
    if si.size:
        si = si[np.r_[True, np.diff(t[si]) > 0]]
    e_stamps, n_s = interp_error(t[si], q[si], rows.scale)
    e_loop, n_l = interp_error(t0 + p * n, q[rows.ui], rows.scale)
    if min(n_s, n_l) < MIN_TRIPLES:
        return False, f"too little motion to judge the stamps ({min(n_s, n_l)} moving rows)"
    ratio = e_loop / e_stamps if e_stamps > 0 else math.inf
    said = f"interpolation error {ratio:.2g}× the stamps'"
    if not ratio < CLEAR_RATIO:
        return False, f"the loop's clock does not explain the motion better: {said}"
    eta = stats["wander"]
    if eta < WANDER:
        return False, (
            f"the stamps wander about the {in_ms(p)} line (von Neumann ratio {eta:.2g}; "
            f"a loop's independent delays give 2): a logger's pace, not a loop; {said}"
        )
    return True, f"the motion is smoother on the loop's clock: {said}"


def _kept(
    rows: _Rows, mode: str, reason: str, period: float | None = None, **kw: float
) -> ClockFit:
    """The stamps as they are, and the report of what was found."""
    n_rows = rows.size
    report = ClockReport(
        mode=mode,
        repaired=False,
        period=period,
        step=float(kw.get("step", 1.0)),
        jitter=float(kw.get("jitter", 0.0)),
        jitter_max=float(kw.get("jitter_max", 0.0)),
        wander=float(kw.get("wander", 2.0)),
        stale=int(rows.stale.sum()),
        repeated_at_rest=int((rows.repeated & ~rows.stale).sum()),
        drops=0,
        largest_correction=0.0,
        rows=n_rows,
        counter=rows.counter is not None,
        reason=reason,
    )
    return ClockFit(
        t=rows.t.copy(),
        stale=np.zeros(n_rows, dtype=bool),
        drops=np.zeros(n_rows, dtype=np.int64),
        tick=np.full(n_rows, -1, dtype=np.int64),
        report=report,
    )


def _placed(
    rows: _Rows, mode: str, reason: str, n: Floats, t0: float, p: float, stats: dict[str, float]
) -> ClockFit:
    """Every row on the loop's clock: usable rows at their tick, outliers at the tick the
    motion gives them between their neighbours', stale rows at the tick of the sample they
    repeat; a row left out for its time otherwise (an outlier without a free tick) keeps
    its stamp (LogEstimator's time rules handle it)."""
    t = rows.t
    tick_u = np.full(rows.size, np.nan)
    tick_u[rows.ui] = n
    if rows.outlier.any():
        tick_u = place_between(tick_u, np.flatnonzero(rows.outlier), rows.q, rows.scale)
    fresh = np.isfinite(tick_u)
    fi = np.flatnonzero(fresh)
    ticks = _fill_forward(tick_u)
    stale_out = ~fresh & np.isfinite(ticks) & np.isfinite(t) & rows.stale
    t_out = t.copy()
    placed = fresh | stale_out
    t_out[placed] = t0 + p * ticks[placed]
    drops = np.zeros(rows.size, dtype=np.int64)
    if stats["step"] <= 1.0:
        drops[fi[1:]] = np.maximum(np.diff(tick_u[fi]) - 1, 0).astype(np.int64)
    corr = np.abs(t_out[placed] - t[placed])
    report = ClockReport(
        mode=mode,
        repaired=True,
        period=p,
        step=stats["step"],
        jitter=stats["jitter"],
        jitter_max=stats["jitter_max"],
        wander=stats["wander"],
        stale=int(stale_out.sum()),
        repeated_at_rest=int((rows.repeated & ~rows.stale).sum()),
        drops=int(drops.sum()),
        largest_correction=float(corr.max()) if corr.size else 0.0,
        rows=rows.size,
        counter=rows.counter is not None,
        reason=reason,
        outliers=int((rows.outlier & fresh).sum()),
    )
    tick_int = np.where(np.isfinite(ticks) & placed, ticks, -1).astype(np.int64)
    return ClockFit(
        t_out, stale_out, drops, tick_int, report, t0=t0, period=p, outlier=rows.outlier
    )


def fit_clock(
    t: Floats,
    q: Floats,
    *,
    mode: str = "auto",
    tick: Floats | None = None,
) -> ClockFit:
    """The loop's clock of a log (module docstring).

    Args:
        t: the stamps [s], shape ``(N,)`` (non-finite: unplaced rows, left as they are).
        q: positions, shape ``(N, nq)`` (a NaN row: a sample without a position).
        mode: ``"auto"`` (repair when the motion clearly says so), ``"stamps"``
            (keep the stamps; stale rows still found and reported, not skipped) or
            ``"loop"`` (repair whenever a loop period is found).
        tick: a sample counter per row (module docstring, step 5), or ``None``.

    Raises:
        OptionError: ``mode`` is not one of :data:`CLOCK_MODES`.
        TimestampError: ``mode="loop"`` and no period can be found (fewer than 3 rows
            with increasing stamps), or the counter goes back without wrapping.
    """
    if mode not in CLOCK_MODES:
        raise OptionError(f"clock={mode!r}: use one of {', '.join(map(repr, CLOCK_MODES))}")
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    q = (
        q.reshape(t.size, q.shape[-1] if q.ndim == 2 else -1)
        if t.size
        else q.reshape(0, -1 if q.size else 0)
    )
    rows = _screen(t, q, tick)
    if mode == "stamps":
        return _kept(rows, mode, "clock='stamps'")
    if rows.ui.size < 3:
        if mode == "loop":
            raise TimestampError(
                f"clock='loop': {rows.ui.size} rows with increasing stamps and a new "
                "position; a loop period cannot be found from fewer than 3"
            )
        return _kept(rows, mode, "too few rows to find a loop period")
    found = _find_loop(rows)
    if found is None:
        if mode == "loop":
            raise TimestampError("clock='loop': no loop period explains the stamps")
        return _kept(rows, mode, "no loop period explains the stamps")
    n, t0, p = found
    res = t[rows.ui] - (t0 + p * n)
    dn = np.diff(n)
    stats = {
        "step": float(np.median(dn)) if dn.size else 1.0,
        "jitter": float(np.sqrt(np.mean(res**2))),
        "jitter_max": float(np.max(np.abs(res))),
        "wander": successive_ratio(res),
    }
    repair, reason = _verdict(rows, mode, n, t0, p, stats)
    if not repair:
        return _kept(rows, mode, reason, p, **stats)
    return _placed(rows, mode, reason, n, t0, p, stats)


def _fill_forward(x: Floats) -> Floats:
    """NaN entries take the last finite value before them (NaN before the first)."""
    idx = np.where(np.isfinite(x), np.arange(x.size), 0)
    idx = np.maximum.accumulate(idx)
    out = x[idx]
    if x.size and not np.isfinite(x[0]):
        first = np.flatnonzero(np.isfinite(x))
        out[: first[0] if first.size else x.size] = np.nan
    return out


# -------------------------------------------------------------- streaming
@dataclass
class ClockRepair:
    """:func:`fit_clock` over a log's chunks, memory bounded by :data:`WINDOW_ROWS`.

    The clock is chosen and fitted on the first ``WINDOW_ROWS`` rows (chunks are held
    until then), then followed chunk by chunk: each chunk's ticks continue the last
    row's, and the line ``T0 + P n`` is refitted over the last window (a drifting
    logger clock).  The chunks come out with their times repaired and
    :attr:`~pinobs.io.Log.stale` / :attr:`~pinobs.io.Log.drops` set.

    Args:
        mode: as :func:`fit_clock`.
    """

    mode: str = "auto"
    window: int = WINDOW_ROWS
    report: ClockReport | None = None
    _held: list[Log] = field(default_factory=list)
    _fit: ClockFit | None = None
    _tail_t: Floats | None = None
    _tail_n: Floats | None = None
    _last_tick: float = math.nan
    _last_q: Floats | None = None  # the position of the row at _last_tick
    _scale: Floats | None = None
    _stats: dict[str, float] = field(default_factory=dict)
    # the rows before the next chunk: the last fresh row and the row before it (for the
    # stale rule), and a trailing run of repeats not judged yet (its next fresh row decides)
    _ctx: Floats | None = None
    _carry: Log | None = None
    _counter: CounterTrack | None = None

    def __post_init__(self) -> None:
        if self.mode not in CLOCK_MODES:
            raise OptionError(
                f"clock={self.mode!r}: use one of {', '.join(map(repr, CLOCK_MODES))}"
            )

    def feed(self, chunk: Log) -> list[Log]:
        """The chunks ready (none while the first window fills; a chunk's trailing
        repeats of one sample are held until the next fresh row tells whether they are
        stale)."""
        if self._fit is None:
            self._held.append(chunk)
            if sum(len(c) for c in self._held) < self.window:
                return []
            return self._decide(final=False)
        return self._follow(chunk, final=False)

    def finish(self) -> list[Log]:
        """Rows still held (a log shorter than the first window; a trailing run)."""
        if self._fit is None:
            return self._decide(final=True)
        if self._carry is None:
            return []
        from pinobs.io.readers import slice_log

        return self._follow(slice_log(self._carry, 0, 0), final=True)

    # ------------------------------------------------------------ internals
    def _decide(self, *, final: bool) -> list[Log]:
        from pinobs.io.readers import concat_logs, slice_log

        held, self._held = self._held, []
        if not held:
            return []
        log = concat_logs(held)
        fit = fit_clock(log.t, log.q, mode=self.mode, tick=log.tick)
        self._fit = fit
        self.report = fit.report
        self._stats = {
            "stale": fit.report.stale,
            "drops": fit.report.drops,
            "rest": fit.report.repeated_at_rest,
            "corr": fit.report.largest_correction,
            "rows": fit.report.rows,
            "outliers": fit.report.outliers,
        }
        if not fit.report.repaired:
            return [log]
        repeated = _repeats(log.q)
        # the last row (or a trailing run) waits for its next fresh row: a repeat for the
        # stale rule, any row for the stamps' order (an outlier needs its next row)
        k = len(log) if final else min(_decided(repeated, self.window), len(log) - 1)
        if k < len(log):
            self._carry = slice_log(log, k, len(log))
            self._carry_out(log, fit, repeated, k)
        placed = fit.tick[:k] >= 0
        idx = np.flatnonzero(placed & ~fit.stale[:k])
        outlier = fit.outlier[:k] if fit.outlier is not None else np.zeros(k, dtype=bool)
        keep = np.flatnonzero(placed & ~fit.stale[:k] & ~outlier)[-self.window :]
        self._tail_t = log.t[keep]
        self._tail_n = fit.tick[keep].astype(float)
        if idx.size:
            self._last_tick = float(fit.tick[idx[-1]])
            self._last_q = log.q[idx[-1]].copy()
        q_ok = log.q[idx]
        sc = np.median(np.abs(np.diff(q_ok, axis=0)), axis=0) if idx.size > 1 else None
        self._scale = None if sc is None else np.where(sc > 0, sc, 1.0)
        self._quantum = _quantum(log.q) if len(log) > 2 else np.zeros(log.q.shape[1])
        self._ctx = _context(np.vstack([np.full((2, log.q.shape[1]), np.nan), log.q[:k]]))
        if fit.report.counter and k and log.tick is not None:
            self._counter = CounterTrack.after(log.tick, fit.tick, k)
        if k == 0:
            return []
        head = log if k == len(log) else replace(slice_log(log, 0, k), notes=log.notes)
        return [replace(head, t=fit.t[:k], stale=fit.stale[:k], drops=fit.drops[:k])]

    def _carry_out(self, log: Log, fit: ClockFit, repeated: Bool, k: int) -> None:
        """The report of the first window without its rows ``k:`` (carried to the next
        chunk, where they are judged and counted)."""
        if repeated[k:].any():  # (a carried repeat: which of them are at rest)
            rows = _screen(np.asarray(log.t, dtype=float), log.q, log.tick)
            rest = int((repeated & ~rows.stale)[:k].sum())
        else:
            rest = fit.report.repeated_at_rest
        placed = fit.tick[:k] >= 0
        corr = np.abs(fit.t[:k][placed] - log.t[:k][placed])
        self._stats = {
            "stale": int(fit.stale[:k].sum()),
            "drops": int(fit.drops[:k].sum()),
            "rest": rest,
            "corr": float(corr.max()) if corr.size else 0.0,
            "rows": k,
            "outliers": int((fit.outlier[:k] & (fit.tick[:k] >= 0)).sum())
            if fit.outlier is not None
            else 0,
        }
        self.report = self._reported(self._stats)

    def _reported(self, stats: dict[str, float]) -> ClockReport:
        assert self._fit is not None  # (internal: _decide ran)
        return replace(
            self._fit.report,
            stale=int(stats["stale"]),
            drops=int(stats["drops"]),
            repeated_at_rest=int(stats["rest"]),
            largest_correction=float(stats["corr"]),
            rows=int(stats["rows"]),
            outliers=int(stats.get("outliers", 0)),
        )

    def _follow(self, chunk: Log, *, final: bool) -> list[Log]:
        fit = self._fit
        assert fit is not None  # (internal: _decide ran)
        rep = fit.report
        if not rep.repaired:
            self._stats["rows"] += len(chunk)
            self.report = replace(rep, rows=int(self._stats["rows"]))
            return [chunk]
        assert self._ctx is not None  # (internal: _decide ran)
        if self._carry is not None:
            from pinobs.io.readers import concat_logs

            chunk, self._carry = concat_logs([self._carry, chunk]), None
        # stale rows: repeats of the previous row (the first compared with the last row
        # out, a fresh one), judged with the two rows before the chunk
        qq = np.vstack([self._ctx, chunk.q])
        rep_all = _repeats(qq)
        rep_all[:2] = False
        k = len(chunk) if final else min(_decided(rep_all[2:], self.window), len(chunk) - 1)
        if k < len(chunk):
            from pinobs.io.readers import slice_log

            self._carry = slice_log(chunk, k, len(chunk))
            chunk = replace(slice_log(chunk, 0, k), notes=chunk.notes)
            qq, rep_all = qq[: 2 + k], rep_all[: 2 + k]
        if k == 0:
            return []
        if len(qq) > 3 and not self._quantum.all():  # a coordinate still in the first window
            self._quantum = np.where(self._quantum > 0, self._quantum, _quantum(qq[1:]))
        self._ctx = _context(qq)
        return [self._placed_chunk(chunk, qq, rep_all)]

    def _placed_chunk(self, chunk: Log, qq: Floats, rep_all: Bool) -> Log:
        fit = self._fit
        assert fit is not None  # (internal: _decide ran)
        rep = fit.report
        n_rows = len(chunk)
        self._stats["rows"] += n_rows
        p = fit.period
        t, q = chunk.t, chunk.q
        repq = rep_all[2:]
        stale = _stale(qq, rep_all, self._quantum)[2:]
        counted = None
        if self._counter is not None and chunk.tick is not None:
            counted, repeated = self._counter.follow(chunk.tick)
            stale |= repeated
        usable = np.isfinite(t) & ~stale & np.isfinite(q).all(axis=1)
        assert self._tail_t is not None and self._tail_n is not None
        t0, p = line(self._tail_n, self._tail_t, p)
        n, ui, outliers = self._chunk_ticks(t, q, usable, counted, t0, p)
        fresh = np.isfinite(n)
        fi = np.flatnonzero(fresh)
        prev_tick = self._last_tick
        ticks = _fill_forward(np.r_[prev_tick, n])[1:]
        stale_out = stale & ~fresh & np.isfinite(ticks) & np.isfinite(t)
        placed = fresh | stale_out
        t_out = t.copy()
        t_out[placed] = t0 + p * ticks[placed]
        drops = np.zeros(n_rows, dtype=np.int64)
        if fi.size and rep.step <= 1.0:
            d = np.diff(np.r_[prev_tick, n[fi]])
            d = np.where(np.isfinite(d), d, 1.0)
            drops[fi] = np.maximum(d - 1, 0).astype(np.int64)
        if fi.size:
            self._last_tick = float(n[fi[-1]])
            self._last_q = q[fi[-1]].copy()
        if ui.size:
            self._tail_t = np.r_[self._tail_t, t[ui]][-self.window :]
            self._tail_n = np.r_[self._tail_n, n[ui]][-self.window :]
        self._stats["outliers"] = self._stats.get("outliers", 0) + int(fresh[outliers].sum())
        corr = np.abs(t_out[placed] - t[placed])
        self._stats["stale"] += int(stale_out.sum())
        self._stats["drops"] += int(drops.sum())
        self._stats["rest"] += int((repq & ~stale).sum())
        self._stats["corr"] = max(self._stats["corr"], float(corr.max()) if corr.size else 0.0)
        self.report = self._reported(self._stats)
        return replace(chunk, t=t_out, stale=stale_out, drops=drops)

    def _chunk_ticks(
        self, t: Floats, q: Floats, usable: Bool, counted: Floats | None, t0: float, p: float
    ) -> tuple[Floats, NDArray[np.intp], NDArray[np.intp]]:
        """A chunk's ticks (NaN: unplaced), its in-order usable rows and its outliers (module
        docstring, steps 2, 3 and 5), after the last row placed."""
        assert self._tail_t is not None  # (internal: _decide ran)
        n = np.full(t.size, np.nan)
        ui = np.flatnonzero(usable)
        outliers = ui[:0]
        scale = self._scale if self._scale is not None else np.ones(q.shape[1])
        if counted is not None:  # step 5: the counter's ticks
            n[ui] = counted[ui]
            return n, ui, outliers
        if ui.size:  # the stamps' order (step 2) after the last row placed
            floor = float(self._tail_t[-1]) if self._tail_t.size else -math.inf
            keep = in_order(np.r_[floor, t[ui]])[1:] & (t[ui] > floor)
            outliers, ui = ui[~keep], ui[keep]
        if ui.size:
            raw = np.rint((t[ui] - t0) / p)
            start = self._last_tick + 1.0 if math.isfinite(self._last_tick) else raw[0]
            nn = monotone(np.r_[start - 1.0, np.maximum(raw, start)])[1:]
            frac = (t[ui] - t0) / p - nn
            n[ui] = resolve_by_motion(nn, frac, q[ui], scale, AMBIGUOUS)
        if outliers.size and self._last_q is not None:
            q_ext = np.vstack([self._last_q, q])
            n = place_between(np.r_[self._last_tick, n], outliers + 1, q_ext, scale)[1:]
        return n, ui, outliers


def _context(qq: Floats) -> Floats:
    """The last fresh row of ``qq`` (not a repeat of the row before it) and the row
    before it: what the stale rule of the next rows needs (:func:`_stale`)."""
    rep = _repeats(qq)
    rep[:2] = False
    a = int(np.flatnonzero(~rep)[-1])
    return np.asarray(qq[a - 1 : a + 1]).copy()


def repaired_chunks(chunks: Iterator[Log], repair: ClockRepair) -> Iterator[Log]:
    """``chunks`` through ``repair``, in order; the first one yielded even if empty."""
    any_out = False
    last: Log | None = None
    for chunk in chunks:
        last = chunk
        for out in repair.feed(chunk):
            any_out = True
            yield out
    for out in repair.finish():
        any_out = True
        yield out
    if not any_out and last is not None:
        yield last


def without_stale(log: Log, *, mode: str = "auto") -> tuple[Log, ClockReport]:
    """A whole log on its loop's clock with its stale rows left out, for what needs one
    sample per row (identification); and the report.  The rows left out are counted in
    the report (``stale``), not lost silently."""
    fit = fit_clock(log.t, log.q, mode=mode, tick=log.tick)
    if not fit.report.repaired:
        return log, fit.report
    keep = ~fit.stale
    kept_lines = {int(x) for x in np.asarray(log.lines)[keep]}

    def cut(x: Any) -> Any:
        return None if x is None else np.asarray(x)[keep]

    return (
        replace(
            log,
            t=fit.t[keep],
            q=log.q[keep],
            tau=cut(log.tau),
            problems=tuple(p for p in log.problems if p[0] in kept_lines),
            lines=np.asarray(log.lines)[keep],
            tick=cut(log.tick),
            stale=None,
            drops=fit.drops[keep],
        ),
        fit.report,
    )
