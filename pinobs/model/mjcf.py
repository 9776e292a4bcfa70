"""MJCF files as MuJoCo compiles them, turned into a Pinocchio model and cross-checked.

Pinocchio's own MJCF parser misreads ordinary MuJoCo files (geom masses set
through ``<default>`` classes, ``settotalmass``, second body trees, armature).
With MuJoCo installed (``pip install pinobs[mujoco]``) the file is compiled
by MuJoCo and the Pinocchio model is built from the compiled ``mjModel``:

* one Pinocchio joint per MuJoCo joint, in MuJoCo's order (so ``v`` has
  MuJoCo's dof order): ``hinge`` → revolute, ``slide`` → prismatic (aligned
  ``RX``/``PY``/… when the axis is a positive unit axis, unaligned otherwise),
  ``ball`` → spherical, ``free`` → free-flyer;
* MuJoCo places a body at ``body_pos``/``body_quat`` in its parent and moves
  it by each of its joints in turn, about the joint's anchor ``jnt_pos``:
  ``X_body = X_parent · B · T(p₁) J₁(q₁) T(−p₁) · T(p₂) J₂(q₂) T(−p₂) ⋯`` (MuJoCo's
  ``mj_kinematics``), so joint ``i``'s placement is ``B · T(p₁)`` for the
  first and ``T(pᵢ − pᵢ₋₁)`` for the next ones, and the body sits at
  ``T(−p_k)`` after its last joint; a body without joints is welded to its
  parent's last joint;
* each body's inertia is ``body_mass`` at ``body_ipos`` with principal moments
  ``body_inertia`` along the axes ``body_iquat`` (in the body frame);
* ``dof_armature`` → ``model.armature`` (Pinocchio's CRBA adds it to the
  diagonal of ``M`` as ``mj_fullM`` does), ``dof_damping`` → ``model.damping``
  (viscous, used by default), ``dof_frictionloss`` → ``model.friction``
  (Pinocchio's smoothed Coulomb term approximates MuJoCo's dry-friction
  constraint), ``opt.gravity`` → ``model.gravity``;
* a limited hinge or slide joint's ``jnt_range`` (compiled, so in radians
  whatever ``<compiler angle>`` says) → ``lowerPositionLimit`` and
  ``upperPositionLimit``, shifted by ``qpos0`` as ``q`` is (below); joints
  without ``limited``/``range``, and ball and free joints (a cone is no box
  on the quaternion), keep Pinocchio's "no limit" (±1.8e308);
* the largest ``|τ|`` MuJoCo can apply to a hinge or slide dof →
  ``effortLimit``: the sum over the actuators driving that joint of
  ``|gear| ×`` the actuator's force bound (its ``forcerange`` when
  ``forcelimited``; for a motor-like actuator, fixed gain and no bias,
  ``|gain| × max |ctrlrange|`` (``max |actrange|`` with activation dynamics)),
  capped by the joint's ``actuatorfrcrange``.  Pinocchio's effort limit is
  symmetric, so an asymmetric range gives its larger magnitude.  A dof that
  no actuator drives, or that an actuator drives without a bound (position
  servos, tendon or site transmissions), keeps "no limit" unless
  ``actuatorfrcrange`` bounds it;
* ``<option><flag …="disable"/>``: ``gravity`` disabled → zero gravity,
  ``damper`` → no damping, ``frictionloss`` → no friction, ``limit`` → no
  position limits (``constraint`` disables both), ``clampctrl`` → ``ctrlrange``
  bounds no effort;
* ``gravcomp``: when every body with mass has ``gravcomp="1"`` (and no joint
  routes it through a clamped ``actuatorgravcomp``), the bodies are weightless
  and the model's gravity is zero; partial compensation cannot be written as a
  Pinocchio model and is named in a :class:`~pinobs.errors.ModelWarning`
  (pinobs' dynamics apply full gravity to those bodies).

Coordinates differ in three places, handled by :class:`MujocoMap`:

* a hinge or slide joint's Pinocchio ``q`` is MuJoCo's ``qpos − qpos0``
  (MuJoCo measures from the joint's ``ref``);
* quaternions: MuJoCo stores ``w, x, y, z``, Pinocchio ``x, y, z, w``;
* a free joint's linear velocity is in the world frame in MuJoCo and in the
  body frame in Pinocchio: ``qvel_lin = R(q) v_lin``, angular velocity in the
  body frame in both.  Hence ``M_pin = Jᵀ M_mj J`` with ``qvel = J v``.

Not modelled (a :class:`~pinobs.errors.ModelWarning` names them when
present): joint stiffness (springs), equality constraints, tendons, partial
gravity compensation; contacts.

An unnamed MuJoCo object is named after its type and index (``joint3``,
``body2``, ``geom0``), with ``_2``, ``_3``, … appended when the file uses that
name for another object of the type.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from pinobs.errors import ModelError, ModelWarning

__all__ = ["MASS_MATRIX_RTOL", "MujocoMap", "build_from_mujoco", "cross_check"]

#: Relative agreement required between Pinocchio's ``M(q)`` and ``mj_fullM``
#: (and between the total masses) when an MJCF model is loaded through MuJoCo.
MASS_MATRIX_RTOL = 1e-8

Vector = NDArray[np.float64]

_FREE, _BALL, _SLIDE, _HINGE = 0, 1, 2, 3  # mjtJoint


def _rotation(quat_wxyz: NDArray[Any]) -> Vector:
    """Rotation matrix of a MuJoCo quaternion ``(w, x, y, z)``."""
    w, x, y, z = (float(c) for c in quat_wxyz)
    return np.asarray(pin.Quaternion(w, x, y, z).normalized().toRotationMatrix(), dtype=float)


def _axis_joint(kind: int, axis: NDArray[Any]) -> Any:
    """Revolute (hinge) or prismatic (slide) joint about ``axis`` (aligned when possible)."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    for i, name in enumerate("XYZ"):
        if np.allclose(axis, np.eye(3)[i], atol=1e-15):
            return getattr(pin, f"JointModel{'R' if kind == _HINGE else 'P'}{name}")()
    if kind == _HINGE:
        return pin.JointModelRevoluteUnaligned(axis)
    return pin.JointModelPrismaticUnaligned(axis)


