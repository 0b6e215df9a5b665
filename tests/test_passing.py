"""Passing through a neighbour lane (the maneuver planner, planning.driver.PlannedMpc, on a road
with ``neighbours``): a parked car in the route lane with the left lane free is passed and the
car comes back; with both lanes blocked it stops before the obstacles without contact."""

from __future__ import annotations

import numpy as np
import pytest

from mpcdrive.planning.driver import PlannedMpc
from mpcdrive.scenarios import build_experiment, run_experiment
from mpcdrive.scenarios.schema import ScenarioSpec
from mpcdrive.sim import LANE_TOLERANCE_M, compute_metrics


def _spec(obstacles, backend="fast", neighbours=True) -> dict:
    """A straight two-lane road (3.5 m lanes, the route the right one), a BMW at 10 m/s."""
    road = {"lane_width_m": 3.5, "margin_m": 0.1}
    if neighbours:
        road["neighbours"] = [[0.0, 3.5, 0.0]]
    return {
        "id": "pass",
        "dt_s": 0.1,
        "duration_s": 14.0,
        "vehicle": {"model": "kinematic4", "preset": "commonroad_bmw_320i", "speed_mps": 10.0},
        "path": {"type": "straight", "start": [0.0, 0.0], "end": [160.0, 0.0]},
        "road": road,
        "initial_state": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0, "v_mps": 10.0},
        "obstacles": obstacles,
        "avoidance": {"formulation": "hard", "margin_m": 0.3, "max_obstacles": 4, "influence_m": 40.0},
        "controller": {
            "horizon": 30,
            "Q": [1.0, 1.0, 2.0, 1.0],
            "R": [10.0, 0.1],
            "Rc": [100.0, 1.0],
            "max_steer_deg": 30.0,
            "max_steer_rate_deg_s": 22.9,  # CommonRoad: 0.4 rad/s = 22.92 deg/s at most
            "accel_limits_mps2": [-8.0, 3.0],
            "speed_limits_mps": [0.0, 12.0],
            "horizon_step_m": 0.5,
            "backend": backend,
        },
    }


PARKED = {"shape": "rectangle", "position": [50.0, 0.0], "length_m": 4.5, "width_m": 1.8, "name": "parked"}
BESIDE = {"shape": "rectangle", "position": [50.0, 3.5], "length_m": 4.5, "width_m": 1.8, "name": "beside"}


@pytest.mark.parametrize("backend", ["fast", "osqp"])
def test_parked_car_with_a_free_neighbour_lane_is_passed(backend):
    exp = build_experiment(ScenarioSpec.model_validate(_spec([PARKED], backend)))
    assert isinstance(exp.controller, PlannedMpc)
    # the planner knows the margin the controller's obstacle rows keep (its relations use it)
    limits = exp.controller.planner.limits
    assert limits.disc_margin_m == exp.controller.mpc.avoidance.config.margin_m
    res = run_experiment(exp)
    m = compute_metrics(res)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.2
    assert m["max_lane_excess_m"] <= LANE_TOLERANCE_M  # inside the two lanes
    assert res.x_final[0] > 80.0  # past the parked car, on its way
    assert res.e_y_m.max() > 1.5  # over in the left lane beside it
    assert abs(res.e_y_m[-1]) < 0.2  # and back in the route lane
    # metrics.json["planner"]: a replanning every control step, what each checked and cost
    p = m["planner"]
    assert p["replannings"] == m["steps"] and p["unsafe"] == 0
    assert 0 < p["checked"]["p50"] <= p["sampled"]["p50"] and p["checked"]["max"] <= p["sampled"]["max"]
    assert 0 < p["plan_time_us"]["p50"] <= p["plan_time_us"]["p99"] <= p["plan_time_us"]["max"]


def test_the_step_time_includes_the_planning():
    """solve_time_s is the whole step's: with an MPC that reports no time at all, the planned
    controller's steps still take the replanning's time."""
    import dataclasses

    exp = build_experiment(ScenarioSpec.model_validate(_spec([PARKED], "fast")))
    mpc = exp.controller.mpc
    inner = mpc.step
    mpc.step = lambda x, warm: dataclasses.replace(inner(x, warm), solve_time_s=0.0)
    warm = exp.controller.initial_warm(exp.x0)
    out = exp.controller.step(np.asarray(exp.x0, float), warm)
    assert out.status == "ok" and out.solve_time_s > 0.0


