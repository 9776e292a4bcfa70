"""Gains SciPy solved, kept on disk: a later process takes them without importing ``scipy.linalg``.

``riemannian``'s gains from the noise (:func:`~pinobs.observers.riemannian.gains_from_noise`)
solve a 2 × 2 discrete Riccati equation with ``scipy.linalg.solve_discrete_are``.  Importing
``scipy.linalg`` costs 0.15 s of CPU and loads SciPy's OpenBLAS, whose worker thread then
spins 0.1–0.2 s of CPU on the other core (issue 39: most of what ``riemannian``'s
``make_observer`` cost above the compiled kernels' loading).  The solution depends on the
equation and on the SciPy that solved it, nothing else: so it is kept, as numba keeps its
compiled kernels, in a JSON file in ``pinobs/observers/__pycache__`` (or, where that is not
writable, ``$XDG_CACHE_HOME/pinobs``, ``~/.cache/pinobs`` by default), each float64 as its
``float.hex`` (the same bits back), keyed by the inputs' bytes and SciPy's version.  A miss,
or a file that cannot be read, solves with SciPy and stores the result (a store that fails is
skipped: the next process solves again).  The gains are the same bits either way (tested).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.observers.base import Vector

__all__ = ["cache_dirs", "solve_discrete_are"]

_FILE = "pinobs_gains.json"


def cache_dirs() -> tuple[Path, ...]:
    """Where the solutions are kept, in the order tried: beside this module (as numba's
    cache), then the user's cache folder."""
    here = Path(__file__).resolve().parent / "__pycache__"
    try:
        user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "pinobs"
    except (RuntimeError, KeyError):  # (no home folder to be found)
        return (here,)
    return (here, user)


def solve_discrete_are(a: Vector, b: Vector, q: Vector, r: Vector) -> Vector:
    """``scipy.linalg.solve_discrete_are(a, b, q, r)``, the same bits, from the cache when it
    was solved before with this SciPy (module docstring)."""
    import scipy  # (the package alone: its version; numba has imported it already)

    arrays = [np.ascontiguousarray(x, dtype=np.float64) for x in (a, b, q, r)]
    key = "|".join(
        ["solve_discrete_are", scipy.__version__]
        + [f"{x.shape}:{x.tobytes().hex()}" for x in arrays]
    )
    for folder in cache_dirs():
        hit = _read(folder / _FILE).get(key)
        if isinstance(hit, dict):
            try:
                values = [float.fromhex(v) for v in hit["data"]]
                return np.array(values, dtype=np.float64).reshape(hit["shape"])
            except (KeyError, TypeError, ValueError):
                break  # (a damaged entry: solved again and stored over it)
    from scipy.linalg import solve_discrete_are as solve  # lazy: 0.15 s CPU at import

    x = np.asarray(solve(a, b, q, r), dtype=np.float64)  # (the caller's arrays, as given)
    entry = {"shape": list(x.shape), "data": [float(v).hex() for v in x.ravel()]}
    for folder in cache_dirs():
        if _store(folder / _FILE, key, entry):
            break
    return x


def _read(path: Path) -> dict[str, Any]:
    """The cache file's entries (none if it is missing or cannot be read)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _store(path: Path, key: str, entry: dict[str, Any]) -> bool:
    """Add ``entry`` under ``key`` to the file at ``path`` (written whole to a temporary
    file, then renamed over it: a reader never sees half a file); False if it cannot be."""
    data = _read(path)
    data[key] = entry
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
