"""The compiled obstacle cost terms of the step assembly (:mod:`mpcdrive.ocp.assembly`).

For the cost formulations of :mod:`mpcdrive.ocp.avoidance` (``potential``, eq. 55, and
``gaussian``, eq. 56), as that module computes them for the OSQP controller: which obstacles a
step considers (:func:`select_obstacles`), the paper's trapezoidal detour of the references
around static circles (:func:`detour`, :func:`shift_references`) and the cost's convex
second-order model at the linearization trajectory (:func:`obstacle_cost`). They read the
assembly's container (:class:`~mpcdrive.ocp.assembly.StepAssembly`, its struct ``asm``): its
obstacles (the arrays of :func:`cost_obstacle_arrays`: static, constant-velocity and recorded
motions, lifetimes, circles and polygons, evaluated by the kernels of
:mod:`mpcdrive.ocp.avoidance_compiled`), the cost's settings and the road.

Compiled with numba's on-disk cache, which numba keys to this file only: the cache is dropped
(by :mod:`mpcdrive._jitcache`) when a file whose code these functions link in changes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._subroutine import subroutine
from ..paths.compiled import path_eval, path_project
from ..scene.road import _interp
from .avoidance_compiled import (
    SHAPE_CIRCLE,
    SIDE_BLOCKED,
    obstacle_table,
    pick_side,
    pose_at,
    select_into,
    trapezoid_into,
)

#: obstacle cost formulations (``StepAssembly.obstacle_form``)
OBS_NONE, OBS_POTENTIAL, OBS_GAUSSIAN = 0, 1, 2


def cost_obstacle_arrays(obstacles) -> dict[str, Any]:
    """The ``ob_*`` fields of :class:`~mpcdrive.ocp.assembly.StepAssembly` for ``obstacles``: the
    arrays of their :class:`~mpcdrive.ocp.avoidance_compiled.ObstacleTable` (``has_life`` as
    int64: the containers hold float64 and int64 arrays)."""
    tab = obstacle_table(list(obstacles))
    return {
        f"ob_{k}": np.ascontiguousarray(getattr(tab, k), dtype=np.int64 if k == "has_life" else None)
        for k in _COST_FIELDS
    }


#: the fields of an ObstacleTable the compiled cost reads
_COST_FIELDS = (
    "pose",
    "vel",
    "tr_lo",
    "tr_hi",
    "tr_t",
    "tr_d",
    "bound_r",
    "life",
    "has_life",
    "shape",
    "radius",
    "verts",
    "nverts",
)


@subroutine
def select_obstacles(asm, t_s, x, s0):
    """The ``max_obstacles`` nearest obstacles present at some time of the horizon and within the
    influence distance of the vehicle at time ``t_s`` (nearest first, ties by index, as
    ``Avoidance.relevant``) into ``asm.osel``; returns how many. ``asm.oproj[j]`` = (s, e_y) [m]
    of each one's projected point now (its centre, or a polygon's vertex mean, as
    ``ocp.frenet.frenet_boxes`` projects it, searched near ``s0``)."""
    osel, oproj = asm.osel, asm.oproj
    nsel = select_into(
        t_s, x[0], x[1], t_s + asm.N * asm.dt, asm.obstacle_influence, asm.ob_pose, asm.ob_vel, asm.ob_tr_lo,
        asm.ob_tr_hi, asm.ob_tr_t, asm.ob_tr_d, asm.ob_bound_r, asm.ob_life, asm.ob_has_life, asm.omax, osel,
        asm.odist,
    )  # fmt: skip
    pkind, geo, tab_s, tab_xy, tab_h, tab_k = asm.path, asm.geo, asm.tab_s, asm.tab_xy, asm.tab_h, asm.tab_k
    px0, py0, _h0, _k0 = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s0)
    # the arrays as locals: a struct's field read in a loop costs a reference count
    pose, vel, tr_lo, tr_hi, tr_t, tr_d = asm.ob_pose, asm.ob_vel, asm.ob_tr_lo, asm.ob_tr_hi, asm.ob_tr_t, asm.ob_tr_d
    shape, radius, verts, nverts = asm.ob_shape, asm.ob_radius, asm.ob_verts, asm.ob_nverts
    for a in range(nsel):
        j = osel[a]
        ox, oy, oyaw = pose_at(j, t_s, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
        if shape[j] == SHAPE_CIRCLE:
            cx, cy, win = ox, oy, max(2.0, 2.0 * radius[j])
        else:  # the world outline now: its vertex mean, and its extent for the search window
            co, so = math.cos(oyaw), math.sin(oyaw)
            sx, sy, lo, hi = 0.0, 0.0, math.inf, -math.inf
            m = nverts[j]
            for v in range(m):
                wx = ox + co * verts[j, v, 0] - so * verts[j, v, 1]
                wy = oy + so * verts[j, v, 0] + co * verts[j, v, 1]
                sx += wx
                sy += wy
                lo = min(lo, wx, wy)
                hi = max(hi, wx, wy)
            cx, cy, win = sx / m, sy / m, 2.0 + (hi - lo)
        oproj[j, 0], oproj[j, 1] = path_project(
            pkind, geo, tab_s, tab_xy, s0, win + math.hypot(cx - px0, cy - py0), cx, cy
        )
    return nsel


@subroutine
def detour(asm, xref, sides):
    """The paper's trapezoidal detour around the selected (static, circular) obstacles, as
    ``ocp.avoidance``: pick each one's passing side (kept from ``sides`` while it has room
    between the obstacle and the road's edge beside it, ``lane`` = 1 when there is a road: the
    body's half width, the road's margin, the obstacle margin and the body's half width again),
    shift the references sideways over the obstacle with ramps before and after it, and turn
    their heading with the slope. ``xref`` (N+1, nx): the state references; ``sides``: the side
    memory per obstacle."""
    nsel, osel, oproj, N = asm.nsel, asm.osel, asm.oproj, asm.N
    s_arr, refs, e_ref, lane = asm.s_arr, asm.refs, asm.e_ref, asm.lane
    margin, hw, hl, ramp = asm.obstacle_margin, asm.half_width, asm.half_length, asm.detour_ramp
    road_s, road_l, road_r, period, edge = (
        asm.road_s,
        asm.road_left,
        asm.road_right,
        asm.road_period,
        asm.road_margin[0],
    )
    bound_r = asm.ob_bound_r
    need = margin + hw  # as Avoidance.passing_room_m for the cost formulations, less the edge's share
    for k in range(N + 1):
        e_ref[k] = 0.0
    any_shift = False
    for a in range(nsel):
        j = osel[a]
        r = bound_r[j]
        s_ref, e_c = oproj[j, 0], oproj[j, 1]
        e_lo, e_hi = e_c - r, e_c + r
        if lane:
            lim_l = _interp(road_s, road_l, s_ref, period) - hw - edge
            lim_r = _interp(road_s, road_r, s_ref, period) + hw + edge
            room_left, room_right = lim_l - e_hi, e_lo - lim_r
        else:
            room_left = room_right = math.inf
        side = pick_side(sides[j], room_left, room_right, need)
        sides[j] = side
        if side != SIDE_BLOCKED and trapezoid_into(
            e_ref, s_arr, side, s_ref - r, s_ref + r, e_lo, e_hi, hw, hl, margin, ramp
        ):
            any_shift = True
    if any_shift:
        shift_references(N, s_arr, refs, e_ref, xref)


@subroutine
def shift_references(N, s_arr, refs, e_ref, xref):
    """The detour: shift the state references sideways by ``e_ref`` (N+1,) [m] from the path
    points ``refs`` and turn their heading with the slope of the shift."""
    for k in range(N + 1):
        h = refs[k, 2]
        xref[k, 0] -= math.sin(h) * e_ref[k]
        xref[k, 1] += math.cos(h) * e_ref[k]
    for k in range(1, N + 1):
        xref[k, 2] += math.atan((e_ref[k] - e_ref[k - 1]) / max(s_arr[k] - s_arr[k - 1], 1e-9))


@subroutine
def obstacle_cost(asm, t_s, We, qt):
    """Add the potential (eq. 55) or Gaussian (eq. 56) cost of the selected obstacles, its
    second-order model at the linearization trajectory (x_k = Xbar[k], x_N = F[N-1]) with the
    Hessian projected onto the PSD cone, to the state cost ``x' We x - 2 qt' x`` of x_1..x_N, as
    ``ocp.avoidance`` does for the OSQP controller: each obstacle predicted by its motion, no cost
    at the steps outside its lifetime, Sigma aligned with the path where the obstacle is now."""
    form, nsel, osel, oproj, N = asm.obstacle_form, asm.nsel, asm.osel, asm.oproj, asm.N
    dt, Xbar, F = asm.dt, asm.Xbar, asm.F
    pkind, geo, tab_s, tab_xy, tab_h, tab_k = asm.path, asm.geo, asm.tab_s, asm.tab_xy, asm.tab_h, asm.tab_k
    w, eps = asm.obstacle_weight, asm.obstacle_epsilon
    sx, sy = asm.obstacle_sigma_x, asm.obstacle_sigma_y
    isx2, isy2 = 1.0 / (sx * sx), 1.0 / (sy * sy)
    pose, vel, tr_lo, tr_hi, tr_t, tr_d = asm.ob_pose, asm.ob_vel, asm.ob_tr_lo, asm.ob_tr_hi, asm.ob_tr_t, asm.ob_tr_d
    has_life, lives = asm.ob_has_life, asm.ob_life
    s00, s01, s11 = 0.0, 0.0, 0.0
    for a in range(nsel):
        j = osel[a]
        life = has_life[j] != 0
        t_on, t_off = lives[j, 0], lives[j, 1]
        if form == OBS_GAUSSIAN:
            h = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, oproj[j, 0])[2]
            ch, sh = math.cos(h), math.sin(h)
            s00 = ch * ch * isx2 + sh * sh * isy2
            s01 = ch * sh * (isx2 - isy2)
            s11 = sh * sh * isx2 + ch * ch * isy2
        for k in range(1, N + 1):
            if k < N:
                px, py = Xbar[k, 0], Xbar[k, 1]
            else:
                px, py = F[N - 1, 0], F[N - 1, 1]
            tk = t_s + dt * k
            if life and not (t_on <= tk <= t_off):
                continue
            ox, oy, _ = pose_at(j, tk, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
            dx = px - ox
            dy = py - oy
            if form == OBS_POTENTIAL:
                den = dx * dx + dy * dy + eps
                d2, d3 = den * den, den * den * den
                g0, g1 = -2.0 * w * dx / d2, -2.0 * w * dy / d2
                a = -2.0 * w / d2 + 8.0 * w * dx * dx / d3
                b = 8.0 * w * dx * dy / d3
                cc = -2.0 * w / d2 + 8.0 * w * dy * dy / d3
            else:
                sd0, sd1 = s00 * dx + s01 * dy, s01 * dx + s11 * dy
                val = w * math.exp(-0.5 * (dx * sd0 + dy * sd1))
                g0, g1 = -val * sd0, -val * sd1
                a, b, cc = val * (sd0 * sd0 - s00), val * (sd0 * sd1 - s01), val * (sd1 * sd1 - s11)
            # projection of [[a, b], [b, cc]] onto the PSD cone (closed-form 2 x 2 eigen-split)
            half = 0.5 * (a + cc)
            rad = math.sqrt(0.25 * (a - cc) * (a - cc) + b * b)
            l1, l2 = half + rad, half - rad
            if l2 >= 0.0:
                h00, h01, h11 = a, b, cc
            elif l1 <= 0.0:
                h00, h01, h11 = 0.0, 0.0, 0.0
            else:
                f = l1 / (l1 - l2)
                h00, h01, h11 = f * (a - l2), f * b, f * (cc - l2)
            We[k - 1, 0, 0] += 0.5 * h00
            We[k - 1, 0, 1] += 0.5 * h01
            We[k - 1, 1, 0] += 0.5 * h01
            We[k - 1, 1, 1] += 0.5 * h11
            qt[k - 1, 0] -= 0.5 * (g0 - h00 * px - h01 * py)
            qt[k - 1, 1] -= 0.5 * (g1 - h01 * px - h11 * py)


# numba caches these functions keyed to this file only; they inline code from these
from .. import _jitcache  # noqa: E402
from ..paths import compiled as _paths_compiled, profile_compiled as _profile_compiled  # noqa: E402
from ..scene import road as _road  # noqa: E402
from . import avoidance_compiled as _avoidance_compiled  # noqa: E402

_jitcache.refresh(
    select_obstacles,  # one file: one fingerprint for all its functions
    [m.__file__ for m in (_paths_compiled, _profile_compiled, _road, _avoidance_compiled) if m.__file__ is not None],
)
