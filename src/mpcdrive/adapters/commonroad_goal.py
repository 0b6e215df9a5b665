"""The drive a CommonRoad planning problem asks for: route, where to stop, and the speed.

* **Route.** :func:`~.commonroad_route.find_route` to the goal lanelets; a goal without a
  position follows the lane (:func:`~.commonroad_route.lane_forward`) far enough for the goal
  time at the cruise speed plus the braking distance.
* **Where to stop.** The reference speed is a curvature / friction limited
  :class:`~mpcdrive.paths.speed_profile.SpeedProfile` that ends at 0 where the path ends. With a
  goal region the path goes on along the lane past it (:func:`~.commonroad_route.lane_forward`:
  with a time window, as far as the car drives by the window's end, when the run ends, and its
  braking distance) and the car drives through it and on (a region reaching the route's end
  holds the car when it stops there); when no cruise speed has the car
  in the region inside the time window that way and the goal's speed range admits a stop, the path
  ends in the middle of the route's stretch in the region instead (the car stops inside it, arriving
  by the window's end).
* **Road's end.** Where the route ends at the end of the mapped road (a lane without a
  successor, nothing beside it going on: :func:`~.commonroad_route.mapped_road_ends`), the path
  ends :data:`FRONT_REACH_M` + :data:`ROAD_MARGIN_M` before it (:func:`stop_inside`): the car
  stops with its whole body on the road, its front bumper the road margin short of the end.
* **Speed.** The cruise speed (the profile's top speed) is the goal speed range's middle, else
  the initial speed (:data:`DEFAULT_SPEED_MPS` for a car starting at rest); with a time window it
  is the speed closest to that (inside the goal's speed range) whose profile is in the goal region
  inside the window. When no speed does, the plan's note says so and the run shows what happens.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..models.presets import PRESETS
from . import commonroad_route as cr

LAT_ACCEL_MPS2 = 4.0  # lateral acceleration the reference speed allows in bends
#: the harder bends [m/s^2] a plan may take, in turn, when no cruise speed at
#: :data:`LAT_ACCEL_MPS2` has the car in the goal region inside its time window (the window asks
#: for a faster drive through the bends): at most 0.8 g, inside the friction circle the controller
#: plans with on every CommonRoad car (0.9 of a_max = 11.5 m/s^2: 10.35 m/s^2) with room left to
#: brake and steer
HURRY_LAT_ACCEL_MPS2 = (6.0, 8.0)
#: the fastest [m/s] a plan with harder bends drives (60 km/h: junctions, roundabouts, town
#: roads). Faster, the dynamic car's side slip at those lateral accelerations takes it off its
#: line (DEU_A9-2 on the ST plant, bends at 8 m/s^2 at 27-33 m/s: 2.8 m off the reference and out
#: of the goal), and the comfortable bends stay
HURRY_MAX_SPEED_MPS = 60.0 / 3.6
COMFORT_ACCEL_MPS2 = 3.0  # largest forward / braking acceleration of the reference speed
DEFAULT_SPEED_MPS = 8.0  # cruise speed of a car starting (nearly) at rest without a goal speed
RUN_ON_S = 3.0  # the run ends this long after the reference stops (unless the goal time is later)
#: the vehicle whose longitudinal limit the planned speeds keep to (a_max 11.5 m/s^2, v_switch
#: 7.319 m/s, the BMW 320i's; the default vehicle, the Ford Escort, switches at 4.755 m/s)
_LIMIT_PRESET = PRESETS["commonroad_bmw_320i"]
_PLAN_DS_M = 0.25  # grid of the speed profiles compared while planning
_MISSED = "no cruise speed"  # how the note of a plan that misses the goal window begins
APPROACH_LEAD_M = 5.0  # a slower approach is back at the goal speed this far before the region [m]
#: the speeds planned for a goal keep this far [m/s] inside its speed range (at most a quarter of
#: it): the controller's speed lags the reference by up to about that while it speeds up, and a
#: plan at the range's very bound leaves the car just outside it
GOAL_SPEED_MARGIN_MPS = 0.3


def inside_speeds(v: tuple[float, float]) -> tuple[float, float]:
    """The goal's speed range ``v`` [m/s] that the plans aim for: :data:`GOAL_SPEED_MARGIN_MPS`
    inside each bound (a lower bound of 0, a stop, stays)."""
    lo, hi = float(v[0]), float(v[1])
    m = min(GOAL_SPEED_MARGIN_MPS, 0.25 * (hi - lo))  # (an open range: inf - m stays inf)
    return (lo + m if lo > 0.0 else lo), hi - m


#: the fastest change of curvature [1/(m s)] the reference speed lets the steering follow: the
#: controller's steering rate (0.95 of CommonRoad's 0.4 rad/s, the same for its three cars) over
#: the longest wheelbase of them (the BMW 320i's 2.58 m): the speed slows where a bend sets in
#: faster than that (a roundabout's exit, a tight turn at a junction)
CURVATURE_RATE_1PMS = 0.95 * _LIMIT_PRESET.max_steer_rate_rad_s / _LIMIT_PRESET.params.wheelbase_m
#: distance [m] the body keeps from the road's edges (the controller's road margin), and the
#: front bumper from the mapped road's end where the car stops there
ROAD_MARGIN_M = 0.1
#: how far [m] the front bumper reaches ahead of the reference point (the centre of gravity, the
#: middle of CommonRoad's rectangle) on the longest CommonRoad vehicle (VW Vanagon: 4.569 m): one
#: path serves every ``--vehicle``
FRONT_REACH_M = max(0.5 * p.length_m for n, p in PRESETS.items() if n.startswith("commonroad_"))
#: the widest CommonRoad vehicle's width [m] (the VW Vanagon's)
WIDEST_M = max(p.width_m for n, p in PRESETS.items() if n.startswith("commonroad_"))


#: the share of the tyres' friction circle (CommonRoad's ``a_max``, the radius its feasibility
#: check of ST drives uses) that the controller plans with: per-stage steering and acceleration
#: bounds at the planned speed (:mod:`mpcdrive.ocp.friction`)
FRICTION_SHARE = 0.9


def friction_accel(a_max_mps2: float) -> float:
    """The controller's friction circle [m/s^2] for a vehicle whose tyres give ``a_max_mps2``."""
    return FRICTION_SHARE * float(a_max_mps2)


