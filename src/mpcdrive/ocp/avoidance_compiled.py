"""Compiled (numba) kernels of :mod:`mpcdrive.ocp.avoidance` for its hot, per-step part: the
obstacle selection, the horizon tracks (placement and Frenet boxes) of static,
constant-velocity and recorded-trajectory obstacles, and the hard avoidance rows, on the paths
:func:`mpcdrive.paths.compiled.path_arrays` describes (straight, circle, waypoints).

The selection, tracks and rows are the compiled form of the numpy code kept in ``ocp.avoidance``
(``Avoidance.relevant``, ``Avoidance._tracks``, ``Avoidance._hard_rows``), which still serves
every other case (motions of other types, other path types) and is the reference they are
tested against. The decisions of a step -- which side to pass each obstacle on
(:func:`pick_side`, also the rule of the compiled detour), which to yield to, which car follows
in the lane, where a stop line can go -- exist only here (:func:`decide`), for every case. Obstacles are described by arrays (see :class:`ObstacleTable`),
the considered ones in the order of ``relevant``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .._subroutine import subroutine
from ..paths.compiled import path_eval, path_project
from ..paths.profile_compiled import bracket, lerp
from ..scene.road import _interp
from ..scene.obstacles import Circle, ConstantVelocity, Obstacle, Static, TrajectoryMotion

SHAPE_CIRCLE, SHAPE_POLYGON = 0, 1
#: the passing side of an obstacle (``SIDE_NONE``: none decided yet)
SIDE_LEFT, SIDE_RIGHT, SIDE_BLOCKED, SIDE_NONE = 1, -1, 0, 2
#: the row of an obstacle: avoid it (nearest-point or lateral half-plane), stop behind it
#: (blocked lane ahead), keep ahead of it (a car following in the lane)
MODE_AVOID, MODE_STOP, MODE_AHEAD = 0, 1, 2
#: the fields of a Frenet box, in the order of ``box`` arrays (n, 5, K)
BOX_S_REF, BOX_S_LO, BOX_S_HI, BOX_E_LO, BOX_E_HI = 0, 1, 2, 3, 4
#: an obstacle whose box moves less than this along the path per step [m] is standing (a parked
#: car, a recorded one jittering by centimetres)
STANDING_STEP_M = 0.05


@dataclass(frozen=True, eq=False)
class ObstacleTable:
    """The obstacles of a list as arrays, obstacle j in row j: ``pose`` (n, 3) at t = 0, ``vel``
    (n, 2) world velocity [m/s] (0 when static or recorded), ``moving`` (n,), ``simple`` (n,)
    (a motion the kernels evaluate: static, constant velocity or a recorded trajectory),
    ``shape`` (n,) (SHAPE_*), ``radius`` (n,) (circles), ``verts`` (n, V, 2) body-frame
    vertices of polygons (the first ``nverts`` (n,) of V), ``bound_r`` (n,) bounding radii,
    ``life`` (n, 2) lifetimes, ``has_life`` (n,). A recorded trajectory's samples are rows
    ``tr_lo[j]:tr_hi[j]`` of ``tr_t`` (T,) [s] and ``tr_d`` (T, 3) (dx m, dy m, dyaw rad);
    ``tr_lo == tr_hi`` for the other motions (see :func:`pose_at`). ``all_simple``: every
    obstacle is simple. ``obstacles`` keeps the list it was made of."""

    obstacles: tuple
    pose: np.ndarray
    vel: np.ndarray
    moving: np.ndarray
    simple: np.ndarray
    shape: np.ndarray
    radius: np.ndarray
    verts: np.ndarray
    nverts: np.ndarray
    bound_r: np.ndarray
    life: np.ndarray
    has_life: np.ndarray
    tr_lo: np.ndarray
    tr_hi: np.ndarray
    tr_t: np.ndarray
    tr_d: np.ndarray
    all_simple: bool

    @property
    def motion(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The arguments of :func:`pose_at` after the obstacle and the time."""
        return self.pose, self.vel, self.tr_lo, self.tr_hi, self.tr_t, self.tr_d


