"""A reader per format behind a suffix table; :func:`iter_log`, :func:`read_log`, :func:`find_logs`."""

from __future__ import annotations

import glob
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pinobs.errors import DimensionError, ModelFileError, OptionError
from pinobs.io.drives import Drives
from pinobs.io.readers.bags import BAG_FILES, bag_chunks, is_bag
from pinobs.io.readers.csv_log import csv_chunks
from pinobs.io.readers.legged import legged_notes
from pinobs.io.readers.log import CHUNK_ROWS, Log, LogSource, concat_logs
from pinobs.io.readers.npz import npz_log
from pinobs.io.readers.parquet import parquet_chunks
from pinobs.io.readers.table import frame_log
from pinobs.model import Robot
from pinobs.observers.checks import positive


@dataclass(frozen=True)
class _Options:
    columns: Mapping[str, str] | None
    topic: str | None
    chunk_rows: int
    drives: Drives | None
    rate: float | None = None  # [Hz] a table without a t column is sampled at


@dataclass(frozen=True)
class Reader:
    """One format's reader: its chunks, and the options it takes.

    Attributes:
        name: what the format is called in messages (``"log"``, ``"bag"``).
        chunks: ``(path, robot, options) -> Log`` chunks; at least one, maybe empty.
        columns: whether ``columns=...`` (renaming table columns) applies.
        topic: whether ``topic=...`` (a bag's JointState topic) applies.
        motor_columns: whether drives read motor columns (else ``torque_scale`` only).
        folder: whether the log may be a folder (a rosbag2).
    """

    name: str
    chunks: Callable[[Path, Robot, _Options], Iterator[Log]]
    columns: bool
    topic: bool
    motor_columns: bool
    folder: bool = False


def _or_empty(chunks: Iterator[Log], robot: Robot) -> Iterator[Log]:
    """``chunks``, or one empty chunk when there are none (a header-only file)."""
    first = True
    for chunk in chunks:
        first = False
        yield chunk
    if first:
        yield empty_log(robot)


def _csv(path: Path, robot: Robot, o: _Options) -> Iterator[Log]:
    return _or_empty(csv_chunks(path, robot, o.columns, o.chunk_rows, o.drives, o.rate), robot)


def _parquet(path: Path, robot: Robot, o: _Options) -> Iterator[Log]:
    return _or_empty(parquet_chunks(path, robot, o.columns, o.chunk_rows, o.drives, o.rate), robot)


def _npz(path: Path, robot: Robot, o: _Options) -> Iterator[Log]:
    log = npz_log(path, robot)
    for s in range(0, max(len(log), 1), o.chunk_rows):
        sl = slice(s, s + o.chunk_rows)
        tau = None if log.tau is None else log.tau[sl]
        yield _scaled(
            Log(log.t[sl], log.q[sl], tau, lines=np.arange(log.t.size)[sl], unit="row"), o.drives
        )


def _bag(path: Path, robot: Robot, o: _Options) -> Iterator[Log]:
    for chunk in bag_chunks(path, robot, o.topic, o.chunk_rows):
        yield _scaled(chunk, o.drives)


CSV_READER = Reader("log", _csv, columns=True, topic=False, motor_columns=True)
PARQUET_READER = Reader("log", _parquet, columns=True, topic=False, motor_columns=True)
NPZ_READER = Reader("log", _npz, columns=False, topic=False, motor_columns=False)
BAG_READER = Reader("bag", _bag, columns=False, topic=True, motor_columns=False, folder=True)

#: The reader of each file suffix (lower case); any other suffix is read as CSV.
READERS: dict[str, Reader] = {
    **dict.fromkeys((".csv", ".txt", ".tsv", ".tab"), CSV_READER),
    **dict.fromkeys((".parquet", ".pq"), PARQUET_READER),
    **dict.fromkeys((".npz", ".npy"), NPZ_READER),  # (.npy: refused naming what to do)
    **dict.fromkeys(sorted(BAG_FILES), BAG_READER),
}
#: Logs known by what they are rather than by their suffix (before the suffix table).
DETECTORS: tuple[tuple[Callable[[Path], bool], Reader], ...] = ((is_bag, BAG_READER),)


