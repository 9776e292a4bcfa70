"""The ``pinobs`` command: a thin shell over the library.

pinobs list                                    robots and observers
pinobs run --robot R --observer O [...]        one simulation: a results table, JSON
    [--html FILE.html] [--plot FILE.png] [--meshcat]      watch it: 3D playback, plot
pinobs play RESULT.npz [--html F] [--plot F]   watch a saved run
pinobs demo                                    the main job on a built-in default
pinobs estimate --robot R --observer O --log FILE --out FILE    estimates over a recorded log
    [--force --map COL=NAME --topic T --noise STD --latency S]   (CSV/TSV, Parquet, NPZ, ROS bags)
    [--smooth [--lag S|--chunk S] [--accel-psd P|auto] [--band model|noise|inflated]
     [--latency S|auto]]
                                                 RTS smoother (ekf, adaptive, kf), v_std0..
pinobs estimate --robot R --observer O --log 'GLOB'|FOLDER --out-dir OUT   many logs on Dask
    [--workers N | --scheduler tcp://host:8786] [--smooth ...]   one file per log, a summary
pinobs check ii --robot R                      I&I Assumption 1 on the model
pinobs bench [--quick] [--json FILE]           accuracy and cost against the baselines
    [--workers N | --scheduler tcp://host:8786]          its independent runs on Dask
pinobs sweep --robots R1,R2 --seeds 0-9 ...     robots × scenarios × seeds on Dask: a table, a plot
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import shlex
import sys
import warnings
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.errors import (
    DimensionError,
    GainError,
    ModelFileError,
    OptionError,
    OutputExistsError,
    PinobsError,
    PinobsWarning,
    UnsupportedRobotError,
)
from pinobs.evaluation import evaluate, format_table
from pinobs.io import process_log, read_log
from pinobs.io.clock import CLOCK_MODES
from pinobs.model import Robot, aba_time, load, robot_entries
from pinobs.model.identification import MAX_CONDITION
from pinobs.observers import Observer, make_observer, observer_class, observer_names
from pinobs.observers.base import positive
from pinobs.simulation import (
    INPUT_NAMES,
    MISMATCH_SCENARIOS,
    Result,
    Sensor,
    mismatched_plant,
    simulate,
)

__all__ = ["main", "observer_table"]

DEMO_ROBOTS = ("cartpole", "ur5")
#: The UR5 of the demo carries a payload its observers do not know about
#: (:func:`pinobs.simulation.mismatched_plant`), and its playback shows these
#: observers side by side: the model-free Kalman filter, the EKF on the nominal
#: model, and the adaptive observer once it is registered.
DEMO_MISMATCH = {"ur5": "inertia20_payload"}
DEMO_GHOSTS = ("kf", "ekf", *(("adaptive",) if "adaptive" in observer_names() else ()))


# ----------------------------------------------------------------- helpers
@contextmanager
def _progress(label: str, enabled: bool) -> Any:
    """A rich progress bar on an interactive terminal; nothing otherwise."""
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn("{task.description}"), BarColumn(), TimeRemainingColumn(), transient=True
    ) as bar:
        task = bar.add_task(label, total=None)

        def update(k: int, n: int) -> None:
            if k % 100 == 0 or k == n or not n:
                bar.update(task, completed=k, total=n or None)  # n = 0: unknown length

        yield update


@contextmanager
def _task_progress(label: str, enabled: bool) -> Any:
    """:func:`_progress` for whole tasks (Dask runs): redrawn after every task."""
    with _progress(label, enabled) as progress:
        # _progress redraws every 100th step: count in hundredths of a task
        yield None if progress is None else (lambda k, n: progress(100 * k, 100 * n))


def _check_cluster(args: argparse.Namespace) -> None:
    """``--workers`` / ``--scheduler`` of sweep, bench and ``estimate --out-dir``: refused,
    with the flags' names, before any output or work."""
    if args.workers is not None and args.workers < 0:
        raise OptionError(
            f"--workers {args.workers}: give 0 (the tasks one after the other in this process) "
            "or more local worker processes"
        )
    if args.workers is not None and args.scheduler:
        raise OptionError(
            f"--workers {args.workers} with --scheduler {args.scheduler}: the scheduler's "
            "cluster has its own workers; give one or the other"
        )


def _cluster(args: argparse.Namespace) -> str:
    """Where ``--workers`` / ``--scheduler`` run the tasks, in words."""
    if args.scheduler:
        return f"the Dask cluster at {args.scheduler}"
    if args.workers == 0:
        return "this process"
    return f"a local Dask cluster ({args.workers or 'one worker per core'})"


def _observer_list(spec: Sequence[str]) -> list[str]:
    """``--observer`` values: names, comma lists, ``all``; at least one name."""
    names: list[str] = []
    for item in spec:
        for name in item.split(","):
            name = name.strip()
            if name == "all":
                names.extend(observer_names())
            elif name:
                observer_class(name)  # raises UnknownNameError listing the names
                names.append(name)
    if not names:
        raise OptionError(
            f"--observer {','.join(spec)!r} names no observer; give names (pinobs list) or 'all'"
        )
    return list(dict.fromkeys(names))


def _asks_all(spec: Sequence[str]) -> bool:
    """``all`` among the ``--observer`` values (then observers that refuse the robot are skipped)."""
    return any(name.strip() == "all" for item in spec for name in item.split(","))


def _build(
    robot: Robot, names: Sequence[str], sensor: Sensor, *, strict: bool
) -> tuple[dict[str, Observer[Any]], dict[str, str]]:
    """Observers by name; with ``strict=False`` those that refuse the robot are skipped with the reason."""
    built: dict[str, Observer[Any]] = {}
    skipped: dict[str, str] = {}
    for name in names:
        try:
            built[name] = make_observer(name, robot, rate=sensor.rate, noise_std=sensor.noise_std)
        except UnsupportedRobotError as exc:
            if strict:
                raise
            skipped[name] = _short_reason(exc)
    return built, skipped


def _short_reason(exc: UnsupportedRobotError) -> str:
    """Why an observer refuses a robot, in one short clause (its message up to the first ';')."""
    reason = str(exc).split(";")[0]
    return reason if len(reason) <= 110 else reason[:107] + "..."


def _consistency_warnings(reports: dict[str, Any]) -> list[str]:
    """One line per observer whose innovations say the model does not explain the data,
    and per observer that rejected outlier samples (``reports``: name -> Consistency)."""
    return [line for name, c in reports.items() if c is not None for line in c.messages(name)]


def _run_one(
    robot: Robot,
    names: Sequence[str],
    args: argparse.Namespace,
    *,
    strict: bool,
    mismatch: str | None = None,
) -> tuple[Result, dict[str, Any], str]:
    sensor = Sensor(rate=args.rate, noise_std=args.noise, bits=args.bits)
    if args.seed < 0:  # before the plant draws with it
        raise GainError(f"--seed {args.seed}: give an integer >= 0")
    plant = None if mismatch is None else mismatched_plant(robot, mismatch, seed=args.seed)
    observers, skipped = _build(robot, names, sensor, strict=strict)
    with _progress(f"{robot.name}: simulating", not args.no_progress) as progress:
        result = simulate(
            robot,
            observers,
            duration=args.duration,
            sensor=sensor,
            inputs=args.input,
            perturb_q=args.perturb_q,
            perturb_v=args.perturb_v,
            seed=args.seed,
            plant=plant,
            progress=progress,
        )
    metrics = evaluate(result, robot)
    aba = aba_time(robot)
    title = (
        f"{robot.name} (nv = {robot.nv}): {args.duration:g} s at {args.rate:g} Hz, "
        f"noise {args.noise:g}, input {result.meta['input']}, seed {args.seed}, "
        f"start error |dq| = {args.perturb_q:g}, |dv| = {args.perturb_v:g}; "
        f"one pin.aba = {aba * 1e6:.2f} us"
    )
    if mismatch is not None:
        title += f"; the truth is the {mismatch} model, the observers know the nominal one"
    table = format_table(metrics, aba_seconds=aba, title=title)
    if skipped:
        table += "\n" + "\n".join(f"skipped {k}: {v}" for k, v in skipped.items())
    failures = result.meta.get("failures", {})
    if failures:  # why an observer stopped (the table says only when)
        table += "\n" + "\n".join(f"failed {k}: {v}" for k, v in failures.items())
    warnings = _consistency_warnings({k: ob.consistency() for k, ob in observers.items()})
    if warnings:
        table += "\n" + "\n".join(warnings)
    report = {
        "robot": robot.name,
        "nv": robot.nv,
        "meta": result.meta,
        "aba_seconds": aba,
        "skipped": skipped,
        "consistency": {k: ob.consistency().as_dict() for k, ob in observers.items()},
        "rms_v_error": {m.observer: m.rms_v_error for m in metrics},
        "observers": [
            {
                **m.as_dict(),
                "cost_in_aba": m.time_per_update / aba,
                "options": result.trace(m.observer).options,
            }
            for m in metrics
        ],
    }
    return result, report, table