def obstacle_table(obstacles: list[Obstacle]) -> ObstacleTable:
    """The :class:`ObstacleTable` of ``obstacles``."""
    n = len(obstacles)
    V = max([3] + [len(ob.shape.points) for ob in obstacles if not isinstance(ob.shape, Circle)])
    pose, vel, verts, life = np.zeros((n, 3)), np.zeros((n, 2)), np.zeros((n, V, 2)), np.zeros((n, 2))
    moving, simple, has_life = np.zeros(n, np.bool_), np.zeros(n, np.bool_), np.zeros(n, np.bool_)
    shape, nverts = np.zeros(n, np.int64), np.zeros(n, np.int64)
    radius, bound_r = np.zeros(n), np.zeros(n)
    tr_lo, tr_hi = np.zeros(n, np.int64), np.zeros(n, np.int64)
    tr_t: list[np.ndarray] = []
    tr_d: list[np.ndarray] = []
    used = 0
    for j, ob in enumerate(obstacles):
        pose[j] = ob.pose
        moving[j] = ob.moving
        m = ob.motion
        tr_lo[j] = used
        if type(m) is ConstantVelocity:
            vel[j] = m.vx_mps, m.vy_mps
        elif type(m) is TrajectoryMotion:
            used += len(m.t_s)
            tr_t.append(m.t_s)
            tr_d.append(np.stack([m.dx_m, m.dy_m, m.dyaw_rad], axis=1))
        tr_hi[j] = used
        simple[j] = type(m) in (Static, ConstantVelocity, TrajectoryMotion)
        if isinstance(ob.shape, Circle):
            shape[j], radius[j] = SHAPE_CIRCLE, ob.shape.radius_m
        else:
            pts = np.asarray(ob.shape.points, float)
            shape[j], nverts[j] = SHAPE_POLYGON, len(pts)
            verts[j, : len(pts)] = pts
        bound_r[j] = ob.shape.bounding_radius_m
        life[j] = ob.t_start_s, ob.t_end_s
        has_life[j] = ob.has_lifetime
    return ObstacleTable(
        tuple(obstacles),
        pose,
        vel,
        moving,
        simple,
        shape,
        radius,
        verts,
        nverts,
        bound_r,
        life,
        has_life,
        tr_lo,
        tr_hi,
        np.concatenate(tr_t) if tr_t else np.zeros(1),
        np.concatenate(tr_d) if tr_d else np.zeros((1, 3)),
        bool(simple.all()),
    )


def table_of(obstacles, cached: ObstacleTable | None) -> ObstacleTable:
    """``cached`` if it describes these very ``obstacles`` (the same objects, in order), else
    their new :class:`ObstacleTable` (it holds them: the identities stay unique)."""
    if cached is not None and cached.obstacles is obstacles:  # the tuple it was built from
        return cached
    if cached is not None and len(cached.obstacles) == len(obstacles):
        if all(a is b for a, b in zip(cached.obstacles, obstacles)):
            return cached
    return obstacle_table(obstacles)


@subroutine
def pose_at(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d):
    """Pose (x m, y m, yaw rad) of obstacle j of a :class:`ObstacleTable` at time ``t`` [s]
    (``Obstacle.pose_at``): a recorded trajectory interpolated linearly in time, held before its
    first and after its last sample (as ``np.interp``); else ``pose + vel t``."""
    lo, hi = tr_lo[j], tr_hi[j]
    if hi == lo:
        return pose[j, 0] + vel[j, 0] * t, pose[j, 1] + vel[j, 1] * t, pose[j, 2] + 0.0
    # np.interp of the three columns, their common sample searched once
    if t != t:
        return pose[j, 0] + t, pose[j, 1] + t, pose[j, 2] + t
    if t < tr_t[lo]:
        k = lo
    elif t >= tr_t[hi - 1]:
        k = hi - 1
    else:
        k = bracket(tr_t, lo, hi - 1, t)
        if tr_t[k] != t:
            t0, t1 = tr_t[k], tr_t[k + 1]
            return (
                pose[j, 0] + lerp(t, t0, t1, tr_d[k, 0], tr_d[k + 1, 0]),
                pose[j, 1] + lerp(t, t0, t1, tr_d[k, 1], tr_d[k + 1, 1]),
                pose[j, 2] + lerp(t, t0, t1, tr_d[k, 2], tr_d[k + 1, 2]),
            )
    return pose[j, 0] + tr_d[k, 0], pose[j, 1] + tr_d[k, 1], pose[j, 2] + tr_d[k, 2]


