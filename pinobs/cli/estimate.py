"""``pinobs estimate``: one observer over a recorded log (CSV/TSV, Parquet, NPZ, ROS bag),
filtered or smoothed (``--smooth``, issue 19), one log (``--out``) or many on Dask
(``--out-dir``)."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pinobs.cli.options import (
    add_clock_option,
    add_cluster_options,
    add_drive_options,
    add_log_columns,
    add_progress_option,
    add_robot_options,
    check_cluster,
    cluster_name,
    column_map,
    drives_option,
    load_robot,
    lock_option,
    log_source,
    progress,
    rate_not_used,
    read_args_log,
    task_progress,
)
from pinobs.cli.output import check_output, consistency_warnings, plural
from pinobs.errors import OptionError, OutputExistsError
from pinobs.io import process_log
from pinobs.model import Robot
from pinobs.observers import observer_class
from pinobs.observers.base import positive

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle"]


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs estimate``."""
    p = subparsers.add_parser(
        "estimate", help="run one observer over a recorded log (CSV/TSV, Parquet, NPZ, ROS bag)"
    )
    add_robot_options(p, "URDF/MJCF")
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
    add_log_columns(p)
    add_drive_options(p)
    add_clock_option(p)
    p.add_argument(
        "--html", default=None, help="also write a 3D playback of the log and the estimate"
    )
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        help="sample rate [Hz] (default: from the log's median interval); a CSV/TSV or "
        "Parquet log without a t column is read as sampled at it (row k at t = k/R; with "
        "--observer inekf, only that)",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=None,
        help="position noise std [rad or m] (default: estimated from the log's first second)",
    )
    p.add_argument(
        "--alone",
        action="store_true",
        help="a model-based observer alone; by default a log runs it never behind kf, "
        "blended per joint (pinobs.observers.neverbehind: a model that does not explain the "
        "log on a joint gives way to kf there)",
    )
    p.add_argument(
        "--max-reports",
        type=int,
        default=20,
        help="reported rows listed at most (default %(default)s)",
    )
    add_progress_option(p)
    _add_smoother_options(p)
    _add_legged_options(p)
    add_cluster_options(
        p, "with --out-dir: local worker processes (0: this process; default: one per core)"
    )
    p.set_defaults(func=handle)
    return p


def _add_legged_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "legged robots (--observer inekf: imu.* and force.*/contact.* columns)"
    )
    g.add_argument(
        "--imu-frame",
        default=None,
        help="the IMU's frame in the model (default: imu_link if the model has one, else the base)",
    )
    g.add_argument(
        "--contact-force",
        type=float,
        nargs="+",
        metavar=("ON", "OFF"),
        default=None,
        help="a foot touches from ON [N] until its force falls to OFF (default OFF = ON/2; "
        "default ON = 0.15 of the robot's weight, OFF = 0.075)",
    )
    g.add_argument(
        "--contacts",
        choices=("force", "probability"),
        default=None,
        help="force: the log's contact.* flags or the force threshold (default); probability: "
        "SEROW's force x foot-speed probability (the speed from the filter)",
    )
    g.add_argument(
        "--foot-gate",
        type=float,
        default=None,
        metavar="P",
        help="gate each foot by its own innovation (outlier probability P, e.g. 1e-3): a foot "
        "that slips is re-anchored instead of dragging the base",
    )
    g.add_argument(
        "--foot-radius",
        type=_number_or_urdf,
        default=None,
        metavar="R|urdf",
        help="the feet's sphere radius R [m]: each foot measured at its point that touched "
        "the ground (rolling feet); default 'urdf', the URDF's foot collision spheres (go1 "
        "0.02 m; 0 where a foot has none): on the MuJoCo go1 benchmark it lowers the trot's "
        "base velocity error 0.0123 -> 0.0084 m/s and the sway's 0.0112 -> 0.0090, the "
        "stand's unchanged; 0: the foot frames, as before",
    )


def _add_smoother_options(p: argparse.ArgumentParser) -> None:
    """``--smooth`` and its options (``--latency`` is the filter's too)."""
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


def _number_or_urdf(text: str) -> float | str:
    """``--foot-radius``: a radius [m] (its sign checked by the runner) or ``"urdf"``."""
    if text == "urdf":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a foot radius [m] or 'urdf'") from None


