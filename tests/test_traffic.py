"""Traffic rules of the obstacle terms: lifetimes (an obstacle exists only over its time span),
traffic behind (a car following in the ego's lane is not avoided as if it were ahead) and the
yield rule (a car crossing the road is yielded to; one driving along it is not)."""

import numpy as np
import pytest

from mpcdrive.scenarios import build_experiment, run_experiment, validate_scenario_data
from mpcdrive.scene.obstacles import Circle, Obstacle
from mpcdrive.sim import compute_metrics

BASE = {
    "id": "traffic",
    "dt_s": 0.1,
    "duration_s": 10.0,
    "vehicle": {"model": "kinematic4", "preset": "commonroad_bmw_320i", "speed_mps": 10.0},
    "path": {"type": "straight", "start": [0, 0], "end": [200, 0]},
    "road": {"lane_width_m": 3.5, "margin_m": 0.1},
    "initial_state": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0, "v_mps": 10.0},
    "avoidance": {"formulation": "hard", "margin_m": 0.3, "influence_m": 40.0},
    "controller": {
        "horizon": 30,
        "Q": [1, 1, 2, 1],
        "R": [10, 0.1],
        "Rc": [100, 1],
        "max_steer_deg": 30,
        "accel_limits_mps2": [-6, 3],
        "speed_limits_mps": [0, 15],
        "reference_speed_mps": 10.0,
        "horizon_step_m": 1.0,
    },
}


def drive(obstacles, **top):
    spec = validate_scenario_data({**BASE, **top, "obstacles": obstacles}, "traffic.yaml")
    exp = build_experiment(spec)
    r = run_experiment(exp)
    return r, compute_metrics(r)


def car(x, y, vx, **kw):
    return {"shape": "rectangle", "position": [x, y], "length_m": 4.5, "width_m": 1.8, "velocity_mps": [vx, 0.0], **kw}


def test_a_car_following_in_the_lane_causes_no_swerve_and_no_braking():
    """A faster car 25 m behind in the ego's lane, closing at 2 m/s. It is kept behind by a
    longitudinal row only: the ego never swerves or brakes for it (a lateral half-plane from the
    nearest point, as for a car ahead, pushed it sideways), and it keeps ahead of it no further
    than its own references go: it does not speed away from it either (the follower keeps its
    distance; before, the row pushed the ego to full throttle, on DEU_Salzwedel-107_1 into a
    left turn)."""
    r, m = drive([car(-25.0, 0.0, 12.0, name="follower")])
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.3
    assert np.max(np.abs(r.e_y_m)) < 0.01
    assert np.min(r.v_mps) > 10.0 - 0.02 and np.max(r.v_mps) < 10.0 + 0.05


def test_a_car_passing_in_the_next_lane_is_still_avoided_and_the_ego_keeps_its_lane():
    r, m = drive([car(-25.0, 2.2, 16.0, name="passer")], duration_s=8.0)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.3
    assert m["max_lane_excess_m"] == 0.0


def test_an_obstacle_that_appears_after_the_car_passed_is_not_avoided():
    """A rock on the path at x = 20 m that only exists from t = 6 s on (the car is there at 2 s)."""
    rock = {"shape": "circle", "position": [20.0, 0.0], "radius_m": 0.5, "name": "rock"}
    r, m = drive([{**rock, "lifetime_s": [6.0, 100.0]}], duration_s=4.0)
    assert np.max(np.abs(r.e_y_m)) < 0.01 and m["collisions"] == 0
    r0, m0 = drive([rock], duration_s=4.0)  # always there: the car must go around or stop
    assert m0["collisions"] == 0 and (np.max(np.abs(r0.e_y_m)) > 0.5 or r0.x[-1, 0] < 20.0)


def test_an_obstacle_that_vanished_is_neither_avoided_nor_hit():
    """A parked car at x = 30 m that leaves the scenario at t = 1 s (a CommonRoad vehicle's recording
    ends): the ego drives through where it was, without a collision counted."""
    r, m = drive([car(30.0, 0.0, 0.0, name="gone", lifetime_s=[0.0, 1.0])], duration_s=5.0)
    assert r.x[-1, 0] > 40.0
    assert np.max(np.abs(r.e_y_m)) < 0.01
    assert m["collisions"] == 0


