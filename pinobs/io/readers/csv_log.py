"""CSV and TSV logs: the header read, the fast reader, the careful one from where it stops."""

from __future__ import annotations

import csv
from collections.abc import Iterator, Mapping
from pathlib import Path

from pinobs.errors import LogFormatError
from pinobs.io.drives import Drives
from pinobs.io.readers.csv_careful import careful_chunks
from pinobs.io.readers.csv_fast import Fallback, arrow_csv_chunks
from pinobs.io.readers.layout import clean_header, table_layout
from pinobs.io.readers.log import Log
from pinobs.io.readers.textfile import has_binary_head, has_data_after_header, undecodable_line
from pinobs.model import Robot


def csv_chunks(
    path: Path,
    robot: Robot,
    columns: Mapping[str, str] | None,
    chunk_rows: int,
    drives: Drives | None = None,
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
    header = clean_header(next(csv.reader([first], delimiter=sep)), columns)
    layout = table_layout(header, robot, f"log {str(path)!r}", drives)
    if not has_data_after_header(path):
        return
    start = 0
    try:
        yield from arrow_csv_chunks(path, header, layout, robot, sep, chunk_rows)
        return
    except Fallback as fb:
        start = fb.rows
    yield from careful_chunks(path, header, layout, robot, sep, start, chunk_rows)
