"""The angle chart of continuous joints: same dynamics, angles unwrapped near a reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pinobs
from pinobs.model.chart import AngleChart


@pytest.mark.parametrize("name", ["cartpole_continuous", "double_pendulum_continuous", "pr2"])
def test_the_chart_has_the_dynamics_of_the_robot(name: str, rng: np.random.Generator) -> None:
    robot = pinobs.load(name)
    chart = AngleChart(robot)
    assert chart.chart.nv == robot.nv and chart.chart.nq < robot.nq
    assert not any(b.kind == "circle" for b in chart.chart.joints)
    for _ in range(3):
        q = robot.random_configuration(rng, scale=3.0)
        x = chart.to_chart(q)
        v, tau = rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        np.testing.assert_allclose(chart.from_chart(x), q, rtol=0, atol=1e-15)
        np.testing.assert_allclose(
            chart.chart.mass_matrix(x), robot.mass_matrix(q), rtol=1e-12, atol=1e-12
        )
        np.testing.assert_allclose(
            chart.chart.forward_dynamics(x, v, tau),
            robot.forward_dynamics(q, v, tau),
            rtol=1e-10,
            atol=1e-10,
        )


def test_angles_are_taken_on_the_branch_nearest_the_reference() -> None:
    chart = AngleChart(pinobs.load("cartpole_continuous"))
    q = np.array([0.3, math.cos(0.1), math.sin(0.1)])
    np.testing.assert_allclose(chart.to_chart(q), [0.3, 0.1])
    near = np.array([0.0, 6 * math.pi - 0.2])  # three turns on, just below the branch cut
    np.testing.assert_allclose(chart.to_chart(q, near=near), [0.3, 6 * math.pi + 0.1])
    q_back = np.array([0.0, math.cos(3.1), math.sin(3.1)])  # crossing ±π backwards
    np.testing.assert_allclose(
        chart.to_chart(q_back, near=np.array([0.0, -3.1])), [0.0, 3.1 - 2 * math.pi]
    )