def accel_limit(v_max_mps: float) -> float:
    """CommonRoad's longitudinal limit at speeds up to ``v_max_mps``, with a 10 % margin: a_max,
    reduced to a_max v_switch / v above v_switch [m/s^2]."""
    return 0.9 * _LIMIT_PRESET.accel_limit_mps2(v_max_mps)


@dataclass(frozen=True)
class DrivePlan:
    """Route, reference polyline and speed of a planning problem (module docstring)."""

    route: tuple[int, ...]
    centerline: np.ndarray  # (M, 2) [m]
    mode: str  # "stop in goal", "through goal", "follow lane"
    v_cruise_mps: float
    v_start_mps: float
    accel_mps2: float
    duration_s: float
    goal_window_s: tuple[float, float] | None
    goal_arc_m: tuple[float, float] | None  # the route's stretch inside the goal region [m]
    arrival_s: float | None  # when the reference speed reaches the goal region [s]
    note: str
    start_m: float = 0.0  # the car's arc length on the centre line (it begins behind the car) [m]
    top_speed_until: tuple[tuple[float, float], ...] = ()  # a slower approach: (s_until [m], v [m/s])
    lat_accel_mps2: float = LAT_ACCEL_MPS2  # the bends' lateral acceleration [m/s^2]

    def speed_profile_spec(self) -> dict:
        """The ``controller.speed_profile`` entry of the scenario."""
        return {
            "lateral_accel_max_mps2": self.lat_accel_mps2,
            "accel_max_mps2": self.accel_mps2,
            "decel_max_mps2": self.accel_mps2,
            "v_max_mps": self.v_cruise_mps,
            "v_start_mps": self.v_start_mps,
            "v_end_mps": 0.0,
            "curvature_window_m": 0.3,
            "start_m": self.start_m,
            "top_speed_until": [list(c) for c in self.top_speed_until],
            "curvature_rate_max_1pms": CURVATURE_RATE_1PMS,
        }


