"""The smoothing velocity of a friction law, chosen by cross-validation (identification).

:func:`pinobs.model.identification.identify` with ``friction=LAW``
(:data:`pinobs.model.friction.FRICTION_LAWS`) fits a law's coefficients linearly; its
smoothing velocity ``v_s`` (and a Stribeck law's ``v_st``) enters the columns
nonlinearly.  The rows are built once with every candidate's columns (:func:`widened`:
the expensive drift regressors are shared), and each joint's candidate is chosen by the
cross-validated residual of the fitted rows with the one-standard-error rule
(:func:`search_smoothing`); the chosen columns are then the law's
(:func:`candidate_columns`).  A grid, not a golden-section
search: the candidates' columns must exist before the rows are built.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from pinobs.model.identification import MomentumRegressor

Vector = np.ndarray

__all__ = [
    "SMOOTHING_FOLDS",
    "SMOOTHING_GRID",
    "STRIBECK_GRID",
    "candidate_columns",
    "search_candidates",
    "search_smoothing",
    "widened",
]

#: The smoothing velocities ``v_s`` [rad/s] :func:`~pinobs.model.identification.identify` tries for a law with an
#: identified one (:func:`search_smoothing`): 1e-3 to 0.56 rad/s, four per decade.
SMOOTHING_GRID = tuple(float(10.0 ** (k / 4)) for k in range(-12, -0))

#: A Stribeck law's grid: ``v_s`` two per decade (1e-3 to 0.32), ``v_st`` two per decade
#: (0.01 to 1), pairs with ``v_st > v_s`` only (a coarser grid: every pair is two columns).
STRIBECK_GRID = tuple(
    (float(10.0 ** (a / 2)), float(10.0 ** (b / 2)))
    for a in range(-6, 0)
    for b in range(-4, 1)
    if b > a
)

#: Contiguous blocks of the fitted rows that choose the smoothing velocity by
#: cross-validation (:func:`search_smoothing`).
SMOOTHING_FOLDS = 5


def search_candidates(law: str, smoothing: float | None) -> list[tuple[float, float]]:
    """The ``(v_s, v_st)`` pairs tried for ``law`` (``v_st`` 0 but for Stribeck); with
    ``smoothing`` given, only ``v_st`` is searched (none for the other laws: ``[]``)."""
    if law == "stribeck":
        if smoothing is not None:
            return [(smoothing, b) for b in sorted({b for _, b in STRIBECK_GRID})]
        return list(STRIBECK_GRID)
    return [] if smoothing is not None else [(vs, 0.0) for vs in SMOOTHING_GRID]


def widened(reg: MomentumRegressor, cands: list[tuple[float, float]]) -> MomentumRegressor:
    """A copy of ``reg`` whose friction columns are those of every candidate ``(v_s, v_st)``
    for the terms that depend on them (``damping`` and ``friction_offset`` do not), laid out
    term by term, candidate by candidate (:func:`candidate_columns` indexes it)."""
    wide = copy.copy(reg)
    n = reg.n_joint
    groups, names = [], list(reg.names[: reg.n_inertial])
    for term in reg.friction_terms:
        fixed = term in ("damping", "friction_offset")
        for c, (vs, vst) in enumerate(cands[:1] if fixed else cands):
            groups.append((term, np.full(n, vs), np.full(n, vst)))
            names += [f"{j}.{term}" + ("" if fixed else f"@{c}") for j in reg.actuated_names]
    wide._groups = groups
    wide.names = tuple(names + list(reg.names[reg.n_inertial + len(reg.friction_terms) * n :]))
    return wide


def candidate_columns(reg: MomentumRegressor, n_cands: int, choice: list[int]) -> NDArray[np.intp]:
    """The columns of :func:`widened`'s rows that make ``reg``'s with joint ``j`` at
    candidate ``choice[j]``, in ``reg``'s order."""
    n, n0 = reg.n_joint, reg.n_inertial
    cols = list(range(n0))
    start = n0
    for term in reg.friction_terms:
        fixed = term in ("damping", "friction_offset")
        cols += [start + (0 if fixed else choice[j]) * n + j for j in range(n)]
        start += n * (1 if fixed else n_cands)
    rest = reg.size - n0 - len(reg.friction_terms) * n
    cols += list(range(start, start + rest))
    return np.asarray(cols, dtype=np.intp)


