"""The planner's lateral candidates, compiled (numba subroutines; the method is :mod:`.kernels`'s):
moves to every lane's line (and offsets inside the car's lane), evasive moves, and passes of an
obstacle standing in the route lane (out, then back onto the route lane's line past it)."""

from __future__ import annotations

import math

import numpy as np

from .._subroutine import subroutine
from .work import (
    E_CURV,
    E_D,
    E_LANE,
    E_PREV_LANE,
    E_PREV_OFF,
    E_MOVE_END,
    E_MOVE_LANE,
    E_MOVE_OFF,
    E_S,
    E_SLOPE,
    E_V,
    LANE_ONCOMING,
    LANE_ROUTE,
    LAT_BACK,
    LAT_BACK_LANE,
    LAT_BACK_LEN,
    MAX_LAT,
    P_C_CHANGE,
    P_C_SWITCH,
    P_CO,
    P_HL,
    P_HW,
    P_KAPPA_MAX,
    P_LAT_MIN,
    P_MARGIN,
    P_ONCOMING,
    P_ROAD_MARGIN,
    P_SHIFT,
    P_TURN_BACK,
    P_V_MAX,
    TURN_BACK_S,
)

from .frenet import grid_at, grid_row_at, quintic
from .tracks import _standing


#: a car farther than this [m] from its lane's line, or heading away from it more steeply than
#: this slope, also gets the gentle evasive move back onto the line
EVASIVE_BACK_M = 0.3
EVASIVE_BACK_SLOPE = 0.05


# -- lateral candidates ---------------------------------------------------------------------------
@subroutine
def shortest_move_m(par, dd):
    """The shortest quintic move [m] across ``dd`` [m] (>= 0): its peak curvature 5.77 dd / L^2 half
    the vehicle's tightest."""
    return math.sqrt(5.77 * dd / (0.5 * par[P_KAPPA_MAX]))


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
    w.lat_coef[n, LAT_BACK] = math.inf  # no return (a pass sets one: _passes)
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
    # the way a car out in the road's margin may drive to turn back (checks._road_allowance):
    # the shortest move's, less what the car drives in a second at its speed (a car at speed
    # has that second; a car at rest turns only as it drives off), at least the shortest move
    par[P_TURN_BACK] = max(par[P_LAT_MIN], v_len * np.min(w.lat_lengths_s) - v0 * TURN_BACK_S)
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
            L_min = max(par[P_LAT_MIN], shortest_move_m(par, abs(line0 + off - w.ego[E_D])))
            # the last choice's move, on to where it ends; the other moves to the same line pay
            # the switch: a move sampled over the same duration from every replanning keeps its
            # end ahead of the car and never arrives (and a later arrival is always a little
            # gentler)
            L_go = w.ego[E_MOVE_END] - s0
            go_on = nT > 1 and lane == int(w.ego[E_MOVE_LANE]) and off == w.ego[E_MOVE_OFF] and L_go >= L_min
            # the moves over each duration at the car's speed (short, sharp moves are the evasive
            # ones' below: a quintic's curvature rises fastest at its start, beyond the steering
            # rate at any but a crawling speed)
            last = 0.0
            for m in range(nT):
                L = max(L_min, v_len * w.lat_lengths_s[m])
                if L - last < 0.5:
                    continue  # the same move (a slow car: every duration gives the shortest move)
                last = L
                _add_lateral(w, lane, off, L, cost + (par[P_C_SWITCH] if go_on else 0.0))
            if go_on:
                _add_lateral(w, lane, off, L_go, cost)
    # evasive moves: to every other lane's line, steering as fast as the vehicle can (numeric,
    # with the longitudinal profile they are paired with: ``lat_len`` < 0)
    # (``lat_len`` -1: up to the friction circle's share EVASIVE_HARD; -2: EVASIVE_GENTLE)
    for lane in range(w.lane_kind.shape[0]):
        kind = w.lane_kind[lane]
        if kind == LANE_ONCOMING and par[P_ONCOMING] == 0.0:
            continue
        if lane == now:
            # back onto its own line, steering as fast as needed: a car off its line or heading
            # away from it (a quintic from that heading swings far out before it turns back)
            off_line = abs(w.ego[E_D] - grid_row_at(w.grid, w.lane_line, now, s0))
            if off_line > EVASIVE_BACK_M or abs(w.ego[E_SLOPE]) > EVASIVE_BACK_SLOPE:
                _add_lateral(w, lane, 0.0, -2.0, 0.0)
            continue
        if not _lane_open(w, lane, s0):
            continue
        cost = par[P_C_CHANGE] + (par[P_C_SWITCH] if prev >= 0 and lane != prev else 0.0)
        _add_lateral(w, lane, 0.0, -1.0, cost)
        _add_lateral(w, lane, 0.0, -2.0, cost)
    _passes(w, v_len)
    # hold the offset the car has (a maneuver that stops where it is, mid-change)
    _add_lateral(w, now, w.ego[E_D] - grid_row_at(w.grid, w.lane_line, now, s0), par[P_LAT_MIN], par[P_C_SWITCH])


#: the durations [s] over which a pass returns to the route lane, at the car's pace: 1.5 s is a
#: brisk lane change (3.1 m across peaks at 5.77 * 3.1 / 1.5^2 = 8 m/s^2 of lateral
#: acceleration; the checks keep it inside the friction circle, the lateral comfort cost keeps it
#: for when the longer returns meet a car coming the other way)
PASS_BACK_S = (1.5, 2.0, 3.0)


