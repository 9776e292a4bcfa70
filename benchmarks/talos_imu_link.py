# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[mujoco]"]
# ///
"""TALOS's IMU on its torso (`imu_link`) against the IMU at the root, in MuJoCo (issue 38).

Writes `benchmarks/talos_imu_link.md`.  `pinobs.simulation.humanoid.simulate_humanoid` with a
torso sway (`torso=TORSO`: `torso_1_joint` and `torso_2_joint` ±0.1 rad) added to `stand` and
`sway`, the IMU site on `imu_link` (`imu_body="imu_link"`) or at the root (`base_link`), the same
motion and seed (the seed draws the sensor noise and biases); each run through
`pinobs.io.legged_run.legged_run` with its defaults (`imu_frame=None`: `imu_link`; the root
run `imu_frame="base_link"`), the log's measured columns only (`benchmarks/legged_truth.py`'s
`simulated_log`), the first 0.5 s left out.  Per run: the root's linear velocity error RMS
[m/s] (Pinocchio's `v[0:3]`, root frame, the three axes pooled); `imu_link` only: the same
with the lever arm's raw gyro reading (M3 of `pinobs.observers.imu_link`, the default before
M4's low-pass: `ω̄`, recomputed here with its `smoothed` from the log's readings, taken out),
and M3 with two of its terms taken from the truth instead: the torso's joint velocities
(`kf`'s against MuJoCo's) and the root's angular velocity in the lever arm `ω_b × r_bi` (the
gyro's reading, noisy per sample, against MuJoCo's).

    python benchmarks/talos_imu_link.py [--duration 10] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import pinobs
from pinobs.io.legged_run import LEGGED_GAINS, legged_run
from pinobs.model import FootKinematics
from pinobs.observers.imu_link import smoothed
from pinobs.simulation.humanoid import TALOS_FEET, simulate_humanoid

sys.path.insert(0, str(Path(__file__).parent))
from legged_truth import simulated_log

#: the torso sway's amplitude [rad] (`simulate_humanoid(torso=)`)
TORSO = 0.1


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def one(robot: pinobs.Robot, motion: str, duration: float, seed: int, body: str) -> dict:
    """A run's numbers (module docstring)."""
    run = simulate_humanoid(motion, duration, seed=seed, imu_body=body, torso=TORSO, robot=robot)
    log = simulated_log(run, robot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        detail = legged_run(robot, log, imu_frame=None if body == "imu_link" else "base_link")
    v_est = detail.run.v
    ok = np.isfinite(v_est[:, :6]).all(axis=1)
    ok[: round(0.5 * (run.t.size - 1) / duration)] = False
    truth = run.base_v()
    out = {"v_rms": rms(v_est[ok, :3] - truth[ok, :3]), "truth_rms": rms(truth[ok, :3])}
    out["notes"] = [w for w in detail.run.warnings if "IMU's axes" in w]
    if body != "imu_link":
        return out
    kin = FootKinematics(robot, TALOS_FEET, imu_frame="imu_link")
    dq_true = run.stack(*(f"truth.dq.{j}" for j in run.joints))
    q = run.q_joints()
    raw, mean = v_est[:, :3].copy(), None  # M3: M4's (R_bi (ω̃ − ω̄)) × r_bi taken out
    for k in range(run.t.size):
        R_bi, r_bi, _ = kin.imu_motion(q[k])
        dt = 0.0 if k == 0 else log.t[k] - log.t[k - 1]
        mean = smoothed(mean, log.imu_gyro[k], dt, LEGGED_GAINS.lever_tau)
        raw[k] -= np.cross(R_bi @ (log.imu_gyro[k] - mean), r_bi)
    joints, lever = raw.copy(), raw.copy()
    for k in np.flatnonzero(ok):
        _, r_bi, J = kin.imu_motion(q[k])
        e = v_est[k, 6:] - dq_true[k]  # M3 with MuJoCo's q̇: v_b + J_i e − (J_iω e) × r_bi
        joints[k] += J[:3] @ e - np.cross(J[3:] @ e, r_bi)
        lever[k] += np.cross(v_est[k, 3:6] - truth[k, 3:], r_bi)  # ω_b × r_bi with the true ω_b
    out["v_rms_raw"] = rms(raw[ok] - truth[ok, :3])
    out["v_rms_true_dq"] = rms(joints[ok] - truth[ok, :3])
    out["v_rms_true_w"] = rms(lever[ok] - truth[ok, :3])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--motions", nargs="+", default=["stand", "sway"])
    args = parser.parse_args()
    robot = pinobs.load("talos")
    start, load = time.time(), os.getloadavg()
    lines = [
        "Made by `python benchmarks/talos_imu_link.py` (its docstring has the conditions): "
        f"{args.duration:g} s, seeds {', '.join(map(str, args.seeds))}, torso sway ±{TORSO} rad, "
        "`legged_run` defaults. Root linear velocity error RMS [m/s].",
        "",
        f"| motion | seed | IMU at the root | IMU on `imu_link` (M4, τ = {LEGGED_GAINS.lever_tau:g} s) "
        "| `imu_link`, M3 (raw ω̃ in the lever arm) | M3, true q̇ | M3, true ω_b in ω_b × r_bi "
        "| truth RMS |",
        "|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for motion in args.motions:
        for seed in args.seeds:
            root = one(robot, motion, args.duration, seed, "base_link")
            torso = one(robot, motion, args.duration, seed, "imu_link")
            notes += root["notes"] + torso["notes"]
            lines.append(
                f"| {motion} | {seed} | {root['v_rms']:.4f} | {torso['v_rms']:.4f} | "
                f"{torso['v_rms_raw']:.4f} | "
                f"{torso['v_rms_true_dq']:.4f} | {torso['v_rms_true_w']:.4f} | "
                f"{root['truth_rms']:.4f} |"
            )
            print(lines[-1], flush=True)
    lines += [
        "",
        f"{time.time() - start:.0f} s, load average at the start "
        f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; IMU-frame notes: {len(notes)}.",
    ]
    Path(__file__).with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
