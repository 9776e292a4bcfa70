"""``pinobs check``: an observer's assumptions on a robot (``ii``: Assumption 1)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from pinobs.cli.options import add_robot_options, load_robot

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle"]


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs check``."""
    p = subparsers.add_parser(
        "check", help="check an observer's assumptions on a robot (ii: Assumption 1)"
    )
    p.add_argument(
        "which", choices=["ii"], help="ii: does the Cholesky factor of M^-1 satisfy D_T = 0?"
    )
    add_robot_options(p, "URDF/MJCF")
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """The check's report; exit code 1 when the assumption fails."""
    from pinobs.observers.ii import check_assumption1

    robot = load_robot(args)
    report = check_assumption1(robot)
    print(report.format())
    return 0 if report.holds else 1
