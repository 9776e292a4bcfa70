"""Loading numba kernels from numba's cache with the target context left unrefreshed (issue 39):
the same machine code, numba's full initialisation skipped, compilation as before."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.conftest import last_line

#: A kernel module written to a temporary folder: its cache (``cache=True``) lands there.
_KERNEL = """
import numba
import numpy as np

@numba.njit(cache=True)
def kernel(a):
    out = np.empty(a.shape[0])  # (numba's runtime allocates)
    for i in range(a.shape[0]):
        out[i] = np.sum(a[: i + 1]) * 0.1
    return out
"""

_LOAD = """
import json, sys
import numpy as np
from pinobs.observers.kernel_cache import load_signature
import tiny_kernel
a = np.arange(5.0) / 3.0
first = load_signature(tiny_kernel.kernel, a)
again = tiny_kernel.kernel(a)  # (the loaded signature)
from numba.core import entrypoints
print(json.dumps({"out": first.tolist(), "again": again.tolist(),
                  "refreshed": "numba.np.polynomial.polynomial_functions" in sys.modules,
                  "extensions": entrypoints._already_initialized,
                  "hits": sum(tiny_kernel.kernel.stats.cache_hits.values())}))
"""


def _run(code: str, tmp_path: Path) -> dict[str, object]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), env.get("PYTHONPATH", "")])
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    result: dict[str, object] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def test_a_cache_miss_compiles_and_a_cache_hit_loads_without_refreshing_numba(
    tmp_path: Path,
) -> None:
    """First process: nothing cached, so the kernel compiles (numba's extensions initialised
    first, then its own refresh, every registry); second: loaded from the cache with
    numba's registries not installed (its polynomial module, imported by the refresh only,
    not imported) and its extensions' entry points not read; the same bits."""
    (tmp_path / "tiny_kernel.py").write_text(_KERNEL)
    compiled = _run(_LOAD, tmp_path)
    loaded = _run(_LOAD, tmp_path)
    expected = np.cumsum(np.arange(5.0) / 3.0) * 0.1
    assert compiled["hits"] == 0 and compiled["refreshed"] is True
    assert compiled["extensions"] is True
    assert loaded["hits"] == 1 and loaded["refreshed"] is False
    assert loaded["extensions"] is False
    assert compiled["out"] == loaded["out"] == loaded["again"] == compiled["again"]
    assert np.max(np.abs(np.array(loaded["out"]) - expected)) < 1e-15


def test_a_kernel_without_a_disk_cache_compiles_as_usual() -> None:
    """A dispatcher with no disk cache (``cache=False``) loads nothing: it compiles with
    numba's own refresh, NumPy functions typed as usual."""
    code = (
        "import numba, numpy as np\n"
        "from pinobs.observers.kernel_cache import load_signature\n"
        "f = numba.njit(lambda a: np.linalg.norm(a) + np.sum(a))\n"
        "print(load_signature(f, np.array([3.0, 4.0])))\n"
    )
    assert last_line(code) == "12.0"


def test_numba_compiles_as_usual_after_a_lean_load() -> None:
    """A ``kf`` made (its kernel loaded from the cache without numba's refresh), then a new
    function compiled in the same process: numba refreshes its context for it then."""
    code = (
        "import sys, numba, numpy as np, pinobs\n"
        "pinobs.make_observer('kf', pinobs.load('ur5'), rate=1000.0, noise_std=1e-4)\n"
        "f = numba.njit(lambda a: np.linalg.norm(a) + np.sum(a))\n"
        "print(f(np.array([3.0, 4.0])))\n"
    )
    assert last_line(code) == "12.0"


