"""Generated CommonRoad scenario families: one generator per family, each variation drawn from a seed.

Every ``make_<family>(seed)`` builds a commonroad-io ``Scenario`` and ``PlanningProblemSet`` from
``numpy.random.default_rng(seed)``: the same seed gives the same scenario (and, through
:func:`write_scenario`, the same bytes). Seeds 0..9 are the ten variations the tests drive.
Each family is a situation today's controller is known to get wrong, with parameters kept
physically plausible: lanes 3.0-3.75 m wide, right-hand traffic, cars 4.5 m x 1.8 m, a time step
of 0.1 s, goal time windows (and so runs) of 8-15 s. Moving cars are recorded traffic
(``DynamicObstacle`` with a ``TrajectoryPrediction``; ``interactive_lead``'s car has its initial
state only): they follow their trajectory whatever the ego does, and every trajectory is consistent with the rest of the scene (no car drives through
another or through a parked car).

Families (:data:`FAMILIES`):

* ``parked_follower`` -- a straight two-lane road (same direction); a parked car in the ego's lane
  30-60 m ahead, the left lane free; a car 12-25 m behind in the ego's lane at 9-12 m/s keeps its
  speed and swerves to the left lane late, 3-6 m (its centre) before the parked car: an ego that
  stops behind the parked car is hit, one that passes on the left at speed is not. Goal: a region
  60-70 m past the parked car (ego lane, left lane or both) in a window reachable at the ego's
  speed.
* ``congestion_follower`` -- a single lane; slow traffic ahead (1-3 cars at 2-3 m/s), the ego at
  ~3 m/s, a car behind closing at 3-4 m/s that never brakes (placed so that an ego keeping up with
  the traffic ahead stays clear of it to the end, while one that stops is hit). Goal: speed
  [0, 3] m/s in a region ahead, time window from 0.
* ``left_turn`` -- a T junction; the ego comes up the stem and turns left across the near lane of
  the through road, where a stream of 1-3 cars at 8-11 m/s comes from the left; the first of
  them (car 1) reaches the crossing point about when an ego that does not yield would. Goal:
  the far lane to the west, in a 1-2 s window that a car yielding to car 1 and then turning at
  ~5 m/s meets; the next car leaves a gap of 5.5-7 s after car 1.
* ``blocked_oncoming`` -- a two-lane road with one lane each way (``adjacent_left_same_direction``
  False); a broken-down car in the ego's lane 40-70 m ahead, the ego at 15-20 m/s; the oncoming
  lane is free while the ego passes (0-2 oncoming cars reach the blockage 2.5-4 s after the ego
  is past it). Goal: the ego's lane past the blockage.
* ``road_end`` -- a single lane (a straight, sometimes a bend, a last straight) whose last
  lanelet has no successor; the goal region lies at the end (its far edge 0.5-2 m before it) with
  an orientation range: stop with the whole body on the road.
* ``roundabout_exit`` -- a four-arm roundabout (a ring of lanelets, counter-clockwise, radius
  12-20 m; each arm an entry and an exit joining the ring tangentially); the ego enters from the
  south and leaves by the first, second or third exit; the goal lies on that exit's arm, which
  goes on past it: drive out through the exit.
* ``interactive_lead`` -- a single straight lane; a car 15-30 m ahead
  at 6-10 m/s, slower than the ego (9-13 m/s), given by its initial state only, as an
  interactive scenario gives its traffic (no prediction: a traffic simulator would drive it; by
  CommonRoad's checks it exists at step 0 only). Goal: a region 22-30 m long that a car
  following the lead 2 m behind it reaches after 6-11 s, in a window that a car following it
  2-15 m behind meets; a car that takes the lead for
  standing stops behind it and misses it.

:func:`write_scenario` writes a variation as ``ZAM_<Map>-<seed+1>_1_T-1.xml`` (2020a format,
checked against commonroad-io's XSD; the header's date fixed, so the bytes depend on the seed
only)::

    python tests/scenario_families.py OUT_DIR [FAMILY ...] [--seeds FIRST:STOP]

The tests drive seeds 0-9 (:data:`TEST_SEEDS`); other seeds (``--seeds 10:20``) are variations
the planner was not designed on: held-out checks of a change.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
from commonroad.common.util import AngleInterval, Interval
from commonroad.geometry.shape import Rectangle
from commonroad.planning.goal import GoalRegion
from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
from commonroad.prediction.prediction import TrajectoryPrediction
from commonroad.scenario.intersection import Intersection, IntersectionIncomingElement
from commonroad.scenario.lanelet import Lanelet, LaneletNetwork, LaneletType, LineMarking
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType, StaticObstacle
from commonroad.scenario.scenario import Location, Scenario, ScenarioID, Tag
from commonroad.scenario.state import CustomState, ExtendedPMState, InitialState
from commonroad.scenario.trajectory import Trajectory

DT = 0.1
DATE = "2026-12-02"  # the header's date (fixed: the writer would put today's)
AUTHOR = "mpcdrive"
AFFILIATION = "mpcdrive project"
SOURCE = "generated with commonroad-io 2024.3 (tests/scenario_families.py)"
CAR_L, CAR_W = 4.5, 1.8  # the other cars [m]
LANE_W = (3.0, 3.75)  # lane width range [m]
STRAIGHT_STEP_M = 2.0  # vertex spacing of straight lanelets [m]
EGO_ID, PROBLEM_ID = 1000, 1000


# -- geometry ---------------------------------------------------------------------------------------
def _line(p0, p1, step_m: float = STRAIGHT_STEP_M) -> tuple[np.ndarray, np.ndarray]:
    """(points, unit tangents) from ``p0`` to ``p1`` every ``step_m`` or a little less."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    length = float(np.hypot(*(p1 - p0)))
    n = max(2, int(math.ceil(length / step_m - 1e-9)) + 1)
    pts = p0 + np.linspace(0.0, 1.0, n)[:, None] * (p1 - p0)
    return pts, np.tile((p1 - p0) / length, (n, 1))


