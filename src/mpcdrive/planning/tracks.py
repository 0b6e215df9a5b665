"""The obstacles' predicted Frenet boxes over the planner's horizon, in compiled code.

Each obstacle of an :class:`~mpcdrive.ocp.avoidance_compiled.ObstacleTable` that is present at
some time of the horizon is placed at each sample time ``t0 + k dt`` (its motion: standing,
constant velocity or a recorded trajectory, going on at its last velocity past the trajectory's
end where the obstacle's life does not end there), projected onto the reference path (the first pose
searched within range of the car, each later one near the one before) and given its box along
the path: centre (s, e) and half extents along and across the path at its yaw relative to the
path's heading, and that yaw with the obstacle's own half extents (its oriented box, which the
contact checks use inside the Frenet box). An obstacle is kept when it comes within ``range_m`` along the path and
``lateral_m`` across it at some sample; the nearest rows are kept when more than the work's
slots are in range. Whether a track stands over the horizon (:func:`_standing`) is read by the
passes, the stops and the checks alike.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..ocp.avoidance_compiled import SHAPE_CIRCLE, ObstacleTable, pose_at
from ..paths.compiled import PathArrays, path_eval, path_project
from .._subroutine import subroutine

#: the search margin [m] of each later pose of a track beyond the distance from the one before
TRACK_MARGIN_M = 2.0
#: a projection within this distance [m] of its search window's edge is searched again in a
#: wider window (the window covers whole segments beyond its ends: a nearest point found inside
#: it by more than this is a true local nearest point)
EDGE_M = 1e-6
#: the columns of a track's cache: arc length, offset, half extents along and across the path,
#: cosine and sine of the obstacle's yaw relative to the path
CACHE_COLS = 6
_NO_CACHE = np.zeros((0, 0, CACHE_COLS))
_NO_ORIENT = np.zeros((0, 0, 4))


@subroutine
def _standing(ob_s, o, K, dt):
    """Whether obstacle row ``o`` stands (moves less than 0.5 m over the horizon)."""
    lo, hi = math.inf, -math.inf
    for k in range(K + 1):
        if math.isfinite(ob_s[o, k]):
            lo = min(lo, ob_s[o, k])
            hi = max(hi, ob_s[o, k])
    return hi - lo < 0.5


@subroutine
def pose_ahead(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d):
    """:func:`~mpcdrive.ocp.avoidance_compiled.pose_at`, except that past the last sample of a
    predicted trajectory the obstacle goes on at that last segment's velocity (a prediction over
    the controller's 3 s horizon held still for the planner's 6 s would park every car at 3 s)."""
    lo, hi = tr_lo[j], tr_hi[j]
    if hi - lo >= 2 and t > tr_t[hi - 1]:
        h = tr_t[hi - 1] - tr_t[hi - 2]
        if h > 0.0:
            f = (t - tr_t[hi - 1]) / h
            return (
                pose[j, 0] + tr_d[hi - 1, 0] + f * (tr_d[hi - 1, 0] - tr_d[hi - 2, 0]),
                pose[j, 1] + tr_d[hi - 1, 1] + f * (tr_d[hi - 1, 1] - tr_d[hi - 2, 1]),
                pose[j, 2] + tr_d[hi - 1, 2],
            )
    return pose_at(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d)


def obstacle_tracks(
    tab: ObstacleTable,
    pa: PathArrays,
    t0_s: float,
    dt_s: float,
    s_m: float,
    xy_m: tuple[float, float],
    range_m: float,
    lateral_m: float,
    out_s: np.ndarray,
    out_e: np.ndarray,
    out_hl: np.ndarray,
    out_hw: np.ndarray,
    index: np.ndarray,
    cache: np.ndarray | None = None,
    cache_step_s: float = 0.0,
    out_or: np.ndarray | None = None,
) -> int:
    """Fill rows of ``out_*`` (O, K+1) with the tracks of the obstacles of ``tab`` in range of
    arc length ``s_m`` [m] (the car at ``xy_m`` [m]) at times ``t0_s + k dt_s`` [s] (NaN where
    absent); ``index`` (O,) gets each row's obstacle index. Returns the number of rows.
    ``out_or`` (O, K+1, 4), where given, gets each sample's oriented box: the cosine and sine
    of the obstacle's yaw relative to the path's heading, and its own half length and half width
    [m] (a disc: its radius, at yaw 0).

    ``cache`` (n, C, ``CACHE_COLS``) (NaN: empty) keeps each obstacle's box at the times ``i cache_step_s`` [s]
    (i < C) for the next calls (the same obstacles: a new table needs a new cache): when the
    times of the call lie on that grid, a box already computed is taken from it (a replanning
    every control step shares all but its last samples with the one before)."""
    n = len(tab.obstacles)
    if n == 0:
        return 0
    c0, c_step = -1, 0
    if cache is None or cache_step_s <= 0.0:
        cache = _NO_CACHE
    else:
        q0, qs = t0_s / cache_step_s, dt_s / cache_step_s
        if abs(q0 - round(q0)) < 1e-6 and abs(qs - round(qs)) < 1e-6 and round(qs) >= 1:
            c0, c_step = int(round(q0)), int(round(qs))
    return int(
        _tracks_kernel(
            pa.kind, pa.geo, pa.tab_s, pa.tab_xy, pa.tab_h, pa.tab_k, float(t0_s), float(dt_s), float(s_m),
            float(xy_m[0]), float(xy_m[1]), float(range_m), float(lateral_m), *tab.motion, tab.life, tab.has_life, tab.shape, tab.radius, tab.verts,
            tab.nverts, out_s, out_e, out_hl, out_hw, _NO_ORIENT if out_or is None else out_or, index, cache, c0,
            c_step,
        )
    )  # fmt: skip


@njit(cache=True)
def _tracks_kernel(
    kind, geo, tab_s, tab_xy, tab_h, tab_k, t0, dt, s_m, x_m, y_m, range_m, lateral_m, pose, vel, tr_lo, tr_hi, tr_t,
    tr_d, life, has_life, shape, radius, verts, nverts, out_s, out_e, out_hl, out_hw, out_or, index, cache, c0, c_step,
):  # fmt: skip
    rows, K1 = out_s.shape
    n_obs = pose.shape[0]
    dist = np.empty(rows)
    s_row = np.empty(K1)
    e_row = np.empty(K1)
    hl_row = np.empty(K1)
    hw_row = np.empty(K1)
    cos_row = np.empty(K1)
    sin_row = np.empty(K1)
    orient = out_or.shape[0] > 0
    t_end = t0 + (K1 - 1) * dt
    used = 0
    for j in range(n_obs):
        # an obstacle farther from the car than the range at the horizon's start, middle and end
        # (and where it exists) is not tracked
        far = True
        for q in range(3):
            t = t0 + 0.5 * q * (t_end - t0)
            if has_life[j]:
                t = min(max(t, life[j, 0]), life[j, 1])
                if life[j, 1] < t0 or life[j, 0] > t_end:
                    break
            x, y, _ = pose_ahead(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
            if math.hypot(x - x_m, y - y_m) <= range_m + lateral_m:
                far = False
                break
        if far:
            continue
        # its own half extents (a polygon's about its pose, in its frame)
        own_l, own_w = radius[j], radius[j]
        if shape[j] != SHAPE_CIRCLE:
            own_l, own_w = 0.0, 0.0
            for m in range(nverts[j]):
                own_l = max(own_l, abs(verts[j, m, 0]))
                own_w = max(own_w, abs(verts[j, m, 1]))
        # with every row in use, the track replaces the farthest one if it is nearer
        r = used if used < rows else -1
        # samples placed so far: from the second on, the guess goes on by the last step's way
        seen = 0
        guess, px, py, prev_s = s_m, 0.0, 0.0, s_m
        # the pose of the sample before, looked up only where a projection needs it (a cached
        # box needs none: with a replanning every control step most are cached)
        prev_t = math.nan
        near = math.inf
        keep = False
        for k in range(K1):
            t = t0 + k * dt
            s_row[k] = math.nan
            e_row[k] = math.nan
            hl_row[k] = math.nan
            hw_row[k] = math.nan
            cos_row[k] = 1.0
            sin_row[k] = 0.0
            if has_life[j] and not (life[j, 0] <= t and t <= life[j, 1]):
                continue
            ci = c0 + k * c_step if c0 >= 0 else -1
            if 0 <= ci < cache.shape[1] and math.isfinite(cache[j, ci, 0]):
                # the same obstacle at the same time, projected at an earlier replanning
                s, e, hl, hw = cache[j, ci, 0], cache[j, ci, 1], cache[j, ci, 2], cache[j, ci, 3]
                cos_row[k], sin_row[k] = cache[j, ci, 4], cache[j, ci, 5]
                guess = s + (s - prev_s if seen > 0 else 0.0)
                seen += 1
                prev_s = s
                prev_t = t
                s_row[k], e_row[k], hl_row[k], hw_row[k] = s, e, hl, hw
                ds = abs(s - s_m) - hl
                if ds <= range_m and abs(e) - hw <= lateral_m:
                    keep = True
                    near = min(near, max(ds, 0.0) + max(abs(e) - hw, 0.0))
                continue
            x, y, yaw = pose_ahead(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
            way = 0.0
            if seen == 0:
                # the path between the car and the obstacle is about as long as the way between
                # them (a bend makes it longer: half as long again, and a lane's width)
                window = min(range_m, 1.5 * math.hypot(x - x_m, y - y_m) + 2.0 * lateral_m)
            else:
                # near where the last step's motion along the path takes it (a car driving along
                # the road), within the margin and a tenth of its way (one crossing it); from
                # the first sample, whose guess has no motion yet, within its whole way
                if not math.isnan(prev_t):  # the sample before was cached
                    px, py = pose_ahead(j, prev_t, pose, vel, tr_lo, tr_hi, tr_t, tr_d)[:2]
                way = math.hypot(x - px, y - py)
                window = (0.1 * way if seen > 1 else way) + TRACK_MARGIN_M
            s, e = path_project(kind, geo, tab_s, tab_xy, guess, window, x, y)
            if seen > 0 and abs(s - guess) >= window - EDGE_M:
                # at the window's edge: the nearest point may lie beyond it (a car that turns
                # off the road it drove along, crossing the path, leaves the guess its motion
                # along the path gave). Search again within its whole way from the last sample.
                wide = window + abs(guess - prev_s) + way + TRACK_MARGIN_M
                s, e = path_project(kind, geo, tab_s, tab_xy, guess, wide, x, y)
            guess = s + (s - prev_s if seen > 0 else 0.0)
            seen += 1
            prev_s, px, py, prev_t = s, x, y, math.nan
            s_row[k] = s
            e_row[k] = e
            if shape[j] == SHAPE_CIRCLE:
                hl, hw = radius[j], radius[j]
            else:
                dyaw = yaw - path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, s)[2]
                c, sn = math.cos(dyaw), math.sin(dyaw)
                cos_row[k], sin_row[k] = c, sn
                hl, hw = 0.0, 0.0
                for m in range(nverts[j]):
                    vx, vy = verts[j, m, 0], verts[j, m, 1]
                    hl = max(hl, abs(c * vx - sn * vy))
                    hw = max(hw, abs(sn * vx + c * vy))
            hl_row[k] = hl
            hw_row[k] = hw
            if 0 <= ci < cache.shape[1]:
                cache[j, ci, 0], cache[j, ci, 1], cache[j, ci, 2], cache[j, ci, 3] = s, e, hl, hw
                cache[j, ci, 4], cache[j, ci, 5] = cos_row[k], sin_row[k]
            ds = abs(s - s_m) - hl
            if ds <= range_m and abs(e) - hw <= lateral_m:
                keep = True
                near = min(near, max(ds, 0.0) + max(abs(e) - hw, 0.0))
        if not keep:
            continue
        if r < 0:
            far = 0
            for q in range(1, rows):
                if dist[q] > dist[far]:
                    far = q
            if near >= dist[far]:
                continue
            r = far
        else:
            used += 1
        dist[r] = near
        index[r] = j
        for k in range(K1):
            out_s[r, k] = s_row[k]
            out_e[r, k] = e_row[k]
            out_hl[r, k] = hl_row[k]
            out_hw[r, k] = hw_row[k]
            if orient:
                out_or[r, k, 0] = cos_row[k]
                out_or[r, k, 1] = sin_row[k]
                out_or[r, k, 2] = own_l
                out_or[r, k, 3] = own_w
    return min(used, rows)


def _refresh_cache() -> None:
    from .. import _jitcache
    from ..ocp import avoidance_compiled as _ac
    from ..paths import compiled as _paths_compiled, profile_compiled as _profile_compiled

    files = [m.__file__ for m in (_ac, _paths_compiled, _profile_compiled) if m.__file__ is not None]
    _jitcache.refresh(_tracks_kernel, files)


_refresh_cache()