def handle(args: argparse.Namespace) -> int:
    """The options checked, then one log filtered or smoothed, or many logs on Dask."""
    _check_options(args)
    if args.out_dir is not None:
        check_cluster(args)
        return _estimate_many(args)
    if args.workers is not None or args.scheduler:  # one log runs here: they were ignored
        flag = "--workers" if args.workers is not None else "--scheduler"
        raise OptionError(
            f"{flag}: many logs run on Dask (--log GLOB|FOLDER --out-dir OUT); one log "
            "(--out) runs in this process"
        )
    if args.observer == INEKF:
        return _estimate_legged(args)
    if args.smooth:
        return _estimate_smoothed(args)
    return _estimate_filtered(args)


def _check_options(args: argparse.Namespace) -> None:
    """Options refused before any work: out of range, or given where they would be ignored."""
    _check_legged_options(args)
    positive("rate", args.rate, allow_none=True)  # (inf divided by zero, 0 meant "from the log")
    if args.max_reports < 0:
        raise OptionError(f"--max-reports {args.max_reports}: give a count >= 0")
    if not args.smooth:  # the smoother's options, given without it, would be ignored
        given = [f for f in ("lag", "chunk", "accel_psd", "band") if getattr(args, f) is not None]
        if given:
            flags = ", ".join("--" + f.replace("_", "-") for f in given)
            raise OptionError(f"{flags}: options of the smoother; add --smooth")
    if args.alone and (args.smooth or args.observer == INEKF):
        what = "the smoother" if args.smooth else INEKF
        raise OptionError(f"--alone: {what} runs its observer alone (no never-behind blend)")
    if args.smooth and args.observer == "kf" and args.accel_psd not in (None, "auto"):
        raise OptionError(
            f"--accel-psd {args.accel_psd:g}: kf has no white acceleration; its white-jerk "
            "density is its own (1e3 rad²/s⁵) or, with --accel-psd auto, chosen from the log"
        )


def _observer_options(args: argparse.Namespace) -> dict[str, Any] | None:
    """The observer's options ``estimate`` gives (``--latency``, ``--alone``), or ``None``."""
    options: dict[str, Any] = {"never_behind": False} if args.alone else {}
    if args.latency is None:
        return options or None
    if args.latency == "auto" and not args.smooth:
        raise OptionError(
            "--latency auto is chosen from the whole log by the smoother: add --smooth, or "
            "give the latency in seconds"
        )
    return {**options, "latency": args.latency}


def _estimate_filtered(args: argparse.Namespace) -> int:
    """``estimate --out``: the observer over one log, its warnings and reported rows."""
    robot = load_robot(args)
    columns = column_map(args.map)
    keep = bool(args.html)
    with progress(f"{robot.name}: {args.observer}", not args.no_progress) as step:
        try:
            run = process_log(
                log_source(args),
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
                progress=step,
                clock=args.clock or "auto",
                drives=drives_option(args),
            )
        except ModuleNotFoundError as exc:  # the io extra (pandas, pyarrow, rosbags)
            print(f"pinobs: error: {exc}", file=sys.stderr)
            return 2
    for w in run.warnings:
        print(f"warning: {w}", file=sys.stderr)
    for w in consistency_warnings({args.observer: run.consistency}):
        print(w, file=sys.stderr)
    _print_bad_rows(args, run)
    if args.html and run.estimated:
        _log_playback(args, robot, run, args.observer)
    nan = " (every row NaN)" if run.estimated == 0 else ""
    print(f"{args.observer} on {robot.name}: {run.summary()}; wrote {args.out}{nan}")
    if run.estimated == 0:
        print("pinobs: error: no row of the log could be estimated", file=sys.stderr)
        return 1
    return 0


def _print_bad_rows(args: argparse.Namespace, run: Any) -> None:
    """The log's reported rows, ``--max-reports`` of them at most, on stderr."""
    where = f"{args.log}:" if run.unit == "line" else f"{args.log}: {run.unit} "
    for line, reason in run.bad_rows[: args.max_reports]:
        print(f"{where}{line}: {reason}", file=sys.stderr)
    if len(run.bad_rows) > args.max_reports:
        print(
            f"... and {len(run.bad_rows) - args.max_reports} more reported rows "
            f"(--max-reports N to list more)",
            file=sys.stderr,
        )