#: the reference path through the route's centre line: a cubic spline, tabulated every 0.2 m.
#: The line is smoothed already, so the spline does not overshoot, and its curvature is
#: continuous; a shape-preserving curve (pchip) would flatten x(t) and y(t) at each waypoint where
#: one of them peaks (wherever the road heads along an axis), a curvature spike that the steering
#: rate cannot follow
PATH_INTERPOLATION = "spline"
PATH_DS_M = 0.2


def path_spec(line: np.ndarray) -> dict:
    """The scenario's ``path`` entry for the centre line ``line`` (M, 2) [m]
    (:data:`PATH_INTERPOLATION`)."""
    return {
        "type": "waypoints",
        "points": [tuple(map(float, p)) for p in line],
        "ds_m": PATH_DS_M,
        "interpolation": PATH_INTERPOLATION,
    }


def line_path(line: np.ndarray):
    """The reference path along the centre line ``line`` (M, 2) [m], as :func:`path_spec`
    describes it."""
    from ..paths import WaypointPath

    return WaypointPath(line, ds_m=PATH_DS_M, interpolation=PATH_INTERPOLATION)


def _profile(path, v_cruise: float, pb: _Problem, caps: tuple = ()):
    """The speed profile along ``path`` (:func:`line_path`) of problem ``pb``, starting at its
    initial speed where the car is (``caps``: its ``top_speed_until``)."""
    from ..paths.speed_profile import SpeedProfile

    return SpeedProfile(
        path,
        pb.lat,
        pb.accel,
        pb.accel,
        v_cruise,
        v_start_mps=pb.v0,
        v_end_mps=0.0,
        ds_m=_PLAN_DS_M,
        curvature_window_m=0.3,
        s_start_m=start_arc(path, pb.p0),
        top_speed_until=caps,
        curvature_rate_max_1pms=CURVATURE_RATE_1PMS,
    )


def start_arc(path, p0: np.ndarray) -> float:
    """Arc length [m] of the car at ``p0`` on ``path`` (which begins a metre behind it)."""
    return float(min(max(path.project(np.asarray(p0, float), 0.0, 10.0)[0], 0.0), path.length_m))


#: how far [m] along the path from its own end a route's closing edge is looked for (the path
#: ends on the route's last lanelet's centre line; a slanted edge reaches a few metres from it)
END_SEARCH_M = 20.0


def road_ends_m(net, route, path) -> tuple[float | None, float | None]:
    """(start_m, end_m): the arc lengths [m] along ``path`` (the route's reference path; its
    ends extend along their tangents) where the mapped road begins / ends around ``route``
    (:func:`~.commonroad_route.mapped_road_ends`; None where the network goes on). A closing
    edge counts from its point nearest the road (a slanted edge: its near corner), and of lanes
    side by side the road reaches as far as the farthest: past a lane's end the lane beside it is
    still road. Each edge is projected near its own end of the path (a route that comes back
    to where it began has both edges in one place)."""
    start, end = cr.mapped_road_ends(net, route)

    def arcs(pts: np.ndarray, near_m: float) -> np.ndarray:  # (lanelets, 2): each closing edge's points
        s = [path.project(np.asarray(q, float), near_m, END_SEARCH_M)[0] for q in pts]
        return np.array(s, float).reshape(-1, 2)

    start_m = None if start is None else float(np.min(arcs(start, 0.0).max(axis=1)))
    end_m = None if end is None else float(np.max(arcs(end, path.length_m).min(axis=1)))
    return start_m, end_m


