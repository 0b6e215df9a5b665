"""The planner's longitudinal candidates, compiled (numba subroutines; the method is
:mod:`.kernels`'s, the lateral moves :mod:`.lateral`'s): profiles (speed targets, stops at
points, the wanted-speed profile, the intelligent driver model behind each lane's leader, the
goal's arrivals), and each profile's own cost."""

from __future__ import annotations

import math

import numpy as np

from .._subroutine import subroutine
from .work import (
    E_A,
    E_D,
    E_LANE,
    E_S,
    E_T,
    E_V,
    G_HAS,
    G_S_HI,
    G_S_LO,
    G_T_HI,
    G_T_LO,
    G_V_HI,
    G_V_LO,
    LANE_ONCOMING,
    LON_FOLLOW,
    LON_GOAL,
    LON_REFERENCE,
    LON_SPEED,
    LON_STOP,
    MAX_LON,
    P_A_COMF,
    P_A_MAX,
    P_CO,
    P_CREEP,
    P_D_COMF,
    P_D_MAX,
    P_HL,
    P_HW,
    P_JERK_REF,
    P_MARGIN,
    P_ONCOMING,
    P_ROAD_END,
    P_ROAD_MARGIN,
    P_STANDSTILL,
    P_TIME_GAP,
    P_V_MAX,
    PLAN_TOLERANCE,
)

from .frenet import grid_at, grid_row_at, poly_eval, quintic
from .lateral import _lane_open, shortest_move_m
from .tracks import _standing

#: the wanted-speed profile's time constant [s]: how fast the speed follows the wanted one
SPEED_TAU_S = 1.0


@subroutine
def wanted_at(grid, g_vref, par, s):
    """The wanted speed [m/s] at arc length ``s`` [m] (``g_vref`` on ``grid``), at most the
    vehicle's top speed."""
    return min(grid_at(grid, g_vref, s), par[P_V_MAX])


@subroutine
def regain_time_s(v_wanted, v, a_comf):
    """The time [s] a car at speed ``v`` [m/s] loses on one at the wanted speed ``v_wanted``
    [m/s] getting back to it at the comfortable acceleration ``a_comf`` [m/s^2]:
    ``(v_w - v)^2 / (2 a v_w)`` (``v_w`` taken at least 1 m/s); 0 at or above the wanted speed."""
    short = v_wanted - v
    if short <= 0.0:
        return 0.0
    return short * short / (2.0 * a_comf * max(v_wanted, 1.0))


@subroutine
def wanted_speed_ahead(w, s, v):
    """The wanted speed [m/s] the intelligent driver model behind a leader wants, at arc length
    ``s`` [m] and speed ``v`` [m/s]: looked up where the car will be in :data:`SPEED_TAU_S`, at
    least as far as it gets in that time from rest at the comfort acceleration (a car at rest
    where the reference speed starts from 0 sees the speed it is to pick up). The wanted-speed
    profile itself follows :func:`_wanted_accel`."""
    tau = SPEED_TAU_S
    ahead = max(v * tau, 0.5 * w.par[P_A_COMF] * tau * tau)
    return wanted_at(w.grid, w.g_vref, w.par, s + ahead)


#: jerk [m/s^3] of the numeric profiles (reference, follow): a firm but comfortable onset
PROFILE_JERK_MPS3 = 5.0


@subroutine
def _wanted_accel(w, s, v):
    """The acceleration [m/s^2] that follows the wanted speed along the path at arc length
    ``s`` [m] and speed ``v`` [m/s]: the wanted profile's own acceleration (v dv/ds, read ahead
    by half the time :data:`PROFILE_JERK_MPS3` takes to reach the comfort deceleration) plus the
    speed's difference from the wanted one over :data:`SPEED_TAU_S`. The profile's slowing for a
    bend that sets in faster than the car steers is then kept, not passed 1 m/s fast (a
    lookahead alone lags the profile's braking); from rest where the wanted speed starts at 0
    the profile's acceleration starts the car."""
    grid, g_vref, par = w.grid, w.g_vref, w.par
    h = grid[1]
    ahead = s + v * (0.5 * par[P_D_COMF] / PROFILE_JERK_MPS3)
    v_hi = wanted_at(grid, g_vref, par, ahead + h)
    v_lo = wanted_at(grid, g_vref, par, ahead - h)
    a_ff = (v_hi * v_hi - v_lo * v_lo) / (4.0 * h)
    return a_ff + (wanted_at(grid, g_vref, par, s) - v) / SPEED_TAU_S


