"""Vehicle models: continuous dynamics f(x, u), analytic Jacobians, discretization."""

from .base import VehicleModel
from .convert import state_converter
from .discretize import discrete_jacobians, discrete_step, discrete_step_and_jacobians, rollout
from .dynamic import DynamicBicycle, DynamicParams
from .kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams
from .presets import DEFAULT_STEERING, PRESETS, SteeringSystem, VehiclePreset, get_preset, steering_of

__all__ = [
    "DEFAULT_STEERING",
    "PRESETS",
    "SteeringSystem",
    "steering_of",
    "DynamicBicycle",
    "DynamicParams",
    "VehiclePreset",
    "get_preset",
    "state_converter",
    "KinematicBicycle3",
    "KinematicBicycle4",
    "KinematicParams",
    "VehicleModel",
    "discrete_jacobians",
    "discrete_step",
    "discrete_step_and_jacobians",
    "rollout",
]
