"""Obstacles: a shape in its own frame plus a motion giving its pose over time.

Poses are ``(x m, y m, yaw rad)``; shapes are defined around the obstacle's reference point.
Predictions over a horizon are the poses at ``t + k dt`` (constant velocity, or a given
trajectory interpolated in time; static obstacles never move); the motions' ``offset`` and
:meth:`Obstacle.poses_at` take a time or an array of times, so a horizon is placed at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Circle:
    """Disc of ``radius_m`` [m] around the reference point."""

    radius_m: float

    def __post_init__(self):
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"circle radius_m must be a positive finite number, got {self.radius_m}")

    @property
    def bounding_radius_m(self) -> float:
        return self.radius_m


@dataclass(frozen=True, eq=False)
class Polygon:
    """Convex polygon, vertices ``points`` (M, 2) [m] in the obstacle frame (any orientation;
    stored counter-clockwise)."""

    points: np.ndarray

    def __post_init__(self):
        p = np.asarray(self.points, float)
        if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3:
            raise ValueError(f"a polygon needs at least 3 points of 2 coordinates, got shape {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("polygon points must be finite")
        area2 = float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))
        if abs(area2) < 1e-12:
            raise ValueError("polygon has zero area")
        if area2 < 0:
            p = p[::-1].copy()
        e = np.roll(p, -1, axis=0) - p
        cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        if np.any(cross < -1e-12):
            raise ValueError("polygon must be convex (split non-convex obstacles into convex parts)")
        object.__setattr__(self, "points", p)

    @property
    def bounding_radius_m(self) -> float:
        return float(np.max(np.hypot(self.points[:, 0], self.points[:, 1])))


def rectangle(length_m: float, width_m: float) -> Polygon:
    """Rectangle centred on the reference point, length along the obstacle's x axis."""
    if not (length_m > 0 and width_m > 0):
        raise ValueError(f"rectangle length_m and width_m must be positive, got {length_m}, {width_m}")
    hl, hw = 0.5 * length_m, 0.5 * width_m
    return Polygon(np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]]))


@dataclass(frozen=True)
class Static:
    """Never moves."""

    def offset(self, t_s):
        """Offset (dx m, dy m, dyaw rad) from the initial pose at time(s) ``t_s`` [s]."""
        return 0.0, 0.0, 0.0


@dataclass(frozen=True)
class ConstantVelocity:
    """Moves at constant world-frame velocity ``(vx, vy)`` [m/s]."""

    vx_mps: float
    vy_mps: float

    def offset(self, t_s):
        return self.vx_mps * t_s, self.vy_mps * t_s, 0.0


@dataclass(frozen=True, eq=False)
class TrajectoryMotion:
    """Follows a recorded trajectory: poses ``(x, y, yaw)`` at times ``t_s`` [s], relative to the
    initial pose (linear interpolation; held before the first and after the last sample)."""

    t_s: np.ndarray
    dx_m: np.ndarray
    dy_m: np.ndarray
    dyaw_rad: np.ndarray

    def __post_init__(self):
        t = np.asarray(self.t_s, float)
        if t.ndim != 1 or len(t) < 1 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
            raise ValueError("trajectory times t_s must be finite and strictly increasing")
        for name in ("dx_m", "dy_m", "dyaw_rad"):
            a = np.asarray(getattr(self, name), float)
            if a.shape != t.shape or not np.all(np.isfinite(a)):
                raise ValueError(f"trajectory {name} must be finite with one value per time")
            object.__setattr__(self, name, a)
        object.__setattr__(self, "t_s", t)

    def offset(self, t_s):
        dx, dy, dyaw = (np.interp(t_s, self.t_s, a) for a in (self.dx_m, self.dy_m, self.dyaw_rad))
        if np.ndim(t_s) == 0:
            return float(dx), float(dy), float(dyaw)
        return dx, dy, dyaw


@dataclass(frozen=True)
class WorldCircle:
    center: np.ndarray
    radius_m: float


@dataclass(frozen=True)
class WorldPolygon:
    points: np.ndarray  # (M, 2) counter-clockwise


