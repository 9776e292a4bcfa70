"""The steps of :func:`smooth_quietly` (:func:`pinobs.smooth` without its warnings): the
arguments checked, the log on its ticks, the filter prepared at the latency asked or found, its
density, the windows, the passes, the result, and a latency searched where the model does not
explain the log."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal, NamedTuple, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import (
    GainError,
    NoiseWarning,
    NonFiniteError,
    ObserverDiverged,
    OptionError,
)
from pinobs.model import Robot
from pinobs.model.sampling import on_ticks
from pinobs.observers.base import (
    Vector,
    positive,
)
from pinobs.observers.kf import WhiteJerkFilter
from pinobs.smoothing.constants import (
    AUTO_WHITE_SCALE,
    BANDS,
    DEFAULT_GRID,
    JERK_GRID,
    LIKELIHOOD_MARGIN,
    RHO_WARN,
)
from pinobs.smoothing.densities import consistent_scale, select_density
from pinobs.smoothing.filters import prepare_log, smoothable_class
from pinobs.smoothing.jerk import white_jerk_smooth
from pinobs.smoothing.latency import likeliest_latency
from pinobs.smoothing.logs import LogLike, at_rows, latency_option, log_noise_std, smoothing_arrays
from pinobs.smoothing.rts import Smoothed, Smoother, log_rows
from pinobs.smoothing.windows import spread_configurations, window_samples

__all__ = ["smooth_quietly"]


def _filter_options(options: Any) -> dict[str, Any]:
    """``filter_options`` as a dict, or :class:`OptionError` (not a mapping, or an option
    :func:`smooth` takes itself)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise OptionError(
            f"filter_options is a {type(options).__name__}; give a mapping of option names to "
            "values, e.g. {'latency': 0.001}"
        )
    for name, why in (
        ("noise_std", "give noise_std= to smooth()"),
        ("rate", "the log's times set it"),
    ):
        if name in options:
            raise OptionError(f"filter_options[{name!r}]: not a filter option here ({why})")
    return dict(options)


def smooth_quietly(
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
    find_latency: bool = False,
    _prepared: dict[float, Any] | None = None,
) -> Smoothed:
    """:func:`smooth` without its warnings (the same arguments and result), for callers that
    report the consistency their own way (a log file's run, the identification's refinement).

    ``find_latency``: a log the model does not explain, with no latency given, is searched
    for one (:func:`smooth` sets it).  ``_prepared`` is internal: :func:`prepare_log`'s results
    by latency, shared with the latency search's own calls.

    The steps: the arguments checked (:func:`_checked`), the log on its ticks with its
    ``σ`` (:func:`_on_ticks`), the filter's preparation at the latency asked or found
    (:func:`_prepared_at`), its density (:func:`_density_filter`), the windows
    (:func:`_window_sizes`), the passes (:func:`_smoothed_rows`), the result
    (:func:`_result`), and a latency searched where the model does not explain the log
    (:func:`_latency_retried`)."""
    accel_psd, options, band, cls = _checked(
        observer, noise_std, accel_psd, chunk, overlap, lag, filter_options, band
    )
    ticks, noise_std, noise_from_data = _on_ticks(robot, log, noise_std)
    req = _Request(
        robot=robot,
        ticks=ticks,
        observer=observer,
        noise_std=noise_std,
        noise_from_data=noise_from_data,
        asked_psd=accel_psd,
        disturbance_psd=disturbance_psd,
        chunk=chunk,
        overlap=overlap,
        lag=lag,
        model_window=model_window,
        band=band,
        adaptive=cls.learns_model,
        model_free=cls.model_free,
        prepared={} if _prepared is None else _prepared,
    )
    options, latency_from_log, (arrays, k0, rows, make, extra) = _prepared_at(req, options)
    filt, accel_psd, extra = _density_filter(req, make, arrays, k0, extra)
    n_run, n_chunk, n_over, dt = _window_sizes(req, filt, extra, accel_psd, arrays, k0)
    passes = _smoothed_rows(req, filt, arrays, k0, n_run, n_chunk, n_over)
    result = _result(req, filt, extra, accel_psd, rows, passes, n_chunk, n_over, dt)
    result = replace(result, options={**result.options, "latency_from_log": latency_from_log})
    # "auto" over ekf makes ρ about 1 whatever the log: a density above the filter's default
    # says the model does not explain the log at its own density, which a latency might (a
    # UR5 log 2 ms late: "auto" took 1e-2 rad²/s³, ρ 0.605, RMS 9.45e-3 rad/s; 1.8e-5 under
    # the latency)
    hidden = (
        req.asked_psd == "auto"
        and not req.adaptive
        and not req.model_free
        and isinstance(accel_psd, float)
        and accel_psd > make(None).gains.accel_psd
    )
    rho = result.consistency
    if not (
        find_latency
        and "latency" not in options
        and not req.model_free  # without a model a late log is as likely: nothing to find
        and math.isfinite(rho)
        and (rho > RHO_WARN or hidden)
    ):
        return at_rows(result, ticks.rows, ticks.t_given)
    hidden_psd = accel_psd if hidden and isinstance(accel_psd, float) else None
    return _latency_retried(req, result, options, hidden_psd)


