"""The lane decision layer: which lane, which action, and the lateral reference to get there."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcdrive.control.lanes import LaneConfig, LaneDecision, LateralRamp, _tracks, decide_lane, lane_of
from mpcdrive.ocp.avoidance_compiled import obstacle_table
from mpcdrive.paths import CirclePath
from mpcdrive.paths.compiled import path_arrays
from mpcdrive.paths.straight import StraightPath
from mpcdrive.paths.waypoints import WaypointPath
from mpcdrive.scene.obstacles import ConstantVelocity, Obstacle, Static, TrajectoryMotion, rectangle
from mpcdrive.scene.road import Lane, Road
from shapes import random_shape

W = 4.0  # lane width [m]
PATH = StraightPath((0.0, 0.0), (5000.0, 0.0))  # the route lane's centre, along +x
CFG = LaneConfig(desired_speed_mps=30.0)


def road(n_lanes: int = 3, route: int = 0) -> Road:
    """Lanes 0, 1, 2 ... centred at 0, +4, +8 m (left of the path), the route lane ``route``."""
    s = np.array([0.0, 5000.0])
    lanes = tuple(
        Lane(f"lane-{i}", np.full(2, i * W), np.full(2, i * W + W / 2), np.full(2, i * W - W / 2))
        for i in range(n_lanes)
    )
    return Road(s, (n_lanes - 0.5) * W, -W / 2, lanes=lanes, route_lane=route)


def car(x: float, lane: int, speed: float, **kw) -> Obstacle:
    """A 5 m x 2 m car at ``x`` [m] at t = 0, centred in ``lane``, driving ``speed`` [m/s] along +x."""
    return Obstacle(rectangle(5.0, 2.0), (x, lane * W, 0.0), ConstantVelocity(speed, 0.0), **kw)


def _same_decision(a: LaneDecision, b: LaneDecision):
    for f in ("lane", "current", "action", "free", "band", "called_back", "origin", "speed_cap_mps"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("free_m", "band_m", "stop_m", "since_s", "gap_m"):
        assert getattr(a, f) == pytest.approx(getattr(b, f), abs=1e-9), f
    for f in ("s0_m", "s1_m", "e0_m"):
        assert getattr(a.ramp, f) == pytest.approx(getattr(b.ramp, f), abs=1e-9), f


def decide(obstacles, *, x=100.0, e_y=0.0, v=30.0, t=0.0, previous=None, rd=None, cfg=CFG) -> LaneDecision:
    """The decision with the obstacles tracked in numpy, checked against the compiled tracks'."""
    d = decide_lane(rd or road(), PATH, x, e_y, v, obstacles, t, previous, cfg)
    compiled = (obstacle_table(obstacles), path_arrays(PATH))
    _same_decision(decide_lane(rd or road(), PATH, x, e_y, v, obstacles, t, previous, cfg, compiled=compiled), d)
    return d


def test_free_road_keeps_the_route_lane_and_reports_every_lane_free():
    d = decide([])
    assert (d.lane, d.current, d.action) == (0, 0, "keep")
    assert all(d.free) and len(set(d.free_m)) == 1 and d.free_m[0] > 30.0 * CFG.horizon_s
    assert d.band == (0,) and d.band_m == (-2.0, 2.0) and d.stop_m is None
    assert d.ramp.offset(1e4) == 0.0


def test_slow_car_ahead_and_free_neighbour_changes_to_it():
    d = decide([car(160.0, 0, 20.0)])  # 60 m ahead, 10 m/s slower: reached within the horizon
    assert d.action == "change" and d.lane == 1 and d.current == 0
    assert not d.free[0] and d.free[1]
    assert d.free_m[0] < 30.0 and d.free_m[1] > d.free_m[0] + CFG.min_gain_m
    assert d.band == (0, 1) and d.band_m == (-2.0, 6.0)  # the body may use both lanes now
    # the ramp: from the ego's offset to the target's centre, smooth, lateral accel within bounds
    r = d.ramp
    assert r.offset(100.0) == 0.0 and r.offset(r.s1_m) == pytest.approx(W) and r.offset(1e4) == pytest.approx(W)
    s = np.linspace(r.s0_m, r.s1_m, 2001)
    e = r.offset(s)
    assert np.all(np.diff(e) >= 0)
    acc = np.gradient(np.gradient(e, s), s) * 30.0**2  # d2e/dt2 at 30 m/s
    assert np.abs(acc).max() <= CFG.max_lat_accel_mps2 * 1.01
    assert np.gradient(e, s)[[0, -1]] == pytest.approx([0.0, 0.0], abs=1e-3)


