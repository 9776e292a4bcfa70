"""Recorded logs in, estimates out.

Log format (CSV): a header row naming the columns, then one row per sample::

    t, q0, q1, ..., q{nq-1}, tau0, ..., tau{nv-1}

``t`` in seconds, strictly increasing; ``q`` in Pinocchio's order
(quaternions ``x, y, z, w``); the ``tau`` columns are optional (without them
every torque is zero, which a model-based observer must be told about: see
:attr:`LogRun.warnings`).  An ``.npz`` file with arrays ``t`` (N,), ``q``
(N, nq) and optionally ``tau`` (N, nv) is read the same way.

Bad rows lose nothing else: a row whose ``q`` is unreadable, non-finite or off
its manifold is fed to the observer as a dropped sample (``q_meas=None``:
propagate only); a row whose ``t`` is unreadable or not after the previous
good one gets NaN estimates.  Every bad row is reported with its line number
and the reason.  The estimates have one row per log row.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.errors import DimensionError, ModelFileError, PinobsError, TimestampError
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.observers import Observer

__all__ = ["Log", "LogRun", "estimate_log", "read_log", "write_estimates", "write_log"]


@dataclass(frozen=True)
class Log:
    """A recorded log: raw rows (NaN where a cell was unreadable).

    Attributes:
        t: times [s], shape ``(N,)``.
        q: configurations, shape ``(N, nq)``.
        tau: torques, shape ``(N, nv)``, or ``None`` when the log has none.
        problems: ``(line, reason)`` for cells that could not be read.
    """

    t: Vector
    q: Vector
    tau: Vector | None
    problems: tuple[tuple[int, str], ...] = ()


def _columns(header: list[str], robot: Robot) -> tuple[int, list[int], list[int] | None]:
    names = [h.strip() for h in header]
    want_q = [f"q{i}" for i in range(robot.nq)]
    want_tau = [f"tau{i}" for i in range(robot.nv)]
    missing = [n for n in ["t", *want_q] if n not in names]
    if missing:
        raise DimensionError(
            f"log header {names} lacks columns {missing}; robot {robot.name!r} needs "
            f"t, q0..q{robot.nq - 1} (nq = {robot.nq}) and optionally tau0..tau{robot.nv - 1}"
        )
    tau_idx = None
    if any(n in names for n in want_tau):
        absent = [n for n in want_tau if n not in names]
        if absent:
            raise DimensionError(
                f"log has some torque columns but lacks {absent} (nv = {robot.nv})"
            )
        tau_idx = [names.index(n) for n in want_tau]
    return names.index("t"), [names.index(n) for n in want_q], tau_idx


def read_log(path: str | Path, robot: Robot) -> Log:
    """Read a CSV or NPZ log for ``robot`` (module docstring for the format).

    Raises:
        ModelFileError: the file is missing or not a log (a ``FileNotFoundError``).
        DimensionError: the columns do not match the robot (a ``ValueError``).
    """
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"log file {str(path)!r} does not exist")
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                t = np.asarray(z["t"], dtype=float)
                q = np.asarray(z["q"], dtype=float)
                tau = np.asarray(z["tau"], dtype=float) if "tau" in z else None
        except (KeyError, ValueError, OSError) as exc:
            raise ModelFileError(
                f"log {str(path)!r} is not an npz with arrays t, q (and tau): {exc}"
            ) from exc
        if (
            q.ndim != 2
            or q.shape != (t.size, robot.nq)
            or (tau is not None and tau.shape != (t.size, robot.nv))
        ):
            raise DimensionError(
                f"log {str(path)!r}: t {t.shape}, q {q.shape}, tau {None if tau is None else tau.shape}; "
                f"robot {robot.name!r} needs q of shape (N, {robot.nq}) and tau of shape (N, {robot.nv})"
            )
        return Log(t=t, q=q, tau=tau, problems=())
    problems: list[tuple[int, str]] = []
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            raise ModelFileError(f"log {str(path)!r} is empty") from None
        it, iq, itau = _columns(header, robot)
        rows_t, rows_q, rows_tau = [], [], []
        for line, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue

            def cell(i: int, line: int = line, row: list[str] = row) -> float:
                try:
                    return float(row[i])
                except (IndexError, ValueError):
                    problems.append(
                        (
                            line,
                            f"column {header[i].strip()!r} unreadable: {row[i] if i < len(row) else '(missing)'!r}",
                        )
                    )
                    return math.nan

            rows_t.append(cell(it))
            rows_q.append([cell(i) for i in iq])
            if itau is not None:
                rows_tau.append([cell(i) for i in itau])
    t = np.array(rows_t, dtype=float)
    q = np.array(rows_q, dtype=float).reshape(len(rows_t), robot.nq)
    tau = None if itau is None else np.array(rows_tau, dtype=float).reshape(len(rows_t), robot.nv)
    return Log(t=t, q=q, tau=tau, problems=tuple(problems))


@dataclass
class LogRun:
    """Estimates over a log, one row per log row (NaN where the row could not be used).

    Attributes:
        t: the log's times [s] (as read, NaN where unreadable).
        q: estimated configurations ``(N, nq)``.
        v: estimated velocities ``(N, nv)``.
        bad_rows: ``(line, reason)`` for every row that was not used as a measurement.
        warnings: what the run could not do (e.g. no torques for a model-based observer).
    """

    t: Vector
    q: Vector
    v: Vector
    bad_rows: list[tuple[int, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def estimate_log(
    observer: Observer[Any],
    log: Log,
    *,
    first_line: int = 2,
    progress: Callable[[int, int], None] | None = None,
) -> LogRun:
    """Run ``observer`` over ``log`` row by row (bad rows handled as in the module docstring).

    ``first_line`` is the file line of row 0 (2 for a CSV with a header), for the reports.
    """
    robot = observer.robot
    n = log.t.size
    out_q = np.full((n, robot.nq), np.nan)
    out_v = np.full((n, robot.nv), np.nan)
    run = LogRun(t=log.t, q=out_q, v=out_v)
    if log.tau is None and observer.uses_torque:
        run.warnings.append(
            f"the log has no torque columns: {observer.name!r} uses the model's dynamics and now "
            "assumes zero applied torque (gravity stays modelled); its estimates carry the effect "
            "of the missing inputs. Add tau0..tau{n-1} columns, or use a model-free observer (fd, kf)."
        )
    reported = {line for line, _ in log.problems}
    run.bad_rows.extend(log.problems)
    started = False
    for k in range(n):
        line = first_line + k
        t = float(log.t[k])
        tau = None if log.tau is None or not np.all(np.isfinite(log.tau[k])) else log.tau[k]
        if log.tau is not None and tau is None and line not in reported:
            run.bad_rows.append((line, f"non-finite torque {log.tau[k].tolist()}: zero used"))
        try:
            if not started:
                est = observer.reset(t, log.q[k], None, tau)
                started = True
            else:
                try:
                    est = observer.update(t, log.q[k], tau)
                except TimestampError:
                    raise
                except PinobsError as exc:
                    if line not in reported:
                        run.bad_rows.append((line, f"{exc} (used as a dropped sample)"))
                    est = observer.update(t, None, tau)
        except PinobsError as exc:
            if line not in reported:
                run.bad_rows.append((line, str(exc)))
            continue
        out_q[k], out_v[k] = est.q, est.v
        if progress is not None:
            progress(k + 1, n)
    run.bad_rows.sort()
    return run


def write_estimates(path: str | Path, run: LogRun) -> Path:
    """Write ``t, q0.., v0..`` columns, one row per log row, to a CSV file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    nq, nv = run.q.shape[1], run.v.shape[1]
    header = ["t", *(f"q{i}" for i in range(nq)), *(f"v{i}" for i in range(nv))]
    data = np.column_stack([run.t, run.q, run.v])
    np.savetxt(path, data, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    return path


def write_log(
    path: str | Path, t: Vector, q: Vector, tau: Vector | None = None, *, digits: int = 17
) -> Path:
    """Write a log in the CSV format :func:`read_log` reads (``digits`` significant digits)."""
    path = Path(path)
    nq = q.shape[1]
    cols = [t, q]
    header = ["t", *(f"q{i}" for i in range(nq))]
    if tau is not None:
        cols.append(tau)
        header += [f"tau{i}" for i in range(tau.shape[1])]
    np.savetxt(
        path,
        np.column_stack(cols),
        delimiter=",",
        header=",".join(header),
        comments="",
        fmt="%.17g",
    )
    return path
