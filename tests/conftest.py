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


@pytest.fixture
def robot_factory():
    return lambda name: cached_robot(name).copy()
