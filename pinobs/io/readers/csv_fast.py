"""Clean CSV through Arrow's streaming reader, straight into NumPy (no pandas)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.io.readers.layout import Layout
from pinobs.io.readers.log import Log
from pinobs.io.readers.table import from_arrays
from pinobs.model import Robot
from pinobs.model.robot import Vector


class Fallback(Exception):
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
    pa: Any, pa_csv: Any, path: Path, names: list[str], used: list[str], sep: str, skip: int
) -> Any:
    return pa_csv.open_csv(
        path,
        read_options=pa_csv.ReadOptions(
            column_names=names,
            skip_rows=skip,
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


def _pyarrow() -> tuple[Any, Any]:
    """``pyarrow`` and ``pyarrow.csv``; without them, :class:`Fallback` from the first row."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pa_csv
    except ImportError:  # pragma: no cover - pyarrow is in the io and test extras
        raise Fallback(0) from None
    return pa, pa_csv


def arrow_csv_chunks(
    path: Path,
    header: list[str],
    layout: Layout,
    robot: Robot,
    sep: str,
    chunk_rows: int,
    skip: int = 1,
) -> Iterator[Log]:
    """Clean CSV through Arrow's streaming reader (typed float columns, no pandas).

    Any row it cannot parse as numbers (a stray quote, a bad cell, a blank line,
    a wrong cell count) raises :class:`Fallback` with the rows already yielded,
    and :func:`csv_chunks` re-reads from there with :func:`careful_chunks`, which
    reports the cell or names the line.  (Quoting is off here: a quoted field with a
    separator or a line break makes a wrong cell count, so the careful reader, which
    reads quoting and counts lines, takes over.)  ``skip``: the header's lines (0: a file
    without one, :func:`~pinobs.io.readers.csv_log.headless`).
    """
    pa, pa_csv = _pyarrow()
    used = list(dict.fromkeys(layout.used))
    names = [f"{c}\x00{i}" if c not in used else c for i, c in enumerate(header)]
    try:
        reader = _open_arrow_csv(pa, pa_csv, path, names, used, sep, skip)
    except (pa.ArrowException, UnicodeDecodeError):
        raise Fallback(0) from None
    start = 0  # rows yielded
    pending: list[dict[str, Vector]] = []
    rows = 0

    def flush() -> Log:
        nonlocal start, pending, rows
        arrays = {c: np.concatenate([p[c] for p in pending]) for c in used}
        lines = np.arange(start, start + rows) + 1 + skip  # (lines 1..skip: the header)
        log = from_arrays(arrays, rows, layout, robot, lines, "line", [], row0=start)
        start, pending, rows = start + rows, [], 0
        return log

    try:
        while True:
            try:
                batch = reader.read_next_batch()
            except StopIteration:
                break
            except (pa.ArrowException, UnicodeDecodeError):
                raise Fallback(start) from None
            off = 0
            while off < batch.num_rows:
                take = min(chunk_rows - rows, batch.num_rows - off)
                part = batch.slice(off, take)
                cols = {c: _float_column(part.column(c)) for c in used}
                if _all_nan_row(list(cols.values())):
                    # a blank line (Arrow: a row of nulls): pandas's, which are not rows (a
                    # sweep found them rows here, NaN and unreported, and dropped after a
                    # fallback: one log read two ways)
                    raise Fallback(start)
                pending.append(cols)
                rows, off = rows + take, off + take
                if rows == chunk_rows:
                    yield flush()
        if rows:
            yield flush()
    finally:
        reader.close()
