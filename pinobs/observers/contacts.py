"""Foot contacts from measured normal forces: a threshold with hysteresis, or a probability
from the force and the foot's speed (:class:`ContactProbability`, as SEROW) (issue 38, item 2).

A foot is in contact from the first sample whose normal force reaches ``on`` until the
first one that falls to ``off`` (``off < on``): a Schmitt trigger per foot,

    c_k = 1 if f_k ≥ on,    c_k = 0 if f_k ≤ off,    c_k = c_{k−1} otherwise,

so a force that hovers near one threshold does not make the contact chatter (each change
adds or removes a foot in :class:`pinobs.observers.inekf.InvariantEKF`'s state).  A
missing force (NaN) keeps the foot's previous state.  Before the first decisive sample a
foot is out of contact (``initial``).

Defaults scale with the robot's weight ``W = m g`` (:func:`default_thresholds`):
``on = 0.15 W``, ``off = 0.075 W`` (20 N is the legged benchmark's threshold for a 12.7 kg
Go1, whose ``0.15 W`` is 18.7 N; a foot of a trotting quadruped carries about ``W/2``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import DimensionError, GainError
from pinobs.model import Robot

#: ``on`` and ``off`` as fractions of the robot's weight (module docstring).
ON_FRACTION, OFF_FRACTION = 0.15, 0.075
#: Standard gravity [m/s²].
G = 9.80665


def default_thresholds(robot: Robot) -> tuple[float, float]:
    """``(on, off)`` [N]: :data:`ON_FRACTION` and :data:`OFF_FRACTION` of the robot's weight."""
    weight = G * robot.total_mass()
    return ON_FRACTION * weight, OFF_FRACTION * weight


def contacts_from_forces(
    force: ArrayLike, on: float, off: float | None = None, *, initial: ArrayLike | None = None
) -> NDArray[np.bool_]:
    """Contact flags ``(N, feet)`` from normal forces ``(N, feet)`` [N] (module docstring).

    Args:
        force: normal force per sample and foot [N]; NaN where not measured.
        on: force at or above which a foot touches [N].
        off: force at or below which it leaves [N], ``< on`` (default ``on / 2``).
        initial: each foot's state before the first sample (default: out of contact).

    Raises:
        DimensionError: ``force`` not two-dimensional, ``initial`` of another length.
        GainError: thresholds not finite, or ``off ≥ on``.
    """
    f = np.asarray(force, dtype=float)
    if f.ndim != 2:
        raise DimensionError(f"force must have shape (samples, feet), got shape {f.shape}")
    off = 0.5 * on if off is None else off
    if not (math.isfinite(on) and math.isfinite(off)) or off >= on:
        raise GainError(
            f"contact thresholds on={on!r}, off={off!r} [N]: give finite ones with off < on"
        )
    start = np.zeros(f.shape[1]) if initial is None else np.asarray(initial, dtype=float)
    if start.shape != (f.shape[1],):
        raise DimensionError(f"initial must have one flag per foot ({f.shape[1]})")
    decided = np.where(f >= on, 1.0, np.where(f <= off, 0.0, np.nan))  # NaN: keep
    rows = np.vstack([start[None, :], decided])
    # forward fill along time: each row takes the last decided row at or before it
    index = np.where(np.isnan(rows), 0, np.arange(rows.shape[0])[:, None])
    last = np.maximum.accumulate(index, axis=0)
    return np.take_along_axis(rows, last, axis=0)[1:] > 0.5


# ------------------------------------------------------------- contact probability
#: :class:`ContactProbability`'s defaults: its force's mid-point and spread as fractions of
#: the weight (between :data:`OFF_FRACTION` and :data:`ON_FRACTION`), the foot speed below
#: which a foot is still [m/s] and its spread [m/s] (SEROW's ``VelocityThres: 0.2`` and
#: ``lvnorm_sigma: 0.05``, config/estimation_params.yaml at mrsp/serow d968c5b).
FORCE_MID, FORCE_SPREAD, SPEED_MAX, SPEED_SIGMA = 0.1125, 0.0375, 0.5, 0.1