#: a pair whose curvature exceeds the vehicle's by this share is infeasible (the controller's
#: model and the planner's Frenet approximation differ by about that)
KAPPA_SLACK = 1.05
#: at most this many stop points are sampled (the nearest)
MAX_STOPS = 4


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
def _fill_quintic(w, n, c, t_h, T):
    """Samples of the car's speed held for ``t_h`` [s] (0: none; its acceleration now at the
    first sample only), then of the quintic ``c`` (in the time after ``t_h``) up to ``T``, then
    its end speed held."""
    K = w.lon_s.shape[1] - 1
    dt = w.dt[0]
    s0, v0 = w.ego[E_S], w.ego[E_V]
    pT, vT, _, _ = poly_eval(c, T)
    for k in range(K + 1):
        t = k * dt
        if t_h > 0.0 and t <= t_h:
            p, v, a = s0 + v0 * t, v0, (w.ego[E_A] if k == 0 else 0.0)
        elif t - t_h <= T:
            p, v, a, _ = poly_eval(c, t - t_h)
        else:
            p, v, a = pT + vT * (t - t_h - T), vT, 0.0
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
    par, grid, ego = w.par, w.grid, w.ego
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
        if lane < 0:
            # above the wanted speed (it slows for bends the car cannot steer faster through) the
            # car brakes beyond the comfortable, up to its limit, to get back under it
            a_des = _wanted_accel(w, s, v)
            a_des = min(max(a_des, -d_max), a_c)
        else:
            v_want = v_max if top else wanted_speed_ahead(w, s, v)
            # the road's end is a leader that stands (the car stops with its front inside it)
            gap = par[P_ROAD_END] - par[P_ROAD_MARGIN] - (s + hl) if math.isfinite(par[P_ROAD_END]) else math.inf
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
def _turn_out_m(par, d, e, hw):
    """The length [m] a car at lateral offset ``d`` needs behind a standing obstacle (centre
    ``e``, half width ``hw``) to steer round it from standstill, to whichever side is nearer:
    a lateral move of ``dd`` at half the steering range takes sqrt(5.77 dd / (kappa_max / 2))."""
    need = e + hw + par[P_HW] + par[P_MARGIN] - (d - par[P_HW])
    need = min(need, d + par[P_HW] - (e - hw - par[P_HW] - par[P_MARGIN]))
    return shortest_move_m(par, max(need, 0.0))


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
        _fill_quintic(w, n, c, 0.0, T)


#: a wanted speed this much [m/s] below the car's speed is a slowing worth its own profiles
SLOWING_MPS = 0.5
#: the shares of the way to a slower wanted speed ahead over which the slowing profiles slow
#: (the rest of the way first at the car's speed): the whole way at a constant deceleration, the
#: gentlest, and its last half, twice as firm and half as much time lost
SLOWING_SHARES = (1.0, 0.5)