def _arc(c, r: float, a0: float, a1: float, step_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(points, unit tangents) on the circle about ``c`` of radius ``r`` from angle ``a0`` to
    ``a1`` [rad] (counter-clockwise when a1 > a0), every ``step_m`` of arc or a little less."""
    n = max(2, int(math.ceil(abs(a1 - a0) * r / step_m - 1e-9)) + 1)
    a = np.linspace(a0, a1, n)
    pts = np.column_stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a)])
    sign = 1.0 if a1 > a0 else -1.0
    return pts, sign * np.column_stack([-np.sin(a), np.cos(a)])


def _join(*parts) -> tuple[np.ndarray, np.ndarray]:
    """Polylines (points, tangents) joined end to start (the shared vertex once)."""
    pts = [parts[0][0]] + [p[0][1:] for p in parts[1:]]
    tan = [parts[0][1]] + [p[1][1:] for p in parts[1:]]
    return np.vstack(pts), np.vstack(tan)


def _reverse(line) -> tuple[np.ndarray, np.ndarray]:
    return line[0][::-1].copy(), -line[1][::-1].copy()


def _transform(line, rot: float, mirror_x: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``line`` mirrored in x (optionally), then rotated by ``rot`` [rad] about the origin."""
    pts, tan = np.array(line[0], float), np.array(line[1], float)
    if mirror_x:
        pts[:, 0] *= -1.0
        tan[:, 0] *= -1.0
    c, s = math.cos(rot), math.sin(rot)
    m = np.array([[c, -s], [s, c]])
    return pts @ m.T, tan @ m.T


def _lanelet(lid: int, center, width: float, **kw) -> Lanelet:
    """A lanelet ``width`` wide around the centre polyline ``center`` (points, unit tangents): its
    bounds half a width to either side along the exact normals (where lanelets meet at the same
    point and direction their end and start vertices coincide)."""
    pts, t = center
    n = np.column_stack([-t[:, 1], t[:, 0]])  # left normal
    kw.setdefault("lanelet_type", {LaneletType.URBAN})
    return Lanelet(pts + 0.5 * width * n, pts, pts - 0.5 * width * n, lid, **kw)


# -- states, obstacles, goals -------------------------------------------------------------------------
def _initial(x: float, y: float, yaw: float, v: float) -> InitialState:
    return InitialState(
        position=np.array([x, y], float),
        orientation=float(yaw),
        velocity=float(v),
        acceleration=0.0,
        yaw_rate=0.0,
        slip_angle=0.0,
        time_step=0,
    )


def _parked(oid: int, x: float, y: float, yaw: float = 0.0) -> StaticObstacle:
    return StaticObstacle(oid, ObstacleType.PARKED_VEHICLE, Rectangle(CAR_L, CAR_W), _initial(x, y, yaw, 0.0))


def _moving(oid: int, xy: np.ndarray) -> DynamicObstacle:
    """A car at the positions ``xy`` (N + 1, 2), one per time step from step 0; orientation and
    speed from the differences (the last repeated)."""
    d = np.diff(xy, axis=0)
    yaw = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    v = np.hypot(d[:, 0], d[:, 1]) / DT
    yaw, v = np.r_[yaw, yaw[-1]], np.r_[v, v[-1]]
    acc = np.r_[np.diff(v) / DT, 0.0]
    states = [
        ExtendedPMState(
            time_step=k,
            position=np.array(xy[k], float),
            velocity=float(v[k]),
            orientation=float(yaw[k]),
            acceleration=float(acc[k]),
        )
        for k in range(1, len(xy))
    ]
    shape = Rectangle(CAR_L, CAR_W)
    init = _initial(float(xy[0, 0]), float(xy[0, 1]), float(yaw[0]), float(v[0]))
    return DynamicObstacle(oid, ObstacleType.CAR, shape, init, TrajectoryPrediction(Trajectory(1, states), shape))


def _steps(t_s: float) -> int:
    return int(round(t_s / DT))


def _problem(
    init: InitialState, center, yaw: float, length: float, width: float, window_s, velocity=None, heading=None
):
    """The planning problem: ``init``, and a goal rectangle (``length`` along ``yaw``) inside the
    time window ``window_s`` [s] (and a velocity / orientation range when given)."""
    kw = {}
    if velocity is not None:
        kw["velocity"] = Interval(*velocity)
    if heading is not None:
        kw["orientation"] = AngleInterval(*heading)
    goal = CustomState(
        position=Rectangle(length, width, np.asarray(center, float), float(yaw)),
        time_step=Interval(_steps(window_s[0]), _steps(window_s[1])),
        **kw,
    )
    return PlanningProblemSet([PlanningProblem(PROBLEM_ID, init, GoalRegion([goal]))])


def _scenario(map_name: str, seed: int, lanelets, obstacles=(), intersections=()) -> Scenario:
    sid = ScenarioID(country_id="ZAM", map_name=map_name, map_id=seed + 1, configuration_id=1)
    sid.obstacle_behavior, sid.prediction_id = "T", 1
    sc = Scenario(DT, sid, author=AUTHOR, affiliation=AFFILIATION, source=SOURCE, location=Location())
    net = LaneletNetwork()
    for ll in lanelets:
        net.add_lanelet(ll)
    for inter in intersections:
        net.add_intersection(inter)
    sc.add_objects(net)
    for o in obstacles:
        sc.add_objects(o)
    return sc


def _straight_lanes(length: float, width: float, n_lanes: int = 2, pieces: int = 2, oncoming: bool = False):
    """Lanes along x from 0 to ``length`` (the right lane's centre at y = 0, the next ``width``
    to its left), each cut into ``pieces`` lanelets. Ids: lane k (0 = right), piece j has id
    ``1 + k + n_lanes * j``. With ``oncoming`` the second lane runs the other way (towards -x),
    adjacent with ``adjacent_left_same_direction`` False."""
    edges = np.linspace(0.0, length, pieces + 1)
    out = []
    for k in range(n_lanes):
        y = k * width
        against = oncoming and k == 1
        for j in range(pieces):
            lid = 1 + k + n_lanes * j
            x0, x1 = edges[j], edges[j + 1]
            line = _line((x1, y), (x0, y)) if against else _line((x0, y), (x1, y))
            nxt, prv = lid + n_lanes, lid - n_lanes
            succ = [nxt] if j < pieces - 1 else []
            pred = [prv] if j > 0 else []
            if against:
                succ, pred = pred, succ
            kw = dict(predecessor=pred, successor=succ)
            if n_lanes == 2:
                other = lid + 1 if k == 0 else lid - 1
                same = not oncoming
                if k == 0 or against:  # the other lane is on the left (the opposite lanes share their left bounds)
                    kw.update(adjacent_left=other, adjacent_left_same_direction=same)
                else:
                    kw.update(adjacent_right=other, adjacent_right_same_direction=same)
                kw.update(
                    line_marking_left_vertices=LineMarking.DASHED if (k == 0 or against) else LineMarking.SOLID,
                    line_marking_right_vertices=LineMarking.SOLID if (k == 0 or against) else LineMarking.DASHED,
                )
            else:
                kw.update(line_marking_left_vertices=LineMarking.SOLID, line_marking_right_vertices=LineMarking.SOLID)
            out.append(_lanelet(lid, line, width, **kw))
    return out


def _single_lane(parts, width: float) -> list:
    """A single lane ``width`` wide along the polylines ``parts`` (points, tangents), a lanelet
    each (ids 1, 2, ...), each the next one's predecessor, solid edges."""
    edges = dict(line_marking_left_vertices=LineMarking.SOLID, line_marking_right_vertices=LineMarking.SOLID)
    out = []
    for k, part in enumerate(parts):
        lid = k + 1
        pred = [lid - 1] if k > 0 else []
        succ = [lid + 1] if k < len(parts) - 1 else []
        out.append(_lanelet(lid, part, width, predecessor=pred, successor=succ, **edges))
    return out


def _smooth01(u):
    """0 -> 1 with zero slope at both ends (half a cosine), ``u`` clipped to [0, 1]."""
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(math.pi * u)


# -- 1. parked car ahead, a car behind ------------------------------------------------------------------
def make_parked_follower(seed: int):
    """A parked car in the ego's lane, the left lane free, a car behind that swerves around the
    parked car late (module docstring)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(*LANE_W)
    x0, v0 = 30.0, rng.uniform(10.0, 13.0)
    x_p = x0 + rng.uniform(30.0, 60.0)  # the parked car's centre
    gap = rng.uniform(12.0, 25.0)  # the follower's centre behind the ego's
    v_f = rng.uniform(9.0, min(12.0, v0))
    swerve_end = rng.uniform(3.0, 6.0)  # the follower's centre is in the left lane this far before the parked car
    swerve_len = rng.uniform(20.0, 25.0)
    x_g = x_p + rng.uniform(60.0, 70.0)  # the goal region's centre
    lane = int(rng.integers(3))  # the goal in the ego's lane, the left lane, or across both
    t_in = (x_g - 5.0 - x0) / v0
    window = (max(0.0, t_in - 2.0), min(t_in + 2.5, 15.0))
    length = x_g + 70.0
    n = _steps(window[1] + 1.0)
    t = np.arange(n + 1) * DT
    xf = x0 - gap + v_f * t
    lc_end = x_p - 0.5 * CAR_L - swerve_end
    yf = w * _smooth01((xf - (lc_end - swerve_len)) / swerve_len)
    obstacles = [_parked(100, x_p, rng.uniform(-0.15, 0.15)), _moving(101, np.column_stack([xf, yf]))]
    sc = _scenario("ParkedFollower", seed, _straight_lanes(length, w), obstacles)
    gy, gw = [(0.0, w - 0.3), (w, w - 0.3), (0.5 * w, 2 * w - 0.3)][lane]
    pps = _problem(_initial(x0, 0.0, 0.0, v0), (x_g, gy), 0.0, 10.0, gw, window)
    return sc, pps


# -- 2. slow traffic ahead, a car closing from behind ----------------------------------------------------
def make_congestion_follower(seed: int):
    """Slow traffic ahead, a car behind closing without braking, goal speed [0, 3] m/s (module
    docstring)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(*LANE_W)
    x0, v0 = 40.0, rng.uniform(2.7, 3.3)
    v_lead = rng.uniform(2.0, 3.0)
    amp = rng.uniform(0.0, 1.0) * min(0.4, v_lead - 1.8, 3.2 - v_lead)
    period = rng.uniform(6.0, 10.0)
    t_end = rng.uniform(10.0, 12.0)  # the goal window's end (the run's length)
    n = _steps(t_end + 1.0)
    t = np.arange(n + 1) * DT
    obstacles = []
    x_front = x0 + 0.5 * CAR_L  # the front of the car behind the next lead car
    s_first = None
    for i in range(int(rng.integers(1, 4))):
        phase = rng.uniform(0.0, 2 * math.pi)
        v = v_lead + amp * np.sin(2 * math.pi * t / period + phase)
        s = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * DT)]
        xc = x_front + rng.uniform(5.0, 9.0) + 0.5 * CAR_L
        obstacles.append(_moving(100 + i, np.column_stack([xc + s, np.zeros_like(s)])))
        s_first = s if s_first is None else s_first
        x_front = xc + 0.5 * CAR_L
    v_b = rng.uniform(3.0, 4.0)
    # bumper gap behind: an ego keeping up with the traffic ahead is >= 2.5 m ahead of it at the end
    gap_b = max(6.0, 2.5 + (v_b - v_lead + amp) * (t_end + 1.0)) + rng.uniform(0.0, 2.0)
    xb = x0 - CAR_L - gap_b + v_b * t
    obstacles.append(_moving(110, np.column_stack([xb, np.zeros_like(xb)])))
    road = x_front + float(s_first[-1]) + 40.0
    # the region: where an ego following the first car is about 3 s before the window's end
    g0 = x0 + float(np.interp(t_end - 3.0, t, s_first)) - 4.0
    sc = _scenario("CongestionFollower", seed, _straight_lanes(road, w, n_lanes=1), obstacles)
    pps = _problem(_initial(x0, 0.0, 0.0, v0), (g0 + 5.0, 0.0), 0.0, 10.0, w - 0.3, (0.0, t_end), velocity=(0.0, 3.0))
    return sc, pps


