"""Joint friction from the URDF, and perturbed copies of a robot."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.simulation import MISMATCH_SCENARIOS, mismatched_plant
from pinobs.tolerances import COULOMB_SMOOTHING_VELOCITY


def test_urdf_dynamics_tags_become_the_friction_torque() -> None:
    robot = pinobs.load("z1", friction=True)  # damping and friction tags in its URDF
    assert robot.has_friction
    v = np.linspace(-1.0, 1.0, robot.nv)
    expected = -robot.model.damping * v - robot.model.friction * np.tanh(
        v / COULOMB_SMOOTHING_VELOCITY
    )
    np.testing.assert_allclose(robot.friction_torque(v), expected)
    assert not pinobs.load("z1").has_friction  # opt-in
    assert not pinobs.load("ur5").has_friction


def test_forward_dynamics_includes_friction_and_its_derivatives_match_finite_differences(
    rng,
) -> None:
    robot = pinobs.load("z1", friction=True)
    q = robot.random_configuration(rng)
    v, tau, x = rng.standard_normal((3, robot.nv))
    m = robot.mass_matrix(q)
    a = robot.forward_dynamics(q, v, tau)
    np.testing.assert_allclose(
        m @ a + robot.nonlinear_effects(q, v), tau + robot.friction_torque(v), atol=1e-8
    )
    dq, dv, _ = robot.forward_dynamics_derivatives(q, v, tau)
    e = 1e-6
    fd_v = (
        robot.forward_dynamics(q, v + e * x, tau) - robot.forward_dynamics(q, v - e * x, tau)
    ) / (2 * e)
    fd_q = (
        robot.forward_dynamics(robot.integrate(q, e * x), v, tau)
        - robot.forward_dynamics(robot.integrate(q, -e * x), v, tau)
    ) / (2 * e)
    np.testing.assert_allclose(dv @ x, fd_v, rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(dq @ x, fd_q, rtol=1e-6, atol=1e-5)
    _, dq2, dv2 = robot.forward_dynamics_jacobians(
        q, v, tau + robot.friction_torque(v)
    )  # rigid body only
    np.testing.assert_allclose(dq2, dq, atol=1e-9)
    np.testing.assert_allclose(dv2 + np.linalg.inv(m) * robot.friction_derivative(v), dv, atol=1e-6)


def test_friction_dissipates_energy_in_a_free_motion() -> None:
    plant = pinobs.load("ur5").perturbed(damping=np.full(6, 0.5), coulomb=np.full(6, 0.2))
    res = pinobs.simulate(plant, [], duration=1.0, inputs="zero", v0=np.full(6, 1.0), seed=0)
    energy = np.array(
        [
            plant.kinetic_energy(q, v) + plant.potential_energy(q)
            for q, v in zip(res.q, res.v, strict=True)
        ]
    )
    assert np.all(np.diff(energy) <= 1e-9)
    assert energy[-1] < energy[0] - 0.1


def test_perturbed_copy_scales_inertias_adds_a_payload_and_leaves_the_original_alone() -> None:
    robot = pinobs.load("ur5")
    before = robot.mass_matrix(robot.neutral())
    scaled = robot.perturbed(inertia_scale=np.full(6, 2.0))
    np.testing.assert_allclose(scaled.mass_matrix(robot.neutral()), 2.0 * before, rtol=1e-12)
    heavy = robot.perturbed(payload=(1.0, [0.0, 0.0, 0.0]))
    assert np.trace(heavy.mass_matrix(robot.neutral())) > np.trace(before)
    np.testing.assert_array_equal(robot.mass_matrix(robot.neutral()), before)
    with pytest.raises(pinobs.DimensionError, match="inertia_scale needs 6 positive factors"):
        robot.perturbed(inertia_scale=[1.0, 2.0])


@pytest.mark.parametrize("scenario", MISMATCH_SCENARIOS)
def test_mismatch_scenarios_are_seeded_and_change_the_truth_only_as_named(scenario: str) -> None:
    robot = pinobs.load("ur5")
    a, b = mismatched_plant(robot, scenario, seed=3), mismatched_plant(robot, scenario, seed=3)
    q = robot.random_configuration(np.random.default_rng(0))
    np.testing.assert_array_equal(a.mass_matrix(q), b.mass_matrix(q))
    changed_mass = not np.allclose(a.mass_matrix(q), robot.mass_matrix(q))
    assert changed_mass == scenario.startswith("inertia")
    assert a.has_friction == (scenario == "friction")


def test_unknown_scenario_lists_the_known_ones() -> None:
    with pytest.raises(
        pinobs.UnknownNameError, match=r"unknown mismatch scenario 'payload'.*inertia5"
    ):
        mismatched_plant(pinobs.load("ur5"), "payload")
