"""The lane excess a drive is judged by (Road.measure_excess_m) is exact: against the geometry of
a circle, a straight road that narrows, a periodic road of varying width and a spline path,
each computed here without the library's projection, to the measure's sampling tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcdrive.paths import CirclePath, StraightPath, WaypointPath
from mpcdrive.scene import Footprint
from mpcdrive.scene.road import EXCESS_SAMPLING_TOL_M, Road

CAR = Footprint(0.5, 0.27)  # the README's 1:10 car
TOL = EXCESS_SAMPLING_TOL_M + 1e-9


def _outline(fp: Footprint, pose, n: int = 4000) -> np.ndarray:
    """(4 n, 2) world points densely along the body's outline at ``pose``."""
    c = fp.corners()
    tau = np.linspace(0.0, 1.0, n)
    body = (c[:, None, :] + tau[None, :, None] * (np.roll(c, -1, axis=0) - c)[:, None, :]).reshape(-1, 2)
    x, y, yaw = pose
    cs, sn = math.cos(yaw), math.sin(yaw)
    return np.column_stack([x + cs * body[:, 0] - sn * body[:, 1], y + sn * body[:, 0] + cs * body[:, 1]])


def _poses_near_circle(rng, R: float, n: int, spread_m: float, yaw_spread: float):
    """(n, 3) poses of the reference point near a ccw circle of radius R about the origin and
    their arc lengths (n,)."""
    th = rng.uniform(0.0, 2 * math.pi, n)
    rho = R + rng.uniform(-spread_m, spread_m, n)
    yaw = th + math.pi / 2 + rng.uniform(-yaw_spread, yaw_spread, n)
    return np.column_stack([rho * np.cos(th), rho * np.sin(th), yaw]), R * th


def test_on_the_readme_circle_the_excess_is_exact():
    """Radius 1.5 m, a 1 m lane: the farthest corner from the centre against the outer edge, the
    nearest point of the rectangle (often in the middle of a side) against the inner edge."""
    from mpcdrive.scene.geometry import point_polygon

    R, half = 1.5, 0.5
    road = Road.constant(2 * half, 0.05)
    path = CirclePath(radius_m=R)
    poses, s = _poses_near_circle(np.random.default_rng(3), R, 400, 0.45, 0.6)
    got = road.measure_excess_m(path, poses, s, CAR)
    exact = []
    for p in poses:
        poly = CAR.polygon(*p).points
        outer = np.hypot(poly[:, 0], poly[:, 1]).max() - (R + half)
        d, _ = point_polygon(np.zeros(2), poly)
        inner = (R - half) - max(d, 0.0)
        exact.append(max(outer, inner, 0.0))
    exact = np.array(exact)
    assert np.count_nonzero(exact > 0.01) > 50  # many poses out of the lane
    np.testing.assert_allclose(got, exact, rtol=0, atol=TOL)
    # the controller rows' linearized rule over-reports here by millimetres
    rel = poses[:, 2] - (s / R + math.pi / 2)
    old = road.body_excess_m(s, R - np.hypot(poses[:, 0], poses[:, 1]), 1.0 / R, rel, CAR)
    assert np.max(old - exact) > 1e-3


