"""The EKF's covariance algebra on the blocks of its Jacobian, for large robots (issue 39).

:mod:`pinobs.observers.ekf` builds ``Φ = I + Ah(I + Ah/2 (I + Ah/3))`` from

    A = [[−ad_v̂, I, 0], [∂a/∂q, ∂a/∂v, M⁻¹], [0, 0, 0]]      (n = 2nv, or 3nv with the offset)

and corrects with ``H = [I 0]`` (Joseph form).  Above
:data:`~pinobs.observers.linalg.KERNEL_MAX_NV` these are BLAS products (one thread: the
filter's update limits it), where the dense ``n × n`` products spend half their
multiply-adds on ``A``'s constant rows.  Here:

* ``A X`` (:func:`times_a`) is the identity block's rows copied, the dynamics rows
  ``[∂a/∂q ∂a/∂v M⁻¹] X`` one ``nv × n × n`` product, and ``−ad_v̂ X_q`` only on the rows
  where ``ad`` can be nonzero (the spherical, free-flyer and planar joints': six of 38 rows
  on a talos); the offset's rows are zero.  :func:`transition` builds ``Φ`` with two of
  them instead of two ``n × n × n`` products;
* the Joseph update's ``S⁻¹ (H P)`` (:func:`joseph_update`) by a Cholesky factor (LAPACK
  ``dpotrf``) and two triangular solves (BLAS ``dtrsm``) on ``P``'s column block, which lies
  in memory as the solves want it (``dposv`` on the same system: 34 against 25 µs for a
  talos, one thread), then the same products as
  :func:`pinobs.observers.linalg.joseph_update`.

:mod:`pinobs.observers.ekf`'s ``predict`` and ``correct`` take them from :data:`MIN_NV` on
(its ``step`` without the offset state takes :mod:`pinobs.observers.blockstep`'s).  The same equations as the
dense products, equal to them to rounding (tested in ``tests/observers/test_fused_lie.py``).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from pinobs.model import Robot
from pinobs.observers.base import Vector
from pinobs.observers.linalg import cholesky_solve, identity, joseph_from_gain, scaled_identity

__all__ = ["MIN_NV", "bracket_rows", "joseph_update", "times_a", "transition"]

#: Smallest ``nv`` where :mod:`pinobs.observers.ekf` takes these (one BLAS thread, µs block
#: against dense, alone: :func:`transition` nv = 18: 14.0 vs 9.7, 24: 17.3 vs 15.1,
#: 30: 22.5 vs 24.5, 38: 34 vs 44; :func:`joseph_update` 20.9 vs 21.8 at 18, 66 vs 79 at 38,
#: but in the filter's loop not faster on a go1, nv = 18).
MIN_NV = 28


def bracket_rows(robot: Robot) -> tuple[slice, ...]:
    """The runs of rows of ``ad_x`` (:meth:`~pinobs.model.Robot.bracket_matrix`) that can be
    nonzero, as slices: the spherical, free-flyer and planar joints' blocks (``ad`` is
    block-diagonal), read off ``ad`` at a generic ``x``."""
    ad = robot.bracket_matrix(np.arange(1.0, robot.nv + 1.0))
    rows = np.flatnonzero(np.abs(ad).sum(axis=1)).tolist()
    runs: list[list[int]] = []
    for i in rows:
        if runs and runs[-1][1] == i:
            runs[-1][1] = i + 1
        else:
            runs.append([i, i + 1])
    return tuple(slice(a, b) for a, b in runs)


def times_a(A: Vector, X: Vector, nv: int, rows: tuple[slice, ...], out: Vector) -> Vector:
    """``out = A X`` for the EKF's ``A`` (module docstring): the identity block's rows
    copied, the dynamics rows one product, ``−ad`` on ``rows`` only (``ad`` is
    block-diagonal: the run ``s`` of rows meets only the columns ``s``); returns ``out``."""
    out[:nv] = X[nv : 2 * nv]
    for s in rows:
        out[s] += A[s, s].dot(X[s])
    np.dot(A[nv : 2 * nv], X, out=out[nv : 2 * nv])
    out[2 * nv :] = 0.0
    return out


def transition(A: Vector, h: float, nv: int, rows: tuple[slice, ...]) -> Vector:
    """``Φ = I + Ah(I + Ah/2 (I + Ah/3))`` (:func:`pinobs.observers.linalg.transition_matrix`)
    by two :func:`times_a`, a new array."""
    n = A.shape[0]
    eye = identity(n)
    inner = A * (h / 3.0)
    inner += eye
    mid = times_a(A, inner, nv, rows, np.empty((n, n)))
    mid *= 0.5 * h
    mid += eye
    out = times_a(A, mid, nv, rows, inner)  # (inner is not needed any more)
    out *= h
    out += eye
    return out


@functools.cache
def _lapack() -> tuple[Any, Any]:
    """LAPACK ``dpotrf`` and BLAS ``dtrsm`` (scipy, imported on first use)."""
    from scipy.linalg.blas import dtrsm  # lazy: start-up time
    from scipy.linalg.lapack import dpotrf

    return dpotrf, dtrsm


def joseph_update(P: Vector, e: Vector, meas_var: float) -> tuple[Vector, Vector]:
    """:func:`pinobs.observers.linalg.joseph_update` (``H = [I 0]``, ``R = meas_var · I``):
    ``(K e, P⁺)``, with ``K = P_·q S⁻¹`` from the Cholesky factor ``S = L Lᵀ`` by two
    triangular solves on ``P_·q`` (module docstring); where ``S`` is not positive
    definite, :func:`~pinobs.observers.linalg.cholesky_solve`'s general solve."""
    nv = e.shape[0]
    dpotrf, dtrsm = _lapack()
    B = P[:nv]  # H P
    S = B[:, :nv] + scaled_identity(nv, meas_var)
    L, info = dpotrf(S, lower=1, clean=0)
    if info == 0:  # K = P_·q L⁻ᵀ L⁻¹: X Lᵀ = P_·q, then K L = X (P symmetric: P_·q = Bᵀ)
        K = dtrsm(1.0, L, dtrsm(1.0, L, B.T, side=1, lower=1, trans_a=1), side=1, lower=1)
        Kt = K.T
    else:
        Kt, _ = cholesky_solve(S, B)
        K = Kt.T
    return joseph_from_gain(P, B, K, Kt, e, meas_var)
