"""Closed-loop simulation: plant, disturbances, measurement noise, full log, metrics."""

from .closed_loop import Disturbance, Plant, simulate
from .metrics import Footprint, compute_metrics

__all__ = ["Plant", "Disturbance", "simulate", "Footprint", "compute_metrics"]
