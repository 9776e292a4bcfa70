"""Offline smoothing of a log file: the io readers' screening and row accounting, the io writer.

:func:`smooth_log` runs :func:`pinobs.smooth` over a log read chunk by chunk
with :func:`pinobs.io.iter_log` (every format), through the same screening as
``pinobs estimate`` (:class:`~pinobs.io.LogEstimator`: unreadable or absurd
rows, time going back, gaps propagated over in sub-steps, restarts after a
long gap, every fault reported once): a recorder stands in for the observer
and keeps the samples the estimator would feed it, then each stretch between
restarts is smoothed and written with :class:`~pinobs.io.EstimateWriter`
(atomic; no overwrite without ``force``; never over an input), one row per
log row, ``t, q0.., v0.., v_std0..``.

Memory: with ``chunk`` or ``lag`` and a given ``accel_psd`` over ``ekf``, the
log streams: each sample goes to a :class:`~pinobs.smoothing.Smoother`
as the estimator screens it, finished samples are written as soon as every
row before them is, and only ``chunk + overlap`` samples' states (and the rows
waiting for them) are held.  Otherwise (the whole log at once,
``accel_psd="auto"``, which passes over the log once per candidate,
``adaptive``, whose learning pass comes first, or ``band="inflated"``, scaled by
the whole log's ``ρ``) the screened samples,
``1 + nq + nv`` floats per row, are kept and smoothed at the end.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from pinobs.errors import PinobsError
from pinobs.io.clock import ClockRepair
from pinobs.io.drives import Drives
from pinobs.io.readers import CHUNK_ROWS, LogSource, chain_chunks
from pinobs.io.runs import read_repaired
from pinobs.io.stream import (
    LogEstimator,
    LogRun,
    noise_rows,
    time_unit_warning,
)
from pinobs.io.writers import EstimateWriter
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.model.sampling import missing_samples
from pinobs.observers.base import NOISE_FLOOR, Estimate, median_period, observer_class, positive
from pinobs.smoothing import (
    Smoother,
    latency_note,
    log_noise_std,
    smooth_quietly,
    smoothing_warnings,
    streaming_smoother,
)

__all__ = ["smooth_log"]


class _Recorder:
    """Observer-like stand-in for :class:`LogEstimator`: keeps what it is fed, one list of
    ``(t, q or None, tau)`` per start (a restart begins a new one); its estimate's ``v``
    holds the running sample number, so each output row finds its smoothed sample."""

    def __init__(self, robot: Robot, name: str) -> None:
        self.robot = robot
        self.name = name
        self.uses_torque = observer_class(name).uses_torque  # kf: no torque, no warning
        self.segments: list[list[tuple[float, Vector | None, Vector]]] = []
        self._n = 0
        # whether each sample from number `had_q_from` on had its measurement (the rows'
        # "with their measurement" count; a stream pops what it has written)
        self.had_q: deque[bool] = deque()
        self.had_q_from = 0

    def _keep(self, t: float, q: Any, tau: Any) -> Estimate:
        tau_arr = np.zeros(self.robot.nv) if tau is None else np.asarray(tau, dtype=float)
        q_arr = None if q is None else self.robot.check_configuration(q, what="q")
        self._take(float(t), q_arr, tau_arr)
        self.had_q.append(q_arr is not None)
        self._n += 1
        shown = self.robot.neutral() if q_arr is None else q_arr
        return Estimate(float(t), shown, np.full(self.robot.nv, float(self._n - 1)))

    def _take(self, t: float, q: Vector | None, tau: Vector) -> None:
        self.segments[-1].append((t, q, tau))

    def reset(self, t0: float, q0: Any, v0: Any = None, tau0: Any = None) -> Estimate:
        self.segments.append([])
        return self._keep(t0, q0, tau0)

    def update(self, t: float, q_meas: Any, tau: Any = None) -> Estimate:
        return self._keep(t, q_meas, tau)


class _Streamer(_Recorder):
    """The recorder's interface, each sample smoothed as it comes: a stretch (between
    restarts) is one :class:`Smoother`; finished samples wait in :attr:`finished`.

    A sample after an interval of :data:`~pinobs.model.sampling.MISSING_PERIODS` periods or
    more is preceded by the samples the log lost there, at their ticks with their torques
    on the line across the interval, as :func:`pinobs.smooth` puts a log on its ticks
    (:func:`~pinobs.model.sampling.on_ticks`); they have no row and are not output."""

    def __init__(self, robot: Robot, name: str, new: Callable[[], Smoother], period: float) -> None:
        super().__init__(robot, name)
        self._new = new
        self._period = period
        self._sm: Smoother | None = None
        self._first = 0  # number of the stretch's first sample
        # per sample pushed to the stretch's smoother from number `_pushed_from` on: its
        # sample number, or -1 for a lost one put back on its tick
        self._numbers: deque[int] = deque()
        self._pushed_from = 0
        self._last: tuple[float, Vector] | None = None  # the previous sample's (t, tau)
        self.finished: deque[tuple[int, Vector, Vector, Vector]] = deque()
        self.rho = [0.0, 0]  # the stretches' filter–smoother consistency terms (sum, count)

    def _take(self, t: float, q: Vector | None, tau: Vector) -> None:
        assert self._sm is not None  # reset comes first (LogEstimator)
        if self._last is not None:
            t0, tau0 = self._last
            lost = int(missing_samples(np.array([t0, t]), self._period)[0])
            for i in range(1, lost + 1):
                s = i / (lost + 1)
                self._push(t0 + s * (t - t0), None, tau0 + s * (tau - tau0), -1)
        self._last = (t, tau)
        self._push(t, q, tau, self._n)

    def _push(self, t: float, q: Vector | None, tau: Vector, number: int) -> None:
        assert self._sm is not None
        self._numbers.append(number)
        self._finish(self._sm.push(t, q, tau))

    def _finish(self, done: list[tuple[int, Vector, Vector, Vector]]) -> None:
        """``done``'s samples (by their place in the stretch) as sample numbers, in order."""
        for k, *rest in done:
            while self._pushed_from < k:
                self._numbers.popleft()
                self._pushed_from += 1
            number = self._numbers.popleft()
            self._pushed_from += 1
            if number >= 0:
                self.finished.append((number, *rest))  # type: ignore[arg-type]

    def reset(self, t0: float, q0: Any, v0: Any = None, tau0: Any = None) -> Estimate:
        self.flush()
        self._sm, self._first = self._new(), self._n  # no segment list: nothing is kept
        self._numbers.clear()
        self._pushed_from, self._last = 0, None
        try:
            return self._keep(t0, q0, tau0)
        except Exception:
            self._sm = None
            raise

    def flush(self) -> None:
        """Smooth what the stretch still holds (a restart, or the log's end)."""
        if self._sm is not None:
            done = self._sm.close()
            if self._n - self._first > 1:  # one sample: no velocity to smooth
                self._finish(done)
            n = self._sm.consistency_terms  # ρ is a mean over n terms: the stretches pool
            self.rho[0] += self._sm.consistency * n if n else 0.0
            self.rho[1] += n
            self._sm = None


