"""Circular path."""

from __future__ import annotations

import math

import numpy as np

from .base import ReferencePath


class CirclePath(ReferencePath):
    """Circle of ``radius_m`` around ``center`` (2,) [m].

    Starts at polar angle ``start_angle_rad`` and runs counter-clockwise when ``ccw`` (left turn,
    curvature +1/r), clockwise otherwise.
    """

    closed = True

    def __init__(self, center=(0.0, 0.0), radius_m: float = 1.5, ccw: bool = True, start_angle_rad: float = 0.0):
        if not (np.isfinite(radius_m) and radius_m > 0):
            raise ValueError(f"radius_m must be a positive finite number, got {radius_m}")
        c = np.asarray(center, float)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ValueError(f"center must be 2 finite numbers [x m, y m], got {center!r}")
        if not np.isfinite(start_angle_rad):
            raise ValueError(f"start_angle_rad must be finite, got {start_angle_rad!r}")
        self.center = c
        self.radius_m = float(radius_m)
        self.sign = 1.0 if ccw else -1.0
        self.start_angle_rad = float(start_angle_rad)
        self.length_m = 2.0 * math.pi * self.radius_m

    def _theta(self, s):
        return self.start_angle_rad + self.sign * np.asarray(s, float) / self.radius_m

    def position(self, s):
        th = self._theta(s)
        return self.center + self.radius_m * np.stack([np.cos(th), np.sin(th)], axis=-1)

    def heading(self, s):
        h = self._theta(s) + self.sign * 0.5 * math.pi
        return float(h) if np.ndim(h) == 0 else h

    def curvature(self, s):
        k = self.sign / self.radius_m
        return np.full(np.shape(s), k) if np.ndim(s) else k

    def _project_xy(self, xy, s_guess, window_m):
        d = xy - self.center
        rho = float(np.hypot(*d))
        th = math.atan2(d[1], d[0])
        s_local = (self.sign * (th - self.start_angle_rad) * self.radius_m) % self.length_m
        s = self._lap_shift(s_local, s_guess)
        e_y = self.sign * (self.radius_m - rho)
        return float(s), float(e_y)

    def _project_many_xy(self, xy, s_guess, window_m):
        d = xy - self.center
        rho = np.hypot(d[:, 0], d[:, 1])
        th = np.arctan2(d[:, 1], d[:, 0])
        s_local = (self.sign * (th - self.start_angle_rad) * self.radius_m) % self.length_m
        return self._lap_shift(s_local, s_guess), self.sign * (self.radius_m - rho)

    def _project_track_xy(self, xy, s_guess, window_m, step_margin_m):
        s_local, e_y = self._project_many_xy(xy, None, None)
        if len(xy) == 0:
            return s_local, e_y
        # each point on the lap nearest the one before, the first on the guess's
        s = np.unwrap(s_local, period=self.length_m)
        return s + self.length_m * np.round((s_guess - s[0]) / self.length_m), e_y
