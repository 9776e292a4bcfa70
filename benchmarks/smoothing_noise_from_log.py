# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""The smoother with σ estimated from the log against σ given, on the exact-model logs.

The sixteen 3 s logs of ``benchmarks/smoothing.py``'s seeds table (UR5 and Panda,
``pd`` tracking, 1 kHz, σ = 1e-4 and 1e-3 rad, seeds 0–3), each smoothed with
``accel_psd="auto"`` twice: ``noise_std=σ`` and ``noise_std=None`` (σ̂ from the log's
first second, :func:`pinobs.smoothing.log_noise_std`).  Velocity RMS error
and ±2σ coverage over t > 0.5 s.

    python benchmarks/smoothing_noise_from_log.py --out benchmarks
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

import pinobs
from pinobs.errors import NoiseWarning
from pinobs.io import Log
from pinobs.simulation import Sensor, simulate
from pinobs.smoothing import smooth


def main(out: Path) -> str:
    rows = [
        "| robot | σ [rad] | seed | σ̂ / σ | accel_psd (σ given / σ̂) | RMS (σ̂) / RMS (σ) "
        "| cover ±2σ (σ given / σ̂) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name in ("ur5", "panda"):
        robot = pinobs.load(name)
        for sigma in (1e-4, 1e-3):
            for seed in range(4):
                res = simulate(
                    robot, [], sensor=Sensor(1000, sigma), inputs="pd", duration=3, seed=seed
                )
                log = Log(t=res.t, q=res.q_meas, tau=res.tau)
                late = res.t > 0.5
                cells = []
                for noise_std in (sigma, None):
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore", NoiseWarning)
                        s = smooth(robot, log, noise_std=noise_std, accel_psd="auto")
                    err = (s.v - res.v)[late]
                    cells.append(
                        (
                            s.options["noise_std"],
                            s.options["accel_psd"],
                            float(np.sqrt(np.mean(err**2))),
                            100 * float(np.mean(np.abs(err) <= 2 * s.v_std[late])),
                        )
                    )
                (_, psd, rms, cover), (hat, psd_hat, rms_hat, cover_hat) = cells
                rows.append(
                    f"| {name} | {sigma:g} | {seed} | {hat / sigma:.3f} | {psd:g} / {psd_hat:g} "
                    f"| {rms_hat / rms:.3f} | {cover:.1f} % / {cover_hat:.1f} % |"
                )
    text = "\n".join(rows) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing_noise_from_log.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks"))
    print(main(parser.parse_args().out))
