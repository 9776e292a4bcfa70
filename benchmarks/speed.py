# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Issue 18's numbers: update cost (× one ``pin.aba`` call), pickles, BLAS threads.

Writes ``benchmarks/speed.md``.  Costs are :func:`pinobs.evaluation.measure_cost`
ratios (chunks of updates each followed by as many ``pin.aba`` calls, same
process); the spread is min / median / max over ``--repeats`` measurements
with different seeds.  Quote the machine's load next to them: on a shared
machine the spread is wide.

    python benchmarks/speed.py             # about 5 minutes
    python benchmarks/speed.py --quick     # UR5 only, two repeats
    python benchmarks/speed.py --cpu       # CPU time: a loaded machine

``--cpu``: the cost chunks timed by ``time.thread_time`` (this thread's CPU time, the
``clock`` of :func:`~pinobs.evaluation.measure_cost`), for a shared machine, where wall
time waits for a core (at load 7–11 on 2 cores, go1 ``ekf`` read 178× ``pin.aba`` by wall
time).
"""

from __future__ import annotations

import argparse
import os
import pickle
import time
from pathlib import Path

import numpy as np

import pinobs
from pinobs.evaluation import measure_cost

OBSERVERS = ("ekf", "kalman", "riemannian", "kf")
ROBOTS = ("ur5", "panda", "go1", "talos")

#: The clock of the cost chunks (``--cpu``: this thread's CPU time).
CLOCK = {"wall": time.perf_counter, "cpu": time.thread_time}


def cost_table(robots: tuple[str, ...], repeats: int, samples: int, clock: str) -> list[str]:
    rows = ["| robot (nv) | " + " | ".join(OBSERVERS) + " |", "|---" * (len(OBSERVERS) + 1) + "|"]
    for name in robots:
        robot = pinobs.load(name)
        cells = []
        for obs in OBSERVERS:
            ob = pinobs.make_observer(obs, robot, rate=1000.0, noise_std=1e-4)
            r = [
                measure_cost(ob, samples=samples, rounds=5, seed=s, clock=CLOCK[clock])["ratio"]
                for s in range(repeats)
            ]
            cells.append(f"{np.median(r):.1f} ({min(r):.1f}–{max(r):.1f})")
        rows.append(f"| {name} ({robot.nv}) | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
    return rows


def blas_rows(name: str, repeats: int, samples: int, clock: str) -> list[str]:
    """``ekf`` on a large robot with BLAS limited to one thread (the default now) and not."""
    robot = pinobs.load(name)
    ob = pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
    c = CLOCK[clock]
    one = [
        measure_cost(ob, samples=samples, rounds=5, seed=s, clock=c)["ratio"]
        for s in range(repeats)
    ]
    free = [
        measure_cost.__wrapped__(ob, samples=samples, rounds=5, seed=s, clock=c)["ratio"]  # type: ignore[attr-defined]
        for s in range(repeats)
    ]
    return [
        f"`ekf` on {name} (nv = {robot.nv}, P is {2 * robot.nv}²): "
        f"one BLAS thread {np.median(one):.0f}× aba ({min(one):.0f}–{max(one):.0f}), "
        f"default threads {np.median(free):.0f}× ({min(free):.0f}–{max(free):.0f})."
    ]


def pickle_rows() -> list[str]:
    rows = []
    for name in ("ur5", "go1"):
        t = time.perf_counter()
        robot = pinobs.load(name)
        load = time.perf_counter() - t
        size = len(pickle.dumps(robot))
        rows.append(f"`pinobs.load({name!r})` {load:.3f} s; pickled `Robot` {size / 1e3:.0f} kB.")
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--cpu", action="store_true", help="CPU time, not wall (module doc)")
    parser.add_argument("--out", default=str(Path(__file__).parent / "speed.md"))
    args = parser.parse_args()
    robots = ("ur5",) if args.quick else ROBOTS
    repeats = 2 if args.quick else args.repeats
    clock = "cpu" if args.cpu else "wall"
    flags = (" --quick" if args.quick else "") + (" --cpu" if args.cpu else "")
    timed = (
        "this thread's CPU time (`time.thread_time`)"
        if args.cpu
        else "wall time (`time.perf_counter`)"
    )
    start = time.time()
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    lines = [
        f"Made by `python benchmarks/speed.py{flags}` "
        f"(load average at start {load} on {os.cpu_count()} CPUs: a shared machine, "
        "so read the spreads).",
        "",
        "Cost per update, × one `pin.aba` call (median, min–max over "
        f"{repeats} seeds; 1 kHz, σ = 1e-4 rad; {timed}):",
        "",
        *cost_table(robots, repeats, 600, clock),
        "",
        *blas_rows("talos", repeats, 200, clock),
        "",
        "Start-up (`make_observer` and the first update in fresh processes, numba's cache "
        "warm): `benchmarks/startup.py`, `benchmarks/startup.md`.",
        "",
        *pickle_rows(),
        "",
        f"({time.time() - start:.0f} s)",
    ]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