# -- 3. left turn from the stem of a T junction across a stream ------------------------------------------
def _t_junction(w: float, b: float, arm_s: float, arm_w: float, arm_e: float):
    """A T junction about the origin: a through road along x (eastbound lane y = -w/2, westbound
    y = +w/2), a stem to the south (northbound x = +w/2); the box |x|, |y| <= b. Lanelets:
    1 stem north, 2 stem south, 3 west arm east, 4 west arm west (the ego's goal), 5 east arm
    east, 6 east arm west, 7 box east, 8 box west, 9 stem left turn (the ego's), 10 stem right,
    11 west -> stem (right), 12 east -> stem (left)."""
    h = 0.5 * w
    q = 0.5 * math.pi
    arm = {"lanelet_type": {LaneletType.URBAN}}
    box = {"lanelet_type": {LaneletType.INTERSECTION}}
    lanes = [
        (1, _line((h, -arm_s), (h, -b)), [], [9, 10], 2, arm),
        (2, _line((-h, -b), (-h, -arm_s)), [11, 12], [], 1, arm),
        (3, _line((-arm_w, -h), (-b, -h)), [], [7, 11], 4, arm),
        (4, _line((-b, h), (-arm_w, h)), [8, 9], [], 3, arm),
        (5, _line((b, -h), (arm_e, -h)), [7, 10], [], 6, arm),
        (6, _line((arm_e, h), (b, h)), [], [8, 12], 5, arm),
        (7, _line((-b, -h), (b, -h), 1.0), [3], [5], 8, box),
        (8, _line((b, h), (-b, h), 1.0), [6], [4], 7, box),
        (9, _arc((-b, -b), b + h, 0.0, q), [1], [4], None, box),
        (10, _arc((b, -b), b - h, math.pi, q), [1], [5], None, box),
        (11, _arc((-b, -b), b - h, q, 0.0), [3], [2], None, box),
        (12, _arc((b, -b), b + h, q, math.pi), [6], [2], None, box),
    ]
    out = []
    for lid, c, pred, succ, adj, kind in lanes:
        kw = dict(predecessor=pred, successor=succ, **kind)
        if adj is not None:
            kw.update(adjacent_left=adj, adjacent_left_same_direction=False)
        if kind is arm:
            kw.update(line_marking_left_vertices=LineMarking.DASHED, line_marking_right_vertices=LineMarking.SOLID)
        out.append(_lanelet(lid, c, w, **kw))
    incomings = [
        IntersectionIncomingElement(61, {1}, successors_right={10}, successors_left={9}),
        IntersectionIncomingElement(62, {3}, successors_right={11}, successors_straight={7}, left_of=61),
        IntersectionIncomingElement(63, {6}, successors_straight={8}, successors_left={12}, left_of=62),
    ]
    return out, Intersection(60, incomings)


