"""highway-env adapter: action scaling, the racetrack's lane centreline as a path, and closed-loop
drives of ``racetrack-v0`` by the LTV-MPC (skipped when highway-env is not installed; CI installs
the ``highway`` extra)."""

from __future__ import annotations

import math
import os
import warnings

import numpy as np
import pytest

from mpcdrive.adapters.highway_env import (
    ActionScaling,
    DriverSettings,
    HighwayEnvMpcDriver,
    drive_env,
    lane_centerline,
    lane_following_obstacle,
    lane_sequence,
    racetrack_config,
    vehicle_obstacle,
)
from mpcdrive.sim import compute_metrics, run_verdict
from mpcdrive.types import ControlOutput, WarmStart

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # pygame without a display


# --------------------------------------------------------------------------- no env needed
def test_action_scaling_maps_ranges_to_unit_interval():
    sc = ActionScaling((-0.5, 0.5), (-4.0, 2.0))
    np.testing.assert_allclose(sc.to_action(0.5, 2.0), [1.0, 1.0])
    np.testing.assert_allclose(sc.to_action(-0.5, -4.0), [-1.0, -1.0])
    np.testing.assert_allclose(sc.to_action(0.0, -1.0), [0.0, 0.0])  # the ranges' midpoints
    np.testing.assert_allclose(sc.to_action(0.25, 0.5), [0.5, 0.5])
    np.testing.assert_allclose(sc.to_action(3.0, -9.0), [-1.0, 1.0])  # clipped into [-1, 1]
    steer, accel = sc.from_action(sc.to_action(0.123, 1.5))
    assert steer == pytest.approx(0.123, abs=1e-6) and accel == pytest.approx(1.5, abs=1e-6)
    lat = ActionScaling((-math.pi / 4, math.pi / 4), None)
    assert not lat.longitudinal
    np.testing.assert_allclose(lat.to_action(math.pi / 8), [0.5])
    assert lat.from_action([0.5]) == pytest.approx((math.pi / 8, 0.0))


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"steering_range_rad": (0.5, -0.5)}, "steering_range_rad"),
        ({"acceleration_range_mps2": (1.0, float("nan"))}, "acceleration_range_mps2"),
    ],
)
def test_action_scaling_rejects_bad_ranges(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ActionScaling(**kwargs)
    with pytest.raises(ValueError, match="finite"):
        ActionScaling().to_action(float("nan"))
    with pytest.raises(ValueError, match="2 component"):
        ActionScaling().from_action([0.1])


def test_lane_following_prediction_on_a_circle():
    """A car 0.8 m outside the lane centre, yawed 0.1 rad towards it, at 8 m/s on a 20 m circle:
    the prediction starts at its pose, moves 8 m/s along the lane and steers onto its centre."""
    from types import SimpleNamespace

    from mpcdrive.paths import CirclePath

    path = CirclePath((0.0, 0.0), 20.0)  # counter-clockwise: the centre is on the left
    th = 0.3
    car = SimpleNamespace(
        position=np.array([20.8 * math.cos(th), 20.8 * math.sin(th)]),
        heading=th + math.pi / 2 + 0.1,
        speed=8.0,
        LENGTH=5.0,
        WIDTH=2.0,
    )
    ob = lane_following_obstacle(car, path, np.arange(0.0, 3.01, 0.2), t_s=1.0, tau_lateral_s=0.5)
    assert ob.pose_at(1.0) == pytest.approx((*car.position, car.heading), abs=1e-12)
    assert ob.pose_at(0.0) == ob.pose_at(1.0)  # held before now
    np.testing.assert_allclose(np.ptp(ob.shape.points, axis=0), [5.0, 2.0])
    s0, e0 = path.project(car.position)
    assert e0 == pytest.approx(-0.8)
    for t in (0.5, 1.0, 3.0):
        x, y, yaw = ob.pose_at(1.0 + t)
        s, e = path.project([x, y], s0 + 8.0 * t, 3.0)
        assert s == pytest.approx(s0 + 8.0 * t, abs=0.02)
        assert e == pytest.approx(-0.8 * math.exp(-t / 0.5), abs=0.02)
        assert yaw == pytest.approx(float(path.heading(s)) + 0.1 * math.exp(-t / 0.5), abs=1e-3)
    assert ob.pose_at(9.0) == ob.pose_at(4.0)  # held after the last prediction
    with pytest.raises(ValueError, match="times_s"):
        lane_following_obstacle(car, path, [0.2, 0.4])
    with pytest.raises(ValueError, match="tau_lateral_s"):
        lane_following_obstacle(car, path, [0.0, 0.2], tau_lateral_s=0.0)


def test_racetrack_config_checks_its_numbers():
    cfg = racetrack_config(steering_range_rad=(-0.6, 0.6), policy_frequency_hz=5, simulation_frequency_hz=15)
    assert cfg["other_vehicles"] == 1  # highway-env's own default: one car ahead in the ego's lane
    assert racetrack_config(other_vehicles=0)["other_vehicles"] == 0
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="other_vehicles"):
            racetrack_config(other_vehicles=bad)
    assert cfg["action"]["steering_range"] == [-0.6, 0.6] and cfg["action"]["longitudinal"] is True
    with pytest.raises(ValueError, match="simulation_frequency_hz"):
        racetrack_config(policy_frequency_hz=5, simulation_frequency_hz=12)
    with pytest.raises(ValueError, match="steering_range_rad"):
        racetrack_config(steering_range_rad=(0.1, 0.1))
    with pytest.raises(ValueError, match="horizon"):
        DriverSettings(horizon=0)


