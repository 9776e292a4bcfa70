"""Immersion & Invariance reduced-order momentum observer (Sarras, Venkatraman, Ortega, van der Schaft).

Revolute, prismatic and continuous joints: I&I lives in coordinates.  A
continuous joint (``q = (cos θ, sin θ)``) is run in its angle chart
(:class:`pinobs.model.chart.AngleChart`: the same robot with a revolute joint,
identical ``M``, ``c``, ``g`` at ``θ``), ``θ`` unwrapped along the measured
path: each measurement's ``atan2(sin, cos)`` is taken on the ``2π``-branch
nearest the step's prediction, so the chart never jumps while the joint
turns less than ``π`` per sample.  Lie-group joints belong to the
``liegroup`` / ``riemannian`` observers.  (MATH §5)

Coordinates.  ``M⁻¹(q) = T(q) T(q)ᵀ`` (Sarras et al. eq. 16) with ``T`` a
Cholesky factor taken in a joint ordering ``p``: ``L`` is the lower Cholesky
factor of ``M⁻¹`` with rows and columns permuted by ``p``, and
``T[p_i, p_j] = L[i, j]``.  The momenta ``P = Tᵀ p = T⁻¹ v`` satisfy
``|P|² = 2 × kinetic energy`` and (eq. 9, with an input torque)::

    q̇ = T P,    Ṗ = Tᵀ(τ − ∂V/∂q) + D_T(q, P),
    D_T(q, P) = {P, P}_J P,   {P_i, P_j} = −pᵀ [T_i, T_j]          (eqs. 18-19)

with ``[T_i, T_j] = (∂T_j/∂q) T_i − (∂T_i/∂q) T_j`` the Lie bracket of the
columns of ``T``.  Writing ``[T_i, T_j] = Σ_l c_ij^l T_l`` gives
``D_T,i = −Σ_{j,l} c_ij^l P_j P_l``: Assumption 1 (``D_T ≡ 0``) holds iff the
symmetric part of every ``(c_ij^l)_{j,l}`` vanishes, which
:func:`check_assumption1` measures over sampled configurations and orderings.

Observer (Proposition 5 with an input torque; the paper's eq. 30 is the case
``τ = 0``, ``M̄ = I``)::

    η̇ = 𝒫(q) T(q) (β(q) − η) − T(q)ᵀ(τ − ∂V/∂q),    P̂ = β(q) − η,    v̂ = T(q) P̂,
    𝒫 = ∂β/∂q                                                        (eq. 31)

so ``z = P̂ − P`` obeys ``ż = −𝒫 T z − D_T`` (proof of Prop. 5, eq. 33) and,
under Assumption 2 (``𝒫T + (𝒫T)ᵀ ≥ εI``, eq. 27),
``|P̂(t) − P(t)|² ≤ e^{−εt} |P̂(0) − P(0)|²``.

Constructive β (two cases, chosen automatically):

* ``"potential"`` — the columns of T commute (always the case when ``n ≤ 2``
  and Assumption 1 holds).  Then ``T⁻¹`` is a Jacobian (Fact 1, eq. 20):
  ``∂Q/∂q = T⁻¹``, and ``β = k Q`` gives ``𝒫T = kI``, ``ε = 2k``: the error
  ``|z|`` decays at exactly the rate ``k``.  ``Q`` is the path integral of
  ``T⁻¹ dq``, computed by Gauss-Legendre quadrature along straight segments
  (path independence is what Fact 1 guarantees and what the tests check).
  The observer carries ``β`` along the measured path, one short segment per
  sample, so the quadrature never spans a long excursion.
* ``"homotopy"`` — otherwise (the columns do not commute, or Assumption 1
  fails and the caller opted in with ``unguaranteed=True``).  β is the
  Poincaré homotopy of the rows of ``T⁻¹`` from a reference ``q_r`` (the
  configuration at reset), discretised by an N-point Gauss-Legendre rule::

      β(q) = k Σ_m w_m T⁻¹(q_r + s_m Δ) Δ,    Δ = q − q_r,
      𝒫(q) = k Σ_m w_m [T⁻¹(γ_m) + s_m Σ_j (∂_j T⁻¹)(γ_m) Δ e_jᵀ]

  ``𝒫`` is the exact Jacobian of this β (the rule is differentiated, not the
  integral), so the manifold ``η = β − P`` stays invariant exactly; ``𝒫T``
  equals ``kI`` when the columns commute and differs from it by
  ``O(k |Δ| |[T_i, T_j]|)`` otherwise, so Assumption 2 holds near ``q_r``
  only.  ε is checked on sampled configurations in ``q_r + [−region, region]ⁿ``
  at every reset and reported in :attr:`IIObserver.options`.

Sampled data (MATH §7).  η's ODE needs ``q(t)`` between samples, which is not
measured.  Each step (1) predicts the plant over the interval with the model
from the current estimate ``(q_k, v̂_k)`` and the held torque (RK4, ``substeps``
steps), (2) builds the path ``q̃(s) = H(s) + (s/h)(q_{k+1} − H(h))`` where ``H``
is the cubic Hermite interpolant of the prediction, so the path starts and ends
on the measurements, and (3) integrates η along it with RK4.  Started on the
truth, the prediction *is* the truth (up to RK4 error) and the correction
vanishes: the estimate stays on the truth.  From an error ``z``, the path
differs from the true one by ``O(h² k |T z|)`` inside the interval, a
perturbation of the decay rate of relative order ``(kh)²`` at most.  Without a
sample, the predicted path is used and ``q̂`` is the prediction.  Measured on
the cart-pole and two variants (PD tracking, 1 kHz, k = 10 /s, kh = 0.01):
started on the truth, ``|v̂ − v| ≤ 1.0e-10`` rad/s over 1 s; from a perturbed
velocity, the fitted decay rate of ``|z|`` is k to within 7e-8 relative and
``|z_k|`` exceeds the bound ``e^{−kt}|z₀|`` by at most 5e-10 (the invariance
floor).  ``tests/observers/test_ii.py``, ``examples/ii_cartpole.py``.

Consistency and outliers.  The observer has no covariance; the innovation
``e = q_meas − q̂⁻`` (the sample against the step's prediction ``q̂⁻``, which
starts from the previous sample) gets a variance from the observer's own
error dynamics.  Per joint, flat case, white noise ``n`` of variance σ²
(σ = ``noise_std``, 1e-6 if not given): ``e = n_{k+1} − n_k − h(v̂ − v) + O(h²)``,
and ``P̂ = β(q_meas) − η`` carries the noise into the velocity as
``v̂ − v ≈ k(n_k − n̄_k) + T z`` (``n̄`` the noise low-passed at ``k``, ``z`` the
momentum error of eq. 33), so to first order in ``kh``::

    S = σ² (2 + 2kh) + h² v0_std² e^{−ε t}

the last term the start-up error, ``|v̂(0) − v(0)|`` of standard deviation
``v0_std`` per joint decaying as the I&I bound guarantees (``ε`` of
Assumption 2, ``2k`` for the potential construction; ``2k`` assumed where
nothing is guaranteed).  ``NIS = |e|²/S`` is then χ²(nv) to that order, with
an exact model (a model error adds ``h Δa/k`` to ``e``: the velocity bias it
causes).  Successive innovations share ``n_k`` (correlation ≈ −½), which
does not change the mean NIS but widens its spread over a window by about
√1.5.  A sample the gate rejects (:func:`pinobs.observers.base.outlier_gate`)
is not used: the path and ``q̂`` are the prediction, as without a sample.

Unguaranteed mode (``unguaranteed=True``, Assumption 1 fails).  The observer
then adds the certainty-equivalent term ``−D_T(q, P̂)`` to η̇, so that
``ż = −𝒫Tz − (D_T(q, P) − D_T(q, P̂))``: the manifold stays invariant (started
on the truth it stays there) and the error contracts locally when ``k``
dominates ``|c| |P|``, but no global bound holds.  Where Assumption 1 holds
the term is identically zero and is not computed.
"""

