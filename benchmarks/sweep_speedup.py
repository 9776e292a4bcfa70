# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[dask]"]
# ///
"""Dask speed-up of ``pinobs sweep``: the same runs on 1, 2, ... local worker processes.

    python benchmarks/sweep_speedup.py              # 4 UR5 runs of 3 s, 1 and 2 workers
    python benchmarks/sweep_speedup.py --runs 8 --workers 1,2,4

Wall-clock times include starting the local cluster (about a second).  On a
shared machine the load average is printed with the result: read it.
"""

from __future__ import annotations

import argparse
import os
import time

from pinobs.evaluation.distributed import sweep, sweep_tasks

if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--workers", default="1,2")
    parser.add_argument("--duration", type=float, default=3.0)
    args = parser.parse_args()
    tasks = sweep_tasks(
        ["ur5"],
        ["exact"],
        range(args.runs),
        {"ekf": ("ekf", {}), "kf": ("kf", {})},
        duration=args.duration,
    )
    base = None
    for n in (int(w) for w in args.workers.split(",")):
        load = os.getloadavg()[0]
        t = time.perf_counter()
        table = sweep(tasks, workers=n)
        wall = time.perf_counter() - t
        base = base or wall
        assert table["error"].isna().all()
        print(
            f"{args.runs} runs of {args.duration:g} s on {n} worker(s): {wall:.1f} s "
            f"(speed-up {base / wall:.2f}×; load average {load:.1f} on {os.cpu_count()} CPUs)",
            flush=True,
        )
