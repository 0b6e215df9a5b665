"""Quantities of a finished run beyond the CONTRACT metrics: lateral acceleration, road excess
against a track's own widths, lap time (reads a SimResult, never simulates)."""

from __future__ import annotations

import numpy as np

from ..paths.tracks import Track
from ..types import SimResult
from ..scene.footprint import Footprint


def lateral_acceleration_mps2(result: SimResult) -> np.ndarray:
    """(K,) lateral acceleration [m/s^2] of the reference point, left positive, from the logged
    positions: ``a_y = (v x a)_z / |v|`` with velocity and acceleration by central differences."""
    xy = np.asarray(result.xy, float)
    if xy.shape[0] < 3:
        return np.zeros(xy.shape[0])
    dt = float(result.dt_s)
    vel = np.gradient(xy, dt, axis=0)
    acc = np.gradient(vel, dt, axis=0)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    cross = vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]
    return np.where(speed > 1e-6, cross / np.maximum(speed, 1e-6), 0.0)


def road_excess_m(result: SimResult, track: Track, footprint: Footprint) -> float:
    """Largest distance [m] by which a footprint corner left the road (0 inside), with the track's
    right / left widths at each step's arc length."""
    if not track.has_widths:
        raise ValueError(f"track {track.name!r} has no road widths")
    h = result.yaw_rad - result.e_psi_rad  # path heading at each step
    c = footprint.corners()
    yaw = result.yaw_rad
    dx = np.cos(yaw)[:, None] * c[:, 0] - np.sin(yaw)[:, None] * c[:, 1]
    dy = np.sin(yaw)[:, None] * c[:, 0] + np.cos(yaw)[:, None] * c[:, 1]
    lat = result.e_y_m[:, None] + (-np.sin(h)[:, None] * dx + np.cos(h)[:, None] * dy)
    w_right, w_left = track.widths_at(result.s_m)
    over = np.maximum(lat - w_left[:, None], -lat - w_right[:, None])
    return float(max(0.0, np.max(over)))


def lap_time_s(result: SimResult) -> float | None:
    """Time to the goal (a lap of a closed track, the end of an open one) [s]; None if not reached."""
    if not result.goal_reached:
        return None
    return float(result.steps * result.dt_s)