def smooth_log(
    source: LogSource,
    robot: Robot,
    out: str | Path,
    *,
    observer: str = "ekf",
    noise_std: float | None = None,
    accel_psd: float | Literal["auto"] | None = None,
    lag: float | None = None,
    chunk: float | None = None,
    force: bool = False,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    rate: float | None = None,
    options: Mapping[str, Any] | None = None,
    chunk_rows: int = CHUNK_ROWS,
    stream: bool = True,
    band: str | None = None,
    clock: str = "auto",
    drives: Drives | None = None,
) -> tuple[LogRun, list[dict[str, Any]]]:
    """Smooth a log file into ``out`` (module docstring); returns the row accounting and
    the smoother's options of each stretch (with its ``consistency``,
    :attr:`pinobs.smoothing.Smoother.consistency`, and ``consistency_terms``, how
    many terms it averages; streamed: one, over every stretch).  A stretch whose ``ρ``
    exceeds :data:`~pinobs.smoothing.RHO_WARN` (or whose ``"auto"`` density is the
    grid's largest) adds what :func:`pinobs.smooth` would warn
    (:func:`~pinobs.smoothing.smoothing_warnings`) to the run's ``warnings``, and
    so does a latency found for a stretch the model did not explain as stamped
    (:func:`~pinobs.smoothing.latency_note`; not when streamed: the search passes
    over the whole log).

    Args:
        source: log path or DataFrame (:func:`pinobs.io.iter_log`).
        robot: the robot of the log.
        out: CSV file ``t, q0.., v0.., v_std0..`` (refused if it exists, unless ``force``,
            or if it is ``source``).
        observer, accel_psd, lag, chunk, band: as :func:`pinobs.smooth`.
        noise_std: position noise σ [rad or m]; ``None``: estimated from the log's first
            second as :func:`pinobs.smooth` does, reported in the run's ``warnings``,
            ``noise_std`` and ``noise_std_per_joint``.
        columns, topic, drives: as :func:`pinobs.io.iter_log`.
        rate: sample rate [Hz] (default: from the log's median interval); a table log
            without a ``t`` column is read as sampled at it (:func:`pinobs.io.iter_log`).
        options: further options of the filter (``filter_options`` of :func:`pinobs.smooth`).
        chunk_rows: rows read at a time (:func:`pinobs.io.iter_log`).
        stream: stream when possible (module docstring); ``False``: keep the samples and
            smooth at the end (the same numbers, more memory).
        clock: the log's clock, as :func:`pinobs.io.process_log` (stale rows give the
            smoothed estimate of the sample they repeat).

    Raises:
        OutputExistsError: ``out`` exists (without ``force``) or is the input.
        GainError: no ``noise_std`` and too few finite rows at the log's start to estimate it.
        and what :func:`pinobs.smooth` and :func:`pinobs.io.iter_log` raise.
    """
    positive("rate", rate, allow_none=True)  # (0 or less: not "from the log")
    inputs = [] if type(source).__name__ == "DataFrame" else [source]
    writer = EstimateWriter(
        out, robot, force=force, inputs=inputs, extra_columns=[f"v_std{i}" for i in range(robot.nv)]
    )
    how = _Smoothing(observer, noise_std, accel_psd, lag, chunk, options, band)
    try:
        repair, chunks = read_repaired(
            source, robot, clock, columns, topic, chunk_rows, drives, rate
        )
        run, stretches = _smoothed(chunks, robot, writer, how, rate, stream and how.streams())
    except BaseException:
        writer.abort()
        raise
    _tell(run, stretches, repair)
    return run, stretches