def reader_for(path: Path) -> Reader:
    """The reader of ``path``: a detector's, else its suffix's, else CSV's."""
    for detect, reader in DETECTORS:
        if detect(path):
            return reader
    return READERS.get(path.suffix.lower(), CSV_READER)


def iter_log(
    source: LogSource,
    robot: Robot,
    *,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    chunk_rows: int = CHUNK_ROWS,
    drives: Drives | None = None,
    rate: float | None = None,
) -> Iterator[Log]:
    """Read a log chunk by chunk (formats and columns: module docstring).

    Args:
        source: a file or bag path, or a pandas ``DataFrame``.
        robot: the robot the log is of (its joints name the columns).
        columns: other column names -> ``t`` / ``q.<joint>`` / ``q3`` / ``tau.<joint>`` ...
        topic: the ``sensor_msgs/JointState`` topic of a bag.
        chunk_rows: rows per chunk (> 0).
        drives: gear ratios, motor constants, coupled joints (:class:`~pinobs.io.Drives`):
            ``qm.<joint>`` motor positions and ``i.<joint>`` currents read as joint
            positions and torques, ``tau.<joint>`` scaled (CSV, TSV, Parquet, DataFrame;
            NPZ and bags: ``torque_scale`` only).
        rate: sample rate [Hz] of a table log (CSV, TSV, Parquet, DataFrame) without a ``t``
            column: its row ``k`` (from 0, across chunks; a row with an unreadable cell
            counts, a blank line does not) at ``t = k / rate``, said in :attr:`Log.notes`.
            A log with a ``t`` column, an NPZ or a bag keeps its own times.

    Yields:
        :class:`Log` chunks, in order; the first one is yielded even when empty.

    Raises:
        ModelFileError: the file is missing (a ``FileNotFoundError``).
        LogFormatError: the file cannot be parsed; the message names the line.
        DimensionError: the columns do not match the robot.
        OptionError: drives the log does not use, or motor columns without their drives.
        GainError: ``rate`` is not a finite number > 0.
    """
    if chunk_rows < 1:
        raise DimensionError(f"chunk_rows={chunk_rows} must be >= 1")
    rate = positive("rate", rate, allow_none=True)
    if type(source).__name__ == "DataFrame":
        _refuse_ignored("DataFrame", columns=None, topic=topic)
        yield from _said(iter([frame_log(source, robot, columns, drives, rate)]), robot)
        return
    path = Path(source)
    if not path.exists():
        raise ModelFileError(f"log {str(path)!r} does not exist")
    reader = reader_for(path)
    what = f"{reader.name} {str(path)!r}"
    # (a sweep found --map ignored for bags and NPZ, --topic for the others, silently)
    _refuse_ignored(
        what,
        columns=None if reader.columns else columns,
        topic=None if reader.topic else topic,
    )
    if not reader.motor_columns:
        _check_array_drives(f"log {str(path)!r}", drives, robot)
    if path.is_dir() and not reader.folder:
        raise ModelFileError(f"log {str(path)!r} is a folder but not a rosbag2 (no metadata.yaml)")
    yield from _said(
        reader.chunks(path, robot, _Options(columns, topic, chunk_rows, drives, rate)), robot
    )


def _said(chunks: Iterator[Log], robot: Robot) -> Iterator[Log]:
    """``chunks``, the first with what its legged columns say of the log (units, no base)."""
    first = next(chunks, None)
    if first is None:
        return
    notes = legged_notes(robot, first.q, first.imu_gyro, first.imu_acc)
    yield replace(first, notes=first.notes + notes) if notes else first
    yield from chunks