@dataclass(frozen=True)
class MujocoMap:
    """Where each MuJoCo joint sits in Pinocchio's ``q``/``v`` (module docstring).

    Attributes:
        kinds: MuJoCo joint type per joint (0 free, 1 ball, 2 slide, 3 hinge).
        qposadr: first index of each joint in MuJoCo's ``qpos``.
        dofadr: first index of each joint in MuJoCo's ``qvel`` (= Pinocchio's ``v``).
        idx_q: first index of each joint in Pinocchio's ``q``.
        qpos0: MuJoCo's reference configuration ``qpos0``.
        nv: number of velocities (MuJoCo's and Pinocchio's).
    """

    kinds: tuple[int, ...]
    qposadr: tuple[int, ...]
    dofadr: tuple[int, ...]
    idx_q: tuple[int, ...]
    qpos0: Vector
    nv: int

    def q_from_qpos(self, qpos: NDArray[Any]) -> Vector:
        """Pinocchio ``q`` of a MuJoCo ``qpos``."""
        q = np.zeros(sum({0: 7, 1: 4}.get(k, 1) for k in self.kinds))
        for k, a, iq in zip(self.kinds, self.qposadr, self.idx_q, strict=True):
            if k == _FREE:
                q[iq : iq + 3] = qpos[a : a + 3]
                q[iq + 3 : iq + 6] = qpos[a + 4 : a + 7]  # x, y, z
                q[iq + 6] = qpos[a + 3]  # w
            elif k == _BALL:
                q[iq : iq + 3] = qpos[a + 1 : a + 4]
                q[iq + 3] = qpos[a]
            else:
                q[iq] = qpos[a] - self.qpos0[a]
        return q

    def qpos_from_q(self, q: NDArray[Any]) -> Vector:
        """MuJoCo ``qpos`` of a Pinocchio ``q``."""
        qpos = self.qpos0.copy()
        for k, a, iq in zip(self.kinds, self.qposadr, self.idx_q, strict=True):
            if k == _FREE:
                qpos[a : a + 3] = q[iq : iq + 3]
                qpos[a + 3] = q[iq + 6]
                qpos[a + 4 : a + 7] = q[iq + 3 : iq + 6]
            elif k == _BALL:
                qpos[a] = q[iq + 3]
                qpos[a + 1 : a + 4] = q[iq : iq + 3]
            else:
                qpos[a] = q[iq] + self.qpos0[a]
        return qpos

    def velocity_jacobian(self, q: NDArray[Any]) -> Vector:
        """``J`` with MuJoCo's ``qvel = J v`` (identity but for free joints' linear part)."""
        jac = np.eye(self.nv)
        for k, d, iq in zip(self.kinds, self.dofadr, self.idx_q, strict=True):
            if k == _FREE:
                x, y, z, w = q[iq + 3 : iq + 7]
                jac[d : d + 3, d : d + 3] = pin.Quaternion(w, x, y, z).toRotationMatrix()
        return jac

    def v_from_qvel(self, q: NDArray[Any], qvel: NDArray[Any]) -> Vector:
        """Pinocchio ``v`` of a MuJoCo ``qvel`` at Pinocchio configuration ``q``."""
        return np.linalg.solve(self.velocity_jacobian(q), qvel)


