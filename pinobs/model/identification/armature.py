"""Which rotor inertias (armatures) a log determines (:func:`determined_armature`): the
rest are the model's own, not fitted (the package docstring of
:mod:`pinobs.model.identification`, "Armature: only where the data determine it").

A rotor inertia ``I_a,j`` is kept when its estimate differs from the model's own
``I_a,j⁰`` by more than :data:`ARMATURE_SIGMAS` of its posterior standard deviation
``σ_j`` (:func:`~pinobs.model.identification.leastsquares.solve`'s ``std``)::

    |Î_a,j − I_a,j⁰| > ARMATURE_SIGMAS · σ_j                             (a z-test)

Three, as the online learner's test of a friction coefficient.  A column the data do not
determine only adds variance (measured: package docstring).  The posterior ``σ_j`` treats
the rows as independent; it is tested again after each refit, so a rotor kept must stay
significant on the fit without the others.
"""

from __future__ import annotations

import numpy as np

from pinobs.model.identification.leastsquares import Solution
from pinobs.model.identification.regressor import MomentumRegressor
from pinobs.model.robot import Robot, Vector

__all__ = ["ARMATURE_SIGMAS", "determined_armature", "kept_armature_weights"]

#: A fitted rotor inertia is kept when it differs from the model's own by more than this
#: many posterior standard deviations (:func:`determined_armature`).
ARMATURE_SIGMAS = 3.0


def determined_armature(reg: MomentumRegressor, sol: Solution) -> tuple[str, ...]:
    """The joints of ``reg.armature_joints`` whose fitted armature ``sol`` determines: the
    z-test of the module docstring, ``|θ̂ − θ₀| > ARMATURE_SIGMAS · σ``, in their order."""
    arm = reg.armature_slice
    step = np.abs(sol.theta[arm] - reg.nominal()[arm])
    std = np.maximum(sol.std[arm], 1e-300)
    return tuple(
        j for j, z in zip(reg.armature_joints, step / std, strict=True) if z > ARMATURE_SIGMAS
    )


def kept_armature_weights(reg: MomentumRegressor, theta: Vector, kept: tuple[str, ...]) -> Robot:
    """The weights' model of the fit on ``kept`` (:meth:`MomentumRegressor.armature_weights`):
    the nominal robot carrying ``θ``'s armature on the joints ``kept``, the model's own on the
    others."""
    theta = np.array(theta, dtype=float)
    arm = np.arange(theta.size)[reg.armature_slice]
    dropped = [k for k, j in zip(arm, reg.armature_joints, strict=True) if j not in kept]
    theta[dropped] = reg.nominal()[dropped]
    return reg.armature_weights(theta)