def _json_safe(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_json_safe(v) for v in x]
    return x


def _check_output(flag: str, path: str | Path, *, folder: bool = False) -> None:
    """Refuse an output path that cannot be written, before the work: a file where a
    folder is wanted or the reverse, a parent that is a file, a parent not writable."""
    path = Path(path)
    if path.is_dir() and not folder:
        raise OutputExistsError(f"{flag} {str(path)!r} is a directory; give a file name")
    if path.exists() and folder and not path.is_dir():
        raise OutputExistsError(f"{flag} {str(path)!r} is a file; give a folder")
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise OutputExistsError(
            f"{flag} {str(path)!r}: {str(parent)!r} is a file, not a folder; give another path"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputExistsError(f"{flag} {str(path)!r}: {str(parent)!r} is not writable")


def _write_json(path: str | Path, payload: Any) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_json_safe(payload), indent=2, default=float) + "\n")
    return path


def _watch(result: Result, robot: Robot, args: argparse.Namespace) -> None:
    """``--html`` / ``--plot`` / ``--meshcat``: the visualization layer, imported only when asked."""
    from pinobs.visualization import plot, serve, write_html

    if args.html:
        with _progress(f"{robot.name}: playback", not args.no_progress) as progress:
            path = write_html(result, robot, args.html, progress=progress)
        print(
            f"wrote {path} (open it in a browser; Open Controls -> Animations: play, pause, time)"
        )
    if args.plot:
        print(f"wrote {plot(result, robot, args.plot)}")
    if args.meshcat:
        with serve(result, robot):
            try:
                input("meshcat is serving the playback; press Enter to stop\n")
            except (EOFError, KeyboardInterrupt):
                pass


def observer_table() -> str:
    """The README's observer table, generated from the registry."""
    lines = ["| name | what it is |", "|---|---|"]
    lines += [f"| `{n}` | {observer_class(n).summary} |" for n in observer_names()]
    return "\n".join(lines)


# ------------------------------------------------------------- subcommands
def _cmd_list(args: argparse.Namespace) -> int:
    print("Robots (pinobs.load(name); root joint in brackets):")
    for e in robot_entries():
        print(f"  {e.name:28s} {e.description} [{e.root_joint}] ({e.origin})")
    print("\nObservers (pinobs.make_observer(name, robot, ...)):")
    for name in observer_names():
        print(f"  {name:10s} {observer_class(name).summary}")
    return 0


def _check_outputs(args: argparse.Namespace, flags: Sequence[str]) -> None:
    """The output files of ``flags`` (those given): writable, distinct, a plot's format known."""
    given = {f: getattr(args, f) for f in flags if getattr(args, f, None)}
    seen: dict[Path, str] = {}
    for flag, value in given.items():
        _check_output(f"--{flag}", value)
        path = Path(value).resolve()
        if flag == "plot":
            from pinobs.visualization.plots import plot_path

            path = plot_path(path)  # .png added when no suffix; a format matplotlib lacks refused
        if path in seen:
            raise OutputExistsError(
                f"--{seen[path]} and --{flag} are the same file {value!r}; give each its own"
            )
        seen[path] = flag


def _cmd_run(args: argparse.Namespace) -> int:
    _check_outputs(args, ("json", "save", "html", "plot"))
    robot = _load(args)
    names = _observer_list(args.observer)
    result, report, table = _run_one(robot, names, args, strict=not _asks_all(args.observer))
    print(table)
    if args.json:
        print(f"wrote {_write_json(args.json, report)}")
    if args.save:
        print(f"wrote {result.save(args.save)}")
    _watch(result, robot, args)
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from pinobs.visualization import write_html

    out = Path(args.out)
    _check_output("--out", out, folder=True)
    reports = []
    pages = []
    for name in DEMO_ROBOTS:
        robot = load(name)
        mismatch = DEMO_MISMATCH.get(name)
        result, report, table = _run_one(
            robot, observer_names(), args, strict=False, mismatch=mismatch
        )
        print(table + "\n")
        reports.append(report)
        if mismatch is None:  # ghosts for the three most accurate observers that did not diverge
            ranked = sorted(
                (o for o in report["observers"] if o["diverged_at"] is None),
                key=lambda o: o["rms_v_error"],
            )
            ghosts = [o["observer"] for o in ranked[:3]]
            what = "the 3 best estimates"
        else:
            ghosts = [g for g in DEMO_GHOSTS if g in result.observer_names]
            what = f"{', '.join(ghosts)} (the truth carries a payload their model lacks)"
        with _progress(f"{name}: playback", not args.no_progress) as progress:
            page = write_html(
                result, robot, out / f"{name}_playback.html", observers=ghosts, progress=progress
            )
        pages.append((page, what))
    path = _write_json(out / "demo.json", {"runs": reports})
    print(f"wrote {path}")
    for page, what in pages:
        print(
            f"playback: open {page} in a browser (the robot, {what} as ghosts; "
            "true and estimated velocity charted below)"
        )
    return 0


def _cmd_play(args: argparse.Namespace) -> int:
    _check_outputs(args, ("html", "plot"))
    result = Result.load(args.result)
    source = args.robot or result.meta.get("robot_source") or result.robot
    root = args.root_joint or result.meta.get("root_joint")
    if args.robot is None:
        _check_saved_robot_file(args, str(source), result.meta.get("lock"))
    lock = _lock_option(args.lock)
    mimic = None
    if args.robot is None:  # the run's robot as it was loaded, locked joints and all
        mimic, lock = result.meta.get("mimic"), lock or result.meta.get("lock")
    robot = load(source, root_joint=root, mimic=mimic, lock=lock)
    if robot.name != result.robot and not args.force:
        raise UnsupportedRobotError(
            f"{args.result!r} is a run of {result.robot!r}, not of {robot.name!r}; leave out "
            "--robot, or give --force to play it on this robot"
        )
    if (robot.nq, robot.nv) != (result.q.shape[1], result.v.shape[1]):
        raise DimensionError(
            f"{args.result!r} has nq = {result.q.shape[1]}, nv = {result.v.shape[1]}; robot "
            f"{robot.name!r} has nq = {robot.nq}, nv = {robot.nv}"
        )
    if not (args.html or args.plot or args.meshcat):
        args.html = str(Path(args.result).with_suffix(".html"))
    _watch(result, robot, args)
    return 0


