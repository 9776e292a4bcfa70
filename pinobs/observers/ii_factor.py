"""The factor ``T(q)`` of the I&I observer: ``M⁻¹ = T Tᵀ`` and the brackets of its columns.

``T`` is a Cholesky factor of ``M⁻¹`` taken in a joint ordering ``p``
(Sarras et al. eq. 16): ``L`` is the lower Cholesky factor of ``M⁻¹`` with
rows and columns permuted by ``p``, and ``T[p_i, p_j] = L[i, j]``
(:class:`CholeskyFactor`), or a caller-given factor (:class:`CustomFactor`).
The structure functions ``c_ij^l`` of the columns, ``[T_i, T_j] = Σ_l c_ij^l T_l``,
give ``D_T(q, P)`` (eqs. 18-19).  The observer and the theory are in
:mod:`pinobs.observers.ii`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import GainError
from pinobs.model import Robot
from pinobs.observers.base import Vector, positive

__all__ = [
    "CholeskyFactor",
    "CustomFactor",
    "Factor",
    "momentum_residual",
    "ordered_cholesky",
    "ordered_cholesky_derivatives",
    "structure_functions",
]


class Factor(ABC):
    """A factor ``T(q)`` with ``M⁻¹ = T Tᵀ`` and its directional derivative.

    Subclasses implement :meth:`frame` and :meth:`derivative` (and may
    override the others to share work).

    Attributes:
        n: dimension.
        label: a short description for reports.
    """

    n: int
    label: str

    @abstractmethod
    def frame(self, q: Vector) -> Vector:
        """``T(q)``, shape ``(n, n)`` [1/√kg, 1/√(kg·m²)]."""

    @abstractmethod
    def derivative(self, q: Vector, x: Vector) -> Vector:
        """``D_x T(q)``, shape ``(n, n)``."""

    def inverse(self, q: Vector) -> Vector:
        """``T(q)⁻¹``."""
        return np.asarray(np.linalg.inv(self.frame(q)))

    def jet(self, q: Vector, xs: Sequence[Vector]) -> tuple[Vector, list[Vector]]:
        """``(T(q), [D_x T(q) for x in xs])``; subclasses share work between the two."""
        return self.frame(q), [self.derivative(q, x) for x in xs]

    def columns_jet(self, q: Vector) -> tuple[Vector, list[Vector]]:
        """``(T, [D_{T_i} T for each column T_i])``: what the brackets ``[T_i, T_j]`` need."""
        t = self.frame(q)
        return t, self.jet(q, [t[:, i] for i in range(t.shape[1])])[1]


def ordered_cholesky(
    m: Vector, p: Sequence[int], ix: tuple[NDArray[np.intp], ...] | None = None
) -> tuple[Vector, Vector, Vector]:
    """``(T, L, W)``: ``W = (M[p][:, p])⁻¹ = L Lᵀ``, ``T[p_i, p_j] = L[i, j]``."""
    if ix is None:
        ix = np.ix_(np.asarray(p, dtype=np.intp), np.asarray(p, dtype=np.intp))
    w = np.linalg.inv(m[ix])
    w = 0.5 * (w + w.T)
    l_ = np.linalg.cholesky(w)
    t = np.empty_like(l_)
    t[ix] = l_
    return t, l_, w


def ordered_cholesky_derivatives(l_: Vector, w: Vector, p: Sequence[int], dms: Vector) -> Vector:
    """``D T`` for a stack of ``D M`` (shape ``(m, n, n)``), batched.

    ``dW = −W dA W`` with ``dA = dM[p][:, p]``; ``dL = L Φ(L⁻¹ dW L⁻ᵀ)``, ``Φ``
    the strict lower triangle plus half the diagonal; ``D T[p_i, p_j] = dL[i, j]``.
    """
    n = l_.shape[0]
    pa = np.asarray(p)
    da = dms[:, pa][:, :, pa]
    dw = -(w @ da @ w)
    li = np.linalg.inv(l_)
    x = li @ dw @ li.T
    phi = np.tril(np.ones((n, n))) - 0.5 * np.eye(n)
    dl = l_ @ (x * phi)
    out = np.empty_like(dl)
    out[:, pa[:, None], pa[None, :]] = dl
    return out


class CholeskyFactor(Factor):
    """The Cholesky factor of ``M⁻¹`` in a joint ordering (:mod:`pinobs.observers.ii`).

    Args:
        robot: a vector-joint robot (or :class:`~pinobs.model.AnalyticMetric`).
        ordering: a permutation of ``range(n)``; ``T`` is lower-triangular in
            this order.  ``(1, 0)`` on the cart-pole ``(x, θ)`` eliminates θ
            first (``T`` upper-triangular in model order).
    """

    def __init__(self, robot: Robot, ordering: Sequence[int]) -> None:
        self.robot = robot
        self.n = robot.nv
        p = tuple(int(i) for i in ordering)
        if sorted(p) != list(range(self.n)):
            raise GainError(f"ordering={ordering!r} is not a permutation of 0..{self.n - 1}")
        self.ordering = p
        self._ix = np.ix_(np.asarray(p, dtype=np.intp), np.asarray(p, dtype=np.intp))
        names = robot.joint_names
        self.label = "Cholesky, lower-triangular in order (" + ", ".join(names[i] for i in p) + ")"

    def parts(self, q: Vector) -> tuple[Vector, Vector, Vector]:
        """``(T, L, W)`` at ``q`` (see :func:`ordered_cholesky`)."""
        return ordered_cholesky(self.robot.mass_matrix(q), self.ordering, self._ix)

    def frame(self, q: Vector) -> Vector:
        return self.parts(q)[0]

    def inverse(self, q: Vector) -> Vector:
        """``T⁻¹ = Tᵀ M`` (from ``Tᵀ M T = I``): no matrix inverse."""
        m = self.robot.mass_matrix(q)
        return np.asarray(ordered_cholesky(m, self.ordering, self._ix)[0].T @ m)

    def derivative(self, q: Vector, x: Vector) -> Vector:
        return self.jet(q, [x])[1][0]

    def jet(self, q: Vector, xs: Sequence[Vector]) -> tuple[Vector, list[Vector]]:
        t, l_, w = self.parts(q)
        if not len(xs):
            return t, []
        dms = np.stack([self.robot.mass_matrix_derivative(q, x) for x in xs])
        return t, list(ordered_cholesky_derivatives(l_, w, self.ordering, dms))

    def columns_jet(self, q: Vector) -> tuple[Vector, list[Vector]]:
        t, l_, w = self.parts(q)
        eye = np.eye(self.n)
        dms = np.stack([self.robot.mass_matrix_derivative(q, eye[k]) for k in range(self.n)])
        along = np.einsum("ki,kab->iab", t, dms)  # D_{T_i} M = Σ_k T_ki ∂_k M
        return t, list(ordered_cholesky_derivatives(l_, w, self.ordering, along))


class CustomFactor(Factor):
    """A caller-given factor ``T(q)`` (e.g. Sarras et al. eq. 23), derivative by central differences.

    Args:
        frame: ``q -> T(q)``.
        n: dimension.
        derivative: ``(q, x) -> D_x T(q)``; central differences (step ``fd_step``) if ``None``.
        label: a description for reports.
        fd_step: difference step [rad or m].
    """

    def __init__(
        self,
        frame: Callable[[Vector], ArrayLike],
        *,
        n: int,
        derivative: Callable[[Vector, Vector], ArrayLike] | None = None,
        label: str = "custom factor",
        fd_step: float = 1e-6,
    ) -> None:
        self._frame = frame
        self._derivative = derivative
        self.n = int(n)
        self.label = label
        self.fd_step = float(positive("fd_step", fd_step) or 0.0)

    def frame(self, q: Vector) -> Vector:
        return np.array(self._frame(np.asarray(q, dtype=float)), dtype=float)

    def derivative(self, q: Vector, x: Vector) -> Vector:
        if self._derivative is not None:
            return np.array(self._derivative(q, x), dtype=float)
        h = self.fd_step
        return (self.frame(q + h * x) - self.frame(q - h * x)) / (2.0 * h)


# ============================================================= brackets
def structure_functions(t: Vector, dts: Sequence[Vector]) -> tuple[Vector, float]:
    """``(c, scale)``: ``c[i, j, l] = c_ij^l`` with ``[T_i, T_j] = Σ_l c_ij^l T_l``.

    Args:
        t: ``T(q)``.
        dts: ``dts[i] = D_{T_i} T(q)`` (derivative of T along its i-th column).

    ``scale`` is ``max |T⁻¹ (D_{T_i} T) e_j|``, the size of the terms whose
    differences form the brackets (used to make residuals relative).
    """
    ti = np.linalg.inv(t)
    terms = np.stack([ti @ d for d in dts])  # terms[i][:, j] = T⁻¹ D_{T_i} T_j
    # c[i, j, l] = (T⁻¹[T_i, T_j])_l = terms[i, l, j] − terms[j, l, i]
    c = terms.transpose(0, 2, 1) - terms.transpose(2, 0, 1)
    return c, float(np.abs(terms).max())


def momentum_residual(c: Vector, p: Vector) -> Vector:
    """``D_T(q, P)_i = −Σ_{j,l} c_ij^l P_j P_l`` (Sarras et al. eqs. 18-19) from the structure functions."""
    return np.asarray(-np.einsum("ijl,j,l->i", c, p, p))
