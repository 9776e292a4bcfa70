"""A log's rows for the identification: read and checked (:func:`log_arrays`), short NaN
runs filled (:func:`fill_short_gaps`), split into contiguous stretches (:func:`segments`),
and each stretch's weighted windows (:func:`build_rows`)."""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Callable, Mapping
from os import PathLike
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import DimensionError, IdentificationError, PinobsWarning, TimestampError
from pinobs.model.identification.savgol import smooth_path
from pinobs.model.robot import Robot, Vector
from pinobs.model.sampling import SPLIT_GAP_PERIODS
from pinobs.tolerances import ABSURD_LIMIT_FACTOR, ABSURD_VALUE

if TYPE_CHECKING:
    from pinobs.model.identification.payload import PayloadRegressor
    from pinobs.model.identification.regressor import MomentumRegressor

__all__ = [
    "MAX_FILL",
    "SETTLE_WINDOWS",
    "build_rows",
    "fill_short_gaps",
    "fit_rows",
    "holdout_in_newton_metres",
    "holdout_rows",
    "log_arrays",
    "read_fit_log",
    "segments",
]


def segments(t: Vector, q: Vector, tau: Vector) -> list[slice]:
    """Contiguous stretches of finite rows, of two rows or more, split where a row is not
    finite or an interval is longer than :data:`~pinobs.model.sampling.SPLIT_GAP_PERIODS`
    median intervals.

    Within a stretch the intervals are the log's own: dropped samples (an interval of a
    few periods) and irregular sampling are used as they are
    (:mod:`pinobs.model.sampling`).

    Raises:
        IdentificationError: the median interval is not positive (timestamps repeated).
    """
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(tau), axis=1)
    if good.sum() < 2:
        return []
    h = float(np.median(np.diff(t[good])))
    if not h > 0.0:
        raise IdentificationError(
            f"the log's median sample interval is {h:g} s: its timestamps repeat; give each "
            "sample its own time"
        )
    out, start = [], None
    for k in range(t.shape[0]):
        ok = bool(good[k]) and (
            start is None or (0.0 < t[k] - t[k - 1] <= SPLIT_GAP_PERIODS * h and bool(good[k - 1]))
        )
        if ok and start is None:
            start = k
        elif not ok:
            if start is not None:
                out.append(slice(start, k))
            start = k if good[k] else None
    if start is not None:
        out.append(slice(start, t.shape[0]))
    return [seg for seg in out if seg.stop - seg.start >= 2]


#: A given path's samples closer than this many half windows (of :func:`build_rows`) to
#: the end of its stretch are not used: a smoother started afresh on each stretch has not
#: converged there.  Measured (UR5, σ = 1e-4, RTS on the identified model, gaps of 20
#: rows): its velocity error is 30–130× the interior's at a stretch's first sample, 2–5× at
#: 20 samples, 1–2× at 50, 1× at 100 (two half windows at 1 kHz).
SETTLE_WINDOWS = 2


