# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]"]
# ///
"""A long UR5 log through `pinobs estimate`: peak memory, and reading/writing against the observer loop.

Writes a CSV log of MINUTES minutes at 1 kHz (smooth multi-sine joint motion,
torques from inverse dynamics, σ = 1e-3 rad noise, seed 0), then

1. runs `pinobs estimate --robot ur5 --observer O --log LOG --out EST.csv` in a
   child process and reads its peak resident memory (``VmHWM``), next to
   that of a child that only imports pinobs;
2. times, in this process, reading the log (`pinobs.io.iter_log`), the
   observer loop over the rows read (`pinobs.io.LogEstimator`) and writing the
   estimates (`pinobs.io.EstimateWriter`), each per row and as a multiple of
   one `pin.aba` call on the UR5 measured in the same run.

    python benchmarks/io_bench.py                 # 10 minutes, kf and ekf
    python benchmarks/io_bench.py --minutes 1     # quicker
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import pinobs
from pinobs.io import EstimateWriter, LogEstimator, iter_log, write_log
from pinobs.model import aba_time


def make_log(path: Path, minutes: float, seed: int = 0) -> int:
    robot = pinobs.load("ur5")
    rng = np.random.default_rng(seed)
    n = round(minutes * 60 * 1000)
    t = np.arange(1, n + 1) * 1e-3
    amp, freq, phase = (
        rng.uniform(0.2, 0.6, (3, 6)),
        rng.uniform(0.1, 0.8, (3, 6)),
        rng.uniform(0, 2 * np.pi, (3, 6)),
    )
    w = 2 * np.pi * freq
    arg = w[None] * t[:, None, None] + phase[None]
    q = (amp * np.sin(arg)).sum(axis=1)
    v = (amp * w * np.cos(arg)).sum(axis=1)
    a = -(amp * w**2 * np.sin(arg)).sum(axis=1)
    tau = np.array([robot.inverse_dynamics(q[k], v[k], a[k]) for k in range(n)])
    write_log(path, t, q + 1e-3 * rng.standard_normal(q.shape), tau, digits=10)
    return n


def peak_rss_mb(args: list[str]) -> float:
    # VmHWM of the child's own address space (ru_maxrss would carry over the
    # parent's peak across fork + exec on Linux)
    code = (
        "import re, sys\n"
        "from pinobs.cli import main\n"
        f"rc = main({args!r}) if {bool(args)} else 0\n"
        "status = open('/proc/self/status').read()\n"
        "print(re.search(r'VmHWM:\\s+(\\d+)', status).group(1))\n"
        "sys.exit(rc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0  # VmHWM is in kB


def split_times(log: Path, name: str, folder: Path) -> dict[str, float]:
    import pandas  # noqa: F401  (imported before the clock starts)
    import pyarrow.csv  # noqa: F401

    robot = pinobs.load("ur5")
    start = time.perf_counter()
    chunks = list(iter_log(log, robot))
    read = time.perf_counter() - start
    ob = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-3)
    est = LogEstimator(ob, period=1e-3)
    start = time.perf_counter()
    parts = [est.feed(c) for c in chunks] + [est.finish()]
    loop = time.perf_counter() - start
    writer = EstimateWriter(folder / f"split_{name}.csv", robot, force=True)
    start = time.perf_counter()
    for p in parts:
        writer.write(*p)
    writer.close()
    write = time.perf_counter() - start
    return {"read": read, "loop": loop, "write": write, "rows": est.rows}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--minutes", type=float, default=10.0, help="log length (default 10)")
    parser.add_argument("--observers", default="kf,ekf", help="comma-separated (default kf,ekf)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        log = folder / "ur5_long.csv"
        n = make_log(log, args.minutes)
        size = log.stat().st_size / 2**20
        aba = aba_time(pinobs.load("ur5"))
        print(
            f"log: {n} rows ({args.minutes:g} min at 1 kHz), {size:.0f} MB CSV; one pin.aba = {aba * 1e6:.2f} us"
        )
        base = peak_rss_mb([])
        print(f"peak RSS of a process that imports pinobs: {base:.0f} MB")
        print(
            "| observer | peak RSS `pinobs estimate` | read / row | observer loop / row | write / row | (read + write) / loop |"
        )
        print("|---|---|---|---|---|---|")
        for name in args.observers.split(","):
            rss = peak_rss_mb(
                [
                    "estimate",
                    "--robot",
                    "ur5",
                    "--observer",
                    name,
                    "--log",
                    str(log),
                    "--out",
                    str(folder / f"est_{name}.csv"),
                    "--noise",
                    "1e-3",
                    "--no-progress",
                ]
            )
            s = split_times(log, name, folder)
            r, lp, w = (s[k] / s["rows"] for k in ("read", "loop", "write"))
            print(
                f"| {name} | {rss:.0f} MB | {r * 1e6:.2f} us ({r / aba:.2f}x aba) | "
                f"{lp * 1e6:.1f} us ({lp / aba:.1f}x aba) | {w * 1e6:.2f} us ({w / aba:.2f}x aba) | "
                f"{(r + w) / lp:.0%} |"
            )
    print(
        f"(peak RSS: VmHWM of the child process; timings on a shared, loaded machine; {time.strftime('%Y-%m-%d')})"
    )
