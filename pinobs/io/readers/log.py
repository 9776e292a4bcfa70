"""The :class:`Log` a reader returns, and chunks of one joined."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.model.robot import Vector

#: Rows per chunk when streaming a log.
CHUNK_ROWS = 10_000

LogSource = Any  # str | Path | pandas.DataFrame (pandas is optional)


@dataclass(frozen=True)
class Log:
    """A recorded log, or one chunk of it: raw rows (NaN where a cell was unreadable).

    Attributes:
        t: times [s], shape ``(N,)``.
        q: configurations, shape ``(N, nq)``.
        tau: torques [N·m or N], shape ``(N, nv)``, or ``None`` when the log has none.
        problems: ``(position, reason)`` for cells that could not be read.
        lines: where each row is in the source, shape ``(N,)`` (what it counts: ``unit``).
        unit: ``"line"`` (file line of a CSV, from 1), ``"row"`` (NPZ, Parquet,
            DataFrame, from 0) or ``"message"`` (a bag, from 0).
        notes: what the reader says of the log as a whole, not of a row (bag messages
            skipped); :class:`~pinobs.io.LogEstimator` adds them to its warnings.
        tick: the log's own sample counter per row (a ``tick`` column), or ``None``.
        stale: rows that repeat the previous sample (set by the clock repair,
            :mod:`pinobs.io.clock`): no measurement, the estimate at that sample's time.
        drops: per row, the loop samples missing just before it (the clock repair).
        imu_gyro: trunk IMU angular velocity [rad/s], shape ``(N, 3)``, or ``None``
            (``imu.gyro.x|y|z`` columns, :mod:`pinobs.io.readers.legged`).
        imu_acc: trunk IMU specific force [m/s²], shape ``(N, 3)``, or ``None``.
        foot_force: normal force per foot [N], shape ``(N, len(feet))``, or ``None``.
        contact: contact flag per foot (0, 1), shape ``(N, len(feet))``, or ``None``.
        feet: the foot frames of ``foot_force`` and ``contact`` columns, in order.
    """

    t: Vector
    q: Vector
    tau: Vector | None
    problems: tuple[tuple[int, str], ...] = ()
    lines: Any = None
    unit: str = "row"
    notes: tuple[str, ...] = ()
    tick: Vector | None = None
    stale: NDArray[np.bool_] | None = None
    drops: NDArray[np.int64] | None = None
    imu_gyro: Vector | None = None
    imu_acc: Vector | None = None
    foot_force: Vector | None = None
    contact: Vector | None = None
    feet: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.lines is None:
            object.__setattr__(self, "lines", np.arange(self.t.size))

    def __len__(self) -> int:
        return int(self.t.size)


def chain_chunks(first: Log, rest: Iterator[Log]) -> Iterator[Log]:
    """``first``, then the chunks of ``rest``: an :func:`iter_log` whose first chunk was
    taken to look at (its period, its σ) and must still be run."""
    yield first
    yield from rest


def _joined(parts: Sequence[Any], sizes: Sequence[int], fill: Any, width: int | None) -> Any:
    """``parts`` concatenated, a ``None`` part as ``fill`` rows; ``None`` if all are."""
    if all(x is None for x in parts):
        return None
    shape: tuple[int, ...]
    full = []
    for x, size in zip(parts, sizes, strict=True):
        shape = (size,) if width is None else (size, width)
        full.append(x if x is not None else np.full(shape, fill))
    return np.concatenate(full)


def concat_logs(chunks: Sequence[Log], *, nv: int | None = None) -> Log:
    """Chunks of one log as one :class:`Log`, in order (a missing torque block: NaN rows)."""
    if len(chunks) == 1:
        return chunks[0]
    sizes = [len(c) for c in chunks]
    if nv is None:
        nv = next((c.tau.shape[1] for c in chunks if c.tau is not None), 0)
    feet = next((c.feet for c in chunks if c.feet), ())
    return Log(
        t=np.concatenate([c.t for c in chunks]),
        q=np.concatenate([c.q for c in chunks]),
        tau=_joined([c.tau for c in chunks], sizes, np.nan, nv),
        problems=tuple(p for c in chunks for p in c.problems),
        lines=np.concatenate([c.lines for c in chunks]),
        unit=next((c.unit for c in chunks if len(c)), chunks[0].unit),
        notes=tuple(n for c in chunks for n in c.notes),
        tick=_joined([c.tick for c in chunks], sizes, np.nan, None),
        stale=_joined([c.stale for c in chunks], sizes, False, None),
        drops=_joined([c.drops for c in chunks], sizes, 0, None),
        imu_gyro=_joined([c.imu_gyro for c in chunks], sizes, np.nan, 3),
        imu_acc=_joined([c.imu_acc for c in chunks], sizes, np.nan, 3),
        foot_force=_joined([c.foot_force for c in chunks], sizes, np.nan, len(feet)),
        contact=_joined([c.contact for c in chunks], sizes, np.nan, len(feet)),
        feet=feet,
    )


def slice_log(log: Log, a: int, b: int) -> Log:
    """Rows ``a:b`` of ``log`` (its problems on those rows; its notes not: they are of the
    log as a whole, said once)."""
    lines = log.lines[a:b]
    keep = set(int(x) for x in lines)

    def cut(x: Any) -> Any:
        return None if x is None else x[a:b]

    return Log(
        t=log.t[a:b],
        q=log.q[a:b],
        tau=cut(log.tau),
        problems=tuple(p for p in log.problems if p[0] in keep),
        lines=lines,
        unit=log.unit,
        tick=cut(log.tick),
        stale=cut(log.stale),
        drops=cut(log.drops),
        imu_gyro=cut(log.imu_gyro),
        imu_acc=cut(log.imu_acc),
        foot_force=cut(log.foot_force),
        contact=cut(log.contact),
        feet=log.feet,
    )
