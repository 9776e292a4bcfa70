# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Identification and smoothing on logs off a uniform grid, against the clean log (issue 35.2).

For each seed, on 8 s planar_3r logs at 1 kHz (the tests' truth:
``tests.conftest.planar_3r_truth``, σ = 1e-4 rad, ``pd`` input):

* **drops**: 8 % of the rows deleted (``tests.conftest.dropped_rows``: 80 % of the
  losses single rows, the others runs of 3–9), torques held;
* **irregular**: one 10 kHz run sampled every 1 ms (its clean log) and at intervals
  uniform in 0.5–1.5 ms (``tests.conftest.resampled_log``), torques as sampled;

and prints the acceleration error of the identified model against the truth (RMS of
``forward_dynamics`` at 100 random states, seed 0) for ``identify`` (Savitzky–Golay
velocities) and ``pinobs.identify`` (refined by the model-based smoother), and the
ratio to the clean log's.  Then on a 4 s UR5 log of the exact model (σ = 1e-4) it prints
``pinobs.smooth``'s velocity RMS error on the clean log and with 8 % of the rows dropped.

    PYTHONPATH=. python benchmarks/irregular_logs.py                 # seeds 1-5
    PYTHONPATH=. python benchmarks/irregular_logs.py --seeds 1,2 --no-refine

It prints each line as it goes and writes the table to ``benchmarks/irregular_logs.md``
(``--md``: another path).
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

import pinobs
from pinobs.model.identification import identify
from pinobs.simulation import Sensor
from tests.conftest import dropped_rows, planar_3r_truth, resampled_log


def acceleration_error(model: pinobs.Robot, truth: pinobs.Robot) -> float:
    rng = np.random.default_rng(0)
    errs = []
    for _ in range(100):
        q, v = truth.random_configuration(rng), rng.normal(size=truth.nv)
        tau = rng.normal(size=truth.nv)
        errs.append(model.forward_dynamics(q, v, tau) - truth.forward_dynamics(q, v, tau))
    return float(np.sqrt(np.mean(np.square(errs))))


def held_log(robot: pinobs.Robot, plant: pinobs.Robot, duration: float, seed: int) -> tuple:
    res = pinobs.simulate(
        robot, [], duration=duration, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=seed,
        plant=plant,
    )  # fmt: skip
    q = np.array(res.q_meas)
    q[0] = res.q[0]
    return res, (res.t, q, np.array(res.tau))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1,2,3,4,5")
    parser.add_argument("--no-refine", action="store_true", help="identify (SG) only")
    parser.add_argument("--md", default=str(Path(__file__).with_suffix(".md")))
    args = parser.parse_args()
    start = time.perf_counter()
    rows: list[str] = []
    seeds = [int(s) for s in args.seeds.split(",")]
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    fits = {"identify": lambda log, torque: identify(robot, log, offset=False, torque=torque)}
    if not args.no_refine:
        fits["pinobs.identify"] = lambda log, torque: pinobs.identify(robot, log, torque=torque)
    ratios: dict[tuple[str, str], list[float]] = {}
    for seed in seeds:
        _, (t, q, tau) = held_log(robot, truth, 8.0, seed)
        keep = dropped_rows(t.size, 0.08, seed)
        clean10k, irregular = resampled_log(robot, truth, 8.0, 1e-4, seed)
        cases = {
            "drops": ((t, q, tau), (t[keep], q[keep], tau[keep]), "held"),
            "irregular": (clean10k, irregular, "sampled"),
        }
        for fit_name, fit in fits.items():
            for case, (clean_log, other_log, torque) in cases.items():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    e0 = acceleration_error(fit(clean_log, torque).robot, truth)
                    e1 = acceleration_error(fit(other_log, torque).robot, truth)
                ratios.setdefault((fit_name, case), []).append(e1 / e0)
                rows.append(
                    f"| {fit_name} | {case} | {seed} | {e0:.4g} | {e1:.4g} | {e1 / e0:.3f} |"
                )
                print(
                    f"seed {seed} {fit_name:16s} {case:9s} clean {e0:.4g} {case} {e1:.4g} "
                    f"ratio {e1 / e0:.3f}",
                    flush=True,
                )
    for (fit_name, case), r in ratios.items():
        gm = math.exp(float(np.mean(np.log(r))))
        print(f"{fit_name:16s} {case:9s} ratios {', '.join(f'{x:.3f}' for x in r)}; "
              f"geometric mean {gm:.3f}")  # fmt: skip
    ur5 = pinobs.load("ur5")
    for seed in seeds[:3]:
        res, (t, q, tau) = held_log(ur5, ur5, 4.0, seed)
        keep = dropped_rows(t.size, 0.08, seed)
        out = []
        for sel in (np.ones(t.size, dtype=bool), keep):
            sm = pinobs.smooth(ur5, (t[sel], q[sel], tau[sel]), noise_std=1e-4)
            err = (sm.v - res.v[sel])[(t[sel] > 0.2) & (t[sel] < t[-1] - 0.2)]
            out.append(float(np.sqrt(np.mean(err**2))))
        print(
            f"seed {seed} pinobs.smooth ur5 velocity RMS clean {out[0]:.3g} drops {out[1]:.3g} "
            f"ratio {out[1] / out[0]:.3f}",
            flush=True,
        )
        rows.append(
            f"| pinobs.smooth (ur5, velocity RMS) | drops | {seed} | {out[0]:.3g} | "
            f"{out[1]:.3g} | {out[1] / out[0]:.3f} |"
        )
    means = [
        f"| {f} | {c} | geometric mean | | | {math.exp(float(np.mean(np.log(r)))):.3f} |"
        for (f, c), r in ratios.items()
    ]
    made = f"Made by `PYTHONPATH=. python benchmarks/irregular_logs.py --seeds {args.seeds}`"
    Path(args.md).write_text(
        f"{made} in {time.perf_counter() - start:.0f} s.\n\n"
        "| fit | log | seed | clean | dropped or irregular | ratio |\n"
        "|---|---|---:|---:|---:|---:|\n" + "\n".join(rows + means) + "\n"
    )


if __name__ == "__main__":
    main()