@dataclass(frozen=True)
class _Smoothing:
    """How :func:`smooth_log` smooths: its arguments of the same names."""

    observer: str
    noise_std: float | None
    accel_psd: float | Literal["auto"] | None
    lag: float | None
    chunk: float | None
    options: Mapping[str, Any] | None
    band: str | None

    def streams(self) -> bool:
        """Whether the log can stream (module docstring), when asked to."""
        return (
            (self.chunk is not None or self.lag is not None)
            and self.accel_psd != "auto"
            and self.observer == "ekf"
            and self.band != "inflated"  # scaled by the whole log's ρ
            and not (self.options or {}).get("latency")  # re-timed as a whole (pinobs.smooth)
        )


def _smoothed(
    chunks: Any,
    robot: Robot,
    writer: EstimateWriter,
    how: _Smoothing,
    rate: float | None,
    stream: bool,
) -> tuple[LogRun, list[dict[str, Any]]]:
    """The log's chunks smoothed into ``writer`` (closed); a failure of the smoothing says
    the log's time unit when it is not seconds."""
    first = next(chunks)
    period = 1.0 / rate if rate else median_period(first.t)
    unit = time_unit_warning(median_period(first.t))
    try:
        said, sigma_joint = [], None
        # (a sweep found an empty log "give noise_std")
        if how.noise_std is None and not len(first):
            how = replace(how, noise_std=NOISE_FLOOR)
        elif how.noise_std is None:  # as pinobs.smooth, from the first chunk
            noise_std, sigma_joint, message = log_noise_std(robot, *noise_rows(first))
            how = replace(how, noise_std=noise_std)
            said.append(message)
        if stream and period is not None:
            run, stretches = _streamed(first, chunks, robot, writer, period, how)
        else:
            run, stretches = _recorded(first, chunks, robot, writer, period, how)
        writer.close()
    except PinobsError as exc:
        if unit is not None and exc.args and isinstance(exc.args[0], str):
            # (a sweep found a log in ms fail here saying only "the filter is lost")
            exc.args = (f"{exc.args[0]} (and {unit})", *exc.args[1:])
        raise
    run.warnings[:0] = said
    run.noise_std_per_joint = sigma_joint
    return run, stretches


