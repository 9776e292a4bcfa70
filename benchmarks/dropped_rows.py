# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Observers on logs with dropped rows and on irregular stamps (math.md §7, **Dropped samples**;
the never-behind blend's **Irregular steps**).

* **drops**: a 3 s ``pd`` run at 1 kHz, σ = 1e-4 rad (``pinobs.simulate``, seed ``s``), its
  rows dropped at random (``rng(100 + s)``, rate 2 %, 8 %, 20 %; position *and* torque lost;
  times exact), fed row by row to each observer; also ``pinobs.smooth`` on the same rows
  (the offline floor).  ``--scenario`` a mismatch of ``pinobs.simulation.mismatch`` for the
  truth (the blend must then give the ``kf``).
* **irregular**: an exact-model ``pd`` run whose plant holds each torque over its own
  interval, intervals uniform in 0.5–1.5 ms (RK4 steps of ``dynamics_rk4``), σ = 1e-4 rad,
  ``ekf`` against its never-behind blend.

Velocity RMS error after 1 s.  Each line printed as it goes::

    PYTHONPATH=. python benchmarks/dropped_rows.py drops ur5 --seeds 1,2,3
    PYTHONPATH=. python benchmarks/dropped_rows.py drops ur5 --scenario inertia20_payload \
        --names kf,ekf,ekf+nb --drops 0,0.08,0.2 --no-smooth
    PYTHONPATH=. python benchmarks/dropped_rows.py irregular ur5 --seeds 1,2,3,4,5,6
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import pinobs
from pinobs.model.integrators import dynamics_rk4
from pinobs.simulation import Sensor
from pinobs.simulation.inputs import make_input
from pinobs.simulation.mismatch import mismatched_plant

RATE, SIGMA, DURATION = 1000.0, 1e-4, 3.0


def rms_after(v: np.ndarray, truth: np.ndarray, t: np.ndarray) -> float:
    late = t > 1.0
    return float(np.sqrt(np.mean((v - truth)[late] ** 2)))


def observer(name: str, robot: pinobs.Robot, rate: float) -> pinobs.Observer:
    base, *suffix = name.split("+")
    opts = {"never_behind": True} if "nb" in suffix else {}
    return pinobs.make_observer(base, robot, rate=rate, noise_std=SIGMA, **opts)


def feed(ob: pinobs.Observer, t: np.ndarray, q: np.ndarray, tau: np.ndarray) -> np.ndarray:
    ob.reset(t[0], q[0], None, tau[0])
    return np.array([ob.update(t[k], q[k], tau[k]).v for k in range(1, t.size)])


def drops(args: argparse.Namespace) -> None:
    robot = pinobs.load(args.robot)
    for seed in args.seeds:
        plant = None if args.scenario == "exact" else mismatched_plant(robot, args.scenario)
        res = pinobs.simulate(
            robot, [], duration=DURATION, sensor=Sensor(RATE, SIGMA), seed=seed, plant=plant,
            inputs="pd",
        )  # fmt: skip
        for drop in args.drops:
            rng = np.random.default_rng(100 + seed)
            keep = np.r_[1, 2, np.flatnonzero(rng.random(res.t.size) >= drop)]
            keep = np.unique(keep[keep >= 1])  # (the first simulated sample has no position)
            t, q, tau, v = res.t[keep], res.q_meas[keep], res.tau[keep], res.v[keep]
            row = []
            for name in args.names:
                ob = observer(name, robot, RATE)
                row.append(f"{name}={rms_after(feed(ob, t, q, tau), v[1:], t[1:]):.3g}")
                if hasattr(ob, "weights"):
                    row[-1] += f"(w_min={ob.weights.min():.2f},reseeds={ob.reseeds})"
            if args.smooth:
                sm = pinobs.smooth(robot, (t, q, tau), noise_std=SIGMA)
                row.append(f"smooth={rms_after(sm.v[1:], v[1:], t[1:]):.3g}")
            print(args.robot, args.scenario, seed, drop, " ".join(row), flush=True)


def irregular(args: argparse.Namespace) -> None:
    robot = pinobs.load(args.robot)
    for seed in args.seeds:
        rng = np.random.default_rng(seed)
        q = robot.random_configuration(rng, scale=0.3)
        v = np.zeros(robot.nv)
        inputs = make_input("pd", robot, rng=rng, center=q)
        t = np.r_[0.0, np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 4000))]  # (4000 > 3 s worth)
        t = t[t < DURATION]
        qs, vs, taus = [], [], []
        for k in range(t.size):  # the plant holds each torque over its own interval
            if k:
                q, v = dynamics_rk4(robot, q, v, taus[-1], t[k] - t[k - 1])
            taus.append(inputs.torque(t[k], q, v))
            qs.append(q)
            vs.append(v)
        q_meas = np.array(qs) + SIGMA * rng.standard_normal((t.size, robot.nq))
        rate = 1.0 / float(np.median(np.diff(t)))
        row = []
        for name in args.names:
            ob = observer(name, robot, rate)
            err = rms_after(feed(ob, t, q_meas, np.array(taus)), np.array(vs)[1:], t[1:])
            row.append(f"{name}={err:.3g}")
        print(args.robot, "irregular 0.5-1.5 ms", seed, " ".join(row), flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("case", choices=["drops", "irregular"])
    p.add_argument("robot")
    p.add_argument("--seeds", default="1,2,3", type=lambda s: [int(x) for x in s.split(",")])
    p.add_argument("--drops", default="0,0.02,0.08,0.2", type=lambda s: [float(x) for x in s.split(",")])  # fmt: skip
    p.add_argument("--scenario", default="exact")
    p.add_argument("--names", default=None, type=lambda s: s.split(","))
    p.add_argument("--no-smooth", dest="smooth", action="store_false")
    args = p.parse_args()
    if args.names is None:
        args.names = (
            ["kf", "ekf", "ekf+nb", "riemannian", "kalman", "adaptive"]
            if args.case == "drops"
            else ["ekf", "ekf+nb"]
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (drops if args.case == "drops" else irregular)(args)


if __name__ == "__main__":
    main()
