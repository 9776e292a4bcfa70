"""Many independent runs on a Dask cluster: ``run_tasks`` and the robustness ``sweep``.

A lab with a fleet of robots, or a robustness study over thousands of runs,
outgrows one process.  The runs are independent, so they go to
``dask.distributed``: a local cluster by default (``workers`` processes, one
thread each: the observers are single-threaded Python), or an existing one by
address (``scheduler="tcp://host:8786"``), so ``dask-jobqueue`` (Slurm, PBS)
or ``dask-kubernetes`` carry the same call to a cluster.  A task that raises
fails alone: its error is reported in its row and the others go on.

:func:`sweep` runs robots × mismatch scenarios × seeds × observer options
(:func:`pinobs.simulate` then :func:`pinobs.evaluate`, one task per
combination) and returns a tidy table (one row per run and observer) that
:func:`write_sweep` saves as Parquet (or CSV) with a plot.

Many logs through one observer or smoother: :mod:`pinobs.evaluation.many_logs`,
on :func:`run_tasks`.

Dask, pandas and pyarrow are the ``dask`` extra: ``pip install "pinobs[dask]"``.
"""

from __future__ import annotations

import importlib.util
import itertools
import os
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pinobs.errors import OptionError, OutputExistsError

if TYPE_CHECKING:
    from pinobs.evaluation.metrics import Metrics

__all__ = [
    "SWEEP_COLUMNS",
    "SWEEP_FILES",
    "SweepTask",
    "TaskOutcome",
    "check_sweep_out",
    "run_tasks",
    "sweep",
    "sweep_tasks",
    "write_sweep",
    "write_table",
]


@dataclass(frozen=True)
class TaskOutcome:
    """What one task gave: its value, or the error it raised (``value`` is then ``None``)."""

    task: Any
    value: Any = None
    error: str | None = None


def _dask() -> Any:
    try:
        import dask.distributed as dd
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise OptionError(
            'many runs need Dask: pip install "pinobs[dask]" (dask[distributed], pandas, pyarrow)'
        ) from exc
    return dd


def _reason(exc: BaseException) -> str:
    """An exception as the last line of its traceback (``module.Type: message``)."""
    return traceback.format_exception_only(type(exc), exc)[-1].strip()


def _guarded(fn: Callable[[Any], Any], task: Any) -> TaskOutcome:
    try:
        return TaskOutcome(task, fn(task))
    except Exception as exc:  # a bad task fails alone, with its reason
        return TaskOutcome(task, None, _reason(exc))


def _lost(dd: Any, exc: Exception) -> str:
    """Why a task has no outcome: its worker died, the scheduler was lost, or Dask's own error."""
    if isinstance(exc, dd.KilledWorker):
        return (
            "its worker process died while running it (killed, e.g. out of memory, or "
            f"crashed): {type(exc).__name__}"
        )
    if isinstance(exc, dd.CancelledError):  # the client cancels them all: scheduler lost
        return "not done: the connection to the Dask scheduler was lost"
    return f"not done: Dask failed ({_reason(exc)})"


