"""The options several commands share, each with what reads it.

The robot (``--robot``, ``--root-joint``, ``--friction``, ``--mimic``, ``--lock``;
:func:`load_robot`), a log's columns (``--map``, ``--topic``; :func:`column_map`),
its clock (``--clock``), a simulation (``--duration`` ... ``--perturb-v``), where
independent tasks run (``--workers``, ``--scheduler``; :func:`check_cluster`), and
the progress bar (``--no-progress``; :func:`progress`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import numpy as np

from pinobs.errors import DimensionError, OptionError
from pinobs.io.clock import CLOCK_MODES
from pinobs.io.drives import Drives
from pinobs.io.readers import Log, read_log
from pinobs.io.readers.table import sampled_note
from pinobs.model import Robot, load
from pinobs.simulation import INPUT_NAMES

if TYPE_CHECKING:
    #: What each command module's ``add_parser`` is given (``add_subparsers()``'s action).
    Subparsers = argparse._SubParsersAction[argparse.ArgumentParser]

__all__ = [
    "ROOT_JOINTS",
    "add_clock_option",
    "add_cluster_options",
    "add_drive_options",
    "add_join_option",
    "add_lock_option",
    "add_log_columns",
    "add_progress_option",
    "add_robot_options",
    "add_sim_options",
    "check_cluster",
    "cluster_name",
    "column_map",
    "drives_option",
    "load_robot",
    "lock_option",
    "log_source",
    "progress",
    "task_progress",
]

#: ``--root-joint`` of the commands that load any robot.
ROOT_JOINTS = ["fixed", "spherical", "freeflyer", "planar"]


# ------------------------------------------------------------------ robot
def add_robot_options(p: argparse.ArgumentParser, files: str = "URDF/MJCF") -> None:
    """``--robot`` and ``--root-joint``, the options of every subcommand that loads a robot."""
    p.add_argument("--robot", required=True, help=f"robot name (pinobs list) or {files} path")
    p.add_argument("--root-joint", default=None, choices=ROOT_JOINTS)
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
    p.add_argument(
        "--no-check",
        action="store_true",
        help="load a model the sanity check refuses (a singular mass matrix, massless "
        "links; pinobs.load(check=False)): its estimates may then fail",
    )
    add_lock_option(p)


def add_lock_option(p: argparse.ArgumentParser) -> None:
    """``--lock JOINT[=VALUE]`` (repeatable): :func:`pinobs.load`'s ``lock``."""
    p.add_argument(
        "--lock",
        action="append",
        default=None,
        metavar="JOINT[=VALUE]",
        help="lock a joint the log does not have (a gripper's fingers) at VALUE [rad or m; "
        "a continuous joint's angle; nq comma-separated numbers for other joints], default "
        "its neutral value (0); the locked bodies move with their parent; JOINT may be a "
        "quoted shell pattern, 'hand_*' (repeatable)",
    )


def lock_option(items: Sequence[str] | None) -> list[str] | dict[str, Any] | None:
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


def load_robot(args: argparse.Namespace) -> Robot:
    """The robot of ``--robot``, ``--root-joint``, ``--friction``, ``--mimic``, ``--lock`` and
    ``--no-check``."""
    friction = True if getattr(args, "friction", False) else None
    mimic = getattr(args, "mimic", None)
    lock = lock_option(getattr(args, "lock", None))
    check = not getattr(args, "no_check", False)
    return load(
        args.robot,
        root_joint=args.root_joint,
        friction=friction,
        mimic=mimic,
        lock=lock,
        check=check,
    )


# -------------------------------------------------------------------- log
def add_log_columns(p: argparse.ArgumentParser) -> None:
    """``--map``, ``--topic`` and ``--join``: which columns, or which bag topic, a log is read
    from, and the tables joined to it."""
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
    add_join_option(p)


def rate_not_used(rate: float | None, log: Log) -> str | None:
    """What to say when ``--rate`` is only the sample rate of a log without ``t`` (``identify``,
    ``estimate --observer inekf``: no observer takes it) and ``log`` has its own times;
    ``None`` when it was used or not given."""
    if rate is None or sampled_note(rate) in log.notes:
        return None
    return f"--rate {rate:g} not used: the log has its own times (a t column, NPZ t or bag stamps)"


def column_map(items: Sequence[str] | None) -> dict[str, str] | None:
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


