"""Readers: a recorded log, from any of its formats, as chunks of ``t, q, tau`` rows.

Formats (chosen from the source):

- CSV (``.csv``, ``.txt``) and TSV (``.tsv``, ``.tab``): a header row, then one
  row per sample.  UTF-8 (a byte-order mark is accepted).  The columns are
  found by name (any order, extra columns ignored):

  - ``t``: time [s];
  - positional ``q0 .. q{nq-1}`` and ``tau0 .. tau{nv-1}`` (Pinocchio's order,
    quaternions ``x, y, z, w``), or named ``q.<joint>`` / ``tau.<joint>``
    (``q.<joint>.<k>`` / ``tau.<joint>.<k>`` for a joint with several
    coordinates); a continuous joint (``cos, sin`` in Pinocchio) may also be
    given as one angle column ``q.<joint>`` [rad];
  - ``tick`` (optional): the logger's sample counter (ROS ``header.seq``, a
    robot's cycle count), used by the clock repair (:mod:`pinobs.io.clock`);
  - ``columns`` maps other column names to these (``{"pos_1": "q.elbow"}``,
    ``{"seq": "tick"}``).
  - with ``drives`` (:class:`~pinobs.io.Drives`): ``qm.<joint>`` motor positions and
    ``i.<joint>`` motor currents, read through gear ratios, a transmission matrix of
    coupled joints and motor constants as the joints' ``q`` and ``tau``
    (:mod:`pinobs.io.drives`); ``tau.<joint>`` scaled by ``torque_scale``.

  The torque columns are optional (every torque then reads as zero, and a
  model-based observer is warned).
- Parquet (``.parquet``, ``.pq``): the same columns.
- NPZ (``.npz``): arrays ``t`` (N,), ``q`` (N, nq), optionally ``tau`` (N, nv).
  A result saved by ``pinobs run --save`` (:meth:`pinobs.Result.save`) is read
  as the log its sensor recorded: its measurements ``q_meas`` (a NaN row: a
  dropped sample) are the log's ``q``, not its simulated truth ``q``.
- A pandas ``DataFrame``: the same columns as a CSV.
- ROS bags (a rosbag2 directory with sqlite3 or MCAP storage, a ``.mcap`` or
  ``.db3`` file, a ROS 1 ``.bag``), read with the ``rosbags`` library:
  ``sensor_msgs/JointState`` messages on ``topic`` (default: the only
  JointState topic), joints matched by name in any order, ``position`` as q,
  ``effort`` as τ, the header stamp as t (the bag's receive time when the first
  message's stamp is unset, 0: said in :attr:`Log.problems`); a ROS 1 header's ``seq`` as
  the sample counter (:attr:`Log.tick`, used by the clock repair).

A clean CSV/TSV is read by Arrow's streaming CSV reader straight into NumPy
(fast, and without importing pandas); from the first row it cannot parse as
numbers on, a careful reader takes the rest record by record and says what is
wrong with each row.  Both read standard CSV double-quoting, as the header is
read (``"moving, fast"``, ``""`` for a quote, a quoted field over several lines:
its row named by its first line); a quote that makes no such field (a stray one)
is a character of its cell, which then cannot be read.  A short row is said as
such (``row has 5 of 13 cells``); a long one is an error naming its line.

Nothing is dropped while reading: a cell that cannot be read becomes NaN and
is reported in :attr:`Log.problems` with its line (CSV) or row / message
number (the others); a file that cannot be parsed at all raises
:class:`~pinobs.errors.LogFormatError` naming the line.  CSV, TSV, Parquet and
bags are read in chunks (:func:`iter_log`), so memory does not grow with the
log; NPZ files are loaded whole.
"""

from __future__ import annotations

import csv
import glob
import io
import zipfile
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import DimensionError, LogFormatError, ModelFileError, OptionError
from pinobs.io.drives import Drives
from pinobs.model import Robot
from pinobs.model.robot import Vector

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "CHUNK_ROWS",
    "Log",
    "LogSource",
    "chain_chunks",
    "concat_logs",
    "find_logs",
    "iter_log",
    "read_log",
]

#: Rows per chunk when streaming a log.
CHUNK_ROWS = 10_000

LogSource = Any  # str | Path | pandas.DataFrame (pandas is optional)

_CSV = {".csv", ".txt", ".tsv", ".tab"}
_PARQUET = {".parquet", ".pq"}
_BAG_FILES = {".bag", ".mcap", ".db3"}
_JOINT_STATE = ("sensor_msgs/msg/JointState", "sensor_msgs/JointState")
_INSTALL_IO = 'pip install "pinobs[io]"'


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

    def __post_init__(self) -> None:
        if self.lines is None:
            object.__setattr__(self, "lines", np.arange(self.t.size))

    def __len__(self) -> int:
        return int(self.t.size)


# ------------------------------------------------------------------ columns
@dataclass(frozen=True)
class _Layout:
    """Where the robot's ``t``, ``q`` and ``tau`` are among a table's columns."""

    t: str
    q: tuple[tuple[str, ...], ...]  # per q block: its columns (one angle column for a circle)
    q_angle: tuple[bool, ...]  # per q block: given as an angle
    q_slices: tuple[slice, ...]
    tau: tuple[str, ...] | None
    tick: str | None = None  # the log's own sample counter (pinobs.io.clock)
    drives: Drives | None = None  # how motor-side columns map to the joints (pinobs.io.drives)
    motor: tuple[str, ...] = ()  # qm.<joint> per joint: positions from the motors (drives)
    current: tuple[str, ...] = ()  # i.<joint> per joint: torques from the currents (drives)

    @property
    def used(self) -> list[str]:
        cols = [self.t, *(c for block in self.q for c in block), *self.motor, *self.current]
        return cols + list(self.tau or ()) + ([self.tick] if self.tick else [])