def test_a_narrowing_road_is_measured_at_its_knots():
    """A straight road whose left edge steps in from 1 m to 0.6 m between s = 2 and 2.5 m: the
    excess is linear between the knots, so its largest value over the body is at a corner or
    where a side crosses a knot (computed here exactly)."""
    s_k, left_k, right_k = [0.0, 2.0, 2.5, 5.0], [1.0, 1.0, 0.6, 0.6], [1.0, 1.0, 1.0, 1.0]
    road = Road.from_widths(s_k, left_k, right_k, 0.0)
    path = StraightPath((0.0, 0.0), (5.0, 0.0))
    car = Footprint(1.2, 0.6)
    rng = np.random.default_rng(5)
    poses = np.column_stack([rng.uniform(0.5, 4.5, 300), rng.uniform(-0.5, 0.8, 300), rng.uniform(-0.5, 0.5, 300)])
    got = road.measure_excess_m(path, poses, poses[:, 0], car)
    exact = []
    for p in poses:
        c = car.polygon(*p).points
        pts = [c]
        for a, b in zip(c, np.roll(c, -1, axis=0)):
            for sj in s_k:
                if (a[0] - sj) * (b[0] - sj) < 0:
                    pts.append([a + (sj - a[0]) / (b[0] - a[0]) * (b - a)])
        q = np.vstack(pts)
        left, right = np.interp(q[:, 0], s_k, left_k), -np.interp(q[:, 0], s_k, right_k)
        exact.append(max(float(np.max(q[:, 1] - left)), float(np.max(right - q[:, 1])), 0.0))
    exact = np.array(exact)
    assert np.count_nonzero(exact > 0.01) > 30
    np.testing.assert_allclose(got, exact, rtol=0, atol=TOL)


def test_a_periodic_road_of_varying_width_on_a_closed_path():
    """A circle of radius 5 m whose left width varies around the lap (knots every 45 deg, the
    last joined to the first): the outline densely in polar coordinates, where the arc length
    and the lateral offset are exact, against the edges."""
    R = 5.0
    path = CirclePath(radius_m=R)
    L = path.length_m
    s_k = np.linspace(0.0, L, 9)[:-1]
    wl = np.array([1.0, 0.8, 1.2, 0.7, 1.0, 0.9, 1.3, 0.75])
    road = Road.from_widths(s_k, wl, 0.9, 0.0, period_m=L)
    car = Footprint(1.5, 0.7)
    poses, s = _poses_near_circle(np.random.default_rng(11), R, 120, 0.6, 0.4)
    s = s + L * (np.arange(len(s)) % 3)  # on other laps too (arc length counts laps)
    got = road.measure_excess_m(path, poses, s, car)
    exact = []
    for p in poses:
        q = _outline(car, p)
        th = np.arctan2(q[:, 1], q[:, 0]) % (2 * math.pi)
        e = R - np.hypot(q[:, 0], q[:, 1])  # left (towards the centre) positive
        left = np.interp(R * th, s_k, wl, period=L)
        exact.append(max(float(np.max(e - left)), float(np.max(-0.9 - e)), 0.0))
    exact = np.array(exact)
    assert np.count_nonzero(exact > 0.01) > 20
    np.testing.assert_allclose(got, exact, rtol=0, atol=TOL + 1e-5)  # the dense outline's own spacing


def test_a_spline_path_is_measured_against_its_own_table():
    """An S-curve through waypoints: each outline point's lateral offset from the path's polyline
    found here by brute force over all its segments."""
    path = WaypointPath([[0, 0], [3, 1], [6, -1], [9, 0]], interpolation="spline")
    road = Road.constant(1.0, 0.0)
    s_line = np.linspace(0.0, path.length_m, 4001)  # 2.6 mm apart: chords within 1e-6 m of the table's
    line = path.position(s_line)
    rng = np.random.default_rng(2)
    s = rng.uniform(1.0, path.length_m - 1.0, 60)
    h = np.asarray(path.heading(s), float)
    off = rng.uniform(-0.45, 0.45, 60)
    base = path.position(s)
    poses = np.column_stack(
        [base[:, 0] - off * np.sin(h), base[:, 1] + off * np.cos(h), h + rng.uniform(-0.5, 0.5, 60)]
    )
    got = road.measure_excess_m(path, poses, s, CAR)
    exact = []
    for p, sp in zip(poses, s):
        q = _outline(CAR, p, 300)
        near = (s_line >= sp - 1.0) & (s_line <= sp + 1.0)  # the body is within 0.3 m of its s
        a, d = line[near][:-1], np.diff(line[near], axis=0)
        rel = q[:, None, :] - a[None, :, :]
        t = np.clip(np.einsum("kmi,mi->km", rel, d) / np.einsum("mi,mi->m", d, d), 0.0, 1.0)
        gap = rel - t[..., None] * d[None]
        dist = np.hypot(gap[..., 0], gap[..., 1])
        j = np.argmin(dist, axis=1)
        side = np.sign(d[j, 0] * rel[np.arange(len(q)), j, 1] - d[j, 1] * rel[np.arange(len(q)), j, 0])
        e = side * dist[np.arange(len(q)), j]
        exact.append(max(float(np.max(np.abs(e) - 0.5)), 0.0))
    exact = np.array(exact)
    assert np.count_nonzero(exact > 0.01) > 10
    # the outline here 300 points a side (< 2 mm apart: sampling error < 1e-6 m at kappa < 1 / m)
    np.testing.assert_allclose(got, exact, rtol=0, atol=TOL + 1e-5)


