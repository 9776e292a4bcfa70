"""Where each joint sits in ``q`` and ``v`` and what group it lives on (:class:`JointBlock`),
read from a Pinocchio model (:func:`joint_blocks`; :class:`~pinobs.model.robot.Robot`'s)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pinocchio as pin

__all__ = ["JointBlock", "joint_blocks", "joint_kind"]


@dataclass(frozen=True)
class JointBlock:
    """Where one joint sits in ``q`` and ``v``, and what group it lives on.

    Attributes:
        name: joint name in the model.
        kind: ``"vector"`` (revolute, prismatic, and any joint whose velocity is
            the time derivative of its coordinates), ``"circle"`` (continuous
            joint, ``q = (cos, sin)``), ``"so3"`` (spherical, quaternion),
            ``"se3"`` (free-flyer), ``"se2"`` (planar).
        idx_q: first index in ``q``.
        nq: number of entries in ``q``.
        idx_v: first index in ``v``.
        nv: number of entries in ``v``.
    """

    name: str
    kind: str
    idx_q: int
    nq: int
    idx_v: int
    nv: int


_KIND_BY_SHORTNAME = {
    "JointModelSpherical": "so3",
    "JointModelFreeFlyer": "se3",
    "JointModelPlanar": "se2",
}


def joint_kind(joint: Any) -> str:
    """A Pinocchio joint's :attr:`JointBlock.kind`."""
    short = joint.shortname()
    if short in _KIND_BY_SHORTNAME:
        return _KIND_BY_SHORTNAME[short]
    if short.startswith("JointModelRUB"):  # continuous joint: SO(2), abelian
        return "circle"
    return "vector"


def joint_blocks(model: pin.Model) -> tuple[JointBlock, ...]:
    """The blocks of ``model``'s joints that move (``nv > 0``), in the model's order."""
    return tuple(
        JointBlock(
            name=model.names[i],
            kind=joint_kind(j),
            idx_q=j.idx_q,
            nq=j.nq,
            idx_v=j.idx_v,
            nv=j.nv,
        )
        for i, j in enumerate(model.joints)
        if i > 0 and j.nv > 0
    )