@subroutine
def _slow_for_bend(w, c):
    """Profiles to the slowest wanted speed within the wanted-speed profile's reach over the
    horizon (a bend the car steers through no faster, a lower limit), arriving where it is
    wanted: the car's speed held over part of the way, then a quintic over the rest
    (:data:`SLOWING_SHARES`), then held: the slowing a driver starts early. The wanted-speed
    profile itself keeps its speed up to the bend's braking and brakes at the profile's
    deceleration; where that costs more jerk than a half-speed target's lost time, without these
    profiles the car chose the half-speed target at every replanning and drove the slow speed
    long before the bend (measured: 4.1 m/s for 2.5 s before a roundabout's exit wanted at
    4.3 m/s)."""
    par = w.par
    s0, v0 = w.ego[E_S], w.ego[E_V]
    K = w.lon_s.shape[1] - 1
    reach = w.lon_s[0, K]  # the wanted-speed profile's own end (the first profile)
    h = w.grid[1]
    v_b, s_b = math.inf, s0
    s = s0 + h
    while s <= reach:
        v = wanted_at(w.grid, w.g_vref, par, s)
        if v < v_b:
            v_b, s_b = v, s
        s += h
    if not (0.0 < v_b < v0 - SLOWING_MPS):
        return
    D = s_b - s0
    for q in range(len(SLOWING_SHARES)):
        # a constant deceleration from v0 to v_b covers its share of the way in
        # 2 share D / (v0 + v_b); the rest of the way at v0 first
        T = 2.0 * SLOWING_SHARES[q] * D / (v0 + v_b)
        if (v0 - v_b) / T > par[P_D_COMF]:
            return  # sharper than comfortable: the wanted-speed profile's own braking
        t_h = (1.0 - SLOWING_SHARES[q]) * D / v0
        n = _new_lon(w, LON_SPEED, v_b)
        if n < 0:
            return
        # (the car's acceleration now where it slows from the start, none after a hold)
        quintic(s0 + v0 * t_h, v0, 0.0 if t_h > 0.0 else w.ego[E_A], s_b, v_b, 0.0, T, c)
        _fill_quintic(w, n, c, t_h, T)


#: how far [m] inside the goal region's start the latest arrival aims (at most half the
#: region): the controller's tracking error along the path that a replanning goes on from
#: (:data:`~.work.PLAN_TOLERANCE`)
GOAL_INSIDE_M = PLAN_TOLERANCE[0]


@subroutine
def _goal_speed(g, par, v):
    """``v`` [m/s] inside the goal's speed range ``g`` and within the top speed (not below 0)."""
    if math.isfinite(g[G_V_LO]):
        v = min(max(v, g[G_V_LO]), g[G_V_HI])
    return min(max(v, 0.0), par[P_V_MAX])


@subroutine
def longitudinal_candidates(w, c):
    """The longitudinal profiles (module docstring) into ``w.lon_*``; returns the nearest stop
    point [m] in the car's lane (inf: none, or the profiles' slots ran out before the stops)."""
    par = w.par
    w.lon_n[0] = 0
    s0, v0 = w.ego[E_S], w.ego[E_V]
    v_want = wanted_at(w.grid, w.g_vref, par, s0)
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
                return math.inf
            _speed_target(w, v1, T, c)
            _fill_quintic(w, n, c, 0.0, T)
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
    _slow_for_bend(w, c)
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
                return math.inf
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
                    stop -= _turn_out_m(par, w.ego[E_D], e, hw)
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
    nearest = math.inf
    for q in range(ns):
        nearest = min(nearest, max(stops[q], s0))
        if stops[q] > s0 + v0 * w.dt[0] * (w.lon_s.shape[1] - 1) + 60.0:
            continue  # beyond what the horizon can reach: the speed targets cover it
        _stop_at(w, max(stops[q], s0), c)
    # the goal: in its region inside its time window
    g = w.goal
    if g[G_HAS] != 0.0 and math.isfinite(g[G_T_HI]) and g[G_T_HI] > w.ego[E_T] and g[G_S_HI] > s0:
        t_lo = max(g[G_T_LO], w.ego[E_T] + 0.2)
        t_mid = 0.5 * (t_lo + g[G_T_HI])
        s_in = max(g[G_S_LO], s0)  # the region's part ahead of the car
        s_mid = 0.5 * (s_in + g[G_S_HI])
        T = t_mid - w.ego[E_T]
        dt = w.dt[0]
        horizon = dt * (w.lon_s.shape[1] - 1)
        n = _new_lon(w, LON_GOAL, s_mid)
        if n >= 0:
            if T <= horizon:
                quintic(s0, v0, w.ego[E_A], s_mid, _goal_speed(g, par, (s_mid - s0) / T), 0.0, T, c)
                _fill_quintic(w, n, c, 0.0, T)
            else:
                _speed_target(w, min(max((s_mid - s0) / T, 0.0), par[P_V_MAX]), min(w.speed_s[0], T), c)
                _fill_quintic(w, n, c, 0.0, min(w.speed_s[0], T))
        # a car that the wanted speed (the first profile) gets there too late hurries: the latest
        # arrival, just inside the region's start by the window's last step, at the speed a
        # constant acceleration from the car's gives (the middle of both asks more than it needs)
        t_late = g[G_T_HI] - dt
        s_late = s_in + min(GOAL_INSIDE_M, 0.5 * (g[G_S_HI] - s_in))
        T = t_late - w.ego[E_T]
        if t_late > t_lo and dt <= T <= horizon and s_late > s0 and w.lon_s[0, int(T / dt)] < s_late:
            n = _new_lon(w, LON_GOAL, s_late)
            if n >= 0:
                quintic(s0, v0, w.ego[E_A], s_late, _goal_speed(g, par, 2.0 * (s_late - s0) / T - v0), 0.0, T, c)
                _fill_quintic(w, n, c, 0.0, T)
    return nearest


