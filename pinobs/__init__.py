"""pinobs: velocity observers for any URDF robot, on Pinocchio's dynamics.

Examples:
    >>> import pinobs
    >>> robot = pinobs.load("cartpole")
    >>> obs = pinobs.make_observer("kf", robot, rate=1000.0, noise_std=1e-4)
"""

from pinobs.calibration import identify
from pinobs.errors import (
    ConfigurationError,
    DimensionError,
    GainError,
    IdentificationError,
    LogFormatError,
    ModelError,
    ModelFileError,
    ModelTypeError,
    ModelWarning,
    NonFiniteError,
    NotResetError,
    ObserverDiverged,
    OptionError,
    OutputExistsError,
    PinobsError,
    PinobsWarning,
    TimestampError,
    UnknownNameError,
    UnsupportedRobotError,
)
from pinobs.evaluation import Metrics, evaluate
from pinobs.io import estimate
from pinobs.model import Robot, load, robot_names
from pinobs.model.identification import Identification
from pinobs.observers import Consistency, Estimate, Observer, make_observer, observer_names
from pinobs.simulation import Logger, RecordedLog, Result, Sensor, simulate
from pinobs.smoothing import Smoothed, smooth

__version__ = "0.1.0"

__all__ = [
    "ConfigurationError",
    "Consistency",
    "DimensionError",
    "Estimate",
    "GainError",
    "Identification",
    "IdentificationError",
    "LogFormatError",
    "Logger",
    "Metrics",
    "ModelError",
    "ModelFileError",
    "ModelTypeError",
    "ModelWarning",
    "NonFiniteError",
    "NotResetError",
    "Observer",
    "ObserverDiverged",
    "OptionError",
    "OutputExistsError",
    "PinobsError",
    "PinobsWarning",
    "RecordedLog",
    "Result",
    "Robot",
    "Sensor",
    "Smoothed",
    "TimestampError",
    "UnknownNameError",
    "UnsupportedRobotError",
    "estimate",
    "evaluate",
    "identify",
    "load",
    "make_observer",
    "observer_names",
    "robot_names",
    "simulate",
    "smooth",
]
