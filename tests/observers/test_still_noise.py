"""σ from the log's stillest second (``still_noise_std``): quantised encoders, a moving start."""

from __future__ import annotations

import numpy as np

import pinobs
from pinobs.observers.noise import still_noise_std, stillest_rows

RATE = 400.0
STEPS = np.array([6e-5, 4e-5])  # the real Go1 log's encoder steps [rad] (hip/thigh, calf)


def _two_joints() -> pinobs.Robot:
    return pinobs.load("double_pendulum")


def _log(rng: np.random.Generator, white: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """5 s at 400 Hz: a swing for 2 s (0.5 rad at 5 Hz, fading out), then still; the reading
    ``Δ round((q + n)/Δ)``; returns ``(t, readings, true angles)``."""
    t = np.arange(0.0, 5.0, 1.0 / RATE)
    swing = 0.5 * np.sin(2 * np.pi * 5.0 * t) * np.clip(1.0 - t / 2.0, 0.0, None) ** 2
    q = np.column_stack([0.4 + swing, -0.7 + 0.5 * swing])
    reading = np.round((q + white * rng.standard_normal(q.shape)) / STEPS) * STEPS
    return t, reading, q


def test_still_noise_std_recovers_a_quantised_encoders_error_after_a_moving_start(rng) -> None:
    """White 3e-5 rad under steps of 6e-5 and 4e-5 rad (σ of the reading's error
    ≈ √(σ² + Δ²/12) = 3.5e-5, 3.2e-5): the stillest second gives it within 15 %."""
    robot = _two_joints()
    t, reading, q = _log(rng, 3e-5)
    true = np.std((reading - q)[t > 2.5], axis=0)
    got = still_noise_std(t, reading, robot)
    assert got is not None
    np.testing.assert_allclose(got, true, rtol=0.15)
    rows = stillest_rows(t, reading, robot)
    assert rows is not None and t[rows[0]] >= 2.0  # a window after the swing


def test_a_reading_that_never_moves_while_still_is_its_rounding(rng) -> None:
    """No white noise: still, the readings repeat exactly (no third differences); σ is the
    rounding's ``Δ/√12`` (the smallest change between rows, in the swing, is one step)."""
    robot = _two_joints()
    t, reading, _ = _log(rng, 0.0)
    got = still_noise_std(t, reading, robot)
    assert got is not None
    np.testing.assert_allclose(got, STEPS / np.sqrt(12.0), rtol=1e-6)


def test_too_few_rows_give_none() -> None:
    robot = _two_joints()
    t = np.arange(10) / RATE
    assert still_noise_std(t, np.zeros((10, 2)), robot) is None
    q = np.zeros((40, 2))
    q[::2] = np.nan  # no four consecutive finite rows
    assert still_noise_std(np.arange(40) / RATE, q, robot) is None
