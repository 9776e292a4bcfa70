"""Drive gains (motor current → joint torque) identified from a known payload
(:func:`identify_drive_gains`; Mamedov et al. 2020, their ``estimate_drive_gains.m``;
Gautier & Briot 2014).

A drive's torque is its current times a gain, ``τ_j = K_j i_j`` [N·m/A] (the gear ratio
times the motor constant: :class:`pinobs.io.Drives`).  With ``K`` unknown, a log of
currents fixes the robot's parameters only up to a common scale per joint: every row of
the momentum form (MATH §9; :class:`MomentumRegressor` weighted by ``"torque"``, each
window's mean) reads::

    Y(q, v) θ = K ⊙ ī                                                            (1)

``ī`` the window's mean current, ``θ`` the robot's parameters in N·m (inertials,
viscous + Coulomb friction, a rotor inertia per joint, a torque offset).  (1) is
homogeneous in ``(θ, K)``.  A run with a load of known mass ``m`` on a body adds the load's
ten parameters ``φ = (m, m·c, I)`` (at the body's frame, :class:`PayloadRegressor`'s ``T``,
``Y_b`` the columns of the body's joint)::

    Y(q, v) θ + Y_b(q, v) T φ = K ⊙ ī                                             (2)

and the known ``m`` fixes the scale.  The unloaded rows (1) and the loaded rows (2) are
stacked with the mass's column moved to the right-hand side and the other nine of ``φ``
unknown (Mamedov et al. 2020, ``estimate_drive_gains.m``, its ``'OLS'`` method; Gautier &
Briot 2014, "Global identification of joint drive gains and dynamic parameters of robots",
ASME J. Dyn. Sys., Meas., Control 136(5), the known-payload form)::

    ⎡ Y_u   0        −diag(ī_u) ⎤ ⎡ θ  ⎤   ⎡ 0              ⎤
    ⎣ Y_l   Y_l,φ′   −diag(ī_l) ⎦ ⎢ φ′ ⎥ = ⎣ −m · Y_l,m      ⎦                    (3)
                                  ⎣ K  ⎦

(``φ′`` = ``φ`` without ``m``, ``Y_l,m`` the loaded rows' mass column, ``diag(ī)`` each row's
mean current in its joint's gain column).  Their code regresses accelerations of filtered
velocities; here the rows are the momentum form's integrals (no acceleration), with the
same unknowns.

**Two estimators.**  ``method="ols"`` solves (3) as it stands, by least squares in
torque (their ``'OLS'``).  Its unloaded rows are homogeneous: any equation error (friction
the law does not capture, the velocity estimate's error) costs ``∝ K²`` there, so the fit
shrinks the gains wherever the load's known mass pins them weakly, and a gain whose joint
the mass barely loads (a wrist whose axis passes near the load) can collapse towards 0
with its parameters (measured on the real UR10e's 15harm pair: wrists 2 and 3 at 0.016 and
0.011 N·m/A, published 9.48 and 10.12; on its 14harm pair the shoulder pan, which the load
loads through its inertia alone, at 2.52, published 10.0).  ``method="current"`` (the default) takes the residual in the measured
currents instead, ``β_j = 1 / K_j``::

    ī_j = β_j · (Y θ + Y_b T φ)_j     (unloaded: φ = 0; loaded: m known)             (4)

bilinear in ``(θ, φ′)`` and ``β``: a zero gain no longer fits the currents for free.  It
is solved by Gauss–Newton from one common gain for every joint (the median of the
``"ols"`` gains, so that no joint starts collapsed), until the gains move by less than
:data:`GAIN_STEP_TOL` of themselves.  Measured on both real UR10e pairs (with the channel weights, without Huber's), Gauss–Newton
reached the same gains to four digits started from the published ones and from 5 N·m/A on
every joint.  On a simulated UR5 (``tests/model/test_drive_gains.py``: σ = 1e-4 rad, current
noise 0.05 A against wrist 3's current RMS of 0.011 A) wrist 3's gain was +1.1 % ± 3.1 % off
by ``"current"``, −11.9 % by ``"ols"`` (the torque-side fit shrinking it); at 0.01 A both
within 3 % there, the other joints within 0.5 %.  The standard deviations assume independent
windows: on the UR10e the two pairs' gains differ by more than they say (the pan's 10.9 ± 0.4
and 13.5 ± 0.3; the others within 2 %: ``benchmarks/drive_gains.md``).

**Solve.**  The columns are scaled to unit norm, each joint's rows divided by its own
residual scale ``σ_j`` (``1.4826 · median |r|``, re-estimated at every pass: feasible
generalised least squares) and re-weighted by Huber's loss (as :func:`solve`); each linear
step is the singular value decomposition truncated at :data:`GAIN_RANK_TOL`: the
combinations of ``θ`` the logs do not fix (the base parameters' complement) take their
minimum-norm value, and a gain is *determined* when no such combination moves it (its
share of the null space below :data:`GAIN_NULL_TOL`), else refused.  No prior: the scale
comes from ``m`` alone.  The same friction, rotors and offsets are taken in both runs (as
Mamedov et al.'s).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import DimensionError, GainError, IdentificationError, OptionError
from pinobs.model.identification.leastsquares import channel_sigma
from pinobs.model.identification.payload import PayloadRegressor
from pinobs.model.identification.regressor import (
    SUFFIXES,
    MomentumRegressor,
    check_options,
    check_torque,
)
from pinobs.model.identification.rows import fill_short_gaps, fit_rows, log_arrays
from pinobs.model.robot import Robot, Vector

__all__ = [
    "GAIN_MAX_STEPS",
    "GAIN_METHODS",
    "GAIN_NULL_TOL",
    "GAIN_RANK_TOL",
    "GAIN_STEP_TOL",
    "DriveGains",
    "identify_drive_gains",
]

#: Singular values of the scaled, weighted rows of (3) below this share of the largest are
#: taken as zero: the combinations the logs do not determine.
GAIN_RANK_TOL = 1e-9

#: Gauss–Newton of ``method="current"`` stops when no gain moves by more than this share of
#: itself (or after :data:`GAIN_MAX_STEPS` steps, with a warning in the report).
GAIN_STEP_TOL, GAIN_MAX_STEPS = 1e-10, 100

#: The estimators of :func:`identify_drive_gains` (module docstring).
GAIN_METHODS = ("current", "ols")

#: A gain is determined when its component in every undetermined combination (the unit
#: null-space vectors, in column-scaled units) is below this.
GAIN_NULL_TOL = 1e-6


@dataclass(frozen=True)
class DriveGains:
    """What :func:`identify_drive_gains` returns.

    Attributes:
        gains: ``K`` per joint [N·m/A, or N/A]: ``τ = K ⊙ i``.
        std: their standard deviations (from the weighted rows' residual scales).
        joints: the joints, in the order of ``gains``.
        report: ``load`` (its mass [kg] as given, centre of mass [m, in the body's frame]
            and the nine identified parameters), ``rank``, ``n_parameters``, ``condition``
            (of the scaled, weighted rows of the last linear step on the determined
            combinations), ``rows`` (unloaded, loaded), per joint ``residual_unloaded`` /
            ``residual_loaded`` (RMS of the windows' mean-torque residual [N·m], the
            currents' times the gains with ``method="current"``), ``channel_sigma`` (the
            residual scales: [A] with ``method="current"``, [N·m] with ``"ols"``),
            ``method``, ``steps`` (Gauss–Newton's) and ``warnings``.
    """

    gains: Vector
    std: Vector
    joints: tuple[str, ...]
    report: dict[str, Any]


def identify_drive_gains(
    robot: Robot,
    unloaded: Any,
    loaded: Any,
    *,
    body: str,
    load_mass: float,
    method: str = "current",
    friction: bool | str = True,
    offset: bool = True,
    window: float = 0.1,
    torque: str = "held",
    paths: tuple[Any, Any] | None = None,
    irls: int = 4,
    huber: float = 1.345,
) -> DriveGains:
    """Each joint's drive gain ``K_j`` [N·m/A] from an unloaded and a loaded run, the load's
    mass known (module docstring: (3), solved by ``method`` ``"current"`` (4) or ``"ols"``).

    Args:
        robot: the robot (its structure: every joint one coordinate; its parameters are
            identified afresh, not used).
        unloaded, loaded: ``(t, q, current)`` arrays ``(N,)``, ``(N, nq)``, ``(N, nv)`` [s,
            rad, A], or a mapping or object with ``t``, ``q`` and ``current``.
        body: the body or frame the load is fixed to (its frame: the load's ``c`` and ``I``).
        load_mass: the load's mass [kg].
        method: ``"current"`` (the residual in the currents, (4)) or ``"ols"`` ((3) by
            least squares in torque, Mamedov et al.'s ``'OLS'``).
        friction, offset: as :class:`MomentumRegressor`'s (the rotor inertias are always
            identified: in N·m they are unknown too).
        window: integration window [s].
        torque: ``"held"`` or ``"sampled"``: how the currents were taken (for ``∫ i dt``).
        paths: ``((q, v), (q, v))`` of the two runs instead of their Savitzky–Golay fits.
        irls, huber: robust passes and Huber's threshold (as :func:`solve`).

    Raises:
        GainError: no load mass, or one that is not a finite mass > 0.
        OptionError: a body that is not in the model (naming its bodies); an unknown method.
        IdentificationError: a log without currents; gains the logs do not determine.
        DimensionError: a joint of several coordinates; logs that do not fit the robot.
    """
    _check(robot, load_mass, method, friction, offset, window, torque)
    load = PayloadRegressor(robot, body)  # (refuses a body not in the model, by name)
    reg = MomentumRegressor(
        robot, friction=friction, offset=offset, armature=True, weighting="torque"
    )
    rows = [
        _rows(reg, log, name, None if paths is None else paths[k], window, torque)
        for k, (name, log) in enumerate(
            zip(("unloaded", "loaded"), (unloaded, loaded), strict=True)
        )
    ]
    nv, m = robot.nv, float(load_mass)
    (A_u, i_u), (A_l, i_l) = rows
    P = A_l[:, 10 * (load.joint - 1) : 10 * load.joint] @ load.placement_map(load.placement)
    # (3): Z w + c = K ⊙ ī, w = (θ, φ′), c the known mass's torque
    Z = np.block([[A_u, np.zeros((A_u.shape[0], 9))], [A_l, P[:, 1:]]])
    c = np.concatenate([np.zeros(A_u.shape[0]), m * P[:, 0]])
    current = np.concatenate([i_u, i_l])
    channel = np.tile(np.arange(nv), Z.shape[0] // nv)
    G = np.zeros((Z.shape[0], nv))
    G[np.arange(Z.shape[0]), channel] = current
    w, gains, std, fit = _solve(np.hstack([Z, -G]), -c, channel, irls, huber)
    _check_determined(robot, fit["null_share"][Z.shape[1] :], body, m)
    if method == "current":
        w, gains, std, fit = _output_error(Z, c, current, channel, gains, irls, huber)
        _check_determined(robot, fit["null_share"][Z.shape[1] :], body, m)
    res = Z @ w + c - gains[channel] * current  # [N·m]
    report = _report(res, w[reg.size :], fit, (body, m, method, torque), A_u.shape[0], nv)
    return DriveGains(gains=gains, std=std, joints=tuple(robot.joint_names), report=report)


def _report(
    res: Vector, phi9: Vector, fit: dict[str, Any], given: tuple, n_u: int, nv: int
) -> dict[str, Any]:
    """:class:`DriveGains`' report: ``res`` the rows' residuals [N·m] (the unloaded run's
    first ``n_u``), ``phi9`` the load's nine identified parameters, ``fit`` the solve's,
    ``given`` the body, load mass, method and torque sampling."""
    body, m, method, torque = given
    phi = np.concatenate([[m], phi9])
    return {
        "load": {
            "body": body,
            "mass": m,
            "com": (phi[1:4] / m).tolist(),
            "parameters": dict(zip(SUFFIXES, phi.tolist(), strict=True)),
        },
        "rank": fit["rank"],
        "n_parameters": int(fit["null_share"].size),
        "condition": fit["condition"],
        "rows": {"unloaded": n_u, "loaded": int(res.size - n_u)},
        "residual_unloaded": _rms(res[:n_u], nv),
        "residual_loaded": _rms(res[n_u:], nv),
        "channel_sigma": fit["sigma"].tolist(),
        "method": method,
        "steps": fit.get("steps", 0),
        "warnings": fit.get("warnings", []),
        "torque": torque,
    }


def _check_determined(robot: Robot, null_share: Vector, body: str, m: float) -> None:
    """Refuse gains with a share in the combinations the logs do not determine.

    Raises:
        IdentificationError: naming those joints.
    """
    loose = [robot.joint_names[j] for j in np.flatnonzero(null_share > 0)]
    if loose:
        raise IdentificationError(
            f"the logs do not determine the drive gains of {loose}: the loaded run must move "
            f"those joints and the load must change their torques (a load on {body!r} of "
            f"{m:g} kg; excite them, or put it farther from their axes)"
        )


def _check(
    robot: Robot,
    load_mass: object,
    method: object,
    friction: object,
    offset: object,
    window: object,
    torque: object,
) -> None:
    """:func:`identify_drive_gains`' options (named in the error)."""
    if isinstance(load_mass, bool) or not isinstance(load_mass, (int, float, np.number)):
        raise GainError(f"load_mass={load_mass!r}: give the load's mass [kg], a number > 0")
    if not 0.0 < float(load_mass) < math.inf:
        raise GainError(f"load_mass={load_mass!r} [kg]: give a finite mass > 0")
    if method not in GAIN_METHODS:
        raise OptionError(f"method={method!r}: give one of {', '.join(GAIN_METHODS)}")
    check_options(friction, offset, True, 0.0, window, 10.0)
    check_torque(torque)
    many = [j.name for j in robot.joints if j.nv != 1]
    if many:
        raise DimensionError(
            f"drive gains are per one-coordinate joint; {robot.name!r} has joints {many} of "
            "several coordinates (a floating base?)"
        )


def _currents(log: Any, name: str) -> tuple[Any, Any, Any]:
    """``(t, q, current)`` of a run (:func:`identify_drive_gains`'s forms).

    Raises:
        IdentificationError: a log with no currents (torques only, or nothing).
    """
    if isinstance(log, (tuple, list)) and len(log) == 3:
        return log[0], log[1], log[2]
    if isinstance(log, Mapping) and "current" in log:
        return log["t"], log["q"], log["current"]
    if not isinstance(log, Mapping) and hasattr(log, "current"):
        return log.t, log.q, log.current
    raise IdentificationError(
        f"the {name} log has no motor currents: drive gains need (t, q, current) arrays or a "
        f"mapping or object with 't', 'q', 'current' (a {type(log).__name__}; torques at an "
        "unknown scale can be given as the current: the gains are then that scale)"
    )


def _rows(
    reg: MomentumRegressor,
    log: Any,
    name: str,
    path: Any,
    window: float,
    torque: str,
) -> tuple[Vector, Vector]:
    """``(Y, ī)`` of a run: its rows (every window of every contiguous stretch) and each
    row's mean current.  Every joint's rotor inertia has a column, so no known torque is
    moved to the right-hand side and the rows' ``y`` is ``ī``."""
    t, q, i = _currents(log, name)
    t, q, i = log_arrays(reg.robot, (t, q, i), warn_filled=False)
    q, i, _ = fill_short_gaps(reg.robot, t, q, i)
    est = None if path is None else (np.asarray(path[0], float), np.asarray(path[1], float))
    if est is not None and (est[0].shape != q.shape or est[1].shape != i.shape):
        raise DimensionError(
            f"the {name} path's shapes {est[0].shape}, {est[1].shape} do not fit its log "
            f"({q.shape}, {i.shape})"
        )
    everything = np.ones(t.shape[0], dtype=bool)
    A, y, _ = fit_rows(reg, (t, q, i), everything, window=window, path=est, torque=torque)
    return A, y


def _weights(res: Vector, channel: NDArray[np.intp], huber: float | None) -> tuple[Vector, Vector]:
    """``(σ per channel, row weights)``: ``σ_j = 1.4826 · median |r|`` over channel ``j``'s
    rows (:func:`~pinobs.model.identification.leastsquares.channel_sigma`: at least
    ``CHANNEL_SIGMA_FLOOR`` of the largest; all 1 when every residual is 0), each row
    ``1/σ²`` times its Huber weight (none when ``huber`` is ``None``)."""
    labels = np.unique(channel)
    sigma = channel_sigma(res, channel)
    s_row = sigma[np.searchsorted(labels, channel)]
    if huber is None:
        return sigma, 1.0 / s_row**2
    u = np.abs(res) / s_row
    return sigma, np.where(u <= huber, 1.0, huber / np.maximum(u, 1e-300)) / s_row**2


def _step(J: Vector, r: Vector, row_w: Vector) -> tuple[Vector, Vector, dict[str, Any]]:
    """``(δ, std, fit)``: the truncated-SVD least squares ``J δ ≈ r`` (columns scaled to unit
    norm, rows weighted by ``row_w``), its standard deviations and ``fit``'s ``rank``,
    ``condition`` and per column ``null_share`` (0 when determined)."""
    norms = np.linalg.norm(J, axis=0)
    scale = 1.0 / np.where(norms > 0.0, norms, 1.0)
    sw = np.sqrt(row_w)
    U, S, Vt = np.linalg.svd(J * scale * sw[:, None], full_matrices=False)
    rank = int(np.sum(S > GAIN_RANK_TOL * S[0])) if S.size and S[0] > 0 else 0
    if rank == 0:
        raise IdentificationError("the rows are zero: the logs never move the robot")
    d = Vt[:rank].T @ ((U[:, :rank].T @ (r * sw)) / S[:rank])
    cov = (Vt[:rank].T / S[:rank] ** 2) @ Vt[:rank]
    null = np.linalg.norm(Vt[rank:], axis=0) if rank < Vt.shape[0] else np.zeros(J.shape[1])
    fit = {
        "rank": rank,
        "condition": float(S[0] / S[rank - 1]),
        "null_share": np.where(null > GAIN_NULL_TOL, null, 0.0),
    }
    return scale * d, scale * np.sqrt(np.diag(cov)), fit


def _solve(
    X: Vector, b: Vector, channel: NDArray[np.intp], irls: int, huber: float
) -> tuple[Vector, Vector, Vector, dict[str, Any]]:
    """``(w, K, std(K), fit)`` of (3), ``X = [Z, −diag(ī)]``, ``b = −c``, by least squares in
    torque: unweighted, then by channel, then Huber's ``irls`` passes (module docstring)."""
    nv = int(np.unique(channel).size)
    row_w: Vector = np.ones(X.shape[0])
    sigma: Vector = np.ones(nv)
    for it in range(irls + 2):
        x, std, fit = _step(X, b, row_w)
        if it == irls + 1:
            break
        sigma, row_w = _weights(X @ x - b, channel, huber if it > 0 else None)
    fit["sigma"] = sigma
    return x[:-nv], x[-nv:], std[-nv:], fit


def _output_error(
    Z: Vector,
    c: Vector,
    current: Vector,
    channel: NDArray[np.intp],
    start: Vector,
    irls: int,
    huber: float,
) -> tuple[Vector, Vector, Vector, dict[str, Any]]:
    """``(w, K, std(K), fit)`` of (4) by Gauss–Newton (module docstring): ``r = ī −
    β_ch (Z w + c)``, ``∂r/∂w = −β_ch Z``, ``∂r/∂β_j = −(Z w + c)`` on joint ``j``'s rows;
    from one common gain, the median of ``start`` (the ``"ols"`` gains)."""
    nv = int(np.unique(channel).size)
    rows = np.arange(Z.shape[0])
    positive = start[start > 0]
    beta = np.full(nv, 1.0 / float(np.median(positive)) if positive.size else 1.0)
    w = _step(Z, current / beta[channel] - c, np.ones(Z.shape[0]))[0]
    warnings: list[str] = []
    for it in range(GAIN_MAX_STEPS):
        s = Z @ w + c
        r = current - beta[channel] * s
        sigma, row_w = _weights(r, channel, huber if it >= min(irls, 1) else None)
        J = np.zeros((Z.shape[0], Z.shape[1] + nv))
        J[:, : Z.shape[1]] = beta[channel][:, None] * Z
        J[rows, Z.shape[1] + channel] = s
        d, std, fit = _step(J, r, row_w)
        w, beta = w + d[: Z.shape[1]], beta + d[Z.shape[1] :]
        if np.all(np.abs(d[Z.shape[1] :]) <= GAIN_STEP_TOL * np.abs(beta)):
            break
    else:
        warnings.append(
            f"Gauss–Newton did not settle in {GAIN_MAX_STEPS} steps: the last moved the gains "
            f"by up to {float(np.max(np.abs(d[Z.shape[1] :] / beta))):.3g} of themselves"
        )
    fit |= {"sigma": sigma, "steps": it + 1, "warnings": warnings}
    return w, 1.0 / beta, std[Z.shape[1] :] / beta**2, fit  # std(1/β) = std(β)/β²


def _rms(res: Vector, nv: int) -> list[float]:
    """Per joint, the RMS of its rows' residuals."""
    return np.sqrt(np.mean(res.reshape(-1, nv) ** 2, axis=0)).tolist()
