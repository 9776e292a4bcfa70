"""BLAS on one thread for the length of one observer call, the caller's setting restored after.

An observer's matrices are small, too small to gain from threads; past
OpenBLAS's own size thresholds (measured here: ``np.linalg.inv`` and ``eigh``
from 48², scipy's ``cho_solve`` from 32², a product from about 96²; ``ekf``'s
covariance on talos is 76²) a multi-threaded BLAS splits the work over its
threads anyway, and on a busy machine they wait for a core.  :func:`pinobs.simulate` and
:func:`pinobs.evaluation.measure_cost` run on one thread; a user's own loop
runs with the process's default (two threads here), so :func:`one_blas_thread`
puts :meth:`~pinobs.observers.Observer.update`, ``reset`` and
:func:`~pinobs.observers.make_observer` on one thread for the length of the
call and restores the count after, whatever the caller set.  ``make_observer``
too: a family's gains (``riemannian``'s discrete Riccati equation, by scipy)
woke scipy's OpenBLAS worker thread, which then spins about 50 ms waiting for
more work, on the other core, through the first updates (measured: 48–50 ms of
its run time during 3000 UR5 updates after each build; none with the build on
one thread).

How, at a cost measured against one ``pin.aba`` call on a UR5 timed in the same
run (loaded 2-core machine, load average 4–6):

* OpenBLAS with its own (pthreads) thread pool, the pip wheels of numpy and
  scipy: its ``openblas_get_num_threads`` / ``openblas_set_num_threads``
  called through :mod:`ctypes` (a get per library, and a set down and back
  where the count is not 1 already).  For the two libraries numpy and scipy
  load, back to back: 0.6× one warm ``pin.aba`` (0.4–0.8); in a loop paced at
  1 kHz, where every call starts with cold caches: 11–12 µs, 4.6–5.1× a warm
  ``pin.aba`` (1.4× the ``pin.aba`` call timed at the same point of the tick).
  A fresh ``threadpoolctl.threadpool_limits`` per call costs 650–870× a warm
  ``pin.aba`` (it scans the process's libraries), a cached controller's
  ``limit`` 1–17×.
* Any other BLAS (MKL, BLIS, OpenBLAS on OpenMP): a cached
  ``threadpoolctl`` controller's ``limit(limits=1)`` around the call.

What it buys: ``ekf`` on talos (76² covariance, past OpenBLAS's threading
thresholds) took 8.6 ms an update with the default two threads against 0.4 ms
with the limit (300 updates, load average 4–6), bit-identical estimates.  Small
robots are not safe by size alone: with the limit off, ``highgain``'s updates
woke the BLAS worker threads on a UR5 and a Panda (24–38 ms of their run time,
from ``/proc``, in 2 s of updates; its p99.9 update 7–9 ms against 0.5–3.5 ms
with the limit), while those of every other family on UR5, Panda and go1 did
not (zero): for those the limit is only its cost.  (``highgain``'s step is compiled on a
vector space since: no BLAS call there, no limit; 0 ms of BLAS threads in 3000 UR5
updates, 50 ms before.)

The libraries are found once (about 3 ms, at the first call: ``reset``), and
once more after ``scipy.linalg`` is first imported (it loads scipy's own
OpenBLAS).  OpenBLAS's pthreads pool is process-wide: a BLAS call that another
thread makes *during* an update runs on one thread too, and a count another
thread sets during an update is overwritten when it ends (as with
``threadpoolctl``'s own limits).
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys
from collections.abc import Callable
from typing import Any, NamedTuple, ParamSpec, TypeVar

__all__ = ["BlasLibraries", "OpenBLASPool", "blas_libraries", "found_libraries", "one_blas_thread"]

P = ParamSpec("P")
R = TypeVar("R")

#: The affixes of OpenBLAS's symbols (threadpoolctl's list: ``scipy_openblas`` wheels
#: export ``scipy_openblas_get_num_threads64_``).
_OPENBLAS_AFFIXES = [(p, s) for p in ("", "scipy_") for s in ("", "64_", "_64")]


class OpenBLASPool(NamedTuple):
    """One OpenBLAS library's thread-count functions (:mod:`ctypes`)."""

    filepath: str
    get_threads: Callable[[], int]
    set_threads: Callable[[int], None]


class BlasLibraries(NamedTuple):
    """The BLAS libraries loaded in the process, as :func:`one_blas_thread` limits them.

    Attributes:
        openblas: OpenBLAS libraries with their own (pthreads) pool, called directly.
        others: a ``threadpoolctl`` controller of every other BLAS library, or ``None``.
    """

    openblas: tuple[OpenBLASPool, ...]
    others: Any


def _openblas_pool(filepath: str) -> OpenBLASPool | None:
    """The thread-count functions of the loaded OpenBLAS at ``filepath`` (``None``: not found)."""
    try:  # RTLD_NOLOAD: a handle to the library already loaded, never a second copy
        lib = ctypes.CDLL(filepath, mode=getattr(os, "RTLD_NOLOAD", 0) | ctypes.RTLD_LOCAL)
    except OSError:
        return None
    for prefix, suffix in _OPENBLAS_AFFIXES:
        get = getattr(lib, f"{prefix}openblas_get_num_threads{suffix}", None)
        set_ = getattr(lib, f"{prefix}openblas_set_num_threads{suffix}", None)
        if get is not None and set_ is not None:
            get.restype, get.argtypes = ctypes.c_int, []
            set_.restype, set_.argtypes = None, [ctypes.c_int]
            return OpenBLASPool(filepath, get, set_)
    return None


def _scan() -> BlasLibraries:
    from threadpoolctl import ThreadpoolController  # lazily: import pinobs stays light

    controller = ThreadpoolController().select(user_api="blas")
    pools, others = [], []
    for info in controller.info():
        pool = None
        if info["internal_api"] == "openblas" and info.get("threading_layer") == "pthreads":
            pool = _openblas_pool(info["filepath"])
        if pool is None:
            others.append(info["filepath"])
        else:
            pools.append(pool)
    return BlasLibraries(tuple(pools), controller.select(filepath=others) if others else None)


_FOUND: dict[bool, BlasLibraries] = {}  # a cache of _scan, by whether scipy.linalg is loaded


#: ``found_libraries("scipy.linalg" in sys.modules)``: :func:`blas_libraries`' result where it
#: was found already, else ``None`` (a C call, not a Python one: ``ekf``'s plain update on a
#: large robot limits the threads inline, :func:`pinobs.observers.ekf_fused.update_blocks`).
found_libraries = _FOUND.get


def blas_libraries() -> BlasLibraries:
    """The BLAS libraries numpy and scipy use, found once (and again once ``scipy.linalg``,
    which loads scipy's own, is imported)."""
    key = "scipy.linalg" in sys.modules
    found = _FOUND.get(key)
    if found is None:
        found = _FOUND[key] = _scan()
    return found


def one_blas_thread(func: Callable[P, R]) -> Callable[P, R]:
    """Decorator: ``func`` runs with every BLAS library on one thread; each library's thread
    count is set back after the call to what it was before (module docstring)."""

    @functools.wraps(func)
    def limited(*args: P.args, **kwargs: P.kwargs) -> R:
        libs = blas_libraries()
        lowered = []
        for pool in libs.openblas:
            n = pool.get_threads()
            if n != 1:
                pool.set_threads(1)
                lowered.append((pool, n))
        try:
            if libs.others is None:
                return func(*args, **kwargs)
            with libs.others.limit(limits=1):
                return func(*args, **kwargs)
        finally:
            for pool, n in lowered:
                pool.set_threads(n)

    return limited