@njit(cache=True)
def select(t_s, x, y, t_end, reach, pose, vel, tr_lo, tr_hi, tr_t, tr_d, bound_r, life, has_life, max_n, out):
    """``Avoidance.relevant``: :func:`select_into` with its work array allocated here."""
    dist = np.empty(pose.shape[0])
    return select_into(
        t_s, x, y, t_end, reach, pose, vel, tr_lo, tr_hi, tr_t, tr_d, bound_r, life, has_life, max_n, out, dist
    )


@subroutine
def select_into(
    t_s, x, y, t_end, reach, pose, vel, tr_lo, tr_hi, tr_t, tr_d, bound_r, life, has_life, max_n, out, dist
):
    """The obstacles present at some time of [t_s, t_end] [s] whose pose at ``t_s`` minus the
    bounding radius ``bound_r`` (n,) lies within ``reach`` [m] of (x, y), nearest first (ties by
    index), at most ``max_n``, into ``out``; returns how many. pose ... tr_d: the motions
    (``ObstacleTable.motion``, :func:`pose_at`); life (n, 2) lifetimes [s], used where
    ``has_life``; dist (n,): work."""
    n = pose.shape[0]
    for j in range(n):
        dist[j] = math.inf
        if has_life[j] and (life[j, 1] < t_s or life[j, 0] > t_end):
            continue
        ox, oy, _ = pose_at(j, t_s, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
        d = math.hypot(ox - x, oy - y) - bound_r[j]
        if d <= reach:
            dist[j] = d
    count = 0
    while count < max_n:
        best = -1
        for j in range(n):
            if dist[j] < math.inf and (best < 0 or dist[j] < dist[best]):
                best = j
        if best < 0:
            break
        dist[best] = math.inf
        out[count] = best
        count += 1
    return count


@njit(cache=True)
def tracks(
    kind,
    geo,
    tab_s,
    tab_xy,
    tab_h,
    tab_k,
    t_s,
    dt_s,
    s_arr,
    sel,
    pose,
    vel,
    tr_lo,
    tr_hi,
    tr_t,
    tr_d,
    moving,
    shape,
    radius,
    verts,
    nverts,
    centers,
    outlines,
    box,
):
    """``Avoidance._tracks`` of the obstacles ``sel`` (n,) (motions as :func:`pose_at`) over the K =
    len(s_arr) horizon times ``t_s + k dt_s``: centres (n, K, 2), world vertices (n, K, V, 2) of
    polygons (the first ``nverts`` of V) and Frenet boxes (n, 5, K) (``frenet_boxes``: a disc's
    centre, a polygon's vertex mean projected near ``s_arr[k]``), into those arrays. A static
    obstacle is placed and projected once, near ``s_arr[0]``, and repeated."""
    K = s_arr.shape[0]
    for i in range(sel.shape[0]):
        j = sel[i]
        nk = K if moving[j] else 1
        nv = nverts[j]
        for k in range(nk):
            t = t_s + dt_s * k
            x, y, yaw = pose_at(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
            centers[i, k, 0] = x
            centers[i, k, 1] = y
            g = s_arr[k]
            gx, gy, _, _ = path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, g)
            if shape[j] == SHAPE_CIRCLE:
                r = radius[j]
                far = math.hypot(x - gx, y - gy)
                s, e = path_project(kind, geo, tab_s, tab_xy, g, max(2.0, 2 * r) + far, x, y)
                box[i, BOX_S_REF, k] = s
                box[i, BOX_S_LO, k] = s - r
                box[i, BOX_S_HI, k] = s + r
                box[i, BOX_E_LO, k] = e - r
                box[i, BOX_E_HI, k] = e + r
                continue
            c, sn = math.cos(yaw), math.sin(yaw)
            mx, my = 0.0, 0.0
            lo, hi = math.inf, -math.inf
            for m in range(nv):
                px, py = verts[j, m, 0], verts[j, m, 1]
                wx = x + c * px - sn * py
                wy = y + sn * px + c * py
                outlines[i, k, m, 0] = wx
                outlines[i, k, m, 1] = wy
                mx += wx
                my += wy
                lo = min(lo, wx, wy)
                hi = max(hi, wx, wy)
            mx /= nv
            my /= nv
            far = math.hypot(mx - gx, my - gy)
            s, _ = path_project(kind, geo, tab_s, tab_xy, g, 2.0 + (hi - lo) + far, mx, my)
            qx, qy, h, _ = path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, s)
            ch, sh = math.cos(h), math.sin(h)
            a_lo, a_hi, e_lo, e_hi = math.inf, -math.inf, math.inf, -math.inf
            for m in range(nv):
                dx = outlines[i, k, m, 0] - qx
                dy = outlines[i, k, m, 1] - qy
                along = dx * ch + dy * sh
                across = dy * ch - dx * sh
                a_lo = min(a_lo, along)
                a_hi = max(a_hi, along)
                e_lo = min(e_lo, across)
                e_hi = max(e_hi, across)
            box[i, BOX_S_REF, k] = s
            box[i, BOX_S_LO, k] = s + a_lo
            box[i, BOX_S_HI, k] = s + a_hi
            box[i, BOX_E_LO, k] = e_lo
            box[i, BOX_E_HI, k] = e_hi
        for k in range(nk, K):  # a static obstacle: the same at every time
            centers[i, k, 0] = centers[i, 0, 0]
            centers[i, k, 1] = centers[i, 0, 1]
            for m in range(nv):
                outlines[i, k, m, 0] = outlines[i, 0, m, 0]
                outlines[i, k, m, 1] = outlines[i, 0, m, 1]
            for f in range(5):
                box[i, f, k] = box[i, f, 0]


