# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""The smoother over ``adaptive`` on the online-learning benchmark's other model errors.

``benchmarks/smoothing.py`` smooths three of ``benchmarks/learning.py``'s model-error
scenarios (inertia ±20 % and a payload, torque scale, friction).  This script runs the
other three, built as there (12 s, 1 kHz, σ = 1e-4 rad, PD tracking, truth seeds 1–4;
the causal ``adaptive`` started from the same perturbed state; RMS and coverage after 5 s):

* ``latency``: positions measured 1 ms (one sample) late, unknown to both; smoothed
  three times: with the smoother's defaults (no latency given: the log as stamped is not
  explained, so a latency is searched for and used if it explains it), as stamped
  (``filter_options={"latency": 0}``: row ``latency (as stamped)``) and with
  ``filter_options={"latency": "auto"}`` (the likeliest latency from the log,
  ``select_latency``: row ``latency (auto)``);
* ``latency_given``: the same with ``latency=1e-3`` given (the causal observer's option;
  the smoother's ``filter_options={"latency": 1e-3}``, which re-times the log);
* ``stale``: the model identified offline under one payload (``pinobs identify``, 15 s,
  seed 3), the truth carrying another.

Columns: the causal ``adaptive``'s RMS, the smoother's (``pinobs.smooth(...,
observer="adaptive")``, its defaults: the inflated band), their ratio, the band's
coverage of the truth, ``ρ``, what ``pinobs.smooth`` warned (``yes``: the model does not
explain the log, ``ConsistencyWarning``; ``latency``: it does with a latency found in the
log, ``LatencyWarning``), the latency the smoother used [ms], and its CPU time over the
causal run's (one run each).

    python benchmarks/smoothing_scenarios.py --out benchmarks
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import pinobs
from pinobs.errors import ConsistencyWarning, LatencyWarning
from pinobs.io import Log
from pinobs.observers import make_observer
from pinobs.simulation.mismatch import mismatched_plant
from pinobs.smoothing import smooth

SCENARIOS = ("latency", "latency_given", "stale")


def main(out: Path, seeds: tuple[int, ...]) -> str:
    from learning import NOISE, RATE, feed, record, rms_after, start

    started = time.perf_counter()
    rows = [
        "| robot | scenario | seed | adaptive | smoother | adaptive / smoother "
        "| cover ±2σ | ρ | warned | latency [ms] | CPU / adaptive |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|",
    ]
    for name in ("ur5", "panda"):
        robot = pinobs.load(name)
        plant_a = mismatched_plant(robot, "inertia20_payload", seed=0)
        stale = pinobs.identify(robot, record(robot, plant_a, duration=15.0, seed=3)).robot
        for seed in seeds:
            for scenario in SCENARIOS:
                model, delay, options = robot, 0, {}
                if scenario == "stale":
                    plant, model = mismatched_plant(robot, "inertia20_payload", seed=1), stale
                else:
                    plant, delay = robot.copy(), 1
                if scenario == "latency_given":
                    options = {"latency": 1e-3}
                res = record(robot, plant, duration=12.0, seed=seed, delay=delay)
                q0, v0 = start(robot, res)
                causal = make_observer("adaptive", model, rate=RATE, noise_std=NOISE, **options)
                t0 = time.process_time()
                e_ad = rms_after(res, feed(causal, res, res.tau, q0, v0), 5.0)
                cpu_ad = time.process_time() - t0
                log = Log(t=res.t, q=res.q_meas, tau=np.array(res.tau))
                runs = [(scenario, options)]
                if scenario == "latency":
                    runs.append(("latency (as stamped)", {"latency": 0.0}))
                    runs.append(("latency (auto)", {"latency": "auto"}))
                for label, smoothed in runs:
                    with warnings.catch_warnings(record=True) as said:
                        warnings.simplefilter("always", ConsistencyWarning)
                        warnings.simplefilter("always", LatencyWarning)
                        t0 = time.process_time()
                        s = smooth(
                            model, log, observer="adaptive", noise_std=NOISE,
                            filter_options=smoothed,
                        )  # fmt: skip
                        cpu = time.process_time() - t0
                    warned = "no"
                    if any(issubclass(w.category, LatencyWarning) for w in said):
                        warned = "latency"
                    if any(issubclass(w.category, ConsistencyWarning) for w in said):
                        warned = "yes"
                    late = res.t > 5.0
                    err = np.abs(s.v - res.v)[late]
                    e_s = rms_after(res, np.array(s.v), 5.0)
                    cover = 100 * float(np.mean(err <= 2 * s.v_std[late]))
                    rows.append(
                        f"| {name} | {label} | {seed} | {e_ad:.2e} | {e_s:.2e} "
                        f"| {e_ad / e_s:.2f} | {cover:.1f} % | {s.consistency:.3g} "
                        f"| {warned} | {1e3 * s.options['latency']:.3g} "
                        f"| {cpu / cpu_ad:.1f} |"
                    )
                    print(rows[-1], flush=True)
    text = (
        f"Made by `python benchmarks/smoothing_scenarios.py` in "
        f"{time.perf_counter() - started:.0f} s (seeds {', '.join(map(str, seeds))}).\n\n"
        + "\n".join(rows)
        + "\n"
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing_scenarios.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    args = parser.parse_args()
    print(main(args.out, tuple(args.seeds)))
