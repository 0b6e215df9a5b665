"""Reference paths: pose and curvature at arc length s, projection to (s, e_y, e_psi)."""

from .base import ReferencePath, Projection
from .circle import CirclePath
from .reference import horizon_arc_lengths, horizon_states
from .speed_profile import ConstantSpeed, SpeedProfile, SpeedReference
from .straight import StraightPath
from .tracks import Track, load_track_csv, track_from_text, write_track_csv
from .waypoints import WaypointPath

__all__ = [
    "CirclePath",
    "ConstantSpeed",
    "SpeedProfile",
    "SpeedReference",
    "Track",
    "load_track_csv",
    "track_from_text",
    "write_track_csv",
    "ReferencePath",
    "Projection",
    "StraightPath",
    "WaypointPath",
    "horizon_arc_lengths",
    "horizon_states",
]