def _refuse_ignored(what: str, *, columns: Mapping[str, str] | None, topic: str | None) -> None:
    """Refuse an option ``what`` would ignore: ``columns`` (a bag, an NPZ), ``topic`` (not a bag)."""
    if columns:
        raise OptionError(
            f"{what}: columns=... (--map) renames the columns of a CSV, Parquet or DataFrame "
            f"log; this one has none to rename ({dict(columns)})"
        )
    if topic is not None:
        raise OptionError(
            f"{what}: topic=... (--topic {topic}) chooses the JointState topic of a ROS bag; "
            "this log is not a bag"
        )


def _check_array_drives(what: str, drives: Drives | None, robot: Robot) -> None:
    """NPZ arrays and bag messages have no motor columns: only ``torque_scale`` applies."""
    if drives is None:
        return
    drives.check(robot)
    other = [
        name
        for name in ("gear_ratio", "transmission", "motor_constant", "position_offset")
        if getattr(drives, name) is not None
    ]
    if other:
        raise OptionError(
            f"{what}: drives {other} read motor columns (qm.<joint>, i.<joint>) of a CSV, "
            "Parquet or DataFrame log; an NPZ or a bag has q and tau only (torque_scale "
            "scales its tau): convert the motor values first (pinobs.io.Drives."
            "joint_positions / joint_torques)"
        )


def _scaled(log: Log, drives: Drives | None) -> Log:
    """``log`` with its torques times ``drives.torque_scale`` ((4) of :mod:`pinobs.io.drives`)."""
    if drives is None or drives.torque_scale is None:
        return log
    if log.tau is None and len(log):
        raise OptionError("drives given but not used: torque_scale (the log has no torques)")
    tau = None if log.tau is None else drives.scaled_torques(log.tau)
    return replace(log, tau=tau)


def empty_log(robot: Robot) -> Log:
    return Log(np.empty(0), np.empty((0, robot.nq)), None, unit="row")


def read_log(
    source: LogSource,
    robot: Robot,
    *,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    drives: Drives | None = None,
    rate: float | None = None,
) -> Log:
    """Read a whole log into memory (:func:`iter_log` streams it).

    Args and raises as :func:`iter_log`.  Returns one :class:`Log` with every
    row, in order, and every cell that could not be read in ``problems``.
    """
    chunks = list(iter_log(source, robot, columns=columns, topic=topic, drives=drives, rate=rate))
    return chunks[0] if len(chunks) == 1 else concat_logs(chunks, nv=robot.nv)


def find_logs(spec: str | Path) -> list[Path]:
    """The logs a path, folder or glob pattern names, sorted.

    - a pattern (``*``, ``?``, ``[``; ``**`` descends into folders): every
      match that is a log (a file of a format read here, or a rosbag2 folder);
    - a rosbag2 folder (with ``metadata.yaml``) or a file: itself;
    - any other folder: the logs directly in it (files with a suffix read here,
      rosbag2 folders), not its subfolders.

    Raises:
        ModelFileError: nothing there, or no log among what is there (the
            message lists the suffixes read).
    """
    text = str(spec)
    path = Path(text)

    def is_log(p: Path) -> bool:
        return is_bag(p) or (p.is_file() and p.suffix.lower() in READERS)

    if any(c in text for c in "*?["):
        found = [Path(p) for p in glob.glob(text, recursive=True)]
        logs = sorted(p for p in found if is_log(p))
    elif is_bag(path) or path.is_file():
        return [path]
    elif path.is_dir():
        logs = sorted(p for p in path.iterdir() if is_log(p))
    else:
        raise ModelFileError(f"log {text!r} does not exist")
    if not logs:
        suffixes = ", ".join(sorted(s for s in READERS if s != ".npy"))  # (.npy: refused)
        raise ModelFileError(
            f"no log in {text!r}: give a file, a folder or a pattern matching files "
            f"ending in {suffixes} or rosbag2 folders"
        )
    return logs
