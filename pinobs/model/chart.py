"""The angle chart of continuous joints: a robot in coordinates for coordinate-based observers.

A continuous joint (Pinocchio's ``JointModelRUBX/Y/Z``) stores ``q = (cos θ,
sin θ)`` on the circle, with velocity ``θ̇``.  Observers written in
coordinates (the I&I observer of Sarras et al.) need ``θ`` itself.  The chart
replaces each continuous joint by the revolute joint about the same axis,
with the same placement and body: ``M``, ``c`` and ``g`` at ``θ`` are those of
the original at ``(cos θ, sin θ)``, and velocities are unchanged.

``θ`` is recovered from a measurement as ``atan2(sin, cos)`` moved by a
multiple of ``2π`` to the value nearest a reference (the previous estimate):
the angle unwrapped along the measured path, correct as long as the joint
turns less than ``π`` between two samples.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from pinobs.model.robot import Robot, Vector

__all__ = ["AngleChart"]

_REVOLUTE = {
    "JointModelRUBX": pin.JointModelRX,
    "JointModelRUBY": pin.JointModelRY,
    "JointModelRUBZ": pin.JointModelRZ,
}


class AngleChart:
    """A robot whose continuous joints are replaced by revolute ones, and the maps between them.

    Attributes:
        robot: the original robot (``q`` of size ``nq``).
        chart: the robot in the chart (continuous joints revolute; ``nq = nv``
            when the others are vector joints).
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        src = robot.model
        model = pin.Model()
        model.name = src.name
        for j in range(1, src.njoints):
            joint = src.joints[j]
            short = joint.shortname()
            jm = _REVOLUTE[short]() if short in _REVOLUTE else joint
            jid = model.addJoint(int(src.parents[j]), jm, src.jointPlacements[j], src.names[j])
            model.appendBodyToJoint(jid, src.inertias[j], pin.SE3.Identity())
        model.gravity = src.gravity
        model.armature = src.armature.copy()
        model.damping = src.damping.copy()
        model.friction = src.friction.copy()
        self.chart = Robot(
            model,
            name=robot.name,
            source=robot.source,
            friction=robot.friction,
            root_joint=robot.root_joint,
        )
        # (idx_q, nq) in the robot, (idx_q, nq) in the chart, continuous?
        self._blocks = tuple(
            (a.idx_q, a.nq, b.idx_q, b.nq, a.kind == "circle")
            for a, b in zip(robot.joints, self.chart.joints, strict=True)
        )

    def to_chart(self, q: Vector, near: Vector | None = None) -> Vector:
        """Chart coordinates of ``q``; each ``θ`` within ``π`` of ``near``'s (if given) [rad]."""
        out = np.empty(self.chart.nq)
        for iq, nq, ic, nc, circle in self._blocks:
            if circle:
                theta = math.atan2(q[iq + 1], q[iq])
                if near is not None:
                    ref = float(near[ic])
                    theta = ref + math.remainder(theta - ref, 2.0 * math.pi)
                out[ic] = theta
            else:
                out[ic : ic + nc] = q[iq : iq + nq]
        return out

    def from_chart(self, x: Vector) -> Vector:
        """The robot's ``q`` at chart coordinates ``x``: ``(cos θ, sin θ)`` for each continuous joint."""
        out = np.empty(self.robot.nq)
        for iq, nq, ic, nc, circle in self._blocks:
            if circle:
                out[iq], out[iq + 1] = math.cos(x[ic]), math.sin(x[ic])
            else:
                out[iq : iq + nq] = x[ic : ic + nc]
        return out