def _tell(run: LogRun, stretches: list[dict[str, Any]], repair: ClockRepair) -> None:
    """The run's clock report, its repair said first in the run's warnings, then what
    :func:`pinobs.smooth` warns, per stretch."""
    run.clock = repair.report
    if run.clock is not None and (run.clock.repaired or run.clock.stale):
        run.warnings.insert(0, run.clock.message())
    for i, opts in enumerate(stretches):  # what pinobs.smooth warns, per stretch
        note = latency_note(opts)
        for told in ([] if note is None else [note]) + smoothing_warnings(
            opts["consistency"], opts
        ):
            run.warnings.append(told if len(stretches) == 1 else f"stretch {i + 1}: {told}")


class _Rows:
    """The rows a stream has read and not yet written: each written, in order, once its
    sample is smoothed (its ``t`` and estimate, NaN without one), counted as
    :class:`LogRun`'s ``estimated`` and ``measured``."""

    def __init__(self, rec: _Streamer, writer: EstimateWriter) -> None:
        self.rec, self.writer = rec, writer
        self.pending: deque[tuple[float, float]] = deque()  # (t, sample number or NaN)
        self.estimated = self.measured = 0
        self.nan_q, self.nan_v = np.full(rec.robot.nq, np.nan), np.full(rec.robot.nv, np.nan)

    def add(self, t: Vector, idx: Any) -> None:
        """Rows read (their times and :class:`LogEstimator`'s estimates: sample numbers)."""
        self.pending.extend(zip(t.tolist(), idx[:, 0].tolist(), strict=True))

    def drain(self, final: bool) -> None:
        """Write the rows whose samples are done (``final``: every row)."""
        rows: list[tuple[float, Vector, Vector, Vector]] = []
        pending, rec, done = self.pending, self.rec, self.rec.finished
        nan_q, nan_v = self.nan_q, self.nan_v
        while pending:
            t, idx = pending[0]
            if math.isnan(idx):
                rows.append((t, nan_q, nan_v, nan_v))
            else:
                while done and done[0][0] < idx:
                    done.popleft()  # gap sub-steps: no row of their own
                if done and done[0][0] == idx:
                    _, qs, vs, var = done[0]
                    rows.append((t, qs, vs, np.sqrt(np.maximum(var, 0.0))))
                    if np.all(np.isfinite(vs)):
                        self.estimated += 1
                        while rec.had_q_from < idx:  # samples no row will ask for again
                            rec.had_q.popleft()
                            rec.had_q_from += 1
                        self.measured += rec.had_q[0]
                elif final:
                    rows.append((t, nan_q, nan_v, nan_v))  # a one-sample stretch
                else:
                    break
            pending.popleft()
        if rows:
            self.writer.write(*(np.array(c) for c in zip(*rows, strict=True)))