def test_static_obstacle_ahead_changes_lane_too():
    ob = Obstacle(rectangle(4.0, 2.0), (250.0, 0.0, 0.0), Static())
    d = decide([ob])
    assert d.action == "change" and d.lane == 1


def test_both_lanes_blocked_stops_with_the_stop_distance():
    obs = [Obstacle(rectangle(4.0, 2.0), (150.0, 0.0, 0.0)), Obstacle(rectangle(4.0, 2.0), (150.0, W, 0.0))]
    d = decide(obs, rd=road(2))
    assert d.action == "stop" and d.lane == 0 and not any(d.free)
    # 50 m centre to centre, 2 + 2.5 m of bodies, 8 m kept before it
    assert d.stop_m == pytest.approx(50.0 - 4.5 - CFG.standstill_m)
    assert d.free_m[0] < 0.0 and d.free_m[1] < 0.0  # the ego would run into both at 30 m/s


def test_car_from_behind_in_own_lane_is_ignored():
    d = decide([car(60.0, 0, 38.0)])  # 40 m behind, closing at 8 m/s
    assert (d.lane, d.action) == (0, "keep") and d.free[0]


def test_fast_car_from_behind_in_the_neighbour_lane_prevents_the_change():
    slow = car(160.0, 0, 20.0)
    assert decide([slow]).lane == 1  # without it the ego changes
    fast = car(40.0, 1, 40.0)  # 60 m behind, 10 m/s faster: alongside within the horizon
    d = decide([slow, fast], rd=road(2))
    assert d.action == "stop" and d.lane == 0 and not d.free[1]
    # the same car far enough behind and not faster leaves the lane free
    assert decide([slow, car(20.0, 1, 28.0)], rd=road(2)).lane == 1


def test_the_better_of_two_free_neighbours_wins():
    rd = Road(
        np.array([0.0, 5000.0]),
        1.5 * W + W,
        -1.5 * W,
        lanes=tuple(
            Lane(str(i), np.full(2, c), np.full(2, c + W / 2), np.full(2, c - W / 2))
            for i, c in enumerate((-W, 0.0, W))
        ),
        route_lane=1,
    )
    obs = [car(160.0, 0, 20.0), car(230.0, -1, 25.0)]  # ego's lane blocked; right lane less free
    d = decide(obs, rd=rd)
    assert d.action == "change" and d.lane == 2 and d.free_m[2] > d.free_m[0]


def test_lifetimes_count():
    gone = car(160.0, 0, 20.0, t_end_s=-1.0)  # left the scene before now
    assert decide([gone]).action == "keep"
    later = car(160.0, 0, 20.0, t_start_s=20.0)  # appears after the horizon
    assert decide([later]).action == "keep"


def test_a_change_is_held_until_the_ego_arrives_then_kept():
    obs = [car(160.0, 0, 20.0)]
    d = decide(obs)
    assert d.lane == 1
    d2 = decide(obs, x=110.0, e_y=1.0, t=0.2, previous=d)  # under way
    assert d2.action == "change" and d2.lane == 1 and d2.ramp is d.ramp and d2.since_s == 0.0
    d3 = decide(obs, x=200.0, e_y=W - 0.1, t=3.5, previous=d2)  # arrived
    assert d3.action == "keep" and d3.lane == 1 and d3.current == 1 and d3.band == (1,)


def test_a_change_whose_target_closes_returns_to_the_origin_lane():
    slow = car(160.0, 0, 20.0)
    d = decide([slow], rd=road(2))
    assert d.lane == 1
    fast = car(50.0, 1, 45.0)  # appears in the target lane, closing fast
    d2 = decide([slow, fast], x=106.0, e_y=0.5, t=0.2, previous=d, rd=road(2))
    assert d2.action == "change" and d2.lane == 0 and d2.ramp is not d.ramp
    assert d2.ramp.offset(106.0) == pytest.approx(0.5) and d2.ramp.offset(1e4) == 0.0
    # called back with the body across the line (centre 0.3 m into the target lane): the body
    # may still use both lanes, not only the one it is now mostly in
    d3 = decide([slow, fast], x=106.0, e_y=W / 2 + 0.3, t=0.2, previous=d, rd=road(2))
    assert d3.action == "change" and d3.lane == d3.current == 1
    assert d3.band == (0, 1) and d3.band_m == (-2.0, 6.0)


