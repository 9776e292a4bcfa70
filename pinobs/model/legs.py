"""Leg kinematics of a floating-base robot: foot positions in the base frame, and their Jacobians.

The contact-aided invariant EKF (:mod:`pinobs.observers.inekf`) measures each
foot in contact through forward kinematics of the measured joint angles::

    h_j(q) = position of foot frame j in the base frame   (Hartley et al.'s h_p(α))
    J_j(q) = ∂h_j/∂v_joints,  a 3 × (nv − 6) matrix

The base frame is the frame of the free-flyer root joint (Pinocchio's
``q[0:7]``, the frame whose body velocity is ``v[0:6]``), or, with
``imu_frame``, the IMU's frame (a frame fixed to the base: go1's
``imu_link``, 7 cm from the root): then ``h_j`` and ``J_j`` are expressed in it,
``R_bi (h_j − r_bi)``-wise, and :attr:`FootKinematics.imu_placement` is
``(R_bi, r_bi)``, the IMU's rotation and position in the root joint's frame.  Both are computed
with the base placed at the identity, so the world-aligned frame Jacobian of
Pinocchio *is* the base-frame one: ``J_j`` is the linear rows, joint columns,
of ``getFrameJacobian(..., LOCAL_WORLD_ALIGNED)`` at ``q = (0, 0, 0, 0, 0, 0, 1, q_joints)``.
For revolute and prismatic joints ``J_j = ∂h_j/∂q_joints``; for continuous
joints it is with respect to the joint's velocity coordinate (its angle).

:func:`foot_sphere_radius` reads a foot's collision sphere from the robot's URDF (go1's
2 cm feet), the radius the filters' ``foot_radius`` takes (:mod:`pinobs.observers.rolling`).
"""

from __future__ import annotations

import difflib
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import (
    ConfigurationError,
    DimensionError,
    UnknownNameError,
    UnsupportedRobotError,
)
from pinobs.model.loading import resolve_source
from pinobs.model.robot import Robot

__all__ = ["FootKinematics", "foot_sphere_radii", "foot_sphere_radius"]

Vector = NDArray[np.floating[Any]]

#: The configuration of a free-flyer at the identity: position 0, quaternion (x, y, z, w) = (0, 0, 0, 1).
_BASE_AT_IDENTITY = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
_LOCAL_WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
#: ``+0.0`` as a 0-d array (read-only): ``x + _ZERO`` is ``x + 0.0``
_ZERO = np.zeros(())
_ZERO.setflags(write=False)


