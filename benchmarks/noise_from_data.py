# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]"]
# ///
"""Estimates with σ estimated from the log against those with the true σ (and the default).

A 4 s UR5 log at 1 kHz (PD tracking of a multi-sine, seed 5) with position
noise σ; each observer runs four times over it through `pinobs.io.process_log`:
with the true σ, with σ estimated from the log (no noise level given), built
without a noise level (live: it estimates σ from its first second of samples,
rebuilds and replays them, with a warning), and with its family's default
σ = 1e-6 given (what every observer did before it learnt σ).  Velocity RMS
error after 1.5 s (the live observers rebuild at 1 s).

    python benchmarks/noise_from_data.py                       # σ = 1e-3 rad
    python benchmarks/noise_from_data.py --sigma 1e-4 --observers kf,ekf
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
import pandas as pd

import pinobs
from pinobs.io import estimate_noise_std, process_log

if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--sigma", type=float, default=1e-3, help="true noise σ [rad]")
    parser.add_argument(
        "--observers",
        default="kf,ekf,riemannian,fd,highgain,sliding,kalman",
        help="comma-separated",
    )
    parser.add_argument("--quick", action="store_true", help="kf only")
    args = parser.parse_args()
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=4.0, sensor=pinobs.Sensor(1000.0, args.sigma), seed=5)
    t, q, tau, v = res.t[1:], res.q_meas[1:], res.tau[1:], res.v[1:]
    df = pd.DataFrame({"t": t, **{f"q{i}": q[:, i] for i in range(6)}})
    df = df.assign(**{f"tau{i}": tau[:, i] for i in range(6)})
    sigma_hat = estimate_noise_std(t, q, robot)
    print(
        f"true σ = {args.sigma:g} rad; estimated per joint {np.array2string(sigma_hat, formatter={'float_kind': '{:.3e}'.format})}"
    )
    k0 = int(np.searchsorted(t, t[0] + 1.5))

    def rms(run: pinobs.io.LogRun) -> float:
        return float(np.sqrt(np.mean((run.v[k0:] - v[k0:]) ** 2)))

    print(
        "| observer | RMS true σ | RMS σ from the log | ratio | RMS live (no σ) | ratio "
        "| RMS default σ | ratio |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in ["kf"] if args.quick else args.observers.split(","):
        alone = {"never_behind": False}  # the family, as the live runs below
        true = rms(process_log(df, robot, name, noise_std=args.sigma, options=alone))
        est = rms(process_log(df, robot, name, options=alone))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pinobs.errors.NoiseWarning)
            live = rms(process_log(df, robot, pinobs.make_observer(name, robot, rate=1000.0)))
        fixed = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-6)
        default = rms(process_log(df, robot, fixed))
        print(
            f"| {name} | {true:.3g} | {est:.3g} | {est / true:.3f} | {live:.3g} | "
            f"{live / true:.3f} | {default:.3g} | {default / true:.1f} |"
        )
