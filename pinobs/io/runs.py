"""Whole runs over a log: read, repair its clock, estimate, write (:func:`process_log`), a
log held in memory (:func:`estimate_log`) and the Python API's DataFrame (:func:`estimate`).

The row rules are :class:`~pinobs.io.stream.LogEstimator`'s (:mod:`pinobs.io.stream`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any
from warnings import warn

import numpy as np

from pinobs.errors import ConsistencyWarning, DimensionError, PinobsWarning, TimestampWarning
from pinobs.io.clock import ClockRepair, repaired_chunks
from pinobs.io.drives import Drives
from pinobs.io.readers import CHUNK_ROWS, Log, LogSource, chain_chunks, iter_log
from pinobs.io.stream import LogEstimator, LogRun, ObserverLike, noise_rows
from pinobs.io.writers import EstimateWriter
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.observers import make_observer, observer_class
from pinobs.observers.base import NOISE_STD_RANGE
from pinobs.observers.base import median_period as _median_period
from pinobs.observers.noise import noise_from_log

__all__ = ["estimate", "estimate_log", "process_log"]


def process_log(
    source: LogSource,
    robot: Robot,
    observer: str | ObserverLike,
    *,
    out: str | Path | None = None,
    force: bool = False,
    keep: bool = True,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    rate: float | None = None,
    noise_std: float | None = None,
    options: Mapping[str, Any] | None = None,
    chunk_rows: int = CHUNK_ROWS,
    progress: Callable[[int, int], None] | None = None,
    clock: str = "auto",
    drives: Drives | None = None,
) -> LogRun:
    """Read, estimate and (optionally) write a log chunk by chunk.

    Args:
        source: log path or DataFrame (:func:`pinobs.io.iter_log`).
        robot: the robot of the log.
        observer: a registry name (built with ``rate``, ``noise_std`` and
            ``options``) or a ready observer-like object.
        out: CSV file for the estimates (written through a temporary file).
        force: overwrite an existing ``out``.
        keep: keep the estimates in the returned run (``False``: memory stays flat).
        columns: as :func:`pinobs.io.iter_log`.
        topic: as :func:`pinobs.io.iter_log`.
        rate: sample rate [Hz] (default: from the log's median interval); a table log
            without a ``t`` column is read as sampled at it (:func:`pinobs.io.iter_log`).
        noise_std: position noise σ [rad or m]; ``None`` with a name: estimated
            from the log's first second (:func:`pinobs.io.estimate_noise_std`) and reported.
        options: further observer options (with a name).
        progress: called as ``progress(rows_done, 0)`` after each chunk.
        clock: the log's clock (:mod:`pinobs.io.clock`): ``"auto"`` (repair the stamps of a
            fixed-rate loop when the motion clearly says so), ``"stamps"`` (as stamped) or
            ``"loop"`` (always the loop's clock).
        drives: motor positions and currents as joint ones, torque columns scaled
            (:class:`pinobs.io.Drives`, :func:`pinobs.io.iter_log`).
    """
    repair, chunks = read_repaired(source, robot, clock, columns, topic, chunk_rows, drives, rate)
    first = next(chunks)
    period = 1.0 / rate if rate else _median_period(first.t)
    ob, noise_std, sigma_joint, warnings = _observer(
        observer, robot, first, period, noise_std, options
    )
    est = LogEstimator(ob, period=period)
    inputs = [] if type(source).__name__ == "DataFrame" else [source]
    writer = None if out is None else EstimateWriter(out, robot, force=force, inputs=inputs)
    parts = _stream(est, chain_chunks(first, chunks), writer, keep, progress)
    unit = first.unit
    run = LogRun(
        t=np.concatenate([p[0] for p in parts]) if parts else np.empty(0),
        q=np.concatenate([p[1] for p in parts]) if parts else np.empty((0, robot.nq)),
        v=np.concatenate([p[2] for p in parts]) if parts else np.empty((0, robot.nv)),
        bad_rows=est.bad_rows,
        warnings=warnings + est.warnings,
        rows=est.rows,
        estimated=est.estimated,
        measured=est.measured,
        unit=unit,
        noise_std=noise_std if isinstance(observer, str) else getattr(ob, "noise_std", None),
        noise_std_per_joint=sigma_joint,
        period=period,
        consistency=_consistency(est.observer),
        clock=repair.report,
    )
    if run.clock is not None and (run.clock.repaired or run.clock.stale):
        run.warnings.insert(0, run.clock.message())
    said = blend_report(observer, est.observer) if isinstance(observer, str) else None
    if said is not None:
        run.warnings.append(said)
    return run


def read_repaired(
    source: LogSource,
    robot: Robot,
    clock: str,
    columns: Mapping[str, str] | None,
    topic: str | None,
    chunk_rows: int,
    drives: Drives | None,
    rate: float | None,
) -> tuple[ClockRepair, Iterator[Log]]:
    """The log's chunks (:func:`pinobs.io.iter_log`, its arguments of the same names) through
    the repair of its clock ``clock`` (:mod:`pinobs.io.clock`), and that repair (its report)."""
    repair = ClockRepair(clock)
    chunks = iter_log(
        source,
        robot,
        columns=columns,
        topic=topic,
        chunk_rows=chunk_rows,
        drives=drives,
        rate=rate,
    )
    return repair, repaired_chunks(chunks, repair)


def _observer(
    observer: str | ObserverLike,
    robot: Robot,
    first: Log,
    period: float | None,
    noise_std: float | None,
    options: Mapping[str, Any] | None,
) -> tuple[ObserverLike, float | None, Vector | None, list[str]]:
    """:func:`process_log`'s observer: a name built (with σ from the log's first chunk
    when ``noise_std`` is ``None``), or ``observer`` itself; with the σ used, the σ per
    joint found and what to say."""
    sigma_joint = None
    warnings: list[str] = []
    if isinstance(observer, str):
        if noise_std is None:
            noise_std, sigma_joint, said = _log_noise(first, robot)
            warnings.append(said)
        ob: ObserverLike = make_observer(
            observer,
            robot,
            rate=(1.0 / period) if period else None,
            noise_std=noise_std,
            **log_options(observer, options),
        )
    else:
        ob = observer
    return ob, noise_std, sigma_joint, warnings


def log_options(name: str, options: Mapping[str, Any] | None) -> dict[str, Any]:
    """The options a log runs the observer ``name`` with: ``options``, and a model-based
    family never behind the model-free ``kf`` unless ``never_behind`` is given
    (:mod:`pinobs.observers.neverbehind`).

    A log is estimated offline, where the blend's cost (its family plus a ``kf`` plus about
    3 ``pin.aba`` per update, ``benchmarks/never_behind.md``) buys what no model can promise
    on a real robot: on the 17 UR10e logs of ``benchmarks/real_logs.md`` ``ekf`` alone on
    the registry model is 1.1e4-4.2e4x ``kf``'s error and blended 1.00x.  On an exact model
    the blend is never behind ``kf`` but can fall behind the family alone
    (``benchmarks/never_behind_exact.md``, UR5 and Panda, seeds 0-9: ``ekf`` 1.00-1.04x at
    1 kHz and 500 Hz with σ = 1e-4 rad, up to 4.1x with σ = 1e-3 and 8.1x at 100 Hz;
    ``riemannian`` up to 10x): ``never_behind=False`` for a model one trusts.  A live loop
    (:func:`pinobs.observers.make_observer`) keeps the family alone unless asked.
    """
    opts = dict(options or {})
    if "never_behind" not in opts and "latency" not in opts and observer_class(name).uses_torque:
        opts["never_behind"] = True  # (the blend takes no latency: given one, the family alone)
    return opts


def blend_report(name: str, observer: ObserverLike) -> str | None:
    """What a log run says of a never-behind blend whose model lost some joints (a final
    weight below one half, or a re-seed): those joints' estimates are ``kf``'s."""
    weights = getattr(observer, "weights", None)
    reseeds = int(getattr(observer, "reseeds", 0))
    if weights is None or not (np.nanmin(weights) < 0.5 or reseeds):
        return None
    lost = [int(j) for j in np.flatnonzero(~(weights >= 0.5))]
    return (
        f"{name} ran never behind kf, blended per joint (never_behind=False runs it alone): "
        f"the model's weight at the end is below 1/2 on {len(lost)} of {weights.size} "
        f"coordinates {lost} (their estimates are kf's); re-seeded {reseeds} times"
    )


def _log_noise(first: Log, robot: Robot) -> tuple[float | None, Vector | None, str]:
    """σ from the log's first chunk (:func:`pinobs.observers.noise.noise_from_log`), per
    joint, and what to say; ``None``: the observer's default (a log too short, or still)."""
    found = noise_from_log(*noise_rows(first), robot)
    if found is None:
        return (
            None,
            None,
            "no noise level given and the log is too short to estimate it: the "
            "observer's default σ is used; pass noise_std (--noise)",
        )
    if found[0] < NOISE_STD_RANGE[0]:  # a still robot, positions quantised
        # (a static UR10e pose printed to 4 decimals gave 3.7e-17, refused by make_observer)
        return (
            None,
            None,
            f"the noise level estimated from the log is {found[0]:.3g} (the positions do "
            "not move in its first second): the observer's default σ is used; pass "
            "noise_std (--noise)",
        )
    return found