def _blocks(robot: Robot) -> list[tuple[str, str, int, int, int, int]]:
    """``(name, kind, idx_q, nq, idx_v, nv)`` of every joint."""
    return [(b.name, b.kind, b.idx_q, b.nq, b.idx_v, b.nv) for b in robot.joints]


def _motor_layout(
    header: Sequence[str], robot: Robot, where: str, drives: Drives | None
) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The ``qm.<joint>`` and ``i.<joint>`` columns (:mod:`pinobs.io.drives`) read through
    ``drives``: each all or none; a column ``drives`` cannot read, or drives the log does not
    use, refused naming them."""
    names = set(header)
    found = {}
    for kind, what in (("qm", "motor position"), ("i", "motor current")):
        want = [f"{kind}.{n}" for n in robot.joint_names]
        have = [c for c in want if c in names]
        if have and drives is not None and len(have) < len(want):
            raise DimensionError(
                f"{where}: has {what} columns {have} but lacks "
                f"{[c for c in want if c not in names]}: give one per joint"
            )
        found[kind] = tuple(have)
    if drives is None:
        return (), ()
    drives.check(robot)
    motor, current = found["qm"], found["i"]
    q_too = [f"q.{n}" for n in robot.joint_names if f"q.{n}" in names] if motor else []
    tau_too = [f"tau.{n}" for n in robot.joint_names if f"tau.{n}" in names] if current else []
    if q_too or tau_too:
        raise DimensionError(
            f"{where}: has both {list(q_too or tau_too)} and "
            f"{list(motor if q_too else current)}: the joint's own and the motor's; keep one "
            "(drop or rename the other)"
        )
    unused = []
    if drives.matrix is not None and not (motor or current):
        unused.append("gear_ratio or transmission (no qm.<joint> or i.<joint> columns)")
    if drives.motor_constant is not None and not current:
        unused.append("motor_constant (no i.<joint> current columns)")
    if drives.position_offset is not None and not motor:
        unused.append("position_offset (no qm.<joint> motor position columns)")
    if drives.torque_scale is not None and (
        current or not any(c.startswith("tau") for c in header)
    ):
        unused.append(
            "torque_scale (it scales tau.<joint> columns; "
            + ("currents take motor_constant)" if current else "the log has none)")
        )
    if unused:
        raise OptionError(f"{where}: drives given but not used: {'; '.join(unused)}")
    if current:
        drives.joint_torques(np.zeros((0, robot.nv)))  # refuses a missing constant or ratio
    if motor:
        drives.joint_positions(np.zeros((0, robot.nv)))
    return motor, current


def _layout(
    header: Sequence[str], robot: Robot, where: str, drives: Drives | None = None
) -> _Layout:
    """Match column names to the robot (module docstring); raise naming what is missing."""
    motor, current = _motor_layout(header, robot, where, drives)
    names = set(header)
    counts = Counter(header)

    def one(candidates: list[str], what: str) -> str | None:
        found = [c for c in candidates if c in names]
        if len(found) > 1:
            raise DimensionError(f"{where}: columns {found} all give {what}; keep one")
        if found and counts[found[0]] > 1:  # (the first was used, silently)
            raise DimensionError(
                f"{where}: {counts[found[0]]} columns are named {found[0]!r} (after columns=..., "
                "if given); keep one"
            )
        return found[0] if found else None

    t = one(["t"], "t")
    q_cols: list[tuple[str, ...]] = []
    q_angle: list[bool] = []
    q_slices: list[slice] = []
    missing: list[str] = []
    absent: list[str] = []  # joints with a q column missing
    for name, kind, iq, nq, _, _ in _blocks(robot):
        q_slices.append(slice(iq, iq + nq))
        if motor:  # every q from the motors (drives)
            q_cols.append(())
            q_angle.append(kind == "circle")
            continue
        cols: list[str] = []
        for k in range(nq):
            named = f"q.{name}" if nq == 1 else f"q.{name}.{k}"
            cols.append(one([f"q{iq + k}", named], f"q{iq + k}") or "")
        if all(cols):
            q_cols.append(tuple(cols))
            q_angle.append(False)
        elif kind == "circle" and not any(cols) and f"q.{name}" in names:
            q_cols.append((f"q.{name}",))
            q_angle.append(True)
        else:
            missing += [
                f"q{iq + k} or q.{name}" + ("" if nq == 1 else f".{k}")
                for k, c in enumerate(cols)
                if not c
            ]
            absent.append(name)
            q_cols.append(tuple(cols))
            q_angle.append(False)
    tau_cols: list[str | None] = []
    for name, _, _, _, iv, nv in _blocks(robot):
        for k in range(nv):
            named = f"tau.{name}" if nv == 1 else f"tau.{name}.{k}"
            tau_cols.append(None if current else one([f"tau{iv + k}", named], f"tau{iv + k}"))
    beyond = [
        c
        for c in header
        for kind, n in (("q", robot.nq), ("tau", robot.nv))
        if c.startswith(kind) and c[len(kind) :].isdigit() and int(c[len(kind) :]) >= n
    ]
    if beyond:  # another robot's log (or this one loaded without its root joint)
        raise DimensionError(
            f"{where}: columns {beyond} are beyond robot {robot.name!r}'s nq = {robot.nq}, "
            f"nv = {robot.nv}: the log of another robot, or a floating base loaded fixed "
            "(root_joint=...)? Drop or rename them (columns=...) if they are not its own"
        )
    motor_only = [c for c in header if c.startswith("qm.")] if missing and not motor else []
    if t is None or missing:
        lock = _lock_hint(absent) if absent and len(absent) < len(robot.joints) else ""
        if motor_only:
            lock += (
                f". Columns {motor_only} are motor positions: read them through the drives "
                "(drives=pinobs.io.Drives(gear_ratio=...), --gear-ratio or --transmission)"
            )
        raise DimensionError(
            f"{where}: columns {list(header)} lack {(['t'] if t is None else []) + missing}; "
            f"robot {robot.name!r} needs t, then q0..q{robot.nq - 1} (nq = {robot.nq}) or "
            f"q.<joint> for joints {list(robot.joint_names)}, and optionally "
            f"tau0..tau{robot.nv - 1} or tau.<joint> (or map other names with columns=...)" + lock
        )
    tau: tuple[str, ...] | None = None
    if any(c is not None for c in tau_cols):
        absent = [f"tau{i}" for i, c in enumerate(tau_cols) if c is None]
        if absent:
            raise DimensionError(
                f"{where}: has some torque columns but lacks {absent} (nv = {robot.nv})"
            )
        tau = tuple(c for c in tau_cols if c is not None)
    currents = [c for c in header if c.startswith("i.")]
    if tau is None and not current and currents:
        raise OptionError(
            f"{where}: columns {currents} are motor currents [A] and the log has no torque "
            "columns: give their scale, drives=pinobs.io.Drives(motor_constant=..., "
            "gear_ratio=...) (--motor-constant, --gear-ratio), to read them as torques "
            "τ = N·k·i, or drop them"
        )
    tick = one(["tick"], "the sample counter")
    return _Layout(
        t,
        tuple(q_cols),
        tuple(q_angle),
        tuple(q_slices),
        tau,
        tick,
        drives=drives,
        motor=motor,
        current=current,
    )


def _lock_hint(absent: Sequence[str]) -> str:
    """What to do when a log records some of the robot's joints but not ``absent``."""
    flags = " ".join(f"--lock {n}" for n in absent)
    return (
        f". If the log does not record joints {list(absent)} (a gripper's fingers), lock them "
        f"at a fixed value: pinobs.load(..., lock={list(absent)}) (or lock={{name: value}}), "
        f"or {flags} (the pinobs command)"
    )