from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import GainError, UnsupportedRobotError
from pinobs.model import Robot, dynamics_rk4
from pinobs.model.chart import AngleChart
from pinobs.observers.base import (
    NOISE_FLOOR,
    GateState,
    Observer,
    Vector,
    gate_threshold,
    positive,
    register,
)
from pinobs.tolerances import II_ASSUMPTION1_TOL

__all__ = [
    "Assumption1Report",
    "Assumption2Report",
    "CholeskyFactor",
    "CustomFactor",
    "Factor",
    "IIGains",
    "IIObserver",
    "OrderingResult",
    "check_assumption1",
    "check_assumption2",
    "momentum_residual",
    "potential",
    "structure_functions",
]

_FULL_SEARCH_MAX_N = 5  # all n! orderings up to n = 5 (120); a heuristic subset above
# Gauss-Legendre rules for Q on one sample segment: 3 nodes (exact to degree 5) up to
# _SHORT_SEGMENT, 6 nodes (degree 11) above; potential() cuts long lines into pieces.
_GL_SHORT = np.polynomial.legendre.leggauss(3)
_GL_SEGMENT = np.polynomial.legendre.leggauss(6)
_SHORT_SEGMENT = 0.02  # [rad or m]: 3-node error ~ (0.02)^7 |∂⁶ T⁻¹| / 2e6, below 1e-17
_STEP_KH = 0.25  # sub-steps so that k·h_sub <= 0.25 (RK4 factor within (kh)⁵/120 = 8e-6 of e^{−kh})


# =================================================================== factors
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