@subroutine
def longitudinal_costs(w, s_stop):
    """Each profile's limits (``lon_ok``) and its own cost: the time it ends behind (or ahead of)
    the wanted-speed profile, the time it loses after the horizon regaining the wanted speed
    (no faster than lets it still stop at ``s_stop`` [m], the nearest stop point in the car's
    lane: behind a blockage there is no speed to regain), its jerk and its braking beyond the
    comfortable; and (``lon_bend``) the steering rate the route's own bends ask at its speeds,
    relative to the vehicle's (the speed times ``g_bend`` along the distance it drives, > 1:
    faster than the car steers), which every lateral move with it steers at least; and
    (``lon_vend``) the speed it is bound for (a stop's 0, a speed target's target, else its
    speed at the horizon's end)."""
    par = w.par
    lon_s, lon_v, lon_a, lon_ok, lon_cost = w.lon_s, w.lon_v, w.lon_a, w.lon_ok, w.lon_cost
    K = lon_s.shape[1] - 1
    dt = w.dt[0]
    s_ref = lon_s[0, K]
    v_scale = max(0.5 * (w.ego[E_V] + lon_v[0, K]), 1.0)
    v_max, a_max, d_max, d_comf, j_ref = par[P_V_MAX], par[P_A_MAX], par[P_D_MAX], par[P_D_COMF], par[P_JERK_REF]
    a_comf = par[P_A_COMF]
    grid, g_bend, lon_bend, lon_vend = w.grid, w.g_bend, w.lon_bend, w.lon_vend
    for n in range(w.lon_n[0]):
        ok = 1
        cost = 0.0
        bend = 0.0
        for k in range(K + 1):
            v, a = lon_v[n, k], lon_a[n, k]
            if k > 0:
                bend = max(bend, v * grid_at(grid, g_bend, lon_s[n, k]) / KAPPA_SLACK)
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
        # ending slower than the wanted speed there: the time it loses beyond the horizon getting
        # back to it at the comfort acceleration, (v_w - v)^2 / (2 a v_w), from the speed the
        # profile is bound for (a stop's 0 and a speed target's target, where it gets there only
        # after the horizon: a stop stretched past the horizon saves nothing)
        v_w = wanted_at(w.grid, w.g_vref, par, lon_s[n, K])
        if math.isfinite(s_stop):
            v_w = min(v_w, math.sqrt(2.0 * d_comf * max(s_stop - lon_s[n, K], 0.0)))
        v_end = lon_v[n, K]
        if w.lon_kind[n] == LON_STOP:
            v_end = 0.0
        elif w.lon_kind[n] == LON_SPEED:
            v_end = w.lon_target[n]
        cost += regain_time_s(v_w, v_end, a_comf)
        lon_ok[n] = ok
        lon_cost[n] = cost
        lon_bend[n] = bend
        lon_vend[n] = v_end
