"""Writers: estimates out (streamed, atomically), logs out (for tests and examples).

The estimates file has columns ``t, q0 .. q{nq-1}, v0 .. v{nv-1}``, one row per
log row, floats in their shortest round-trip form.  It is written to a
temporary file beside the target and renamed at the end, so a failed run never
leaves a truncated file; the target may not be one of the inputs and is not
overwritten without ``force``.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from pinobs.errors import OutputExistsError
from pinobs.model.robot import Vector

if TYPE_CHECKING:
    from pinobs.io.stream import LogRun

__all__ = ["EstimateWriter", "write_estimates", "write_log"]

#: Output suffixes of other formats: the estimates are CSV text, refused under these names.
_NOT_CSV = {".parquet", ".pq", ".npz", ".npy", ".feather", ".arrow", ".bag", ".mcap", ".db3"}


class _HasDims(Protocol):
    """Anything with ``nq`` and ``nv`` (a :class:`~pinobs.Robot`)."""

    @property
    def nq(self) -> int: ...  # pragma: no cover

    @property
    def nv(self) -> int: ...  # pragma: no cover


class EstimateWriter:
    """Write ``t, q0.., v0..`` rows to a CSV file, chunk by chunk, atomically.

    Rows go to a temporary file beside ``path``, renamed to ``path`` by
    :meth:`close` (a failed run leaves no truncated output; :meth:`abort`
    removes the temporary file).

    Raises:
        OutputExistsError: ``path`` is one of ``inputs``, or exists and not ``force``.
    """

    def __init__(
        self,
        path: str | Path,
        robot: _HasDims,
        *,
        force: bool = False,
        inputs: Iterable[str | Path] = (),
        extra_columns: Iterable[str] = (),
    ) -> None:
        self.path = Path(path)
        for src in inputs:
            s = Path(src)
            if s.exists() and (
                s.resolve() == self.path.resolve()
                or (self.path.exists() and os.path.samefile(s, self.path))
            ):
                raise OutputExistsError(
                    f"output {str(self.path)!r} is the input log: choose another --out"
                )
            if s.is_dir() and self.path.resolve().is_relative_to(s.resolve()):
                # a rosbag2 folder: its files are the input (a sweep found --out
                # bag/bag.db3 overwrite the bag it was reading)
                raise OutputExistsError(
                    f"output {str(self.path)!r} is inside the input bag folder {str(s)!r}: "
                    "choose an --out outside it"
                )
        if self.path.suffix.lower() in _NOT_CSV:
            raise OutputExistsError(
                f"output {str(self.path)!r}: the estimates are written as CSV text, not "
                f"{self.path.suffix}; name the output .csv"
            )
        if self.path.is_dir():  # (--force would only fail on it, after the work)
            raise OutputExistsError(f"output {str(self.path)!r} is a directory; give a file name")
        if self.path.exists() and not force:
            raise OutputExistsError(
                f"output {str(self.path)!r} exists; pass --force (force=True) to overwrite it"
            )
        try:  # (a sweep found a raw FileExistsError / PermissionError traceback here)
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(
                dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".part"
            )
        except OSError as exc:
            raise OutputExistsError(
                f"output {str(self.path)!r} cannot be written ({type(exc).__name__}: "
                f"{exc.strerror or exc}): choose another --out"
            ) from None
        self.columns = [
            "t",
            *(f"q{i}" for i in range(robot.nq)),
            *(f"v{i}" for i in range(robot.nv)),
            *extra_columns,
        ]
        self._tmp = Path(tmp)
        self._fh = os.fdopen(fd, "wb")
        self._fh.write((",".join(self.columns) + "\n").encode())

    def write(self, t: Vector, q: Vector, v: Vector, *extra: Vector) -> None:
        """Append rows (``t`` (n,), ``q`` (n, nq), ``v`` (n, nv), then the arrays of the
        ``extra_columns``, e.g. ``v_std`` (n, nv)); shortest round-trip floats."""
        if not len(t):
            return
        data = np.column_stack([t, q, v, *extra])
        try:
            import pyarrow as pa
            import pyarrow.csv as pa_csv
        except ImportError:  # pragma: no cover - pyarrow is in the io and test extras
            import pandas as pd

            text = pd.DataFrame(data).to_csv(header=False, index=False, lineterminator="\n")
            self._fh.write(text.encode())
            return
        # Arrow's C++ writer: shortest round-trip floats, ~5x faster than pandas' to_csv
        # arrays from their buffers: pa.array(ndarray) would import pandas (~60 MB)
        cols = [
            pa.Array.from_buffers(
                pa.float64(), len(data), [None, pa.py_buffer(np.ascontiguousarray(data[:, i]))]
            )
            for i in range(data.shape[1])
        ]
        table = pa.Table.from_arrays(cols, names=self.columns)
        pa_csv.write_csv(table, self._fh, pa_csv.WriteOptions(include_header=False))

    def close(self) -> Path:
        """Finish the file and move it into place."""
        self._fh.close()
        os.replace(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Drop the temporary file (the output is left as it was)."""
        self._fh.close()
        self._tmp.unlink(missing_ok=True)


def write_estimates(path: str | Path, run: LogRun, *, force: bool = True) -> Path:
    """Write a :class:`LogRun` held in memory: ``t, q0.., v0..``, one row per log row."""
    nq, nv = run.q.shape[1], run.v.shape[1]
    writer = EstimateWriter(path, _Dims(nq, nv), force=force)
    writer.write(run.t, run.q, run.v)
    return writer.close()


@dataclass(frozen=True)
class _Dims:
    nq: int
    nv: int


def write_log(
    path: str | Path, t: Vector, q: Vector, tau: Vector | None = None, *, digits: int = 17
) -> Path:
    """Write a positional CSV log ``t, q0.., tau0..`` that :func:`pinobs.io.read_log` reads.

    ``digits``: significant digits of every value.
    """
    path = Path(path)
    cols = [np.asarray(t, dtype=float)[:, None], np.asarray(q, dtype=float)]
    header = ["t", *(f"q{i}" for i in range(q.shape[1]))]
    if tau is not None:
        cols.append(np.asarray(tau, dtype=float))
        header += [f"tau{i}" for i in range(tau.shape[1])]
    np.savetxt(
        path,
        np.hstack(cols),
        delimiter=",",
        header=",".join(header),
        comments="",
        fmt=f"%.{digits}g",
    )
    return path