def _unique_names(mj: Any, obj: Any, count: int, prefix: str) -> list[str]:
    """Names of MuJoCo's objects of one type; an unnamed one is ``prefix<index>``, with
    ``_2``, ``_3``, … appended while another object of the type has that name."""
    import mujoco

    given = [mujoco.mj_id2name(mj, obj, i) or "" for i in range(count)]
    taken = {n for n in given if n}
    names = []
    for i, n in enumerate(given):
        if not n:
            n = base = f"{prefix}{i}"
            k = 1
            while n in taken:
                k += 1
                n = f"{base}_{k}"
            taken.add(n)
        names.append(n)
    return names


def _disabled(mj: Any, *flags: str) -> bool:
    """Whether any of MuJoCo's ``<option><flag>`` bits ``flags`` (``"gravity"``, …) is disabled."""
    import mujoco

    bits = 0
    for f in flags:
        bits |= int(getattr(mujoco.mjtDisableBit, f"mjDSBL_{f.upper()}"))
    return bool(int(mj.opt.disableflags) & bits)


def _actuator_force_bound(mj: Any, a: int) -> float:
    """The largest ``|actuator_force|`` actuator ``a`` can produce [N or N·m], ``inf`` if unbounded."""
    import mujoco

    bound = np.inf
    if mj.actuator_forcelimited[a]:
        bound = float(np.abs(mj.actuator_forcerange[a]).max())
    motor_like = (
        int(mj.actuator_gaintype[a]) == mujoco.mjtGain.mjGAIN_FIXED
        and int(mj.actuator_biastype[a]) == mujoco.mjtBias.mjBIAS_NONE
    )
    if motor_like:  # force = gain · input
        gain = abs(float(mj.actuator_gainprm[a, 0]))
        if int(mj.actuator_dyntype[a]) == mujoco.mjtDyn.mjDYN_NONE:  # input = ctrl
            if mj.actuator_ctrllimited[a] and not _disabled(mj, "clampctrl"):
                bound = min(bound, gain * float(np.abs(mj.actuator_ctrlrange[a]).max()))
        elif mj.actuator_actlimited[a]:  # input = act, clamped to actrange
            bound = min(bound, gain * float(np.abs(mj.actuator_actrange[a]).max()))
    return bound


def _effort_limits(mj: Any) -> Vector:
    """Per MuJoCo dof, the largest ``|τ|`` its actuators can apply (module docstring); ``inf``
    where nothing bounds it."""
    import mujoco

    driven = np.zeros(mj.nv, dtype=bool)
    effort = np.zeros(mj.nv)
    unbounded = np.zeros(mj.nv, dtype=bool)
    joint_trn = (mujoco.mjtTrn.mjTRN_JOINT, mujoco.mjtTrn.mjTRN_JOINTINPARENT)
    for a in range(mj.nu):
        if int(mj.actuator_trntype[a]) not in joint_trn:  # tendon, site, body: every dof it
            unbounded[:] = True  # may move is unbounded (moment arms depend on q)
            continue
        j = int(mj.actuator_trnid[a, 0])
        if int(mj.jnt_type[j]) not in (_HINGE, _SLIDE):
            continue
        d, gear = int(mj.jnt_dofadr[j]), abs(float(mj.actuator_gear[a, 0]))
        driven[d] = True
        effort[d] += gear * _actuator_force_bound(mj, a) if gear else 0.0
    effort = np.where(driven & ~unbounded, effort, np.inf)
    for j in range(mj.njnt):
        if int(mj.jnt_type[j]) in (_HINGE, _SLIDE) and mj.jnt_actfrclimited[j]:
            d = int(mj.jnt_dofadr[j])
            effort[d] = min(effort[d], float(np.abs(mj.jnt_actfrcrange[j]).max()))
    return effort


