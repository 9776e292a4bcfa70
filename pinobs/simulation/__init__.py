"""Simulation layer: ground truth on the manifold, inputs, sensors, the result type."""

from pinobs.simulation.inputs import (
    INPUT_NAMES,
    InputProfile,
    MultiSine,
    PDTracking,
    Zero,
    make_input,
)
from pinobs.simulation.logs import Log, LogRun, estimate_log, read_log, write_estimates, write_log
from pinobs.simulation.mismatch import MISMATCH_SCENARIOS, mismatched_plant
from pinobs.simulation.result import ObserverTrace, Result
from pinobs.simulation.run import default_input, perturb, simulate
from pinobs.simulation.sensors import Sensor

__all__ = [
    "INPUT_NAMES",
    "MISMATCH_SCENARIOS",
    "InputProfile",
    "Log",
    "LogRun",
    "MultiSine",
    "ObserverTrace",
    "PDTracking",
    "Result",
    "Sensor",
    "Zero",
    "default_input",
    "estimate_log",
    "make_input",
    "mismatched_plant",
    "perturb",
    "read_log",
    "simulate",
    "write_estimates",
    "write_log",
]
