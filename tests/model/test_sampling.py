"""Logs off a uniform grid: missing samples, the held torque's integral, the tick grid."""

from __future__ import annotations

import numpy as np

from pinobs.model.identification.regressor import _window_nodes
from pinobs.model.identification.savgol import _local_polynomial
from pinobs.model.noise import third_difference_std
from pinobs.model.sampling import held_torque_integral, missing_samples, on_ticks
from tests.conftest import dropped_rows


def _ticks(n: int = 2000, h: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * h
    tau = np.column_stack([np.sin(3 * t), 2 + t**2])  # the torque held at each tick
    return t, tau


def test_missing_samples_count_the_lost_ticks_and_none_on_irregular_sampling(
    rng: np.random.Generator,
) -> None:
    t, _ = _ticks()
    keep = dropped_rows(t.size, 0.08, 1)
    lost = missing_samples(t[keep])
    assert lost.sum() == t.size - keep.sum()
    assert set(lost.tolist()) <= {0, 1, *range(3, 10)}
    irregular = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 5000))
    assert not missing_samples(irregular).any()  # (the median a little under 1 ms)


def test_held_integral_with_dropped_ticks_is_exact_for_a_torque_linear_across_each_gap() -> None:
    t, _ = _ticks()
    tau = np.column_stack([0.3 + 2.0 * t, -1.0 * t])  # linear: interpolation is exact
    full = np.zeros_like(tau)
    full[1:] = np.cumsum(tau[:-1] * np.diff(t)[:, None], axis=0)  # every tick held
    keep = dropped_rows(t.size, 0.08, 2)
    np.testing.assert_allclose(held_torque_integral(t[keep], tau[keep]), full[keep], atol=1e-13)
    # holding the last torque across each gap instead is off by τ̇Δ²(m−1)/(2m) per gap
    dt = np.diff(t[keep])
    naive = np.concatenate([[0.0], np.cumsum(tau[keep][:-1, 0] * dt)])
    assert np.abs(naive - full[keep, 0]).max() > 1e-5


def test_held_integral_of_a_uniform_log_is_the_plain_sum() -> None:
    t, tau = _ticks()
    plain = np.zeros_like(tau)
    plain[1:] = np.cumsum(tau[:-1] * np.diff(t)[:, None], axis=0)
    assert np.array_equal(held_torque_integral(t, tau), plain)


def test_on_ticks_puts_each_row_back_on_its_tick_with_interpolated_torques() -> None:
    t, tau = _ticks()
    q = np.column_stack([np.cos(t)])
    keep = dropped_rows(t.size, 0.08, 3)
    t_x, q_x, tau_x, rows = on_ticks(t[keep], q[keep], tau[keep])
    assert rows is not None
    np.testing.assert_allclose(t_x, t, atol=1e-15)
    np.testing.assert_array_equal(rows, np.flatnonzero(keep))
    assert np.array_equal(np.isnan(q_x[:, 0]), ~keep)
    lin = np.column_stack([np.interp(t, t[keep], tau[keep][:, j]) for j in range(2)])
    np.testing.assert_allclose(tau_x, lin, atol=1e-14)
    same = on_ticks(t, q, tau)
    assert same[3] is None and same[0] is t and same[2] is tau


def test_windows_of_a_uniform_log_are_every_window_rows_and_nodes_every_stride() -> None:
    t, _ = _ticks(1001)
    nodes, bounds = _window_nodes(t, 100, 2)
    np.testing.assert_array_equal(nodes, np.arange(0, 1001, 2))
    np.testing.assert_array_equal(nodes[bounds], np.arange(0, 1001, 100))


def test_a_dropped_sample_moves_a_node_to_the_next_row_without_splitting_the_window() -> None:
    t, _ = _ticks(1001)
    keep = np.ones(t.size, dtype=bool)
    keep[[100, 101, 102, 350]] = False  # a window's end, and a node inside one
    tk = t[keep]
    nodes, bounds = _window_nodes(tk, 100, 2)
    ends = tk[nodes[bounds]]
    np.testing.assert_allclose(ends, [0.0, 0.103, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0])
    # steps of 2 ms; across the drops, from the node before them to the first row after
    np.testing.assert_allclose(np.sort(np.diff(tk[nodes]))[-3:], [0.002, 0.003, 0.005])


def test_real_time_fit_on_a_uniform_grid_is_savitzky_golay(rng: np.random.Generator) -> None:
    from scipy.signal import savgol_filter

    t = np.arange(3001) * 1e-3
    u = np.column_stack([np.sin(3 * t), np.cos(2 * t)]) + rng.normal(0, 1e-4, (t.size, 2))
    u_s, v = _local_polynomial(t, u, 50e-3, 4, 0.5e-3)
    np.testing.assert_allclose(
        v, savgol_filter(u, 101, 4, deriv=1, delta=1e-3, axis=0, mode="interp"), atol=1e-9
    )
    np.testing.assert_allclose(u_s, savgol_filter(u, 101, 4, axis=0, mode="interp"), atol=1e-12)


def test_noise_estimate_is_unbiased_with_drops_and_irregular_sampling(
    rng: np.random.Generator,
) -> None:
    """The binomial third difference on uneven rows: 2.0× σ with 30 % dropped, 5.4–6.4× at
    intervals uniform in 0.5–1.5 ms (1 rad/s motion); the divided difference 0.99–1.01×."""
    sigma = 1e-4

    def path(t: np.ndarray) -> np.ndarray:
        return np.column_stack([2 * np.sin(3 * t), np.cos(7 * t)])

    t = np.arange(20_001) * 1e-3
    keep = rng.random(t.size) > 0.3
    irregular = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 20_000))
    for times in (t, t[keep], irregular):
        x = path(times) + rng.normal(0, sigma, (times.size, 2))
        found = third_difference_std(x, times)
        assert found is not None
        np.testing.assert_allclose(found, sigma, rtol=0.05)