# --------------------------------------------------------------------------- with highway-env
@pytest.fixture(scope="module")
def gym():
    pytest.importorskip("highway_env", reason="highway-env is not installed (pip install mpcdrive[highway])")
    import gymnasium
    import highway_env  # noqa: F401  (registers the environments)

    return gymnasium


def make_env(gym, seed: int, **config):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # "racetrack-v0 is out of date"
        env = gym.make("racetrack-v0", config={**racetrack_config(), **config})
    env.reset(seed=seed)
    return env


@pytest.mark.slow
@pytest.mark.parametrize("lane_id", [0, 1])
def test_centerline_follows_the_racetrack_lane(gym, lane_id):
    env = make_env(gym, 0, other_vehicles=0)
    net = env.unwrapped.road.network
    seq, closed = lane_sequence(net, ("a", "b", lane_id))
    assert closed and len(seq) == 9 and all(ix[2] == lane_id for ix in seq)
    path, half = lane_centerline(net, ("a", "b", lane_id))
    assert path.closed and half == pytest.approx(2.5)
    lanes = [net.get_lane(ix) for ix in seq]
    # the pieces overlap by up to about a metre where they join
    total = sum(lane.length for lane in lanes)
    assert total - 9.0 < path.length_m < total + 0.5
    s = np.linspace(0.0, path.length_m, 700, endpoint=False)
    # every point of the path lies on the centre of one of the lanes (a few cm at the joins)
    lateral = [min(abs(lane.local_coordinates(p)[1]) for lane in lanes if lane.on_lane(p)) for p in path.position(s)]
    assert max(lateral) < 0.1
    # curvature: the tightest bend has a 15 m radius; the joins add no spikes
    kappa = np.abs(path.curvature(s))
    assert kappa.max() < 1.5 / 15.0 and np.median(kappa) < 1.0 / 15.0
    # the path's heading agrees with the lanes' heading
    for si in s[::50]:
        p = path.position(si)
        lane = min(lanes, key=lambda ln: abs(ln.local_coordinates(p)[1]) if ln.on_lane(p) else np.inf)
        lon, _ = lane.local_coordinates(p)
        d = (float(path.heading(si)) - lane.heading_at(lon) + np.pi) % (2 * np.pi) - np.pi
        assert abs(d) < 0.05
    env.close()