@subroutine
def _route_blocker(w):
    """(where [m] the car's rear is past the nearest obstacle standing in the route lane ahead of
    the car (its front plus the margin), where the car's front reaches its rear (less the
    margin), the route lane): inf, inf without one within the horizon's reach."""
    par = w.par
    K = w.ob_s.shape[1] - 1
    s0 = w.ego[E_S]
    route = 0
    for lane in range(w.lane_kind.shape[0]):
        if w.lane_kind[lane] == LANE_ROUTE:
            route = lane
    reach = s0 + par[P_V_MAX] * K * w.dt[0]
    best = math.inf
    reach_rear = math.inf
    for o in range(w.ob_n[0]):
        So = w.ob_s[o, 0]
        if not math.isfinite(So) or So < s0 or So > reach or not _standing(w.ob_s, o, K, w.dt[0]):
            continue
        lo = grid_row_at(w.grid, w.lane_right, route, So)
        hi = grid_row_at(w.grid, w.lane_left, route, So)
        e, hw = w.ob_e[o, 0], w.ob_hw[o, 0]
        if min(e + hw, hi) - max(e - hw, lo) > 0.0:
            # the car's rear (centre offset co, half length hl) past the obstacle's front
            clear = So + w.ob_hl[o, 0] + par[P_HL] - par[P_CO] + par[P_MARGIN]
            if clear < best:
                best = clear
                reach_rear = So - w.ob_hl[o, 0] - par[P_HL] - par[P_CO] - par[P_MARGIN]
    return best, reach_rear, route


@subroutine
def _passes(w, v_len):
    """Passes of an obstacle standing in the route lane: a move into another lane (each of that
    lane's moves sampled so far, or staying on it when the car is there) that returns to the route
    lane once the car's rear is past the obstacle (:func:`_route_blocker`), blended back over
    each of :data:`PASS_BACK_S` at the car's pace: the two lane changes of an overtaking, which a
    move that stays in the other lane (into oncoming traffic, say) cannot be. The move out is one
    that is on the other lane's line by the time the car's front reaches the obstacle: a longer
    one would put the pass off from one replanning to the next until the swerve left is too sharp
    (measured: a bound of only the body clear of the obstacle's side passed 2 of the 10 generated
    blocked-lane scenarios, this one 7); where every move sampled into a lane is too late, the
    latest that is on time is sampled too, and so in the lane the car is in when it is off that
    lane's line (a car mid-pass in the oncoming lane, its plant overshooting the line by 0.4 m,
    had no pass from there, only passes through the lane it had left, and turned back)."""
    clear, rear, route = _route_blocker(w)
    if not math.isfinite(clear):
        return
    par = w.par
    s0 = w.ego[E_S]
    prev = int(w.ego[E_PREV_LANE])
    # the latest move out, on another lane's line just as the car's front reaches the obstacle,
    # where every move sampled into that lane gets there too late (a car already swerving when
    # it has left its plan replans from where it is: the durations' moves from there are longer
    # than the way left), and it is no sharper than the shortest move
    n0 = w.lat_n[0]
    now = int(w.ego[E_LANE])
    for lane in range(w.lane_kind.shape[0]):
        if lane == route:
            continue
        first, late = -1, True
        for i in range(n0):
            if w.lat_lane[i] == lane and w.lat_len[i] > 0.0 and w.lat_off[i] == 0.0:
                first = i if first < 0 else first
                late = late and s0 + w.lat_len[i] > rear
        L = rear - s0 - 1e-6  # (within the bound of the passes' test below)
        if lane == now:
            # the lane the car passes in already, off its line (a plant that overshoots it, a
            # car that has left its plan): back onto the line over the way left, or over the
            # shortest move sampled (which counts as staying in the lane, below)
            L = max(L, par[P_LAT_MIN])
        dd = abs(grid_row_at(w.grid, w.lane_line, lane, rear) - w.ego[E_D])
        if first >= 0 and late and L >= max(par[P_LAT_MIN], shortest_move_m(par, dd)):
            _add_lateral(w, lane, 0.0, L, w.lat_cost[first])
    n0 = w.lat_n[0]
    for i in range(n0):
        lane = w.lat_lane[i]
        if lane == route or w.lat_len[i] <= 0.0 or w.lat_off[i] != 0.0:
            continue
        L = w.lat_len[i]
        if s0 + L > rear and not (lane == now and L <= par[P_LAT_MIN] + 1e-9):
            continue  # out too late (staying on the lane the car is in is no move out)
        width = grid_row_at(w.grid, w.lane_line, lane, clear) - grid_row_at(w.grid, w.lane_line, route, clear)
        L_min = shortest_move_m(par, abs(width))
        for m in range(len(PASS_BACK_S)):
            n = w.lat_n[0]
            if n >= MAX_LAT:
                return
            for c in range(LAT_BACK):
                w.lat_coef[n, c] = w.lat_coef[i, c]
            w.lat_lane[n] = lane
            w.lat_off[n] = 0.0
            w.lat_len[n] = L
            w.lat_coef[n, LAT_BACK] = max(clear - s0, L)
            w.lat_coef[n, LAT_BACK_LEN] = max(L_min, v_len * PASS_BACK_S[m], 1.0)
            w.lat_coef[n, LAT_BACK_LANE] = route
            # the way back is a lane change too; the choice it continues is judged by the lane it
            # ends in (the move's own switch cost out, the return's in)
            cost = w.lat_cost[i] + par[P_C_CHANGE]
            if prev >= 0 and lane != prev:
                cost -= par[P_C_SWITCH]
            if prev >= 0 and route != prev:
                cost += par[P_C_SWITCH]
            w.lat_cost[n] = cost
            w.lat_n[0] = n + 1
