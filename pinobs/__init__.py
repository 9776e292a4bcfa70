"""pinobs: velocity observers for any URDF robot, on Pinocchio's dynamics.

Examples:
    >>> import pinobs
    >>> robot = pinobs.load("cartpole")
    >>> obs = pinobs.make_observer("kf", robot, rate=1000.0, noise_std=1e-4)
"""

import importlib
from typing import TYPE_CHECKING, Any

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

if TYPE_CHECKING:
    from pinobs.calibration import identify
    from pinobs.evaluation import Metrics, evaluate
    from pinobs.io import estimate
    from pinobs.model import Robot, load, robot_names
    from pinobs.model.identification import Identification
    from pinobs.observers import Consistency, Estimate, Observer, make_observer, observer_names
    from pinobs.simulation import Logger, RecordedLog, Result, Sensor, simulate
    from pinobs.smoothing import Smoothed, smooth

#: Each public name beyond the errors -> the module that defines it, imported on first use
#: (PEP 562 ``__getattr__``): ``import pinobs`` imports neither pinocchio nor the layers, so
#: a program pays only for the layers it uses (issue 39: ``import pinobs`` <= 0.3 s CPU).
_LAZY = {
    "identify": "pinobs.calibration",
    "Metrics": "pinobs.evaluation",
    "evaluate": "pinobs.evaluation",
    "estimate": "pinobs.io",
    "Robot": "pinobs.model",
    "load": "pinobs.model",
    "robot_names": "pinobs.model",
    "Identification": "pinobs.model.identification",
    "Consistency": "pinobs.observers",
    "Estimate": "pinobs.observers",
    "Observer": "pinobs.observers",
    "make_observer": "pinobs.observers",
    "observer_names": "pinobs.observers",
    "Logger": "pinobs.simulation",
    "RecordedLog": "pinobs.simulation",
    "Result": "pinobs.simulation",
    "Sensor": "pinobs.simulation",
    "simulate": "pinobs.simulation",
    "Smoothed": "pinobs.smoothing",
    "smooth": "pinobs.smoothing",
}


def __getattr__(name: str) -> Any:
    """A public name of :data:`_LAZY`, imported from its module on first use (then cached)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'pinobs' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


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