def run_tasks(
    fn: Callable[[Any], Any],
    tasks: Sequence[Any],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    progress: Callable[[int, int], None] | None = None,
    on_result: Callable[[TaskOutcome], None] | None = None,
) -> list[TaskOutcome]:
    """``fn(task)`` for every task on a Dask cluster, in the order of ``tasks``.

    Args:
        fn: a picklable function (module level) of one task.
        tasks: picklable task descriptions.
        scheduler: address of an existing scheduler (``tcp://host:8786``);
            ``None``: a local cluster, closed at the end.
        workers: local worker processes (default: Dask's choice, one per core);
            ``0``: no cluster, the tasks run one after the other in this
            process (Dask not needed).
        processes: local workers as processes (``False``: threads, for tests).
        progress: called as ``progress(done, total)`` after each task.
        on_result: called with each :class:`TaskOutcome` as it completes
            (completion order).

    Returns:
        One :class:`TaskOutcome` per task; a task that raised has ``error`` set, and so
        has one whose worker process died running it (killed for lack of memory, a
        crash: a local cluster does not run it again) or that a lost scheduler left
        undone; the others are unaffected.

    Raises:
        OptionError: ``workers`` is negative, or given with ``scheduler``; ``scheduler``
            is not an address.
    """
    _check_cluster(scheduler, workers)

    def report(done: int, outcome: TaskOutcome) -> None:
        if on_result is not None:
            on_result(outcome)
        if progress is not None:
            progress(done, len(tasks))

    if scheduler is None and workers == 0:
        serial = []
        for done, task in enumerate(tasks, start=1):
            serial.append(_guarded(fn, task))
            report(done, serial[-1])
        return serial
    dd = _dask()
    client, cluster = _client(dd, scheduler, workers, processes)
    try:
        futures = client.map(_guarded, [fn] * len(tasks), list(tasks), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        out: list[TaskOutcome | None] = [None] * len(tasks)
        for done, fut in enumerate(dd.as_completed(futures), start=1):
            try:
                outcome = fut.result()
            except Exception as exc:  # not the task's own error (_guarded has those)
                outcome = TaskOutcome(tasks[index[fut.key]], None, _lost(dd, exc))
            fut.release()  # kept here: not recomputed if its worker dies later
            out[index[fut.key]] = outcome
            report(done, outcome)
        return [o for o in out if o is not None]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _check_cluster(scheduler: str | None, workers: int | None) -> None:
    """:func:`run_tasks`' refusals of ``workers`` negative, or given with ``scheduler``."""
    if workers is not None and workers < 0:
        raise OptionError(f"workers={workers}: give 0 (this process) or more local workers")
    if scheduler is not None and workers is not None:
        raise OptionError(
            f"workers={workers} with scheduler={scheduler!r}: the scheduler's cluster "
            "has its own workers; give one or the other"
        )


def _client(dd: Any, scheduler: str | None, workers: int | None, processes: bool) -> Any:
    """The client of the cluster at ``scheduler`` and ``None``, or of a new local cluster of
    ``workers`` and that cluster (to close after the client)."""
    if scheduler is not None:
        try:
            return dd.Client(scheduler), None
        except ValueError as exc:  # a malformed address (no port, an unknown scheme)
            raise OptionError(
                f"--scheduler (scheduler=) {scheduler!r} is not a Dask scheduler's address "
                f"({exc}); give one as tcp://host:8786"
            ) from exc
    # no statistical profiler in our workers: every 10 ms it takes the GIL from the
    # task to walk its stack (4 two-minute UR5 logs: 5 % of the wall time); a task
    # whose worker dies (killed for lack of memory, a crash) fails at once instead of
    # being run 3 more times, and is the only task that worker held (a saturation of
    # 1: no task queued on it behind the running one, to be charged with its death)
    import dask.config

    with dask.config.set(
        {
            "distributed.worker.profile.enabled": False,
            "distributed.scheduler.allowed-failures": 0,
            "distributed.scheduler.worker-saturation": 1.0,
        }
    ):
        cluster = dd.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=processes,
            dashboard_address=None,  # no dashboard; its HTTP server still starts, so:
            # on a free port, not 8787 (taken by any other Dask on the machine: a
            # UserWarning, an error under -W error; the tests failed so beside another)
            scheduler_kwargs={"dashboard_address": ":0"},
        )
    return dd.Client(cluster), cluster


#: The columns of :func:`sweep`'s table, one row per run and observer label: the run
#: (robot, mismatch scenario, seed), the observer's label and options, its RMS and max
#: velocity error [rad/s] after the transient, convergence time [s], whether it diverged
#: (NA when it did not run), and the error of an observer or run that failed (empty
#: otherwise; its metrics are then NaN).
SWEEP_COLUMNS = (
    "robot",
    "scenario",
    "seed",
    "observer",
    "options",
    "rms_v_error",
    "max_v_error",
    "convergence_time",
    "diverged",
    "error",
)


@dataclass(frozen=True)
class SweepTask:
    """One simulation of a sweep: a robot, a mismatch scenario, a seed, observers with options."""

    robot: str
    scenario: str
    seed: int
    observers: tuple[tuple[str, str, tuple[tuple[str, Any], ...]], ...]  # (label, name, options)
    duration: float
    rate: float
    noise_std: float


