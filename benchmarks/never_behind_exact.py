"""The never-behind blend against its family alone on exact models (the blend is the default
for a log: :func:`pinobs.io.runs.log_options`; on an exact model it must keep the family's
accuracy).  Each run: ``pinobs.simulate(robot, [], duration=3 s, sensor=Sensor(rate, σ),
seed=s)`` (exact plant, its default input), every observer fed the measured samples from the
first one (row 0 of the result has none; ``reset`` at ``q₀``, no velocity); velocity RMS against the truth after 1 s; the
ratio blend / alone; the blend's per-joint model weight ``w``, its minimum over the joints at
the end (``w_end``) and its minimum over the joints of the mean after 1 s (``w_mean``).

    python benchmarks/never_behind_exact.py ur5 ekf,riemannian 0-9 1000,500,100 1e-4,1e-3
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import pinobs
from pinobs.simulation import Sensor


def seeds(text: str) -> list[int]:
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def run(ob: pinobs.Observer, t: np.ndarray, q: np.ndarray, tau: np.ndarray, blend: bool):
    ob.reset(t[0], q[0], None, tau[0])
    v = np.empty((t.size - 1, q.shape[1]))
    w = np.ones_like(v)
    for k in range(1, t.size):
        v[k - 1] = ob.update(t[k], q[k], tau[k]).v
        if blend:
            w[k - 1] = ob.weights  # type: ignore[attr-defined]
    return v, w


def main() -> None:
    robot_name = sys.argv[1] if len(sys.argv) > 1 else "ur5"
    families = sys.argv[2].split(",") if len(sys.argv) > 2 else ["ekf", "riemannian"]
    seed_list = seeds(sys.argv[3]) if len(sys.argv) > 3 else list(range(10))
    rates = [float(r) for r in sys.argv[4].split(",")] if len(sys.argv) > 4 else [1000.0]
    sigmas = [float(s) for s in sys.argv[5].split(",")] if len(sys.argv) > 5 else [1e-4]
    robot = pinobs.load(robot_name)
    print("robot rate sigma seed family alone blend ratio w_end w_mean reseeds", flush=True)
    for rate in rates:
        for sigma in sigmas:
            for seed in seed_list:
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = pinobs.simulate(
                        robot, [], duration=3.0, sensor=Sensor(rate, sigma), seed=seed
                    )
                # (row 0 holds no sample)
                t, q, tau, truth = res.t[1:], res.q_meas[1:], res.tau[1:], res.v[1:]
                late = t[1:] > 1.0
                for fam in families:
                    rms = {}
                    for blend in (False, True):
                        ob = pinobs.make_observer(
                            fam, robot, rate=rate, noise_std=sigma, never_behind=blend
                        )
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            v, w = run(ob, t, q, tau, blend)
                        err = (v - truth[1:])[late]
                        rms[blend] = float(np.sqrt(np.mean(err**2)))
                    w_end = float(w[-1].min())
                    w_mean = float(w[late].mean(axis=0).min())
                    print(
                        f"{robot_name} {rate:g} {sigma:g} {seed} {fam} {rms[False]:.3e} "
                        f"{rms[True]:.3e} {rms[True] / rms[False]:.3f} {w_end:.3f} "
                        f"{w_mean:.3f} {ob.reseeds}",  # type: ignore[attr-defined]
                        f"({time.perf_counter() - t0:.0f}s)",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
