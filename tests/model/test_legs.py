"""Foot kinematics (``pinobs.model.legs``): positions in the base frame and their Jacobians."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.errors import DimensionError, UnknownNameError, UnsupportedRobotError
from pinobs.model import FootKinematics, foot_sphere_radius

FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


def test_positions_are_the_feet_in_the_base_frame_whatever_the_base_pose(rng) -> None:
    robot = pinobs.load("go1")
    kin = FootKinematics(robot, FEET)
    model, data = robot.model, robot.model.createData()
    for _ in range(5):
        q = robot.random_configuration(rng)  # a random base pose and joint angles
        pin.framesForwardKinematics(model, data, q)
        base = data.oMi[1]  # the free-flyer's frame
        expected = [base.actInv(data.oMf[model.getFrameId(f)]).translation for f in FEET]
        np.testing.assert_allclose(kin.positions(q[7:]), expected, rtol=0, atol=1e-14)


def test_jacobians_match_central_differences(rng) -> None:
    robot = pinobs.load("go1")
    kin = FootKinematics(robot, FEET)
    q = rng.uniform(-1, 1, kin.nq_joints)
    h, jac = kin.positions_and_jacobians(q)
    np.testing.assert_array_equal(h, kin.positions(q))
    eps = 1e-6
    for i in range(kin.nv_joints):
        dq = eps * np.eye(kin.nv_joints)[i]
        fd = (kin.positions(q + dq) - kin.positions(q - dq)) / (2 * eps)
        np.testing.assert_allclose(jac[:, :, i], fd, rtol=0, atol=1e-9)
    # a leg moves its own foot only
    assert not jac[0][:, 3:].any() and jac[0][:, :3].any()


def test_an_unknown_frame_is_named_with_the_closest_ones() -> None:
    with pytest.raises(UnknownNameError, match=r"no frame 'FR_feet'.*did you mean 'FR_foot'"):
        FootKinematics(pinobs.load("go1"), ["FL_foot", "FR_feet"])
    with pytest.raises(UnknownNameError, match="twice"):
        FootKinematics(pinobs.load("go1"), ["FL_foot", "FL_foot"])
    with pytest.raises(UnknownNameError, match="non-empty"):
        FootKinematics(pinobs.load("go1"), [])


def test_a_robot_without_a_floating_base_is_refused_with_the_fix() -> None:
    with pytest.raises(UnsupportedRobotError, match="root_joint='freeflyer'"):
        FootKinematics(pinobs.load("ur5"), ["tool0"])


def test_with_an_imu_frame_the_feet_are_in_the_imu_frame(rng) -> None:
    robot = pinobs.load("go1")
    kin = FootKinematics(robot, FEET, imu_frame="imu_link")
    model, data = robot.model, robot.model.createData()
    q = robot.random_configuration(rng)
    pin.framesForwardKinematics(model, data, q)
    imu = data.oMf[model.getFrameId("imu_link")]
    expected = [imu.actInv(data.oMf[model.getFrameId(f)]).translation for f in FEET]
    h, jac = kin.positions_and_jacobians(q[7:])
    np.testing.assert_allclose(h, expected, rtol=0, atol=1e-14)
    R_bi, r_bi = kin.imu_placement
    np.testing.assert_allclose(r_bi, [-0.01592, -0.06659, -0.00617])
    _, jac_base = FootKinematics(robot, FEET).positions_and_jacobians(q[7:])
    np.testing.assert_allclose(jac, R_bi.T @ jac_base, atol=1e-15)
    moving = FootKinematics(robot, FEET, imu_frame="FL_calf")  # a frame that moves: allowed
    calf = data.oMf[model.getFrameId("FL_calf")]
    expected = [calf.actInv(data.oMf[model.getFrameId(f)]).translation for f in FEET]
    assert moving.imu_moves and not kin.imu_moves
    np.testing.assert_allclose(moving.positions(q[7:]), expected, rtol=0, atol=1e-14)


def test_foot_sphere_radius_reads_the_urdf_collision_spheres() -> None:
    go1 = pinobs.load("go1")
    assert [foot_sphere_radius(go1, f) for f in GO1_FEET_NAMES] == [0.02] * 4
    talos = pinobs.load("talos")  # flat soles: boxes, not spheres
    assert foot_sphere_radius(talos, "left_sole_link") == 0.0
    with pytest.raises(UnknownNameError, match="FL_fot"):
        foot_sphere_radius(go1, "FL_fot")


GO1_FEET_NAMES = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


@pytest.mark.parametrize("imu_frame", ["imu_link", None, "camera_optical_face"])
def test_preloaded_rows_give_the_bits_of_the_rows_computed_one_by_one(rng, imu_frame) -> None:
    """``preload`` (a log's rows at once) then ``shared_placements_and_jacobians`` of each row,
    in any order, equals what a fresh ``FootKinematics`` computes for that row alone."""
    robot = pinobs.load("go1")
    alone = FootKinematics(robot, FEET, imu_frame=imu_frame)
    preloaded = FootKinematics(robot, FEET, imu_frame=imu_frame)
    rows = np.tile([0.0, 0.8, -1.6], 4) + 0.3 * rng.normal(size=(7, 12))
    preloaded.preload(rows)
    for k in rng.permutation(len(rows)):
        got = preloaded.shared_placements_and_jacobians(rows[k].copy())
        want = alone.shared_placements_and_jacobians(rows[k])
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)
            assert a.flags.writeable
            assert a.flags.c_contiguous or not b.flags.c_contiguous


def test_preload_refuses_rows_of_the_wrong_width() -> None:
    legs = FootKinematics(pinobs.load("go1"), ("FL_foot",), imu_frame="imu_link")
    with pytest.raises(DimensionError, match=r"q_rows must have shape \(M, 12\)"):
        legs.preload(np.zeros((3, 11)))
