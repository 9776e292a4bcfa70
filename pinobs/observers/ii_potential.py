"""β and its Jacobian 𝒫 for the I&I observer: the potential ``Q`` and the homotopy.

``"potential"`` construction: ``Q(q) = ∫ T⁻¹ dq`` (Sarras et al. Fact 1,
eq. 20), path independent when the columns of ``T`` commute, by
Gauss-Legendre quadrature along straight segments (:func:`segment_integral`,
:func:`potential`).  ``"homotopy"`` construction: the Poincaré homotopy of the
rows of ``T⁻¹`` from a reference, with the exact Jacobian of the discretised
rule (:class:`Homotopy`).  The formulas are in :mod:`pinobs.observers.ii`.
"""

from __future__ import annotations

import math

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.ii_factor import Factor

__all__ = ["Homotopy", "potential", "segment_integral"]

# Gauss-Legendre rules for Q on one sample segment: 3 nodes (exact to degree 5) up to
# _SHORT_SEGMENT, 6 nodes (degree 11) above; potential() cuts long lines into pieces.
_GL_SHORT = np.polynomial.legendre.leggauss(3)
_GL_SEGMENT = np.polynomial.legendre.leggauss(6)
_SHORT_SEGMENT = 0.02  # [rad or m]: 3-node error ~ (0.02)^7 |∂⁶ T⁻¹| / 2e6, below 1e-17


def segment_integral(factor: Factor, a: Vector, b: Vector) -> Vector:
    """``∫ T⁻¹ dq`` along the straight segment ``a → b`` (3- or 6-point Gauss-Legendre)."""
    d = b - a
    if not np.any(d):
        return np.zeros_like(d)
    xs, ws = _GL_SHORT if float(np.abs(d).max()) <= _SHORT_SEGMENT else _GL_SEGMENT
    acc = np.zeros_like(d)
    for x, w in zip(xs, ws, strict=True):
        acc += 0.5 * w * (factor.inverse(a + 0.5 * (x + 1.0) * d) @ d)
    return acc


def potential(factor: Factor, q: Vector, q_ref: Vector, *, max_segment: float = 0.25) -> Vector:
    """``Q(q) = ∫_{q_ref}^{q} T⁻¹ dq`` along the straight line, composite Gauss-Legendre.

    Path independent iff the rows of ``T⁻¹`` are closed forms, i.e. iff the
    columns of ``T`` commute (Sarras et al. Fact 1, eq. 20).  The line is cut
    into pieces no longer than ``max_segment`` [rad or m], 6 nodes each.
    """
    d = np.asarray(q, dtype=float) - q_ref
    pieces = max(1, math.ceil(float(np.linalg.norm(d)) / max_segment))
    acc = np.zeros_like(d)
    for i in range(pieces):
        acc += segment_integral(factor, q_ref + (i / pieces) * d, q_ref + ((i + 1) / pieces) * d)
    return acc


class Homotopy:
    """β and 𝒫 of the homotopy construction (:mod:`pinobs.observers.ii`), exact Jacobian of the rule."""

    def __init__(self, factor: Factor, gain: float, nodes: int) -> None:
        self.factor = factor
        self.gain = gain
        self.s, self.w = np.polynomial.legendre.leggauss(nodes)
        self.s = 0.5 * (self.s + 1.0)
        self.w = 0.5 * self.w

    def beta_and_jacobian(self, q: Vector, q_ref: Vector) -> tuple[Vector, Vector]:
        n = q.shape[0]
        d = q - q_ref
        eye = np.eye(n)
        beta = np.zeros(n)
        jac = np.zeros((n, n))
        moved = bool(np.any(d))
        for s, w in zip(self.s, self.w, strict=True):
            g = q_ref + s * d
            t, dts = self.factor.jet(g, list(eye) if moved else [])
            ti = np.linalg.inv(t)
            beta += w * (ti @ d)
            jac += w * ti
            for j, dt_j in enumerate(dts):  # ∂_j T⁻¹ = −T⁻¹ (∂_j T) T⁻¹
                jac[:, j] -= w * s * (ti @ dt_j @ ti @ d)
        return self.gain * beta, self.gain * jac