def test_without_a_neighbour_lane_it_stops_behind_the_parked_car():
    res = run_experiment(build_experiment(ScenarioSpec.model_validate(_spec([PARKED], neighbours=False))))
    m = compute_metrics(res)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.0
    assert res.x_final[0] < 50.0 - 2.25 and res.v_mps[-1] < 0.1


@pytest.mark.parametrize("backend", ["fast", "osqp"])
def test_both_lanes_blocked_stops_before_them_with_clearance(backend):
    # it closes up to the standstill gap at a walking pace (a stop anywhere behind costs the
    # same: the road is blocked for good), then waits; a creep further back costs less than a stop
    # (it is not bound for a standstill), so it creeps up from where it first slowed: standing by
    # 28 s from 10 m/s (by 20 s when a stop further back was free)
    exp = build_experiment(ScenarioSpec.model_validate(_spec([PARKED, BESIDE], backend) | {"duration_s": 32.0}))
    res = run_experiment(exp)
    m = compute_metrics(res)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.0
    assert res.x_final[0] < 50.0 - 2.25 and res.v_mps[-1] < 0.1
    assert m["max_lane_excess_m"] <= LANE_TOLERANCE_M
    # it braked at the vehicle's capability when it had to, never beyond
    assert np.min(res.accel_mps2) >= -8.0 - 1e-9
    assert exp.controller.maneuver.v_mps.max() < 0.1  # waiting


def _both_solvers(neighbours: bool):
    """The compiled and the OSQP controller (at 1e-9) of the free road of :func:`_spec`."""
    fast = build_experiment(ScenarioSpec.model_validate(_spec([], backend="fast", neighbours=neighbours))).mpc
    spec_osqp = ScenarioSpec.model_validate(
        _spec([], backend="osqp", neighbours=neighbours)
        | {"controller": {**_spec([])["controller"], "backend": "osqp", "osqp_eps": 1e-9}}
    )
    osqp = build_experiment(spec_osqp).mpc
    assert (fast.backend_name, osqp.backend_name) == ("fast", "osqp")
    return fast, osqp


def test_lateral_reference_is_tracked_the_same_by_both_solvers():
    """set_lateral_reference: the path shifted 1 m to the left; the compiled controller (two
    stages, the offsets written between them) gives OSQP's commands at the same states, and the
    car settles 1 m left of the path."""
    from mpcdrive.sim import Plant

    fast, osqp = _both_solvers(neighbours=True)
    road = build_experiment(ScenarioSpec.model_validate(_spec([], neighbours=True))).road
    for c in (fast, osqp):
        c.set_road(road.band([1, 2]))  # the route and the left lane
        c.set_lateral_reference(lambda s: np.ones_like(np.asarray(s, float)))
    plant = Plant(osqp.model)
    x = np.array([0.0, 0.0, 0.0, 10.0])
    wf, wo = fast.initial_warm(x), osqp.initial_warm(x)
    for _ in range(60):
        of, oo = fast.step(x, wf), osqp.step(x, wo)
        assert of.status == "ok" and oo.status == "ok"
        np.testing.assert_allclose(of.u, oo.u, atol=1e-4)
        wf, wo = of.warm, oo.warm
        x = plant.step(x, oo.u, 0.1)
    assert abs(oo.e_y_m - 1.0) < 0.05


def test_speed_cap_is_kept_the_same_by_both_solvers():
    """set_speed_cap: 10 m/s references capped at 4 m/s, reached braking at 2 m/s^2: the compiled
    controller (two stages, the capped references placed between them) gives OSQP's commands at
    the same states, and the car settles at the cap; None lifts it; bad caps are refused."""
    from mpcdrive.sim import Plant

    fast, osqp = _both_solvers(neighbours=False)
    for c in (fast, osqp):
        c.set_speed_cap(4.0, 2.0)
    plant = Plant(osqp.model)
    x = np.array([0.0, 0.0, 0.0, 10.0])
    wf, wo = fast.initial_warm(x), osqp.initial_warm(x)
    for k in range(60):
        of, oo = fast.step(x, wf), osqp.step(x, wo)
        assert of.status == "ok" and oo.status == "ok"
        np.testing.assert_allclose(of.u, oo.u, atol=1e-4)
        np.testing.assert_allclose(of.refs[:, 3], oo.refs[:, 3], atol=1e-9)
        if k == 0:  # references: down from 10 m/s at 2 m/s^2 to the cap
            np.testing.assert_allclose(oo.refs[:4, 3], [10.0, 9.8, 9.6, 9.4], atol=1e-9)
            assert oo.refs[-1, 3] == pytest.approx(4.0)
        wf, wo = of.warm, oo.warm
        x = plant.step(x, oo.u, 0.1)
    assert abs(x[3] - 4.0) < 0.1
    for c in (fast, osqp):
        c.set_speed_cap(None)
        assert c.step(x, wo).refs[-1, 3] > 9.0
        for bad in (-1.0, float("nan")):
            with pytest.raises(ValueError, match="speed cap"):
                c.set_speed_cap(bad)
        with pytest.raises(ValueError, match="braking"):
            c.set_speed_cap(3.0, 0.0)


