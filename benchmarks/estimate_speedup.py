# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[dask,io]"]
# ///
"""Dask speed-up of ``pinobs estimate --out-dir``: LOGS UR5 logs on 0, 1, 2 ... workers.

Writes LOGS CSV logs of MINUTES minutes at 1 kHz (``io_bench.make_log``: multi-sine
joint motion, inverse-dynamics torques, σ = 1e-3 rad, seeds 0 ..), then times the
whole command

    pinobs estimate --robot ur5 --observer O --log LOGDIR --out-dir OUT --workers N --force

as a child process, REPEATS times per worker count, interleaved (0, 1, 2, 0, 1, 2 ...),
``--workers 0`` being the serial path (the logs one after the other in one
process, no Dask).  Prints every wall time, the medians, the speed-ups over the
serial medians, and the load average before each run: on a shared machine, read it.

With ``--smooth`` the command smooths each log instead (``--smooth --lag 1
--accel-psd 1e-8``: the fixed-lag smoother over ``ekf``, which streams, so a
worker's memory stays bounded whatever the log's length).

    python benchmarks/estimate_speedup.py                       # riemannian and ekf, 4 logs of 1 min
    python benchmarks/estimate_speedup.py --observers kf --repeats 5
    python benchmarks/estimate_speedup.py --observers ekf --workers 0,2 --smooth
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from io_bench import make_log

if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--logs", type=int, default=4)
    parser.add_argument("--minutes", type=float, default=1.0)
    parser.add_argument("--workers", default="0,1,2")
    parser.add_argument("--observers", default="riemannian,ekf")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--smooth", action="store_true", help="smooth each log (ekf)")
    args = parser.parse_args()
    smooth = ["--smooth", "--lag", "1", "--accel-psd", "1e-8"] if args.smooth else []
    counts = [int(w) for w in args.workers.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        logs = Path(tmp) / "logs"
        logs.mkdir()
        for seed in range(args.logs):
            make_log(logs / f"ur5_{seed}.csv", args.minutes, seed=seed)
        print(f"{args.logs} UR5 logs of {args.minutes:g} min at 1 kHz; {os.cpu_count()} CPUs")
        for observer in args.observers.split(","):
            walls: dict[int, list[float]] = {n: [] for n in counts}
            for _ in range(args.repeats):
                for n in counts:
                    cmd = [sys.executable, "-m", "pinobs.cli", "estimate", "--robot", "ur5"]
                    cmd += ["--observer", observer]
                    cmd += ["--log", str(logs), "--out-dir", str(Path(tmp) / "out")]
                    cmd += ["--workers", str(n), "--force", "--no-progress", "--noise", "1e-3"]
                    cmd += smooth
                    load = os.getloadavg()[0]
                    start = time.perf_counter()
                    subprocess.run(cmd, check=True, capture_output=True)
                    walls[n].append(time.perf_counter() - start)
                    print(
                        f"  {observer}{' smoothed' if smooth else ''} --workers {n}: "
                        f"{walls[n][-1]:.1f} s (load average {load:.1f})",
                        flush=True,
                    )
            serial = statistics.median(walls[counts[0]])
            for n in counts:
                med = statistics.median(walls[n])
                print(
                    f"{observer}, --workers {n}: median {med:.1f} s over {args.repeats} "
                    f"(min {min(walls[n]):.1f}, max {max(walls[n]):.1f}); "
                    f"speed-up {serial / med:.2f}x over --workers {counts[0]}"
                )