class FootKinematics:
    """Positions of some frames (the feet) in a free-flyer robot's base frame, from its joint angles.

    Owns its ``pin.Data`` (a copy of ``robot``'s model's data), so it shares
    nothing with the robot it was built from.

    Args:
        robot: a robot whose first joint is a free-flyer (``pinobs.load("go1")``;
            other URDFs: ``pinobs.load(path, root_joint="freeflyer")``).
        feet: names of the foot frames in the model (``"FL_foot"``, ...), at least one.
        imu_frame: a frame fixed to the root joint (the IMU's) to express the feet in,
            instead of the root joint's frame.

    Attributes:
        feet: the foot frame names, in the given order.
        nq_joints: number of joint coordinates after the free-flyer (``nq − 7``).
        nv_joints: number of joint velocities after the free-flyer (``nv − 6``).
        imu_placement: ``(R_bi, r_bi)``: rotation and position [m] of the frame the feet are
            expressed in, in the root joint's frame (identity and zero without ``imu_frame``).

    Raises:
        UnsupportedRobotError: the robot's first joint is not a free-flyer, or the
            ``imu_frame`` is not fixed to it.
        UnknownNameError: a foot name is not a frame of the model (the message
            lists the closest frame names and the model's frames).
    """

    def __init__(self, robot: Robot, feet: Sequence[str], *, imu_frame: str | None = None) -> None:
        model = robot.model
        if not robot.joints or robot.joints[0].kind != "se3" or robot.joints[0].idx_q != 0:
            first = robot.joints[0].name if robot.joints else "none"
            raise UnsupportedRobotError(
                f"{robot.name}: foot kinematics needs a free-flyer root joint (the floating "
                f"base), but the first joint is {first!r}; load the robot with "
                f"pinobs.load(..., root_joint='freeflyer')"
            )
        if isinstance(feet, str) or len(feet) == 0:
            raise UnknownNameError(
                f"feet must be a non-empty sequence of frame names, got {feet!r}"
            )
        ids = [_frame_id(robot, foot) for foot in feet]
        if len(set(ids)) != len(ids):
            raise UnknownNameError(f"feet lists a frame twice: {list(feet)}")
        self.feet: tuple[str, ...] = tuple(str(f) for f in feet)
        self.nq_joints = int(model.nq) - 7
        self.nv_joints = int(model.nv) - 6
        self._model = model
        self._data = model.createData()
        self._oMf = self._data.oMf  # (the frames' placements, in place: one attribute look-up)
        self._ids = tuple(ids)
        #: each foot's placement in ``oMf`` (a reference into this object's data, which the
        #: Jacobians update in place: ``.homogeneous`` without indexing ``oMf`` each sample)
        self._foot_oMf = tuple(self._oMf[f] for f in ids)
        self._q = np.concatenate([_BASE_AT_IDENTITY, pin.neutral(model)[7:]])
        #: per method, the last joint angles' bytes and its results (:meth:`_recall`)
        self._memo: dict[str, tuple[bytes, tuple[Vector, ...]]] = {}
        #: :meth:`preload`'s rows: each row's angles' bytes → its index into the block's arrays
        self._preloaded: dict[bytes, int] = {}
        self._block: tuple[Vector, ...] = ()
        self.robot_name = robot.name
        self.imu_frame = imu_frame
        self.imu_placement: tuple[Vector, Vector] = (np.eye(3), np.zeros(3))
        if imu_frame is not None:
            fid = _frame_id(robot, imu_frame)
            if model.frames[fid].parentJoint != 1:
                raise UnsupportedRobotError(
                    f"{robot.name}: imu_frame {imu_frame!r} moves with joint "
                    f"{model.names[model.frames[fid].parentJoint]!r}, not with the base "
                    f"({model.names[1]!r}): give a frame fixed to the base"
                )
            placement = model.frames[fid].placement  # in the root joint's frame
            self.imu_placement = (
                np.array(placement.rotation, dtype=float),
                np.array(placement.translation, dtype=float),
            )
        for a in self.imu_placement:
            a.setflags(write=False)
        self._to_imu = None if imu_frame is None else self.imu_placement
        #: the IMU's axes are the base's (``R_bi`` exactly ``I``, go1's ``imu_link``)
        self._imu_aligned = bool(np.array_equal(self.imu_placement[0], np.eye(3)))

    def __repr__(self) -> str:
        return f"FootKinematics({self.robot_name!r}, feet={self.feet})"

    def _set(self, q_joints: ArrayLike) -> None:
        self._q[7:] = q_joints

    def _recall(self, name: str, q_joints: ArrayLike) -> tuple[bytes, tuple[Vector, ...] | None]:
        """The key of ``q_joints`` and copies of ``name``'s results for it if they are the last
        ones computed (the same angles twice in a row: a filter's sample and a caller's
        velocities at it), else ``None``; the same bytes give the same results."""
        key = np.asarray(q_joints, dtype=float).tobytes()
        last = self._memo.get(name)
        if last is None or last[0] != key:
            return key, None
        return key, tuple(a.copy() for a in last[1])

    def _keep(self, name: str, key: bytes, out: tuple[Vector, ...]) -> tuple[Vector, ...]:
        """``out``, with a copy kept for :meth:`_recall`."""
        self._memo[name] = (key, tuple(a.copy() for a in out))
        return out

    def positions(self, q_joints: ArrayLike) -> Vector:
        """``h_j(q)`` for every foot, shape ``(len(feet), 3)`` [m], in the base (or IMU) frame."""
        self._set(q_joints)
        pin.framesForwardKinematics(self._model, self._data, self._q)
        h = np.array([self._data.oMf[i].translation for i in self._ids])
        if self._to_imu is not None:
            R_bi, r_bi = self._to_imu
            h = (h - r_bi) @ R_bi  # rows: R_biᵀ (h − r_bi)
        return h

    def positions_and_jacobians(self, q_joints: ArrayLike) -> tuple[Vector, Vector]:
        """``(h, J)``: foot positions ``(K, 3)`` [m] and their Jacobians ``(K, 3, nv_joints)``
        [m/rad] with respect to the joint velocities, in the base (or IMU) frame."""
        key, last = self._recall("positions_and_jacobians", q_joints)
        if last is not None:
            return last[0], last[1]
        self._set(q_joints)
        model, data = self._model, self._data
        pin.computeJointJacobians(model, data, self._q)
        pin.updateFramePlacements(model, data)
        h = np.empty((len(self._ids), 3))
        jac = np.empty((len(self._ids), 3, self.nv_joints))
        for k, fid in enumerate(self._ids):
            h[k] = data.oMf[fid].translation
            full = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            jac[k] = full[:3, 6:]
        if self._to_imu is not None:
            R_bi, r_bi = self._to_imu
            h = (h - r_bi) @ R_bi
            jac = R_bi.T @ jac
        self._keep("positions_and_jacobians", key, (h, jac))
        return h, jac

    def placements_and_jacobians(self, q_joints: ArrayLike) -> tuple[Vector, ...]:
        """``(h, R, J, J_ω)``: the feet's positions ``(K, 3)`` [m] and orientations ``(K, 3, 3)``,
        their linear ``(K, 3, nv_joints)`` [m/rad] and angular ``(K, 3, nv_joints)`` [rad/rad]
        Jacobians with respect to the joint velocities, all in the base (or IMU) frame."""
        return tuple(a.copy() for a in self.shared_placements_and_jacobians(q_joints))

    def shared_placements_and_jacobians(self, q_joints: ArrayLike) -> tuple[Vector, ...]:
        """:meth:`placements_and_jacobians` without the copies: the arrays are this object's, kept
        for its next call with the same angles, and are not to be written to (the rolling feet
        read them every sample; writable, the compiled kernels' signatures).

        One ``computeJointJacobians``, then per foot ``getFrameJacobian``, which also sets the
        foot's ``oMf`` (``oMi · placement``, what ``updateFramePlacements`` gives it): the same
        arithmetic as before, without the placements of the frames that are not feet.  Angles
        whose bytes are those of a row given to :meth:`preload` get that row's arrays."""
        key = np.asarray(q_joints, dtype=float).tobytes()
        last = self._memo.get("placements_and_jacobians")
        if last is not None and last[0] == key:
            return last[1]
        row = self._preloaded.get(key)
        if row is not None:
            return self._kept(key, tuple(a[row] for a in self._block))
        self._set(q_joints)
        return self._kept(key, self._in_imu_frame(*self._feet_at_q()))

    def preload(self, q_rows: ArrayLike) -> None:
        """:meth:`shared_placements_and_jacobians` of each row of ``q_rows`` ``(M, nq_joints)``,
        computed now and kept (replacing the rows kept before) for the calls with the same
        angles' bytes: the same values (the same Pinocchio calls, then the same elementwise
        operations on the whole block at once, or per row where the IMU's axes are not the
        base's), without a call's NumPy work each sample.  A log's runner
        (:func:`pinobs.io.legged_run.legged_run`) preloads its rows block by block.

        Raises:
            DimensionError: ``q_rows`` not of shape ``(M, nq_joints)``.
        """
        rows = np.ascontiguousarray(q_rows, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != self.nq_joints:
            raise DimensionError(
                f"q_rows must have shape (M, {self.nq_joints}) (joint angles per row), got "
                f"shape {rows.shape}"
            )
        model, data, ids, q = self._model, self._data, self._ids, self._q
        jacobians: list[Vector] = []
        placements: list[Vector] = []
        for angles in rows:
            q[7:] = angles  # (_set)
            pin.computeJointJacobians(model, data, q)
            jacobians.extend(
                [pin.getFrameJacobian(model, data, f, _LOCAL_WORLD_ALIGNED) for f in ids]
            )
            placements.extend([m.homogeneous for m in self._foot_oMf])
        m, k = rows.shape[0], len(ids)
        full = np.concatenate(jacobians).reshape(m, k, 6, -1)  # (the rows stacked: copies)
        placement = np.concatenate(placements).reshape(m, k, 4, 4)
        if self._to_imu is not None and self._imu_aligned:
            block = self._in_imu_frame(full, placement)  # (elementwise: one call for the block)
        else:
            per_row = [self._in_imu_frame(f, p) for f, p in zip(full, placement, strict=True)]
            block = tuple(np.array(a) for a in zip(*per_row, strict=True))
        self._block = tuple(np.ascontiguousarray(a) for a in block)
        self._preloaded = {angles.tobytes(): i for i, angles in enumerate(rows)}

    def _feet_at_q(self) -> tuple[Vector, Vector]:
        """The feet's frame Jacobians ``(K, 6, nv)`` (``LOCAL_WORLD_ALIGNED``) and placements
        ``(K, 4, 4)`` in the world (the root at the identity) at ``self._q``."""
        model, data = self._model, self._data
        pin.computeJointJacobians(model, data, self._q)
        ids = self._ids  # each foot's Jacobian, then its oMf (set by getFrameJacobian)
        full = np.array([pin.getFrameJacobian(model, data, f, _LOCAL_WORLD_ALIGNED) for f in ids])
        return full, np.array([m.homogeneous for m in self._foot_oMf])

    def _in_imu_frame(self, full: Vector, placement: Vector) -> tuple[Vector, ...]:
        """``(h, R, J, J_ω)`` from :meth:`_feet_at_q`'s arrays, in the base (or IMU) frame; with
        the IMU's axes the base's, elementwise (a block ``(M, K, …)`` too)."""
        h, rot = placement[..., :3, 3], placement[..., :3, :3]
        if self._to_imu is not None and self._imu_aligned:
            # R_bi = I: R_biᵀ x is x (its products' terms x·1 + y·0 + z·0, x finite), and
            # x + 0 its zeros' signs as the products leave them (-0 + 0 = +0; a 0-d array's
            # zero: the same sum, without converting a Python float each call)
            h, rot = h - self._to_imu[1], rot + _ZERO
            return h, rot, full[..., :3, 6:] + _ZERO, full[..., 3:, 6:] + _ZERO
        jac = np.ascontiguousarray(full[:, :, 6:])
        lin, ang = jac[:, :3], jac[:, 3:]
        if self._to_imu is not None:
            R_bi, r_bi = self._to_imu
            h, rot = (h - r_bi) @ R_bi, R_bi.T @ rot
            lin, ang = R_bi.T @ lin, R_bi.T @ ang
        else:
            h, rot = np.ascontiguousarray(h), np.ascontiguousarray(rot)
        return h, rot, lin, ang

    def _kept(self, key: bytes, out: tuple[Vector, ...]) -> tuple[Vector, ...]:
        """``out``, kept (not copied) for the next call with the same angles' bytes ``key``."""
        self._memo["placements_and_jacobians"] = (key, out)
        return out


def _frame_id(robot: Robot, name: str) -> int:
    """The frame's index, or an error naming the closest frames and listing them all."""
    model = robot.model
    if not model.existFrame(name):
        names = [str(f.name) for f in model.frames]
        close = difflib.get_close_matches(str(name), names, n=4, cutoff=0.5)
        hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
        raise UnknownNameError(
            f"{robot.name} has no frame {name!r}{hint} Its frames: {', '.join(names)}"
        )
    return int(model.getFrameId(name))


def foot_sphere_radius(robot: Robot, foot: str) -> float:
    """The radius [m] of the collision sphere of the URDF link named ``foot`` (a foot frame of
    a URDF robot is its link's), centred on the link's frame; 0 if its collision geometry is
    not a sphere (a flat sole: the frame is the contact point).

    Raises:
        UnknownNameError: ``foot`` is not a frame of the model, or not a link of the URDF.
        ConfigurationError: the robot was not loaded from a URDF, or the sphere is off the
            link's origin (the frame would not be its centre).
    """
    return foot_sphere_radii(robot, (foot,))[foot]


def foot_sphere_radii(robot: Robot, feet: Sequence[str]) -> dict[str, float]:
    """:func:`foot_sphere_radius` of each of ``feet``, the URDF read once (its errors, for the
    first foot that has one, in the order of ``feet``)."""
    links: dict[Any, Any] | None = None
    out = {}
    for foot in feet:
        _frame_id(robot, foot)
        if links is None:
            path = resolve_source(robot.source)[0]
            if path.suffix.lower() != ".urdf":
                raise ConfigurationError(
                    f"{robot.name}: foot_sphere_radius reads a URDF, got {path.name}"
                )
            links = {link.get("name"): link for link in ET.parse(path).getroot().iter("link")}
        if foot not in links:
            raise UnknownNameError(
                f"{robot.name}: {foot!r} is a frame but not a link of {path.name}"
            )
        out[foot] = _sphere_radius(robot, foot, links[foot])
    return out


def _sphere_radius(robot: Robot, foot: str, link: Any) -> float:
    """The radius of ``link``'s first collision sphere (:func:`foot_sphere_radius`)."""
    for collision in link.findall("collision"):
        sphere = collision.find("geometry/sphere")
        if sphere is None:
            continue
        origin = collision.find("origin")
        xyz = [
            float(a)
            for a in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()
        ]
        if any(xyz):
            raise ConfigurationError(
                f"{robot.name}: {foot}'s collision sphere is centred at {xyz}, not at the "
                "link's origin: the foot frame is not its centre"
            )
        return float(sphere.get("radius", "nan"))
    return 0.0
