"""The planner's compiled part: sample, check and choose (numba; :func:`plan` is the entry).

Candidates are made in the road's Frenet frame (arc length ``s`` along the reference path,
lateral offset ``d``, positive left), as in Werling et al., "Optimal trajectory generation for
dynamic street scenarios in a Frenet frame" (ICRA 2010):

* **lateral moves** ``d(s)``: quintic polynomials in the distance ``u = s - s0`` driven, from the
  car's offset, slope and curvature to a lane's line (plus an offset inside the car's lane)
  over a length that the car covers in 2-6 s at its speed (at least ``lateral_min_m``); past
  it, the line itself. A function of the distance driven, not of time: a car that stands does
  not move sideways, at any speed the path's curvature is the polynomial's;
* **longitudinal profiles** ``s(t)``: quartics to a target speed (hold it, the wanted speed, the
  top speed, a stop), quintics to a stop at a point (behind the first obstacle in the car's lane,
  before a crossing car's way, inside the road's end), the wanted-speed profile driven with a
  speed time constant, the intelligent driver model behind each lane's leader (Treiber et al.
  2000), and a quintic arriving in the goal region inside its time window.

Every pair (lateral, longitudinal) is a maneuver. A maneuver is checked on the grid ``t_k = k
dt`` against every obstacle's predicted Frenet box (swept: the segment of the two boxes'
relative motion between two samples against the sum of their extents and the margin), the
road (the body's four corners inside the edges of the lanes it may use and inside the road's
ends), and the vehicle (curvature, its rate, the friction circle); it is *safe* when nothing is
hit over the horizon and, at its end, braking still stops the car behind the car ahead. Costs
(seconds of travel time, :class:`~.config.PlannerConfig`) separate into a lateral and a
longitudinal part, which bound a pair's cost from below: pairs are checked in the order of that
bound and the search stops when the bound passes the best safe maneuver's cost (branch and
bound: most replannings check a handful of pairs). With no safe maneuver, the one that is hit
latest is taken (time to collision), the cheapest among equals.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._subroutine import subroutine
from .work import (
    E_A,
    E_CURV,
    E_D,
    E_LANE,
    E_PREV_LANE,
    E_PREV_OFF,
    E_S,
    E_SLOPE,
    E_T,
    E_V,
    G_D_HI,
    G_D_LO,
    G_HAS,
    G_HAS_YAW,
    G_S_HI,
    G_S_LO,
    G_T_HI,
    G_T_LO,
    G_V_HI,
    G_V_LO,
    G_YAW_HI,
    G_YAW_LO,
    LANE_ONCOMING,
    LANE_ROUTE,
    LON_FOLLOW,
    LON_GOAL,
    LON_REFERENCE,
    LON_SPEED,
    LON_STOP,
    MAX_LAT,
    MAX_LON,
    P_A_COMF,
    P_A_MAX,
    P_C_CHANGE,
    P_C_GAP,
    P_C_GOAL,
    P_C_OFFROUTE,
    P_C_ONCOMING,
    P_C_SWITCH,
    P_CO,
    P_CREEP,
    P_R_DISC,
    P_D_COMF,
    P_D_MAX,
    P_FRICTION,
    P_HL,
    P_HW,
    P_JERK_REF,
    P_KAPPA_MAX,
    P_KAPPA_RATE,
    P_LAT_MIN,
    P_LAT_REF,
    P_MARGIN,
    P_ONCOMING,
    P_ROAD_END,
    P_ROAD_MARGIN,
    P_ROAD_START,
    P_SHIFT,
    P_STANDSTILL,
    P_TIME_GAP,
    P_V_MAX,
    P_BAND_K,
    R_CHECKED,
    R_COMBOS,
    R_COST,
    R_GOAL,
    R_I,
    R_J,
    R_KIND,
    R_LANE,
    R_OFF,
    R_RATE,
    R_SAFE,
    R_SAFE_COUNT,
    R_TARGET,
    R_TTC,
    REL_AHEAD,
    REL_BEHIND,
    REL_CLEAR,
    REL_LEFT,
    REL_RIGHT,
)

#: the wanted-speed profile's time constant [s]: how fast the speed follows the wanted one
SPEED_TAU_S = 1.0
#: jerk [m/s^3] of the numeric profiles (reference, follow): a firm but comfortable onset
PROFILE_JERK_MPS3 = 5.0
#: a pair whose curvature exceeds the vehicle's by this share is infeasible (the controller's
#: model and the planner's Frenet approximation differ by about that)
KAPPA_SLACK = 1.05
#: at most this many stop points are sampled (the nearest)
MAX_STOPS = 4


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


# -- lateral candidates ---------------------------------------------------------------------------
@subroutine
def _add_lateral(w, lane, off, L, cost):
    n = w.lat_n[0]
    if n >= MAX_LAT:
        return
    s0 = w.ego[E_S]
    s1 = s0 + L
    ds = w.grid[1]
    line = grid_row_at(w.grid, w.lane_line, lane, s1)
    slope = (grid_row_at(w.grid, w.lane_line, lane, s1 + ds) - line) / ds
    w.lat_lane[n] = lane
    w.lat_off[n] = off
    w.lat_len[n] = L
    if L > 0.0:
        quintic(w.ego[E_D], w.ego[E_SLOPE], w.ego[E_CURV], line + off, slope, 0.0, L, w.lat_coef[n])
    w.lat_cost[n] = cost
    w.lat_n[0] = n + 1


#: lanes whose line is farther than this [m] from the car are not sampled (two lanes over and a
#: half: a maneuver of the horizon changes one or two lanes)
LANE_REACH_M = 9.0


@subroutine
def _lane_open(w, lane, s0):
    """Whether ``lane`` is wide enough for the car here or just ahead (a lane that has ended or
    not begun, narrower than the body and the road's margins, is no target) and within
    ``LANE_REACH_M`` of it."""
    par = w.par
    if abs(grid_row_at(w.grid, w.lane_line, lane, s0) - w.ego[E_D]) > LANE_REACH_M:
        return False
    best = 0.0
    for q in range(3):
        s = s0 + q * par[P_LAT_MIN]
        best = max(best, grid_row_at(w.grid, w.lane_left, lane, s) - grid_row_at(w.grid, w.lane_right, lane, s))
    return best >= 2.0 * par[P_HW] + 2.0 * par[P_ROAD_MARGIN]


@subroutine
def lateral_candidates(w):
    """Moves to every lane's line (the car's own lane also to offsets inside it), over the
    lengths the car drives in ``lat_lengths_s`` at its speed (module docstring)."""
    par = w.par
    w.lat_n[0] = 0
    s0, v0 = w.ego[E_S], w.ego[E_V]
    now = int(w.ego[E_LANE])
    prev = int(w.ego[E_PREV_LANE])
    v_want = grid_at(w.grid, w.g_vref, s0)
    v_len = 0.5 * (v0 + max(v0, v_want))
    for lane in range(w.lane_kind.shape[0]):
        kind = w.lane_kind[lane]
        if kind == LANE_ONCOMING and par[P_ONCOMING] == 0.0:
            continue
        if lane != now and not _lane_open(w, lane, s0):
            continue
        width_ahead = grid_row_at(w.grid, w.lane_left, lane, s0 + par[P_LAT_MIN]) - grid_row_at(
            w.grid, w.lane_right, lane, s0 + par[P_LAT_MIN]
        )
        base = 0.0
        if lane != now:
            base += par[P_C_CHANGE]
        if prev >= 0 and lane != prev:
            base += par[P_C_SWITCH]
        room = 0.5 * width_ahead - par[P_HW] - par[P_ROAD_MARGIN]
        shift = min(par[P_SHIFT], room) if lane == now else 0.0
        n_off = 3 if shift > 0.05 else 1
        line0 = grid_row_at(w.grid, w.lane_line, lane, s0)
        for q in range(n_off):
            off = 0.0 if q == 0 else (shift if q == 1 else -shift)
            cost = base
            if q > 0 and not (lane == prev and w.ego[E_PREV_OFF] * off > 0.0):
                cost += 0.2 * shift  # off the lane's line (not the offset chosen last)
            # a car on the line already, heading along it, has one move: stay
            on_line = abs(line0 + off - w.ego[E_D]) < 0.05 and abs(w.ego[E_SLOPE]) < 0.02
            nT = 1 if on_line else w.lat_lengths_s.shape[0]
            # the shortest move: its peak curvature 5.77 |dd| / L^2 half the vehicle's tightest
            L_min = max(par[P_LAT_MIN], math.sqrt(5.77 * abs(line0 + off - w.ego[E_D]) / (0.5 * par[P_KAPPA_MAX])))
            # the moves over each duration at the car's speed (short, sharp moves are the evasive
            # ones' below: a quintic's curvature rises fastest at its start, beyond the steering
            # rate at any but a crawling speed)
            last = 0.0
            for m in range(nT):
                L = max(L_min, v_len * w.lat_lengths_s[m])
                if L - last < 0.5:
                    continue  # the same move (a slow car: every duration gives the shortest move)
                last = L
                _add_lateral(w, lane, off, L, cost)
    # evasive moves: to every other lane's line, steering as fast as the vehicle can (numeric,
    # with the longitudinal profile they are paired with: ``lat_len`` < 0)
    # (``lat_len`` -1: up to the friction circle's share EVASIVE_HARD; -2: EVASIVE_GENTLE)
    for lane in range(w.lane_kind.shape[0]):
        kind = w.lane_kind[lane]
        if lane == now or (kind == LANE_ONCOMING and par[P_ONCOMING] == 0.0):
            continue
        if not _lane_open(w, lane, s0):
            continue
        cost = par[P_C_CHANGE] + (par[P_C_SWITCH] if prev >= 0 and lane != prev else 0.0)
        _add_lateral(w, lane, 0.0, -1.0, cost)
        _add_lateral(w, lane, 0.0, -2.0, cost)
    # hold the offset the car has (a maneuver that stops where it is, mid-change)
    _add_lateral(w, now, w.ego[E_D] - grid_row_at(w.grid, w.lane_line, now, s0), par[P_LAT_MIN], par[P_C_SWITCH])


# -- longitudinal candidates -----------------------------------------------------------------------
@subroutine
def _new_lon(w, kind, target):
    n = w.lon_n[0]
    if n >= MAX_LON:
        return -1
    w.lon_kind[n] = kind
    w.lon_target[n] = target
    w.lon_n[0] = n + 1
    return n


@subroutine
def _fill_quintic(w, n, c, T):
    """Samples of the quintic ``c`` (in t) up to ``T``, then its end speed held."""
    K = w.lon_s.shape[1] - 1
    dt = w.dt[0]
    pT, vT, _, _ = poly_eval(c, T)
    for k in range(K + 1):
        t = k * dt
        if t <= T:
            p, v, a, _ = poly_eval(c, t)
        else:
            p, v, a = pT + vT * (t - T), vT, 0.0
        w.lon_s[n, k] = p
        w.lon_v[n, k] = v
        w.lon_a[n, k] = a


@subroutine
def _speed_target(w, v1, T, c):
    """A quartic to speed ``v1`` with zero acceleration at ``T`` (in ``c`` as a quintic)."""
    s0, v0, a0 = w.ego[E_S], w.ego[E_V], w.ego[E_A]
    dv = v1 - v0 - a0 * T
    da = -a0
    c4 = -(dv - 0.5 * T * da) / (2.0 * T**3)
    c3 = (da - 12.0 * T * T * c4) / (6.0 * T)
    c[0] = s0
    c[1] = v0
    c[2] = 0.5 * a0
    c[3] = c3
    c[4] = c4
    c[5] = 0.0


@subroutine
def _numeric(w, n, lane, top):
    """The wanted-speed profile (``lane`` < 0) or the intelligent driver model behind ``lane``'s
    leader (wanting the top speed with ``top``), integrated on the grid with the profile jerk."""
    par, grid, g_vref, ego = w.par, w.grid, w.g_vref, w.ego
    lon_s, lon_v, lon_a = w.lon_s, w.lon_v, w.lon_a
    ob_s, ob_e, ob_hl, ob_hw, n_obs = w.ob_s, w.ob_e, w.ob_hl, w.ob_hw, w.ob_n[0]
    lane_left, lane_right = w.lane_left, w.lane_right
    K = lon_s.shape[1] - 1
    dt = w.dt[0]
    s, v, a = ego[E_S], ego[E_V], ego[E_A]
    hl = par[P_HL] + par[P_CO]
    a_c, b_c = par[P_A_COMF], par[P_D_COMF]
    v_max, d_max = par[P_V_MAX], par[P_D_MAX]
    standstill, time_gap = par[P_STANDSTILL], par[P_TIME_GAP]
    sqrt_ab = 2.0 * math.sqrt(a_c * b_c)
    j = PROFILE_JERK_MPS3 * dt
    for k in range(K + 1):
        lon_s[n, k] = s
        lon_v[n, k] = v
        lon_a[n, k] = a
        if k == K:
            break
        v_want = v_max if top else min(grid_at(grid, g_vref, s + v * SPEED_TAU_S), v_max)
        if lane < 0:
            a_des = (v_want - v) / SPEED_TAU_S
            a_des = min(max(a_des, -b_c), a_c)
        else:
            gap = math.inf
            v_lead = 0.0
            for o in range(n_obs):
                So = ob_s[o, k]
                if not math.isfinite(So):
                    continue
                g = So - ob_hl[o, k] - (s + hl)
                if g < -hl or g >= gap:
                    continue
                lo = grid_row_at(grid, lane_right, lane, So)
                hi = grid_row_at(grid, lane_left, lane, So)
                e, hw = ob_e[o, k], ob_hw[o, k]
                if min(e + hw, hi) - max(e - hw, lo) > 0.3:
                    gap = g
                    S1 = ob_s[o, k + 1]
                    v_lead = (S1 - So) / dt if math.isfinite(S1) else 0.0
            ratio = v / max(v_want, 0.1)
            a_des = a_c * (1.0 - ratio**4)
            if math.isfinite(gap):
                s_star = standstill + max(0.0, v * time_gap + v * (v - v_lead) / sqrt_ab)
                if gap <= 0.1:
                    a_des = -d_max
                else:
                    a_des -= a_c * (s_star / gap) ** 2
            a_des = min(max(a_des, -d_max), a_c)
        a = min(max(a_des, a - j), a + j)
        v_new = v + a * dt
        if v_new < 0.0:
            v_new = 0.0
            a = -v / dt
        s += 0.5 * (v + v_new) * dt
        v = v_new


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
def _stop_at(w, s_stop, c):
    """Quintics to a stop at ``s_stop`` over the durations that brake comfortably (and half as
    hard again): added as candidates."""
    s0, v0 = w.ego[E_S], w.ego[E_V]
    D = s_stop - s0
    if D < 0.05:
        D = 0.0
    b = w.par[P_D_COMF]
    # a constant deceleration stops in 2 D / v0; from (near) standstill a quintic covers D in T
    # with a peak acceleration of 5.77 D / T^2
    T0 = max(2.0 * D / max(v0, 0.1), math.sqrt(5.77 * D / b), v0 / b, 0.5)
    for f in (1.0, 1.5):
        n = _new_lon(w, LON_STOP, s_stop)
        if n < 0:
            return
        T = T0 * f
        quintic(s0, v0, w.ego[E_A], s0 + D, 0.0, 0.0, T, c)
        _fill_quintic(w, n, c, T)


@subroutine
def longitudinal_candidates(w, c):
    par = w.par
    w.lon_n[0] = 0
    s0, v0 = w.ego[E_S], w.ego[E_V]
    v_want = min(grid_at(w.grid, w.g_vref, s0), par[P_V_MAX])
    n = _new_lon(w, LON_REFERENCE, v_want)
    _numeric(w, n, -1, False)
    # speed targets: hold, the wanted speed, the top speed, half the speed, a stop
    nV = w.speed_s.shape[0]
    targets = (v0, v_want, par[P_V_MAX], 0.5 * v0, par[P_CREEP], 0.0)
    for q in range(6):
        v1 = targets[q]
        dup = False
        for p in range(q):
            if abs(targets[p] - v1) < 0.25:
                dup = True
        if dup:
            continue
        # a slowing target also at the vehicle's hard braking (the quartic's peak is 1.5 dv / T)
        hard = v1 < v0 - 0.5
        for m in range(nV + (1 if hard else 0)):
            if m == nV:
                T = max(1.5 * (v0 - v1) / (0.9 * par[P_D_MAX]), 0.3)
            else:
                T = w.speed_s[m]
                if v1 == 0.0:
                    T = max(T, v0 / par[P_D_COMF])
            n = _new_lon(w, LON_SPEED, v1)
            if n < 0:
                return
            _speed_target(w, v1, T, c)
            _fill_quintic(w, n, c, T)
            # a stop quartic that rolls back is no stop: hold at the first standstill
            if v1 == 0.0:
                K = w.lon_s.shape[1] - 1
                for k in range(1, K + 1):
                    if w.lon_v[n, k] <= 0.0:
                        for kk in range(k, K + 1):
                            w.lon_s[n, kk] = w.lon_s[n, k - 1]
                            w.lon_v[n, kk] = 0.0
                            w.lon_a[n, kk] = 0.0
                        break
    # the intelligent driver model behind each lane's leader, wanting the wanted speed or the
    # top speed (keeping up with traffic faster than the car wants to drive, a car behind)
    for lane in range(w.lane_kind.shape[0]):
        if w.lane_kind[lane] == LANE_ONCOMING and par[P_ONCOMING] == 0.0:
            continue
        if lane != int(w.ego[E_LANE]) and not _lane_open(w, lane, s0):
            continue
        for top in range(2):
            n = _new_lon(w, LON_FOLLOW, lane)
            if n < 0:
                return
            _numeric(w, n, lane, top == 1)
    # stops: before the first obstacles in the car's lane (a parked car, the conflict zone of a
    # crossing one), inside the road's end
    hl = par[P_HL] + par[P_CO]
    ob_s = w.ob_s
    K = ob_s.shape[1] - 1
    now = int(w.ego[E_LANE])
    stops = np.empty(MAX_STOPS + 1)
    ns = 0
    for o in range(w.ob_n[0]):
        for k in range(K + 1):
            So = w.ob_s[o, k]
            if not math.isfinite(So):
                continue
            front = So - w.ob_hl[o, k]
            if front < s0 + hl - 0.5:
                continue
            lo = grid_row_at(w.grid, w.lane_right, now, So)
            hi = grid_row_at(w.grid, w.lane_left, now, So)
            e, hw = w.ob_e[o, k], w.ob_hw[o, k]
            if min(e + hw, hi) - max(e - hw, lo) > 0.0:
                stop = front - par[P_STANDSTILL] - hl
                if k == 0 and _standing(ob_s, o, K, w.dt[0]):
                    # behind a standing obstacle: the room to steer round it later
                    need = e + hw + par[P_HW] + par[P_MARGIN] - (w.ego[E_D] - par[P_HW])
                    need = min(need, w.ego[E_D] + par[P_HW] - (e - hw - par[P_HW] - par[P_MARGIN]))
                    stop -= math.sqrt(5.77 * max(need, 0.0) / (0.5 * par[P_KAPPA_MAX]))
                if ns < MAX_STOPS:
                    stops[ns] = stop
                    ns += 1
                else:  # keep the nearest
                    far = 0
                    for q in range(1, ns):
                        if stops[q] > stops[far]:
                            far = q
                    if stop < stops[far]:
                        stops[far] = stop
                break
    if math.isfinite(par[P_ROAD_END]):
        stops[ns] = par[P_ROAD_END] - par[P_ROAD_MARGIN] - hl
        ns += 1
    for q in range(ns):
        if stops[q] > s0 + v0 * w.dt[0] * (w.lon_s.shape[1] - 1) + 60.0:
            continue  # beyond what the horizon can reach: the speed targets cover it
        _stop_at(w, max(stops[q], s0), c)
    # the goal: in its region inside its time window
    g = w.goal
    if g[G_HAS] != 0.0 and math.isfinite(g[G_T_HI]) and g[G_T_HI] > w.ego[E_T] and g[G_S_HI] > s0:
        t_lo = max(g[G_T_LO], w.ego[E_T] + 0.2)
        t_mid = 0.5 * (t_lo + g[G_T_HI])
        s_mid = 0.5 * (max(g[G_S_LO], s0) + g[G_S_HI])
        T = t_mid - w.ego[E_T]
        v_goal = (s_mid - s0) / T
        if math.isfinite(g[G_V_LO]):
            v_goal = min(max(v_goal, g[G_V_LO]), g[G_V_HI])
        v_goal = min(max(v_goal, 0.0), par[P_V_MAX])
        horizon = w.dt[0] * (w.lon_s.shape[1] - 1)
        n = _new_lon(w, LON_GOAL, s_mid)
        if n >= 0:
            if T <= horizon:
                quintic(s0, v0, w.ego[E_A], s_mid, v_goal, 0.0, T, c)
                _fill_quintic(w, n, c, T)
            else:
                _speed_target(w, min(max((s_mid - s0) / T, 0.0), par[P_V_MAX]), min(w.speed_s[0], T), c)
                _fill_quintic(w, n, c, min(w.speed_s[0], T))


@subroutine
def longitudinal_costs(w):
    """Each profile's limits (``lon_ok``) and its own cost: the time it ends behind (or ahead of)
    the wanted-speed profile, its jerk and its braking beyond the comfortable."""
    par = w.par
    lon_s, lon_v, lon_a, lon_ok, lon_cost = w.lon_s, w.lon_v, w.lon_a, w.lon_ok, w.lon_cost
    K = lon_s.shape[1] - 1
    dt = w.dt[0]
    s_ref = lon_s[0, K]
    v_scale = max(0.5 * (w.ego[E_V] + lon_v[0, K]), 1.0)
    v_max, a_max, d_max, d_comf, j_ref = par[P_V_MAX], par[P_A_MAX], par[P_D_MAX], par[P_D_COMF], par[P_JERK_REF]
    for n in range(w.lon_n[0]):
        ok = 1
        cost = 0.0
        for k in range(K + 1):
            v, a = lon_v[n, k], lon_a[n, k]
            if v < -0.05 or v > v_max + 0.05:
                ok = 0
            if a > a_max + 1e-6 or a < -d_max - 1e-6:
                ok = 0
            if k > 0:
                jerk = (a - lon_a[n, k - 1]) / dt / j_ref
                cost += jerk * jerk * dt
            if a < -d_comf:
                cost += ((-a - d_comf) / d_comf) * dt * 4.0
        cost += abs(s_ref - lon_s[n, K]) / v_scale
        lon_ok[n] = ok
        lon_cost[n] = cost


# -- checking a pair ---------------------------------------------------------------------------------
@subroutine
def _segment_hits_box(x0, y0, x1, y1, bx, by):
    """Whether the segment (x0, y0)-(x1, y1) meets the box |x| < bx, |y| < by (slabs)."""
    t0, t1 = 0.0, 1.0
    dx, dy = x1 - x0, y1 - y0
    if abs(dx) < 1e-12:
        if abs(x0) >= bx:
            return False
    else:
        ta, tb = (-bx - x0) / dx, (bx - x0) / dx
        if ta > tb:
            ta, tb = tb, ta
        t0, t1 = max(t0, ta), min(t1, tb)
        if t0 > t1:
            return False
    if abs(dy) < 1e-12:
        if abs(y0) >= by:
            return False
    else:
        ta, tb = (-by - y0) / dy, (by - y0) / dy
        if ta > tb:
            ta, tb = tb, ta
        t0, t1 = max(t0, ta), min(t1, tb)
        if t0 > t1:
            return False
    return True


@subroutine
def _box_distance(x, y, bx, by):
    """Distance from the point (x, y) to the box |x| <= bx, |y| <= by (0 inside)."""
    dx = max(abs(x) - bx, 0.0)
    dy = max(abs(y) - by, 0.0)
    return math.sqrt(dx * dx + dy * dy)


@subroutine
def _road_excess(grid, left_tab, right_tab, par, s, d, cth, sth):
    """How far [m] the body's corners at (s, d), yawed (cos, sin) from the path, are outside the
    edges ``left_tab`` / ``right_tab`` less the road's margin, or past the road's ends (the left
    corners against the left edge, the right ones against the right edge)."""
    hl, hw, co, rm = par[P_HL], par[P_HW], par[P_CO], par[P_ROAD_MARGIN]
    front, rear = co + hl, co - hl
    worst = 0.0
    for q in range(2):
        ax = front if q == 0 else rear
        # left corner (ay = hw) and right corner (ay = -hw)
        s_l = s + ax * cth - hw * sth
        d_l = d + ax * sth + hw * cth
        s_r = s + ax * cth + hw * sth
        d_r = d + ax * sth - hw * cth
        worst = max(worst, d_l - (grid_at(grid, left_tab, s_l) - rm), (grid_at(grid, right_tab, s_r) + rm) - d_r)
        if q == 0:
            worst = max(worst, max(s_l, s_r) - (par[P_ROAD_END] - rm))
        else:
            worst = max(worst, (par[P_ROAD_START] + rm) - min(s_l, s_r))
    return worst


@subroutine
def _lat_eval(coef, L, s0, lane_line, lane, off, grid, s):
    """(d, d', d'') of the lateral move with quintic ``coef`` over length ``L`` from ``s0``, then
    ``lane``'s line plus ``off``, at ``s``."""
    u = s - s0
    if u < L:
        if u < 0.0:
            u = 0.0
        d, d1, d2, _ = poly_eval(coef, u)
        return d, d1, d2
    ds = grid[1]
    a = grid_row_at(grid, lane_line, lane, s)
    b = grid_row_at(grid, lane_line, lane, s + ds)
    return a + off, (b - a) / ds, 0.0


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
def _evasive_step(d, th, kap, s_prev, v_prev, v, dt, grid, lane_line, lane, off, par, share):
    """One check step of the evasive move: the heading it wants points at the target line (``lane``'s
    line plus ``off``) ``EVASIVE_LOOK_S`` ahead, at most ``EVASIVE_MAX_YAW``; the curvature turns
    the heading there within the vehicle's curvature, the friction circle at the speed and the
    steering rate, and no sharper than it can unwind by the time the heading is reached (no
    overshoot). Integrated in ``EVASIVE_SUBSTEPS`` substeps along the longitudinal profile (speed
    linear over the step); ``share`` of the friction circle turns the car at most. Returns (d,
    heading, curvature) relative to the path."""
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
        s += ds
    return d, th, kap


@subroutine
def _first_contact(
    i, j, par, grid, ego, lane_line, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v, ob_s, ob_e, ob_hl, ob_hw, dt,
    discs, rel_idx, n_rel, p_disc_s, p_disc_d,
):  # fmt: skip
    """When [s] pair (``i``, ``j``)'s discs first come within their radius and the margin of one
    of the obstacles ``rel_idx[:n_rel]`` (swept between samples, as :func:`check_pair` checks
    them), inf if never: the part of a pair's check that rejects most pairs, run before the rest
    (costs, road, vehicle)."""
    if n_rel == 0:
        return math.inf
    K = lon_s.shape[1] - 1
    lane_i = lat_lane[i]
    coef = lat_coef[i]
    L, off = lat_len[i], lat_off[i]
    s0 = ego[E_S]
    nd = discs.shape[0]
    rn = par[P_R_DISC] + par[P_MARGIN]
    evasive = L < 0.0
    ev_d, ev_th, ev_k = ego[E_D], math.atan(ego[E_SLOPE]), ego[E_CURV]
    for k in range(K + 1):
        s, v = lon_s[j, k], lon_v[j, k]
        if evasive:
            if k > 0:
                ev_d, ev_th, ev_k = _evasive_step(
                    ev_d, ev_th, ev_k, lon_s[j, k - 1], lon_v[j, k - 1], v, dt, grid, lane_line, lane_i, off, par,
                    EVASIVE_HARD if L > -1.5 else EVASIVE_GENTLE,
                )  # fmt: skip
            d, d1 = ev_d, math.tan(ev_th)
        else:
            d, d1, _ = _lat_eval(coef, L, s0, lane_line, lane_i, off, grid, s)
        nrm = math.sqrt(1.0 + d1 * d1)
        cth, sth = 1.0 / nrm, d1 / nrm
        t = k * dt
        for q_o in range(n_rel):
            o = rel_idx[q_o]
            So = ob_s[o, k]
            if not math.isfinite(So):
                continue
            Eo, HL, HW = ob_e[o, k], ob_hl[o, k], ob_hw[o, k]
            prev = k > 0 and math.isfinite(ob_s[o, k - 1])
            for q in range(nd):
                qs = s + discs[q] * cth - So
                qd = d + discs[q] * sth - Eo
                if prev:
                    q0s = p_disc_s[q] - ob_s[o, k - 1]
                    q0d = p_disc_d[q] - ob_e[o, k - 1]
                    bl = max(HL, ob_hl[o, k - 1]) + rn
                    bw = max(HW, ob_hw[o, k - 1]) + rn
                    if _segment_hits_box(q0s, q0d, qs, qd, bl, bw):
                        seg = math.hypot(qs - q0s, qd - q0d)
                        if (
                            seg > rn
                            or min(
                                _box_distance(q0s, q0d, bl - rn, bw - rn),
                                _box_distance(0.5 * (qs + q0s), 0.5 * (qd + q0d), bl - rn, bw - rn),
                                _box_distance(qs, qd, bl - rn, bw - rn),
                            )
                            < rn
                        ):
                            return t - dt
                elif k == 0 and _box_distance(qs, qd, HL, HW) < rn:
                    return 0.0
        for q in range(nd):
            p_disc_s[q] = s + discs[q] * cth
            p_disc_d[q] = d + discs[q] * sth
    return math.inf


@subroutine
def check_pair(
    i, j, excess0, write, bound, par, grid, ego, goal_arr, g_kappa, g_heading, lane_left, lane_right, lane_line, lane_kind,
    same_left, same_right, all_left, all_right, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v, lon_a, ob_s, ob_e,
    ob_hl, ob_hw, n_obs, dt, relation, plan_s, plan_v, plan_a, plan_d, discs, rel_idx, n_rel, scratch,
):  # fmt: skip
    """(safe, feasible, rate, ttc [s], cost [s], goal) of lateral move ``i`` with profile ``j``
    (``feasible``: within the vehicle's curvature and friction circle; ``rate``: the largest
    change of the move's curvature (the path's own left out) over a step relative to what the
    steering rate allows, > 1 where the move steers faster than the vehicle can);
    ``excess0`` [m]: how far the car is outside the road now (a maneuver may not go further
    out, and gets a second to come back in; -2: the car is in an oncoming lane). With ``write``,
    the maneuver and its relations to the obstacles go into ``relation`` and ``plan_*``; else
    the check stops at the first contact (the time to collision is known) or once the cost
    passes ``bound`` [s] (it cannot be chosen), returning it unsafe, and looks only at the
    obstacles ``rel_idx[:n_rel]`` (those that may come near the pair: :func:`_near_obstacles`)."""
    K = lon_s.shape[1] - 1
    horizon = K * dt
    hl, hw, co = par[P_HL], par[P_HW], par[P_CO]
    margin = par[P_MARGIN]
    kappa_max = par[P_KAPPA_MAX] * KAPPA_SLACK
    kappa_step = par[P_KAPPA_RATE] * KAPPA_SLACK * dt + 1e-9
    fric2 = par[P_FRICTION] ** 2 * 1.0001
    lat_ref, c_onc, c_off = par[P_LAT_REF], par[P_C_ONCOMING], par[P_C_OFFROUTE]
    time_gap, c_gap = par[P_TIME_GAP], par[P_C_GAP]
    lane_i = lat_lane[i]
    coef = lat_coef[i]
    L, off = lat_len[i], lat_off[i]
    s0 = ego[E_S]
    in_oncoming = excess0 < -1.0
    use_all = lane_kind[lane_i] == LANE_ONCOMING or in_oncoming
    if in_oncoming:
        excess0 = 0.0
    left_tab = all_left if use_all else same_left
    right_tab = all_right if use_all else same_right
    nl = lane_kind.shape[0]
    has_onc = False
    route = 0
    for lane in range(nl):
        if lane_kind[lane] == LANE_ONCOMING:
            has_onc = True
        if lane_kind[lane] == LANE_ROUTE:
            route = lane
    ttc = math.inf
    feasible = True
    rate = 0.0
    cost = 0.0
    goal = False
    passed_goal = False
    has_goal = goal_arr[G_HAS] != 0.0
    kappa_prev = 0.0
    nd = discs.shape[0]
    rn = par[P_R_DISC] + margin
    p_disc_s = scratch[0]
    p_disc_d = scratch[1]
    if not write:
        first = _first_contact(
            i, j, par, grid, ego, lane_line, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v, ob_s, ob_e, ob_hl,
            ob_hw, dt, discs, rel_idx, n_rel, p_disc_s, p_disc_d,
        )  # fmt: skip
        if first < math.inf:
            return False, True, 0.0, first, 0.0, False
    hit = False
    evasive = L < 0.0
    # the evasive move's state: offset, heading and curvature relative to the path
    ev_d, ev_th, ev_k = ego[E_D], math.atan(ego[E_SLOPE]), ego[E_CURV]
    for k in range(K + 1):
        s, v, a = lon_s[j, k], lon_v[j, k], lon_a[j, k]
        if evasive:
            if k > 0:
                ev_d, ev_th, ev_k = _evasive_step(
                    ev_d, ev_th, ev_k, lon_s[j, k - 1], lon_v[j, k - 1], v, dt, grid, lane_line, lane_i, off, par,
                    EVASIVE_HARD if L > -1.5 else EVASIVE_GENTLE,
                )  # fmt: skip
            d1 = math.tan(ev_th)
            d, d2 = ev_d, ev_k * (1.0 + d1 * d1) ** 1.5  # the plane curve's d'' of that curvature
        else:
            d, d1, d2 = _lat_eval(coef, L, s0, lane_line, lane_i, off, grid, s)
        t = k * dt
        nrm = math.sqrt(1.0 + d1 * d1)
        cth, sth = 1.0 / nrm, d1 / nrm
        # the path's curvature plus the move's (a plane curve y = d(x))
        k_move = d2 / (nrm * nrm * nrm)
        kappa = grid_at(grid, g_kappa, s) + k_move
        speed = v * nrm
        v2 = speed * speed
        a_lat = v2 * kappa
        if k > 0:
            if abs(kappa) > kappa_max or a * a + a_lat * a_lat > fric2:
                feasible = False
            # the steering rate the move adds (the route's own bends are the reference's: its
            # speed profile slows for them, the controller steers them)
            rate = max(rate, abs(k_move - kappa_prev) / kappa_step)
        kappa_prev = k_move
        # lateral comfort: the move's own lateral acceleration
        a_move = v2 * k_move / lat_ref
        cost += a_move * a_move * dt
        # the road
        if not hit:
            allow = excess0 * max(0.0, 1.0 - t) + 1e-3
            if _road_excess(grid, left_tab, right_tab, par, s, d, cth, sth) > allow:
                ttc = t
                hit = True
        sc = s + co * cth
        dc = d + co * sth
        hws = hw * cth + hl * abs(sth)
        hls = hl * cth + hw * abs(sth)
        # lanes: time out of the route lane, in the oncoming lane
        lo = grid_row_at(grid, lane_right, route, sc)
        hi = grid_row_at(grid, lane_left, route, sc)
        if not (lo <= dc and dc <= hi):
            cost += c_off * dt
            if k == K:  # ending out of the route lane: the time it stays out beyond the horizon
                cost += c_off * horizon
        if has_onc:
            for lane in range(nl):
                if lane_kind[lane] == LANE_ONCOMING:
                    lo = grid_row_at(grid, lane_right, lane, sc)
                    hi = grid_row_at(grid, lane_left, lane, sc)
                    if min(dc + hws, hi) - max(dc - hws, lo) > 0.05:
                        cost += c_onc * dt
        # the obstacles
        for q_o in range(n_obs if write else n_rel):
            o = q_o if write else rel_idx[q_o]
            So = ob_s[o, k]
            if not math.isfinite(So):
                if write:
                    relation[o, k] = REL_CLEAR
                continue
            rs = sc - So
            rd = dc - ob_e[o, k]
            bx = hls + ob_hl[o, k]
            by = hws + ob_hw[o, k]
            Eo, HL, HW = ob_e[o, k], ob_hl[o, k], ob_hw[o, k]
            # the body as the controller's discs: each keeps its radius and the margin off the box
            near = False
            blocked = False
            for q in range(nd):
                qs = s + discs[q] * cth - So
                qd = d + discs[q] * sth - Eo
                if abs(qs) < HL + rn:
                    near = True
                    if abs(qd) < HW + rn:
                        blocked = True
                if not hit:
                    if k > 0 and math.isfinite(ob_s[o, k - 1]):
                        q0s = p_disc_s[q] - ob_s[o, k - 1]
                        q0d = p_disc_d[q] - ob_e[o, k - 1]
                        bl = max(HL, ob_hl[o, k - 1]) + rn
                        bw = max(HW, ob_hw[o, k - 1]) + rn
                        if _segment_hits_box(q0s, q0d, qs, qd, bl, bw):
                            # the rounded box: the disc's nearest approach (a segment no longer
                            # than the radius: its ends and middle; else the square box)
                            seg = math.hypot(qs - q0s, qd - q0d)
                            if (
                                seg > rn
                                or min(
                                    _box_distance(q0s, q0d, bl - rn, bw - rn),
                                    _box_distance(0.5 * (qs + q0s), 0.5 * (qd + q0d), bl - rn, bw - rn),
                                    _box_distance(qs, qd, bl - rn, bw - rn),
                                )
                                < rn
                            ):
                                ttc = t - dt
                                hit = True
                    elif k == 0 and _box_distance(qs, qd, HL, HW) < rn:
                        ttc = 0.0
                        hit = True
            if write:
                if blocked:
                    relation[o, k] = REL_AHEAD if rs > 0.0 else REL_BEHIND
                elif near:
                    relation[o, k] = REL_LEFT if rd > 0.0 else REL_RIGHT
                else:
                    relation[o, k] = REL_CLEAR
            # time gaps to the cars ahead of and behind the car in its lane
            if abs(rd) < by:
                gap = abs(rs) - bx
                if gap > 0.0:
                    if rs < 0.0:  # the obstacle ahead
                        tg = gap / max(speed, 1.0)
                        if tg < time_gap:
                            cost += c_gap * (1.0 - tg / time_gap) * dt
                    elif k < K and math.isfinite(ob_s[o, k + 1]):
                        v_o = (ob_s[o, k + 1] - So) / dt
                        if v_o > speed - 0.5 and v_o > 0.5:  # closing in (it does not react)
                            tg = gap / v_o
                            if tg < time_gap:
                                cost += c_gap * (1.0 - tg / time_gap) * dt
                if k == K and rs < 0.0 and not hit:
                    # beyond the horizon: braking still stops behind the car ahead
                    v_o = 0.0
                    if math.isfinite(ob_s[o, k - 1]):
                        v_o = max((So - ob_s[o, k - 1]) / dt, 0.0)
                    need = (v2 - v_o * v_o) / (2.0 * par[P_D_MAX] * 0.8) + margin
                    if -rs - bx < need:
                        ttc = min(ttc, horizon + 0.5 * dt)
                    # ending bound to stop behind an obstacle that stands for good: the car would wait
                    # there for ever (it misses its goal), unless it steers round it later
                    if -rs - bx < v2 / (2.0 * par[P_D_COMF]) + par[P_STANDSTILL] + 2.0 * par[P_LAT_MIN] + margin:
                        if _standing(ob_s, o, K, dt):
                            cost += par[P_C_GOAL]
        if k == K and not hit and math.isfinite(par[P_ROAD_END]):
            # beyond the horizon: braking still stops inside the road's end
            front = s + (hl + co) * cth + hw * abs(sth)
            if par[P_ROAD_END] - par[P_ROAD_MARGIN] - front < v2 / (2.0 * par[P_D_MAX] * 0.8):
                ttc = min(ttc, horizon + 0.5 * dt)
        for q in range(nd):
            p_disc_s[q] = s + discs[q] * cth
            p_disc_d[q] = d + discs[q] * sth
        if not write and (hit or cost > bound):
            return False, feasible, rate, ttc, cost, goal
        # the goal
        if has_goal and s > goal_arr[G_S_HI]:
            passed_goal = True
        if has_goal and not goal:
            tt = ego[E_T] + t
            if goal_arr[G_T_LO] - 1e-9 <= tt and tt <= goal_arr[G_T_HI] + 1e-9:
                if goal_arr[G_S_LO] <= s and s <= goal_arr[G_S_HI] and goal_arr[G_D_LO] <= d and d <= goal_arr[G_D_HI]:
                    if goal_arr[G_V_LO] - 1e-6 <= speed and speed <= goal_arr[G_V_HI] + 1e-6:
                        ok = True
                        if goal_arr[G_HAS_YAW] != 0.0:
                            yaw = grid_at(grid, g_heading, s) + math.atan(d1)
                            mid = 0.5 * (goal_arr[G_YAW_LO] + goal_arr[G_YAW_HI])
                            dev = (yaw - mid + math.pi) % (2.0 * math.pi) - math.pi
                            ok = abs(dev) <= 0.5 * (goal_arr[G_YAW_HI] - goal_arr[G_YAW_LO]) + 1e-9
                        goal = ok
        if write:
            plan_s[k] = s
            plan_v[k] = v
            plan_a[k] = a
            plan_d[k] = d
    if has_goal and not goal and goal_arr[G_T_HI] >= ego[E_T]:
        # missed: the window closes within the horizon, or the maneuver drives through the region
        # (and past it) without being in it
        if goal_arr[G_T_HI] <= ego[E_T] + horizon or (passed_goal and ego[E_S] <= goal_arr[G_S_HI]):
            cost += par[P_C_GOAL]
    safe = not hit and ttc == math.inf  # nothing hit, and braking still works past the horizon
    return safe, feasible, rate, ttc, cost, goal


@subroutine
def _excess_now(par, grid, ego, lane_left, lane_right, lane_kind, same_left, same_right):
    """How far [m] the car's body is outside the same-direction lanes now (-2: in an oncoming
    lane, judged against all lanes then)."""
    s0, d0 = ego[E_S], ego[E_D]
    nrm = math.sqrt(1.0 + ego[E_SLOPE] ** 2)
    cth, sth = 1.0 / nrm, ego[E_SLOPE] / nrm
    hws = par[P_HW] * cth + par[P_HL] * abs(sth)
    dc = d0 + par[P_CO] * sth
    for lane in range(lane_kind.shape[0]):
        if lane_kind[lane] == LANE_ONCOMING:
            lo = grid_row_at(grid, lane_right, lane, s0)
            hi = grid_row_at(grid, lane_left, lane, s0)
            if min(dc + hws, hi) - max(dc - hws, lo) > 0.0:
                return -2.0
    return max(_road_excess(grid, same_left, same_right, par, s0, d0, cth, sth), 0.0)


#: the ranges of :func:`_ranges`: (lo, hi) along and across the path
RANGE_S_LO, RANGE_S_HI, RANGE_D_LO, RANGE_D_HI = 0, 1, 2, 3


@subroutine
def _ranges(par, grid, ego, lane_line, lat_coef, lat_len, lat_lane, lat_off, nlat, lon_s, nlon, ob_s, ob_e, ob_hl,
            ob_hw, n_obs, discs, lat_rng, lon_rng, ob_rng):  # fmt: skip
    """Where each candidate and each obstacle can be over the horizon: lateral moves across the
    path (``lat_rng`` (n, 2): the quintic's extremes on a grid of its length and the line past it,
    an evasive move between its start and its target with half a lane's overshoot), profiles
    along it (``lon_rng``), obstacles both (``ob_rng`` (n, 4), their extents included); the
    car's discs, their radius and the margin, and a time gap at the top speed are added to the
    candidates' ranges. Pairs check only the obstacles whose ranges meet theirs."""
    K = lon_s.shape[1] - 1
    s0 = ego[E_S]
    reach = par[P_R_DISC] + par[P_MARGIN]
    spread = 0.0
    for q in range(discs.shape[0]):
        spread = max(spread, abs(discs[q]))
    lat_pad = reach + 0.5 * spread  # the discs of a car yawed up to 30 deg
    lon_pad = reach + spread + par[P_V_MAX] * par[P_TIME_GAP]
    s_far = s0 + 1.0
    for j in range(nlon):
        lon_rng[j, 0] = lon_s[j, 0] - lon_pad
        lon_rng[j, 1] = lon_s[j, K] + lon_pad
        s_far = max(s_far, lon_s[j, K])
    for i in range(nlat):
        lane = lat_lane[i]
        L = lat_len[i]
        lo, hi = math.inf, -math.inf
        if L > 0.0:
            for q in range(9):
                d = poly_eval(lat_coef[i], L * q / 8.0)[0]
                lo, hi = min(lo, d), max(hi, d)
            s_end = s0 + L
        else:  # evasive: from the car to the target line, overshooting by up to half a lane
            lo, hi = ego[E_D] - 1.75, ego[E_D] + 1.75
            s_end = s0
        # the line (and offset) past the move, to the farthest profile's end
        for q in range(9):
            d = grid_row_at(grid, lane_line, lane, s_end + (s_far - s_end) * q / 8.0) + lat_off[i]
            lo, hi = min(lo, d), max(hi, d)
        lat_rng[i, 0] = lo - lat_pad
        lat_rng[i, 1] = hi + lat_pad
    for o in range(n_obs):
        slo, shi, dlo, dhi = math.inf, -math.inf, math.inf, -math.inf
        for k in range(K + 1):
            So = ob_s[o, k]
            if not math.isfinite(So):
                continue
            slo = min(slo, So - ob_hl[o, k])
            shi = max(shi, So + ob_hl[o, k])
            dlo = min(dlo, ob_e[o, k] - ob_hw[o, k])
            dhi = max(dhi, ob_e[o, k] + ob_hw[o, k])
        ob_rng[o, RANGE_S_LO] = slo
        ob_rng[o, RANGE_S_HI] = shi
        ob_rng[o, RANGE_D_LO] = dlo
        ob_rng[o, RANGE_D_HI] = dhi


@subroutine
def _near_obstacles(i, j, lat_rng, lon_rng, ob_rng, n_obs, rel_idx):
    """The obstacles whose ranges meet pair (``i``, ``j``)'s, into ``rel_idx``; their number."""
    n = 0
    for o in range(n_obs):
        if ob_rng[o, RANGE_D_HI] < lat_rng[i, 0] or ob_rng[o, RANGE_D_LO] > lat_rng[i, 1]:
            continue
        if ob_rng[o, RANGE_S_HI] < lon_rng[j, 0] or ob_rng[o, RANGE_S_LO] > lon_rng[j, 1]:
            continue
        rel_idx[n] = o
        n += 1
    return n


@njit(cache=True)
def plan(w):
    """One replanning on the struct ``w`` (:class:`~.work.PlannerWork`): candidates, checks,
    the choice (module docstring). The choice and its figures go to ``w.result``, the maneuver to
    ``w.plan_*`` and its relations to the obstacles to ``w.relation``."""
    c = np.empty(6)
    lateral_candidates(w)
    longitudinal_candidates(w, c)
    longitudinal_costs(w)
    # the struct's arrays read once (each read of a field costs a reference count)
    par, grid, ego, goal_arr = w.par, w.grid, w.ego, w.goal
    g_kappa, g_heading = w.g_kappa, w.g_heading
    lane_left, lane_right, lane_line, lane_kind = w.lane_left, w.lane_right, w.lane_line, w.lane_kind
    same_left, same_right, all_left, all_right = w.same_left, w.same_right, w.all_left, w.all_right
    lat_coef, lat_len, lat_lane, lat_off, lat_cost = w.lat_coef, w.lat_len, w.lat_lane, w.lat_off, w.lat_cost
    lon_s, lon_v, lon_a, lon_ok, lon_cost = w.lon_s, w.lon_v, w.lon_a, w.lon_ok, w.lon_cost
    ob_s, ob_e, ob_hl, ob_hw = w.ob_s, w.ob_e, w.ob_hl, w.ob_hw
    n_obs = w.ob_n[0]
    dt = w.dt[0]
    relation, plan_s, plan_v, plan_a, plan_d = w.relation, w.plan_s, w.plan_v, w.plan_a, w.plan_d
    discs = w.discs
    keys, codes = w.keys, w.order
    nlat, nlon = w.lat_n[0], w.lon_n[0]
    m = 0
    now = int(ego[E_LANE])
    lon_kind, lon_target = w.lon_kind, w.lon_target
    for i in range(nlat):
        for j in range(nlon):
            if lon_ok[j] == 0:
                continue
            # following a lane's leader goes with moves into that lane (or staying), stopping
            # behind something in the car's lane with moves inside it
            if lon_kind[j] == LON_FOLLOW and lat_lane[i] != int(lon_target[j]) and lat_lane[i] != now:
                continue
            if lon_kind[j] == LON_STOP and lat_lane[i] != now:
                continue
            keys[m] = lat_cost[i] + lon_cost[j]
            codes[m] = i * MAX_LON + j
            m += 1
    order = np.argsort(keys[:m])
    excess0 = _excess_now(par, grid, ego, lane_left, lane_right, lane_kind, same_left, same_right)
    lat_rng = np.empty((max(nlat, 1), 2))
    lon_rng = np.empty((max(nlon, 1), 2))
    ob_rng = np.empty((max(n_obs, 1), 4))
    rel_idx = np.empty(max(n_obs, 1), np.int64)
    scratch = np.empty((2, discs.shape[0]))
    _ranges(
        par, grid, ego, lane_line, lat_coef, lat_len, lat_lane, lat_off, nlat, lon_s, nlon, ob_s, ob_e, ob_hl, ob_hw,
        n_obs, discs, lat_rng, lon_rng, ob_rng,
    )  # fmt: skip
    # the choice: the cheapest safe maneuver within the vehicle's limits; else the safe one that
    # steers least beyond the steering rate (the controller steers at its limit, the obstacle
    # rows keep the clearance); else the one hit latest (time to collision), feasible first
    best = -1
    best_total = math.inf
    checked = 0
    n_safe = 0
    sr, sr_rate, sr_total = -1, math.inf, math.inf
    fb, fb_ttc, fb_total, fb_feasible = -1, -1.0, math.inf, False
    for q in range(m):
        key = keys[order[q]]
        if best >= 0 and key >= best_total:
            break
        code = codes[order[q]]
        i, j = code // MAX_LON, code % MAX_LON
        n_rel = _near_obstacles(i, j, lat_rng, lon_rng, ob_rng, n_obs, rel_idx)
        safe, feasible, rate, ttc, pair, goal = check_pair(
            i, j, excess0, False, best_total - key, par, grid, ego, goal_arr, g_kappa, g_heading, lane_left,
            lane_right, lane_line, lane_kind, same_left, same_right, all_left, all_right, lat_coef, lat_len, lat_lane,
            lat_off, lon_s, lon_v, lon_a, ob_s, ob_e, ob_hl, ob_hw, n_obs, dt, relation, plan_s, plan_v, plan_a, plan_d,
            discs, rel_idx, n_rel, scratch,
        )  # fmt: skip
        checked += 1
        total = key + pair
        if safe and feasible:
            n_safe += 1
            if rate <= 1.0:
                if total < best_total:
                    best, best_total = code, total
            elif rate < sr_rate - 1e-9 or (abs(rate - sr_rate) <= 1e-9 and total < sr_total):
                sr, sr_rate, sr_total = code, rate, total
        better = False
        if feasible and not fb_feasible:
            better = True
        elif feasible == fb_feasible:
            if ttc > fb_ttc + 1e-9 or (abs(ttc - fb_ttc) <= 1e-9 and total < fb_total):
                better = True
        if better:
            fb, fb_ttc, fb_total, fb_feasible = code, ttc, total, feasible
    safe_found = best >= 0 or sr >= 0
    if best < 0:
        if sr >= 0:
            best, best_total = sr, sr_total
        else:
            best, best_total = fb, fb_total
    r = w.result
    r[R_CHECKED] = checked
    r[R_COMBOS] = m
    r[R_SAFE_COUNT] = n_safe
    r[R_SAFE] = 1.0 if safe_found else 0.0
    if best < 0:
        r[R_I] = -1.0
        return
    i, j = best // MAX_LON, best % MAX_LON
    safe, feasible, rate, ttc, pair, goal = check_pair(
        i, j, excess0, True, math.inf, par, grid, ego, goal_arr, g_kappa, g_heading, lane_left, lane_right, lane_line,
        lane_kind, same_left, same_right, all_left, all_right, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v,
        lon_a, ob_s, ob_e, ob_hl, ob_hw, n_obs, dt, relation, plan_s, plan_v, plan_a, plan_d, discs, rel_idx, 0,
        scratch,
    )  # fmt: skip
    r[R_I] = i
    r[R_J] = j
    r[R_COST] = best_total
    r[R_TTC] = ttc
    r[R_LANE] = lat_lane[i]
    r[R_OFF] = lat_off[i]
    r[R_KIND] = w.lon_kind[j]
    r[R_TARGET] = w.lon_target[j]
    r[R_GOAL] = 1.0 if goal else 0.0
    r[R_RATE] = rate
    # the lanes the body overlaps over the controller's horizon (its road)
    K = min(lon_s.shape[1] - 1, int(par[P_BAND_K]))
    plan_lanes = w.plan_lanes
    for lane in range(lane_kind.shape[0]):
        plan_lanes[lane] = 0
    for k in range(K + 1):
        s, d = plan_s[k], plan_d[k]
        d1 = 0.0
        if k > 0 and plan_s[k] - plan_s[k - 1] > 1e-6:
            d1 = (plan_d[k] - plan_d[k - 1]) / (plan_s[k] - plan_s[k - 1])
        nrm = math.sqrt(1.0 + d1 * d1)
        hws = par[P_HW] / nrm + par[P_HL] * abs(d1) / nrm
        for lane in range(lane_kind.shape[0]):
            lo = grid_row_at(grid, lane_right, lane, s)
            hi = grid_row_at(grid, lane_left, lane, s)
            if min(d + hws, hi) - max(d - hws, lo) > 0.0:
                plan_lanes[lane] = 1


def _refresh_cache() -> None:
    """numba keys this module's cache to this file only: the plan links in code from these."""
    from .. import _jitcache
    from . import work as _work

    files = [m.__file__ for m in (_work,) if m.__file__ is not None]
    _jitcache.refresh(plan, files)


_refresh_cache()