def _gravity(mj: Any, body_names: list[str]) -> tuple[Vector, str | None]:
    """MuJoCo's gravity as Pinocchio can have it, and what of ``gravcomp`` it cannot (module
    docstring)."""
    gravity = np.asarray(mj.opt.gravity, dtype=float).copy()
    if _disabled(mj, "gravity") or not np.any(gravity):
        return np.zeros(3), None  # MuJoCo applies no gravity compensation either
    comp = np.asarray(getattr(mj, "body_gravcomp", np.zeros(mj.nbody)), dtype=float)
    massive = np.asarray(mj.body_mass, dtype=float) > 0
    if not np.any(comp[massive]):
        return gravity, None
    routed = getattr(mj, "jnt_actgravcomp", np.zeros(mj.njnt, dtype=bool))
    clamped = np.any(np.asarray(routed, dtype=bool) & np.asarray(mj.jnt_actfrclimited, dtype=bool))
    if np.all(comp[massive] == 1.0) and not clamped:
        return np.zeros(3), None  # every weight compensated: the bodies are weightless
    held = [f"{body_names[b]} ({comp[b]:g})" for b in np.flatnonzero(massive & (comp != 0.0))]
    return gravity, (
        f"gravity compensation (gravcomp) of {', '.join(held)}: those bodies get their full "
        "weight (only gravcomp=1 on every body with mass, zero gravity, can be modelled)"
    )


def _geometry(
    mj: Any, where: dict[int, tuple[int, pin.SE3]], names: list[str]
) -> pin.GeometryModel:
    """MuJoCo's primitive geoms (box, sphere, capsule, cylinder, ellipsoid) as visual geometry.

    A geom sits at ``geom_pos``/``geom_quat`` in its body, so at
    ``X_body · X_geom`` in its body's joint frame; ``size`` holds half-sizes
    (MuJoCo) where coal takes full lengths.  Planes, meshes and height fields
    are left out.
    """
    import coal  # ships with Pinocchio
    import mujoco

    geom = pin.GeometryModel()
    for g in range(mj.ngeom):
        kind, size = int(mj.geom_type[g]), np.asarray(mj.geom_size[g], dtype=float)
        shape: Any
        if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            shape = coal.Sphere(size[0])
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            shape = coal.Capsule(size[0], 2.0 * size[1])
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            shape = coal.Cylinder(size[0], 2.0 * size[1])
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            shape = coal.Box(*(2.0 * size))
        elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
            shape = coal.Ellipsoid(*size)
        else:
            continue
        joint, body_place = where[int(mj.geom_bodyid[g])]
        place = body_place * pin.SE3(_rotation(mj.geom_quat[g]), mj.geom_pos[g].copy())
        obj = pin.GeometryObject(names[g], joint, place, shape)
        obj.meshColor = np.asarray(mj.geom_rgba[g], dtype=float).copy()
        geom.addGeometryObject(obj)
    return geom


def build_from_mujoco(path: Path) -> tuple[pin.Model, Any, MujocoMap, pin.GeometryModel]:
    """Compile ``path`` with MuJoCo and build the Pinocchio model (module docstring).

    Returns:
        ``(model, mj_model, map, visual geometry)``.

    Raises:
        ImportError: MuJoCo is not installed.
        ValueError: MuJoCo cannot compile the file (its message).
    """
    import mujoco  # optional extra pinobs[mujoco]

    mj = mujoco.MjModel.from_xml_path(str(path))
    model = pin.Model()
    model.name = mj.names[: mj.names.index(b"\0")].decode() if mj.names else path.stem
    joint_names = _unique_names(mj, mujoco.mjtObj.mjOBJ_JOINT, mj.njnt, "joint")
    body_names = _unique_names(mj, mujoco.mjtObj.mjOBJ_BODY, mj.nbody, "body")
    gravity, gravcomp = _gravity(mj, body_names)
    model.gravity = pin.Motion(gravity, np.zeros(3))

    where, mapping = _add_bodies(model, mj, joint_names, body_names)
    if model.nv != mj.nv:  # pragma: no cover - every joint type is mapped above
        raise ModelError(f"built nv = {model.nv} from {path}, MuJoCo has nv = {mj.nv}")
    # MuJoCo's dofs follow its joint order, as Pinocchio's velocity indices do
    model.armature = np.asarray(mj.dof_armature, dtype=float).copy()
    model.damping = np.asarray(mj.dof_damping, dtype=float) * (not _disabled(mj, "damper"))
    model.friction = np.asarray(mj.dof_frictionloss, dtype=float) * (
        not _disabled(mj, "frictionloss", "constraint")
    )
    _set_limits(model, mj, list(mapping.idx_q))
    _warn_left_out(path, mj, joint_names, gravcomp)
    geom_names = _unique_names(mj, mujoco.mjtObj.mjOBJ_GEOM, mj.ngeom, "geom")
    return model, mj, mapping, _geometry(mj, where, geom_names)