def _clean_header(header: Sequence[Any], columns: Mapping[str, str] | None) -> list[str]:
    out = [str(h).strip().strip('"').strip("'").strip() for h in header]
    if columns:
        unknown = sorted(set(columns) - set(out))
        if unknown:
            raise DimensionError(
                f"columns mapping names {unknown}, which the log does not have; it has {out}"
            )
        out = [columns.get(h, h) for h in out]
    return out


#: Cells that read as a missing value, not as an unreadable one (pandas' ``na_values``).
_NA_TEXT = [
    *("", "nan", "-nan", "na", "n/a", "null", "none", "<na>", "#n/a", "#na"),
    *("#n/a n/a", "-1.#ind", "1.#ind", "-1.#qnan", "1.#qnan"),
]


def _numeric(frame: pd.DataFrame, lines: Any, problems: list[tuple[int, str]]) -> None:
    """Convert every column to float in place; unreadable cells -> NaN, reported once per row."""
    import pandas as pd

    bad: dict[int, list[str]] = {}
    for col in frame.columns:
        s = frame[col]
        if s.dtype.kind in "fiu":
            continue
        if s.dtype.kind == "b":
            frame[col] = s.astype(float)
            continue
        text = s.astype("string").str.strip().str.replace(r'^"(.*)"$', r"\1", regex=True)
        num = pd.to_numeric(text, errors="coerce")
        unreadable = num.isna() & text.notna() & ~text.str.lower().isin(_NA_TEXT)
        for i in np.flatnonzero(unreadable.to_numpy()):
            bad.setdefault(int(lines[i]), []).append(f"{col!r} unreadable: {s.iloc[i]!r}")
        frame[col] = num.astype(float)
    for line in sorted(bad):
        problems.append((line, "; ".join(bad[line])))


def _time_in_seconds(frame: pd.DataFrame, t: str, problems: list[tuple[int, str]]) -> None:
    """A datetime or timedelta ``t`` column as seconds, in place, said on row 0 in ``problems``.

    (A sweep found every row of such a log reported as "'t' unreadable".)
    """
    import pandas as pd

    s = frame[t]
    kind = s.dtype.kind
    if kind == "M":
        tz = getattr(s.dtype, "tz", None)
        frame[t] = (s - pd.Timestamp(0, tz=tz)).dt.total_seconds()
        said = "t is a date-time column: read as seconds since 1970-01-01 UTC"
    elif kind == "m":
        frame[t] = s.dt.total_seconds()
        said = "t is a duration column: read as seconds"
    else:
        return
    problems.append((0, said))


def _from_frame(
    frame: pd.DataFrame,
    layout: _Layout,
    robot: Robot,
    lines: Any,
    unit: str,
    problems: list[tuple[int, str]],
) -> Log:
    """A :class:`Log` chunk from a table whose columns follow ``layout``."""
    frame = frame[layout.used].copy()
    _numeric(frame, lines, problems)
    arrays = {c: frame[c].to_numpy(dtype=float) for c in layout.used}
    return _from_arrays(arrays, len(frame), layout, robot, lines, unit, problems)


def _from_arrays(
    arrays: Mapping[str, Vector],
    n: int,
    layout: _Layout,
    robot: Robot,
    lines: Any,
    unit: str,
    problems: list[tuple[int, str]],
) -> Log:
    """A :class:`Log` chunk from float columns named as ``layout`` says."""
    q = np.empty((n, robot.nq))
    drives = layout.drives
    from_motor = None
    if layout.motor and drives is not None:  # (1) of pinobs.io.drives, one angle per joint
        from_motor = drives.joint_positions(_stack(arrays, layout.motor, n))
    for k, (cols, angle, sl) in enumerate(
        zip(layout.q, layout.q_angle, layout.q_slices, strict=True)
    ):
        if from_motor is not None:
            a = from_motor[:, k]
            q[:, sl] = np.column_stack([np.cos(a), np.sin(a)]) if angle else a[:, None]
        elif angle:
            a = arrays[cols[0]]
            q[:, sl] = np.column_stack([np.cos(a), np.sin(a)])
        else:
            q[:, sl] = np.column_stack([arrays[c] for c in cols])
    tau = None
    if layout.current and drives is not None:  # (2), (3) of pinobs.io.drives
        tau = drives.joint_torques(_stack(arrays, layout.current, n))
    elif layout.tau is not None:
        tau = np.column_stack([arrays[c] for c in layout.tau])
        if drives is not None:  # (4)
            tau = drives.scaled_torques(tau)
    return Log(
        t=np.asarray(arrays[layout.t], dtype=float),
        q=q,
        tau=tau,
        problems=tuple(problems),
        lines=lines,
        unit=unit,
        tick=None if layout.tick is None else np.asarray(arrays[layout.tick], dtype=float),
    )


