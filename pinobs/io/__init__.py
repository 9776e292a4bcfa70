"""Recorded logs in, estimates out: readers, the streaming estimate, writers.

Beside :mod:`pinobs.simulation` (same layer): it runs observers over data
that were recorded rather than simulated.  :func:`read_log` and
:func:`iter_log` read CSV/TSV, Parquet, NPZ, DataFrames and ROS bags;
:class:`LogEstimator` runs an observer over the rows, one output row per input
row, every fault reported once; :func:`process_log` streams a log from file to
file; :func:`estimate` returns a DataFrame.  :func:`fit_clock` (and
:class:`ClockRepair`, chunk by chunk) reconstructs the clock of a fixed-rate loop
behind a logger's jittery stamps, stale rows and drops.
"""

from pinobs.io.clock import CLOCK_MODES, ClockFit, ClockRepair, ClockReport, fit_clock
from pinobs.io.drives import Drives
from pinobs.io.readers import (
    CHUNK_ROWS,
    Log,
    concat_logs,
    find_logs,
    iter_log,
    join_tables,
    read_log,
)
from pinobs.io.runs import estimate, estimate_log, process_log
from pinobs.io.stream import LogEstimator, LogRun, ObserverLike
from pinobs.io.writers import EstimateWriter, write_estimates, write_log
from pinobs.observers.noise import estimate_noise_std

__all__ = [
    "CHUNK_ROWS",
    "CLOCK_MODES",
    "ClockFit",
    "ClockRepair",
    "ClockReport",
    "Drives",
    "EstimateWriter",
    "Log",
    "LogEstimator",
    "LogRun",
    "ObserverLike",
    "concat_logs",
    "estimate",
    "estimate_log",
    "estimate_noise_std",
    "find_logs",
    "fit_clock",
    "iter_log",
    "join_tables",
    "process_log",
    "read_log",
    "write_estimates",
    "write_log",
]
