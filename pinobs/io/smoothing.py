"""Offline smoothing of a log file: the io readers' screening and row accounting, the io writer.

:func:`smooth_log` runs :func:`pinobs.smooth` over a log read chunk by chunk
with :func:`pinobs.io.iter_log` (every format), through the same screening as
``pinobs estimate`` (:class:`~pinobs.io.LogEstimator`: unreadable or absurd
rows, time going back, gaps propagated over in sub-steps, restarts after a
long gap, every fault reported once): a recorder stands in for the observer
and keeps the samples the estimator would feed it, then each stretch between
restarts is smoothed and written with :class:`~pinobs.io.EstimateWriter`
(atomic; no overwrite without ``force``; never over an input), one row per
log row, ``t, q0.., v0.., v_std0..``.

Memory: the recorded samples, ``1 + nq + nv`` floats per row, are kept (the
smoother needs the whole stretch, or its chunks' overlap, and ``"auto"``
passes over it once per candidate); the smoother's own per-sample states are
bounded by ``chunk``/``lag`` (:mod:`pinobs.observers.smoothing`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np

from pinobs.io.readers import LogSource, iter_log
from pinobs.io.stream import LogEstimator, LogRun, _chain, _median_period
from pinobs.io.writers import EstimateWriter
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.observers.base import Estimate
from pinobs.observers.smoothing import smooth

__all__ = ["smooth_log"]


class _Recorder:
    """Observer-like stand-in for :class:`LogEstimator`: keeps what it is fed, one list of
    ``(t, q or None, tau)`` per start (a restart begins a new one); its estimate's ``v``
    holds the running sample number, so each output row finds its smoothed sample."""

    def __init__(self, robot: Robot, name: str) -> None:
        self.robot = robot
        self.name = name
        self.uses_torque = True
        self.segments: list[list[tuple[float, Vector | None, Vector]]] = []
        self._n = 0

    def _keep(self, t: float, q: Any, tau: Any) -> Estimate:
        tau_arr = np.zeros(self.robot.nv) if tau is None else np.asarray(tau, dtype=float)
        q_arr = None if q is None else self.robot.check_configuration(q, what="q")
        self.segments[-1].append((float(t), q_arr, tau_arr))
        self._n += 1
        shown = self.robot.neutral() if q_arr is None else q_arr
        return Estimate(float(t), shown, np.full(self.robot.nv, float(self._n - 1)))

    def reset(self, t0: float, q0: Any, v0: Any = None, tau0: Any = None) -> Estimate:
        self.segments.append([])
        return self._keep(t0, q0, tau0)

    def update(self, t: float, q_meas: Any, tau: Any = None) -> Estimate:
        return self._keep(t, q_meas, tau)


def smooth_log(
    source: LogSource,
    robot: Robot,
    out: str | Path,
    *,
    observer: str = "ekf",
    noise_std: float,
    accel_psd: float | Literal["auto"] | None = None,
    lag: float | None = None,
    chunk: float | None = None,
    force: bool = False,
    columns: Mapping[str, str] | None = None,
    topic: str | None = None,
    rate: float | None = None,
    options: Mapping[str, Any] | None = None,
) -> tuple[LogRun, list[dict[str, Any]]]:
    """Smooth a log file into ``out`` (module docstring); returns the row accounting and
    the smoother's options of each stretch.

    Args:
        source: log path or DataFrame (:func:`pinobs.io.iter_log`).
        robot: the robot of the log.
        out: CSV file ``t, q0.., v0.., v_std0..`` (refused if it exists, unless ``force``,
            or if it is ``source``).
        observer, noise_std, accel_psd, lag, chunk: as :func:`pinobs.smooth`.
        columns, topic: as :func:`pinobs.io.iter_log`.
        rate: sample rate [Hz] (default: from the log's median interval).
        options: further options of the filter (``filter_options`` of :func:`pinobs.smooth`).

    Raises:
        OutputExistsError: ``out`` exists (without ``force``) or is the input.
        and what :func:`pinobs.smooth` and :func:`pinobs.io.iter_log` raise.
    """
    inputs = [] if type(source).__name__ == "DataFrame" else [source]
    writer = EstimateWriter(
        out, robot, force=force, inputs=inputs, extra_columns=[f"v_std{i}" for i in range(robot.nv)]
    )
    try:
        chunks = iter_log(source, robot, columns=columns, topic=topic)
        first = next(chunks)
        period = 1.0 / rate if rate else _median_period(first.t)
        rec = _Recorder(robot, observer)
        est = LogEstimator(rec, period=period)
        parts = [est.feed(c) for c in _chain(first, chunks)]
        parts.append(est.finish())
        t = np.concatenate([p[0] for p in parts])
        idx = np.concatenate([p[2][:, 0] for p in parts])  # sample number, NaN: no estimate
        nv = robot.nv
        q_s = np.full((len(t), robot.nq), np.nan)
        v_s = np.full((len(t), nv), np.nan)
        std_s = np.full((len(t), nv), np.nan)
        samples_q = np.full((rec._n, robot.nq), np.nan)
        samples_v = np.full((rec._n, nv), np.nan)
        samples_std = np.full((rec._n, nv), np.nan)
        stretches: list[dict[str, Any]] = []
        first_k = 0
        for seg in rec.segments:
            k = slice(first_k, first_k + len(seg))
            first_k += len(seg)
            if len(seg) < 2:
                continue  # one sample: no velocity to smooth
            seg_t = np.array([s[0] for s in seg])
            seg_q = np.array([np.full(robot.nq, np.nan) if s[1] is None else s[1] for s in seg])
            seg_tau = np.array([s[2] for s in seg])
            res = smooth(
                robot,
                (seg_t, seg_q, seg_tau),
                observer=observer,
                noise_std=noise_std,
                accel_psd=accel_psd,
                lag=lag,
                chunk=chunk,
                filter_options=options,
            )
            samples_q[k], samples_v[k], samples_std[k] = res.q, res.v, res.v_std
            stretches.append(res.options)
        ok = np.isfinite(idx)
        rows = idx[ok].astype(int)
        q_s[ok], v_s[ok], std_s[ok] = samples_q[rows], samples_v[rows], samples_std[rows]
        writer.write(t, q_s, v_s, std_s)
        writer.close()
    except BaseException:
        writer.abort()
        raise
    run = LogRun(
        t=t,
        q=q_s,
        v=v_s,
        bad_rows=est.bad_rows,
        warnings=est.warnings,
        rows=est.rows,
        estimated=int(np.all(np.isfinite(v_s), axis=1).sum()),
        measured=est.measured,
        unit=first.unit,
        noise_std=noise_std,
        period=period,
    )
    return run, stretches