def _log_playback(
    args: argparse.Namespace,
    robot: Robot,
    run: Any,
    label: str,
    log: Any = None,
    what: str = "the logged motion",
) -> None:
    """``estimate --html``: the logged motion (``log``, read again if not given), and the
    estimates (kept in ``run``) as a ghost."""
    from pinobs.visualization import log_result, write_html

    if log is None:
        log = read_args_log(args, robot)
    page = write_html(
        log_result(robot, log, {label: run}), robot, args.html, truth_label="measured"
    )
    print(f"wrote {page} ({what}, and the estimate as a ghost)")


# ------------------------------------------------- estimate --observer inekf (issue 38)
#: The legged robots' observer: not a registry family (IMU, legs and contacts, not q and τ).
INEKF = "inekf"


def _check_legged_options(args: argparse.Namespace) -> None:
    legged = [
        f
        for f in ("imu_frame", "contact_force", "contacts", "foot_gate", "foot_radius")
        if getattr(args, f) is not None
    ]
    if args.observer != INEKF:
        if legged:
            flags = ", ".join("--" + f.replace("_", "-") for f in legged)
            raise OptionError(f"{flags}: options of --observer {INEKF} (legged robots)")
        return
    given = [
        flag
        for flag, on in (
            ("--out-dir", args.out_dir is not None),
            ("--smooth", args.smooth),
            ("--latency", args.latency is not None),
            ("--noise", args.noise is not None),
        )
        if on
    ]
    if given:
        raise OptionError(f"{', '.join(given)}: not available with --observer {INEKF}")
    if args.contact_force is not None and len(args.contact_force) > 2:
        raise OptionError("--contact-force takes ON [N] and optionally OFF [N]")


def _estimate_legged(args: argparse.Namespace) -> int:
    """``estimate --observer inekf``: the base from the IMU, the legs and the contacts."""
    from pinobs.io.legged_run import estimate_legged
    from pinobs.io.writers import write_estimates

    robot = load_robot(args)
    check_output("--out", args.out)
    if Path(args.out).exists() and not args.force:  # (before the work, not after it)
        raise OutputExistsError(f"--out {args.out!r} exists; pass --force to overwrite it")
    with warnings.catch_warnings(record=True) as caught:  # (shown once: the log's notes too)
        warnings.simplefilter("always")
        log = read_args_log(args, robot)
    for said in caught:
        warnings.showwarning(said.message, said.category, said.filename, said.lineno)
    warned = {str(said.message) for said in caught}
    on, off = [*(args.contact_force or []), None, None][:2]
    run = estimate_legged(
        robot,
        log,
        imu_frame=args.imu_frame,
        contact_on=on,
        contact_off=off,
        contacts=args.contacts or "force",
        foot_gate=args.foot_gate,
        foot_radius="urdf" if args.foot_radius is None else args.foot_radius,
    )
    write_estimates(args.out, run, force=args.force)
    # (the note that the base pose is not in the log: this observer fills it)
    notes = [n for n in log.notes if not n.startswith("the base pose") and n not in warned]
    for w in (*notes, rate_not_used(args.rate, log), *run.warnings):
        if w:
            print(f"warning: {w}", file=sys.stderr)
    _print_bad_rows(args, run)
    c = run.consistency
    if c is not None and c.samples:
        print(
            f"{INEKF}: feet's NIS over {c.samples} stance rows: {c.mean_nis:.3g} per degree of "
            f"freedom (expected 1), {100 * c.details['inside']:.0f} % inside their 95 % χ² "
            f"interval ({100 * c.details['below']:.0f} % below, {100 * c.details['above']:.0f} "
            f"% above){f'; {c.gated} foot measurements gated' if c.gated else ''}"
        )
        for w in consistency_warnings({INEKF: replace(c, gated=0)}):
            print(w, file=sys.stderr)
    if args.html and run.estimated:
        # the legs as measured on the estimated base (a legged log has no base pose to show)
        shown = replace(log, q=np.where(np.isnan(log.q), run.q, log.q))
        _log_playback(args, robot, run, INEKF, shown, "the measured legs on the estimated base")
    print(f"{INEKF} on {robot.name}: {run.summary()}; wrote {args.out}")
    return 0 if run.estimated else 1