def _check_saved_robot_file(
    args: argparse.Namespace, source: str, result_lock: dict[str, Any] | None = None
) -> None:
    """A run of a robot file that has since moved: the command to play it with the file's new
    path (one found under the same name next to the result or here, else a placeholder)."""
    path = Path(source)
    if path.suffix.lower() not in (".urdf", ".xml", ".mjcf") or path.exists():
        return
    near = [Path(args.result).resolve().parent, Path.cwd()]
    found = sorted(
        {p.resolve() for d in near for p in [*d.glob(path.name), *d.glob(f"*/{path.name}")]}
    )
    new = str(found[0]) if found else f"NEW/PATH/TO/{path.name}"
    argv = ["pinobs", "play", args.result, "--robot", new]
    for flag in ("root_joint", "html", "plot", "meshcat", "force", "no_progress"):
        value = getattr(args, flag)
        if value:  # the other options as given
            argv += ["--" + flag.replace("_", "-")] + ([] if value is True else [value])
    locked = args.lock or [  # the run's locked joints, as it was loaded
        f"{n}={v}" if not isinstance(v, list) else f"{n}={','.join(map(str, v))}"
        for n, v in (result_lock or {}).items()
    ]
    for item in locked:
        argv += ["--lock", item]
    command = " ".join(shlex.quote(a) for a in argv)
    where = (
        f"a file of that name is at {new}; if it is the same robot, play it with"
        if found
        else "if it moved, give its new path"
    )
    raise ModelFileError(
        f"{args.result!r} is a run of the robot file {source!r}, which no longer exists; "
        f"{where}:\n  {command}"
    )


def _column_map(items: Sequence[str] | None) -> dict[str, str] | None:
    """``--map COL=NAME[,COL=NAME]`` -> ``{COL: NAME}``."""
    if not items:
        return None
    out: dict[str, str] = {}
    for item in items:
        for pair in item.split(","):
            col, sep, name = pair.partition("=")
            if not sep or not col.strip() or not name.strip():
                raise DimensionError(
                    f"--map {pair!r}: give COLUMN=NAME, NAME one of t, q.<joint>, tau.<joint>, q3, tau3"
                )
            out[col.strip()] = name.strip()
    return out


def _add_log_columns(p: argparse.ArgumentParser) -> None:
    """``--map`` and ``--topic``: which columns, or which bag topic, a log is read from."""
    p.add_argument(
        "--map",
        action="append",
        default=None,
        metavar="COL=NAME",
        help="rename log columns: NAME is t, q.<joint>, tau.<joint>, q3 or tau3 (repeatable)",
    )
    p.add_argument(
        "--topic", default=None, help="JointState topic of a bag (default: the only one)"
    )


def _cmd_estimate(args: argparse.Namespace) -> int:
    positive("rate", args.rate, allow_none=True)  # (inf divided by zero, 0 meant "from the log")
    if args.max_reports < 0:
        raise OptionError(f"--max-reports {args.max_reports}: give a count >= 0")
    if not args.smooth:  # the smoother's options, given without it, would be ignored
        given = [f for f in ("lag", "chunk", "accel_psd", "band") if getattr(args, f) is not None]
        if given:
            flags = ", ".join("--" + f.replace("_", "-") for f in given)
            raise OptionError(f"{flags}: options of the smoother; add --smooth")
    if args.smooth and args.clock is not None:
        raise OptionError(
            f"--clock {args.clock}: the smoother reads the log's stamps as they are (the "
            "clock repair runs with the filter only, for now)"
        )
    if args.smooth and args.observer == "kf" and args.accel_psd not in (None, "auto"):
        raise OptionError(
            f"--accel-psd {args.accel_psd:g}: kf has no white acceleration; its white-jerk "
            "density is its own (1e3 rad²/s⁵) or, with --accel-psd auto, chosen from the log"
        )
    if args.out_dir is not None:
        _check_cluster(args)
        return _estimate_many(args)
    if args.workers is not None or args.scheduler:  # one log runs here: they were ignored
        flag = "--workers" if args.workers is not None else "--scheduler"
        raise OptionError(
            f"{flag}: many logs run on Dask (--log GLOB|FOLDER --out-dir OUT); one log "
            "(--out) runs in this process"
        )
    if args.smooth:
        return _estimate_smoothed(args)
    robot = _load(args)
    columns = _column_map(args.map)
    keep = bool(args.html)
    with _progress(f"{robot.name}: {args.observer}", not args.no_progress) as progress:
        try:
            run = process_log(
                args.log,
                robot,
                args.observer,
                out=args.out,
                force=args.force,
                keep=keep,
                columns=columns,
                topic=args.topic,
                rate=args.rate,
                noise_std=args.noise,
                options=_observer_options(args),
                progress=progress,
                clock=args.clock or "auto",
            )
        except ModuleNotFoundError as exc:  # the io extra (pandas, pyarrow, rosbags)
            print(f"pinobs: error: {exc}", file=sys.stderr)
            return 2
    for w in run.warnings:
        print(f"warning: {w}", file=sys.stderr)
    for w in _consistency_warnings({args.observer: run.consistency}):
        print(w, file=sys.stderr)
    where = f"{args.log}:" if run.unit == "line" else f"{args.log}: {run.unit} "
    for line, reason in run.bad_rows[: args.max_reports]:
        print(f"{where}{line}: {reason}", file=sys.stderr)
    if len(run.bad_rows) > args.max_reports:
        print(
            f"... and {len(run.bad_rows) - args.max_reports} more reported rows "
            f"(--max-reports N to list more)",
            file=sys.stderr,
        )
    if args.html and run.estimated:
        _log_playback(args, robot, run, args.observer)
    nan = " (every row NaN)" if run.estimated == 0 else ""
    print(f"{args.observer} on {robot.name}: {run.summary()}; wrote {args.out}{nan}")
    if run.estimated == 0:
        print("pinobs: error: no row of the log could be estimated", file=sys.stderr)
        return 1
    return 0


def _log_playback(args: argparse.Namespace, robot: Robot, run: Any, label: str) -> None:
    """``estimate --html``: the logged motion, and the estimates (kept in ``run``) as a ghost."""
    from pinobs.visualization import log_result, write_html

    log = read_log(args.log, robot, columns=_column_map(args.map), topic=args.topic)
    page = write_html(
        log_result(robot, log, {label: run}), robot, args.html, truth_label="measured"
    )
    print(f"wrote {page} (the logged motion, and the estimate as a ghost)")


