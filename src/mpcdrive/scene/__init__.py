"""The scene: obstacle shapes and their motion, the vehicle footprint, clearance geometry."""

from .footprint import Footprint
from .geometry import shape_distance
from .obstacles import (
    Circle,
    ConstantVelocity,
    Obstacle,
    Polygon,
    Static,
    TrajectoryMotion,
    WorldCircle,
    WorldPolygon,
    rectangle,
)

__all__ = [
    "Footprint",
    "Circle",
    "Polygon",
    "rectangle",
    "Obstacle",
    "Static",
    "ConstantVelocity",
    "TrajectoryMotion",
    "WorldCircle",
    "WorldPolygon",
    "shape_distance",
]
