"""Checks an observer and the log reader share: options, the sample clock, pauses.

:func:`positive` validates a gain or an option; :func:`median_period` and
:func:`time_unit_warning` read a log's sample period; :func:`gap_substeps` and
:func:`propagate_gap` are the pause rule of the live observer
(:meth:`pinobs.observers.base.Observer.update`) and of the log reader
(:class:`pinobs.io.LogEstimator`), defined once here; :func:`interval_substeps` adds the
samples a loop dropped (MATH §7, **Dropped samples**) and :func:`lost_torque` their torques.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import GainError
from pinobs.model.sampling import MISSING_PERIODS
from pinobs.tolerances import GAP_PERIODS, MAX_PLAUSIBLE_PERIOD, MIN_PLAUSIBLE_PERIOD

__all__ = [
    "MODEL_ACCEL_PSD",
    "gap_substeps",
    "interval_substeps",
    "lost_torque",
    "median_period",
    "model_accel_psd",
    "positive",
    "propagate_gap",
    "time_unit_warning",
]

Vector = NDArray[np.floating[Any]]
S = TypeVar("S")


def positive(
    name: str, value: float | None, *, allow_none: bool = False, allow_zero: bool = False
) -> float | None:
    """Validate a gain or option: a finite real number > 0 (or >= 0), or ``None`` if allowed.

    Raises:
        GainError: naming the option, the value and the accepted range.
    """
    if value is None:
        if allow_none:
            return None
        raise GainError(f"{name} is required: give a finite number > 0")
    if isinstance(value, (str, bytes, bool)) or not isinstance(value, numbers.Real):
        # a string would pass float() here and crash the first update (issue 17)
        raise GainError(f"{name}={value!r} is not a number; give a finite number > 0")
    x = float(value)
    ok = math.isfinite(x) and (x >= 0 if allow_zero else x > 0)
    if not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise GainError(f"{name}={value!r} is out of range; give a finite number {bound}")
    return x


#: The model-based observers' white-acceleration density [rad²/s³] on a robot that carries no
#: model error of its own (:attr:`pinobs.model.Robot.model_error_psd` ``None``): the model
#: trusted as exact.
MODEL_ACCEL_PSD = 1e-8


def model_accel_psd(robot: Any, accel_psd: float | None) -> float:
    """The ``accel_psd`` [rad²/s³] a model-based observer uses: the one given, else the robot's
    own model error (:attr:`~pinobs.model.Robot.model_error_psd`, measured by
    ``pinobs.identify``), else :data:`MODEL_ACCEL_PSD`; checked > 0.

    Raises:
        GainError: a given value that is not a finite number > 0.
    """
    if accel_psd is None:
        own = getattr(robot, "model_error_psd", None)
        accel_psd = MODEL_ACCEL_PSD if own is None else own
    return positive("accel_psd", accel_psd)  # type: ignore[return-value]


def gap_substeps(dt: float, period: float | None, *, span: float = math.inf) -> int:
    """Steps of at most one sample ``period`` [s] over an interval ``dt`` [s]: the pause rule
    of the live observer (:meth:`Observer.update`) and of the log reader
    (:class:`pinobs.io.LogEstimator`).

    ``1`` (one step) unless ``dt`` is longer than :data:`~pinobs.tolerances.GAP_PERIODS`
    periods; then ``⌈min(dt, span) / period⌉`` (``span`` [s]: the most of a pause
    propagated in steps of one period; the steps are ``dt / n`` long).  ``period`` ``None``
    (not known yet): ``1``.
    """
    if period is None or not dt > GAP_PERIODS * period:
        return 1
    return math.ceil(min(dt, span) / period - 1e-9)


def interval_substeps(dt: float, period: float | None, *, span: float = math.inf) -> int:
    """The sub-steps of a model-based observer's step of ``dt`` [s] (MATH §7, **Dropped
    samples**): :func:`gap_substeps`, and below :data:`~pinobs.tolerances.GAP_PERIODS`
    periods ``m = round(dt / period)`` from :data:`~pinobs.model.sampling.MISSING_PERIODS`
    periods on (the ``m − 1`` samples the loop dropped: ``pinobs.model.sampling``'s rule)."""
    n = gap_substeps(dt, period, span=span)
    if n == 1 and period is not None and dt >= MISSING_PERIODS * period:
        return round(dt / period)
    return n


def lost_torque(tau_a: Vector, tau_b: Vector, j: int, n: int) -> Vector:
    """The torque held over sub-step ``j`` (``0 … n − 1``) of ``n`` between samples holding
    ``tau_a`` and ``tau_b`` [N·m or N], on the line between them (MATH §7, **Dropped
    samples**): ``τ_a + (j/n)(τ_b − τ_a)``, ``τ_a`` itself for ``j = 0``."""
    return tau_a if j == 0 else tau_a + (j / n) * (tau_b - tau_a)  # type: ignore[no-any-return]


def propagate_gap(
    advance: Callable[[S, int, int], S],
    state: S,
    dt: float,
    period: float | None,
    *,
    span: float = math.inf,
) -> tuple[S, int]:
    """The predictions through a step of ``dt`` [s] split by the pause rule: ``(state, n)``.

    ``n = gap_substeps(dt, period, span=span)`` (:func:`gap_substeps`); ``state ←
    advance(state, j, n)`` for ``j = 1 … n − 1``, each sub-step without a sample ending at
    the fraction ``j / n`` of the step.  The last sub-step (``j = n``, the one with the
    sample) is the caller's: the live observer takes it with the held torque
    (:meth:`pinobs.observers.base.Observer.update`), the log reader at the row's own time
    (:class:`pinobs.io.LogEstimator`).
    """
    n = gap_substeps(dt, period, span=span)
    for j in range(1, n):
        state = advance(state, j, n)
    return state, n


def time_unit_warning(period: float | None) -> str | None:
    """What to say of a log whose median sample period [s] is implausible (``None``: nothing).

    A log timed in milliseconds or nanoseconds reads as seconds 1000x or 1e9x too long:
    its velocities come out that many times too small (a sweep found a kf median |v| of
    6.7e-4 rad/s for 0.67, and ekf re-initialised at every row of a ns log).
    """
    if period is None or MIN_PLAUSIBLE_PERIOD < period < MAX_PLAUSIBLE_PERIOD:
        return None
    if period >= MAX_PLAUSIBLE_PERIOD:
        unit = "milliseconds, microseconds or nanoseconds (t / 1000, t * 1e-6, t * 1e-9)"
    else:
        unit = "a unit larger than seconds"
    return (
        f"the median sample period is {period:.6g} s ({1 / period:.6g} Hz): is t in {unit}? "
        "give t in seconds: velocities are per second of t, so they are off by the same factor"
    )


def median_period(t: Vector) -> float | None:
    """The median of a log's positive sample intervals [s] (finite times), or ``None``."""
    d = np.diff(t[np.isfinite(t)])
    d = d[d > 0]
    return float(np.median(d)) if d.size else None
