"""CSV and TSV logs: the header read, the fast reader, the careful one from where it stops."""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path

from pinobs.errors import LogFormatError
from pinobs.io.drives import Drives
from pinobs.io.readers.csv_careful import careful_chunks
from pinobs.io.readers.csv_fast import Fallback, arrow_csv_chunks
from pinobs.io.readers.layout import Layout, clean_header, table_layout
from pinobs.io.readers.log import Log
from pinobs.io.readers.textfile import has_binary_head, has_data_after_header, undecodable_line
from pinobs.model import Robot


def csv_chunks(
    path: Path,
    robot: Robot,
    columns: Mapping[str, str] | None,
    chunk_rows: int,
    drives: Drives | None = None,
    rate: float | None = None,
) -> Iterator[Log]:
    line, hint = undecodable_line(path) if has_binary_head(path) else (0, "")
    if line:
        raise LogFormatError(f"log {str(path)!r}: line {line} is not UTF-8 text{hint}")
    sep = "\t" if path.suffix.lower() in (".tsv", ".tab") else ","
    with path.open(encoding="utf-8-sig", errors="strict") as fh:
        try:
            first = fh.readline()
        except UnicodeDecodeError:
            line, hint = undecodable_line(path)
            raise LogFormatError(
                f"log {str(path)!r}: line {line or 1} is not UTF-8 text{hint}"
            ) from None
    if not first.strip():
        raise LogFormatError(f"log {str(path)!r} is empty or its line 1 (the header) is blank")
    if sep == "," and "\t" in first and "," not in first:
        sep = "\t"
    elif sep == "\t" and "," in first and "\t" not in first:
        sep = ","
    cells = next(csv.reader([first], delimiter=sep))
    where, skip, note = f"log {str(path)!r}", 1, ""
    if headless(cells):
        said = HEADLESS.format(n=len(cells), last=len(cells) - 1)
        where, skip = f"{where} (no header: {said})", 0
        note = f"no header row: line 1 read as data ({said})"
        cells = [str(i) for i in range(len(cells))]
    header = clean_header(cells, columns)
    layout = table_layout(header, robot, where, drives, rate)
    if skip and not has_data_after_header(path):
        return
    chunks = _chunks(path, header, layout, robot, sep, chunk_rows, skip)
    first_chunk = next(chunks, None)
    if first_chunk is not None:
        yield replace(first_chunk, notes=(*first_chunk.notes, note)) if note else first_chunk
        yield from chunks


#: What a CSV without a header is read as (``{n}`` cells on line 1, the ``{last}`` index).
HEADLESS = (
    "its line 1 is numbers, so its {n} columns are named by position, 0 to {last}: name them "
    "with columns={{'0': 't', '1': 'q0', ...}} (--map 0=t --map 1=q0 ...)"
)


def headless(cells: list[str]) -> bool:
    """Whether a CSV's line 1 (``cells``) is data, not a header: two or more cells, every one
    a finite number (a header names its columns)."""
    if len(cells) < 2:
        return False
    try:
        return all(math.isfinite(float(c)) for c in cells)
    except ValueError:
        return False


def _chunks(
    path: Path, header: list[str], layout: Layout, robot: Robot, sep: str, chunk_rows: int,
    skip: int,
) -> Iterator[Log]:  # fmt: skip
    """The rows after the ``skip`` header lines: the fast reader, the careful one from where
    it stops."""
    start = 0
    try:
        yield from arrow_csv_chunks(path, header, layout, robot, sep, chunk_rows, skip)
        return
    except Fallback as fb:
        start = fb.rows
    yield from careful_chunks(path, header, layout, robot, sep, start, chunk_rows, skip)
