"""The typed run metrics: :class:`~mpcdrive.sim.Metrics` has one field per key of ``metrics.json``,
and its JSON view (``as_dict()``, the read-only Mapping) is exactly the dict the metrics were
before they were typed: the same keys in the same order, plain JSON values."""

import dataclasses
import json
import pickle
import warnings

import pytest
from test_verdict import COLLIDE  # a car at 1 m/s on a straight path through a rock: one collision

from mpcdrive.io import write_json
from mpcdrive.sim.contact import SWEEP_DEPTH_M
from mpcdrive.scenarios import build_experiment, load_scenario, run_experiment
from mpcdrive.sim import (
    CollisionEvent,
    CommonRoadCheck,
    Metrics,
    SolveTimes,
    apply_goal_region,
    compute_metrics,
    run_verdict,
)

#: the keys of ``metrics.json`` in the order the untyped ``compute_metrics`` wrote them
EXPECTED_KEYS = [
    "steps",
    "duration_s",
    "rms_lateral_error_m",
    "max_abs_lateral_error_m",
    "final_lateral_error_m",
    "converged_rms_lateral_error_m",
    "converged_max_abs_lateral_error_m",
    "rms_heading_error_rad",
    "max_abs_steer_rad",
    "max_abs_steer_rate_rad_s",
    "steer_total_variation_rad",
    "min_obstacle_clearance_m",
    "collisions",
    "collision_events",
    "first_collision",
    "road_given",
    "max_lane_excess_m",
    "solver_failures",
    "fallbacks",
    "fallback_counts",
    "solve_time_us",
    "goal_region_reached",
    "goal_reached",
    "termination",
    "controller_backend",
    # added with the verdict: the steering's limits and saturation, the criteria, the verdict
    "final_speed_mps",
    "steer_limit_rad",
    "steer_rate_limit_rad_s",
    "steer_saturated_fraction",
    "steer_rate_saturated_fraction",
    "steering_actuator",
    "criteria",
]
#: the verdict comes last, after the CommonRoad block of a CommonRoad run
LAST_KEY = "verdict"
EVENT_KEYS = ["obstacle", "name", "step", "t_s", "steps", "depth_m"]
FALLBACK_KEYS = ["relax", "shifted_plan", "brake", "hold_last"]


_RUNS: dict = {}


def run(source: str, tmp_path_factory=None):
    """(result, metrics) of a built-in scenario shortened to 2 s, or of the COLLIDE file."""
    if source not in _RUNS:
        if source == "collide":
            p = tmp_path_factory.mktemp("metrics") / "collide.yaml"
            p.write_text(COLLIDE)
            spec = load_scenario(p)
        else:
            spec = load_scenario(source)
        spec = spec.model_copy(update={"duration_s": min(spec.duration_s, 2.0)})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = run_experiment(build_experiment(spec))
        _RUNS[source] = (result, compute_metrics(result))
    return _RUNS[source]


