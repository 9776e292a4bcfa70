"""The estimate over a log: one output row per input row, every fault reported once.

:class:`LogEstimator` feeds log chunks to an observer-like object (anything
with ``robot``, ``name``, ``uses_torque``, ``reset(t, q, v, tau)`` and
``update(t, q_or_None, tau)``, MATH §7's sampled-data contract) and returns,
for every row, in order, the estimate at that row's time, or NaN when the row
could not be placed in time.  Per row (``T`` the nominal sample period, the
median interval of the first chunk unless given):

- **time** unreadable or not after the previous accepted row: the row is
  skipped (NaN), alone; after ``TIME_BACK_ROWS`` such rows that increase
  among themselves (a clock reset, a burst of stamps ahead) the observer
  re-initialises at the next one.  A row more than ``GAP_PERIODS`` periods ahead whose
  *next* row comes back before it (``t_k > t_{k+1}``) is a glitch: skipped
  alone, the rows after it are kept.
- **gap**: a true gap ``GAP_PERIODS·T < Δt ≤ MAX_GAP_PERIODS·T`` is
  propagated in ``⌈Δt/T⌉`` sub-steps ``update(t_j, None, τ_j)`` of at
  most ``T`` each (the sub-step estimates are not output), never in one giant
  step, the torques ``τ_j`` the log lost on the line from the held one to the
  row's (:mod:`pinobs.model.sampling`); a longer gap re-initialises the observer
  at the row (its position, zero velocity), which recovers faster than a long
  open-loop propagation
  with a held torque (measured: :data:`pinobs.tolerances.MAX_GAP_PERIODS`).
- **position** unreadable, non-finite, off its manifold or absurd (further
  outside the URDF range than ``ABSURD_LIMIT_FACTOR`` ranges): the row is a
  dropped sample (propagate only, the estimate is output).
- **torque** unreadable, non-finite or absurd (beyond ``ABSURD_LIMIT_FACTOR``
  times the URDF effort limit): the previously accepted torque is held; a
  rejected torque never reaches the observer.
- an observer that fails on a row (``ObserverDiverged``, a singular matrix), or
  whose velocity estimate is absurd (beyond ``ABSURD_LIMIT_FACTOR`` times the
  URDF velocity limit: a diverged filter stays finite for a while, up to 4e203
  rad/s on a UR5 log with torques ×50, which counted as estimated), is
  re-initialised at the next row with a usable position.

Each such row is reported once, ``(position, reason)``, with the reasons of
the row joined; positions are file lines (CSV) or row / message numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import (
    ConfigurationError,
    DimensionError,
    NonFiniteError,
    ObserverDiverged,
    PinobsError,
)
from pinobs.io.clock import ClockReport
from pinobs.io.readers import Log, concat_logs, slice_log
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.observers import Estimate
from pinobs.observers.base import median_period as _median_period
from pinobs.observers.checks import propagate_gap, time_unit_warning
from pinobs.tolerances import (
    ABSURD_LIMIT_FACTOR,
    ABSURD_VALUE,
    GAP_PERIODS,
    LIMIT_WARN_FRACTION,
    MAX_GAP_PERIODS,
    TIME_BACK_ROWS,
    TIME_EPS,
)

#: Rows :meth:`LogEstimator.feed_log` feeds one by one before it offers the observer the rest
#: at once again (while it learns σ and its period, or past a row it left).
_ROWS_ONE_BY_ONE = 32
#: The most rows :meth:`LogEstimator.feed_log` offers at once (each offer checks the rows it
#: offers: a log whose rows the observer leaves here and there is not checked to its end at
#: every offer).
_ROWS_AT_ONCE = 4096

__all__ = ["LogEstimator", "LogRun", "ObserverLike", "noise_rows", "time_screened"]


class ObserverLike(Protocol):
    """What :class:`LogEstimator` needs of an observer (an :class:`~pinobs.Observer` is one)."""

    robot: Robot

    @property
    def name(self) -> str: ...  # pragma: no cover

    @property
    def uses_torque(self) -> bool: ...  # pragma: no cover

    def reset(
        self, t0: float, q0: Any, v0: Any = None, tau0: Any = None
    ) -> Estimate: ...  # pragma: no cover

    def update(self, t: float, q_meas: Any, tau: Any = None) -> Estimate: ...  # pragma: no cover


@dataclass
class LogRun:
    """Estimates over a log, one row per log row (NaN where the row could not be placed in time).

    Attributes:
        t: the log's times [s] (as read).  Empty when the run was streamed to a file.
        q: estimated configurations ``(N, nq)``.
        v: estimated velocities ``(N, nv)``.
        bad_rows: ``(position, reason)``, once for every row dropped or repaired, in order.
        warnings: what the run could not do or found suspicious.
        rows: rows in the log.
        estimated: rows with an estimate (finite output).
        measured: rows whose position corrected the estimate.
        unit: what the positions of ``bad_rows`` count (``"line"``, ``"row"``, ``"message"``).
        noise_std: the σ the observer was built with [rad or m] (``None``: its default).
        noise_std_per_joint: σ per velocity coordinate estimated from the log, or ``None``.
        period: the nominal sample period [s] used for gaps.
        consistency: the observer's innovation test at the end of the run
            (:meth:`pinobs.Observer.consistency`), or ``None`` for an observer-like
            object without one.
        clock: what the log's clock repair found and did (:mod:`pinobs.io.clock`),
            or ``None`` when it was not run.
    """

    t: Vector
    q: Vector
    v: Vector
    bad_rows: list[tuple[int, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    rows: int = 0
    estimated: int = 0
    measured: int = 0
    unit: str = "line"
    noise_std: float | None = None
    noise_std_per_joint: Vector | None = None
    period: float | None = None
    consistency: Any = None
    clock: ClockReport | None = None

    def summary(self) -> str:
        """One line: rows in, rows estimated (with / without their measurement), rows reported;
        and the clock's repair when there was one."""
        line = (
            f"{self.rows} rows: {self.estimated} estimated ({self.measured} with their "
            f"measurement, {self.estimated - self.measured} propagated only), "
            f"{self.rows - self.estimated} without an estimate; {len(self.bad_rows)} rows reported"
        )
        if self.clock is not None and self.clock.repaired:
            c = self.clock
            line += (
                f"; clock repaired: {1e3 * (c.period or 0.0):.4g} ms loop, stamp jitter "
                f"{1e3 * c.jitter:.3g} ms RMS, {c.stale} stale rows, {c.drops} samples dropped, "
                f"largest correction {1e3 * c.largest_correction:.3g} ms"
            )
        return line


