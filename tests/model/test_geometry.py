"""The metric geometry of the model layer against independent constructions.

The reference connection is built from the Koszul formula for frame-constant
fields, using only finite differences of ``M(q)`` along ``integrate`` and the
frame bracket, which is itself checked against the group commutator.  No ABA
call enters the reference.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.model import Robot
from pinobs.model.integrators import dynamics_calls
from pinobs.model.reference import fd_curvature, koszul_connection, mass_matrix_derivative_fd

ROBOTS = [
    "cartpole",
    "ur5",
    "panda",
    "top",
    "rigid_body",
    "planar_body",
    "double_pendulum_continuous",
]
EPS = 1e-5


@cache
def _robot(name: str) -> Robot:
    if name == "planar_body":  # a body on a planar joint (SE(2)) and an arm on it
        model = pin.Model()
        j = model.addJoint(0, pin.JointModelPlanar(), pin.SE3.Identity(), "base")
        model.appendBodyToJoint(
            j,
            pin.Inertia(2.0, np.array([0.1, 0.05, 0.0]), np.diag([0.1, 0.2, 0.3])),
            pin.SE3.Identity(),
        )
        k = model.addJoint(
            j, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([0.3, 0.0, 0.0])), "arm"
        )
        model.appendBodyToJoint(
            k,
            pin.Inertia(0.5, np.array([0.2, 0.0, 0.0]), np.diag([0.01, 0.02, 0.03])),
            pin.SE3.Identity(),
        )
        return Robot(model, name=name, source=name)
    return pinobs.load(name)


def _point(robot: Robot, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng)
    x, y, z, w = rng.standard_normal((4, robot.nv))
    return q, x, y, z, w


@pytest.mark.parametrize("name", ROBOTS)
def test_bracket_matches_group_commutator(name: str) -> None:
    robot = _robot(name)
    q, x, y, _, _ = _point(robot, 1)
    h = 1e-4
    qq = robot.integrate(
        robot.integrate(robot.integrate(robot.integrate(q, h * x), h * y), -h * x), -h * y
    )
    # q·e^{hx}e^{hy}e^{-hx}e^{-hy} = q·exp(h²[x,y] + O(h³))
    np.testing.assert_allclose(
        robot.difference(q, qq) / h**2,
        robot.bracket(x, y),
        atol=50 * h * (1 + np.abs(x).max() * np.abs(y).max()) ** 2,
    )


@pytest.mark.parametrize("name", ROBOTS)
def test_connection_matches_koszul_formula(name: str) -> None:
    robot = _robot(name)
    q, x, y, _, _ = _point(robot, 2)
    got = robot.connection(q, x, y)
    ref = koszul_connection(robot, q, x, y)
    assert np.linalg.norm(got - ref) <= 1e-7 * (1 + np.linalg.norm(ref))


@pytest.mark.parametrize("name", ROBOTS)
def test_christoffel_is_symmetric_and_polarises_the_spray(name: str) -> None:
    robot = _robot(name)
    q, x, y, _, _ = _point(robot, 3)
    np.testing.assert_allclose(robot.christoffel(q, x, y), robot.christoffel(q, y, x), atol=1e-10)
    np.testing.assert_allclose(
        robot.christoffel(q, x, x), robot.geodesic_spray(q, x), rtol=1e-10, atol=1e-12
    )
    # free motion: v̇ = −Γs(v, v) is the zero-gravity, zero-torque dynamics
    m = robot.mass_matrix(q)
    np.testing.assert_allclose(
        m @ robot.geodesic_spray(q, x), robot.coriolis(q, x), rtol=1e-9, atol=1e-10
    )


@pytest.mark.parametrize("name", ROBOTS)
def test_connection_is_torsion_free_and_metric_compatible(name: str) -> None:
    robot = _robot(name)
    q, x, y, z, _ = _point(robot, 4)
    np.testing.assert_allclose(
        robot.connection(q, x, y) - robot.connection(q, y, x), robot.bracket(x, y), atol=1e-10
    )
    m = robot.mass_matrix(q)
    lhs = y @ mass_matrix_derivative_fd(robot, q, x) @ z  # X⟨Y, Z⟩ for frame-constant Y, Z
    rhs = robot.connection(q, x, y) @ m @ z + y @ m @ robot.connection(q, x, z)
    assert abs(lhs - rhs) <= 1e-7 * (1 + abs(lhs))


@pytest.mark.parametrize("name", ROBOTS)
def test_curvature_matches_finite_differences_of_the_koszul_connection(name: str) -> None:
    robot = _robot(name)
    q, x, y, z, _ = _point(robot, 5)
    ref = fd_curvature(robot, q, x, y, z)
    got = robot.curvature(q, x, y, z)
    assert np.linalg.norm(got - ref) <= 2e-4 * (1 + np.linalg.norm(ref))


@pytest.mark.parametrize("name", ROBOTS)
def test_curvature_has_the_riemann_symmetries_and_first_bianchi(name: str) -> None:
    robot = _robot(name)
    q, x, y, z, w = _point(robot, 6)
    m = robot.mass_matrix(q)
    r = robot.curvature
    scale = 1 + np.linalg.norm(r(q, x, y, z))
    np.testing.assert_allclose(r(q, x, y, z), -r(q, y, x, z), atol=1e-10 * scale)
    assert abs(r(q, x, y, z) @ m @ w + r(q, x, y, w) @ m @ z) <= 1e-9 * scale * np.linalg.norm(m)
    assert abs(r(q, x, y, z) @ m @ w - r(q, z, w, x) @ m @ y) <= 1e-9 * scale * np.linalg.norm(m)
    bianchi = r(q, x, y, z) + r(q, y, z, x) + r(q, z, x, y)
    assert np.linalg.norm(bianchi) <= 1e-9 * scale


@pytest.mark.parametrize("c", [0.25, 1.0, 3.0])
def test_isotropic_body_on_spherical_joint_has_sectional_curvature_one_over_4c(
    c: float, rng
) -> None:
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    model.appendBodyToJoint(j, pin.Inertia(1.0, np.zeros(3), c * np.eye(3)), pin.SE3.Identity())
    robot = Robot(model, name="ball", source="test")
    for _ in range(3):
        q = robot.random_configuration(rng, scale=3.0)
        x, y = rng.standard_normal((2, 3))
        assert robot.sectional_curvature(q, x, y) == pytest.approx(1.0 / (4.0 * c), rel=1e-10)


def test_cartpole_metric_is_flat(rng) -> None:
    robot = _robot("cartpole")
    for _ in range(5):
        q = robot.random_configuration(rng, scale=3.0)
        x, y, z = rng.standard_normal((3, 2))
        assert np.linalg.norm(robot.curvature(q, x, y, z)) < 1e-12


def test_spray_derivative_matches_finite_differences(rng) -> None:
    robot = _robot("ur5")
    q = robot.random_configuration(rng)
    x, z = rng.standard_normal((2, robot.nv))
    fd = (
        robot.geodesic_spray(robot.integrate(q, EPS * z), x)
        - robot.geodesic_spray(robot.integrate(q, -EPS * z), x)
    ) / (2 * EPS)
    np.testing.assert_allclose(robot.spray_derivative(q, x) @ z, fd, rtol=1e-6, atol=1e-8)


def test_mass_matrix_is_symmetric_positive_definite(rng) -> None:
    for name in ROBOTS:
        robot = _robot(name)
        m = robot.mass_matrix(robot.random_configuration(rng))
        np.testing.assert_array_equal(m, m.T)
        assert np.linalg.eigvalsh(m).min() > 0


def test_dynamics_pieces_add_up(rng) -> None:
    robot = _robot("panda")
    q = robot.random_configuration(rng)
    v, tau = rng.standard_normal((2, robot.nv))
    m = robot.mass_matrix(q)
    a = robot.forward_dynamics(q, v, tau)
    np.testing.assert_allclose(m @ a + robot.coriolis(q, v) + robot.gravity(q), tau, atol=1e-9)
    np.testing.assert_allclose(robot.coriolis_matrix(q, v) @ v, robot.coriolis(q, v), atol=1e-9)
    np.testing.assert_allclose(
        robot.nonlinear_effects(q, v), robot.coriolis(q, v) + robot.gravity(q), atol=1e-9
    )
    np.testing.assert_allclose(robot.inverse_dynamics(q, v, a), tau, atol=1e-9)
    np.testing.assert_allclose(
        robot.force_per_metric(q, tau), np.linalg.solve(m, tau - robot.gravity(q)), atol=1e-9
    )
    _, _, minv = robot.forward_dynamics_derivatives(q, v, tau)
    np.testing.assert_allclose(minv, np.linalg.inv(m), rtol=1e-8, atol=1e-10)
    assert robot.kinetic_energy(q, v) == pytest.approx(0.5 * v @ m @ v, rel=1e-12)


@pytest.mark.parametrize("name", ["ur5", "go1"])
def test_gravity_free_dynamics_calls_are_the_negated_spray_jacobians(name: str, rng) -> None:
    """``dynamics_calls(robot, gravity=False)``'s derivatives at ``(q, x, 0)`` leave
    ``−Γs(x, x)``, ``−∂_q Γs(x, x)``, ``−∂_x Γs(x, x)`` to the bit, on a new ``pin.Data``
    or on one shared with the model's own calls (whose results it leaves as they were)."""
    robot = _robot(name)
    own = dynamics_calls(robot)
    free = dynamics_calls(robot, gravity=False)
    shared = dynamics_calls(robot, gravity=False, data=own.data)
    assert shared.data is own.data and free.data is not own.data
    assert np.any(robot.model.gravity.linear != 0.0)  # (the model's own calls have gravity)
    zero = np.zeros(robot.nv)
    for _ in range(3):
        q, (x, tau) = robot.random_configuration(rng), rng.standard_normal((2, robot.nv))
        spray, s_q, s_x = robot.spray_jacobians(q, x)
        for calls in (free, shared):
            calls.derivatives(q, x, zero)
            d = calls.data
            for got, want in ((d.ddq, spray), (d.ddq_dq, s_q), (d.ddq_dv, s_x)):
                np.testing.assert_array_equal(-got, want)
        own.derivatives(q, x, tau)  # gravity back: the model's own dynamics
        np.testing.assert_array_equal(own.data.ddq, robot.forward_dynamics_jacobians(q, x, tau)[0])
