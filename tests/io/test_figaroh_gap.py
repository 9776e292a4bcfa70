"""``benchmarks/figaroh_gap.py``'s measurements on series whose answer is known (no data, no
FIGAROH needed: its pure helpers)."""

from __future__ import annotations

import numpy as np

from tests.io.test_real_data import bench_module


def _gap():
    return bench_module("figaroh_gap")


def _rows(n: int = 2000, seed: int = 3) -> dict:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    w = 2 * np.pi * np.array([0.3, 0.7, 1.1, 2.5, 0.5])
    v = 0.05 * np.sin(np.outer(t, w) + rng.uniform(0, 6, 5))
    a = np.gradient(v, t, axis=0)
    fit = t < 0.8 * t[-1]
    return {"t": t, "v": v, "a": a, "fit": fit, "held": ~fit}


def test_inertia_left_recovers_a_missing_inertia() -> None:
    """A residual ``−ΔI a + offset + viscous + Coulomb`` gives back ``ΔI`` per joint."""
    gap = _gap()
    d = _rows()
    missing = np.array([0.0, 2.0, 0.5, -0.3, 1.0])
    r = -missing * d["a"] + 0.1 + 3.0 * d["v"] + 0.2 * np.tanh(d["v"] / 0.01)
    np.testing.assert_allclose(gap.inertia_left(d, r, d["fit"]), missing, atol=1e-9)
    # a constant inertia is left alike at every band of the moving average
    for band in gap.inertia_by_band(d, r):
        np.testing.assert_allclose(band, missing, rtol=0.02, atol=1e-3)


def test_boot_ratio_of_a_scaled_residual_is_that_scale_with_a_tight_interval() -> None:
    gap = _gap()
    d = _rows()
    rng = np.random.default_rng(0)
    den = rng.normal(size=d["v"].shape)
    out = gap.boot_ratio(d, 1.5 * den, den)
    for ratio, lo, hi in out:
        assert abs(ratio - 1.5) < 1e-12 and abs(lo - 1.5) < 1e-9 and abs(hi - 1.5) < 1e-9
    noisy = gap.boot_ratio(d, rng.normal(size=den.shape), den)
    assert all(lo < ratio < hi for ratio, lo, hi in noisy)


def test_folds_cover_the_fitted_rows_once_in_time_order() -> None:
    gap = _gap()
    d = _rows()
    blocks = gap.folds(d)
    assert len(blocks) == gap.FOLDS
    np.testing.assert_array_equal(np.sum(blocks, axis=0), d["fit"].astype(int))
    ends = [d["t"][b].max() for b in blocks]
    starts = [d["t"][b].min() for b in blocks]
    assert all(e < s for e, s in zip(ends[:-1], starts[1:], strict=True))


def test_joined_drops_a_block_and_marks_the_gap_with_one_nan_row() -> None:
    gap = _gap()
    t = np.arange(10.0)
    q = np.arange(20.0).reshape(10, 2)
    keep = np.ones(10, bool)
    keep[3:6] = False
    keep[:1] = False
    T, Q = gap.joined(keep, t, q)
    np.testing.assert_array_equal(T, [1, 2, 5, 6, 7, 8, 9])
    assert np.isnan(Q[2]).all() and np.isfinite(np.delete(Q, 2, axis=0)).all()
    np.testing.assert_array_equal(Q[[0, 1, 3]], q[[1, 2, 6]])
    assert np.all(np.diff(T) > 0)
