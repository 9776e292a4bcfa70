"""Which rotor inertias identification keeps (pinobs.model.identification.armature)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.errors import OptionError
from pinobs.model.identification import (
    ARMATURE_SHARE,
    ARMATURE_SIGMAS,
    MomentumRegressor,
    Solution,
    determined_armature,
    identify,
)
from pinobs.model.identification.armature import kept_armature_weights
from pinobs.simulation import Sensor
from tests.conftest import planar_3r_truth, torque_error


def _with_armature(robot: pinobs.Robot, armature: list[float]) -> pinobs.Robot:
    model = robot.model.copy()
    model.armature = np.asarray(armature, dtype=float)
    return robot.with_model(model)


def _solution(theta: np.ndarray, std: np.ndarray) -> Solution:
    return Solution(
        theta=theta,
        std=std,
        excited=np.ones(theta.size, bool),
        rank=theta.size,
        base=(),
        condition=1.0,
        sigma=1.0,
        projected=False,
        n_rows=100,
    )


def test_a_rotor_is_kept_only_beyond_two_sigmas_and_one_percent_of_its_joints_inertia() -> None:
    """``|θ̂ − θ₀| > max(2 σ, 0.01 M̄ⱼⱼ)`` (closed form), either side of a model's own rotor."""
    robot = _with_armature(pinobs.load("planar_3r"), [0.0, 0.1, 0.1])
    m_bar = np.diag(robot.mass_matrix(robot.neutral()))
    reg = MomentumRegressor(robot, friction=False, offset=False, armature=True)
    assert (ARMATURE_SIGMAS, ARMATURE_SHARE) == (2.0, 0.01)
    theta, std = reg.nominal(), np.full(reg.size, 1.0)
    arm = reg.armature_slice
    nominal = theta[arm].copy()

    def kept(step: list[float], sigma: list[float]) -> tuple[str, ...]:
        theta[arm] = nominal + np.array(step) * m_bar
        std[arm] = np.array(sigma) * m_bar
        return determined_armature(reg, _solution(theta, std))

    # the standard deviation binding (1 % of M̄): z = 2.1 kept, 1.9 not, on either side
    assert kept([0.021, 0.019, -0.021], [0.01, 0.01, 0.01]) == ("joint1", "joint3")
    # the share binding (σ = 0.1 % of M̄): 1.1 % kept, 0.9 % not (z = 9)
    assert kept([0.011, 0.009, -0.009], [0.001, 0.001, 0.001]) == ("joint1",)


def test_a_joint_without_inertia_of_its_own_keeps_its_rotor() -> None:
    """A massless last link (M singular without a rotor, as FIGAROH's TX40 link 6)."""
    robot = pinobs.load("planar_3r")
    model = robot.model.copy()
    model.inertias[3] = pin.Inertia.Zero()
    massless = robot.with_model(model)
    assert np.diag(massless.mass_matrix(massless.neutral()))[2] == 0.0
    reg = MomentumRegressor(massless, friction=False, offset=False, armature=True)
    assert determined_armature(reg, _solution(reg.nominal(), np.ones(reg.size))) == ("joint3",)


@pytest.mark.parametrize("joints", [("joint2",), ("joint1", "joint3")])
def test_rows_vanish_on_the_true_parameters_with_the_armature_of_some_joints(
    joints: tuple[str, ...],
) -> None:
    """The rotors not identified are known (moved to the torque side), the others columns."""
    robot = _with_armature(pinobs.load("planar_3r"), [0.05, 0.2, 0.1])
    res = pinobs.simulate(robot, [], duration=2.0, sensor=Sensor(rate=1000.0), seed=3)
    reg = MomentumRegressor(robot, friction=False, offset=False, armature=joints)
    assert reg.armature_joints == joints
    assert reg.names[reg.armature_slice] == tuple(f"{j}.armature" for j in joints)
    A, y = reg.system(res.t, res.q, res.v, res.tau, window=100, stride=1)
    assert A.shape[1] == reg.n_inertial + len(joints)
    assert np.abs(A @ reg.nominal() - y).max() / np.abs(y).max() < 1e-4
    # the weights' floor only on the joints identified, the calibrated robot's rotors there
    floor = reg.armature_floor()
    on = np.isin(reg.actuated_names, joints)
    np.testing.assert_allclose(
        reg.prior_robot.model.armature, np.array([0.05, 0.2, 0.1]) + np.where(on, floor, 0.0)
    )
    theta = reg.nominal()
    theta[reg.armature_slice] = 0.3
    np.testing.assert_allclose(
        reg.with_parameters(theta).model.armature, np.where(on, 0.3, robot.model.armature)
    )


def test_the_weights_of_the_rotors_kept_carry_the_models_own_elsewhere() -> None:
    robot = _with_armature(pinobs.load("planar_3r"), [0.05, 0.0, 0.0])
    reg = MomentumRegressor(robot, friction=False, offset=False, armature=True)
    theta = reg.nominal()
    theta[reg.armature_slice] = [0.4, 0.5, 0.6]
    weights = kept_armature_weights(reg, theta, ("joint3",))
    np.testing.assert_array_equal(weights.model.armature, [0.05, 0.0, 0.6])


def test_an_armature_name_that_is_not_an_actuated_joint_is_refused_naming_them() -> None:
    robot = pinobs.load("planar_3r")
    with pytest.raises(OptionError, match="joint1, joint2, joint3"):
        MomentumRegressor(robot, armature=("joint4",))


def test_a_truth_without_rotors_is_fitted_as_without_armature_columns() -> None:
    """planar_3r with 20 % inertia error, no rotors (8 s, σ = 1e-5): no rotor is kept, so the
    fit is the one without armature, weights and priors included (the spurious columns cost
    ``benchmarks/learning.py``'s one-pass ``ekf`` up to 1.16×: package docstring)."""
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    res = pinobs.simulate(
        robot, [], duration=8.0, sensor=Sensor(rate=1000.0, noise_std=1e-5), seed=1, plant=truth
    )
    ident = identify(robot, res)
    without = identify(robot, res, armature=False)
    assert ident.regressor.armature_joints == ()
    assert ident.parameters.names == without.parameters.names
    np.testing.assert_array_equal(ident.parameters.values, without.parameters.values)
    np.testing.assert_array_equal(
        torque_error(ident.robot, truth), torque_error(without.robot, truth)
    )


def test_a_truth_with_rotors_keeps_those_the_data_determine() -> None:
    """planar_3r with rotors of 0, 0.2, 0.1 kg·m² (8 s, σ = 1e-5): joints 2 and 3 kept and
    recovered within 2 %, joint 1 (no rotor, and its column link 1's inertia) not."""
    robot = pinobs.load("planar_3r")
    truth = _with_armature(planar_3r_truth(robot), [0.0, 0.2, 0.1])
    res = pinobs.simulate(
        robot, [], duration=8.0, sensor=Sensor(rate=1000.0, noise_std=1e-5), seed=1, plant=truth
    )
    ident = identify(robot, res)
    assert ident.regressor.armature_joints == ("joint2", "joint3")
    np.testing.assert_allclose(ident.robot.model.armature, [0.0, 0.2, 0.1], rtol=0.02, atol=0)