def _fold_grams(A: Vector, y: Vector, nv: int) -> tuple[list[Vector], list[Vector], list[float]]:
    """``(AᵀA, Aᵀy, yᵀy)`` of each of the :data:`SMOOTHING_FOLDS` contiguous blocks of the
    rows (a window's ``nv`` rows stay together)."""
    blocks = np.array_split(np.arange(A.shape[0] // nv), SMOOTHING_FOLDS)
    grams, rhs, yy = [], [], []
    for b in blocks:
        rows = (b[:, None] * nv + np.arange(nv)).ravel()  # a window's rows stay together
        grams.append(A[rows].T @ A[rows])
        rhs.append(A[rows].T @ y[rows])
        yy.append(float(y[rows] @ y[rows]))
    return grams, rhs, yy


def _nearest(cands: list[tuple[float, float]], vs: float, vst: float) -> int:
    """The index of the candidate ``(v_s, v_st)`` nearest ``(vs, vst)`` in log scale."""
    return int(
        np.argmin(
            [
                abs(math.log(c[0] / vs)) + abs(math.log(max(c[1], 1e-9) / max(vst, 1e-9)))
                for c in cands
            ]
        )
    )


def _one_standard_error(
    e: Vector, kept: list[int], cands: list[tuple[float, float]], own: tuple[float, float]
) -> int:
    """The one-standard-error rule (:func:`search_smoothing`; ESL §7.10): of the ``kept``
    candidates (rows of ``e``, each block's ``e_k``), the nearest to ``own`` in log scale
    whose ``CV`` is within one standard error of the best's; ties to the smaller ``CV``."""
    cv = e.sum(axis=1)
    best = min(kept, key=lambda c: cv[c])
    se = math.sqrt(e.shape[1]) * float(np.std(e[best], ddof=1))  # SE of the best's sum
    within = [c for c in kept if cv[c] <= cv[best] + se]

    def distance(c: int) -> float:
        (a, b), (a0, b0) = cands[c], own
        return abs(math.log(a / a0)) + abs(math.log(max(b, 1e-9) / max(b0, 1e-9)))

    return min(within, key=lambda c: (distance(c), cv[c]))


def _picker(
    cands: list[tuple[float, float]], own: list[int], minimum: bool
) -> Callable[[Vector, list[int], int], int]:
    """Joint ``j``'s candidate among the ``kept`` rows of ``e`` (each block's ``e_k``): the
    least ``CV`` with ``minimum``, else :func:`_one_standard_error` about ``own[j]``."""

    def pick(e: Vector, kept: list[int], j: int) -> int:
        if minimum:
            return min(kept, key=lambda c: float(e[c].sum()))
        return _one_standard_error(e, kept, cands, cands[own[j]])

    return pick


def _descend(
    choice: list[int],
    n_joint: int,
    n_c: int,
    folds: Callable[[list[int]], Vector],
    consistent: Callable[[list[int], int], bool],
    pick: Callable[[Vector, list[int], int], int],
) -> list[int]:
    """:func:`search_smoothing`'s coordinate descent from ``choice``: every joint's ``n_c``
    candidates tried with the others held (``folds``' blocks, ``pick`` among those
    ``consistent``), sweeps until none changes, three at most."""
    for _ in range(3):
        changed = False
        for j in range(n_joint):
            trials = [[*choice[:j], c, *choice[j + 1 :]] for c in range(n_c)]
            e = np.array([folds(trial) for trial in trials])
            kept = [c for c in range(n_c) if consistent(trials[c], j)] or list(range(n_c))
            c = pick(e, kept, j)
            if c != choice[j]:
                choice[j], changed = c, True
        if not changed:
            break
    return choice


def search_smoothing(
    reg: MomentumRegressor,
    A: Vector,
    y: Vector,
    cands: list[tuple[float, float]],
    *,
    minimum: bool = False,
) -> tuple[list[int], dict[str, Any]]:
    """Each joint's ``(v_s, v_st)`` among ``cands``: the one nearest ``reg``'s own whose
    columns predict the fitted rows, under cross-validation, within one standard error of
    the best, and what the search saw.

    The rows (of :func:`widened`) are cut into :data:`SMOOTHING_FOLDS` contiguous blocks;
    each candidate's prior-regularised linear fit (:func:`~pinobs.model.identification.solve`'s
    Gaussian prior and residual scale, without its Huber weights and consistency step) on
    all blocks but one predicts the one left out; the sum of squares over the blocks is the
    criterion ``CV(c) = Σ_k e_k(c)``.  The one-standard-error rule (Hastie, Tibshirani &
    Friedman, *The Elements of Statistical Learning*, 2nd ed., §7.10): of the candidates with
    ``CV(c) ≤ CV(c*) + SE(c*)``, ``SE(c*) = √K · sd_k(e_k(c*))`` the standard error of the
    best's sum over the ``K`` blocks, the most regular is kept, here the nearest (in log
    scale) to ``reg``'s own (0.01 rad/s: :data:`pinobs.tolerances.COULOMB_SMOOTHING_VELOCITY`,
    unless the model's law says otherwise); ties to the smaller ``CV``.  Only candidates
    whose fit on all the blocks leaves the joint's dissipative friction ``≥ 0`` compete (all
    of them if none does): :func:`~pinobs.model.identification.solve` projects the others
    onto that set, a fit the cross-validation did not measure.  Without the rule the
    minimum was taken however small its lead: on the real TX40 and UR10e, 0.01's ``CV`` was
    0 to 9 % above the minimum's (one standard error: 18 to 29 %), and the minimum
    (1e-3 to 0.56 rad/s) predicted the held-out torques worse than 0.01 kept
    (benchmarks/tx40_friction.md, benchmarks/real_friction.json).  ``minimum=True`` takes
    the least ``CV`` instead (the law of a smoother: :mod:`pinobs.calibration`).

    The joints' choices interact only through the shared inertial parameters, so they are
    made one joint at a time (coordinate descent: every joint's grid, with the others held;
    sweeps until none changes, three at most), from the candidate nearest ``reg``'s own.
    The fits are solved on precomputed Gram blocks (``AᵀA`` per block): a candidate costs
    ``SMOOTHING_FOLDS + 1`` solves of ``reg.size`` unknowns.
    """
    theta0, s = reg.nominal(), reg.prior_std()
    n_c = len(cands)
    grams, rhs, yy = _fold_grams(A, y, reg.robot.nv)
    g_all, r_all = np.sum(grams, axis=0), np.sum(rhs, axis=0)
    own = [
        _nearest(cands, float(a), float(b))
        for a, b in zip(reg.smoothing, reg.stribeck_velocity, strict=True)
    ]
    # residual scale: of the starting choice's plain fit (as solve's first pass)
    cols = candidate_columns(reg, n_c, own)
    th = np.linalg.lstsq(A[:, cols], y, rcond=None)[0]
    sigma2 = max(1.4826 * float(np.median(np.abs(A[:, cols] @ th - y))), 1e-300) ** 2
    prec0 = 1.0 / s**2

    def folds(choice: list[int]) -> Vector:
        """``e_k``: each block's sum of squares predicted by the fit on the others."""
        cols = candidate_columns(reg, n_c, choice)
        ix = np.ix_(cols, cols)
        out = []
        for g, r, e in zip(grams, rhs, yy, strict=True):
            h = (g_all - g)[ix] / sigma2 + np.diag(prec0)
            th = np.linalg.solve(h, (r_all - r)[cols] / sigma2 + prec0 * theta0)
            out.append(float(th @ g[ix] @ th - 2.0 * th @ r[cols] + e))
        return np.asarray(out)

    def consistent(choice: list[int], j: int) -> bool:
        """Whether the fit on all the blocks leaves joint ``j``'s dissipative friction
        ``≥ 0`` (what :func:`~pinobs.model.identification.solve`'s consistency step
        enforces)."""
        cols = candidate_columns(reg, n_c, choice)
        h = g_all[np.ix_(cols, cols)] / sigma2 + np.diag(prec0)
        th = np.linalg.solve(h, r_all[cols] / sigma2 + prec0 * theta0)
        n0, n = reg.n_inertial, reg.n_joint
        terms = [k for k, t in enumerate(reg.friction_terms) if t != "friction_offset"]
        return all(th[n0 + k * n + j] >= 0.0 for k in terms)

    choice = _descend(list(own), reg.n_joint, n_c, folds, consistent, _picker(cands, own, minimum))
    return choice, {"cv_sum_of_squares": float(folds(choice).sum()), "candidates": n_c}