def _estimate_many(args: argparse.Namespace) -> int:
    """``estimate --log GLOB|FOLDER --out-dir OUT``: every log on Dask, a summary table."""
    from pinobs.evaluation.distributed import (
        TaskOutcome,
        estimate_logs,
        log_summary,
        log_tasks,
        write_table,
    )
    from pinobs.io import find_logs

    if args.html:
        raise OptionError("--html is for one log (--out FILE), not with --out-dir")
    _check_output("--out-dir", args.out_dir, folder=True)  # a file there: refused before any work
    observer_class(args.observer)  # an unknown name: UnknownNameError listing the registered ones
    _load(args)  # a bad robot fails here, not once per log
    found = find_logs(args.log)
    tasks = log_tasks(
        found,
        args.out_dir,
        robot=args.robot,
        observer=args.observer,
        root_joint=args.root_joint,
        friction=True if args.friction else None,
        mimic=args.mimic,
        lock=_lock_option(args.lock),
        force=args.force,
        columns=_column_map(args.map),
        topic=args.topic,
        rate=args.rate,
        noise_std=args.noise,
        options=_observer_options(args),
        clock=args.clock or "auto",
        smooth=None
        if not args.smooth
        else {"lag": args.lag, "chunk": args.chunk, "accel_psd": args.accel_psd, "band": args.band},
    )
    what = f"{args.observer}{' smoothed' if args.smooth else ''}"
    if len(tasks) < len(found):
        print(
            f"note: {len(found) - len(tasks)} of the {len(found)} logs found left out: the "
            f"outputs of an earlier run (in --out-dir {args.out_dir})",
            file=sys.stderr,
        )
    print(f"pinobs estimate: {_plural(len(tasks), 'log')}, {what} on {_cluster(args)}")
    done: dict[Any, TaskOutcome] = {}

    def keep(outcome: TaskOutcome) -> None:
        done[outcome.task] = outcome

    try:
        with _task_progress("estimate", not args.no_progress) as step:
            table = estimate_logs(
                tasks,
                scheduler=args.scheduler,
                workers=args.workers,
                progress=step,
                on_result=keep,
            )
    except KeyboardInterrupt:  # Ctrl-C: the summary of the logs done, the others said
        table = log_summary(
            [done.get(t) or TaskOutcome(t, None, "not done: interrupted") for t in tasks]
        )
        path = write_table(table, Path(args.out_dir) / "summary")
        print(f"wrote {path}")
        print(f"interrupted: {len(done)} of {len(tasks)} logs done", file=sys.stderr)
        return 130
    _print_summary(table, f"{what} on {args.robot}")
    path = write_table(table, Path(args.out_dir) / "summary")
    failed = table[table["error"].notna()]
    written = int(table["out"].notna().sum())  # a log without an estimated row: all NaN
    print(f"wrote {written} estimates files and {path}")
    for _, row in table[table["warnings"].notna()].iterrows():  # as each log alone says them
        for line in row["warnings"].splitlines():
            print(f"{row['log']}: {line}", file=sys.stderr)
    for _, row in failed.iterrows():
        print(f"failed: {row['log']}: {row['error']}", file=sys.stderr)
    if len(failed):
        print(f"pinobs: error: {len(failed)} of {len(table)} logs failed", file=sys.stderr)
        return 1
    return 0


def _print_summary(table: Any, title: str) -> None:
    """The batch summary (without the output paths) as a rich table; errors cut to
    60 characters and warnings counted (they are printed in full below it)."""
    import pandas as pd
    from rich.console import Console
    from rich.table import Table

    shown = table.drop(columns="out")
    shown["warnings"] = table["warnings"].map(lambda w: None if pd.isna(w) else w.count("\n") + 1)
    if shown["warnings"].isna().all():
        shown = shown.drop(columns="warnings")
    if table["rho"].isna().all():
        shown = shown.drop(columns="rho")  # filtered logs: no smoother
    if table["consistency"].isna().all():
        shown = shown.drop(columns="consistency")  # smoothed logs: ρ instead
    if (table["latency"].fillna(0.0) == 0.0).all():
        shown = shown.drop(columns="latency")  # none given or found
    formats = {"sigma": "{:.3g}", "rho": "{:.3g}", "latency": "{:.6g}", "seconds": "{:.1f}"}
    out = Table(title=title)
    for col in shown.columns:
        out.add_column(col, justify="left" if col in ("log", "consistency", "error") else "right")
    for rec in shown.itertuples(index=False):
        cells = [
            "" if pd.isna(x) else formats.get(col, "{}").format(x)
            for col, x in zip(shown.columns, rec, strict=True)
        ]
        if len(cells[-1]) > 60:
            cells[-1] = cells[-1][:59] + "…"
        out.add_row(*cells)
    console = Console()
    Console(width=console.width if console.is_terminal else 160).print(out)


#: ``pinobs identify`` suggests comparing with ``--no-refine`` at or above this smoother
#: consistency: clean simulated logs gave 0.44–14.8, 1 % torque noise 20–183 (where the
#: refinement still helped a UR5), 5 % 108–4500 (where it did not, on average:
#: :mod:`pinobs.observers.calibration`).
SMOOTHER_RHO_HINT = 100.0


def _identify_report(ident: Any) -> str:
    """The identification report as text tables (``pinobs identify``)."""
    rep = ident.report
    lines = [
        f"rows {rep['rows']} fitted, {rep['holdout_rows']} held out; "
        f"{rep['rank']} identifiable combinations of {rep['n_parameters']} parameters; "
        f"condition number {rep['condition']:.3g}"
        + ("; physical consistency enforced" if rep["projected"] else ""),
        "",
        "torque residual RMS per joint (rows weighted by M⁻¹/Δt, rad/s²-like)",
        f"{'joint':24s} {'fit before':>11s} {'fit after':>11s} {'unexplained':>12s} "
        f"{'held-out before':>16s} {'held-out after':>15s}",
    ]
    for j, name in enumerate(rep["coordinates"]):
        lines.append(
            f"{name:24s} {rep['residual_before'][j]:11.4g} {rep['residual_after'][j]:11.4g} "
            + (
                f"{100 * rep['unexplained'][j]:10.3g} % "
                if math.isfinite(rep["unexplained"][j])
                else f"{'no torque':>12s} "
            )
            + f"{rep['holdout_before'][j]:16.4g} {rep['holdout_after'][j]:15.4g}"
        )
    lines += ["", f"{'parameter':32s} {'nominal':>12s} {'identified':>12s} {'std':>10s}"]
    for name, value, std, nominal, excited in ident.parameters.as_rows():
        if excited:
            lines.append(f"{name:32s} {nominal:12.5g} {value:12.5g} {std:10.2g}")
    n_not = len(rep["not_excited"])
    if n_not:
        moved = rep.get("moved_by_consistency", [])
        values = dict(zip(ident.parameters.names, ident.parameters.values, strict=True))
        nominal = dict(zip(ident.parameters.names, ident.parameters.nominal, strict=True))
        lines.append(
            f"({n_not} parameters not excited by this log: "
            + ", ".join(rep["not_excited"][:6])
            + (", ..." if n_not > 6 else "")
            + "; "
            + (
                f"physical consistency moved {len(moved)} of them: "
                + ", ".join(f"{n} {nominal[n]:.4g} → {values[n]:.4g}" for n in moved[:6])
                + (", ..." if len(moved) > 6 else "")
                + "; the others stay near their nominal values)"
                if moved
                else "they stay near their nominal values)"
            )
        )
    rho = rep.get("smoother_consistency", math.nan)
    if math.isfinite(rho):  # observers.calibration's "Limitation: noisy torques"
        lines.append(
            f"velocities: {rep['velocities']}, smoother consistency ρ = {rho:.3g} (about 1 "
            "when the model and the torques explain the positions"
            + (
                "; this high, the torques are likely noisy and the refined fit may be no "
                "better than --no-refine's: compare the two)"
                if rho >= SMOOTHER_RHO_HINT
                else ")"
            )
        )
    lines += [f"warning: {w}" for w in rep.get("warnings", [])]
    if np.any(ident.offset):
        lines.append(
            "torque offset b per joint [N·m] (not stored in the URDF; the model is driven by tau + b: add it to the torques "
            "or let the observer estimate it): " + ", ".join(f"{b:.4g}" for b in ident.offset)
        )
    return "\n".join(lines)


def _cmd_identify(args: argparse.Namespace) -> int:
    from pinobs.observers.calibration import REFINE_ACCEL_PSD, identify

    out = Path(args.out)
    _check_output("--out", out)  # before the work, as the other commands
    robot = _load(args)
    if out.exists() and not args.force:
        raise OutputExistsError(f"{str(out)!r} exists; give --force to overwrite it")
    if out.resolve() == Path(args.log).resolve():
        raise OutputExistsError(f"--out {str(out)!r} is the log itself")
    log = read_log(args.log, robot, columns=_column_map(args.map), topic=args.topic)
    ident = identify(
        robot,
        log,
        friction=not args.no_friction,
        offset=args.offset,
        holdout=args.holdout,
        max_condition=args.max_condition,
        torque=args.torque,
        refine=() if args.no_refine else REFINE_ACCEL_PSD,
    )
    print(_identify_report(ident))
    path = ident.save(str(out))
    opts = ", ".join(f"{k}={v:g}" for k, v in ident.report["observer_options"].items())
    root = robot.root_joint if robot.root_joint not in (None, "fixed") else None
    how = f"{path!r}, friction=True" + ("" if root is None else f", root_joint={root!r}")
    cli = f"--robot {path} --friction" + ("" if root is None else f" --root-joint {root}")
    print(f"wrote {path}: load it with pinobs.load({how}) (pinobs estimate: {cli})")
    print(
        f"run ekf or riemannian on it with {opts or 'their default options'}, or adaptive "
        "starting from it"
    )
    return 0