def _add_bodies(
    model: pin.Model, mj: Any, joint_names: list[str], body_names: list[str]
) -> tuple[dict[int, tuple[int, pin.SE3]], MujocoMap]:
    """Add MuJoCo's bodies and joints to ``model`` (module docstring), in place.

    Returns:
        per MuJoCo body its Pinocchio joint and the placement of the body frame in that
        joint's frame, and the map of MuJoCo's ``qpos``/``qvel`` to Pinocchio's.
    """
    where: dict[int, tuple[int, pin.SE3]] = {0: (0, pin.SE3.Identity())}
    kinds, qposadr, dofadr, idx_q = [], [], [], []
    frame_of_joint: dict[int, int] = {0: 0}
    for b in range(1, mj.nbody):
        parent_joint, parent_place = where[int(mj.body_parentid[b])]
        place = parent_place * pin.SE3(_rotation(mj.body_quat[b]), mj.body_pos[b].copy())
        joint = parent_joint
        anchor = np.zeros(3)
        for j in range(int(mj.body_jntadr[b]), int(mj.body_jntadr[b]) + int(mj.body_jntnum[b])):
            kind = int(mj.jnt_type[j])
            pos = mj.jnt_pos[j].copy() if kind != _FREE else np.zeros(3)
            jm: Any
            if kind == _FREE:
                jm = pin.JointModelFreeFlyer()
            elif kind == _BALL:
                jm = pin.JointModelSpherical()
            else:
                jm = _axis_joint(kind, mj.jnt_axis[j])
            if kind == _FREE:  # qpos of a free joint is the world pose of the body
                joint_place = pin.SE3.Identity()
            else:
                joint_place = place * pin.SE3(np.eye(3), pos - anchor)
            joint = model.addJoint(joint, jm, joint_place, joint_names[j])
            kinds.append(kind)
            qposadr.append(int(mj.jnt_qposadr[j]))
            dofadr.append(int(mj.jnt_dofadr[j]))
            idx_q.append(int(model.joints[joint].idx_q))
            frame_of_joint[joint] = model.addJointFrame(joint, -1)
            place, anchor = pin.SE3.Identity(), pos
        place = place * pin.SE3(np.eye(3), -anchor)
        where[b] = (joint, place)
        rot = _rotation(mj.body_iquat[b])
        inertia = pin.Inertia(
            float(mj.body_mass[b]),
            mj.body_ipos[b].copy(),
            rot @ np.diag(mj.body_inertia[b]) @ rot.T,
        )
        model.appendBodyToJoint(joint, inertia, place)
        model.addBodyFrame(body_names[b], joint, place, frame_of_joint[joint])
    mapping = MujocoMap(
        tuple(kinds),
        tuple(qposadr),
        tuple(dofadr),
        tuple(idx_q),
        np.array(mj.qpos0, dtype=float),
        int(mj.nv),
    )
    return where, mapping


def _warn_left_out(path: Path, mj: Any, joint_names: list[str], gravcomp: str | None) -> None:
    """One :class:`~pinobs.errors.ModelWarning` naming what of MuJoCo's model pinobs'
    dynamics leave out (springs, equality constraints, tendons, gravity compensation)."""
    missing = []
    if np.any(mj.jnt_stiffness) and not _disabled(mj, "spring"):
        stiff = [joint_names[int(j)] for j in np.flatnonzero(mj.jnt_stiffness)]
        missing.append(f"joint stiffness (springs) of {', '.join(stiff)}")
    if mj.neq and not _disabled(mj, "equality", "constraint"):
        missing.append(f"{mj.neq} equality constraint(s)")
    if mj.ntendon:
        missing.append(f"{mj.ntendon} tendon(s)")
    if gravcomp is not None:
        missing.append(gravcomp)
    if missing:
        warnings.warn(
            f"{path}: pinobs' dynamics leave out MuJoCo's " + "; ".join(missing),
            ModelWarning,
            stacklevel=4,
        )