def test_kf_and_ekf_estimates_are_the_same_bits_with_numba_refreshed_first() -> None:
    """Issue 39: the estimates of ``kf`` and ``ekf`` (UR5, 1 kHz, 100 updates) from kernels
    loaded the lean way equal, to the bit, those of a process that refreshed numba's
    target context first (numba's own way of loading a cached kernel)."""
    code = (
        "import sys, json, numpy as np, pinobs\n"
        "if sys.argv[1] == 'full':\n"
        "    from numba.core.registry import cpu_target\n"
        "    cpu_target.target_context.refresh()\n"
        "robot = pinobs.load('ur5'); q0 = robot.neutral(); out = {}\n"
        "for name in ('kf', 'ekf'):\n"
        "    obs = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)\n"
        "    obs.reset(0.0, q0)\n"
        "    out[name] = [obs.update(k * 1e-3, robot.integrate(q0, 0.2 * np.sin(k * 3e-3 + "
        "np.arange(robot.nv)))).v.tolist() for k in range(1, 101)]\n"
        "print(json.dumps(out))\n"
    )

    def run(mode: str) -> dict[str, list[list[float]]]:
        done = subprocess.run(
            [sys.executable, "-c", code, mode], capture_output=True, text=True, check=True
        )
        result: dict[str, list[list[float]]] = json.loads(done.stdout.strip().splitlines()[-1])
        return result

    full, lean = run("full"), run("lean")
    assert full == lean  # floats through JSON's repr: the same bits
    assert len(lean["kf"]) == len(lean["ekf"]) == 100


def test_kf_made_from_a_warm_cache_imports_neither_scipy_linalg_nor_numba_s_registries() -> None:
    """Issue 39: ``kf``'s kernel makes no BLAS or LAPACK call, so with its kernel in the
    cache (the first process fills it if need be) ``make_observer("kf")`` imports no
    ``scipy.linalg`` (0.17 s of CPU) and not numba's registries (0.2 s)."""
    code = (
        "import sys, pinobs\n"
        "pinobs.make_observer('kf', pinobs.load('ur5'), rate=1000.0, noise_std=1e-4)\n"
        "heavy = ('scipy.linalg', 'numba.np.polynomial.polynomial_functions', 'numba')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    assert last_line(code, runs=2) == "['numba']"


#: A kernel module for ``LazyKernel``'s ``contracted``: ``caller`` calls ``_axpy_fma``, which
#: must be ``axpy`` compiled with ``contract`` whatever the name was bound to before.
_CONTRACTED = """
def axpy(w, x, y, h):
    for i in range(x.shape[0]):
        w[i] = x[i] + h * y[i]


def caller(w, x, y, h):
    _axpy_fma(w, x, y, h)


_axpy_fma = axpy
"""


def test_a_contracted_helper_keeps_its_flag_when_its_name_is_another_kernel_s_inlined_helper(
    tmp_path: Path, monkeypatch
) -> None:
    """``LazyKernel(..., contracted=(name,))``: ``name`` is compiled with ``contract`` (one FMA
    for ``x + h·y``) also where it was bound to a helper another kernel compiled without it
    (``riemannian_fused``'s ``_rk4_start_fma = fused.rk4_start_loops``, imported after an
    ``ekf`` kernel had put its inlined helper in ``fused``'s scope: the fused ``riemannian``
    then moved by an ulp on about 1 sample in 500, order-dependently).  Checked against the
    exactly rounded ``x + h·y`` (fractions)."""
    import importlib
    from fractions import Fraction

    import numba

    from pinobs.observers.linalg import LazyKernel

    (tmp_path / "tiny_contracted.py").write_text(_CONTRACTED)
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = importlib.import_module("tiny_contracted")
    # what another kernel's `helpers` leaves: the name bound to an inlined, uncontracted kernel
    mod._axpy_fma = numba.njit(error_model="numpy", inline="always")(mod.axpy)
    n = 64
    kernel = LazyKernel(
        mod.caller, np.zeros(n), np.zeros(n), np.zeros(n), 1e-3, contracted=("_axpy_fma",)
    )
    kernel.load()
    assert kernel.compiled is not None
    rng = np.random.default_rng(0)
    fused = plain = 0
    for _ in range(50):
        x, y, w = rng.normal(size=n), rng.normal(size=n) * 10, np.empty(n)
        kernel.compiled(w, x, y, 5e-4)
        exact = [
            float(Fraction(a) + Fraction(5e-4) * Fraction(b)) for a, b in zip(x, y, strict=True)
        ]
        fused += int(np.array_equal(w, exact))
        plain += int(np.array_equal(w, x + 5e-4 * y))
    assert fused == 50 and plain < 50  # every row one FMA; rows where it differs exist
