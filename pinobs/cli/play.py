"""``pinobs play``: watch a result saved by ``run --save`` (3D playback, plot)."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pinobs.cli.options import ROOT_JOINTS, add_lock_option, add_progress_option, lock_option
from pinobs.cli.output import check_outputs, watch
from pinobs.errors import DimensionError, ModelFileError, UnsupportedRobotError
from pinobs.model import load
from pinobs.simulation import Result

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle"]


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs play``."""
    p = subparsers.add_parser("play", help="watch a result saved by run --save (3D playback, plot)")
    p.add_argument("result", help=".npz file written by pinobs run --save")
    p.add_argument("--robot", default=None, help="robot (default: the one stored in the result)")
    p.add_argument("--root-joint", default=None, choices=ROOT_JOINTS)
    p.add_argument("--html", default=None, help="playback page (default: RESULT.html)")
    p.add_argument("--meshcat", action="store_true", help="serve it on a local meshcat server")
    p.add_argument("--plot", default=None, help="write true vs estimated velocities to this PNG")
    p.add_argument(
        "--force",
        action="store_true",
        help="play it on a --robot of another name (same nq and nv)",
    )
    add_lock_option(p)
    add_progress_option(p)
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """The saved run on its robot (or ``--robot``): a page (the default), a plot, meshcat."""
    check_outputs(args, ("html", "plot"))
    result = Result.load(args.result)
    source = args.robot or result.meta.get("robot_source") or result.robot
    root = args.root_joint or result.meta.get("root_joint")
    if args.robot is None:
        _check_saved_robot_file(args, str(source), result.meta.get("lock"))
    lock = lock_option(args.lock)
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
    watch(result, robot, args)
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