def stop_inside(net, route, line: np.ndarray) -> np.ndarray:
    """``line`` (the route's centre line) ending where a car stopping at its end has its whole
    body on the road: :data:`FRONT_REACH_M` + :data:`ROAD_MARGIN_M` before the mapped road's end
    where the route ends there (and never closer than a metre ahead of the car, which stands a
    metre along the line); unchanged where the road goes on past the line's end."""
    _, end_m = road_ends_m(net, route, line_path(line))
    length = float(np.sum(np.hypot(*np.diff(line, axis=0).T)))
    if end_m is None:
        return line
    s_stop = max(end_m - FRONT_REACH_M - ROAD_MARGIN_M, min(2.0, length))
    return _cut(line, s_stop) if s_stop < length - 1e-6 else line


def _cut(line: np.ndarray, s_end: float) -> np.ndarray:
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(line, axis=0).T))]
    k = int(np.searchsorted(s, s_end))
    if k >= len(line):
        return line
    end = np.array([np.interp(s_end, s, line[:, 0]), np.interp(s_end, s, line[:, 1])])
    return np.vstack([line[:k], end]) if s_end - s[k - 1] > 1e-3 else line[:k]


def _candidates(v_want: float, lo: float, hi: float) -> list[float]:
    """Cruise speeds to try, closest to ``v_want`` first, within [lo, hi]."""
    grid = np.unique(np.r_[np.linspace(lo, hi, 25), np.clip(v_want, lo, hi)])
    return sorted(grid.tolist(), key=lambda v: abs(v - v_want))


def plan_drive(net, pp, p0: np.ndarray, yaw0: float, v0: float, dt_s: float) -> DrivePlan:
    """The route and speed for planning problem ``pp`` from the pose (p0, yaw0) at ``v0``
    (module docstring); ValueError when no route reaches the goal."""
    goal = pp.goal.state_list[0]
    steps = cr.bounds(getattr(goal, "time_step", None))
    window = None if steps is None else (steps[0] * dt_s, steps[1] * dt_s)
    v_goal = cr.bounds(getattr(goal, "velocity", None))
    if v_goal is not None:
        v_goal = inside_speeds(v_goal)
    shapes = [sh for st in pp.goal.state_list for sh in cr.goal_shapes(st)]
    v_want = 0.5 * (v_goal[0] + v_goal[1]) if v_goal is not None else (v0 if v0 >= 1.0 else DEFAULT_SPEED_MPS)
    v_lo, v_hi = (max(v_goal[0], 1.0), max(v_goal[1], 1.0)) if v_goal is not None else (1.0, max(v_want, v0) * 1.25)
    accel = min(COMFORT_ACCEL_MPS2, accel_limit(max(v_hi, v0) + 2.0))
    pb = _Problem(v0, accel, window, dt_s, np.asarray(p0, float))
    t_last = window[1] if window is not None and math.isfinite(window[1]) else 60.0
    starts = cr.start_lanelets(net, p0, yaw0)
    goals = cr.goal_lanelets(net, pp)
    brake_m = max(v_hi, v0) ** 2 / (2 * accel) + 10.0
    if not goals:
        first = net.find_lanelet_by_id(starts[0])
        # a time-only goal is to drive on for its whole time: at a fork nothing decides, the
        # branch that turns least (after a goal region the route may end at such a fork instead)
        route = cr.lane_forward(
            net, [starts[0]], max(v_want, v0) * t_last + brake_m, from_m=cr._arc_to(first, p0), choose=True
        )
        line = cr.route_centerline(net, route, p0, max(v_want, v0) * t_last + brake_m)
        route = cr.trim_route(net, route, line)
        line = stop_inside(net, route, line)
        return _finish(
            route, line, "follow lane", v_want, pb, note="time-only goal: follows the lane, stops at its end"
        )
    route = cr.find_route(net, starts, goals)
    if route is None:
        raise ValueError(f"no route from lanelet(s) {starts} to the goal lanelets {sorted(goals)}")
    goal_xy = cr.point(shapes[0].center) if shapes else None
    line = stop_inside(net, route, cr.route_centerline(net, route, p0, goal_xy=goal_xy))
    # the route's stretch in the goal region (the centre line's point nearest a small region it misses)
    arc = (cr.arc_inside(line, shapes) or cr.nearest_arc(line, shapes)) if shapes else None
    if arc is None:  # a goal of lanelets only, or a region the centre line misses: stop at the route's end
        return _finish(route, line, "stop at route end", v_want, pb, note="stops at the end of the goal lanelet")
    # past the goal the route goes on along the lane (where the network does): far enough to
    # brake after the region, and with a time window, for the car to drive on at its top speed
    # until the run ends (the window's end) and brake then, rather than stop at the route's end
    ahead_m = arc[1] + brake_m
    if window is not None and math.isfinite(window[1]):
        car_m = cr._arc_to(net.find_lanelet_by_id(route[0]), p0)  # (lane_forward counts from the lanelet's start)
        ahead_m = max(ahead_m, car_m + max(v_hi, v0) * window[1] + brake_m)
    ahead = cr.lane_forward(net, route, ahead_m)
    first = None
    # comfortable bends first; harder ones only where the goal's window asks for them
    for lat in (LAT_ACCEL_MPS2, *HURRY_LAT_ACCEL_MPS2):
        v_range = (v_lo, v_hi)
        if lat != LAT_ACCEL_MPS2:
            v_range = (v_lo, min(v_hi, HURRY_MAX_SPEED_MPS))
            if v0 > HURRY_MAX_SPEED_MPS or v_range[1] < v_range[0]:
                break
        ctx = _GoalDrive(
            net, route, ahead, line, shapes, arc, p0, v_want, v_range, v_goal, replace(pb, lat=lat), goal_xy
        )
        for way in (_through, _stop):
            plan = way(ctx)
            if plan is not None and not plan.note.startswith(_MISSED):
                if lat != LAT_ACCEL_MPS2:
                    plan = replace(plan, note=f"{plan.note}, bends at up to {lat:g} m/s^2 to make the window")
                return plan
            first = first or plan
        if window is None:
            break
    return first