def _settled_runs(finite: NDArray[np.bool_], settle: int) -> list[slice]:
    """The runs of ``finite``, each without its first and last ``settle`` samples."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], finite.astype(np.int8), [0]])))
    out = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a > 2 * settle + 1:
            out.append(slice(int(a) + settle, int(b) - settle))
    return out


def build_rows(
    reg: MomentumRegressor | PayloadRegressor,
    t: Vector,
    q: Vector,
    tau: Vector,
    *,
    window: float = 0.1,
    half_window: float = 0.05,
    quadrature: float = 0.002,
    path: tuple[Vector, Vector] | None = None,
    torque: str = "held",
) -> tuple[Vector, Vector, list[float]]:
    """Weighted rows of every contiguous stretch of a log, and the window end times.

    Args:
        window: window length [s].
        half_window: half-width of the Savitzky–Golay fit of :func:`smooth_path` [s].
        quadrature: longest trapezoid step of the regressor integrals [s].
        path: estimated ``(q, v)`` at every sample, ``(N, nq)`` and ``(N, nv)``
            (e.g. a model-based smoother's), used instead of :func:`smooth_path`
            on every stretch where it is finite, except within :data:`SETTLE_WINDOWS`
            half windows of its runs' ends (those rows are not used).
        torque: how the torques were sampled (:meth:`MomentumRegressor.system`).
    """
    As, ys, ends = [], [], []
    for seg in segments(t, q, tau):
        ts, qs, taus = t[seg], q[seg], tau[seg]
        h = float(np.median(np.diff(ts)))
        stride = max(1, round(quadrature / h))
        win = max(stride, round(window / h / stride) * stride)
        hw = max(2, round(half_window / h))
        if ts[-1] - ts[0] < (max(win, 2 * hw) - 0.5) * h:  # (uniform: fewer rows than that)
            continue
        given = None if path is None else np.all(np.isfinite(path[1][seg]), axis=1)
        if given is None or not given.any():  # no estimate given, or none for this stretch
            q_s, v = smooth_path(reg.robot, ts, qs, half_window=hw)
            parts = [(slice(0, ts.shape[0]), q_s, v)]
        else:
            assert path is not None
            parts = [
                (run, path[0][seg][run], path[1][seg][run])
                for run in _settled_runs(given, SETTLE_WINDOWS * hw)
            ]
        for run, q_s, v in parts:
            A, y = reg.system(ts[run], q_s, v, taus[run], window=win, stride=stride, torque=torque)
            As.append(A)
            ys.append(y)
            ends += reg.window_ends(ts[run], win, stride)
    if not As:
        return np.zeros((0, reg.size)), np.zeros(0), []
    return np.vstack(As), np.concatenate(ys), ends


def log_arrays(
    robot: Robot, log: Any, *, warn_filled: bool = True
) -> tuple[Vector, Vector, Vector]:
    """``(t, q, tau)`` of a log as :func:`identify` reads it, checked against ``robot``, short
    runs of NaN rows filled (:func:`fill_short_gaps`, with a :class:`PinobsWarning`;
    ``warn_filled=False`` leaves them).

    ``log``: a tuple ``(t, q, tau)``, or an object with ``t``, ``q``, ``tau``
    (a ``Log``); a simulation ``Result`` is read through its measured
    ``q_meas``, never its true ``q``.

    Raises:
        IdentificationError: no torques.
        DimensionError: shapes that do not fit ``robot``.
        TimestampError: finite times that repeat or step back.
    """
    t, q, tau = _unpack_log(log)
    if tau is None:
        raise IdentificationError("the log has no torques: identification needs tau columns")
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    tau = np.asarray(tau, dtype=float)
    _check_log(robot, t, q, tau)
    if warn_filled:
        q, tau, filled = fill_short_gaps(robot, t, q, tau)
        if filled:
            warnings.warn(
                f"{filled} row(s) with NaN positions or torques, in runs of at most "
                f"{MAX_FILL} rows, were filled by interpolating their neighbours (longer runs "
                "split the log into stretches)",
                PinobsWarning,
                stacklevel=3,
            )
    return t, q, tau


def read_fit_log(
    robot: Robot, log: Any, path: tuple[ArrayLike, ArrayLike] | None
) -> tuple[Vector, Vector, Vector, int, tuple[Vector, Vector] | None]:
    """``(t, q, tau, filled, path)``: the log read (:func:`log_arrays`), its short NaN runs
    filled (:func:`fill_short_gaps`, ``filled`` rows), and the given path as arrays.

    Raises:
        DimensionError: a path whose shapes do not fit the log.
    """
    t, q, tau = log_arrays(robot, log, warn_filled=False)
    q, tau, filled = fill_short_gaps(robot, t, q, tau)
    est: tuple[Vector, Vector] | None = None
    if path is not None:
        est = (np.asarray(path[0], dtype=float), np.asarray(path[1], dtype=float))
        if est[0].shape != q.shape or est[1].shape != tau.shape:
            raise DimensionError(
                f"path shapes q {est[0].shape}, v {est[1].shape} do not fit the log: "
                f"give ({t.shape[0]}, {robot.nq}) and ({t.shape[0]}, {robot.nv})"
            )
    return t, q, tau, filled, est


def _unpack_log(log: Any) -> tuple[Any, Any, Any]:
    """``(t, q, tau)`` of the forms :func:`log_arrays` reads (``tau`` ``None`` if absent)."""
    if isinstance(log, (tuple, list)):
        if len(log) != 3:
            raise DimensionError(
                f"log is a sequence of {len(log)} arrays; identification needs (t, q, tau)"
            )
        t, q, tau = log
    elif isinstance(log, Mapping) and {"t", "q"} <= set(log):
        t, q, tau = log["t"], log["q"], log.get("tau")
    elif hasattr(log, "t") and hasattr(log, "q"):
        # a simulation Result carries the truth in q: identify from what was measured
        t, tau = log.t, getattr(log, "tau", None)
        q = log.q_meas if hasattr(log, "q_meas") else log.q
    else:
        read = (
            " (read a file with pinobs.io.read_log(path, robot))"
            if isinstance(log, (str, PathLike)) or hasattr(log, "columns")
            else ""
        )
        raise DimensionError(
            f"log is a {type(log).__name__}; give a pinobs.io.Log, a pinobs.Result, (t, q, tau) "
            f"arrays or a mapping with 't', 'q', 'tau'{read}"
        )
    return t, q, tau


def _check_log(robot: Robot, t: Vector, q: Vector, tau: Vector) -> None:
    """:func:`log_arrays`'s checks: shapes, absurd torques, increasing finite times."""
    if (
        t.ndim != 1
        or q.ndim != 2
        or q.shape != (t.shape[0], robot.nq)
        or tau.shape != (t.shape[0], robot.nv)
    ):
        raise DimensionError(
            f"log shapes t {t.shape}, q {q.shape}, tau {tau.shape} do not fit robot "
            f"{robot.name!r} (t (N,), q (N, nq = {robot.nq}), tau (N, nv = {robot.nv}))"
        )
    with np.errstate(invalid="ignore"):
        absurd = np.abs(tau) > robot.absurd_torque
    if absurd.any():
        k, j = (int(i[0]) for i in np.nonzero(absurd))
        raise IdentificationError(
            f"{int(absurd.any(axis=1).sum())} row(s) have absurd torques, the first tau[{k}] "
            f"(t = {t[k]:.9g} s) = {tau[k, j]:.6g} on coordinate {j}, beyond "
            f"{robot.absurd_torque[j]:.6g} ({ABSURD_LIMIT_FACTOR:g}× the URDF effort limit, "
            f"{ABSURD_VALUE:g} without one): check the torques' units, or set those rows to NaN"
        )
    tf = t[np.isfinite(t)]
    back = np.flatnonzero(np.diff(tf) <= 0.0)
    if back.size:
        k = int(back[0])
        raise TimestampError(
            f"the log's times do not increase: {back.size} finite row(s) repeat or step back, "
            f"the first at t = {tf[k]:.9g} s followed by t = {tf[k + 1]:.9g} s; give each sample "
            "its own, increasing time (sort the log and drop duplicated rows)"
        )


#: Runs of at most this many rows with NaN positions or torques between finite rows are
#: filled by interpolation (:func:`fill_short_gaps`); a longer run splits the log.  At 1 kHz
#: the linear interpolation errs by ``|q̈|(4h)²/8`` ≈ 2e-5 rad at 10 rad/s², below the noise.
MAX_FILL = 3


def fill_short_gaps(robot: Robot, t: Vector, q: Vector, tau: Vector) -> tuple[Vector, Vector, int]:
    """``(q, tau, n)``: runs of at most :data:`MAX_FILL` rows whose positions or torques are
    not finite, between finite rows, interpolated linearly in time (on the configuration
    manifold for ``q``); ``n`` the rows filled.  Not where the run and its neighbours span
    more than 1.5 median intervals per step (dropped samples beside it: the interpolation
    would span too long; the rows then split the log).

    A missing sample broke the log into stretches that each need their own smoothing
    start-up and lose their ends: with 2 % of a UR5 log's rows NaN (single rows), the
    stretches averaged 50 samples, shorter than one window.
    """
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(tau), axis=1)
    if good.all() or good.sum() < 2:
        return q, tau, 0
    q, tau = q.copy(), tau.copy()
    h = float(np.median(np.diff(t[good])))
    idx = np.flatnonzero(good)
    filled = 0
    for a, b in itertools.pairwise(idx):
        gap = b - a - 1
        if gap == 0 or gap > MAX_FILL or not np.all(np.isfinite(t[a : b + 1])):
            continue
        steps = np.diff(t[a : b + 1])
        if np.any(steps <= 0.0) or t[b] - t[a] > 1.5 * (gap + 1) * h:  # a drop beside them
            continue
        for k in range(a + 1, b):
            s = (t[k] - t[a]) / (t[b] - t[a])
            q[k] = robot.interpolate(q[a], q[b], s)
            tau[k] = (1.0 - s) * tau[a] + s * tau[b]
        filled += gap
    return q, tau, filled