@pytest.mark.slow
def test_action_scaling_matches_the_environment(gym):
    env = make_env(
        gym,
        0,
        action={
            "type": "ContinuousAction",
            "longitudinal": True,
            "lateral": True,
            "steering_range": [-0.6, 0.6],
            "acceleration_range": [-3.0, 4.0],
        },
    )
    sc = ActionScaling.from_env(env)
    assert sc.steering_range_rad == (-0.6, 0.6) and sc.acceleration_range_mps2 == (-3.0, 4.0)
    at = env.unwrapped.action_type
    for steer, accel in [(0.3, 1.2), (-0.6, -3.0), (0.0, 0.0), (0.55, 3.9)]:
        applied = at.get_action(sc.to_action(steer, accel))
        assert float(applied["steering"]) == pytest.approx(steer, abs=1e-6)
        assert float(applied["acceleration"]) == pytest.approx(accel, abs=1e-6)
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_mpc_drives_the_empty_racetrack_on_the_road(gym, seed):
    env = make_env(gym, seed, other_vehicles=0)
    driver = HighwayEnvMpcDriver(env, DriverSettings(v_ref_mps=10.0))
    vehicle = env.unwrapped.vehicle
    assert driver.model.params.lf_m == driver.model.params.lr_m == vehicle.LENGTH / 2
    drive = drive_env(env, driver, 300)
    r = drive.result
    assert r.steps == 300, "the episode ended early (off the road or crashed)"
    assert drive.on_road.all() and not drive.crashed and not drive.terminated
    assert r.s_m[-1] - r.s_m[0] > driver.path.length_m  # more than a lap
    m = compute_metrics(r)
    assert m["solver_failures"] == 0 and m["fallbacks"] == 0
    assert m["max_abs_lateral_error_m"] < 0.5 and m["max_lane_excess_m"] == 0.0
    assert np.all(np.abs(r.steer_rad) <= driver.scaling.steering_range_rad[1] + 1e-9)
    assert np.abs(r.v_mps[20:] - 10.0).max() < 0.5
    # the controller's model is the environment's vehicle: one-step predictions come true
    yaw_err = np.abs(r.X_pred[:-1, 1, 2] - r.x[1:, 2])
    pos_err = np.hypot(*(r.X_pred[:-1, 1, :2] - r.x[1:, :2]).T)
    assert yaw_err.max() < 1e-3 and pos_err.max() < 0.1
    env.close()


@pytest.mark.slow
def test_steering_only_keeps_the_speed_and_the_road(gym):
    env = make_env(
        gym, 2, other_vehicles=0, action={"type": "ContinuousAction", "longitudinal": False, "lateral": True}
    )
    driver = HighwayEnvMpcDriver(env)
    assert driver.model.nx == 3 and not driver.scaling.longitudinal
    drive = drive_env(env, driver, 150)
    assert drive.result.steps == 150 and drive.on_road.all() and not drive.crashed
    assert np.ptp(drive.result.v_mps) == 0.0
    assert np.max(np.abs(drive.result.e_y_m)) < 0.5
    env.close()


@pytest.mark.slow
def test_a_vehicle_becomes_its_rectangle_moving_at_its_velocity(gym):
    env = make_env(gym, 1, other_vehicles=10)
    u = env.unwrapped
    others = [v for v in u.road.vehicles if v is not u.vehicle]
    assert len(others) >= 3
    for v in others:
        ob = vehicle_obstacle(v, t_s=3.0)  # the controller's clock reads 3 s now
        assert ob.pose_at(3.0) == pytest.approx((v.position[0], v.position[1], v.heading), abs=1e-12)
        # the same corners as highway-env's own collision polygon
        corners = ob.at(3.0).points
        theirs = v.polygon()[:4]
        assert sorted(map(tuple, np.round(corners, 9))) == sorted(map(tuple, np.round(theirs, 9)))
        np.testing.assert_allclose(np.ptp(ob.shape.points, axis=0), [v.LENGTH, v.WIDTH])
        # a constant velocity: highway-env's speed along the heading
        x0, y0, h0 = ob.pose_at(3.0)
        x1, y1, h1 = ob.pose_at(3.5)
        np.testing.assert_allclose([(x1 - x0) / 0.5, (y1 - y0) / 0.5], v.velocity, atol=1e-9)
        assert h1 == h0 and math.hypot(*v.velocity) == pytest.approx(v.speed)
    env.close()


