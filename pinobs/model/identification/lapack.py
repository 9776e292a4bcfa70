"""LAPACK's column-pivoted QR (``dgeqp3``) from NumPy's own LAPACK, without importing SciPy.

:func:`pivoted_qr` is ``scipy.linalg.qr(a, mode="economic", pivoting=True)``'s ``(R, P)``
(Businger & Golub, "Linear least squares solutions by Householder transformations",
*Numer. Math.* 7, 1965; LAPACK's ``dgeqp3``, Quintana-Ortí, Sun & Bischof 1998): the same
LAPACK routine, called through :mod:`ctypes` in the OpenBLAS that NumPy's wheels bundle and
have loaded already (``scipy_dgeqp3_64_``: ``scipy-openblas64``), with SciPy's workspace
query.  Why: :func:`~pinobs.model.identification.solve` is the only SciPy call of ``adaptive``'s
synchronous learning, and ``import scipy.linalg`` cost that observer's construction 0.13 s
on its main thread and about 0.09 s more on SciPy's OpenBLAS thread, which spins once the
library loads (issue 39: make + first update ≤ 0.5 s).  Where NumPy carries no such symbol
(a NumPy built on MKL or on a system LAPACK) SciPy's ``qr`` is used, as before.
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["numpy_has_dgeqp3", "pivoted_qr"]

#: ``dgeqp3``'s symbol in the OpenBLAS builds NumPy's wheels bundle, with its integer type:
#: ``scipy-openblas64`` (ILP64, the wheels since NumPy 2.0), ``scipy-openblas32``.
_SYMBOLS = (
    ("scipy_dgeqp3_64_", ctypes.c_int64),
    ("dgeqp3_64_", ctypes.c_int64),
    ("scipy_dgeqp3_", ctypes.c_int32),
)


@functools.cache
def _numpy_dgeqp3() -> tuple[Any, Any] | None:
    """``(dgeqp3, its integer type)`` from the OpenBLAS NumPy loaded, or ``None``."""
    root = os.path.dirname(np.__file__)
    for folder in (root + ".libs", os.path.join(root, ".dylibs"), os.path.join(root, ".libs")):
        for path in sorted(glob.glob(os.path.join(folder, "*openblas*"))):
            try:  # RTLD_NOLOAD: the library NumPy loaded, never a second copy
                lib = ctypes.CDLL(path, mode=getattr(os, "RTLD_NOLOAD", 0) | ctypes.RTLD_LOCAL)
            except OSError:
                continue
            for name, int_t in _SYMBOLS:
                func = getattr(lib, name, None)
                if func is not None:
                    func.restype = None
                    return func, int_t
    return None


def numpy_has_dgeqp3() -> bool:
    """Whether :func:`pivoted_qr` calls NumPy's LAPACK (``False``: SciPy's ``qr``); the
    library is looked up now, once (a construction's work, not a first solve's)."""
    return _numpy_dgeqp3() is not None


def pivoted_qr(a: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """``(R, P)`` with ``A[:, P] = Q R`` (``R`` economic: ``min(m, n) × n``, upper
    triangular; ``P`` 0-based), as ``scipy.linalg.qr(a, mode="economic", pivoting=True)``
    gives them (``Q`` is not formed).

    Raises:
        ValueError: ``a`` holds a NaN or an infinity (SciPy's ``check_finite``).
    """
    a = np.asarray_chkfinite(a, dtype=np.float64)
    found = _numpy_dgeqp3()
    if found is None or a.ndim != 2 or a.size == 0:
        from scipy.linalg import qr  # lazily: NumPy without dgeqp3 (see the module docstring)

        _, R, piv = qr(a, mode="economic", pivoting=True)
        return R, piv
    dgeqp3, int_t = found
    m, n = a.shape
    work_a = np.array(a, order="F")  # overwritten by the factors
    jpvt = np.zeros(n, dtype=int_t)  # 0: every column free to move
    tau = np.empty(min(m, n))
    info = int_t(0)
    dim_m, dim_n, lda = int_t(m), int_t(n), int_t(max(1, m))

    def call(work: NDArray[np.float64], lwork: int) -> None:
        dgeqp3(
            ctypes.byref(dim_m), ctypes.byref(dim_n), work_a.ctypes.data_as(ctypes.c_void_p),
            ctypes.byref(lda), jpvt.ctypes.data_as(ctypes.c_void_p),
            tau.ctypes.data_as(ctypes.c_void_p), work.ctypes.data_as(ctypes.c_void_p),
            ctypes.byref(int_t(lwork)), ctypes.byref(info),
        )  # fmt: skip
        if info.value < 0:
            raise ValueError(f"illegal value in {-info.value}th argument of internal geqp3")

    query = np.empty(1)
    call(query, -1)  # the workspace query, as SciPy's safecall makes it
    lwork = int(query[0])
    call(np.empty(max(1, lwork)), lwork)
    R = np.triu(work_a if m < n else work_a[:n, :])
    return R, jpvt.astype(np.intp) - 1
