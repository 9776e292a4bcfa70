"""Cost per update of the never-behind observers as a ratio to pin.aba on a UR5
(pinobs.evaluation.timing.measure_cost, thread CPU time, five seeds: median and range).

    python benchmarks/never_behind_cost.py
"""

import time

import numpy as np

import pinobs
from pinobs.evaluation.timing import measure_cost
from pinobs.observers import make_observer

robot = pinobs.load("ur5")
rows = {}
for label, name, opts in [
    ("kf", "kf", {}),
    ("ekf", "ekf", {}),
    ("ekf+d", "ekf", {"disturbance_psd": 1.0}),
    ("ekf+auto", "ekf", {"disturbance_psd": "auto"}),
    ("ekf+nb", "ekf", {"never_behind": True}),
    ("riemannian", "riemannian", {}),
    ("riemannian+nb", "riemannian", {"never_behind": True}),
    ("kalman", "kalman", {}),
    ("kalman+nb", "kalman", {"never_behind": True}),
]:
    ob = make_observer(name, robot, rate=1000.0, noise_std=1e-4, **opts)
    rs = [
        measure_cost(ob, samples=1000, rounds=5, seed=s, clock=time.thread_time)["ratio"]
        for s in range(5)
    ]
    print(
        f"{label:15s} ratio to pin.aba: median {np.median(rs):.1f}, range {min(rs):.1f}-{max(rs):.1f}",
        flush=True,
    )
