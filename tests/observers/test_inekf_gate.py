"""The invariant EKF's foot gate (eq. 8): each foot's own NIS, compiled, against NumPy, and
the gate's effect on the estimate."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.errors import GainError
from pinobs.observers.inekf import InEKFGains, InvariantEKF
from pinobs.observers.legs import replace_state

FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


@pytest.fixture(scope="module")
def go1():
    return pinobs.load("go1")


def _numpy_foot_nis(ekf: InvariantEKF, state, h, jac) -> np.ndarray:
    """Eq. (8) written out with NumPy: r_j, S_jj = P_pp − P_pd − P_dp + P_dd + N_j."""
    R, x, P, g = state.R, state.x, state.P, ekf.gains
    out = []
    for s, j in enumerate(state.feet):
        r = R @ h[j] - (x[2 + s] - x[1])
        a = 9 + 3 * s
        N = R @ (g.joint**2 * jac[j] @ jac[j].T + g.kinematics**2 * np.eye(3)) @ R.T
        S = P[6:9, 6:9] - P[6:9, a : a + 3] - P[a : a + 3, 6:9] + P[a : a + 3, a : a + 3] + N
        out.append(float(r @ np.linalg.solve(S, r)))
    return np.array(out)


def test_the_compiled_foot_nis_equals_numpys_and_one_foots_is_the_filters_nis(go1, rng) -> None:
    ekf = InvariantEKF(go1, FEET, imu_frame="imu_link", foot_gate=1e-3)
    q = np.concatenate([[0, 0, 0.3, 0, 0, 0, 1], np.tile([0.0, 0.8, -1.6], 4)])
    ekf.reset(0.0, q, contacts=[True] * 4)
    state = ekf.state
    A = rng.standard_normal((state.P.shape[0],) * 2)
    x = state.x + 0.01 * rng.standard_normal(state.x.shape)  # feet off their measurement
    state = replace_state(state, P=state.P + 1e-4 * A @ A.T, x=x)
    h, jac = ekf.setup.legs(q[7:] + 0.01 * rng.standard_normal(12))
    np.testing.assert_allclose(
        ekf.foot_nis(state, h, jac), _numpy_foot_nis(ekf, state, h, jac), rtol=1e-10
    )
    # one foot in the state: its own NIS is the update's (same r, same S)
    one = InvariantEKF(go1, FEET, imu_frame="imu_link")
    g = np.array([0.0, 0.0, 9.81])
    one.reset(0.0, q, gyro=np.zeros(3), acc=g, contacts=[True, False, False, False])
    flags = [True, False, False, False]
    prior = one.state
    est = one.update(0.0025, q[7:] + 0.002, np.zeros(3), g, flags)
    assert est.nis_dof == 3
    # the update's NIS, from the propagated state: recompute it there
    propagated = one._propagate(prior, prior.imu, 0.0025, 0.0025)
    h1, jac1 = one.setup.legs(q[7:] + 0.002)
    assert one.foot_nis(propagated, h1, jac1)[0] == pytest.approx(est.nis, rel=1e-9)


def test_a_foot_that_jumps_is_gated_and_re_anchored_others_measured(go1) -> None:
    ekf = InvariantEKF(
        go1, FEET, imu_frame="imu_link", gains=InEKFGains(contact=0.007), foot_gate=1e-3
    )
    q = np.concatenate([[0, 0, 0.3, 0, 0, 0, 1], np.tile([0.0, 0.8, -1.6], 4)])
    g = np.array([0.0, 0.0, 9.81])
    ekf.reset(0.0, q, gyro=np.zeros(3), acc=g, contacts=[True] * 4)
    est = None
    for k in range(1, 200):
        est = ekf.update(k * 0.0025, q[7:], np.zeros(3), g, [True] * 4)
    assert est is not None and est.gated == () and est.nis_dof == 12
    jumped = q[7:].copy()
    jumped[1] += 0.05  # FL's thigh: its foot moves ~1 cm in one sample
    est = ekf.update(0.5, jumped, np.zeros(3), g, [True] * 4)
    assert est.gated == ("FL_foot",) and est.nis_dof == 9
    assert est.contacts[-1] == "FL_foot"  # re-anchored: added after the update
    assert np.linalg.norm(est.v[:3]) < 1e-3  # the base did not move with it
    est = ekf.update(0.5025, jumped, np.zeros(3), g, [True] * 4)
    assert est.gated == () and est.nis_dof == 12


def test_the_foot_gate_is_checked(go1) -> None:
    with pytest.raises(GainError, match=r"foot_gate: .*\(0, 0.5\)"):
        InvariantEKF(go1, FEET, foot_gate=0.6)


@pytest.mark.parametrize("family", ["inekf", "qekf"])
def test_nis_dof_counts_the_feet_measured(go1, family) -> None:
    from pinobs.observers.qekf import QuaternionEKF

    cls = InvariantEKF if family == "inekf" else QuaternionEKF
    ekf = cls(go1, FEET, imu_frame="imu_link")
    q = np.concatenate([[0, 0, 0.3, 0, 0, 0, 1], np.tile([0.0, 0.8, -1.6], 4)])
    g = np.array([0.0, 0.0, 9.81])
    assert (
        ekf.reset(0.0, q, gyro=np.zeros(3), acc=g, contacts=[True, True, False, False]).nis_dof == 0
    )
    est = ekf.update(0.0025, q[7:], np.zeros(3), g, [True, True, True, False])  # RL lands
    assert est.nis_dof == 6 and est.nis is not None
    est = ekf.update(0.005, q[7:], np.zeros(3), g, [False] * 4)
    assert est.nis_dof == 0 and est.nis is None
