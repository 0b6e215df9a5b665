"""Straight-line path."""

from __future__ import annotations

import numpy as np

from .base import ReferencePath


#: the shortest straight path [m]: shorter ones are a typo (or a unit slip), and their
#: arc-length tables would underflow
MIN_LENGTH_M = 1e-6


class StraightPath(ReferencePath):
    """Segment from ``start`` to ``end`` (2,) [m], extended along its direction beyond the ends."""

    closed = False

    def __init__(self, start, end):
        self.start = np.asarray(start, float)
        end = np.asarray(end, float)
        if self.start.shape != (2,) or end.shape != (2,):
            raise ValueError(f"start and end must be points [x m, y m], got {start!r} and {end!r}")
        d = end - self.start
        self.length_m = float(np.hypot(*d))
        if not np.isfinite(self.length_m) or self.length_m < MIN_LENGTH_M:
            raise ValueError(
                f"a straight path needs two finite points at least {MIN_LENGTH_M:g} m apart, got {start} and {end}"
            )
        self.t = d / self.length_m
        self.n = np.array([-self.t[1], self.t[0]])
        self._heading = float(np.arctan2(self.t[1], self.t[0]))

    def position(self, s):
        s = np.asarray(s, float)
        return self.start + s[..., None] * self.t

    def heading(self, s):
        return np.full(np.shape(s), self._heading) if np.ndim(s) else self._heading

    def curvature(self, s):
        return np.zeros(np.shape(s)) if np.ndim(s) else 0.0

    def _project_xy(self, xy, s_guess, window_m):
        d = xy - self.start
        return float(d @ self.t), float(d @ self.n)

    def _project_many_xy(self, xy, s_guess, window_m):
        d = xy - self.start
        return d @ self.t, d @ self.n

    def _project_track_xy(self, xy, s_guess, window_m, step_margin_m):
        return self._project_many_xy(xy, None, None)  # one nearest point: no search to narrow
