"""Parquet logs, batch by batch, columns as a CSV's."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from pinobs.errors import LogFormatError
from pinobs.io.drives import Drives
from pinobs.io.readers.layout import clean_header, table_layout
from pinobs.io.readers.log import Log
from pinobs.io.readers.table import INSTALL_IO, from_frame, require_pandas, time_in_seconds
from pinobs.model import Robot


def parquet_chunks(
    path: Path,
    robot: Robot,
    columns: Mapping[str, str] | None,
    chunk_rows: int,
    drives: Drives | None = None,
    rate: float | None = None,
) -> Iterator[Log]:
    require_pandas()
    try:
        import pyarrow.parquet as pq
        from pyarrow import ArrowException
    except ImportError as exc:  # pragma: no cover - pyarrow is in the io and test extras
        raise ModuleNotFoundError(f"reading Parquet logs needs pyarrow: {INSTALL_IO}") from exc
    try:
        pf = pq.ParquetFile(path)
    except (ArrowException, OSError) as exc:
        raise LogFormatError(f"log {str(path)!r} is not a readable Parquet file: {exc}") from None
    raw = list(pf.schema_arrow.names)
    header = clean_header(raw, columns)
    layout = table_layout(header, robot, f"log {str(path)!r}", drives, rate)
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
            if len(frame) and layout.t is not None:
                time_in_seconds(frame, layout.t, problems if start == 0 else [])
            yield from_frame(frame, layout, robot, lines, "row", problems, row0=start)
            start += len(frame)
    except (ArrowException, OSError) as exc:
        raise LogFormatError(f"log {str(path)!r}: unreadable after row {start}: {exc}") from None