def _why_no_window(t: Vector, q: Vector, tau: Vector) -> str:
    """What broke the log into stretches too short for a window (for the refusal)."""
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(tau), axis=1)
    if good.sum() < 2:
        return ": fewer than two finite rows"
    dt = np.diff(t[good])
    h = float(np.median(dt))
    long = dt > SPLIT_GAP_PERIODS * h
    if long.mean() > 0.01:
        return (
            f": {100 * long.mean():.3g} % of its intervals between finite rows are gaps longer "
            f"than {SPLIT_GAP_PERIODS:g} median intervals ({h:.3g} s), the longest "
            f"{float(dt.max()):.3g} s; dropped samples are used as they are, but a gap that "
            "long splits the log (record without such gaps, or fill them)"
        )
    return f": {100 * (1 - good.mean()):.3g} % of its rows have NaN (gaps split it)"


def _rows_of(
    path: tuple[Vector, Vector] | None, rows: NDArray[np.bool_]
) -> tuple[Vector, Vector] | None:
    return None if path is None else (path[0][rows], path[1][rows])


def fit_rows(
    reg: MomentumRegressor | PayloadRegressor,
    log: tuple[Vector, Vector, Vector],
    rows: NDArray[np.bool_],
    *,
    window: float,
    path: tuple[Vector, Vector] | None,
    torque: str,
) -> tuple[Vector, Vector, list[float]]:
    """:func:`build_rows` of the log's ``rows`` (its fitted part), ``path`` (the whole log's
    estimate, or ``None``) taken on the same rows.

    Raises:
        IdentificationError: no complete window there, saying what broke the log.
    """
    t, q, tau = log
    A, y, ends = build_rows(
        reg, t[rows], q[rows], tau[rows], window=window, path=_rows_of(path, rows), torque=torque
    )
    if A.shape[0] == 0:
        raise IdentificationError(
            "no complete window of contiguous finite samples in the log" + _why_no_window(t, q, tau)
        )
    return A, y, ends