def test_a_called_back_change_is_driven_home_not_called_back_again():
    """The return of a called-back change is not called back in turn when the body's centre
    swings over the line with the origin lane still blocked ahead: no flip-flop between lanes."""
    slow = car(160.0, 0, 20.0)
    d = decide([slow], rd=road(2))
    fast = car(50.0, 1, 45.0)
    back = decide([slow, fast], x=106.0, e_y=0.5, t=0.2, previous=d, rd=road(2))
    assert (back.action, back.lane, back.called_back) == ("change", 0, True) and not back.free[0]
    # the centre swung 0.2 m over the line into lane 1: the return goes on to lane 0
    on = decide([slow, fast], x=112.0, e_y=W / 2 + 0.2, t=0.4, previous=back, rd=road(2))
    assert (on.action, on.lane, on.current, on.called_back) == ("change", 0, 1, True)
    assert on.ramp is back.ramp and on.band == (0, 1)
    home = decide([slow, fast], x=118.0, e_y=0.05, t=0.6, previous=on, rd=road(2))
    assert home.lane == 0 and home.action != "change" and not home.called_back


def test_hysteresis_alternating_marginal_gains_do_not_flip_every_step():
    """Each step the other lane is 20 m freer than the ego's (min_gain_m = 15) and the ego's is
    blocked: without the dwell time the ego would flip lanes at every step."""
    rd = road(2, route=0)
    e_y, prev, times = 0.0, None, []
    for k in range(60):  # 6 s at 0.1 s
        t, x = 0.1 * k, 100.0 + 30.0 * 0.1 * k
        cur = lane_of(rd, x, e_y)
        # cars at 30 m/s, 55 m ahead in the ego's lane and 75 m ahead in the other one, now
        obs = [car(x + 55.0 - 30.0 * t, cur, 30.0), car(x + 75.0 - 30.0 * t, 1 - cur, 30.0)]
        d = decide(obs, x=x, e_y=e_y, t=t, previous=prev, rd=rd)
        if prev is None or d.lane != prev.lane:
            times.append(t)
        prev = d
        e_y = rd.lanes[d.lane].center_m[0]  # the ego gets there at once
    assert times[0] == 0.0 and 2 <= len(times) <= 1 + 6.0 / CFG.min_dwell_s
    assert np.all(np.diff(times) >= CFG.min_dwell_s - 1e-9)


def test_a_change_needs_min_gain_more_free_distance():
    """Own lane blocked (50 m free, 53 m needed), the neighbour free: 10 m more is not enough
    (min_gain_m = 15), 20 m more is."""
    rd = road(2)
    own = car(155.0, 0, 30.0)  # same speed: the gap stays 50 m
    small = decide([own, car(165.0, 1, 30.0)], rd=rd)
    assert small.free == (False, True) and small.free_m == pytest.approx((50.0, 60.0))
    assert (small.action, small.lane) == ("keep", 0)
    assert decide([own, car(175.0, 1, 30.0)], rd=rd).lane == 1


def test_returns_to_the_route_lane_after_passing():
    rd = road(2, route=0)
    slow = car(160.0, 0, 20.0)
    d = decide([slow], rd=rd)
    assert d.lane == 1
    # alongside the slow car in lane 1: lane 0 is not free (the car is next to the ego)
    t = 6.0
    x = 160.0 + 20.0 * t + 2.0
    d = decide([slow], x=x, e_y=W, t=t, previous=d, rd=rd)
    assert d.current == 1 and d.action == "keep" and d.lane == 1 and not d.free[0]
    # well past it (and after the dwell): back to the route lane
    t = 12.0
    x = 160.0 + 20.0 * t + 60.0
    d = decide([slow], x=x, e_y=W, t=t, previous=d, rd=rd)
    assert d.action == "change" and d.lane == 0 and d.free[0]
    assert d.ramp.offset(x) == pytest.approx(W) and d.ramp.offset(x + 1e3) == 0.0


def test_lane_of_and_config_checks():
    rd = road()
    assert [lane_of(rd, 0.0, e) for e in (-1.9, 0.0, 2.1, 5.0, 9.0, 30.0, -9.0)] == [0, 0, 1, 1, 2, 2, 0]
    with pytest.raises(ValueError, match="horizon_s"):
        LaneConfig(horizon_s=0.0)
    with pytest.raises(ValueError, match="min_dwell_s"):
        LaneConfig(min_dwell_s=-1.0)
    with pytest.raises(ValueError, match="no lanes"):
        decide_lane(Road.constant(4.0), PATH, 0.0, 0.0, 10.0, [], 0.0)
    r = LateralRamp(0.0, 100.0, 1.0, np.array([0.0, 1.0]), np.array([3.0, 3.0]))
    assert r.offset(-5.0) == 1.0 and r.offset(50.0) == pytest.approx(2.0) and not math.isnan(r.offset(1e9))