def _streamed(
    first: Any, chunks: Any, robot: Robot, writer: EstimateWriter, period: float, how: _Smoothing
) -> tuple[LogRun, list[dict[str, Any]]]:
    """Rows in, smoothed rows out as soon as they and every row before them are done."""
    new, opts = streaming_smoother(
        robot,
        dt=period,
        observer=how.observer,
        noise_std=how.noise_std,
        accel_psd=how.accel_psd if how.accel_psd != "auto" else None,
        chunk=how.chunk,
        lag=how.lag,
        filter_options=how.options,
        band=how.band or "model",
        configurations=first.q if np.any(np.isfinite(first.q).all(axis=1)) else None,
    )
    rec = _Streamer(robot, how.observer, new, period)
    est = LogEstimator(rec, period=period, check_v=False)
    rows = _Rows(rec, writer)
    for c in chain_chunks(first, chunks):
        t, _, idx = est.feed(c)
        rows.add(t, idx)
        rows.drain(False)
    t, _, idx = est.finish()
    rows.add(t, idx)
    rec.flush()
    rows.drain(True)
    empty = np.empty(0)
    run = LogRun(
        t=empty,
        q=np.empty((0, robot.nq)),
        v=np.empty((0, robot.nv)),
        bad_rows=est.bad_rows,
        warnings=est.warnings,
        rows=est.rows,
        estimated=rows.estimated,
        measured=rows.measured,  # rows estimated with their measurement (not est's: rows fed)
        unit=first.unit,
        noise_std=how.noise_std,
        period=period,
    )
    rho_sum, rho_n = rec.rho
    return run, [
        {**opts, "consistency": rho_sum / rho_n if rho_n else math.nan, "consistency_terms": rho_n}
    ]


def _recorded(
    first: Any,
    chunks: Any,
    robot: Robot,
    writer: EstimateWriter,
    period: float | None,
    how: _Smoothing,
) -> tuple[LogRun, list[dict[str, Any]]]:
    """Every screened sample kept, each stretch smoothed at the end."""
    rec = _Recorder(robot, how.observer)
    est = LogEstimator(rec, period=period, check_v=False)
    parts = [est.feed(c) for c in chain_chunks(first, chunks)]
    parts.append(est.finish())
    t = np.concatenate([p[0] for p in parts])
    idx = np.concatenate([p[2][:, 0] for p in parts])  # sample number, NaN: no estimate
    nv = robot.nv
    q_s = np.full((len(t), robot.nq), np.nan)
    v_s = np.full((len(t), nv), np.nan)
    std_s = np.full((len(t), nv), np.nan)
    samples_q = np.full((rec._n, robot.nq), np.nan)
    samples_v = np.full((rec._n, nv), np.nan)
    samples_std = np.full((rec._n, nv), np.nan)
    stretches: list[dict[str, Any]] = []
    first_k = 0
    for seg in rec.segments:
        k = slice(first_k, first_k + len(seg))
        first_k += len(seg)
        if len(seg) < 2:
            continue  # one sample: no velocity to smooth
        seg_t = np.array([s[0] for s in seg])
        seg_q = np.array([np.full(robot.nq, np.nan) if s[1] is None else s[1] for s in seg])
        seg_tau = np.array([s[2] for s in seg])
        res = smooth_quietly(  # the consistency is reported in the run's warnings (smooth_log)
            robot,
            (seg_t, seg_q, seg_tau),
            observer=how.observer,
            noise_std=how.noise_std,
            accel_psd=how.accel_psd,
            lag=how.lag,
            chunk=how.chunk,
            filter_options=how.options,
            band=how.band,
            find_latency=True,  # as pinobs.smooth: a latency found is said (smooth_log)
        )
        samples_q[k], samples_v[k], samples_std[k] = res.q, res.v, res.v_std
        stretches.append(
            {**res.options, "consistency": res.consistency, "t_span": (seg_t[0], seg_t[-1])}
        )
    ok = np.isfinite(idx)
    rows = idx[ok].astype(int)
    q_s[ok], v_s[ok], std_s[ok] = samples_q[rows], samples_v[rows], samples_std[rows]
    done = np.all(np.isfinite(v_s[ok]), axis=1)  # the rows estimated, among those with a sample
    writer.write(t, q_s, v_s, std_s)
    run = LogRun(
        t=t,
        q=q_s,
        v=v_s,
        bad_rows=est.bad_rows,
        warnings=est.warnings,
        rows=est.rows,
        estimated=int(np.all(np.isfinite(v_s), axis=1).sum()),
        measured=int(np.sum(np.array(rec.had_q, dtype=bool)[rows][done])),
        unit=first.unit,
        noise_std=how.noise_std,
        period=period,
    )
    return run, stretches
