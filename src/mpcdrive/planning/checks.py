"""The planner's checks of a maneuver (a lateral move paired with a longitudinal profile),
compiled (numba subroutines; the method is :mod:`.kernels`'s): contact with every obstacle's
predicted box (swept between samples, on the controller's footprint discs), the road's edges and
ends, the vehicle's curvature, friction circle and steering rate, the goal, and the maneuver's
costs."""

from __future__ import annotations

import math


from .._subroutine import subroutine
from .work import (
    LAT_BACK_LANE,
    E_CURV,
    E_D,
    E_S,
    E_SLOPE,
    E_T,
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
    P_A_COMF,
    P_C_GAP,
    P_C_GOAL,
    P_C_RATE,
    P_C_OFFROUTE,
    P_C_ONCOMING,
    P_CO,
    P_R_DISC,
    P_REAR,
    P_ROWS_EXCESS,
    P_D_COMF,
    P_D_MAX,
    P_FRICTION,
    P_HL,
    P_HW,
    P_KAPPA_MAX,
    P_KAPPA_RATE,
    P_LAT_MIN,
    P_LAT_REF,
    P_MARGIN,
    P_ROAD_END,
    P_ROAD_MARGIN,
    P_ROAD_START,
    P_STANDSTILL,
    P_TIME_GAP,
    P_TURN_BACK,
    P_V_MAX,
    REL_AHEAD,
    REL_BEHIND,
    REL_CLEAR,
    REL_LEFT,
    REL_RIGHT,
    TURN_BACK_S,
)

from .contact import _beyond_box, _disc_meets
from .candidates import KAPPA_SLACK, _turn_out_m, regain_time_s, wanted_at
from .tracks import _standing
from .frenet import (
    EVASIVE_GENTLE,
    EVASIVE_HARD,
    evasive_step,
    grid_at,
    grid_row_at,
    heading_within,
    is_pass,
    lateral_at,
    poly_eval,
)


# -- checking a pair ---------------------------------------------------------------------------------
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
def _road_allowance(excess0, par, t, way):
    """How far [m] beyond the road's edges less its margin a maneuver's body may be at ``t`` [s]
    after the replanning, ``way`` [m] along the path from where it starts: the road's margin is
    room for the controller's tracking, and a maneuver may use it, and the ``excess0`` [m] the
    car is out now, shrinking to nothing over the first second (a car drifting towards the edge
    needs that long to turn back). A car already in the margin keeps it until it has also driven
    the way ``P_TURN_BACK`` (:func:`~.lateral.lateral_candidates`): at rest or crawling it
    turns back only as it drives, and its rear corner swings out until its move has straightened
    it (with a second alone, a car at rest a few centimetres into the margin had no safe
    maneuver at all). A car inside gets the second only: a turn from rest may not lean on the
    margin over its first metres, which the controller's tracking needs."""
    done = t / TURN_BACK_S
    if excess0 > 0.0:
        done = min(done, way / par[P_TURN_BACK])
    return (excess0 + par[P_ROAD_MARGIN]) * max(0.0, 1.0 - done) + 1e-3


@subroutine
def _clear_of_edges(grid, edge_win, row, par, s, d, cth, sth, allow):
    """Whether the body at (s, d), yawed (cos, sin) from the path, keeps within ``allow`` [m] of
    the edges and the road's ends for sure: its corners lie within ``|ax| |sin| + hw cos`` across
    of ``d`` (``ax`` the larger of the front's and the rear's distance from the reference point)
    and along within the reach that ``edge_win``'s rows ``row`` (left) and ``row + 1`` (right) are
    tightest over (:func:`~.work.road_windows`). True only where :func:`_road_excess` is at most
    ``allow``; False says nothing (the corners are then looked up)."""
    rm = par[P_ROAD_MARGIN]
    hw = par[P_HW]
    front, rear = par[P_CO] + par[P_HL], par[P_CO] - par[P_HL]
    x = (s - grid[0]) * grid[3]
    g = 0 if x <= 0.0 else min(int(x), edge_win.shape[1] - 1)
    across = max(abs(front), abs(rear)) * abs(sth) + hw * cth
    clear = allow - 1e-9
    return (
        d + across - (edge_win[row, g] - rm) <= clear
        and (edge_win[row + 1, g] + rm) - (d - across) <= clear
        and s + front * cth + hw * abs(sth) - (par[P_ROAD_END] - rm) <= clear
        and (par[P_ROAD_START] + rm) - (s + rear * cth - hw * abs(sth)) <= clear
    )