def test_ramps_are_gentle_at_low_speed_and_a_stopped_car_looks_as_far_as_it_wants_to_drive():
    """At 0.5 m/s behind a parked car 12 m ahead the ramp to the free lane is no steeper than
    max_slope (25 m for 4 m), and with the MPC's reference speed (9 m/s) as the desired speed the
    car looks far enough ahead to see the lane blocked and change; looking only as far as its
    own speed goes (0.5 m/s) it would not."""
    parked = [Obstacle(rectangle(4.0, 2.0), (100.0 + 2.5 + 12.0 + 2.0, 0.0, 0.0), Static())]
    cfg = LaneConfig()
    d = decide_lane(road(), PATH, 100.0, 0.0, 0.5, parked, 0.0, None, cfg, 9.0)
    assert d.action == "change" and d.lane == 1
    assert d.ramp.s1_m - d.ramp.s0_m == pytest.approx(15.0 / 8.0 * W / cfg.max_slope)
    assert decide_lane(road(), PATH, 100.0, 0.0, 0.5, parked, 0.0, None, cfg).action == "keep"  # not blocked
    # the first decision is no lane change: the dwell time does not hold the next one back
    keep = decide([])
    assert keep.since_s == -math.inf
    assert decide([car(160.0, 0, 20.0)], t=0.5, previous=keep).action == "change"


def test_a_route_lane_wider_than_the_lane_of_the_path_is_driven_along_the_path():
    """A route that moves over a lane: the route lane's table holds the path's lane and the one
    to its right (its middle W/2 right of the path), a neighbour lies to the left. The ramps run
    to the path in the route lane (to the table's middle, the controller was pulled W/2 off the
    path when it started), to the neighbour's centre out of it, and a return home ends on the path."""
    s = np.array([0.0, 5000.0])
    route = Lane("route", np.full(2, -W / 2), np.full(2, W / 2), np.full(2, -1.5 * W))
    left = Lane("left", np.full(2, W), np.full(2, 1.5 * W), np.full(2, W / 2))
    rd = Road(s, 1.5 * W, -1.5 * W, lanes=(route, left), route_lane=0)
    d = decide([], e_y=0.3, rd=rd)
    assert (d.action, d.lane) == ("keep", 0)
    assert d.ramp.offset(100.0) == pytest.approx(0.3) and d.ramp.offset(1e4) == 0.0
    out = decide([car(160.0, 0, 20.0)], rd=rd)  # blocked ahead: out to the neighbour's centre
    assert (out.action, out.lane) == ("change", 1) and out.ramp.offset(1e4) == pytest.approx(W)
    home = decide([], e_y=W, rd=rd)  # in the neighbour, the route lane free: home to the path
    assert (home.action, home.lane) == ("change", 0) and home.ramp.offset(1e4) == 0.0
    there = decide([], x=200.0, e_y=0.1, t=3.0, previous=home, rd=rd)
    assert (there.action, there.lane) == ("keep", 0)


def test_a_change_that_cannot_clear_a_close_obstacle_at_speed_is_capped_until_past_it():
    """A parked car 10 m ahead (bumper to bumper) at 9 m/s, the neighbour lane free: the ramp at
    that speed (26 m for 4 m) would still overlap the car when the ego reaches it, so the change
    has its references capped at ``turn_out_mps`` (the MPC brakes to it while easing out) until
    the ego is past the car; the same car 40 m ahead is passed at speed, no cap. Once past, in
    the target lane with the route lane clear, the change ends before the ego settles on the
    lane's centre, and the return starts."""
    cfg = LaneConfig()
    rd = road(2)
    parked = [Obstacle(rectangle(4.0, 2.0), (100.0 + 2.5 + 10.0 + 2.0, 0.0, 0.0), Static())]

    close = decide_lane(rd, PATH, 100.0, 0.0, 9.0, parked, 0.0, None, cfg, 9.0)
    assert (close.action, close.lane, close.origin) == ("change", 1, 0)
    assert close.speed_cap_mps == cfg.turn_out_mps and close.band == (0, 1) and close.gap_m == pytest.approx(10.0)
    # under way beside the parked car: still capped
    beside = decide_lane(rd, PATH, 112.0, 2.5, 2.0, parked, 3.0, close, cfg, 9.0)
    assert (beside.action, beside.lane, beside.origin, beside.speed_cap_mps) == ("change", 1, 0, cfg.turn_out_mps)
    # its centre behind the ego's: no cap; the change goes on while the body still overlaps it
    level = decide_lane(rd, PATH, 117.0, W - 1.2, 2.0, parked, 4.0, beside, cfg, 9.0)
    assert (level.action, level.lane, level.speed_cap_mps) == ("change", 1, None)
    # clear of it, 1.2 m short of the lane centre: the change is over, heading home
    past = decide_lane(rd, PATH, 122.0, W - 1.2, 2.0, parked, 5.0, level, cfg, 9.0)
    assert (past.action, past.lane, past.current, past.speed_cap_mps) == ("change", 0, 1, None)
    # far enough ahead for the ramp at 9 m/s: the change starts at speed, not capped
    far = [Obstacle(rectangle(4.0, 2.0), (100.0 + 2.5 + 40.0 + 2.0, 0.0, 0.0), Static())]
    d = decide_lane(rd, PATH, 100.0, 0.0, 9.0, far, 0.0, None, cfg, 9.0)
    assert (d.action, d.lane, d.speed_cap_mps) == ("change", 1, None)
    with pytest.raises(ValueError, match="turn_out_mps"):
        LaneConfig(turn_out_mps=0.0)
    with pytest.raises(ValueError, match="pass_margin_m"):
        LaneConfig(pass_margin_m=-0.1)


