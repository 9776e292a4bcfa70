"""Leg kinematics of a floating-base robot: foot positions in the base frame, and their Jacobians.

The contact-aided invariant EKF (:mod:`pinobs.observers.inekf`) measures each
foot in contact through forward kinematics of the measured joint angles::

    h_j(q) = position of foot frame j in the base frame   (Hartley et al.'s h_p(α))
    J_j(q) = ∂h_j/∂v_joints,  a 3 × (nv − 6) matrix

The base frame is the frame of the free-flyer root joint (Pinocchio's
``q[0:7]``, the frame whose body velocity is ``v[0:6]``), or, with
``imu_frame``, the IMU's frame.  Everything is computed with the root placed at
the identity, so the world-aligned frame Jacobian of Pinocchio *is* the
root-frame one: ``J_f`` (linear rows) and ``J_fω`` (angular rows) are the joint
columns of ``getFrameJacobian(..., LOCAL_WORLD_ALIGNED)`` at
``q = (0, 0, 0, 0, 0, 0, 1, q_joints)``, and ``p_f``, ``R_f`` the foot's placement.
For revolute and prismatic joints ``J_f = ∂p_f/∂q_joints``; for continuous
joints it is with respect to the joint's velocity coordinate (its angle).

The IMU frame's placement in the root joint's frame is ``(R_bi, r_bi)``
(:meth:`FootKinematics.imu_motion`).  The feet in it::

    h_j = R_biᵀ (p_f − r_bi),      R_j = R_biᵀ R_f                                  (K1)
    J_j = R_biᵀ (J_f − J_i + (p_f − r_bi)^ J_iω),   J_jω = R_biᵀ (J_fω − J_iω)       (K2)

``J_i``, ``J_iω`` the IMU frame's own Jacobians (its origin's velocity and its angular
velocity relative to the root, in the root frame, per joint velocity).  (K2) is the time
derivative of (K1): ``ḣ_j = R_biᵀ (ṗ_f − ṙ_bi) + Ṙ_biᵀ (p_f − r_bi)`` with
``Ṙ_bi = (J_iω q̇)^ R_bi``, and ``−ω × d = d^ ω``.

* A frame fixed to the root joint (go1's ``imu_link``, 7 cm from the root): ``J_i = J_iω = 0``
  and ``(R_bi, r_bi)`` is a constant, :attr:`FootKinematics.imu_placement`; (K1)-(K2) are
  then ``R_biᵀ (p_f − r_bi)`` and ``R_biᵀ J_f``, computed as such (the same arithmetic as
  before moving frames were supported, so the same bits).
* A frame that moves with other joints (TALOS's ``imu_link``, on the torso after
  ``torso_1_joint`` and ``torso_2_joint``): ``(R_bi, r_bi)``, ``J_i``, ``J_iω`` at each
  ``q_joints`` (:attr:`FootKinematics.imu_moves`), and the feet's Jacobians (K2) have
  columns for the torso joints as well as the leg's: a foot measured in the IMU's frame
  moves when the torso turns.

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
        imu_frame: a frame of the model (the IMU's) to express the feet in, instead of the
            root joint's frame: fixed to the root joint, or moving with other joints
            (module docstring).

    Attributes:
        feet: the foot frame names, in the given order.
        nq_joints: number of joint coordinates after the free-flyer (``nq − 7``).
        nv_joints: number of joint velocities after the free-flyer (``nv − 6``).
        imu_placement: ``(R_bi, r_bi)``: rotation and position [m] of the frame the feet are
            expressed in, in the root joint's frame (identity and zero without ``imu_frame``);
            of a moving frame, at the model's neutral joint angles (:meth:`imu_motion` gives
            it at any).
        imu_moves: whether ``imu_frame`` moves relative to the root joint (a joint other than
            the root lies between them).

    Raises:
        UnsupportedRobotError: the robot's first joint is not a free-flyer.
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
        #: :meth:`preload`'s rows: each row's ``(h, R, J, J_ω)`` (views of one block) by its
        #: angles' bytes
        self._preloaded: dict[bytes, tuple[Vector, ...]] = {}
        self.robot_name = robot.name
        self.imu_frame = imu_frame
        self.imu_placement: tuple[Vector, Vector] = (np.eye(3), np.zeros(3))
        self.imu_moves = False
        #: the IMU frame's index when it moves (K1-K2 at each q), else ``None``
        self._imu_id: int | None = None
        if imu_frame is not None:
            fid = _frame_id(robot, imu_frame)
            self.imu_moves = model.frames[fid].parentJoint != 1
            if self.imu_moves:
                self._imu_id = fid
                data = model.createData()  # the placement at the neutral angles
                pin.framesForwardKinematics(model, data, self._q)
                placement = data.oMf[fid]
            else:
                placement = model.frames[fid].placement  # in the root joint's frame
            self.imu_placement = (
                np.array(placement.rotation, dtype=float),
                np.array(placement.translation, dtype=float),
            )
        for a in self.imu_placement:
            a.setflags(write=False)
        self._to_imu = None if imu_frame is None or self.imu_moves else self.imu_placement
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

    def imu_motion(self, q_joints: ArrayLike) -> tuple[Vector, Vector, Vector]:
        """``(R_bi, r_bi, J_bi)``: the IMU frame's rotation and position [m] in the root joint's
        frame at ``q_joints``, and its Jacobian ``(6, nv_joints)`` ``[J_i; J_iω]`` (its origin's
        velocity [m/rad] and its angular velocity [rad/rad] relative to the root, in the root
        frame, per joint velocity; module docstring).  A frame fixed to the root (or none):
        :attr:`imu_placement` and zeros."""
        if self._imu_id is None:
            R_bi, r_bi = self.imu_placement
            return R_bi.copy(), r_bi.copy(), np.zeros((6, self.nv_joints))
        _, last = self._recall("imu_motion", q_joints)  # (the feet's, at the same angles)
        if last is not None:
            return last[0], last[1], last[2]
        self._set(q_joints)
        pin.computeJointJacobians(self._model, self._data, self._q)
        return self._imu_now()

    def _imu_now(self) -> tuple[Vector, Vector, Vector]:
        """:meth:`imu_motion` after ``computeJointJacobians`` at ``self._q``, kept for
        :meth:`_recall` (``getFrameJacobian`` sets the IMU frame's ``oMf``)."""
        full = pin.getFrameJacobian(self._model, self._data, self._imu_id, _LOCAL_WORLD_ALIGNED)
        oMi = self._data.oMf[self._imu_id]
        out = (np.array(oMi.rotation), np.array(oMi.translation), full[:, 6:].copy())
        return self._keep("imu_motion", self._q[7:].tobytes(), out)  # type: ignore[return-value]

    def _in_moving_imu(
        self, h: Vector, rot: Vector | None, lin: Vector, ang: Vector | None
    ) -> tuple[Vector, ...]:
        """The feet's root-frame ``p_f, R_f, J_f, J_fω`` in the moving IMU frame, (K1)-(K2),
        after ``computeJointJacobians`` at the same angles (``rot``, ``ang``: ``None``, not
        computed)."""
        R_bi, r_bi, J_bi = self._imu_now()
        J_i, J_iw = J_bi[:3], J_bi[3:]
        d = h - r_bi  # p_f − r_bi, (K, 3)
        skew = np.zeros((len(d), 3, 3))  # (K2)'s (p_f − r_bi)^
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -d[:, 2], d[:, 1], -d[:, 0]
        skew -= skew.transpose(0, 2, 1)
        out = [d @ R_bi, None, R_bi.T @ (lin - J_i + skew @ J_iw), None]
        if rot is not None and ang is not None:
            out[1], out[3] = R_bi.T @ rot, R_bi.T @ (ang - J_iw)
        return tuple(out)  # type: ignore[arg-type]

    def positions(self, q_joints: ArrayLike) -> Vector:
        """``h_j(q)`` for every foot, shape ``(len(feet), 3)`` [m], in the base (or IMU) frame."""
        self._set(q_joints)
        pin.framesForwardKinematics(self._model, self._data, self._q)
        h = np.array([self._data.oMf[i].translation for i in self._ids])
        to_imu = self._to_imu
        if self._imu_id is not None:  # a moving frame: its placement at these angles
            oMi = self._data.oMf[self._imu_id]
            to_imu = (oMi.rotation, oMi.translation)
        if to_imu is not None:
            R_bi, r_bi = to_imu
            h = (h - r_bi) @ R_bi  # (K1), rows: R_biᵀ (h − r_bi)
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
        h: Vector = np.empty((len(self._ids), 3))
        jac: Vector = np.empty((len(self._ids), 3, self.nv_joints))
        for k, fid in enumerate(self._ids):
            h[k] = data.oMf[fid].translation
            full = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            jac[k] = full[:3, 6:]
        if self._imu_id is not None:
            h, _, jac, _ = self._in_moving_imu(h, None, jac, None)
        elif self._to_imu is not None:
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
            return self._kept(key, row)
        self._set(q_joints)
        full, placement = self._feet_at_q()
        if self._imu_id is not None:  # a moving IMU: its Jacobians at these angles, (K1)-(K2)
            h, rot = placement[:, :3, 3], placement[:, :3, :3]
            return self._kept(key, self._in_moving_imu(h, rot, full[:, :3, 6:], full[:, 3:, 6:]))
        return self._kept(key, self._in_imu_frame(full, placement))

    def preload(self, q_rows: ArrayLike) -> None:
        """:meth:`shared_placements_and_jacobians` of each row of ``q_rows`` ``(M, nq_joints)``,
        computed now and kept (replacing the rows kept before) for the calls with the same
        angles' bytes: the same values (the same Pinocchio calls, then the same elementwise
        operations on the whole block at once, or per row where the IMU's axes are not the
        base's), without a call's NumPy work each sample.  A log's runner
        (:func:`pinobs.io.legged_run.legged_run`) preloads its rows block by block.  An IMU
        on a moving link keeps nothing (its Jacobians are taken at each call's angles).

        Raises:
            DimensionError: ``q_rows`` not of shape ``(M, nq_joints)``.
        """
        rows = np.ascontiguousarray(q_rows, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != self.nq_joints:
            raise DimensionError(
                f"q_rows must have shape (M, {self.nq_joints}) (joint angles per row), got "
                f"shape {rows.shape}"
            )
        if self._imu_id is not None:  # (a moving IMU's Jacobians: row by row, at each call)
            return
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
        # each row's views (C-contiguous, the kernels' signatures), made once for the block
        views = zip(*(list(np.ascontiguousarray(a)) for a in block), strict=True)
        self._preloaded = {angles.tobytes(): row for angles, row in zip(rows, views, strict=True)}

    def _feet_at_q(self) -> tuple[Vector, Vector]:
        """The feet's frame Jacobians ``(K, 6, nv)`` (``LOCAL_WORLD_ALIGNED``) and placements
        ``(K, 4, 4)`` in the world (the root at the identity) at ``self._q``."""
        model, data = self._model, self._data
        pin.computeJointJacobians(model, data, self._q)
        ids = self._ids  # each foot's Jacobian, then its oMf (set by getFrameJacobian)
        full = np.array([pin.getFrameJacobian(model, data, f, _LOCAL_WORLD_ALIGNED) for f in ids])
        return full, np.array([m.homogeneous for m in self._foot_oMf])

    def _in_imu_frame(self, full: Vector, placement: Vector) -> tuple[Vector, ...]:
        """``(h, R, J, J_ω)`` from :meth:`_feet_at_q`'s arrays, in the base (or a fixed IMU)
        frame; with the IMU's axes the base's, elementwise (a block ``(M, K, …)`` too)."""
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