@dataclass(frozen=True)
class _GoalDrive:
    """What the two ways of driving to a goal region compare."""

    net: object
    route: list
    ahead: list  # the route continued along the lane past the goal region
    line: np.ndarray  # the route's centre line [m]
    shapes: list  # goal region shapes
    arc: tuple  # the route's stretch in the region [m]
    p0: np.ndarray
    v_want: float
    v_range: tuple
    v_goal: tuple | None
    pb: object
    goal_xy: np.ndarray | None


def _stop(g: _GoalDrive):
    """Stop in the middle of the route's stretch in the goal region, arriving by the window's end."""
    route, line, arc, v_want, v_range, pb = g.route, g.line, g.arc, g.v_want, g.v_range, g.pb
    if g.v_goal is not None and g.v_goal[0] > 0.5:
        return None
    window = pb.window
    stop_line = _cut(line, 0.5 * (arc[0] + arc[1]))
    path = line_path(stop_line)
    for v in _candidates(v_want, *v_range):
        prof = _profile(path, v, pb)
        t_in = float(prof.time_at(min(arc[0] + 1.0, path.length_m)))
        if window is None or t_in <= window[1] - 0.1 * (window[1] - window[0]) - pb.dt_s:
            return _finish(
                route,
                stop_line,
                "stop in goal",
                v,
                pb,
                arc=arc,
                arrival=t_in,
                note=f"stops in the goal region (reached at {t_in:.1f} s)",
            )
    return None


