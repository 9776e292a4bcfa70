"""A log as the smoother reads it: its arrays checked (:func:`smoothing_arrays`), re-timed under a
known latency (:func:`retimed`), and the result put back at the log's own rows
(:func:`at_rows`); its noise σ when none is given (:func:`log_noise_std`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import (
    ConfigurationError,
    DimensionError,
    GainError,
    NonFiniteError,
    OptionError,
    TimestampError,
)
from pinobs.model import Robot
from pinobs.observers.base import NOISE_FLOOR, Vector, positive
from pinobs.observers.noise import noise_from_log
from pinobs.smoothing.rts import Smoothed
from pinobs.tolerances import QUATERNION_NORM_TOL

__all__ = [
    "LogLike",
    "at_rows",
    "first_good",
    "latency_option",
    "log_noise_std",
    "retimed",
    "smoothing_arrays",
]


class LogLike(Protocol):
    """Anything with a log's arrays ``t``, ``q`` (measured), ``tau``: :class:`pinobs.io.Log`.

    An object that also has ``q_meas`` (a :class:`pinobs.Result`, whose ``q`` is
    the truth) is read through ``q_meas``.
    """

    @property
    def t(self) -> Vector: ...
    @property
    def q(self) -> Vector: ...
    @property
    def tau(self) -> Vector | None: ...


def smoothing_arrays(
    robot: Robot, log: LogLike | Sequence[ArrayLike] | Mapping[str, ArrayLike]
) -> tuple[Vector, Vector, Vector]:
    """``(t, q, tau)`` of a log, checked (``tau`` zero when the log has none)."""
    t, q, tau = _log_fields(log)
    t_arr = np.asarray(t, dtype=float)
    q_arr = np.asarray(q, dtype=float)
    if t_arr.ndim != 1 or t_arr.size < 2:
        raise DimensionError(f"t has shape {t_arr.shape}; give a 1-D array of at least 2 times [s]")
    n = t_arr.size
    if q_arr.shape != (n, robot.nq):
        raise DimensionError(
            f"q has shape {q_arr.shape}; robot {robot.name!r} with {n} times needs ({n}, {robot.nq})"
        )
    _check_times(t_arr)
    off = np.flatnonzero(robot.off_unit_rows(q_arr))
    if off.size:  # refused before the passes, not at the row, after minutes (a sweep found it)
        rows = ", ".join(map(str, off[:5])) + (", …" if off.size > 5 else "")
        raise ConfigurationError(
            f"{off.size} rows of q have a quaternion or (cos, sin) pair off unit norm by more "
            f"than {QUATERNION_NORM_TOL:g} (rows {rows}; row {off[0]}: {q_arr[off[0]].tolist()}); "
            "set such rows to NaN to smooth over them as dropped samples"
        )
    return t_arr, q_arr, _torques(robot, tau, n)


def _log_fields(log: Any) -> tuple[Any, Any, Any]:
    """The log's ``t``, measured ``q`` and ``tau`` (``None`` without), as given."""
    if isinstance(log, (tuple, list)):
        if len(log) not in (2, 3):
            raise DimensionError(f"log is a tuple of {len(log)} arrays; give (t, q) or (t, q, tau)")
        t, q, tau = (*log, None)[:3]
        return t, q, tau
    if isinstance(log, Mapping):
        if not {"t", "q"} <= set(log):
            raise DimensionError(f"log has the keys {sorted(log)}; give 't', 'q' (and 'tau')")
        return log["t"], log["q"], log.get("tau")
    if hasattr(log, "t") and hasattr(log, "q"):
        # a Result's q is the truth: its measurements are q_meas
        return log.t, getattr(log, "q_meas", log.q), getattr(log, "tau", None)
    raise DimensionError(
        f"log is a {type(log).__name__}; give a pinobs.io.Log, a pinobs.Result, (t, q) or "
        "(t, q, tau) arrays, or a mapping with 't', 'q' (and 'tau')"
    )


def _check_times(t: Vector) -> None:
    """Refuse times that are not finite or not strictly increasing, naming the first."""
    if not np.all(np.isfinite(t)):
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        raise TimestampError(f"t[{bad}] = {t[bad]!r} is not finite; every time must be")
    steps = np.diff(t)
    if np.any(steps <= 0):
        bad = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise TimestampError(
            f"t[{bad}] = {t[bad]!r} s is not after t[{bad - 1}] = {t[bad - 1]!r} s; "
            "timestamps must be strictly increasing"
        )


def _torques(robot: Robot, tau: ArrayLike | None, n: int) -> Vector:
    """The log's torques ``(n, nv)``, checked; zero when it has none."""
    if tau is None:
        return np.zeros((n, robot.nv))
    tau_arr = np.asarray(tau, dtype=float)
    if tau_arr.shape != (n, robot.nv):
        raise DimensionError(
            f"tau has shape {tau_arr.shape}; robot {robot.name!r} with {n} times needs ({n}, {robot.nv})"
        )
    if not np.all(np.isfinite(tau_arr)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(tau_arr), axis=1))[0])
        raise NonFiniteError(f"tau[{bad}] = {tau_arr[bad].tolist()} is not finite")
    return tau_arr


