"""The planner's Frenet-frame primitives, compiled (numba subroutines): the road on its uniform
grid (:func:`grid_at`), the lane at an offset (:func:`lane_at`), a heading in a range
(:func:`heading_within`), quintic polynomials (:func:`quintic`, :func:`poly_eval`), a lateral
move at an arc length (:func:`lateral_at`) and the evasive move's step (:func:`evasive_step`):
steering towards a line as fast as the vehicle can."""

from __future__ import annotations

import math


from .._subroutine import subroutine
from .work import (
    LAT_BACK,
    LAT_BACK_LANE,
    LAT_BACK_LEN,
    LANE_ONCOMING,
    P_FRICTION,
    P_KAPPA_MAX,
    P_KAPPA_RATE,
)


# -- small helpers ------------------------------------------------------------------------------
@subroutine
def grid_at(grid, tab, s):
    """Linear interpolation of ``tab`` (G,) on the uniform grid ``grid`` (s0, ds, G, 1 / ds) at ``s``,
    constant beyond the ends."""
    x = (s - grid[0]) * grid[3]
    n = tab.shape[0]
    if x <= 0.0:
        return tab[0]
    if x >= n - 1:
        return tab[n - 1]
    i = int(x)
    f = x - i
    return tab[i] * (1.0 - f) + tab[i + 1] * f


@subroutine
def heading_within(yaw, lo, hi):
    """Whether heading ``yaw`` [rad] lies in the interval [``lo``, ``hi``] [rad] (lo <= hi), round
    the circle: the one rule of a goal's heading range, for the planner's compiled checks and
    (through ``.py_func``) for :meth:`~.planner.PlanningGoal.reached`."""
    mid = 0.5 * (lo + hi)
    dev = (yaw - mid + math.pi) % (2.0 * math.pi) - math.pi
    return abs(dev) <= 0.5 * (hi - lo) + 1e-9


@subroutine
def grid_row_at(grid, tab, r, s):
    """:func:`grid_at` of row ``r`` of ``tab`` (R, G)."""
    x = (s - grid[0]) * grid[3]
    n = tab.shape[1]
    if x <= 0.0:
        return tab[r, 0]
    if x >= n - 1:
        return tab[r, n - 1]
    i = int(x)
    f = x - i
    return tab[r, i] * (1.0 - f) + tab[r, i + 1] * f


@subroutine
def lane_at(grid, lane_left, lane_right, lane_line, lane_kind, s, d):
    """The lane whose edges at arc length ``s`` hold offset ``d`` (of several, the one whose line is
    nearest, a lane going the car's way before an oncoming one at the same distance; of none, the
    lane whose line is nearest)."""
    best, best_key, best_in = 0, math.inf, False
    for r in range(lane_kind.shape[0]):
        inside = grid_row_at(grid, lane_right, r, s) <= d <= grid_row_at(grid, lane_left, r, s)
        key = abs(grid_row_at(grid, lane_line, r, s) - d) + (1e-3 if lane_kind[r] == LANE_ONCOMING else 0.0)
        if (inside and not best_in) or (inside == best_in and key < best_key):
            best, best_key, best_in = r, key, inside
    return best


@subroutine
def quintic(x0, v0, a0, x1, v1, a1, T, c):
    """Coefficients ``c`` (6,) of the quintic from (x0, v0, a0) at 0 to (x1, v1, a1) at ``T``."""
    h = x1 - (x0 + v0 * T + 0.5 * a0 * T * T)
    dv = v1 - (v0 + a0 * T)
    da = a1 - a0
    c[0] = x0
    c[1] = v0
    c[2] = 0.5 * a0
    c[3] = (10.0 * h - 4.0 * dv * T + 0.5 * da * T * T) / T**3
    c[4] = (-15.0 * h + 7.0 * dv * T - da * T * T) / T**4
    c[5] = (6.0 * h - 3.0 * dv * T + 0.5 * da * T * T) / T**5


@subroutine
def poly_eval(c, t):
    """(p, p', p'', p''') of the quintic ``c`` at ``t``."""
    p = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
    d1 = c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * (4.0 * c[4] + t * 5.0 * c[5])))
    d2 = 2.0 * c[2] + t * (6.0 * c[3] + t * (12.0 * c[4] + t * 20.0 * c[5]))
    d3 = 6.0 * c[3] + t * (24.0 * c[4] + t * 60.0 * c[5])
    return p, d1, d2, d3


@subroutine
def is_pass(coef, L):
    """Whether the lateral move with ``coef`` (a row of ``lat_coef``) and length ``L`` is a pass:
    a quintic move out with a return (:data:`~.work.LAT_BACK` finite)."""
    return L > 0.0 and math.isfinite(coef[LAT_BACK])


