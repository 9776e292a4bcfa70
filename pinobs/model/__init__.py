"""Model layer: the only code that calls Pinocchio's dynamics."""

from pinobs.model.integrators import lie_rk4
from pinobs.model.loading import RobotEntry, load, robot_entries, robot_names
from pinobs.model.robot import JointBlock, Robot

__all__ = ["JointBlock", "Robot", "RobotEntry", "lie_rk4", "load", "robot_entries", "robot_names"]
