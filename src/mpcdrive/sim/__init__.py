"""Closed-loop simulation: plant, disturbances, measurement noise, full log, metrics."""

from .actuator import ActuatorState, SteeringActuator
from .closed_loop import Disturbance, Plant, simulate
from .metrics import Footprint, compute_metrics, lane_excess_per_step

__all__ = ["ActuatorState", "SteeringActuator", "Disturbance", "Footprint", "Plant", "compute_metrics",
           "lane_excess_per_step", "simulate"]