@subroutine
def _nearest(px, py, shape, radius, centers, outlines, nv, i, k):
    """Signed distance [m] and nearest boundary point of (px, py) to obstacle i at time k
    (``Avoidance._nearest``: a disc, or a convex ccw polygon as ``points_polygons``)."""
    if shape == SHAPE_CIRCLE:
        cx, cy = centers[i, k, 0], centers[i, k, 1]
        vx, vy = px - cx, py - cy
        n = max(math.hypot(vx, vy), 1e-12)
        return n - radius, cx + radius * vx / n, cy + radius * vy / n
    best, qx, qy = math.inf, 0.0, 0.0
    inside = True
    for m in range(nv):
        ax, ay = outlines[i, k, m, 0], outlines[i, k, m, 1]
        m1 = m + 1 if m + 1 < nv else 0
        dx, dy = outlines[i, k, m1, 0] - ax, outlines[i, k, m1, 1] - ay
        rx, ry = px - ax, py - ay
        t = min(max((rx * dx + ry * dy) / (dx * dx + dy * dy), 0.0), 1.0)
        cx, cy = ax + t * dx, ay + t * dy
        d = math.hypot(px - cx, py - cy)
        if d < best:
            best, qx, qy = d, cx, cy
        if not (dx * ry - dy * rx >= 0.0):
            inside = False
    return (-best if inside else best), qx, qy