# ------------------------------------------------------------------ screening
def _absurd_bounds(robot: Robot) -> tuple[Vector, Vector, Vector, Vector, Vector]:
    """Per q coordinate: (absurd low, absurd high, warn low, warn high); per v: |τ| bound."""
    lo = np.array(robot.model.lowerPositionLimit, dtype=float)
    hi = np.array(robot.model.upperPositionLimit, dtype=float)
    # a joint without limits has ±1.8e308 in Pinocchio: clip before any arithmetic
    lo, hi = np.maximum(lo, -2 * ABSURD_VALUE), np.minimum(hi, 2 * ABSURD_VALUE)
    rng = hi - lo
    limited = np.isfinite(rng) & (rng > 0) & (rng < ABSURD_VALUE)
    pad = np.where(limited, ABSURD_LIMIT_FACTOR * rng, np.inf)
    a_lo = np.where(limited, lo - pad, -ABSURD_VALUE)
    a_hi = np.where(limited, hi + pad, ABSURD_VALUE)
    w_lo = np.where(limited, lo - LIMIT_WARN_FRACTION * rng, -np.inf)
    w_hi = np.where(limited, hi + LIMIT_WARN_FRACTION * rng, np.inf)
    return a_lo, a_hi, w_lo, w_hi, robot.absurd_torque  # the live API's bound too