def make_left_turn(seed: int):
    """Left turn from the stem of a T junction across a stream from the left (module docstring)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(*LANE_W)
    h = 0.5 * w
    b = w + rng.uniform(3.0, 4.5)  # the box's half size
    r = b + h  # the left turn's radius
    a_c = math.asin((b - h) / r)  # angle along the turn where it crosses the eastbound lane's centre
    x_c = -b + r * math.cos(a_c)
    v0 = rng.uniform(5.5, 8.0)
    d0 = rng.uniform(20.0, 35.0)  # the ego's centre before the box
    v_s = rng.uniform(8.0, 11.0)
    v_turn = min(v0, math.sqrt(4.0 * r))
    t_nat = d0 / v0 + r * a_c / v_turn  # at the crossing point without yielding
    t1 = t_nat + rng.uniform(-0.3, 0.5)  # car 1 there then
    # a car that lets car 1 by and then turns at 5 m/s: at the crossing when car 1's rear is 1 m past its body
    t_c = t1 + (0.5 * CAR_L + 0.9 + 0.5 * CAR_L + 1.0) / v_s
    d_r = rng.uniform(6.0, 12.0)  # the goal region's start, past the box
    t_in = t_c + (r * (0.5 * math.pi - a_c) + d_r) / 5.0
    width = rng.uniform(1.0, 2.0)
    window = (t_in - rng.uniform(0.0, 0.5) * width, 0.0)
    window = (window[0], window[0] + width)
    n_cars = int(rng.integers(1, 4))
    times = [t1]
    if n_cars >= 2:
        times.append(t1 + rng.uniform(5.5, 7.0))
    if n_cars >= 3:
        times.insert(0, t1 - rng.uniform(2.5, 4.0))
    arm_w = max(60.0, v_s * max(times) - x_c + 10.0)  # every car on the road from step 0
    arm_e = 60.0
    lanelets, inter = _t_junction(w, b, 60.0, arm_w, arm_e)
    n = _steps(window[1] + 1.0)
    t = np.arange(n + 1) * DT
    obstacles = []
    for i, ti in enumerate(times):
        x = x_c + v_s * (t - ti)
        keep = x <= arm_e - 0.5 * CAR_L  # the trajectory ends where the road does
        obstacles.append(_moving(100 + i, np.column_stack([x[keep], np.full(int(keep.sum()), -h)])))
    sc = _scenario("LeftTurnStream", seed, lanelets, obstacles, [inter])
    init = _initial(h, -b - d0, 0.5 * math.pi, v0)
    pps = _problem(init, (-b - d_r - 5.0, h), math.pi, 10.0, w - 0.3, window)
    return sc, pps


# -- 4. blocked lane, pass in the oncoming lane ------------------------------------------------------------
def make_blocked_oncoming(seed: int):
    """A broken-down car in the ego's lane on a road with one lane each way (module docstring)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(*LANE_W)
    x0, v0 = 30.0, rng.uniform(15.0, 20.0)
    x_p = x0 + rng.uniform(40.0, 70.0)
    x_g = x_p + rng.uniform(40.0, 60.0)
    t_in = (x_g - 5.0 - x0) / v0
    window = (max(0.0, t_in - 2.0), max(8.0, t_in + 3.0))
    t_past = (x_p + 0.5 * CAR_L + 12.0 - x0) / v0  # the ego back in its lane 12 m past the blockage
    n = _steps(window[1] + 1.0)
    t = np.arange(n + 1) * DT
    obstacles = [_parked(100, x_p, rng.uniform(-0.2, 0.2))]  # (the XSD's static types: a parked vehicle)
    starts = []
    t_on = t_past
    for i in range(int(rng.integers(0, 3))):
        v_on = rng.uniform(12.0, 16.0)
        t_on += rng.uniform(2.5, 4.0)  # at the blockage then (each after the one before)
        x = x_p + v_on * (t_on - t)
        keep = x >= 0.5 * CAR_L
        starts.append(x[0])
        obstacles.append(_moving(101 + i, np.column_stack([x[keep], np.full(int(keep.sum()), w)])))
    length = max([x_g + 60.0] + [s + 10.0 for s in starts])
    sc = _scenario("BlockedOncoming", seed, _straight_lanes(length, w, oncoming=True), obstacles)
    pps = _problem(_initial(x0, 0.0, 0.0, v0), (x_g, 0.0), 0.0, 10.0, w - 0.3, window)
    return sc, pps


