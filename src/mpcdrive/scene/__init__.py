"""The scene: the world a drive happens in (:class:`Scene`: the road, the obstacles, the vehicle's
body), obstacle shapes and their motion, clearance geometry."""

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
from .road import Lane, Road
from .world import Scene

__all__ = [
    "Scene",
    "Road",
    "Lane",
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
