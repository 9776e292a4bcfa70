"""An analytic kinetic-energy metric on Rⁿ with the geometry interface of :class:`Robot`.

Papers state examples as a formula for ``M(q)``, not as a URDF: Sarras et al.
eq. (21) is a metric on R³ that no chain of rigid bodies produces.
:class:`AnalyticMetric` wraps such a formula so that observers and checks
written against :class:`~pinobs.model.Robot` run on it unchanged.  Every joint
is a vector joint: ``integrate(q, v) = q + v``, ``difference(q0, q1) = q1 - q0``,
the frame is the coordinate frame and every frame bracket vanishes.

Dynamics (Sarras et al. eqs. 11-12)::

    M(q) v̇ + c(q, v) + g(q) = τ,   c(q, v) = M Γ(v, v),
    Γ_{k,ij} = ½ (∂_j M_ki + ∂_i M_kj − ∂_k M_ij)        (Christoffel, first kind)

``D_x M`` comes from the caller (exact) or from central differences of ``M``
(step ``fd_step`` ≈ ε^{1/3}, error ~1e-10 relative for smooth ``M``); curvature and the
spray derivative are central differences of the Christoffel symbols.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.model.robot import JointBlock, Robot
from pinobs.tolerances import ABSURD_VALUE

__all__ = ["AnalyticMetric"]

Vector = NDArray[np.float64]
MatrixFn = Callable[[Vector], ArrayLike]
MatrixDerivativeFn = Callable[[Vector, Vector], ArrayLike]

_FD_CURVATURE = 1e-5  # [rad or m] step of the differences of Γ (analytic D M: error ~1e-10)


class AnalyticMetric:
    """A mechanical system on Rⁿ given by ``M(q)`` (and optionally ``D_x M`` and ``V``).

    Args:
        mass_matrix: ``q -> M(q)``, symmetric positive definite ``(n, n)`` [kg, kg·m, kg·m²].
        n: dimension of the configuration space.
        mass_matrix_derivative: ``(q, x) -> D_x M(q)``; central differences if ``None``.
        gravity: ``q -> ∂V/∂q`` [N·m or N]; zero if ``None``.
        potential: ``q -> V(q)`` [J], for :meth:`potential_energy`; zero if ``None``.
        name: a label for reports.
        fd_step: step of the differences of ``M`` when no derivative is given [rad or m].
    """

    def __init__(
        self,
        mass_matrix: MatrixFn,
        *,
        n: int,
        mass_matrix_derivative: MatrixDerivativeFn | None = None,
        gravity: Callable[[Vector], ArrayLike] | None = None,
        potential: Callable[[Vector], float] | None = None,
        name: str = "analytic",
        fd_step: float = 1e-5,
    ) -> None:
        if int(n) != n or n < 1:
            raise ValueError(f"n={n!r} must be a positive integer")
        self._m = mass_matrix
        self._dm = mass_matrix_derivative
        self._g = gravity
        self._v = potential
        self._n = int(n)
        self.name = name
        self.source = "analytic"
        self.fd_step = float(fd_step)
        self.joints: tuple[JointBlock, ...] = tuple(
            JointBlock(name=f"q{i + 1}", kind="vector", idx_q=i, nq=1, idx_v=i, nv=1)
            for i in range(self._n)
        )

    @classmethod
    def from_inverse(
        cls,
        inverse_mass_matrix: MatrixFn,
        *,
        n: int,
        inverse_mass_matrix_derivative: MatrixDerivativeFn | None = None,
        **kwargs: object,
    ) -> AnalyticMetric:
        """Build from ``M⁻¹(q)`` (and ``D_x M⁻¹``): ``D_x M = −M (D_x M⁻¹) M``."""

        def m(q: Vector) -> Vector:
            return np.asarray(np.linalg.inv(np.asarray(inverse_mass_matrix(q), dtype=float)))

        dm: MatrixDerivativeFn | None = None
        if inverse_mass_matrix_derivative is not None:
            dminv = inverse_mass_matrix_derivative

            def dm(q: Vector, x: Vector) -> Vector:
                mq = m(q)
                return np.asarray(-mq @ np.asarray(dminv(q, x), dtype=float) @ mq)

        return cls(m, n=n, mass_matrix_derivative=dm, **kwargs)  # type: ignore[arg-type]

    def __repr__(self) -> str:
        return f"AnalyticMetric({self.name!r}, n={self._n})"

    # ------------------------------------------------------------------ basics
    @property
    def nq(self) -> int:
        """Number of configuration coordinates (``n``)."""
        return self._n

    @property
    def nv(self) -> int:
        """Number of velocities (``n``)."""
        return self._n

    @property
    def absurd_torque(self) -> Vector:
        """The |τ| beyond which a torque is absurd (no effort limits: :data:`ABSURD_VALUE`;
        see :attr:`Robot.absurd_torque`)."""
        return np.full(self._n, ABSURD_VALUE)

    @property
    def absurd_torque_list(self) -> list[float]:
        """:attr:`absurd_torque` as a list (:attr:`Robot.absurd_torque_list`)."""
        return [ABSURD_VALUE] * self._n

    @property
    def joint_names(self) -> tuple[str, ...]:
        """``("q1", ..., "qn")``."""
        return tuple(b.name for b in self.joints)

    @property
    def is_vector_space(self) -> bool:
        """Always true."""
        return True

    @property
    def has_lie_group_joints(self) -> bool:
        """Always false."""
        return False

    def copy(self) -> AnalyticMetric:
        """A new instance with the same functions (there is no mutable state to share)."""
        return AnalyticMetric(
            self._m,
            n=self._n,
            mass_matrix_derivative=self._dm,
            gravity=self._g,
            potential=self._v,
            name=self.name,
            fd_step=self.fd_step,
        )

    def check_configuration(self, q: ArrayLike, *, what: str = "q") -> Vector:
        """``q`` as a fresh float array of shape ``(n,)``, or raise (see :meth:`Robot.check_vector`)."""
        return np.asarray(Robot.check_vector(q, self._n, what=what), dtype=np.float64)

    @staticmethod
    def check_vector(x: ArrayLike, n: int, *, what: str) -> Vector:
        """See :meth:`Robot.check_vector`."""
        return np.asarray(Robot.check_vector(x, n, what=what), dtype=np.float64)

    # ------------------------------------------------------------ vector space
    def neutral(self) -> Vector:
        """The origin."""
        return np.zeros(self._n)

    def random_configuration(self, rng: np.random.Generator, *, scale: float = 1.0) -> Vector:
        """Uniform in ``[-scale, scale]ⁿ``."""
        return rng.uniform(-scale, scale, self._n)

    def integrate(self, q: Vector, v: Vector) -> Vector:
        """``q + v``."""
        return np.asarray(q, dtype=float) + v

    def difference(self, q0: Vector, q1: Vector) -> Vector:
        """``q1 − q0``."""
        return np.asarray(q1, dtype=float) - q0

    def integrate_jacobian(self, q: Vector, xi: Vector) -> Vector:
        """The identity."""
        return np.eye(self._n)

    def normalize(self, q: Vector) -> Vector:
        """A copy of ``q`` (nothing to normalise)."""
        return np.array(q, dtype=float)

    def bracket(self, x: Vector, y: Vector) -> Vector:
        """Zero: coordinate fields commute."""
        return np.zeros(self._n)

    # ---------------------------------------------------------------- dynamics
    def mass_matrix(self, q: Vector) -> Vector:
        """``M(q)``, symmetrised."""
        m = np.asarray(self._m(np.asarray(q, dtype=float)), dtype=float)
        return 0.5 * (m + m.T)

    def mass_matrix_derivative(self, q: Vector, x: Vector) -> Vector:
        """``D_x M(q)``: the caller's formula, or central differences of ``M``."""
        if self._dm is not None:
            d = np.asarray(self._dm(np.asarray(q, dtype=float), np.asarray(x, dtype=float)))
            return 0.5 * (d + d.T)
        h = self.fd_step
        return (self.mass_matrix(q + h * x) - self.mass_matrix(q - h * x)) / (2.0 * h)

    def _dm_all(self, q: Vector) -> list[Vector]:
        eye = np.eye(self._n)
        return [self.mass_matrix_derivative(q, eye[k]) for k in range(self._n)]

    def gravity(self, q: Vector) -> Vector:
        """``∂V/∂q`` [N·m or N]; zero if no gravity was given."""
        if self._g is None:
            return np.zeros(self._n)
        return np.array(self._g(np.asarray(q, dtype=float)), dtype=float)

    def potential_energy(self, q: Vector) -> float:
        """``V(q)`` [J]; zero if no potential was given."""
        return 0.0 if self._v is None else float(self._v(np.asarray(q, dtype=float)))

    def kinetic_energy(self, q: Vector, v: Vector) -> float:
        """``½ vᵀ M(q) v`` [J]."""
        return 0.5 * float(v @ self.mass_matrix(q) @ v)

    def coriolis(self, q: Vector, v: Vector) -> Vector:
        """``c(q, v) = (D_v M) v − ½ ∂_q(vᵀ M v)``."""
        dms = self._dm_all(q)
        grad = np.array([v @ d @ v for d in dms])
        dmv = sum((v[k] * dms[k] for k in range(self._n)), np.zeros((self._n, self._n)))
        return np.asarray(dmv @ v - 0.5 * grad)

    def coriolis_matrix(self, q: Vector, v: Vector) -> Vector:
        """``C(q, v)_kj = Σ_i Γ_{k,ij} vᵢ`` (Christoffel form: ``Ṁ − 2C`` skew, ``C v = c``)."""
        dms = self._dm_all(q)
        dmv = sum((v[k] * dms[k] for k in range(self._n)), np.zeros((self._n, self._n)))
        # Γ_{k,ij} v_i = ½ (∂_j M_ki v_i + (D_v M)_kj − ∂_k M_ij v_i)
        a = np.column_stack([dms[j] @ v for j in range(self._n)])  # a[k, j] = ∂_j M_ki v_i
        b = np.vstack([dms[k] @ v for k in range(self._n)])  # b[k, j] = ∂_k M_ij v_i
        return np.asarray(0.5 * (a + dmv - b))

    def nonlinear_effects(self, q: Vector, v: Vector) -> Vector:
        """``c(q, v) + g(q)``."""
        return self.coriolis(q, v) + self.gravity(q)

    def forward_dynamics(self, q: Vector, v: Vector, tau: Vector) -> Vector:
        """``v̇ = M⁻¹(τ − c − g)``."""
        return np.asarray(np.linalg.solve(self.mass_matrix(q), tau - self.nonlinear_effects(q, v)))

    def forward_dynamics_derivatives(
        self, q: Vector, v: Vector, tau: Vector
    ) -> tuple[Vector, Vector, Vector]:
        """``(∂v̇/∂q, ∂v̇/∂v, M⁻¹)`` by central differences (step ``fd_step``)."""
        n, h = self._n, self.fd_step
        eye = np.eye(n)
        dq = np.column_stack(
            [
                (
                    self.forward_dynamics(q + h * eye[j], v, tau)
                    - self.forward_dynamics(q - h * eye[j], v, tau)
                )
                / (2 * h)
                for j in range(n)
            ]
        )
        dv = np.column_stack(
            [
                (
                    self.forward_dynamics(q, v + h * eye[j], tau)
                    - self.forward_dynamics(q, v - h * eye[j], tau)
                )
                / (2 * h)
                for j in range(n)
            ]
        )
        return dq, dv, np.asarray(np.linalg.inv(self.mass_matrix(q)), dtype=np.float64)

    def forward_dynamics_jacobians(
        self, q: Vector, v: Vector, tau: Vector
    ) -> tuple[Vector, Vector, Vector]:
        """``(v̇, ∂v̇/∂q, ∂v̇/∂v)``, the interface of :meth:`Robot.forward_dynamics_jacobians`."""
        dq, dv, _ = self.forward_dynamics_derivatives(q, v, tau)
        return self.forward_dynamics(q, v, tau), dq, dv

    def spray_jacobians(self, q: Vector, x: Vector) -> tuple[Vector, Vector, Vector]:
        """``(Γs(x, x), ∂_q Γs(x, x), ∂_x Γs(x, x) = 2 Γs(x, ·))``, as :meth:`Robot.spray_jacobians`."""
        dx = 2.0 * np.column_stack([self.christoffel(q, x, e) for e in np.eye(self._n)])
        return self.geodesic_spray(q, x), self.spray_derivative(q, x), dx

    def friction_derivative(self, v: Vector) -> Vector:
        """Zero: an analytic metric carries no joint friction."""
        return np.zeros(self.nv)

    def inverse_dynamics(self, q: Vector, v: Vector, a: Vector) -> Vector:
        """``τ = M a + c + g``."""
        return np.asarray(self.mass_matrix(q) @ a + self.nonlinear_effects(q, v))

    #: An analytic metric has no joint friction (the interface of :class:`Robot`).
    has_friction = False

    def friction_torque(self, v: Vector) -> Vector:
        """Zero: an analytic metric carries no joint friction."""
        return np.zeros(self.nv)

    def force_per_metric(self, q: Vector, tau: Vector) -> Vector:
        """``S = M⁻¹(τ − g)``."""
        return np.asarray(np.linalg.solve(self.mass_matrix(q), tau - self.gravity(q)))

    # ---------------------------------------------------------------- geometry
    def metric(self, q: Vector, x: Vector, y: Vector) -> float:
        """``xᵀ M(q) y``."""
        return float(x @ self.mass_matrix(q) @ y)

    def christoffel(self, q: Vector, x: Vector, y: Vector) -> Vector:
        """``Γ(q)(x, y) = M⁻¹ Γ_{k,ij} xⁱ yʲ`` (Sarras et al. eq. 12 raised with ``M⁻¹``)."""
        dmx = self.mass_matrix_derivative(q, x)
        dmy = self.mass_matrix_derivative(q, y)
        grad = np.array([x @ d @ y for d in self._dm_all(q)])
        lowered = 0.5 * (dmy @ x + dmx @ y - grad)
        return np.asarray(np.linalg.solve(self.mass_matrix(q), lowered))

    def geodesic_spray(self, q: Vector, x: Vector) -> Vector:
        """``Γ(q)(x, x)``."""
        return self.christoffel(q, x, x)

    def connection(self, q: Vector, x: Vector, y: Vector) -> Vector:
        """``ω(x, y) = Γ(q)(x, y)`` (no bracket on Rⁿ)."""
        return self.christoffel(q, x, y)

    def spray_derivative(self, q: Vector, x: Vector) -> Vector:
        """``∂/∂q Γ(q)(x, x)`` by central differences, column j along ``e_j``."""
        eye = np.eye(self._n)
        return np.column_stack(
            [self.christoffel_derivative(q, x, x, eye[j]) for j in range(self._n)]
        )

    def christoffel_derivative(self, q: Vector, x: Vector, y: Vector, z: Vector) -> Vector:
        """``D_z Γ(q)(x, y)`` by central differences (step 1e-5)."""
        h = _FD_CURVATURE
        return (self.christoffel(q + h * z, x, y) - self.christoffel(q - h * z, x, y)) / (2.0 * h)

    def curvature(self, q: Vector, x: Vector, y: Vector, z: Vector) -> Vector:
        """``R(x, y) z = D_x Γ(y, z) − D_y Γ(x, z) + Γ(x, Γ(y, z)) − Γ(y, Γ(x, z))`` (MATH §3)."""
        return (
            self.christoffel_derivative(q, y, z, x)
            - self.christoffel_derivative(q, x, z, y)
            + self.christoffel(q, x, self.christoffel(q, y, z))
            - self.christoffel(q, y, self.christoffel(q, x, z))
        )

    def sectional_curvature(self, q: Vector, x: Vector, y: Vector) -> float:
        """``⟨R(x,y)y, x⟩ / (|x|²|y|² − ⟨x,y⟩²)``."""
        m = self.mass_matrix(q)
        area2 = (x @ m @ x) * (y @ m @ y) - (x @ m @ y) ** 2
        if not math.isfinite(area2) or area2 <= 0.0:
            raise ValueError("x and y must be linearly independent")
        return float(self.curvature(q, x, y, y) @ m @ x / area2)
