"""Reference paths: pose and curvature at arc length s, projection to (s, e_y, e_psi)."""

from .base import Path, Projection
from .circle import CirclePath
from .reference import horizon_arc_lengths, horizon_states
from .straight import StraightPath
from .waypoints import WaypointPath

__all__ = [
    "CirclePath",
    "Path",
    "Projection",
    "StraightPath",
    "WaypointPath",
    "horizon_arc_lengths",
    "horizon_states",
]
