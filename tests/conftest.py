"""Shared fixtures: a seeded generator and robots built once per session."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

import pinobs


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)


@cache
def cached_robot(name: str) -> pinobs.Robot:
    """Load once per session; callers that mutate must ``.copy()``."""
    return pinobs.load(name)


def planar_3r_truth(robot: pinobs.Robot) -> pinobs.Robot:
    """The identification tests' truth for a planar 3R: inertias scaled by (1.2, 0.8, 1.1),
    a 0.5 kg payload 5 cm out, viscous and Coulomb friction."""
    return robot.perturbed(
        inertia_scale=[1.2, 0.8, 1.1],
        payload=(0.5, [0.05, 0.0, 0.0]),
        damping=[0.2, 0.1, 0.05],
        coulomb=[0.1, 0.05, 0.02],
    )


@pytest.fixture
def robot_factory():
    return lambda name: cached_robot(name).copy()
