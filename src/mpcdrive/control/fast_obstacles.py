"""The compiled obstacle terms of the fast controller's step (:mod:`mpcdrive.control.fast_step`).

For the cost formulations of :mod:`mpcdrive.ocp.avoidance` (``potential``, eq. 55, and
``gaussian``, eq. 56), as that module computes them for the OSQP controller: which obstacles a
step considers (:func:`_select_obstacles`), the paper's trapezoidal detour of the references
around static circles (:func:`_detour`, :func:`_shift_references`) and the cost's convex
second-order model at the linearization trajectory (:func:`_obstacle_cost`). They read the
obstacle table and the float parameters named in :mod:`mpcdrive.control.fast_layout`.

Compiled with numba's on-disk cache, which numba keys to this file only: the cache is dropped
(by :mod:`mpcdrive._jitcache`) when a file whose code these functions link in changes.
"""

from __future__ import annotations

import math

from numba import njit

from ..paths.compiled import path_eval, path_project
from ..scene.road import _interp

# the layout of the compiled step's buffers
from .fast_layout import _SIDE_LEFT, _SIDE_RIGHT, _SIDE_BLOCKED, _OBS_POTENTIAL, _OBS_GAUSSIAN, _OB_X, _OB_Y, _OB_VX
from .fast_layout import _OB_VY, _OB_RB, _OB_OX, _OB_OY, _OB_WIN
from .fast_layout import _F_RMARGIN, _F_OW, _F_OEPS, _F_OSX, _F_OSY, _F_OINF, _F_OMARGIN, _F_HW, _F_HL, _F_RAMP
from .fast_layout import _F_RPERIOD


@njit(cache=True)
def _select_obstacles(nobs, omax, obs, odist, oproj, osel, fp, t_s, x, s0, pkind, geo, tab_s, tab_xy, tab_h, tab_k):
    """The ``max_obstacles`` nearest obstacles within the influence distance of the vehicle at time
    ``t_s`` (nearest first, ties by index, as ``ocp.avoidance``) into osel; returns how many.
    oproj[j] = (s, e_y) of each one's projected point [m] (its Frenet position now)."""
    reach = fp[_F_OINF]
    for j in range(nobs):
        d = math.hypot(obs[j, _OB_X] + obs[j, _OB_VX] * t_s - x[0], obs[j, _OB_Y] + obs[j, _OB_VY] * t_s - x[1])
        d -= obs[j, _OB_RB]
        odist[j] = d if d <= reach else math.inf
    px0, py0, _h0, _k0 = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s0)
    nsel = 0
    for _slot in range(min(omax, nobs)):
        j, best = -1, math.inf
        for jj in range(nobs):
            if odist[jj] < best:
                j, best = jj, odist[jj]
        if j < 0:
            break
        odist[j] = math.inf
        osel[nsel] = j
        nsel += 1
        cx = obs[j, _OB_X] + obs[j, _OB_VX] * t_s + obs[j, _OB_OX]
        cy = obs[j, _OB_Y] + obs[j, _OB_VY] * t_s + obs[j, _OB_OY]
        oproj[j, 0], oproj[j, 1] = path_project(
            pkind, geo, tab_s, tab_xy, s0, obs[j, _OB_WIN] + math.hypot(cx - px0, cy - py0), cx, cy
        )
    return nsel


