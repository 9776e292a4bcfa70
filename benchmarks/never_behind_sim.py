"""Never-behind observers on the mismatch scenarios (pinobs.evaluation.bench's conditions: pd
tracking, 1 kHz, σ = 1e-4 rad, start perturbed by 0.05 rad / 0.5 rad/s, seed 0; RMS of
pinobs.evaluate).  Labels: ``family+nb`` = ``never_behind=True``, ``+auto`` =
``disturbance_psd="auto"``, ``+d`` = ``disturbance_psd=1``.

    python benchmarks/never_behind_sim.py ur5 exact,inertia5,inertia20_payload,friction \
        kf,ekf,ekf+auto,ekf+d,ekf+nb,ekf+auto+nb,riemannian+nb,kalman+nb 4
"""

import sys
import time
import warnings

import numpy as np

import pinobs
from pinobs.evaluation import evaluate
from pinobs.observers import make_observer
from pinobs.simulation import Sensor, simulate
from pinobs.simulation.mismatch import mismatched_plant

robot_name = sys.argv[1] if len(sys.argv) > 1 else "ur5"
scen = (
    sys.argv[2].split(",")
    if len(sys.argv) > 2
    else ["exact", "inertia5", "inertia20_payload", "friction"]
)
names = (
    sys.argv[3].split(",")
    if len(sys.argv) > 3
    else ["kf", "ekf", "ekf+nb", "riemannian+nb", "kalman+nb"]
)
dur = float(sys.argv[4]) if len(sys.argv) > 4 else 4.0
extra = eval(sys.argv[5]) if len(sys.argv) > 5 else {}
robot = pinobs.load(robot_name)
rate, noise = 1000.0, 1e-4
for sc in scen:
    obs = {}
    for n in names:
        base, *suf = n.split("+")
        opts = dict(extra.get(n, {}))
        if "nb" in suf:
            opts["never_behind"] = True
        if "auto" in suf:
            opts["disturbance_psd"] = "auto"
        if "d" in suf:
            opts["disturbance_psd"] = 1.0
        obs[n] = make_observer(base, robot, rate=rate, noise_std=noise, **opts)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(
            robot,
            obs,
            duration=dur,
            sensor=Sensor(rate, noise),
            inputs="pd",
            perturb_q=0.05,
            perturb_v=0.5,
            seed=0,
            plant=mismatched_plant(robot, sc, seed=0),
        )
    m = {x.observer: x for x in evaluate(res, robot)}
    line = f"{robot_name} {sc:18s}" + " ".join(f"{n}={m[n].rms_v_error:.3g}" for n in names)
    extra_info = " ".join(
        f"{n}:reseeds={obs[n].reseeds},w={np.round(obs[n].weights, 2).tolist()}"
        for n in names
        if hasattr(obs[n], "reseeds")
    )
    print(line, f"({time.perf_counter() - t0:.0f}s)", extra_info, flush=True)
