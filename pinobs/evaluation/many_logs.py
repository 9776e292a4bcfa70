"""Many logs through one observer (or the smoother) on Dask: one estimates file per log
and a summary table.

:func:`estimate_logs` runs :func:`pinobs.io.process_log` over many logs (the
tasks of :func:`log_tasks`, one per log), or with ``smooth`` the RTS smoother
(:func:`pinobs.io.smoothing.smooth_log`, which costs a few times the filter,
so the logs gain more from the cluster): one estimates file per log, written
by the single-log writer (atomic, never over an existing file without
``force``), and a summary table, one row per log (:data:`SUMMARY_COLUMNS`).
The tasks run through :func:`pinobs.evaluation.distributed.run_tasks`.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pinobs.errors import OptionError, OutputExistsError
from pinobs.evaluation.distributed import TaskOutcome, run_tasks

if TYPE_CHECKING:
    from pinobs.io.drives import Drives

__all__ = [
    "SUMMARY_COLUMNS",
    "LogTask",
    "estimate_logs",
    "log_summary",
    "log_tasks",
    "run_log_task",
]

#: The columns of :func:`estimate_logs`'s summary: the log (as found), its
#: estimates file, rows read, rows with an estimate, rows reported (dropped or
#: repaired), the noise σ used [rad or m], the innovation test's verdict
#: (``consistent`` / ``inconsistent`` / ``unknown``: too few samples or an
#: observer without the test; for a smoothed log, ``inconsistent`` when a stretch is
#: what :func:`pinobs.smooth` warns of, :func:`pinobs.smoothing.smoothing_warnings`),
#: the filter–smoother consistency ``ρ`` of a smoothed log
#: (:attr:`pinobs.smoothing.Smoother.consistency`, over all its stretches; NaN
#: when filtered), the measurement latency [s] the log was estimated under (given, or
#: found from the log by the smoother: :func:`pinobs.smooth`; its longest stretch's when
#: stretches differ), wall-clock seconds in the worker, what the run warned of (the
#: ``warning:`` and ``note:`` lines ``pinobs estimate`` prints for that log alone, one a
#: line; empty if none: a ``sigma`` of NaN is the observer's default, said there),
#: and the error of a log that failed (empty otherwise).
SUMMARY_COLUMNS = (
    "log",
    "out",
    "rows",
    "estimated",
    "bad_rows",
    "sigma",
    "consistency",
    "rho",
    "latency",
    "seconds",
    "warnings",
    "error",
)
SUMMARY_STEM = "summary"


@dataclass(frozen=True)
class LogTask:
    """One log of a batch: where it is and where its estimates go (absolute paths,
    so workers elsewhere on a shared file system find them), how to estimate."""

    name: str  # the log as the user named or globbed it (the summary's ``log``)
    log: str
    out: str
    robot: str
    observer: str
    root_joint: str | None = None
    friction: bool | None = None  # pinobs.load's friction
    mimic: str | None = None  # pinobs.load's mimic
    #: pinobs.load's lock, as (joint, value) pairs (value None: the neutral one)
    lock: tuple[tuple[str, Any], ...] = ()
    check: bool = True  # pinobs.load's check (False: --no-check)
    force: bool = False
    columns: tuple[tuple[str, str], ...] = ()
    topic: str | None = None
    rate: float | None = None
    noise_std: float | None = None
    #: ``None``: filtered (:func:`pinobs.io.process_log`); else smoothed, with these options
    #: of :func:`pinobs.io.smoothing.smooth_log` (``lag``, ``chunk``, ``accel_psd``, ``band``)
    smooth: tuple[tuple[str, Any], ...] | None = None
    #: further options of the observer (``latency``), filtered or smoothed
    options: tuple[tuple[str, Any], ...] = ()
    #: the log's clock (:func:`pinobs.io.process_log`'s ``clock``), filtered or smoothed
    clock: str = "auto"
    #: the log's drives (:class:`pinobs.io.Drives`), filtered or smoothed
    drives: Drives | None = None


def log_tasks(
    logs: Sequence[str | Path],
    out_dir: str | Path,
    *,
    robot: str,
    observer: str,
    root_joint: str | None = None,
    friction: bool | None = None,
    mimic: str | None = None,
    lock: Sequence[str] | Mapping[str, Any] | None = None,
    check: bool = True,
    force: bool = False,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    rate: float | None = None,
    noise_std: float | None = None,
    smooth: Mapping[str, Any] | None = None,
    options: Mapping[str, Any] | None = None,
    clock: str = "auto",
    drives: Drives | None = None,
) -> list[LogTask]:
    """One :class:`LogTask` per log; the estimates of ``logs/a/run.parquet`` go to
    ``out_dir/a/run.csv`` (the log's path below the logs' common folder, suffix
    ``.csv``).  The batch's own outputs among ``logs`` (found again by a glob or a
    folder on a second run) are left out: the summary files, and every file under
    ``out_dir`` when some logs are outside it; so a run gives fewer tasks than logs.

    Args:
        logs: log files or rosbag2 folders (:func:`pinobs.io.find_logs`).
        out_dir: folder of the estimates and the summary.
        robot: a registry name or a URDF/MJCF path.
        observer: a registry name.
        root_joint, columns, topic, rate, noise_std, drives: as :func:`pinobs.io.process_log`
            (``noise_std=None``: estimated from each log's first second).
        friction: :func:`pinobs.load`'s (the URDF's joint friction in the dynamics).
        mimic, lock, check: :func:`pinobs.load`'s (the joints the logs do not have, locked;
            ``check=False``: a model the sanity check refuses).
        force: overwrite existing estimates and summary.
        smooth: smooth each log instead of filtering it, with these options of
            :func:`pinobs.io.smoothing.smooth_log` (``{}``: its defaults; ``lag``,
            ``chunk``, ``accel_psd``, ``band``); the estimates files get ``v_std0..``.
        options: further options of the observer, filtered or smoothed (``latency`` [s];
            smoothed, also ``"auto"``: :func:`pinobs.smooth`).

    Raises:
        OptionError: no logs (or only outputs), or two logs whose estimates would share a file.
        OutputExistsError: the summary exists and not ``force`` (checked before any work).
    """
    planned = _planned(logs, Path(out_dir).resolve(), force)
    robot_source = str(Path(robot).resolve()) if Path(robot).is_file() else robot
    return [
        LogTask(
            name=str(name),
            log=str(path),
            out=str(target),
            robot=robot_source,
            observer=observer,
            root_joint=root_joint,
            friction=friction,
            mimic=mimic,
            lock=_lock_pairs(lock),
            check=check,
            force=force,
            columns=tuple(sorted((columns or {}).items())),
            topic=topic,
            rate=rate,
            noise_std=noise_std,
            smooth=None if smooth is None else tuple(sorted(smooth.items())),
            options=tuple(sorted((options or {}).items())),
            clock=clock,
            drives=drives,
        )
        for name, path, target in planned
    ]


def _planned(
    logs: Sequence[str | Path], out: Path, force: bool
) -> list[tuple[str | Path, Path, Path]]:
    """The logs :func:`log_tasks` keeps (the batch's own outputs left out), each as given,
    resolved, and with its estimates file in ``out``; refused as :func:`log_tasks` says."""
    if not logs:
        raise OptionError("no logs given: give at least one log file or rosbag2 folder")
    # the batch's own outputs, found again by a glob or a folder: the summary, and, when
    # some logs are outside out_dir, everything in it (with the logs in out_dir, only the
    # summary: the estimates go next to the logs, and one found again clashes below)
    found = [(name, Path(name).resolve()) for name in logs]
    summaries = tuple(out / (SUMMARY_STEM + suffix) for suffix in (".parquet", ".csv"))
    elsewhere = any(not p.is_relative_to(out) for _, p in found)
    kept = [
        (name, p)
        for name, p in found
        if p not in summaries and not (elsewhere and p.is_relative_to(out))
    ]
    if not kept:
        raise OptionError(
            f"the {len(logs)} logs given are the outputs of an earlier run in {str(out)!r} "
            "(its summary, or estimates under it): give the logs, or another output folder"
        )
    base = Path(os.path.commonpath([str(p.parent) for _, p in kept]))
    planned = [(name, p, out / p.relative_to(base).with_suffix(".csv")) for name, p in kept]
    seen: dict[Path, str | Path] = {}
    for name, _, target in planned:
        if target in seen:
            raise OptionError(
                f"logs {str(seen[target])!r} and {str(name)!r} would both write {str(target)!r}: "
                "rename one, or run them separately"
            )
        if target.parent == out and target.stem == SUMMARY_STEM:
            raise OptionError(
                f"log {str(name)!r} would write {str(target)!r}, the summary's name: rename it"
            )
        seen[target] = name
    for summary in summaries:
        if summary.exists() and not force:
            raise OutputExistsError(
                f"summary {str(summary)!r} exists; pass --force (force=True) to overwrite "
                "it and the estimates"
            )
    return planned


def _lock_pairs(lock: Sequence[str] | Mapping[str, Any] | None) -> tuple[tuple[str, Any], ...]:
    """``lock`` as hashable ``(joint, value)`` pairs in its order (sequences as tuples)."""
    if not lock:
        return ()
    items = lock.items() if isinstance(lock, Mapping) else ((n, None) for n in lock)
    return tuple(
        (str(n), tuple(v) if isinstance(v, Sequence) and not isinstance(v, str) else v)
        for n, v in items
    )


def run_log_task(task: LogTask) -> dict[str, Any]:
    """One log through :func:`pinobs.io.process_log` (streamed to its file), or with
    ``task.smooth`` :func:`pinobs.io.smoothing.smooth_log`; its summary row.

    A log where no row could be estimated keeps its (all-NaN) file and has ``error`` set.
    """
    from pinobs.io import process_log
    from pinobs.io.smoothing import smooth_log
    from pinobs.model import load
    from pinobs.smoothing import smoothing_warnings

    start = time.perf_counter()
    robot = load(
        task.robot,
        root_joint=task.root_joint,
        friction=task.friction,
        mimic=task.mimic,
        lock=dict(task.lock) or None,
        check=task.check,
    )
    common: dict[str, Any] = {
        "force": task.force,
        "columns": dict(task.columns) or None,
        "topic": task.topic,
        "rate": task.rate,
        "noise_std": task.noise_std,
        "options": dict(task.options) or None,
        "drives": task.drives,
    }
    verdict, rho, told = None, math.nan, []
    given = dict(task.options).get("latency", 0.0)  # smoothed, also "auto": found per stretch
    latency = math.nan if given == "auto" else float(given)
    if task.smooth is None:
        run = process_log(
            task.log, robot, task.observer, out=task.out, keep=False, clock=task.clock, **common
        )
        if run.consistency is not None:
            verdict = run.consistency.verdict
            told = run.consistency.messages(task.observer)
    else:
        run, stretches = smooth_log(
            task.log,
            robot,
            task.out,
            observer=task.observer,
            clock=task.clock,
            **common,
            **dict(task.smooth),
        )
        rho = _pooled_rho(stretches)
        said = any(smoothing_warnings(s["consistency"], s) for s in stretches)
        verdict = "inconsistent" if said else ("consistent" if math.isfinite(rho) else "unknown")
        if stretches:
            latency = max(stretches, key=lambda s: s["consistency_terms"]).get("latency", 0.0)
    return {
        "log": task.name,
        "out": task.out,
        "rows": run.rows,
        "estimated": run.estimated,
        "bad_rows": len(run.bad_rows),
        "sigma": float("nan") if run.noise_std is None else float(run.noise_std),
        "consistency": verdict,
        "rho": rho,
        "latency": latency,
        "seconds": time.perf_counter() - start,
        "warnings": "\n".join([f"warning: {w}" for w in run.warnings] + told) or None,
        "error": None if run.estimated else "no row of the log could be estimated",
    }


def _pooled_rho(stretches: Sequence[Mapping[str, Any]]) -> float:
    """``ρ`` of a log smoothed in stretches: their values weighted by their terms' counts."""
    terms = [(s["consistency"], s["consistency_terms"]) for s in stretches]
    n = sum(k for _, k in terms)
    return sum(rho * k for rho, k in terms if k) / n if n else math.nan


def estimate_logs(
    tasks: Sequence[LogTask],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    progress: Callable[[int, int], None] | None = None,
    on_result: Callable[[TaskOutcome], None] | None = None,
) -> Any:
    """Run the logs on Dask (``workers=0``: here, one after the other); the summary as a
    ``pandas.DataFrame``, one row per log in the order of ``tasks`` (:data:`SUMMARY_COLUMNS`).

    A log that raised (unreadable, wrong columns, an existing output without
    ``force``) fails alone: its row has ``error`` set (the exception's last
    line) and NaN counts, and no estimates file.  ``on_result`` (as :func:`run_tasks`'s)
    lets a caller interrupted (``KeyboardInterrupt``) still make the summary of the
    logs done: :func:`log_summary`.
    """
    return log_summary(
        run_tasks(
            run_log_task,
            tasks,
            scheduler=scheduler,
            workers=workers,
            processes=processes,
            progress=progress,
            on_result=on_result,
        )
    )


def log_summary(outcomes: Sequence[TaskOutcome]) -> Any:
    """The summary table of :func:`estimate_logs` from the outcomes of :func:`run_log_task`."""
    import pandas as pd

    rows: list[dict[str, Any]] = []
    for o in outcomes:
        t: LogTask = o.task
        if o.error is None:
            rows.append(o.value)
            continue
        nan = float("nan")
        rows.append(
            {
                "log": t.name,
                "out": None,
                "rows": nan,
                "estimated": nan,
                "bad_rows": nan,
                "sigma": nan,
                "consistency": None,
                "latency": nan,
                "seconds": nan,
                "warnings": None,
                "error": o.error,
            }
        )
    counts = {"rows": "Int64", "estimated": "Int64", "bad_rows": "Int64"}  # NA where it failed
    return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS)).astype(counts)
