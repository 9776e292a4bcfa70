"""Gains SciPy solved, kept on disk (:mod:`pinobs.observers.gain_cache`, issue 39): the same
bits as SciPy's, without importing ``scipy.linalg`` once solved."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from pinobs.observers import gain_cache
from pinobs.observers.riemannian import gains_from_noise


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The cache in a temporary folder (its user folder: one that cannot be made)."""
    folder = tmp_path / "cache"
    blocked = tmp_path / "a_file"
    blocked.write_text("")
    monkeypatch.setattr(gain_cache, "cache_dirs", lambda: (folder, blocked / "sub"))
    return folder / "pinobs_gains.json"


def _equation(h: float, psd: float, std: float) -> tuple[np.ndarray, ...]:
    F = np.array([[1.0, h], [0.0, 1.0]])
    Q = psd * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]])
    return F.T, np.array([[1.0], [0.0]]), Q, np.array([[std**2]])


def test_a_solution_taken_from_the_cache_is_scipys_to_the_bit(cache, monkeypatch) -> None:
    args = _equation(1e-3, 1e3, 1e-4)
    expected = scipy.linalg.solve_discrete_are(*args)
    solved = gain_cache.solve_discrete_are(*args)  # a miss: solved, then stored
    assert cache.is_file() and np.array_equal(solved, expected)

    def no_scipy(*_args):
        raise AssertionError("solved again")

    monkeypatch.setattr(scipy.linalg, "solve_discrete_are", no_scipy)
    hit = gain_cache.solve_discrete_are(*args)
    assert np.array_equal(hit, expected) and hit.dtype == np.float64 and hit.shape == (2, 2)
    other = _equation(1e-3, 1e3, 2e-4)  # another equation: not in the cache
    with pytest.raises(AssertionError, match="solved again"):
        gain_cache.solve_discrete_are(*other)


def test_riemannians_gains_are_the_same_solved_or_cached(cache) -> None:
    solved = gains_from_noise(1000.0, 1e-4, 1e3)
    assert cache.is_file()
    assert gains_from_noise(1000.0, 1e-4, 1e3) == solved  # (from the cache: the same floats)


def test_another_scipy_version_solves_again(cache, monkeypatch) -> None:
    args, version = _equation(1e-3, 1e3, 1e-4), scipy.__version__
    gain_cache.solve_discrete_are(*args)
    monkeypatch.setattr(scipy, "__version__", "0.0.0")
    gain_cache.solve_discrete_are(*args)
    keys = json.loads(cache.read_text())
    assert sorted(k.split("|")[1] for k in keys) == sorted(["0.0.0", version])


def test_a_damaged_cache_is_solved_again_and_an_unwritable_one_skipped(
    cache, tmp_path, monkeypatch
) -> None:
    args = _equation(2e-3, 10.0, 1e-3)
    expected = scipy.linalg.solve_discrete_are(*args)
    cache.parent.mkdir(parents=True)
    cache.write_text("{not json")
    assert np.array_equal(gain_cache.solve_discrete_are(*args), expected)
    entries = json.loads(cache.read_text())  # written anew
    key = next(iter(entries))
    cache.write_text(json.dumps({key: {"shape": [2, 2], "data": ["zz"] * 4}}))
    assert np.array_equal(gain_cache.solve_discrete_are(*args), expected)
    assert json.loads(cache.read_text())[key]["data"] != ["zz"] * 4  # stored over it
    blocked = tmp_path / "a_file"  # neither folder can be made: solved, nothing stored
    monkeypatch.setattr(gain_cache, "cache_dirs", lambda: (blocked / "x", blocked / "y"))
    assert np.array_equal(gain_cache.solve_discrete_are(*args), expected)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "cache"]


def test_the_cache_is_beside_the_module_then_in_the_users_cache_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    here, user = gain_cache.cache_dirs()
    assert here == Path(gain_cache.__file__).resolve().parent / "__pycache__"
    assert user == tmp_path / "pinobs"


def test_lyapunov_and_expm_taken_from_the_cache_are_scipys_to_the_bit(cache, monkeypatch) -> None:
    F = np.array([[-4.0, 1.0], [-6.0, 0.0]])
    Q = -np.outer([4.0, 6.0], [4.0, 6.0])
    M, times = np.array([[-3.0, 1.0, 3.0], [-2.0, 0.0, 2.0], [0.0, 0.0, 0.0]]), np.r_[1e-3, 0.1]
    lyapunov = scipy.linalg.solve_continuous_lyapunov(F, Q)
    expms = np.stack([scipy.linalg.expm(M * t) for t in times])
    assert np.array_equal(gain_cache.solve_continuous_lyapunov(F, Q), lyapunov)  # solved
    assert np.array_equal(gain_cache.expm_at(M, times), expms)

    def no_scipy(*_args):
        raise AssertionError("solved again")

    monkeypatch.setattr(scipy.linalg, "solve_continuous_lyapunov", no_scipy)
    monkeypatch.setattr(scipy.linalg, "expm", no_scipy)
    assert np.array_equal(gain_cache.solve_continuous_lyapunov(F, Q), lyapunov)  # cached
    hit = gain_cache.expm_at(M, times)
    assert np.array_equal(hit, expms) and hit.shape == (2, 3, 3)
    with pytest.raises(AssertionError, match="solved again"):
        gain_cache.expm_at(M, times[:1])  # other inputs: not in the cache


def test_the_file_keeps_the_newest_entries(cache, monkeypatch) -> None:
    monkeypatch.setattr(gain_cache, "_MAX_ENTRIES", 3)
    for k in range(5):
        gain_cache.cached("square", np.square, np.array([float(k)]))
    keys = list(json.loads(cache.read_text()))
    assert len(keys) == 3 and [k.split("|")[0] for k in keys] == ["square"] * 3
    assert [float.fromhex(json.loads(cache.read_text())[k]["data"][0]) for k in keys] == [
        4.0,
        9.0,
        16.0,
    ]
