"""Waypoint paths: a curve through points (a shape-preserving cubic or a smoothed cubic spline),
tabulated densely by arc length."""

from __future__ import annotations

import math

import numpy as np

from . import compiled as _compiled
from .base import ReferencePath


#: the curves a :class:`WaypointPath` can draw through its points
INTERPOLATIONS = ("spline", "pchip")


def _spline_curve(pts: np.ndarray, closed: bool, smoothing: float):
    """``curve(u, der)`` (n, 2): scipy's parametric cubic spline through ``pts``, u in [0, 1]."""
    from scipy.interpolate import splev, splprep  # here: scipy.interpolate takes ~0.5 s to import

    k = min(3, len(pts) - 1)
    tck, _ = splprep(pts.T, s=smoothing, per=int(closed), k=k)

    def curve(u, der):
        if der > k:
            return np.zeros((len(u), 2))
        return np.array(splev(u, tck, der=der)).T

    return curve


def _pchip_curve(pts: np.ndarray, closed: bool):
    """``curve(u, der)`` (n, 2): shape-preserving cubics x(t), y(t) through ``pts`` (closed: the
    last repeats the first) on the cumulative chord length t, u = t / t_end in [0, 1]."""
    from scipy.interpolate import PchipInterpolator

    if closed:  # the slopes are local (two neighbours each side): pad with the wrapped points
        pad = min(2, len(pts) - 2)
        ext = np.vstack([pts[-1 - pad : -1], pts, pts[1 : 1 + pad]])
    else:
        pad = 0
        ext = pts
    t = np.r_[0.0, np.cumsum(np.hypot(*np.diff(ext, axis=0).T))]
    t0, t1 = t[pad], t[len(t) - 1 - pad]
    f = PchipInterpolator(t, ext, axis=0)
    span = t1 - t0

    def curve(u, der):
        return f(t0 + np.asarray(u, float) * span, der) * span**der

    return curve