@subroutine
def _first_hit(
    i, j, par, grid, ego, lane_line, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v, ob_s, ob_e, ob_hl, ob_hw, ob_or,
    dt, discs, rel_idx, n_rel, p_disc_s, p_disc_d, excess0, left_tab, right_tab, edge_win, win_row, path,
):  # fmt: skip
    """The part of a pair's check that rejects most pairs, run before the rest (costs, lanes,
    vehicle): the step at which pair (``i``, ``j``) first leaves the road (its body's corners
    beyond the edges ``left_tab`` / ``right_tab`` by more than :func:`_road_allowance`; where
    the body keeps clear of the tightest edges within its reach, ``edge_win``'s rows
    ``win_row`` and ``win_row + 1``, the corners are not looked up) or its discs first come
    within their radius and the margin of one of the obstacles ``rel_idx[:n_rel]`` (swept
    between samples, as :func:`check_pair` checks them). Returns
    (``k``, time [s]): ``k`` >= 0 the road's step (its time ``k dt``), -1 an obstacle's contact
    (the time the swept check gives it), -2 neither (time inf). The way the pair drives, (arc
    length, offset, slope, d'') per step, goes to ``path`` up to the step returned (all of it
    with none), where :func:`check_pair` reads it instead of driving the pair again."""
    K = lon_s.shape[1] - 1
    lane_i = lat_lane[i]
    coef = lat_coef[i]
    L, off = lat_len[i], lat_off[i]
    s0 = ego[E_S]
    nd = discs.shape[0]
    rn = par[P_R_DISC] + par[P_MARGIN]
    evasive = L < 0.0
    ev_d, ev_th, ev_k = ego[E_D], math.atan(ego[E_SLOPE]), ego[E_CURV]
    reach = 0.0
    for q in range(nd):
        reach = max(reach, abs(discs[q]))
    s = s0
    d1 = ego[E_SLOPE]
    d = ego[E_D]
    for k in range(K + 1):
        s_before, d_before = s, d
        v = lon_v[j, k]
        if evasive:
            if k > 0:
                ev_d, ev_th, ev_k, s = evasive_step(
                    ev_d, ev_th, ev_k, s, lon_v[j, k - 1], v, dt, grid, lane_line, lane_i, off, par,
                    EVASIVE_HARD if L > -1.5 else EVASIVE_GENTLE,
                )  # fmt: skip
            d, d1 = ev_d, math.tan(ev_th)
            d2 = ev_k * (1.0 + d1 * d1) ** 1.5  # the plane curve's d'' of that curvature
        else:
            if k > 0:  # the profile is the car's way; along the path it is that over the slope
                s += (lon_s[j, k] - lon_s[j, k - 1]) / math.sqrt(1.0 + d1 * d1)
            d, d1, d2 = lateral_at(coef, L, s0, lane_line, lane_i, off, grid, s)
        path[k, 0] = s
        path[k, 1] = d
        path[k, 2] = d1
        path[k, 3] = d2
        nrm = math.sqrt(1.0 + d1 * d1)
        cth, sth = 1.0 / nrm, d1 / nrm
        t = k * dt
        # the road first (its time is the step's; an obstacle's swept contact is the step before)
        allow = _road_allowance(excess0, par, t, s - s0)
        road_hit = not _clear_of_edges(grid, edge_win, win_row, par, s, d, cth, sth, allow) and (
            _road_excess(grid, left_tab, right_tab, par, s, d, cth, sth) > allow
        )
        for q_o in range(n_rel):
            o = rel_idx[q_o]
            So = ob_s[o, k]
            if not math.isfinite(So):
                continue
            Eo, HL, HW = ob_e[o, k], ob_hl[o, k], ob_hw[o, k]
            prev = k > 0 and math.isfinite(ob_s[o, k - 1])
            if prev:
                # the box over the step, grown by the radius and the margin
                bl = max(HL, ob_hl[o, k - 1]) + rn
                bw = max(HW, ob_hw[o, k - 1]) + rn
                if _beyond_box(s_before - ob_s[o, k - 1], d_before - ob_e[o, k - 1], s - So, d - Eo, reach, bl, bw):
                    continue
            elif k > 0:
                continue  # present from this step on: its way is swept from the next one
            elif _beyond_box(s - So, d - Eo, s - So, d - Eo, reach, HL + rn, HW + rn):
                continue
            for q in range(nd):
                qs = s + discs[q] * cth - So
                qd = d + discs[q] * sth - Eo
                if prev:
                    q0s = p_disc_s[q] - ob_s[o, k - 1]
                    q0d = p_disc_d[q] - ob_e[o, k - 1]
                    if _disc_meets(q0s, q0d, qs, qd, bl - rn, bw - rn, ob_or, o, k - 1, k, rn):
                        return -1, t - dt
                elif _disc_meets(qs, qd, qs, qd, HL, HW, ob_or, o, k, k, rn):
                    return -1, 0.0
        if road_hit:
            return k, t
        for q in range(nd):
            p_disc_s[q] = s + discs[q] * cth
            p_disc_d[q] = d + discs[q] * sth
    return -2, math.inf


