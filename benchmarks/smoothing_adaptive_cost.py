# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""The smoother over ``adaptive`` against the causal ``adaptive``: CPU time, paired runs.

``benchmarks/smoothing.py`` times each of its twelve model-error logs once, which
is noisy on a shared machine.  Here three of those logs (``benchmarks/learning.py``:
12 s, σ = 1e-4, 1 kHz) are timed ``--repeats`` times, the causal run (``feed``, as
there) and ``pinobs.smooth(..., observer="adaptive")`` (default band, learning pass
included) in turn, and the ratio is taken pair by pair: median, min and max.
The three logs are the one with the largest single-run ratio in that table
(Panda payload, seed 1), and two others.

    python benchmarks/smoothing_adaptive_cost.py --out benchmarks
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import pinobs
from pinobs.io import Log
from pinobs.observers import make_observer
from pinobs.simulation.mismatch import mismatched_plant
from pinobs.smoothing import smooth

LOGS = (
    ("panda", "inertia20_payload", 1),
    ("ur5", "inertia20_payload", 1),
    ("panda", "friction", 2),
)


def main(out: Path, repeats: int) -> str:
    from learning import NOISE, RATE, feed, record, start

    rows = [
        f"| robot | scenario | seed | causal CPU [s] | smoother CPU [s] "
        f"| smoother / causal, median of {repeats} pairs | min–max |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for name, scenario, seed in LOGS:
        robot = pinobs.load(name)
        res = record(robot, mismatched_plant(robot, scenario, seed=0), duration=12.0, seed=seed)
        tau = np.array(res.tau)
        q0, v0 = start(robot, res)
        log = Log(t=res.t, q=res.q_meas, tau=tau)
        smooth(robot, log, observer="adaptive", noise_std=NOISE)  # warm-up (compiled kernels)
        causal, smoother = [], []
        for _ in range(repeats):
            obs = make_observer("adaptive", robot, rate=RATE, noise_std=NOISE)
            t0 = time.process_time()
            feed(obs, res, tau, q0, v0)
            t1 = time.process_time()
            smooth(robot, log, observer="adaptive", noise_std=NOISE)
            t2 = time.process_time()
            causal.append(t1 - t0)
            smoother.append(t2 - t1)
        ratio = np.array(smoother) / np.array(causal)
        rows.append(
            f"| {name} | {scenario} | {seed} | {np.median(causal):.2f} | {np.median(smoother):.2f} "
            f"| {np.median(ratio):.2f} | {ratio.min():.2f}–{ratio.max():.2f} |"
        )
    text = "\n".join(rows) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing_adaptive_cost.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks"))
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(main(args.out, args.repeats))
