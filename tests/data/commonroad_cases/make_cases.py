"""Build the hand-made CommonRoad scenarios in this folder with commonroad-io (2024.3).

Each case is a situation the real files in ``tests/data/commonroad`` do not cover (README.md
here says what each one tests). The scenarios are built from commonroad-io objects -- lanelets
with left / centre / right vertices, adjacency and successor relations, static and dynamic
obstacles (rectangles; a moving car's trajectory as a ``TrajectoryPrediction``), a planning
problem with an initial state and a goal region (a rectangle in the goal lane and a time-step
interval, as in ``ZAM_Tutorial_Urban-3_2.xml``) -- and written with ``CommonRoadFileWriter``.

The output is deterministic: nothing is random, the tags are written in a fixed order (the
writer iterates what it is given; a ``set`` of enum members has no fixed order across runs) and
the header's ``date`` attribute, which the writer fills with today's date, is set to
:data:`DATE`. Rerunning the script rewrites the same bytes::

    python tests/data/commonroad_cases/make_cases.py [OUT_DIR]
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
from commonroad.common.util import Interval
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

HERE = Path(__file__).resolve().parent
DT = 0.1
DATE = "2026-12-02"  # the header's date (the day the cases were made)
AUTHOR = "mpcdrive"
AFFILIATION = "mpcdrive project"
SOURCE = "hand-crafted with commonroad-io 2024.3 (tests/data/commonroad_cases/make_cases.py)"
LANE_W = 3.5  # lane width of the straight roads [m]
ROAD_END_M = 200.0  # the straight roads run from x = 0 to here [m]


# -- geometry ---------------------------------------------------------------------------------------
def _lanelet(lid: int, center, widths, **kw) -> Lanelet:
    """A lanelet around the centre polyline ``center``: points (N, 2), or (points, unit tangents)
    as :func:`_line` and :func:`_arc` give them; ``widths`` (N,) or a number wide. Its left and
    right bounds lie half a width to either side of the direction of travel (exact normals: where
    two lanelets meet, the end vertices of the one are the start vertices of the other)."""
    center, t = center
    w = np.broadcast_to(np.asarray(widths, float), (len(center),))
    n = np.column_stack([-t[:, 1], t[:, 0]])  # left normal
    left = center + 0.5 * w[:, None] * n
    right = center - 0.5 * w[:, None] * n
    kw.setdefault("lanelet_type", {LaneletType.URBAN})
    return Lanelet(left, center, right, lid, **kw)


def _line(p0, p1, step_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(points, tangents) from ``p0`` to ``p1`` every ``step_m`` or a little less (ends included)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    length = float(np.hypot(*(p1 - p0)))
    n = max(2, int(math.ceil(length / step_m - 1e-9)) + 1)
    pts = p0 + np.linspace(0.0, 1.0, n)[:, None] * (p1 - p0)
    return pts, np.tile((p1 - p0) / length, (n, 1))


def _arc(c, r: float, a0: float, a1: float, step_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(points, tangents) on the circle about ``c`` of radius ``r`` from angle ``a0`` to ``a1``
    [rad] (counter-clockwise when a1 > a0), every ``step_m`` of arc or a little less."""
    n = max(2, int(math.ceil(abs(a1 - a0) * r / step_m - 1e-9)) + 1)
    a = np.linspace(a0, a1, n)
    pts = np.column_stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a)])
    sign = 1.0 if a1 > a0 else -1.0
    return pts, sign * np.column_stack([-np.sin(a), np.cos(a)])


def _straight_two_lane_road() -> list[Lanelet]:
    """Two lanes in the same direction along +x from x = 0 to :data:`ROAD_END_M`, each in two
    lanelets (a successor relation halfway): right lane 1 -> 3 (centre y = 0), left lane 2 -> 4
    (centre y = :data:`LANE_W`)."""
    half = 0.5 * ROAD_END_M
    out = []
    for lid, (x0, x1), y, succ, pred in (
        (1, (0.0, half), 0.0, [3], []),
        (2, (0.0, half), LANE_W, [4], []),
        (3, (half, ROAD_END_M), 0.0, [], [1]),
        (4, (half, ROAD_END_M), LANE_W, [], [2]),
    ):
        right_lane = y == 0.0
        out.append(
            _lanelet(
                lid,
                _line((x0, y), (x1, y)),
                LANE_W,
                predecessor=pred,
                successor=succ,
                adjacent_left=lid + 1 if right_lane else None,
                adjacent_left_same_direction=True if right_lane else None,
                adjacent_right=None if right_lane else lid - 1,
                adjacent_right_same_direction=None if right_lane else True,
                line_marking_left_vertices=LineMarking.DASHED if right_lane else LineMarking.SOLID,
                line_marking_right_vertices=LineMarking.SOLID if right_lane else LineMarking.DASHED,
            )
        )
    return out


