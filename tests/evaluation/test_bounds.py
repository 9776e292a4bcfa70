"""Bounds under a noisy reference: three-cornered hat, second differences, known-input filter."""

from __future__ import annotations

import numpy as np
import pytest

from pinobs.errors import DimensionError, GainError
from pinobs.evaluation.bounds import (
    known_input_filter,
    second_difference_noise_std,
    three_cornered_hat,
)


def test_three_cornered_hat_recovers_each_estimates_independent_noise() -> None:
    rng = np.random.default_rng(3)
    t = np.linspace(0, 50, 200_000)
    x = np.sin(t)[:, None] * np.array([1.0, 2.0])
    sig = (0.01, 0.03, 0.05)
    est = [x + s * rng.standard_normal(x.shape) for s in sig]
    got = three_cornered_hat(*est)
    for s, g in zip(sig, got, strict=True):
        np.testing.assert_allclose(np.sqrt(g), s, rtol=0.03)


def test_three_cornered_hat_is_exact_on_known_differences_and_shows_correlation() -> None:
    # errors e1 = +1, e2 = -1, e3 = 0 on every row: D12 = 4, D13 = 1, D23 = 1
    x = np.zeros(10)
    s1, s2, s3 = three_cornered_hat(x + 1, x - 1, x)
    assert (s1[0], s2[0], s3[0]) == (2.0, 2.0, -1.0)  # e1, e2 anti-correlated: c12 = -1


def test_three_cornered_hat_refuses_mismatched_shapes() -> None:
    with pytest.raises(DimensionError, match="shapes differ"):
        three_cornered_hat(np.zeros(5), np.zeros(5), np.zeros(6))


def test_second_difference_sees_white_noise_not_a_smooth_signal() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(100_000) * 0.01
    smooth = np.sin(0.5 * t)
    np.testing.assert_allclose(second_difference_noise_std(smooth, t), 0.0, atol=1e-5)
    got = second_difference_noise_std(smooth + 0.002 * rng.standard_normal(t.size), t)
    np.testing.assert_allclose(got, 0.002, rtol=0.02)
    # rows next to an uneven gap are left out, not misread
    t2 = t.copy()
    t2[50_000:] += 0.005
    got2 = second_difference_noise_std(smooth + 0.002 * rng.standard_normal(t.size), t2)
    np.testing.assert_allclose(got2, 0.002, rtol=0.02)


def _truth(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = np.array([1.0, 2.3])
    return np.sin(t[:, None] * w), w * np.cos(t[:, None] * w), -(w**2) * np.sin(t[:, None] * w)


def test_known_input_filter_started_on_the_truth_noise_free_stays_there() -> None:
    t = np.arange(2000) * 0.01
    q, v, a = _truth(t)
    r = known_input_filter(t, q, a, noise_std=1e-6, accel_psd=1e-6, v0=v[0])
    # the input is linear between samples: an O(dt²) integration error only
    assert np.max(np.abs(r.v - v)) < 1e-5
    assert np.max(np.abs(r.d)) == 0.0  # no disturbance state when its density is 0


def test_known_input_filter_converges_from_a_wrong_start_and_absorbs_an_offset() -> None:
    rng = np.random.default_rng(5)
    t = np.cumsum(0.008 + 0.004 * rng.random(3000))  # irregular steps
    q, v, a = _truth(t)
    qm = q + 1e-4 * rng.standard_normal(q.shape)
    late = t > t[0] + 5
    known = known_input_filter(t, qm, a, noise_std=1e-4, accel_psd=1e-4)
    assert np.sqrt(np.mean((known.v - v)[late] ** 2)) < 2e-3
    # a biased model (a + 0.5): the offset state learns −0.5, the velocity stays right
    biased = known_input_filter(t, qm, a + 0.5, noise_std=1e-4, accel_psd=1e-4, disturbance_psd=1.0)
    np.testing.assert_allclose(np.mean(biased.d[late], axis=0), -0.5, atol=0.05)
    assert np.sqrt(np.mean((biased.v - v)[late] ** 2)) < 5e-3
    without = known_input_filter(t, qm, a + 0.5, noise_std=1e-4, accel_psd=1e-4)
    assert np.sqrt(np.mean((without.v - v)[late] ** 2)) > 3 * np.sqrt(
        np.mean((biased.v - v)[late] ** 2)
    )
    # likelihood prefers the model that has the offset
    assert (biased.nll < without.nll).all()


def test_known_input_filter_with_an_acceleration_measurement_beats_the_model_free_one() -> None:
    rng = np.random.default_rng(6)
    t = np.arange(3000) * 0.01
    q, v, a = _truth(t)
    qm = q + 1e-4 * rng.standard_normal(q.shape)
    zero = np.zeros_like(a)
    late = t > 5
    opts = {"noise_std": 1e-4, "accel_psd": 0.0, "disturbance_psd": 10.0}
    free = known_input_filter(t, qm, zero, **opts)
    fused = known_input_filter(
        t,
        qm,
        zero,
        **opts,
        accel_measurement=a + 0.05 * rng.standard_normal(a.shape),
        accel_noise_std=0.05,
    )
    same = known_input_filter(t, qm, zero, **opts, accel_measurement=a, accel_noise_std=np.inf)
    e = lambda r: np.sqrt(np.mean((r.v - v)[late] ** 2))  # noqa: E731
    assert e(fused) < 0.5 * e(free)
    np.testing.assert_array_equal(same.v, free.v)  # σ_a = ∞: the model-free filter exactly


def test_known_input_filter_rejects_bad_input() -> None:
    t = np.arange(5) * 0.01
    q = np.zeros((5, 2))
    with pytest.raises(GainError, match="noise_std > 0"):
        known_input_filter(t, q, q, noise_std=0.0, accel_psd=1.0)
    with pytest.raises(DimensionError, match="strictly increasing"):
        known_input_filter(t[::-1], q, q, noise_std=1e-3, accel_psd=1.0)
    with pytest.raises(DimensionError, match="need"):
        known_input_filter(t, q, q[:, :1], noise_std=1e-3, accel_psd=1.0)
