"""A log exported as several tables of one clock, joined on ``t``.

A ROS ``sensor_msgs/JointState`` topic exported to CSV is often written as one table per
field (FIGAROH's TIAGo data: ``tiago_position.csv``, ``tiago_velocity.csv`` and
``tiago_effort.csv``, each ``t`` then one column per joint).  :func:`join_tables` puts such
tables side by side: one ``t`` column, every other column once, so the log reads as if it
had been written as one table (``--map`` then names the columns as for any log).  The rows
are matched by position and their ``t`` must be equal, value for value (the tables come from
one clock); a table with other stamps is refused, the first differing row named, not
interpolated.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.errors import DimensionError, LogFormatError, ModelFileError
from pinobs.io.readers.table import require_pandas

__all__ = ["TABLE_SUFFIXES", "join_tables"]

#: What :func:`join_tables` reads: CSV (any other suffix), TSV and Parquet tables.
TABLE_SUFFIXES = (".csv", ".tsv", ".txt", ".parquet", ".pq")


def _table(path: Path) -> Any:
    pd = require_pandas()
    if not path.is_file():
        raise ModelFileError(f"log table {str(path)!r} does not exist")
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        return pd.read_parquet(path)
    if suffix in (".npz", ".npy", ".bag", ".mcap", ".db3"):
        raise LogFormatError(
            f"{str(path)!r}: only CSV, TSV or Parquet tables are joined on t (not {suffix})"
        )
    return pd.read_csv(path, sep="\t" if suffix == ".tsv" else ",")


def join_tables(paths: Sequence[str | Path]) -> Any:
    """The tables of ``paths`` side by side on their common ``t`` (module docstring): a
    ``pandas.DataFrame`` with ``t`` first, then each table's other columns in order.

    Raises:
        ModelFileError: a path that is not a file.
        LogFormatError: a table without a ``t`` column, or not a CSV, TSV or Parquet table.
        DimensionError: tables of different lengths or whose ``t`` differ (the first row
            named), or a column name in two tables.
    """
    pd = require_pandas()
    tables = [(str(p), _table(Path(p)).rename(columns=lambda c: str(c).strip())) for p in paths]
    first_name, first = tables[0]
    seen: dict[str, str] = {}
    parts = []
    for name, table in tables:
        if "t" not in table.columns:
            raise LogFormatError(
                f"{name!r}: no t column to join on (its columns: {list(table.columns)}); each "
                "table needs the t of the common clock"
            )
        t0, t = first["t"].to_numpy(dtype=float), table["t"].to_numpy(dtype=float)
        if t.size != t0.size:
            raise DimensionError(
                f"{name!r} has {t.size} rows and {first_name!r} {t0.size}: tables joined on t "
                "must hold the same samples"
            )
        differ = np.flatnonzero(~((t == t0) | (np.isnan(t) & np.isnan(t0))))
        if differ.size:
            k = int(differ[0])
            raise DimensionError(
                f"{name!r}'s t differs from {first_name!r}'s at row {k + 1} (t = {t[k]!r} "
                f"against {t0[k]!r}; {differ.size} rows differ): tables are joined on equal t"
            )
        others = [c for c in table.columns if c != "t"]
        twice = [c for c in others if c in seen]
        if twice:
            raise DimensionError(
                f"columns {twice} are in {seen[twice[0]]!r} and in {name!r}: rename them "
                "in one table (a column is taken once)"
            )
        seen.update(dict.fromkeys(others, name))
        parts.append(table[others])
    return pd.concat([first[["t"]], *parts], axis=1)