@pytest.mark.slow
def test_lane_following_prediction_stays_on_the_lane_and_comes_true(gym):
    """The predicted rectangles start at the vehicles' poses, keep to their lanes through the
    bends (where a straight line leaves the road) and are where highway-env drives them 1 s on."""
    env = make_env(gym, 1, other_vehicles=10)
    u = env.unwrapped
    driver = HighwayEnvMpcDriver(env, DriverSettings(v_ref_mps=10.0))
    others = driver.others
    net = u.road.network
    times = np.arange(0.0, 3.01, 0.2)
    obs = driver.plant.traffic(t_s=2.0)
    straight_off_road = 0
    for v, ob in zip(others, obs):
        assert ob.pose_at(2.0) == pytest.approx((v.position[0], v.position[1], v.heading), abs=1e-9)
        for t in times[5:]:  # after 1 s: any offset from the lane centre has mostly decayed
            x, y, _ = ob.pose_at(2.0 + t)
            lane = net.get_lane(net.get_closest_lane_index(np.array([x, y])))
            assert abs(lane.local_coordinates(np.array([x, y]))[1]) < 0.5 * lane.width_at(0.0)
        xs, ys, _ = vehicle_obstacle(v, 2.0).pose_at(5.0)
        lane = net.get_lane(net.get_closest_lane_index(np.array([xs, ys])))
        straight_off_road += not lane.on_lane(np.array([xs, ys]))
    assert straight_off_road >= 1  # the straight-line prediction leaves the road within 3 s
    # drive 1 s (5 policy steps): the vehicles are where the prediction put them
    predicted = [ob.pose_at(2.0 + 1.0) for ob in obs]
    assert drive_env(env, driver, 5).result.steps == 5
    err = [math.hypot(v.position[0] - p[0], v.position[1] - p[1]) for v, p in zip(others, predicted)]
    assert max(err) < 1.0, err
    env.close()


def drive_among_other_vehicles(gym, seed: int, settings: DriverSettings = DriverSettings(), steps: int = 300):
    env = make_env(gym, seed, other_vehicles=10)
    driver = HighwayEnvMpcDriver(env, settings)
    drive = drive_env(env, driver, steps)
    env.close()
    return driver, drive


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 7])
def test_mpc_drives_among_other_vehicles_without_a_crash(gym, seed):
    """300 policy steps (60 s, over a lap) among highway-env's IDM cars: no crash, never off the
    road, in its lane; the cars came near and were avoided as obstacles (passed in the next lane,
    followed in its own)."""
    driver, drive = drive_among_other_vehicles(gym, seed)
    r = drive.result
    assert len(driver.others) >= 4
    assert r.steps == 300, "the episode ended early (off the road or crashed)"
    assert not drive.crashed and drive.on_road.all() and not drive.terminated
    m = compute_metrics(r)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] == pytest.approx(drive.clearance_m.min())
    assert 0.5 < drive.clearance_m.min() < 3.0  # close, and clear of them
    assert (drive.considered > 0).sum() > 100 and drive.considered.max() >= 2
    assert m["solver_failures"] == 0 and m["fallbacks"] == 0
    assert m["max_abs_lateral_error_m"] < 0.5 and m["max_lane_excess_m"] == 0.0
    assert r.v_mps.min() < 9.0  # slowed down behind a slower car at least once
    assert r.s_m[-1] - r.s_m[0] > 0.9 * driver.path.length_m


# --------------------------------------------------------------------------- highway-v0
def test_highway_road_is_the_lanes_along_the_route_lane(gym):
    """highway-v0's four straight lanes become a Road along the ego's lane (offsets +-4 m
    apart), with a path per lane for the other vehicles' predictions."""
    from highway_env.road.road import RoadNetwork

    from mpcdrive.adapters.highway_env import straight_road

    net = RoadNetwork.straight_road_network(4)
    road, path, paths = straight_road(net, ("0", "1", 1))
    assert road.route_lane == 1 and len(road.lanes) == 4 and len(paths) == 4
    np.testing.assert_allclose([ln.center_m[0] for ln in road.lanes], [-4.0, 0.0, 4.0, 8.0])
    np.testing.assert_allclose(road.edges(100.0), (10.0, -6.0))
    assert paths[("0", "1", 3)].project(np.array([50.0, 12.0])) == pytest.approx((50.0, 0.0))