@subroutine
def _goal_fraction(goal_arr, s0, s1, t0, t1):
    """Where [0, 1] on the way from arc length ``s0`` at ``t0`` to ``s1`` at ``t1`` (linear in
    time) the middle of the stretch in the goal region and inside its time window is; -1 when
    there is none."""
    lo = max(t0, goal_arr[G_T_LO])
    hi = min(t1, goal_arr[G_T_HI])
    if s1 > s0:
        lo = max(lo, t0 + (goal_arr[G_S_LO] - s0) / (s1 - s0) * (t1 - t0))
        hi = min(hi, t0 + (goal_arr[G_S_HI] - s0) / (s1 - s0) * (t1 - t0))
    elif not (goal_arr[G_S_LO] <= s0 and s0 <= goal_arr[G_S_HI]):
        return -1.0
    if lo > hi + 1e-9:
        return -1.0
    return min(max((0.5 * (lo + hi) - t0) / (t1 - t0), 0.0), 1.0)


@subroutine
def _in_goal(goal_arr, grid, g_heading, par, s, tt, speed, d, d1, kappa):
    """Whether the car at arc length ``s`` [m], offset ``d`` [m] and slope ``d1`` at time ``tt``
    [s] and ``speed`` [m/s] is in the goal (region, time window, speed and orientation ranges);
    on its way's curvature ``kappa`` [1/m] the body heads the slip angle ``asin(rear_axle
    kappa)`` (kinematic; positive turning left) to the right of the way its reference point
    moves."""
    if not (goal_arr[G_T_LO] - 1e-9 <= tt and tt <= goal_arr[G_T_HI] + 1e-9):
        return False
    if not (
        goal_arr[G_S_LO] - 1e-9 <= s
        and s <= goal_arr[G_S_HI] + 1e-9
        and goal_arr[G_D_LO] <= d
        and d <= goal_arr[G_D_HI]
    ):
        return False
    if not (goal_arr[G_V_LO] - 1e-6 <= speed and speed <= goal_arr[G_V_HI] + 1e-6):
        return False
    if goal_arr[G_HAS_YAW] == 0.0:
        return True
    slip = math.asin(min(max(par[P_REAR] * kappa, -1.0), 1.0))
    return heading_within(grid_at(grid, g_heading, s) + math.atan(d1) - slip, goal_arr[G_YAW_LO], goal_arr[G_YAW_HI])