# -- states -----------------------------------------------------------------------------------------
def _initial(x: float, y: float, yaw: float, v: float) -> InitialState:
    return InitialState(
        position=np.array([x, y]),
        orientation=yaw,
        velocity=v,
        acceleration=0.0,
        yaw_rate=0.0,
        slip_angle=0.0,
        time_step=0,
    )


def _car_rect(length: float = 4.5, width: float = 1.8) -> Rectangle:
    return Rectangle(length, width)


def _parked(oid: int, x: float, y: float, yaw: float = 0.0, length: float = 4.5, width: float = 1.8):
    return StaticObstacle(oid, ObstacleType.PARKED_VEHICLE, _car_rect(length, width), _initial(x, y, yaw, 0.0))


def _moving(oid: int, xy: np.ndarray, steps: int) -> DynamicObstacle:
    """A car following the positions ``xy`` (steps + 1, 2), one per time step from step 0; its
    orientation and speed from the differences (the last repeated)."""
    d = np.diff(xy, axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    v = np.hypot(d[:, 0], d[:, 1]) / DT
    yaw, v = np.r_[yaw, yaw[-1]], np.r_[v, v[-1]]
    acc = np.r_[np.diff(v) / DT, 0.0]
    init = _initial(float(xy[0, 0]), float(xy[0, 1]), float(yaw[0]), float(v[0]))
    states = [
        ExtendedPMState(
            time_step=k,
            position=np.array(xy[k], float),
            velocity=float(v[k]),
            orientation=float(yaw[k]),
            acceleration=float(acc[k]),
        )
        for k in range(1, steps + 1)
    ]
    shape = _car_rect()
    return DynamicObstacle(oid, ObstacleType.CAR, shape, init, TrajectoryPrediction(Trajectory(1, states), shape))


def _problem(pid: int, init: InitialState, center, yaw: float, length: float, width: float, last_step: int):
    """A planning problem: ``init``, and a goal rectangle (in the goal lane) within time steps
    [0, last_step]."""
    goal = CustomState(
        position=Rectangle(length, width, np.asarray(center, float), yaw),
        time_step=Interval(0, last_step),
    )
    return PlanningProblemSet([PlanningProblem(pid, init, GoalRegion([goal]))])


def _scenario(map_id: int, lanelets, obstacles=(), intersections=()) -> Scenario:
    sid = ScenarioID(country_id="ZAM", map_name="MpcdriveCase", map_id=map_id, configuration_id=1)
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


# -- the cases --------------------------------------------------------------------------------------
def case_1():
    """A parked car in the ego's lane 40 m ahead on a straight two-lane road, the left lane free;
    the goal lies in the ego's lane past it: pass on the left and return."""
    sc = _scenario(1, _straight_two_lane_road(), [_parked(100, 50.0, 0.0)])
    pps = _problem(1000, _initial(10.0, 0.0, 0.0, 10.0), (110.0, 0.0), 0.0, 10.0, 3.0, 120)
    return sc, pps, [Tag.URBAN, Tag.MULTI_LANE, Tag.EVASIVE, Tag.NO_ONCOMING_TRAFFIC]


def case_2():
    """Both lanes blocked by parked cars side by side 40 m ahead (2 m wide: no gap lets the ego
    through); the goal lies past them: stop before them."""
    sc = _scenario(
        2,
        _straight_two_lane_road(),
        [_parked(100, 50.0, 0.0, length=4.8, width=2.0), _parked(101, 50.0, LANE_W, length=4.8, width=2.0)],
    )
    pps = _problem(1000, _initial(10.0, 0.0, 0.0, 10.0), (110.0, 0.0), 0.0, 10.0, 3.0, 100)
    return sc, pps, [Tag.URBAN, Tag.MULTI_LANE, Tag.EMERGENCY_BRAKING, Tag.NO_ONCOMING_TRAFFIC]


FOLLOWER_STEPS = 120


def follower_positions() -> np.ndarray:
    """Case 3's follower: 25 m behind the ego at 14 m/s (the ego 10 m/s) in its lane; from 2 s to
    5 s it moves over to the left lane (a smoothstep in y), then passes the ego there."""
    t = np.arange(FOLLOWER_STEPS + 1) * DT
    x = 15.0 + 14.0 * t
    u = np.clip((t - 2.0) / 3.0, 0.0, 1.0)
    y = LANE_W * u * u * (3.0 - 2.0 * u)
    return np.column_stack([x, y])


def case_3():
    """A faster car approaching from behind in the ego's lane, overtaking on the left: keep the
    lane and the speed."""
    sc = _scenario(3, _straight_two_lane_road(), [_moving(100, follower_positions(), FOLLOWER_STEPS)])
    pps = _problem(1000, _initial(40.0, 0.0, 0.0, 10.0), (120.0, 0.0), 0.0, 10.0, 3.0, 110)
    return sc, pps, [Tag.URBAN, Tag.MULTI_LANE, Tag.LANE_FOLLOWING, Tag.NO_ONCOMING_TRAFFIC]


# case 4: a T intersection of a north-south road (x = 0 its middle) and a road to the west
# (y = 0 its middle), lanes LANE_W wide, right-hand traffic; the box is |x|, |y| <= BOX_M
BOX_M = 7.0
ARM_M = 60.0
ONCOMING_V = 10.0
#: when [s] the oncoming car's centre crosses y = 0, in the middle of the oncoming lane: where
#: and when the ego, driving its left turn without the oncoming car, crosses that lane's centre
#: (measured on mpcdrive's drives of the BMW 320i on CommonRoad's KS and ST models)
ONCOMING_AT_S = 5.6
ONCOMING_STEPS = int(round((ONCOMING_AT_S + (ARM_M - 2.0) / ONCOMING_V) / DT))  # to 2 m before the arm's end


def _intersection() -> tuple[list[Lanelet], Intersection]:
    b, h = BOX_M, 0.5 * LANE_W
    q = 0.5 * math.pi
    arm = {"lanelet_type": {LaneletType.URBAN}}
    box = {"lanelet_type": {LaneletType.INTERSECTION}}
    lanes = [
        # (id, centre, predecessors, successors, adjacent left (the opposite lane), kind)
        (1, _line((h, -ARM_M), (h, -b)), [], [7, 8], 2, arm),  # south arm northbound (the ego's)
        (2, _line((-h, -b), (-h, -ARM_M)), [9, 11], [], 1, arm),  # south arm southbound
        (3, _line((-h, ARM_M), (-h, b)), [], [9, 10], 4, arm),  # north arm southbound (the oncoming car's)
        (4, _line((h, b), (h, ARM_M)), [7, 12], [], 3, arm),  # north arm northbound
        (5, _line((-b, h), (-ARM_M, h)), [8, 10], [], 6, arm),  # west arm westbound (the ego's goal)
        (6, _line((-ARM_M, -h), (-b, -h)), [], [11, 12], 5, arm),  # west arm eastbound
        (7, _line((h, -b), (h, b)), [1], [4], 9, box),  # south -> north
        (8, _arc((-b, -b), b + h, 0.0, q), [1], [5], None, box),  # south -> west: the ego's left turn
        (9, _line((-h, b), (-h, -b)), [3], [2], 7, box),  # north -> south: the oncoming car
        (10, _arc((-b, b), b - h, 0.0, -q), [3], [5], None, box),  # north -> west (right turn)
        (11, _arc((-b, -b), b - h, q, 0.0), [6], [2], None, box),  # west -> south (right turn)
        (12, _arc((-b, b), b + h, -q, 0.0), [6], [4], None, box),  # west -> north (left turn)
    ]
    out = []
    for lid, c, pred, succ, adj, kind in lanes:
        kw = dict(predecessor=pred, successor=succ, **kind)
        if adj is not None:
            kw.update(adjacent_left=adj, adjacent_left_same_direction=False)
        if kind is arm:
            kw.update(line_marking_left_vertices=LineMarking.DASHED, line_marking_right_vertices=LineMarking.SOLID)
        out.append(_lanelet(lid, c, LANE_W, **kw))
    # incomings: from the south (61), the north (62), the west (63); left_of: the incoming on the left
    incomings = [
        IntersectionIncomingElement(61, {1}, successors_straight={7}, successors_left={8}, left_of=63),
        IntersectionIncomingElement(62, {3}, successors_right={10}, successors_straight={9}),
        IntersectionIncomingElement(63, {6}, successors_right={11}, successors_left={12}, left_of=62),
    ]
    return out, Intersection(60, incomings)


def oncoming_positions() -> np.ndarray:
    """Case 4's oncoming car: southbound at :data:`ONCOMING_V` in the middle of lanelets 3 -> 9 ->
    2 (x = -LANE_W / 2), its centre at y = 0 at :data:`ONCOMING_AT_S`."""
    t = np.arange(ONCOMING_STEPS + 1) * DT
    y = ONCOMING_V * (ONCOMING_AT_S - t)
    return np.column_stack([np.full_like(y, -0.5 * LANE_W), y])


def case_4():
    """A left turn at a T intersection across the lane of an oncoming car that goes straight on:
    yield, then complete the turn into the west arm."""
    lanelets, inter = _intersection()
    sc = _scenario(4, lanelets, [_moving(100, oncoming_positions(), ONCOMING_STEPS)], [inter])
    pps = _problem(1000, _initial(0.5 * LANE_W, -40.0, 0.5 * math.pi, 8.0), (-25.0, 0.5 * LANE_W), 0.0, 10.0, 3.0, 150)
    return sc, pps, [Tag.URBAN, Tag.INTERSECTION, Tag.TURN_LEFT, Tag.ONCOMING_TRAFFIC]


# case 5: one lane, a straight, a 90 deg left bend of radius BEND_R_M (its centre line) along which
# the lane narrows linearly from WIDE_M to NARROW_M, and a straight at NARROW_M
BEND_R_M = 30.0
WIDE_M = 3.7
NARROW_M = 3.0


def case_5():
    """A lane that narrows from 3.7 m to 3.0 m along a 30 m radius left bend, no obstacles: the
    body stays inside."""
    r = BEND_R_M
    bend = _arc((30.0, 30.0), r, -0.5 * math.pi, 0.0)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(bend[0], axis=0).T))]
    edges = dict(line_marking_left_vertices=LineMarking.SOLID, line_marking_right_vertices=LineMarking.SOLID)
    lanelets = [
        _lanelet(1, _line((0.0, 0.0), (30.0, 0.0)), WIDE_M, successor=[2], **edges),
        _lanelet(2, bend, WIDE_M + (NARROW_M - WIDE_M) * s / s[-1], predecessor=[1], successor=[3], **edges),
        _lanelet(3, _line((30.0 + r, r), (30.0 + r, r + 60.0)), NARROW_M, predecessor=[2], **edges),
    ]
    sc = _scenario(5, lanelets)
    pps = _problem(1000, _initial(5.0, 0.0, 0.0, 10.0), (30.0 + r, r + 30.0), 0.5 * math.pi, 10.0, 2.6, 120)
    return sc, pps, [Tag.RURAL, Tag.SINGLE_LANE, Tag.LANE_FOLLOWING]


