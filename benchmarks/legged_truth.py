# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[mujoco]"]
# ///
"""Legged base estimation against MuJoCo's truth: the invariant EKF and the quaternion EKF.

Writes `benchmarks/legged_truth.json` and `benchmarks/legged_truth.md`. go1 simulated by
`pinobs.simulation.legged.simulate_legged` (MuJoCo, 500 Hz samples, 1 ms physics steps;
its docstring has the robot, controller, motions and sensor noise), per motion and seed,
and TALOS by `pinobs.simulation.humanoid.simulate_humanoid` (stand, sway; and stepping
forward, 60 s like the long trot, `--long`; the IMU at the base), and a 60 s go1 trot.
Both filters get the same inputs: the IMU readings (`imu.*`, held between samples), the
measured joint angles (`q.*`), contacts = measured foot normal force > `CONTACT_FORCE`;
the same noise parameters (`GAINS`: the simulation's IMU and encoder noise; the foot slip
measured on the truth of the trot, seed 0, and the kinematics term chosen on that run, see
`GAINS`' comment: the stand and sway rows are held out; TALOS: `TALOS_GAINS`, its contact
density measured on its stepping's truth), go1's IMU frame `imu_link`;
both start on the true base pose and velocity at the first sample, with zero bias
estimates and a prior of the simulation's bias σ (`truth` start), or from a roll error
and a lateral velocity error with a prior of twice those: 10° and 0.3 m/s (`perturbed`),
30° and 1 m/s (`large`, the filters' convergence tests' perturbation), where the two
errors' dynamics differ most. The motion is the same for every seed (the controller reads
the true joint angles); the seed draws the sensor noise and biases. The world's origin is
where the simulation puts it (the invariant EKF's prior no longer depends on it).

Metrics (per run; the tables give the mean over seeds and the worst seed):
* `v rms`: RMS over the run of the base's linear velocity error in the base frame [m/s]
  (Pinocchio's `v[0:3]`, all three components pooled);
* `yaw drift`: |yaw error| at the end, per metre walked (trot, step: the base's horizontal
  path, for the stepping mostly its side-to-side shifts) or per second (stand, sway);
* `pos drift`: horizontal position error at the end, likewise per metre or per second;
* `NEES/3`: mean of `eᵀ Σ⁻¹ e / 3` for that error (1 for a consistent filter; below 1:
  the filter's σ is larger than its errors; the report calls < 0.5 conservative, > 2
  overconfident);
* `in 2σ`: fraction of samples × components where the IMU's world velocity error is within
  ±2σ of the filter's own covariance (95.4 % for a consistent Gaussian filter). The
  invariant EKF's velocity error is `v̂ − v ≈ ξ_v − v̂^ ξ_R` (right-invariant), the
  quaternion EKF's `δv` directly.

* `in ±2σ x / y / z`: the same per axis of the world frame.
* `IMU frame: in ±2σ x / y / z`, `NEES/3`: the same for the velocity in the IMU's frame,
  `v̂_b − v_b ≈ R̂ᵀ ξ_v` (invariant), `−R̂ᵀ δv − v̂_b^ δθ` (quaternion), where the yaw, not
  observable, does not enter: in the world frame its prior's σ (0.1 rad) times the walking
  speed widens the horizontal axes' σ (rows run before these columns: blank).
* cost: seconds per update against one `pin.aba` on go1, interleaved in chunks of 20 (as
  `pinobs.evaluation.timing.measure_cost`, which takes an `Observer`), by this thread's CPU
  time and by wall time; and `legged_run` with its defaults (`pinobs estimate --observer
  inekf`: `slip_speed`, joint velocities from `kf`) over the trot's log, per row, alternated
  with as many `pin.aba` calls.

Issue 38 targets: `v rms` ≤ 0.05 m/s and ≤ 0.7 × the quaternion EKF's; ≥ 95 % in ±2σ on
every axis and consistent (NEES/3 0.5-2); an update ≤ 30 `pin.aba` on go1.

    python benchmarks/legged_truth.py [--duration 10] [--seeds 0 1 2] [--long 60]
        [--sections go1 humanoid cost real slip rolling lift density] [--merge] [--quick]
        [--starts truth perturbed large]

    python benchmarks/legged_truth.py --sections cost --merge    # the cost table alone
    python benchmarks/legged_truth.py --sections real --merge    # the real Go1 log alone

With `--merge` the sections not run are kept from `legged_truth.json`.  The report's header
lists, per section, the run that made its rows (`runs` in the JSON: date, command, seconds,
load average; a rerun replaces its section's entry) with the section's note (`NOTES`); the
JSON's `gains` holds the gains each section ran with.

`real`: SEROW's Go1 log (no truth; `benchmarks/real_data.py`) through
`pinobs.io.legged_run.legged_run` with its defaults (`LEGGED_GAINS`, the encoders' σ from the
log's stillest second, `slip_speed`, `foot_radius="urdf"` and `rolling_lift`: chosen on
MuJoCo, the log held out), with `foot_radius=0` (the foot frames, the default before), with
`rolling_lift=False` (rolling.py's R4 alone, the default before), with σ_q from the
first second (the default before), with `imu_noise="log"`, and with the white foot noise of
before (`GAINS`), contacts from the force threshold or SEROW's probability, with and
without the foot gate: the feet's NIS over the stance rows
(`pinobs.observers.legs.stance_consistency`: NIS per degree of freedom, expected 1, and the
share of stance rows inside their own 95 % χ² interval, expected 95 %), and the base speed
where every joint moves slower than 0.05 rad/s (the stands); and, with `LOG_GAINS` (the IMU
and encoder noise measured on the log's stands), the kinematics term varied; then the same
NIS on the MuJoCo go1 (`simulated_nis`), where the defaults were chosen, its encoders white
(`NOISE`) or quantised as the real log's (`QUANTISED`).

`rolling`: go1's `--motions` and the `--long` trot with both filters given `foot_radius`
(the URDF's foot spheres, 2 cm: each foot measured at its point that touched the ground,
`pinobs.observers.rolling`), with `GO1_GAINS` (the contact density measured at that point,
`density`); the section's other rows kept (`rolling_white`: the rows with `GO1_WHITE_GAINS`,
before, and `rolling_gains` those with `GAINS`, before that).

`lift`: the `rolling` runs with both filters given `rolling_lift` too (rolling.py's R5: the
anchored point's cycloid rise removed), `GO1_GAINS` unchanged, over `--starts`; and
(`lift_diagnosis`) the feet's vertical motion over their stances on the truth (`stance_rise`:
anchored point, sphere centre, cycloid) of trot 20 s (the measuring run), stand and sway
(seed 0), with the invariant EKF's mean velocity error on the trot without and with it.

`density`: the contact density of the feet's true motion over their stances
(`contact_density`, no filter): go1's trot at the touch point, which gives `GO1_GAINS`, and
the runs that check the method against `GAINS`' and `TALOS_GAINS`' numbers; and
(`density_diagnosis`) the invariant EKF on the measuring motion with one term of
`GO1_GAINS` changed at a time: what keeps go1 conservative (a diagnosis, not a choice).

`slip`: go1 standing in MuJoCo, one foot made to slide while its force keeps it in contact
(`SlidingLegs`), with and without the foot gate: the base velocity error (`slip_table`).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import platform
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation
from threadpoolctl import threadpool_limits

import pinobs
from pinobs.model import FootKinematics, aba_call, foot_sphere_radius
from pinobs.observers.inekf import InEKFGains, InEKFPrior, InvariantEKF, skew
from pinobs.observers.qekf import QuaternionEKF
from pinobs.simulation.humanoid import HUMANOID_MOTIONS, simulate_humanoid
from pinobs.simulation.legged import (
    FOOT_RADIUS,
    GO1_FEET,
    LEGGED_MOTIONS,
    LeggedNoise,
    simulate_legged,
)

CONTACT_FORCE = 20.0  # [N]
NOISE = LeggedNoise()
#: IMU and encoder noise from the simulation's; ``contact`` (foot slip) measured on the truth of
#: the tuning run (trot, seed 0, 5 s): the random walk with the foot centre's mean-square
#: displacement over a stance, sqrt(Σ|Δd|² / (3 Σ τ)) = 0.0069 m/s/√Hz (the 2 cm sphere rolls:
#: 3.7 mm per 0.11 s stance); ``kinematics``: the smallest of 0.1, 1, 5 mm with ≥ 95 % in ±2σ on
#: that run (0.1 mm: 85 %, NEES/3 1.6; 1 mm: 98 %, 0.74; 5 mm: 100 %, 0.48); the rolling is a
#: drift, not a random walk, and this white term covers the difference. Before (issue 38's
#: first benchmark) contact 0.1 and kinematics 5 mm: σ 3.3-4× the errors (`OLD_GAINS` rows).
GAINS = InEKFGains(
    gyro=NOISE.gyro,
    accel=NOISE.acc,
    gyro_bias=NOISE.gyro_walk,
    accel_bias=NOISE.acc_walk,
    contact=0.007,
    joint=NOISE.encoder,
    kinematics=1e-3,
)
OLD_GAINS = dataclasses.replace(GAINS, contact=0.1, kinematics=5e-3)
#: TALOS's: ``GAINS`` with the contact density measured the same way on TALOS's truth (the
#: stepping, 20 s, seed 0: sqrt(Σ|Δd|² / (3 Σ τ)) = 8.8e-4 m/s/√Hz; standing 1.5e-4, swaying
#: 2.5e-4): its flat soles do not roll, go1's 2 cm spheres do (0.0069).  With go1's 0.007 the
#: TALOS rows were conservative (NEES/3 0.31-0.44, σ 1.5-1.8× the errors); on TALOS stand
#: (10 s, seed 0) the contact term alone made it: contact 1e-6 → NEES/3 0.85 (0.42 with
#: 0.007), the kinematics term 0 instead → 0.42 (unchanged), the encoders' J Σ_q Jᵀ 0 → 0.42.
TALOS_GAINS = dataclasses.replace(GAINS, contact=8.8e-4)
#: go1 with rolling feet (``foot_radius=FOOT_RADIUS``, the ``rolling`` rows; ``legged_run``'s
#: default radius), before (``GO1_WHITE_GAINS``): ``GAINS`` with the contact density measured
#: the same way on go1's truth at the point each foot touched the ground (rolling.py's (R2)),
#: not its centre (``contact_density``; the trot, 20 s, seed 0: sqrt(Σ|Δa|² / (3 Σ τ)) =
#: 0.0053 m/s/√Hz, 390 stances); NEES/3 0.42-0.47 on trot and stand: σ ~1.5× the errors.
GO1_WHITE_GAINS = dataclasses.replace(GAINS, contact=5.3e-3)
#: ``GO1_GAINS``: that displacement split at ``LANDING_TIME`` after each contact flag rises
#: (``stance_density``'s ``landing`` / ``after``, same run): the first 20 ms move the point
#: 0.0136 m/s/√Hz (x / y / z 0.014 / 0.0025 / 0.019; 0.18 / 0.03 / 0.25 m/s RMS in the
#: first 10 ms: the sphere still settling into MuJoCo's soft contact, and short bounces),
#: the rest of the stance 0.0023 (0.0021 / 0.0020 / 0.0026).  One white density spreads the
#: landing over the whole stance; ``contact`` is now the rest's and ``landing`` the first
#: 20 ms' excess, sqrt(0.0136² − 0.0023²) = 0.0134 (``InEKFGains.landing``, both filters).
#: Measured on the trot's truth (the motion is the same for every seed): the trot rows are
#: not held out; stand and sway are.  ``kinematics`` stays 1 mm.
GO1_GAINS = dataclasses.replace(GAINS, contact=2.3e-3, landing=1.34e-2, landing_time=0.02)
#: go1's encoders quantised as the real Go1 log's are (steps 6e-5 rad hip and thigh, 4e-5 rad
#: calf; white 3e-5 rad under the rounding, so 44 % of a still joint's readings repeat the
#: previous one, the log's 35-57 %): the ``real_sim`` rows' second noise.
QUANTISED = dataclasses.replace(NOISE, encoder=3e-5, encoder_step=(6e-5, 6e-5, 4e-5) * 4)
#: start → (roll error [deg], lateral velocity error [m/s]); "large" is the perturbation of
#: the filters' convergence tests (tests/observers/test_inekf.py, test_qekf.py)
STARTS = {"truth": (0.0, 0.0), "perturbed": (10.0, 0.3), "large": (30.0, 1.0)}
FILTERS = {"inekf": InvariantEKF, "qekf": QuaternionEKF}
#: The motions whose drift is per metre walked (the others': per second).
WALKS = ("trot", "step")
#: The real log's IMU densities measured on its stands (per-sample σ / √400 Hz, mean of the
#: axes: gyro 0.014, 0.015, 0.063 rad/s; accelerometer 0.13, 0.09, 0.16 m/s²) and kf's
#: encoder σ on the log (1e-4 rad); the kinematics term is the one varied in the table.
LOG_GAINS = dataclasses.replace(GAINS, gyro=1.5e-3, accel=6.4e-3, joint=1e-4)
#: A short note per section (the report's list of runs): what its gains were measured on,
#: what is held out, how to read its numbers.
NOTES = {
    "go1": "`GAINS`: contact density measured on the trot's truth (seed 0, 5 s; the foot centre) "
    "and kinematics chosen on that run: stand and sway held out. Accuracy rows from the NumPy "
    "steps (the compiled ones equal them to 5e-11 relative); includes the cost table",
    "cost": "By this thread's CPU time and by wall time: on a loaded machine the wall time "
    "counts the other processes (read the CPU rows)",
    "humanoid": "`TALOS_GAINS`: contact density measured on TALOS's stepping truth (20 s, "
    "seed 0): the step rows are not held out, stand and sway are. The stepping walks 1.30 m "
    "forward; the base's path, the drifts' denominator, is 5.87 m (side-to-side shifts)",
    "rolling": "`GO1_GAINS`: contact density after the landing and landing term (a foot's first "
    "20 ms) measured on the trot's truth at the touch point "
    "(20 s, seed 0; section `density`): the trot rows are not held out (the motion is the same "
    "for every seed), stand and sway are",
    "rolling_gains": "`GAINS` with rolling feet, the rows before `GO1_WHITE_GAINS` (not rerun)",
    "rolling_white": "`GO1_WHITE_GAINS` with rolling feet, the rows before `GO1_GAINS` (not rerun)",
    "density": "Measured on the truth alone (no filter): seed 0, the motions of `DENSITY_RUNS`; "
    "`density_diagnosis`: filters on the measuring motion, not used to choose",
    "real": "The real log held out: run once with the settings MuJoCo gave, nothing tuned on "
    "it (`GO1_GAINS` rows: run once, after the rolling rows; `rolling_lift` rows: once, after "
    "the `lift` rows, then rerun when it became the default; rerun with M4 on go1's `imu_link`: "
    "the NIS the same bits, the stands' speed moves)",
    "slip": "`GAINS`, go1 standing (seed 0), one foot made to slide",
    "lift": "`GO1_GAINS` as the `rolling` rows, with `rolling_lift` (derived, no parameter: "
    "nothing chosen); `lift_diagnosis` on the truth of the measuring run (trot 20 s, seed 0) and "
    "on stand and sway (seed 0). Rerun with imu_link.py's M4 on go1's fixed `imu_link` (the "
    "root velocity's lever arm low-passed, decided on seeds 3-5: the `v rms` column moves; the "
    "±2σ and NEES columns check the filter's state, which M4 leaves bit for bit)",
}
#: The foot gate's outlier probability in the cost table's ``inekf+gate`` row and the real
#: log's rows (``InvariantEKF(foot_gate=)``).
FOOT_GATE = 1e-3


def run_filter(
    name: str,
    run: Any,
    robot: pinobs.Robot,
    start: str,
    gains: InEKFGains = GAINS,
    foot_radius: float = 0.0,
    rolling_lift: bool = False,
) -> dict[str, float]:
    imu_frame = "imu_link" if run.feet == GO1_FEET else None  # TALOS: the IMU at the base
    ekf = FILTERS[name](
        robot,
        run.feet,
        gains=gains,
        imu_frame=imu_frame,
        foot_radius=foot_radius,
        rolling_lift=rolling_lift,
    )
    r_bi = ekf.imu_placement[1]
    t = run.t
    q_meas = run.q_joints()
    gyro, acc = run.gyro(), run.acc()
    contacts = run.forces() > CONTACT_FORCE
    base_q, base_v = run.base_q(), run.base_v()
    q0 = np.concatenate([base_q[0], q_meas[0]])
    v0 = np.concatenate([base_v[0], np.zeros(len(run.joints))])
    # the bias prior is the simulation's (σ of the initial biases); the rest InEKFPrior's
    prior = InEKFPrior(gyro_bias=NOISE.gyro_bias, accel_bias=NOISE.acc_bias)
    roll, speed = STARTS[start]
    if roll or speed:  # a roll error, a lateral (base y) velocity error, a prior of twice those
        tilt = Rotation.from_rotvec([math.radians(roll), 0.0, 0.0])
        q0[3:7] = (Rotation.from_quat(q0[3:7]) * tilt).as_quat()
        v0[1] += speed
        prior = dataclasses.replace(prior, attitude=math.radians(2 * roll), velocity=2 * speed)
    ekf.reset(t[0], q0, v0, gyro=gyro[0], acc=acc[0], contacts=contacts[0], prior=prior)
    err_v, inside, nees, yaw_err, pos_err = [], [], [], 0.0, np.zeros(2)
    err_w = np.zeros(3)  # Σ of the IMU's world velocity error (its mean: the bias)
    inside_b, nees_b = [], []  # the same in the IMU frame (no yaw in it)
    for k in range(1, t.size):
        est = ekf.update(t[k], q_meas[k], gyro[k], acc[k], contacts[k])
        err_v.append(est.v[:3] - base_v[k, :3])
        R_b = Rotation.from_quat(base_q[k, 3:]).as_matrix()
        # the IMU's world velocity, truth and estimate, and its error covariance
        v_imu = R_b @ (base_v[k, :3] + np.cross(base_v[k, 3:], r_bi))
        v_hat = ekf.state.x[0]
        P = ekf.state.P
        if name == "inekf":
            T = np.hstack([-skew(v_hat), np.eye(3)])
            cov = T @ P[0:6, 0:6] @ T.T
        else:
            cov = P[3:6, 3:6]
        e = v_hat - v_imu
        err_w += e
        inside.append(np.abs(e) <= 2.0 * np.sqrt(np.diag(cov)))
        nees.append(float(e @ np.linalg.solve(cov, e)) / 3.0)
        # in the IMU frame: v̂_b − v_b ≈ R̂ᵀ ξ_v (invariant), −R̂ᵀ δv − v̂_b^ δθ (quaternion)
        R_hat = ekf.state.R
        e_b = R_hat.T @ v_hat - (R_b @ ekf.imu_placement[0]).T @ v_imu
        M = np.hstack([np.zeros((3, 3)) if name == "inekf" else skew(R_hat.T @ v_hat), R_hat.T])
        cov_b = M @ P[0:6, 0:6] @ M.T
        inside_b.append(np.abs(e_b) <= 2.0 * np.sqrt(np.diag(cov_b)))
        nees_b.append(float(e_b @ np.linalg.solve(cov_b, e_b)) / 3.0)
        if k == t.size - 1:
            rel = Rotation.from_matrix(est.rotation @ R_b.T).as_euler("ZYX")
            yaw_err = abs(float(rel[0]))
            pos_err = est.q[:2] - base_q[k, :2]
    err = np.array(err_v)
    walked = float(np.sum(np.linalg.norm(np.diff(base_q[:, :2], axis=0), axis=1)))
    per = walked if run.motion in WALKS else float(t[-1] - t[0])
    return {
        "v_rms": float(np.sqrt(np.mean(err**2))),
        "yaw_drift": yaw_err / per,
        "pos_drift": float(np.linalg.norm(pos_err)) / per,
        "in_2sigma": float(np.mean(inside)),
        "in_2sigma_xyz": np.mean(inside, axis=0).tolist(),
        "nees": float(np.mean(nees)),
        "in_2sigma_body_xyz": np.mean(inside_b, axis=0).tolist(),
        "nees_body": float(np.mean(nees_b)),
        "walked_m": walked,
        "mean_error_xyz": (err_w / (t.size - 1)).tolist(),
    }


#: :func:`stance_density`'s split of each stance: its first ``LANDING_TIME`` [s] and the rest.
LANDING_TIME = 0.02
#: Frequency bands [Hz] of :func:`stance_density`'s velocity spectrum.
PSD_BANDS = ((5.0, 20.0), (20.0, 60.0), (60.0, 250.0))


def stance_density(
    t: np.ndarray,
    centres: np.ndarray,
    rotations: np.ndarray,
    flags: np.ndarray,
    radius: float,
    normal: Any = (0.0, 0.0, 1.0),
) -> dict[str, Any]:
    """The contact density a foot's true motion over its stances amounts to: each stance
    (a run of ``flags``, samples ``k₀..k₁``) moves the foot's measured point by ``Δa``, and a
    random walk of density ``σ_c`` (the filters' ``ḋ_j = R h_R w_c``) has ``E|Δa|² = 3 σ_c² τ``
    over a stance of ``τ = t[k₁] − t[k₀]``, so::

        σ_c = sqrt(Σ |Δa|² / (3 Σ τ)),   per axis  sqrt(Σ Δa_i² / Σ τ)

    with ``a = c + R_f s``, ``s = R_f(t₀)ᵀ (−r n)`` (:mod:`pinobs.observers.rolling`'s (R2): the
    point that touched the ground; ``radius`` 0: the foot frame).  That is the point's velocity
    spectrum at zero frequency over the stances: with ``V(f) = Σ ȧ e^{−2πi f t} Δt`` over a
    stance (``ȧ`` by differences, ``f = k/τ``), ``V(0) = Δa`` and a white velocity of density
    ``σ`` gives ``E|V(f)|² = 3 σ² τ`` at every ``f``; ``psd`` is ``sqrt(Σ|V|² / (3 Σ τ))`` over
    the bins in each of :data:`PSD_BANDS` (the spectrum's shape: a white walk is flat).
    ``t`` (N,) [s], evenly sampled, ``centres`` (N, K, 3) the foot frames' world positions [m],
    ``rotations`` (N, K, 3, 3) their world orientations, ``flags`` (N, K) contact; stances of
    one sample are skipped (τ = 0)."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    dt = float(t[1] - t[0])
    sq, tau, stances = np.zeros(3), 0.0, 0
    split = np.zeros((2, 4))  # first LANDING_TIME, the rest: Σ Δa_i², Σ τ
    m = round(LANDING_TIME / dt)
    band = np.zeros((len(PSD_BANDS), 2))  # Σ|V|², Σ τ
    for j in range(flags.shape[1]):
        edges = np.diff(np.concatenate([[0], flags[:, j].astype(int), [0]]))
        for k0, k1 in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True):
            if k1 > k0:
                s = rotations[k0, j].T @ (-radius * n)  # (R2)
                a = centres[k0 : k1 + 1, j] + rotations[k0 : k1 + 1, j] @ s
                d = a[-1] - a[0]
                sq, tau, stances = sq + d * d, tau + float(t[k1] - t[k0]), stances + 1
                km = min(m, k1 - k0)
                for i, (lo, hi) in enumerate(((0, km), (km, k1 - k0))):
                    split[i, :3] += (a[hi] - a[lo]) ** 2
                    split[i, 3] += (hi - lo) * dt
                power = np.sum(np.abs(np.fft.rfft(np.diff(a, axis=0), axis=0)) ** 2, axis=1)
                f = np.fft.rfftfreq(k1 - k0, dt)
                for i, (lo, hi) in enumerate(PSD_BANDS):
                    inside = (f >= lo) & (f < hi)
                    band[i] += power[inside].sum(), inside.sum() * (k1 - k0) * dt
    if tau <= 0:
        raise ValueError("no stance of two samples or more: no contact density to measure")
    return {
        "density": float(np.sqrt(sq.sum() / (3.0 * tau))),
        "per_axis": np.sqrt(sq / tau).tolist(),
        "psd": [float(np.sqrt(p / (3.0 * w))) if w > 0 else math.nan for p, w in band],
        "stances": stances,
        "stance_s": tau,
        "landing": float(np.sqrt(split[0, :3].sum() / (3.0 * split[0, 3]))),
        "landing_per_axis": np.sqrt(split[0, :3] / split[0, 3]).tolist(),
        "after": float(np.sqrt(split[1, :3].sum() / (3.0 * split[1, 3]))),
        "after_per_axis": np.sqrt(split[1, :3] / split[1, 3]).tolist(),
    }


def contact_density(run: Any, robot: pinobs.Robot, radius: float) -> dict[str, Any]:
    """:func:`stance_density` of a simulated run's truth: the feet from the true base pose and
    joint angles, the stances from the measured forces (> ``CONTACT_FORCE``, the filters')."""
    legs = FootKinematics(robot, run.feet)
    q, base = run.q_joints(truth=True), run.base_q()
    R_b = Rotation.from_quat(base[:, 3:]).as_matrix()
    centres = np.empty((run.t.size, len(run.feet), 3))
    rotations = np.empty((run.t.size, len(run.feet), 3, 3))
    for k in range(run.t.size):
        h, rot, _, _ = legs.placements_and_jacobians(q[k])
        centres[k] = base[k, :3] + h @ R_b[k].T
        rotations[k] = R_b[k] @ rot
    return stance_density(run.t, centres, rotations, run.forces() > CONTACT_FORCE, radius)


#: The ``density`` section's runs: label → (robot, motion, duration [s], foot radius [m]);
#: seed 0.  The first gives ``GO1_GAINS``; the others check the method against the numbers of
#: ``GAINS`` (go1's foot centre, the trot's first 5 s) and ``TALOS_GAINS`` (TALOS's soles).
DENSITY_RUNS = {
    "go1 trot 20 s, touch point (GO1_GAINS)": ("go1", "trot", 20.0, FOOT_RADIUS),
    "go1 trot 20 s, foot centre": ("go1", "trot", 20.0, 0.0),
    "go1 trot 5 s, foot centre (GAINS)": ("go1", "trot", 5.0, 0.0),
    "TALOS step 20 s, sole (TALOS_GAINS)": ("talos", "step", 20.0, 0.0),
}


def density_section() -> dict[str, Any]:
    """The ``density`` section: :func:`contact_density` of :data:`DENSITY_RUNS`."""
    out: dict[str, Any] = {}
    for label, (name, motion, duration, radius) in DENSITY_RUNS.items():
        robot = pinobs.load(name)
        simulate = simulate_legged if name == "go1" else simulate_humanoid
        run = simulate(motion, duration, seed=0, noise=NOISE, robot=robot)
        out[label] = contact_density(run, robot, radius)
        print("density", label, out[label], flush=True)
    return out


#: The ``density_diagnosis`` rows: ``GO1_GAINS`` and one term changed at a time.
DIAGNOSIS_GAINS = {
    "GO1_GAINS (contact 0.0023, landing 0.0134 for 20 ms, kinematics 1 mm)": GO1_GAINS,
    "GO1_WHITE_GAINS (contact 0.0053, no landing term: before)": GO1_WHITE_GAINS,
    "contact 0.0023, no landing term": dataclasses.replace(GO1_GAINS, landing=0.0),
    "contact 1e-6": dataclasses.replace(GO1_WHITE_GAINS, contact=1e-6),
    "kinematics 0.1 mm": dataclasses.replace(GO1_GAINS, kinematics=1e-4),
    "kinematics 0": dataclasses.replace(GO1_GAINS, kinematics=0.0),
}


def density_diagnosis() -> dict[str, Any]:
    """The invariant EKF with rolling feet on the motion ``GO1_GAINS`` was measured on (trot,
    10 s, seed 0, truth start) with :data:`DIAGNOSIS_GAINS`: a diagnosis of what keeps go1
    conservative, not a choice (the ``rolling`` rows keep ``GO1_GAINS``)."""
    robot = pinobs.load("go1")
    run = simulate_legged("trot", 10.0, seed=0, noise=NOISE, robot=robot)
    return {
        label: run_filter("inekf", run, robot, "truth", gains, FOOT_RADIUS)
        for label, gains in DIAGNOSIS_GAINS.items()
    }


def stance_rise(run: Any, robot: pinobs.Robot, after: float = LANDING_TIME) -> dict[str, float]:
    """The vertical motion of the feet over their stances of ``≥ 0.1 s`` (measured force >
    ``CONTACT_FORCE``) after their first ``after`` [s], on the truth: of the anchored point
    ``a`` (rolling.py's R2, anchored at ``after``), of the sphere's centre, and the cycloid
    ``r (1 − cos φ)`` (R3's lift, ``φ`` the foot's rotation since); means [m], durations [s]."""
    legs = FootKinematics(robot, run.feet)
    q, base = run.q_joints(truth=True), run.base_q()
    R_b = Rotation.from_quat(base[:, 3:]).as_matrix()
    flags = run.forces() > CONTACT_FORCE
    m = round(after * run.rate)
    rows = []
    for j in range(flags.shape[1]):
        edges = np.diff(np.concatenate([[0], flags[:, j].astype(int), [0]]))
        for k0, k1 in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True):
            if (k1 - k0) / run.rate < 0.1:
                continue
            ends = []
            for k in (k0 + m, k1):
                h, rot, _, _ = legs.placements_and_jacobians(q[k])
                ends.append((base[k, :3] + R_b[k] @ h[j], R_b[k] @ rot[j]))
            (c0, f0), (c1, f1) = ends
            s = f0.T @ np.array([0.0, 0.0, -FOOT_RADIUS])  # R2, anchored at k0 + m
            phi = np.linalg.norm(Rotation.from_matrix(f1 @ f0.T).as_rotvec())
            rows.append(((k1 - k0 - m) / run.rate, (c1 + f1 @ s - c0 - f0 @ s)[2], c1[2] - c0[2],
                         FOOT_RADIUS * (1.0 - math.cos(phi))))  # fmt: skip
    mean = np.mean(rows, axis=0)
    keys = ("duration_s", "point_rise_m", "centre_rise_m", "cycloid_m")
    return {"stances": len(rows), **dict(zip(keys, mean.tolist(), strict=True))}


