"""The planner's candidates, compiled (numba subroutines; the method is :mod:`.kernels`'s):
lateral moves to every lane's line (and offsets inside the car's lane, and evasive moves),
longitudinal profiles (speed targets, stops at points, the wanted-speed profile, the intelligent
driver model behind each lane's leader, the goal's arrivals), and each profile's own cost."""

from __future__ import annotations

import math

import numpy as np

from .._subroutine import subroutine
from .work import (
    E_A,
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
    LANE_ROUTE,
    LAT_BACK,
    LAT_BACK_LANE,
    LAT_BACK_LEN,
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
    P_C_SWITCH,
    P_CO,
    P_CREEP,
    P_D_COMF,
    P_D_MAX,
    P_HL,
    P_HW,
    P_JERK_REF,
    P_KAPPA_MAX,
    P_LAT_MIN,
    P_MARGIN,
    P_ONCOMING,
    P_ROAD_END,
    P_ROAD_MARGIN,
    P_SHIFT,
    P_STANDSTILL,
    P_TIME_GAP,
    P_TURN_BACK,
    P_V_MAX,
    PLAN_TOLERANCE,
    TURN_BACK_S,
)

from .frenet import grid_at, grid_row_at, poly_eval, quintic

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
#: a car farther than this [m] from its lane's line, or heading away from it more steeply than
#: this slope, also gets the gentle evasive move back onto the line
EVASIVE_BACK_M = 0.3
EVASIVE_BACK_SLOPE = 0.05
#: at most this many stop points are sampled (the nearest)
MAX_STOPS = 4


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
def _standing(ob_s, o, K, dt):
    """Whether obstacle row ``o`` stands (moves less than 0.5 m over the horizon)."""
    lo, hi = math.inf, -math.inf
    for k in range(K + 1):
        if math.isfinite(ob_s[o, k]):
            lo = min(lo, ob_s[o, k])
            hi = max(hi, ob_s[o, k])
    return hi - lo < 0.5


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
