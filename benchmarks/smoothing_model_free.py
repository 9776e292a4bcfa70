# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""The model-free smoother (over ``kf``) where the model is wrong: the floor under ``ekf``'s.

On ``benchmarks/learning.py``'s model-error logs (12 s, 1 kHz, σ = 1e-4 rad, PD tracking;
UR5 and Panda; truth seeds 1 and 2; RMS and coverage after 5 s), with no model learned:

* ``kf*``: the causal ``kf`` at its best ``jerk_psd`` of ``learning.JERKS``, chosen on the
  truth (the baseline a user tunes by hand);
* ``ekf sm.``: ``pinobs.smooth(..., accel_psd="auto")`` over ``ekf`` with the wrong model;
* ``kf sm.``: ``pinobs.smooth(..., observer="kf", accel_psd="auto")``, its white-jerk
  density chosen from the log (no truth), its default (inflated noise) band;
* ``adaptive``: the causal ``adaptive``, which learns the model (for scale).

Columns: those RMS [rad/s], ``kf*`` over ``kf sm.``, the jerk density chosen, the band's
coverage of the truth, ``ρ``, and the model-free smoother's CPU time over the causal ``kf``'s
at that density (one run each, numba's compiled kernels loaded first).

    python benchmarks/smoothing_model_free.py --out benchmarks
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import pinobs
from pinobs.errors import ConsistencyWarning
from pinobs.io import Log
from pinobs.observers import make_observer
from pinobs.simulation.mismatch import mismatched_plant
from pinobs.smoothing import smooth

SCENARIOS = ("inertia20_payload", "torque_scale", "friction", "latency")


def main(out: Path, seeds: tuple[int, ...]) -> str:
    from learning import JERKS, NOISE, RATE, feed, record, rms_after, start

    started = time.perf_counter()
    rows = [
        "| robot | scenario | seed | kf* | ekf sm. | kf sm. | kf* / kf sm. | jerk_psd "
        "| cover ±2σ | ρ | adaptive | CPU / kf |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name in ("ur5", "panda"):
        robot = pinobs.load(name)
        warm = np.arange(0.0, 0.2, 1e-3)  # numba's compiled kernels loaded before timing
        walk = np.cumsum(np.random.default_rng(0).normal(0.0, 1e-3, (warm.size, robot.nq)), 0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConsistencyWarning)
            smooth(robot, (warm, walk), observer="kf", noise_std=NOISE, accel_psd="auto")
        for seed in seeds:
            for scenario in SCENARIOS:
                delay = 1 if scenario == "latency" else 0
                plant = robot.copy()
                if scenario in ("inertia20_payload", "friction"):
                    plant = mismatched_plant(robot, scenario, seed=0)
                res = record(robot, plant, duration=12.0, seed=seed, delay=delay)
                tau = 0.9 * res.tau + 0.3 if scenario == "torque_scale" else np.array(res.tau)
                q0, v0 = start(robot, res)
                hints = {"rate": RATE, "noise_std": NOISE}
                kfs = {
                    j: rms_after(
                        res,
                        feed(make_observer("kf", robot, jerk_psd=j, **hints), res, tau, q0, v0),
                        5.0,
                    )
                    for j in JERKS
                }
                e_kf = min(kfs.values())
                e_ad = rms_after(
                    res, feed(make_observer("adaptive", robot, **hints), res, tau, q0, v0), 5.0
                )
                log = Log(t=res.t, q=res.q_meas, tau=tau)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", ConsistencyWarning)
                    e_ekf = rms_after(
                        res, np.array(smooth(robot, log, noise_std=NOISE, accel_psd="auto").v), 5.0
                    )
                    t0 = time.process_time()
                    s = smooth(robot, log, observer="kf", noise_std=NOISE, accel_psd="auto")
                    cpu = time.process_time() - t0
                jerk = s.options["jerk_psd"]
                t0 = time.process_time()
                feed(make_observer("kf", robot, jerk_psd=jerk, **hints), res, tau, q0, v0)
                cpu_kf = time.process_time() - t0
                late = res.t > 5.0
                e_s = rms_after(res, np.array(s.v), 5.0)
                cover = 100 * float(np.mean(np.abs(s.v - res.v)[late] <= 2 * s.v_std[late]))
                rows.append(
                    f"| {name} | {scenario} | {seed} | {e_kf:.2e} | {e_ekf:.2e} | {e_s:.2e} "
                    f"| {e_kf / e_s:.2f} | {jerk:.3g} | {cover:.1f} % | {s.consistency:.3g} "
                    f"| {e_ad:.2e} | {cpu / cpu_kf:.2g} |"
                )
                print(rows[-1], flush=True)
    text = (
        f"Made by `python benchmarks/smoothing_model_free.py` in "
        f"{time.perf_counter() - started:.0f} s (seeds {', '.join(map(str, seeds))}).\n\n"
        + "\n".join(rows)
        + "\n"
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing_model_free.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    print(main(args.out, tuple(args.seeds)))
