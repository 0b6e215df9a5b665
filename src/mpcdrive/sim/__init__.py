"""Closed-loop simulation: plant, disturbances, measurement noise, full log, metrics, verdict."""

from .actuator import ActuatorState, SteeringActuator
from .closed_loop import Disturbance, Plant, inner_attr, simulate
from ..scene.footprint import Footprint
from .metrics import (
    LANE_TOLERANCE_M,
    CollisionEvent,
    CommonRoadCheck,
    Metrics,
    SolveTimes,
    WholeDriveCheck,
    apply_goal_region,
    compute_metrics,
    lane_excess_per_step,
)
from .verdict import RunVerdict, VerdictCriteria, VerdictPart, run_verdict

__all__ = [
    "ActuatorState",
    "CollisionEvent",
    "CommonRoadCheck",
    "SteeringActuator",
    "Disturbance",
    "Footprint",
    "LANE_TOLERANCE_M",
    "Metrics",
    "Plant",
    "RunVerdict",
    "SolveTimes",
    "VerdictCriteria",
    "VerdictPart",
    "WholeDriveCheck",
    "apply_goal_region",
    "compute_metrics",
    "inner_attr",
    "lane_excess_per_step",
    "run_verdict",
    "simulate",
]
