"""Model layer: the only code that calls Pinocchio's dynamics."""

from pinobs.model.analytic import AnalyticMetric
from pinobs.model.integrators import dynamics_rk4, lie_rk4
from pinobs.model.legs import FootKinematics, foot_sphere_radii, foot_sphere_radius
from pinobs.model.loading import RobotEntry, load, robot_entries, robot_names
from pinobs.model.robot import JointBlock, Robot
from pinobs.model.timing import aba_call, aba_time, pinocchio_version

__all__ = [
    "AnalyticMetric",
    "FootKinematics",
    "JointBlock",
    "Robot",
    "RobotEntry",
    "aba_call",
    "aba_time",
    "dynamics_rk4",
    "foot_sphere_radii",
    "foot_sphere_radius",
    "lie_rk4",
    "load",
    "pinocchio_version",
    "robot_entries",
    "robot_names",
]