@njit(cache=True)
def hard_rows(
    kind,
    geo,
    tab_s,
    tab_xy,
    tab_h,
    tab_k,
    Xlin,
    s_arr,
    offsets,
    r_disc,
    margin,
    half_length,
    influence,
    shape,
    radius,
    centers,
    outlines,
    nverts,
    box,
    side,
    mode,
    present,
    stop_gap,
    a,
    b,
):
    """``Avoidance._hard_rows``: the hard half-plane rows of the n considered obstacles (in row
    slots 0..n-1, disc d of slot i in row ``i * len(offsets) + d``) at steps 1..N, into a (N, M, 3)
    and b (N, M) (unused rows: 0 and -inf). Obstacle i: ``shape``, ``radius`` (n,), centres
    (n, N+1, 2), vertices (n, N+1, V, 2) (``nverts`` (n,) of them), Frenet boxes (n, 5, N+1),
    per step 1..N the passing ``side`` (n, N) (SIDE_*; a lateral row only for SIDE_LEFT /
    SIDE_RIGHT), the ``mode`` (n, N) (MODE_*) and ``present`` (n, N); a stop row keeps
    ``stop_gap`` [m] more before the obstacle."""
    N = a.shape[0]
    nd = offsets.shape[0]
    for k in range(N):
        for r in range(a.shape[1]):
            a[k, r, 0] = 0.0
            a[k, r, 1] = 0.0
            a[k, r, 2] = 0.0
            b[k, r] = -math.inf
    n_obs = shape.shape[0]
    if n_obs == 0:
        return
    r_need = r_disc + margin
    acc = 0.0
    for k in range(N):
        x0, y0, th = Xlin[k + 1, 0], Xlin[k + 1, 1], Xlin[k + 1, 2]
        ds = math.hypot(x0 - Xlin[k, 0], y0 - Xlin[k, 1])
        acc += ds
        s_lin = s_arr[0] + acc
        c, s = math.cos(th), math.sin(th)
        for i in range(n_obs):
            sd = side[i, k]
            md = mode[i, k]
            s_lo, s_hi, s_ref = box[i, BOX_S_LO, k + 1], box[i, BOX_S_HI, k + 1], box[i, BOX_S_REF, k + 1]
            # lateral from half a car length before a moving obstacle (a hedge on its prediction);
            # before a standing one from where the disc may reach its side by the next step
            moving = abs(s_ref - box[i, BOX_S_REF, k]) > STANDING_STEP_M
            reach = r_need + (half_length if moving else min(half_length, ds))
            e_edge = box[i, BOX_E_HI, k + 1] if sd == 1 else box[i, BOX_E_LO, k + 1]
            rx, ry, h, _ = path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, s_ref)
            nlx, nly = -math.sin(h), math.cos(h)
            qlx, qly = rx + nlx * e_edge, ry + nly * e_edge
            for d in range(nd):
                off = offsets[d]
                px, py = x0 + off * c, y0 + off * s
                s_disc = s_arr[k + 1] + off
                dist, qx, qy = _nearest(px, py, shape[i], radius[i], centers, outlines, nverts[i], i, k + 1)
                vx, vy = px - qx, py - qy
                nv = max(math.hypot(vx, vy), 1e-12)
                sg = 1.0 if dist >= 0 else -1.0
                nx, ny = vx / nv * sg, vy / nv * sg
                active = dist - r_disc <= influence
                s_near = s_lin + off  # where the plan has the disc
                if (sd == SIDE_LEFT or sd == SIDE_RIGHT) and s_lo - reach <= s_near and s_near <= s_hi + reach:
                    nx, ny = sd * nlx, sd * nly
                    qx, qy = qlx, qly
                    active = True
                if md != MODE_AVOID:
                    s_at = s_lin + off
                    if md == MODE_STOP:  # behind its near end at that step
                        s_end = s_lo - stop_gap
                        s_bar = min(s_at, s_end - r_need)
                    else:  # ahead of its far end, as far as the disc's reference goes
                        s_end = min(s_hi, s_disc - r_need)
                        s_bar = max(s_at, s_end + r_need)
                    bx, by, bh, _ = path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, s_bar)
                    tx, ty = math.cos(bh), math.sin(bh)
                    qx, qy = bx + tx * (s_end - s_bar), by + ty * (s_end - s_bar)
                    if md == MODE_STOP:
                        nx, ny = -tx, -ty
                    else:
                        nx, ny = tx, ty
                    active = True
                if not (active and present[i, k]):
                    continue
                ay = off * (-nx * s + ny * c)
                rhs = (nx * qx + ny * qy) + r_need - (nx * px + ny * py) + nx * x0 + ny * y0 + ay * th
                row = i * nd + d
                a[k, row, 0] = nx
                a[k, row, 1] = ny
                a[k, row, 2] = ay
                b[k, row] = rhs


@subroutine
def trapezoid_into(e_ref, s_arr, side, s_lo, s_hi, e_lo, e_hi, half_width, half_length, margin, ramp):
    """The paper's trapezoidal detour around one obstacle spanning [s_lo, s_hi] x [e_lo, e_hi]
    [m] along / across the path, passed on ``side`` (SIDE_LEFT, else right): the lateral shift
    that keeps ``2 margin`` plus half the body width beside it, held along it (and half the body
    length before and after) and ramping from 0 over ``ramp`` [m] before and after; written
    into ``e_ref`` (N+1,) at the references ``s_arr`` where it is larger in magnitude than what
    is there (the widest detour wins; a tie keeps the earlier obstacle's). Returns whether any
    written value is non-zero."""
    shift = (e_hi + half_width + 2.0 * margin) if side == SIDE_LEFT else (e_lo - half_width - 2.0 * margin)
    lo_s, hi_s = s_lo - half_length, s_hi + half_length
    rr = max(ramp, 1e-9)
    any_shift = False
    for k in range(e_ref.shape[0]):
        f = min(max(min((s_arr[k] - (lo_s - ramp)) / rr, ((hi_s + ramp) - s_arr[k]) / rr), 0.0), 1.0)
        cand = shift * f
        if abs(cand) > abs(e_ref[k]):
            e_ref[k] = cand
            any_shift = any_shift or cand != 0.0
    return any_shift