def _cmd_excite(args: argparse.Namespace) -> int:
    from pinobs.model.excitation import excite

    robot = _load(args)
    out = Path(args.out)
    _check_output("--out", out)
    if out.exists() and not args.force:
        raise OutputExistsError(f"{str(out)!r} exists; give --force to overwrite it")
    exc = excite(robot, duration=args.duration, rate=args.rate, seed=args.seed)
    out.parent.mkdir(parents=True, exist_ok=True)  # as run and sweep do
    names = exc.joint_names
    header = ["t"] + [f"{k}.{n}" for k in ("q", "v", "a", "tau") for n in names]
    table = np.column_stack([exc.t, exc.q, exc.v, exc.a, exc.tau])
    tmp = out.with_name(out.name + ".tmp")
    np.savetxt(tmp, table, delimiter=",", header=",".join(header), comments="", fmt="%.10g")
    tmp.replace(out)
    print(
        f"wrote {out}: {exc.t.size} samples over {args.duration:g} s, regressor condition number "
        f"{exc.condition:.3g}; peak |v| {np.abs(exc.v).max():.3g} rad/s, peak |tau| "
        f"{np.abs(exc.tau).max():.3g} N·m (nominal model)"
    )
    return 0


# ------------------------------------------------- estimate --smooth (issue 19)
def _number_or_auto(what: str) -> Callable[[str], float | str]:
    """An argparse type: a number (``what`` names it in the error) or ``"auto"``."""

    def parse(text: str) -> float | str:
        if text == "auto":
            return text
        try:
            return float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {what} or 'auto'") from None

    return parse


def _observer_options(args: argparse.Namespace) -> dict[str, Any] | None:
    """The observer's options ``estimate`` gives (``--latency``), or ``None``."""
    if args.latency is None:
        return None
    if args.latency == "auto" and not args.smooth:
        raise OptionError(
            "--latency auto is chosen from the whole log by the smoother: add --smooth, or "
            "give the latency in seconds"
        )
    return {"latency": args.latency}


def _estimate_smoothed(args: argparse.Namespace) -> int:
    """``estimate --smooth``: the RTS smoother over the log (read and screened as ``estimate``
    reads it, written atomically by the io writer); ``estimate``'s columns plus ``v_std0..``."""
    from pinobs.io.smoothing import smooth_log
    from pinobs.observers.smoothing import AUTO_WHITE_SCALE

    robot = _load(args)
    try:
        run, stretches = smooth_log(
            args.log,
            robot,
            args.out,
            observer=args.observer,
            noise_std=args.noise,
            accel_psd=args.accel_psd,
            lag=args.lag,
            chunk=args.chunk,
            force=args.force,
            columns=_column_map(args.map),
            topic=args.topic,
            rate=args.rate,
            band=args.band,
            options=_observer_options(args),
            stream=not args.html,  # the playback needs the estimates kept
        )
    except ModuleNotFoundError as exc:  # the io extra (pandas, pyarrow, rosbags)
        print(f"pinobs: error: {exc}", file=sys.stderr)
        return 2
    for w in run.warnings:
        print(f"warning: {w}", file=sys.stderr)
    where = f"{args.log}:" if run.unit == "line" else f"{args.log}: {run.unit} "
    for line, reason in run.bad_rows[: args.max_reports]:
        print(f"{where}{line}: {reason}", file=sys.stderr)
    if len(run.bad_rows) > args.max_reports:
        print(
            f"... and {len(run.bad_rows) - args.max_reports} more reported rows "
            f"(--max-reports N to list more)",
            file=sys.stderr,
        )
    for i, opts in enumerate(stretches):
        if len(stretches) > 1:  # each stretch between gaps is smoothed on its own
            a, b = opts["t_span"]
            print(
                f"stretch {i + 1} of {len(stretches)}, t = {a:.6g} to {b:.6g} s:", file=sys.stderr
            )
        print(
            f"filter–smoother consistency ρ = {opts['consistency']:.3g} (about 1: the densities "
            "explain the log; ≫ 1: too small, the band is too narrow; < 1: too large)",
            file=sys.stderr,
        )
        if opts.get("band") in ("noise", "inflated"):
            scaled = (
                f", times √max(1, ρ) = {opts['band_scale']:.3g} for the model error ρ shows"
                if opts["band"] == "inflated"
                else ""
            )
            print(
                f"v_std: the smoothed error driven by the measurement noise alone{scaled} "
                f"(--band {opts['band']}; a model error that is smooth in time cancels in the "
                "smoother)",
                file=sys.stderr,
            )
        if opts.get("offset_scale") is not None:
            print(
                f"densities chosen from the log (ρ = 1): offset × {opts['offset_scale']:.3g}, "
                f"white acceleration × {AUTO_WHITE_SCALE:g} of each window's regime's",
                file=sys.stderr,
            )
        if opts.get("latency_from_log"):
            print(f"latency = {opts['latency']:.6g} s (chosen from the log)", file=sys.stderr)
        if args.accel_psd == "auto" and opts["accel_psd"] is not None:
            print(
                f"accel_psd = {opts['accel_psd']:g} rad²/s³ (chosen from the log)", file=sys.stderr
            )
        if args.accel_psd == "auto" and args.observer == "kf":
            print(
                f"jerk_psd = {opts['jerk_psd']:.3g} rad²/s⁵ (chosen from the log)", file=sys.stderr
            )
        if "model_window" in opts:
            print(
                f"{args.observer}: learned model frozen per {opts['model_window']:g} s window "
                f"(the model held at each window's end; regimes {'/'.join(opts['model_regimes'])})",
                file=sys.stderr,
            )
    mode = "whole log" if args.lag is None else f"lag {args.lag:g} s"
    if args.chunk is not None:
        mode = f"chunks of {args.chunk:g} s"
    if args.html and run.estimated:
        _log_playback(args, robot, run, f"{args.observer} smoothed")
    nan = " (every row NaN)" if run.estimated == 0 else ""
    print(
        f"smoothed {args.observer} on {robot.name} ({mode}): {run.summary()}; wrote {args.out}{nan}"
    )
    if run.estimated == 0:
        print("pinobs: error: no row of the log could be smoothed", file=sys.stderr)
        return 1
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from pinobs.observers.ii import check_assumption1

    robot = _load(args)
    report = check_assumption1(robot)
    print(report.format())
    return 0 if report.holds else 1


def _cmd_bench(args: argparse.Namespace) -> int:
    from pinobs.evaluation.bench import BenchConfig, bench_tasks, format_bench, run_bench

    _check_cluster(args)
    if args.workers is None and not args.scheduler:
        args.workers = 0  # bench's default: its timings not loaded by each other
    cfg = BenchConfig.quick() if args.quick else BenchConfig()
    print(
        f"pinobs bench ({'quick' if args.quick else 'full'}): robots {', '.join(cfg.robots)}; timing also {', '.join(cfg.cost_robots)}"
    )
    print(f"independent runs on {_cluster(args)}")
    report = run_bench(
        cfg,
        log=lambda msg: print(msg, flush=True),
        scheduler=args.scheduler,
        workers=args.workers,
    )
    print(format_bench(report))
    print(
        f"\nbench took {report['seconds']:.0f} s on {report['machine']['processor']} ({report['machine']['system']})"
    )
    if args.json:
        print(f"wrote {_write_json(args.json, report)}")
    if report["failed"]:
        n = len(bench_tasks(cfg))
        print(f"pinobs: error: {len(report['failed'])} of {n} bench tasks failed", file=sys.stderr)
        return 1
    return 0


