"""Which rotor inertias (armatures) a log determines (:func:`determined_armature`): the
rest are the model's own, not fitted (the package docstring of
:mod:`pinobs.model.identification`, "Armature: only where the data determine it").

A rotor inertia ``I_a,j`` is kept when its step from the model's own ``I_a,j⁰`` is both
determined by the data (beyond :data:`ARMATURE_SIGMAS` of its posterior standard
deviation ``σ_j``, :func:`~pinobs.model.identification.leastsquares.solve`'s ``std``) and
large enough to matter (beyond :data:`ARMATURE_SHARE` of the joint's nominal inertia
``M̄ⱼⱼ``, neutral configuration, the model's armature included)::

    |Î_a,j − I_a,j⁰| > max(ARMATURE_SIGMAS · σ_j, ARMATURE_SHARE · M̄ⱼⱼ)

The posterior ``σ_j`` treats the rows as independent, which model error and the windows'
shared end velocities make optimistic (rotors of simulated truths without any reached
z = 3.65), and a rotor whose column is nearly another's (a base joint's, against its
link's inertia about the same axis) has a wide ``σ_j`` however large it is (the real
UR10e's shoulder pan, 2.5 kg·m², z = 2.8; the TX40's joint 5, 10× its link's inertia,
z = 2.6).  Hence both: a geared motor's rotor is a large share of its joint's inertia
(``J_m N²``), a spurious one a small share (0.06–0.8 % on the simulated truths).  A
joint the model gives no inertia of its own (:data:`MASSLESS_SHARE`: FIGAROH's TX40 link
6, ``M`` singular without a rotor) keeps its rotor.
"""

from __future__ import annotations

import numpy as np

from pinobs.model.identification.leastsquares import Solution
from pinobs.model.identification.regressor import MomentumRegressor
from pinobs.model.robot import Robot, Vector

__all__ = [
    "ARMATURE_SHARE",
    "ARMATURE_SIGMAS",
    "MASSLESS_SHARE",
    "determined_armature",
    "kept_armature_weights",
]

#: A fitted rotor inertia is kept when its step from the model's own is beyond this many
#: posterior standard deviations (about 95 % two-sided) and beyond :data:`ARMATURE_SHARE`.
ARMATURE_SIGMAS = 2.0

#: ... and beyond this share of its joint's nominal inertia ``M̄ⱼⱼ`` (:func:`determined_armature`).
ARMATURE_SHARE = 0.01

#: A joint whose nominal inertia ``M̄ⱼⱼ`` (neutral configuration, the model's armature
#: included) is at most this share of the largest is massless: it keeps its rotor.
MASSLESS_SHARE = 1e-9


def determined_armature(reg: MomentumRegressor, sol: Solution) -> tuple[str, ...]:
    """The joints of ``reg.armature_joints`` whose fitted armature ``sol`` determines (module
    docstring: ``|θ̂ − θ₀| > max(ARMATURE_SIGMAS · σ, ARMATURE_SHARE · M̄ⱼⱼ)``, and the
    massless joints), in their order."""
    arm = reg.armature_slice
    step = np.abs(sol.theta[arm] - reg.nominal()[arm])
    robot = reg.robot
    m_bar = np.diag(robot.mass_matrix(robot.neutral()))[reg.armature_coordinates]
    keep = step > np.maximum(ARMATURE_SIGMAS * sol.std[arm], ARMATURE_SHARE * m_bar)
    # a joint the model gives no inertia of its own (M singular without a rotor)
    keep |= m_bar <= MASSLESS_SHARE * float(np.max(m_bar, initial=0.0))
    return tuple(j for j, k in zip(reg.armature_joints, keep, strict=True) if k)


def kept_armature_weights(reg: MomentumRegressor, theta: Vector, kept: tuple[str, ...]) -> Robot:
    """The weights' model of the fit on ``kept`` (:meth:`MomentumRegressor.armature_weights`):
    the nominal robot carrying ``θ``'s armature on the joints ``kept``, the model's own on the
    others."""
    theta = np.array(theta, dtype=float)
    arm = np.arange(theta.size)[reg.armature_slice]
    dropped = [k for k, j in zip(arm, reg.armature_joints, strict=True) if j not in kept]
    theta[dropped] = reg.nominal()[dropped]
    return reg.armature_weights(theta)