def test_lifetime_in_the_core_and_the_schema():
    ob = Obstacle(Circle(1.0), (0.0, 0.0, 0.0), t_start_s=1.0, t_end_s=2.0)
    assert ob.has_lifetime and not ob.present(0.5) and ob.present(1.0) and ob.present(2.0) and not ob.present(2.1)
    assert list(ob.present(np.array([0.0, 1.5, 3.0]))) == [False, True, False]
    assert not Obstacle(Circle(1.0), (0.0, 0.0, 0.0)).has_lifetime
    with pytest.raises(ValueError, match="t_start_s <= t_end_s"):
        Obstacle(Circle(1.0), (0.0, 0.0, 0.0), t_start_s=2.0, t_end_s=1.0)
    with pytest.raises(ValueError, match="lifetime_s"):
        validate_scenario_data({**BASE, "obstacles": [car(30.0, 0.0, 0.0, lifetime_s=[3.0, 1.0])]}, "t.yaml")


def test_a_crossing_car_is_yielded_to_not_swerved_around():
    """A car crossing the ego's road at 5 m/s, timed to meet it (both at x = 30 m at t = 3 s).
    The ego yields: it slows and lets it cross, keeps its lane (no swerve around or rush ahead
    of it) and goes on once it is clear, without contact."""
    crossing = {
        "shape": "rectangle",
        "position": [30.0, -15.0],
        "length_m": 4.5,
        "width_m": 1.8,
        "yaw_deg": 90.0,
        "velocity_mps": [0.0, 5.0],
        "name": "crossing",
    }
    r, m = drive([crossing], duration_s=8.0)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.3
    assert np.max(np.abs(r.e_y_m)) < 0.3  # no swerve
    assert np.min(r.v_mps) < 6.0 and np.max(r.v_mps) <= 10.0 + 0.05  # slowed for it, never rushed
    assert r.x[-1, 0] > 45.0  # and went on after it


def _lane_change_path(shift_m: float = -3.5, start_m: float = 30.0, length_m: float = 40.0):
    """Waypoints (every metre to x = 150 m) of a path that moves over a lane: straight along y = 0,
    a cosine ramp to y = ``shift_m`` over ``length_m`` from x = ``start_m``, then straight on
    (a CommonRoad route changing lanes is such a path), and the y of the path at each point."""
    x = np.arange(0.0, 151.0)
    ramp = np.clip((x - start_m) / length_m, 0.0, 1.0)
    y = shift_m * 0.5 * (1.0 - np.cos(np.pi * ramp))
    return np.column_stack([x, y]), y


@pytest.mark.parametrize("backend", ["fast", "osqp"])
def test_a_car_along_its_lane_where_the_path_moves_over_a_lane_is_not_yielded_to(backend):
    """Two 3.5 m lanes; the path moves from the left one into the right one over 40 m, where a car
    a little faster than the ego drives straight along the right one, beside it. In the path's
    frame that car drifts sideways at the path's slope (up to 1.5 m/s, above the crossing speed
    of the yield rule): it must not be taken for a crossing car (a stop row before a car beside
    cannot be kept: the ego braked at full force, yawed its nose away from it and left the road
    by 0.7 m). It is avoided as a car driving along the road: the ego keeps beside it in the left
    lane, neither braking nor swerving, and stays on the road."""
    points, y = _lane_change_path()
    # the road: both lanes, as offsets from the path (the path's slope is at most 0.14: the normal
    # offsets are the lateral ones to within 1 %)
    widths = [[float(x), 1.75 - float(yy), 5.25 + float(yy)] for (x, _), yy in zip(points, y)]
    r, m = drive(
        [car(-1.0, -3.5, 11.0, name="beside")],
        duration_s=8.0,
        path={"type": "waypoints", "points": points.tolist(), "ds_m": 0.2},
        road={"widths": widths, "margin_m": 0.1},
        controller={**BASE["controller"], "backend": backend},
    )
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.3
    assert m["max_lane_excess_m"] == 0.0
    assert np.min(r.accel_mps2) > -3.0  # no braking for it
    assert np.max(np.abs(r.yaw_rad)) < 0.15  # no swerve: the lane runs along x