class Steady:
    """Holds the steering at ``steer_rad``: a kinematic bicycle then drives a circle. Its
    outputs' path coordinates are the state's on ``path``."""

    nx, nu, N = 3, 1, 0

    def __init__(self, steer_rad: float, path):
        self.steer, self.path = steer_rad, path

    def initial_warm(self, x0):
        from mpcdrive.types import WarmStart

        return WarmStart(s_m=float(self.path.project(np.asarray(x0[:2], float))[0]), u_prev=np.zeros(1))

    def step(self, x, warm):
        from mpcdrive.types import STATUS_OK, ControlOutput, WarmStart

        f = self.path.frenet(x[:3], warm.s_m)
        X = np.asarray(x, float)[None, :]
        return ControlOutput(
            np.array([self.steer]), STATUS_OK, "", 0.0, f.s_m, f.e_y_m, f.e_psi_rad, X, X, WarmStart(f.s_m, np.zeros(1))
        )


def test_a_drive_on_the_readme_circle_reports_its_exact_excess():
    """The README's circle (radius 1.5 m, a 1 m lane) driven at a steady 1.1 m radius about its
    centre: the body's inner side cuts the inner edge, deepest in the middle of the side. The
    run's max_lane_excess_m is the exact excess of its logged poses (the rows' rule said 4 mm
    more on the README's own drive: 0.0426 m for 0.0384 m)."""
    from mpcdrive.models import KinematicBicycle3, KinematicParams
    from mpcdrive.scene.geometry import point_polygon
    from mpcdrive.sim import Plant, compute_metrics, simulate

    lf, lr, rho = 0.17, 0.16, 1.1
    beta = math.asin(lr / rho)  # the centre of gravity on radius rho: sin(beta) = lr / rho
    steer = math.atan(math.tan(beta) * (lf + lr) / lr)
    model = KinematicBicycle3(1.0, KinematicParams(lf, lr))
    x0 = [rho * math.cos(beta), rho * math.sin(beta), math.pi / 2]  # its velocity (yaw + beta) tangent
    path = CirclePath(radius_m=1.5)
    r = simulate(Steady(steer, path), Plant(model), path, x0, 0.01, 300, road=Road.constant(1.0), footprint=CAR)
    assert np.allclose(np.hypot(r.x[:, 0], r.x[:, 1]), rho, atol=1e-3)  # the circle about the centre
    exact = 0.0
    for p in r.x:
        poly = CAR.polygon(*p[:3]).points
        d, _ = point_polygon(np.zeros(2), poly)
        exact = max(exact, np.hypot(poly[:, 0], poly[:, 1]).max() - 2.0, 1.0 - max(d, 0.0))
    assert exact > 0.02
    assert compute_metrics(r).max_lane_excess_m == pytest.approx(exact, abs=TOL)


