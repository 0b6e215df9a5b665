"""Maneuver planning between the scene and the controller: sample maneuvers in the road's Frenet
frame, check them against the predicted traffic, the road and the vehicle, and choose one
(:class:`~.planner.ManeuverPlanner`); the controller drives the chosen maneuver
(:class:`~.driver.PlannedMpc`)."""

from .config import PlannerConfig, VehicleLimits
from .planner import LateralMove, Maneuver, ManeuverPlanner, PlanningGoal

__all__ = ["LateralMove", "Maneuver", "ManeuverPlanner", "PlannerConfig", "PlanningGoal", "VehicleLimits"]