def _plain_json(value) -> bool:
    """Only the types ``json.loads`` gives back (no numpy scalars, tuples or dataclasses)."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return type(value).__module__ == "builtins"
    if isinstance(value, list):
        return all(_plain_json(v) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, str) and _plain_json(v) for k, v in value.items())
    return False


@pytest.mark.parametrize("source", ["paper-exp1", "obstacle-overtake", "collide"])
def test_as_dict_is_the_old_metrics_dict(source, tmp_path_factory):
    result, m = run(source, tmp_path_factory)
    assert isinstance(m, Metrics)
    d = m.as_dict()
    assert list(d) == [*EXPECTED_KEYS, LAST_KEY]
    assert [f.name for f in dataclasses.fields(Metrics)] == [*EXPECTED_KEYS, "commonroad", "planner", LAST_KEY]
    for key, value in d.items():
        assert _plain_json(value), f"{key}: {value!r} is not plain JSON"
    # every value round-trips through JSON (the runs have no NaN: each step has a lateral error)
    assert json.loads(json.dumps(d, allow_nan=False)) == d
    assert list(d["fallback_counts"]) == FALLBACK_KEYS
    assert list(d["solve_time_us"]) == ["p50", "p99", "max"]
    # the figures the run itself recorded, unchanged
    assert d["steps"] == result.steps
    assert d["collisions"] == int(result.meta.get("collisions", 0))
    assert d["collision_events"] == [dict(e) for e in result.meta.get("collision_events", ())]
    assert d["first_collision"] == (d["collision_events"][0] if d["collision_events"] else None)
    assert d["min_obstacle_clearance_m"] == result.meta.get("min_obstacle_clearance_m")
    assert d["goal_region_reached"] == result.goal_reached
    assert d["controller_backend"] == (result.meta.get("backend") or None)


def test_collision_events_are_typed(tmp_path_factory):
    _, m = run("collide", tmp_path_factory)
    assert m.collisions == 1 and len(m.collision_events) == 1
    ev = m.collision_events[0]
    assert isinstance(ev, CollisionEvent) and m.first_collision == ev
    # the front touches the rock at x = 0.97 m, between the steps at 0.95 s (19) and 1.00 s
    assert (ev.obstacle, ev.name, ev.step) == (1, "rock", 19) and ev.depth_m > 0.0
    assert 0.97 <= ev.t_s <= 0.97 + 2 * SWEEP_DEPTH_M / 1.0  # to the sweep's resolution at 1 m/s
    assert list(m["collision_events"][0]) == EVENT_KEYS and m["first_collision"] == ev.as_dict()
    assert isinstance(m.solve_time_us, SolveTimes) and m["solve_time_us"]["p50"] == m.solve_time_us.p50
    assert m.goal_reached is False  # the 2 s drive does not get to the path's end


def test_metrics_is_a_read_only_mapping_over_the_json_view(tmp_path_factory, tmp_path):
    _, m = run("collide", tmp_path_factory)
    d = m.as_dict()
    keys = [*EXPECTED_KEYS, LAST_KEY]
    assert dict(m) == d and {**m} == d and m == d and len(m) == len(keys) and list(m) == keys
    assert m["collisions"] == m.collisions and m.get("max_lane_excess_m") == m.max_lane_excess_m
    assert "commonroad" not in m and m.get("commonroad") is None
    assert "planner" not in m and m.get("planner") is None  # no lanes: no maneuver planner
    with pytest.raises(KeyError):
        m["commonroad"]
    with pytest.raises(KeyError):
        m["planner"]
    with pytest.raises(KeyError):
        m["no_such_key"]
    # the items are copies: changing one changes nothing
    m["fallback_counts"]["relax"] = 99
    m["collision_events"].clear()
    assert m.fallback_counts["relax"] == 0 and m["collision_events"] == d["collision_events"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.collisions = 0  # type: ignore[misc]
    assert pickle.loads(pickle.dumps(m)) == m
    # written as JSON it is its as_dict(), byte for byte
    a = write_json(tmp_path / "a.json", m).read_bytes()
    assert a == write_json(tmp_path / "b.json", d).read_bytes()
    # the verdict reads the same from the Metrics and from metrics.json read back
    assert run_verdict(m) == run_verdict(json.loads(a))


def test_first_collision_follows_the_events(tmp_path_factory):
    _, m = run("collide", tmp_path_factory)
    clean = dataclasses.replace(m, collisions=0, collision_events=())
    assert clean.first_collision is None and clean["first_collision"] is None
    assert clean.collision_events == () and clean["collision_events"] == []


def test_commonroad_block_is_typed_and_written_last(tmp_path_factory):
    _, m = run("collide", tmp_path_factory)
    cr = CommonRoadCheck(
        file="X.xml",
        route_lanelets=(3, 4),
        plan=None,
        goal_reached=True,
        goal_step=12,
        collision_free=True,
        road_compliant=True,
        ks_feasible=True,
        states_checked=13,
        passed=True,
        solution="solution.xml",
        vehicle_type="FORD_ESCORT",
        vehicle_model="KS",
        solution_valid=True,
        solution_check="",
    )
    judged = apply_goal_region(dataclasses.replace(m, commonroad=cr), cr.goal_reached)
    assert isinstance(judged, Metrics) and judged.commonroad == cr
    d = judged.as_dict()
    assert list(d) == [*EXPECTED_KEYS, "commonroad", LAST_KEY] and len(judged) == len(d)
    assert d["commonroad"] == {**cr.as_dict(), "route_lanelets": [3, 4]} and _plain_json(d["commonroad"])
    # the planning problem's goal is reached, but the run collided: not the goal
    assert judged.goal_region_reached is True and judged.goal_reached is False
    assert "CommonRoad checker: collision-free, road-compliant, KS-feasible" in run_verdict(judged).text()
