"""Robot's fast paths and its pickled form."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs


@pytest.mark.parametrize(("name", "root"), [("top", None), ("go1", None), ("planar_3r", "planar")])
def test_bracket_matrix_is_the_bracket(name: str, root: str | None) -> None:
    robot = pinobs.load(name, root_joint=root)
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=robot.nv), rng.normal(size=robot.nv)
    np.testing.assert_allclose(robot.bracket_matrix(x) @ y, robot.bracket(x, y), atol=1e-14)


def test_one_derivatives_call_gives_the_dynamics_and_its_jacobians_with_friction() -> None:
    robot = pinobs.load("ur5").perturbed(damping=np.full(6, 0.3), coulomb=np.full(6, 1.5))
    rng = np.random.default_rng(1)
    q, v, tau = robot.random_configuration(rng), rng.normal(size=6), rng.normal(size=6)
    acc, dq, dv, minv = (np.array(x) for x in robot.forward_dynamics_with_derivatives(q, v, tau))
    np.testing.assert_allclose(acc, robot.forward_dynamics(q, v, tau), rtol=1e-12, atol=1e-12)
    fd_q = np.column_stack(
        [
            (
                robot.forward_dynamics(robot.integrate(q, 1e-7 * e), v, tau)
                - robot.forward_dynamics(robot.integrate(q, -1e-7 * e), v, tau)
            )
            / 2e-7
            for e in np.eye(6)
        ]
    )
    np.testing.assert_allclose(dq, fd_q, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(minv, np.linalg.inv(robot.mass_matrix(q)), rtol=1e-9)
    eps = 1e-7  # ∂v̇/∂v by central differences (the Coulomb slope included)
    fd = np.column_stack(
        [
            (
                robot.forward_dynamics(q, v + eps * e, tau)
                - robot.forward_dynamics(q, v - eps * e, tau)
            )
            / (2 * eps)
            for e in np.eye(6)
        ]
    )
    np.testing.assert_allclose(dv, fd, rtol=1e-5, atol=1e-5)


def test_a_pickled_robot_is_small_has_the_same_dynamics_and_reloads_its_visuals() -> None:
    import pickle

    robot = pinobs.load("ur5")
    robot.visual_model  # noqa: B018  (loaded before pickling: still left out)
    blob = pickle.dumps(robot)
    assert len(blob) < 1_000_000  # measured 39 kB (187 MB with the meshes)
    back = pickle.loads(blob)
    assert back._geometry is None  # not loaded until something draws
    assert not back._zero_nv.flags.writeable
    rng = np.random.default_rng(2)
    q, v, tau = robot.random_configuration(rng), rng.normal(size=6), rng.normal(size=6)
    np.testing.assert_array_equal(
        back.forward_dynamics(q, v, tau), robot.forward_dynamics(q, v, tau)
    )
    assert back.visual_model.ngeoms == robot.visual_model.ngeoms > 0


def test_loading_builds_no_geometry_until_it_is_asked_for() -> None:
    robot = pinobs.load("ur5")
    assert robot._geometry is None
    assert robot.copy()._geometry is None
    assert robot.collision_model.ngeoms > 0
    assert robot.copy().collision_model is robot.collision_model  # copies share what is loaded


@pytest.mark.parametrize(("name", "root"), [("top", None), ("go1", None), ("planar_3r", "planar")])
def test_integrate_jacobian_solve_is_the_dense_solve(name: str, root: str | None) -> None:
    robot = pinobs.load(name, root_joint=root)
    rng = np.random.default_rng(3)
    q = robot.random_configuration(rng)
    for scale in (1e-6, 1e-4, 1e-3, 1e-2, 0.5):
        xi, u = scale * rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        dense = np.linalg.solve(robot.integrate_jacobian(q, xi), u)
        np.testing.assert_allclose(robot.integrate_jacobian_solve(q, xi, u), dense, atol=1e-14)


def test_a_robot_on_another_model_shares_the_geometry_without_loading_it() -> None:
    robot = pinobs.load("ur5")
    other = robot.with_model(robot.model.copy(), name="ur5*")
    assert other.name == "ur5*" and other._geometry is None and robot._geometry is None
    assert robot.perturbed(payload=(1.0, [0, 0, 0.1]))._geometry is None


@pytest.mark.parametrize(("name", "root"), [("top", None), ("go1", None), ("planar_3r", "planar")])
def test_interpolate_is_pinocchios_and_ends_on_its_endpoints(name: str, root: str | None) -> None:
    import pinocchio as pin

    robot = pinobs.load(name, root_joint=root)
    rng = np.random.default_rng(4)
    q0, q1 = robot.random_configuration(rng), robot.random_configuration(rng)
    np.testing.assert_allclose(robot.interpolate(q0, q1, 0.0), q0, atol=1e-14)
    np.testing.assert_allclose(robot.difference(robot.interpolate(q0, q1, 1.0), q1), 0, atol=1e-12)
    for s in (0.25, 0.5, 0.75):
        np.testing.assert_allclose(
            robot.interpolate(q0, q1, s), pin.interpolate(robot.model, q0, q1, s), atol=1e-12
        )


@pytest.mark.parametrize(("name", "root"), [("ur5", None), ("go1", None), ("planar_3r", "planar")])
def test_a_robot_with_other_inertials_is_the_one_with_model_builds(
    name: str, root: str | None
) -> None:
    """``with_inertials`` (the tree's attributes shared, issue 39) gives what ``with_model``
    gives: every attribute, and the dynamics to the bit, with and without gravity."""
    import pinocchio as pin

    from pinobs.model.friction import FrictionLaw

    robot = pinobs.load(name, root_joint=root)
    model = robot.model.copy()
    for i in range(1, model.njoints):
        inertia = model.inertias[i]
        model.inertias[i] = pin.Inertia(1.3 * inertia.mass, inertia.lever, inertia.inertia)
    law = FrictionLaw.from_urdf(np.full(robot.nv, 0.2), np.full(robot.nv, 0.5))
    fast = robot.with_inertials(model.copy(), name="x", friction=True, friction_law=law)
    slow = robot.with_model(model.copy(), name="x", friction=True, friction_law=law)
    q0 = pin.neutral(model)
    fast.coriolis(q0, np.zeros(robot.nv))  # its zero-gravity copy, built on first use
    assert set(fast.__dict__) == set(slow.__dict__)
    assert fast.locked == slow.locked and fast.locked is not robot.locked
    for k in ("name", "source", "root_joint", "package_dirs", "mimic", "joints", "friction"):
        assert getattr(fast, k) == getattr(slow, k), k
    assert fast.has_friction and fast.friction_law is law and slow.friction_law is law
    rng = np.random.default_rng(0)
    for _ in range(3):
        q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
        v, tau = rng.standard_normal(robot.nv), rng.standard_normal(robot.nv)
        for a, b in [
            (fast.forward_dynamics(q, v, tau), slow.forward_dynamics(q, v, tau)),
            (fast.coriolis(q, v), slow.coriolis(q, v)),
            *zip(fast.spray_jacobians(q, v), slow.spray_jacobians(q, v), strict=True),
            *zip(
                fast.forward_dynamics_with_derivatives(q, v, tau),
                slow.forward_dynamics_with_derivatives(q, v, tau),
                strict=True,
            ),
        ]:
            np.testing.assert_array_equal(a, b)
