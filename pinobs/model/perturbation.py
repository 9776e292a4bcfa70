"""A robot's model with its dynamics changed, for model-mismatch studies
(:meth:`~pinobs.model.robot.Robot.perturbed`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from pinobs.errors import DimensionError
from pinobs.model.friction import FrictionLaw

if TYPE_CHECKING:
    from pinobs.model.robot import Robot

__all__ = ["perturbed_model"]


def perturbed_model(
    robot: Robot,
    *,
    inertia_scale: ArrayLike | None = None,
    payload: tuple[float, ArrayLike] | None = None,
    damping: ArrayLike | None = None,
    coulomb: ArrayLike | None = None,
) -> tuple[pin.Model, bool, FrictionLaw | None]:
    """``(model, friction, law)``: a copy of ``robot``'s model changed as
    :meth:`~pinobs.model.robot.Robot.perturbed` says (its arguments), whether friction is on,
    and the friction law replacing the robot's (``None``: the robot's own)."""
    model = robot.model.copy()
    if inertia_scale is not None:
        scale = np.asarray(inertia_scale, dtype=float)
        ids = [i for i, j in enumerate(model.joints) if i > 0 and j.nv > 0]
        if scale.shape != (len(ids),) or np.any(scale <= 0):
            raise DimensionError(
                f"inertia_scale needs {len(ids)} positive factors, got {scale.tolist()}"
            )
        for f, i in zip(scale, ids, strict=True):
            inertia = model.inertias[i]
            model.inertias[i] = pin.Inertia(f * inertia.mass, inertia.lever, f * inertia.inertia)
    if payload is not None:
        mass, offset = payload
        # the tool: the last moving body, passing over prismatic gripper fingers
        moving = [i for i, j in enumerate(model.joints) if i > 0 and j.nv > 0]
        tools = [i for i in moving if not model.joints[i].shortname().startswith("JointModelP")]
        last = (tools or moving)[-1]
        model.inertias[last] = model.inertias[last] + pin.Inertia(
            float(mass), np.asarray(offset, dtype=float), np.zeros((3, 3))
        )
    friction, law = robot.friction, None
    if damping is not None or coulomb is not None:
        model.damping = np.asarray(
            damping if damping is not None else np.zeros(robot.nv), dtype=float
        )
        model.friction = np.asarray(
            coulomb if coulomb is not None else np.zeros(robot.nv), dtype=float
        )
        friction = True
        law = FrictionLaw.from_urdf(model.damping, model.friction)  # replaces a given law
    return model, friction, law
