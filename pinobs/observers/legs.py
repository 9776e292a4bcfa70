"""What the contact-aided filters share: legs, contacts, options, state, inputs and outputs.

:class:`pinobs.observers.inekf.InvariantEKF` and
:class:`pinobs.observers.qekf.QuaternionEKF` estimate the same state from the
same inputs and differ only in their error (right-invariant or additive with a
local attitude error).  Everything else lives here, once:

* the legs (:class:`ContactKinematics`, :func:`contact_kinematics`) and the IMU's
  placement ``(R_bi, r_bi)`` in the base (root joint) frame;
* the options (:class:`InEKFGains`, :class:`InEKFPrior`) and the noise they give:
  the process densities ``Q_c = diag(σ_g², σ_a², 0, σ_c² …, σ_bg², σ_ba²)``
  (:func:`noise_densities`) and a foot measurement's covariance in the IMU frame
  ``J Σ_q Jᵀ + σ_k² I`` (:func:`foot_noise`, Hartley et al. IJRR 2020, the
  forward-kinematics measurement; Bloesch et al. RSS 2012 likewise);
* the state (:class:`LegState`), the input checks of ``reset``/``update``
  (:class:`LeggedSetup`), a foot's marginalisation at lift-off
  (:func:`remove_feet`), and the output (:class:`InEKFEstimate`), converted from
  the IMU frame to the root joint (Pinocchio's ``q[0:7]``, ``v[0:6]``)::

      R_b = R R_biᵀ,  p_b = p − R_b r_bi,  ω_b = R_bi (ω̃ − b̂_g),  v_b = R_bᵀ v − ω̄_b × r_bi
  (``ω̄_b = R_bi (ω̄ − b̂_g)``, the gyro low-passed in the lever arm: imu_link.py's M4, for
  any IMU frame off the root; an IMU frame that moves relative to the root: with the joints'
  terms, imu_link.py's M3).

Each filter holds a :class:`LeggedSetup` (composition) and keeps its mathematics.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import (
    ConfigurationError,
    ContactWarning,
    DimensionError,
    GainError,
    NotResetError,
    ObserverDiverged,
    TimestampError,
    UnknownNameError,
)
from pinobs.model import FootKinematics, Robot
from pinobs.model.robot import read_only
from pinobs.observers.base import Vector
from pinobs.observers.imu_link import LEVER_TAU, imu_state, lever_shift, root_twist
from pinobs.observers.inekf_loops import base_kernel, finite_kernel, load_leg_kernels
from pinobs.observers.rolling import RollingFeet
from pinobs.observers.rotations import quaternion_to_rotation, rotation_to_quaternion
from pinobs.observers.stance import stance_consistency
from pinobs.tolerances import NO_CONTACT_WARN_TIME, QUATERNION_NORM_TOL, TIME_EPS

__all__ = [
    "GRAVITY",
    "ContactKinematics",
    "InEKFEstimate",
    "InEKFGains",
    "InEKFPrior",
    "LegState",
    "LeggedSetup",
    "ResetInputs",
    "UpdateInputs",
    "check_contacts",
    "check_joint_std",
    "check_time",
    "contact_kinematics",
    "foot_noise",
    "noise_densities",
    "quaternion_to_rotation",
    "remove_feet",
    "replace_state",
    "rotation_to_quaternion",
    "slip_densities",
    "slip_speeds",
    "stance_consistency",
]

#: Gravity in the world frame [m/s²] (z up).
GRAVITY = (0.0, 0.0, -9.81)
_I3 = np.eye(3)


#: the held reading of a state without one (:meth:`LeggedSetup.estimate`: ω̃ = 0)
_NO_READING = np.zeros(6)


# ------------------------------------------------------------------- checks
def check_time(t: Any, previous: float | None) -> float:
    """``t`` as a finite float after ``previous`` (by more than TIME_EPS), or a TimestampError."""
    try:
        t = float(t)
    except (TypeError, ValueError) as exc:
        raise TimestampError(f"t must be a number, got {t!r}") from exc
    if not math.isfinite(t):
        raise TimestampError(f"t must be finite, got {t!r}")
    if previous is not None and t <= previous + TIME_EPS:
        raise TimestampError(f"t = {t!r} is not after the previous update's t = {previous!r}")
    return t


def check_contacts(feet: tuple[str, ...], contacts: Any) -> list[bool]:
    """Contact flags in the order of ``feet`` from a mapping (every foot named) or a sequence
    of bools; UnknownNameError or DimensionError naming what is wrong."""
    if isinstance(contacts, Mapping):
        unknown = [k for k in contacts if k not in feet]
        if unknown:
            raise UnknownNameError(f"contacts names {unknown}, not among the feet {list(feet)}")
        missing = [f for f in feet if f not in contacts]
        if missing:
            raise UnknownNameError(
                f"contacts has no entry for {missing}: give a bool for each of {list(feet)}"
            )
        values = [contacts[f] for f in feet]
    elif isinstance(contacts, (str, bytes)) or not isinstance(contacts, (Sequence, np.ndarray)):
        raise DimensionError(
            f"contacts must map each of {list(feet)} to a bool (or be a sequence of "
            f"{len(feet)} bools), got {contacts!r}"
        )
    else:
        values = list(contacts)
        if len(values) != len(feet):
            raise DimensionError(
                f"contacts has {len(values)} entries, expected {len(feet)} "
                f"(one bool per foot: {list(feet)})"
            )
    out = []
    for name, value in zip(feet, values, strict=True):
        if isinstance(value, (bool, np.bool_)):
            out.append(bool(value))
        elif isinstance(value, (int, np.integer)) and value in (0, 1):
            out.append(bool(value))
        else:
            raise DimensionError(f"contacts[{name!r}] must be a bool, got {value!r}")
    return out


# ----------------------------------------------------------------- kinematics
@runtime_checkable
class ContactKinematics(Protocol):
    """What the filter needs of the legs: foot positions in the base frame and their Jacobians.

    :class:`pinobs.model.FootKinematics` is one (from a Pinocchio model); tests
    use synthetic ones.
    """

    feet: tuple[str, ...]
    nq_joints: int
    nv_joints: int

    def positions_and_jacobians(self, q_joints: Vector) -> tuple[Vector, Vector]:
        """``(h, J)``: shapes ``(K, 3)`` [m] and ``(K, 3, nv_joints)`` [m/rad]."""
        ...


def contact_kinematics(
    robot: Robot | ContactKinematics, feet: Sequence[str] | None, imu_frame: str | None
) -> ContactKinematics:
    """The legs a contact-aided filter measures: :class:`pinobs.model.FootKinematics` of a
    robot's ``feet`` (in its ``imu_frame``), or a given :class:`ContactKinematics`.

    Raises:
        UnknownNameError: a robot without ``feet``, ``feet`` that differ from the
            kinematics' own, or ``imu_frame`` with a :class:`ContactKinematics`.
        TypeError: neither a robot nor a :class:`ContactKinematics`.
    """
    if isinstance(robot, Robot):
        if feet is None:
            raise UnknownNameError(
                f"{robot.name}: give the foot frame names (feet=[...]) to measure"
            )
        return FootKinematics(robot, feet, imu_frame=imu_frame)
    elif isinstance(robot, ContactKinematics):
        if imu_frame is not None:
            raise UnknownNameError(
                "imu_frame is for a robot; a ContactKinematics gives imu_placement itself"
            )
        if feet is not None and tuple(feet) != tuple(robot.feet):
            raise UnknownNameError(
                f"feet={list(feet)} differs from the kinematics' feet {list(robot.feet)}"
            )
        return robot
    else:
        raise TypeError(
            f"robot must be a pinobs.Robot or a ContactKinematics, got {type(robot).__name__}"
        )


# ------------------------------------------------------------------- options
@dataclass(frozen=True)
class InEKFGains:
    """Noise levels of the contact-aided filters (``Q_c`` of the process, ``N`` of a foot).

    Densities are of continuous white noise (σ of a sample at rate f is density·√f).

    Attributes:
        gyro: gyro noise density [rad/s/√Hz].
        accel: accelerometer noise density [m/s²/√Hz].
        gyro_bias: gyro bias random walk [rad/s²/√Hz].
        accel_bias: accelerometer bias random walk [m/s³/√Hz].
        contact: foot velocity while in contact (slip) [m/s/√Hz].
        joint: joint encoder noise, σ per sample [rad].
        kinematics: foot position model error (foot radius, link lengths), σ per sample [m].
        landing: foot velocity over the first ``landing_time`` of a contact, added to
            ``contact`` (the touch-down transient: the foot still settling after its contact
            flag rose) [m/s/√Hz]; 0 (default): none
            (:func:`~pinobs.observers.legged_filter.landing_densities`).
        landing_time: how long after a foot's contact began ``landing`` applies [s].
        lever_tau: with an IMU frame off the root (fixed, go1's, or moving, TALOS's), the
            time constant of the gyro's low-pass in the root velocity's lever arm [s]
            (:mod:`~pinobs.observers.imu_link`'s (M4)); 0: the raw reading (M3).  The state
            is unaffected.
    """

    gyro: float = 1e-2
    accel: float = 1e-1
    gyro_bias: float = 1e-5
    accel_bias: float = 1e-4
    contact: float = 1e-1
    joint: float = 1e-3
    kinematics: float = 1e-3
    landing: float = 0.0
    landing_time: float = 0.0
    lever_tau: float = LEVER_TAU

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise GainError(f"InEKFGains.{f.name} must be a finite number ≥ 0, got {value!r}")
        if self.joint == 0 and self.kinematics == 0:
            raise GainError(
                "InEKFGains.joint and InEKFGains.kinematics are both 0: the foot measurement "
                "would be exact and its innovation covariance singular; make one > 0"
            )


@dataclass(frozen=True)
class InEKFPrior:
    """Initial uncertainty (standard deviations at ``reset``) of the IMU frame's attitude,
    velocity (in its own frame, as ``reset`` takes it) and world position and of the
    biases, independent of each other.

    Attributes:
        attitude: orientation [rad] (per axis).
        velocity: velocity [m/s].
        position: position in the world [m] (the same wherever the world's origin is).
        gyro_bias: gyro bias [rad/s].
        accel_bias: accelerometer bias [m/s²].
    """

    attitude: float = 0.1
    velocity: float = 0.5
    position: float = 0.1
    gyro_bias: float = 1e-2
    accel_bias: float = 1e-1

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise GainError(f"InEKFPrior.{f.name} must be a finite number > 0, got {value!r}")

    def covariance(self) -> Vector:
        """``diag(σ_θ², σ_v², σ_p², σ_bg², σ_ba²)`` (each thrice), 15 square."""
        return np.diag(
            np.concatenate(
                [
                    np.full(3, self.attitude**2),
                    np.full(3, self.velocity**2),
                    np.full(3, self.position**2),
                    np.full(3, self.gyro_bias**2),
                    np.full(3, self.accel_bias**2),
                ]
            )
        )


@functools.lru_cache(maxsize=64)
def noise_densities(gains: InEKFGains, n_contacts: int) -> Vector:
    """The diagonal of ``Q_c`` in the order of the filters' error
    ``(R, v, p, d_1 … d_K, b_g, b_a)``, read-only."""
    out = np.concatenate(
        [
            np.full(3, gains.gyro**2),
            np.full(3, gains.accel**2),
            np.zeros(3),
            np.full(3 * n_contacts, gains.contact**2),
            np.full(3, gains.gyro_bias**2),
            np.full(3, gains.accel_bias**2),
        ]
    )
    out.setflags(write=False)
    return out


def foot_noise(gains: InEKFGains, jac: Vector, joint_var: float | None = None) -> Vector:
    """``J Σ_q Jᵀ + σ_k² I`` in the IMU frame, for one ``J`` (3, n) or a stack (m, 3, n),
    ``Σ_q = σ_q² I`` with ``σ_q² = joint_var`` (default ``gains.joint²``; 1 for a ``J``
    whose columns are already scaled by each joint's σ)."""
    var = gains.joint**2 if joint_var is None else joint_var
    return var * (jac @ np.swapaxes(jac, -1, -2)) + (gains.kinematics**2) * _I3


def slip_densities(
    qc: Vector, speed: Vector, h: float, feet: Sequence[int] | None = None
) -> Vector:
    """Eq. (9) of :mod:`pinobs.observers.inekf`: ``Q_c`` (:func:`noise_densities`, feet in
    state order) with each foot's density raised by ``|ṗ_j|² h`` (``speed`` [m/s], one per
    foot in the state, or with ``feet`` (the state's feet, indices into ``speed``) one per
    foot of the filter; ``h`` the step [s]), read-only.  In Python floats (the same bits as
    NumPy's ``qc + np.repeat(speed**2 * h, 3)``; a sample's handful, cheaper so)."""
    sp = np.asarray(speed, dtype=float).tolist()
    out = np.asarray(qc, dtype=float).tolist()
    for s, j in enumerate(range(len(sp)) if feet is None else feet):
        for o in range(9 + 3 * s, 12 + 3 * s):
            out[o] += sp[j] * sp[j] * h
    density = np.array(out)
    density.setflags(write=False)
    return density


def slip_speeds(velocities: Vector, h: Vector, gyro: float, period: float) -> Vector:
    """Eq. (10) of :mod:`pinobs.observers.inekf`: each foot's speed [m/s] for eq. (9) with the
    gyro's white noise taken out, ``√max(|ṗ̂_j|² − 2 |h_j|² σ_g²/T, 0)``: ``velocities``
    ``ṗ̂_j`` (K, 3) [m/s], ``h`` the feet's positions from the IMU (K, 3) [m], ``gyro``
    ``σ_g`` [rad/s/√Hz], ``period`` ``T`` the reading's sample period [s] (the held
    reading's noise variance per axis: ``σ_g²/T``; ``tr([h]×[h]×ᵀ) = 2|h|²``).

    MuJoCo go1 standing 10 s, seed 0, encoders quantised as the real Go1's, through
    :func:`pinobs.io.legged_run.legged_run`: stance rows inside their 95 % χ² interval
    0.5 % with the raw speed, 46 % with ``imu_noise="log"`` (the IMU's densities measured
    on the log and (10)); the encoders white 5e-4 rad: 87 % and 95 %
    (``benchmarks/legged_truth.md``)."""
    speed2 = np.sum(velocities * velocities, axis=1)
    if gyro == 0.0 and math.isfinite(period) and period > 0.0 and np.isfinite(speed2).all():
        # the noise term is 0 and |ṗ̂_j|² − 0 is |ṗ̂_j|² (finite speeds come from finite h;
        # |h_j|² overflowing, |h_j| > 1e154 m, would have made it NaN)
        return np.sqrt(np.maximum(speed2, 0.0))
    noise = 2.0 * np.sum(h * h, axis=1) * gyro**2 / period
    return np.sqrt(np.maximum(speed2 - noise, 0.0))


def check_joint_std(joint_std: ArrayLike, n: int) -> Vector:
    """``joint_std`` as a read-only ``(n,)`` array of finite numbers ≥ 0 [rad].

    Raises:
        DimensionError: not ``n`` entries.
        GainError: a negative or non-finite entry (named).
    """
    out = np.array(Robot.check_vector(joint_std, n, what="joint_std"), dtype=float)
    bad = ~np.isfinite(out) | (out < 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise GainError(
            f"joint_std[{k}] = {float(out[k])!r}: each joint's encoder σ must be a finite number ≥ 0 [rad]"
        )
    out.setflags(write=False)
    return out


# ---------------------------------------------------------------- state, output
@dataclass(frozen=True)
class LegState:
    """A contact-aided filter's state (immutable).

    Attributes:
        t: time [s].
        R: world from IMU rotation.
        x: rows ``v, p, d_1 … d_K`` (world frame) [m/s, m], shape ``(2 + K, 3)``.
        feet: index (into the kinematics' feet) of each ``d_j``, in state order.
        bias: ``(b_g, b_a)`` [rad/s, m/s²].
        P: covariance of the filter's error ``(R, v, p, d_1 … d_K, b_g, b_a)``,
            ``9 + 3K + 6`` square (right-invariant for the invariant EKF, additive with a
            local attitude error for the quaternion EKF).
        imu: the held reading ``(ω̃, ã)``, or ``None`` before the first one.
        last_contact: time a foot was last in contact (the reset time if none yet) [s].
        lever: the gyro's low-passed reading ``ω̄`` for the lever arm of an IMU frame off
            the root (:func:`~pinobs.observers.imu_link.smoothed`), ``None`` otherwise.
    """

    t: float
    R: Vector
    x: Vector
    feet: tuple[int, ...]
    bias: Vector
    P: Vector
    imu: Vector | None
    last_contact: float
    lever: Vector | None = None


_STATE_FIELDS = frozenset(f.name for f in fields(LegState))


def replace_state(state: LegState, **changes: Any) -> LegState:
    """``state`` with ``changes`` (``dataclasses.replace`` without its checks): its fields
    copied in one dictionary update (a frozen dataclass's ``__init__`` sets them one by one;
    the filters make three states a sample)."""
    if not changes.keys() <= _STATE_FIELDS:
        raise TypeError(f"LegState has no field {sorted(changes.keys() - _STATE_FIELDS)}")
    new = object.__new__(LegState)
    values = new.__dict__
    values.update(state.__dict__)
    values.update(changes)
    return new


def remove_feet(state: LegState, slots: list[int]) -> LegState:
    """Marginalise the feet at state positions ``slots``: delete their rows and columns."""
    keep = np.ones(state.P.shape[0], dtype=bool)  # (the indices np.setdiff1d gave, by masks)
    rows = np.ones(state.x.shape[0], dtype=bool)
    for s in slots:
        keep[9 + 3 * s : 12 + 3 * s] = False
        rows[2 + s] = False
    keep, rows = np.flatnonzero(keep), np.flatnonzero(rows)
    feet = tuple(f for s, f in enumerate(state.feet) if s not in slots)
    return replace_state(state, x=state.x[rows], P=state.P[np.ix_(keep, keep)], feet=feet)


@dataclass(frozen=True)
class InEKFEstimate:
    """A contact-aided filter's estimate at one time (read-only arrays).

    Attributes:
        t: time [s].
        q: free-flyer configuration ``(p, quaternion xyzw, joint positions as measured)``,
            ``nq`` entries (``7 + nq_joints``).
        v: ``(base linear velocity in the base frame, base angular velocity R_bi (ω̃ − b̂_g), joint
            velocities)``, ``nv`` entries; the joint velocities are not estimated here: the
            ones passed to ``update`` (``joint_velocities=``), else NaN.
        rotation: world from base (root joint) rotation.
        velocity_world: velocity of the base's origin in the world [m/s].
        bias: ``(b_g, b_a)`` [rad/s, m/s²].
        covariance: covariance of the filter's error (:attr:`LegState.P`) of the IMU
            frame's state.
        contacts: names of the feet in the state (in contact), in state order.
        foot_positions: their world positions ``d_j``, shape ``(K, 3)`` [m].
        nis: normalized innovation squared of this update's foot measurements (χ² with
            ``nis_dof`` degrees of freedom for a consistent filter), or ``None``.
        nis_dof: its degrees of freedom, 3 × (feet measured); 0 with no measurement.
        gated: the feet whose measurement the foot gate rejected at this update (re-anchored
            instead: :class:`pinobs.observers.inekf.InvariantEKF`'s ``foot_gate``).
    """

    t: float
    q: Vector
    v: Vector
    rotation: Vector
    velocity_world: Vector
    bias: Vector
    covariance: Vector
    contacts: tuple[str, ...]
    foot_positions: Vector
    nis: float | None = None
    nis_dof: int = 0
    gated: tuple[str, ...] = ()


# ------------------------------------------------------------------ the setup
class ResetInputs(NamedTuple):
    """``reset``'s arguments, checked: the IMU frame's ``R``, rows ``x = (v, p)`` in the world."""

    t: float
    q_joints: Vector
    R: Vector
    x: Vector
    imu: Vector | None
    flags: list[bool]
    prior: InEKFPrior
    bias: Vector
    dq: Vector | None = None


class UpdateInputs(NamedTuple):
    """``update``'s arguments, checked."""

    t: float
    q_joints: Vector
    reading: Vector
    flags: list[bool]
    joint_velocities: Vector | None


class LeggedSetup:
    """The legs, options and input/output conversions of a contact-aided filter.

    Args:
        name: the filter's class name (in messages).
        robot: as :class:`pinobs.observers.inekf.InvariantEKF` takes it.
        feet: likewise.
        gains: likewise.
        gravity: likewise.
        imu_hold: likewise.
        imu_frame: likewise.
        foot_radius: likewise (:class:`pinobs.observers.rolling.RollingFeet`).
        rolling_lift: likewise (``RollingFeet``'s ``lift``).

    Raises:
        GainError: an ``imu_hold`` that is neither ``"previous"`` nor ``"average"``, or
            ``gains`` that are not an :class:`InEKFGains`.
        UnknownNameError: a foot frame that is not in the model (names the frames).
        UnsupportedRobotError: a robot without a free-flyer root joint.
    """

    def __init__(
        self,
        name: str,
        robot: Robot | ContactKinematics,
        feet: Sequence[str] | None,
        *,
        gains: InEKFGains | None,
        gravity: ArrayLike,
        imu_hold: str,
        imu_frame: str | None,
        foot_radius: float = 0.0,
        rolling_lift: bool = True,
    ) -> None:
        if imu_hold not in ("previous", "average"):
            raise GainError(f"imu_hold must be 'previous' or 'average', got {imu_hold!r}")
        self.name = name
        self.imu_hold = imu_hold
        self.kinematics = contact_kinematics(robot, feet, imu_frame)
        if gains is not None and not isinstance(gains, InEKFGains):
            raise GainError(f"gains must be an InEKFGains, got {type(gains).__name__}")
        self.gains = gains if gains is not None else InEKFGains()
        self.gravity = Robot.check_vector(gravity, 3, what="gravity")
        self.feet: tuple[str, ...] = tuple(self.kinematics.feet)
        self.nq_joints = int(self.kinematics.nq_joints)
        self.nv_joints = int(self.kinematics.nv_joints)
        placement = getattr(self.kinematics, "imu_placement", None)
        #: ``(R_bi, r_bi)``: the IMU's placement in the root frame (moving: at the neutral angles).
        self.imu_placement: tuple[Vector, Vector] = (
            (np.eye(3), np.zeros(3))
            if placement is None
            else (np.asarray(placement[0], dtype=float), np.asarray(placement[1], dtype=float))
        )
        #: ``imu_placement`` as the compiled estimate takes it (writable, C-contiguous copies)
        #: and whether ``R_bi`` is column-major (Pinocchio's: NumPy's ``R_bi @ ω`` then sums
        #: its columns, another order of the products; :data:`~.inekf_loops.base_kernel`)
        R_bi = self.imu_placement[0]
        columns = bool(R_bi.flags.f_contiguous and not R_bi.flags.c_contiguous)
        self._placement = (
            np.ascontiguousarray(R_bi, dtype=float).copy(),
            np.array(self.imu_placement[1], dtype=float),
            columns,
        )
        #: the IMU frame moves relative to the root (:mod:`~pinobs.observers.imu_link`)
        self.imu_moves = bool(getattr(self.kinematics, "imu_moves", False))
        #: the IMU frame is off the root's origin or moves: imu_link.py's (M4) in its lever arm
        self.imu_off_root = self.imu_moves or bool(np.any(self.imu_placement[1]))
        load_leg_kernels()  # compiled (or loaded from numba's cache) now, not at the first update
        #: the feet's names of each state's ``feet`` seen (:meth:`estimate`'s ``contacts``)
        self._names: dict[tuple[int, ...], tuple[str, ...]] = {}
        #: the rolling feet's model (``None``: ``foot_radius`` 0, the foot frames measured)
        self.rolling = (
            RollingFeet(self.kinematics, foot_radius, lift=rolling_lift)
            if foot_radius != 0
            else None
        )

    def not_reset(self) -> NotResetError:
        """The error for a call before ``reset``."""
        return NotResetError(f"{self.name}: call reset(t, q, ...) before update")

    def reset_inputs(
        self,
        t: float,
        q: ArrayLike,
        v: ArrayLike | None,
        gyro: ArrayLike | None,
        acc: ArrayLike | None,
        contacts: Mapping[str, bool] | Sequence[bool] | None,
        prior: InEKFPrior | None,
        bias: ArrayLike | None,
    ) -> ResetInputs:
        """Check ``reset``'s arguments (its docstring names the errors); the IMU's world
        velocity is the base's plus ``ω × (IMU − base origin)``."""
        t = check_time(t, None)
        nq, nv = 7 + self.nq_joints, 6 + self.nv_joints
        q = Robot.check_vector(q, nq, what="q")
        quat_norm = float(np.linalg.norm(q[3:7]))
        if abs(quat_norm - 1.0) > QUATERNION_NORM_TOL:
            raise ConfigurationError(
                f"q[3:7] = {q[3:7].tolist()} is not a unit quaternion (x, y, z, w) "
                f"(norm {quat_norm:.6g}); its norm must be 1 within {QUATERNION_NORM_TOL:g}"
            )
        v = np.zeros(nv) if v is None else Robot.check_vector(v, nv, what="v")
        imu = None
        if (gyro is None) != (acc is None):
            raise DimensionError("give both gyro and acc to reset, or neither")
        if gyro is not None and acc is not None:
            imu = np.concatenate(
                [Robot.check_vector(gyro, 3, what="gyro"), Robot.check_vector(acc, 3, what="acc")]
            )
        flags = (
            check_contacts(self.feet, contacts)
            if contacts is not None
            else [False] * len(self.feet)
        )
        prior = prior if prior is not None else InEKFPrior()
        if not isinstance(prior, InEKFPrior):
            raise GainError(f"prior must be an InEKFPrior, got {type(prior).__name__}")
        theta = np.zeros(6) if bias is None else Robot.check_vector(bias, 6, what="bias")
        R_bi, r_bi = self.imu_placement
        R_b = quaternion_to_rotation(q[3:7])
        x: Vector = np.array([R_b @ (v[:3] + np.cross(v[3:6], r_bi)), q[:3] + R_b @ r_bi])
        R: Vector = R_b @ R_bi
        if self.imu_moves:  # imu_link.py's (M1)-(M2)
            R, x = imu_state(R_b, q, v, *self.kinematics.imu_motion(q[7:]))  # type: ignore[attr-defined]
        if self.rolling is not None:
            self.rolling.restart()  # the feet down at reset land now
        return ResetInputs(t, q[7:], R, x, imu, flags, prior, theta, v[6:])

    def update_inputs(
        self,
        previous: float,
        t: float,
        q: ArrayLike,
        gyro: ArrayLike,
        acc: ArrayLike,
        contacts: Mapping[str, bool] | Sequence[bool],
        joint_velocities: ArrayLike | None,
    ) -> UpdateInputs:
        """Check ``update``'s arguments (its docstring names the errors)."""
        t = check_time(t, previous)
        q = np.asarray(q, dtype=float) if not isinstance(q, np.ndarray) else q
        if q.shape == (7 + self.nq_joints,):
            q_joints = Robot.check_vector(q, 7 + self.nq_joints, what="q")[7:]
        else:
            if q.shape != (self.nq_joints,):
                raise DimensionError(
                    f"q must have shape ({self.nq_joints},) (joint angles) or "
                    f"({7 + self.nq_joints},) (a free-flyer q), got shape {q.shape}"
                )
            q_joints = Robot.check_vector(q, self.nq_joints, what="q")
        reading = np.concatenate(
            [Robot.check_vector(gyro, 3, what="gyro"), Robot.check_vector(acc, 3, what="acc")]
        )
        flags = check_contacts(self.feet, contacts)
        dq = (
            None
            if joint_velocities is None
            else Robot.check_vector(joint_velocities, self.nv_joints, what="joint_velocities")
        )
        return UpdateInputs(t, q_joints, reading, flags, dq)

    def held(self, state: LegState, reading: Vector) -> Vector:
        """The reading to propagate with over ``[state.t, t]`` (``imu_hold``)."""
        held = state.imu if state.imu is not None else reading
        if self.imu_hold == "average":
            held = 0.5 * (held + reading)
        return held

    def legs(self, q_joints: Vector, R: Any = None, flags: Any = None) -> tuple[Vector, Vector]:
        """Foot positions in the IMU frame ``(K, 3)`` and their Jacobians ``(K, 3, nv_j)``; with
        ``foot_radius``, of the points :class:`~pinobs.observers.rolling.RollingFeet` measures
        (feet that land anchored from the estimated orientation ``R`` and the contact ``flags``)."""
        if self.rolling is not None:
            return self.rolling.legs(q_joints, R, flags)
        h, jac = self.kinematics.positions_and_jacobians(q_joints)
        return np.asarray(h, dtype=float), np.asarray(jac, dtype=float)

    def settle(self, R: Vector) -> None:
        """The orientation the filter ended its sample with, for the rolling feet's (R5)
        normals (:meth:`pinobs.observers.rolling.RollingFeet.settle`); nothing without them."""
        if self.rolling is not None and self.rolling.lift:
            self.rolling.settle(R)

    def warn_without_contact(self, warned: bool, t: float, flags: list[bool], last: float) -> bool:
        """Warn once when no foot has been in contact for NO_CONTACT_WARN_TIME; whether warned."""
        if any(flags) or warned or t - last < NO_CONTACT_WARN_TIME:
            return warned
        warnings.warn(
            f"{self.name}: no foot in contact for {t - last:.3g} s "
            f"(since t = {last:.6g} s): the velocity is the IMU's open-loop "
            f"integral and drifts; contacts must set each of {', '.join(self.feet)} "
            "to True while it is on the ground",
            ContactWarning,
            stacklevel=3,
        )
        return True

    def finite(self, state: LegState) -> bool:
        """Whether ``state``'s ``R``, ``x``, ``P`` and bias are finite: their sum is iff every
        entry is (or it overflowed: diverged as well), in one compiled pass
        (:data:`~pinobs.observers.inekf_loops.finite_kernel`)."""
        kernel = finite_kernel.compiled
        assert kernel is not None  # loaded by the constructor
        return bool(kernel(state.R, state.x, state.P, state.bias))

    def diverged(self, state: LegState, last: InEKFEstimate | None) -> ObserverDiverged:
        """The error for a ``state`` that is not :meth:`finite` (``last``: the estimate before)."""
        message = f"{self.name}: non-finite estimate at t = {state.t!r}"
        return ObserverDiverged(message, t=state.t, last_estimate=last)

    def base(
        self, state: LegState, q_joints: Vector, dq: Vector | None, rates: Vector | None = None
    ) -> tuple[Vector, Vector, Vector]:
        """``state`` converted to the root joint (module docstring): ``R_b``, the rows ``p_b,
        ω_b, v_b, R_b v_b`` (compiled: ``base_kernel``) and ``R_b``'s unit quaternion ``xyzw``
        (its sign as computed); an IMU frame that moves, through the joints' velocities
        ``rates`` (``dq`` if not given)."""
        R_b, base, quat = np.empty((3, 3)), np.empty((4, 3)), np.empty(4)
        kernel = base_kernel.compiled
        assert kernel is not None  # loaded by the constructor
        R, x, bias = state.R, state.x, state.bias
        imu = state.imu if state.imu is not None else _NO_READING
        if self.imu_moves:  # imu_link.py's (M3): the placement at q, then the joints' terms
            R_bi, r_bi, J_bi = self.kinematics.imu_motion(q_joints)  # type: ignore[attr-defined]
            kernel(R, x, imu, imu, bias, np.ascontiguousarray(R_bi), r_bi, False, R_b, base, quat)
            rates = dq if rates is None else rates
            root_twist(base, R_b, rates, r_bi, J_bi, lever_shift(R_bi, state.imu, state.lever))
        else:
            arm = imu if state.lever is None else state.lever  # imu_link.py's (M4): ω̄
            kernel(R, x, imu, arm, bias, *self._placement, R_b, base, quat)
        quat /= math.sqrt(float(quat @ quat))  # (rotation_to_quaternion's last steps)
        return R_b, base, quat

    def estimate(
        self,
        state: LegState,
        last: InEKFEstimate | None,
        q_joints: Vector,
        dq: Vector | None,
        nis: float | None,
        nis_dof: int = 0,
        gated: tuple[int, ...] = (),
        rates: Vector | None = None,
    ) -> InEKFEstimate:
        """Check ``state`` is :meth:`finite` (else ObserverDiverged with ``last``), convert it to
        the root joint (:meth:`base`)."""
        if not self.finite(state):
            raise self.diverged(state, last)
        R_b, base, quat = self.base(state, q_joints, dq, rates)
        q = np.concatenate([base[0], -quat if quat[3] < 0 else quat, q_joints])
        v = np.concatenate(
            [base[2], base[1], np.full(self.nv_joints, np.nan) if dq is None else dq]
        )
        world = base[3]
        for fresh in (q, v, R_b, world):  # made here: read-only without a copy
            fresh.setflags(write=False)
        x, P, bias = state.x, state.P, state.bias
        names = self._names.get(state.feet)
        if names is None:
            names = self._names[state.feet] = tuple(self.feet[j] for j in state.feet)
        out = object.__new__(InEKFEstimate)  # every field set in one dictionary update (as
        out.__dict__.update(  # replace_state: the frozen __init__ sets them one by one)
            t=state.t,
            q=q,
            v=v,
            rotation=R_b,
            velocity_world=world,
            bias=read_only(bias),
            covariance=read_only(P),
            contacts=names,
            foot_positions=read_only(x[2:]),
            nis=nis,
            nis_dof=nis_dof,
            gated=tuple(self.feet[j] for j in gated) if gated else (),
        )
        return out
