"""TALOS stepping in MuJoCo (``pinobs.simulation.humanoid``): it stays up, its swing sole
leaves the floor and carries weight again, and the invariant EKF tracks its base."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("mujoco")

import pinobs
from pinobs.errors import UnknownNameError
from pinobs.model import FootKinematics
from pinobs.observers.inekf import InvariantEKF
from pinobs.simulation import humanoid, legged
from pinobs.simulation.humanoid import (
    STEP_LENGTH,
    STEP_SHIFT,
    STEP_SWING,
    TALOS_FEET,
    simulate_humanoid,
)
from tests.simulation.test_legged import GAINS, NOISE, QUIET

STEP = STEP_SHIFT + STEP_SWING  # [s], one step: the right foot swings in [STEP_SHIFT, STEP)


@cache
def talos() -> pinobs.Robot:
    return pinobs.load("talos")


@cache
def first_steps(noise: legged.LeggedNoise = QUIET) -> legged.LeggedRun:
    """The first step and the next shift of the weight (onto the foot that swung)."""
    return simulate_humanoid("step", STEP + 1.0, seed=0, noise=noise, robot=talos())


def weight() -> float:
    return 9.81 * sum(i.mass for i in talos().model.inertias)


def test_the_humanoid_names_are_still_importable_from_legged() -> None:
    assert legged.simulate_humanoid is humanoid.simulate_humanoid
    assert legged.TALOS_FEET == TALOS_FEET and "step" in legged.HUMANOID_MOTIONS
    with pytest.raises(AttributeError, match="no_such_name"):
        _ = legged.no_such_name  # type: ignore[attr-defined]
    with pytest.raises(UnknownNameError, match="stand, sway, step"):
        simulate_humanoid("run", 1.0)


def test_the_swing_sole_leaves_the_floor_and_carries_weight_again() -> None:
    """Noise-free: in the middle of its swing the right sole carries nothing and the left one
    the weight (±5 %); once the next shift moves the weight onto it, ≥ 30 % of it; the base
    stays up (no SimulationFailed, above 0.95 m, tilt < 3°)."""
    run = first_steps()
    t, forces, w = run.t, run.forces(), weight()
    swing = (t > STEP_SHIFT + 0.2) & (t < STEP - 0.2)
    assert float(np.abs(forces[swing, 1]).max()) < 1e-3 * w  # measured 0
    assert float(np.abs(forces[swing, 0] / w - 1.0).max()) < 0.05  # measured 0.008
    assert not run["contact.right_sole_link"][swing].any()
    after = t > STEP + 0.7
    assert float(forces[after, 1].min()) > 0.3 * w  # measured 0.37
    assert run["contact.right_sole_link"][after].all()
    assert float(run["truth.p.z"].min()) > 0.95
    tilt = Rotation.from_quat(run.base_q()[:, 3:]).as_euler("xyz")[:, :2]
    assert float(np.abs(tilt).max()) < np.radians(3.0)  # measured 1.4°


def test_the_swing_sole_lands_a_step_ahead() -> None:
    """The right sole moves forward by about ``STEP_LENGTH`` (planned; measured 5.7 of 6 cm),
    the left one stays (< 3 mm)."""
    run = first_steps()
    legs = FootKinematics(talos(), TALOS_FEET)
    base, q = run.base_q(), run.q_joints(truth=True)

    def soles(k: int) -> np.ndarray:
        R = Rotation.from_quat(base[k, 3:]).as_matrix()
        return base[k, :3] + legs.positions(q[k]) @ R.T

    moved = soles(-1) - soles(0)
    assert abs(moved[1, 0] - STEP_LENGTH) < 0.25 * STEP_LENGTH
    assert float(np.abs(moved[0]).max()) < 3e-3
    assert float(np.abs(moved[:, 2]).max()) < 3e-3  # both soles back on the floor


def test_the_invariant_ekf_tracks_the_stepping_base() -> None:
    """The benchmark's gains and sensor noise, started on the truth: base velocity error RMS
    < 0.02 m/s over the step and the next shift (measured 0.0079 m/s)."""
    run = first_steps(NOISE)
    err = _inekf_velocity_errors(run)
    assert float(np.sqrt(np.mean(np.square(err)))) < 0.02
    assert float(np.abs(run.base_v()[:, :3]).max()) > 0.05  # it does move


def _inekf_velocity_errors(run: legged.LeggedRun) -> np.ndarray:
    ekf = InvariantEKF(talos(), TALOS_FEET, gains=GAINS)
    q, gyro, acc, forces = run.q_joints(), run.gyro(), run.acc(), run.forces()
    base_q, base_v = run.base_q(), run.base_v()
    ekf.reset(
        run.t[0],
        np.concatenate([base_q[0], q[0]]),
        np.concatenate([base_v[0], np.zeros(len(run.joints))]),
        gyro=gyro[0],
        acc=acc[0],
        contacts=forces[0] > 20.0,
    )
    return np.array(
        [
            ekf.update(run.t[k], q[k], gyro[k], acc[k], forces[k] > 20.0).v[:3] - base_v[k, :3]
            for k in range(1, run.t.size)
        ]
    )


@pytest.mark.slow
def test_talos_walks_60_seconds_and_the_velocity_error_stays_bounded() -> None:
    """60 s of stepping (24 steps): it stays up, walks forward > 1 m (planned 1.44 m), and the
    invariant EKF's velocity error RMS over the last 10 s is < 0.02 m/s."""
    run = simulate_humanoid("step", 60.0, seed=1, noise=NOISE, robot=talos())
    assert float(run["truth.p.x"][-1] - run["truth.p.x"][0]) > 1.0
    err = _inekf_velocity_errors(run)
    last = run.t[1:] > 50.0
    assert float(np.sqrt(np.mean(np.square(err[last])))) < 0.02