@njit(cache=True)
def _detour(nsel, osel, obs, oproj, sides, fp, N, s_arr, refs, xref, e_ref, lane, rd_s, rd_l, rd_r):
    """The paper's trapezoidal detour around the selected (static, circular) obstacles, as
    ``ocp.avoidance``: pick each one's passing side (kept from ``sides`` while it has room
    between the obstacle and the road's edge beside it, ``lane`` = 1 when there is a road: the
    body's half width, the road's margin, the obstacle margin and the body's half width again),
    shift the references sideways over the obstacle with ramps before and after it, and turn
    their heading with the slope."""
    margin, hw, hl, ramp = fp[_F_OMARGIN], fp[_F_HW], fp[_F_HL], fp[_F_RAMP]
    need = margin + hw  # as Avoidance.passing_room_m for the cost formulations, less the edge's share
    for k in range(N + 1):
        e_ref[k] = 0.0
    any_shift = False
    for a in range(nsel):
        j = osel[a]
        r = obs[j, _OB_RB]
        s_ref, e_c = oproj[j, 0], oproj[j, 1]
        e_lo, e_hi = e_c - r, e_c + r
        if lane == 1:
            lim_l = _interp(rd_s, rd_l, s_ref, fp[_F_RPERIOD]) - hw - fp[_F_RMARGIN]
            lim_r = _interp(rd_s, rd_r, s_ref, fp[_F_RPERIOD]) + hw + fp[_F_RMARGIN]
            room_left, room_right = lim_l - e_hi, e_lo - lim_r
        else:
            room_left = room_right = math.inf
        prev = sides[j]
        if prev == _SIDE_LEFT and room_left >= need:
            side = _SIDE_LEFT
        elif prev == _SIDE_RIGHT and room_right >= need:
            side = _SIDE_RIGHT
        elif max(room_left, room_right) < need:
            side = _SIDE_BLOCKED
        else:
            side = _SIDE_LEFT if room_left >= room_right else _SIDE_RIGHT
        sides[j] = side
        if side == _SIDE_BLOCKED:
            continue
        shift = (e_hi + hw + 2.0 * margin) if side == _SIDE_LEFT else (e_lo - hw - 2.0 * margin)
        lo_s, hi_s = s_ref - r - hl, s_ref + r + hl
        rr = max(ramp, 1e-9)
        for k in range(N + 1):
            f = min(max(min((s_arr[k] - (lo_s - ramp)) / rr, ((hi_s + ramp) - s_arr[k]) / rr), 0.0), 1.0)
            cand = shift * f
            if abs(cand) > abs(e_ref[k]):
                e_ref[k] = cand
                any_shift = any_shift or cand != 0.0
    if any_shift:
        _shift_references(N, s_arr, refs, e_ref, xref)


@njit(cache=True)
def _shift_references(N, s_arr, refs, e_ref, xref):
    """The detour: shift the state references sideways by ``e_ref`` (N+1,) [m] from the path
    points ``refs`` and turn their heading with the slope of the shift."""
    for k in range(N + 1):
        h = refs[k, 2]
        xref[k, 0] -= math.sin(h) * e_ref[k]
        xref[k, 1] += math.cos(h) * e_ref[k]
    for k in range(1, N + 1):
        xref[k, 2] += math.atan((e_ref[k] - e_ref[k - 1]) / max(s_arr[k] - s_arr[k - 1], 1e-9))


@njit(cache=True)
def _obstacle_cost(
    form, nsel, osel, obs, oproj, fp, t_s, dt, Xbar, F, N, pkind, geo, tab_s, tab_xy, tab_h, tab_k, We, qt
):
    """Add the potential (eq. 55) or Gaussian (eq. 56) cost of the selected obstacles, its
    second-order model at the linearization trajectory (x_k = Xbar[k], x_N = F[N-1]) with the
    Hessian projected onto the PSD cone, to the state cost ``x' We x - 2 qt' x`` of x_1..x_N, as
    ``ocp.avoidance`` does for the OSQP controller: each obstacle predicted at constant velocity,
    Sigma aligned with the path where the obstacle is now."""
    w, eps = fp[_F_OW], fp[_F_OEPS]
    isx2, isy2 = 1.0 / (fp[_F_OSX] * fp[_F_OSX]), 1.0 / (fp[_F_OSY] * fp[_F_OSY])
    s00, s01, s11 = 0.0, 0.0, 0.0
    for a in range(nsel):
        j = osel[a]
        vx, vy = obs[j, _OB_VX], obs[j, _OB_VY]
        if form == _OBS_GAUSSIAN:
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
            dx = px - (obs[j, _OB_X] + vx * tk)
            dy = py - (obs[j, _OB_Y] + vy * tk)
            if form == _OBS_POTENTIAL:
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


# numba caches these functions keyed to this file only; they inline code (and constants) from these
from .. import _jitcache  # noqa: E402
from . import fast_layout as _fast_layout  # noqa: E402
from ..paths import compiled as _paths_compiled  # noqa: E402
from ..scene import road as _road  # noqa: E402

_jitcache.refresh(
    _select_obstacles,  # one file: one fingerprint for all its functions
    [m.__file__ for m in (_paths_compiled, _road, _fast_layout) if m.__file__ is not None],
)
