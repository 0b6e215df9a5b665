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
    lane_sequence,
    racetrack_config,
)
from mpcdrive.sim import compute_metrics

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


@pytest.mark.parametrize("kwargs, field", [
    ({"steering_range_rad": (0.5, -0.5)}, "steering_range_rad"),
    ({"acceleration_range_mps2": (1.0, float("nan"))}, "acceleration_range_mps2"),
])
def test_action_scaling_rejects_bad_ranges(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ActionScaling(**kwargs)
    with pytest.raises(ValueError, match="finite"):
        ActionScaling().to_action(float("nan"))
    with pytest.raises(ValueError, match="2 component"):
        ActionScaling().from_action([0.1])


def test_racetrack_config_checks_its_numbers():
    cfg = racetrack_config(steering_range_rad=(-0.6, 0.6), policy_frequency_hz=5, simulation_frequency_hz=15)
    assert cfg["other_vehicles"] == 0
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
    env = make_env(gym, 0)
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
    lateral = [min(abs(lane.local_coordinates(p)[1]) for lane in lanes if lane.on_lane(p))
               for p in path.position(s)]
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
    env = make_env(gym, 0, action={"type": "ContinuousAction", "longitudinal": True, "lateral": True,
                                   "steering_range": [-0.6, 0.6], "acceleration_range": [-3.0, 4.0]})
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
def test_mpc_drives_the_racetrack_on_the_road(gym, seed):
    env = make_env(gym, seed)
    driver = HighwayEnvMpcDriver(env, DriverSettings(v_ref_mps=10.0))
    vehicle = env.unwrapped.vehicle
    assert driver.model.params.lf_m == driver.model.params.lr_m == vehicle.LENGTH / 2
    drive = drive_env(env, driver, 300)
    r = drive.result
    assert r.steps == 300, "the episode ended early (off the road or crashed)"
    assert drive.on_road.all() and not drive.crashed and not drive.terminated
    assert r.s_m[-1] - r.s_m[0] > driver.path.length_m  # more than a lap
    m = compute_metrics(r, drive.footprint)
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
    env = make_env(gym, 2, action={"type": "ContinuousAction", "longitudinal": False, "lateral": True})
    driver = HighwayEnvMpcDriver(env)
    assert driver.model.nx == 3 and not driver.scaling.longitudinal
    drive = drive_env(env, driver, 150)
    assert drive.result.steps == 150 and drive.on_road.all() and not drive.crashed
    assert np.ptp(drive.result.v_mps) == 0.0
    assert np.max(np.abs(drive.result.e_y_m)) < 0.5
    env.close()


@pytest.mark.slow
def test_driver_refuses_other_vehicles(gym):
    # TODO(obstacles): drive among other vehicles once the controller avoids obstacles
    env = make_env(gym, 0, other_vehicles=1)
    with pytest.raises(ValueError, match="obstacle avoidance is not supported yet"):
        HighwayEnvMpcDriver(env)
    env.close()