class _Ticks(NamedTuple):
    """A log on the grid of its ticks (:func:`~pinobs.model.sampling.on_ticks`): its arrays,
    and the given log's rows among them and times (``rows`` None: nothing was missing)."""

    t: Vector
    q: Vector
    tau: Vector
    rows: NDArray[np.intp] | None
    t_given: Vector


@dataclass(frozen=True)
class _Request:
    """What :func:`smooth_quietly` was asked, checked, and the log on its ticks; ``prepared``
    (latency → :func:`prepare_log`'s results) is shared with the latency search's calls."""

    robot: Robot
    ticks: _Ticks
    observer: str
    noise_std: float
    noise_from_data: bool
    asked_psd: float | str | None
    disturbance_psd: float | None
    chunk: float | None
    overlap: float | None
    lag: float | None
    model_window: float | None
    band: str
    adaptive: bool
    model_free: bool
    prepared: dict[float, Any]


def _checked(
    observer: str,
    noise_std: float | None,
    accel_psd: Any,
    chunk: float | None,
    overlap: float | None,
    lag: float | None,
    filter_options: Mapping[str, Any] | None,
    band: str | None,
) -> tuple[Any, dict[str, Any], str, Any]:
    """:func:`smooth_quietly`'s arguments checked before any pass over the log: ``accel_psd``
    (a float, ``"auto"`` or ``None``), the filter options as a dict, the band (its default
    resolved: :mod:`pinobs.smoothing`) and the observer's class."""
    if accel_psd is not None and not isinstance(accel_psd, str):  # a float from here on
        accel_psd = positive("accel_psd", accel_psd)
    positive("noise_std", noise_std, allow_none=True)  # (a filter would floor 0 to NOISE_FLOOR)
    options = _filter_options(filter_options)
    if lag is not None and (chunk is not None or overlap is not None):
        raise OptionError(
            f"lag={lag!r} sets the chunk and the overlap; give lag alone, or chunk and overlap"
        )
    if isinstance(accel_psd, str) and accel_psd != "auto":
        raise GainError(f"accel_psd={accel_psd!r}: give a number > 0 [rad²/s³] or 'auto'")
    for name, seconds in (("chunk", chunk), ("overlap", overlap), ("lag", lag)):
        positive(name, seconds, allow_none=True)  # before any pass over the log
    cls = smoothable_class(observer)
    if cls.model_free and accel_psd is not None and accel_psd != "auto":
        raise OptionError(
            f"accel_psd={accel_psd!r}: {observer!r} has no white acceleration; its process "
            f"density is its white jerk: give filter_options={{'jerk_psd': {accel_psd!r}}} "
            "[rad²/s⁵], or accel_psd='auto' to choose it from the log"
        )
    if band is None:  # the noise band where the densities are adaptive's causal regimes'
        band = "inflated" if (cls.learns_model and accel_psd is None) or cls.model_free else "model"
    if band not in BANDS:
        raise OptionError(f"band={band!r}: give one of {list(BANDS)}")
    return accel_psd, options, band, cls


