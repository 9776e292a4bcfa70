"""The one exception tree of pinobs.

Every error pinobs raises on purpose derives from :class:`PinobsError` and
also from the builtin a caller would catch for the same mistake, so
``except ValueError`` keeps working for code that does not know pinobs.
Messages name the bad value and say what would be accepted.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "ChunkWarning",
    "ConfigurationError",
    "ConsistencyWarning",
    "ContactWarning",
    "CostWarning",
    "DimensionError",
    "GainError",
    "IdentificationError",
    "LatencyWarning",
    "LogFormatError",
    "ModelError",
    "ModelFileError",
    "ModelTypeError",
    "ModelWarning",
    "NoiseWarning",
    "NonFiniteError",
    "NotResetError",
    "ObserverDiverged",
    "OptionError",
    "OutputExistsError",
    "PinobsError",
    "PinobsWarning",
    "SensorWarning",
    "SimulationFailed",
    "TimestampError",
    "TimestampWarning",
    "UnknownNameError",
    "UnsupportedRobotError",
]


class PinobsError(Exception):
    """Root of every error pinobs raises on purpose."""


class UnknownNameError(PinobsError, KeyError):
    """A robot, observer or scenario name that is not registered."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class ModelFileError(PinobsError, FileNotFoundError):
    """A model file that is missing or cannot be parsed."""


class LogFormatError(PinobsError, ValueError):
    """A log file that cannot be parsed (encoding, truncation, wrong container); names the line."""


class ModelTypeError(PinobsError, TypeError):
    """A robot source that is neither a name, a path, a ``pin.Model`` nor a ``RobotWrapper``."""


class ModelError(PinobsError, ValueError):
    """A model whose dynamics are wrong or unusable (NaN or negative mass, impossible
    inertia, singular or indefinite mass matrix, mimic joints, a dropped inertial)."""


class DimensionError(PinobsError, ValueError):
    """An array of the wrong shape."""


class NonFiniteError(PinobsError, ValueError):
    """An input containing NaN or infinity."""


class TimestampError(PinobsError, ValueError):
    """A timestamp that is not finite or not strictly increasing."""


class ConfigurationError(PinobsError, ValueError):
    """A configuration off its manifold (e.g. a quaternion far from unit norm)."""


class GainError(PinobsError, ValueError):
    """A gain or option outside its valid range."""


class OptionError(PinobsError, TypeError):
    """An option name an observer does not accept."""


class NotResetError(PinobsError, RuntimeError):
    """``update`` called before ``reset``."""


class UnsupportedRobotError(PinobsError, ValueError):
    """An observer asked to run on a robot it is not built for."""


class OutputExistsError(PinobsError, FileExistsError):
    """An output file exists (and overwriting was not asked for) or is an input."""


class IdentificationError(PinobsError, ValueError):
    """Identification is impossible or would be unreliable (no torques, too short, not excited)."""


class ObserverDiverged(PinobsError, ArithmeticError):
    """An observer produced a non-finite estimate.

    Attributes:
        t: time of the update that diverged [s].
        last_estimate: the last finite estimate, or ``None``.
    """

    def __init__(self, message: str, *, t: float, last_estimate: Any = None) -> None:
        super().__init__(message)
        self.t = t
        self.last_estimate = last_estimate


class SimulationFailed(PinobsError, RuntimeError):
    """A simulation left its valid range (a legged robot fell, a non-finite state)."""


class PinobsWarning(UserWarning):
    """Root of every warning pinobs issues on purpose."""


class NoiseWarning(PinobsWarning):
    """An observer built without ``noise_std`` estimated σ from its data and retuned itself."""


class ConsistencyWarning(PinobsWarning):
    """An estimate whose own residuals say the model does not explain the data."""


class LatencyWarning(PinobsWarning):
    """A measurement latency that was not given was found from the data and used."""


class ContactWarning(PinobsWarning):
    """A contact-aided filter that has had no foot in contact for a while: its velocity is the
    IMU's integral alone and drifts (contact flags never set, or set to the wrong feet)."""


class CostWarning(PinobsWarning):
    """Options that make a run far costlier than needed for what they ask (a memory bound
    that bounds nothing)."""


class ChunkWarning(PinobsWarning):
    """A chunked smoother whose given overlap is too short for its estimates to equal the
    whole log's to the stated tolerance."""


class TimestampWarning(PinobsWarning):
    """Timestamps whose sample period says they are in another unit than seconds."""


class SensorWarning(PinobsWarning):
    """Sensor columns whose values say they are in another unit than the one read (an
    accelerometer in g, a gyro in deg/s)."""


class ModelWarning(PinobsWarning):
    """A model that loads and is usable but not all of it (meshes missing, parser limits)."""