@njit(cache=True)
def detour_offsets(box, use, side, s_arr, half_width, half_length, margin, ramp, e_ref):
    """The detour of the row formulations: ``e_ref`` (N+1,) [m], the references' lateral shift
    (:func:`trapezoid_into`) around every obstacle i with ``use[i]`` passed on a side
    (``side[i]``; none for SIDE_BLOCKED), from its box now (``box`` (n, 5, N+1), time 0)."""
    for k in range(e_ref.shape[0]):
        e_ref[k] = 0.0
    for i in range(use.shape[0]):
        if use[i] and side[i] != SIDE_BLOCKED:
            trapezoid_into(
                e_ref, s_arr, side[i], box[i, BOX_S_LO, 0], box[i, BOX_S_HI, 0], box[i, BOX_E_LO, 0],
                box[i, BOX_E_HI, 0], half_width, half_length, margin, ramp,
            )  # fmt: skip


@njit(cache=True)
def corridor_bounds(box, use, side, present, s_arr, margin, half_length, half_width, lo, hi):
    """The corridor formulation's lateral bounds: ``lo``, ``hi`` (N,) [m], the bounds on e_y of
    steps 1..N (the road's on entry), narrowed in place by every obstacle i with ``use[i]``
    present at that step (``present`` (n, N) bool) whose box (``box`` (n, 5, N+1), BOX_* fields)
    reaches the step's reference arc length ``s_arr[k]`` within ``margin`` plus half the body
    length: passed on the left (``side[i]``, SIDE_*), e_y stays ``margin`` plus half the body
    width above the box; on the right, as far below it. Where the bounds cross, both are set to
    their middle (the tube stays non-empty; the slack handles the rest)."""
    N = lo.shape[0]
    n = use.shape[0]
    reach = margin + half_length
    clear = margin + half_width
    for k in range(1, N + 1):
        sk = s_arr[k]
        for i in range(n):
            if not use[i] or not present[i, k - 1]:
                continue
            if not (box[i, BOX_S_LO, k] - reach <= sk <= box[i, BOX_S_HI, k] + reach):
                continue
            if side[i] == SIDE_LEFT:
                lo[k - 1] = max(lo[k - 1], box[i, BOX_E_HI, k] + clear)
            elif side[i] == SIDE_RIGHT:
                hi[k - 1] = min(hi[k - 1], box[i, BOX_E_LO, k] - clear)
    for k in range(N):
        if lo[k] > hi[k]:
            mid = 0.5 * (lo[k] + hi[k])
            lo[k] = mid
            hi[k] = mid


@subroutine
def pick_side(prev, room_left, room_right, need):
    """The passing side of an obstacle with ``room_left`` / ``room_right`` [m] between it and
    the road's edges beside it, when passing needs ``need`` [m]: the side ``prev`` (SIDE_*)
    while it keeps the room, else the roomier side, SIDE_BLOCKED when neither has it."""
    if prev == SIDE_LEFT and room_left >= need:
        return SIDE_LEFT
    if prev == SIDE_RIGHT and room_right >= need:
        return SIDE_RIGHT
    if max(room_left, room_right) < need:
        return SIDE_BLOCKED
    return SIDE_LEFT if room_left >= room_right else SIDE_RIGHT


