"""Results SciPy computed, kept on disk: a later process takes them without importing ``scipy.linalg``.

Importing ``scipy.linalg`` costs 0.15 s of CPU and loads SciPy's OpenBLAS, whose worker thread
then spins 0.1–0.2 s of CPU on the other core (issue 39).  Three families' constructors needed
it for numbers that depend on their inputs alone: ``riemannian``'s gains from the noise
(:func:`~pinobs.observers.riemannian.gains_from_noise`, a 2 × 2 discrete Riccati equation:
:func:`solve_discrete_are`), and ``highgain``'s (``kalman`` builds one) default bandwidth
(the Lyapunov equation of its noise coefficient: :func:`solve_continuous_lyapunov`) and
exact first-order hold at its nominal sample interval (:func:`expm_at`; module docstring of
:mod:`pinobs.observers.differentiators`).  :func:`cached` serves the three: a result depends on
the solver, its inputs and the SciPy that computed it, nothing else, so it is kept, as numba
keeps its compiled kernels, in a JSON file in ``pinobs/observers/__pycache__`` (or, where that
is not writable, ``$XDG_CACHE_HOME/pinobs``, ``~/.cache/pinobs`` by default), each float64 as
its ``float.hex`` (the same bits back), keyed by the solver's name, SciPy's version and the
inputs' bytes; the newest :data:`_MAX_ENTRIES` are kept.  A miss, or a file that cannot be
read, computes with SciPy and stores the result (a store that fails is skipped: the next
process computes again).  The results are the same bits either way (tested).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.blas import one_blas_thread

__all__ = ["cache_dirs", "cached", "expm_at", "solve_continuous_lyapunov", "solve_discrete_are"]

_FILE = "pinobs_gains.json"
#: Entries kept in the file, the newest (a read stays a few milliseconds).
_MAX_ENTRIES = 32


def cache_dirs() -> tuple[Path, ...]:
    """Where the solutions are kept, in the order tried: beside this module (as numba's
    cache), then the user's cache folder."""
    here = Path(__file__).resolve().parent / "__pycache__"
    try:
        user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "pinobs"
    except (RuntimeError, KeyError):  # (no home folder to be found)
        return (here,)
    return (here, user)


def cached(name: str, solve: Callable[..., Vector], *inputs: Vector) -> Vector:
    """``solve(*inputs)`` as a float64 array, from the cache when ``name`` was solved before on
    the same inputs with this SciPy, else solved and stored (module docstring).  ``solve``
    imports SciPy's solver itself (lazily: a hit imports no ``scipy.linalg``); the inputs are
    passed to it as given."""
    import scipy  # (the package alone: its version; numba has imported it already)

    arrays = [np.ascontiguousarray(x, dtype=np.float64) for x in inputs]
    key = "|".join([name, scipy.__version__] + [f"{x.shape}:{x.tobytes().hex()}" for x in arrays])
    for folder in cache_dirs():
        hit = _read(folder / _FILE).get(key)
        if isinstance(hit, dict):
            try:
                values = [float.fromhex(v) for v in hit["data"]]
                return np.array(values, dtype=np.float64).reshape(hit["shape"])
            except (KeyError, TypeError, ValueError):
                break  # (a damaged entry: solved again and stored over it)
    x = np.asarray(solve(*inputs), dtype=np.float64)
    entry = {"shape": list(x.shape), "data": [float(v).hex() for v in x.ravel()]}
    for folder in cache_dirs():
        if _store(folder / _FILE, key, entry):
            break
    return x


def solve_discrete_are(a: Vector, b: Vector, q: Vector, r: Vector) -> Vector:
    """``scipy.linalg.solve_discrete_are(a, b, q, r)``, the same bits, from the cache when it
    was solved before with this SciPy (module docstring)."""
    return cached("solve_discrete_are", _dare, a, b, q, r)


def solve_continuous_lyapunov(a: Vector, q: Vector) -> Vector:
    """``scipy.linalg.solve_continuous_lyapunov(a, q)`` (``a x + x aᵀ = q``), the same bits,
    from the cache when it was solved before with this SciPy (module docstring)."""
    return cached("solve_continuous_lyapunov", _lyapunov, a, q)


def expm_at(a: Vector, times: Vector) -> Vector:
    """``exp(a·t)`` for each ``t`` in ``times``, shape ``(len(times), *a.shape)``: each
    ``scipy.linalg.expm(a * t)`` on one BLAS thread, the same bits, from the cache when they
    were computed before with this SciPy (module docstring)."""
    return cached("expm_at", _expm_at, a, times)


def _dare(a: Vector, b: Vector, q: Vector, r: Vector) -> Vector:
    from scipy.linalg import solve_discrete_are as solve  # lazy: 0.15 s CPU at import

    return solve(a, b, q, r)  # type: ignore[no-any-return]


def _lyapunov(a: Vector, q: Vector) -> Vector:
    from scipy.linalg import solve_continuous_lyapunov as solve  # lazy: 0.15 s CPU at import

    return solve(a, q)  # type: ignore[no-any-return]


def _expm_at(a: Vector, times: Vector) -> Vector:
    from scipy.linalg import expm  # lazy: 0.15 s CPU at import

    one = one_blas_thread(expm)  # (a constructor may run without make_observer's limit)
    return np.stack([one(a * t) for t in times])


def _read(path: Path) -> dict[str, Any]:
    """The cache file's entries (none if it is missing or cannot be read)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _store(path: Path, key: str, entry: dict[str, Any]) -> bool:
    """Add ``entry`` under ``key`` to the file at ``path`` (written whole to a temporary
    file, then renamed over it: a reader never sees half a file), dropping the oldest beyond
    :data:`_MAX_ENTRIES`; False if it cannot be."""
    data = _read(path)
    data.pop(key, None)  # (stored again: the newest)
    data[key] = entry
    for old in list(data)[: max(0, len(data) - _MAX_ENTRIES)]:
        del data[old]  # the oldest first: a read stays a few milliseconds
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(data))
        os.replace(tmp, path)
    except OSError:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        return False
    return True
