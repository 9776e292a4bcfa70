"""Model layer: the only code that calls Pinocchio's dynamics."""

from pinobs.model.integrators import lie_rk4
from pinobs.model.loading import RobotEntry, load, robot_entries, robot_names
from pinobs.model.robot import JointBlock, Robot
from pinobs.model.timing import aba_time, pinocchio_version

__all__ = [
    "JointBlock",
    "Robot",
    "RobotEntry",
    "aba_time",
    "lie_rk4",
    "pinocchio_version",
    "load",
    "robot_entries",
    "robot_names",
]
