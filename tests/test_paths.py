"""Tests of angles (mpcdrive.units) and reference paths (mpcdrive.paths)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.paths import (
    ReferencePath,
    CirclePath,
    StraightPath,
    WaypointPath,
    horizon_arc_lengths,
    horizon_states,
)
from mpcdrive.units import unwrap_near, wrap_angle

SETTINGS = settings(max_examples=60, deadline=None)
finite = dict(allow_nan=False, allow_infinity=False)
TWO_PI = 2 * math.pi


def left_normal(h):
    return np.array([-math.sin(h), math.cos(h)])


def offset_point(path, s, e_y):
    return np.asarray(path.position(s), float) + e_y * left_normal(float(path.heading(s)))


# --------------------------------------------------------------------------------------
# units
# --------------------------------------------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(st.floats(-1e4, 1e4, **finite))
def test_wrap_angle_range_and_multiple_of_two_pi(a):
    w = wrap_angle(a)
    assert isinstance(w, float)
    assert -math.pi < w <= math.pi
    k = (w - a) / TWO_PI
    assert abs(k - round(k)) < 1e-9 * max(1.0, abs(a))
    # idempotent
    assert wrap_angle(w) == pytest.approx(w, abs=1e-12)


def test_wrap_angle_boundaries_and_arrays():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(0.0) == 0.0
    assert wrap_angle(TWO_PI + 0.1) == pytest.approx(0.1)
    assert wrap_angle(-TWO_PI - 0.1) == pytest.approx(-0.1)
    a = np.array([-7.0, -math.pi, 0.0, math.pi, 7.0, 100.0])
    w = wrap_angle(a)
    assert isinstance(w, np.ndarray) and w.shape == a.shape
    assert np.all((w > -math.pi) & (w <= math.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)


@SETTINGS
@given(st.floats(-100, 100, **finite), st.floats(-100, 100, **finite))
def test_unwrap_near_scalar(a, ref):
    out = unwrap_near(a, ref)
    assert isinstance(out, float)
    assert abs(out - ref) <= math.pi + 1e-9
    k = (out - a) / TWO_PI
    assert abs(k - round(k)) < 1e-9


@SETTINGS
@given(st.floats(-50, 50, **finite), st.floats(-50, 50, **finite), st.integers(1, 20))
def test_unwrap_near_array_keeps_shape_of_sequence(a0, ref, n):
    seq = a0 + 0.3 * np.arange(n)  # continuous sequence, may exceed pi in total
    out = unwrap_near(seq, ref)
    assert out.shape == seq.shape
    assert abs(out[0] - ref) <= math.pi + 1e-9
    np.testing.assert_allclose(np.diff(out), np.diff(seq), atol=1e-9)
    shift = out[0] - seq[0]
    assert abs(shift / TWO_PI - round(shift / TWO_PI)) < 1e-9


# --------------------------------------------------------------------------------------
# path fixtures
# --------------------------------------------------------------------------------------
def s_curve_path():
    """Open smooth S-curve (min radius ~ 2 m)."""
    t = np.linspace(0.0, 1.0, 30)
    pts = np.column_stack([12.0 * t, 1.5 * np.sin(2 * math.pi * t)])
    return WaypointPath(pts)


def closed_wavy_path():
    """Closed, non-circular loop."""
    th = np.linspace(0.0, TWO_PI, 50, endpoint=False)
    r = 4.0 + 0.5 * np.cos(3 * th)
    return WaypointPath(np.column_stack([r * np.cos(th), r * np.sin(th)]), closed=True)


def hairpin_path(gap=0.5, leg=5.0):
    """Leg 1 along +x at y=0, a half circle of diameter ``gap``, leg 2 back along -x at y=gap."""
    xs = np.arange(0.0, leg + 1e-9, 0.25)
    leg1 = np.column_stack([xs, np.zeros_like(xs)])
    r = gap / 2
    a = np.linspace(-math.pi / 2, math.pi / 2, 15)[1:-1]
    arc = np.column_stack([leg + r * np.cos(a), r + r * np.sin(a)])
    leg2 = np.column_stack([xs[::-1], np.full_like(xs, gap)])
    return WaypointPath(np.vstack([leg1, arc, leg2]))


S_CURVE = s_curve_path()
WAVY = closed_wavy_path()
HAIRPIN = hairpin_path()


def min_radius(path):
    s = np.linspace(0.0, path.length_m, 4000)
    return 1.0 / max(np.abs(path.curvature(s)).max(), 1e-9)


# --------------------------------------------------------------------------------------
# projection round trips
# --------------------------------------------------------------------------------------
@SETTINGS
@given(
    st.tuples(st.floats(-20, 20, **finite), st.floats(-20, 20, **finite)),
    st.floats(-math.pi, math.pi, **finite),
    st.floats(0.5, 30, **finite),
    st.floats(-1.0, 2.0, **finite),
    st.floats(-5.0, 5.0, **finite),
    st.floats(-1.0, 1.0, **finite),
)
def test_straight_round_trip(start, ang, L, frac, e_y, dguess):
    start = np.array(start)
    end = start + L * np.array([math.cos(ang), math.sin(ang)])
    p = StraightPath(start, end)
    assert p.length_m == pytest.approx(L, rel=1e-12)
    s = frac * L  # includes the extension before the start and beyond the end
    # the same direction: -pi and +pi are one heading
    assert abs(math.remainder(float(p.heading(s)) - ang, 2 * math.pi)) <= 1e-12
    assert p.curvature(s) == 0.0
    xy = offset_point(p, s, e_y)
    for guess in (None, s + dguess):
        s_hat, ey_hat = p.project(xy, s_guess=guess)
        assert s_hat == pytest.approx(s, abs=1e-9 * (1 + abs(s) + np.abs(start).max()))
        assert ey_hat == pytest.approx(e_y, abs=1e-9 * (1 + abs(s) + np.abs(start).max()))
    # frenet: heading error of a pose
    fr = p.frenet(np.r_[xy, ang + 0.3], s_guess=s)
    assert fr.e_psi_rad == pytest.approx(0.3, abs=1e-9)


@SETTINGS
@given(
    st.tuples(st.floats(-20, 20, **finite), st.floats(-20, 20, **finite)),
    st.floats(0.3, 20.0, **finite),
    st.booleans(),
    st.floats(-math.pi, math.pi, **finite),
    st.floats(0.0, 0.999, **finite),
    st.floats(-0.49, 0.49, **finite),
    st.floats(-0.3, 0.3, **finite),
)
def test_circle_round_trip(center, r, ccw, start_angle, frac, ey_frac, dguess):
    p = CirclePath(center=center, radius_m=r, ccw=ccw, start_angle_rad=start_angle)
    assert p.length_m == pytest.approx(TWO_PI * r)
    s = frac * p.length_m
    e_y = ey_frac * r
    # the geometry: on the circle, heading tangent, curvature sign
    pos = p.position(s)
    assert np.hypot(*(pos - np.asarray(center))) == pytest.approx(r, rel=1e-12)
    assert p.curvature(s) == pytest.approx((1 if ccw else -1) / r)
    h = float(p.heading(s))
    ds = 1e-6 * r
    fd_dir = (p.position(s + ds) - p.position(s - ds)) / (2 * ds)
    np.testing.assert_allclose(fd_dir, [math.cos(h), math.sin(h)], atol=1e-6)
    # left normal points to the centre for a left turn
    n_dir = np.dot(left_normal(h), np.asarray(center) - pos)
    assert (n_dir > 0) == ccw
    xy = offset_point(p, s, e_y)
    s_hat, ey_hat = p.project(xy, s_guess=s + dguess * r)
    tol = 1e-9 * (1 + r + np.abs(center).max())
    assert s_hat == pytest.approx(s, abs=tol)
    assert ey_hat == pytest.approx(e_y, abs=tol)
    # without a guess the answer is the same point modulo the length
    s0, ey0 = p.project(xy)
    assert ey0 == pytest.approx(e_y, abs=tol)
    d = (s0 - s) / p.length_m
    assert abs(d - round(d)) < 1e-9
    assert 0.0 <= s0 < p.length_m + tol


@pytest.mark.parametrize("path", [S_CURVE, WAVY, HAIRPIN], ids=["s_curve", "wavy_closed", "hairpin"])
@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 1.0, **finite), st.floats(-1.0, 1.0, **finite), st.floats(-0.3, 0.3, **finite))
def test_waypoint_round_trip(path, frac, ey_frac, dguess):
    rmin = min_radius(path)
    lim = 0.45 * rmin
    if path is HAIRPIN:
        lim = min(lim, 0.2)  # stay nearer to the own branch than to the other leg (0.5 m away)
    e_y = ey_frac * lim
    s = frac * path.length_m
    xy = offset_point(path, s, e_y)
    s_hat, ey_hat = path.project(xy, s_guess=s + dguess)
    assert s_hat == pytest.approx(s, abs=1e-3)
    assert ey_hat == pytest.approx(e_y, abs=1e-3)
    # projected point and pose agree with the geometry
    np.testing.assert_allclose(offset_point(path, s_hat, ey_hat), xy, atol=2e-3)


def test_waypoint_path_passes_through_waypoints():
    pts = np.array([[0.0, 0.0], [2.0, 0.5], [4.0, -0.5], [6.0, 1.0], [8.0, 0.0]])
    p = WaypointPath(pts)
    np.testing.assert_allclose(p.position(0.0), pts[0], atol=1e-9)
    np.testing.assert_allclose(p.position(p.length_m), pts[-1], atol=1e-6)
    for q in pts:
        s, e_y = p.project(q)
        assert abs(e_y) < 1e-4
    # length is at least the polyline (chord) length, and not much more for a gentle curve
    chord = np.hypot(*np.diff(pts, axis=0).T).sum()
    assert chord <= p.length_m < 1.2 * chord
    # arc-length parameterization: |d position / ds| = 1
    s = np.linspace(0.1, p.length_m - 0.1, 200)
    v = (p.position(s + 1e-3) - p.position(s - 1e-3)) / 2e-3
    np.testing.assert_allclose(np.hypot(*v.T), 1.0, atol=2e-3)


# --------------------------------------------------------------------------------------
# closed paths: laps
# --------------------------------------------------------------------------------------
WAVY_CW = WaypointPath(WAVY.waypoints[::-1], closed=True)  # the same loop driven clockwise
CLOSED = [
    CirclePath(center=(1.0, -2.0), radius_m=1.5),
    CirclePath(center=(0.0, 0.0), radius_m=3.0, ccw=False, start_angle_rad=1.0),
    WAVY,
    WAVY_CW,
]
CLOSED_IDS = ["circle_ccw", "circle_cw", "wavy", "wavy_cw"]


@pytest.mark.parametrize("path", CLOSED, ids=CLOSED_IDS)
@settings(max_examples=40, deadline=None)
@given(
    st.floats(0.0, 1.0, **finite), st.integers(-3, 5), st.floats(-0.2, 0.2, **finite), st.floats(-0.3, 0.3, **finite)
)
def test_closed_path_s_counts_laps(path, frac, k, ey, dguess):
    L = path.length_m
    s = frac * L
    xy = offset_point(path, s, ey)
    s_hat, ey_hat = path.project(xy, s_guess=s + k * L + dguess)
    tol = 1e-9 * (1 + abs(k) * L) if isinstance(path, CirclePath) else 1e-3
    assert s_hat == pytest.approx(s + k * L, abs=tol)
    assert ey_hat == pytest.approx(ey, abs=tol)
    # position is periodic, heading turns by one full turn per lap
    np.testing.assert_allclose(path.position(s + k * L), path.position(s), atol=1e-9 * (1 + abs(k) * L))
    turn = float(path.heading(s + L)) - float(path.heading(s))
    assert abs(abs(turn) - TWO_PI) < 1e-6
    assert float(path.heading(s + k * L)) == pytest.approx(float(path.heading(s)) + k * turn, abs=1e-6)


@pytest.mark.parametrize("path", CLOSED, ids=CLOSED_IDS)
@pytest.mark.parametrize("k", [-2, -1, 0, 1, 2, 7])
def test_closed_path_heading_continuous_across_lap_boundary(path, k):
    L = path.length_m
    eps = 1e-4
    for at in (k * L, k * L + 0.5 * L):
        jump = float(path.heading(at + eps)) - float(path.heading(at - eps))
        assert abs(jump) < 1e-2
        jump_pos = np.hypot(*(path.position(at + eps) - path.position(at - eps)))
        assert jump_pos == pytest.approx(2 * eps, rel=1e-2)
    # a dense sweep over two laps shows no jump at all
    s = np.linspace(k * L - 0.3 * L, k * L + 1.3 * L, 5001)
    h = path.heading(s)
    assert np.abs(np.diff(h)).max() < 0.05


@pytest.mark.parametrize("path", CLOSED, ids=CLOSED_IDS)
def test_closed_path_frenet_has_no_two_pi_error(path):
    L = path.length_m
    for k in (0, 1, 3):
        for frac in (0.0, 0.999, 0.5):
            s = frac * L + k * L
            pose = np.r_[path.position(s), float(path.heading(s)) + 0.1]
            fr = path.frenet(pose, s_guess=s)
            assert fr.e_psi_rad == pytest.approx(0.1, abs=1e-3)
            assert fr.s_m == pytest.approx(s, abs=1e-3)


# --------------------------------------------------------------------------------------
# self-approaching path (window search)
# --------------------------------------------------------------------------------------
def _leg2_s(path, x):
    """Arc length of the point (x, gap) on leg 2 of the hairpin, by global projection."""
    return path.project(np.array([x, 0.5]))[0]


@settings(max_examples=60, deadline=None)
@given(st.floats(0.5, 3.0, **finite), st.floats(-0.2, 0.45, **finite), st.floats(-0.3, 0.3, **finite))
def test_hairpin_window_search_stays_on_own_leg(x, y, dguess):
    p = HAIRPIN
    s_leg1 = x  # leg 1 starts at the origin along +x
    assert float(p.heading(s_leg1)) == pytest.approx(0.0, abs=1e-3)
    xy = np.array([x, y])
    s_hat, ey_hat = p.project(xy, s_guess=s_leg1 + dguess)
    assert s_hat == pytest.approx(s_leg1, abs=2e-3)
    assert ey_hat == pytest.approx(y, abs=2e-3)
    # a global projection returns the nearest leg: leg 2 once the point is closer to it
    s_glob, ey_glob = p.project(xy)
    if y < 0.24:
        assert s_glob == pytest.approx(s_leg1, abs=2e-3)
    elif y > 0.26:
        s2 = _leg2_s(p, x)
        assert s2 > p.length_m / 2
        assert s_glob == pytest.approx(s2, abs=2e-3)
        assert ey_glob == pytest.approx(0.5 - y, abs=2e-3)  # leg 2 runs along -x: left is -y
    # seen from leg 2 (guess on leg 2) the same point belongs to leg 2
    s2 = _leg2_s(p, x)
    s_hat2, ey_hat2 = p.project(xy, s_guess=s2 + dguess)
    assert s_hat2 == pytest.approx(s2, abs=2e-3)
    assert ey_hat2 == pytest.approx(0.5 - y, abs=2e-3)


def test_hairpin_geometry():
    p = HAIRPIN
    # leg 1 (5 m) + half circle of radius 0.25 + leg 2 (5 m)
    assert p.length_m == pytest.approx(10.0 + math.pi * 0.25, abs=0.02)
    assert float(p.heading(p.length_m)) == pytest.approx(math.pi, abs=1e-2)
    np.testing.assert_allclose(p.position(p.length_m), [0.0, 0.5], atol=1e-9)


# --------------------------------------------------------------------------------------
# sampled circle vs exact circle
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("repeat_first", [False, True])
def test_waypoint_circle_matches_circle_path(repeat_first):
    r = 1.5
    th = np.linspace(0.0, TWO_PI, 40, endpoint=False)
    pts = np.column_stack([r * np.cos(th), r * np.sin(th)])
    if repeat_first:
        pts = np.vstack([pts, pts[:1]])
    wp = WaypointPath(pts, closed=True)
    cp = CirclePath(center=(0.0, 0.0), radius_m=r, ccw=True, start_angle_rad=0.0)
    assert wp.closed
    assert wp.length_m == pytest.approx(cp.length_m, abs=1e-3)
    s = np.linspace(0.0, 3 * wp.length_m, 3001)
    np.testing.assert_allclose(wp.curvature(s), 1.0 / r, atol=1e-2)
    np.testing.assert_allclose(wp.position(s), cp.position(s), atol=2e-3)
    np.testing.assert_allclose(wp.heading(s), cp.heading(s), atol=2e-3)
    # projections agree too
    rng = np.random.default_rng(0)
    for _ in range(50):
        sq = rng.uniform(0, 2 * cp.length_m)
        xy = offset_point(cp, sq, rng.uniform(-0.6, 0.6))
        s1, e1 = wp.project(xy, s_guess=sq + 0.1)
        s2, e2 = cp.project(xy, s_guess=sq + 0.1)
        assert s1 == pytest.approx(s2, abs=3e-3)
        assert e1 == pytest.approx(e2, abs=1e-3)


# --------------------------------------------------------------------------------------
# open path extension beyond the ends
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "path", [S_CURVE, HAIRPIN, StraightPath((1.0, 1.0), (4.0, 5.0))], ids=["s_curve", "hairpin", "straight"]
)
@pytest.mark.parametrize("d", [0.05, 0.7, 3.0])
@pytest.mark.parametrize("e_y", [0.0, 0.1, -0.15])
def test_open_path_extension(path, d, e_y):
    L = path.length_m
    h0, h1 = float(path.heading(0.0)), float(path.heading(L))
    t0 = np.array([math.cos(h0), math.sin(h0)])
    t1 = np.array([math.cos(h1), math.sin(h1)])
    p_before = path.position(-d)
    p_after = path.position(L + d)
    np.testing.assert_allclose(p_before, path.position(0.0) - d * t0, atol=1e-9)
    np.testing.assert_allclose(p_after, path.position(L) + d * t1, atol=1e-9)
    assert float(path.heading(-d)) == pytest.approx(h0, abs=1e-9)
    assert float(path.heading(L + d)) == pytest.approx(h1, abs=1e-9)
    assert path.curvature(-d) == 0.0 and path.curvature(L + d) == 0.0
    # a waypoint path's projection extends its first/last table segment (a chord), its position
    # extends the spline's end tangent: they differ by ~kappa*ds/2 rad
    tol = 1e-9 if isinstance(path, StraightPath) else 1e-4
    for s in (-d, L + d):
        xy = offset_point(path, s, e_y)
        for guess in (s, s + 0.2, None):
            if path is HAIRPIN and guess is None and s < 0 and abs(e_y) > 0:
                continue  # leg 2's end is also near the start: a global search may pick it
            s_hat, ey_hat = path.project(xy, s_guess=guess)
            assert s_hat == pytest.approx(s, abs=tol)
            assert ey_hat == pytest.approx(e_y, abs=tol)
    assert path.project(offset_point(path, -d, e_y), s_guess=0.0)[0] < 0
    assert path.project(offset_point(path, L + d, e_y), s_guess=L)[0] > L


# --------------------------------------------------------------------------------------
# horizon references
# --------------------------------------------------------------------------------------
@SETTINGS
@given(
    st.floats(-10, 100, **finite), st.integers(1, 50), st.floats(0.001, 0.2, **finite), st.floats(0.001, 0.5, **finite)
)
def test_horizon_arc_lengths_paper(s0, N, dt, step):
    s = horizon_arc_lengths(s0, N, "paper", dt, speed_mps=123.0, step_m=step)
    assert s.shape == (N + 1,)
    assert s[0] == s0
    np.testing.assert_allclose(np.diff(s), step, rtol=1e-9, atol=1e-12)
    # the paper's scheme ignores the speed
    np.testing.assert_array_equal(s, horizon_arc_lengths(s0, N, "paper", dt, speed_mps=0.1, step_m=step))
    assert horizon_arc_lengths(s0, N, "paper", dt)[1] - s0 == pytest.approx(0.025)


@SETTINGS
@given(st.floats(-10, 100, **finite), st.integers(1, 50), st.floats(0.001, 0.2, **finite), st.floats(-5, 5, **finite))
def test_horizon_arc_lengths_arc_length(s0, N, dt, v):
    s = horizon_arc_lengths(s0, N, "arc_length", dt, speed_mps=v)
    assert s.shape == (N + 1,)
    assert s[0] == s0
    np.testing.assert_allclose(np.diff(s), abs(v) * dt, rtol=1e-9, atol=1e-12)
    rng = np.random.default_rng(N)
    vs = rng.uniform(0, 3, N)
    s2 = horizon_arc_lengths(s0, N, "arc_length", dt, speed_mps=vs)
    np.testing.assert_allclose(np.diff(s2), vs * dt, rtol=1e-9, atol=1e-12)
    assert np.all(np.diff(s2) >= 0)


@pytest.mark.parametrize("mode", ["Paper", "arc", "time", ""])
def test_horizon_arc_lengths_bad_mode(mode):
    with pytest.raises(ValueError):
        horizon_arc_lengths(0.0, 10, mode, 0.05)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 1.0, **finite), st.integers(-4, 4), st.floats(-3.0, 3.0, **finite), st.booleans())
def test_horizon_states_heading_near_yaw(frac, k, dyaw, ccw):
    p = CirclePath(center=(0.5, 0.5), radius_m=1.5, ccw=ccw)
    s0 = frac * p.length_m + 2 * p.length_m  # somewhere on the third lap
    yaw = float(p.heading(s0)) + k * TWO_PI + dyaw
    s = horizon_arc_lengths(s0, 20, "arc_length", 0.05, speed_mps=1.0)
    ref = horizon_states(p, s, yaw)
    assert ref.shape == (21, 4)
    np.testing.assert_allclose(ref[:, :2], p.position(s), atol=1e-12)
    np.testing.assert_allclose(ref[:, 3], p.curvature(s), atol=1e-12)
    assert abs(ref[0, 2] - yaw) <= math.pi + 1e-9
    # same heading as the path up to one multiple of 2 pi, continuous
    shift = (ref[:, 2] - p.heading(s)) / TWO_PI
    np.testing.assert_allclose(shift, np.round(shift[0]), atol=1e-9)
    np.testing.assert_allclose(np.diff(ref[:, 2]), np.diff(s) * p.curvature(s[1:]), atol=1e-9)
    assert np.round(shift[0]) == k


def test_horizon_states_yaw_four_pi():
    p = CirclePath(center=(0.0, 0.0), radius_m=1.5)
    s0 = 0.75 * p.length_m  # heading(s0) = 2 pi
    ref = horizon_states(p, horizon_arc_lengths(s0, 30, "paper", 0.05, step_m=0.05), 4 * math.pi + 0.05)
    assert ref[0, 2] == pytest.approx(4 * math.pi, abs=1e-12)
    assert np.all(np.abs(ref[:, 2] - 4 * math.pi) < 1.1)
    assert np.all(np.diff(ref[:, 2]) > 0)
    np.testing.assert_allclose(np.diff(ref[:, 2]), 0.05 / 1.5, atol=1e-12)


def test_horizon_states_across_lap_on_waypoint_path():
    p = WAVY
    s0 = p.length_m - 0.3
    s = horizon_arc_lengths(s0, 40, "paper", 0.05, step_m=0.025)
    yaw = float(p.heading(s0)) - 6 * math.pi + 0.2
    ref = horizon_states(p, s, yaw)
    assert abs(ref[0, 2] - yaw) <= math.pi
    assert np.abs(np.diff(ref[:, 2])).max() < 0.05
    np.testing.assert_allclose(ref[:, :2], p.position(s), atol=1e-12)


def test_horizon_states_straight():
    p = StraightPath((0.0, 0.0), (0.0, 10.0))  # heading pi/2
    s = horizon_arc_lengths(1.0, 5, "paper", 0.1, step_m=0.5)
    ref = horizon_states(p, s, -3 * math.pi / 2 - 0.2)
    np.testing.assert_allclose(ref[:, 2], -3 * math.pi / 2, atol=1e-12)
    np.testing.assert_allclose(ref[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(ref[:, 1], s, atol=1e-12)
    np.testing.assert_array_equal(ref[:, 3], 0.0)


# --------------------------------------------------------------------------------------
# bad inputs
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "points,closed",
    [
        ([[0.0, 0.0]], False),
        ([[1.0, 1.0], [1.0, 1.0]], False),
        ([[0.0, 0.0], [1.0, 0.0]], True),
        ([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]], True),
        ([[0.0, 0.0], [float("nan"), 1.0], [2.0, 0.0]], False),
        ([[0.0, 0.0], [1.0, float("inf")], [2.0, 0.0]], False),
        ([0.0, 1.0, 2.0], False),
        (np.zeros((3, 3)), False),
        (np.zeros((0, 2)), False),
    ],
)
def test_waypoint_path_bad_points(points, closed):
    with pytest.raises(ValueError):
        WaypointPath(points, closed=closed)


def test_waypoint_path_bad_smoothing():
    pts = [[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]]
    with pytest.raises(ValueError):
        WaypointPath(pts, smoothing=-1.0)
    with pytest.raises(ValueError):
        WaypointPath(pts, smoothing=float("nan"))


def test_two_point_waypoint_path_is_a_segment():
    p = WaypointPath([[0.0, 0.0], [3.0, 4.0]])
    assert p.length_m == pytest.approx(5.0, abs=1e-9)
    np.testing.assert_allclose(p.position(2.5), [1.5, 2.0], atol=1e-9)
    s, e_y = p.project(np.array([1.5 - 0.8, 2.0 + 0.6]))
    assert s == pytest.approx(2.5, abs=1e-9) and e_y == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize(
    "start,end", [((0.0, 0.0), (0.0, 0.0)), ((1.0, 2.0), (1.0, 2.0)), ((0.0, float("nan")), (1.0, 1.0))]
)
def test_straight_path_bad(start, end):
    with pytest.raises(ValueError):
        StraightPath(start, end)


@pytest.mark.parametrize("r", [-1.0, 0.0, float("nan"), float("inf")])
def test_circle_path_bad_radius(r):
    with pytest.raises(ValueError):
        CirclePath(radius_m=r)


@pytest.mark.parametrize("xy", [[float("nan"), 0.0], [0.0, float("inf")], [1.0, 2.0, 3.0], [1.0]])
@pytest.mark.parametrize(
    "path", [StraightPath((0, 0), (1, 0)), CirclePath(), S_CURVE], ids=["straight", "circle", "wp"]
)
def test_project_rejects_bad_points(path, xy):
    with pytest.raises(ValueError):
        path.project(np.array(xy))


def test_polyline():
    for p in (S_CURVE, WAVY, CirclePath(radius_m=2.0)):
        pl = p.polyline()
        assert pl.ndim == 2 and pl.shape[1] == 2 and len(pl) >= 2
        np.testing.assert_allclose(pl[0], p.position(0.0), atol=1e-9)
        np.testing.assert_allclose(pl[-1], p.position(p.length_m), atol=1e-9)


#: one path of each kind for the multi-point projections
PROJECTION_PATHS = [
    StraightPath([1.0, -2.0], [9.0, 4.0]),
    CirclePath(center=(1.0, 2.0), radius_m=3.0, ccw=False, start_angle_rad=0.4),
    WaypointPath(np.array([[0.0, 0.0], [4.0, 1.0], [8.0, -1.0], [12.0, 2.0], [16.0, 0.0]])),
    WaypointPath(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]), closed=True),
]
PROJECTION_IDS = ["straight", "circle", "waypoints", "closed-waypoints"]


@pytest.mark.parametrize("path", PROJECTION_PATHS, ids=PROJECTION_IDS)
def test_project_many_is_project_point_by_point(path):
    rng = np.random.default_rng(3)
    s_guess = rng.uniform(-0.5 * path.length_m, 2.5 * path.length_m, 40)
    xy = path.position(s_guess) + rng.normal(0.0, 1.5, (40, 2))
    window = rng.uniform(0.5, 1.5 * path.length_m, 40)
    s, e = path.project_many(xy, s_guess, window)
    want = np.array([path.project(p, g, w) for p, g, w in zip(xy, s_guess, window)])
    np.testing.assert_allclose(s, want[:, 0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(e, want[:, 1], rtol=0, atol=1e-9)
    # the generic per-point projection gives the same
    s2, e2 = ReferencePath._project_many_xy(path, xy, s_guess, window)
    np.testing.assert_array_equal(s2, want[:, 0])
    np.testing.assert_array_equal(e2, want[:, 1])
    with pytest.raises(ValueError):
        path.project_many(np.array([[np.nan, 0.0]]), [0.0], [1.0])


def _nearest_on_table(path, xy):
    """Oracle for the waypoint projection, written independently of paths.compiled: the
    nearest point of every segment of the path's arc-length table (an open path's end segments
    extended along their tangents), as (s, e_y) with e_y positive to the left."""
    p0, p1 = path._xy[:-1], path._xy[1:]
    d = p1 - p0
    length = np.linalg.norm(d, axis=1)
    t = np.einsum("ij,ij->i", xy - p0, d) / length**2
    lo = np.zeros_like(t)
    hi = np.ones_like(t)
    if not path.closed:
        lo[0], hi[-1] = -np.inf, np.inf
    t = np.clip(t, lo, hi)
    foot = p0 + t[:, None] * d
    j = int(np.argmin(np.linalg.norm(xy - foot, axis=1)))
    r = xy - foot[j]
    tangent = d[j] / length[j]
    return path._s[j] + t[j] * length[j], float(tangent[0] * r[1] - tangent[1] * r[0])


@pytest.mark.parametrize("closed", [False, True], ids=["open", "closed"])
def test_waypoint_projection_is_the_nearest_table_point(closed):
    """Open and closed waypoint paths: project (without a guess, and near a guess on the right
    lap) finds the nearest point of the table polyline, and project_many agrees point by point."""
    pts = np.array([[0.0, 0.0], [6.0, 1.0], [12.0, -2.0], [18.0, 3.0], [24.0, 0.0]])
    if closed:
        th = np.linspace(0.0, 2.0 * np.pi, 9)[:-1]
        pts = np.c_[20.0 * np.cos(th), 12.0 * np.sin(th)]
    path = WaypointPath(pts, closed=closed)
    rng = np.random.default_rng(11)
    L = path.length_m
    s_true = rng.uniform(-3.0 if not closed else 0.0, L + (3.0 if not closed else 0.0), 300)
    xy = path.position(s_true) + rng.normal(0.0, 0.4, (300, 2))
    got, guess = [], []
    for p, s in zip(xy, s_true):
        s_o, e_o = _nearest_on_table(path, p)
        s_n, e_n = path.project(p)
        assert (s_n, e_n) == pytest.approx((s_o, e_o), abs=1e-9)
        lap = 2 * L if closed else 0.0  # a guess two laps on: the same point, on the guess's lap
        s_g, e_g = path.project(p, s + lap, 3.0)
        if closed:
            s_o += L * round((s + lap - s_o) / L)
        assert (s_g, e_g) == pytest.approx((s_o, e_o), abs=1e-9)
        got.append((s_g, e_g))
        guess.append(s + lap)
    s_m, e_m = path.project_many(xy, np.array(guess), np.full(len(xy), 3.0))
    np.testing.assert_array_equal(np.c_[s_m, e_m], np.array(got))


@pytest.mark.parametrize("closed", [False, True], ids=["open", "closed"])
def test_waypoint_projection_steps_over_far_segments_exactly(closed):
    """A long winding path (about 4,000 table segments) and points up to 60 m off it, searched
    in windows of 1 m to the whole path: the projection, which steps over segments it can prove
    farther, finds the nearest point of the segments in the window (the oracle's full scan;
    where two segments meet at the nearest point, either)."""
    t = np.linspace(0.0, 2.0 * np.pi, 60)[: -1 if closed else None]
    pts = np.c_[(120.0 + 25.0 * np.sin(5.0 * t)) * np.cos(t), (80.0 + 25.0 * np.sin(5.0 * t)) * np.sin(t)]
    path = WaypointPath(pts, closed=closed, ds_m=0.2)
    rng = np.random.default_rng(5)
    L, ds, m = path.length_m, path._ds, len(path._s) - 1
    far = 0
    for _ in range(300):
        s_guess = float(rng.uniform(0.0, L))
        window = float(np.exp(rng.uniform(0.0, np.log(L))))
        p = path.position(float(rng.uniform(0.0, L))) + rng.normal(0.0, 20.0, 2)
        s_n, e_n = path.project(p, s_guess, window)
        # the oracle: every segment of the window (as the kernel picks them), each end of an
        # open path extended along its tangent
        i0, i1 = int(np.floor((s_guess - window) / ds)), int(np.ceil((s_guess + window) / ds))
        if 2.0 * window >= L:
            i0, i1 = 0, m - 1
        elif not closed:
            i0, i1 = min(max(i0, 0), m - 1), min(max(i1, 0), m - 1)
        ii = np.arange(i0, i1 + 1)
        j = ii % m if closed else ii
        p0, d = path._xy[j], path._xy[j + 1] - path._xy[j]
        tt = np.einsum("ij,ij->i", p - p0, d) / np.einsum("ij,ij->i", d, d)
        lo, hi = np.zeros_like(tt), np.ones_like(tt)
        if not closed:
            lo[j == 0], hi[j == m - 1] = -np.inf, np.inf
        tt = np.clip(tt, lo, hi)
        r = p - p0 - tt[:, None] * d
        dist = np.hypot(r[:, 0], r[:, 1])
        ln = np.hypot(d[:, 0], d[:, 1])
        near = np.flatnonzero(dist <= dist.min() + 1e-9)
        s_o = path._s[j[near]] + tt[near] * ln[near]
        e_o = (d[near, 0] * r[near, 1] - d[near, 1] * r[near, 0]) / ln[near]
        ds_o = s_o - s_n
        if closed:  # the lap is another test's business
            ds_o = (ds_o + 0.5 * L) % L - 0.5 * L
        assert np.any((np.abs(ds_o) <= 1e-9) & (np.abs(e_o - e_n) <= 1e-9)), (s_n, e_n, s_o, e_o)
        far += dist.min() > 10.0
    assert far > 100  # most points far from the path: most segments are stepped over


@pytest.mark.parametrize("path", PROJECTION_PATHS, ids=PROJECTION_IDS)
def test_project_track_chains_each_point_to_the_one_before(path):
    """project_track equals the generic per-point chain (each point searched near the previous
    one's s within their distance plus the margin), over more than one lap on closed paths."""
    L = path.length_m
    s_true = np.linspace(0.2 * L, 2.6 * L if path.closed else 0.9 * L, 60)
    rng = np.random.default_rng(5)
    xy = path.position(s_true) + rng.normal(0.0, 0.05, (60, 2))
    s, e = path.project_track(xy, float(s_true[0]), 0.5)
    s2, e2 = ReferencePath._project_track_xy(path, xy, float(s_true[0]), 0.5, 2.0)
    np.testing.assert_allclose(s, s2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(e, e2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s, s_true, atol=0.2)  # on the right lap all along
    assert path.project_track(np.zeros((0, 2)), 0.0, 1.0)[0].shape == (0,)
    with pytest.raises(ValueError):
        path.project_track(np.array([[np.nan, 0.0]]), 0.0, 1.0)
    with pytest.raises(ValueError):
        path.project_track(xy, 0.0, 1.0, step_margin_m=0.0)


def test_project_track_keeps_a_track_on_its_branch_of_a_hairpin():
    """A car driving out along the first leg of a hairpin whose legs are 3 m apart: one wide
    window (project_many) puts its later positions on the nearer return leg once they are nearer
    to it; the track stays on the leg it is driving."""
    pts = np.array([[0.0, 0.0], [30.0, 0.0], [33.0, 1.5], [30.0, 3.0], [0.0, 3.0]])
    path = WaypointPath(pts, interpolation="pchip")
    xy = np.c_[np.linspace(2.0, 25.0, 24), np.full(24, 1.6)]  # just past the middle, on leg one's side
    xy[0, 1] = 0.5  # starts clearly on leg one
    s, e = path.project_track(xy, 2.0, 1.0)
    np.testing.assert_allclose(s, xy[:, 0], atol=1e-6)  # leg one, moving on
    np.testing.assert_allclose(e, xy[:, 1], atol=1e-6)
    s_wide, _ = path.project_many(xy, np.full(24, 2.0), np.full(24, 1e3))
    assert np.all(s_wide[1:] > 40.0)  # the wide search puts them on the return leg