def _stream(
    est: LogEstimator,
    chunks: Iterator[Log],
    writer: EstimateWriter | None,
    keep: bool,
    progress: Callable[[int, int], None] | None,
) -> list[tuple[Vector, Vector, Vector]]:
    """Every chunk through ``est``, written as it is done (the writer aborted on any
    failure); the parts kept when ``keep``."""
    parts: list[tuple[Vector, Vector, Vector]] = []
    try:
        for chunk in chunks:
            part = est.feed(chunk)
            if writer is not None:
                writer.write(*part)
            if keep:
                parts.append(part)
            if progress is not None:
                progress(est.rows, 0)
        part = est.finish()
        if writer is not None:
            writer.write(*part)
            writer.close()
        if keep:
            parts.append(part)
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    return parts


def _consistency(observer: Any) -> Any:
    check = getattr(observer, "consistency", None)
    return check() if callable(check) else None


def estimate_log(observer: ObserverLike, log: Log, *, period: float | None = None) -> LogRun:
    """Run ``observer`` over a log held in memory (rules: module docstring)."""
    est = LogEstimator(observer, period=period)
    a = est.feed_log(log)
    b = est.finish()
    return LogRun(
        t=np.concatenate([a[0], b[0]]),
        q=np.concatenate([a[1], b[1]]),
        v=np.concatenate([a[2], b[2]]),
        bad_rows=est.bad_rows,
        warnings=est.warnings,
        rows=est.rows,
        estimated=est.estimated,
        measured=est.measured,
        unit=log.unit,
        noise_std=getattr(observer, "noise_std", None),
        period=est.period,
        consistency=_consistency(observer),
    )