class WaypointPath(ReferencePath):
    """ReferencePath through waypoints ``points`` (M, 2) [m].

    ``interpolation`` chooses the curve, a function of the cumulative chord length t [m]:

    - ``"spline"``: a parametric cubic spline (``smoothing`` is scipy's ``splprep`` smoothing
      factor, 0 = interpolate). Smooth (curvature continuous) but it overshoots: through
      ``[[0, 0], [5, 0], [5, 5]]`` it bulges 0.6 m outside the corner and the first leg starts at
      -23 deg.
    - ``"pchip"``: x(t) and y(t) are each a shape-preserving piecewise cubic (scipy's
      ``PchipInterpolator``): it passes through every waypoint and never leaves the range of a
      coordinate between two waypoints, so straight legs stay straight and a corner stays a
      corner (the heading turns at the waypoint; the curvature table there is the heading change
      over one table step). Heading continuous, curvature piecewise continuous. ``smoothing``
      must be 0.

    The curve is re-parameterized by arc length and tabulated every ``ds_m`` metres; between
    table points position, heading and curvature are interpolated linearly (position error
    about kappa * ds^2 / 8). ``closed=True`` makes the curve periodic (the last point may repeat
    the first).
    """

    def __init__(
        self,
        points,
        closed: bool = False,
        smoothing: float = 0.0,
        ds_m: float | None = None,
        interpolation: str = "spline",
    ):
        pts = np.asarray(points, float)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"waypoints must have shape (M, 2), got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("waypoints contain non-finite values")
        if len(pts):
            pts = pts[np.r_[True, np.hypot(*np.diff(pts, axis=0).T) > 1e-9]]
        if closed and len(pts) > 2 and np.hypot(*(pts[0] - pts[-1])) < 1e-9:
            pts = pts[:-1]
        min_pts = 3 if closed else 2
        if len(pts) < min_pts:
            raise ValueError(
                f"{'a closed' if closed else 'an open'} path needs at least {min_pts} distinct points, got {len(pts)}"
            )
        if not np.isfinite(smoothing) or smoothing < 0:
            raise ValueError(f"smoothing must be >= 0, got {smoothing}")
        if ds_m is not None and not (np.isfinite(ds_m) and ds_m > 0):
            raise ValueError(f"ds_m must be a positive finite number, got {ds_m}")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        if interpolation == "pchip" and smoothing != 0:
            raise ValueError(
                f"smoothing applies to interpolation 'spline' only, got smoothing {smoothing} with 'pchip'"
            )
        self.closed = bool(closed)
        self.interpolation = interpolation
        self.waypoints = pts
        if closed:
            pts = np.vstack([pts, pts[:1]])
        curve = _pchip_curve(pts, closed) if interpolation == "pchip" else _spline_curve(pts, closed, smoothing)
        # arc length of the curve parameter u in [0, 1] by dense chord sums
        u_dense = np.linspace(0.0, 1.0, max(2000, 60 * len(pts)))
        p_dense = curve(u_dense, 0)
        s_dense = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p_dense, axis=0).T))]
        self.length_m = float(s_dense[-1])
        if ds_m is None:
            ds_m = float(np.clip(self.length_m / 20000.0, 0.002, 0.1))
        if interpolation == "pchip":
            # the parameter speed drops to zero at a corner: s(u) is far from linear there, so
            # the parameter is sampled a few times finer than the table before inverting s(u)
            u_dense = np.linspace(0.0, 1.0, max(len(u_dense), int(math.ceil(4.0 * self.length_m / ds_m)) + 1))
            p_dense = curve(u_dense, 0)
            s_dense = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p_dense, axis=0).T))]
            self.length_m = float(s_dense[-1])
        n = max(3, int(math.ceil(self.length_m / ds_m)) + 1)
        s_tab = np.linspace(0.0, self.length_m, n)
        u_tab = np.interp(s_tab, s_dense, u_dense)
        self._s = s_tab
        self._xy = np.ascontiguousarray(curve(u_tab, 0))
        self._ds = s_tab[1] - s_tab[0]
        d1 = curve(u_tab, 1)
        if interpolation == "pchip":
            # the parameter speed vanishes where x and y both turn at a waypoint (a corner): the
            # heading there is that of the neighbouring table points, the curvature the
            # heading's change per metre
            dx, dy = d1[:, 0], d1[:, 1]
            moving = np.hypot(dx, dy) > 1e-9 * max(1.0, float(np.max(np.hypot(dx, dy))))
            h = np.arctan2(dy, dx)
            if not np.all(moving):
                i = np.arange(len(h))
                h = np.interp(i, i[moving], np.unwrap(h[moving]))
            self._h = np.unwrap(h)
            self._k = np.gradient(self._h, s_tab)
        else:
            dx, dy = d1[:, 0], d1[:, 1]
            d2 = curve(u_tab, 2)
            self._h = np.unwrap(np.arctan2(dy, dx))
            self._k = (dx * d2[:, 1] - dy * d2[:, 0]) / np.maximum(np.hypot(dx, dy) ** 3, 1e-12)
        # total heading change per lap (a multiple of 2*pi on a closed path)
        self._lap_turn = 2.0 * math.pi * round((self._h[-1] - self._h[0]) / (2.0 * math.pi)) if closed else 0.0
        #: the scalars of the compiled description (paths.compiled.PathArrays.geo)
        #: (length, closed, table step, lap turn, longest table segment)
        seg = float(np.max(np.hypot(*np.diff(self._xy, axis=0).T)))
        self._geo = np.array([self.length_m, float(closed), self._ds, self._lap_turn, seg])

    # -- evaluation -----------------------------------------------------------------------
    def _split(self, s):
        s = np.asarray(s, float)
        if self.closed:
            laps = np.floor(s / self.length_m)
            return s - laps * self.length_m, laps
        return s, np.zeros_like(s)

    def position(self, s):
        s_loc, _ = self._split(s)
        x = np.interp(s_loc, self._s, self._xy[:, 0])
        y = np.interp(s_loc, self._s, self._xy[:, 1])
        p = np.stack([x, y], axis=-1)
        if not self.closed:
            h0, h1 = self._h[0], self._h[-1]
            before = np.minimum(s_loc, 0.0)[..., None]
            after = np.maximum(s_loc - self.length_m, 0.0)[..., None]
            p = p + before * np.array([math.cos(h0), math.sin(h0)]) + after * np.array([math.cos(h1), math.sin(h1)])
        return p

    def heading(self, s):
        s_loc, laps = self._split(s)
        h = np.interp(s_loc, self._s, self._h) + laps * self._lap_turn
        return float(h) if np.ndim(h) == 0 else h

    def curvature(self, s):
        s_loc, _ = self._split(s)
        k = np.interp(s_loc, self._s, self._k)
        if not self.closed:
            k = np.where((s_loc < 0) | (s_loc > self.length_m), 0.0, k)
        return float(k) if np.ndim(k) == 0 else k

    # -- projection -----------------------------------------------------------------------
    # one projection rule, compiled (paths.compiled), for this class and the compiled controller
    def _project_xy(self, xy, s_guess, window_m):
        if s_guess is None:  # every segment, no lap shift
            s_loc, e_y = _compiled.waypoints_project_local(
                self._geo, self._s, self._xy, 0.0, math.inf, float(xy[0]), float(xy[1])
            )
            return float(s_loc), float(e_y)
        s, e_y = _compiled.path_project(
            _compiled.KIND_WAYPOINTS,
            self._geo,
            self._s,
            self._xy,
            float(s_guess),
            float(window_m),
            float(xy[0]),
            float(xy[1]),
        )
        return float(s), float(e_y)

    def _project_track_xy(self, xy, s_guess, window_m, step_margin_m):
        s, e_y = np.empty(len(xy)), np.empty(len(xy))
        _compiled.waypoints_project_track(
            self._geo, self._s, self._xy, s_guess, window_m, step_margin_m, np.ascontiguousarray(xy), s, e_y
        )
        return s, e_y

    def _project_many_xy(self, xy, s_guess, window_m):
        s, e_y = np.empty(len(xy)), np.empty(len(xy))
        _compiled.waypoints_project_many(
            self._geo,
            self._s,
            self._xy,
            np.ascontiguousarray(s_guess, dtype=float),
            np.ascontiguousarray(window_m, dtype=float),
            np.ascontiguousarray(xy, dtype=float),
            s,
            e_y,
        )
        return s, e_y