@subroutine
def lateral_at(coef, L, s0, lane_line, lane, off, grid, s):
    """(d, d', d'') of the lateral move with quintic ``coef`` over length ``L`` from ``s0``, then
    ``lane``'s line plus ``off``, at ``s``; for a pass (:func:`is_pass`) from ``s0`` plus its
    ``LAT_BACK`` on blended over ``LAT_BACK_LEN`` [m] onto the line of lane ``LAT_BACK_LANE`` (a
    smooth step, 10 t^3 - 15 t^4 + 6 t^5, of the gap between the two lines)."""
    u = s - s0
    ds = grid[1]
    if u < L:
        if u < 0.0:
            u = 0.0
        d, d1, d2, _ = poly_eval(coef, u)
    else:
        a = grid_row_at(grid, lane_line, lane, s)
        b = grid_row_at(grid, lane_line, lane, s + ds)
        d, d1, d2 = a + off, (b - a) / ds, 0.0
    back = coef[LAT_BACK]
    if not (u > back):  # no return (inf), or not yet
        return d, d1, d2
    L2 = coef[LAT_BACK_LEN]
    tau = min((u - back) / L2, 1.0)
    lane2 = int(coef[LAT_BACK_LANE])
    a = grid_row_at(grid, lane_line, lane2, s)
    b = grid_row_at(grid, lane_line, lane2, s + ds)
    gap = a - d
    gap1 = (b - a) / ds - d1
    if tau >= 1.0:
        return d + gap, d1 + gap1, d2
    h = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
    h1 = 30.0 * tau * tau * (1.0 - tau) * (1.0 - tau) / L2
    h2 = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / (L2 * L2)
    return d + h * gap, d1 + h * gap1 + h1 * gap, d2 + h2 * gap + 2.0 * h1 * gap1


#: the evasive move aims at the target line this far ahead: the time [s] at its speed, at least
#: ``EVASIVE_LOOK_M`` [m] (a driver's gaze about a second ahead)
EVASIVE_LOOK_S = 1.0
EVASIVE_LOOK_M = 4.0
#: the largest heading [rad] an evasive move takes to the path (about 30 deg: a car turning out
#: from behind a parked one)
EVASIVE_MAX_YAW = 0.5
#: the time [s] in which it turns its heading to the one it wants (before the limits)
EVASIVE_TURN_S = 0.3
#: the shares of the friction circle an evasive move turns with: hard (what the tyres give, less
#: a reserve for braking and for the controller's tracking) and gentle (a brisk lane change)
EVASIVE_HARD = 0.8
EVASIVE_GENTLE = 0.4
#: substeps of the evasive move per check step (the steering rate acts within a step)
EVASIVE_SUBSTEPS = 4


@subroutine
def evasive_step(d, th, kap, s_prev, v_prev, v, dt, grid, lane_line, lane, off, par, share):
    """One check step of the evasive move: the heading it wants points at the target line (``lane``'s
    line plus ``off``) ``EVASIVE_LOOK_S`` ahead, at most ``EVASIVE_MAX_YAW``; the curvature turns
    the heading there within the vehicle's curvature, the friction circle at the speed and the
    steering rate, and no sharper than it can unwind by the time the heading is reached (no
    overshoot). Integrated in ``EVASIVE_SUBSTEPS`` substeps along the longitudinal profile (speed
    linear over the step, from the path's arc length ``s_prev`` [m]); ``share`` of the friction
    circle turns the car at most. Returns (d, heading, curvature) relative to the path and the
    arc length [m] the car has reached along the path."""
    h = dt / EVASIVE_SUBSTEPS
    k_rate = par[P_KAPPA_RATE]
    dk = k_rate * h
    s = s_prev
    for q in range(EVASIVE_SUBSTEPS):
        f = (q + 0.5) / EVASIVE_SUBSTEPS
        vq = max(v_prev + (v - v_prev) * f, 0.0)
        ds = vq * h
        look = max(vq * EVASIVE_LOOK_S, EVASIVE_LOOK_M)
        target = grid_row_at(grid, lane_line, lane, s + look) + off
        th_want = math.atan((target - d) / look)
        th_want = min(max(th_want, -EVASIVE_MAX_YAW), EVASIVE_MAX_YAW)
        err = th_want - th
        top = par[P_KAPPA_MAX] * 0.95
        if vq > 0.1:
            top = min(top, share * par[P_FRICTION] / (vq * vq))
            # a curvature k turns the heading by v k^2 / (2 rate) while it is unwound
            top = min(top, math.sqrt(2.0 * k_rate * abs(err) / vq))
            want = err / (vq * EVASIVE_TURN_S)
        else:
            want = math.copysign(top, err)
        want = min(max(want, -top), top)
        kap = min(max(want, kap - dk), kap + dk)
        th += kap * ds
        d += math.sin(th) * ds
        s += math.cos(th) * ds
    return d, th, kap, s
