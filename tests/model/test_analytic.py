"""AnalyticMetric against Robot (same M), against differences, and against Sarras et al. eq. (22)."""

from __future__ import annotations

import itertools
from functools import cache

import numpy as np
import pytest

import pinobs
from pinobs.model import AnalyticMetric, Robot
from pinobs.model.paper_systems import sarras_eq21

# Methods the observers and the simulation call on a Robot: AnalyticMetric must offer them all.
GEOMETRY_INTERFACE = [
    "nq", "nv", "joints", "joint_names", "is_vector_space", "has_lie_group_joints", "copy",
    "check_configuration", "check_vector", "neutral", "random_configuration", "integrate",
    "difference", "integrate_jacobian", "normalize", "bracket", "mass_matrix",
    "mass_matrix_derivative", "gravity", "coriolis", "coriolis_matrix", "nonlinear_effects",
    "forward_dynamics", "forward_dynamics_derivatives", "inverse_dynamics", "kinetic_energy",
    "potential_energy", "force_per_metric", "metric", "geodesic_spray", "christoffel",
    "connection", "spray_derivative", "christoffel_derivative", "curvature", "sectional_curvature",
]  # fmt: skip


@cache
def _planar() -> Robot:
    return pinobs.load("planar_3r")


def _as_analytic(robot: Robot, *, exact_derivative: bool) -> AnalyticMetric:
    r = robot.copy()
    return AnalyticMetric(
        r.mass_matrix,
        n=r.nv,
        mass_matrix_derivative=r.mass_matrix_derivative if exact_derivative else None,
        gravity=r.gravity,
        potential=r.potential_energy,
        name="planar_3r_analytic",
    )


def test_analytic_metric_offers_the_robot_geometry_interface() -> None:
    m = sarras_eq21()
    missing = [name for name in GEOMETRY_INTERFACE if not hasattr(m, name)]
    assert missing == []
    assert all(hasattr(Robot, name) or name in ("joints",) for name in GEOMETRY_INTERFACE)


@pytest.mark.parametrize("exact_derivative", [True, False])
def test_analytic_dynamics_equal_pinocchio_on_the_same_mass_matrix(
    rng: np.random.Generator, exact_derivative: bool
) -> None:
    robot = _planar()
    m = _as_analytic(robot, exact_derivative=exact_derivative)
    tol = 1e-12 if exact_derivative else 1e-7  # measured: 1.8e-14 / 2.2e-9
    for _ in range(3):
        q = robot.random_configuration(rng, scale=2.0)
        v, a, x, y = rng.standard_normal((4, 3))
        tau = rng.standard_normal(3)
        assert np.allclose(m.coriolis(q, v), robot.coriolis(q, v), atol=tol)
        assert np.allclose(m.coriolis_matrix(q, v) @ v, robot.coriolis(q, v), atol=tol)
        assert np.allclose(
            m.forward_dynamics(q, v, tau), robot.forward_dynamics(q, v, tau), atol=tol
        )
        assert np.allclose(m.inverse_dynamics(q, v, a), robot.inverse_dynamics(q, v, a), atol=tol)
        assert np.allclose(m.christoffel(q, x, y), robot.christoffel(q, x, y), atol=tol)
        assert np.allclose(m.force_per_metric(q, tau), robot.force_per_metric(q, tau), atol=tol)


def test_analytic_curvature_equals_pinocchio_curvature(rng: np.random.Generator) -> None:
    robot = _planar()
    m = _as_analytic(robot, exact_derivative=True)
    for _ in range(2):
        q = robot.random_configuration(rng, scale=2.0)
        x, y, z = rng.standard_normal((3, 3))
        ref = robot.curvature(q, x, y, z)
        assert np.allclose(
            m.curvature(q, x, y, z), ref, atol=1e-7 * (1 + np.abs(ref).max())
        )  # measured 5e-10 relative


