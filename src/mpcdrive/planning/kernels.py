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
  2000), and quintics arriving in the goal region inside its time window (in the middle of
  both; and at the latest, for a car the wanted speed gets there too late).

Every pair (lateral, longitudinal) is a maneuver. A maneuver is checked on the grid ``t_k = k
dt`` against every obstacle's predicted Frenet box (swept: the segment of the two boxes'
relative motion between two samples against the sum of their extents and the margin), the
road (the body's four corners inside the edges of the lanes it may use and inside the road's
ends), and the vehicle (curvature, its rate, the friction circle); it is *safe* when nothing is
hit over the horizon and, at its end, braking still stops the car behind the car ahead. Costs
(seconds of travel time, :class:`~.config.PlannerConfig`) separate into a lateral and a
longitudinal part, which bound a pair's cost from below: pairs are checked in the order of that
bound and the search stops when the bound passes the best safe maneuver's cost (branch and
bound: most replannings check a handful of pairs; a goal miss that a profile cannot avoid is
part of that bound). A pair's check first drives it through the obstacles and the road alone
(what rejects most pairs) and stops at its first harm; the costs, lanes and vehicle limits
follow on the way it drove. Steering beyond the rate is a cost of the choice, not a wall. With no
safe maneuver, the one that is hit latest (its time to collision: the first harm, leaving the
road or touching an obstacle) is taken, the cheapest among equals.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .work import (
    LAT_BACK_LANE,
    PARALLEL_M,
    REL_CLEAR,
    REL_LEFT,
    REL_RIGHT,
    E_LANE,
    LON_FOLLOW,
    LON_STOP,
    MAX_LON,
    P_HL,
    P_HW,
    P_BAND_K,
    P_C_RATE,
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
)

from .candidates import longitudinal_candidates, longitudinal_costs
from .lateral import lateral_candidates
from .checks import _excess_now, _near_obstacles, _ranges, check_pair, goal_missed_by_profile
from .frenet import grid_row_at, is_pass