CASES = {
    "ZAM_MpcdriveCase-1_1_T-1.xml": case_1,
    "ZAM_MpcdriveCase-2_1_T-1.xml": case_2,
    "ZAM_MpcdriveCase-3_1_T-1.xml": case_3,
    "ZAM_MpcdriveCase-4_1_T-1.xml": case_4,
    "ZAM_MpcdriveCase-5_1_T-1.xml": case_5,
}


def write(name: str, build, out_dir: Path) -> Path:
    """Build one case and write it as ``out_dir / name`` (header date :data:`DATE`)."""
    sc, pps, tags = build()
    path = Path(out_dir) / name
    writer = CommonRoadFileWriter(
        sc, pps, author=AUTHOR, affiliation=AFFILIATION, source=SOURCE, tags=tags, location=Location()
    )
    writer.write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    text = path.read_text(encoding="utf-8")
    text, n = re.subn(r'(<commonRoad [^>]*\bdate=")[^"]*(")', rf"\g<1>{DATE}\g<2>", text, count=1)
    if n != 1:
        raise RuntimeError(f"{name}: no date attribute in the header")
    # the writer's own check_validity only returns the verdict: check against the XSD here
    if not CommonRoadFileWriter.check_validity_of_commonroad_file(text.encode("utf-8")):
        raise RuntimeError(f"{name}: not valid against the CommonRoad XSD")
    path.write_text(text, encoding="utf-8")
    return path


def main(out_dir: str | Path = HERE) -> list[Path]:
    """Write every case into ``out_dir``; returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [write(name, build, out_dir) for name, build in CASES.items()]


if __name__ == "__main__":
    for p in main(*sys.argv[1:2]):
        print(p)