def _on_ticks(
    robot: Robot, log: LogLike | tuple[ArrayLike, ...], noise_std: float | None
) -> tuple[_Ticks, float, bool]:
    """The log's arrays on the grid of its ticks, its ``σ`` (from the log if not given:
    :func:`log_noise_std`, warned), and whether it came from the log."""
    t_all, q_all, tau_all = smoothing_arrays(robot, log)
    # dropped samples: smoothed on the grid of ticks, each missing one predicted over with
    # its torque on the line between its neighbours' (pinobs.model.sampling), and the
    # estimate given at the log's own rows (given_rows; None: nothing was missing)
    t_given = t_all
    t_all, q_all, tau_all, given_rows = on_ticks(t_all, q_all, tau_all)
    noise_from_data = noise_std is None
    if noise_std is None:
        noise_std, _, said = log_noise_std(robot, t_all, q_all)
        warnings.warn(NoiseWarning(said), stacklevel=4)  # the caller of smooth()
    return _Ticks(t_all, q_all, tau_all, given_rows, t_given), noise_std, noise_from_data


def _find_latency(
    req: _Request, options: Mapping[str, Any] | None, tried: dict[float, float] | None = None
) -> float:
    """:func:`select_latency` on the log, its passes shared through ``req.prepared``."""
    ticks = req.ticks
    return likeliest_latency(
        req.robot,
        (ticks.t, ticks.q, ticks.tau),
        req.noise_std,
        req.observer,
        req.asked_psd if isinstance(req.asked_psd, float) else None,
        req.disturbance_psd,
        options,
        req.model_window,
        prepared=req.prepared,
        tried=tried,
    )[0]


def _prepared_at(
    req: _Request, options: dict[str, Any]
) -> tuple[dict[str, Any], bool, tuple[Any, ...]]:
    """The filter options (``latency="auto"`` replaced by the latency found:
    :func:`select_latency`), whether it was found, and :func:`prepare_log`'s results at that
    latency (``adaptive``: its learning pass), once per latency."""
    latency_from_log = options.get("latency") == "auto"
    if latency_from_log and req.model_free:
        raise OptionError(
            f"latency='auto' with {req.observer!r}: without a model a late log is as likely as "
            "one on time, so the log cannot tell its latency; give it in seconds, or smooth "
            "with ekf or adaptive to find it"
        )
    if latency_from_log:  # the likeliest latency (select_latency), then smoothed under it
        rest = {k: v for k, v in options.items() if k != "latency"}
        options = {**rest, "latency": _find_latency(req, rest)}
    latency = latency_option(options)[0]
    if latency not in req.prepared:  # (adaptive: the learning pass)
        ticks = req.ticks
        req.prepared[latency] = prepare_log(
            req.robot,
            ticks.t,
            ticks.q,
            ticks.tau,
            req.observer,
            req.noise_std,
            req.disturbance_psd,
            options,
            req.model_window,
        )
    return options, latency_from_log, req.prepared[latency]


def _density_filter(
    req: _Request, make: Callable[..., Any], arrays: Any, k0: int, extra: dict[str, Any]
) -> tuple[Any, Any, dict[str, Any]]:
    """The filter at the density asked, or chosen from the log with ``"auto"``
    (:func:`select_accel_psd`; ``adaptive``: :func:`consistent_offset_scale`, ``ρ = 1``),
    that density, and the options to report."""
    accel_psd = req.asked_psd
    if accel_psd == "auto" and req.adaptive:
        offset_scale = consistent_scale(make, arrays)  # ρ = 1 (consistent_offset_scale)
        extra = {
            **extra,
            "offset_scale": offset_scale,
            "model_accel_psd": [AUTO_WHITE_SCALE * a for a in extra["model_accel_psd"]],
            "model_densities": [
                (AUTO_WHITE_SCALE * a, offset_scale * d) for a, d in extra["model_densities"]
            ],
        }
        return make(None, offset_scale), accel_psd, extra
    if accel_psd == "auto":
        grid = JERK_GRID if req.model_free else DEFAULT_GRID  # kf: its jerk_psd
        accel_psd = select_density(make, arrays, k0, grid, LIKELIHOOD_MARGIN, req.model_free)
    return make(None if isinstance(accel_psd, str) else accel_psd), accel_psd, extra