def _parse_seeds(spec: str) -> list[int]:
    """``"0-4"`` -> 0..4, ``"0,3,7"`` -> those; seeds >= 0, each once, ranges not empty."""
    seeds: list[int] = []
    for part in spec.split(","):
        part = part.strip()
        lo, dash, hi = part.partition("-")
        if not lo.isdigit() or (dash and not hi.isdigit()):  # '5-', '0--2', '-1', 'x'
            raise OptionError(
                f"--seeds {spec!r}: {part!r} is not a seed or a range; give seeds >= 0 as "
                "'0-9' or '0,3,7'"
            )
        first, last = int(lo), int(hi if dash else lo)
        if first > last:
            raise OptionError(f"--seeds {spec!r}: the range {part!r} is empty; give LOW-HIGH")
        seeds.extend(range(first, last + 1))
    _no_repeats("--seeds", spec, seeds)
    return seeds


def _no_repeats(flag: str, spec: str, items: list[Any]) -> None:
    """Refuse a list that names an entry twice (a repeated run, skewing the medians)."""
    repeated = sorted({x for x in items if items.count(x) > 1})
    if repeated:
        raise OptionError(
            f"{flag} {spec!r} names {', '.join(map(str, repeated))} more than once; each would "
            "run the same simulations again"
        )


def _unique_list(flag: str, spec: str) -> list[str]:
    """A comma list of names; refused when empty or when a name repeats (a repeated run)."""
    items = [x.strip() for x in spec.split(",")]
    if not all(items):
        raise OptionError(f"{flag} {spec!r}: an empty name; give a comma-separated list")
    _no_repeats(flag, spec, items)
    return items


def _option_value(text: str) -> Any:
    """A sweep option's value: an int, a float, true/false, or the string itself."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


#: Options every sweep observer gets from the sweep's own flags.
_SWEEP_SHARED = {"rate": "--rate", "noise_std": "--noise"}


def _parse_sweep_observers(spec: str) -> dict[str, tuple[str, dict[str, Any]]]:
    """``"kf,ekf+d=ekf:disturbance_psd=1"``: a name, or ``label=name:key=value;key=value``.

    Values are ints, floats, ``true``/``false`` or strings; labels are unique.
    """
    out: dict[str, tuple[str, dict[str, Any]]] = {}
    for item in spec.split(","):
        item = item.strip()
        if not item:
            raise OptionError(f"--observers {spec!r}: an empty entry; give a comma-separated list")
        head, _, opts = item.partition(":")
        label, eq, name = head.partition("=")
        if not eq:
            label = name = head
        label, name = label.strip(), name.strip()
        if not label or not name:
            raise OptionError(
                f"--observers {item!r}: give NAME, NAME:key=value or LABEL=NAME:key=value"
            )
        observer_class(name)  # an unknown name: UnknownNameError listing the registered ones
        options: dict[str, Any] = {}
        for kv in filter(None, (x.strip() for x in opts.split(";"))):
            key, sep, value = kv.partition("=")
            key = key.strip()
            if not sep or not key or not value.strip():
                raise OptionError(f"--observers {item!r}: option {kv!r} is not key=value")
            if key in _SWEEP_SHARED:
                raise OptionError(
                    f"--observers {item!r}: {key} is the same for every observer of a sweep; "
                    f"give {_SWEEP_SHARED[key]}"
                )
            options[key] = _option_value(value)
        if label in out:
            raise OptionError(
                f"--observers {spec!r}: the label {label!r} is used twice; give each entry its "
                "own label (LABEL=NAME:key=value)"
            )
        out[label] = (name, options)
    return out


def _cmd_sweep(args: argparse.Namespace) -> int:
    from pinobs.evaluation.distributed import check_sweep_out, sweep, sweep_tasks, write_sweep

    # everything a run would refuse, refused here once rather than in every task
    _check_cluster(args)
    positive("--duration", args.duration)
    positive("--rate", args.rate)
    positive("--noise", args.noise, allow_zero=True)
    if args.duration * args.rate < 1.0:
        raise GainError(
            f"--duration {args.duration:g} s is shorter than one sample at {args.rate:g} Hz"
        )
    _check_output("--out", args.out, folder=True)
    check_sweep_out(args.out, force=args.force)
    robots = _unique_list("--robots", args.robots)
    scenarios = _unique_list("--scenarios", args.scenarios)
    unknown = [s for s in scenarios if s not in MISMATCH_SCENARIOS]
    if unknown:
        raise OptionError(
            f"--scenarios: unknown {', '.join(map(repr, unknown))}; give some of "
            + ", ".join(MISMATCH_SCENARIOS)
        )
    seeds = _parse_seeds(args.seeds)
    observers = _parse_sweep_observers(args.observers)
    refusals = []
    for robot_name in robots:  # a bad robot or observer option fails here, not once per task
        robot = load(robot_name)
        for label, (name, options) in observers.items():
            try:
                make_observer(name, robot, rate=args.rate, noise_std=args.noise, **options)
            except UnsupportedRobotError as exc:  # its rows fail alone, the others run
                refusals.append(
                    f"warning: {label} refuses {robot_name}: {_short_reason(exc)}; its "
                    f"{_plural(len(scenarios) * len(seeds), 'run')} there are reported as failed"
                )
    tasks = sweep_tasks(
        robots,
        scenarios,
        seeds,
        observers,
        duration=args.duration,
        rate=args.rate,
        noise_std=args.noise,
    )
    for line in refusals:
        print(line, file=sys.stderr)
    print(f"pinobs sweep: {_plural(len(tasks), 'run')} on {_cluster(args)}")
    with _task_progress("sweep", not args.no_progress) as step:
        table = sweep(tasks, scheduler=args.scheduler, workers=args.workers, progress=step)
    failed = table[table["error"].notna()]
    for line in _failed_runs(failed):
        print(line, file=sys.stderr)
    if len(failed) == len(table):  # not one observer ran
        print(f"pinobs: error: 0 of {_plural(len(tasks), 'run')} succeeded", file=sys.stderr)
    else:
        # over every run: a robot and scenario where an observer always failed shows NaN
        summary = (
            table.groupby(["robot", "scenario", "observer"], sort=False)["rms_v_error"]
            .median()
            .unstack("observer")
        )
        print("median RMS velocity error [rad/s] over seeds (nan: every run failed):")
        print(summary.to_string(float_format=lambda x: f"{x:.3g}"))
        if len(failed):
            print(
                f"pinobs: error: {len(failed)} of {len(table)} observer runs failed",
                file=sys.stderr,
            )
    for path in write_sweep(table, args.out, force=args.force):
        print(f"wrote {path}")
    return 0 if failed.empty else 1


def _failed_runs(failed: Any) -> list[str]:
    """The failed rows of a sweep, one line per robot, scenario, observers and error,
    with the seeds where they failed."""
    runs: dict[tuple[str, str, int, str], list[str]] = {}
    for r in failed.itertuples(index=False):
        runs.setdefault((r.robot, r.scenario, r.seed, r.error), []).append(r.observer)
    lines: dict[tuple[str, str, tuple[str, ...], str], list[int]] = {}
    for (robot, scenario, seed, error), labels in runs.items():
        lines.setdefault((robot, scenario, tuple(labels), error), []).append(int(seed))
    return [
        f"failed: {', '.join(labels)} on {robot} {scenario}, "
        f"seed{'s' if len(seeds) > 1 else ''} {_seed_spec(seeds)}: {error}"
        for (robot, scenario, labels, error), seeds in lines.items()
    ]


def _seed_spec(seeds: Sequence[int]) -> str:
    """Seeds as :func:`_parse_seeds` reads them: ``[0, 1, 2, 5]`` -> ``"0-2,5"``."""
    parts: list[str] = []
    for _, group in itertools.groupby(enumerate(sorted(seeds)), lambda x: x[1] - x[0]):
        run = [s for _, s in group]
        parts.append(str(run[0]) if len(run) == 1 else f"{run[0]}-{run[-1]}")
    return ",".join(parts)


def _plural(n: int, word: str) -> str:
    """``1 run``, ``2 runs``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


