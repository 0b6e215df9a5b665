"""Vehicle models: continuous dynamics f(x, u), analytic Jacobians, discretization."""

from .base import VehicleModel
from .discretize import discrete_jacobians, discrete_step, discrete_step_and_jacobians, rollout
from .kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams

__all__ = [
    "VehicleModel",
    "KinematicBicycle3",
    "KinematicBicycle4",
    "KinematicParams",
    "discrete_step",
    "discrete_jacobians",
    "discrete_step_and_jacobians",
    "rollout",
]
