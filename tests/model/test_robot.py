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