def _window_sizes(
    req: _Request, filt: Any, extra: dict[str, Any], accel_psd: Any, arrays: Any, k0: int
) -> tuple[int, int, int, float]:
    """The rows the filter runs over (the log's, or re-timed: :func:`prepare_log`), the
    window and overlap in samples (:func:`window_samples`), and the sample interval [s]."""
    run_t = arrays[0]
    n_run = k0 + run_t.size
    dt = meas_dt = float(np.median(np.diff(req.ticks.t)))
    if "latency" in extra and run_t.size > 1:  # re-timed rows: their mean interval
        dt = float(run_t[-1] - run_t[0]) / (run_t.size - 1)
    configs = spread_configurations(arrays[1][arrays[3]])  # rows measured, from the first
    n_chunk, n_over = window_samples(
        filt,
        extra,
        accel_psd,
        req.chunk,
        req.overlap,
        req.lag,
        dt,
        meas_dt,
        robot=req.robot,
        configurations=configs,
        rows=n_run,
    )
    return n_run, n_run if n_chunk is None else n_chunk, n_over, dt


def _smoothed_rows(
    req: _Request, filt: Any, arrays: Any, k0: int, n_run: int, n_chunk: int, n_over: int
) -> tuple[Vector, Vector, Vector, float, float, int, float]:
    """The passes: ``(q^s, v^s, var, log-likelihood, ρ, its terms, band scale)`` over the
    filter's rows (NaN before its first, ``k0``), compiled for ``kf`` on a vector space
    (:func:`white_jerk_smooth`), else :class:`Smoother` fed row by row."""
    model = filt.robot
    out_q = np.full((n_run, model.nq), np.nan)
    out_v = np.full((n_run, model.nv), np.nan)
    out_var = np.full((n_run, model.nv), np.nan)
    inner = "noise" if req.band == "inflated" else req.band  # scaled below, once ρ is known
    window = None if n_over == 0 else n_chunk
    if req.model_free and model.is_vector_space:  # the same in compiled passes
        jerk = cast(WhiteJerkFilter, filt)
        out_q[k0:], out_v[k0:], out_var[k0:], loglik, rho_sum, terms = white_jerk_smooth(
            jerk, arrays, window, n_over, inner
        )
        rho = rho_sum / terms if terms else math.nan
    else:
        smoother = Smoother(filt, window, n_over, inner)

        def keep(done: list[tuple[int, Vector, Vector, Vector]]) -> None:
            for k, qs, vs, var in done:
                out_q[k0 + k], out_v[k0 + k], out_var[k0 + k] = qs, vs, var

        for row in log_rows(*arrays):
            keep(smoother.push(*row))
        keep(smoother.close())
        loglik, rho, terms = (
            smoother.log_likelihood,
            smoother.consistency,
            smoother.consistency_terms,
        )
    # "inflated": the a-posteriori variance factor of least squares (σ̂₀², Koch 1999, §3.2.2),
    # ρ, scales the noise band where the log's filter–smoother differences exceed the model's
    scale = math.sqrt(max(1.0, rho)) if req.band == "inflated" and math.isfinite(rho) else 1.0
    out_var *= scale**2
    if not (np.all(np.isfinite(out_v[k0:])) and np.all(np.isfinite(out_var[k0:]))):
        raise NonFiniteError(
            "the smoothed estimate is not finite (the filter is lost): check the model, the "
            "torques and noise_std, or smooth with accel_psd='auto' or observer='adaptive'"
        )
    return out_q, out_v, out_var, loglik, rho, terms, scale