@subroutine
def check_pair(
    i, j, excess0, write, bound, prepaid, v_bound, par, grid, ego, goal_arr, g_kappa, g_heading, rate0, lane_left, lane_right,
    lane_line, lane_kind, same_left, same_right, all_left, all_right, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v, lon_a, ob_s, ob_e,
    ob_hl, ob_hw, ob_or, n_obs, dt, relation, plan_s, plan_v, plan_a, plan_d, discs, rel_idx, n_rel, scratch, path,
    edge_win,
):  # fmt: skip
    """(safe, feasible, rate, ttc [s], cost [s], goal) of lateral move ``i`` with profile ``j``
    (``feasible``: within the vehicle's curvature and friction circle; ``rate``: the largest
    change of the move's curvature (the path's own left out) over a step relative to what the
    steering rate allows, or ``rate0``, the rate the route's own bends ask at the profile's speeds
    (``lon_bend``, :func:`~.candidates.longitudinal_costs`), > 1 where the move steers faster than
    the vehicle can);
    ``excess0`` [m]: how far the car is outside the road now (a maneuver may not go further
    out, and gets :func:`_road_allowance`'s time and way to come back in; -2: the car is in an
    oncoming lane). With ``write``, the maneuver and its relations to the obstacles go into
    ``relation`` and ``plan_*``; else the check stops at the first contact (the time to
    collision is known) or once the cost and the rate's excess costed (``rate_excess_s``, as the
    choice scores it) pass ``bound`` [s] (it cannot be chosen), returning it unsafe, and looks
    only at the obstacles ``rel_idx[:n_rel]`` (those that may come near the pair: :func:`_near_obstacles`),
    after :func:`_first_hit` (an obstacle's contact ends the check there; the road's is the
    check's own, reached on the way :func:`_first_hit` left in ``path`` (K + 1, 4)).
    ``prepaid`` [s]: the goal's miss cost already counted in the pair's bound
    (:func:`goal_missed_by_profile`), left out of the cost returned; ``v_bound`` [m/s]: the speed
    the profile is bound for (0: it stops, within the horizon or after it)."""
    K = lon_s.shape[1] - 1
    horizon = K * dt
    hl, hw, co = par[P_HL], par[P_HW], par[P_CO]
    margin = par[P_MARGIN]
    kappa_max = par[P_KAPPA_MAX] * KAPPA_SLACK
    kappa_step = par[P_KAPPA_RATE] * KAPPA_SLACK * dt + 1e-9
    fric2 = par[P_FRICTION] ** 2 * 1.0001
    lat_ref, c_onc, c_off = par[P_LAT_REF], par[P_C_ONCOMING], par[P_C_OFFROUTE]
    time_gap, c_gap, c_rate = par[P_TIME_GAP], par[P_C_GAP], par[P_C_RATE]
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
    rate = rate0
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
        first, t_first = _first_hit(
            i, j, par, grid, ego, lane_line, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v, ob_s, ob_e, ob_hl,
            ob_hw, ob_or, dt, discs, rel_idx, n_rel, p_disc_s, p_disc_d, excess0, left_tab, right_tab, edge_win,
            2 if use_all else 0, path,
        )  # fmt: skip
        if first == -1:
            return False, True, 0.0, t_first, 0.0, False
    else:
        first = -2
    hit = False
    waits = False
    evasive = L < 0.0
    # the evasive move's state: offset, heading and curvature relative to the path
    ev_d, ev_th, ev_k = ego[E_D], math.atan(ego[E_SLOPE]), ego[E_CURV]
    s = s0
    d1 = ego[E_SLOPE]
    s_prev, v_prev, d_prev, d1_prev, k_prev = s0, 0.0, 0.0, 0.0, 0.0
    for k in range(K + 1):
        # the profile gives the car's speed and the way it drives (``lon_s``); the path's arc
        # length follows from the move's slope
        v, a = lon_v[j, k], lon_a[j, k]
        if not write:  # the way :func:`_first_hit` drove
            s, d, d1, d2 = path[k, 0], path[k, 1], path[k, 2], path[k, 3]
        elif evasive:
            if k > 0:
                ev_d, ev_th, ev_k, s = evasive_step(
                    ev_d, ev_th, ev_k, s, lon_v[j, k - 1], v, dt, grid, lane_line, lane_i, off, par,
                    EVASIVE_HARD if L > -1.5 else EVASIVE_GENTLE,
                )  # fmt: skip
            d1 = math.tan(ev_th)
            d, d2 = ev_d, ev_k * (1.0 + d1 * d1) ** 1.5  # the plane curve's d'' of that curvature
        else:
            if k > 0:
                s += (lon_s[j, k] - lon_s[j, k - 1]) / math.sqrt(1.0 + d1 * d1)
            d, d1, d2 = lateral_at(coef, L, s0, lane_line, lane_i, off, grid, s)
        t = k * dt
        nrm = math.sqrt(1.0 + d1 * d1)
        cth, sth = 1.0 / nrm, d1 / nrm
        # the path's curvature plus the move's (a plane curve y = d(x))
        k_move = d2 / (nrm * nrm * nrm)
        kappa = grid_at(grid, g_kappa, s) + k_move
        speed = v
        v2 = speed * speed
        a_lat = v2 * kappa
        if k > 0:
            if abs(kappa) > kappa_max or a * a + a_lat * a_lat > fric2:
                feasible = False
            # the steering rate the move adds (the route's own bends at the profile's speeds: rate0)
            rate = max(rate, abs(k_move - kappa_prev) / kappa_step)
        kappa_prev = k_move
        # lateral comfort: the move's own lateral acceleration
        a_move = v2 * k_move / lat_ref
        cost += a_move * a_move * dt
        # the road
        if not hit:
            # the road (in the search, :func:`_first_hit` has found the step that leaves it, if any)
            if write:
                allow = _road_allowance(excess0, par, t, s - s0)
                if _road_excess(grid, left_tab, right_tab, par, s, d, cth, sth) > allow:
                    ttc = t
                    hit = True
            elif k == first:
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
            # (in the search, :func:`_first_hit` has tested these discs against these
            # obstacles and found no contact, and what the loop finds besides is written only)
            near = False
            blocked = False
            for q in range(nd if write else 0):
                qs = s + discs[q] * cth - So
                qd = d + discs[q] * sth - Eo
                # squarely behind (or ahead of) it, the disc's centre within its width: the
                # controller's stop or keep-ahead row, which the maneuver keeps, at any distance
                # (else the nearest-point half-plane, taken about the controller's own last
                # prediction, may open the side the maneuver does not take); level with it along
                # and clear across: beside it; within reach both ways (round its corner): behind
                # or ahead where the gap along the path is the larger, else beside
                if abs(qd) < HW + rn:
                    if abs(qs) >= HL + rn:
                        if abs(qd) < HW:
                            blocked = True
                    elif abs(qd) - HW < abs(qs) - HL:
                        blocked = True
                    else:
                        near = True
                elif abs(qs) < HL + rn:
                    near = True
                if not hit:
                    if k > 0 and math.isfinite(ob_s[o, k - 1]):
                        q0s = p_disc_s[q] - ob_s[o, k - 1]
                        q0d = p_disc_d[q] - ob_e[o, k - 1]
                        bl = max(HL, ob_hl[o, k - 1])
                        bw = max(HW, ob_hw[o, k - 1])
                        if _disc_meets(q0s, q0d, qs, qd, bl, bw, ob_or, o, k - 1, k, rn):
                            ttc = t - dt
                            hit = True
                    elif k == 0 and _disc_meets(qs, qd, qs, qd, HL, HW, ob_or, o, k, k, rn):
                        ttc = 0.0
                        hit = True
            if write:
                if max(HL - ob_or[o, k, 2], HW - ob_or[o, k, 3]) > par[P_ROWS_EXCESS]:
                    # its Frenet box exceeds its outline (yawed to the path) by more than the
                    # maneuver may keep off it: the outline's own nearest-point half-plane
                    relation[o, k] = REL_CLEAR
                elif blocked:
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
                    # there for ever (it misses its goal), unless it steers round it later (a stop
                    # that leaves the room to turn out is within that room and a shortest move)
                    room = _turn_out_m(par, d, ob_e[o, k], ob_hw[o, k]) + par[P_STANDSTILL] + par[P_LAT_MIN]
                    if -rs - bx < v2 / (2.0 * par[P_D_COMF]) + room:
                        if _standing(ob_s, o, K, dt):
                            cost += par[P_C_GOAL]
                            waits = True
        if k == K and not hit and math.isfinite(par[P_ROAD_END]):
            # beyond the horizon: braking still stops inside the road's end
            front = s + (hl + co) * cth + hw * abs(sth)
            if par[P_ROAD_END] - par[P_ROAD_MARGIN] - front < v2 / (2.0 * par[P_D_MAX] * 0.8):
                ttc = min(ttc, horizon + 0.5 * dt)
        for q in range(nd):
            p_disc_s[q] = s + discs[q] * cth
            p_disc_d[q] = d + discs[q] * sth
        # (the score so far: the costs and the rate's excess only grow along the maneuver)
        if not write and (hit or cost + c_rate * max(rate - 1.0, 0.0) > bound):
            return False, feasible, rate, ttc, cost, goal
        # the goal
        if has_goal and s > goal_arr[G_S_HI]:
            passed_goal = True
        if has_goal and not goal:
            # on the way from the step before to this one (the car's state interpolated): the
            # times it is in the region and inside the window, their middle. A region shorter
            # than a step's way (2.6 m at 13 m/s over 0.2 s) or a window shorter than a step (a
            # single instant, as many files give) lies between two samples
            # (the body heads at the slip angle to the way its reference point moves)
            if k == 0:
                goal = _in_goal(goal_arr, grid, g_heading, par, s, ego[E_T], speed, d, d1, kappa)
            else:
                t1 = ego[E_T] + t
                f = _goal_fraction(goal_arr, s_prev, s, t1 - dt, t1)
                if f >= 0.0:
                    goal = _in_goal(
                        goal_arr, grid, g_heading, par, s_prev + f * (s - s_prev), t1 - (1.0 - f) * dt,
                        v_prev + f * (speed - v_prev), d_prev + f * (d - d_prev), d1_prev + f * (d1 - d1_prev),
                        k_prev + f * (kappa - k_prev),
                    )  # fmt: skip
        s_prev, v_prev, d_prev, d1_prev, k_prev = s, speed, d, d1, kappa
        if write:
            plan_s[k] = s
            plan_v[k] = v
            plan_a[k] = a
            plan_d[k] = d
    if not waits and not hit and v_bound < STOPPED_MPS:
        # stopping further back behind an obstacle that stands for good in the way (one the
        # search may not have looked at, as the car never comes near it): standing there only
        # puts the wait off (``sc``, ``dc``, ``hws``: the car at the horizon's end)
        for o in range(n_obs):
            if math.isfinite(ob_s[o, K]) and sc < ob_s[o, K] and abs(dc - ob_e[o, K]) < hws + ob_hw[o, K]:
                if _standing(ob_s, o, K, dt):
                    cost += par[P_C_GOAL]
                    break
    if has_goal and not goal and goal_arr[G_T_HI] >= ego[E_T]:
        # missed: the window closes within the horizon, or the maneuver drives through the region
        # (and past it) without being in it
        if goal_arr[G_T_HI] <= ego[E_T] + horizon or (passed_goal and ego[E_S] <= goal_arr[G_S_HI]):
            cost += par[P_C_GOAL] - prepaid
    safe = not hit and ttc == math.inf  # nothing hit, and braking still works past the horizon
    return safe, feasible, rate, ttc, cost, goal