@dataclass(frozen=True, eq=False)
class Obstacle:
    """An obstacle: ``shape`` placed at ``pose`` (x m, y m, yaw rad) at t = 0, moved by ``motion``,
    present from ``t_start_s`` to ``t_end_s`` [s] (inclusive; default: always). A CommonRoad
    vehicle, for one, exists only over its recorded time span: outside its lifetime an obstacle
    is neither avoided nor collided with."""

    shape: Circle | Polygon
    pose: tuple[float, float, float]
    motion: Static | ConstantVelocity | TrajectoryMotion = field(default_factory=Static)
    name: str = ""
    t_start_s: float = -math.inf
    t_end_s: float = math.inf

    def __post_init__(self):
        pose = tuple(float(v) for v in self.pose)
        if len(pose) != 3 or not all(math.isfinite(v) for v in pose):
            raise ValueError(f"obstacle pose must be 3 finite numbers (x m, y m, yaw rad), got {self.pose}")
        object.__setattr__(self, "pose", pose)
        t0, t1 = float(self.t_start_s), float(self.t_end_s)
        if math.isnan(t0) or math.isnan(t1) or t1 < t0:
            raise ValueError(f"obstacle lifetime must be t_start_s <= t_end_s, got [{self.t_start_s}, {self.t_end_s}]")
        object.__setattr__(self, "t_start_s", t0)
        object.__setattr__(self, "t_end_s", t1)

    @property
    def has_lifetime(self) -> bool:
        """True when the obstacle is absent at some time (a finite start or end)."""
        return math.isfinite(self.t_start_s) or math.isfinite(self.t_end_s)

    def present(self, t_s):
        """Whether the obstacle exists at time ``t_s`` [s] (scalar or array)."""
        return (self.t_start_s <= np.asarray(t_s)) & (np.asarray(t_s) <= self.t_end_s)

    @property
    def moving(self) -> bool:
        return not isinstance(self.motion, Static)

    def pose_at(self, t_s: float) -> tuple[float, float, float]:
        dx, dy, dyaw = self.motion.offset(t_s)
        return self.pose[0] + dx, self.pose[1] + dy, self.pose[2] + dyaw

    def poses_at(self, t_s: np.ndarray) -> np.ndarray:
        """(K, 3) poses (x m, y m, yaw rad) at the times ``t_s`` (K,) [s], as :meth:`pose_at`."""
        t = np.asarray(t_s, float)
        out = np.empty((len(t), 3))
        out[:, 0], out[:, 1], out[:, 2] = self.pose_at(t)  # type: ignore[arg-type]
        return out

    def point_speeds_mps(self, t_s: np.ndarray) -> np.ndarray:
        """(K - 1,) the fastest any point of the obstacle moves [m/s] during each interval of the
        times ``t_s`` (K,) [s] (increasing): its reference point's speed plus its yaw rate times
        the shape's bounding radius, the largest over the motion's pieces in the interval (a
        recorded trajectory is linear between its samples and still before and after them)."""
        t = np.asarray(t_s, float)
        K = len(t)
        if K < 2 or isinstance(self.motion, Static):
            return np.zeros(max(K - 1, 0))
        r = self.shape.bounding_radius_m
        if isinstance(self.motion, ConstantVelocity):
            return np.full(K - 1, math.hypot(self.motion.vx_mps, self.motion.vy_mps))
        m = self.motion
        dt = np.diff(m.t_s)
        if dt.size == 0:
            return np.zeros(K - 1)
        # each piece's speed, padded with the still motion before the first and after the last sample
        v = np.r_[0.0, (np.hypot(np.diff(m.dx_m), np.diff(m.dy_m)) + r * np.abs(np.diff(m.dyaw_rad))) / dt, 0.0]
        # the pieces (indices into v) holding each interval's start and end
        j0 = np.searchsorted(m.t_s, t[:-1], side="right")
        j1 = np.searchsorted(m.t_s, t[1:], side="left")
        out = np.maximum(v[j0], v[j1])
        for k in np.flatnonzero(j1 - j0 > 1):  # an interval over several pieces
            out[k] = v[j0[k] : j1[k] + 1].max()
        return out

    def moves_linearly(self, t_s: np.ndarray) -> np.ndarray:
        """(K - 1,) True where the obstacle's pose is linear in time over the interval between
        two of the times ``t_s`` (K,) [s] (increasing): always for a static or constant-velocity
        one; for a recorded trajectory where no sample lies strictly inside the interval."""
        t = np.asarray(t_s, float)
        if not isinstance(self.motion, TrajectoryMotion):
            return np.ones(max(len(t) - 1, 0), dtype=bool)
        inside = np.searchsorted(self.motion.t_s, t[1:], side="left") - np.searchsorted(
            self.motion.t_s, t[:-1], side="right"
        )
        return inside <= 0

    def outlines_at(self, t_s: np.ndarray) -> np.ndarray:
        """(K, M, 2) world vertices [m] of a polygon obstacle at the times ``t_s`` (K,) [s], as
        :meth:`at` places them."""
        if not isinstance(self.shape, Polygon):
            raise ValueError(f"obstacle {self.name or '?'} is a circle: it has no outline")
        poses = self.poses_at(t_s)
        return placed_points(self.shape.points, poses[:, 0], poses[:, 1], poses[:, 2])

    def at(self, t_s: float) -> WorldCircle | WorldPolygon:
        """The obstacle's shape in the world at time ``t_s`` [s]."""
        x, y, yaw = self.pose_at(t_s)
        if isinstance(self.shape, Circle):
            return WorldCircle(np.array([x, y]), self.shape.radius_m)
        return WorldPolygon(placed_points(self.shape.points, x, y, yaw))


def placed_points(points: np.ndarray, x, y, yaw) -> np.ndarray:
    """Points (M, 2) of a body frame placed at pose (x m, y m, yaw rad): (M, 2) [m] for one pose,
    (K, M, 2) for poses given as arrays (K,)."""
    x, y, yaw = (np.asarray(v, float)[..., None] for v in (x, y, yaw))
    c, s = np.cos(yaw), np.sin(yaw)
    px, py = points[:, 0], points[:, 1]
    return np.stack([x + c * px - s * py, y + s * px + c * py], axis=-1)