def _stack(arrays: Mapping[str, Vector], cols: Sequence[str], n: int) -> Vector:
    return np.column_stack([arrays[c] for c in cols]).reshape(n, len(cols))


def _require_pandas() -> Any:
    try:
        import pandas as pd
    except ImportError as exc:  # pragma: no cover - pandas is in the io and test extras
        raise ModuleNotFoundError(f"reading CSV/Parquet logs needs pandas: {_INSTALL_IO}") from exc
    return pd


# ---------------------------------------------------------------------- CSV
#: Magic bytes of compressed files, their kind and a command that decompresses them.
_COMPRESSED = (
    (b"\x1f\x8b", "gzip", "gunzip -k"),
    (b"BZh", "bzip2", "bunzip2 -k"),
    (b"\xfd7zXZ\x00", "xz", "unxz -k"),
    (b"\x28\xb5\x2f\xfd", "zstd", "unzstd"),
)


def _zip_hint(path: Path) -> str:
    """What a zip archive read as text is: an .npz misnamed, or a zipped log to unzip."""
    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
    except (zipfile.BadZipFile, OSError):
        names = []
    if names and all(n.endswith(".npy") for n in names):
        return " (it is an .npz archive of arrays: name it .npz)"
    return f" (it is a zip archive of {names}: unzip it first, e.g. `unzip {path}`)"


def _undecodable_line(path: Path) -> tuple[int, str]:
    """The first line of ``path`` that is not UTF-8, and a hint about what the file is."""
    with path.open("rb") as fh:
        head = fh.read(8)
    hint = ""
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        hint = " (it starts with a UTF-16 byte-order mark: re-save it as UTF-8)"
    elif head.startswith(b"PK"):
        hint = _zip_hint(path)
    elif head.startswith((b"ARROW1", b"FEA1")):  # (a sweep found it "not UTF-8", no more)
        hint = (
            " (it is a Feather / Arrow IPC file, which pinobs does not read: convert it to "
            "Parquet, e.g. pandas.read_feather(path).to_parquet('log.parquet'))"
        )
    elif head.startswith(b"\x93NUMPY"):
        hint = " (it is a .npy array: save the log with np.savez(path, t=..., q=..., tau=...))"
    else:  # compressed text: a sweep found a .csv.gz refused with no word of why
        for magic, kind, tool in _COMPRESSED:
            if head.startswith(magic):
                hint = f" (it is {kind}-compressed: decompress it first, e.g. `{tool} {path}`)"
    with path.open("rb") as fh:
        for number, raw in enumerate(fh, start=1):
            if number == 1 and raw.startswith(b"\xef\xbb\xbf"):
                raw = raw[3:]
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError:
                return number, hint
    return 0, hint


class _Fallback(Exception):
    """The fast reader met a row it cannot parse: the careful one takes over from ``rows``."""

    def __init__(self, rows: int) -> None:
        super().__init__(rows)
        self.rows = rows


def _all_nan_row(cols: list[Vector]) -> bool:
    """Whether some row is NaN in every column (the first column's NaN rows checked in the
    others: no copy of a clean batch)."""
    rows = np.flatnonzero(np.isnan(cols[0]))
    for c in cols[1:]:
        if not rows.size:
            break
        rows = rows[np.isnan(c[rows])]
    return bool(rows.size)


def _float_column(col: Any) -> Vector:
    """An Arrow float64 array as a NumPy array, nulls as NaN.

    Read from its buffers: Arrow's own ``to_numpy`` imports pandas (~60 MB).
    """
    validity, data = col.buffers()
    x = np.frombuffer(data, dtype=np.float64, count=len(col), offset=col.offset * 8).copy()
    if col.null_count:
        bits = np.unpackbits(np.frombuffer(validity, dtype=np.uint8), bitorder="little")
        x[bits[col.offset : col.offset + len(col)] == 0] = np.nan
    return x


def _open_arrow_csv(
    pa: Any, pa_csv: Any, path: Path, names: list[str], used: list[str], sep: str
) -> Any:
    return pa_csv.open_csv(
        path,
        read_options=pa_csv.ReadOptions(
            column_names=names,
            skip_rows=1,
            block_size=1 << 18,  # Arrow's RSS grows ~20x the block: 256 kB costs ~15 MB
            use_threads=False,
        ),
        parse_options=pa_csv.ParseOptions(
            delimiter=sep, quote_char=False, ignore_empty_lines=False
        ),
        convert_options=pa_csv.ConvertOptions(
            column_types={c: pa.float64() for c in used}, include_columns=used
        ),
        memory_pool=pa.system_memory_pool(),
    )