@njit(cache=True)
def decide(
    box, moving, s_arr, has_road, road_s, road_left, road_right, road_period, need, reach, dt, oncoming_mps,
    follow, e_car, half_width, half_length, stop_m, prev, side, following, ahead,
):  # fmt: skip
    """The decisions of ``ocp.avoidance.Avoidance.terms`` for n obstacles with Frenet boxes
    ``box`` (n, 5, K) over the horizon arc lengths ``s_arr`` (K,), ``moving`` (n,):

    - ``side`` (n,): SIDE_BLOCKED for an obstacle coming towards the car along its path or
      across its road (faster than ``oncoming_mps`` [m/s] where the car meets it: the step its
      reference is nearest to it, step 0 for a standing one) whose prediction is on the road
      where the car's reference is (within ``reach`` [m] along the path); else
      :func:`pick_side` at that step (``prev`` (n,): the sides of the step before, SIDE_NONE),
      the room beside it measured to the road's edges (tables ``road_*``; none without a road);
    - ``following`` (n,): with ``follow``, a car directly behind in the car's lane (its box now
      wholly behind the body's rear, overlapping the body's lateral extent around the car's
      offset ``e_car`` [m]; never at the start of an open path, ``s_arr[0]`` <= 0 and
      ``road_period`` = 0 -- the caller passes ``follow`` False there);
    - ``ahead`` (n,): a stop line is possible: its centre ahead of the car, its near end within
      ``stop_m`` [m] of the last reference."""
    n, K = box.shape[0], box.shape[2]
    s0, s_end = s_arr[0], s_arr[K - 1]
    for i in range(n):
        meet = 0
        if moving[i]:
            best = math.inf
            for k in range(K):
                d = abs(box[i, BOX_S_REF, k] - s_arr[k])
                if d < best:
                    best, meet = d, k
        blocked = False
        if has_road and K >= 2:
            k0, k1 = max(meet - 1, 0), min(meet + 1, K - 1)
            span = (k1 - k0) * dt
            v_s = (box[i, BOX_S_REF, k1] - box[i, BOX_S_REF, k0]) / span
            l0 = _interp(road_s, road_left, box[i, BOX_S_REF, k0], road_period)
            l1 = _interp(road_s, road_left, box[i, BOX_S_REF, k1], road_period)
            r0 = _interp(road_s, road_right, box[i, BOX_S_REF, k0], road_period)
            r1 = _interp(road_s, road_right, box[i, BOX_S_REF, k1], road_period)
            d_e = 0.5 * ((box[i, BOX_E_LO, k1] + box[i, BOX_E_HI, k1]) - (box[i, BOX_E_LO, k0] + box[i, BOX_E_HI, k0]))
            v_e = min(abs(d_e), abs(d_e - (l1 - l0)), abs(d_e - (r1 - r0))) / span
            if v_s <= -oncoming_mps or v_e >= oncoming_mps:
                for k in range(K):
                    if box[i, BOX_S_LO, k] - reach <= s_arr[k] <= box[i, BOX_S_HI, k] + reach:
                        sr = box[i, BOX_S_REF, k]
                        if box[i, BOX_E_LO, k] < _interp(road_s, road_left, sr, road_period) and box[
                            i, BOX_E_HI, k
                        ] > _interp(road_s, road_right, sr, road_period):
                            blocked = True
                            break
        if blocked:
            side[i] = SIDE_BLOCKED
        else:
            room_left = room_right = math.inf
            if has_road:
                sr = box[i, BOX_S_REF, meet]
                room_left = _interp(road_s, road_left, sr, road_period) - box[i, BOX_E_HI, meet]
                room_right = box[i, BOX_E_LO, meet] - _interp(road_s, road_right, sr, road_period)
            side[i] = pick_side(prev[i], room_left, room_right, need)
        following[i] = (
            follow
            and box[i, BOX_S_HI, 0] < s0 - half_length
            and box[i, BOX_E_LO, 0] < e_car + half_width
            and box[i, BOX_E_HI, 0] > e_car - half_width
        )
        ahead[i] = s0 <= box[i, BOX_S_REF, 0] and box[i, BOX_S_LO, 0] <= s_end + stop_m


def _refresh_cache() -> None:
    from .. import _jitcache
    from ..paths import compiled as _paths_compiled, profile_compiled as _profile_compiled
    from ..scene import road as _road

    # one file: one fingerprint for all its functions
    deps = (_paths_compiled, _profile_compiled, _road)
    _jitcache.refresh(hard_rows, [m.__file__ for m in deps if m.__file__ is not None])


_refresh_cache()
