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

Dask, pandas and pyarrow are the ``dask`` extra: ``pip install "pinobs[dask]"``.
"""

from __future__ import annotations

import itertools
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pinobs.errors import OptionError

__all__ = ["SweepTask", "TaskOutcome", "run_tasks", "sweep", "sweep_tasks", "write_sweep"]


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


def _guarded(fn: Callable[[Any], Any], task: Any) -> TaskOutcome:
    try:
        return TaskOutcome(task, fn(task))
    except Exception as exc:  # a bad task fails alone, with its reason
        last = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return TaskOutcome(task, None, last)


def run_tasks(
    fn: Callable[[Any], Any],
    tasks: Sequence[Any],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> list[TaskOutcome]:
    """``fn(task)`` for every task on a Dask cluster, in the order of ``tasks``.

    Args:
        fn: a picklable function (module level) of one task.
        tasks: picklable task descriptions.
        scheduler: address of an existing scheduler (``tcp://host:8786``);
            ``None``: a local cluster, closed at the end.
        workers: local worker processes (default: Dask's choice, one per core).
        processes: local workers as processes (``False``: threads, for tests).
        progress: called as ``progress(done, total)`` after each task.

    Returns:
        One :class:`TaskOutcome` per task; a task that raised has ``error`` set.
    """
    dd = _dask()
    if scheduler is not None:
        client = dd.Client(scheduler)
        cluster = None
    else:
        cluster = dd.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=processes, dashboard_address=None
        )
        client = dd.Client(cluster)
    try:
        futures = client.map(_guarded, [fn] * len(tasks), list(tasks), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        out: list[TaskOutcome | None] = [None] * len(tasks)
        for done, fut in enumerate(dd.as_completed(futures), start=1):
            out[index[fut.key]] = fut.result()
            if progress is not None:
                progress(done, len(tasks))
        return [o for o in out if o is not None]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


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
    return [
        SweepTask(r, s, int(k), obs, duration, rate, noise_std)
        for r, s, k in itertools.product(robots, scenarios, seeds)
    ]


def run_sweep_task(task: SweepTask) -> list[dict[str, Any]]:
    """One sweep simulation: rows of (robot, scenario, seed, observer, options, metrics)."""
    from pinobs.evaluation.metrics import evaluate
    from pinobs.model import load
    from pinobs.observers import make_observer
    from pinobs.simulation import Sensor, mismatched_plant, simulate

    robot = load(task.robot)
    plant = mismatched_plant(robot, task.scenario, seed=task.seed)
    obs = {
        label: make_observer(name, robot, rate=task.rate, noise_std=task.noise_std, **dict(opts))
        for label, name, opts in task.observers
    }
    res = simulate(
        robot,
        obs,
        duration=task.duration,
        sensor=Sensor(task.rate, task.noise_std),
        inputs="pd",
        seed=task.seed,
        plant=plant,
    )
    options = {label: dict(opts) for label, _, opts in task.observers}
    return [
        {
            "robot": task.robot,
            "scenario": task.scenario,
            "seed": task.seed,
            "observer": m.observer,
            "options": repr(options[m.observer]),
            "rms_v_error": m.rms_v_error,
            "max_v_error": m.max_v_error,
            "convergence_time": m.convergence_time,
            "diverged": m.diverged_at is not None,
            "error": None,
        }
        for m in evaluate(res, robot)
    ]


def sweep(
    tasks: Sequence[SweepTask],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> Any:
    """Run the tasks on Dask; a tidy ``pandas.DataFrame``, one row per run and observer.

    A run that raised gives one row per observer label with ``error`` set
    (its message) and NaN metrics.
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
            continue
        for label, _, opts in t.observers:
            rows.append(
                {
                    "robot": t.robot,
                    "scenario": t.scenario,
                    "seed": t.seed,
                    "observer": label,
                    "options": repr(dict(opts)),
                    "rms_v_error": float("nan"),
                    "max_v_error": float("nan"),
                    "convergence_time": float("nan"),
                    "diverged": False,
                    "error": o.error,
                }
            )
    return pd.DataFrame(rows)


def write_sweep(table: Any, out_dir: str | Path, *, plot: bool = True) -> list[Path]:
    """Save a :func:`sweep` table as ``sweep.parquet`` (``sweep.csv`` without pyarrow) and,
    with matplotlib, ``sweep.png`` (RMS velocity error per observer, one panel per robot
    and scenario, one dot per seed, log scale)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    try:
        path = out / "sweep.parquet"
        table.to_parquet(path, index=False)
    except ImportError:
        path = out / "sweep.csv"
        table.to_csv(path, index=False)
    written.append(path)
    if plot:
        try:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ImportError:
            return written
        groups = list(table.groupby(["robot", "scenario"], sort=True))
        fig, axes = plt.subplots(
            1, len(groups), figsize=(3.2 * len(groups), 3.2), squeeze=False, sharey=True
        )
        for ax, ((robot, scenario), g) in zip(axes[0], groups, strict=True):
            labels = list(dict.fromkeys(g["observer"]))
            for i, label in enumerate(labels):
                y = g.loc[g["observer"] == label, "rms_v_error"]
                ax.plot([i] * len(y), y, "o", alpha=0.6)
            ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right")
            ax.set_yscale("log")
            ax.set_title(f"{robot}, {scenario}", fontsize=9)
        axes[0][0].set_ylabel("RMS velocity error [rad/s]")
        fig.tight_layout()
        png = out / "sweep.png"
        fig.savefig(png, dpi=100)
        plt.close(fig)
        written.append(png)
    return written