def _arrow_csv_chunks(
    path: Path, header: list[str], layout: _Layout, robot: Robot, sep: str, chunk_rows: int
) -> Iterator[Log]:
    """Clean CSV through Arrow's streaming reader (typed float columns, no pandas).

    Any row it cannot parse as numbers (a stray quote, a bad cell, a blank line,
    a wrong cell count) raises :class:`_Fallback` with the rows already yielded,
    and :func:`_csv_chunks` re-reads from there with :func:`_careful_chunks`, which
    reports the cell or names the line.  (Quoting is off here: a quoted field with a
    separator or a line break makes a wrong cell count, so the careful reader, which
    reads quoting and counts lines, takes over.)
    """
    try:
        import pyarrow as pa
        import pyarrow.csv as pa_csv
    except ImportError:  # pragma: no cover - pyarrow is in the io and test extras
        raise _Fallback(0) from None
    used = list(dict.fromkeys(layout.used))
    names = [f"{c}\x00{i}" if c not in used else c for i, c in enumerate(header)]
    try:
        reader = _open_arrow_csv(pa, pa_csv, path, names, used, sep)
    except (pa.ArrowException, UnicodeDecodeError):
        raise _Fallback(0) from None
    start = 0  # rows yielded
    pending: list[dict[str, Vector]] = []
    rows = 0

    def flush() -> Log:
        nonlocal start, pending, rows
        arrays = {c: np.concatenate([p[c] for p in pending]) for c in used}
        lines = np.arange(start, start + rows) + 2  # line 1 is the header
        log = _from_arrays(arrays, rows, layout, robot, lines, "line", [])
        start, pending, rows = start + rows, [], 0
        return log

    try:
        while True:
            try:
                batch = reader.read_next_batch()
            except StopIteration:
                break
            except (pa.ArrowException, UnicodeDecodeError):
                raise _Fallback(start) from None
            off = 0
            while off < batch.num_rows:
                take = min(chunk_rows - rows, batch.num_rows - off)
                part = batch.slice(off, take)
                cols = {c: _float_column(part.column(c)) for c in used}
                if _all_nan_row(list(cols.values())):
                    # a blank line (Arrow: a row of nulls): pandas's, which are not rows (a
                    # sweep found them rows here, NaN and unreported, and dropped after a
                    # fallback: one log read two ways)
                    raise _Fallback(start)
                pending.append(cols)
                rows, off = rows + take, off + take
                if rows == chunk_rows:
                    yield flush()
        if rows:
            yield flush()
    finally:
        reader.close()


def _csv_chunks(
    path: Path,
    robot: Robot,
    columns: Mapping[str, str] | None,
    chunk_rows: int,
    drives: Drives | None = None,
) -> Iterator[Log]:
    line, hint = _undecodable_line(path) if _has_binary_head(path) else (0, "")
    if line:
        raise LogFormatError(f"log {str(path)!r}: line {line} is not UTF-8 text{hint}")
    sep = "\t" if path.suffix.lower() in (".tsv", ".tab") else ","
    with path.open(encoding="utf-8-sig", errors="strict") as fh:
        try:
            first = fh.readline()
        except UnicodeDecodeError:
            line, hint = _undecodable_line(path)
            raise LogFormatError(
                f"log {str(path)!r}: line {line or 1} is not UTF-8 text{hint}"
            ) from None
    if not first.strip():
        raise LogFormatError(f"log {str(path)!r} is empty or its line 1 (the header) is blank")
    if sep == "," and "\t" in first and "," not in first:
        sep = "\t"
    elif sep == "\t" and "," in first and "\t" not in first:
        sep = ","
    header = _clean_header(next(csv.reader([first], delimiter=sep)), columns)
    layout = _layout(header, robot, f"log {str(path)!r}", drives)
    if not _has_data_after_header(path):
        return
    start = 0
    try:
        yield from _arrow_csv_chunks(path, header, layout, robot, sep, chunk_rows)
        return
    except _Fallback as fb:
        start = fb.rows
    yield from _careful_chunks(path, header, layout, robot, sep, start, chunk_rows)


#: Physical lines a quoted field may span before its opening quote counts as a stray one.
_MAX_FIELD_LINES = 100


def _careful_records(
    path: Path, sep: str, ncols: int, skip: int
) -> Iterator[tuple[int, list[str], str | None]]:
    """``(line, cells, problem)`` of every record after line ``1 + skip``, blank lines left out.

    Standard CSV quoting (``"a, b"``, ``""`` for a quote, a quoted field over several
    lines: its record named by its first line), as the header is read; a quote that does
    not make such a field (a stray one) is a character of its cell, which then cannot be
    read: that row alone is lost (a sweep found a quoted comma fail the whole log and a
    quoted line break shift the cells of an extra row).  A short row is padded with empty
    cells and said; a long one raises :class:`LogFormatError`.
    """
    with path.open(encoding="utf-8-sig", errors="strict", newline=None) as fh:
        for _ in range(1 + skip):
            fh.readline()
        number = 1 + skip
        pending: list[str] = []  # lines read ahead while looking for a field's closing quote
        while True:
            line = pending.pop(0) if pending else fh.readline()
            if not line:
                return
            number += 1
            at = number  # a record is named by its first line
            if not line.strip():
                continue
            if '"' not in line:
                cells = line.rstrip("\n").split(sep)
            else:
                text, extra = line, 0
                while text.count('"') % 2 and extra < _MAX_FIELD_LINES:
                    more = pending[extra] if extra < len(pending) else fh.readline()
                    if not more:
                        break
                    if extra >= len(pending):
                        pending.append(more)
                    text, extra = text + more, extra + 1
                try:
                    parsed = next(csv.reader([text], delimiter=sep, skipinitialspace=True), [])
                except csv.Error:  # (a line break outside quotes: lines joined past a stray one)
                    parsed = []
                if text.count('"') % 2 == 0 and len(parsed) == ncols:
                    cells = parsed
                    del pending[:extra]
                    number += extra
                else:  # a stray quote: a character of its cell, this line alone
                    cells = line.rstrip("\n").split(sep)
            if len(cells) > ncols:
                raise LogFormatError(
                    f"log {str(path)!r}: line {at} has {len(cells)} cells, the header {ncols}"
                )
            said = None
            if len(cells) < ncols:
                said = f"row has {len(cells)} of {ncols} cells"
                cells = cells + [""] * (ncols - len(cells))
            yield at, cells, said


