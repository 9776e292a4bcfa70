"""Recorded logs in, estimates out: readers, the streaming estimate, writers.

Beside :mod:`pinobs.simulation` (same layer): it runs observers over data
that were recorded rather than simulated.  :func:`read_log` and
:func:`iter_log` read CSV/TSV, Parquet, NPZ, DataFrames and ROS bags;
:class:`LogEstimator` runs an observer over the rows, one output row per input
row, every fault reported once; :func:`process_log` streams a log from file to
file; :func:`estimate` returns a DataFrame.
"""

from pinobs.io.readers import CHUNK_ROWS, Log, find_logs, iter_log, read_log
from pinobs.io.stream import LogEstimator, LogRun, ObserverLike, estimate, estimate_log, process_log
from pinobs.io.writers import EstimateWriter, write_estimates, write_log
from pinobs.observers.noise import estimate_noise_std

__all__ = [
    "CHUNK_ROWS",
    "EstimateWriter",
    "Log",
    "LogEstimator",
    "LogRun",
    "ObserverLike",
    "estimate",
    "estimate_log",
    "estimate_noise_std",
    "find_logs",
    "iter_log",
    "process_log",
    "read_log",
    "write_estimates",
    "write_log",
]
