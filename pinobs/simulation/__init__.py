"""Simulation layer: ground truth on the manifold, inputs, sensors, the result type, a logger."""

from pinobs.simulation.inputs import (
    INPUT_NAMES,
    InputProfile,
    MultiSine,
    PDTracking,
    Zero,
    make_input,
)
from pinobs.simulation.logger import Logger, RecordedLog
from pinobs.simulation.mismatch import MISMATCH_SCENARIOS, mismatched_plant
from pinobs.simulation.result import ObserverTrace, Result
from pinobs.simulation.run import default_input, perturb, simulate
from pinobs.simulation.sensors import Sensor

__all__ = [
    "INPUT_NAMES",
    "MISMATCH_SCENARIOS",
    "InputProfile",
    "Logger",
    "MultiSine",
    "ObserverTrace",
    "PDTracking",
    "RecordedLog",
    "Result",
    "Sensor",
    "Zero",
    "default_input",
    "make_input",
    "mismatched_plant",
    "perturb",
    "simulate",
]