@dataclass(frozen=True)
class ContactProbability:
    """A foot's contact probability from its normal force and its speed (issue 38, item 2).

        SEROW's probabilistic contact detection (Piperakis et al., mrsp/serow,
        ``include/serow/ContactDetectionQuad.h`` at commit d968c5b, ``computeForceContactProb``
        and ``computeKinContactProb``): the force and the foot's speed, each with a Gaussian
        uncertainty, must both say "in contact"::

            p = Φ((f − f_min) / σ_f) · Φ((v_max − |v_foot|) / σ_v),     in contact ⇔ p > ½

    (``Φ`` the standard normal CDF; SEROW's current ``Serow::runContactEstimator``,
        core/src/Serow.cpp at b2e0d0b, also sets the status at ``p > 0.5``).  ``v_foot`` is the
        foot's velocity in the world as the filter predicts it
        (:meth:`~pinobs.observers.inekf.InvariantEKF.foot_velocities`): a foot still pushing down but
        already moving (lift-off) or sliding is out of contact, where a force threshold keeps it.
        SEROW normalises its four probabilities by their sum (so that they share one); that
        would put four feet in stance at ¼ each, so each foot is kept on its own here.

        Attributes:
            force_min: ``f_min`` [N].
            force_sigma: ``σ_f`` [N].
            speed_max: ``v_max`` [m/s].
            speed_sigma: ``σ_v`` [m/s].
    """

    force_min: float
    force_sigma: float
    speed_max: float = SPEED_MAX
    speed_sigma: float = SPEED_SIGMA

    def __post_init__(self) -> None:
        for name in ("force_min", "force_sigma", "speed_max", "speed_sigma"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise GainError(
                    f"ContactProbability.{name} must be a finite number ≥ 0, got {value!r}"
                )
        if self.force_sigma == 0 or self.speed_sigma == 0:
            raise GainError("ContactProbability: force_sigma and speed_sigma must be > 0")

    @classmethod
    def for_robot(cls, robot: Robot) -> ContactProbability:
        """Defaults from the robot's weight ``W``: ``f_min = 0.1125 W``, ``σ_f = 0.0375 W``
        (the Schmitt trigger's ``on`` and ``off`` are ``f_min ± σ_f``)."""
        weight = G * robot.total_mass()
        return cls(FORCE_MID * weight, FORCE_SPREAD * weight)

    def __call__(self, force: ArrayLike, foot_speed: ArrayLike) -> NDArray[np.float64]:
        """``p`` per foot (same shape as ``force``) from forces [N] and speeds [m/s]; a NaN
        force gives NaN (:func:`contacts_from_probability` keeps the previous state)."""
        # Φ(z) = ½ erfc(−z/√2); SEROW d968c5b ContactDetectionQuad.h: p_f · p_v
        return self.force_factor(force) * self.speed_factor(foot_speed)

    def force_factor(self, force: ArrayLike) -> NDArray[np.float64]:
        """``¼ erfc(−z_f/√2)``, ``z_f = (f − f_min)/σ_f``: ``p`` is this times
        :meth:`speed_factor` (the same bits as ``__call__``, which multiplies them), so a
        run can take it for all its rows at once (:func:`pinobs.io.legged_run.legged_run`)."""
        z_f = (np.asarray(force, dtype=float) - self.force_min) / self.force_sigma
        return 0.25 * _erfc(-z_f / math.sqrt(2.0))

    def speed_factor(self, foot_speed: ArrayLike) -> NDArray[np.float64]:
        """``erfc(−z_v/√2)``, ``z_v = (v_max − |v_foot|)/σ_v``, the speed's factor of ``p``;
        computed as ``erfc(((|v_foot| − v_max)/σ_v)/√2)`` in place (the same bits: ``a − b``
        is exactly ``−(b − a)`` and a quotient's sign its dividend's; a log's rows call this
        once each, :func:`pinobs.io.legged_run.legged_run`)."""
        z = np.subtract(foot_speed, self.speed_max, dtype=float)
        z /= self.speed_sigma
        z /= _SQRT2
        return _erfc(z)

    def row_flags(
        self, force_factor: list[float], speed: NDArray[np.floating[Any]], previous: list[bool]
    ) -> list[bool]:
        """One row's flags ``p > ½`` (a NaN ``p`` keeping the foot's ``previous`` flag) from its
        :meth:`force_factor` (Python floats) and its feet's speeds: :func:`contact_flags` of
        ``force_factor · speed_factor(speed)``, the same bits, with ``z`` in Python floats (a
        row's handful of feet: one NumPy call, SciPy's ``erfc``)."""
        v_max, sigma = self.speed_max, self.speed_sigma
        z = [((v - v_max) / sigma) / _SQRT2 for v in speed.tolist()]
        by_speed = _erfc_ufunc()(z).tolist()
        return contact_flags([f * s for f, s in zip(force_factor, by_speed, strict=True)], previous)


_SQRT2 = math.sqrt(2.0)


@functools.cache
def _erfc_ufunc() -> Any:
    """SciPy's ``erfc`` (imported at the first call: ``import pinobs`` does not import SciPy)."""
    from scipy.special import erfc

    return erfc


def _erfc(z: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.asarray(_erfc_ufunc()(z), dtype=float)


#: A foot is in contact where its probability is above this (SEROW's rule).
CONTACT_PROBABILITY = 0.5


def contacts_from_probability(p: ArrayLike, previous: ArrayLike) -> NDArray[np.bool_]:
    """Flags ``p > ½`` per foot; a NaN probability keeps the foot's ``previous`` flag."""
    prob, prev = np.asarray(p, dtype=float), np.asarray(previous, dtype=bool)
    return np.where(np.isnan(prob), prev, prob > CONTACT_PROBABILITY)


def contact_flags(p: list[float], previous: list[bool]) -> list[bool]:
    """:func:`contacts_from_probability` on a row's Python floats (a log's per-row path:
    no NumPy call for a handful of feet)."""
    return [
        b if math.isnan(x) else x > CONTACT_PROBABILITY for x, b in zip(p, previous, strict=True)
    ]