def _set_limits(model: pin.Model, mj: Any, idx_q: list[int]) -> None:
    """Position and effort limits of hinge and slide joints (module docstring), in place."""
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    effort = np.array(model.effortLimit, dtype=float)
    limits_on = not _disabled(mj, "limit", "constraint")
    bound = _effort_limits(mj)
    for j in range(mj.njnt):
        if int(mj.jnt_type[j]) not in (_HINGE, _SLIDE):
            continue
        iq, d = idx_q[j], int(mj.jnt_dofadr[j])
        if limits_on and mj.jnt_limited[j]:  # MuJoCo limits qpos; Pinocchio's q = qpos - qpos0
            qpos0 = float(mj.qpos0[int(mj.jnt_qposadr[j])])
            lower[iq], upper[iq] = (float(x) - qpos0 for x in mj.jnt_range[j])
        if np.isfinite(bound[d]):
            effort[d] = bound[d]
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper
    model.effortLimit = effort
    if hasattr(model, "lowerEffortLimit"):  # Pinocchio ≥ 4: effortLimit is the upper one
        model.lowerEffortLimit = -effort


def _full_mass_matrix(mujoco: Any, mj: Any, data: Any, out: Vector) -> None:
    """``mj_fullM`` into ``out``: MuJoCo ≥ 3.3 takes ``(m, d, dst)``, older ones ``(m, dst, d.qM)``."""
    if hasattr(data, "qM"):
        mujoco.mj_fullM(mj, out, data.qM)
    else:
        mujoco.mj_fullM(mj, data, out)


def cross_check(
    model: pin.Model, mj: Any, mapping: MujocoMap, *, samples: int = 20, seed: int = 0
) -> float:
    """Compare total mass and ``M(q)`` with MuJoCo's ``mj_fullM`` at random configurations.

    Configurations are ``neutral ⊕ ξ``, ξ uniform in ``[-π, π]^nv`` (seeded).

    Returns:
        The largest relative difference ``|M_pin − Jᵀ M_mj J|_max / |M_mj|_max`` seen.

    Raises:
        ModelError: the total masses or a mass matrix differ by more than
            :data:`MASS_MATRIX_RTOL` (relative), naming the body and both values.
    """
    import mujoco

    total_mj = float(np.sum(mj.body_mass))
    total_pin = float(sum(i.mass for i in model.inertias))
    if abs(total_pin - total_mj) > MASS_MATRIX_RTOL * max(total_mj, 1e-300):
        raise ModelError(f"total mass: Pinocchio {total_pin!r} kg, MuJoCo {total_mj!r} kg")
    if mj.nv == 0:
        return 0.0
    data = mujoco.MjData(mj)
    pdata = model.createData()
    rng = np.random.default_rng(seed)
    full = np.zeros((mj.nv, mj.nv))
    worst = 0.0
    for _ in range(samples):
        q = pin.integrate(model, pin.neutral(model), rng.uniform(-np.pi, np.pi, model.nv))
        data.qpos[:] = mapping.qpos_from_q(q)
        mujoco.mj_forward(mj, data)
        _full_mass_matrix(mujoco, mj, data, full)
        jac = mapping.velocity_jacobian(q)
        m_mj = jac.T @ full @ jac
        m_pin = np.array(pin.crba(model, pdata, q))
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        diff = np.abs(m_pin - m_mj)
        rel = float(diff.max() / np.abs(m_mj).max())
        worst = max(worst, rel)
        if rel > MASS_MATRIX_RTOL:
            i, k = np.unravel_index(int(np.argmax(diff)), diff.shape)
            dof = int(i)
            body = mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_BODY, int(mj.dof_bodyid[dof]))
            raise ModelError(
                f"M(q)[{i}, {k}] (dof of body {body!r}) differs: Pinocchio {m_pin[i, k]!r}, "
                f"MuJoCo mj_fullM {m_mj[i, k]!r} (relative {rel:.3g} > {MASS_MATRIX_RTOL:g}) "
                f"at q = {np.round(q, 4).tolist()}"
            )
    return worst
