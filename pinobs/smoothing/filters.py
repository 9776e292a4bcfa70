"""The filter a log is smoothed over: its class from the registry (:func:`smoothable_class`),
a maker of it at a density (:func:`filter_maker`), and the log prepared for it
(:func:`prepare_log`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import (
    GainError,
    OptionError,
)
from pinobs.model import Robot
from pinobs.observers.base import (
    GaussianFilter,
    Observer,
    Vector,
    make_observer,
    observer_class,
    observer_names,
)
from pinobs.smoothing.logs import first_good, latency_option, retimed
from pinobs.smoothing.replay import learned_models

__all__ = ["filter_maker", "prepare_log", "smoothable_class"]


def prepare_log(
    robot: Robot,
    t: Vector,
    q: Vector,
    tau: Vector,
    observer: str,
    noise_std: float | None,
    disturbance_psd: float | None,
    filter_options: Mapping[str, Any] | None,
    model_window: float | None,
) -> tuple[tuple[Vector, Vector, Vector, Vector], int, NDArray[np.intp], Any, dict[str, Any]]:
    """The rows the filter runs over (from the first good one), its first index, the row of
    each log sample, and :func:`filter_maker`'s maker and options.  With a ``latency`` in
    ``filter_options`` the rows are the log re-timed (:func:`retimed`); ``adaptive``'s
    learning pass then runs on the log as stamped, with the latency (its own handling), and
    its windows' models are mapped onto the re-timed rows."""
    latency, options = latency_option(filter_options)
    if latency >= t[-1] - t[0]:
        raise GainError(
            f"latency={latency!r} s is not shorter than the log ({t[-1] - t[0]:.6g} s): no sample "
            "would have been taken within it; give the measurement latency in seconds"
        )
    rows = np.arange(t.size)
    run_t, run_q, run_tau = t, q, tau
    if latency > 0.0:
        run_t, run_q, run_tau, rows = retimed(t, q, tau, latency)
    k0, good = first_good(run_q)
    arrays = (run_t[k0:], run_q[k0:], run_tau[k0:], good)
    learn = None
    if latency > 0.0:
        j0, good_j = first_good(q)
        learn = ((t[j0:], q[j0:], tau[j0:], good_j), {**options, "latency": latency})
    make, extra = filter_maker(
        robot, observer, arrays, noise_std, disturbance_psd, options, model_window, learn
    )
    if latency > 0.0:
        extra = {**extra, "latency": latency}
    return arrays, k0, rows, make, extra


def smoothable_class(observer: str) -> type[Observer[Any]]:
    """The class of ``observer``, if a smoother can run it (its
    :attr:`~pinobs.observers.base.Observer.smoothable`; else :class:`OptionError`)."""
    cls = observer_class(observer)
    if not cls.smoothable:
        smoothable = [n for n in observer_names() if observer_class(n).smoothable]
        raise OptionError(
            f"observer {observer!r} keeps no error-state covariance to smooth; "
            f"smoothable: {smoothable}"
        )
    return cls


def filter_maker(
    robot: Robot,
    observer: str,
    arrays: tuple[Vector, Vector, Vector, Vector],
    noise_std: float | None,
    disturbance_psd: float | None,
    filter_options: Mapping[str, Any] | None,
    model_window: float | None,
    learn: tuple[tuple[Vector, Vector, Vector, Vector], Mapping[str, Any]] | None = None,
) -> tuple[Callable[..., GaussianFilter], dict[str, Any]]:
    """``make(accel_psd)`` -> the filter the smoother runs over ``arrays`` (``None``: the
    observer's own density), and the options to report beyond the filter's (``adaptive``:
    after its learning pass, over ``learn``'s arrays with its options when given: a known
    latency, :func:`prepare_log`)."""
    cls = smoothable_class(observer)
    if cls.learns_model:
        if disturbance_psd is not None:
            raise OptionError(
                f"disturbance_psd={disturbance_psd!r}: adaptive's densities are its regimes' "
                "(give them in filter_options: disturbance_psd, learned_disturbance_psd, ...)"
            )
        if learn is None:
            return learned_models(
                robot, *arrays, noise_std, dict(filter_options or {}), model_window
            )
        return learned_models(
            robot, *learn[0], noise_std, learn[1], model_window, frozen_t=arrays[0]
        )
    if model_window is not None:
        raise OptionError(
            f"model_window={model_window!r} is for a filter that learns its model (adaptive), "
            f"not {observer!r}"
        )

    density = cls.process_density  # the process density make() sets
    options = dict(filter_options or {})
    if disturbance_psd is not None:
        options["disturbance_psd"] = disturbance_psd

    def make(psd: float | None) -> GaussianFilter:
        extra = {} if psd is None else {density: psd}
        filt = make_observer(observer, robot, noise_std=noise_std, **{**options, **extra})
        return filt.smoothing_filter()  # kf: its predict and correct apart (WhiteJerkFilter)

    return make, {}
