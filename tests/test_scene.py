"""Scene geometry: clearance between the vehicle footprint and each obstacle shape."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.scene import (
    Circle,
    ConstantVelocity,
    Footprint,
    Obstacle,
    Polygon,
    TrajectoryMotion,
    rectangle,
    shape_distance,
)
from mpcdrive.scene.geometry import point_polygon, points_polygon, points_polygons

coord = st.floats(-5, 5, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


def sample(p, n=400):
    q = np.roll(p, -1, axis=0)
    t = np.linspace(0, 1, n)[:, None, None]
    return (p[None] + t * (q - p)[None]).reshape(-1, 2)


def dense_distance(a_pts, b_pts, sample_b=True):
    """Brute-force distance between two boundaries sampled densely (reference)."""
    A = sample(a_pts)
    B = sample(b_pts) if sample_b else b_pts
    d = np.hypot(A[:, None, 0] - B[None, :, 0], A[:, None, 1] - B[None, :, 1])
    return d.min()


@settings(max_examples=60, deadline=None)
@given(x=coord, y=coord, yaw=angle, ox=coord, oy=coord, r=st.floats(0.05, 1.5))
def test_footprint_to_circle_clearance_matches_brute_force(x, y, yaw, ox, oy, r):
    fp = Footprint(0.5, 0.27)
    car = fp.polygon(x, y, yaw)
    circle = Obstacle(Circle(r), (ox, oy, 0.0)).at(0.0)
    d = shape_distance(car, circle)
    th = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    ring = np.column_stack([ox + r * np.cos(th), oy + r * np.sin(th)])
    inside_centre = point_polygon(np.array([ox, oy]), car.points)[0] < 0
    if d > 1e-3:
        assert d == pytest.approx(dense_distance(car.points, ring, sample_b=False), abs=2e-3)
    elif d < -1e-3:  # overlap: centre inside the body, a body corner inside the disc, or crossing
        corner_in = np.any(np.hypot(car.points[:, 0] - ox, car.points[:, 1] - oy) < r)
        assert inside_centre or corner_in or dense_distance(car.points, ring, sample_b=False) < 2e-3


@settings(max_examples=60, deadline=None)
@given(x=coord, y=coord, yaw=angle, ox=coord, oy=coord, oyaw=angle, L=st.floats(0.1, 2), W=st.floats(0.1, 2))
def test_footprint_to_rectangle_clearance_matches_brute_force(x, y, yaw, ox, oy, oyaw, L, W):
    car = Footprint(0.5, 0.27).polygon(x, y, yaw)
    box = Obstacle(rectangle(L, W), (ox, oy, oyaw)).at(0.0)
    d = shape_distance(car, box)
    ref = dense_distance(car.points, box.points)
    if d > 1e-3:
        assert d == pytest.approx(ref, abs=2e-3)
    else:
        # touching or overlapping: some vertex of one lies in (or on) the other, or edges cross
        assert (
            ref < 5e-3
            or min(point_polygon(p, box.points)[0] for p in car.points) <= 1e-9
            or min(point_polygon(p, car.points)[0] for p in box.points) <= 1e-9
        )


@settings(max_examples=40, deadline=None)
@given(x=coord, y=coord, yaw=angle, ox=coord, oy=coord, r=st.floats(0.05, 1.0), n=st.integers(1, 6))
def test_footprint_discs_cover_the_body(x, y, yaw, ox, oy, r, n):
    """Disc clearance never exceeds body clearance: keeping the discs clear keeps the body clear."""
    fp = Footprint(0.5, 0.27, n_discs=n)
    circle = Obstacle(Circle(r), (ox, oy, 0.0)).at(0.0)
    body = shape_distance(fp.polygon(x, y, yaw), circle)
    c, s = math.cos(yaw), math.sin(yaw)
    discs = [math.hypot(x + o * c - ox, y + o * s - oy) - fp.disc_radius_m - r for o in fp.disc_offsets_m]
    if body >= 0:
        assert min(discs) <= body + 1e-9
    if min(discs) > 0:
        assert body > 0


def test_vectorized_point_polygon_agrees():
    rng = np.random.default_rng(0)
    poly = Obstacle(rectangle(1.0, 0.5), (0.3, -0.2, 0.7)).at(0.0).points
    P = rng.uniform(-2, 2, size=(200, 2))
    d, q = points_polygon(P, poly)
    for k in range(len(P)):
        dk, qk = point_polygon(P[k], poly)
        assert d[k] == pytest.approx(dk) and np.allclose(q[k], qk)


def test_point_to_its_own_polygon_agrees():
    """A moving obstacle: point k against the polygon at time k (inside, outside, on corners)."""
    rng = np.random.default_rng(1)
    turning = TrajectoryMotion(
        np.array([0.0, 20.0]), np.array([0.0, 16.0]), np.array([0.0, -6.0]), np.array([0.0, 10.0])
    )
    ob = Obstacle(rectangle(1.0, 0.5), (0.3, -0.2, 0.7), turning)
    polys = np.stack([ob.at(0.1 * k).points for k in range(200)])
    P = polys.mean(axis=1) + rng.uniform(-1.2, 1.2, size=(200, 2))
    d, q = points_polygons(P, polys)
    assert (d < 0).any() and (d > 0).any()
    for k in range(len(P)):
        dk, qk = point_polygon(P[k], polys[k])
        assert d[k] == pytest.approx(dk, abs=1e-12) and np.allclose(q[k], qk, atol=1e-12)


def test_motion_models():
    ob = Obstacle(Circle(0.3), (1.0, 2.0, 0.0), ConstantVelocity(0.5, -1.0))
    assert ob.pose_at(2.0) == pytest.approx((2.0, 0.0, 0.0))
    tr = TrajectoryMotion(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 1.0]), np.array([0.0, 0.0, 2.0]), np.zeros(3))
    ob2 = Obstacle(rectangle(1, 1), (0.0, 0.0, 0.0), tr)
    assert ob2.pose_at(0.5) == pytest.approx((0.5, 0.0, 0.0))
    assert ob2.pose_at(5.0) == pytest.approx((1.0, 2.0, 0.0))
    assert ob2.moving and not Obstacle(Circle(1), (0, 0, 0)).moving


@pytest.mark.parametrize(
    "make",
    [
        lambda: Circle(0.0),
        lambda: Circle(float("nan")),
        lambda: rectangle(0, 1),
        lambda: Polygon(np.array([[0, 0], [1, 0]])),
        lambda: Polygon(
            np.array([[0, 0], [2, 0], [1, 0.2], [1, 2]]) * [1, 1]
            + [[0, 0], [0, 0], [0, 0.5], [0, 0]] * 0
            + np.array([[0, 0], [0, 0], [0, 1.5], [0, 0]])
        ),
        lambda: Obstacle(Circle(1), (0, float("inf"), 0)),
        lambda: TrajectoryMotion(np.array([0.0, 0.0]), np.zeros(2), np.zeros(2), np.zeros(2)),
    ],
)
def test_bad_shapes_raise_value_error(make):
    with pytest.raises(ValueError):
        make()


@pytest.mark.parametrize(
    "motion",
    [
        None,
        ConstantVelocity(2.0, -1.0),
        TrajectoryMotion([0.0, 1.0, 3.0], [0.0, 2.0, 3.0], [0.0, 1.0, -1.0], [0.0, 0.5, 1.0]),
    ],
)
def test_poses_and_outlines_over_times_are_those_at_each_time(motion):
    kw = {} if motion is None else {"motion": motion}
    ob = Obstacle(rectangle(2.0, 1.0), (1.0, 2.0, 0.3), **kw)
    times = np.linspace(-0.5, 3.5, 9)
    np.testing.assert_allclose(ob.poses_at(times), [ob.pose_at(t) for t in times], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ob.outlines_at(times), [ob.at(t).points for t in times], rtol=0, atol=1e-12)