# -- 5. the road ends --------------------------------------------------------------------------------------
def make_road_end(seed: int):
    """A single lane ending at the goal (module docstring)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(*LANE_W)
    v0 = rng.uniform(8.0, 14.0)
    x0 = 10.0
    total = x0 + v0 * rng.uniform(4.5, 7.0) + 0.5 * v0 * v0 / 3.0  # the road's length along its centre line
    bend = rng.random() < 0.6
    last = rng.uniform(20.0, 35.0)
    if bend:
        radius = rng.uniform(40.0, 80.0)
        angle = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 0.6)
        first = max(x0 + 15.0, total - last - radius * abs(angle))
        c = (first, radius if angle > 0 else -radius)
        a0 = -0.5 * math.pi if angle > 0 else 0.5 * math.pi
        arc = _arc(c, radius, a0, a0 + angle)
        p1, heading = arc[0][-1], angle
        end = p1 + last * np.array([math.cos(heading), math.sin(heading)])
        parts = [_line((0.0, 0.0), (first, 0.0)), arc, _line(p1, end)]
    else:
        heading = 0.0
        end = np.array([total, 0.0])
        parts = [_line((0.0, 0.0), (total - last, 0.0)), _line((total - last, 0.0), end)]
    lanelets = _single_lane(parts, w)
    g_len = rng.uniform(8.0, 15.0)
    far = rng.uniform(0.5, 2.0)  # the region's far edge before the road's end
    u = np.array([math.cos(heading), math.sin(heading)])
    center = end - (far + 0.5 * g_len) * u
    s_goal = total - far - g_len
    t_stop = (s_goal - x0) / v0 + v0 / 3.0
    window = (0.0, float(np.clip(t_stop + rng.uniform(2.5, 4.0), 8.0, 15.0)))
    sc = _scenario("RoadEnd", seed, lanelets)
    pps = _problem(
        _initial(x0, 0.0, 0.0, v0), center, heading, g_len, w - 0.3, window, heading=(heading - 0.4, heading + 0.4)
    )
    return sc, pps


# -- 6. roundabout ----------------------------------------------------------------------------------------
ARMS = (-0.5 * math.pi, 0.0, 0.5 * math.pi, math.pi)  # the arms' directions from the centre: S, E, N, W


def _roundabout(w: float, radius: float, r_conn: float, arm_m: float, goal_arm: int, out_len: float):
    """A roundabout about the origin (module docstring) and its lanelets; returns (lanelets,
    alpha, ids): ``alpha`` the angle [rad] from an arm's direction to where its entry joins the
    ring (its exit leaves at minus that), ``ids`` per arm (in straight, in connector, out
    connector, out straight). The exit of arm ``goal_arm`` is ``out_len`` long."""
    h = 0.5 * w
    alpha = math.asin((r_conn + h) / (radius + r_conn))
    # the entry of the south arm, in that arm's frame: a straight north at x = +h, then a right turn
    # about cc onto the ring at angle -pi/2 + alpha
    th_e = -0.5 * math.pi + alpha
    cc = (radius + r_conn) * np.array([math.cos(th_e), math.sin(th_e)])
    y_t = float(cc[1])
    conn = _arc(cc, r_conn, math.pi, th_e + math.pi)
    ring_pt = radius * np.array([math.cos(th_e), math.sin(th_e)])
    conn[0][-1] = ring_pt  # exactly on the ring
    conn[1][-1] = np.array([-math.sin(th_e), math.cos(th_e)])
    ids = {}
    lanelets = []
    lid = 1
    splits = []  # (angle on the ring, arm, "in"|"out")
    for k, psi in enumerate(ARMS):
        rot = psi + 0.5 * math.pi
        length = out_len if k == goal_arm else arm_m
        s_in = _transform(_line((h, -arm_m + y_t), (h, y_t)), rot)
        c_in = _transform(conn, rot)
        c_out = _transform(_reverse(conn), rot, mirror_x=True)
        s_out = _transform(_line((h, y_t), (h, -length + y_t)), rot, mirror_x=True)
        ids[k] = (lid, lid + 1, lid + 2, lid + 3)
        lanelets += [("in", k, s_in), ("cin", k, c_in), ("cout", k, c_out), ("out", k, s_out)]
        lid += 4
        splits += [(psi - alpha, k, "out"), (psi + alpha, k, "in")]
    splits.sort()
    n_ring = len(splits)
    ring_ids = [lid + i for i in range(n_ring)]
    # ring lanelet i runs from splits[i] to splits[i + 1] (the last one round to the first)
    built = []
    for kind, k, line in lanelets:
        a, b, c, d = ids[k]
        j_in = next(i for i, s in enumerate(splits) if s[1] == k and s[2] == "in")
        j_out = next(i for i, s in enumerate(splits) if s[1] == k and s[2] == "out")
        prev_of_out = ring_ids[(j_out - 1) % n_ring]
        kw = {
            "in": dict(lid=a, successor=[b], adjacent_left=d),
            "cin": dict(lid=b, predecessor=[a], successor=[ring_ids[j_in]]),
            "cout": dict(lid=c, predecessor=[prev_of_out], successor=[d]),
            "out": dict(lid=d, predecessor=[c], adjacent_left=a),
        }[kind]
        the_id = kw.pop("lid")
        if "adjacent_left" in kw:
            kw["adjacent_left_same_direction"] = False
        built.append(_lanelet(the_id, line, w, **kw))
    for i, (a0, k, kind) in enumerate(splits):
        a1 = splits[(i + 1) % n_ring][0] + (2 * math.pi if i == n_ring - 1 else 0.0)
        nxt = ring_ids[(i + 1) % n_ring]
        succ = [nxt]
        k_next, kind_next = splits[(i + 1) % n_ring][1:]
        if kind_next == "out":
            succ.append(ids[k_next][2])
        pred = [ring_ids[(i - 1) % n_ring]]
        if kind == "in":
            pred.append(ids[k][1])
        built.append(
            _lanelet(
                ring_ids[i],
                _arc((0.0, 0.0), radius, a0, a1),
                w,
                predecessor=pred,
                successor=succ,
                lanelet_type={LaneletType.URBAN},
            )
        )
    return built, alpha, ids, y_t


def make_roundabout_exit(seed: int):
    """Through a roundabout and out by its first, second or third exit (module docstring)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(*LANE_W)
    exit_no = int(rng.integers(1, 4))  # 1: east, 2: north, 3: west
    # (the third exit, three quarters round, on a small roundabout: within 15 s)
    radius = rng.uniform(12.0, 20.0) if exit_no < 3 else rng.uniform(12.0, 13.0)
    r_conn = rng.uniform(10.0, 15.0) if exit_no < 3 else rng.uniform(10.0, 11.0)
    v0 = rng.uniform(6.0, 9.0)
    g_at = rng.uniform(8.0, 15.0)  # the goal region's start on the exit's straight
    out_len = g_at + 10.0 + rng.uniform(30.0, 50.0)
    h = 0.5 * w
    alpha = math.asin((r_conn + h) / (radius + r_conn))
    # the time to the region at the entry's, the ring's and the exit's curvature-limited speed:
    # the approach d0 (the ego before the entry's turn) drawn so that it is in by about 10 s
    turn = r_conn * (0.5 * math.pi - alpha)
    ring = radius * (exit_no * 0.5 * math.pi - 2 * alpha)
    v_ring = min(v0, math.sqrt(3.0 * radius), math.sqrt(3.0 * r_conn))
    rest = (2 * turn + ring) / v_ring + g_at / v0 + 1.0
    d0 = float(np.clip(rng.uniform(20.0, 35.0), 10.0, max(10.0, (10.0 - rest) * v0)))
    t_in = d0 / v0 + rest
    lanelets, alpha, ids, y_t = _roundabout(w, radius, r_conn, 60.0, exit_no, out_len)
    window = (0.0, float(np.clip(t_in + 3.0, 8.0, 15.0)))
    psi = ARMS[exit_no]
    u = np.array([math.cos(psi), math.sin(psi)])  # outwards along the exit arm
    start_out = _transform((np.array([[h, y_t]]), np.array([[0.0, -1.0]])), psi + 0.5 * math.pi, mirror_x=True)[0][0]
    center = start_out + (g_at + 5.0) * u
    sc = _scenario("RoundaboutExit", seed, lanelets)
    yaw = psi
    pps = _problem(
        _initial(h, y_t - d0, 0.5 * math.pi, v0),
        center,
        yaw,
        10.0,
        w - 0.3,
        window,
        heading=(yaw - 0.5, yaw + 0.5),
    )
    return sc, pps


