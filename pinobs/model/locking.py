"""Lock joints of a robot: a reduced model, its geometry reduced with it.

Joints are locked as :func:`pinobs.load`'s ``lock`` asks: the model is reduced by
``pin.buildReducedModel`` so each locked joint's child bodies are merged into its
parent's, the geometry with it.  A list of joint names locks each at its neutral
value (``pin.neutral``: 0 for revolute and prismatic joints); a mapping name →
value at that value: a float for a revolute [rad], prismatic [m] or continuous
(its angle [rad]) joint, within its position limits; for any joint also a
sequence of its ``nq`` coordinates (Pinocchio's ``q`` of the joint, unit
quaternions and ``(cos, sin)`` pairs), ``None`` for its neutral value.  A name
with ``*``, ``?`` or ``[...]`` is a shell pattern (:func:`fnmatch.fnmatchcase`)
over the moving joints' names: ``"hand_*"`` locks a hand's every joint (each at
the pattern's value); a pattern that matches no joint is an error, as an unknown
name is, and so is a joint that two entries name.  The robot
keeps what was locked (:attr:`Robot.locked`, name → value, a float for one-dof
joints) and :func:`~pinobs.model.urdf_writer.write_urdf` writes those joints back
as fixed ones at their values.
"""

from __future__ import annotations

import difflib
import fnmatch
import re
from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any

import numpy as np
import pinocchio as pin

from pinobs.errors import (
    DimensionError,
    GainError,
    ModelTypeError,
    NonFiniteError,
    UnknownNameError,
)
from pinobs.model.robot import Robot

__all__ = ["LockSpec", "is_locked", "lock_joints", "lock_names"]

#: Joints to lock: names (each at its neutral value, ``pin.neutral``), or name → value: a
#: float for a one-dof joint (revolute or prismatic [rad or m]; continuous: its angle [rad]),
#: ``nq`` numbers (Pinocchio's ``q`` of the joint) for any joint, ``None`` for the neutral.
LockSpec = Sequence[str] | Mapping[str, "float | Sequence[float] | None"]

_PATTERN = re.compile(r"[*?\[]")  # a shell pattern's characters (fnmatch)


def _expand(
    values: Mapping[str, float | Sequence[float] | None], moving: Sequence[str]
) -> tuple[dict[str, float | Sequence[float] | None], list[str]]:
    """``values`` with each pattern replaced by the joints it matches (module docstring), and
    the names and patterns that match no moving joint."""
    out: dict[str, float | Sequence[float] | None] = {}
    unknown: list[str] = []
    for key, value in values.items():
        name = str(key)
        hits = (
            [m for m in moving if fnmatch.fnmatchcase(m, name)]
            if _PATTERN.search(name)
            else ([name] if isinstance(key, str) and name in moving else [])
        )
        if not hits:
            unknown.append(key)
        for hit in hits:
            if hit in out:
                raise GainError(f"lock names joint {hit!r} more than once ({name!r}); name it once")
            out[hit] = value
    return out, unknown


def _lock_values(
    model: pin.Model, lock: LockSpec, robot: str
) -> tuple[list[int], np.ndarray, dict[str, float | tuple[float, ...]]]:
    """The joint ids to lock, the configuration they are locked at (the others neutral) and
    what was locked, name → value as :attr:`Robot.locked` keeps it (a float for one-dof
    joints, a continuous joint's angle included; Pinocchio's ``q`` of the joint otherwise)."""
    if isinstance(lock, str | bytes) or not isinstance(lock, Sequence | Mapping):
        raise ModelTypeError(
            f"lock={lock!r}: give a list of joint names, or a mapping joint name → value "
            f"(lock=[{lock!r}] locks that joint at its neutral value)"
            if isinstance(lock, str)
            else f"lock={lock!r}: give a list of joint names, or a mapping joint name → value"
        )
    values: Mapping[str, float | Sequence[float] | None] = (
        lock if isinstance(lock, Mapping) else dict.fromkeys(lock)
    )
    if not isinstance(lock, Mapping) and len(values) < len(lock):
        twice = sorted({n for n in lock if list(lock).count(n) > 1})
        raise GainError(f"lock names {twice} more than once; name each joint once")
    moving = [model.names[i] for i in range(1, model.njoints) if model.joints[i].nv > 0]
    values, unknown = _expand(values, moving)
    if unknown:
        close = sorted({c for n in unknown for c in difflib.get_close_matches(str(n), moving, n=2)})
        hint = f"did you mean {' or '.join(map(repr, close))}? " if close else ""
        raise UnknownNameError(
            f"lock (--lock) names {unknown}, which robot {robot!r} does not have among its "
            f"moving joints; {hint}its joints: {moving}"
        )
    q_ref = pin.neutral(model)
    ids: list[int] = []
    locked: dict[str, float | tuple[float, ...]] = {}
    for name, value in values.items():
        jid = model.getJointId(name)
        joint = model.joints[jid]
        iq, nq = joint.idx_q, joint.nq
        short = joint.shortname()
        circle = short.startswith("JointModelRUB")  # continuous: q = (cos, sin)
        ids.append(jid)
        if value is not None:
            q_ref[iq : iq + nq] = _lock_q(model, name, value, iq, nq, circle)
        if nq == 1:
            locked[name] = float(q_ref[iq])
        elif circle:
            locked[name] = float(np.arctan2(q_ref[iq + 1], q_ref[iq]))
        else:
            locked[name] = tuple(float(x) for x in q_ref[iq : iq + nq])
    if sum(model.joints[i].nv for i in ids) == model.nv:
        raise GainError(
            f"lock={list(values)} locks every moving joint of robot {robot!r}: nothing "
            "would move; leave at least one joint free"
        )
    return sorted(ids), q_ref, locked