#: ``lift_diagnosis``'s runs: label → (motion, duration [s]); seed 0.
LIFT_RUNS = {"trot 20 s (the measuring run)": ("trot", 20.0), "stand 10 s": ("stand", 10.0),
             "sway 10 s": ("sway", 10.0)}  # fmt: skip


def lift_diagnosis() -> dict[str, Any]:
    """Where the trot's z velocity bias comes from: :func:`stance_rise` of :data:`LIFT_RUNS`'
    truths and, on the measuring run (trot 20 s, seed 0), the invariant EKF's mean world
    velocity error with ``GO1_GAINS`` and rolling feet, without and with ``rolling_lift``."""
    robot = pinobs.load("go1")
    out: dict[str, Any] = {}
    for label, (motion, duration) in LIFT_RUNS.items():
        run = simulate_legged(motion, duration, seed=0, noise=NOISE, robot=robot)
        out[label] = stance_rise(run, robot)
        if motion == "trot":
            for lift in (False, True):
                r = run_filter("inekf", run, robot, "truth", GO1_GAINS, FOOT_RADIUS, lift)
                out[label][f"filter_lift_{lift}"] = r
        print("lift", label, out[label], flush=True)
    return out


def _lift_lines(rows: dict[str, Any]) -> list[str]:
    if not rows:
        return []
    md = [
        "`lift_diagnosis`: the feet's vertical motion over their stances of ≥ 0.1 s after "
        f"their first {LANDING_TIME * 1e3:g} ms (truth, seed 0, `stance_rise`): the anchored "
        "point's rise is the sphere centre's (MuJoCo's soft contact) plus the cycloid "
        "r (1 − cos φ) (rolling.py's R3, which `rolling_lift` removes); and the invariant "
        "EKF's mean world velocity error on the measuring run (z: the bias):",
        "",
        "| run | stances | after 20 ms [s] | point rise [mm] | centre [mm] | cycloid [mm] "
        "| inekf mean error x / y / z [mm/s] | with `rolling_lift` |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, r in rows.items():
        errs = [
            " / ".join(f"{1e3 * e:.2f}" for e in r[k]["mean_error_xyz"]) if k in r else ""
            for k in ("filter_lift_False", "filter_lift_True")
        ]
        md.append(
            f"| {label} | {r['stances']} | {r['duration_s']:.3f} | {1e3 * r['point_rise_m']:.3f} "
            f"| {1e3 * r['centre_rise_m']:.3f} | {1e3 * r['cycloid_m']:.3f} | {' | '.join(errs)} |"
        )
    return [*md, ""]


def _diagnosis_lines(rows: dict[str, Any]) -> list[str]:
    if not rows:
        return []
    md = [
        "`density_diagnosis`: the invariant EKF with rolling feet on the measuring motion (trot, "
        "10 s, seed 0, truth start) with `GO1_GAINS` and one term changed (a diagnosis, not "
        "used to choose):",
        "",
        "| gains | v rms [m/s] | in ±2σ x / y / z | NEES/3 |",
        "|---|---:|---:|---:|",
    ]
    for label, r in rows.items():
        xyz = " / ".join(f"{100 * a:.1f}" for a in r["in_2sigma_xyz"])
        md.append(f"| {label} | {r['v_rms']:.4f} | {xyz} | {r['nees']:.3g} |")
    return [*md, ""]


def _density_lines(density: dict[str, Any]) -> list[str]:
    if not density:
        return []
    md = [
        "`density`: contact densities measured on the truth (`contact_density`, seed 0; each stance, "
        "measured force > 20 N, moves the foot's point by Δa: σ_c = sqrt(Σ|Δa|² / (3 Σ τ)), "
        "the point's velocity spectrum at 0 Hz; the bands: the same spectrum there, flat for "
        "the filters' random walk): the first row is `GO1_GAINS`' (the rolling rows), the "
        "others check the method against `GAINS`' and `TALOS_GAINS`' numbers:",
        "",
        "| run | σ_c [m/s/√Hz] | x / y / z | "
        + " | ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in PSD_BANDS)
        + f" | first {LANDING_TIME * 1e3:g} ms (x / y / z) | after (x / y / z) "
        "| stances | stance time [s] |",
        "|---|---:|---:|" + "---:|" * len(PSD_BANDS) + "---:|---:|---:|---:|",
    ]
    for label, r in density.items():
        split = [
            f"{r[k]:.2g} ({' / '.join(f'{a:.2g}' for a in r[k + '_per_axis'])})" if k in r else ""
            for k in ("landing", "after")
        ]
        md.append(
            f"| {label} | {r['density']:.2g} | {' / '.join(f'{a:.2g}' for a in r['per_axis'])} "
            f"| {' | '.join(f'{p:.2g}' for p in r['psd'])} | {' | '.join(split)} "
            f"| {r['stances']} | {r['stance_s']:.1f} |"
        )
    return [*md, ""]


def _verdict(nees: float) -> str:
    if nees < 0.5:
        return f"conservative, σ ≈ {nees**-0.5:.2g}× the errors"
    return "consistent" if nees < 2.0 else "overconfident"


def _table(section: dict[str, Any]) -> list[str]:
    md = [
        "| motion, start | filter | v rms [m/s] | yaw drift | pos drift | in ±2σ | "
        "in ±2σ x / y / z | NEES/3 | IMU frame: in ±2σ x / y / z | NEES/3 | walked [m] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for motion, per_filter in section.items():
        unit = "/m" if any(w in motion for w in WALKS) else "/s"
        for name, runs in per_filter.items():
            v, yaw, pos, ins, nees, walked = (
                np.array([r[k] for r in runs])
                for k in ("v_rms", "yaw_drift", "pos_drift", "in_2sigma", "nees", "walked_m")
            )
            xyz = 100 * np.mean([r["in_2sigma_xyz"] for r in runs], axis=0)
            body = _body_cells(runs)
            md.append(
                f"| {motion} | `{name}` | {v.mean():.3g} ({v.max():.3g}) | "
                f"{math.degrees(yaw.mean()):.3g}°{unit} ({math.degrees(yaw.max()):.3g}) | "
                f"{100 * pos.mean():.3g} cm{unit} ({100 * pos.max():.3g}) | "
                f"{100 * ins.mean():.1f} % ({100 * ins.min():.1f}) | "
                f"{' / '.join(f'{a:.1f}' for a in xyz)} | {nees.mean():.3g} | {body} | "
                f"{walked.mean():.2f} |"
            )
    return md


def _body_cells(runs: list[dict[str, Any]]) -> str:
    """The IMU frame's ``in ±2σ x / y / z | NEES/3`` cells (blank for rows run before them)."""
    if not all("nees_body" in r for r in runs):
        return " | "
    xyz = 100 * np.mean([r["in_2sigma_body_xyz"] for r in runs], axis=0)
    nees = np.mean([r["nees_body"] for r in runs])
    return f"{' / '.join(f'{a:.1f}' for a in xyz)} | {nees:.3g}"


def _targets(section: dict[str, Any]) -> list[str]:
    md = []
    for motion, per_filter in section.items():
        inekf = np.mean([r["v_rms"] for r in per_filter["inekf"]])
        qekf = np.mean([r["v_rms"] for r in per_filter["qekf"]])
        xyz = np.mean([r["in_2sigma_xyz"] for r in per_filter["inekf"]], axis=0)
        nees = float(np.mean([r["nees"] for r in per_filter["inekf"]]))
        ok = xyz.min() >= 0.95 and 0.5 <= nees <= 2.0
        md.append(
            f"* {motion}: inekf v rms {inekf:.3g} m/s (≤ 0.05: "
            f"{'met' if inekf <= 0.05 else 'missed'}); {inekf / qekf:.3g}× qekf's (≤ 0.7: "
            f"{'met' if inekf <= 0.7 * qekf else 'missed'}); in ±2σ per axis "
            f"{' / '.join(f'{100 * a:.1f}' for a in xyz)} % and NEES/3 {nees:.2g} "
            f"(≥ 95 % on every axis and consistent: {'met' if ok else 'missed'}; {_verdict(nees)})"
            + _body_target(per_filter["inekf"])
        )
    return md


def _body_target(runs: list[dict[str, Any]]) -> str:
    """The IMU frame's numbers for :func:`_targets` (none for rows run before them)."""
    if not all("nees_body" in r for r in runs):
        return ""
    xyz = np.mean([r["in_2sigma_body_xyz"] for r in runs], axis=0)
    nees = float(np.mean([r["nees_body"] for r in runs]))
    return (
        f"; in the IMU frame {' / '.join(f'{100 * a:.1f}' for a in xyz)} % and NEES/3 "
        f"{nees:.2g} ({_verdict(nees)})"
    )


def measure_cost(run: Any, robot: pinobs.Robot, chunk: int = 20, chunks: int = 100) -> dict:
    """Per update, ``chunk`` updates on ``run`` then ``chunk`` ``pin.aba`` calls on go1, repeated
    (as :func:`pinobs.evaluation.timing.measure_cost`: the same load for both); medians [s]
    and of the ratio, by CPU time of this thread (the machine is shared) and by wall time."""
    contacts = run.forces() > CONTACT_FORCE
    q, gyro, acc = run.q_joints(), run.gyro(), run.acc()
    aba = aba_call(robot)
    out: dict[str, Any] = {}
    gated = functools.partial(InvariantEKF, foot_gate=FOOT_GATE)
    radius = foot_sphere_radius(robot, GO1_FEET[0])  # the CLI's default, "urdf"
    rolling = functools.partial(InvariantEKF, foot_radius=radius)
    with threadpool_limits(limits=1, user_api="blas"):
        for name, cls in {**FILTERS, "inekf+gate": gated, "inekf+rolling": rolling}.items():
            for clock_name, clock in (("cpu", time.thread_time), ("wall", time.perf_counter)):
                ekf = cls(robot, GO1_FEET, gains=GAINS, imu_frame="imu_link")
                q0 = np.concatenate([run.base_q()[0], q[0]])
                ekf.reset(run.t[0], q0, gyro=gyro[0], acc=acc[0], contacts=contacts[0])
                ups, abas = [], []
                for k0 in range(1, 1 + chunk * min(chunks, (run.t.size - 1) // chunk), chunk):
                    t0 = clock()
                    for k in range(k0, k0 + chunk):
                        ekf.update(run.t[k], q[k], gyro[k], acc[k], contacts[k])
                    t1 = clock()
                    for _ in range(chunk):
                        aba()
                    t2 = clock()
                    ups.append((t1 - t0) / chunk)
                    abas.append((t2 - t1) / chunk)
                out[f"{name}_{clock_name}"] = {
                    "update_s": float(np.median(ups)),
                    "aba_s": float(np.median(abas)),
                    "ratio": float(np.median(np.array(ups) / np.array(abas))),
                }
        out.update(legged_run_cost(simulated_log(run, robot), robot, aba))
    return out


def legged_run_cost(log: Any, robot: pinobs.Robot, aba: Any, repeats: int = 3) -> dict:
    """What ``pinobs estimate --observer inekf`` costs per row: ``legged_run`` with its
    defaults (``slip_speed``, σ_q from the log, ``foot_radius="urdf"``, ``rolling_lift``; the
    joint velocities from ``kf``; contacts from the forces, or SEROW's probability) over the
    whole log, set-up included, per row; then as many ``pin.aba`` calls; ``repeats`` times,
    alternated; medians [s], by this thread's CPU time and by wall time (the same passes)."""
    import warnings

    from pinobs.io.legged_run import legged_run

    out: dict[str, Any] = {}
    for contacts in ("force", "probability"):
        times: dict[str, list[list[float]]] = {"cpu": [], "wall": []}
        for _ in range(repeats):
            c0, w0 = time.thread_time(), time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the run's notes (no base pose in the log)
                legged_run(robot, log, contacts=contacts)
            c1, w1 = time.thread_time(), time.perf_counter()
            for _ in range(len(log)):
                aba()
            c2, w2 = time.thread_time(), time.perf_counter()
            times["cpu"].append([(c1 - c0) / len(log), (c2 - c1) / len(log)])
            times["wall"].append([(w1 - w0) / len(log), (w2 - w1) / len(log)])
        for clock_name, pairs in times.items():
            ups, abas = np.array(pairs).T
            out[f"legged_run {contacts}_{clock_name}"] = {
                "update_s": float(np.median(ups)),
                "aba_s": float(np.median(abas)),
                "ratio": float(np.median(ups / abas)),
            }
    return out


def simulated_log(run: Any, robot: pinobs.Robot) -> Any:
    """A simulated run as the log ``pinobs estimate`` reads (its measured columns only: no
    truth, no contact flags, so contacts come from the forces)."""
    import warnings

    import pandas as pd

    from pinobs.io import read_log

    frame = pd.DataFrame(
        {k: v for k, v in run.columns.items() if not k.startswith(("truth.", "contact."))}
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the note that the log has no base pose
        return read_log(frame, robot)


def format_report(report: dict[str, Any]) -> str:
    """The markdown report: a short header, the runs that made each section's rows (their
    command, date, seconds and load, with the section's note: ``NOTES``), then the tables."""
    m = report["machine"]
    md = [
        "Made by `python benchmarks/legged_truth.py`, section by section: `--sections NAME "
        "--merge` reruns one and keeps every other row from `legged_truth.json` (conditions: "
        "the script's docstring; the JSON's `conditions`, and `gains`: each section's). Mean "
        "over the seeds (worst seed in brackets); drift per metre walked (trot, TALOS's step) "
        f"or per second (stand, sway). MuJoCo {m['mujoco']}, Python {m['python']}.",
        "",
        "Runs, the last of each section (a rerun replaces its line; load: the 1-min load "
        "average at the start and the end, on 2 cores shared with other work):",
        "",
        *_run_lines(report.get("runs") or {}),
        "",
        "go1, the foot frames measured (`foot_radius=0`, the filters' default), `GAINS`:",
        "",
    ]
    tables = [
        ("motions", "", True),
        (
            "humanoid",
            "TALOS (`simulate_humanoid`: 32 joints, flat soles, IMU at the base), `TALOS_GAINS`, "
            "drift per second (stand, sway) or per metre walked (step: the base's horizontal "
            "path, side-to-side shifts included):",
            True,
        ),
        ("long", "go1, long trot, `GAINS`:", True),
        (
            "old_gains",
            f"The trot with the first benchmark's gains (contact {OLD_GAINS.contact:g} m/s/√Hz, "
            f"kinematics {1e3 * OLD_GAINS.kinematics:g} mm; same runs):",
            False,
        ),
    ]
    for key, title, targets in tables:
        md += _section_lines(report.get(key) or {}, title, targets)
    md += _cost_lines(report.get("cost") or {})
    rolling = (
        f"go1 with rolling feet: both filters with `foot_radius={FOOT_RADIUS:g}` (go1's foot "
        "spheres; `pinobs.observers.rolling`: each foot measured at its point that touched the "
        "ground; a change of the measurement model the two filters share; `legged_run`'s "
        "default), "
    )
    md += _section_lines(
        report.get("rolling") or {},
        "`rolling`: "
        + rolling
        + f"`GO1_GAINS` (contact {GO1_GAINS.contact:g} m/s/√Hz, landing {GO1_GAINS.landing:g} "
        f"m/s/√Hz over a foot's first {GO1_GAINS.landing_time * 1e3:g} ms of contact, both "
        "measured: `density`):",
    )
    md += _section_lines(
        report.get("rolling_white") or {},
        "`rolling_white`: "
        + rolling
        + f"`GO1_WHITE_GAINS` (contact {GO1_WHITE_GAINS.contact:g} m/s/√Hz, no landing term; "
        "the rows before `GO1_GAINS`):",
    )
    md += _section_lines(
        report.get("rolling_gains") or {},
        "`rolling_gains`: "
        + rolling
        + f"`GAINS` (contact {GAINS.contact:g} m/s/√Hz; the rows before `GO1_WHITE_GAINS`):",
    )
    md += _section_lines(
        report.get("lift") or {},
        "`lift`: "
        + rolling
        + "and `rolling_lift=True` (rolling.py's R5: the anchored point's cycloid lift "
        "r (1 − cos φ) removed), `GO1_GAINS` (unchanged, not retuned; `lift_diagnosis`):",
    )
    md += _lift_lines(report.get("lift_diagnosis") or {})
    md += _density_lines(report.get("density") or {})
    md += _diagnosis_lines(report.get("density_diagnosis") or {})
    md += _slip_lines(report.get("slip") or {})
    md += _real_table(report.get("real") or {})
    md += _sim_nis_lines(report.get("real_sim") or {})
    return "\n".join(md)


def _section_lines(section: dict[str, Any], title: str, targets: bool = True) -> list[str]:
    """A section's table under ``title``, with issue 38's targets if ``targets``."""
    if not section:
        return []
    md = [*([title, ""] if title else []), *_table(section), ""]
    if targets:
        md += ["Targets (issue 38), as measured:", "", *_targets(section), ""]
    return md


def _cost_lines(cost: dict[str, Any]) -> list[str]:
    if not cost:
        return []
    md = [
        "Cost per update on go1 (trot, 4 feet, measured in the same run as `pin.aba`, "
        "interleaved in chunks of 20; medians; target ≤ 30× aba). The filter rows: "
        "`InvariantEKF` with its own defaults (no `slip_speed`, no joint velocities); the "
        "`legged_run` rows: what `pinobs estimate --observer inekf` does, `legged_run` with "
        "its defaults (`slip_speed`, σ_q from the log, the URDF's rolling feet, joint "
        "velocities from `kf`) over the whole simulated log, set-up included, per row, "
        "contacts from the forces or SEROW's probability; alternated with as many `pin.aba` "
        "calls, 3 times:",
        "",
        "| filter | clock | update [µs] | aba [µs] | ratio |",
        "|---|---|---:|---:|---:|",
    ]
    for key, c in cost.items():
        name, clock = key.rsplit("_", 1)
        md.append(
            f"| `{name}` | {clock} | {1e6 * c['update_s']:.0f} | {1e6 * c['aba_s']:.2f} | "
            f"{c['ratio']:.0f}× ({'met' if c['ratio'] <= 30 else 'missed'}) |"
        )
    return [*md, ""]


def _run_lines(runs: dict[str, Any]) -> list[str]:
    """One line per entry of ``report["runs"]``, with its section's note."""
    md = []
    for label, r in runs.items():
        note = NOTES.get(label.split()[0], "")
        md.append(
            f"* `{label}`: {r['date']}, `{r['command']}`, {r['seconds']:.0f} s, load "
            f"{r['load']}{'. ' + note if note else ''}."
        )
    return md


def record_run(report: dict[str, Any], args: argparse.Namespace, seconds: float, load: str) -> None:
    """``report["runs"]``: this run's entry for each section it ran, replacing that section's
    entries (all of them when the section was run whole, else the one of the same rows)."""
    import sys

    runs = report.setdefault("runs", {})
    entry = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "command": " ".join(["python", "benchmarks/legged_truth.py", *sys.argv[1:]]),
        "seconds": seconds,
        "load": load,
    }
    for label in _ran(args):
        section = label.split()[0]
        whole = label == section
        for old in [k for k in runs if k.split()[0] == section and (whole or k == label)]:
            del runs[old]
        runs[label] = entry


def real_log_nis() -> dict[str, Any]:
    """The real Go1 log's feet NIS over stance rows and standing speed, per contact mode and
    gate (module docstring, ``real``); empty without the shared data."""
    import warnings

    import real_data as real  # beside this script

    from pinobs.io import read_log
    from pinobs.io.legged_run import legged_run

    root = real.data_root()
    if root is None or not (root / real.SEROW_GO1).is_file():
        return {}
    go1 = pinobs.load("go1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the note that the log has no base pose
        log = read_log(real.serow_go1_frame(root / real.SEROW_GO1), go1)
    out: dict[str, Any] = {}
    modes = [(c, g) for c in ("force", "probability") for g in (None, FOOT_GATE)]
    white = {"joint_std": None, "slip_speed": False}  # the foot noise before (white)
    rows: list[tuple[str, InEKFGains | None, str, float | None, dict[str, Any]]]
    rows = [(f"defaults, {c}, gate {g}", None, c, g, {}) for c, g in modes]
    rows += [  # the default σ_q rule before: the log's first second (it settles then)
        (
            f"defaults but σ_q from the first second, {c}",
            None,
            c,
            None,
            {"joint_std": "first-second"},
        )
        for c in ("force", "probability")
    ]
    rows += [  # the foot frames measured (the runner's default before its foot_radius="urdf")
        (f"defaults but foot_radius 0, {c}", None, c, None, {"foot_radius": 0.0})
        for c in ("force", "probability")
    ]
    rows += [  # the IMU's densities from the log's stillest second, and eq. (10)
        (f"defaults + imu_noise='log', {c}", None, c, None, {"imu_noise": "log"})
        for c in ("force", "probability")
    ]
    rows += [(f"white, {c}, gate {g}", GAINS, c, g, white) for c, g in modes]
    rows += [  # the contact density measured at go1's touch point (the rolling rows' gains)
        (f"white, GO1_GAINS, {c}", GO1_GAINS, c, None, white) for c in ("force", "probability")
    ]
    rows += [  # rolling.py's R4 alone (rolling_lift=False): the default before R5's
        (f"defaults but rolling_lift=False, {c}", None, c, None, {"rolling_lift": False})
        for c in ("force", "probability")
    ]
    rows += [
        (
            f"white, GO1_GAINS but rolling_lift=False, {c}",
            GO1_GAINS,
            c,
            None,
            {**white, "rolling_lift": False},
        )
        for c in ("force", "probability")
    ]
    rows += [
        (
            f"white, probability, log's noise, kinematics {1e3 * k:g} mm",
            dataclasses.replace(LOG_GAINS, kinematics=k),
            "probability",
            None,
            white,
        )
        for k in (1e-3, 3e-4, 1e-4)
    ]
    for name, gains, contacts, gate, foot in rows:
        run, flags, nis, dof = legged_run(
            go1, log, gains=gains, contacts=contacts, foot_gate=gate, **foot
        )
        c = run.consistency
        still = np.abs(run.v[:, 6:]).max(axis=1) < 0.05
        speed = np.linalg.norm(run.v[still, :3], axis=1)
        per_dof = nis / np.maximum(dof, 1)
        stance = dof > 0
        out[name] = {
            "stance_rows": c.samples,
            "rows": run.rows,
            "nis_per_dof": c.mean_nis,
            **{k: c.details[k] for k in ("median_per_dof", "inside", "below", "above")},
            "gated": c.gated,
            "in_contact": float(flags.mean()),
            "still_rows": int(still.sum()),
            "still_speed_max": float(speed.max()),
            "still_speed_median": float(np.median(speed)),
            "median_per_dof_standing": float(np.median(per_dof[stance & still])),
            "median_per_dof_walking": float(np.median(per_dof[stance & ~still])),
            "first_second_speed_max": float(
                np.linalg.norm(run.v[run.t < run.t[0] + 1, :3], axis=1).max()
            ),
            "diverged": int(np.isnan(run.q).any(axis=1).sum()),
        }
    return out


def simulated_nis(duration: float = 10.0, seed: int = 0) -> dict[str, Any]:
    """The ``real`` table's settings on the MuJoCo go1 (stand, sway, trot; where
    ``LEGGED_GAINS`` were chosen), through ``legged_run`` from the simulated log (contacts
    from the forces): the stance rows' NIS and the base velocity error after 0.5 s."""
    from pinobs.io.legged_run import legged_run

    go1 = pinobs.load("go1")
    white = {"joint_std": None, "slip_speed": False}
    settings = {"defaults": (None, {}), "defaults but foot_radius 0": (None, {"foot_radius": 0.0}),
                "defaults but rolling_lift=False": (None, {"rolling_lift": False}),
                "defaults + imu_noise='log'": (None, {"imu_noise": "log"}),
                "white, GAINS": (GAINS, white),
                "white, GO1_GAINS": (GO1_GAINS, white),
                "white, InEKFGains()": (InEKFGains(), white)}  # fmt: skip
    out: dict[str, Any] = {}
    for motion, noise in [(m, n) for n in ("white", "quantised") for m in LEGGED_MOTIONS]:
        run = simulate_legged(
            motion, duration, seed=seed, noise=NOISE if noise == "white" else QUANTISED, robot=go1
        )
        label = motion if noise == "white" else f"{motion} (quantised encoders)"
        log = simulated_log(run, go1)
        late = run.t > run.t[0] + 0.5
        true_std = np.std(run.q_joints() - run.q_joints(truth=True), axis=0)
        for name, (gains, foot) in settings.items():
            if noise != "white" and name in ("white, InEKFGains()", "white, GO1_GAINS"):
                continue
            est = legged_run(go1, log, gains=gains, **foot).run
            c = est.consistency
            err = est.v[late, :3] - run.base_v()[late, :3]
            out[f"{label}, {name}"] = {
                "sigma_q_over_true": _sigma_ratio(go1, log, true_std)
                if name == "defaults"
                else None,
                "nis_per_dof": c.mean_nis,
                **{k: c.details[k] for k in ("median_per_dof", "inside", "below", "above")},
                "v_rms": float(np.sqrt(np.mean(err**2))),
            }
    return out


def _sigma_ratio(go1: pinobs.Robot, log: Any, true_std: np.ndarray) -> list[float]:
    """``joint_std="log"``'s σ_q per joint over the readings' true error σ: (min, max)."""
    from pinobs.observers.noise import still_noise_std

    fixed = pinobs.load(go1.model, lock=[list(go1.model.names)[1]])
    ratio = still_noise_std(log.t, log.q[:, 7:], fixed) / true_std
    return [float(ratio.min()), float(ratio.max())]


def _sim_nis_lines(sim: dict[str, Any]) -> list[str]:
    if not sim:
        return []
    md = [
        "Where `legged_run`'s defaults were chosen: the MuJoCo go1 (10 s, seed 0) through "
        "`legged_run` (contacts from the forces), the stance rows' NIS and the base velocity "
        "error after 0.5 s; the encoders white (`NOISE`, 5e-4 rad) or quantised as the real "
        'log\'s (`QUANTISED`); `defaults` with `foot_radius="urdf"` (2 cm), `defaults but '
        "foot_radius 0` the foot frames; the last column: the defaults' σ_q per joint over the "
        "readings' true error σ:",
        "",
        "| motion, foot noise | NIS/dof mean (median) | inside | below | above | v rms [m/s] "
        "| σ_q / true σ (min-max) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, r in sim.items():
        ratio = r.get("sigma_q_over_true")
        md.append(
            f"| {name} | {r['nis_per_dof']:.3g} ({r['median_per_dof']:.3g}) "
            f"| {100 * r['inside']:.1f} % | {100 * r['below']:.1f} % "
            f"| {100 * r['above']:.1f} % | {r['v_rms']:.4f} "
            f"| {'' if ratio is None else f'{ratio[0]:.2f}-{ratio[1]:.2f}'} |"
        )
    return [*md, ""]


class SlidingLegs:
    """go1's legs with one foot's measured position moved by ``offset`` (IMU frame): the foot
    slid by ``R_imuᵀ Δd`` in the world while its force keeps it in contact (a
    :class:`~pinobs.observers.legs.ContactKinematics`)."""

    def __init__(self, legs: Any) -> None:
        self.legs, self.feet = legs, legs.feet
        self.nq_joints, self.nv_joints = legs.nq_joints, legs.nv_joints
        self.imu_placement = legs.imu_placement
        self.offset = np.zeros((len(legs.feet), 3))

    def positions_and_jacobians(self, q_joints: Any) -> tuple[Any, Any]:
        h, jac = self.legs.positions_and_jacobians(q_joints)
        return h + self.offset, jac


def slip_track(
    run: Any, *, gate: float | None, speed: float, duration: float, t0: float = 1.0
) -> tuple[np.ndarray, int]:
    """The invariant EKF (``GAINS``, started on the truth) with FL sliding at ``speed`` [m/s]
    (direction (2, 1, 0)/√5) from ``t0`` for ``duration`` [s]: the base velocity error
    ``(samples, 3)`` and the foot measurements gated."""
    robot = pinobs.load("go1")
    legs = SlidingLegs(FootKinematics(robot, GO1_FEET, imu_frame="imu_link"))
    ekf = InvariantEKF(legs, gains=GAINS, foot_gate=gate)
    q, gyro, acc = run.q_joints(), run.gyro(), run.acc()
    contacts = run.forces() > CONTACT_FORCE
    base_q, base_v = run.base_q(), run.base_v()
    R_imu = Rotation.from_quat(base_q[:, 3:]).as_matrix() @ legs.imu_placement[0]
    u = speed * np.array([2.0, 1.0, 0.0]) / np.sqrt(5.0)
    q0, v0 = np.concatenate([base_q[0], q[0]]), np.concatenate([base_v[0], np.zeros(12)])
    ekf.reset(run.t[0], q0, v0, gyro=gyro[0], acc=acc[0], contacts=contacts[0])
    err, gated = [np.zeros(3)], 0
    for k in range(1, run.t.size):
        legs.offset[0] = R_imu[k].T @ (u * min(max(run.t[k] - t0, 0.0), duration))
        est = ekf.update(run.t[k], q[k], gyro[k], acc[k], contacts[k])
        err.append(est.v[:3] - base_v[k, :3])
        gated += len(est.gated)
    return np.array(err), gated


#: (speed [m/s], duration [s]) of the slides of the ``slip`` section.
SLIDES = ((1.0, 0.03), (0.5, 0.1), (0.2, 1.0))


def slip_table() -> dict[str, Any]:
    """The ``slip`` section: go1 standing 3 s (seed 0), FL sliding at t = 1 s, base velocity
    error RMS (and max) over the slide and 0.5 s after, without and with the foot gate."""
    run = simulate_legged("stand", 3.0, seed=0, noise=NOISE)
    out: dict[str, Any] = {}
    for speed, duration in SLIDES:
        window = (run.t >= 1.0) & (run.t <= 1.5 + duration)
        row: dict[str, Any] = {}
        for gate in (None, FOOT_GATE, 1e-2):
            err, gated = slip_track(run, gate=gate, speed=speed, duration=duration)
            row[str(gate)] = {
                "rms": float(np.sqrt(np.mean(err[window] ** 2))),
                "max": float(np.abs(err[window]).max()),
                "gated": gated,
                "before": float(np.sqrt(np.mean(err[(run.t > 0.2) & (run.t < 1.0)] ** 2))),
            }
        out[f"{100 * speed * duration:g} cm in {duration:g} s ({speed:g} m/s)"] = row
    return out


def _slip_lines(slip: dict[str, Any]) -> list[str]:
    if not slip:
        return []
    gates = list(next(iter(slip.values())))
    md = [
        "A foot that slides while its force keeps it in contact (`SlidingLegs`: go1 standing, "
        "seed 0, FL moved in the world from t = 1 s; the invariant EKF from the truth): base "
        "velocity error RMS [m/s] over the slide and 0.5 s after (max; foot measurements gated):",
        "",
        "| slide | " + " | ".join(f"foot_gate {g}" for g in gates) + " |",
        "|---|" + "---:|" * len(gates),
    ]
    for name, row in slip.items():
        cells = [f"{r['rms']:.4f} ({r['max']:.3f}; {r['gated']})" for r in row.values()]
        md.append(f"| {name} | " + " | ".join(cells) + " |")
    before = next(iter(next(iter(slip.values())).values()))["before"]
    return [*md, "", f"Before the slide: {before:.4f} m/s RMS.", ""]


def _real_table(real: dict[str, Any]) -> list[str]:
    if not real:
        return []
    md = [
        "SEROW's Go1 log (real, 25 s at 400 Hz, no truth): the feet's NIS over the stance rows "
        "(each row against its own 95 % χ² interval, dof = 3 × feet measured; a consistent "
        "filter: NIS/dof 1, 95 % inside) and the base speed on the stands (every joint slower "
        "than 0.05 rad/s) and over the first second. `defaults`: `legged_run`'s (the CLI's: "
        "`LEGGED_GAINS`, σ_q per joint from the log's stillest second, `slip_speed`; chosen on "
        "MuJoCo, this log held out); `σ_q from the first second`: the default before; "
        "`imu_noise='log'`: the IMU's densities from the log's stillest second and eq. (10) "
        "(off by default since this table); `white`: the foot noise before (`joint_std=None, "
        "slip_speed=False`) with `GAINS`, `GO1_GAINS` or `LOG_GAINS`; every row with `legged_run`'s "
        'default `foot_radius="urdf"` (go1\'s 2 cm foot spheres: the rolling feet) but '
        "`foot_radius 0` (the foot frames, the default before), and with `rolling_lift` "
        "(rolling.py's R5, the default since the `lift` rows; first run once, after them) but "
        "`rolling_lift=False` (R4 alone, the default before):",
        "",
        "| contacts, gate | stance rows | NIS/dof mean (median) | inside | below | above "
        "| gated | in contact | NIS/dof median standing / walking "
        "| stand speed max (median) [m/s] | first 1 s speed max | rows lost |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, r in real.items():
        md.append(
            f"| {name} | {r['stance_rows']} / {r['rows']} | {r['nis_per_dof']:.3g} "
            f"({r['median_per_dof']:.3g}) | {100 * r['inside']:.1f} % | {100 * r['below']:.1f} % "
            f"| {100 * r['above']:.1f} % | {r['gated']} | {100 * r['in_contact']:.1f} % "
            f"| {r['median_per_dof_standing']:.3g} / {r['median_per_dof_walking']:.3g} "
            f"| {r['still_speed_max']:.3f} ({r['still_speed_median']:.3f}) "
            f"| {r.get('first_second_speed_max', math.nan):.3f} | {r.get('diverged', 0)} |"
        )
    return [*md, ""]


def _runs(
    report: dict[str, Any],
    section: str,
    label: str,
    run: Any,
    robot: Any,
    gains: InEKFGains,
    foot_radius: float = 0.0,
    starts: Any = tuple(STARTS),
) -> None:
    lift = section == "lift"
    for start_kind in starts if section != "old_gains" else ("truth", "large"):
        key = f"{label}, {start_kind} start"
        report[section].setdefault(key, {name: [] for name in FILTERS})
        for name in FILTERS:
            out: dict[str, Any] = run_filter(name, run, robot, start_kind, gains, foot_radius, lift)
            out["seed"] = run.seed
            report[section][key][name].append(out)
            print(section, key, run.seed, name, out, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time [s]")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--motions", nargs="+", default=list(LEGGED_MOTIONS))
    parser.add_argument("--long", type=float, default=60.0, help="long trot [s] (0: none)")
    parser.add_argument("--long-seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument(
        "--sections",
        nargs="+",
        choices=["go1", "humanoid", "cost", "real", "slip", "rolling", "lift", "density"],
        default=["go1", "humanoid"],
        help="what to run (go1 includes cost; cost alone: its trot only); with --merge, "
        "the others are kept from legged_truth.json",
    )
    parser.add_argument("--merge", action="store_true", help="keep the sections not run")
    parser.add_argument(
        "--starts",
        nargs="+",
        choices=list(STARTS),
        default=list(STARTS),
        help="the starts of the rolling and lift sections' rows",
    )
    parser.add_argument(
        "--humanoid-motions",
        nargs="+",
        choices=HUMANOID_MOTIONS,
        default=list(HUMANOID_MOTIONS),
        help="TALOS's motions to run (the humanoid section; the others' rows are kept)",
    )
    parser.add_argument("--quick", action="store_true", help="5 s, seed 0, no files written")
    args = parser.parse_args()
    if args.quick:
        args.duration, args.seeds, args.long = 5.0, [0], 0.0
    here = Path(__file__).parent
    start, load = time.time(), os.getloadavg()[0]
    report: dict[str, Any] = {section: {} for section in SECTIONS}
    if args.merge:
        report.update(json.loads((here / "legged_truth.json").read_text()))
    _run_sections(report, args)
    record_run(report, args, time.time() - start, f"{load:.1f} → {os.getloadavg()[0]:.1f}")
    report["machine"] = {"python": platform.python_version(), "mujoco": mujoco.__version__}
    report["conditions"] = {
        "contact_force_N": CONTACT_FORCE,
        "starts_roll_deg_lateral_speed_m_s": STARTS,
        "noise": NOISE.__dict__,
        "quantised_noise": QUANTISED.__dict__,
    }
    md = format_report(report)
    print(md)
    if not args.quick:
        (here / "legged_truth.json").write_text(json.dumps(report, indent=1) + "\n")
        (here / "legged_truth.md").write_text(md)


#: The report's sections (``legged_truth.json``'s keys besides ``runs``, ``gains``,
#: ``machine`` and ``conditions``); ``rolling_gains``, ``rolling_white``: the rolling rows with
#: ``GAINS`` and ``GO1_WHITE_GAINS`` (kept).
SECTIONS = ("motions", "long", "old_gains", "cost", "humanoid", "real", "slip", "real_sim",
            "rolling", "rolling_white", "rolling_gains", "lift", "lift_diagnosis", "density",
            "density_diagnosis", "gains")  # fmt: skip


def _gains(**named: InEKFGains) -> dict[str, Any]:
    return {name: dataclasses.asdict(g) for name, g in named.items()}


def _run_sections(report: dict[str, Any], args: argparse.Namespace) -> None:
    """The sections of ``args.sections`` into ``report``, each with its gains (``gains``)."""
    gains = report["gains"]
    if "go1" in args.sections:
        report.update(motions={}, long={}, old_gains={}, cost={})
        _go1_sections(report, args)
        gains["go1"] = _gains(GAINS=GAINS, OLD_GAINS=OLD_GAINS)
    elif "cost" in args.sections:
        robot = pinobs.load("go1")
        run = simulate_legged("trot", args.duration, seed=args.seeds[0], noise=NOISE, robot=robot)
        report["cost"] = measure_cost(run, robot)
    if {"go1", "cost"} & set(args.sections):
        gains["cost"] = _gains(GAINS=GAINS)
    if "humanoid" in args.sections:
        _humanoid_section(report, args)
        gains["humanoid"] = _gains(TALOS_GAINS=TALOS_GAINS)
    if "real" in args.sections:
        report["real"] = real_log_nis()
        report["real_sim"] = simulated_nis()
        gains["real"] = {
            "defaults": "legged_run's LEGGED_GAINS, σ_q from the log, slip_speed",
            **_gains(GAINS=GAINS, GO1_GAINS=GO1_GAINS, LOG_GAINS=LOG_GAINS),
        }
    if "slip" in args.sections:
        report["slip"] = slip_table()
        gains["slip"] = _gains(GAINS=GAINS)
    if "density" in args.sections:
        report["density"] = density_section()
        report["density_diagnosis"] = density_diagnosis()
        gains["density"] = _gains(**DIAGNOSIS_GAINS)
    if "rolling" in args.sections:
        _rolling_section(report, args)
        gains["rolling"] = _gains(GO1_GAINS=GO1_GAINS)
    if "lift" in args.sections:
        _rolling_section(report, args, "lift")
        report["lift_diagnosis"] = lift_diagnosis()
        gains["lift"] = _gains(GO1_GAINS=GO1_GAINS)


def _ran(args: argparse.Namespace) -> list[str]:
    """A label per section run, for ``report["runs"]``: its name, and the motions run when
    not all (go1, rolling: ``--motions`` and the long trot; humanoid: TALOS's)."""
    out = []
    for section in args.sections:
        if section == "humanoid" and args.humanoid_motions != list(HUMANOID_MOTIONS):
            section += " " + " ".join(args.humanoid_motions)
        elif section in ("go1", "rolling", "lift") and (
            set(args.motions) != set(LEGGED_MOTIONS) or args.long <= 0
        ):
            section += " " + " ".join(
                [*args.motions, *([f"+ trot {args.long:g} s"] if args.long > 0 else [])]
            )
        out.append(section)
    return out


def _humanoid_section(report: dict[str, Any], args: argparse.Namespace) -> None:
    """TALOS's rows: stand and sway for ``--duration`` over ``--seeds``; the stepping for
    ``--long`` s over ``--long-seeds`` (``--duration`` and ``--seeds`` without ``--long``);
    ``--humanoid-motions`` keeps the other motions' rows (from the JSON with ``--merge``)."""
    section = report.setdefault("humanoid", {})
    for key in [k for k in section if k.split(",")[0].split()[1] in args.humanoid_motions]:
        del section[key]
    talos = pinobs.load("talos")
    for motion in args.humanoid_motions:
        long = motion == "step" and args.long > 0
        duration, label = (
            (args.long, f"TALOS step {args.long:g} s")
            if long
            else (
                args.duration,
                f"TALOS {motion}",
            )
        )
        for seed in args.long_seeds if long else args.seeds:
            run = simulate_humanoid(motion, duration, seed=seed, noise=NOISE, robot=talos)
            _runs(report, "humanoid", label, run, talos, TALOS_GAINS)


def _go1_sections(report: dict[str, Any], args: argparse.Namespace) -> None:
    robot = pinobs.load("go1")
    for motion in args.motions:
        for seed in args.seeds:
            run = simulate_legged(motion, args.duration, seed=seed, noise=NOISE, robot=robot)
            _runs(report, "motions", motion, run, robot, GAINS)
            if motion == "trot":
                _runs(report, "old_gains", "trot, old gains", run, robot, OLD_GAINS)
                if seed == args.seeds[0]:
                    report["cost"] = measure_cost(run, robot)
    for seed in args.long_seeds if args.long > 0 else []:
        run = simulate_legged("trot", args.long, seed=seed, noise=NOISE, robot=robot)
        _runs(report, "long", f"trot {args.long:g} s", run, robot, GAINS)


def _rolling_section(
    report: dict[str, Any], args: argparse.Namespace, name: str = "rolling"
) -> None:
    """go1's ``--motions`` over ``--seeds`` and the ``--long`` trot over ``--long-seeds`` with
    ``foot_radius=FOOT_RADIUS`` (section ``lift``: and ``rolling_lift``), the ``--starts``; the
    section's other rows are kept (from the JSON with ``--merge``), those of the motions run
    replaced; gains ``GO1_GAINS``."""
    section = report.setdefault(name, {})
    labels = [*args.motions, *([f"trot {args.long:g} s"] if args.long > 0 else [])]
    for key in [k for k in section if k.split(",")[0] in labels]:
        del section[key]
    robot = pinobs.load("go1")
    radius = {foot_sphere_radius(robot, foot) for foot in GO1_FEET}  # the URDF's spheres
    if radius != {FOOT_RADIUS}:  # the simulation's feet
        raise RuntimeError(f"go1.urdf's foot spheres {radius} are not the simulation's")
    for motion in args.motions:
        for seed in args.seeds:
            run = simulate_legged(motion, args.duration, seed=seed, noise=NOISE, robot=robot)
            _runs(report, name, motion, run, robot, GO1_GAINS, FOOT_RADIUS, args.starts)
    for seed in args.long_seeds if args.long > 0 else []:
        run = simulate_legged("trot", args.long, seed=seed, noise=NOISE, robot=robot)
        label = f"trot {args.long:g} s"
        _runs(report, name, label, run, robot, GO1_GAINS, FOOT_RADIUS, args.starts)


if __name__ == "__main__":
    main()