def holdout_rows(
    reg: MomentumRegressor | PayloadRegressor,
    log: tuple[Vector, Vector, Vector],
    rows: NDArray[np.bool_],
    *,
    holdout: float,
    window: float,
    path: tuple[Vector, Vector] | None,
    torque: str,
) -> tuple[Vector, Vector]:
    """The held-out ``rows``' weighted rows ``(A, y)`` (:func:`build_rows`; none when
    ``holdout`` is 0)."""
    if not holdout > 0:
        return np.zeros((0, reg.size)), np.zeros(0)
    t, q, tau = log
    A_h, y_h, _ = build_rows(
        reg, t[rows], q[rows], tau[rows], window=window, path=_rows_of(path, rows), torque=torque
    )
    return A_h, y_h


def holdout_in_newton_metres(
    reg: MomentumRegressor | PayloadRegressor,
    unweighted: Callable[[], MomentumRegressor | PayloadRegressor],
    held: tuple[Vector, Vector],
    log: tuple[Vector, Vector, Vector],
    rows: NDArray[np.bool_],
    *,
    window: float,
    path: tuple[Vector, Vector] | None,
    torque: str,
) -> tuple[Vector, Vector]:
    """The held-out rows in N·m: ``held`` (:func:`holdout_rows`) themselves when ``reg``
    already weights by torque, else the same windows of the log's ``rows`` built again
    through ``unweighted()`` (their mean torques)."""
    A_h, _ = held
    if reg.weighting == "torque" or A_h.shape[0] == 0:
        return held
    t, q, tau = log
    A_nm, y_nm, _ = build_rows(
        unweighted(),
        t[rows],
        q[rows],
        tau[rows],
        window=window,
        path=_rows_of(path, rows),
        torque=torque,
    )
    return A_nm, y_nm