# ------------------------------------------------- estimate --smooth (issue 19)
def _estimate_smoothed(args: argparse.Namespace) -> int:
    """``estimate --smooth``: the RTS smoother over the log (read and screened as ``estimate``
    reads it, written atomically by the io writer); ``estimate``'s columns plus ``v_std0..``."""
    from pinobs.io.smoothing import smooth_log

    robot = load_robot(args)
    try:
        run, stretches = smooth_log(
            log_source(args),
            robot,
            args.out,
            observer=args.observer,
            noise_std=args.noise,
            accel_psd=args.accel_psd,
            lag=args.lag,
            chunk=args.chunk,
            force=args.force,
            columns=column_map(args.map),
            topic=args.topic,
            rate=args.rate,
            band=args.band,
            options=_observer_options(args),
            clock=args.clock or "auto",
            drives=drives_option(args),
            stream=not args.html,  # the playback needs the estimates kept
        )
    except ModuleNotFoundError as exc:  # the io extra (pandas, pyarrow, rosbags)
        print(f"pinobs: error: {exc}", file=sys.stderr)
        return 2
    for w in run.warnings:
        print(f"warning: {w}", file=sys.stderr)
    _print_bad_rows(args, run)
    for i, opts in enumerate(stretches):
        if len(stretches) > 1:  # each stretch between gaps is smoothed on its own
            a, b = opts["t_span"]
            print(
                f"stretch {i + 1} of {len(stretches)}, t = {a:.6g} to {b:.6g} s:", file=sys.stderr
            )
        _print_stretch(args, opts)
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


def _print_stretch(args: argparse.Namespace, opts: dict[str, Any]) -> None:
    """What the smoother says of one stretch of the log (its consistency, the band, what it
    chose from the log), on stderr."""
    from pinobs.smoothing import AUTO_WHITE_SCALE

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
        print(f"accel_psd = {opts['accel_psd']:g} rad²/s³ (chosen from the log)", file=sys.stderr)
    if args.accel_psd == "auto" and args.observer == "kf":
        print(f"jerk_psd = {opts['jerk_psd']:.3g} rad²/s⁵ (chosen from the log)", file=sys.stderr)
    if "model_window" in opts:
        print(
            f"{args.observer}: learned model frozen per {opts['model_window']:g} s window "
            f"(the model held at each window's end; regimes {'/'.join(opts['model_regimes'])})",
            file=sys.stderr,
        )


# ------------------------------------------------------ estimate --out-dir
def _estimate_many(args: argparse.Namespace) -> int:
    """``estimate --log GLOB|FOLDER --out-dir OUT``: every log on Dask, a summary table."""
    from pinobs.evaluation.distributed import TaskOutcome, write_table
    from pinobs.evaluation.many_logs import estimate_logs, log_summary, log_tasks
    from pinobs.io import find_logs

    if args.html:
        raise OptionError("--html is for one log (--out FILE), not with --out-dir")
    if args.join:
        raise OptionError("--join is for one log (--out FILE), not with --out-dir")
    check_output("--out-dir", args.out_dir, folder=True)  # a file there: refused before any work
    observer_class(args.observer)  # an unknown name: UnknownNameError listing the registered ones
    load_robot(args)  # a bad robot fails here, not once per log
    found = find_logs(args.log)
    tasks = log_tasks(
        found,
        args.out_dir,
        robot=args.robot,
        observer=args.observer,
        root_joint=args.root_joint,
        friction=True if args.friction else None,
        mimic=args.mimic,
        lock=lock_option(args.lock),
        check=not args.no_check,
        force=args.force,
        columns=column_map(args.map),
        topic=args.topic,
        rate=args.rate,
        noise_std=args.noise,
        options=_observer_options(args),
        clock=args.clock or "auto",
        drives=drives_option(args),
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
    print(f"pinobs estimate: {plural(len(tasks), 'log')}, {what} on {cluster_name(args)}")
    done: dict[Any, TaskOutcome] = {}

    def keep(outcome: TaskOutcome) -> None:
        done[outcome.task] = outcome

    try:
        with task_progress("estimate", not args.no_progress) as step:
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
    return _report_many(args, table, what)


def _report_many(args: argparse.Namespace, table: Any, what: str) -> int:
    """The batch's summary printed and written, each log's warnings and failure said."""
    from pinobs.evaluation.distributed import write_table

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
