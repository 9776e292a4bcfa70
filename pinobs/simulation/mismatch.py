"""Model mismatch: the truth runs a perturbed copy of the robot, the observers keep the nominal one.

Scenarios, by name (seeded; ``M̄ᵢ`` is the diagonal of the nominal mass
matrix at the neutral configuration, the inertia each joint drives):

* ``exact`` — the truth is the nominal model;
* ``inertia5`` — every link's mass and inertia scaled by 1 ± 5 % (random sign);
* ``inertia20_payload`` — 1 ± 20 % and a point payload of 10 % of the moving
  mass, 5 cm out along the z axis of the tool body (the last moving body,
  passing over prismatic gripper fingers: on the Panda, link 7) — an unknown tool;
* ``friction`` — unmodelled joint friction: viscous ``D = 2 M̄ᵢ`` [N·m·s/rad]
  (a 0.5 s time constant on each joint alone) and Coulomb ``F = 0.5 M̄ᵢ``
  [N·m] (half a rad/s² of stiction-like resistance), smoothed as in
  :meth:`Robot.friction_torque`.
"""

from __future__ import annotations

import numpy as np

from pinobs.errors import UnknownNameError
from pinobs.model import Robot

__all__ = ["MISMATCH_SCENARIOS", "mismatched_plant"]

MISMATCH_SCENARIOS = ("exact", "inertia5", "inertia20_payload", "friction")


def mismatched_plant(robot: Robot, scenario: str, *, seed: int = 0) -> Robot:
    """The truth's model for ``scenario`` (module docstring); ``robot`` is left untouched."""
    rng = np.random.default_rng(seed)
    n_bodies = len(robot.joints)
    if scenario == "exact":
        return robot.copy()
    if scenario in ("inertia5", "inertia20_payload"):
        error = 0.05 if scenario == "inertia5" else 0.20
        scale = 1.0 + error * rng.choice([-1.0, 1.0], n_bodies)
        payload = None
        if scenario == "inertia20_payload":
            payload = (0.1 * robot.total_mass(), [0.0, 0.0, 0.05])
        return robot.perturbed(
            name=f"{robot.name}[{scenario}]", inertia_scale=scale, payload=payload
        )
    if scenario == "friction":
        m_bar = np.diag(robot.mass_matrix(robot.neutral()))
        return robot.perturbed(
            name=f"{robot.name}[friction]", damping=2.0 * m_bar, coulomb=0.5 * m_bar
        )
    raise UnknownNameError(
        f"unknown mismatch scenario {scenario!r}; available: {', '.join(MISMATCH_SCENARIOS)}"
    )
