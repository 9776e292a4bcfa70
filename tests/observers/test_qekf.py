"""The contact-aided quaternion EKF (``pinobs.observers.qekf``), the invariant EKF's baseline:
invariance on the truth, convergence from a perturbed start, its error dynamics against
finite differences, and its interface (the invariant EKF's).

The truths are those of ``tests/observers/test_inekf.py`` (made independently of both
filters: the exact flow of the IMU model by a generic matrix exponential).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from threadpoolctl import threadpool_limits

import pinobs
from pinobs.errors import GainError, NotResetError, UnknownNameError
from pinobs.observers.inekf import GRAVITY, InEKFPrior, gammas, propagate_mean
from pinobs.observers.qekf import QuaternionEKF, error_dynamics
from tests.observers.test_inekf import (
    GO1_FEET,
    Go1Legs,
    SyntheticLegs,
    pose_errors,
    run,
    synthetic_truth,
    truth,
)
from tests.observers.test_rolling import _worst_pose_error


@pytest.fixture(autouse=True, scope="module")
def _one_blas_thread():
    with threadpool_limits(limits=1):
        yield


def test_started_on_the_truth_it_stays_there_through_contact_changes() -> None:
    samples = synthetic_truth()
    ekf = QuaternionEKF(SyntheticLegs(3))
    worst = 0.0
    seen = set()
    for est, (R, v, p) in run(ekf, samples):
        worst = max(worst, *pose_errors(est, R, v, p))
        seen.add(est.contacts)
        assert est.covariance.shape == (15 + 3 * len(est.contacts),) * 2
    assert worst < 1e-9
    assert seen == {("foot0", "foot1", "foot2"), ("foot0", "foot2"), ("foot0", "foot2", "foot1")}
    np.testing.assert_allclose(est.bias, 0.0, atol=1e-9)


@pytest.mark.parametrize("imu_frame", [None, "imu_link"])
def test_started_on_the_truth_it_stays_there_on_go1(imu_frame: str | None) -> None:
    """As the invariant EKF's test: the truth is the IMU's motion, the estimate the root's
    (the raw gyro in the lever arm: ``_worst_pose_error``'s ``lever_tau`` 0)."""
    legs = Go1Legs(imu_frame)
    samples = truth(legs, 200.0, 1.0, wobble=0.5, feet_z=None, inverse=legs.inverse)
    assert _worst_pose_error(QuaternionEKF, samples, legs, imu_frame=imu_frame) < 1e-9


@pytest.mark.parametrize("legs", ["synthetic", "go1"])
def test_converges_in_roll_pitch_and_velocity_from_30_degrees_and_1_m_per_s(legs: str) -> None:
    """The invariant EKF's convergence test, run on the quaternion EKF."""
    if legs == "go1":
        kin = Go1Legs()
        samples = truth(kin, 200.0, 4.0, wobble=0.5, feet_z=None, inverse=kin.inverse)
        ekf = QuaternionEKF(pinobs.load("go1"), GO1_FEET)
    else:
        samples = synthetic_truth(rate=200.0, duration=6.0, swing=False)
        ekf = QuaternionEKF(SyntheticLegs(3))
    R0, v0 = samples[0][1], samples[0][2]
    axis = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    Rw = Rotation.from_rotvec(math.radians(30) * axis).as_matrix() @ R0
    vw = v0 + np.array([0.6, 0.8, 0.0])
    prior = InEKFPrior(attitude=0.6, velocity=1.0)
    tilt, speed = [], []
    for est, (R, v, _) in run(ekf, samples, R0=Rw, v0=vw, prior=prior):
        cos = float(np.clip((est.rotation.T @ [0, 0, 1]) @ (R.T @ [0, 0, 1]), -1, 1))
        tilt.append(math.acos(cos))
        speed.append(np.linalg.norm(est.v[:3] - R.T @ v))
    tilt, speed = np.array(tilt), np.array(speed)
    assert tilt[0] > math.radians(25) and speed[0] > 0.3  # (after the first update)
    # slower than the invariant EKF (whose test asks 5e-3 m/s in the last second; measured
    # here 8.5e-3 m/s on the synthetic legs): its error dynamics depend on
    # the (wrong) estimate
    assert tilt[-200:].max() < 2e-3 and speed[-200:].max() < 1.5e-2
    assert speed[-1] < 0.02 * np.linalg.norm([0.6, 0.8])


def test_error_dynamics_match_finite_differences_of_the_flow(rng) -> None:
    """``F`` of eq. (2) against the flow of the true state from ``x̂ ⊕ ε e`` minus that from
    ``x̂``, expressed back in the error (one foot, so ``F`` is 18 square)."""
    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    v, p = rng.normal(size=3), rng.normal(size=3)
    b = 0.1 * rng.normal(size=6)
    reading = rng.normal(size=6)
    F = error_dynamics(R, reading[:3] - b[:3], reading[3:] - b[3:], 1)
    h, eps = 1e-4, 1e-6

    def step(R, v, p, b):
        return propagate_mean(R, v, p, reading[:3] - b[:3], reading[3:] - b[3:], h, GRAVITY)

    R1, v1, p1 = step(R, v, p, b)
    for i in range(18):
        e = np.zeros(18)
        e[i] = eps
        Rt = R @ gammas(e[:3])[0]
        R2, v2, p2 = step(Rt, v + e[3:6], p + e[6:9], b + e[12:])
        dtheta = Rotation.from_matrix(R1.T @ R2).as_rotvec()
        e1 = np.concatenate([dtheta, v2 - v1, p2 - p1, e[9:12], e[12:]])
        predicted = e + h * F @ e
        np.testing.assert_allclose(e1, predicted, atol=eps * h * 1e-2 + 1e-14 + eps * h**2 * 50)


def test_interface_errors_are_the_invariant_ekfs() -> None:
    ekf = QuaternionEKF(SyntheticLegs(3))
    with pytest.raises(NotResetError, match="reset"):
        ekf.update(0.1, np.zeros(9), np.zeros(3), np.zeros(3), [True] * 3)
    with pytest.raises(GainError, match="imu_hold"):
        QuaternionEKF(SyntheticLegs(3), imu_hold="next")
    with pytest.raises(UnknownNameError, match="feet"):
        QuaternionEKF(pinobs.load("go1"))