def test_analytic_coriolis_matrix_makes_mdot_minus_2c_skew(rng: np.random.Generator) -> None:
    m = sarras_eq21()
    q, v = rng.standard_normal((2, 3))
    s = m.mass_matrix_derivative(q, v) - 2.0 * m.coriolis_matrix(q, v)
    assert np.abs(s + s.T).max() < 1e-12


def test_from_inverse_derivative_matches_central_differences(rng: np.random.Generator) -> None:
    m = sarras_eq21()
    fd = AnalyticMetric(m.mass_matrix, n=3)
    q, x = rng.standard_normal((2, 3))
    assert np.allclose(m.mass_matrix_derivative(q, x), fd.mass_matrix_derivative(q, x), atol=1e-8)


def test_robot_mass_matrix_derivative_is_c_plus_c_transpose(rng: np.random.Generator) -> None:
    """The Robot method added for the I&I factor derivative, against differences along integrate."""
    for name in ("cartpole", "planar_3r", "ur5"):
        robot = pinobs.load(name)
        q = robot.random_configuration(rng)
        x = rng.standard_normal(robot.nv)
        e = 1e-6
        fd = (
            robot.mass_matrix(robot.integrate(q, e * x))
            - robot.mass_matrix(robot.integrate(q, -e * x))
        ) / (2 * e)
        assert np.abs(robot.mass_matrix_derivative(q, x) - fd).max() < 1e-8


def _riemann_eq22(m: AnalyticMetric, q: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """Sarras et al. eq. (22) literally, with second differences of M (independent of AnalyticMetric's Γ)."""
    n = 3
    e = np.eye(n)
    d1 = [(m.mass_matrix(q + h * e[a]) - m.mass_matrix(q - h * e[a])) / (2 * h) for a in range(n)]
    d2 = np.empty((n, n, n, n))
    for a, b in itertools.product(range(n), repeat=2):
        d2[a, b] = (
            m.mass_matrix(q + h * e[a] + h * e[b])
            - m.mass_matrix(q + h * e[a] - h * e[b])
            - m.mass_matrix(q - h * e[a] + h * e[b])
            + m.mass_matrix(q - h * e[a] - h * e[b])
        ) / (4 * h * h)
    c = np.empty(
        (n, n, n)
    )  # eq. (12): C^k_ij = ½ (∂_j M_ik + ∂_i M_jk − ∂_k M_ij), stored c[k, i, j]
    for k, i, j in itertools.product(range(n), repeat=3):
        c[k, i, j] = 0.5 * (d1[j][i, k] + d1[i][j, k] - d1[k][i, j])
    minv = np.linalg.inv(m.mass_matrix(q))
    r = np.empty((n, n, n, n))
    for i, j, k, ll in itertools.product(range(n), repeat=4):
        r[i, j, k, ll] = (
            0.5 * (d2[j, ll][i, k] + d2[i, k][j, ll] - d2[j, k][i, ll] - d2[i, ll][j, k])
            + np.einsum("ab,a,b->", minv, c[:, j, ll], c[:, i, k])
            - np.einsum("ab,a,b->", minv, c[:, i, ll], c[:, j, k])
        )
    return r


def test_curvature_contraction_equals_minus_sarras_eq22(rng: np.random.Generator) -> None:
    """Eq. (22) (Landau-Lifshitz form) is ``−⟨e_i, R(e_k, e_l) e_j⟩`` in our convention (MATH §3)."""
    m = sarras_eq21()
    q = rng.uniform(-1.5, 1.5, 3)
    ref = _riemann_eq22(m, q)
    e = np.eye(3)
    mq = m.mass_matrix(q)
    ours = np.empty((3, 3, 3, 3))
    for i, j, k, ll in itertools.product(range(3), repeat=4):
        ours[i, j, k, ll] = e[i] @ mq @ m.curvature(q, e[k], e[ll], e[j])
    assert np.abs(ref + ours).max() < 1e-6  # measured 3e-9 (second differences of M)
    assert np.abs(ours).max() > 0.01
