"""Backward differences with a first-order low-pass filter: the baseline users run today.

    v_raw,k = difference(q_{k-1}, q_k) / Δ_k                 (backward difference on the group)
    v_k     = v_{k-1} + a_k (v_raw,k − v_{k-1}),  a_k = 1 − exp(−2π f_c Δ_k)

``Δ_k`` is the time since the previous *received* sample (dropouts widen it).
The configuration estimate is the latest measurement, moved forward along
``v`` when a sample is missing.

Default cut-off (documented rule).  For white position noise σ and a signal
whose acceleration is bounded by A, the filtered difference has noise
variance ≈ 2π σ² f_c / h and a lag error ≈ A / (2π f_c); their sum is least at

    f_c = (A² h / (4 π³ σ²))^{1/3},   capped at the Nyquist rate 1/(2h),

with A = ``accel_bound`` (default 10 rad/s²).  Without ``noise_std`` (or with
σ = 0) the filter is off (f_c at Nyquist): the plain backward difference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from pinobs.model import Robot
from pinobs.observers.base import Observer, Vector, positive, register

__all__ = ["FDGains", "FiniteDifference", "default_cutoff"]

_DEFAULT_RATE = 1000.0  # [Hz] assumed for the default cut-off when no rate is given


def default_cutoff(rate: float, noise_std: float | None, accel_bound: float) -> float:
    """The cut-off [Hz] minimising noise plus lag error (module docstring)."""
    h = 1.0 / rate
    nyquist = 0.5 * rate
    if not noise_std:
        return nyquist
    fc = (accel_bound**2 * h / (4.0 * math.pi**3 * noise_std**2)) ** (1.0 / 3.0)
    return min(fc, nyquist)


@dataclass(frozen=True)
class FDGains:
    """Validated options of :class:`FiniteDifference`.

    Attributes:
        cutoff: low-pass cut-off frequency [Hz], > 0.
    """

    cutoff: float

    def __post_init__(self) -> None:
        positive("cutoff", self.cutoff)


class _State(NamedTuple):
    q_last: Vector  # last received measurement
    since: float  # time since it [s]
    q: Vector
    v: Vector


@register
class FiniteDifference(Observer[_State]):
    """Backward difference + first-order low-pass filter.

    Args:
        robot: the robot (only its Lie-group operations are used).
        cutoff: low-pass cut-off [Hz]; default from ``rate``/``noise_std`` (module docstring).
        accel_bound: acceleration bound A [rad/s²] used by the default cut-off rule.
        rate: sample rate hint [Hz].
        noise_std: position noise hint [rad or m].
    """

    name = "fd"
    summary = "backward difference + first-order low-pass (model-free baseline)"
    uses_torque = False
    uses_noise_std = True
    uses_blas = False  # differences, Pinocchio's integrate and elementwise NumPy only

    def __init__(
        self,
        robot: Robot,
        *,
        cutoff: float | None = None,
        accel_bound: float = 10.0,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        positive("accel_bound", accel_bound)
        if cutoff is None:
            cutoff = default_cutoff(self.rate or _DEFAULT_RATE, self.noise_std, accel_bound)
        self.gains = FDGains(cutoff=float(cutoff))

    @property
    def options(self) -> dict[str, object]:
        return {**super().options, "cutoff": self.gains.cutoff}

    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        return _State(q_last=q0.copy(), since=0.0, q=q0.copy(), v=v0.copy())

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        since = state.since + dt
        if q_meas is None:
            return _State(state.q_last, since, self.robot.integrate(state.q, state.v * dt), state.v)
        v_raw = self.robot.difference(state.q_last, q_meas) / since
        a = 1.0 - math.exp(-2.0 * math.pi * self.gains.cutoff * since)
        v = state.v + a * (v_raw - state.v)
        return _State(q_last=q_meas.copy(), since=0.0, q=q_meas.copy(), v=v)

    def output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q, state.v
