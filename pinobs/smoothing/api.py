"""What a user calls: :func:`smooth` (with its warnings; :func:`~pinobs.smoothing.pipeline.smooth_quietly`
without), and
:func:`streaming_smoother` (a :class:`~pinobs.smoothing.rts.Smoother` for a log read as it
goes).

**The options of** :func:`smooth` **in full** (its docstring lists them in short):

- ``log``: ``(t, q)`` or ``(t, q, tau)`` arrays (a tuple or a list, or a mapping with those
  keys), or an object with ``t``, ``q``, ``tau`` attributes (:class:`pinobs.io.Log`; a
  :class:`pinobs.Result` is read through its ``q_meas``): times [s] ``(N,)`` strictly
  increasing, at any intervals (an interval of ``m ≥ 2`` median intervals holds ``m − 1``
  samples the log lost: they are predicted over at their ticks, each with its torque on the
  line between its neighbours', :func:`pinobs.model.sampling.on_ticks`;
  ``options["missing_samples"]``); measured configurations ``(N, nq)``, a row with a
  non-finite entry being a dropped sample (predicted over, not corrected with; rows before
  the first good one get NaN); torques applied from each sample on [N·m or N] ``(N, nv)``
  (zero-order hold, MATH §7; ``None``: zero).
- ``observer``: ``"adaptive"`` has its learned model frozen per ``model_window``
  (:mod:`pinobs.smoothing`); the model-free ``"kf"`` (white jerk, no torque) is the floor
  where the model is wrong.
- ``noise_std``: ``None`` is the median over joints of its estimate from the log's first
  second (:func:`pinobs.observers.noise.noise_from_log`; at least
  :data:`~pinobs.observers.base.NOISE_FLOOR`), warned (:class:`~pinobs.errors.NoiseWarning`)
  and reported in ``options`` (``noise_std``, ``noise_std_from_log``).
- ``accel_psd``: ``None`` is the observer's own (``ekf``: :data:`DEFAULT_ACCEL_PSD`;
  ``adaptive``: each window's regime's; ``kf`` takes no number: its density is ``jerk_psd``
  in ``filter_options``, default (and with ``"auto"``, the causal filter's default) 1e3
  rad²/s⁵); ``"auto"`` is chosen from this log, for ``ekf`` by :func:`select_accel_psd` (one
  forward pass per grid value), for ``kf`` its ``jerk_psd`` likewise (:data:`JERK_GRID`,
  then the half-decades either side), for ``adaptive`` by :func:`consistent_offset_scale`
  (``ρ = 1``; 3–7 smoother passes); :mod:`pinobs.smoothing`.  Reported in ``options``
  (``accel_psd``, ``accel_psd_from_log``).
- ``overlap``: default :func:`default_overlap`: agreement with the whole-log smoother to
  :data:`CHUNK_TOL` of ``v_std``.
- ``model_window``: default ``adaptive``'s ``horizon``, 10 s (:mod:`pinobs.smoothing`).
- ``filter_options``: for ``adaptive``, those of its causal learning pass.  ``latency`` [s],
  a known measurement latency (the sample stamped ``t`` was taken at ``t − latency``, as
  :meth:`pinobs.observers.base.Observer.set_latency`): the log is smoothed on the times its
  samples were taken, the torque switching at the stamped times, and the estimate given at
  the stamped times (:func:`retimed`; reported in ``options["latency"]``); ``"auto"``: the
  likeliest latency from the log (:func:`select_latency`, at ``accel_psd`` if a number is
  given, else the observer's own density; ``options["latency_from_log"]``).  Not given: 0,
  unless the model does not explain the log as stamped (``ρ`` > :data:`RHO_WARN`), which is
  then searched as with ``"auto"`` and smoothed under the latency found if that explains it
  (``ρ`` ≤ :data:`RHO_WARN`; ``options["latency_searched"]``,
  ``"consistency_without_latency"``; :mod:`pinobs.smoothing`), or ``accel_psd="auto"`` chose
  a density above ``ekf``'s own (``"accel_psd_without_latency"``); ``0``: as stamped.
- ``band`` (:data:`BANDS`): ``"model"``, the smoother's covariance ``P^s`` under the filter's
  noise model (white acceleration and offset as modelled); ``"noise"``, the covariance of
  the same estimate's error driven by the measurement noise alone (:func:`_backward`), for a
  model error that is smooth in time, which the forward and backward passes lag in opposite
  directions and the smoother cancels (:mod:`pinobs.smoothing`); ``"inflated"``, the noise
  band scaled by ``√max(1, ρ)`` (``ρ`` = :attr:`Smoothed.consistency` of this log;
  :mod:`pinobs.smoothing`: a model error the densities do not explain widens it, never below
  the noise's own); ``None``: ``"inflated"`` over ``adaptive`` with its regimes' densities
  (tuned for the causal filter's tracking, not fitted to the log) and over ``kf`` (a
  robot's motion is not white jerk: :mod:`pinobs.smoothing`), ``"model"`` otherwise
  (``ekf``; densities given or chosen from the log).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import (
    ConsistencyWarning,
    DimensionError,
    GainError,
    LatencyWarning,
    OptionError,
    TimestampWarning,
)
from pinobs.model import Robot
from pinobs.observers.base import (
    Vector,
    median_period,
    observer_class,
    positive,
    time_unit_warning,
)
from pinobs.smoothing.constants import (
    BANDS,
    DEFAULT_GRID,
    OVERLAP_CONFIGURATIONS,
    RHO_WARN,
)
from pinobs.smoothing.filters import filter_maker
from pinobs.smoothing.latency import LATENCY_INTERVALS, latency_note
from pinobs.smoothing.logs import LogLike, latency_option
from pinobs.smoothing.pipeline import smooth_quietly
from pinobs.smoothing.rts import Smoothed, Smoother
from pinobs.smoothing.windows import spread_configurations, window_samples

__all__ = ["smooth", "smoothing_warnings", "streaming_smoother"]


def streaming_smoother(
    robot: Robot,
    *,
    dt: float,
    observer: str = "ekf",
    noise_std: float | None = None,
    accel_psd: float | None = None,
    disturbance_psd: float | None = None,
    chunk: float | None = None,
    overlap: float | None = None,
    lag: float | None = None,
    filter_options: Mapping[str, Any] | None = None,
    band: str = "model",
    configurations: ArrayLike | None = None,
) -> tuple[Callable[[], Smoother], dict[str, Any]]:
    """A maker of :class:`Smoother` for a log read as it goes (memory bounded by ``chunk`` or
    ``lag``), and the options to report; the arguments as :func:`smooth`, ``dt`` the
    nominal sample period [s] (the chunks are counted in samples of it), ``configurations``
    rows of ``q`` the log visits, its first sample first (with a torque offset the default
    overlap depends on the inertia along them, :func:`default_overlap`; default the robot's
    neutral configuration and :data:`OVERLAP_CONFIGURATIONS` − 1 random ones, seed 0).

    Not for ``accel_psd="auto"`` or ``adaptive``: both pass over the log more than once.
    ``noise_std`` is required: a stream has no log to estimate it from
    (:func:`pinobs.io.smoothing.smooth_log` estimates it from the log's first chunk).

    Raises:
        OptionError: those two, or neither ``chunk`` nor ``lag`` (the whole log is not a stream).
        GainError: no ``noise_std``.
    """
    _check_streamable(observer, accel_psd, chunk, lag, band, filter_options, dt, noise_std)
    empty = np.empty(0)
    make, extra = filter_maker(
        robot,
        observer,
        (empty, empty, empty, empty),
        noise_std,
        disturbance_psd,
        filter_options,
        None,
    )
    filt = make(accel_psd)
    configs = _overlap_configurations(robot, configurations)
    n_chunk, n_over = window_samples(
        filt, extra, accel_psd, chunk, overlap, lag, dt, robot=robot, configurations=configs
    )
    opts = {
        **filt.options,
        "observer": observer,
        "chunk": None if n_chunk is None else n_chunk * dt,
        "overlap": n_over * dt if n_over else None,
        "lag": lag,
        "band": band,
    }
    return (lambda: Smoother(make(accel_psd), n_chunk, n_over, band)), opts


def _check_streamable(
    observer: str,
    accel_psd: float | None,
    chunk: float | None,
    lag: float | None,
    band: str,
    filter_options: Mapping[str, Any] | None,
    dt: float,
    noise_std: float | None,
) -> None:
    """:func:`streaming_smoother`'s refusals (its docstring), before any filter is made."""
    cls = observer_class(observer)
    if accel_psd == "auto" or cls.learns_model or (chunk is None and lag is None):
        raise OptionError(
            f"a streamed smoother needs chunk or lag, a given accel_psd and a filter with one "
            f"model (got observer={observer!r}, accel_psd={accel_psd!r}, chunk={chunk!r}, "
            f"lag={lag!r}); use smooth() on the whole log"
        )
    if band not in BANDS[:2]:
        raise OptionError(
            f"band={band!r}: a streamed smoother gives one of {list(BANDS[:2])} ('inflated' "
            "scales by the whole log's ρ: use smooth() on the whole log)"
        )
    if latency_option(filter_options)[0] > 0.0:
        raise OptionError(
            "a known latency re-times the whole log (its samples on the times they were "
            "taken): use smooth() on the whole log"
        )
    positive("dt", dt)
    if noise_std is None:  # the filter's default σ would be used, silently
        raise GainError(
            "a streamed smoother needs noise_std [rad or m]: it has no log to estimate it from"
        )


def _overlap_configurations(robot: Robot, configurations: ArrayLike | None) -> Vector:
    """The configurations the default overlap takes the inertia at: the finite rows of
    ``configurations`` spread out, or the neutral one and random ones (seed 0)."""
    if configurations is None:
        rng = np.random.default_rng(0)
        configs = np.array(
            [robot.neutral()]
            + [robot.random_configuration(rng) for _ in range(OVERLAP_CONFIGURATIONS - 1)]
        )
    else:
        configs = np.asarray(configurations, dtype=float).reshape(-1, robot.nq)
        configs = spread_configurations(configs[np.all(np.isfinite(configs), axis=1)])
        if not len(configs):
            raise DimensionError("configurations has no finite row of q")
    return configs


def smoothing_warnings(consistency: float, options: Mapping[str, Any]) -> list[str]:
    """What :func:`smooth` warns of its result (:class:`~pinobs.errors.ConsistencyWarning`),
    from its ``consistency`` ``ρ`` and ``options`` (``accel_psd_from_log``: ``"auto"`` was asked):

    * ``ρ`` above :data:`RHO_WARN`: the model does not explain the log, so the estimate
      follows a model error, and a band that ``ρ`` does not scale is too narrow;
    * ``"auto"`` over ``ekf`` chose the grid's largest density: the likelihood still rises
      there, so the model explains the log no better than white acceleration does, and the
      smoother is model-free (measured on the learning benchmark's six model-error logs of
      seed 1, 12 s: ``"auto"`` chose 1 rad²/s³ on every one, RMS 1.24e-2 to 1.26e-2 rad/s,
      98–126× the smoother over ``adaptive``'s; at the default 1e-8, 0.25–2.4 rad/s with
      ``ρ`` 3e8 to 3e9 and a model band that covers none of the truth).
    """
    said = []
    band = options.get("band")
    if options.get("accel_psd_from_log") and options.get("accel_psd") == DEFAULT_GRID[-1]:
        said.append(
            f"accel_psd='auto' chose {DEFAULT_GRID[-1]:g} rad²/s³, the largest it tries: the "
            "model explains the log no better than white acceleration does (the smoother is "
            "model-free, and white acceleration is a poorer prior than the model-free kf's white "
            "jerk); check the model and the torques, or smooth with observer='adaptive' (learns "
            "the model) or observer='kf' with accel_psd='auto' (model-free)"
        )
    if math.isfinite(consistency) and consistency > RHO_WARN:
        scale = math.sqrt(consistency)
        widened = (
            f"the band is widened by √ρ = {scale:.3g}"
            if band == "inflated"
            else f"the {band} band is too narrow, by about √ρ = {scale:.3g} (band='inflated' "
            "scales it)"
        )
        latency = (
            f"no measurement latency of up to {LATENCY_INTERVALS} sample intervals explains it "
            "(searched); check the model, the torques"
            if options.get("latency_searched")
            else "check the model, the torques, a measurement latency (filter_options="
            "{'latency': 'auto'} finds one)"
        )
        check = (
            f"{latency} and noise_std, or smooth with accel_psd='auto', "
            "observer='adaptive' (learns the model) or observer='kf' (model-free)"
        )
        if options.get("observer") == "kf":  # no model: its white jerk is too small
            check = (
                "the motion has more jerk than jerk_psd says: smooth with accel_psd='auto' "
                "(chosen from the log), or check noise_std"
            )
        said.append(
            f"the model does not explain the log: filter–smoother consistency ρ = "
            f"{consistency:.3g} (about 1 when it does; above {RHO_WARN:g}, the estimate follows "
            f"a model error); {widened}; {check}"
        )
    return said


def _warn_time_unit(log: LogLike | tuple[ArrayLike, ...]) -> None:
    """:class:`~pinobs.errors.TimestampWarning` for a median sample period of 0.1 s or more, or
    1 µs or less: a log timed in ms reads as 1000× too slow (the filter is lost, or ``v``
    1000× too small)."""
    try:
        times = log[0] if isinstance(log, tuple) else log.t
        unit = time_unit_warning(median_period(np.asarray(times, dtype=float).ravel()))
    except (AttributeError, TypeError, ValueError, IndexError):
        unit = None  # smooth_quietly says what is wrong with the log
    if unit is not None:
        warnings.warn(TimestampWarning(unit), stacklevel=3)  # the caller of smooth()


def smooth(
    robot: Robot,
    log: LogLike | tuple[ArrayLike, ...],
    *,
    observer: str = "ekf",
    noise_std: float | None = None,
    accel_psd: float | Literal["auto"] | None = None,
    disturbance_psd: float | None = None,
    chunk: float | None = None,
    overlap: float | None = None,
    lag: float | None = None,
    model_window: float | None = None,
    filter_options: Mapping[str, Any] | None = None,
    band: str | None = None,
) -> Smoothed:
    """Fixed-interval RTS smoothing of a log on the manifold (equations: :mod:`pinobs.smoothing`;
    each option in full, and what it reports in ``options``: this module's docstring).

    Args:
        robot: the model (the filter's process model; ``adaptive``'s nominal model).
        log: ``(t, q)`` or ``(t, q, tau)``: times [s] ``(N,)``, configurations ``(N, nq)`` (a
            non-finite row is a dropped sample), torques held from each sample [N·m or N]
            ``(N, nv)``; arrays, a mapping, a :class:`pinobs.io.Log` or a :class:`pinobs.Result`.
        observer: the filter smoothed: ``"ekf"``, ``"adaptive"`` or the model-free ``"kf"``.
        noise_std: position noise standard deviation [rad or m]; ``None``: from the log, warned.
        accel_psd: white-acceleration density of the filter [rad²/s³]; ``None``: the
            observer's own; ``"auto"``: chosen from this log.
        disturbance_psd: the EKF's torque offset density [rad²/s⁵] (``adaptive``: its regimes').
        chunk: memory bound: the backward pass runs on windows of ``chunk``
            seconds (``None``: the whole log at once).
        overlap: seconds of later samples each window's backward pass starts from.
        lag: fixed-lag mode [s]: chunks of ``lag``, ``lag`` of overlap (no ``chunk``, ``overlap``).
        model_window: ``adaptive`` only: the window [s] over which its learned model is frozen.
        filter_options: further options of the filter (``q0_std``, ``v0_std``, ...);
            ``latency``: a measurement latency [s], or ``"auto"`` (found in the log).
        band: what ``v_std`` states: ``"model"``, ``"noise"`` or ``"inflated"``; ``None``:
            ``"inflated"`` over ``adaptive`` and ``kf``, ``"model"`` over ``ekf``.

    Raises:
        UnknownNameError, OptionError: ``observer`` is unknown or cannot be smoothed, or an
            option it does not take; ``overlap`` without ``chunk``; ``filter_options`` not a
            mapping, or with ``noise_std`` or ``rate`` (given to :func:`smooth`, or the log's).
        GainError: a non-positive ``noise_std``, ``chunk``, ``overlap``, ``lag`` or
            ``model_window``, a latency not shorter than the log, a bad filter option, or no
            ``noise_std`` and too few finite rows to estimate it.
        DimensionError, TimestampError, NonFiniteError: malformed log arrays.
        ConfigurationError: rows with a quaternion or ``(cos, sin)`` pair off unit norm
            (before any pass; NaN such rows to smooth over them).

    Warns:
        NoiseWarning: ``noise_std`` not given (σ estimated from the log).
        CostWarning: a ``chunk`` more than :data:`COST_WARN` times shorter than its overlap.
        ChunkWarning: an ``overlap`` given shorter than :func:`default_overlap`'s.
        TimestampWarning: a median sample period ≥ 0.1 s or ≤ 1 µs (``t`` in ms, µs or ns?).
        LatencyWarning: the log explained only with a latency found in it (:func:`latency_note`).
        ConsistencyWarning: ``ρ`` (:attr:`Smoothed.consistency`) above :data:`RHO_WARN`,
            or ``"auto"`` at the grid's largest density (:func:`smoothing_warnings`).
    """
    _warn_time_unit(log)
    result = smooth_quietly(
        robot,
        log,
        observer=observer,
        noise_std=noise_std,
        accel_psd=accel_psd,
        disturbance_psd=disturbance_psd,
        chunk=chunk,
        overlap=overlap,
        lag=lag,
        model_window=model_window,
        filter_options=filter_options,
        band=band,
        find_latency=True,
    )
    note = latency_note(result.options)
    if note is not None:
        warnings.warn(LatencyWarning(note), stacklevel=2)
    for said in smoothing_warnings(result.consistency, result.options):
        warnings.warn(ConsistencyWarning(said), stacklevel=2)
    return result