def _careful_chunks(
    path: Path,
    header: list[str],
    layout: _Layout,
    robot: Robot,
    sep: str,
    start: int,
    chunk_rows: int,
) -> Iterator[Log]:
    """The rows after the first ``start`` (one line each), read record by record (
    :func:`_careful_records`), every cell that cannot be read reported with its line."""
    pd = _require_pandas()
    used = list(dict.fromkeys(layout.used))
    where = [header.index(c) for c in used]
    rows: list[list[str]] = []
    lines: list[int] = []
    problems: list[tuple[int, str]] = []

    def flush() -> Log:
        frame = pd.DataFrame(rows, columns=used, dtype=object)
        log = _from_frame(frame, layout, robot, np.array(lines), "line", problems)
        rows.clear()
        lines.clear()
        return log

    try:
        for number, cells, said in _careful_records(path, sep, len(header), start):
            rows.append([cells[i] for i in where])
            lines.append(number)
            if said is not None:
                problems.append((number, said))
            if len(rows) == chunk_rows:
                yield flush()
                problems = []
        if rows:
            yield flush()
    except UnicodeDecodeError:
        line, hint = _undecodable_line(path)
        raise LogFormatError(f"log {str(path)!r}: line {line} is not UTF-8 text{hint}") from None


def _has_data_after_header(path: Path) -> bool:
    """Whether anything but white space follows line 1, whatever the line ends (``\n``,
    ``\r\n`` or a lone ``\r``: a sweep found every row of a CR-only file lost)."""
    header = True
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 16), b""):
            if header:
                ends = [i for i in (block.find(b"\n"), block.find(b"\r")) if i >= 0]
                if not ends:
                    continue
                block, header = block[min(ends) + 1 :], False
            if block.strip():
                return True
    return False


def _has_binary_head(path: Path) -> bool:
    with path.open("rb") as fh:
        head = fh.read(4096)
    if head.startswith(b"\xef\xbb\xbf"):
        head = head[3:]
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        return exc.start < len(head) - 4  # not just a character cut by the 4096-byte window
    return b"\x00" in head


# ------------------------------------------------------------------ Parquet
def _parquet_chunks(
    path: Path,
    robot: Robot,
    columns: Mapping[str, str] | None,
    chunk_rows: int,
    drives: Drives | None = None,
) -> Iterator[Log]:
    _require_pandas()
    try:
        import pyarrow.parquet as pq
        from pyarrow import ArrowException
    except ImportError as exc:  # pragma: no cover - pyarrow is in the io and test extras
        raise ModuleNotFoundError(f"reading Parquet logs needs pyarrow: {_INSTALL_IO}") from exc
    try:
        pf = pq.ParquetFile(path)
    except (ArrowException, OSError) as exc:
        raise LogFormatError(f"log {str(path)!r} is not a readable Parquet file: {exc}") from None
    raw = list(pf.schema_arrow.names)
    header = _clean_header(raw, columns)
    layout = _layout(header, robot, f"log {str(path)!r}", drives)
    back = dict(zip(header, raw, strict=True))
    named = dict(zip(raw, header, strict=True))
    start = 0
    try:
        for batch in pf.iter_batches(batch_size=chunk_rows, columns=[back[c] for c in layout.used]):
            # the columns as stored: pandas' metadata would make a DataFrame index of a
            # column written as one (a sweep found `t` so lost: KeyError)
            frame = batch.to_pandas(ignore_metadata=True)
            # by the names as cleaned and mapped (a sweep found ' t' or '"t"' a KeyError)
            frame.columns = [named[c] for c in batch.schema.names]
            lines = np.arange(start, start + len(frame))
            problems: list[tuple[int, str]] = []
            if len(frame):
                _time_in_seconds(frame, layout.t, problems if start == 0 else [])
            start += len(frame)
            yield _from_frame(frame, layout, robot, lines, "row", problems)
    except (ArrowException, OSError) as exc:
        raise LogFormatError(f"log {str(path)!r}: unreadable after row {start}: {exc}") from None


# ---------------------------------------------------------------------- NPZ
def _npz_log(path: Path, robot: Robot) -> Log:
    try:
        with path.open("rb") as fh:
            loaded = np.load(io.BytesIO(fh.read()), allow_pickle=False)
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as exc:
        raise LogFormatError(
            f"log {str(path)!r} is not a readable .npz archive ({type(exc).__name__}: {exc}); "
            "a truncated copy? write one with np.savez(path, t=..., q=..., tau=...)"
        ) from None
    if isinstance(loaded, np.ndarray):
        raise LogFormatError(
            f"log {str(path)!r} holds one .npy array of shape {loaded.shape}, not an .npz "
            "archive with arrays t, q (and tau): write one with np.savez(path, t=..., q=..., tau=...)"
        )
    with loaded as z:
        keys = list(z.keys())
        if "t" not in keys or "q" not in keys:
            raise LogFormatError(
                f"log {str(path)!r} has arrays {keys}; a log needs t, q (and optionally tau)"
            )
        try:
            t = np.asarray(z["t"], dtype=float)
            # a saved simulation result: what its sensor measured, not the truth
            q_name = "q_meas" if "q_meas" in keys else "q"
            q = np.asarray(z[q_name], dtype=float)
            tau = np.asarray(z["tau"], dtype=float) if "tau" in keys else None
        except (zipfile.BadZipFile, EOFError, OSError, ValueError) as exc:
            raise LogFormatError(
                f"log {str(path)!r}: an array cannot be read ({type(exc).__name__}: {exc}); "
                "a truncated copy?"
            ) from None
    if (
        t.ndim != 1
        or q.shape != (t.size, robot.nq)
        or (tau is not None and tau.shape != (t.size, robot.nv))
    ):
        raise DimensionError(
            f"log {str(path)!r}: t {t.shape}, {q_name} {q.shape}, "
            f"tau {None if tau is None else tau.shape}; "
            f"robot {robot.name!r} needs {q_name} of shape (N, {robot.nq}) and tau of shape "
            f"(N, {robot.nv})"
            + (" (q_meas is read as the log's q when present)" if q_name != "q" else "")
            + (
                _lock_hint([b.name for b in robot.joints if b.idx_q + b.nq > q.shape[1]])
                if q.ndim == 2 and 0 < q.shape[1] < robot.nq
                else ""
            )
        )
    return Log(t=t, q=q, tau=tau, unit="row")