def test_a_route_lane_wider_than_the_lane_of_the_path_does_not_pull_the_car_off_the_path():
    """The route lane's table two lanes wide, the path in its left one (a CommonRoad route moving
    over a lane: its lanelets side by side), a neighbour lane to the left: on a free road the car
    drives along the path (its lateral reference is the path, not the table's middle 1.75 m to
    the right, and not shifted by it either: the car was pulled 1.75 m to the left)."""
    spec = _spec([])
    spec["road"] = {"widths": [[0.0, 1.75, 5.25]], "neighbours": [[0.0, 3.5, 0.0]], "margin_m": 0.1}
    exp = build_experiment(ScenarioSpec.model_validate(spec))
    assert isinstance(exp.controller, PlannedMpc)
    res = run_experiment(exp)
    assert np.max(np.abs(res.e_y_m)) < 0.05
    assert compute_metrics(res)["max_lane_excess_m"] == 0.0


def test_every_planner_setting_is_reachable_from_yaml_and_bad_ones_are_refused():
    """``planner`` sets the maneuver planner's PlannerConfig by its field names (each field, changed
    from its default, arrives) and ``replan_s`` its replanning period; unknown names and bad values
    are refused with the reason."""
    import dataclasses

    from mpcdrive.planning import PlannerConfig
    from mpcdrive.scenarios.loader import ScenarioError, validate_scenario_data

    exp = build_experiment(ScenarioSpec.model_validate(_spec([PARKED])))
    assert exp.controller.config == PlannerConfig() and exp.controller.replan_s == 0.0
    changed = {
        "lateral_s": [3.0, 5.0],
        "speed_s": [2.5],
        "oncoming": True,
        "horizon_s": 5.0,
        "dt_s": 0.25,
    }
    for f in dataclasses.fields(PlannerConfig):
        value = changed[f.name] if f.name in changed else getattr(PlannerConfig(), f.name) * 1.5 + 0.5
        spec = _spec([PARKED]) | {"planner": {f.name: value, "replan_s": 0.3}}
        c = build_experiment(ScenarioSpec.model_validate(spec)).controller
        got = getattr(c.config, f.name)
        assert got == (tuple(value) if isinstance(value, list) else pytest.approx(value)), f.name
        assert c.replan_s == 0.3
    for planner, words in (
        ({"time_gap": 1.0}, "unknown planner setting"),
        ({"margin_m": -1.0}, "margin_m"),
        ({"replan_s": 0.8}, "replan_s"),
    ):
        with pytest.raises(ScenarioError, match=words):
            validate_scenario_data(_spec([PARKED]) | {"planner": planner}, "planner.yaml")


def test_a_pass_through_the_free_oncoming_lane_is_driven_without_braking():
    """A car standing in the route lane 40 m ahead, the lane to the left oncoming and free, the
    planner allowed to use it: the car passes at speed. A pass ends on the route lane's line it
    starts from, and was handed to the controller as that line (judged 1 m ahead, where the move
    had barely begun): the car stayed in its lane, replanned the pass from there at every
    replanning and braked for the blockage."""
    spec = _spec([dict(PARKED, position=[40.0, 0.0])])
    spec["road"] = {
        "lane_width_m": 3.5,
        "margin_m": 0.1,
        "lane_rows": [{"name": "oncoming", "oncoming": True, "rows": [[0.0, 5.25, 1.75]]}],
    }
    spec["planner"] = {"oncoming": True}
    exp = build_experiment(ScenarioSpec.model_validate(spec))
    res = run_experiment(exp)
    m = compute_metrics(res)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.2
    assert m["max_lane_excess_m"] <= LANE_TOLERANCE_M
    assert res.e_y_m.max() > 1.75  # over in the oncoming lane beside it
    assert res.x[:, 3].min() > 8.0  # at speed: no braking for the blockage
    assert abs(res.e_y_m[-1]) < 0.2  # and back in its own lane