# -- 7. traffic known by its initial state only -----------------------------------------------------------
def _initial_only(oid: int, x: float, y: float, yaw: float, v: float) -> DynamicObstacle:
    """A car given by its initial state only, as an interactive scenario gives its traffic (a
    traffic simulator drives it): no prediction."""
    return DynamicObstacle(oid, ObstacleType.CAR, Rectangle(CAR_L, CAR_W), _initial(x, y, yaw, v))


def make_interactive_lead(seed: int):
    """A single straight lane; a car ahead known by its initial state only (module docstring)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(*LANE_W)
    x0, v0 = 10.0, rng.uniform(9.0, 13.0)
    v_l = rng.uniform(6.0, 10.0)
    x_l = x0 + rng.uniform(15.0, 30.0)  # the lead's centre
    g_len = rng.uniform(22.0, 30.0)
    # where the goal region begins along the lane: a follower 2 m behind the lead reaches it
    # after 6-11 s
    s_g = x_l - CAR_L - 2.0 + v_l * rng.uniform(6.0, 11.0)
    # the lead drives on at v_l; a car following it 2-15 m behind its rear has its centre in the
    # region from (s_g + CAR_L + gap - x_l) / v_l for g_len / v_l: the window is inside that for
    # every such gap
    t1 = (s_g + CAR_L + 2.0 - x_l) / v_l
    window = (t1 + 13.0 / v_l + 0.2, t1 + 13.0 / v_l + 0.2 + min(1.0, g_len / v_l - 13.0 / v_l - 0.6))
    total = s_g + g_len + 80.0
    cut = s_g + 0.5 * g_len + rng.uniform(5.0, 20.0)  # where the two lanelets meet
    parts = [_line((0.0, 0.0), (cut, 0.0)), _line((cut, 0.0), (total, 0.0))]
    lanelets = _single_lane(parts, w)
    sc = _scenario("InteractiveLead", seed, lanelets, [_initial_only(100, x_l, 0.0, 0.0, v_l)])
    pps = _problem(_initial(x0, 0.0, 0.0, v0), (s_g + 0.5 * g_len, 0.0), 0.0, g_len, w - 0.3, window)
    return sc, pps


# -- the families and writing them ------------------------------------------------------------------------
FAMILIES = {
    "parked_follower": make_parked_follower,
    "congestion_follower": make_congestion_follower,
    "left_turn": make_left_turn,
    "blocked_oncoming": make_blocked_oncoming,
    "road_end": make_road_end,
    "roundabout_exit": make_roundabout_exit,
    "interactive_lead": make_interactive_lead,
}

TAGS = {
    "parked_follower": [Tag.URBAN, Tag.MULTI_LANE, Tag.EVASIVE, Tag.NO_ONCOMING_TRAFFIC],
    "congestion_follower": [Tag.URBAN, Tag.SINGLE_LANE, Tag.TRAFFIC_JAM, Tag.LANE_FOLLOWING],
    "left_turn": [Tag.URBAN, Tag.INTERSECTION, Tag.TURN_LEFT],
    "blocked_oncoming": [Tag.RURAL, Tag.TWO_LANE, Tag.EVASIVE, Tag.ONCOMING_TRAFFIC],
    "road_end": [Tag.URBAN, Tag.SINGLE_LANE, Tag.LANE_FOLLOWING],
    "roundabout_exit": [Tag.URBAN, Tag.ROUNDABOUT, Tag.SINGLE_LANE],
    "interactive_lead": [Tag.URBAN, Tag.SINGLE_LANE, Tag.LANE_FOLLOWING],
}


#: families whose traffic includes a car given by its initial state only
INITIAL_ONLY = {"interactive_lead"}


def _xsd_errors(text: str) -> list[str]:
    """The messages of CommonRoad's 2020a XSD on the scenario file ``text``."""
    import commonroad
    from lxml import etree

    xsd = Path(commonroad.__file__).parent / "scenario_definition" / "xml_definition_files" / "XML_commonRoad_XSD.xsd"
    schema = etree.XMLSchema(etree.parse(str(xsd)))
    schema.validate(etree.fromstring(text.encode("utf-8")))
    return [e.message for e in schema.error_log]