def sweep_tasks(
    robots: Iterable[str],
    scenarios: Iterable[str],
    seeds: Iterable[int],
    observers: Mapping[str, tuple[str, Mapping[str, Any]]],
    *,
    duration: float = 3.0,
    rate: float = 1000.0,
    noise_std: float = 1e-4,
) -> list[SweepTask]:
    """The tasks of :func:`sweep`: every robot × scenario × seed, all ``observers`` in each run.

    ``observers`` maps a label to ``(registry name, options)``, so one observer
    can appear with several option sets (``{"ekf": ("ekf", {}), "ekf+d":
    ("ekf", {"disturbance_psd": 1.0})}``).
    """
    obs = tuple(
        (label, name, tuple(sorted(opts.items()))) for label, (name, opts) in observers.items()
    )
    # a robot file's path made absolute: a worker may run in another directory
    robots = [str(Path(r).resolve()) if Path(r).is_file() else r for r in robots]
    return [
        SweepTask(r, s, int(k), obs, duration, rate, noise_std)
        for r, s, k in itertools.product(robots, scenarios, seeds)
    ]


def run_sweep_task(task: SweepTask) -> list[dict[str, Any]]:
    """One sweep simulation: rows of (robot, scenario, seed, observer, options, metrics),
    one per observer label in order; an observer that cannot be built gets its error."""
    from pinobs.evaluation.metrics import evaluate
    from pinobs.model import load
    from pinobs.observers import make_observer
    from pinobs.simulation import Sensor, mismatched_plant, simulate

    robot = load(task.robot)
    plant = mismatched_plant(robot, task.scenario, seed=task.seed)
    obs: dict[str, Any] = {}
    refused: dict[str, str] = {}  # an observer that cannot be built fails alone, with its reason
    for label, name, opts in task.observers:
        try:
            obs[label] = make_observer(
                name, robot, rate=task.rate, noise_std=task.noise_std, **dict(opts)
            )
        except Exception as exc:
            refused[label] = _reason(exc)
    if not obs:
        return [_row(task, label, opts, error=refused[label]) for label, _, opts in task.observers]
    res = simulate(
        robot,
        obs,
        duration=task.duration,
        sensor=Sensor(task.rate, task.noise_std),
        inputs="pd",
        seed=task.seed,
        plant=plant,
    )
    metrics = {m.observer: m for m in evaluate(res, robot)}
    return [  # in the order of task.observers, failed ones included
        _row(task, label, opts, metrics.get(label), refused.get(label))
        for label, _, opts in task.observers
    ]


def _row(
    task: SweepTask,
    label: str,
    opts: tuple[tuple[str, Any], ...],
    m: Metrics | None = None,
    error: str | None = None,
) -> dict[str, Any]:
    """A row of :func:`sweep`: an observer's metrics ``m``, or without them (it did not run: ``error``) NaN metrics and ``diverged`` NA."""
    nan = float("nan")
    return {
        "robot": task.robot,
        "scenario": task.scenario,
        "seed": task.seed,
        "observer": label,
        "options": repr(dict(opts)),
        "rms_v_error": nan if m is None else m.rms_v_error,
        "max_v_error": nan if m is None else m.max_v_error,
        "convergence_time": nan if m is None else m.convergence_time,
        "diverged": None if m is None else m.diverged_at is not None,
        "error": error,
    }


