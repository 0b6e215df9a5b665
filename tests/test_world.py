"""The world lives in one object: the controller is built with a scene (road, obstacles, body)
and simulate judges the drive against it, so the accounting cannot be left out; a scene given to
simulate that is not the controller's is an error naming what differs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mpcdrive.control import DelayCompensator, LtvMpc, StateAdapter
from mpcdrive.models import KinematicBicycle3
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import StraightPath
from mpcdrive.scene import Circle, Footprint, Lane, Obstacle, Road, Scene
from mpcdrive.sim import Plant, SteeringActuator, compute_metrics, simulate

MODEL = KinematicBicycle3(v_mps=1.0)
PATH = StraightPath([0.0, 0.0], [3.0, 0.0])
BODY = Footprint(0.5, 0.27)


def _rock() -> Obstacle:
    return Obstacle(Circle(0.3), (1.52, 0.0, 0.0), name="rock")


def _problem(road: Road | None = None) -> MpcProblem:
    return MpcProblem(3, 1, 10, 0.05, Q=[1, 1, 1], R=1.0, u_min=-1.0, u_max=1.0, road=road)


def _blind(**kw) -> LtvMpc:
    """An MPC that knows the rock but gives it no weight (the potential cost at weight 0): the
    car drives straight into it at t = 0.97 s."""
    from mpcdrive.ocp import AvoidanceConfig

    return LtvMpc(MODEL, PATH, kw.pop("problem", _problem()), avoidance=AvoidanceConfig("potential", weight=0.0), **kw)


def _drive(ctrl, steps: int = 40, **kw):
    return simulate(ctrl, Plant(MODEL), PATH, [0.0, 0.0, 0.0], 0.05, steps, **kw)


def test_a_drive_is_judged_against_the_controllers_world_when_simulate_is_given_none():
    """The older way of building (the road in the problem, obstacles= and footprint=): simulate
    without them still counts the collision and measures the road (they were silently dropped)."""
    road = Road.constant(1.0)
    mpc = _blind(problem=_problem(road), obstacles=(_rock(),), footprint=BODY)
    m = compute_metrics(_drive(mpc))
    assert m.road_given and m.min_obstacle_clearance_m is not None
    assert m.collisions == 1 and m.collision_events[0].name == "rock"
    assert m.goal_reached is False


def test_the_controller_keeps_the_scene_it_was_built_with():
    scene = Scene(Road.constant(1.0), (_rock(),), BODY)
    mpc = _blind(scene=scene)
    assert mpc.scene is scene and mpc.problem.road is scene.road
    assert mpc.footprint == BODY and [o.name for o in mpc.obstacles] == ["rock"]
    r = _drive(mpc)
    assert r.lane_excess_m is not None and r.meta["collisions"] == 1
    # fresh predictions change what the controller avoids, not the world it is judged in
    mpc.set_obstacles((Obstacle(Circle(0.3), (1.52, 5.0, 0.0), name="rock"),))
    assert mpc.scene is scene and compute_metrics(_drive(mpc)).collisions == 1


def test_the_same_world_given_again_is_accepted():
    mpc = _blind(scene=Scene(Road.constant(1.0), (_rock(),), BODY))
    again = Scene(Road.constant(1.0, margin_m=0.2), (_rock(),), Footprint(0.5, 0.27, n_discs=5))  # by value
    assert compute_metrics(_drive(mpc, scene=again)).collisions == 1
    assert compute_metrics(_drive(mpc, obstacles=(_rock(),), footprint=BODY)).collisions == 1


@pytest.mark.parametrize(
    "given, words",
    [
        (dict(scene=Scene(Road.constant(1.0), (), BODY)), "obstacles: 1 vs 0"),
        (dict(obstacles=(Obstacle(Circle(0.3), (1.6, 0.0, 0.0), name="rock"),)), r"obstacles\[0\] \(rock vs rock\)"),
        (dict(road=Road.constant(2.0)), "road: different edges"),
        (dict(scene=Scene(None, (_rock(),), BODY)), "road: a road vs none"),
        (dict(footprint=Footprint(4.5, 1.8)), "footprint: 0.5 x 0.27 m"),
    ],
)
def test_a_scene_that_is_not_the_controllers_is_an_error_naming_what_differs(given, words):
    mpc = _blind(scene=Scene(Road.constant(1.0), (_rock(),), BODY))
    with pytest.raises(ValueError, match=words):
        _drive(mpc, steps=2, **given)


def test_the_scene_or_its_parts_not_both():
    mpc = _blind(scene=Scene(Road.constant(1.0), (_rock(),), BODY))
    with pytest.raises(ValueError, match="not both"):
        _drive(mpc, steps=2, scene=mpc.scene, road=mpc.scene.road)
    with pytest.raises(ValueError, match="obstacles given both"):
        _blind(scene=Scene(None, (_rock(),), BODY), obstacles=(_rock(),))
    with pytest.raises(ValueError, match="MpcProblem.road is not the scene's road"):
        _blind(scene=Scene(Road.constant(1.0)), problem=_problem(Road.constant(2.0)))
    with pytest.raises(ValueError, match="scene must be a mpcdrive.scene.Scene"):
        _blind(scene=(_rock(),))


def test_a_controller_without_a_scene_is_judged_on_what_simulate_is_given():
    class Straight:
        """Steers straight ahead: a controller with no world of its own."""

        nx, nu, N = 3, 1, 10

        def __init__(self):
            self.mpc = _blind()

        def initial_warm(self, x0):
            return self.mpc.initial_warm(x0)

        def step(self, x, warm):
            return dataclasses.replace(self.mpc.step(x, warm), u=np.zeros(1))

    r = _drive(Straight(), obstacles=(_rock(),), footprint=BODY)
    assert r.meta["collisions"] == 1 and r.lane_excess_m is None


def test_wrappers_are_looked_through():
    mpc = _blind(scene=Scene(Road.constant(1.0), (_rock(),), BODY))
    servo = SteeringActuator(time_constant_s=0.0, dead_time_s=0.05)
    for wrapped in (StateAdapter(mpc, MODEL, MODEL), DelayCompensator(mpc, MODEL, servo, 0.05, PATH)):
        assert compute_metrics(_drive(wrapped)).collisions == 1
        with pytest.raises(ValueError, match="obstacles: 1 vs 0"):
            _drive(wrapped, steps=2, obstacles=())


def test_the_planned_mpc_is_judged_on_the_whole_road():
    """The maneuver planner narrows the MPC's road to the lanes its maneuver uses; its scene is
    the full road and the drive is judged inside every lane (Road.whole)."""
    from mpcdrive.planning.driver import PlannedMpc

    s = np.array([0.0, 3.0])
    lanes = (
        Lane("right", np.full(2, -1.0), np.full(2, -0.5), np.full(2, -1.5)),
        Lane("route", np.zeros(2), np.full(2, 0.5), np.full(2, -0.5)),
    )
    road = Road(s, 0.5, -0.5, 0.05, lanes, 1)
    whole = road.whole()
    np.testing.assert_allclose(whole.left_m, 0.5)
    np.testing.assert_allclose(whole.right_m, -1.5)
    from mpcdrive.control import MpcConfig
    from mpcdrive.models import KinematicBicycle4

    model = KinematicBicycle4()
    problem = MpcProblem(
        4, 2, 10, 0.05, Q=[1, 1, 1, 1], R=[1.0, 0.1], u_min=[-0.5, -3.0], u_max=[0.5, 3.0], road=road.band((1,))
    )
    mpc = LtvMpc(model, PATH, problem, MpcConfig(v_ref_mps=0.5), scene=Scene(road.band((1,)), (), BODY))
    planned = PlannedMpc(mpc, road)
    assert planned.scene.road is road and planned.scene.judged_road().right_m[0] == -1.5
    r = simulate(planned, Plant(model), PATH, [0.0, -0.9, 0.0, 0.5], 0.05, 4)
    assert r.lane_excess_m is not None and r.lane_excess_m[0] == 0.0  # in the right lane: inside
    assert Road.constant(1.0).whole().left_m[0] == 0.5  # no lanes: the road itself


def test_the_lanes_the_body_overlaps_now_are_those_its_corners_reach():
    """The planned MPC's road always holds the lanes the body overlaps now. A car turned across
    its lanes reaches further to its side than its half width: a 4.5 m x 1.8 m body 0.5 m left
    of a 3.5 m lane's line reaches 1.4 m left of it heading along the path, inside its lane, and
    0.5 + 2.25 sin(0.5) + 0.9 cos(0.5) = 2.37 m turned 0.5 rad left, 0.62 m into the lane
    beside. Judged by its half width alone, that lane was left out of the MPC's road, and on
    DEU_Backnang-9 (ST) the MPC accelerated at 7.2 m/s^2 against a plan stopping, to pull the
    corner back in, then braked again: a limit cycle CommonRoad's ST feasibility check rejected."""
    from mpcdrive.control import MpcConfig
    from mpcdrive.models import KinematicBicycle4
    from mpcdrive.planning.driver import PlannedMpc

    s = np.array([0.0, 60.0])
    lanes = (
        Lane("route", np.zeros(2), np.full(2, 1.75), np.full(2, -1.75)),
        Lane("left", np.full(2, 3.5), np.full(2, 5.25), np.full(2, 1.75)),
    )
    road = Road(s, 5.25, -1.75, 0.1, lanes, 0)
    body = Footprint(4.5, 1.8)
    path = StraightPath([0.0, 0.0], [60.0, 0.0])
    problem = MpcProblem(4, 2, 10, 0.1, Q=[1, 1, 1, 1], R=[1.0, 0.1], u_min=[-0.5, -3.0], u_max=[0.5, 3.0])
    mpc = LtvMpc(KinematicBicycle4(), path, problem, MpcConfig(v_ref_mps=5.0), scene=Scene(road.band((0,)), (), body))
    planned = PlannedMpc(mpc, road)
    assert planned._lanes_now(20.0, 0.5, 0.0) == {0}
    assert planned._lanes_now(20.0, 0.5, 0.5) == {0, 1}
    assert planned._lanes_now(20.0, -0.5, -0.5) == {0}  # turned the other way: towards the road's edge
    assert planned._lanes_now(20.0, 3.5, 0.0) == {1}


def test_what_the_readme_shows_is_exported():
    import mpcdrive.ocp
    import mpcdrive.scene

    from mpcdrive.ocp.avoidance import AvoidanceConfig

    assert mpcdrive.ocp.AvoidanceConfig is AvoidanceConfig
    for name in ("Scene", "Road", "Lane", "Footprint", "Circle", "Polygon", "rectangle", "Obstacle"):
        assert name in mpcdrive.scene.__all__ and hasattr(mpcdrive.scene, name)
    assert math.isclose(Road.constant(1.0).min_width_m, 1.0)