def test_a_body_past_the_road_end_is_outside_by_how_far_it_reaches():
    """A straight road from s = 2 m to s = 10 m (a lane with no predecessor / successor): a body
    whose nose is 2.24 m past the end is 2.24 m outside, one wholly before it 0; a corner also
    beyond a side edge is outside by the straight-line distance to the road's corner; behind the
    start likewise. Poses at random, each against the exact rectangle."""
    road = Road.from_widths([0.0, 12.0], [1.5, 1.5], [1.5, 1.5], 0.0, start_m=2.0, end_m=10.0)
    path = StraightPath((0.0, 0.0), (12.0, 0.0))  # (the path goes on past the road's end)
    car = Footprint(4.48, 1.8)
    nose = np.array([[10.0 - 2.24, 0.0, 0.0]])  # the centre 2.24 m before the end: the nose on it
    assert road.measure_excess_m(path, nose, nose[:, 0], car)[0] == pytest.approx(0.0, abs=TOL)
    past = nose + [2.24, 0.0, 0.0]
    assert road.measure_excess_m(path, past, past[:, 0], car)[0] == pytest.approx(2.24, abs=TOL)
    assert road.measure_end_excess_m(path, past, past[:, 0], car)[0] == pytest.approx(2.24, abs=TOL)
    # without its ends the same road reports nothing
    assert road.with_ends(None, None).measure_excess_m(path, past, past[:, 0], car)[0] == 0.0
    rng = np.random.default_rng(11)
    poses = np.column_stack([rng.uniform(-1.0, 14.0, 300), rng.uniform(-1.0, 1.0, 300), rng.uniform(-0.4, 0.4, 300)])
    got = road.measure_excess_m(path, poses, poses[:, 0], car)
    ends = road.measure_end_excess_m(path, poses, poses[:, 0], car)
    exact, exact_ends = [], []
    for p in poses:
        c = car.polygon(*p).points  # a convex body: its farthest point outside is a corner
        side = np.maximum(np.abs(c[:, 1]) - 1.5, 0.0)
        beyond = np.maximum(np.maximum(c[:, 0] - 10.0, 2.0 - c[:, 0]), 0.0)
        exact.append(np.max(np.hypot(side, beyond)))
        exact_ends.append(np.max(beyond))
    assert np.count_nonzero(np.array(exact_ends) > 0.1) > 50
    np.testing.assert_allclose(got, exact, rtol=0, atol=TOL)
    np.testing.assert_allclose(ends, exact_ends, rtol=0, atol=TOL)
    # the controller rows' form (body_excess_m) counts the ends too
    rows = road.body_excess_m(poses[:, 0], poses[:, 1], 0.0, poses[:, 2], car)
    assert np.all(rows >= np.array(exact_ends) - 1e-9)
    assert float(road.body_excess_m(past[0, 0], 0.0, 0.0, 0.0, car)) == pytest.approx(2.24)


def test_road_ends_are_kept_by_every_road_built_from_it():
    from mpcdrive.scenarios.build import build_road
    from mpcdrive.scenarios.schema import RoadSpec

    road = Road.from_widths([0.0, 5.0], [1.0, 1.2], [1.0, 1.0], 0.1, start_m=-1.0, end_m=4.0)
    spec = RoadSpec(widths=[(0.0, 1.0, 1.0), (5.0, 1.2, 1.0)], neighbours=[(0.0, 3.0, 0.0)], start_m=-1.0, end_m=4.0)
    built = build_road(spec, StraightPath((0.0, 0.0), (5.0, 0.0)))
    assert built is not None and len(built.lanes) == 3
    for r in (road, built, built.whole(), built.band([1]), built.band([1, 2])):
        assert (r.start_m, r.end_m) == (-1.0, 4.0)
    with pytest.raises(ValueError, match="start_m .* must be before"):
        Road.per_side(1.0, 1.0).with_ends(3.0, 2.0)
    with pytest.raises(ValueError, match="periodic"):
        Road.from_widths([0.0, 5.0], [1.0, 1.0], [1.0, 1.0], 0.0, period_m=10.0, end_m=4.0)
    with pytest.raises(ValueError, match="start_m 3 m must be before"):
        RoadSpec(lane_width_m=3.0, start_m=3.0, end_m=1.0)