def file_name(family: str, seed: int) -> str:
    """The benchmark-style file name of a variation, e.g. ``ZAM_RoadEnd-4_1_T-1.xml`` (seed 3)."""
    sc, _ = FAMILIES[family](seed)
    return f"{sc.scenario_id}.xml"


def write_scenario(family: str, seed: int, out_dir: str | Path) -> Path:
    """Build variation ``seed`` of ``family`` and write it into ``out_dir`` (2020a format, checked
    against the XSD, header date :data:`DATE`); returns the file's path."""
    sc, pps = FAMILIES[family](seed)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{sc.scenario_id}.xml"
    writer = CommonRoadFileWriter(
        sc, pps, author=AUTHOR, affiliation=AFFILIATION, source=SOURCE, tags=TAGS[family], location=Location()
    )
    writer.write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    text = path.read_text(encoding="utf-8")
    text, n = re.subn(r'(<commonRoad [^>]*\bdate=")[^"]*(")', rf"\g<1>{DATE}\g<2>", text, count=1)
    if n != 1:
        raise RuntimeError(f"{path.name}: no date attribute in the header")
    if not CommonRoadFileWriter.check_validity_of_commonroad_file(text.encode("utf-8")):
        errors = _xsd_errors(text)
        # CommonRoad's XSD asks every dynamic obstacle for a trajectory (or an occupancy set, a
        # signal state); real interactive scenarios (DEU_Hoerstein-1_1_I-1) give their traffic
        # without one, as INITIAL_ONLY families do: that error alone is allowed there
        only_that = all("dynamicObstacle" in e and "Missing child element" in e for e in errors)
        if not (family in INITIAL_ONLY and errors and only_that):
            raise RuntimeError(f"{path.name}: not valid against the CommonRoad XSD: {errors[:3]}")
    path.write_text(text, encoding="utf-8")
    return path


#: the seeds the tests drive
TEST_SEEDS = range(10)


def main(argv: list[str]) -> list[Path]:
    """``OUT_DIR [FAMILY ...] [--seeds FIRST:STOP]``: the families' variations (all families,
    :data:`TEST_SEEDS`, by default) written to ``OUT_DIR``."""
    args, seeds = list(argv), TEST_SEEDS
    if "--seeds" in args:
        at = args.index("--seeds")
        if at + 1 >= len(args) or not re.fullmatch(r"\d+:\d+", args[at + 1]):
            raise SystemExit("--seeds takes FIRST:STOP, e.g. --seeds 10:20")
        first, stop = (int(v) for v in args[at + 1].split(":"))
        seeds = range(first, stop)
        del args[at : at + 2]
    if not args:
        raise SystemExit("usage: scenario_families.py OUT_DIR [FAMILY ...] [--seeds FIRST:STOP]")
    out_dir, families = Path(args[0]), args[1:] or list(FAMILIES)
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        raise SystemExit(f"unknown families {unknown}; known: {', '.join(FAMILIES)}")
    return [write_scenario(f, seed, out_dir) for f in families for seed in seeds]


if __name__ == "__main__":
    for p in main(sys.argv[1:]):
        print(p)