# ---------------------------------------------------------------- ROS bags
def _is_bag(path: Path) -> bool:
    return (path.is_dir() and (path / "metadata.yaml").is_file()) or (
        path.suffix.lower() in _BAG_FILES
    )


def _bag_chunks(path: Path, robot: Robot, topic: str | None, chunk_rows: int) -> Iterator[Log]:
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ModuleNotFoundError(f"reading ROS bags needs rosbags: {_INSTALL_IO}") from exc
    for name, kind, *_ in _blocks(robot):
        if kind not in ("vector", "circle"):
            raise DimensionError(
                f"joint {name!r} of {robot.name!r} is a {kind} joint, which "
                "sensor_msgs/JointState cannot carry; load the robot with a fixed root"
            )
    index = {b.name: b for b in robot.joints}
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, OSError) as exc:
        raise LogFormatError(f"bag {str(path)!r} cannot be opened: {exc}") from None
    try:
        states = [c for c in reader.connections if c.msgtype in _JOINT_STATE]
        topics = sorted({c.topic for c in states})
        if not topics:  # (a sweep found "0 topics []", nothing on what the bag holds)
            present = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
            raise DimensionError(
                f"bag {str(path)!r} has no sensor_msgs/JointState topic; its topics: {present}"
            )
        if topic is None:
            if len(topics) != 1:
                raise DimensionError(
                    f"bag {str(path)!r} has {len(topics)} sensor_msgs/JointState topics "
                    f"{topics}; choose one with topic=... (--topic)"
                )
            topic = topics[0]
        if topic not in topics:
            raise DimensionError(
                f"bag {str(path)!r} has no sensor_msgs/JointState topic {topic!r}; "
                f"its JointState topics: {topics}"
            )
        conns = [c for c in states if c.topic == topic]
        buf_t: list[float] = []
        buf_q: list[Vector] = []
        buf_tau: list[Vector] = []
        buf_n: list[int] = []  # message numbers (messages of another publisher are skipped)
        buf_seq: list[float] | None = []  # ROS 1 header.seq: the sample counter (pinobs.io.clock)
        problems: list[tuple[int, str]] = []
        start = 0
        skipped: list[int] = []
        others: set[str] = set()
        any_tau = False
        receive_time = False  # the header stamps are t, unless the publisher left them unset
        for number, (conn, received, raw) in enumerate(reader.messages(connections=conns)):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            names = list(msg.name)
            pos = np.asarray(msg.position, dtype=float)
            where = {n: i for i, n in enumerate(names)}
            lacking = [n for n in index if n not in where or where[n] >= pos.size]
            if len(lacking) == len(index):
                # another publisher on the topic (a gripper's JointState): not a row of this
                # robot (a sweep found it refused at message 0, or every one a dropped row)
                skipped.append(number)
                others.update(names)
                continue
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            notes = []
            if not buf_n and start == 0 and stamp == 0.0:
                # a sweep found such a bag read as one row at t = 0 and the rest repeats of it
                receive_time = True
                notes.append(
                    "header stamps unset (0): the bag's receive times are used as t for "
                    "every message"
                )
            elif stamp == 0.0 and not receive_time:
                notes.append("header stamp unset (0)")
            buf_t.append(1e-9 * received if receive_time else stamp)
            buf_n.append(number)
            seq = getattr(msg.header, "seq", None)  # ROS 2 headers have none
            if seq is None:
                buf_seq = None
            elif buf_seq is not None:
                buf_seq.append(float(seq))
            eff = np.asarray(msg.effort, dtype=float)
            q = np.full(robot.nq, np.nan)
            tau = np.full(robot.nv, np.nan)
            if lacking:
                notes.append(f"no position for joints {lacking}")
            for jname, b in index.items():
                i = where.get(jname)
                if i is None:
                    continue
                if i < pos.size:
                    if b.kind == "circle":
                        q[b.idx_q : b.idx_q + 2] = np.cos(pos[i]), np.sin(pos[i])
                    else:
                        q[b.idx_q] = pos[i]
                if i < eff.size:
                    tau[b.idx_v] = eff[i]
            any_tau = any_tau or eff.size > 0
            if eff.size and np.isnan(tau).any():
                notes.append("effort lacks some joints")
            if notes:
                problems.append((number, "; ".join(notes)))
            buf_q.append(q)
            buf_tau.append(tau)
            if len(buf_t) == chunk_rows:
                yield _bag_log(
                    buf_t, buf_q, buf_tau, buf_n, problems, any_tau, robot.nq, robot.nv, (), buf_seq
                )
                start += len(buf_t)
                buf_t, buf_q, buf_tau, buf_n, problems = [], [], [], [], []
                buf_seq = None if buf_seq is None else []
        if skipped and not start and not buf_t:
            raise DimensionError(
                f"bag {str(path)!r}, topic {topic!r}: the JointState joints {sorted(others)} "
                f"include none of the joints of robot {robot.name!r}, {list(index)}"
            )
        said: tuple[str, ...] = ()
        if skipped:
            said = (
                f"{len(skipped)} messages on {topic!r} (the first: message {skipped[0]}) carry "
                f"none of the joints of robot {robot.name!r} (they name {sorted(others)}: another "
                "publisher on the topic?): skipped, not rows",
            )
        if buf_t or start == 0 or said:
            yield _bag_log(
                buf_t, buf_q, buf_tau, buf_n, problems, any_tau, robot.nq, robot.nv, said, buf_seq
            )
    finally:
        reader.close()


