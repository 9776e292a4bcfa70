"""LAPACK's pivoted QR from NumPy's own OpenBLAS (:mod:`pinobs.model.identification.lapack`):
SciPy's ``qr(mode="economic", pivoting=True)``'s ``R`` and ``P``, without importing SciPy."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from pinobs.model.identification import lapack


def _cases(rng: np.random.Generator) -> list[np.ndarray]:
    """The learner's shapes (few rows of many parameters, then many rows), rank-deficient
    ones (repeated and zero columns: ties in the pivoting), and columns of wide scales."""
    full = [rng.normal(size=shape) for shape in ((18, 78), (36, 54), (400, 78), (7, 7), (1, 5))]
    low = rng.normal(size=(60, 5)) @ rng.normal(size=(5, 40))
    tied = rng.normal(size=(30, 12))
    tied[:, 6:] = tied[:, :6]  # six pairs of equal columns
    tied[:, 3] = 0.0
    scaled = rng.normal(size=(50, 20)) * np.logspace(-8, 8, 20)
    return [*full, low, tied, scaled]


def test_pivoted_qr_is_scipy_s_to_the_bit(rng: np.random.Generator) -> None:
    """Issue 39: the learner's solve no longer imports ``scipy.linalg`` (0.13 s of
    ``adaptive``'s construction); the QR it asks for is the same LAPACK routine, whose
    factors and pivots are SciPy's, bit for bit, ties and rank deficiency included."""
    assert lapack.numpy_has_dgeqp3()  # NumPy's wheels bundle scipy-openblas
    for a in _cases(rng):
        given = a.copy()
        _, r_scipy, p_scipy = scipy.linalg.qr(a, mode="economic", pivoting=True)
        r, p = lapack.pivoted_qr(a)
        assert np.array_equal(p, p_scipy)
        assert np.array_equal(r, r_scipy)
        assert np.array_equal(a, given)  # (the input is left as it was)


def test_pivoted_qr_without_numpy_s_lapack_is_scipy_s(
    rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A NumPy without ``dgeqp3`` (MKL, a system LAPACK): SciPy's ``qr`` itself; and both
    refuse what SciPy's ``check_finite`` refuses."""
    a = _cases(rng)[0]
    r_numpy, p_numpy = lapack.pivoted_qr(a)
    monkeypatch.setattr(lapack, "_numpy_dgeqp3", lambda: None)
    r, p = lapack.pivoted_qr(a)
    assert np.array_equal(p, p_numpy)
    assert np.array_equal(r, r_numpy)
    bad = a.copy()
    bad[2, 3] = np.nan
    for _ in range(2):
        with pytest.raises(ValueError, match="infs or NaNs"):
            lapack.pivoted_qr(bad)
        monkeypatch.undo()