def first_good(q: Vector) -> tuple[int, Vector]:
    """Index of the first finite row of ``q`` and the finite-row mask from there on."""
    good = np.all(np.isfinite(q), axis=1)
    if not np.any(good):
        raise NonFiniteError("no row of q is finite: nothing to smooth")
    k0 = int(np.argmax(good))  # the filter starts at the first good sample
    return k0, good[k0:]


def retimed(
    t: Vector, q: Vector, tau: Vector, latency: float
) -> tuple[Vector, Vector, Vector, NDArray[np.intp]]:
    """The log on the times its samples were taken, for a known measurement latency ``d`` [s].

    The sample stamped ``t_k`` was taken at ``s_k = t_k − d``; the torque ``τ_k`` is applied
    from ``t_k`` (MATH §7: only the measurement is late).  The rows returned are the union of
    the ``s_k`` (each with its ``q_k``) and the ``t_k`` (no measurement: predicted over), in
    time order, times closer than 1e-6 of the median interval merged (a latency of whole
    sample intervals puts each ``s_k`` on an earlier ``t_j``); each row's torque is the one
    in effect from it on, ``τ_j`` of the latest ``t_j`` at or before it (``τ_0`` before
    ``t_0``).  The filter over these rows is the causal observer under ``latency=d``
    (:meth:`pinobs.observers.base.Observer.set_latency`: the state at ``t − d``, predicted
    to ``t`` with the torques applied since), and the estimate at ``t_k`` is the row at
    ``t_k``.  Returns ``(times, q or NaN, τ, the row of each t_k)``.
    """
    n = t.size
    times = np.concatenate([t - latency, t])
    order = np.argsort(times, kind="stable")
    # merged below 1e-6 of an interval, or a few float64 steps of the times (about 2e-7 s at
    # Unix times, 1.7e9 s: 1e-6 of a 1 ms interval would merge nothing there)
    eps = max(1e-6 * float(np.median(np.diff(t))) if n > 1 else 0.0, 4.0 * _spacing(t))
    new = np.concatenate([[True], np.diff(times[order]) > eps])
    group = np.cumsum(new) - 1  # the row of each sorted time
    row_of = np.empty(2 * n, dtype=np.intp)
    row_of[order] = group
    first = order[new]  # each row's earliest time
    rows_t = times[first]
    rows_q = np.full((rows_t.size, q.shape[1]), np.nan)
    rows_q[row_of[:n]] = q
    rows_t[row_of[n:]] = t  # a row with a stamped time keeps it exactly (the output rows)
    latest = np.searchsorted(t, rows_t + eps, side="right") - 1
    return rows_t, rows_q, tau[np.maximum(latest, 0)], row_of[n:]


def _spacing(t: Vector) -> float:
    """The float64 step at the log's largest time magnitude [s]."""
    return float(np.spacing(np.abs(t).max())) if t.size else 0.0


def latency_option(filter_options: Mapping[str, Any] | None) -> tuple[float, dict[str, Any]]:
    """``filter_options``' ``latency`` [s] (0 if none) and the other options."""
    options = dict(filter_options or {})
    latency = options.pop("latency", None)
    if isinstance(latency, str):
        raise OptionError(
            f"latency={latency!r}: give a number >= 0 [s] (pinobs.smooth alone takes 'auto': "
            "select_latency over the whole log)"
        )
    positive("latency", latency, allow_zero=True, allow_none=True)
    return float(latency or 0.0), options


def at_rows(result: Smoothed, rows: NDArray[np.intp] | None, t: Vector) -> Smoothed:
    """``result`` (of a log on the grid of its ticks: :func:`~pinobs.model.sampling.on_ticks`)
    at the given log's rows ``rows``, its times ``t``; as it is with ``rows`` None."""
    if rows is None:
        return result
    return replace(result, t=t, q=result.q[rows], v=result.v[rows], v_std=result.v_std[rows])


def log_noise_std(robot: Robot, t: Vector, q: Vector) -> tuple[float, Vector, str]:
    """The σ [rad or m] the smoother takes when none is given: ``(σ̂, σ̂ per joint, a sentence
    reporting them)`` from :func:`pinobs.observers.noise.noise_from_log` (the median over
    joints, the log's first second), at least :data:`~pinobs.observers.base.NOISE_FLOOR`
    (the filters' default σ).

    Raises:
        GainError: fewer than 12 finite rows to estimate it from.
    """
    found = noise_from_log(t, q, robot, floor=NOISE_FLOOR)
    if found is None:
        raise GainError("the log has too few finite rows to estimate its noise; give noise_std")
    return found