def _through(g: _GoalDrive):
    """Drive through the goal region along the lane to the route's end; in the region inside the
    time window (a region reaching the route's end holds the stopped car from then on). First at
    one cruise speed; when even the slowest one in the goal's speed range is there too early, with
    a slower approach that speeds up to the goal's speed before the region (:func:`_approaches`)."""
    ahead, v_want, v_range, pb = g.ahead, g.v_want, g.v_range, g.pb
    window = pb.window
    line = stop_inside(g.net, ahead, cr.route_centerline(g.net, ahead, g.p0, goal_xy=g.goal_xy))
    arc = cr.arc_inside(line, g.shapes) or cr.nearest_arc(line, g.shapes)
    s_end = float(np.sum(np.hypot(*np.diff(line, axis=0).T)))
    best = None
    tries = [(v, ()) for v in _candidates(v_want, *v_range)]
    tries += _approaches(v_want, v_range, pb, arc)
    path = line_path(line)
    for v, caps in tries:
        t_in, t_out, miss = _timing(_profile(path, v, pb, caps), arc, s_end, window)
        if best is None or miss < best[2]:
            best = (v, t_in, miss, caps)
        if miss == 0.0:  # in the region at some time inside the window (by a margin from its ends)
            stay = " and stops in it" if math.isinf(t_out) else ""
            slow = f" after an approach at {caps[0][1]:.1f} m/s" if caps else ""
            return _finish(
                ahead,
                line,
                "through goal",
                v,
                pb,
                arc=arc,
                arrival=t_in,
                caps=caps,
                note=f"drives into the goal region at {t_in:.1f} s{slow}{stay}",
            )
    v, t_in, _, caps = best
    return _finish(
        ahead,
        line,
        "through goal",
        v,
        pb,
        arc=arc,
        arrival=t_in,
        caps=caps,
        note=f"{_MISSED} in [{v_range[0]:.1f}, {v_range[1]:.1f}] m/s has the car in the goal region "
        f"in its time window [{window[0]:.1f}, {window[1]:.1f}] s: drives at {v:.1f} m/s "
        f"(in the region at {t_in:.1f} s)",
    )


def _timing(prof, arc: tuple, s_end: float, window) -> tuple[float, float, float]:
    """(time in, time out of the goal region [s], by how much the stay misses the time window
    shrunk by a margin at both ends [s], 0 when inside) of the reference speed ``prof``."""
    if arc[1] - arc[0] < 2.0:  # a small region (or the point nearest one): passed at one time
        t_in = t_out = float(prof.time_at(0.5 * (arc[0] + arc[1])))
    else:
        t_in = float(prof.time_at(arc[0] + 1.0))
        t_out = math.inf if arc[1] >= s_end - 1.0 else float(prof.time_at(arc[1] - 1.0))
    if window is None:
        return t_in, t_out, 0.0
    margin = min(0.3, 0.25 * (window[1] - window[0]))
    return t_in, t_out, max(window[0] + margin - min(t_out, 1e9), t_in + margin - window[1], 0.0)


def _approaches(v_want: float, v_range: tuple, pb: _Problem, arc: tuple) -> list:
    """(goal speed, caps) plans that approach the goal region slower than the goal's speed range
    allows and speed up to the goal speed (at the plan's acceleration) :data:`APPROACH_LEAD_M`
    before the region: for goal speeds closest to ``v_want`` first, the least slowing first."""
    if pb.window is None:
        return []
    out = []
    for v in _candidates(v_want, *v_range):
        for v_slow in np.linspace(v, 1.0, 25)[1:]:
            s_up = arc[0] - APPROACH_LEAD_M - (v * v - v_slow * v_slow) / (2.0 * pb.accel)
            if s_up > 0.0:
                out.append((v, ((float(s_up), float(v_slow)),)))
    return out


@dataclass(frozen=True)
class _Problem:
    v0: float  # initial speed [m/s]
    accel: float  # forward / braking acceleration of the reference speed [m/s^2]
    window: tuple[float, float] | None  # goal time window [s]
    dt_s: float
    p0: np.ndarray  # the car's start [m]
    lat: float = LAT_ACCEL_MPS2  # lateral acceleration in bends [m/s^2]


def _finish(
    route, line, mode: str, v: float, pb: _Problem, *, arc=None, arrival=None, note="", caps: tuple = ()
) -> DrivePlan:
    path = line_path(line)
    prof = _profile(path, v, pb, caps)
    duration = float(prof.time_at(path.length_m)) + RUN_ON_S
    if pb.window is not None:
        # through the goal window's first step (a car waiting in the region must be there then),
        # never past its last
        duration = min(max(duration, pb.window[0] + pb.dt_s), pb.window[1] + pb.dt_s)
    return DrivePlan(
        tuple(route),
        line,
        mode,
        float(v),
        float(pb.v0),
        float(pb.accel),
        float(duration),
        pb.window,
        arc,
        arrival,
        note,
        start_arc(path, pb.p0),
        caps,
        pb.lat,
    )