@dataclass(frozen=True)
class _RowMasks:
    """Per row of a log: its position finite, absurd (beyond the joint ranges' absurd
    bounds), which joints are far outside the limits (``outside``, ``outside_rows``: only
    usable positions), and its torque non-finite or absurd (``None`` without torques)."""

    finite_q: NDArray[np.bool_]
    absurd_q: NDArray[np.bool_]
    outside: NDArray[np.bool_]
    outside_rows: list[bool]
    bad_tau: NDArray[np.bool_] | None

    @classmethod
    def of(cls, log: Log, bounds: tuple[Vector, Vector, Vector, Vector, Vector]) -> _RowMasks:
        a_lo, a_hi, w_lo, w_hi, tau_max = bounds
        q_all, tau_all = log.q, log.tau
        finite_q: NDArray[np.bool_] = np.asarray(np.isfinite(q_all).all(axis=1))
        absurd_q: NDArray[np.bool_] = np.asarray(
            finite_q & ((q_all < a_lo) | (q_all > a_hi)).any(axis=1)
        )
        # rows far outside the limits (the degrees warning of finish): only usable positions
        # of rows placed in time (a sweep found an inf cell said as "|q| up to inf")
        outside = (q_all < w_lo) | (q_all > w_hi)
        outside_rows = (outside.any(axis=1) & finite_q & ~absurd_q).tolist()
        bad_tau: NDArray[np.bool_] | None = None
        if tau_all is not None:
            bad_tau = np.asarray(
                ~np.isfinite(tau_all).all(axis=1) | (np.abs(tau_all) > tau_max).any(axis=1)
            )
        return cls(finite_q, absurd_q, outside, outside_rows, bad_tau)


def _coordinate_names(robot: Robot) -> list[str]:
    names = [""] * robot.nq
    for b in robot.joints:
        for k in range(b.nq):
            names[b.idx_q + k] = b.name if b.nq == 1 else f"{b.name}[{k}]"
    return names


def _called(observer: ObserverLike) -> str:
    """How a warning names ``observer``: its name, or the model-based observer a never-behind
    blend runs (the blend's own name, ``never_behind``, is no observer a user chose)."""
    from pinobs.observers.neverbehind import NeverBehind

    if isinstance(observer, NeverBehind):
        return f"{observer.model.name!r} (blended never behind kf)"
    return repr(observer.name)


