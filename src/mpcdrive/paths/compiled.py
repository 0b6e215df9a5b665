"""Compiled (numba) path geometry for the fast controller: projection and evaluation of the
straight, circle and waypoint paths, reproducing their ``project``, ``position``, ``heading``
and ``curvature`` (tested against them).

A path is described to compiled code by :class:`PathArrays`: ``kind``; ``geo``, a float array
of scalars; and, for waypoint paths, the arc-length tables (``tab_s`` (M,), ``tab_xy`` (M, 2),
``tab_h`` (M,) unwrapped heading, ``tab_k`` (M,) curvature); one-element dummies otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .._subroutine import subroutine

KIND_STRAIGHT = 0  # geo: [start x, start y, t x, t y, n x, n y, heading, length]
KIND_CIRCLE = 1  # geo: [centre x, centre y, radius, sign, start angle, length]
KIND_WAYPOINTS = 2  # geo: [length, closed, ds, lap turn, longest segment]

_PI = math.pi
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class PathArrays:
    kind: int
    geo: np.ndarray
    tab_s: np.ndarray
    tab_xy: np.ndarray
    tab_h: np.ndarray
    tab_k: np.ndarray


def path_arrays(path) -> PathArrays | None:
    """The compiled description of ``path``, or None for a path type compiled code lacks."""
    # the path classes are imported here: the waypoint path projects with this module's kernel
    from .circle import CirclePath
    from .straight import StraightPath
    from .waypoints import WaypointPath

    one, one2 = np.zeros(1), np.zeros((1, 2))
    if type(path) is StraightPath:
        geo = np.array([*path.start, *path.t, *path.n, path._heading, path.length_m])
        return PathArrays(KIND_STRAIGHT, geo, one, one2, one, one)
    if type(path) is CirclePath:
        geo = np.array([*path.center, path.radius_m, path.sign, path.start_angle_rad, path.length_m])
        return PathArrays(KIND_CIRCLE, geo, one, one2, one, one)
    if type(path) is WaypointPath:
        return PathArrays(
            KIND_WAYPOINTS,
            path._geo,
            np.ascontiguousarray(path._s),
            np.ascontiguousarray(path._xy),
            np.ascontiguousarray(path._h),
            np.ascontiguousarray(path._k),
        )
    return None


@subroutine
def wrap_angle(a):
    """``mpcdrive.units.wrap_angle`` for one angle [rad]: to (-pi, pi]."""
    w = np.mod(a + _PI, _TWO_PI) - _PI
    if w <= -_PI:
        w += _TWO_PI
    return w


@subroutine
def _interp(s, tab_s, vals, ds):
    """np.interp on a uniform table (clamped at both ends)."""
    m = tab_s.shape[0]
    if s <= tab_s[0]:
        return vals[0]
    if s >= tab_s[m - 1]:
        return vals[m - 1]
    i = int((s - tab_s[0]) / ds)
    if i > m - 2:
        i = m - 2
    # guard against rounding at the table points
    while i > 0 and s < tab_s[i]:
        i -= 1
    while i < m - 2 and s >= tab_s[i + 1]:
        i += 1
    t = (s - tab_s[i]) / (tab_s[i + 1] - tab_s[i])
    return vals[i] + t * (vals[i + 1] - vals[i])


@subroutine
def _interp_xy(s, tab_s, xy, ds):
    m = tab_s.shape[0]
    if s <= tab_s[0]:
        return xy[0, 0], xy[0, 1]
    if s >= tab_s[m - 1]:
        return xy[m - 1, 0], xy[m - 1, 1]
    i = int((s - tab_s[0]) / ds)
    if i > m - 2:
        i = m - 2
    while i > 0 and s < tab_s[i]:
        i -= 1
    while i < m - 2 and s >= tab_s[i + 1]:
        i += 1
    t = (s - tab_s[i]) / (tab_s[i + 1] - tab_s[i])
    return xy[i, 0] + t * (xy[i + 1, 0] - xy[i, 0]), xy[i, 1] + t * (xy[i + 1, 1] - xy[i, 1])


@subroutine
def _split(geo, s):
    """(local s, laps) on a closed waypoint path; (s, 0) on an open one."""
    if geo[1] != 0.0:
        laps = math.floor(s / geo[0])
        return s - laps * geo[0], laps
    return s, 0.0


@subroutine
def path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, s):
    """(x [m], y [m], heading [rad] continuous in s, curvature [1/m]) at arc length s [m]."""
    if kind == KIND_STRAIGHT:
        return geo[0] + s * geo[2], geo[1] + s * geo[3], geo[6], 0.0
    if kind == KIND_CIRCLE:
        r, sg = geo[2], geo[3]
        th = geo[4] + sg * s / r
        return geo[0] + r * math.cos(th), geo[1] + r * math.sin(th), th + sg * 0.5 * _PI, sg / r
    L, ds = geo[0], geo[2]
    s_loc, laps = _split(geo, s)
    x, y = _interp_xy(s_loc, tab_s, tab_xy, ds)
    h = _interp(s_loc, tab_s, tab_h, ds) + laps * geo[3]
    k = _interp(s_loc, tab_s, tab_k, ds)
    if geo[1] == 0.0:
        m = tab_s.shape[0]
        if s_loc < 0.0:
            x += s_loc * math.cos(tab_h[0])
            y += s_loc * math.sin(tab_h[0])
            k = 0.0
        elif s_loc > L:
            x += (s_loc - L) * math.cos(tab_h[m - 1])
            y += (s_loc - L) * math.sin(tab_h[m - 1])
            k = 0.0
    return x, y, h, k


@subroutine
def _lap_shift(geo_len, closed, s_local, s_guess):
    if not closed:
        return s_local
    return s_local + geo_len * np.rint((s_guess - s_local) / geo_len)


@subroutine
def path_project(kind, geo, tab_s, tab_xy, s_guess, window_m, px, py):
    """(s [m], e_y [m]) of the nearest path point to (px, py) searched within s_guess +- window_m,
    as ``Path.project(xy, s_guess, window_m)``."""
    if kind == KIND_STRAIGHT:
        dx, dy = px - geo[0], py - geo[1]
        return dx * geo[2] + dy * geo[3], dx * geo[4] + dy * geo[5]
    if kind == KIND_CIRCLE:
        dx, dy = px - geo[0], py - geo[1]
        rho = math.hypot(dx, dy)
        th = math.atan2(dy, dx)
        r, sg, L = geo[2], geo[3], geo[5]
        s_local = np.mod(sg * (th - geo[4]) * r, L)
        return _lap_shift(L, True, s_local, s_guess), sg * (r - rho)
    s_loc, e_y = waypoints_project_local(geo, tab_s, tab_xy, s_guess, window_m, px, py)
    return _lap_shift(geo[0], geo[1] != 0.0, s_loc, s_guess), e_y


@subroutine
def _segment_d2(tab_xy, j, m, closed, px, py):
    """Squared distance from (px, py) to segment j of a waypoint path's ``m`` segments (those at
    the ends of an open path extended along their tangents), with its parameter t, squared
    length and the offset (rx, ry) from its nearest point."""
    p0x, p0y = tab_xy[j, 0], tab_xy[j, 1]
    dx, dy = tab_xy[j + 1, 0] - p0x, tab_xy[j + 1, 1] - p0y
    qx, qy = px - p0x, py - p0y
    dd = dx * dx + dy * dy
    t_raw = (qx * dx + qy * dy) / dd
    t = min(max(t_raw, 0.0), 1.0)
    if not closed:
        if j == 0 and t_raw < 0.0:
            t = t_raw
        if j == m - 1 and t_raw > 1.0:
            t = t_raw
    rx, ry = qx - t * dx, qy - t * dy
    return rx * rx + ry * ry, t, dd, rx, ry


@subroutine
def waypoints_project_local(geo, tab_s, tab_xy, s_guess, window_m, px, py):
    """(local s [m], e_y [m]) of the nearest point of a waypoint path (``geo``, tables as
    :class:`PathArrays`) to (px, py), searched on the segments within s_guess +- window_m
    (every segment when 2 window_m >= the length: pass an infinite window without a guess); the
    first of equally near segments wins. The end segments of an open path extend along their
    tangents. ``s`` is not shifted by laps (:func:`path_project` does that)."""
    L, closed, ds = geo[0], geo[1] != 0.0, geo[2]
    m = tab_s.shape[0] - 1  # segments
    if 2.0 * window_m >= L:
        i0, i1 = 0, m - 1
    else:
        s_loc = _split(geo, s_guess)[0]
        i0 = int(math.floor((s_loc - window_m) / ds))
        i1 = int(math.ceil((s_loc + window_m) / ds))
        if not closed:
            i0 = min(max(i0, 0), m - 1)
            i1 = min(max(i1, 0), m - 1)
    # segments far from the point are stepped over: every point of the segments i..i+n-1 lies
    # within n c of segment i's start (c = geo[4], the longest segment), so while the point is
    # farther than that from segment i's start plus a distance some segment reaches, none of
    # them is nearer. That distance comes first from every k-th segment (k ~ sqrt of their
    # number), then from the nearest segment so far. The end segments (which an open path
    # extends) are always searched, and skipped segments are strictly farther: the result is
    # that of the full scan.
    c = geo[4]
    bound = math.inf
    skip = i1 - i0 + 1 > 64  # (a short window is scanned: the test costs more than it saves)
    if skip:
        stride = int(math.sqrt(i1 - i0 + 1))
        for ii in range(i0, i1 + 1, stride):
            bound = min(bound, _segment_d2(tab_xy, ii % m if closed else ii, m, closed, px, py)[0])
    best, bj, bt, bdd, brx, bry = math.inf, 0, 0.0, 1.0, 0.0, 0.0
    ii = i0
    while ii <= i1:
        j = ii % m if closed else ii
        if skip and ii < i1 and (closed or ii > 0):
            qx, qy = px - tab_xy[j, 0], py - tab_xy[j, 1]
            r0 = math.sqrt(qx * qx + qy * qy)
            n_far = int((r0 - math.sqrt(min(best, bound)) - 1e-9 * (1.0 + r0)) / c) - 1
            if n_far > 0:
                ii = min(ii + n_far, i1)
                continue
        ii += 1
        d2, t, dd, rx, ry = _segment_d2(tab_xy, j, m, closed, px, py)
        if d2 < best:
            best, bj, bt, bdd, brx, bry = d2, j, t, dd, rx, ry
    sd = math.sqrt(bdd)
    segx = (tab_xy[bj + 1, 0] - tab_xy[bj, 0]) / sd
    segy = (tab_xy[bj + 1, 1] - tab_xy[bj, 1]) / sd
    return tab_s[bj] + bt * sd, segx * bry - segy * brx


@njit(cache=True)
def waypoints_project_many(geo, tab_s, tab_xy, s_guess, window_m, xy, out_s, out_e):
    """:func:`path_project` of the waypoint path for the points ``xy`` (K, 2) [m], point k
    searched near ``s_guess[k]`` within ``window_m[k]``, into ``out_s``, ``out_e`` (K,)."""
    L, closed = geo[0], geo[1] != 0.0
    for k in range(xy.shape[0]):
        s_loc, e_y = waypoints_project_local(geo, tab_s, tab_xy, s_guess[k], window_m[k], xy[k, 0], xy[k, 1])
        out_s[k] = _lap_shift(L, closed, s_loc, s_guess[k])
        out_e[k] = e_y


@njit(cache=True)
def waypoints_project_track(geo, tab_s, tab_xy, s_guess, window_m, step_margin_m, xy, out_s, out_e):
    """``ReferencePath.project_track`` of the waypoint path: point 0 searched near ``s_guess``
    within ``window_m``, point k near point k-1's s within their distance plus
    ``step_margin_m``, into ``out_s``, ``out_e`` (K,)."""
    L, closed = geo[0], geo[1] != 0.0
    guess, window = s_guess, window_m
    for k in range(xy.shape[0]):
        if k > 0:
            window = math.hypot(xy[k, 0] - xy[k - 1, 0], xy[k, 1] - xy[k - 1, 1]) + step_margin_m
        s_loc, e_y = waypoints_project_local(geo, tab_s, tab_xy, guess, window, xy[k, 0], xy[k, 1])
        out_s[k] = _lap_shift(L, closed, s_loc, guess)
        out_e[k] = e_y
        guess = out_s[k]
