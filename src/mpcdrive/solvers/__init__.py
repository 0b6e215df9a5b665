"""QP backends that are set up once and updated in place each control step."""

from .osqp_backend import OsqpBackend, OsqpSettings
from .projected_gradient import ProjectedGradientBackend, ProjectedGradientSettings

__all__ = ["OsqpBackend", "OsqpSettings", "ProjectedGradientBackend", "ProjectedGradientSettings"]
