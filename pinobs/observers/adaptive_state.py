"""``adaptive``'s state (:mod:`pinobs.observers.adaptive` module docstring, 5): what it
learned and how its filter runs on it (:class:`AdaptiveModel`), the whole state of a step
(:class:`AdaptiveState`), and what :func:`pinobs.smooth` reads of it (:class:`ModelSnapshot`).
"""

from __future__ import annotations

from typing import NamedTuple

from pinobs.model import Robot
from pinobs.observers.adaptive_blend import BankBlend, buffer_part
from pinobs.observers.adaptive_learner import Learner
from pinobs.observers.base import Vector
from pinobs.observers.ekf import EKFState, ExtendedKalmanFilter
from pinobs.observers.kf_bank import BankState

__all__ = ["AdaptiveModel", "AdaptiveState", "ModelSnapshot"]


class ModelSnapshot(NamedTuple):
    """The model-based filter's model as it stands (for :func:`pinobs.smooth`, which freezes it).

    Attributes:
        robot: the learned model (the nominal one before any install), a copy.
        offset: the learned joint-torque offset added to ``tau`` [N·m or N].
        regime: ``"warmup"``, ``"nominal"`` or ``"learned"`` (:mod:`pinobs.observers.adaptive`).
        accel_psd: that regime's white-acceleration density [rad²/s³].
        disturbance_psd: that regime's offset density per joint, ``psd · M̄ᵢᵢ²`` [N²·m²/s].
    """

    robot: Robot
    offset: Vector
    regime: str
    accel_psd: float
    disturbance_psd: Vector


class AdaptiveModel(NamedTuple):
    """What ``adaptive`` has learned and how its filter runs on it (:mod:`pinobs.observers.adaptive`, 5): part
    of its state, made anew when it changes (an install, a regime, a restart), never changed."""

    core: ExtendedKalmanFilter  # the filter on this model at this regime's accel_psd
    learned: Robot  # the learned model whole (friction included); the nominal one before
    held: Vector | None  # 1 where the learned friction is a held input (AdaptiveEKF._install)
    offset: Vector  # the learned torque offset b̂ [N·m or N]
    regime: str  # "warmup", "nominal" or "learned"
    m_bar2: Vector  # M̄ᵢᵢ² at the reset: the offset densities' per-joint scale
    restarts: int  # times the model-based filter was lost and restarted
    restarted: bool  # and not replaced by a solve since: the model is to blame
    rejected_run: int  # the learner's solves rejected in a row, as of the last commit
    said: tuple[str, ...] = ()  # what the steps since the last commit said (restarts)


class AdaptiveState(NamedTuple):
    """On vector joints the bank's and the blend's arrays lie in one float64 buffer ``x``
    (:func:`~pinobs.observers.adaptive_blend.blend_layout`: one array to pass to the compiled
    step and to allocate, issue 39), read through the properties below as read-only views;
    elsewhere ``x`` is a :class:`BankBlend` of them."""

    ekf: EKFState
    x: Vector | BankBlend  # the bank, its scores, s, q̂ and v̂ (blend_layout), or their arrays
    shape: tuple[int, int, int]  # (filters, nq, nv)
    t: float
    v_prev: Vector  # the EKF's v̂ at the start of the last step (held friction, _torque)
    dt_prev: float  # that step [s] (0: none yet)
    model: AdaptiveModel  # what was learned, the regime, the restarts (read only by step)
    learner: Learner  # fed by after_commit only, at the commit boundary (adaptive.py docstring, 5)

    @property
    def kf(self) -> BankState:
        """The bank's filters, rows (no innovations in a buffer)."""
        x = self.x
        if isinstance(x, BankBlend):
            return x.kf
        q, v, a, P = (buffer_part(x, self.shape, i) for i in range(4))
        return BankState(q, v, a, P, None)

    @property
    def score(self) -> Vector:
        """(filters, nv): running mean squared innovation of each kf per coordinate."""
        x = self.x
        return x.score if isinstance(x, BankBlend) else buffer_part(x, self.shape, 5)

    @property
    def s(self) -> Vector:
        """Estimated model-based velocity error variance per coordinate [rad²/s²]."""
        x = self.x
        return x.s if isinstance(x, BankBlend) else buffer_part(x, self.shape, 6)
