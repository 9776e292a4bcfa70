"""The extended Kalman filter's state, options and shared pieces (:mod:`pinobs.observers.ekf`).

:class:`EKFState` and :class:`EKFGains` of :class:`~pinobs.observers.ekf.ExtendedKalmanFilter`,
the ``disturbance_psd="auto"`` constants, ``ad_v``'s matrix (:func:`ad_matrix`) and the
white-acceleration ``Q_d`` (:func:`double_integrator_noise`), which ``ibrir_kalman`` shares.
Split from :mod:`pinobs.observers.ekf` (whose module docstring gives their equations),
unchanged; ``ekf`` re-exports them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pinobs.model import Robot
from pinobs.observers.base import GateState, Vector, positive

__all__ = [
    "AUTO_CEILING",
    "AUTO_D0_ACCEL",
    "AUTO_PSD_BOUNDS",
    "AUTO_PSD_START",
    "AUTO_WINDOW",
    "EKFGains",
    "EKFState",
    "ad_matrix",
    "double_integrator_noise",
]


#: ``disturbance_psd="auto"`` (ekf's module docstring): the starting acceleration density
#: [rad²/s⁵], its bounds, the matching window [s], the initial offset std [rad/s²].
AUTO_PSD_START = 1e-9
AUTO_PSD_BOUNDS = (1e-12, 1e8)
AUTO_WINDOW = 0.1
AUTO_D0_ACCEL = 10.0
#: ``"auto"``: the ceiling of the density, ``ψ ≤ AUTO_CEILING · σ² / h⁵`` [rad²/s⁵] (ekf's module docstring).
AUTO_CEILING = 1.0


def ad_matrix(robot: Robot, v: Vector) -> Vector:
    """The matrix of ``x ↦ ad_v x = [v, x]`` (nv × nv); zero on robots without Lie-group joints."""
    nv = robot.nv
    if not robot.has_lie_group_joints:
        return np.zeros((nv, nv))
    if isinstance(robot, Robot):
        return robot.bracket_matrix(v)
    eye = np.eye(nv)
    return np.column_stack([robot.bracket(v, eye[:, j]) for j in range(nv)])


@functools.lru_cache(maxsize=64)
def _double_integrator_noise(nv: int, h: float, psd: float) -> Vector:
    eye = np.eye(nv)
    out = psd * np.block([[h**3 / 3 * eye, h**2 / 2 * eye], [h**2 / 2 * eye, h * eye]])
    out.setflags(write=False)
    return out


def double_integrator_noise(nv: int, h: float, psd: float) -> Vector:
    """``Q_d`` of white acceleration noise of density ``psd`` [rad²/s³] over ``h`` [s] (ekf's module docstring).

    Read-only, cached on ``(nv, h, psd)``: sample intervals repeat (to the bit,
    a handful of values at a fixed rate), so it is built once per value.
    """
    return _double_integrator_noise(nv, float(h), float(psd))


@dataclass(frozen=True)
class EKFGains:
    """Validated options of :class:`ExtendedKalmanFilter`.

    Attributes:
        accel_psd: white-acceleration noise density [rad²/s³], > 0.
        meas_std: measurement noise standard deviation [rad], > 0.
        q0_std: initial configuration standard deviation [rad], > 0.
        v0_std: initial velocity standard deviation [rad/s], > 0.
    """

    accel_psd: float
    meas_std: float
    q0_std: float
    v0_std: float

    def __post_init__(self) -> None:
        positive("accel_psd", self.accel_psd)
        positive("meas_std", self.meas_std)
        positive("q0_std", self.q0_std)
        positive("v0_std", self.v0_std)


_new_tuple = tuple.__new__  # a NamedTuple made without its __new__ (EKFState.moved)


class EKFState(NamedTuple):
    """The filter's state (``adaptive`` carries one inside its own)."""

    q: Vector
    v: Vector
    P: Vector  # covariance of (δq, δv) or, with the disturbance, of (δq, δv, δd)
    d: Vector | None = None  # estimated joint-torque offset [N·m or N]
    d_psd: Vector | None = None  # its random-walk density per joint [N²·m²/s]
    gate: GateState = GateState()  # the outlier gate's bookkeeping (NIS of the last measurement)
    auto: bool = False  # disturbance_psd="auto": d_psd learned from the innovations
    # "auto": M̄ᵢᵢ² at the reset configuration, the density's scale from rad²/s⁵ to N²·m²/s
    psd_scale: Vector | None = None

    def moved(
        self, q: Vector, v: Vector, P: Vector, gate: GateState, d: Vector | None,
        d_psd: Vector | None,
    ) -> EKFState:  # fmt: skip
        """``_replace(q=q, v=v, P=P, gate=gate, d=d, d_psd=d_psd)``, built directly: the state
        after a step (issue 39).  CPython 3.11's ``_replace`` fills a temporary tuple from a
        ``map``, which has no length: allocated for 10 items (counted by the garbage
        collector) and freed resized to these 8 into the free list (not counted), each call
        left the collector's generation-0 count one higher until that free list was full
        (2000 tuples); a live loop, whose set-up's full collection empties the free lists,
        ran 2–3 generation-0 collections (~20 µs each, nothing to collect) inside its first
        ~2000 updates (UR5 ``ekf`` and ``adaptive``, 20 s).  By ``tuple.__new__``: the
        NamedTuple's own ``__new__`` is a Python call more (every step)."""
        return _new_tuple(EKFState, (q, v, P, d, d_psd, gate, self.auto, self.psd_scale))