#: a profile bound for a speed below this [m/s] stops (within the horizon or after it)
STOPPED_MPS = 0.1


#: slack [m] on the distance a profile drives when it is judged unable to reach the goal region
#: (the evasive move's midpoint integration differs from the profile's own distance by far less)
REACH_SLACK_M = 0.5


@subroutine
def goal_missed_by_profile(par, ego, goal_arr, lon_s, lon_v, nlon, dt, grid, g_vref, g_tref, out):
    """Into ``out[j]``: the goal's miss cost [s] that every pair with profile ``j`` pays for
    sure (:func:`check_pair`'s last term), else 0. The window closes within the horizon, and at
    no step inside it (nor on the way to one from the step before, where the window and the speed
    range meet the way's times and speeds) does the profile have the car at the goal's speed with
    the distance it drives reaching the region's start (a move's path is never longer than the distance driven:
    it runs along the path at most; :data:`REACH_SLACK_M` covers the evasive move, which
    integrates the profile's speed by midpoints). The pairs' bound counts it, so that where no
    profile reaches a closing window the search still stops early. A window closing after the
    horizon is missed by a profile from whose end the wanted speed (its times ``g_tref`` on
    ``grid``), plus the time lost regaining it from the profile's end speed at the comfortable
    acceleration, gets to the region's start only after the window has closed."""
    K = lon_s.shape[1] - 1
    t0 = ego[E_T]
    for j in range(nlon):
        out[j] = 0.0
    if goal_arr[G_HAS] == 0.0 or goal_arr[G_T_HI] < t0:
        return
    if goal_arr[G_T_HI] > t0 + K * dt:
        t_lo = grid_at(grid, g_tref, goal_arr[G_S_LO])
        for j in range(nlon):
            s_end = lon_s[j, K]
            v_w = wanted_at(grid, g_vref, par, s_end)
            rest = t_lo - grid_at(grid, g_tref, s_end) + regain_time_s(v_w, lon_v[j, K], par[P_A_COMF])
            late = t0 + K * dt + rest > goal_arr[G_T_HI]  # (not finite past a standstill: no estimate)
            if s_end + REACH_SLACK_M < goal_arr[G_S_LO] and math.isfinite(rest) and late:
                out[j] = par[P_C_GOAL]
        return
    for j in range(nlon):
        reach = False
        for k in range(K + 1):
            # the step, or the way to it from the step before (where check_pair also looks)
            tt = t0 + k * dt
            tp = tt - dt if k > 0 else tt
            if tt < goal_arr[G_T_LO] - 1e-9 or tp > goal_arr[G_T_HI] + 1e-9:
                continue
            v = lon_v[j, k]
            vp = lon_v[j, k - 1] if k > 0 else v
            if max(v, vp) < goal_arr[G_V_LO] - 1e-6 or min(v, vp) > goal_arr[G_V_HI] + 1e-6:
                continue
            # the distance driven by the window's end on that way (linear in time, as the
            # check interpolates it: the path's arc length is never longer)
            dist = lon_s[j, k] - lon_s[j, 0]
            if k > 0 and tt > goal_arr[G_T_HI]:
                dist = lon_s[j, k - 1] - lon_s[j, 0] + (goal_arr[G_T_HI] - tp) / dt * (lon_s[j, k] - lon_s[j, k - 1])
            if ego[E_S] + dist + REACH_SLACK_M >= goal_arr[G_S_LO]:
                reach = True
                break
        if not reach:
            out[j] = par[P_C_GOAL]


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
            ob_hw, n_obs, dt, discs, lat_rng, lon_rng, ob_rng):  # fmt: skip
    """Where each candidate and each obstacle can be over the horizon: lateral moves across the
    path (``lat_rng`` (n, 2): the quintic's extremes on a grid of its length and the line past it,
    an evasive move between its start and its target with half a lane's overshoot), profiles
    along it (``lon_rng``), obstacles both (``ob_rng`` (n, 4), their extents included); the
    car's discs, their radius and the margin, and a time gap at the top speed are added to the
    candidates' ranges, and ahead of a profile's end the way it needs to brake and the room to
    turn out behind a standing obstacle (the terminal checks of :func:`check_pair`). Pairs check
    only the obstacles whose ranges meet theirs."""
    K = lon_s.shape[1] - 1
    s0 = ego[E_S]
    reach = par[P_R_DISC] + par[P_MARGIN]
    spread = 0.0
    for q in range(discs.shape[0]):
        spread = max(spread, abs(discs[q]))
    lat_pad = reach + 0.5 * spread  # the discs of a car yawed up to 30 deg
    lon_pad = reach + spread + par[P_V_MAX] * par[P_TIME_GAP]
    # ahead of a profile's end: what the terminal checks look at (braking still stops behind
    # the car ahead; a stop behind a standing obstacle leaves the room to turn out)
    ob_hw_max = 0.0
    for o in range(n_obs):
        for k in range(K + 1):
            if math.isfinite(ob_s[o, k]):
                ob_hw_max = max(ob_hw_max, ob_hw[o, k])
    room = _turn_out_m(par, 0.0, 0.0, ob_hw_max) + par[P_STANDSTILL] + par[P_LAT_MIN]
    s_far = s0 + 1.0
    for j in range(nlon):
        v_end = (lon_s[j, K] - lon_s[j, K - 1]) / dt
        stop_m = v_end * v_end / (2.0 * min(par[P_D_COMF], 0.8 * par[P_D_MAX]))
        lon_rng[j, 0] = lon_s[j, 0] - lon_pad
        lon_rng[j, 1] = lon_s[j, K] + max(lon_pad, reach + spread + stop_m + room)
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
        # the line (and offset) past the move, to the farthest profile's end (a pass: and the
        # line of the lane it returns to)
        back = is_pass(lat_coef[i], L)
        for q in range(9):
            sq = s_end + (s_far - s_end) * q / 8.0
            d = grid_row_at(grid, lane_line, lane, sq) + lat_off[i]
            lo, hi = min(lo, d), max(hi, d)
            if back:
                d = grid_row_at(grid, lane_line, int(lat_coef[i, LAT_BACK_LANE]), sq)
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