def _bag_log(
    t: list[float],
    q: list[Vector],
    tau: list[Vector],
    numbers: list[int],
    problems: list[tuple[int, str]],
    any_tau: bool,
    nq: int,
    nv: int,
    notes: tuple[str, ...] = (),
    seq: list[float] | None = None,
) -> Log:
    n = len(t)
    return Log(
        t=np.array(t, dtype=float),
        q=np.array(q, dtype=float).reshape(n, nq),
        tau=np.array(tau, dtype=float).reshape(n, nv) if any_tau else None,
        problems=tuple(problems),
        lines=np.array(numbers, dtype=int),
        unit="message",
        notes=notes,
        tick=None if seq is None or len(seq) != n else np.array(seq, dtype=float),
    )


# ------------------------------------------------------------------- public
def chain_chunks(first: Log, rest: Iterator[Log]) -> Iterator[Log]:
    """``first``, then the chunks of ``rest``: an :func:`iter_log` whose first chunk was
    taken to look at (its period, its σ) and must still be run."""
    yield first
    yield from rest


def iter_log(
    source: LogSource,
    robot: Robot,
    *,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    chunk_rows: int = CHUNK_ROWS,
    drives: Drives | None = None,
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

    Yields:
        :class:`Log` chunks, in order; the first one is yielded even when empty.

    Raises:
        ModelFileError: the file is missing (a ``FileNotFoundError``).
        LogFormatError: the file cannot be parsed; the message names the line.
        DimensionError: the columns do not match the robot.
        OptionError: drives the log does not use, or motor columns without their drives.
    """
    if chunk_rows < 1:
        raise DimensionError(f"chunk_rows={chunk_rows} must be >= 1")
    if type(source).__name__ == "DataFrame":
        _refuse_ignored("DataFrame", columns=None, topic=topic)
        yield _frame_log(source, robot, columns, drives)
        return
    path = Path(source)
    if not path.exists():
        raise ModelFileError(f"log {str(path)!r} does not exist")
    suffix = path.suffix.lower()
    # (a sweep found --map ignored for bags and NPZ, --topic for the others, silently)
    if _is_bag(path):
        _refuse_ignored(f"bag {str(path)!r}", columns=columns, topic=None)
    else:
        npz = suffix in (".npz", ".npy")
        _refuse_ignored(f"log {str(path)!r}", columns=columns if npz else None, topic=topic)
    if _is_bag(path) or suffix in (".npz", ".npy"):
        _check_array_drives(f"log {str(path)!r}", drives, robot)
    if _is_bag(path):
        for chunk in _bag_chunks(path, robot, topic, chunk_rows):
            yield _scaled(chunk, drives)
    elif path.is_dir():
        raise ModelFileError(f"log {str(path)!r} is a folder but not a rosbag2 (no metadata.yaml)")
    elif suffix in (".npz", ".npy"):
        log = _npz_log(path, robot)
        for s in range(0, max(len(log), 1), chunk_rows):
            sl = slice(s, s + chunk_rows)
            tau = None if log.tau is None else log.tau[sl]
            yield _scaled(
                Log(log.t[sl], log.q[sl], tau, lines=np.arange(log.t.size)[sl], unit="row"),
                drives,
            )
    elif suffix in _PARQUET:
        first = True
        for chunk in _parquet_chunks(path, robot, columns, chunk_rows, drives):
            first = False
            yield chunk
        if first:
            yield _empty(robot)
    else:
        first = True
        for chunk in _csv_chunks(path, robot, columns, chunk_rows, drives):
            first = False
            yield chunk
        if first:
            yield _empty(robot)


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


def _empty(robot: Robot) -> Log:
    return Log(np.empty(0), np.empty((0, robot.nq)), None, unit="row")


def _frame_log(
    frame: Any, robot: Robot, columns: Mapping[str, str] | None, drives: Drives | None = None
) -> Log:
    header = _clean_header([str(c) for c in frame.columns], None)
    frame = frame.set_axis(header, axis=1)
    if columns:
        header = _clean_header(header, columns)
        frame = frame.set_axis(header, axis=1)
    layout = _layout(header, robot, "DataFrame", drives)
    frame = frame[layout.used].copy()
    problems: list[tuple[int, str]] = []
    if len(frame):
        _time_in_seconds(frame, layout.t, problems)
    return _from_frame(frame, layout, robot, np.arange(len(frame)), "row", problems)


def read_log(
    source: LogSource,
    robot: Robot,
    *,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    drives: Drives | None = None,
) -> Log:
    """Read a whole log into memory (:func:`iter_log` streams it).

    Args and raises as :func:`iter_log`.  Returns one :class:`Log` with every
    row, in order, and every cell that could not be read in ``problems``.
    """
    chunks = list(iter_log(source, robot, columns=columns, topic=topic, drives=drives))
    return chunks[0] if len(chunks) == 1 else concat_logs(chunks, nv=robot.nv)


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
    )


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
        return _is_bag(p) or (
            p.is_file() and p.suffix.lower() in _CSV | _PARQUET | {".npz", ".npy"}
        )

    if any(c in text for c in "*?["):
        found = [Path(p) for p in glob.glob(text, recursive=True)]
        logs = sorted(p for p in found if is_log(p))
    elif _is_bag(path) or path.is_file():
        return [path]
    elif path.is_dir():
        logs = sorted(p for p in path.iterdir() if is_log(p))
    else:
        raise ModelFileError(f"log {text!r} does not exist")
    if not logs:
        suffixes = ", ".join(sorted(_CSV | _PARQUET | _BAG_FILES | {".npz"}))
        raise ModelFileError(
            f"no log in {text!r}: give a file, a folder or a pattern matching files "
            f"ending in {suffixes} or rosbag2 folders"
        )
    return logs