def add_drive_options(p: argparse.ArgumentParser) -> None:
    """The drives (:class:`pinobs.io.Drives`): motor positions and currents read as the
    joints', torque columns scaled."""
    g = p.add_argument_group(
        "drives",
        "a log's motor-side columns: qm.<joint> motor positions [rad] and i.<joint> currents "
        "[A] read as q = T⁻¹ qm + offset and tau = Tᵀ (k i), T = diag(gear ratio) or the "
        "transmission matrix of coupled joints; one number per joint, comma-separated",
    )
    g.add_argument(
        "--torque-scale", default=None, metavar="S1,S2,..", help="multiply the tau columns"
    )
    g.add_argument(
        "--gear-ratio", default=None, metavar="N1,N2,..", help="motor turns per joint turn"
    )
    g.add_argument(
        "--transmission",
        default=None,
        metavar="ROW;ROW;..",
        help="T (n × n, motor = T · joint), rows separated by ';' (coupled joints; instead "
        "of --gear-ratio)",
    )
    g.add_argument(
        "--motor-constant", default=None, metavar="K1,K2,..", help="motor torque per ampere [N·m/A]"
    )
    g.add_argument(
        "--position-offset",
        default=None,
        metavar="Q1,Q2,..",
        help="added to the joint positions from the motors [rad or m]",
    )


def drives_option(args: argparse.Namespace) -> Drives | None:
    """The :class:`pinobs.io.Drives` of :func:`add_drive_options`' flags, ``None`` without any."""
    return Drives.from_options(
        gear_ratio=getattr(args, "gear_ratio", None),
        transmission=getattr(args, "transmission", None),
        motor_constant=getattr(args, "motor_constant", None),
        torque_scale=getattr(args, "torque_scale", None),
        position_offset=getattr(args, "position_offset", None),
    )


def add_join_option(p: argparse.ArgumentParser) -> None:
    """``--join TABLE`` (repeatable): :func:`pinobs.io.join_tables` with ``--log``."""
    p.add_argument(
        "--join",
        action="append",
        default=None,
        metavar="TABLE",
        help="another CSV/TSV/Parquet table of the same samples, joined to --log's columns on "
        "equal t (a JointState exported as position, velocity and effort tables; repeatable)",
    )


def log_source(args: argparse.Namespace) -> Any:
    """What ``--log`` names: its path, or with ``--join`` the tables joined on ``t``
    (:func:`pinobs.io.join_tables`, a DataFrame: read whole, not in chunks)."""
    joined = getattr(args, "join", None)
    if not joined:
        return args.log
    from pinobs.io.readers.join import join_tables

    return join_tables([args.log, *joined])


def read_args_log(args: argparse.Namespace, robot: Robot) -> Log:
    """``--log`` read as the command's options say (``--join``, ``--map``, ``--topic``, the
    drives, ``--rate``): :func:`pinobs.io.read_log`."""
    return read_log(
        log_source(args),
        robot,
        columns=column_map(args.map),
        topic=args.topic,
        drives=drives_option(args),
        rate=getattr(args, "rate", None),
    )


def add_clock_option(p: argparse.ArgumentParser) -> None:
    """``--clock``: how a log's stamps are read (:mod:`pinobs.io.clock`)."""
    p.add_argument(
        "--clock",
        choices=CLOCK_MODES,
        default=None,
        help="the log's clock: auto (default: repair the stamps of a fixed-rate loop seen "
        "through a jittery logger clock, skip stale rows, when the motion clearly says so), "
        "stamps (as stamped), loop (always the loop's clock)",
    )


# ------------------------------------------------------------- simulation
def add_sim_options(p: argparse.ArgumentParser, *, duration: float) -> None:
    """A simulation's options (``run``, ``demo``), ``--no-progress`` last."""
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
    add_progress_option(p)


# ---------------------------------------------------------------- cluster
def add_cluster_options(p: argparse.ArgumentParser, workers_help: str) -> None:
    """``--workers`` and ``--scheduler``: where independent tasks run (Dask; checked by
    :func:`check_cluster`)."""
    p.add_argument("--workers", type=int, default=None, help=workers_help)
    p.add_argument(
        "--scheduler",
        default=None,
        help="address of a running Dask scheduler (tcp://host:8786), instead of a local cluster",
    )


def check_cluster(args: argparse.Namespace) -> None:
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


def cluster_name(args: argparse.Namespace) -> str:
    """Where ``--workers`` / ``--scheduler`` run the tasks, in words."""
    if args.scheduler:
        return f"the Dask cluster at {args.scheduler}"
    if args.workers == 0:
        return "this process"
    return f"a local Dask cluster ({args.workers or 'one worker per core'})"


# --------------------------------------------------------------- progress
def add_progress_option(p: argparse.ArgumentParser) -> None:
    """``--no-progress``: :func:`progress`'s ``enabled``."""
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


@contextmanager
def progress(label: str, enabled: bool) -> Any:
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
def task_progress(label: str, enabled: bool) -> Any:
    """:func:`progress` for whole tasks (Dask runs): redrawn after every task."""
    with progress(label, enabled) as step:
        # progress redraws every 100th step: count in hundredths of a task
        yield None if step is None else (lambda k, n: step(100 * k, 100 * n))