class LogEstimator:
    """Run an observer-like object over log chunks (rules: module docstring).

    Args:
        observer: the observer (``reset``/``update``, see :class:`ObserverLike`).
        period: nominal sample period [s] (default: the median interval of the first chunk).
        check_v: re-initialise an observer whose velocity estimate is absurd (module
            docstring); off for an observer-like whose estimates carry no velocity.
    """

    def __init__(
        self, observer: ObserverLike, *, period: float | None = None, check_v: bool = True
    ) -> None:
        self.observer = observer
        self.robot = observer.robot
        self.period = period
        self.bad_rows: list[tuple[int, str]] = []
        self.warnings: list[str] = []
        self.rows = 0
        self.estimated = 0
        self.measured = 0
        self._bounds = _absurd_bounds(self.robot)
        vel = np.minimum(np.array(self.robot.model.velocityLimit, dtype=float), 2 * ABSURD_VALUE)
        ok = np.isfinite(vel) & (vel > 0) & (vel < ABSURD_VALUE)
        # (check_v=False: an observer-like whose estimates carry no velocity, the smoother's
        # recorder: pinobs.io.smoothing)
        self._v_max = np.where(ok, ABSURD_LIMIT_FACTOR * vel, ABSURD_VALUE) if check_v else np.inf
        self._names = _coordinate_names(self.robot)
        self._outside: dict[int, float] = {}
        self._pending: Log | None = None
        self._started = False
        self._t = -math.inf
        self._held: Vector | None = None
        self._back = 0  # consecutive rows behind the previous accepted time, increasing
        self._back_t = -math.inf
        self._any_tau = False  # a chunk with torques was fed
        # rows before the first usable torque (zero torque used): count, first and last
        # position (a sweep found them "previous torque held" though none was, and for a bag
        # the reports depended on where its chunks began)
        self._untorqued: list[int] = [0, 0, 0]
        self.failures = 0  # rows where the observer failed or diverged (re-initialised there)
        self._first_failure = math.nan  # the first one's time [s]
        self._unit = "line"
        self._time_skipped = 0  # rows skipped for a time not after the previous row's
        self._unit_checked = False
        self._last: tuple[Vector, Vector] | None = None  # the last estimate output
        self.stale = 0  # stale rows given the previous sample's estimate (pinobs.io.clock)

    # ---------------------------------------------------------------- API
    def feed(self, chunk: Log, *, last: bool = False) -> tuple[Vector, Vector, Vector]:
        """Estimate the rows of ``chunk`` (one row is held back for the look-ahead unless ``last``).

        Returns ``(t, q, v)`` of the rows done, in order: over all calls, one row per input row.
        """
        self._any_tau = self._any_tau or (len(chunk) > 0 and chunk.tau is not None)
        log = chunk if self._pending is None else _concat(self._pending, chunk, self.robot.nv)
        self._said_of(chunk, log)
        n = len(log) if last else max(len(log) - 1, 0)
        self._pending = None if n == len(log) else slice_log(log, n, len(log))
        return self._run(log, n)

    def feed_log(self, log: Log) -> tuple[Vector, Vector, Vector]:
        """:meth:`feed` of a whole log at once (:func:`~pinobs.io.estimate_log`; :meth:`finish`
        after it): the same rows, estimates and reports.  An observer that takes rows in one
        call (``update_rows``: ``kf``'s compiled bank) is given the log's leading plain rows
        (:meth:`_plain_rows`) so, as far as it takes them; the other rows, the first ones (the
        observer's reset, σ learnt from the log) and those it leaves, one by one as
        :meth:`feed` does (each with the next row to look ahead to)."""
        take = getattr(self.observer, "update_rows", None)
        period = _median_period(log.t) if self.period is None else self.period
        plain = self._plain_rows(log, period)
        if take is None or self._started or self._pending is not None or plain < 2:
            return self.feed(log)
        self._said_of(log, log)  # (its period: ``period``, plain ≥ 2 rows)
        k, parts = 0, []
        while k < plain:
            if self._started:  # the rows from k at once, as far as the observer takes them
                stop = min(plain, k + _ROWS_AT_ONCE)
                q, v = take(log.t[k:stop], log.q[k:stop], self._v_max)
                if len(q):
                    parts.append((log.t[k : k + len(q)], q, v))
                    self._taken(log, k, len(q), q[-1], v[-1])
                    k += len(q)
                    continue
            end = min(k + _ROWS_ONE_BY_ONE, plain)
            parts.append(self._run(slice_log(log, k, min(end + 1, len(log))), end - k))
            k = end
        parts.append(self.feed(slice_log(log, plain, len(log))))
        t, q, v = (np.concatenate(x) for x in zip(*parts, strict=True))
        return t, q, v

    def _said_of(self, chunk: Log, log: Log) -> None:
        """``chunk``'s notes in :attr:`warnings`, and once the period and the time unit of
        ``log`` (``chunk`` after the row held back)."""
        self.warnings.extend(n for n in chunk.notes if n not in self.warnings)
        if self.period is None:
            self.period = _median_period(log.t)
        if not self._unit_checked and len(log) > 1:
            self._unit_checked = True
            said = time_unit_warning(_median_period(log.t))
            if said is not None:
                self.warnings.append(said)

    def _plain_rows(self, log: Log, period: float | None) -> int:
        """How many of the log's rows, from its first, are plain: each fed to the observer as
        it is, placed after the one before (a finite time after it by more than ``TIME_EPS``,
        within :data:`GAP_PERIODS` periods: no sub-steps), a finite position within the
        joints' warning limits, nothing reported (no problem, no stale row or dropped samples,
        no torque column); ``period`` the log's (none: no row is)."""
        if log.tau is not None or log.problems or period is None or len(log) < 2:
            return 0
        t, masks = log.t, _RowMasks.of(log, self._bounds)
        ok = masks.finite_q & ~masks.absurd_q & ~masks.outside.any(axis=1) & np.isfinite(t)
        if log.stale is not None:
            ok &= ~log.stale
        if log.drops is not None:
            ok &= log.drops == 0
        ok[1:] &= (t[1:] > t[:-1] + TIME_EPS) & (t[1:] - t[:-1] <= GAP_PERIODS * period)
        return len(t) if ok.all() else int(np.argmin(ok))

    def _taken(self, log: Log, k: int, m: int, q: Vector, v: Vector) -> None:
        """The counts of :meth:`_run` after its rows ``k … k + m − 1`` of ``log``, plain rows
        the observer took at once (``q``, ``v``: the last one's estimate)."""
        self._t, self._last = float(log.t[k + m - 1]), (q.copy(), v.copy())
        self.estimated, self.measured, self.rows = (
            x + m for x in (self.estimated, self.measured, self.rows)
        )
        if not self._untorqued[0]:  # (no torque column: every row counted, as _torque does)
            self._untorqued[1] = int(log.lines[k])
        self._untorqued[0] += m
        self._untorqued[2] = int(log.lines[k + m - 1])

    def finish(self) -> tuple[Vector, Vector, Vector]:
        """The held-back row, and the limit warning (call once, after the last chunk)."""
        out = self.feed(_empty_like(self.robot), last=True)
        if self.rows >= 10 and 2 * self._time_skipped > self.rows:
            # (a sweep found a reversed log estimated on 1 row of 2001, exit 0, no hint)
            self.warnings.append(
                f"{self._time_skipped} of {self.rows} rows were skipped because their t is not "
                "after the previous row's: is the log in reverse order, or is t not its time "
                "column? Sort it by t"
            )
        if self.failures:
            # (found on real UR10e logs: ekf diverged and was re-initialised 299 times, said
            # only row by row, its consistency "unknown" over the 1 sample since the last)
            why = (
                "its model does not explain this log: use a model-free observer (kf) or a "
                "calibrated model (pinobs identify), and check the torque columns"
                if self.observer.uses_torque
                else "check the log's positions and times (the rows reported)"
            )
            self.warnings.append(
                f"{_called(self.observer)} failed or diverged on {self.failures} rows (the first "
                f"at t = {self._first_failure:.6g} s) and was re-initialised at each; {why}"
            )
        n, first, last = self._untorqued
        if self.observer.uses_torque and n and not self._any_tau:
            self.warnings.append(
                f"the log has no torque columns: {_called(self.observer)} uses the model's dynamics "
                "and now assumes zero applied torque (gravity stays modelled); its estimates carry "
                "the effect of the missing inputs. Add tau columns (or JointState effort), or use a "
                "model-free observer (fd, kf)."
            )
        elif self.observer.uses_torque and n:
            self.warnings.append(
                f"{n} rows before the first usable torque ({self._unit} {first} to {last}) have "
                f"none: {_called(self.observer)} assumed zero applied torque there (gravity stays "
                "modelled), so its estimates on them carry the effect of the missing inputs"
            )
        if self._outside:
            joints = ", ".join(
                f"{self._names[i]} (|q| up to {m:.4g})" for i, m in sorted(self._outside.items())
            )
            self.warnings.append(
                f"positions far outside the URDF limits on joints {joints}: a log in degrees? "
                "pinobs expects radians (and metres)"
            )
        return out

    # ------------------------------------------------------------ the loop
    def _run(self, log: Log, n: int) -> tuple[Vector, Vector, Vector]:
        robot = self.robot
        out_q = np.full((n, robot.nq), np.nan)
        out_v = np.full((n, robot.nv), np.nan)
        if n == 0:
            return log.t[:0], out_q, out_v
        masks = _RowMasks.of(log, self._bounds)
        q_all, t_all, tau_all = log.q, log.t, log.tau
        problems: dict[int, list[str]] = {}
        for pos, reason in log.problems:
            problems.setdefault(pos, []).append(reason)
        lines = log.lines
        unit = log.unit
        self._unit = unit
        # a bag's messages are named by number and stamp, file rows by their line
        stamps: list[float | None] = t_all.tolist() if unit == "message" else [None] * n
        stale = log.stale if log.stale is not None else np.zeros(n, dtype=bool)
        drops = log.drops if log.drops is not None else np.zeros(n, dtype=np.int64)
        for k in range(n):
            t = float(t_all[k])
            why = problems.get(int(lines[k]), [])
            notes: list[str] = list(why)
            if stale[k] and self._started and self._last is not None and t == self._t:
                # a repeat of the previous sample (the clock repair): no measurement, the
                # estimate at that sample's time (pinobs.io.clock)
                out_q[k], out_v[k] = self._last
                self.estimated += 1
                self.stale += 1
                if notes:
                    self._report(lines[k], stamps[k], notes)
                continue
            # ---- time
            nxt = float(t_all[k + 1]) if k + 1 < len(log) else None
            skipped = self._time_verdict(t, nxt, unit, notes)
            if skipped is not None:
                self._report(lines[k], stamps[k], [*notes, skipped])
                continue
            # ---- values
            q_ok = self._position_verdict(q_all[k], masks, k, bool(why), notes)
            held = self._held
            tau = self._torque(
                None if tau_all is None else tau_all[k],
                masks.bad_tau is not None and bool(masks.bad_tau[k]),
                int(lines[k]),
                bool(why),
                notes,
            )
            # ---- estimate
            est = self._estimate(t, q_all[k] if q_ok else None, tau, notes, held, int(drops[k]))
            if est is None:
                self._report(lines[k], stamps[k], notes)
                continue
            out_q[k], out_v[k] = est[0].q, est[0].v
            self._last = (out_q[k].copy(), out_v[k].copy())
            self.estimated += 1
            self.measured += int(est[1])
            if notes:
                self._report(lines[k], stamps[k], notes)
        self.rows += n
        return t_all[:n], out_q, out_v

    def _position_verdict(
        self, q: Vector, masks: _RowMasks, k: int, unreadable: bool, notes: list[str]
    ) -> bool:
        """Whether row ``k``'s position ``q`` is usable; its joints far outside the limits
        recorded (the degrees warning of :meth:`finish`), an absurd or non-finite one said in
        ``notes`` (unless the row was ``unreadable``: its problem says why)."""
        if masks.outside_rows[k]:
            for i in np.flatnonzero(masks.outside[k]).tolist():
                self._outside[i] = max(self._outside.get(i, 0.0), abs(float(q[i])))
        finite, absurd = bool(masks.finite_q[k]), bool(masks.absurd_q[k])
        if finite and absurd:
            notes.append(f"position {q.tolist()} absurd for the joint ranges")
        elif not finite and not unreadable:
            notes.append(f"non-finite position {q.tolist()}")
        return finite and not absurd

    def _time_verdict(self, t: float, nxt: float | None, unit: str, notes: list[str]) -> str | None:
        """Why the row at ``t`` is skipped for its time (module docstring), or ``None``: it
        is placed (``notes`` then say when time went back and the observer restarts)."""
        if not math.isfinite(t):
            return f"time {t!r} unreadable: row skipped"
        if self._started and not t > self._t + TIME_EPS:
            # rows that go back in time together (a clock reset, a burst of stamps ahead)
            # would otherwise all be skipped: after TIME_BACK_ROWS, restart
            self._back = self._back + 1 if t > self._back_t + TIME_EPS else 1
            self._back_t = t
            if self._back <= TIME_BACK_ROWS:
                self._time_skipped += 1
                return (
                    f"t = {t!r} s is not after the previous sample at t = {self._t!r} s: "
                    "row skipped"
                )
            notes.append(
                f"time went back to t = {t!r} s (previous sample at t = {self._t!r} s) and "
                f"stayed there for {TIME_BACK_ROWS} rows: observer re-initialised here"
            )
            self._started = False
        self._back = 0
        period = self.period
        if (
            self._started
            and period is not None
            and t - self._t > GAP_PERIODS * period
            and nxt is not None
            and math.isfinite(nxt)
            and self._t < nxt < t
        ):
            return (
                f"t = {t!r} s is far ahead of the next {unit} (t = {nxt!r} s): "
                "timestamp out of order, row skipped"
            )
        return None

    def _torque(
        self, tau: Vector | None, bad: bool, line: int, unreadable: bool, notes: list[str]
    ) -> Vector | None:
        """The torque the row feeds the observer (module docstring): its own, the previous
        one held for a bad one (``notes`` say so), or ``None`` (zero torque, counted)."""
        held = self._held
        if tau is None or (held is None and bad and np.isnan(tau).all()):
            if held is None:  # none yet: zero torque, counted (said once, by finish)
                if not self._untorqued[0]:
                    self._untorqued[1] = line
                self._untorqued[0] += 1
                self._untorqued[2] = line
            return None
        if bad:
            if not unreadable or np.isfinite(tau).all():
                notes.append(f"torque {tau.tolist()} non-finite or absurd")
            notes.append("previous torque held" if held is not None else "zero torque used")
            return held
        self._held = tau
        return tau

    def _estimate(
        self,
        t: float,
        q: Vector | None,
        tau: Vector | None,
        notes: list[str],
        held: Vector | None = None,
        dropped: int = 0,
    ) -> tuple[Estimate, bool] | None:
        """The estimate at ``t`` and whether ``q`` corrected it; ``None``: no estimate.

        ``held`` is the torque the observer holds from the previous row (for gap sub-steps);
        ``dropped`` the loop samples the clock repair found missing before the row (the
        gap they leave is propagated without a note: the clock's report counts them).
        """
        ob = self.observer
        if not self._started:
            return self._start(t, q, tau, notes)
        period = self.period
        gap = t - self._t
        try:
            if period is not None and gap > MAX_GAP_PERIODS * period:
                notes.append(f"gap of {gap:.6g} s ({gap / period:.0f} periods) before this row")
                return self._restart(t, q, tau, notes)
            t0 = self._t

            def substep(_: None, j: int, steps: int) -> None:  # gap/steps <= period; not output
                # the torques the log lost: on the line from the held one to this row's
                # (pinobs.model.sampling: holding it across the gap made a smoother's
                # velocity error 33x on a UR5 log with 8 % of its rows dropped)
                s = j / steps
                lost = held if held is None or tau is None else held + s * (tau - held)
                ob.update(t0 + s * gap, None, lost)

            _, steps = propagate_gap(substep, None, gap, period)  # the observers' pause rule
            if steps > 1 and not dropped and period is not None:
                notes.append(
                    f"gap of {gap:.6g} s ({gap / period:.1f} periods) before this row: "
                    f"propagated in {steps} steps of {gap / steps:.3g} s"
                )
            if q is not None:
                try:
                    est = ob.update(t, q, tau)
                    self._t = t
                    return self._sane(est, t), True
                except (ConfigurationError, NonFiniteError, DimensionError) as exc:
                    notes.append(f"{exc}")
            notes.append("used as a dropped sample (propagated only)")
            est = ob.update(t, None, tau)
            self._t = t
            return self._sane(est, t), False
        except (ObserverDiverged, ArithmeticError, np.linalg.LinAlgError, PinobsError) as exc:
            notes.append(f"observer failed ({type(exc).__name__}: {exc})")
            self.failures += 1
            if self.failures == 1:
                self._first_failure = t
            return self._restart(t, q, tau, notes)

    def _start(
        self, t: float, q: Vector | None, tau: Vector | None, notes: list[str]
    ) -> tuple[Estimate, bool] | None:
        """The observer started on the row at ``t`` (its estimate, corrected by ``q``), or
        ``None`` (``notes`` say why): no usable position, or one it refuses."""
        if q is None:
            notes.append("no usable position yet: no estimate")
            return None
        try:
            est = self.observer.reset(t, q, None, tau)
        except (ConfigurationError, NonFiniteError, DimensionError) as exc:
            notes.append(f"{exc}: no estimate")
            return None
        self._started, self._t = True, t
        return est, True

    def _sane(self, est: Estimate, t: float) -> Estimate:
        """``est``, or :class:`ObserverDiverged` if a velocity is absurd (module docstring)."""
        bad = np.abs(est.v) > self._v_max
        if bad.any():  # (the method: np.any's wrapper costs more than the test, every row)
            i = int(np.argmax(bad))
            raise ObserverDiverged(
                f"v[{i}] = {est.v[i]:.3g} is beyond {ABSURD_LIMIT_FACTOR:g}× the velocity limit "
                "(the observer diverged: its model does not explain the log)",
                t=t,
            )
        return est

    def _restart(
        self, t: float, q: Vector | None, tau: Vector | None, notes: list[str]
    ) -> tuple[Estimate, bool] | None:
        self._started = False
        if q is None:
            notes.append("no usable position here: no estimate until the next one")
            return None
        notes.append("observer re-initialised here")
        return self._estimate(t, q, tau, notes)

    def _report(self, line: Any, stamp: float | None, notes: list[str]) -> None:
        if notes:
            head = [] if stamp is None else [f"stamp {stamp:.9f} s"]
            self.bad_rows.append((int(line), "; ".join(head + notes)))


def noise_rows(log: Log) -> tuple[Vector, Vector]:
    """The times and positions of ``log`` that its noise estimate uses (:func:`time_screened`):
    the first chunk's, for the σ an observer or a smoother takes when none is given."""
    timed = time_screened(log.t)
    return log.t[timed], log.q[timed]


def time_screened(t: Vector) -> NDArray[np.bool_]:
    """Rows whose time is finite and after the previous row's: those the noise estimate
    may use (a sweep found duplicated rows, zero third differences beside jumps, estimate
    σ 3.71e-4 for 9.77e-5)."""
    t = np.asarray(t, dtype=float)
    keep = np.isfinite(t)
    keep[1:] &= t[1:] > t[:-1] + TIME_EPS
    return keep


def _concat(a: Log, b: Log, nv: int) -> Log:
    return concat_logs([x for x in (a, b) if len(x)] or [a], nv=nv)


def _empty_like(robot: Robot) -> Log:
    return Log(np.empty(0), np.empty((0, robot.nq)), None, lines=np.empty(0, dtype=int))
