"""Drives: a log's motor-side columns as joint positions and torques (gear ratios, motor
constants, coupled joints).

A geared joint's motor turns ``N`` times as far as the joint; a coupled wrist's motor
turns with several joints (the Stäubli TX40's sixth motor with joints 5 and 6).  One
square *transmission* matrix ``T`` (``diag(N)`` without coupling) says both, motor
positions ``θ_m`` from joint positions ``q`` and joint torques ``τ`` from motor torques
``τ_m``::

    θ_m = T (q − q₀)          q = T⁻¹ θ_m + q₀                       (1)
    τ_m = k ⊙ i               motor torque [N·m] from current i [A]   (2)
    τ   = Tᵀ τ_m              the power balance τ_mᵀ θ̇_m = τᵀ q̇       (3)
    τ   = s ⊙ τ_col           a torque column at another scale          (4)

(Siciliano et al., *Robotics: Modelling, Planning and Control*, 2009, §5.1, (1) and
(3); FIGAROH's TX40 example builds ``T`` as ``diag(N)`` with ``T[5, 4] = N₆``, its
``_convert_motor_to_joint_positions`` takes ``T⁻¹ θ_m`` and its ``process_torque_data``
``Tᵀ τ_m``.)  ``q₀`` (``position_offset``) puts the motor encoders' zero where the
model's is.

The log's columns (CSV, TSV, Parquet, DataFrame; :func:`pinobs.io.iter_log`):
``qm.<joint>`` motor positions [rad, motor side] read through (1), ``i.<joint>`` motor
currents [A] through (2)–(3), ``tau.<joint>`` scaled by ``torque_scale`` (4) (TIAGo's
efforts: ratio × motor constant × current).  Anything given and not used, or used and
not given, is an error naming it: a current column without ``motor_constant``, a motor
position without a transmission, a transmission of the wrong shape or singular.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import DimensionError, OptionError
from pinobs.model import Robot
from pinobs.model.robot import Vector

__all__ = ["MAX_TRANSMISSION_CONDITION", "Drives"]

#: A transmission matrix worse conditioned than this is refused as singular.
MAX_TRANSMISSION_CONDITION = 1e12


def _transmission(transmission: ArrayLike) -> Vector:
    """``transmission`` as a read-only square matrix, checked: finite, invertible.

    Raises:
        DimensionError: not square, not finite, or singular.
    """
    T = np.asarray(transmission, dtype=float)
    if T.ndim != 2 or T.shape[0] != T.shape[1]:
        raise DimensionError(
            f"transmission must be a square matrix (n × n, θ_m = T q), got shape {T.shape}"
        )
    if not np.all(np.isfinite(T)):
        raise DimensionError("transmission is not finite")
    cond = np.linalg.cond(T)
    if not cond < MAX_TRANSMISSION_CONDITION:
        raise DimensionError(
            f"transmission is singular (condition number {cond:.3g}): no joint "
            f"positions follow from the motors'; T = {T.tolist()}"
        )
    T = T.copy()
    T.flags.writeable = False
    return T


def _vector(name: str, value: ArrayLike | None) -> Vector | None:
    if value is None:
        return None
    out = np.atleast_1d(np.asarray(value, dtype=float))
    if out.ndim != 1 or out.size == 0:
        raise DimensionError(f"{name} must be a vector of one number per joint, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise DimensionError(f"{name} = {out.tolist()} is not finite")
    return out


@dataclass(frozen=True, eq=False)
class Drives:
    """A robot's drives: how its log's motor-side columns map to the joints (module docstring).

    Args:
        gear_ratio: ``N`` per joint (motor turns per joint turn; a negative one turns the
            other way); ``T = diag(N)``.  Give this or ``transmission``.
        transmission: ``T`` (n × n), ``θ_m = T (q − q₀)``, for coupled joints.
        motor_constant: ``k`` per joint [N·m/A]: motor torque from an ``i.<joint>`` current.
        torque_scale: ``s`` per joint: the ``tau.<joint>`` columns times ``s``.
        position_offset: ``q₀`` per joint [rad or m], added to ``T⁻¹ θ_m``.

    Raises:
        DimensionError: vectors of different lengths, not finite, a zero gear ratio or
            motor constant, a transmission that is not square or singular.
        OptionError: both ``gear_ratio`` and ``transmission``; nothing given.
    """

    gear_ratio: Any = None
    transmission: Any = None
    motor_constant: Any = None
    torque_scale: Any = None
    position_offset: Any = None

    def __post_init__(self) -> None:
        if self.gear_ratio is not None and self.transmission is not None:
            raise OptionError(
                "give gear_ratio (--gear-ratio) or transmission (--transmission), not both: "
                "a transmission matrix holds the gear ratios on its diagonal"
            )
        vectors = {
            name: _vector(name, getattr(self, name))
            for name in ("gear_ratio", "motor_constant", "torque_scale", "position_offset")
        }
        for name, value in vectors.items():
            object.__setattr__(self, name, value)
        if all(v is None for v in vectors.values()) and self.transmission is None:
            raise OptionError(
                "Drives() says nothing: give gear_ratio or transmission, motor_constant, "
                "torque_scale or position_offset"
            )
        for name in ("gear_ratio", "motor_constant", "torque_scale"):
            v = vectors[name]
            if v is not None and np.any(v == 0.0):
                raise DimensionError(
                    f"{name} = {v.tolist()} has a zero: every joint needs a non-zero one"
                )
        if self.transmission is not None:
            object.__setattr__(self, "transmission", _transmission(self.transmission))
        sizes = {n: v.size for n, v in vectors.items() if v is not None}
        if self.transmission is not None:
            sizes["transmission"] = self.transmission.shape[0]
        if len(set(sizes.values())) > 1:
            raise DimensionError(f"drives of different sizes: {sizes}; give one number per joint")

    def _key(self) -> tuple[Any, ...]:
        fields = (*self._vectors(), self.transmission)
        return tuple(None if v is None else (v.shape, v.tobytes()) for v in fields)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Drives) and self._key() == other._key()

    def __hash__(self) -> int:  # a LogTask's field (pinobs.evaluation.many_logs)
        return hash(self._key())

    @property
    def size(self) -> int:
        """The number of joints the drives describe."""
        if self.transmission is not None:
            return int(self.transmission.shape[0])
        return next(int(v.size) for v in self._vectors() if v is not None)

    def _vectors(self) -> tuple[Vector | None, ...]:
        return (self.gear_ratio, self.motor_constant, self.torque_scale, self.position_offset)

    @property
    def matrix(self) -> Vector | None:
        """``T``: ``transmission``, or ``diag(gear_ratio)``, or ``None`` (neither given)."""
        if self.transmission is not None:
            return np.array(self.transmission)
        if self.gear_ratio is not None:
            return np.diag(self.gear_ratio)
        return None

    def check(self, robot: Robot) -> None:
        """Refuse drives that do not fit ``robot``: one per joint, each joint one coordinate.

        Raises:
            DimensionError: naming the sizes and the joints.
        """
        many = [b.name for b in robot.joints if b.nv != 1]
        if many:
            raise DimensionError(
                f"drives map one motor per one-coordinate joint; robot {robot.name!r} has "
                f"joints {many} of several coordinates (a floating base?)"
            )
        if self.size != robot.nv:
            raise DimensionError(
                f"drives describe {self.size} joints, robot {robot.name!r} has {robot.nv}: "
                f"{list(robot.joint_names)}; give one number per joint (a {robot.nv} × "
                f"{robot.nv} transmission)"
            )

    def joint_positions(self, motor: ArrayLike) -> Vector:
        """``q = T⁻¹ θ_m + q₀`` (1) of motor positions ``(N, n)`` [rad, motor side].

        Raises:
            OptionError: no gear ratio or transmission.
        """
        T = self.matrix
        if T is None:
            raise OptionError(
                "motor positions (qm.<joint> columns) need gear_ratio or transmission "
                "(--gear-ratio, --transmission): q = T⁻¹ θ_m"
            )
        m = np.asarray(motor, dtype=float)
        q = np.linalg.solve(T, m.T).T  # (1)
        return q if self.position_offset is None else q + self.position_offset

    def motor_positions(self, q: ArrayLike) -> Vector:
        """``θ_m = T (q − q₀)`` (1), the inverse of :meth:`joint_positions`."""
        T = self.matrix
        if T is None:
            raise OptionError("motor positions need gear_ratio or transmission")
        x = np.asarray(q, dtype=float)
        if self.position_offset is not None:
            x = x - self.position_offset
        return np.asarray(x @ T.T)

    def joint_torques(self, current: ArrayLike) -> Vector:
        """``τ = Tᵀ (k ⊙ i)`` (2)–(3) of motor currents ``(N, n)`` [A].

        Raises:
            OptionError: no motor constant, or no gear ratio or transmission.
        """
        if self.motor_constant is None:
            raise OptionError(
                "current columns (i.<joint>) need motor_constant (--motor-constant) [N·m/A]: "
                "τ = Tᵀ (k ⊙ i)"
            )
        T = self.matrix
        if T is None:
            raise OptionError(
                "current columns (i.<joint>) need gear_ratio or transmission (--gear-ratio, "
                "--transmission; 1 for a direct drive): τ = Tᵀ (k ⊙ i)"
            )
        i = np.asarray(current, dtype=float)
        return np.asarray((i * self.motor_constant) @ T)  # (2), (3): rows τᵀ = τ_mᵀ T

    def scaled_torques(self, tau: ArrayLike) -> Vector:
        """``s ⊙ τ_col`` (4) (unchanged without ``torque_scale``)."""
        x = np.asarray(tau, dtype=float)
        return x if self.torque_scale is None else x * self.torque_scale

    @classmethod
    def from_options(
        cls,
        *,
        gear_ratio: str | None = None,
        transmission: str | None = None,
        motor_constant: str | None = None,
        torque_scale: str | None = None,
        position_offset: str | None = None,
    ) -> Drives | None:
        """Drives from the command line's text (comma-separated numbers; a transmission's
        rows separated by ``;``), ``None`` when nothing is given.

        Raises:
            OptionError: a number that does not read, naming the flag.
        """
        texts = {
            "gear_ratio": gear_ratio,
            "motor_constant": motor_constant,
            "torque_scale": torque_scale,
            "position_offset": position_offset,
        }
        if transmission is None and all(v is None for v in texts.values()):
            return None
        values: dict[str, Any] = {k: _numbers(k, v) for k, v in texts.items() if v is not None}
        if transmission is not None:
            rows = [_numbers("transmission", r) for r in transmission.split(";") if r.strip()]
            if len({len(r) for r in rows}) > 1:
                raise DimensionError(
                    f"--transmission {transmission!r}: rows of different lengths "
                    f"{[len(r) for r in rows]}; give n rows of n numbers separated by ';'"
                )
            values["transmission"] = np.array(rows)
        return cls(**values)


def _numbers(name: str, text: str) -> Sequence[float]:
    flag = "--" + name.replace("_", "-")
    try:
        return [float(x) for x in text.replace(" ", ",").split(",") if x.strip()]
    except ValueError:
        raise OptionError(
            f"{flag} {text!r}: give one number per joint, comma-separated"
            + (" (rows separated by ';')" if name == "transmission" else "")
        ) from None