def sweep(
    tasks: Sequence[SweepTask],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> Any:
    """Run the tasks on Dask; a tidy ``pandas.DataFrame``, one row per run and observer
    (:data:`SWEEP_COLUMNS`).

    An observer that cannot be built (it refuses the robot, a bad option) fails
    alone: its row has ``error`` set (the exception's last line), NaN metrics and
    ``diverged`` NA, and the run's other observers are simulated.  A run that
    raised gives such a row for every observer label.
    """
    import pandas as pd

    rows: list[dict[str, Any]] = []
    for o in run_tasks(
        run_sweep_task,
        tasks,
        scheduler=scheduler,
        workers=workers,
        processes=processes,
        progress=progress,
    ):
        t: SweepTask = o.task
        if o.error is None:
            rows.extend(o.value)
        else:
            rows.extend(_row(t, label, opts, error=o.error) for label, _, opts in t.observers)
    return pd.DataFrame(rows, columns=list(SWEEP_COLUMNS)).astype({"diverged": "boolean"})


def write_table(table: Any, stem: str | Path) -> Path:
    """A DataFrame to ``stem.parquet`` (``stem.csv`` without pyarrow), through a
    temporary file renamed at the end: a failed write leaves no truncated table."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    parquet = importlib.util.find_spec("pyarrow") is not None
    path = stem.with_name(stem.name + (".parquet" if parquet else ".csv"))
    tmp = path.with_name(f".{path.name}.part")
    try:
        if parquet:
            table.to_parquet(tmp, index=False)
        else:
            table.to_csv(tmp, index=False)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


#: The files :func:`write_sweep` writes in its folder: the table (Parquet, or CSV
#: without pyarrow) and the plot.
SWEEP_FILES = ("sweep.parquet", "sweep.csv", "sweep.png")


def check_sweep_out(out_dir: str | Path, *, force: bool = False) -> None:
    """Refuse a folder that holds a sweep's outputs (:data:`SWEEP_FILES`) unless ``force``;
    call it before the runs, as :func:`write_sweep` does before writing.

    Raises:
        OutputExistsError: one of them exists and not ``force``.
    """
    found = [Path(out_dir) / name for name in SWEEP_FILES if (Path(out_dir) / name).exists()]
    if found and not force:
        raise OutputExistsError(
            f"{str(found[0])!r} exists; pass --force (force=True) to overwrite the sweep "
            "in that folder"
        )


def write_sweep(
    table: Any, out_dir: str | Path, *, plot: bool = True, force: bool = False
) -> list[Path]:
    """Save a :func:`sweep` table as ``sweep.parquet`` (``sweep.csv`` without pyarrow) and,
    with matplotlib, ``sweep.png`` (RMS velocity error per observer, one panel per robot
    and scenario, one dot per seed, log scale; no plot when no run succeeded).

    A previous sweep's files in ``out_dir`` are replaced (with ``force``); those this
    sweep does not write (its plot when there is none) are removed, so the folder
    holds one sweep.

    Raises:
        OutputExistsError: a previous sweep's file exists and not ``force``.
    """
    import numpy as np

    out = Path(out_dir)
    check_sweep_out(out, force=force)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_table(table, out / "sweep")]
    finite = table["rms_v_error"].to_numpy(dtype=float) if len(table) else np.zeros(0)
    if not np.any(np.isfinite(finite) & (finite > 0)):
        plot = False  # no run succeeded: nothing to draw on a log scale
    if plot and importlib.util.find_spec("matplotlib") is not None:
        written.append(_plot_sweep(table, out / "sweep.png"))
    # a previous sweep's plot (or table format) would be taken for this one's
    for name in SWEEP_FILES:
        if out / name not in written:
            (out / name).unlink(missing_ok=True)
    return written


def _plot_sweep(table: Any, png: Path) -> Path:
    """:func:`write_sweep`'s plot."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = list(table.groupby(["robot", "scenario"], sort=True))
    fig, axes = plt.subplots(
        1, len(groups), figsize=(3.2 * len(groups), 3.2), squeeze=False, sharey=True
    )
    for ax, ((robot, scenario), g) in zip(axes[0], groups, strict=True):
        labels = list(dict.fromkeys(g["observer"]))
        for i, label in enumerate(labels):
            y = g.loc[g["observer"] == label, "rms_v_error"].to_numpy(dtype=float)
            y = y[np.isfinite(y) & (y > 0)]  # failed runs (NaN) are listed, not drawn
            ax.plot([i] * len(y), y, "o", alpha=0.6)
        ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right")
        ax.set_yscale("log")
        ax.set_title(f"{robot}, {scenario}", fontsize=9)
    axes[0][0].set_ylabel("RMS velocity error [rad/s]")
    fig.tight_layout()
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return png
