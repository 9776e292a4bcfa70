"""TALOS in MuJoCo as the truth for base estimation: standing, swaying and stepping.

The robot (:func:`talos_mujoco_spec`), its sensors, noise and columns are those of
:mod:`pinobs.simulation.legged` (its docstring); the controller is its joint PD law::

    τ = τ_ff + K_p (q_ref − q) + K_d (q̇_ref − q̇)     (no torque limit)

around a reference ``q_ref`` (motions below) with a gravity feed-forward ``τ_ff``.

``"step"``: quasi-static walking (a scheme chosen for being simple and stable, not a
humanoid walking controller from the literature), a step every ``STEP_SHIFT + STEP_SWING`` s (:class:`_Steps`).
Each step first moves the base (minimum-jerk, ``STEP_SHIFT`` s) until the robot's centre of
mass is over the centre of the sole that will carry it (the CoM's horizontal offset from the
base taken at the half-sitting stance), then swings the other foot (``STEP_SWING`` s) to
``STEP_LENGTH`` ahead of the stance foot along a raised cosine ``STEP_LIFT`` high, flat;
the right foot first.  The base stays level at its standing height.  ``q_ref`` is the
inverse kinematics of the soles' targets in the base frame with flat feet (:func:`_flat_feet`:
per leg, hip roll ``r``, hip pitch ``p`` and knee ``k`` solved by Newton's method through
:class:`pinobs.model.FootKinematics`; ankle pitch ``−(p + k)`` and ankle roll ``−r`` keep the
sole parallel to the base; hip yaw 0), then the ankles of the standing feet turned against
the base's tilt (:func:`_level`, the balance loop, reading MuJoCo's true base orientation as
a robot reads its IMU; without it the stance leg's compliance lets the CoM drift 4 cm
towards the swinging side in a 1 s swing and TALOS falls at the second step)::

    ankle pitch += w_j LEVEL_GAIN pitch,   ankle roll += w_j LEVEL_GAIN roll      (stance j)

and the legs' feed-forward is the static one::

    τ_ff = g(q_ref) − Σ_j w_j m g J_jᵀ e_z        (joint rows; w_left + w_right = 1)

``g`` the generalized gravity (the base at the identity), ``J_j`` sole ``j``'s Jacobian
(:class:`~pinobs.model.FootKinematics`), ``w_j`` the share of the weight on sole ``j``: 0 on
the swinging foot, while shifting the CoM's lateral position between the soles.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.model import FootKinematics, Robot, load
from pinobs.model.loading import resolve_source
from pinobs.simulation.legged import (
    SETTLE,
    LeggedNoise,
    LeggedRun,
    Machine,
    add_imu_and_floor,
    check_arguments,
    record_run,
)

__all__ = [
    "HUMANOID_MOTIONS",
    "STEP_LENGTH",
    "TALOS_FEET",
    "TALOS_STANCE",
    "simulate_humanoid",
    "talos_mujoco_spec",
]

Vector = NDArray[np.floating[Any]]

#: The motions :func:`simulate_humanoid` can make.
HUMANOID_MOTIONS = ("stand", "sway", "step")
#: TALOS's sole frames (left, right), in Pinocchio's joint order.
TALOS_FEET = ("left_sole_link", "right_sole_link")
_TALOS_LEG = (0.0, 0.0, -0.411354, 0.859395, -0.448041, -0.001708)  # half-sitting [rad]
_TALOS_ARM = (0.25847, 0.173046, -0.0002, -0.525366, 0.0, 0.0, 0.1, -0.005)
#: TALOS's half-sitting configuration (its SRDF's), joints in Pinocchio's order [rad].
TALOS_STANCE = (
    _TALOS_LEG
    + _TALOS_LEG
    + (0.0, 0.006761)
    + _TALOS_ARM
    + tuple(-a if i < 3 else a for i, a in enumerate(_TALOS_ARM))
    + (0.0, 0.0)
)
TALOS_KP, TALOS_KD = 2000.0, 20.0  # [N·m/rad], [N·m·s/rad]
SOLE = (0.1, 0.065, 0.01)  # half-sizes of TALOS's sole box [m]
STEP_LENGTH = 0.06  # [m], the swing foot lands this far ahead of the stance foot
STEP_SHIFT, STEP_SWING = 1.5, 1.0  # [s], moving the CoM over the stance sole; the swing
STEP_LIFT = 0.04  # [m], the swing foot's highest point
#: [rad/rad], the standing ankles' turn per radian of the base's tilt (0.5: TALOS falls at
#: 4.8 s; a rate term, 0.1 s × the base's angular velocity, made the soles chatter)
LEVEL_GAIN = 1.0
#: d q_leg / d (hip roll, hip pitch, knee): the sole stays parallel to the base (hip yaw 0).
_FLAT = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, -1, -1], [-1, 0, 0]], dtype=float)


def _smooth(u: float) -> float:
    """Minimum-jerk ramp 0 → 1 on ``u`` ∈ [0, 1]: ``10u³ − 15u⁴ + 6u⁵``."""
    u = min(max(u, 0.0), 1.0)
    return u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)


class _Steps:
    """The ``"step"`` motion's plan (module docstring): soles' targets in the base frame and
    the weight shares at ``t`` [s].  The world here is the base's standing pose at ``t = 0``.

    Args:
        soles: the soles in the base frame at the stance, (2, 3) [m] (left, right).
        com: the centre of mass's horizontal offset from the base at the stance, (2,) [m].
    """

    def __init__(self, soles: Vector, com: Vector) -> None:
        self.soles = soles
        self.com = com
        self.period = STEP_SHIFT + STEP_SWING

    def _over(self, i: int) -> Vector:
        """The base's horizontal position with the CoM over step ``i``'s stance sole."""
        stance = i % 2  # step 0: the left foot (0) stands, the right one swings
        return self.soles[stance, :2] + (i * STEP_LENGTH, 0.0) - self.com

    def at(self, t: float) -> tuple[Vector, Vector]:
        """``(targets, shares)``: the soles in the base frame (2, 3) [m], the weight on each."""
        if t <= 0.0:
            return self.soles.copy(), np.array([0.5, 0.5])
        i = int(t // self.period)
        tau = t - i * self.period
        stance, swing = i % 2, 1 - i % 2
        feet = self.soles.copy()  # world: before step i, stance at i L, swing at (i − 1) L
        feet[stance, 0] += i * STEP_LENGTH
        feet[swing, 0] += max(i - 1, 0) * STEP_LENGTH
        start: Vector = self._over(i - 1) if i > 0 else np.zeros(2)
        if tau < STEP_SHIFT:
            base: Vector = start + (self._over(i) - start) * _smooth(tau / STEP_SHIFT)
            y_left, y_right = feet[0, 1], feet[1, 1]
            left = min(max((base[1] + self.com[1] - y_right) / (y_left - y_right), 0.0), 1.0)
            shares: Vector = np.array([left, 1.0 - left])
        else:
            base = self._over(i)
            u = (tau - STEP_SHIFT) / STEP_SWING
            land = (i + 1) * STEP_LENGTH + self.soles[swing, 0]
            feet[swing, 0] += (land - feet[swing, 0]) * _smooth(u)
            feet[swing, 2] += STEP_LIFT * 0.5 * (1.0 - math.cos(2.0 * math.pi * u))
            shares = np.zeros(2)
            shares[stance] = 1.0
        feet[:, :2] -= base
        return feet, shares


def _flat_feet(legs: FootKinematics, targets: Vector, q0: Vector) -> Vector:
    """Joint angles putting TALOS's soles at ``targets`` (base frame, (2, 3)) with the soles
    parallel to the base: Newton's method from ``q0`` on each leg's hip roll, hip pitch and
    knee, the ankles following (``_FLAT``); the other joints as in ``q0``."""
    q = q0.copy()
    for _ in range(20):
        h, jac = legs.positions_and_jacobians(q)
        err = targets - h
        if float(np.abs(err).max()) < 1e-10:
            break
        for j, o in enumerate((0, 6)):  # left leg, right leg
            q[o : o + 6] += _FLAT @ np.linalg.solve(jac[j][:, o : o + 6] @ _FLAT, err[j])
    return q


def talos_mujoco_spec(imu_body: str = "base_link") -> Any:
    """TALOS (example-robot-data's ``talos_reduced.urdf``, 32 joints) compiled by MuJoCo:
    every ``<visual>``/``<collision>`` removed (meshes), a box sole (half-sizes ``SOLE``,
    friction 1) under each of :data:`TALOS_FEET`, the only geoms that touch the floor; a
    free joint on ``base_link``, an unlimited torque motor and armature 0.05 kg·m² per
    joint, an IMU site at ``imu_body``'s origin: ``base_link`` (default, the root joint's
    frame) or ``imu_link`` (TALOS's, on the torso: it moves with ``torso_1_joint`` and
    ``torso_2_joint``; its URDF link, kept as a body, is Pinocchio's frame of that name).
    Returns the ``mujoco.MjSpec``."""
    import mujoco

    root = ET.parse(resolve_source("talos")[0]).getroot()
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    for unused in root.findall("transmission") + root.findall("gazebo"):
        root.remove(unused)
    extra = ET.SubElement(root, "mujoco")
    ET.SubElement(extra, "compiler", discardvisual="true", fusestatic="false", angle="radian")
    spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    spec.option.timestep = 1e-3
    spec.body("base_link").add_freejoint(name="root")
    for foot in TALOS_FEET:  # the sole frame is the sole's centre, on the floor
        spec.body(foot).add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(SOLE),
            pos=[0.0, 0.0, SOLE[2]],
            contype=1,
            conaffinity=0,
            condim=3,
        )
    add_imu_and_floor(spec, imu_body)
    for joint in spec.joints:
        if joint.type == mujoco.mjtJoint.mjJNT_HINGE:
            joint.armature = 0.05
            spec.add_actuator(name=joint.name, target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    return spec


def simulate_humanoid(
    motion: str,
    duration: float,
    *,
    seed: int = 0,
    rate: float = 500.0,
    substeps: int = 2,
    noise: LeggedNoise | None = None,
    robot: Robot | None = None,
    imu_body: str = "base_link",
    torso: float = 0.0,
) -> LeggedRun:
    """Simulate TALOS (:func:`talos_mujoco_spec`) in MuJoCo, sampled as
    :func:`~pinobs.simulation.legged.simulate_legged` samples go1 (same columns, sensors and
    noise).

    Controller: the joint PD law (module docstring; ``TALOS_KP``, ``TALOS_KD``, no torque
    limit) around the half-sitting :data:`TALOS_STANCE`, with the feed-forward ``τ_ff`` = the
    arms', torso's and head's gravity torques at the reference (``g(q_ref)``) and, for the
    legs of ``"stand"`` and ``"sway"``, half the weight on each sole
    (``−Σ_j J_jᵀ (m g / 2) e_z``).  ``"stand"`` holds the stance; ``"sway"`` moves both
    legs alike, the feet staying flat: a squat (hip pitch −a, knee +2a, ankle pitch −a,
    a = 0.08 sin(2π 0.5 t) rad: the base ±2.5 cm up and down) and a side sway (hip roll +b,
    ankle roll −b, b = 0.05 sin(2π 0.3 t) rad: ±5 cm sideways), ramped in over 0.5 s;
    ``"step"`` walks forward quasi-statically (module docstring: 6 cm a step, a step every
    2.5 s, the swing foot off the floor for 1 s of it).

    ``imu_body``: the IMU site's body (:func:`talos_mujoco_spec`); ``torso`` [rad]: a torso
    sway of that amplitude added to any motion (:func:`_torso`; 0, default: none).

    Raises:
        UnknownNameError: an unknown motion (one of :data:`HUMANOID_MOTIONS`).
        ConfigurationError: a non-positive duration, rate or substeps.
        SimulationFailed: it fell (base below 0.6 m) or MuJoCo's state became non-finite.
    """
    import mujoco

    check_arguments(motion, HUMANOID_MOTIONS, duration, rate, substeps)
    robot = robot if robot is not None else load("talos")
    legs = FootKinematics(robot, TALOS_FEET)
    spec = talos_mujoco_spec(imu_body)
    spec.option.timestep = 1.0 / (rate * substeps)
    mj = spec.compile()
    stance = np.array(TALOS_STANCE)
    weight = 9.81 * float(np.sum(mj.body_mass))  # [N]
    base_at_identity = np.array([0, 0, 0, 0, 0, 0, 1.0])
    gravity = robot.gravity(np.concatenate([base_at_identity, stance]))[6:]
    soles = legs.positions(stance)
    height = -float(soles[:, 2].mean()) + 1e-3
    at_stance = mujoco.MjData(mj)
    at_stance.qpos[[mj.joint(j.name).qposadr[0] for j in robot.joints[1:]]] = stance
    mujoco.mj_forward(mj, at_stance)
    root = mj.body("base_link").id
    plan = _Steps(soles, at_stance.subtree_com[root, :2] - at_stance.xpos[root, :2])
    first = round(-SETTLE * rate)
    memory = {"q_prev": stance.copy(), "q_ref": stance.copy()}

    def reference(k: int, t: float, data: Any) -> tuple[Vector, Vector, Vector]:
        if motion == "step":
            targets, shares = plan.at(t)
            q_ref = _flat_feet(legs, targets, memory["q_ref"])
            memory["q_ref"] = q_ref
            q_ref = _level(_torso(q_ref, t, torso) if torso else q_ref, shares, data.qpos[3:7])
            _, jac = legs.positions_and_jacobians(q_ref)
            tau_ff = robot.gravity(np.concatenate([base_at_identity, q_ref]))[6:]
            tau_ff -= weight * np.einsum("j,jki,k->i", shares, jac, (0.0, 0.0, 1.0))
        else:
            q_ref = _sway(stance, t) if motion == "sway" else stance.copy()
            _, jac = legs.positions_and_jacobians(q_ref)
            tau_ff = gravity.copy()
            if torso:
                q_ref = _torso(q_ref, t, torso)
                tau_ff = robot.gravity(np.concatenate([base_at_identity, q_ref]))[6:]
            tau_ff[:12] = -0.5 * weight * np.einsum("jki,k->i", jac, (0.0, 0.0, 1.0))[:12]
        dq_ref = (q_ref - memory["q_prev"]) * rate if k > first else np.zeros(stance.size)
        memory["q_prev"] = q_ref
        return q_ref, dq_ref, tau_ff

    machine = Machine("talos", mj, robot, TALOS_FEET, stance, height, TALOS_KP, TALOS_KD, 0.6)
    return record_run(machine, motion, reference, duration, seed, rate, substeps, noise)


def _level(q_ref: Vector, shares: Vector, quat_wxyz: Vector) -> Vector:
    """``q_ref`` with the standing ankles turned against the base's tilt (module docstring)."""
    w, x, y, z = quat_wxyz
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    out = q_ref.copy()
    for j, o in enumerate((0, 6)):  # ankle pitch (o + 4), ankle roll (o + 5)
        out[o + 4] += shares[j] * LEVEL_GAIN * pitch
        out[o + 5] += shares[j] * LEVEL_GAIN * roll
    return out


def _torso(q_ref: Vector, t: float, c: float) -> Vector:
    """``q_ref`` with the torso's sway at ``t`` [s]: ``torso_1_joint`` (yaw) ``+ c sin(2π 0.4 t)``
    and ``torso_2_joint`` (pitch) ``+ c sin(2π 0.25 t)`` [rad], ``c`` ramped in over 0.5 s (the
    torso's joints follow the legs' twelve); :func:`simulate_humanoid` takes the gravity
    feed-forward of the arms, torso and head at that reference."""
    out = q_ref.copy()
    s = c * min(1.0, max(t, 0.0) / 0.5)
    out[12] += s * math.sin(2 * math.pi * 0.4 * t)
    out[13] += s * math.sin(2 * math.pi * 0.25 * t)
    return out


def _sway(stance: Vector, t: float) -> Vector:
    """The ``"sway"`` reference at ``t`` [s] (:func:`simulate_humanoid`)."""
    q_ref = stance.copy()
    if t > 0:
        s = min(1.0, t / 0.5)
        a = 0.08 * s * math.sin(2 * math.pi * 0.5 * t)  # squat
        b = 0.05 * s * math.sin(2 * math.pi * 0.3 * t)  # side sway
        for o in (0, 6):  # left leg, right leg: hip yaw, roll, pitch, knee, ankle pitch, roll
            q_ref[o + 1 : o + 6] += (b, -a, 2 * a, -a, -b)
    return q_ref
