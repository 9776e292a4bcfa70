"""CSV record by record from the first row the fast reader cannot parse: every cell that
cannot be read reported with its line."""

from __future__ import annotations

import csv
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

import numpy as np

from pinobs.errors import LogFormatError
from pinobs.io.readers.layout import Layout
from pinobs.io.readers.log import Log
from pinobs.io.readers.table import from_frame, require_pandas
from pinobs.io.readers.textfile import undecodable_line
from pinobs.model import Robot

#: Physical lines a quoted field may span before its opening quote counts as a stray one.
_MAX_FIELD_LINES = 100


def _careful_records(
    path: Path, sep: str, ncols: int, skip: int, head: int = 1
) -> Iterator[tuple[int, list[str], str | None]]:
    """``(line, cells, problem)`` of every record after line ``head + skip`` (``head``: the
    header's lines), blank lines left out.

    Standard CSV quoting (``"a, b"``, ``""`` for a quote, a quoted field over several
    lines: its record named by its first line), as the header is read; a quote that does
    not make such a field (a stray one) is a character of its cell, which then cannot be
    read: that row alone is lost (a sweep found a quoted comma fail the whole log and a
    quoted line break shift the cells of an extra row).  A short row is padded with empty
    cells and said; a long one raises :class:`LogFormatError`.
    """
    with path.open(encoding="utf-8-sig", errors="strict", newline=None) as fh:
        for _ in range(head + skip):
            fh.readline()
        number = head + skip
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
                cells, extra = _quoted_record(line, fh, pending, sep, ncols)
                number += extra
            if len(cells) > ncols:
                raise LogFormatError(
                    f"log {str(path)!r}: line {at} has {len(cells)} cells, the header {ncols}"
                )
            said = None
            if len(cells) < ncols:
                said = f"row has {len(cells)} of {ncols} cells"
                cells = cells + [""] * (ncols - len(cells))
            yield at, cells, said


def _quoted_record(
    line: str, fh: TextIO, pending: list[str], sep: str, ncols: int
) -> tuple[list[str], int]:
    """The cells of the record that starts with ``line`` (which has a quote) and how many
    further lines it spans (taken from ``pending``, the lines read ahead from ``fh``, which
    keeps the rest); a stray quote: ``line``'s own cells, and 0."""
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
        del pending[:extra]
        return parsed, extra
    return line.rstrip("\n").split(sep), 0  # a stray quote: a character of its cell, this line


def careful_chunks(
    path: Path,
    header: list[str],
    layout: Layout,
    robot: Robot,
    sep: str,
    start: int,
    chunk_rows: int,
    head: int = 1,
) -> Iterator[Log]:
    """The rows after the first ``start`` (one line each; after the ``head`` lines of the
    header), read record by record (:func:`_careful_records`), every cell that cannot be read
    reported with its line."""
    pd = require_pandas()
    used = list(dict.fromkeys(layout.used))
    where = [header.index(c) for c in used]
    rows: list[list[str]] = []
    lines: list[int] = []
    problems: list[tuple[int, str]] = []
    done = start  # the log's rows before the next chunk (the fast reader's, then these)

    def flush() -> Log:
        nonlocal done
        frame = pd.DataFrame(rows, columns=used, dtype=object)
        log = from_frame(frame, layout, robot, np.array(lines), "line", problems, row0=done)
        done += len(rows)
        rows.clear()
        lines.clear()
        return log

    try:
        for number, cells, said in _careful_records(path, sep, len(header), start, head):
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
        line, hint = undecodable_line(path)
        raise LogFormatError(f"log {str(path)!r}: line {line} is not UTF-8 text{hint}") from None
