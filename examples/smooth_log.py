# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]"]
# ///
"""Smooth a recorded log: every sample's velocity with an error bar, σ taken from the log.

A UR5 log is simulated (PD tracking, 1 kHz, σ = 1e-3 rad; the truth set aside)
and written as CSV.  Then, as for a log from a robot, the causal ``ekf`` and
the RTS smoother over it run on the file, the smoother's noise level
estimated from the log's first second and its process noise chosen from the
log by likelihood (no truth used); the Python forms of

    pinobs estimate --robot ur5 --observer ekf --log LOG --out ekf.csv
    pinobs estimate --robot ur5 --observer ekf --log LOG --out smoothed.csv \\
        --smooth --accel-psd auto --html smoothed.html

Both are scored against the truth: the velocity RMS error after 0.5 s and the
share of (sample, joint) pairs whose true velocity lies inside the smoother's
±2σ band (the README's calibration target: 90–98 %), for the default band
(the smoother's posterior under its noise model, ``--band model``) and for the
error the measurement noise alone drives (``--band noise``; README, Smoothing).
Writes ``<out>/ur5_log.csv``, ``<out>/ekf.csv``, ``<out>/smoothed.csv`` and
``<out>/smoothed_noise_band.csv`` (``t, q0.., v0.., v_std0..``) and
``<out>/smoothed.html`` (the logged motion, the smoothed estimate as a ghost).

    python examples/smooth_log.py            # a 5 s log
    python examples/smooth_log.py --quick    # 1.5 s, for CI
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import pinobs
from pinobs.io import process_log, read_log, write_log
from pinobs.io.smoothing import smooth_log
from pinobs.visualization import log_result, write_html

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("examples/out"))
    parser.add_argument("--quick", action="store_true", help="a 1.5 s log")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    robot = pinobs.load("ur5")
    sim = pinobs.simulate(
        robot, [], duration=1.5 if args.quick else 5.0, sensor=pinobs.Sensor(1000.0, 1e-3), seed=3
    )
    rows = slice(1, None)  # the simulator does not measure sample 0: the log starts at 1
    log_path = write_log(args.out / "ur5_log.csv", sim.t[rows], sim.q_meas[rows], sim.tau[rows])
    truth = sim.v[rows]

    causal = process_log(
        log_path, robot, "ekf", out=args.out / "ekf.csv", force=True, noise_std=1e-3
    )
    run, stretches = smooth_log(
        log_path, robot, args.out / "smoothed.csv", accel_psd="auto", force=True, stream=False
    )
    for line in run.warnings:
        print(f"note: {line}")
    opts = stretches[0]
    print(
        f"smoother: σ = {run.noise_std:.3g} rad (true 1e-3), accel_psd = {opts['accel_psd']:g} "
        f"rad²/s³ (chosen from the log), consistency ρ = {opts['consistency']:.2f} (about 1: "
        "the densities explain the log)"
    )
    # the same estimate, its band the error the measurement noise alone drives (band="noise")
    smooth_log(
        log_path, robot, args.out / "smoothed_noise_band.csv", noise_std=run.noise_std,
        accel_psd=opts["accel_psd"], band="noise", force=True,
    )  # fmt: skip
    nq, nv = robot.nq, robot.nv
    late = sim.t[rows] > 0.5
    covers = []
    for name in ("smoothed", "smoothed_noise_band"):
        est = np.loadtxt(args.out / f"{name}.csv", delimiter=",", skiprows=1)
        v_s, v_std = est[:, 1 + nq : 1 + nq + nv], est[:, 1 + nq + nv :]
        covers.append(f"{100 * np.mean(np.abs(v_s - truth)[late] <= 2 * v_std[late]):.1f} %")
    print("| estimate | velocity RMS after 0.5 s [rad/s] | inside ±2σ: model band | noise band |")
    print("|---|---:|---:|---:|")
    for name, v, cover in (("ekf (causal)", causal.v, ["—", "—"]), ("smoothed", v_s, covers)):
        err = float(np.sqrt(np.mean((v - truth)[late] ** 2)))
        print(f"| {name} | {err:.3g} | {cover[0]} | {cover[1]} |")

    page = write_html(
        log_result(robot, read_log(log_path, robot), {"ekf smoothed": run}),
        robot,
        args.out / "smoothed.html",
        truth_label="measured",
    )
    print(f"wrote {log_path}, {args.out / 'ekf.csv'}, {args.out / 'smoothed.csv'} and {page}")
