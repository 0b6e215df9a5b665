"""The planner's contact test with an obstacle's oriented box (mpcdrive.planning.contact): against
an exact geometric oracle (shapely's distances to the turned rectangle), and in the planner, where
a car yawed to the path is no longer its Frenet box (the bounding box along and across the path,
which is 4.5 m by 4.5 m for a 4.5 m by 1.8 m car at 45 degrees)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import LineString, Point
from shapely.geometry import Polygon as ShapelyPolygon

from mpcdrive.ocp.avoidance_compiled import table_of
from mpcdrive.ocp.relations import REL_CLEAR, REL_RIGHT
from mpcdrive.paths.compiled import path_arrays
from mpcdrive.paths.waypoints import WaypointPath
from mpcdrive.planning import VehicleLimits
from mpcdrive.planning.contact import _disc_meets
from mpcdrive.planning.tracks import obstacle_tracks
from mpcdrive.scene.obstacles import ConstantVelocity, Obstacle, rectangle

from test_planning import LIMITS, plan, planner

RN = 1.4  # a disc's radius and the margin [m]


def frenet_box(a: float, b: float, yaw: float) -> tuple[float, float]:
    """The half extents along and across of a box of half extents a, b turned by ``yaw``."""
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    return a * c + b * s, a * s + b * c


def outline(a: float, b: float, yaw: float) -> ShapelyPolygon:
    c, s = math.cos(yaw), math.sin(yaw)
    return ShapelyPolygon([(c * x - s * y, s * x + c * y) for x, y in ((a, b), (-a, b), (-a, -b), (a, -b))])


def meets(p0, p1, a, b, yaw0, yaw1) -> bool:
    or_ = np.array([[[math.cos(yaw0), math.sin(yaw0), a, b], [math.cos(yaw1), math.sin(yaw1), a, b]]])
    bl = max(frenet_box(a, b, yaw0)[0], frenet_box(a, b, yaw1)[0])
    bw = max(frenet_box(a, b, yaw0)[1], frenet_box(a, b, yaw1)[1])
    return bool(_disc_meets.py_func(p0[0], p0[1], p1[0], p1[1], bl, bw, or_, 0, 0, 1, RN))


def test_a_disc_at_rest_meets_the_turned_box_exactly_when_shapely_says_it_is_within_its_radius():
    rng = np.random.default_rng(7)
    n_frenet_only = 0
    for _ in range(4000):
        yaw = rng.uniform(-math.pi, math.pi)
        p = rng.uniform(-5.0, 5.0, 2)
        d = outline(2.25, 0.9, yaw).distance(Point(p))
        if abs(d - RN) < 1e-9:
            continue
        hit = meets(p, p, 2.25, 0.9, yaw, yaw)
        assert hit == (d < RN), (yaw, p, d)
        bl, bw = frenet_box(2.25, 0.9, yaw)
        dx, dy = max(abs(p[0]) - bl, 0.0), max(abs(p[1]) - bw, 0.0)
        n_frenet_only += math.hypot(dx, dy) < RN and not hit
    # the points the Frenet box alone would have called a contact (the test's reason to exist)
    assert n_frenet_only > 300


def test_a_moving_disc_never_passes_through_the_turned_box_unnoticed():
    """The disc's way over a step (the obstacle's yaw the same at both ends): every way that
    shapely finds within the radius of the outline is a contact, and a way no longer than the
    radius is one only when it comes that near (its ends and middle judged)."""
    rng = np.random.default_rng(11)
    for _ in range(3000):
        yaw = rng.uniform(-math.pi, math.pi)
        p0 = rng.uniform(-6.0, 6.0, 2)
        p1 = p0 + rng.uniform(-3.0, 3.0, 2)
        way = LineString([tuple(p0), tuple(p1)])
        box = outline(2.25, 0.9, yaw)
        d = box.distance(way)
        hit = meets(p0, p1, 2.25, 0.9, yaw, yaw)
        if d < RN - 1e-9:
            assert hit, (yaw, p0, p1, d)
        if hit and np.hypot(*(p1 - p0)) <= RN:
            assert d < RN, (yaw, p0, p1, d)


def test_the_tracks_give_each_sample_its_yaw_to_the_path_and_its_own_half_extents():
    path = WaypointPath([(0.0, 0.0), (40.0, 0.0), (80.0, 40.0)], ds_m=0.2)  # a 45 degree bend at 40 m
    yaw = 0.3
    ob = Obstacle(rectangle(4.5, 1.8), (60.0, 25.0, yaw), ConstantVelocity(0.0, 0.0))
    K = 5
    out = [np.full((4, K + 1), np.nan) for _ in range(4)]
    orient = np.full((4, K + 1, 4), np.nan)
    index = np.zeros(4, np.int64)
    n = obstacle_tracks(table_of([ob], None), path_arrays(path), 0.0, 0.2, 40.0, (40.0, 0.0), 100.0, 25.0, *out, index,
                        None, 0.0, orient)  # fmt: skip
    assert n == 1
    rel = yaw - float(path.heading(out[0][0, 0]))  # to the path's heading where it projects
    assert orient[0, :, 0] == pytest.approx(np.full(K + 1, math.cos(rel)), abs=1e-9)
    assert orient[0, :, 1] == pytest.approx(np.full(K + 1, math.sin(rel)), abs=1e-9)
    assert orient[0, :, 2:] == pytest.approx(np.tile([2.25, 0.9], (K + 1, 1)))
    # the Frenet box is the turned outline's bounding box
    hl, hw = frenet_box(2.25, 0.9, rel)
    assert out[2][0] == pytest.approx(np.full(K + 1, hl), abs=1e-9)
    assert out[3][0] == pytest.approx(np.full(K + 1, hw), abs=1e-9)


def _diagonal(yaw: float, v: float, length: float = 4.5, width: float = 1.8) -> Obstacle:
    """A box whose Frenet box's near corner is 0.5 m ahead of and 0.5 m left of the car's front
    disc (the car at rest at s = 20 m on the path), driving ``v`` [m/s] along ``yaw``."""
    h = frenet_box(2.25, 0.9, math.pi / 4)[0]
    x, y = 20.0 + LIMITS.disc_offsets_m[-1] + h + 0.5, h + 0.5
    return Obstacle(rectangle(length, width), (x, y, yaw), ConstantVelocity(v * math.cos(yaw), v * math.sin(yaw)))


@pytest.mark.parametrize("yaw", [math.pi / 4, -0.75 * math.pi])
def test_a_car_turned_away_from_the_path_beside_the_car_at_rest_leaves_it_a_safe_maneuver(yaw):
    # DEU_Salzwedel-107: a car turning past the car at rest came within the margin of its front
    # disc by its Frenet box alone; every maneuver was unsafe from the first replanning, and the
    # controller's rows about that box (a stop row, then none) made its acceleration alternate
    # between +8 and -9 m/s^2 at consecutive steps for a second
    v = 3.0 if yaw > 0 else -3.0  # driving away from the path (the second: reversing away)
    m = plan(planner(), [_diagonal(yaw, v)], s=20.0, v=0.0)
    assert m.safe and m.ttc_s == math.inf
    # its Frenet box exceeds its outline by more than the margin the planner keeps beyond the
    # controller's rows: the controller keeps the outline's nearest-point half-plane
    assert np.all(m.relations == REL_CLEAR)


def test_a_box_as_large_as_that_frenet_box_is_met_at_once():
    h = frenet_box(2.25, 0.9, math.pi / 4)[0]
    m = plan(planner(), [_diagonal(0.0, 3.0 / math.sqrt(2.0), 2 * h, 2 * h)], s=20.0, v=0.0)
    assert not m.safe and m.ttc_s == 0.0


@pytest.mark.parametrize(("yaw", "rows"), [(0.0, {REL_RIGHT}), (0.3, {REL_CLEAR})])
def test_a_car_beside_keeps_the_lateral_row_unless_its_frenet_box_exceeds_its_outline(yaw, rows):
    # a car in the next lane at the car's speed: a lateral row keeps the car right of it; turned
    # 0.3 rad to the path its Frenet box is 0.63 m wider than the car, beyond the 0.3 m the
    # planner keeps beyond the rows (the test's limits keep no margin in the rows)
    ob = Obstacle(rectangle(4.5, 1.8), (21.0, 3.5, yaw), ConstantVelocity(12.0, 0.0))
    m = plan(planner(), [ob], s=20.0, v=12.0)
    assert m.safe
    near = {int(r) for r in m.relations[0, :6]}
    assert near == rows


def test_a_negative_row_margin_of_the_controller_is_refused():
    with pytest.raises(ValueError, match="disc_margin_m"):
        VehicleLimits(**{**LIMITS.__dict__, "disc_margin_m": -0.1})
