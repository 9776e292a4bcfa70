"""``pinobs demo``: every observer on the cart-pole and on a UR5 with an unknown payload:
tables, JSON, playback pages."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from pinobs.cli.options import add_sim_options, progress
from pinobs.cli.output import check_output, write_json
from pinobs.cli.run import run_one
from pinobs.model import load
from pinobs.observers import observer_names

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["DEMO_GHOSTS", "DEMO_MISMATCH", "DEMO_ROBOTS", "add_parser", "handle"]

DEMO_ROBOTS = ("cartpole", "ur5")
#: The UR5 of the demo carries a payload its observers do not know about
#: (:func:`pinobs.simulation.mismatched_plant`), and its playback shows these
#: observers side by side: the model-free Kalman filter, the EKF on the nominal
#: model, and the adaptive observer once it is registered.
DEMO_MISMATCH = {"ur5": "inertia20_payload"}
DEMO_GHOSTS = ("kf", "ekf", *(("adaptive",) if "adaptive" in observer_names() else ()))


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs demo``."""
    p = subparsers.add_parser(
        "demo",
        help="every observer on the cart-pole and a UR5 with an unknown payload: tables, JSON, playback",
    )
    p.add_argument("--out", default="out", help="output folder (default %(default)s)")
    add_sim_options(p, duration=5.0)
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """Each demo robot's run: its table, ``demo.json``, a playback page with ghosts."""
    from pinobs.visualization import write_html

    out = Path(args.out)
    check_output("--out", out, folder=True)
    reports = []
    pages = []
    for name in DEMO_ROBOTS:
        robot = load(name)
        mismatch = DEMO_MISMATCH.get(name)
        result, report, table = run_one(
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
        with progress(f"{name}: playback", not args.no_progress) as step:
            page = write_html(
                result, robot, out / f"{name}_playback.html", observers=ghosts, progress=step
            )
        pages.append((page, what))
    path = write_json(out / "demo.json", {"runs": reports})
    print(f"wrote {path}")
    for page, what in pages:
        print(
            f"playback: open {page} in a browser (the robot, {what} as ghosts; "
            "true and estimated velocity charted below)"
        )
    return 0
