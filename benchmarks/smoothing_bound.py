# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""How far below the causal ``ekf`` any estimator can be expected to go on the exact-model logs.

The sixteen 3 s logs of ``benchmarks/smoothing.py``'s seeds table (UR5 and Panda,
``pd`` tracking, 1 kHz, σ = 1e-4 and 1e-3 rad, seeds 0–3).  The truth has no
process noise, so the smoother at a vanishing ``accel_psd`` (1e-14) is the Bayesian
posterior of the (linearised) model given the measurements, and its ``band="model"``
standard deviation the posterior's: ``bound`` is the RMS over t > 0.5 s of that
``v_std``, the RMS error to be expected of the best estimator on this log's
information (the Cramér–Rao bound of the linearised problem, with the filter's
weak initial prior).  One log's realised error is one draw of a slowly varying curve
around it (``rts (1e-14) / bound``).  ``ekf / bound`` is then the ratio to the causal
``ekf`` (its default options) that the best estimator can be expected to reach on the
log; the issue's target asks for 3.  Errors scale exactly with σ on these logs (the
same draws, 1e-5 to 1e-3: no linearisation loss), so the σ = 1e-3 rows repeat the
σ = 1e-4 ones ten times larger, except the causal ``ekf``, whose default density is
relatively smaller there.

    python benchmarks/smoothing_bound.py --out benchmarks
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import pinobs
from pinobs.io import Log
from pinobs.simulation import Sensor, simulate
from pinobs.smoothing import smooth

VANISHING_PSD = 1e-14


def rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)))


def main(out: Path) -> str:
    rows = [
        "| robot | σ [rad] | seed | ekf | rts (auto) | ekf / rts (auto) | rts (1e-14) | bound "
        "| rts (1e-14) / bound | **ekf / bound** |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    start = time.perf_counter()
    for name in ("ur5", "panda"):
        robot = pinobs.load(name)
        for sigma in (1e-4, 1e-3):
            for seed in range(4):
                res = simulate(
                    robot, ["ekf"], sensor=Sensor(1000, sigma), inputs="pd", duration=3, seed=seed
                )
                log = Log(t=res.t, q=res.q_meas, tau=res.tau)
                late = res.t > 0.5
                e_ekf = rms(res.trace("ekf").v[late] - res.v[late])
                auto = smooth(robot, log, noise_std=sigma, accel_psd="auto")
                e_auto = rms(auto.v[late] - res.v[late])
                post = smooth(robot, log, noise_std=sigma, accel_psd=VANISHING_PSD, band="model")
                e_post = rms(post.v[late] - res.v[late])
                bound = rms(post.v_std[late])
                rows.append(
                    f"| {name} | {sigma:g} | {seed} | {e_ekf:.2e} | {e_auto:.2e} "
                    f"| {e_ekf / e_auto:.1f} | {e_post:.2e} | {bound:.2e} | {e_post / bound:.2f} "
                    f"| **{e_ekf / bound:.1f}** |"
                )
    took = time.perf_counter() - start
    text = "\n".join(
        [f"Made by `python benchmarks/smoothing_bound.py` in {took:.0f} s.", "", *rows, ""]
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing_bound.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks"))
    args = parser.parse_args()
    print(main(args.out))
