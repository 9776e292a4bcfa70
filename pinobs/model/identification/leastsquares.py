"""The regularised, robust least squares of the identification (:func:`solve`) and its
physical consistency (Wensing, Kim, Slotine 2017: :func:`pseudo_inertia`, the posterior-metric
projection :func:`_consistent`); the package docstring of :mod:`pinobs.model.identification`
states both."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import IdentificationError
from pinobs.model.identification.lapack import numpy_has_dgeqp3, pivoted_qr
from pinobs.model.robot import Vector

if TYPE_CHECKING:
    from pinobs.model.identification.payload import PayloadRegressor
    from pinobs.model.identification.regressor import MomentumRegressor

__all__ = [
    "CHANNEL_SIGMA_FLOOR",
    "MAX_CONDITION",
    "MU_END",
    "NORMAL_EQUATIONS_LIMIT",
    "Solution",
    "channel_sigma",
    "pseudo_inertia",
    "solve",
]


#: Last barrier weight of :func:`_consistent` (in units of the largest posterior precision).
MU_END = 1e-16

#: Refuse a log whose base regressor is worse conditioned than this.
MAX_CONDITION = 1e6


def pseudo_inertia(pi: Vector) -> Vector:
    """``J = [[Σ, h], [hᵀ, m]]``, ``Σ = ½ tr(Ī)·1 − Ī``, of one body's ten parameters (Wensing et al. 2017)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = pi
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    out = np.empty((4, 4))
    out[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    out[:3, 3] = out[3, :3] = (hx, hy, hz)
    out[3, 3] = m
    return out


def _from_pseudo_inertia(J: Vector) -> Vector:
    sigma = J[:3, :3]
    inertia = np.trace(sigma) * np.eye(3) - sigma
    return np.array(
        [
            J[3, 3],
            J[0, 3],
            J[1, 3],
            J[2, 3],
            inertia[0, 0],
            inertia[0, 1],
            inertia[1, 1],
            inertia[0, 2],
            inertia[1, 2],
            inertia[2, 2],
        ]
    )


@dataclass(frozen=True)
class Solution:
    """The result of :func:`solve`.

    Attributes:
        theta: the parameters (physically consistent).
        std: posterior standard deviations.
        excited: per parameter, whether the data fixed it (posterior std < ½ prior std), booleans.
        rank: number of identifiable combinations (pivoted QR).
        base: names of the pivot columns, one per identifiable combination.
        condition: condition number of the prior-scaled regressor on those columns.
        sigma: robust residual scale of the weighted rows [rad/s²-like, or N·m with
            channels: the median row's].
        projected: whether physical consistency moved the linear solution.
        n_rows: rows used.
        channel_sigma: per channel (:func:`solve`'s ``channel``, in increasing order), its
            residual scale; one value (``sigma``) without channels.
    """

    theta: Vector
    std: Vector
    excited: NDArray[np.bool_]
    rank: int
    base: tuple[str, ...]
    condition: float
    sigma: float
    projected: bool
    n_rows: int
    precision: Vector = field(repr=False, default_factory=lambda: np.zeros((0, 0)))
    channel_sigma: Vector = field(repr=False, default_factory=lambda: np.zeros(0))


def solve(
    reg: MomentumRegressor | PayloadRegressor,
    A: Vector,
    y: Vector,
    *,
    theta0: Vector | None = None,
    prior_std: Vector | None = None,
    irls: int = 4,
    huber: float = 1.345,
    consistent: bool = True,
    channel: NDArray[np.intp] | None = None,
) -> Solution:
    """Regularised, robust least squares for ``A θ ≈ y`` (module docstring).

    Minimises ``Σᵢ ρ(rᵢ/σ) + ½|(θ − θ₀)/s|²`` with ``r = Aθ − y``, ``ρ`` Huber's
    loss (iteratively re-weighted) and σ re-estimated from the residuals'
    median absolute deviation at each pass; then enforces physical
    consistency (``consistent=False`` skips that last step: the online
    observer checks ``M(q) ≻ 0`` instead, which costs a thousandth).

    ``channel``: per row, the torque channel it belongs to (``(n_rows,)`` integers); each
    channel then has its own σ (``σ_c = 1.4826 · median |r_i|`` over its rows, at least
    :data:`CHANNEL_SIGMA_FLOOR` of the largest), re-estimated at each pass: rows of
    torques in N·m weighted by their own noise (module docstring, "Weighting").  ``None``:
    one σ for all rows (rows made commensurable by their weights beforehand).  Rows weighted
    beyond what the normal equations resolve against the prior (a noise-free log, σ at
    rounding; prior widths many orders wide: :data:`NORMAL_EQUATIONS_LIMIT`) are solved by a
    truncated SVD instead when they over-determine the fit (``_weighted_step``); ``precision``
    is then only as good as a dense matrix holds it (``ε·λ_max`` on every eigenvalue).

    Raises:
        IdentificationError: no rows, or nothing identifiable.
    """
    if A.shape[0] == 0:
        raise IdentificationError("no complete window of data: the log is too short")
    # small dense problems: one BLAS thread is 4x faster than two fighting over a busy machine
    with _blas_controller().limit(limits=1):
        return _solve(reg, A, y, theta0, prior_std, irls, huber, consistent, channel)


@functools.cache
def _blas_controller() -> Any:
    """threadpoolctl's view of the loaded BLAS libraries, scanned once (a scan costs about
    2 ms, which the online learner would pay at every solve)."""
    if not numpy_has_dgeqp3():  # the QR is SciPy's: its BLAS loaded before the scan
        import scipy.linalg  # noqa: F401
    from threadpoolctl import ThreadpoolController  # lazily: import pinobs stays light

    return ThreadpoolController()


def _solve(
    reg: MomentumRegressor | PayloadRegressor,
    A: Vector,
    y: Vector,
    theta0: Vector | None,
    prior_std: Vector | None,
    irls: int,
    huber: float,
    consistent: bool,
    channel: NDArray[np.intp] | None = None,
) -> Solution:
    theta0 = reg.nominal() if theta0 is None else theta0
    s = reg.prior_std() if prior_std is None else prior_std
    As = A * s  # columns in prior units: u = (θ − θ₀)/s
    r0 = y - A @ theta0
    if not np.any(As):
        raise IdentificationError("the regressor is zero: the log never moves the robot")
    # first pass: σ from an almost unregularised fit
    u, _, rank0, _ = np.linalg.lstsq(As, r0, rcond=None)
    over = rank0 < A.shape[0]  # the rows over-determine the fit (_weighted_step)
    sig = _row_sigma(As @ u - r0, channel)
    # identifiable combinations: pivoted QR of the prior-scaled rows, each over its σ (one
    # scalar without channels: the rank and condition number are those of As)
    R, piv = pivoted_qr(As / sig[:, None])  # LAPACK's dgeqp3, as scipy.linalg.qr's
    diag = np.abs(np.diag(R))
    if diag.size == 0 or diag[0] == 0.0:
        raise IdentificationError("the regressor is zero: the log never moves the robot")
    rank = int(np.sum(diag > 1e-8 * diag[0]))
    base = tuple(reg.names[i] for i in piv[:rank])
    sv = np.linalg.svd((As / sig[:, None])[:, piv[:rank]], compute_uv=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    w = np.ones(A.shape[0])
    eye = np.eye(reg.size)
    prec_u: Vector = eye
    for it in range(irls + 1):
        res = As @ u - r0
        sig = _row_sigma(res, channel)
        sigma = float(np.median(sig))
        z = np.abs(res) / sig
        w = np.where(z <= huber, 1.0, huber / np.maximum(z, 1e-300))
        prec_u, lam, vec, step, wide = _weighted_step(As, w / sig**2, r0, eye, over)
        if it < irls:
            u = step
    cov_u = (vec / lam) @ vec.T
    std = s * np.sqrt(np.diag(cov_u))
    theta = theta0 + s * u
    whiten = (lam, vec) if wide else None  # Λ too wide to hold densely (_weighted_step)
    theta_c = _consistent(reg, theta, prec_u, s, whiten) if consistent else theta
    projected = not np.array_equal(theta_c, theta)
    return Solution(
        theta=theta_c,
        std=std,
        excited=std < 0.5 * s,
        rank=rank,
        base=base,
        condition=condition,
        sigma=sigma,
        projected=projected,
        n_rows=int(A.shape[0]),
        precision=prec_u / np.outer(s, s),
        channel_sigma=channel_sigma(res, channel),
    )


#: The normal equations of :func:`solve`'s weighted step are used while their largest
#: eigenvalue times the machine epsilon stays below this share of the prior's unit
#: eigenvalue; above it, the step is taken by a truncated SVD of the weighted rows instead.
NORMAL_EQUATIONS_LIMIT = 1.0


def _weighted_step(
    As: Vector, row_w: Vector, r0: Vector, eye: Vector, over: bool = True
) -> tuple[Vector, Vector, Vector, Vector, bool]:
    """``(Λ, λ, V, u, wide)``: the posterior precision ``Λ = Asᵀ W As + I = V diag(λ) Vᵀ`` (u-units)
    and the step ``u = Λ⁻¹ Asᵀ W r₀`` of rows weighted by ``W = diag(row_w)``; ``wide``:
    beyond the normal equations' limit.

    By the normal equations while ``ε·λ_max ≤`` :data:`NORMAL_EQUATIONS_LIMIT`; beyond it
    (rows weighted by a residual scale at rounding level, a noise-free log, or prior widths
    many orders wide) their rounding, about ``ε·λ_max`` on every eigenvalue (Golub & Van Loan,
    *Matrix Computations*, 4th ed., 2013, §8.1.2, Weyl), swamps the prior's unit eigenvalue:
    the directions the data do not fix then got steps of order rounding/1, which made fitted
    residuals of 60–160 N·m (TIAGo, prior ×1e6) and 8.9 N·m (planar_3r's rigid-body rows,
    noise-free, prior ×1e3) where the truth fits to 1e-14.  Then ``B = W^½ As = U diag(S) Vᵀ``
    (``Λ = V diag(S² + 1) Vᵀ``, with no squaring of ``B``'s condition number), its singular
    values below ``ε·max(B.shape)·S₀`` taken as zero (``numpy.linalg.lstsq``'s default cut-off;
    Golub & Van Loan §5.5.8, the numerical rank): those directions keep the prior's mean
    (``u = 0``) and its width (``λ = 1``), as in :mod:`.drive_gains`'s truncated-SVD step.
    A dense ``Λ`` then no longer holds the prior's unit eigenvalue either, and
    :func:`_consistent` works in ``Λ``'s whitened coordinates instead.  Fitted residuals,
    noise-free planar_3r rows, priors ×1, ×1e3, ×1e6: 9e-15 to 1.1e-14 N·m, against 8.8e-7,
    8.9 and 1.5e19 N·m by the normal equations.

    Only for rows that over-determine the fit (``over``: more rows than the rank of ``As``).
    Fewer (the online learner's first solves: 9–42 rows of rank as many, 39–78 parameters)
    are fitted exactly by :func:`solve`'s first pass, so that their residual scale at
    rounding says nothing about the noise, and the exact fit it asks for overfits: planar 3R
    with a payload, 18 rows, 39 parameters, 64 prior widths from the truth (held-out rows'
    RMS 16.0, the nominal model's 15.9); UR5, 18 rows, 78 parameters: masses of −0.34 kg.
    Those keep the normal equations, as before this step (bit-identical).  Their first pass
    is past the limit all the same (residual RMS 2.9e7 on that planar 3R, rounding), and
    the re-weighted passes shrink σ back from it to a fit that depends on their count
    (second link 1.57 kg at the default 4, 1.61 at 8, −56 at 12, the truth 1.8; with 9 rows,
    5.4e8 kg at 8): left as it was.  The evidence's σ (MacKay, "Bayesian interpolation",
    1992; held over the passes) was measured in its place and left out: the learner's
    velocity RMS after 2 s, 2.8e-3 against 1.6e-3 rad/s.
    """
    Aw = As * row_w[:, None]
    prec_u = Aw.T @ As + eye  # posterior precision in u-units (≥ I)
    prec_u = 0.5 * (prec_u + prec_u.T)
    lam, vec = np.linalg.eigh(prec_u)  # by eigenvalues: huge row weights make it stiff
    if not over or np.finfo(float).eps * float(lam[-1]) <= NORMAL_EQUATIONS_LIMIT:
        lam = np.maximum(lam, 1.0)
        return prec_u, lam, vec, vec @ ((vec.T @ (Aw.T @ r0)) / lam), False
    sw = np.sqrt(row_w)
    # the whole V (p × p) also when there are fewer rows than parameters
    U, S, Vt = np.linalg.svd(As * sw[:, None], full_matrices=As.shape[0] < As.shape[1])
    k = S.size
    S = np.where(S > np.finfo(float).eps * max(As.shape) * S[0], S, 0.0)
    lam, vec = 1.0 + np.concatenate([S, np.zeros(As.shape[1] - k)]) ** 2, Vt.T
    step = vec[:, :k] @ (S / lam[:k] * (U[:, :k].T @ (r0 * sw)))
    return (vec * lam) @ vec.T, lam, vec, step, True


#: A channel's residual scale is taken as at least this share of the largest channel's
#: (:func:`solve`): a channel fitted to rounding (a noise-free simulation) would otherwise
#: outweigh the others by 1e10.
CHANNEL_SIGMA_FLOOR = 1e-6


def channel_sigma(res: Vector, channel: NDArray[np.intp] | None) -> Vector:
    """Per channel (in the order of ``np.unique(channel)``), ``1.4826 · median |r|`` over its
    rows, at least :data:`CHANNEL_SIGMA_FLOOR` of the largest; one value without channels.
    All ones when every residual is exactly 0 (nothing to weigh the rows by: weighting them
    by ``1/0`` made weights of 1e600 and a NaN fit), so the rows are weighted alike."""
    labels = np.unique(channel) if channel is not None else np.zeros(1, dtype=np.intp)
    lab = channel if channel is not None else np.zeros(res.shape, dtype=np.intp)
    out = np.array([1.4826 * float(np.median(np.abs(res[lab == c]))) for c in labels])
    if not out.max() > 0.0:  # every row fitted exactly
        return np.ones_like(out)
    return np.maximum(out, CHANNEL_SIGMA_FLOOR * float(out.max()))


def _row_sigma(res: Vector, channel: NDArray[np.intp] | None) -> Vector:
    """Per row, the σ of its channel (:func:`channel_sigma`)."""
    per = channel_sigma(res, channel)
    if channel is None:
        return np.full(res.shape, per[0])
    return per[np.searchsorted(np.unique(channel), channel)]


def _is_consistent(reg: MomentumRegressor | PayloadRegressor, theta: Vector) -> bool:
    for k in range(reg.n_inertial // 10):
        J = pseudo_inertia(theta[10 * k : 10 * k + 10])
        if np.linalg.eigvalsh(J)[0] < 0.0 or J[3, 3] <= 0:
            return False
    if np.any(theta[_nonnegative(reg)] < 0):
        return False
    return True


def _nonnegative(reg: MomentumRegressor | PayloadRegressor) -> NDArray[np.intp]:
    """The indices of ``θ`` that must not be negative: friction (not its offset, which does not
    dissipate: :mod:`pinobs.model.friction`) and armature."""
    n0, n = reg.n_inertial, reg.n_joint
    friction = np.concatenate(
        [
            np.arange(n0 + k * n, n0 + (k + 1) * n)
            for k, term in enumerate(reg.friction_terms)
            if term != "friction_offset"
        ]
        or [np.zeros(0, dtype=np.intp)]
    )
    arm = reg.armature_slice
    return np.concatenate([friction, np.arange(arm.start, arm.stop)]).astype(np.intp)


def _pseudo_inertia_basis() -> Vector:
    """``E_i = ∂J/∂π_i`` (10 × 4 × 4) of :func:`pseudo_inertia`, which is linear."""
    return np.array([pseudo_inertia(e) for e in np.eye(10)])


_E = _pseudo_inertia_basis()


def _consistent(
    reg: MomentumRegressor | PayloadRegressor,
    theta: Vector,
    prec_u: Vector,
    s: Vector,
    whiten: tuple[Vector, Vector] | None = None,
) -> Vector:
    """The closest physically consistent ``θ`` in the posterior metric (module docstring).

    ``min_u (u − û)ᵀ Λ (u − û)`` over ``u = (θ − θ₀)/s`` subject to every
    body's ``J(θ) ⪰ 0`` and friction and armature ``≥ 0``: a convex problem (``J`` is
    linear in ``θ``), solved by a log-barrier interior-point method (Boyd &
    Vandenberghe, *Convex Optimization*, 2004, §11.3): Newton steps on
    ``(u − û)ᵀΛ(u − û) − μ (Σ_k log det J_k + Σ_j log f_j)`` (``f``: friction and
    armature) for μ = 1, 0.1, …,
    :data:`MU_END` (``Λ`` scaled to a unit largest eigenvalue; each centring stops
    when the Newton decrement is below ``μ/100``), from a strictly feasible start
    (the nominal model, nudged inside).  Newton steps by a full solve: a
    least-squares solve's cut-off at ``1e-16·λ_max`` dropped the weakly seen
    directions, which are the ones consistency moves, and left the solution
    100–10⁴× off the optimum on a noise-free log (UR5, residual 1.7 against
    4.4e-5).

    ``whiten = (λ, V)`` (``Λ = V diag(λ) Vᵀ``, given when ``ε·λ_max`` passes
    :data:`NORMAL_EQUATIONS_LIMIT`): the same steps in ``x = diag(√λ) Vᵀ u``, where the metric
    is the identity and the barrier's derivatives are ``Tᵀ∇`` and ``Tᵀ∇²T``
    (``T = V diag(1/√λ)``, ``u = T x``): a dense ``Λ`` scaled to a unit largest eigenvalue
    held the weakly seen directions at rounding level, which the barrier (μ down to
    :data:`MU_END`) pushed anywhere (noise-free planar_3r, prior ×1e3: fitted residual 2e4
    N·m), and with its eigenvalues capped where a dense matrix still holds them the fit was
    still off (TIAGo, prior ×1e6: torso 36.5 N·m fitted against 0.71 so).
    """
    if _is_consistent(reg, theta):
        return theta
    theta0 = reg.nominal()
    nb = reg.n_inertial // 10
    fr = _nonnegative(reg)
    u_hat = (theta - theta0) / s
    u: Vector = (_feasible_start(theta0, s, nb, fr) - theta0) / s
    E = [_E * s[10 * k : 10 * k + 10, None, None] for k in range(nb)]  # ∂J_k/∂u
    barrier = functools.partial(_log_barrier, theta0=theta0, s=s, E=E, fr=fr)
    T = np.eye(u.size)
    if whiten is None:
        # the metric scaled to a unit largest eigenvalue, so that μ and the stopping rule are
        # relative: the precision of a nearly noise-free log reaches 1e15 (measured, UR5)
        prec_u = prec_u / float(np.linalg.eigvalsh(prec_u)[-1])
    else:  # x = diag(√λ) Vᵀ u, u = T x: the metric is the identity
        root, vec = np.sqrt(whiten[0]), whiten[1]
        T = vec / root
        barrier = functools.partial(_whitened, barrier=barrier, T=T)
        u_hat, u, prec_u = (vec.T @ u_hat) * root, (vec.T @ u) * root, np.eye(u.size)
    mu = 1.0
    while mu >= MU_END:
        u = _centre(barrier, prec_u, u_hat, u, mu)
        mu *= 0.1
    return theta0 + s * (u if whiten is None else T @ u)


def _whitened(
    x: Vector, *, barrier: Callable[[Vector], tuple[float, Vector, Vector] | None], T: Vector
) -> tuple[float, Vector, Vector] | None:
    """``barrier(T x)`` and its gradient and Hessian in ``x``: ``Tᵀ∇``, ``Tᵀ∇²T``."""
    b = barrier(T @ x)
    if b is None:
        return None
    return b[0], T.T @ b[1], T.T @ b[2] @ T


def _feasible_start(theta0: Vector, s: Vector, nb: int, fr: NDArray[np.intp]) -> Vector:
    """A strictly feasible ``θ`` for :func:`_consistent`: each nominal ``J`` nudged inside,
    friction and armature positive."""
    start = theta0.copy()
    for k in range(nb):
        J0 = pseudo_inertia(theta0[10 * k : 10 * k + 10])
        eps = 1e-6 * max(float(np.max(np.abs(J0))), 1e-9)
        lam_min = float(np.linalg.eigvalsh(J0)[0])
        start[10 * k : 10 * k + 10] = _from_pseudo_inertia(
            J0 + (max(0.0, -lam_min) + eps) * np.eye(4)
        )
    start[fr] = np.maximum(theta0[fr], 0.0) + 1e-6 * s[fr]
    return start


def _log_barrier(
    u: Vector, *, theta0: Vector, s: Vector, E: Sequence[Vector], fr: NDArray[np.intp]
) -> tuple[float, Vector, Vector] | None:
    """``(−Σ_k log det J_k − Σ_j log f_j, gradient, Hessian)`` in ``u`` (``E[k]``: ``∂J_k/∂u``);
    ``None`` outside the feasible set."""
    th = theta0 + s * u
    val, grad, hess = 0.0, np.zeros(u.size), np.zeros((u.size, u.size))
    for k in range(len(E)):
        J = pseudo_inertia(th[10 * k : 10 * k + 10])
        try:
            c = np.linalg.cholesky(J)
        except np.linalg.LinAlgError:
            return None
        val -= 2.0 * float(np.sum(np.log(np.diag(c))))
        Ji = np.linalg.inv(c).T @ np.linalg.inv(c)  # J⁻¹ from the factor (J ≻ 0 here)
        JE = np.einsum("ab,ibc->iac", Ji, E[k])  # J⁻¹ E_i
        sl = slice(10 * k, 10 * k + 10)
        grad[sl] -= np.einsum("iaa->i", JE)  # −tr(J⁻¹E_i)
        hess[sl, sl] += np.einsum("iab,jba->ij", JE, JE)  # tr(J⁻¹E_i J⁻¹E_j)
    if fr.size:
        f = th[fr]
        if np.any(f <= 0):
            return None
        val -= float(np.sum(np.log(f)))
        grad[fr] -= s[fr] / f
        hess[fr, fr] += (s[fr] / f) ** 2
    return val, grad, hess


def _centre(
    barrier: Callable[[Vector], tuple[float, Vector, Vector] | None],
    prec_u: Vector,
    u_hat: Vector,
    u: Vector,
    mu: float,
) -> Vector:
    """Damped Newton steps on ``(u − û)ᵀΛ(u − û) + μ·barrier(u)`` from the strictly feasible
    ``u`` until the Newton decrement is below ``μ/100`` (at most 50; :func:`_consistent`)."""

    def objective(u: Vector) -> float | None:
        b = barrier(u)
        if b is None:
            return None
        d = u - u_hat
        return float(d @ prec_u @ d) + mu * b[0]

    for _ in range(50):
        b = barrier(u)
        assert b is not None  # u stays strictly feasible by the line search
        d = u - u_hat
        grad = 2.0 * prec_u @ d + mu * b[1]
        hess = 2.0 * prec_u + mu * b[2]
        try:  # not lstsq: its cut-off would drop the weak directions consistency must move
            step = -np.linalg.solve(hess, grad)
        except np.linalg.LinAlgError:
            step = -np.linalg.lstsq(hess, grad, rcond=None)[0]
        decrement = float(-grad @ step)
        if not decrement >= 1e-2 * mu:  # centred (or a non-finite step: keep u)
            break
        f0 = objective(u)
        assert f0 is not None
        a = 1.0
        while a > 1e-12:
            f1 = objective(u + a * step)
            if f1 is not None and f1 <= f0 - 0.25 * a * decrement:
                break
            a *= 0.5
        else:
            break
        u = u + a * step
    return u
