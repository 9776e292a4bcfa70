"""Evaluation layer: metrics and tables of simulation results."""

from pinobs.evaluation.live import LiveTiming, live_loop
from pinobs.evaluation.metrics import Metrics, convergence_time, evaluate
from pinobs.evaluation.report import format_table
from pinobs.evaluation.timing import measure_cost

__all__ = [
    "LiveTiming",
    "Metrics",
    "convergence_time",
    "evaluate",
    "format_table",
    "live_loop",
    "measure_cost",
]