def _vertices(shape) -> np.ndarray:
    """(M, 2) points [m] outlining a CommonRoad shape (a circle by its four extreme points)."""
    verts = getattr(shape, "vertices", None)
    if verts is not None:
        return np.asarray(verts, float)
    c, r = cr.point(shape.center), float(getattr(shape, "radius", 0.0))
    return c + r * np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])


def frenet_interval(line: np.ndarray, points: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """((s_lo, s_hi), (e_lo, e_hi)) [m]: the arc lengths along the polyline ``line`` (M, 2) of the
    nearest points to ``points`` (P, 2), and their lateral offsets (positive left)."""
    p = np.asarray(line, float)
    seg = np.diff(p, axis=0)
    L = np.hypot(seg[:, 0], seg[:, 1])
    s0 = np.r_[0.0, np.cumsum(L)][:-1]
    S, E = [], []
    for q in np.asarray(points, float):
        t = np.clip(np.einsum("ij,ij->i", q - p[:-1], seg) / np.maximum(L * L, 1e-12), 0.0, 1.0)
        near = p[:-1] + t[:, None] * seg
        d = np.hypot(*(q - near).T)
        i = int(np.argmin(d))
        cross = seg[i, 0] * (q[1] - p[i, 1]) - seg[i, 1] * (q[0] - p[i, 0])
        S.append(s0[i] + t[i] * L[i])
        E.append(math.copysign(d[i], cross))
    return (float(min(S)), float(max(S))), (float(min(E)), float(max(E)))


#: how far [m] to either side of the route the goal region's lateral extent is looked for, and
#: the step [m] of the search
GOAL_SEARCH_M, GOAL_STEP_M = 8.0, 0.1


def _lateral_band(line: np.ndarray, shapes, arc: tuple[float, float]) -> tuple[float, float] | None:
    """(lo, hi) [m]: the lateral offsets from the polyline ``line`` that lie inside the goal
    ``shapes`` all along the route's stretch ``arc`` [m] in them (at each point every metre, the
    stretch of the normal through it inside the region; their common part), None where the line
    is inside nowhere. A goal of one lane is that lane, not the lanes beside it."""
    import shapely

    area = shapely.union_all([sh.shapely_object for sh in shapes])
    shapely.prepare(area)
    p = np.asarray(line, float)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
    t = np.gradient(p, axis=0)
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    n = np.column_stack([-t[:, 1], t[:, 0]])
    idx = np.flatnonzero((s >= arc[0] - 1e-9) & (s <= arc[1] + 1e-9))
    d = np.arange(-GOAL_SEARCH_M, GOAL_SEARCH_M + GOAL_STEP_M / 2, GOAL_STEP_M)
    zero = int(np.argmin(np.abs(d)))
    lo, hi = -math.inf, math.inf
    found = False
    for i in idx:
        q = p[i] + d[:, None] * n[i]
        inside = shapely.contains_xy(area, q[:, 0], q[:, 1])
        if not inside[zero]:
            continue
        a = zero
        while a > 0 and inside[a - 1]:
            a -= 1
        b = zero
        while b < len(d) - 1 and inside[b + 1]:
            b += 1
        lo, hi, found = max(lo, float(d[a])), min(hi, float(d[b])), True
    return (lo, hi) if found and lo <= hi else None


def goal_spec(pp, line: np.ndarray, plan: DrivePlan) -> dict | None:
    """The scenario's ``goal`` entry (the maneuver planner's goal) of planning problem ``pp`` along
    the route's centre line ``line``: the route's stretch in the goal region and the region's
    lateral extent, the time window, the speed and orientation ranges of its first state with a
    position; None for a goal without a position (the time-only goals: the reference drives them)."""
    for st in pp.goal.state_list:
        shapes = cr.goal_shapes(st)
        if not shapes:
            continue
        arc, offset = frenet_interval(line, np.vstack([_vertices(sh) for sh in shapes]))
        if plan.goal_arc_m is not None:  # the route's own stretch inside the region
            arc = plan.goal_arc_m
            band = _lateral_band(line, shapes, arc)
            if band is not None:
                offset = band
        out: dict = {"arc_m": list(arc), "offset_m": list(offset)}
        if plan.goal_window_s is not None:
            lo, hi = plan.goal_window_s
            out["time_s"] = [lo, hi if math.isfinite(hi) else None]
        v = cr.bounds(getattr(st, "velocity", None))
        if v is not None:
            out["speed_mps"] = list(inside_speeds((max(v[0], 0.0), v[1])))
        yaw = cr.bounds(getattr(st, "orientation", None))
        if yaw is not None and yaw[1] - yaw[0] < 2.0 * math.pi - 1e-6:
            out["yaw_deg"] = [math.degrees(yaw[0]), math.degrees(yaw[1])]
        return out
    return None


def goal_miss(imp, result) -> str | None:
    """Why no state of the drive (``result``, on the import ``imp``:
    :class:`~.commonroad.CommonRoadImport`) is in the goal region, in words: the goal's parts (position,
    time window, orientation, speed) that the drive's closest state misses, with the figures;
    None when the goal was reached or the planning problem has no goal states. The closest state
    is the one meeting most parts, position first, then nearest the goal's position, earliest on
    a tie."""
    from shapely.geometry import Point
    from shapely.ops import unary_union

    dt = imp.spec.dt_s
    best: tuple | None = None
    for g in imp.planning_problem.goal.state_list:
        pos = g.position if g.has_value("position") else None
        shape = None
        if pos is not None:
            shape = getattr(pos, "shapely_object", None)
            if shape is None and hasattr(pos, "shapes"):
                shape = unary_union([sh.shapely_object for sh in pos.shapes])
        for k in range(len(result.t_s)):
            x = result.x[k]
            xy = np.array([x[0], x[1]])
            inside = pos is None or bool(pos.contains_point(xy))
            d_m = 0.0 if inside or shape is None else float(shape.distance(Point(xy)))
            parts = _goal_parts(g, (inside, d_m), float(x[2]), float(x[3]), int(round(result.t_s[k] / dt)), dt)
            if not parts:
                continue
            met = sum(ok for ok, _ in parts.values())
            key = (parts.get("position", (True, ""))[0], met, -d_m, -k)
            if best is None or key > best[0]:
                best = (key, k, parts)
    if best is None:
        return None
    _, k, parts = best
    missed = [why for ok, why in parts.values() if not ok]
    if not missed:
        return None
    return f"closest at t = {result.t_s[k]:.2f} s: " + "; ".join(missed)


def _goal_parts(g, where: tuple[bool, float], yaw: float, v_mps: float, step: int, dt: float) -> dict:
    """Each part of one goal state as ``name: (met, why not in words)``; ``where``: whether the
    state is in the goal's position, and its distance [m] from it (0 inside)."""
    parts: dict = {}
    if getattr(g, "time_step", None) is not None:
        lo, hi = g.time_step.start, g.time_step.end
        parts["time"] = (
            bool(g.time_step.contains(step)),
            f"t = {step * dt:.2f} s is outside the goal's time window [{lo * dt:.2f}, {hi * dt:.2f}] s",
        )
    if g.has_value("position"):
        parts["position"] = (where[0], f"outside the goal's position ({where[1]:.1f} m away)")
    if g.has_value("orientation"):  # (AngleInterval.contains takes the angle modulo 2 pi)
        o = g.orientation
        parts["orientation"] = (
            bool(o.contains(yaw)),
            f"heading {yaw:.2f} rad is outside [{o.start:.2f}, {o.end:.2f}] rad",
        )
    if g.has_value("velocity"):
        w = g.velocity
        parts["velocity"] = (
            bool(w.contains(v_mps)),
            f"speed {v_mps:.2f} m/s is outside [{w.start:.2f}, {w.end:.2f}] m/s",
        )
    return parts
