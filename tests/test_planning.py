"""The maneuver planner (mpcdrive.planning): its polynomials, its evasive move, its obstacle
tracks against a numpy oracle, and its choices on a straight road in the situations it exists
for (a parked car with traffic behind, both lanes blocked, a pass through the oncoming lane,
the road's end, a goal window), each a choice a wrong planner gets wrong."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcdrive.ocp.avoidance_compiled import table_of
from mpcdrive.paths.compiled import path_arrays
from mpcdrive.paths.straight import StraightPath
from mpcdrive.paths.waypoints import WaypointPath
from mpcdrive.planning import ManeuverPlanner, PlannerConfig, PlanningGoal, VehicleLimits
from mpcdrive.planning import frenet
from mpcdrive.planning.planner import NO_MOVE
from mpcdrive.planning.tracks import CACHE_COLS, obstacle_tracks
from mpcdrive.scene.obstacles import ConstantVelocity, Obstacle, TrajectoryMotion, rectangle
from mpcdrive.scene.road import Lane, Road

W = 3.5  # lane width [m]
PATH = StraightPath((0.0, 0.0), (400.0, 0.0))
#: a BMW 320i as CommonRoad describes it, the controller's limits (kinematic4, 3 footprint discs)
LIMITS = VehicleLimits(
    length_m=4.508,
    width_m=1.61,
    wheelbase_m=2.579,
    max_steer_rad=1.066,
    max_steer_rate_rad_s=0.38,
    max_accel_mps2=6.9,
    max_decel_mps2=6.9,
    max_speed_mps=22.0,
    friction_mps2=10.35,
    disc_offsets_m=(-1.503, 0.0, 1.503),
    disc_radius_m=math.hypot(0.751, 0.805),
)


def two_lanes(oncoming: bool = False, end_m: float | None = None) -> Road:
    """A straight road: the route lane centred on the path and a lane to its left (going the
    car's way, or the other way), 3.5 m each; ``end_m``: where the mapped road ends."""
    s = np.array([0.0, 400.0])
    lanes = (
        Lane("route", np.zeros(2), np.full(2, W / 2), np.full(2, -W / 2)),
        Lane("left", np.full(2, W), np.full(2, 1.5 * W), np.full(2, W / 2), oncoming=oncoming),
    )
    return Road(s, W / 2, -W / 2, 0.1, lanes, 0, end_m=end_m)


def car(x: float, y: float = 0.0, v: float = 0.0) -> Obstacle:
    """A 4.5 m x 1.8 m car at (x, y) [m] at t = 0 driving ``v`` [m/s] along +x (-x for v < 0)."""
    return Obstacle(rectangle(4.5, 1.8), (x, y, 0.0 if v >= 0 else math.pi), ConstantVelocity(v, 0.0))


def planner(road: Road | None = None, speed: float = 12.0, goal=None, **cfg) -> ManeuverPlanner:
    return ManeuverPlanner(PATH, road or two_lanes(), LIMITS, PlannerConfig(**cfg), wanted_speed=speed, goal=goal)


def plan(pl: ManeuverPlanner, obstacles, *, s=20.0, d=0.0, v=12.0, t=0.0):
    return pl.plan(t, s, d, v, 0.0, 0.0, table_of(list(obstacles) or [car(-500.0)], None))


# -- polynomials and the evasive move --------------------------------------------------------------
@pytest.mark.parametrize("T", [0.7, 2.0, 5.5])
def test_quintic_meets_both_ends(T):
    c = np.empty(6)
    kernels_quintic(1.0, 2.0, -0.5, 10.0, 0.3, 0.2, T, c)
    p0 = poly(c, 0.0)
    p1 = poly(c, T)
    assert p0 == pytest.approx((1.0, 2.0, -0.5), abs=1e-12)
    assert p1 == pytest.approx((10.0, 0.3, 0.2), abs=1e-9)


def kernels_quintic(*args):
    from numba import njit

    @njit
    def run(x0, v0, a0, x1, v1, a1, T, c):
        frenet.quintic(x0, v0, a0, x1, v1, a1, T, c)

    run(*args)


def poly(c, t):
    from numba import njit

    @njit
    def run(c, t):
        p, d1, d2, _ = frenet.poly_eval(c, t)
        return p, d1, d2

    return run(c, t)


def test_evasive_move_steers_within_the_rate_and_settles_on_the_line():
    """From straight ahead at 8 m/s to a line 3.5 m left: the curvature never changes faster than
    the steering rate allows, and the move ends on the line (no swing past it by more than a few
    centimetres) with its heading along the path."""
    from numba import njit

    pl = planner()
    w = pl.work
    par, grid, line = w.par.copy(), w.grid.copy(), w.lane_line.copy()

    @njit
    def run(par, grid, line):
        d, th, kap = 0.0, 0.0, 0.0
        out = np.empty((200, 3))
        s = 0.0
        for k in range(200):
            d, th, kap, s = frenet.evasive_step(d, th, kap, s, 8.0, 8.0, 0.2, grid, line, 1, 0.0, par, 0.4)
            s += 1.6
            out[k, 0], out[k, 1], out[k, 2] = d, th, kap
        return out

    out = run(par, grid, line)
    rate = np.abs(np.diff(np.r_[0.0, out[:, 2]])) / 0.2
    assert rate.max() <= LIMITS.max_curvature_rate_1pms * (1 + 1e-9)
    assert out[:, 0].max() <= W + 0.05
    assert out[-1, 0] == pytest.approx(W, abs=0.01) and abs(out[-1, 1]) < 1e-3
    assert np.max(np.abs(out[:, 2]) * 64.0) <= 0.4 * LIMITS.friction_mps2 * (1 + 1e-9)


# -- tracks against the path's own projection --------------------------------------------------------
def test_obstacle_tracks_match_the_paths_projection():
    path = WaypointPath([(0.0, 0.0), (40.0, 0.0), (80.0, 20.0), (140.0, 30.0)], ds_m=0.2)
    t = np.arange(0.0, 4.01, 0.5)
    pts = np.column_stack([10.0 + 12.0 * t, 1.0 + 2.0 * t])
    yaw = np.full(len(t), math.atan2(2.0, 12.0))
    motion = TrajectoryMotion(t, pts[:, 0] - pts[0, 0], pts[:, 1] - pts[0, 1], yaw - yaw[0])
    rec = Obstacle(rectangle(4.0, 2.0), (pts[0, 0], pts[0, 1], yaw[0]), motion)
    obs = [car(30.0, 3.0, 5.0), rec, car(1000.0)]
    tab = table_of(obs, None)
    K = 18  # (the recorded track ends at 4 s: the planner's goes on at its last velocity)
    out = [np.full((8, K + 1), np.nan) for _ in range(4)]
    index = np.zeros(8, np.int64)
    pa = path_arrays(path)
    cache = np.full((len(obs), 2 * K + 8, CACHE_COLS), np.nan)
    # without a cache; then replanning every 0.1 s with one: from the third call on, most boxes
    # are an earlier call's and the last ones are projected on from where the cached ones were
    for t0, c in [(0.0, None), (0.0, cache), (0.1, cache), (0.2, cache), (0.3, cache)]:
        n = obstacle_tracks(tab, pa, t0, 0.2, 5.0, (5.0, 0.0), 200.0, 25.0, *out, index, c, 0.1)
        assert n == 2 and set(index[:n]) == {0, 1}  # the far car is out of range
        for r in range(n):
            ob = obs[index[r]]
            for k in range(K + 1):
                x, y, _ = ob.pose_at(t0 + 0.2 * k)
                s, e = path.project(np.array([x, y]))
                assert out[0][r, k] == pytest.approx(float(s), abs=1e-6)
                assert out[1][r, k] == pytest.approx(float(e), abs=1e-6)
    assert np.isfinite(cache[:2, : 2 * K + 4, 0]).all()  # every box of the calls' times was kept


@pytest.mark.parametrize("v", [20.0, 30.0, -30.0])
def test_a_fast_cars_track_is_where_it_drives_from_its_second_sample_on(v):
    # from its first sample, a car's next is searched within its whole way (30 m/s: 6 m per
    # step; before, within a tenth of it and 2 m, and its box lagged 3.3 m at 0.2 s)
    path = WaypointPath([(0.0, 0.0), (100.0, 0.0), (200.0, 20.0), (300.0, 30.0)], ds_m=0.2)
    ob = car(60.0, 1.0, v)
    K = 20
    out = [np.full((8, K + 1), np.nan) for _ in range(4)]
    index = np.zeros(8, np.int64)
    assert (
        obstacle_tracks(table_of([ob], None), path_arrays(path), 0.0, 0.2, 5.0, (5.0, 0.0), 200.0, 25.0, *out, index)
        == 1
    )
    for k in range(K + 1):
        x, y, _ = ob.pose_at(0.2 * k)
        s, e = path.project(np.array([x, y]))
        assert (out[0][0, k], out[1][0, k]) == pytest.approx((float(s), float(e)), abs=1e-6), k


def test_a_car_that_turns_across_the_path_is_tracked_where_it_crosses_it():
    # it drives towards the car 6 m left of the path at 14 m/s, then turns to cross it: the
    # guess its motion along the path gave (on by 2.8 m a sample) left its true place behind the
    # search window, and the track had it crossing up to 3 m nearer the car (DEU_Muc-3: a
    # maneuver judged safe every other replanning, unsafe in between)
    path = WaypointPath([(0.0, 0.0), (50.0, 0.0), (100.0, 0.0)], ds_m=0.2)
    t = np.round(np.arange(0.0, 6.01, 0.1), 10)
    x = np.where(t <= 2.0, 60.0 - 14.0 * t, 32.0)
    y = np.where(t <= 2.0, 6.0, 6.0 - 14.0 * (t - 2.0))
    yaw = np.where(t <= 2.0, math.pi, 1.5 * math.pi)
    ob = Obstacle(rectangle(4.5, 1.8), (x[0], y[0], yaw[0]), TrajectoryMotion(t, x - x[0], y - y[0], yaw - yaw[0]))
    tab = table_of([ob], None)
    K = 20
    out = [np.full((8, K + 1), np.nan) for _ in range(4)]
    index = np.zeros(8, np.int64)
    cache = np.full((1, 2 * K + 8, CACHE_COLS), np.nan)
    for t0 in (0.0, 0.1, 0.2, 0.3):  # both phases of the cache, then boxes projected on from it
        assert obstacle_tracks(tab, path_arrays(path), t0, 0.2, 5.0, (5.0, 0.0), 200.0, 25.0, *out, index, cache, 0.1)
        for k in range(K + 1):
            px, py, _ = ob.pose_at(t0 + 0.2 * k)
            s, e = path.project(np.array([px, py]))
            assert (out[0][0, k], out[1][0, k]) == pytest.approx((float(s), float(e)), abs=1e-6), (t0, k)


def test_the_lane_at_an_offset_is_the_one_holding_it_else_the_nearest():
    pl = planner(two_lanes(oncoming=True))
    assert [pl.lane_at(50.0, d) for d in (0.0, 1.7, 1.8, W, 1.5 * W - 0.01)] == [0, 0, 1, 1, 1]
    # on the edge both share, the car's own lane (the oncoming one's line is as near); beyond
    # every edge, the lane whose line is nearest; the same beyond the road's mapped ends
    assert pl.lane_at(50.0, W / 2) == 0
    assert [pl.lane_at(50.0, d) for d in (-4.0, 9.0)] == [0, 1]
    assert [pl.lane_at(s, W) for s in (-30.0, 900.0)] == [1, 1]


def test_a_moves_offset_at_one_arc_length_is_the_one_its_arrays_give():
    m = plan(planner(), [car(60.0)])  # a parked car ahead, the left lane free: a lane change
    lat = m.lateral
    assert lat.samples_s is None and lat.length_m > 0.0 and m.lane == 1
    s = np.linspace(lat.s0_m - 5.0, lat.s0_m + lat.length_m + 20.0, 97)
    assert [lat.at(x) for x in s] == [float(v) for v in lat(s)]


# -- choices -------------------------------------------------------------------------------------------
def test_free_road_keeps_the_lane_at_the_wanted_speed():
    m = plan(planner(), [])
    assert m.safe and m.lane == 0 and m.lanes == (0,)
    assert m.v_mps[-1] == pytest.approx(12.0, abs=0.5)
    assert np.max(np.abs(m.d_m)) < 0.05


def test_a_car_at_rest_where_the_wanted_speed_starts_from_zero_drives_off():
    """The wanted speed rises from 0 at the car (at rest at s = 20 m) at 2 m/s^2 up to 12 m/s, as
    a reference profile from standstill does: the maneuver picks up speed, it does not stand
    still for want of speed where the car is."""

    def wanted(s):
        return np.minimum(np.sqrt(2.0 * 2.0 * np.maximum(np.asarray(s, float) - 20.0, 0.0)), 12.0)

    pl = ManeuverPlanner(PATH, two_lanes(), LIMITS, PlannerConfig(), wanted_speed=wanted)
    m = plan(pl, [], s=20.0, v=0.0)
    assert m.safe and m.v_mps[-1] > 8.0 and m.s_m[-1] > 40.0


def test_parked_car_with_traffic_behind_is_passed_at_speed_not_braked_for():
    """A parked car 30 m ahead in the car's lane and a car 18 m behind at 10 m/s that does not
    brake (recorded traffic): stopping behind the parked car is hit from behind, passing in the
    free left lane is not. The maneuver changes lane and keeps its speed."""
    m = plan(planner(), [car(50.0), car(2.0, 0.0, 10.0)], s=20.0, v=12.0)
    assert m.safe
    # alongside the parked car the car is in the left lane (its body clear of the parked one)
    beside = np.abs(m.s_m - 50.0) < 0.5 * LIMITS.length_m + 2.25
    assert beside.any() and np.all(m.d_m[beside] > W / 2 + 0.9 - 1e-6)
    assert np.max(m.d_m) == pytest.approx(W, abs=0.3)
    assert m.v_mps.min() > 8.0  # no braking into the car behind


def test_both_lanes_blocked_stops_before_the_obstacle():
    m = plan(planner(), [car(60.0), car(62.0, W)], s=20.0, v=12.0)
    assert m.safe
    assert m.v_mps[-1] < 1.0  # stopping (the last metre at a crawl), in either lane
    front = m.s_m.max() + 0.5 * LIMITS.length_m
    assert front < 60.0 - 2.25  # behind the cars' rear


def test_oncoming_lane_is_used_to_pass_only_when_allowed_and_free():
    road = two_lanes(oncoming=True)
    blocked = [car(60.0)]
    m = plan(planner(road, oncoming=True), blocked, v=12.0)
    # in the oncoming lane beside the obstacle, at speed
    beside = np.abs(m.s_m - 60.0) < 0.5 * LIMITS.length_m + 2.25
    assert m.safe and beside.any() and np.all(m.d_m[beside] > W / 2 + 0.9 - 1e-6) and m.v_mps.min() > 10.0
    # not allowed: the car stops behind the obstacle (the last metre at a crawl)
    m = plan(planner(road, oncoming=False), blocked, v=12.0)
    assert m.lane == 0 and m.v_mps[-1] < 1.0 and m.s_m.max() + 0.5 * LIMITS.length_m < 60.0 - 2.25
    # an oncoming car in that lane meets the pass: the car waits
    m = plan(planner(road, oncoming=True), blocked + [car(110.0, W, -12.0)], v=12.0)
    assert m.safe and (m.lane == 0 or np.all(m.d_m < W / 2 - 0.9)) and m.v_mps[-1] < 1.0


def test_a_blockage_far_ahead_is_passed_not_waited_for_further_back():
    """A car standing in the car's lane 80 m ahead (5 s at 16 m/s), the oncoming lane free: the
    maneuver goes round it at speed. Before, a stop further back than the blockage's turn-out
    room was not judged as waiting behind it (the search never came near it) and was the
    cheapest maneuver, replanning after replanning: the car stopped 37 m short and never went."""
    road = two_lanes(oncoming=True)
    m = plan(planner(road, oncoming=True, speed=16.0), [car(100.0)], v=16.0)
    assert m.safe and m.v_mps.min() > 10.0
    assert m.d_m.max() > W / 2 + 0.9  # in the oncoming lane, going round


def test_a_pass_through_the_oncoming_lane_returns_to_its_own_lane_past_the_obstacle():
    """The car in the (free) oncoming lane 30 m behind a car standing in its own lane: it stays
    there beside the obstacle and is back on its own lane's line once past it (the return of a
    pass), not on in the oncoming lane for the horizon."""
    road = two_lanes(oncoming=True)
    pl = planner(road, oncoming=True)
    m = plan(pl, [car(60.0)], s=30.0, d=W, v=12.0)
    beside = np.abs(m.s_m - 60.0) < 0.5 * LIMITS.length_m + 2.25
    assert m.safe and beside.any() and np.all(m.d_m[beside] > W / 2 + 0.9 - 1e-6)
    assert m.lane == 0 and abs(m.d_m[-1]) < 0.05 and m.v_mps.min() > 10.0


def test_a_pass_begun_when_the_moves_out_are_too_long_still_returns_past_the_obstacle():
    """The car 0.6 m out of its lane's line and swerving left at 19 m/s, 38 m behind a car standing
    in its lane, a car coming the other way from 178 m ahead (as when the car leaves its plan
    mid-swerve and replans from where it is). Every move sampled into the oncoming lane (2 s at
    19 m/s: 38 m) gets there after the car's front reaches the obstacle, so none was a pass:
    before, the car went on into the oncoming lane and slowed there (9.5 m/s at the horizon's
    end, the oncoming car closing). The latest move out that is still on time makes the pass,
    at speed and back in its own lane past the obstacle."""
    road = two_lanes(oncoming=True)
    pl = planner(road, oncoming=True, speed=19.0)
    m = pl.plan(0.0, 22.0, 0.6, 19.0, 0.14, 0.0, table_of([car(60.0), car(200.0, W, -12.0)], None))
    beside = np.abs(m.s_m - 60.0) < 0.5 * LIMITS.length_m + 2.25
    assert m.safe and beside.any() and np.all(m.d_m[beside] > W / 2 + 0.9 - 1e-6)
    assert m.lane == 0 and abs(m.d_m[-1]) < 0.05 and m.v_mps.min() > 15.0


@pytest.mark.parametrize("s0, off, slope", [(30.0, 0.4, 0.05), (30.0, 0.2, 0.1), (25.0, 0.3, 0.05)])
def test_a_pass_in_the_oncoming_lane_off_its_line_still_returns_past_the_obstacle(s0, off, slope):
    """The car mid-pass in the oncoming lane, 0.2-0.4 m beyond that lane's line and still heading
    out (a multi-body plant overshoots the line by 0.44 m), 30-35 m behind a car standing in its
    own lane at 16 m/s, a car coming the other way from 220 m ahead. Off its line, the car had no
    move in its lane short enough to be a pass (2 s at 16 m/s is 32 m), only passes through the
    lane it had left: before, it stayed in the oncoming lane slowing to 9 m/s, the oncoming car
    closing (and on a multi-body plant was hit head-on). The move back onto its line over the
    way left makes the pass, at speed and back in its own lane past the obstacle."""
    road = two_lanes(oncoming=True)
    pl = planner(road, oncoming=True, speed=16.0)
    m = pl.plan(0.0, s0, W + off, 16.0, slope, 0.0, table_of([car(60.0), car(220.0, W, -12.0)], None))
    beside = np.abs(m.s_m - 60.0) < 0.5 * LIMITS.length_m + 2.25
    assert m.safe and beside.any() and np.all(m.d_m[beside] > W / 2 + 0.9 - 1e-6)
    assert m.lane == 0 and abs(m.d_m[-1]) < 0.05 and m.v_mps.min() > 15.0


def test_the_road_end_is_a_stop_with_the_whole_body_inside():
    pl = planner(two_lanes(end_m=60.0))
    for s in (20.0, 30.0, 40.0):
        m = plan(pl, [], s=s, v=10.0)
        assert m.safe
        # inside the end, and able to stop before it at the vehicle's braking
        front = m.s_m + 0.5 * LIMITS.length_m
        assert np.all(front <= 60.0 - 0.1 + 1e-6)
        assert front[-1] + m.v_mps[-1] ** 2 / (2 * LIMITS.max_decel_mps2) <= 60.0


def test_the_road_end_is_judged_for_the_car_when_it_runs_ahead_of_the_plan_it_goes_on_from():
    """A replanning 0.1 s on finds the car 0.6 m ahead of the last maneuver, within the tolerance
    it goes on from the maneuver: the road's end is judged for the car (0.6 m nearer in the plan's
    frame), so the car's body stops inside it, as the plan's would; judged for the plan it stuck
    out (on CommonRoad's MB plant a car 0.44 m ahead of its plan while braking for the end of
    ZAM_RoadEnd-8 stopped 3 cm past it)."""
    pl = planner(two_lanes(end_m=60.0))
    free = table_of([car(-500.0)], None)
    m0 = pl.plan(0.0, 40.0, 0.0, 6.0, 0.0, 0.0, free)
    ahead = 0.6
    m = pl.plan(0.1, float(np.interp(0.1, m0.t_s, m0.s_m)) + ahead, 0.0, 6.0, 0.0, 0.0, free)
    assert m.s_m[0] == pytest.approx(float(np.interp(0.1, m0.t_s, m0.s_m)), abs=1e-9)  # went on from the plan
    assert m.safe
    front = m.s_m + ahead + 0.5 * LIMITS.length_m  # the car's front, ahead of the plan
    assert np.all(front <= 60.0 - 0.1 + 1e-6)
    assert front[-1] + m.v_mps[-1] ** 2 / (2 * LIMITS.max_decel_mps2) <= 60.0


def test_a_car_drifting_into_the_road_margin_turns_back_inside_the_road():
    """The car 0.055 m inside the road's margin (0.25 m) at its right edge, heading out of the
    lane at 0.05 rad: a maneuver may use the margin for the first second (no plan can turn a car
    round at once), never the road beyond its edge, and is back out of the margin after it."""
    pl = planner()
    half = 0.5 * LIMITS.width_m
    d0 = -W / 2 + 0.25 + half - 0.055
    m = pl.plan(0.0, 20.0, d0, 12.0, -0.05, 0.0, table_of([car(-500.0)], None))
    assert m.safe
    t = np.asarray(m.t_s)
    corner = 0.5 * LIMITS.length_m * 0.05  # the front corner's reach beyond the body's side at that yaw
    assert np.min(m.d_m) - half - corner >= -W / 2 - 1e-6  # never beyond the lane's edge
    assert np.all(m.d_m[t >= 1.0] - half >= -W / 2 + 0.25 - 0.02)  # out of the margin after 1 s


def test_a_car_at_rest_in_the_road_margin_is_given_the_way_to_turn_back_not_a_second():
    """The car at rest, 0.07 m into the road's margin at its right edge (as a recorded start may
    place it): it turns back only as it drives, and its rear corner swings out until the move
    has straightened it, so the margin is its own until it has driven its shortest lateral move
    (2 s at 6 m/s, half-way to the wanted 12 m/s: 12 m, less the none it drives in a second at
    rest) as well as had a second. Every maneuver
    was unsafe when the margin was gone after a second whatever the car drove (the choice among
    unsafe maneuvers then flips between driving off and standing)."""
    pl = planner()
    half = 0.5 * LIMITS.width_m
    d0 = -W / 2 + 0.25 + half - 0.07
    m = pl.plan(0.0, 20.0, d0, 0.0, 0.0, 0.0, table_of([car(-500.0)], None))
    assert m.safe and m.ttc_s == math.inf
    assert m.s_m[-1] > 40.0  # it drives off
    assert np.min(m.d_m) - half >= -W / 2 - 1e-6  # never beyond the lane's edge
    way = m.s_m - m.s_m[0]
    assert np.all(m.d_m[(way >= 12.0) & (m.t_s >= 1.0)] - half >= -W / 2 + 0.25 - 0.02)


def test_goal_window_is_met_when_the_car_would_otherwise_be_early():
    """The goal 40-45 m ahead between 5.0 and 5.4 s: at the wanted 12 m/s the car is there at 2 s;
    the maneuver arrives inside the window."""
    goal = PlanningGoal(arc_m=(60.0, 65.0), time_s=(5.0, 5.4))
    m = plan(planner(goal=goal), [], s=20.0, v=12.0)
    assert m.goal and m.safe
    inside = (m.s_m >= 60.0) & (m.s_m <= 65.0) & (m.t_s >= 5.0 - 1e-9) & (m.t_s <= 5.4 + 1e-9)
    assert inside.any()


def _goal_profiles(pl: ManeuverPlanner) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(target [m], way [m], speed [m/s]) of the goal's profiles the last replanning sampled."""
    from mpcdrive.planning.work import LON_GOAL

    w = pl.work
    n = int(w.lon_n[0])
    return [
        (float(w.lon_target[j]), w.lon_s[j].copy(), w.lon_v[j].copy()) for j in range(n) if w.lon_kind[j] == LON_GOAL
    ]


def test_a_car_late_for_the_goals_window_gets_the_latest_arrival_too():
    """The wanted 5 m/s gets the car from 20 m to 39 m by 3.8 s; the goal is at 50-60 m between
    3.0 and 4.0 s. Besides the middle of both (55 m at 3.5 s: 35 m from 5 m/s to 10 m/s, more
    than the car needs), the car gets the latest arrival: GOAL_INSIDE_M into the region by the
    window's last check step, at the speed a constant acceleration from 5 m/s gives (11.3 m/s,
    1.7 m/s^2 on average); the maneuver reaches the goal."""
    from mpcdrive.planning.candidates import GOAL_INSIDE_M

    goal = PlanningGoal(arc_m=(50.0, 60.0), time_s=(3.0, 4.0))
    pl = planner(speed=5.0, goal=goal)
    m = plan(pl, [], s=20.0, v=5.0)
    dt = PlannerConfig().dt_s
    profiles = _goal_profiles(pl)
    assert [round(t, 6) for t, _, _ in profiles] == [55.0, 50.0 + GOAL_INSIDE_M]
    _, way, speed = profiles[1]
    k = int(round((4.0 - dt) / dt))
    assert way[k] == pytest.approx(50.0 + GOAL_INSIDE_M, abs=1e-9)
    assert speed[k] == pytest.approx(2.0 * (50.0 + GOAL_INSIDE_M - 20.0) / (4.0 - dt) - 5.0, abs=1e-9)
    assert m.goal and m.safe


def test_a_car_the_wanted_speed_gets_to_the_goal_in_time_does_not_get_the_latest_arrival():
    """At the wanted 12 m/s the car is in the region (50-60 m, 3.0-4.0 s) from 2.5 s: aiming for
    the window's last step would have it dawdle there, with no time left for what may hold it up
    on the way; only the middle of both is sampled."""
    goal = PlanningGoal(arc_m=(50.0, 60.0), time_s=(3.0, 4.0))
    pl = planner(speed=12.0, goal=goal)
    plan(pl, [], s=20.0, v=12.0)
    assert [round(t, 6) for t, _, _ in _goal_profiles(pl)] == [55.0]


def test_replanning_is_deterministic():
    obs = [car(50.0), car(2.0, 0.0, 10.0), car(90.0, W, 8.0)]
    a = plan(planner(), obs)
    b = plan(planner(), obs)
    for f in ("s_m", "v_mps", "d_m"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert (a.kind, a.lane, a.checked, a.candidates) == (b.kind, b.lane, b.checked, b.candidates)


def test_the_warm_up_leaves_no_trace_in_the_replannings_after_it():
    # the warm-up replans twice (the second goes on from the first and reuses its tracks): it
    # keeps nothing of them, and a planner warmed up again plans the same two maneuvers as one
    # warmed up once
    obs = [car(50.0), car(2.0, 0.0, 10.0), car(90.0, W, 8.0)]
    tab = table_of(obs, None)
    runs = []
    for extra in (0, 2):
        pl = planner()
        for _ in range(extra):
            pl._warm_up()
        # nothing of its two maneuvers is kept: no last maneuver to go on from, no move under
        # way, no tracks cached (the real obstacles come in a table of their own)
        assert pl.previous is None and pl._move is NO_MOVE and pl._cache.size == 0 and pl._cache_of is None
        a = pl.plan(0.0, 20.0, W, 12.0, 0.0, 0.0, tab)  # in the left lane (the warm-up's car: right)
        s, v, d = (float(np.interp(0.1, a.t_s, f)) for f in (a.s_m, a.v_mps, a.d_m))
        b = pl.plan(0.1, s, d, v, 0.0, 0.0, tab)
        runs.append((a, b))
    for m0, m1 in zip(*runs):
        for f in ("s_m", "v_mps", "d_m"):
            np.testing.assert_array_equal(getattr(m0, f), getattr(m1, f))
        assert (m0.kind, m0.lane, m0.checked, m0.cost_s) == (m1.kind, m1.lane, m1.checked, m1.cost_s)


@pytest.mark.parametrize(
    "field, value",
    [
        ("horizon_s", 0.0),
        ("dt_s", 0.5),
        ("margin_m", -0.1),
        ("rows_tolerance_m", -0.1),
        ("lateral_s", ()),
        ("time_gap_s", math.nan),
    ],
)
def test_bad_settings_are_refused_naming_them(field, value):
    with pytest.raises(ValueError, match=field):
        PlannerConfig(**{field: value})


def test_a_goal_interval_must_be_ordered():
    with pytest.raises(ValueError, match="arc_m"):
        PlanningGoal(arc_m=(10.0, 5.0))


def test_a_goal_window_no_profile_can_reach_is_paid_by_all_and_prunes_the_search():
    """The goal 280 m ahead with its window closing at 3 s: no profile gets there (12 m/s and
    6.9 m/s^2 cover 67 m), so every maneuver pays the miss. The choice is the one without the
    goal, its cost that plus the miss, and the search stops early as it does without the goal
    (the miss is part of the pairs' bound: an exhaustive search before)."""
    obs = [car(90.0, W, 8.0)]
    goal = PlanningGoal(arc_m=(300.0, 305.0), time_s=(0.0, 3.0))
    cfg = PlannerConfig()
    with_goal = plan(planner(goal=goal), obs)
    without = plan(planner(), obs)
    assert not with_goal.goal
    assert (with_goal.kind, with_goal.lane) == (without.kind, without.lane)
    np.testing.assert_allclose(with_goal.s_m, without.s_m)
    np.testing.assert_allclose(with_goal.d_m, without.d_m)
    assert with_goal.cost_s == pytest.approx(without.cost_s + cfg.goal_miss_s, abs=1e-9)
    assert with_goal.checked <= without.checked + 2 < with_goal.candidates


def test_a_maneuver_keeps_below_the_speed_at_which_the_path_bends_faster_than_the_car_steers():
    """Between 50 and 70 m the path (as the speed profile measures it) bends faster than the car
    can steer above 6 m/s, and the wanted speed dips to 6 m/s there. Without that limit the
    planner holds nearly 12 m/s through it (a cheap profile close to the wanted one); with it
    the maneuver drives there within the steering rate (the 5 % slack of the vehicle checks)."""

    def wanted(s):
        s = np.asarray(s, float)
        before = np.sqrt(np.maximum(36.0 + 2.0 * 2.0 * (45.0 - s), 36.0))
        after = np.sqrt(np.maximum(36.0 + 2.0 * 2.0 * (s - 75.0), 36.0))
        return np.minimum(12.0, np.where(s < 45.0, before, np.where(s > 75.0, after, 6.0)))

    def bend(s):  # the inverse of that speed [s/m]; 0: no limit
        s = np.asarray(s, float)
        return np.where((s >= 50.0) & (s <= 70.0), 1.0 / 6.0, 0.0)

    def in_window_top(m):
        inside = (m.s_m >= 50.0) & (m.s_m <= 70.0)
        assert inside.any()
        return float(np.max(m.v_mps[inside]))

    free = ManeuverPlanner(PATH, two_lanes(), LIMITS, PlannerConfig(), wanted_speed=wanted)
    limited = ManeuverPlanner(PATH, two_lanes(), LIMITS, PlannerConfig(), wanted_speed=wanted, bend=bend)
    assert in_window_top(plan(free, [])) > 6.0 * 1.05
    m = plan(limited, [])
    assert m.safe
    assert in_window_top(m) <= 6.0 * 1.05 + 1e-6


def test_the_steering_the_routes_bends_ask_is_in_the_pairs_bound():
    """Between 50 and 70 m the path bends faster than the car steers above 6 m/s, and the wanted
    speed stays 12 m/s: every profile that keeps its speed there steers beyond the rate with any
    lateral move. That cost (``rate_excess_s`` per unit of the rate's excess) is each profile's
    own (``lon_bend``: the speed times the bend along the way it drives, over the checks' 5 %
    slack), so it is in the pairs' bound: the first pair checked is the choice, on a free road and
    behind a parked car with a car beside (the search checked 108 and 152 of the pairs when the
    rate was found in the check alone), and the choice is the same maneuver at the same cost."""
    from mpcdrive.planning.candidates import KAPPA_SLACK

    def bend(s):
        s = np.asarray(s, float)
        return np.where((s >= 50.0) & (s <= 70.0), 1.0 / 6.0, 0.0)

    for obs in ([], [car(95.0, 0.0, 0.0), car(60.0, W, 12.0)]):
        pl = ManeuverPlanner(PATH, two_lanes(), LIMITS, PlannerConfig(), wanted_speed=12.0, bend=bend)
        m = plan(pl, obs)
        w = pl.work
        n = int(w.lon_n[0])
        grid_s = w.grid[0] + w.grid[1] * np.arange(len(w.g_bend))  # the bend as the planner samples it
        want = np.max(w.lon_v[:n, 1:] * np.interp(w.lon_s[:n, 1:], grid_s, w.g_bend), axis=1) / KAPPA_SLACK
        np.testing.assert_allclose(w.lon_bend[:n], want, rtol=1e-12)
        assert (want[w.lon_ok[:n] == 1] > 1.0).sum() > 5  # many profiles steer beyond the rate
        assert m.safe and m.checked <= 2 < m.candidates
        assert m.kind == "speed" and m.lane == 0
        assert m.cost_s == pytest.approx(7.79, abs=0.01)


def test_the_wanted_speed_is_followed_through_a_bend_it_slows_for_not_passed_fast():
    """A speed profile slows at its braking limit (3 m/s^2, the comfort deceleration) from 12 m/s
    to exactly the 6 m/s at which the path between 50 and 70 m bends as fast as the car steers,
    and picks up speed at 2 m/s^2 after it. The maneuver that follows that profile keeps the
    bend's speed (within the vehicle checks' 5 % slack); the maneuver chosen drives the bend at
    its speed, not at half of it. A wanted-speed profile that looks a second ahead and brakes for
    the difference lags the braking by about 1 m/s and steers beyond the rate in the bend."""

    def wanted(s):
        s = np.asarray(s, float)
        before = np.sqrt(np.maximum(36.0 + 2.0 * 3.0 * (50.0 - s), 36.0))
        after = np.sqrt(np.maximum(36.0 + 2.0 * 2.0 * (s - 70.0), 36.0))
        return np.minimum(12.0, np.where(s < 50.0, before, np.where(s > 70.0, after, 6.0)))

    def bend(s):
        s = np.asarray(s, float)
        return np.where((s >= 50.0) & (s <= 70.0), 1.0 / 6.0, 0.0)

    pl = ManeuverPlanner(PATH, two_lanes(), LIMITS, PlannerConfig(), wanted_speed=wanted, bend=bend)
    m = plan(pl, [], s=10.0, v=12.0)
    w = pl.work
    grid_s = w.grid[0] + w.grid[1] * np.arange(len(w.g_bend))
    # the profile that follows the wanted speed (the first one sampled)
    follow = w.lon_v[0] * np.interp(w.lon_s[0], grid_s, w.g_bend)
    assert float(np.max(follow)) <= 1.05
    assert float(np.min(w.lon_v[0])) >= 6.0 - 0.5
    inside = (m.s_m >= 50.0) & (m.s_m <= 70.0)
    assert m.safe and inside.any()
    assert float(np.max(m.v_mps[inside])) <= 6.0 * 1.05 + 1e-6
    assert float(np.min(m.v_mps[inside])) >= 6.0 - 0.5


@pytest.mark.parametrize("s0", [40.0, 44.0, 48.0])
def test_a_bend_ahead_is_slowed_for_to_its_speed_not_to_half_the_cars(s0):
    """The wanted speed dips from 6.9 m/s to 4.3 m/s at 66 m (it brakes and picks up at
    2.4 m/s^2, the profile of a roundabout's exit bend that the path bends as fast as the car
    steers at). The car comes at 6.4 m/s, braking gently (0.7 m/s^2). Following the dip costs
    jerk; before the slowing profiles, a quartic to half the car's speed (3.2 m/s) was cheaper,
    and replanning chose it again and again (measured on a roundabout: 4.1 m/s for 2.5 s before
    the exit). Now a profile that holds the speed, then slows to the bend's speed where it is
    wanted, is chosen: never below the bend's speed, reaching it by the bend."""

    def wanted(s):
        s = np.asarray(s, float)
        return np.minimum(6.9, np.sqrt(4.3**2 + 2.0 * 2.4 * np.abs(s - 66.0)))

    def bend(s):  # the path bends as fast as the car steers at the wanted speed (5 % within)
        return 0.95 / wanted(s)

    pl = ManeuverPlanner(PATH, two_lanes(), LIMITS, PlannerConfig(), wanted_speed=wanted, bend=bend)
    m = pl.plan(0.0, s0, 0.0, 6.4, 0.0, -0.7, table_of([car(-500.0)], None))
    assert m.safe
    assert float(np.min(m.v_mps)) >= 4.3 - 0.05
    assert float(np.interp(66.0, m.s_m, m.v_mps)) <= 4.3 * 1.05


def test_a_goal_window_closing_after_the_horizon_is_missed_by_a_profile_too_slow_to_make_it():
    """A window closing after the horizon (6 s) is judged from each profile's end: the time the
    wanted speed takes from there to the region, plus the time lost regaining it at the
    comfortable acceleration. Wanted 10 m/s; the region from 130 m, the window closing at 12.5 s:
    a profile at 10 m/s ends at 60 m and is there at 13 s (missed), one at 10 m/s from 70 m at
    12 s (in time), one ending at 70 m at 6 m/s loses (10 - 6)^2 / (2 * 2 * 10) = 0.4 s (in time,
    12.4 s) and at 4 m/s 0.9 s (missed, 12.9 s). A region reached within the horizon, or behind a
    standstill of the wanted speed (no estimate), is not charged."""
    from mpcdrive.planning import work as W
    from mpcdrive.planning.checks import goal_missed_by_profile
    from mpcdrive.planning.planner import wanted_times

    dt, K = 0.2, 30
    grid_s = np.arange(0.0, 300.0, 0.5)
    par = np.zeros(W.N_PAR)
    par[W.P_C_GOAL], par[W.P_V_MAX], par[W.P_A_COMF] = 20.0, 30.0, 2.0
    ego = np.zeros(W.E_MOVE_END + 1)
    ego[W.E_S], ego[W.E_T] = 0.0, 0.0
    grid = np.array([grid_s[0], 0.5, len(grid_s), 2.0])
    goal = np.zeros(12)
    goal[W.G_HAS] = 1.0
    goal[W.G_S_LO], goal[W.G_S_HI] = 130.0, 200.0
    goal[W.G_T_LO], goal[W.G_T_HI] = 0.0, 12.5
    goal[W.G_V_LO], goal[W.G_V_HI] = 0.0, 30.0

    def charged(end_s, end_v, vref=None):
        vref = np.full(len(grid_s), 10.0) if vref is None else vref
        lon_s = np.linspace(0.0, end_s, K + 1)[None, :]
        lon_v = np.full((1, K + 1), end_v)
        out = np.empty(1)
        tref = wanted_times(grid_s, vref, 30.0)
        goal_missed_by_profile.py_func(par, ego, goal, lon_s, lon_v, 1, dt, grid, vref, tref, out)
        return out[0]

    assert charged(60.0, 10.0) == 20.0
    assert charged(70.0, 10.0) == 0.0
    assert charged(70.0, 6.0) == 0.0
    assert charged(70.0, 4.0) == 20.0
    assert charged(131.0, 10.0) == 0.0  # in the region by the horizon's end
    stop = np.where(grid_s > 100.0, 0.0, 10.0)  # the wanted speed stands from 100 m on
    assert charged(60.0, 10.0, stop) == 0.0
    goal[W.G_S_LO] = 130.2  # (between two grid points: the time there is inf, not NaN)
    assert charged(60.0, 10.0, stop) == 0.0 and charged(60.0, 10.0) == 20.0
    t = wanted_times(grid_s, stop, 30.0)
    assert t[grid_s <= 100.0][-1] == pytest.approx(10.0, abs=0.05) and np.isinf(t[-1])


def test_above_the_wanted_speed_the_profile_brakes_beyond_the_comfortable_to_get_under_it():
    """The car drives 12 m/s where the wanted speed is 7 m/s (it entered a bend's slower stretch
    too fast): the profile that follows the wanted speed brakes harder than the comfortable
    3 m/s^2 (never beyond the vehicle's limit), where before it braked at the comfortable rate
    at most, and comes down to the wanted speed."""
    pl = ManeuverPlanner(PATH, two_lanes(), LIMITS, PlannerConfig(), wanted_speed=7.0)
    plan(pl, [], s=20.0, v=12.0)
    w = pl.work
    a, v, t = w.lon_a[0], w.lon_v[0], pl.config.dt_s * np.arange(w.lon_v.shape[1])
    assert float(np.min(a)) < -pl.config.comfort_decel_mps2 - 0.5
    assert float(np.min(a)) >= -LIMITS.max_decel_mps2 - 1e-9
    assert np.all(np.diff(v) <= 1e-9) and float(np.interp(2.0, t, v)) < 8.5 and v[-1] < 7.3


def test_the_goal_is_judged_for_the_car_when_it_lags_the_plan_it_goes_on_from():
    """At 12 m/s the wanted speed reaches the goal region (from 55.6 m, window closing at 3 s)
    0.4 m inside it at the window's end. A replanning 0.1 s later finds the car 0.8 m behind the
    last maneuver (within the tolerance it goes on from the maneuver, not the car): the region is
    judged for the car, so the maneuver chosen gets the car into it in time; judged for the plan,
    holding the speed leaves the car 0.4 m short."""
    goal = PlanningGoal(arc_m=(55.6, 200.0), time_s=(0.0, 3.0))
    pl = planner(goal=goal)
    free = table_of([car(-500.0)], None)
    m0 = pl.plan(0.0, 20.0, 0.0, 12.0, 0.0, 0.0, free)
    assert m0.goal and float(np.interp(3.0, m0.t_s, m0.s_m)) < 55.6 + 0.8
    lag = 0.8
    m = pl.plan(0.1, float(np.interp(0.1, m0.t_s, m0.s_m)) - lag, 0.0, 12.0, 0.0, 0.0, free)
    assert m.safe and m.goal
    assert float(np.interp(2.9, m.t_s, m.s_m)) - lag >= 55.6


def test_a_pass_begun_goes_on_to_where_its_move_ends():
    """Replanned every 0.1 s from where the last maneuver has the car, a pass through the free
    oncoming lane keeps the end of its move out: the car is beside the obstacle's lane line
    where the first plan had it, not 1.2 m further at every replanning. (Moves sampled over the same durations from every replanning
    kept their ends ahead of the car: the move out never arrived, the pass was dropped once no
    move reached the lane in time, and the car braked for the blockage.)"""
    pl = planner(two_lanes(oncoming=True), oncoming=True)
    obs = [car(60.0)]

    def arrival(m):
        """Arc length [m] where the maneuver's body is first clear of its own lane."""
        clear = W / 2 + 0.5 * LIMITS.width_m
        out = np.flatnonzero(m.d_m > clear)
        if not out.size or out[0] == 0:
            return math.inf
        i = out[0]  # between samples i - 1 and i, linearly
        f = (clear - m.d_m[i - 1]) / (m.d_m[i] - m.d_m[i - 1])
        return float(m.s_m[i - 1] + f * (m.s_m[i] - m.s_m[i - 1]))

    m = plan(pl, obs, s=20.0, v=12.0)
    first = arrival(m)
    assert m.safe and first < 60.0 - 4.5
    for k in range(1, 11):
        t = 0.1 * k
        s, d, v = (float(np.interp(0.1, m.t_s, a)) for a in (m.s_m, m.d_m, m.v_mps))
        kappa = m.lateral.curvature(s)  # the car steering as planned (a straight path)
        m = pl.plan(t, s, d, v, 0.0, 0.0, table_of(obs, None), kappa)
        assert m.safe and m.v_mps.min() > 10.0, t
        # (within the chord between the plans' 2.4 m samples; receding: 1.2 m per replanning)
        assert arrival(m) <= first + 1.0, (t, arrival(m), first)


def test_a_goal_region_shorter_than_a_step_of_the_way_is_reached_between_samples():
    """A goal region 0.8 m long 41 m ahead, any time in 6 s at 10-14 m/s: at 12 m/s the car
    drives 2.4 m per planning step (0.2 s), so no sample of the maneuver lies in the region; the
    car passes through it at 3.4 s all the same. The planner judges it reached (before, every
    maneuver was judged to miss the goal, paid its 20 s, and the search checked them all)."""
    goal = PlanningGoal(arc_m=(61.0, 61.8), time_s=(0.0, 6.0), speed_mps=(10.0, 14.0))
    cfg = PlannerConfig()
    with_goal = plan(planner(goal=goal), [], s=20.0, v=12.0)
    without = plan(planner(), [], s=20.0, v=12.0)
    assert not np.any((with_goal.s_m >= 61.0) & (with_goal.s_m <= 61.8))  # between two samples
    assert with_goal.goal and with_goal.safe
    assert with_goal.cost_s < without.cost_s + 0.5 * cfg.goal_miss_s
    assert with_goal.checked <= without.checked + 2


def test_a_goal_window_of_one_instant_between_two_samples_is_met():
    """The goal 50-70 m ahead at 3.3 s exactly (many CommonRoad files give a single time step):
    replanning at 0.0 s, the maneuver's samples are at 3.2 and 3.4 s, the car at 12 m/s in the
    region at both. The planner judges the goal met at 3.3 s (before, every maneuver missed it at
    every other replanning)."""
    goal = PlanningGoal(arc_m=(50.0, 70.0), time_s=(3.3, 3.3))
    m = plan(planner(goal=goal), [], s=20.0, v=12.0)
    assert not np.any(np.isclose(m.t_s, 3.3))
    assert m.goal and m.safe


def test_the_goal_heading_is_the_body_s_which_turns_less_than_the_path_by_the_slip():
    """On a 25 m-radius bend to the left the centre of gravity (1.42 m ahead of the rear axle)
    moves at a slip angle asin(1.42 / 25) = 0.057 rad to the body: the body heads that much to
    the right of the path. A goal whose heading range holds the body's heading and not the
    path's is met (before, the path's heading was judged and the goal missed by every maneuver)."""
    from dataclasses import replace

    ang = np.linspace(-math.pi / 2, 0.6 * math.pi, 400)  # an open arc about (0, 25), ccw
    path = WaypointPath(np.column_stack([25.0 * np.cos(ang), 25.0 + 25.0 * np.sin(ang)]))
    slip = math.asin(1.4227 / 25.0)
    heading = float(path.heading(63.0))
    goal = PlanningGoal(arc_m=(60.0, 66.0), yaw_rad=(heading - slip - 0.02, heading - slip + 0.02))

    def chosen(limits):
        pl = ManeuverPlanner(path, two_lanes(), limits, PlannerConfig(), wanted_speed=8.0, goal=goal)
        return pl.plan(0.0, 20.0, 0.0, 8.0, 0.0, 0.0, table_of([car(-500.0)], None), 1.0 / 25.0)

    m = chosen(replace(LIMITS, rear_axle_m=1.4227))
    assert m.goal and m.safe
    # the rear axle as the reference point: no slip, the path's heading, outside the range
    assert not chosen(LIMITS).goal


def test_a_rear_axle_outside_the_wheelbase_is_refused():
    from dataclasses import replace

    with pytest.raises(ValueError, match="rear_axle_m"):
        replace(LIMITS, rear_axle_m=3.0)


def test_the_search_skips_an_obstacle_only_when_no_disc_can_reach_it():
    """``_beyond_box`` lets the contact test skip an obstacle over a step: both ends of the body's
    reference point lie beyond one side of the obstacle's box grown by the discs' reach. Against
    the exact swept test of every disc (any offset within the reach, any heading at either end):
    whenever it skips, no disc's segment meets the box; and it skips most far-off cases (the test
    would catch a prune that never fires as well as one that skips a contact)."""
    from mpcdrive.planning.contact import _beyond_box, _segment_hits_box

    beyond, hits = _beyond_box.py_func, _segment_hits_box.py_func
    rng = np.random.default_rng(7)
    skipped = 0
    for _ in range(20000):
        s0, d0, s1, d1 = rng.uniform(-12.0, 12.0, 4)
        reach, bl, bw = rng.uniform(0.0, 2.0), rng.uniform(0.5, 3.0), rng.uniform(0.5, 2.0)
        if not beyond(s0, d0, s1, d1, reach, bl, bw):
            continue
        skipped += 1
        for _ in range(4):
            u = rng.uniform(-reach, reach)
            h0, h1 = rng.uniform(-math.pi, math.pi, 2)
            a = (s0 + u * math.cos(h0), d0 + u * math.sin(h0))
            b = (s1 + u * math.cos(h1), d1 + u * math.sin(h1))
            assert not hits(a[0], a[1], b[0], b[1], bl, bw), (s0, d0, s1, d1, reach, bl, bw, u)
    assert skipped > 5000
    # a segment through the box is never skipped, however short the reach
    assert not beyond(-5.0, 0.0, 5.0, 0.0, 0.0, 1.0, 1.0)
    assert not beyond(3.0, 0.0, 3.0, 0.0, 2.5, 1.0, 1.0)  # beyond the box, not beyond its reach


def test_the_road_lookup_is_skipped_only_where_no_corner_can_leave_the_road():
    """``_clear_of_edges`` lets the search skip the body's corner lookups at a step: the body keeps
    clear of the tightest edges within its reach (``road_windows``). Against the exact corners
    (``_road_excess``) on winding random edges and road ends, any offset and heading: whenever
    it says clear, no corner is beyond the allowance; and it says so for most bodies well inside
    the road (a skip that never fires fails as well as one that hides a departure)."""
    from mpcdrive.planning import work as W
    from mpcdrive.planning.checks import _clear_of_edges, _road_excess
    from mpcdrive.planning.work import P_CO, P_HL, P_HW, P_ROAD_END, P_ROAD_MARGIN, P_ROAD_START

    clear_of, excess = _clear_of_edges.py_func, _road_excess.py_func
    rng = np.random.default_rng(11)
    G, ds = 200, 0.5
    grid_s = np.arange(G) * ds
    arrays = W.new_work(10, grid_s, 1)
    said, inside = 0, 0
    for trial in range(40):
        left = 3.0 + np.cumsum(rng.normal(0.0, 0.15, G))
        right = -3.0 + np.cumsum(rng.normal(0.0, 0.15, G))
        for name, tab in (("same_left", left), ("same_right", right), ("all_left", left + 3.5), ("all_right", right)):
            arrays[name][:] = tab
        par = arrays["par"]
        par[P_HL], par[P_HW], par[P_CO] = rng.uniform(1.5, 2.6), rng.uniform(0.8, 1.0), rng.uniform(-0.5, 1.5)
        par[P_ROAD_MARGIN] = rng.uniform(0.0, 0.3)
        par[P_ROAD_START], par[P_ROAD_END] = (5.0, 90.0) if trial % 2 else (-math.inf, math.inf)
        W.road_windows(arrays)
        for _ in range(500):
            s, d = rng.uniform(-5.0, 105.0), rng.uniform(-4.0, 4.0)
            yaw = rng.uniform(-0.6, 0.6)
            cth, sth = math.cos(yaw), math.sin(yaw)
            allow = rng.uniform(1e-3, 0.5)
            row = 2 * int(rng.integers(2))
            lt, rt = (arrays["all_left"], arrays["all_right"]) if row else (arrays["same_left"], arrays["same_right"])
            exact = excess(arrays["grid"], lt, rt, par, s, d, cth, sth)
            if clear_of(arrays["grid"], arrays["edge_win"], row, par, s, d, cth, sth, allow):
                said += 1
                assert exact <= allow, (trial, s, d, yaw, allow, exact)
            elif abs(d) < 0.5 and abs(yaw) < 0.1 and 20.0 < s < 80.0 and exact <= 0.0:
                inside += 1
    assert said > 2000
    assert inside < 0.2 * said  # bodies well inside are skipped, not looked up


def test_a_profile_that_reaches_the_region_only_after_the_window_closes_is_a_sure_miss():
    """The pairs' bound counts the goal's miss for a profile that cannot be in the region by the
    window's end: the distance driven by then, interpolated between the samples around the end
    (here 2.9 s, between 2.8 and 3.0 s), not the distance at the sample after it. At 10 m/s the
    car has driven 29 m by 2.9 s and 30 m by 3.0 s; with the evasive move's slack of 0.5 m a
    region from 29.7 m ahead is a sure miss, one from 29.3 m is not (it may be reached)."""
    from mpcdrive.planning import work as W
    from mpcdrive.planning.checks import REACH_SLACK_M, goal_missed_by_profile

    dt, K = 0.2, 30
    lon_s = np.array([10.0 * dt * np.arange(K + 1)])
    lon_v = np.full((1, K + 1), 10.0)
    par = np.zeros(W.N_PAR)
    par[W.P_C_GOAL] = 20.0
    ego = np.zeros(W.E_MOVE_END + 1)
    ego[W.E_S], ego[W.E_T] = 100.0, 0.0

    def missed(start_ahead_m):
        goal = np.zeros(12)
        goal[W.G_HAS] = 1.0
        goal[W.G_S_LO], goal[W.G_S_HI] = 100.0 + start_ahead_m, 200.0
        goal[W.G_T_LO], goal[W.G_T_HI] = 0.0, 2.9
        goal[W.G_V_LO], goal[W.G_V_HI] = 0.0, 20.0
        out = np.empty(1)
        grid, table = np.array([0.0, 1.0, 2.0, 1.0]), np.zeros(2)  # (the window closes within the horizon)
        goal_missed_by_profile.py_func(par, ego, goal, lon_s, lon_v, 1, dt, grid, table, table, out)
        return out[0]

    assert REACH_SLACK_M == 0.5
    assert missed(29.7) == 20.0  # 29 m + 0.5 m by 2.9 s: short of it
    assert missed(29.3) == 0.0  # within the slack of 29 m: perhaps reached
    assert missed(10.0) == 0.0  # reached well inside the window


def test_only_a_car_already_in_the_margin_keeps_it_over_the_way_it_needs_to_turn_back():
    """The margin's allowance at 2 s, the car having driven 3 m: gone for a car that started clear
    of it (a turn from rest that leaned on the margin left the controller no room: the generated
    left turn of test_commonroad_cases case 4 left the road on ST), still most of it for a car
    that started 0.07 m into it (it turns back only as it drives)."""
    from mpcdrive.planning.checks import _road_allowance
    from mpcdrive.planning.work import P_ROAD_MARGIN, P_TURN_BACK

    par = planner().work.par.copy()
    par[P_TURN_BACK] = 12.0
    allow = _road_allowance.py_func
    assert allow(0.0, par, 2.0, 3.0) == pytest.approx(1e-3)
    assert allow(0.0, par, 0.5, 3.0) == pytest.approx(0.5 * par[P_ROAD_MARGIN] + 1e-3)
    assert allow(0.07, par, 2.0, 3.0) == pytest.approx(0.75 * (0.07 + par[P_ROAD_MARGIN]) + 1e-3)
    assert allow(0.07, par, 2.0, 12.0) == pytest.approx(1e-3)
