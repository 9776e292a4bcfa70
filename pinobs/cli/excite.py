"""``pinobs excite``: an excitation trajectory for identification, as a CSV."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pinobs.cli.options import add_lock_option, load_robot
from pinobs.cli.output import check_output
from pinobs.errors import OutputExistsError

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle"]


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs excite``."""
    p = subparsers.add_parser("excite", help="write an excitation trajectory for identification")
    p.add_argument("--robot", required=True, help="robot name (pinobs list) or URDF path")
    p.add_argument("--root-joint", default=None, choices=["fixed"])
    add_lock_option(p)
    p.add_argument("--duration", type=float, default=20.0, help="length [s] (default %(default)s)")
    p.add_argument(
        "--rate", type=float, default=100.0, help="samples per second (default %(default)s)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the search (default %(default)s)")
    p.add_argument("--out", required=True, help="CSV to write (t, q.*, v.*, a.*, tau.*)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """The trajectory searched, written atomically, summarised."""
    from pinobs.model.excitation import excite

    robot = load_robot(args)
    out = Path(args.out)
    check_output("--out", out)
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
