"""The offline identification of a robot from a log (:func:`identify`), step by step: the
log read and checked, the rows of its fitted part, the friction law's smoothing searched,
the solve checked, and the report (MATH §9; the package docstring of
:mod:`pinobs.model.identification`).

**The options of** :func:`identify` **in full** (its docstring lists them in short):

- ``log``: anything with arrays ``t`` ``(N,)``, ``q`` ``(N, nq)``, ``tau`` ``(N, nv)`` (a
  ``Log``), a simulation ``Result`` (its measured ``q_meas`` is used, never the truth), or a
  tuple ``(t, q, tau)``.  Its intervals are used as they are: dropped samples (rows missing
  from a fixed-rate loop's log) and irregular sampling (:mod:`pinobs.model.sampling`).
  Short runs of NaN rows are filled (:func:`fill_short_gaps`), longer ones are gaps;
  windows never straddle a gap, nor an interval longer than
  :data:`~pinobs.model.sampling.SPLIT_GAP_PERIODS` median intervals.
- ``friction``: ``True`` the URDF's viscous + Coulomb law (``v_s`` fixed at 0.01 rad/s), or a
  law of :data:`~pinobs.model.friction.FRICTION_LAWS` (``"offset-sigmoid"``,
  ``"stribeck"``, ``"asymmetric"``), whose coefficients are fitted linearly and whose
  smoothing velocity ``v_s`` (and Stribeck ``v_st``) per joint is chosen on a grid by
  cross-validation over the fitted part, 0.01 rad/s kept unless another predicts better by
  more than one standard error (:func:`pinobs.model.friction_fit.search_smoothing`);
  the law goes with the calibrated robot (and its sidecar when saved).  ``"offset-sigmoid"``
  carries its own offset ``F_0`` (part of the robot's friction; not dissipative): give
  ``offset=False`` with it.
- ``armature``: a rotor inertia per actuated joint (``model.armature``, added to ``M``'s
  diagonal; prior mean the model's own, usually 0, width :data:`PRIOR_ARMATURE`), kept only
  where the data determine it (:func:`~pinobs.model.identification.armature.determined_armature`:
  a step from the model's own beyond :data:`ARMATURE_SIGMAS` standard deviations and
  :data:`ARMATURE_SHARE` of the joint's inertia), the model's own elsewhere.
- ``path``: ``(N, nq)`` [rad, m] and ``(N, nv)`` [rad/s, m/s], used in the regressor instead
  of the Savitzky–Golay fit (:func:`smooth_path`) of the measured positions
  (``pinobs.identify`` passes a model-based smoother's).
- ``torque``: ``"held"`` (zero-order hold: ``pinobs.simulate``, commanded torques) or
  ``"sampled"`` (at the sample instants: ``pinobs excite``, a torque sensor); the wrong one
  biases the fit ∝ 1/rate (package docstring).
- ``weighting``: ``"inertia"`` (default): the rows weighted by ``M₀⁻¹``
  (acceleration-like); ``"torque"``: each window's rows are its mean torque residual [N·m,
  N], each torque channel weighted by its own residual scale (re-estimated robustly at each
  pass, ``report["torque_sigma"]``) (package docstring, "Weighting": which wins where).
- ``exclude``: a torque that is not measured, or mostly zero, is refused unless excluded
  (:data:`ZERO_TORQUE_SHARE`); the excluded joints' parameters stay near nominal unless
  other channels see them.  With ``weighting="inertia"`` the kept rows are weighted by the
  kept joints' block of ``M₀``, inverted (the excluded joints held).
- ``payload``: only the ten inertial parameters of a load rigidly attached to the body or
  frame named are identified (:func:`identify_payload`), ``robot`` taken as calibrated (its
  inertials, friction, armature fixed: ``friction``, ``offset``, ``armature`` and
  ``max_condition`` do not apply; a poorly excited load is said in ``warnings``).
- ``smoothing``: the same ``v_s`` for every joint, instead of its search (a Stribeck law's
  ``v_st`` is still searched); ``friction=True``'s is 0.01 unless given.
- ``smoothing_minimum``: the searched ``v_s`` (and ``v_st``) at the cross-validation's
  minimum instead of the one-standard-error rule's choice: for the law a model-based
  smoother runs on (``pinobs.identify``'s first pass: :mod:`pinobs.calibration`, "The
  friction law's smoothing velocity").

The report (:class:`~pinobs.model.identification.result.Report`, read as a mapping too):
per coordinate the weighted rows' residual before and after, on the fitted part and the
held-out end, the held-out torques' in N·m, the share of the torques left unexplained
against what noise alone would leave, the condition number, rank and unexcited parameters,
the ``warnings`` (:func:`fit_warnings`) and the ``observer_options`` to run ``ekf`` with on
the calibrated model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import GainError, IdentificationError
from pinobs.model.friction_fit import (
    candidate_columns,
    search_candidates,
    search_smoothing,
    widened,
)
from pinobs.model.identification.armature import determined_armature, kept_armature_weights
from pinobs.model.identification.diagnostics import (
    OUTLIER_SHARE,
    ROWS_PER_COMBINATION,
    STILL_RANGE,
    UNEXPLAINED_WARN,
    check_zero_torques,
    fit_report,
    fit_warnings,
    motion_spans,
    not_excited_message,
    unexplained_shares,
)
from pinobs.model.identification.leastsquares import MAX_CONDITION, Solution, solve
from pinobs.model.identification.payload import identify_payload
from pinobs.model.identification.regressor import (
    MomentumRegressor,
    check_options,
    check_torque,
    check_weighting,
    coordinate_names,
    excluded_coordinates,
)
from pinobs.model.identification.result import Identification, ParameterSet, Report
from pinobs.model.identification.rows import (
    fit_rows,
    holdout_in_newton_metres,
    holdout_rows,
    read_fit_log,
)
from pinobs.model.noise import robust_rms
from pinobs.model.robot import Robot, Vector

__all__ = ["identify"]


def identify(
    robot: Robot,
    log: Any,
    *,
    friction: bool | str = True,
    offset: bool = True,
    armature: bool = True,
    holdout: float = 0.2,
    window: float = 0.1,
    max_condition: float = MAX_CONDITION,
    path: tuple[ArrayLike, ArrayLike] | None = None,
    torque: str = "held",
    weighting: str = "inertia",
    exclude: Sequence[str] = (),
    payload: str | None = None,
    smoothing: float | None = None,
    weight_model: Robot | None = None,
    smoothing_minimum: bool = False,
) -> Identification:
    """Identify ``robot``'s dynamic parameters from a log (options, report: module docstring).

    Args:
        robot: the nominal model (the prior).
        log: ``(t, q, tau)``: a tuple, a ``Log`` or a simulation ``Result`` (its ``q_meas``).
        friction, offset: identify joint friction (``True``: viscous + Coulomb, or a law of
            :data:`~pinobs.model.friction.FRICTION_LAWS`) and a torque offset.
        armature: identify a rotor inertia per actuated joint where the data determine it;
            ``False`` keeps the model's.
        holdout: fraction of the log (its end) kept out of the fit, to report the error on.
        window: integration window [s].
        max_condition: refuse when the base regressor is worse conditioned.
        path: estimated ``(q, v)`` at every sample, instead of a Savitzky–Golay fit of ``q``.
        torque: ``"held"`` (zero-order hold) or ``"sampled"`` (at the sample instants).
        weighting: ``"inertia"`` (rows weighted by ``M₀⁻¹``) or ``"torque"`` (by channel).
        exclude: names of joints whose torque channel is left out of the fit.
        payload: a body or frame name: identify only a load rigidly attached to it.
        smoothing: the friction law's smoothing velocity [rad/s] instead of its search.
        weight_model: the robot whose ``M⁻¹`` weights the rows (``None``: package docstring).
        smoothing_minimum: ``v_s`` at the CV minimum, not the one-SE rule's (a smoother's law).

    Raises:
        IdentificationError: no torques, too short, never moves, or above ``max_condition``.
    """
    check_options(friction, offset, armature, holdout, window, max_condition)
    check_torque(torque)
    check_weighting(weighting)
    if payload is not None:
        opts: dict[str, Any] = {
            "holdout": holdout,
            "window": window,
            "path": path,
            "torque": torque,
        }
        return identify_payload(robot, log, payload, exclude=exclude, weighting=weighting, **opts)
    excluded = excluded_coordinates(robot, exclude)
    t, q, tau, filled, est = read_fit_log(robot, log, path)
    laws: dict[str, Any] = {"friction": friction, "offset": offset, "armature": armature}
    laws |= {"weighting": weighting, "exclude": exclude, "weight_model": weight_model}
    while True:  # inertia weighting: again on the armature the first stage fitted (FGLS)
        reg, cands, rows_reg = _regressors(robot, laws, smoothing)
        split = _fit_end(t, window, holdout)
        fit = t <= split
        rows: dict[str, Any] = {"window": window, "path": est, "torque": torque}
        A, y, ends = fit_rows(rows_reg, (t, q, tau), fit, **rows)
        _check_moves(robot, t[fit], q[fit])
        check_zero_torques(robot, tau, excluded)
        reg, A, channel, used_rows, searched, sol = _search_and_solve(
            reg, cands, A, y, laws, minimum=smoothing_minimum
        )
        first = laws["armature"] is True  # the rotors tested on the fit with all of them
        if not _next_stage(reg, sol, laws, first=first, given=weight_model is not None):
            break
    too_few = _check_solution(
        reg, sol, (A, used_rows), (t[fit], q[fit]), excluded, window, holdout, max_condition
    )
    fitted = {"A": A, "y": y, "ends": ends, "channel": channel[used_rows], "fit": fit}
    info = {"torque": torque, "fit_end": split, "filled_rows": filled, "holdout": holdout}
    report = _assess(reg, sol, (t, q, tau), fitted, excluded, laws, rows, info, searched)
    report["warnings"] = fit_warnings(report) + ([] if too_few is None else [too_few])
    return _result(reg, sol, report)


def _next_stage(
    reg: MomentumRegressor, sol: Solution, laws: dict[str, Any], *, first: bool, given: bool
) -> bool:
    """Whether :func:`identify` fits again, ``laws`` set for that fit: when ``first`` (the fit
    with every rotor), without the rotor inertias ``sol`` does not determine
    (:func:`determined_armature`; the model's own taken, the rows weighted by the nominal
    model with the kept ones unless the weights' model is ``given``; tested once: a refit
    moves the others, and testing them again dropped the real TX40's rotors one by one, its
    joint 2's held-out residual 6.6 → 11 N·m), else the second stage of the inertia
    weighting (package docstring, "Weighting")."""
    kept = determined_armature(reg, sol) if first else reg.armature_joints
    if kept != reg.armature_joints:
        laws["armature"] = kept or False
        if not given:
            laws["weight_model"] = kept_armature_weights(reg, sol.theta, kept) if kept else None
        return True
    if laws["weight_model"] is not None or not reg.armature_weighted:
        return False
    laws["weight_model"] = reg.armature_weights(sol.theta)
    return True


def _regressors(
    robot: Robot, laws: dict[str, Any], smoothing: float | None
) -> tuple[MomentumRegressor, list[tuple[float, float]], MomentumRegressor]:
    """The regressor of ``laws`` (:class:`MomentumRegressor`'s options), the friction law's
    smoothing candidates (none unless its smoothing velocity is searched) and the regressor
    whose rows carry every candidate's columns
    (:func:`~pinobs.model.friction_fit.widened`).

    Raises:
        GainError: a ``smoothing`` that is not a finite velocity > 0 (nor ``None``).
    """
    _check_smoothing(smoothing)
    reg = MomentumRegressor(robot, **laws, smoothing=smoothing)
    # a law with its smoothing velocity identified: rows of every candidate's columns
    cands = (
        search_candidates(reg.friction_law, smoothing)
        if reg.friction_law not in (None, "viscous-coulomb")
        else []
    )
    return reg, cands, (widened(reg, cands) if cands else reg)


def _result(reg: MomentumRegressor, sol: Solution, report: Report) -> Identification:
    """The :class:`Identification` of ``sol``: the calibrated robot, the parameters, the
    offset and ``report``."""
    params = ParameterSet(
        names=reg.names, values=sol.theta, std=sol.std, nominal=reg.nominal(), excited=sol.excited
    )
    calibrated = reg.with_parameters(sol.theta, name=f"{reg.robot.name}+id")
    return Identification(
        robot=calibrated,
        parameters=params,
        offset=reg.offsets(sol.theta),
        report=report,
        regressor=reg,
    )


def _check_smoothing(smoothing: object) -> None:
    if smoothing is not None and not (
        isinstance(smoothing, int | float) and 0.0 < smoothing < math.inf
    ):
        raise GainError(f"smoothing={smoothing!r} [rad/s]: give a finite velocity > 0 or None")


def _fit_end(t: Vector, window: float, holdout: float) -> float:
    """The last time [s] of the fitted part (the rest, ``holdout`` of the span, held out).

    Raises:
        IdentificationError: a log shorter than four windows, or sampled too coarsely for
            them (times in milliseconds).
    """
    finite = np.isfinite(t)
    t_end = float(np.max(t[finite])) if finite.any() else 0.0
    t_start = float(np.min(t[finite])) if finite.any() else 0.0
    if t_end - t_start < 4 * window:
        raise IdentificationError(
            f"the log spans {t_end - t_start:.3g} s; identification needs at least "
            f"{4 * window:.3g} s (and a few seconds of rich motion to be useful)"
        )
    h = float(np.median(np.diff(t[finite]))) if finite.sum() > 1 else math.nan
    if h > window / 4:
        raise IdentificationError(
            f"the log's median sample interval is {h:.3g} s, too coarse for windows of "
            f"{window:g} s (four samples at least); if its times are in milliseconds, give "
            "seconds (t / 1000), else a longer window"
        )
    return t_end - holdout * (t_end - t_start)


def _check_moves(robot: Robot, t: Vector, q: Vector) -> None:
    """Refuse a fitted part where no coordinate moves (:func:`motion_spans`)."""
    span, still = motion_spans(robot, t, q)
    if still.all():
        raise IdentificationError(
            "the robot never moves in this log: nothing to identify (largest range of motion "
            f"{float(span.max()):.3g} rad or m, within {STILL_RANGE:g} or ten times the noise)"
        )


def _search_and_solve(
    reg: MomentumRegressor,
    cands: list[tuple[float, float]],
    A: Vector,
    y: Vector,
    laws: dict,
    *,
    minimum: bool = False,
) -> tuple[
    MomentumRegressor, Vector, NDArray[np.intp], NDArray[np.bool_], dict[str, Any], Solution
]:
    """The fit of the rows ``(A, y)``: the friction law's smoothing searched among ``cands``
    (none: not searched; at the least ``CV`` with ``minimum``:
    :func:`~pinobs.model.friction_fit.search_smoothing`), then :func:`solve` on the rows of
    the channels not excluded, each channel by its own scale with ``weighting="torque"``.  Returns the regressor, its
    columns of ``A``, every row's channel, the rows used, the search's report, the
    solution."""
    nv = reg.robot.nv
    channel = np.tile(np.arange(nv), A.shape[0] // nv)
    used_rows = ~np.isin(channel, reg.excluded)
    searched: dict[str, Any] = {}
    if cands:  # (the search's own least squares, unweighted by channel)
        reg, A, searched = _search_smoothing(reg, A, y, used_rows, cands, laws, minimum)
    by_channel = channel[used_rows] if reg.weighting == "torque" else None
    sol = solve(reg, A[used_rows], y[used_rows], channel=by_channel)
    return reg, A, channel, used_rows, searched, sol


def _search_smoothing(
    reg: MomentumRegressor,
    A: Vector,
    y: Vector,
    used_rows: NDArray[np.bool_],
    cands: list[tuple[float, float]],
    laws: dict[str, Any],
    minimum: bool = False,
) -> tuple[MomentumRegressor, Vector, dict[str, Any]]:
    """The friction law's smoothing velocities chosen among ``cands`` by cross-validation
    (:func:`~pinobs.model.friction_fit.search_smoothing`): the regressor with them, the rows'
    chosen columns, and what the search reports."""
    choice, searched = search_smoothing(reg, A[used_rows], y[used_rows], cands, minimum=minimum)
    A = A[:, candidate_columns(reg, len(cands), choice)]
    reg = MomentumRegressor(
        reg.robot,
        **laws,
        smoothing=[cands[c][0] for c in choice],  # (smoothing, when given, in all)
        stribeck_velocity=[cands[c][1] for c in choice],
    )
    return reg, A, searched


def _check_solution(
    reg: MomentumRegressor,
    sol: Solution,
    rows: tuple[Vector, NDArray[np.bool_]],
    fitted: tuple[Vector, Vector],
    excluded: NDArray[np.intp],
    window: float,
    holdout: float,
    max_condition: float,
) -> str | None:
    """Refuse a fit with no more rows than combinations, or too ill-conditioned (``rows``:
    the fitted rows and which of them were used, ``fitted``: the fitted part's ``(t, q)``);
    the warning of a loosely determined one (fewer than :data:`ROWS_PER_COMBINATION` rows
    each), else ``None``."""
    robot, (A, used_rows) = reg.robot, rows
    enough = ROWS_PER_COMBINATION * sol.rank
    need = enough / robot.nv * window / (1.0 - holdout)  # log length [s] giving that many rows
    used = f"{A.shape[0] // robot.nv} windows of {window:g} s ({sol.n_rows} rows)"
    if sol.n_rows <= sol.rank:
        raise IdentificationError(
            f"{used} for {sol.rank} identifiable combinations: the fit would interpolate the "
            f"data with nothing left to check it; give at least {need:.3g} s of contiguous, "
            f"exciting motion ({ROWS_PER_COMBINATION} rows per combination, holdout "
            f"{holdout:g} kept out)"
        )
    if sol.condition > max_condition:
        raise IdentificationError(
            f"the log does not excite the dynamics enough: condition number "
            f"{sol.condition:.3g} > {max_condition:.3g}"
            + not_excited_message(reg, A[used_rows], sol, *fitted)
            + (
                " (with the torques of "
                + ", ".join(coordinate_names(robot)[j] for j in excluded)
                + " left out, what only they see is seen through the others' alone)"
                if excluded.size
                else ""
            )
            + "; record a richer trajectory (`pinobs excite`), or accept it with a larger "
            "max_condition (--max-condition)"
        )
    if sol.n_rows < enough:
        return (
            f"only {used} for {sol.rank} identifiable combinations (fewer than "
            f"{ROWS_PER_COMBINATION} rows each): the fit is loosely determined; give at least "
            f"{need:.3g} s of contiguous, exciting motion"
        )
    return None


def _assess(
    reg: MomentumRegressor,
    sol: Solution,
    log: tuple[Vector, Vector, Vector],
    fitted: dict[str, Any],
    excluded: NDArray[np.intp],
    laws: dict[str, Any],
    rows: dict[str, Any],
    info: dict[str, Any],
    searched: dict[str, Any],
) -> Report:
    """:func:`identify`'s report but its ``warnings``: the fitted rows diagnosed
    (:func:`_diagnose`), the held-out end's rows built (weighted and in N·m), and the friction
    law fitted.  ``fitted``: the fitted rows ``A``, ``y``, their windows' ``ends``, the used
    rows' ``channel`` and the fitted rows of the log ``fit``; ``laws``: the regressor's
    options; ``rows``: :func:`~pinobs.model.identification.rows.build_rows`' options;
    ``info``: ``torque``, ``fit_end``, ``filled_rows``, ``holdout``; ``searched``: the
    smoothing search's report."""
    t, q, tau = log
    A, y, fit = fitted["A"], fitted["y"], fitted["fit"]
    window = rows["window"]
    diagnosed = _diagnose(
        reg, A, y, sol, (t[fit], q[fit], tau[fit]), window, fitted["ends"], excluded
    )
    held = holdout_rows(reg, log, ~fit, holdout=info["holdout"], **rows)
    held_nm = holdout_in_newton_metres(
        reg,
        lambda: MomentumRegressor(  # the same columns as the fit's, searched smoothing too
            reg.robot,
            friction=laws["friction"],
            offset=laws["offset"],
            armature=laws["armature"],
            weighting="torque",
            smoothing=reg.smoothing,
            stribeck_velocity=reg.stribeck_velocity,
        ),
        held,
        log,
        ~fit,
        **rows,
    )
    theta0 = reg.nominal()
    # of those not excited, the ones physical consistency moved by more than half their
    # prior std
    moved = [
        n
        for n, e, d, sd in zip(
            reg.names, sol.excited, sol.theta - theta0, reg.prior_std(), strict=True
        )
        if not e and sol.projected and abs(d) > 0.5 * sd
    ]
    rows_used = {"fit": (A, y), "held": held, "held_nm": held_nm}
    report = fit_report(
        reg, sol, rows_used, theta0, excluded, fitted["channel"], info, diagnosed, moved=moved
    )
    if reg.friction:  # the law fitted, its velocities per actuated joint [rad/s]
        report["friction_law"] = {
            "law": reg.friction_law,
            "joints": list(reg.actuated_names),
            "smoothing": reg.smoothing.tolist(),
            "stribeck_velocity": reg.stribeck_velocity.tolist(),
            **searched,
        }
    return report


def _diagnose(
    reg: MomentumRegressor,
    A: Vector,
    y: Vector,
    sol: Solution,
    fitted: tuple[Vector, Vector, Vector],
    window: float,
    ends: list[float],
    excluded: NDArray[np.intp],
) -> dict[str, Any]:
    """The report's ``unexplained``, ``unexplained_floor`` (:func:`unexplained_shares`) and
    ``outlier_windows`` (end times [s] of the windows left mostly unexplained) of the fitted
    rows; NaN shares on the excluded coordinates."""
    nv = reg.robot.nv
    unexplained, floor = unexplained_shares(reg, A, y, sol, *fitted, window)
    res_w = np.abs(A @ sol.theta - y).reshape(-1, nv)
    bound = np.maximum(OUTLIER_SHARE, UNEXPLAINED_WARN * np.asarray(floor)) * robust_rms(
        y.reshape(-1, nv)
    )
    kept = ~np.isin(np.arange(nv), excluded)
    outliers = [ends[w] for w in np.flatnonzero(np.any((res_w > bound)[:, kept], axis=1))]
    for j in excluded:  # left out of the fit: nothing to say of how well it explains them
        unexplained[j] = floor[j] = math.nan
    return {"unexplained": unexplained, "unexplained_floor": floor, "outlier_windows": outliers}