def _random_obstacles(rng, path, n):
    """Circles, rectangles and pentagons near the first 150 m of ``path``: static, at constant
    velocity or on uneven recorded trajectories (some ending or starting within the horizon),
    some with lifetimes, some out of range."""
    obstacles = []
    for j in range(n):
        s = rng.uniform(-20.0, 150.0) if j else 400.0  # the first one out of range
        p = path.position(s) + rng.normal(0.0, 3.0, 2)
        yaw = float(path.heading(s)) + rng.normal(0.0, 0.4)
        shape = random_shape(rng)
        m = rng.integers(3)
        motion = (
            Static()
            if m == 0
            else ConstantVelocity(*rng.uniform(-5.0, 15.0, 2))
            if m == 1
            else TrajectoryMotion(
                (ts := float(rng.uniform(-2.0, 4.0)) + np.cumsum(rng.uniform(0.1, 1.0, int(rng.integers(1, 12))))),
                rng.uniform(0.0, 12.0) * (ts - ts[0]),
                rng.normal(0.0, 0.5, len(ts)).cumsum(),
                rng.normal(0.0, 0.1, len(ts)).cumsum(),
            )
        )
        life = {}
        if rng.random() < 0.3:
            t0 = float(rng.uniform(-2.0, 6.0))
            life = {"t_start_s": t0, "t_end_s": t0 + float(rng.uniform(0.0, 5.0))}
        obstacles.append(Obstacle(shape, (*p, yaw), motion, name=f"o{j}", **life))
    return obstacles


@pytest.mark.parametrize(
    "path",
    [
        StraightPath((0.0, 0.0), (300.0, 40.0)),
        CirclePath((0.0, 0.0), 60.0, ccw=False),
        WaypointPath(np.column_stack([np.linspace(0.0, 300.0, 40), 8.0 * np.sin(np.linspace(0.0, 300.0, 40) / 30.0)])),
    ],
    ids=["straight", "circle", "waypoints"],
)
def test_compiled_tracks_equal_the_numpy_tracks(path):
    """The obstacles' tracks along the path (s, e, half extents, presence), compiled and numpy,
    on random scenes: the same obstacles kept, the same numbers to 1e-12."""
    rng = np.random.default_rng(21)
    taus = np.arange(0.0, CFG.horizon_s + 1e-9, CFG.dt_s)
    kept = 0
    for _ in range(40):
        obstacles = _random_obstacles(rng, path, 12)
        s_m, t_s = float(rng.uniform(0.0, 100.0)), float(rng.uniform(0.0, 3.0))
        ref = _tracks(path, obstacles, t_s, taus, s_m, 120.0)
        got = _tracks(path, obstacles, t_s, taus, s_m, 120.0, (obstacle_table(obstacles), path_arrays(path)))
        assert got[0].shape == ref[0].shape
        kept += len(ref[0])
        assert np.array_equal(got[4], ref[4])
        for u, w in zip(got[:4], ref[:4]):
            assert np.array_equal(np.isnan(u), np.isnan(w))
            np.testing.assert_allclose(u[~np.isnan(w)], w[~np.isnan(w)], rtol=0, atol=1e-12)
    assert 100 < kept < 40 * 12  # most obstacles kept, some out of range or absent