# ------------------------------------------------------------------ parser
def _add_sim_options(p: argparse.ArgumentParser, *, duration: float) -> None:
    p.add_argument(
        "--duration", type=float, default=duration, help="simulated time [s] (default %(default)s)"
    )
    p.add_argument(
        "--rate", type=float, default=1000.0, help="sample rate [Hz] (default %(default)s)"
    )
    p.add_argument(
        "--noise",
        type=float,
        default=1e-4,
        help="position noise std [rad or m] (default %(default)s)",
    )
    p.add_argument(
        "--bits", type=int, default=None, help="encoder resolution [bits/turn] (default: none)"
    )
    p.add_argument(
        "--seed", type=int, default=0, help="seed of every random draw (default %(default)s)"
    )
    p.add_argument(
        "--input",
        choices=INPUT_NAMES,
        default=None,
        help="input profile (default: pd, tracking a multi-sine reference)",
    )
    p.add_argument(
        "--perturb-q",
        type=float,
        default=0.05,
        help="initial configuration error [rad] (default %(default)s)",
    )
    p.add_argument(
        "--perturb-v",
        type=float,
        default=0.5,
        help="initial velocity error [rad/s] (default %(default)s)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_robot_options(p: argparse.ArgumentParser, files: str = "URDF/MJCF") -> None:
    """``--robot`` and ``--root-joint``, the options of every subcommand that loads a robot."""
    p.add_argument("--robot", required=True, help=f"robot name (pinobs list) or {files} path")
    p.add_argument(
        "--root-joint", default=None, choices=["fixed", "spherical", "freeflyer", "planar"]
    )
    p.add_argument(
        "--friction",
        action="store_true",
        help="the URDF's joint friction (<dynamics damping friction>, as pinobs identify "
        "writes it) in the dynamics (default: off for URDFs)",
    )
    p.add_argument(
        "--mimic",
        default=None,
        choices=["error", "independent"],
        help="URDF <mimic> joints: refuse them (default for files) or load each as a joint "
        "of its own (default for robot names)",
    )
    _add_lock_option(p)


def _add_lock_option(p: argparse.ArgumentParser) -> None:
    """``--lock JOINT[=VALUE]`` (repeatable): :func:`pinobs.load`'s ``lock``."""
    p.add_argument(
        "--lock",
        action="append",
        default=None,
        metavar="JOINT[=VALUE]",
        help="lock a joint the log does not have (a gripper's fingers) at VALUE [rad or m; "
        "a continuous joint's angle; nq comma-separated numbers for other joints], default "
        "its neutral value (0); the locked bodies move with their parent (repeatable)",
    )


def _lock_option(items: Sequence[str] | None) -> list[str] | dict[str, Any] | None:
    """``--lock J1 --lock J2=0.02`` -> ``{"J1": None, "J2": 0.02}`` (names alone: a list)."""
    if not items:
        return None
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not name:
            raise OptionError(f"--lock {item!r}: give JOINT or JOINT=VALUE")
        if name in out:
            raise OptionError(f"--lock names joint {name!r} twice; give each joint once")
        if not sep:
            out[name] = None
            continue
        try:
            values = [float(x) for x in text.split(",")]
        except ValueError:
            raise OptionError(
                f"--lock {item!r}: VALUE {text!r} is not a number; give JOINT=VALUE with VALUE "
                "in rad (revolute, continuous) or m (prismatic), or the joint's nq numbers "
                "comma-separated, or JOINT alone for its neutral value"
            ) from None
        if not all(np.isfinite(values)):
            raise OptionError(f"--lock {item!r}: VALUE {text!r} is not finite")
        out[name] = values[0] if len(values) == 1 else values
    if all(v is None for v in out.values()):
        return list(out)
    return out


def _load(args: argparse.Namespace) -> Robot:
    """The robot of ``--robot``, ``--root-joint``, ``--friction``, ``--mimic`` and ``--lock``."""
    friction = True if getattr(args, "friction", False) else None
    mimic = getattr(args, "mimic", None)
    lock = _lock_option(getattr(args, "lock", None))
    return load(args.robot, root_joint=args.root_joint, friction=friction, mimic=mimic, lock=lock)


def _add_cluster_options(p: argparse.ArgumentParser, workers_help: str) -> None:
    """``--workers`` and ``--scheduler``: where independent tasks run (Dask; checked by
    :func:`_check_cluster`)."""
    p.add_argument("--workers", type=int, default=None, help=workers_help)
    p.add_argument(
        "--scheduler",
        default=None,
        help="address of a running Dask scheduler (tcp://host:8786), instead of a local cluster",
    )


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pinobs", description="Velocity observers for any URDF robot."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="list robots and observers")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("run", help="simulate a robot and compare observers")
    _add_robot_options(p, "URDF/MJCF")
    p.add_argument(
        "--observer",
        action="append",
        required=True,
        help="observer name, comma list, or 'all' (repeatable)",
    )
    p.add_argument("--json", default=None, help="write the metrics to this JSON file")
    p.add_argument("--save", default=None, help="write the whole result to this .npz file")
    p.add_argument(
        "--html", default=None, help="write a self-contained 3D playback (meshcat) to this file"
    )
    p.add_argument(
        "--meshcat", action="store_true", help="serve the playback on a local meshcat server"
    )
    p.add_argument(
        "--plot", default=None, help="write true vs estimated velocities to this PNG (matplotlib)"
    )
    _add_sim_options(p, duration=3.0)
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("play", help="watch a result saved by run --save (3D playback, plot)")
    p.add_argument("result", help=".npz file written by pinobs run --save")
    p.add_argument("--robot", default=None, help="robot (default: the one stored in the result)")
    p.add_argument(
        "--root-joint", default=None, choices=["fixed", "spherical", "freeflyer", "planar"]
    )
    p.add_argument("--html", default=None, help="playback page (default: RESULT.html)")
    p.add_argument("--meshcat", action="store_true", help="serve it on a local meshcat server")
    p.add_argument("--plot", default=None, help="write true vs estimated velocities to this PNG")
    p.add_argument(
        "--force",
        action="store_true",
        help="play it on a --robot of another name (same nq and nv)",
    )
    _add_lock_option(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_play)

    p = sub.add_parser(
        "estimate", help="run one observer over a recorded log (CSV/TSV, Parquet, NPZ, ROS bag)"
    )
    _add_robot_options(p, "URDF/MJCF")
    p.add_argument("--observer", required=True, help="observer name (pinobs list)")
    p.add_argument(
        "--log",
        required=True,
        help="log: CSV/TSV with columns t, q0.. or q.<joint>, tau0.. or tau.<joint>; Parquet; "
        "NPZ with t, q, tau; a ROS 1/2 bag (sensor_msgs/JointState)",
    )
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", help="CSV file for the estimates: t, q0.., v0..")
    where.add_argument(
        "--out-dir",
        default=None,
        help="many logs (--log a folder or a quoted glob 'logs/*.csv'): one estimates CSV per "
        "log in this folder and summary.parquet; on Dask (--workers, --scheduler)",
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    _add_log_columns(p)
    p.add_argument(
        "--clock",
        choices=CLOCK_MODES,
        default=None,
        help="the log's clock: auto (default: repair the stamps of a fixed-rate loop seen "
        "through a jittery logger clock, skip stale rows, when the motion clearly says so), "
        "stamps (as stamped), loop (always the loop's clock); the filter only",
    )
    p.add_argument(
        "--html", default=None, help="also write a 3D playback of the log and the estimate"
    )
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        help="sample rate [Hz] (default: from the log's median interval)",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=None,
        help="position noise std [rad or m] (default: estimated from the log's first second)",
    )
    p.add_argument(
        "--max-reports",
        type=int,
        default=20,
        help="reported rows listed at most (default %(default)s)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--smooth",
        action="store_true",
        help="RTS smoother over ekf, adaptive or the model-free kf (uses the whole log; with "
        "--out-dir, each "
        "log's); adds v_std0.. columns; σ from --noise, else estimated from the log's first "
        "second (reported)",
    )
    p.add_argument(
        "--lag", type=float, default=None, help="with --smooth: fixed-lag mode, S seconds"
    )
    p.add_argument(
        "--chunk",
        type=float,
        default=None,
        help="with --smooth: memory bound, backward passes over S seconds (+ overlap); "
        "same result as the whole log to 1e-5 of v_std",
    )
    p.add_argument(
        "--latency",
        type=_number_or_auto("a latency [s]"),
        default=None,
        help="measurement latency [s]: the row stamped t was measured at t - LATENCY "
        "(the observer's latency=); with --smooth also 'auto' (the likeliest from the log)",
    )
    p.add_argument(
        "--accel-psd",
        type=_number_or_auto("a number [rad²/s³]"),
        default=None,
        help="with --smooth: process noise [rad²/s³], or 'auto' (from the log: ekf by "
        "likelihood, adaptive by the consistency ρ = 1, kf its white jerk by likelihood); "
        "default: the observer's (ekf 1e-8; adaptive: each window's regime; kf 1e3 rad²/s⁵)",
    )
    p.add_argument(
        "--band",
        choices=("model", "noise", "inflated"),
        default=None,
        help="with --smooth: what v_std states: 'model', the smoother's covariance under the "
        "filter's noise model; 'noise', its error driven by the measurement noise alone "
        "(a smooth model error cancels); 'inflated', the noise band times √max(1, ρ), "
        "widened by the model error the log shows; default: inflated over adaptive and kf, "
        "model over ekf",
    )
    _add_cluster_options(
        p, "with --out-dir: local worker processes (0: this process; default: one per core)"
    )
    p.set_defaults(func=_cmd_estimate)

    p = sub.add_parser(
        "check", help="check an observer's assumptions on a robot (ii: Assumption 1)"
    )
    p.add_argument(
        "which", choices=["ii"], help="ii: does the Cholesky factor of M^-1 satisfy D_T = 0?"
    )
    _add_robot_options(p, "URDF/MJCF")
    p.set_defaults(func=_cmd_check)

    p = sub.add_parser(
        "identify", help="identify inertias and friction from a log; write a calibrated URDF"
    )
    _add_robot_options(p, "URDF")
    p.add_argument(
        "--log",
        required=True,
        help="log with t, q and tau columns (CSV, Parquet, NPZ or a ROS bag, as estimate reads)",
    )
    _add_log_columns(p)
    p.add_argument("--out", required=True, help="the calibrated URDF to write")
    p.add_argument("--no-friction", action="store_true", help="do not identify joint friction")
    p.add_argument(
        "--offset",
        action="store_true",
        help="also identify a torque offset per joint (a biased torque sensor; not in the URDF)",
    )
    p.add_argument(
        "--holdout",
        type=float,
        default=0.2,
        help="fraction of the log (its end) kept out of the fit for the report (default %(default)s)",
    )
    p.add_argument(
        "--max-condition",
        type=float,
        default=MAX_CONDITION,
        help="refuse a log whose identifiable combinations are worse conditioned than this "
        "(default %(default)g)",
    )
    p.add_argument(
        "--torque",
        choices=["held", "sampled"],
        default="held",
        help="how the log's torques were taken: held over each sample (zero-order hold: "
        "pinobs run, most controllers; the default) or sampled at the instants (pinobs "
        "excite's trajectory)",
    )
    p.add_argument(
        "--no-refine",
        action="store_true",
        help="fit once, on Savitzky–Golay velocities, without the model-based smoother's "
        "refinement passes (compare when the report's smoother consistency is in the "
        "hundreds: noisy torques)",
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=_cmd_identify)

    p = sub.add_parser("excite", help="write an excitation trajectory for identification")
    p.add_argument("--robot", required=True, help="robot name (pinobs list) or URDF path")
    p.add_argument("--root-joint", default=None, choices=["fixed"])
    _add_lock_option(p)
    p.add_argument("--duration", type=float, default=20.0, help="length [s] (default %(default)s)")
    p.add_argument(
        "--rate", type=float, default=100.0, help="samples per second (default %(default)s)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the search (default %(default)s)")
    p.add_argument("--out", required=True, help="CSV to write (t, q.*, v.*, a.*, tau.*)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=_cmd_excite)

    p = sub.add_parser("bench", help="accuracy and cost of every observer against the baselines")
    p.add_argument("--quick", action="store_true", help="two robots, short runs: under two minutes")
    p.add_argument("--json", default=None, help="write the full report to this JSON file")
    _add_cluster_options(
        p,
        "its independent runs on a local Dask cluster of N processes (default 0: "
        "one after the other in this process; workers load each other's timings)",
    )
    p.set_defaults(func=_cmd_bench)

    p = sub.add_parser(
        "sweep",
        help="robots × scenarios × seeds × observer options on Dask: a tidy table and a plot",
    )
    p.add_argument("--robots", default="ur5", help="comma-separated (default %(default)s)")
    p.add_argument(
        "--scenarios",
        default="exact",
        help="mismatch scenarios, comma-separated: " + ", ".join(MISMATCH_SCENARIOS),
    )
    p.add_argument("--seeds", default="0-4", help="'0-9' or '0,3,7' (default %(default)s)")
    p.add_argument(
        "--observers",
        default="ekf,kf",
        help="names, or label=name:key=value;key=value (e.g. 'ekf+d=ekf:disturbance_psd=1')",
    )
    p.add_argument("--out", default="sweep", help="output folder (default %(default)s)")
    p.add_argument("--force", action="store_true", help="overwrite a sweep in --out")
    _add_cluster_options(p, "local worker processes (0: this process; default: one per core)")
    p.add_argument("--duration", type=float, default=3.0, help="per run [s] (default %(default)s)")
    p.add_argument(
        "--rate", type=float, default=1000.0, help="sample rate [Hz] (default %(default)s)"
    )
    p.add_argument(
        "--noise", type=float, default=1e-4, help="position noise std (default %(default)s)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_sweep)

    p = sub.add_parser(
        "demo",
        help="every observer on the cart-pole and a UR5 with an unknown payload: tables, JSON, playback",
    )
    p.add_argument("--out", default="out", help="output folder (default %(default)s)")
    _add_sim_options(p, duration=5.0)
    p.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pinobs`` command; returns the exit code."""
    args = _parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return func(args)
    except PinobsError as exc:
        print(f"pinobs: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # an output the system refused (a full disk, permissions, ...)
        print(f"pinobs: error: {exc}", file=sys.stderr)
        return 1


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: Any = None,
    line: str | None = None,
) -> None:
    """A pinobs warning as ``warning: …`` (as a run's own warnings; not Python's file and
    line); others as usual."""
    if issubclass(category, PinobsWarning):
        print(f"warning: {message}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
