"""Evaluation layer: metrics and tables of simulation results."""

from pinobs.evaluation.metrics import Metrics, convergence_time, evaluate

__all__ = ["Metrics", "convergence_time", "evaluate"]
