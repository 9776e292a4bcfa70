"""The I&I observer's assumptions, checked on sampled configurations.

Assumption 1 of Sarras et al. (``D_T(q, P) = {P, P}_J P ≡ 0``, eq. 18) holds
iff the symmetric part of every ``(c_ij^l)_{j,l}`` vanishes, ``c`` the
structure functions of the columns of ``T``
(:func:`~pinobs.observers.ii_factor.structure_functions`):
:func:`check_assumption1` measures it over Cholesky orderings.
Assumption 2 (``𝒫T + (𝒫T)ᵀ ≥ εI``, eq. 27) for the homotopy β:
:func:`check_assumption2`.  The observer and the theory are in
:mod:`pinobs.observers.ii`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from pinobs.errors import GainError, UnsupportedRobotError
from pinobs.model import Robot
from pinobs.model.chart import AngleChart
from pinobs.observers.base import Vector, positive
from pinobs.observers.ii_factor import (
    Factor,
    ordered_cholesky,
    ordered_cholesky_derivatives,
    structure_functions,
)
from pinobs.observers.ii_potential import Homotopy
from pinobs.tolerances import II_ASSUMPTION1_TOL

__all__ = [
    "Assumption1Report",
    "Assumption2Report",
    "OrderingResult",
    "check_assumption1",
    "check_assumption2",
    "require_vector_joints",
]

_FULL_SEARCH_MAX_N = 5  # all n! orderings up to n = 5 (120); a heuristic subset above


# ========================================================= Assumption 1 check
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


def require_vector_joints(robot: Robot) -> None:
    """Raise :class:`~pinobs.errors.UnsupportedRobotError` unless every joint is revolute,
    prismatic or continuous (the joints I&I handles, :mod:`pinobs.observers.ii`)."""
    kinds = sorted({b.kind for b in robot.joints if b.kind not in ("vector", "circle")})
    if kinds:
        raise UnsupportedRobotError(
            f"the I&I observer ('ii') needs revolute, prismatic or continuous joints; "
            f"{robot.name!r} has {', '.join(kinds)} joints. Use the 'liegroup' or "
            "'riemannian' observer for Lie-group joints."
        )


def _in_chart(robot: Robot) -> Robot:
    """``robot`` itself, or its angle chart when it has continuous joints (:mod:`pinobs.observers.ii`)."""
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


def _worst_over(
    qs: Sequence[Vector],
    residuals: Iterable[tuple[float, float, float]],
    label: str,
    ordering: tuple[int, ...] | None,
    tol: float,
) -> OrderingResult:
    """One factor's result: each residual's maximum over the samples ``qs`` (``residuals``
    in the same order), ``worst_q`` where the relative residual is largest (the last on ties)."""
    worst = (0.0, 0.0, 0.0)
    where = qs[0]
    for q, r in zip(qs, residuals, strict=True):
        if r[0] >= worst[0]:
            where = q
        worst = (max(worst[0], r[0]), max(worst[1], r[1]), max(worst[2], r[2]))
    return OrderingResult(
        label, ordering, worst[0], worst[1], tuple(where.tolist()), worst[2], worst[0] <= tol
    )


def _check_given_factor(factor: Factor, qs: Sequence[Vector], tol: float) -> OrderingResult:
    """Assumption 1 for a caller-given factor, on the samples ``qs``."""
    residuals = (_check_factor_on(*factor.columns_jet(q)) for q in qs)
    return _worst_over(qs, residuals, factor.label, None, tol)


def _mass_matrices(robot: Robot, qs: Sequence[Vector]) -> list[tuple[Vector, Vector]]:
    """``(M(q), [∂_k M(q) for each k])`` at each sample: what every ordering shares."""
    eye = np.eye(robot.nv)
    return [
        (robot.mass_matrix(q), np.stack([robot.mass_matrix_derivative(q, e) for e in eye]))
        for q in qs
    ]


def _cholesky_residuals(
    p: tuple[int, ...], per_q: Sequence[tuple[Vector, Vector]]
) -> Iterator[tuple[float, float, float]]:
    """The residuals of the Cholesky factor in ordering ``p`` at each sample's ``(M, ∂M)``."""
    for m, dms in per_q:
        t, l_, w = ordered_cholesky(m, p)
        along = np.einsum("ki,kab->iab", t, dms)  # D_{T_i} M = Σ_k T_ki ∂_k M
        yield _check_factor_on(t, list(ordered_cholesky_derivatives(l_, w, p, along)))


def _check_orderings(
    robot: Robot,
    qs: Sequence[Vector],
    orderings: Sequence[Sequence[int]] | None,
    tol: float,
) -> tuple[list[OrderingResult], str]:
    """Assumption 1 for the Cholesky factor in each candidate ordering, and how they were chosen."""
    n = robot.nv
    if orderings is None:
        cands, search = _candidate_orderings(n)
    else:
        cands, search = [tuple(int(i) for i in o) for o in orderings], "the given orderings"
    per_q = _mass_matrices(robot, qs)
    names = robot.joint_names
    results: list[OrderingResult] = []
    for p in cands:
        if sorted(p) != list(range(n)):
            raise GainError(f"ordering {p!r} is not a permutation of 0..{n - 1}")
        label = "Cholesky in order (" + ", ".join(names[i] for i in p) + ")"
        results.append(_worst_over(qs, _cholesky_residuals(p, per_q), label, p, tol))
    return results, search


def _best_first(results: Sequence[OrderingResult]) -> tuple[OrderingResult, ...]:
    """Factors that hold first, commuting columns preferred among them; then by residual."""
    return tuple(
        sorted(
            results,
            key=lambda r: (not r.holds, r.residual if not r.holds else r.commutator, r.residual),
        )
    )


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
    require_vector_joints(robot)
    robot = _in_chart(robot)
    samples = int(positive("samples", samples) or 1)
    rng = np.random.default_rng(seed)
    qs = [robot.random_configuration(rng, scale=scale) for _ in range(samples)]
    if factor is not None:
        results, search = [_check_given_factor(factor, qs, tol)], "the given factor"
    else:
        results, search = _check_orderings(robot, qs, orderings, tol)
    return Assumption1Report(
        robot=robot.name,
        n=robot.nv,
        samples=samples,
        seed=seed,
        search=search,
        tol=tol,
        results=_best_first(results),
    )


# ========================================================= Assumption 2 check
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
    hom = Homotopy(factor, gain, nodes)
    eps, where = math.inf, q_ref
    for _ in range(samples):
        q = q_ref + rng.uniform(-region, region, q_ref.shape[0])
        _, jac = hom.beta_and_jacobian(q, q_ref)
        a = jac @ factor.frame(q)
        lam = float(np.linalg.eigvalsh(a + a.T)[0])
        if lam < eps:
            eps, where = lam, q
    return Assumption2Report(eps, False, region, samples, tuple(where.tolist()))
