"""The obstacles' predicted Frenet boxes over the planner's horizon, in compiled code.

Each obstacle of an :class:`~mpcdrive.ocp.avoidance_compiled.ObstacleTable` that is present at
some time of the horizon is placed at each sample time ``t0 + k dt`` (its motion: standing,
constant velocity or a recorded trajectory), projected onto the reference path (the first pose
searched within range of the car, each later one near the one before) and given its box along
the path: centre (s, e) and half extents along and across the path at its yaw relative to the
path's heading. An obstacle is kept when it comes within ``range_m`` along the path and
``lateral_m`` across it at some sample; the nearest rows are kept when more than the work's
slots are in range.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..ocp.avoidance_compiled import SHAPE_CIRCLE, ObstacleTable, pose_at
from ..paths.compiled import PathArrays, path_eval, path_project

#: the search margin [m] of each later pose of a track beyond the distance from the one before
TRACK_MARGIN_M = 2.0


def obstacle_tracks(
    tab: ObstacleTable,
    pa: PathArrays,
    t0_s: float,
    dt_s: float,
    s_m: float,
    range_m: float,
    lateral_m: float,
    out_s: np.ndarray,
    out_e: np.ndarray,
    out_hl: np.ndarray,
    out_hw: np.ndarray,
    index: np.ndarray,
) -> int:
    """Fill rows of ``out_*`` (O, K+1) with the tracks of the obstacles of ``tab`` in range of
    arc length ``s_m`` [m] at times ``t0_s + k dt_s`` [s] (NaN where absent); ``index`` (O,) gets
    each row's obstacle index. Returns the number of rows."""
    n = len(tab.obstacles)
    if n == 0:
        return 0
    return int(
        _tracks_kernel(
            pa.kind, pa.geo, pa.tab_s, pa.tab_xy, pa.tab_h, pa.tab_k, float(t0_s), float(dt_s), float(s_m),
            float(range_m), float(lateral_m), *tab.motion, tab.life, tab.has_life, tab.shape, tab.radius, tab.verts,
            tab.nverts, out_s, out_e, out_hl, out_hw, index,
        )
    )  # fmt: skip


@njit(cache=True)
def _tracks_kernel(
    kind, geo, tab_s, tab_xy, tab_h, tab_k, t0, dt, s_m, range_m, lateral_m, pose, vel, tr_lo, tr_hi, tr_t, tr_d,
    life, has_life, shape, radius, verts, nverts, out_s, out_e, out_hl, out_hw, index,
):  # fmt: skip
    rows, K1 = out_s.shape
    n_obs = pose.shape[0]
    dist = np.empty(rows)
    used = 0
    for j in range(n_obs):
        # with every row in use, the track replaces the farthest one if it is nearer
        r = used if used < rows else -1
        s_row = np.empty(K1)
        e_row = np.empty(K1)
        hl_row = np.empty(K1)
        hw_row = np.empty(K1)
        guess, window, px, py, first = s_m, range_m, 0.0, 0.0, True
        near = math.inf
        keep = False
        for k in range(K1):
            t = t0 + k * dt
            s_row[k] = math.nan
            e_row[k] = math.nan
            hl_row[k] = math.nan
            hw_row[k] = math.nan
            if has_life[j] and not (life[j, 0] <= t and t <= life[j, 1]):
                continue
            x, y, yaw = pose_at(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
            if not first:
                window = math.hypot(x - px, y - py) + TRACK_MARGIN_M
            s, e = path_project(kind, geo, tab_s, tab_xy, guess, window, x, y)
            first = False
            guess, px, py = s, x, y
            s_row[k] = s
            e_row[k] = e
            if shape[j] == SHAPE_CIRCLE:
                hl, hw = radius[j], radius[j]
            else:
                dyaw = yaw - path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, s)[2]
                c, sn = math.cos(dyaw), math.sin(dyaw)
                hl, hw = 0.0, 0.0
                for m in range(nverts[j]):
                    vx, vy = verts[j, m, 0], verts[j, m, 1]
                    hl = max(hl, abs(c * vx - sn * vy))
                    hw = max(hw, abs(sn * vx + c * vy))
            hl_row[k] = hl
            hw_row[k] = hw
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
    return min(used, rows)


def _refresh_cache() -> None:
    from .. import _jitcache
    from ..ocp import avoidance_compiled as _ac
    from ..paths import compiled as _paths_compiled

    files = [m.__file__ for m in (_ac, _paths_compiled) if m.__file__ is not None]
    _jitcache.refresh(_tracks_kernel, files)


_refresh_cache()