@pytest.mark.slow
def test_highway_v0_overtakes_a_slower_car_without_a_crash(gym):
    """highway-v0 with its default traffic (50 IDM/MOBIL cars, all slower than the ego wants):
    the MPC with the maneuver planner stays on the road, never crashes, and in a seed where
    a slower car is ahead it changes lanes and passes a car that was ahead of it in its lane."""
    from mpcdrive.adapters.highway_env import highway_config
    from mpcdrive.adapters.highway_eval import highway_episode

    env = gym.make("highway-v0", config=highway_config(duration_s=40.0))
    ep = highway_episode(env, 11)  # a seed with slower cars ahead of the ego in its lane
    env.close()
    assert ep.steps == 200 and not ep.crashed and ep.off_road_steps == 0
    assert ep.lane_changes >= 1 and ep.overtakes >= 1
    assert ep.mean_speed_mps > 20.0
    # the closed loop's own accounting agrees: no contact, inside the road's lanes, every solve ok
    m = compute_metrics(ep.result)
    assert m["steps"] == 200 and m["termination"] == "truncated"  # highway-env's 40 s ran out
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.5
    assert m["max_lane_excess_m"] == 0.0 and m["solver_failures"] == 0 and m["fallbacks"] == 0
    assert not run_verdict(m).unsafe


class FullThrottle:
    """Straight ahead at full acceleration, blind to the traffic (N = 0)."""

    nx, nu, N, dt_s = 4, 2, 0, 0.2

    def initial_warm(self, x0):
        return WarmStart(s_m=0.0, u_prev=np.zeros(2))

    def step(self, x, warm):
        X = np.asarray(x, float)[None, :]
        u = np.array([0.0, 5.0])
        return ControlOutput(u, "ok", "", 0.0, float(x[0]), 0.0, 0.0, X, X, WarmStart(0.0, u, t_s=warm.t_s + 0.2))


@pytest.mark.slow
def test_highway_env_is_the_plant_and_its_crash_ends_the_run(gym):
    """The environment as sim.simulate's plant: its state, its step, its traffic and its end;
    a blind ego at full throttle runs into the car ahead, and the run's accounting says so."""
    from mpcdrive.adapters.highway_env import HighwayEnvPlant, highway_config, straight_road
    from mpcdrive.sim import simulate
    from mpcdrive.sim.closed_loop import EpisodicPlant, ObservedPlant, TrafficPlant

    env = gym.make("highway-v0", config=highway_config(duration_s=40.0))
    env.reset(seed=3)
    plant = HighwayEnvPlant(env, prediction="constant_velocity")
    assert all(isinstance(plant, P) for P in (ObservedPlant, TrafficPlant, EpisodicPlant))
    assert len(plant.traffic(0.0)) == len(plant.others) >= 40
    x = plant.state()
    with pytest.raises(ValueError, match="x0"):
        plant.initial_state(x + 1.0)
    with pytest.raises(ValueError, match="policy period"):
        plant.step(x, [0.0, 0.0], 0.1)
    road, path, _ = straight_road(env.unwrapped.road.network, plant.lane_index)
    r = simulate(FullThrottle(), plant, path, x, plant.dt_s, 200, road=road, footprint=plant.footprint)
    assert r.steps < 200 and r.meta["termination"] == "collision" and env.unwrapped.vehicle.crashed
    assert plant.records[-1].crashed and plant.ended(r.x_final) == "collision"
    m = compute_metrics(r)
    assert m["collisions"] >= 1 and run_verdict(m).collided
    with pytest.raises(ValueError, match="current ego state"):
        plant.step(x, [0.0, 0.0], plant.dt_s)
    env.close()