def estimate(
    observer: str | ObserverLike,
    data: LogSource,
    *,
    robot: Robot | str | None = None,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    rate: float | None = None,
    noise_std: float | None = None,
    options: Mapping[str, Any] | None = None,
    clock: str = "auto",
    drives: Drives | None = None,
) -> Any:
    """Estimates over a log as a pandas ``DataFrame``: ``t, q0.., v0..``, one row per log row.

    Examples:
        >>> import pinobs
        >>> df = pinobs.estimate("kf", "examples/ur5_log.csv", robot="ur5")  # doctest: +SKIP

    Args:
        observer: a registry name or an observer (then ``robot`` defaults to its robot).
        data: a DataFrame or a log path (any format of :func:`pinobs.io.iter_log`).
        robot: a :class:`~pinobs.Robot` or a registry name; required with a name.
        columns: as :func:`process_log`.
        topic: as :func:`process_log`.
        rate: as :func:`process_log`.
        noise_std: as :func:`process_log`.
        options: as :func:`process_log`.
        clock: as :func:`process_log`.
        drives: as :func:`process_log`.

    Returns:
        The DataFrame (``t`` the row's time: repaired where the log's clock was,
        :mod:`pinobs.io.clock`); ``df.attrs`` holds ``bad_rows``, ``warnings`` (what
        the CLI prints: the clock's repair, the noise level found, the observer's
        consistency and rejected outliers), ``summary``, ``noise_std``, ``clock`` (the
        :class:`~pinobs.io.clock.ClockReport`) and ``consistency``.  Each warning is
        also issued as a Python warning (:class:`~pinobs.errors.ConsistencyWarning` for
        the model's consistency, :class:`~pinobs.errors.TimestampWarning` for the clock,
        :class:`~pinobs.errors.PinobsWarning` otherwise).
    """
    from pinobs.model import load

    if isinstance(robot, str):
        robot = load(robot)
    if robot is None:
        if isinstance(observer, str):
            raise DimensionError(
                f"estimate({observer!r}, ...) needs robot=... (a Robot or a registry name)"
            )
        robot = observer.robot
    run = process_log(
        data,
        robot,
        observer,
        columns=columns,
        topic=topic,
        rate=rate,
        noise_std=noise_std,
        options=options,
        clock=clock,
        drives=drives,
    )
    said = _said(run, observer if isinstance(observer, str) else _name_of(observer))
    df = _frame(run, robot, [text for text, _ in said])
    for text, kind in said:
        warn(text, kind, stacklevel=2)
    return df


def _frame(run: LogRun, robot: Robot, warnings: list[str]) -> Any:
    """:func:`estimate`'s DataFrame of ``run`` (its ``attrs`` with ``warnings``)."""
    import pandas as pd

    df = pd.DataFrame(
        np.column_stack([run.t, run.q, run.v]),
        columns=["t", *(f"q{i}" for i in range(robot.nq)), *(f"v{i}" for i in range(robot.nv))],
    )
    df.attrs.update(
        bad_rows=run.bad_rows,
        warnings=warnings,
        summary=run.summary(),
        noise_std=run.noise_std,
        clock=run.clock,
        consistency=run.consistency,
    )
    return df


def _name_of(observer: ObserverLike) -> str:
    """An observer's name for messages."""
    return str(getattr(observer, "name", type(observer).__name__))


def _said(run: LogRun, name: str) -> list[tuple[str, type[Warning]]]:
    """The run's warnings as the CLI prints them, each with its warning class."""
    out: list[tuple[str, type[Warning]]] = []
    for w in run.warnings:
        kind = TimestampWarning if w.startswith("log clock") else PinobsWarning
        out.append((w, kind))
    if run.consistency is not None and hasattr(run.consistency, "messages"):
        for line in run.consistency.messages(name):
            kind = ConsistencyWarning if line.startswith("warning:") else PinobsWarning
            out.append((line.split(": ", 1)[1] if line.startswith("warning: ") else line, kind))
    return out
