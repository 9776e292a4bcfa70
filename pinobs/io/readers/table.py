"""Table columns (CSV cells, Parquet or DataFrame columns) to :class:`Log` arrays."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from pinobs.errors import DimensionError
from pinobs.io.drives import Drives
from pinobs.io.readers.layout import Layout, clean_header, table_layout
from pinobs.io.readers.legged import legged_arrays
from pinobs.io.readers.log import Log
from pinobs.model import Robot
from pinobs.model.robot import Vector

if TYPE_CHECKING:
    import pandas as pd

INSTALL_IO = 'pip install "pinobs[io]"'
#: Cells that read as a missing value, not as an unreadable one (pandas' ``na_values``).
NA_TEXT = [
    *("", "nan", "-nan", "na", "n/a", "null", "none", "<na>", "#n/a", "#na"),
    *("#n/a n/a", "-1.#ind", "1.#ind", "-1.#qnan", "1.#qnan"),
]


def to_numeric(frame: pd.DataFrame, lines: Any, problems: list[tuple[int, str]]) -> None:
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
        unreadable = num.isna() & text.notna() & ~text.str.lower().isin(NA_TEXT)
        for i in np.flatnonzero(unreadable.to_numpy()):
            bad.setdefault(int(lines[i]), []).append(f"{col!r} unreadable: {s.iloc[i]!r}")
        frame[col] = num.astype(float)
    for line in sorted(bad):
        problems.append((line, "; ".join(bad[line])))


def time_in_seconds(frame: pd.DataFrame, t: str, problems: list[tuple[int, str]]) -> None:
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


def from_frame(
    frame: pd.DataFrame,
    layout: Layout,
    robot: Robot,
    lines: Any,
    unit: str,
    problems: list[tuple[int, str]],
    *,
    row0: int,
) -> Log:
    """A :class:`Log` chunk from a table whose columns follow ``layout``; ``row0``: the log's
    rows before this chunk (:func:`from_arrays`)."""
    frame = frame[layout.used].copy()
    to_numeric(frame, lines, problems)
    arrays = {c: frame[c].to_numpy(dtype=float) for c in layout.used}
    return from_arrays(arrays, len(frame), layout, robot, lines, unit, problems, row0=row0)


def from_arrays(
    arrays: Mapping[str, Vector],
    n: int,
    layout: Layout,
    robot: Robot,
    lines: Any,
    unit: str,
    problems: list[tuple[int, str]],
    *,
    row0: int,
) -> Log:
    """A :class:`Log` chunk from float columns named as ``layout`` says.

    ``row0``: the log's rows before this chunk (a row with an unreadable cell counts, a blank
    line does not), which time its rows when the log has no ``t`` column: row ``k`` of the log
    at ``t = k / layout.rate`` (said in the first chunk's notes).
    """
    q = np.empty((n, robot.nq))
    drives = layout.drives
    from_motor = None
    if layout.motor and drives is not None:  # (1) of pinobs.io.drives, one angle per joint
        from_motor = drives.joint_positions(stack_columns(arrays, layout.motor, n))
    for k, (cols, angle, sl) in enumerate(
        zip(layout.q, layout.q_angle, layout.q_slices, strict=True)
    ):
        if from_motor is not None:
            a = from_motor[:, k]
            q[:, sl] = np.column_stack([np.cos(a), np.sin(a)]) if angle else a[:, None]
        elif not cols:  # a legged robot's base pose, not in the log (readers.legged)
            q[:, sl] = np.nan
        elif angle:
            a = arrays[cols[0]]
            q[:, sl] = np.column_stack([np.cos(a), np.sin(a)])
        else:
            q[:, sl] = np.column_stack([arrays[c] for c in cols])
    tau = None
    if layout.current and drives is not None:  # (2), (3) of pinobs.io.drives
        tau = drives.joint_torques(stack_columns(arrays, layout.current, n))
    elif layout.tau is not None:
        tau = np.column_stack([arrays[c] for c in layout.tau])
        if drives is not None:  # (4)
            tau = drives.scaled_torques(tau)
    return Log(
        t=_times(arrays, n, layout, row0),
        q=q,
        tau=tau,
        problems=tuple(problems),
        lines=lines,
        unit=unit,
        notes=(sampled_note(layout.rate),) if layout.rate is not None and row0 == 0 and n else (),
        tick=None if layout.tick is None else np.asarray(arrays[layout.tick], dtype=float),
        **vars(legged_arrays(arrays, n, layout.legged, lines, unit)),
    )


def _times(arrays: Mapping[str, Vector], n: int, layout: Layout, row0: int) -> Vector:
    """The chunk's ``t`` column, or with none its rows' ``k / rate`` [s] (``k`` from ``row0``)."""
    if layout.t is not None:
        return np.asarray(arrays[layout.t], dtype=float)
    if layout.rate is None:  # pragma: no cover - table_layout refuses it
        raise DimensionError("a table without a t column needs its sample rate")
    # t_k = k / R, each the float nearest k/R (k·(1/R) would carry 1/R's rounding error)
    return np.arange(row0, row0 + n) / layout.rate


def sampled_note(rate: float) -> str:
    """What :attr:`Log.notes` says of a table without a ``t`` column read at ``rate`` [Hz]."""
    return f"no t column: rows taken as sampled at {rate:g} Hz, t = k/{rate:g}"


def stack_columns(arrays: Mapping[str, Vector], cols: Sequence[str], n: int) -> Vector:
    return np.column_stack([arrays[c] for c in cols]).reshape(n, len(cols))


def require_pandas() -> Any:
    try:
        import pandas as pd
    except ImportError as exc:  # pragma: no cover - pandas is in the io and test extras
        raise ModuleNotFoundError(f"reading CSV/Parquet logs needs pandas: {INSTALL_IO}") from exc
    return pd


def frame_log(
    frame: Any,
    robot: Robot,
    columns: Mapping[str, str] | None,
    drives: Drives | None = None,
    rate: float | None = None,
) -> Log:
    header = clean_header([str(c) for c in frame.columns], None)
    frame = frame.set_axis(header, axis=1)
    if columns:
        header = clean_header(header, columns)
        frame = frame.set_axis(header, axis=1)
    layout = table_layout(header, robot, "DataFrame", drives, rate)
    frame = frame[layout.used].copy()
    problems: list[tuple[int, str]] = []
    if len(frame) and layout.t is not None:
        time_in_seconds(frame, layout.t, problems)
    return from_frame(frame, layout, robot, np.arange(len(frame)), "row", problems, row0=0)