@njit(cache=True)
def plan(w):
    """One replanning on the struct ``w`` (:class:`~.work.PlannerWork`): candidates, checks,
    the choice (module docstring). The choice and its figures go to ``w.result``, the maneuver to
    ``w.plan_*`` and its relations to the obstacles to ``w.relation``."""
    c = np.empty(6)
    lateral_candidates(w)
    s_stop = longitudinal_candidates(w, c)
    longitudinal_costs(w, s_stop)
    # the struct's arrays read once (each read of a field costs a reference count)
    par, grid, ego, goal_arr = w.par, w.grid, w.ego, w.goal
    g_kappa, g_heading, lon_bend, lon_vend = w.g_kappa, w.g_heading, w.lon_bend, w.lon_vend
    lane_left, lane_right, lane_line, lane_kind = w.lane_left, w.lane_right, w.lane_line, w.lane_kind
    same_left, same_right, all_left, all_right = w.same_left, w.same_right, w.all_left, w.all_right
    edge_win, path = w.edge_win, w.path
    lat_coef, lat_len, lat_lane, lat_off, lat_cost = w.lat_coef, w.lat_len, w.lat_lane, w.lat_off, w.lat_cost
    lon_s, lon_v, lon_a, lon_ok, lon_cost = w.lon_s, w.lon_v, w.lon_a, w.lon_ok, w.lon_cost
    ob_s, ob_e, ob_hl, ob_hw, ob_or = w.ob_s, w.ob_e, w.ob_hl, w.ob_hw, w.ob_or
    n_obs = w.ob_n[0]
    dt = w.dt[0]
    relation, plan_s, plan_v, plan_a, plan_d = w.relation, w.plan_s, w.plan_v, w.plan_a, w.plan_d
    discs = w.discs
    keys, codes = w.keys, w.order
    nlat, nlon = w.lat_n[0], w.lon_n[0]
    # the goal's miss cost that a profile pays for sure belongs in the pairs' bound, and so does
    # the cost of steering beyond the rate that the route's bends ask at its speeds (the choice
    # scores the rate's excess, and a pair steers at least at its profile's ``lon_bend``)
    prepaid = w.lon_goal
    goal_missed_by_profile(par, ego, goal_arr, lon_s, lon_v, nlon, dt, w.grid, w.g_vref, w.g_tref, prepaid)
    c_rate = par[P_C_RATE]
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
            keys[m] = lat_cost[i] + lon_cost[j] + prepaid[j] + c_rate * max(lon_bend[j] - 1.0, 0.0)
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
        n_obs, dt, discs, lat_rng, lon_rng, ob_rng,
    )  # fmt: skip
    # the choice: the cheapest safe maneuver, its steering beyond the rate costed (the controller
    # steers at its limit, the obstacle and road rows keep the clearance); else the one hit
    # latest (time to collision), feasible first. The rate's cost is at least the bends' (in the
    # key): the pairs' bound holds.
    best = -1
    best_total = math.inf
    checked = 0
    n_safe = 0
    fb, fb_ttc, fb_total, fb_feasible = -1, -1.0, math.inf, False
    for q in range(m):
        key = keys[order[q]]
        if best >= 0 and key >= best_total:
            break
        code = codes[order[q]]
        i, j = code // MAX_LON, code % MAX_LON
        base = key - c_rate * max(lon_bend[j] - 1.0, 0.0)  # the rate's cost is the check's
        n_rel = _near_obstacles(i, j, lat_rng, lon_rng, ob_rng, n_obs, rel_idx)
        safe, feasible, rate, ttc, pair, goal = check_pair(
            i, j, excess0, False, best_total - base, prepaid[j], lon_vend[j], par, grid, ego, goal_arr, g_kappa, g_heading, lon_bend[j],
            lane_left, lane_right, lane_line, lane_kind, same_left, same_right, all_left, all_right, lat_coef, lat_len,
            lat_lane, lat_off, lon_s, lon_v, lon_a, ob_s, ob_e, ob_hl, ob_hw, ob_or, n_obs, dt, relation, plan_s, plan_v, plan_a, plan_d,
            discs, rel_idx, n_rel, scratch, path, edge_win,
        )  # fmt: skip
        checked += 1
        total = base + pair
        if safe and feasible:
            n_safe += 1
            score = total + c_rate * max(rate - 1.0, 0.0)
            if score < best_total:
                best, best_total = code, score
        better = False
        if feasible and not fb_feasible:
            better = True
        elif feasible == fb_feasible:
            if ttc > fb_ttc + 1e-9 or (abs(ttc - fb_ttc) <= 1e-9 and total < fb_total):
                better = True
        if better:
            fb, fb_ttc, fb_total, fb_feasible = code, ttc, total, feasible
    safe_found = best >= 0
    if best < 0:
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
        i, j, excess0, True, math.inf, prepaid[j], lon_vend[j], par, grid, ego, goal_arr, g_kappa, g_heading, lon_bend[j], lane_left,
        lane_right, lane_line, lane_kind, same_left, same_right, all_left, all_right, lat_coef, lat_len, lat_lane, lat_off, lon_s, lon_v,
        lon_a, ob_s, ob_e, ob_hl, ob_hw, ob_or, n_obs, dt, relation, plan_s, plan_v, plan_a, plan_d, discs, rel_idx, 0,
        scratch, path, edge_win,
    )  # fmt: skip
    r[R_I] = i
    r[R_J] = j
    r[R_COST] = best_total
    r[R_TTC] = ttc
    # the lane the maneuver ends in (a pass: the one it returns to)
    passing = is_pass(lat_coef[i], lat_len[i])
    r[R_LANE] = int(lat_coef[i, LAT_BACK_LANE]) if passing else lat_lane[i]
    r[R_OFF] = 0.0 if passing else lat_off[i]
    r[R_KIND] = w.lon_kind[j]
    r[R_TARGET] = w.lon_target[j]
    r[R_GOAL] = 1.0 if goal else 0.0
    r[R_RATE] = rate
    # an obstacle that keeps to its line (a parked car, a car in the next lane) and that the
    # maneuver passes beside is passed on that side over the approach too: the controller's
    # lateral row acts from the start (the nearest-point half-plane of a car still behind its
    # corner would hold the car back as it turns out). A crossing car keeps its own relations.
    K = lon_s.shape[1] - 1
    for o in range(n_obs):
        first = -1
        for k in range(K + 1):
            if relation[o, k] == REL_LEFT or relation[o, k] == REL_RIGHT:
                first = k
                break
        if first <= 0:
            continue
        side = relation[o, first]
        e_first = ob_e[o, first]
        for k in range(first - 1, -1, -1):
            if relation[o, k] != REL_CLEAR or not math.isfinite(ob_s[o, k]):
                break
            if abs(ob_e[o, k] - e_first) > PARALLEL_M:
                break
            relation[o, k] = side
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
    from . import candidates, checks, contact, frenet, work

    files = [m.__file__ for m in (work, frenet, candidates, contact, checks) if m.__file__ is not None]
    _jitcache.refresh(plan, files)


_refresh_cache()