def _ordered_cholesky(
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


def _ordered_cholesky_derivatives(l_: Vector, w: Vector, p: Sequence[int], dms: Vector) -> Vector:
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
    """The Cholesky factor of ``M⁻¹`` in a joint ordering (module docstring).

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
        """``(T, L, W)`` at ``q`` (see :func:`_ordered_cholesky`)."""
        return _ordered_cholesky(self.robot.mass_matrix(q), self.ordering, self._ix)

    def frame(self, q: Vector) -> Vector:
        return self.parts(q)[0]

    def inverse(self, q: Vector) -> Vector:
        """``T⁻¹ = Tᵀ M`` (from ``Tᵀ M T = I``): no matrix inverse."""
        m = self.robot.mass_matrix(q)
        return np.asarray(_ordered_cholesky(m, self.ordering, self._ix)[0].T @ m)

    def derivative(self, q: Vector, x: Vector) -> Vector:
        return self.jet(q, [x])[1][0]

    def jet(self, q: Vector, xs: Sequence[Vector]) -> tuple[Vector, list[Vector]]:
        t, l_, w = self.parts(q)
        if not len(xs):
            return t, []
        dms = np.stack([self.robot.mass_matrix_derivative(q, x) for x in xs])
        return t, list(_ordered_cholesky_derivatives(l_, w, self.ordering, dms))

    def columns_jet(self, q: Vector) -> tuple[Vector, list[Vector]]:
        t, l_, w = self.parts(q)
        eye = np.eye(self.n)
        dms = np.stack([self.robot.mass_matrix_derivative(q, eye[k]) for k in range(self.n)])
        along = np.einsum("ki,kab->iab", t, dms)  # D_{T_i} M = Σ_k T_ki ∂_k M
        return t, list(_ordered_cholesky_derivatives(l_, w, self.ordering, along))


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


# ========================================================= Assumption 1 check
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


def _residuals(c: Vector, scale: float) -> tuple[float, float, float]:
    """``(relative D_T residual, max |D_T,i| over |P| = 1, relative commutator)``."""
    n = c.shape[0]
    worst = 0.0
    for i in range(n):
        s = 0.5 * (c[i] + c[i].T)  # D_T,i = −Pᵀ s P
        worst = max(worst, float(np.linalg.norm(s, 2)))
    comm = float(np.abs(c).max())
    if scale == 0.0:
        return 0.0, worst, 0.0
    return worst / scale, worst, comm / scale


@dataclass(frozen=True)
class OrderingResult:
    """Assumption 1 for one factor, over the sampled configurations.

    Attributes:
        label: the factor (ordering) checked.
        ordering: the joint ordering (indices), or ``None`` for a custom factor.
        residual: ``max_q max_i ‖sym(c_i)‖₂ / scale(q)``: relative size of
            ``D_T`` (0 when Assumption 1 holds, ~1 when it fails badly).
        abs_residual: ``max_q max_{i, |P|=1} |D_T,i(q, P)|`` [√J/s per J]:
            ``|D_T|`` for ``|P|² = 2·KE = 1 J``.
        worst_q: the sampled configuration where ``residual`` is largest.
        commutator: relative size of the brackets ``[T_i, T_j]`` (0: the
            columns commute, the metric is flat, β = kQ applies).
        holds: ``residual <= tol``.
    """

    label: str
    ordering: tuple[int, ...] | None
    residual: float
    abs_residual: float
    worst_q: tuple[float, ...]
    commutator: float
    holds: bool


@dataclass(frozen=True)
class Assumption1Report:
    """The result of :func:`check_assumption1`.

    Attributes:
        robot: robot name.
        n: dimension.
        samples: number of sampled configurations.
        seed: seed of the sampler.
        search: how the orderings were chosen.
        tol: the threshold on the relative residual.
        results: one entry per factor checked, best (smallest residual) first.
    """

    robot: str
    n: int
    samples: int
    seed: int
    search: str
    tol: float
    results: tuple[OrderingResult, ...] = field(default_factory=tuple)

    @property
    def best(self) -> OrderingResult:
        """The factor with the smallest residual (commuting columns preferred on ties)."""
        return self.results[0]

    @property
    def holds(self) -> bool:
        """True when some factor satisfies Assumption 1 on every sample."""
        return self.best.holds

    def format(self) -> str:
        """A readable multi-line report."""
        b = self.best
        head = [
            f"Assumption 1 (D_T(q, P) = {{P, P}}_J P ≡ 0, Sarras et al. eq. 18) on {self.robot!r}, n = {self.n}",
            f"  {self.samples} sampled configurations (seed {self.seed}); {self.search}; "
            f"tolerance {self.tol:.1e} on the relative residual",
            f"  verdict: {'HOLDS' if self.holds else 'FAILS'} — best factor: {b.label}",
            f"           relative residual {b.residual:.3e}, max |D_T| {b.abs_residual:.3e} "
            f"(for |P|² = 1 J), columns {'commute' if b.commutator <= self.tol else 'do not commute'} "
            f"(relative bracket {b.commutator:.3e})",
            "           worst at q = [" + ", ".join(f"{x:.4g}" for x in b.worst_q) + "]",
        ]
        rows = ["  ordering (joint indices)     rel. residual    max|D_T|    bracket"]
        for r in self.results[:10]:
            name = "custom" if r.ordering is None else str(r.ordering).replace(" ", "")
            rows.append(
                f"  {name[:28]:<28} {r.residual:>13.3e} {r.abs_residual:>11.3e} "
                f"{r.commutator:>10.3e}{'  holds' if r.holds else ''}"
            )
        if len(self.results) > 10:
            rows.append(f"  ... {len(self.results) - 10} more")
        return "\n".join(head + rows)


def _require_vector_joints(robot: Robot) -> None:
    kinds = sorted({b.kind for b in robot.joints if b.kind not in ("vector", "circle")})
    if kinds:
        raise UnsupportedRobotError(
            f"the I&I observer ('ii') needs revolute, prismatic or continuous joints; "
            f"{robot.name!r} has {', '.join(kinds)} joints. Use the 'liegroup' or "
            "'riemannian' observer for Lie-group joints."
        )


def _in_chart(robot: Robot) -> Robot:
    """``robot`` itself, or its angle chart when it has continuous joints (module docstring)."""
    if isinstance(robot, Robot) and any(b.kind == "circle" for b in robot.joints):
        return AngleChart(robot).chart
    return robot  # vector joints, or an AnalyticMetric


def _candidate_orderings(n: int) -> tuple[list[tuple[int, ...]], str]:
    if n <= _FULL_SEARCH_MAX_N:
        return list(itertools.permutations(range(n))), f"all {math.factorial(n)} orderings"
    ident = tuple(range(n))
    cands = [ident, ident[::-1]]
    for i in range(n):  # move one joint to the front or to the back, in both base orders
        for base in (ident, ident[::-1]):
            rest = [j for j in base if j != i]
            cands += [(i, *rest), (*rest, i)]
    uniq = list(dict.fromkeys(cands))
    return uniq, (
        f"heuristic subset of {len(uniq)} orderings (n = {n} > {_FULL_SEARCH_MAX_N}: "
        "model order, reversed, and each joint moved to the front or back of either)"
    )


def _check_factor_on(t: Vector, dts: Sequence[Vector]) -> tuple[float, float, float]:
    c, scale = structure_functions(t, dts)
    return _residuals(c, scale)


def check_assumption1(
    robot: Robot,
    *,
    samples: int = 12,
    seed: int = 0,
    scale: float = math.pi,
    orderings: Sequence[Sequence[int]] | None = None,
    factor: Factor | None = None,
    tol: float = II_ASSUMPTION1_TOL,
) -> Assumption1Report:
    """Check Assumption 1 of Sarras et al. on sampled configurations, over factor orderings.

    For every sampled ``q`` (``robot.random_configuration(rng, scale=scale)``)
    and every candidate factor, the structure functions ``c_ij^l`` of the
    columns of ``T`` are computed from the analytic derivative of the Cholesky
    factor (``D_x M`` from :meth:`Robot.mass_matrix_derivative`) and the
    residual of ``D_T,i = −Σ c_ij^l P_j P_l`` is measured (see
    :class:`OrderingResult`).

    Args:
        robot: a vector-joint robot or :class:`~pinobs.model.AnalyticMetric`.
        samples: number of configurations.
        seed: seed of the sampler.
        scale: configurations are ``neutral ⊕ U(−scale, scale)ⁿ`` [rad or m].
        orderings: Cholesky orderings to try (default: all ``n!`` for
            ``n <= 5``, a documented heuristic subset above).
        factor: check this factor instead of Cholesky orderings.
        tol: threshold on the relative residual.

    Raises:
        UnsupportedRobotError: the robot has Lie-group joints.
    """
    _require_vector_joints(robot)
    robot = _in_chart(robot)
    samples = int(positive("samples", samples) or 1)
    n = robot.nv
    rng = np.random.default_rng(seed)
    qs = [robot.random_configuration(rng, scale=scale) for _ in range(samples)]
    eye = np.eye(n)
    results: list[OrderingResult] = []
    if factor is not None:
        worst = (0.0, 0.0, 0.0)
        where = qs[0]
        for q in qs:
            r = _check_factor_on(*factor.columns_jet(q))
            if r[0] >= worst[0]:
                where = q
            worst = (max(worst[0], r[0]), max(worst[1], r[1]), max(worst[2], r[2]))
        results.append(
            OrderingResult(
                factor.label,
                None,
                worst[0],
                worst[1],
                tuple(where.tolist()),
                worst[2],
                worst[0] <= tol,
            )
        )
        search = "the given factor"
    else:
        if orderings is None:
            cands, search = _candidate_orderings(n)
        else:
            cands, search = [tuple(int(i) for i in o) for o in orderings], "the given orderings"
        per_q = [
            (robot.mass_matrix(q), np.stack([robot.mass_matrix_derivative(q, e) for e in eye]))
            for q in qs
        ]
        names = robot.joint_names
        for p in cands:
            if sorted(p) != list(range(n)):
                raise GainError(f"ordering {p!r} is not a permutation of 0..{n - 1}")
            worst = (0.0, 0.0, 0.0)
            where = qs[0]
            for q, (m, dms) in zip(qs, per_q, strict=True):
                t, l_, w = _ordered_cholesky(m, p)
                along = np.einsum("ki,kab->iab", t, dms)
                r = _check_factor_on(t, list(_ordered_cholesky_derivatives(l_, w, p, along)))
                if r[0] >= worst[0]:
                    where = q
                worst = (max(worst[0], r[0]), max(worst[1], r[1]), max(worst[2], r[2]))
            label = "Cholesky in order (" + ", ".join(names[i] for i in p) + ")"
            results.append(
                OrderingResult(
                    label, p, worst[0], worst[1], tuple(where.tolist()), worst[2], worst[0] <= tol
                )
            )
    results.sort(
        key=lambda r: (not r.holds, r.residual if not r.holds else r.commutator, r.residual)
    )
    return Assumption1Report(
        robot=robot.name,
        n=n,
        samples=samples,
        seed=seed,
        search=search,
        tol=tol,
        results=tuple(results),
    )


# ============================================================== β and 𝒫
def _segment_integral(factor: Factor, a: Vector, b: Vector) -> Vector:
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
        acc += _segment_integral(factor, q_ref + (i / pieces) * d, q_ref + ((i + 1) / pieces) * d)
    return acc


class _Homotopy:
    """β and 𝒫 of the homotopy construction (module docstring), exact Jacobian of the rule."""

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


@dataclass(frozen=True)
class Assumption2Report:
    """``𝒫T + (𝒫T)ᵀ ≥ εI`` (Sarras et al. eq. 27) over sampled configurations.

    Attributes:
        epsilon: the smallest eigenvalue found [1/s] (> 0: the assumption holds there).
        exact: True when ε is exact (``𝒫T = kI``, the ``potential`` construction).
        region: half-width of the sampled box around the reference [rad or m].
        samples: number of configurations sampled.
        worst_q: where the smallest eigenvalue was found.
    """

    epsilon: float
    exact: bool
    region: float
    samples: int
    worst_q: tuple[float, ...]


def check_assumption2(
    factor: Factor,
    gain: float,
    q_ref: Vector,
    *,
    region: float = 0.5,
    samples: int = 8,
    seed: int = 0,
    nodes: int = 6,
) -> Assumption2Report:
    """Smallest eigenvalue of ``𝒫T + (𝒫T)ᵀ`` for the homotopy β, on ``q_ref + U(−region, region)ⁿ``."""
    rng = np.random.default_rng(seed)
    hom = _Homotopy(factor, gain, nodes)
    eps, where = math.inf, q_ref
    for _ in range(samples):
        q = q_ref + rng.uniform(-region, region, q_ref.shape[0])
        _, jac = hom.beta_and_jacobian(q, q_ref)
        a = jac @ factor.frame(q)
        lam = float(np.linalg.eigvalsh(a + a.T)[0])
        if lam < eps:
            eps, where = lam, q
    return Assumption2Report(eps, False, region, samples, tuple(where.tolist()))


# ================================================================ observer
@dataclass(frozen=True)
class IIGains:
    """Validated options of :class:`IIObserver`.

    Attributes:
        gain: ``k`` in ``β = k Q`` [1/s], > 0: the error decays as ``e^{−kt}``
            (potential construction).
        nodes: Gauss-Legendre nodes of the homotopy β, >= 1.
        region: half-width of the box where Assumption 2 is checked [rad or m], > 0.
    """

    gain: float
    nodes: int
    region: float

    def __post_init__(self) -> None:
        positive("gain", self.gain)
        positive("nodes", self.nodes)
        positive("region", self.region)
        if int(self.nodes) != self.nodes:
            raise GainError(f"nodes={self.nodes!r} must be a positive integer")


class _Stage(NamedTuple):
    t: Vector  # T(q)
    beta: Vector  # β(q)
    pt: Vector  # 𝒫(q) T(q)
    g: Vector  # ∂V/∂q
    c: Vector | None  # structure functions (D_T compensation), or None


class _State(NamedTuple):
    q: Vector  # last measured (or predicted) configuration
    eta: Vector  # η
    beta: Vector  # β(q)
    q_ref: Vector  # homotopy reference (the configuration at reset)
    age: float = 0.0  # [s] since the reset (the prior's decay in the NIS)
    gate: GateState = GateState()  # the outlier gate's bookkeeping (NIS of the last sample)


@register
class IIObserver(Observer[_State]):
    """I&I reduced-order observer of Sarras et al. (Proposition 5), with input torques.

    Args:
        robot: a robot with vector joints only (revolute, prismatic), or an
            :class:`~pinobs.model.AnalyticMetric`.
        gain: ``k`` [1/s]; the momentum error decays as ``e^{−kt}`` when the
            columns of ``T`` commute.
        ordering: Cholesky ordering (joint indices or names); ``None``
            searches the orderings with :func:`check_assumption1`.
        factor: a :class:`Factor` to use instead of a Cholesky factor (must
            satisfy ``T Tᵀ = M⁻¹``; checked).
        unguaranteed: run even when Assumption 1 fails (no convergence
            guarantee; labelled in :attr:`options`).
        check_samples: configurations sampled by the Assumption 1 check.
        seed: seed of the checks' samplers.
        nodes: Gauss-Legendre nodes of the homotopy β.
        region: half-width of the box around the reset configuration where
            Assumption 2 is checked [rad or m] (homotopy β only).
        substeps: RK4 steps per sample interval; ``None``: enough that
            ``k·h ≤ 0.25`` per step.
        v0_std: standard deviation of the initial velocity error [rad/s or m/s],
            for the NIS only (module docstring).
        outlier_probability: false-alarm probability ``p`` of the outlier gate
            (module docstring); ``None`` switches the gate off.
        rate: sample rate hint [Hz] (unused: the observer uses the actual intervals).
        noise_std: position noise standard deviation [rad or m]: the observer ignores
            it, the NIS divides by it (1e-6 if not given, as the filters').

    Raises:
        UnsupportedRobotError: Lie-group joints, or Assumption 1 fails and
            ``unguaranteed`` is false (the message gives the residual).
    """

    name = "ii"
    uses_noise_std = True
    noise_in_gains = False  # σ only in the NIS (_sigma2)
    summary = (
        "Immersion & Invariance reduced-order observer, Cholesky factor of M⁻¹ (Sarras et al.)"
    )

    def __init__(
        self,
        robot: Robot,
        *,
        gain: float = 20.0,
        ordering: Sequence[int | str] | None = None,
        factor: Factor | None = None,
        unguaranteed: bool = False,
        check_samples: int = 6,
        seed: int = 0,
        nodes: int = 6,
        region: float = 0.5,
        substeps: int | None = None,
        v0_std: float = 1.0,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        _require_vector_joints(robot)
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.outlier_probability, self._gate = gate_threshold(outlier_probability, robot.nv)
        self.v0_std = float(positive("v0_std", v0_std) or 0.0)
        self._sigma2 = (self.noise_std or NOISE_FLOOR) ** 2
        # continuous joints: the observer runs in the angle chart, unwrapped along the path
        self.chart: AngleChart | None = None
        self.plant = self.robot
        if isinstance(self.robot, Robot) and any(b.kind == "circle" for b in self.robot.joints):
            self.chart = AngleChart(self.robot)
            self.plant = self.chart.chart
        self.gains = IIGains(gain=gain, nodes=nodes, region=region)
        self.substeps = None if substeps is None else int(positive("substeps", substeps) or 1)
        self.seed = int(seed)
        n = self.robot.nv
        if factor is not None and ordering is not None:
            raise GainError("give either ordering= or factor=, not both")
        if factor is not None:
            if factor.n != n:
                raise GainError(f"factor has dimension {factor.n}, the robot {n}")
            self._check_custom_factor(factor)
            report = check_assumption1(self.plant, samples=check_samples, seed=seed, factor=factor)
        else:
            orderings = None if ordering is None else [self._resolve_ordering(ordering)]
            report = check_assumption1(
                self.plant, samples=check_samples, seed=seed, orderings=orderings
            )
            factor = CholeskyFactor(self.plant, report.best.ordering or tuple(range(n)))
        self.report = report
        best = report.best
        if not best.holds and not unguaranteed:
            raise UnsupportedRobotError(
                f"Assumption 1 of Sarras et al. (D_T = {{P, P}}_J P ≡ 0) fails on {self.robot.name!r}: "
                f"best factor ({best.label}) has relative residual {best.residual:.3g} "
                f"(tolerance {report.tol:.1e}; max |D_T| = {best.abs_residual:.3g} for |P|² = 1 J, "
                f"at q = [{', '.join(f'{x:.3g}' for x in best.worst_q)}]; {report.search}). "
                "Pass unguaranteed=True to run it anyway without a convergence guarantee, "
                "or use the 'liegroup' or 'riemannian' observer."
            )
        self.guaranteed = best.holds
        self.compensate = not best.holds
        self.factor = factor
        self.construction = (
            "potential" if best.holds and best.commutator <= report.tol else "homotopy"
        )
        self._homotopy = _Homotopy(factor, self.gains.gain, self.gains.nodes)
        self.assumption2: Assumption2Report | None = None
        if self.construction == "potential":
            self.assumption2 = Assumption2Report(2.0 * self.gains.gain, True, math.inf, 0, ())

    def __repr__(self) -> str:
        tag = "" if self.guaranteed else ", unguaranteed"
        return f"{type(self).__name__}({self.robot.name!r}{tag})"

    @property
    def label(self) -> str:
        """What is guaranteed: ``"guaranteed ..."`` or ``"UNGUARANTEED (...)"``, with the numbers."""
        a2 = self.assumption2
        if not self.guaranteed:
            return (
                f"UNGUARANTEED (Assumption 1 fails: relative residual "
                f"{self.report.best.residual:.3g})"
            )
        if a2 is None:
            return "Assumption 1 holds; Assumption 2 is checked at reset"
        if a2.epsilon <= 0.0:
            return (
                f"UNGUARANTEED (Assumption 2 fails within ±{a2.region:g} of the reset "
                f"configuration: ε = {a2.epsilon:.3g} /s)"
            )
        how = (
            "exact, everywhere"
            if a2.exact
            else f"sampled; holds while q stays within ±{a2.region:g} of the reset configuration"
        )
        return f"guaranteed: |P̂ − P|² ≤ e^(−εt)|P̂(0) − P(0)|², ε = {a2.epsilon:.4g} /s ({how})"

    @property
    def options(self) -> dict[str, object]:
        a2 = self.assumption2
        return {
            **super().options,
            "gain": self.gains.gain,
            "factor": self.factor.label,
            "construction": self.construction,
            "assumption1_residual": self.report.best.residual,
            "guaranteed": self.guaranteed,
            "label": self.label,
            "assumption2_epsilon": None if a2 is None else a2.epsilon,
            "nodes": self.gains.nodes,
            "region": self.gains.region,
            "substeps": self.substeps,
            "v0_std": self.v0_std,
            "outlier_probability": self.outlier_probability,
        }

    # ------------------------------------------------------------- helpers
    def _resolve_ordering(self, ordering: Sequence[int | str]) -> tuple[int, ...]:
        names = self.robot.joint_names
        out = []
        for o in ordering:
            if isinstance(o, str):
                if o not in names:
                    raise GainError(f"ordering names unknown joint {o!r}; joints: {list(names)}")
                out.append(names.index(o))
            else:
                out.append(int(o))
        if sorted(out) != list(range(self.robot.nv)):
            raise GainError(
                f"ordering={list(ordering)!r} is not a permutation of the joints {list(names)}"
            )
        return tuple(out)

    def _check_custom_factor(self, factor: Factor) -> None:
        rng = np.random.default_rng(self.seed)
        for _ in range(3):
            q = self.plant.random_configuration(rng)
            t = factor.frame(q)
            minv = np.linalg.inv(self.plant.mass_matrix(q))
            err = float(np.abs(t @ t.T - minv).max() / np.abs(minv).max())
            if not err < 1e-8:
                raise GainError(
                    f"factor {factor.label!r} does not satisfy T Tᵀ = M⁻¹ (relative error {err:.3g})"
                )

    def beta_and_jacobian(self, q: Vector, state: _State) -> tuple[Vector, Vector]:
        """``(β(q), 𝒫(q) T(q))`` for the current construction; β relative to ``state``.

        ``potential``: ``β(q) = β(q_k) + k ∫_{q_k}^{q} T⁻¹ dq`` (one straight
        segment, exact by path independence) and ``𝒫T = kI``.
        """
        k = self.gains.gain
        if self.construction == "potential":
            return state.beta + k * _segment_integral(self.factor, state.q, q), k * np.eye(
                q.shape[0]
            )
        beta, jac = self._homotopy.beta_and_jacobian(q, state.q_ref)
        return beta, jac @ self.factor.frame(q)

    def vector_field(
        self, q: Vector, eta: Vector, tau: Vector, *, beta: Vector, pt: Vector
    ) -> Vector:
        """``η̇ = 𝒫T (β − η) − Tᵀ(τ − ∂V/∂q) [− D_T(q, P̂)]`` at measured ``q``.

        Sarras et al. eq. (30) with an input torque.  The bracketed
        certainty-equivalent term is added only when Assumption 1 fails
        (``unguaranteed``); where it holds ``D_T ≡ 0`` and the term vanishes.

        Args:
            q: configuration [rad or m].
            eta: observer state η.
            tau: torque [N·m or N].
            beta: ``β(q)`` (see :meth:`beta_and_jacobian`).
            pt: ``𝒫(q) T(q)`` [1/s].
        """
        return self._eta_dot(self._stage(q, beta, pt), eta, tau)

    def _stage(self, q: Vector, beta: Vector, pt: Vector) -> _Stage:
        if self.compensate:
            t, dts = self.factor.columns_jet(q)
            c: Vector | None = structure_functions(t, dts)[0]
        else:
            t, c = self.factor.frame(q), None
        return _Stage(t, beta, pt, self.plant.gravity(q), c)

    def _eta_dot(self, st: _Stage, eta: Vector, tau: Vector) -> Vector:
        p_hat = st.beta - eta
        if self.plant.has_friction:  # the model's joint friction, a known torque at v̂ = T P̂
            tau = tau + self.plant.friction_torque(st.t @ p_hat)
        out = st.pt @ p_hat - st.t.T @ (tau - st.g)  # Sarras et al. eq. (30), input τ added
        if st.c is not None:
            out -= momentum_residual(
                st.c, p_hat
            )  # certainty equivalence: ż = −𝒫Tz − (D_T(P) − D_T(P̂))
        return out

    def momentum(self, q: Vector, v: Vector) -> Vector:
        """``P = T(q)⁻¹ v`` (``|P|² = 2 × kinetic energy`` [J]); ``q`` the robot's (``nq``)."""
        x = q if self.chart is None else self.chart.to_chart(q)
        return self._momentum(x, v)

    def _momentum(self, x: Vector, v: Vector) -> Vector:
        """``P = T(x)⁻¹ v`` at chart coordinates ``x``."""
        return np.asarray(np.linalg.solve(self.factor.frame(x), v))

    # ------------------------------------------------------ family interface
    # The state lives in the chart (θ unwrapped for continuous joints); q in and out is the robot's.
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        if self.chart is not None:
            q0 = self.chart.to_chart(q0)
        q_ref = q0.copy()
        if self.construction == "potential":
            beta = np.zeros_like(q0)
        else:
            beta, _ = self._homotopy.beta_and_jacobian(q0, q_ref)
            self.assumption2 = check_assumption2(
                self.factor,
                self.gains.gain,
                q_ref,
                region=self.gains.region,
                seed=self.seed,
                nodes=self.gains.nodes,
            )
        eta = beta - self._momentum(q0, v0)  # P̂(0) = β − η = T⁻¹ v0
        return _State(q0.copy(), eta, beta, q_ref)

    def output(self, state: _State) -> tuple[Vector, Vector]:
        v_hat = self.factor.frame(state.q) @ (state.beta - state.eta)
        if self.chart is not None:
            return self.chart.from_chart(state.q), v_hat
        return state.q, v_hat

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        robot = self.plant
        n_sub = self.substeps or max(1, math.ceil(self.gains.gain * dt / _STEP_KH))
        h = dt / n_sub

        # (1) predict the plant from the estimate, torque held (MATH §7)
        v_hat = self.factor.frame(state.q) @ (state.beta - state.eta)
        nodes_q: list[Vector] = [state.q]
        nodes_v: list[Vector] = [v_hat]
        for _ in range(n_sub):
            qn, vn = dynamics_rk4(robot, nodes_q[-1], nodes_v[-1], tau, h)
            nodes_q.append(qn)
            nodes_v.append(vn)
        gate = state.gate.predicted()
        if q_meas is None:
            q_end = nodes_q[-1]
        elif self.chart is not None:  # θ unwrapped: the 2π-branch nearest the prediction
            q_end = self.chart.to_chart(q_meas, near=nodes_q[-1])
        else:
            q_end = q_meas
        if q_meas is not None:  # the innovation, its NIS and the filters' outlier gate
            e = q_end - nodes_q[-1]
            nis = float(e.dot(e)) / self.innovation_variance(state.age, dt)
            gate = state.gate.measured(nis, self._gate, e.size)
            if gate.gated:  # not used: the path and q̂ are the prediction's
                q_end = nodes_q[-1]
        shift = q_end - nodes_q[-1]

        # (2) the path: Hermite interpolant of the prediction, corrected to end on q_meas
        def path(j: int, frac: float) -> Vector:
            q0, q1, v0, v1 = nodes_q[j], nodes_q[j + 1], nodes_v[j], nodes_v[j + 1]
            s = frac
            h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
            h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
            herm = h00 * q0 + h10 * h * v0 + h01 * q1 + h11 * h * v1
            return herm + ((j + frac) / n_sub) * shift

        # (3) RK4 on η along the path; β carried along it (potential) or evaluated (homotopy)
        eta = state.eta
        cur = state
        sa = self._stage(state.q, *self.beta_and_jacobian(state.q, state))
        for j in range(n_sub):
            qm, qb = path(j, 0.5), path(j, 1.0)
            sm = self._stage(qm, *self.beta_and_jacobian(qm, cur))
            sb = self._stage(qb, *self.beta_and_jacobian(qb, cur))
            k1 = self._eta_dot(sa, eta, tau)
            k2 = self._eta_dot(sm, eta + 0.5 * h * k1, tau)
            k3 = self._eta_dot(sm, eta + 0.5 * h * k2, tau)
            k4 = self._eta_dot(sb, eta + h * k3, tau)
            eta = eta + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            cur = _State(qb, eta, sb.beta, state.q_ref)
            sa = sb
        return _State(q_end.copy(), eta, cur.beta, state.q_ref, state.age + dt, gate)

    def innovation_variance(self, age: float, h: float) -> float:
        """``S`` [rad² or m²] per joint of the innovation ``q_meas − q̂⁻`` after ``age`` [s]
        since the reset, over an interval ``h`` [s] (module docstring, "Consistency")::

            S = σ² (2 + 2kh) + h² v0_std² e^{−ε age}
        """
        a2 = self.assumption2
        eps = a2.epsilon if a2 is not None and a2.epsilon > 0.0 else 2.0 * self.gains.gain
        k = self.gains.gain
        return self._sigma2 * (2.0 + 2.0 * k * h) + (h * self.v0_std) ** 2 * math.exp(-eps * age)
