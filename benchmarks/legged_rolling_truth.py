"""Does go1's foot centre move during stance, and does rolling explain it?  MuJoCo's truth.

go1 trotting (`simulate_legged("trot", 10 s, seed 0)`); over the stance rows the filters use
(measured normal force > `CONTACT_FORCE`, `benchmarks/legged_truth.py`), per world axis: the
RMS and mean of the foot centre's true world velocity `ċ` (against zero, the filters' model
with `foot_radius=0`), of the rolling prediction `ω_foot × r n` (eq. R1 of
`pinobs.observers.rolling`) and of the touch-down point's velocity `ċ + ω × R_f s` (eq. R2,
what `foot_radius=r` measures); all rows, the first 20 ms after the force crosses the
threshold (the landing) and the rest.  Then the contact density recipe of `GAINS`' comment,
`sqrt(Σ|Δd|² / (3 Σ τ))` over the stances, for the centre and the touch-down point.

    python benchmarks/legged_rolling_truth.py
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

import pinobs
from pinobs.model import foot_sphere_radius
from pinobs.simulation.legged import GO1_FEET, simulate_legged

CONTACT_FORCE = 20.0  # [N], legged_truth.py's
LANDING = 10  # samples (20 ms at 500 Hz)


def velocities(run, robot, r: float, down: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per row and foot, world [m/s]: the centre's velocity, eq. R1's ``ω × r n`` and the
    velocity of the point anchored at each touch-down (eq. R2)."""
    model, data = robot.model, robot.model.createData()
    up = np.array([0.0, 0.0, 1.0])
    base_q, base_v = run.base_q(), run.base_v()
    q_true = run.q_joints(truth=True)
    dq_true = run.stack(*(f"truth.dq.{j}" for j in run.joints))
    fids = [model.getFrameId(f) for f in GO1_FEET]
    centre, rolling, point = (np.zeros((run.t.size, 4, 3)) for _ in range(3))
    anchor = np.zeros((4, 3))
    for k in range(run.t.size):
        q = np.concatenate([base_q[k], q_true[k]])
        pin.forwardKinematics(model, data, q, np.concatenate([base_v[k], dq_true[k]]))
        pin.updateFramePlacements(model, data)
        for i, fid in enumerate(fids):
            rot = data.oMf[fid].rotation
            if down[k, i] and (k == 0 or not down[k - 1, i]):
                anchor[i] = rot.T @ (-r * up)  # eq. R2's s
            twist = pin.getFrameVelocity(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            centre[k, i] = twist.linear
            rolling[k, i] = np.cross(twist.angular, r * up)  # eq. R1
            point[k, i] = twist.linear + np.cross(twist.angular, rot @ anchor[i])
    return centre, rolling, point


def density(a: np.ndarray, down: np.ndarray, dt: float) -> float:
    """``sqrt(Σ|Δd|² / (3 Σ τ))`` over the stances (`GAINS`' recipe) [m/s/√Hz]."""
    num = den = 0.0
    for i in range(down.shape[1]):
        idx = np.flatnonzero(down[:, i])
        for stance in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):
            if stance.size > 1:
                d = a[stance, i].sum(axis=0) * dt
                num, den = num + d @ d, den + 3 * stance.size * dt
    return float(np.sqrt(num / den))


def main() -> None:
    run = simulate_legged("trot", 10.0, seed=0)
    robot = pinobs.load("go1")
    r = foot_sphere_radius(robot, GO1_FEET[0])
    down = run.forces() > CONTACT_FORCE
    centre, rolling, point = velocities(run, robot, r, down)
    landing = np.zeros_like(down)
    for i in range(4):
        for s in np.flatnonzero(down[1:, i] & ~down[:-1, i]) + 1:
            landing[s : s + LANDING, i] = down[s : s + LANDING, i]
    print(f"foot radius {r} m (go1.urdf); stance rows: force > {CONTACT_FORCE} N; x / y / z [m/s]")
    for name, rows in (("all", down), ("landing", landing), ("rest", down & ~landing)):
        for what, a in (("centre", centre), ("ω × r n", rolling), ("touch-down pt", point)):
            rms, mean = np.sqrt(np.mean(a[rows] ** 2, axis=0)), a[rows].mean(axis=0)
            print(f"{name:8s} ({rows.sum():5d}) {what:14s} rms {rms.round(4)} mean {mean.round(4)}")
    dt = float(np.mean(np.diff(run.t)))
    for what, a in (("centre", centre), ("touch-down point", point)):
        print(f"contact density, {what}: {density(a, down, dt):.4g} m/s/√Hz")


if __name__ == "__main__":
    main()
