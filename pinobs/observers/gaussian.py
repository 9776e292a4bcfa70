"""The interface a smoother runs: :class:`GaussianFilter` (re-exported by
:mod:`pinobs.observers.base`, where it was first defined)."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from pinobs.model import Robot

__all__ = ["GaussianFilter"]

Vector = NDArray[np.floating[Any]]


class GaussianFilter(Protocol):
    """An error-state Gaussian filter, predicted and corrected apart (what a smoother runs).

    The filter's step is ``correct ∘ predict`` (filterpy's ``KalmanFilter.predict`` /
    ``update``), both pure functions of an immutable state carrying the mean ``q, v``
    (and more: a torque offset ``d``, …) and the error covariance ``P``:

    * ``predict(state, dt, tau) -> (state⁻, Φ)`` propagates over ``dt`` [s] with ``tau``
      [N·m or N] held and returns the transition Jacobian ``Φ`` of the error state
      (Rauch-Tung-Striebel needs it);
    * ``predict_flow(state, dt, tau) -> (state⁻, Φ, F)`` also returns ``F``, the Jacobian
      of the mean's step, of which ``Φ`` is only the filter's approximation (a filter
      without a better one returns ``Φ`` as ``F``);
    * ``correct(state⁻, q_meas) -> state⁺`` fuses one measured configuration; a filter with
      an outlier gate keeps its bookkeeping in the state's ``gate`` (:class:`GateState`),
      and ``gate_limit(state⁺)`` is the NIS above which it rejected that measurement.

    Attributes:
        robot: the process model (its configuration space is the filter's).
        gains: the family's frozen gains; ``gains.meas_std`` is the position noise σ
            [rad or m], and the process density is ``gains.accel_psd`` [rad²/s³] (a
            model-based filter) or ``gains.jerk_psd`` [rad²/s⁵] (white jerk).
        disturbance_psd: the density of a random-walk torque offset, or ``None``.
        options: the filter's resolved options (reported with a smoothed result).
    """

    robot: Robot

    @property
    def gains(self) -> Any: ...
    @property
    def disturbance_psd(self) -> float | None: ...
    @property
    def options(self) -> dict[str, Any]: ...
    def initial_state(self, q0: Vector, v0: Vector) -> Any: ...
    def predict(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector]: ...
    def predict_flow(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector, Vector]: ...
    def correct(self, state: Any, q_meas: Vector) -> Any: ...
    def gate_limit(self, state: Any) -> float: ...