def _result(
    req: _Request,
    filt: Any,
    extra: dict[str, Any],
    accel_psd: Any,
    rows: Any,
    passes: tuple[Vector, Vector, Vector, float, float, int, float],
    n_chunk: int,
    n_over: int,
    dt: float,
) -> Smoothed:
    """The :class:`Smoothed` of the passes, on the log's ticks (each row's estimate; re-timed
    under a latency: :func:`retimed`), with its options."""
    out_q, out_v, out_var, loglik, rho, terms, scale = passes
    # kf: none (its jerk_psd, chosen or given, is among the filter's options); adaptive
    # without a given density: each window's regime's (extra["model_accel_psd"])
    reported_psd = None
    if not req.model_free and (isinstance(accel_psd, float) or not req.adaptive):
        reported_psd = accel_psd if isinstance(accel_psd, float) else filt.gains.accel_psd
    opts = {
        **filt.options,
        **extra,
        "accel_psd": reported_psd,
        "observer": req.observer,
        "chunk": None if req.chunk is None and req.lag is None else n_chunk * dt,
        "overlap": n_over * dt if n_over else None,
        "lag": req.lag,
        "band": req.band,
        "band_scale": scale,
        "consistency_terms": terms,
        "noise_std": req.noise_std,
        "noise_std_from_log": req.noise_from_data,
        "accel_psd_from_log": req.asked_psd == "auto",
        "latency": float(extra.get("latency", 0.0)),
        "latency_from_log": False,
        "latency_searched": False,
        "missing_samples": req.ticks.t.size - req.ticks.t_given.size,
    }
    return Smoothed(
        t=req.ticks.t,
        q=out_q[rows],  # each log sample's row (re-timed under a latency: retimed)
        v=out_v[rows],
        v_std=np.sqrt(np.maximum(out_var[rows], 0.0)),
        log_likelihood=loglik,
        consistency=rho,
        options=opts,
    )


def _latency_retried(
    req: _Request, result: Smoothed, options: dict[str, Any], hidden_psd: float | None
) -> Smoothed:
    """The model does not explain the log (``ρ`` > :data:`RHO_WARN`, or ``"auto"`` chose
    ``hidden_psd``, a density above the filter's own): a measurement latency might (module
    docstring).  Adopted only if the log smoothed under it is consistent (``ρ`` ≤
    :data:`RHO_WARN`) and, where ``"auto"`` chose the density, likelier by
    :data:`LIKELIHOOD_MARGIN` (each at its own chosen density); ``result`` otherwise, with
    what was searched in its options."""
    hidden = hidden_psd is not None
    loglik, rho, ticks = result.log_likelihood, result.consistency, req.ticks
    found = 0.0
    # the log as stamped is the search's first candidate: its learning pass is done, and so
    # is its likelihood when the density is the one the search takes (not chosen by "auto")
    tried = {} if req.asked_psd == "auto" else {0.0: loglik}
    try:
        found = _find_latency(req, options, tried)
    except (NonFiniteError, ObserverDiverged):
        pass  # lost at every latency: nothing found
    searched = {
        "latency_searched": True,
        "consistency_without_latency": rho,
        "accel_psd_without_latency": hidden_psd,
        "latency_found": found,
    }

    def under(d: float, psd: Any) -> Smoothed:
        return smooth_quietly(
            req.robot,
            (ticks.t, ticks.q, ticks.tau),
            observer=req.observer,
            noise_std=req.noise_std,
            accel_psd=psd,
            disturbance_psd=req.disturbance_psd,
            chunk=req.chunk,
            overlap=req.overlap,
            lag=req.lag,
            model_window=req.model_window,
            filter_options={**options, "latency": d},
            band=req.band,
            _prepared=req.prepared,
        )

    # "auto": the latency must first explain the log at the filter's own density (one pass;
    # the 20 % inertia/payload logs of UR5 and Panda found 0.5–3 ms there, ρ far above)
    if found > 0.0 and (not hidden or under(found, None).consistency <= RHO_WARN):
        retry = under(found, req.asked_psd)
        likelier = retry.log_likelihood > loglik + LIKELIHOOD_MARGIN
        if retry.consistency <= RHO_WARN and (likelier or not hidden):
            retry_options = {
                **retry.options,
                **searched,
                "latency_from_log": True,
                "noise_std_from_log": req.noise_from_data,
                "missing_samples": ticks.t.size - ticks.t_given.size,
            }
            return at_rows(replace(retry, options=retry_options), ticks.rows, ticks.t_given)
    return at_rows(
        replace(result, options={**result.options, **searched}), ticks.rows, ticks.t_given
    )