def _lock_q(
    model: pin.Model, name: str, value: float | Sequence[float], iq: int, nq: int, circle: bool
) -> np.ndarray:
    """The ``q`` of joint ``name`` locked at ``value`` (a float for one-dof joints, else ``nq``
    numbers), checked against its position limits and, on a Lie group, its unit norms."""
    if isinstance(value, int | float | np.floating | np.integer) and not isinstance(value, bool):
        if nq == 1:
            q = np.array([float(value)])
        elif circle:
            q = np.array([np.cos(float(value)), np.sin(float(value))])
        else:
            raise DimensionError(
                f"lock={{{name!r}: {value!r}}}: joint {name!r} has nq = {nq} coordinates; give "
                f"its {nq} values (Pinocchio's q of the joint), or lock it at its neutral value "
                f"(lock=[{name!r}])"
            )
    else:
        try:
            q = np.array(value, dtype=float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise GainError(
                f"lock={{{name!r}: {value!r}}}: give a number, or the joint's {nq} values"
            ) from exc
        if q.size != nq:
            raise DimensionError(
                f"lock={{{name!r}: {value!r}}}: joint {name!r} has nq = {nq} coordinates"
                + ("" if nq == 1 and not circle else "; give that many values")
                + ("; or its angle as one number" if circle else "")
            )
    if not np.all(np.isfinite(q)):
        raise NonFiniteError(f"lock={{{name!r}: {value!r}}}: the value is not finite")
    lo = np.array(model.lowerPositionLimit[iq : iq + nq], dtype=float)
    hi = np.array(model.upperPositionLimit[iq : iq + nq], dtype=float)
    if nq == 1 and np.isfinite(lo[0]) and np.isfinite(hi[0]) and lo[0] < hi[0] < 1e300:
        if not lo[0] <= q[0] <= hi[0]:
            raise GainError(
                f"lock={{{name!r}: {value!r}}} is outside the position limits "
                f"[{lo[0]:g}, {hi[0]:g}] of joint {name!r}"
            )
    full = pin.neutral(model)
    full[iq : iq + nq] = q
    if not pin.isNormalized(model, full, 1e-6):
        raise GainError(
            f"lock={{{name!r}: {value!r}}}: joint {name!r}'s quaternion or (cos, sin) pair "
            "is not of unit norm"
        )
    return pin.normalize(model, full)[iq : iq + nq]


def _locked_geometry(
    loader: Any, full: pin.Model, ids: list[int], q_ref: np.ndarray, model: pin.Model
) -> tuple[Any, Any]:
    """The geometry of a locked robot: its full model's (from ``loader``), reduced as the
    model was (``pin.buildReducedModel``), so playback draws the locked bodies where they are."""
    visual, collision = loader(full) if loader is not None else (None, None)
    given = [g for g in (visual, collision) if g is not None]
    if not given:
        return visual, collision
    _, reduced = pin.buildReducedModel(full, given, ids, q_ref)
    out = iter(reduced)
    return (
        next(out) if visual is not None else None,
        next(out) if collision is not None else None,
    )


def lock_joints(robot: Robot, lock: LockSpec | None) -> Robot:
    """``robot`` with the joints of ``lock`` locked (module docstring); itself when none."""
    if lock is None or (isinstance(lock, Sequence | Mapping) and len(lock) == 0):
        return robot
    full = robot.model
    ids, q_ref, locked = _lock_values(full, lock, robot.name)
    model = pin.buildReducedModel(full, ids, q_ref)
    if robot._geometry is not None:  # given (pin.Model, RobotWrapper): reduced now
        geometry: dict[str, Any] = dict(
            zip(
                ("visual_model", "collision_model"),
                _locked_geometry(lambda _: robot._geometry, full, ids, q_ref, model),
                strict=True,
            )
        )
    else:  # a loader: reduced when first drawn
        geometry = {"geometry": partial(_locked_geometry, robot._geometry_loader, full, ids, q_ref)}
    out = Robot(
        model,
        name=robot.name,
        source=robot.source,
        friction=robot.friction,
        root_joint=robot.root_joint,
        package_dirs=robot.package_dirs,
        locked=locked,
        **geometry,
    )
    out.mimic = robot.mimic
    return out


def lock_names(lock: LockSpec | None) -> frozenset[str]:
    """The joint names and patterns of ``lock`` (checked against the model later,
    :func:`_lock_values`; :func:`is_locked` tells whether one names a joint)."""
    if lock is None or isinstance(lock, str | bytes):
        return frozenset()
    return frozenset(str(n) for n in lock)


def is_locked(joint: str, names: frozenset[str]) -> bool:
    """Whether ``names`` (:func:`lock_names`) locks ``joint``: by its name or a pattern."""
    return joint in names or any(fnmatch.fnmatchcase(joint, n) for n in names if _PATTERN.search(n))
