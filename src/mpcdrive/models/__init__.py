"""Vehicle models: continuous dynamics f(x, u), analytic Jacobians, discretization."""

from .base import VehicleModel
from .discretize import discrete_jacobians, discrete_step, discrete_step_and_jacobians, rollout
from .kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams

__all__ = [
    "KinematicBicycle3",
    "KinematicBicycle4",
    "KinematicParams",
    "VehicleModel",
    "discrete_jacobians",
    "discrete_step",
    "discrete_step_and_jacobians",
    "rollout",
]
