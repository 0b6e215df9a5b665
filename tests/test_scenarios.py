"""Scenario files: validation, clear one-line errors, round trips."""

import math

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.scenarios import (
    ScenarioError,
    ScenarioSpec,
    build_experiment,
    builtin_ids,
    dump_scenario,
    load_scenario,
)

BASE = {
    "id": "t",
    "duration_s": 0.2,
    "path": {"type": "straight", "start": [0, 0], "end": [5, 0]},
    "controller": {"horizon": 5, "Q": [1, 1, 1], "R": [1]},
}


def write(tmp_path, data, name="s.yaml"):
    p = tmp_path / name
    p.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return p


def test_builtins_load_and_build():
    ids = builtin_ids()
    for required in (
        "paper-exp1",
        "paper-exp2",
        "paper-exp3",
        "paper-exp4",
        "paper-disturbance-v1",
        "paper-disturbance-v4",
        "paper-smoothing",
    ):
        assert required in ids
    for sid in ids:
        spec = load_scenario(sid)
        assert spec.id == sid
        build_experiment(spec)


def test_paper_defaults_from_the_authors_code():
    spec = load_scenario("paper-exp1")
    assert (spec.vehicle.lf_m, spec.vehicle.lr_m) == (0.17, 0.16)
    assert spec.path.start == (1.0, 0.0) and spec.path.end == (11.0, 0.0)
    assert spec.controller.QN == [1.0, 1.0, 1.0]
    exp = build_experiment(spec)
    assert exp.x0[2] == pytest.approx(math.pi / 2)
    assert exp.controller.problem.u_max[0] == pytest.approx(math.radians(60))


@pytest.mark.parametrize(
    "mutate, field, words",
    [
        (lambda d: d.update(colour="red"), "colour", "unknown key"),
        (lambda d: d["controller"].update(horizon=-3), "controller.horizon", "greater than"),
        (lambda d: d["controller"].update(horizn=3), "controller.horizn", "unknown key"),
        (lambda d: d["controller"].update(Q=[1, 1]), "controller.Q", "needs 3 entries"),
        (lambda d: d.update(dt_s=float("nan")), "dt_s", "finite"),
        (lambda d: d.update(duration_s="long"), "duration_s", "number"),
        (lambda d: d["path"].update(end=[0, 0]), "path", "differ"),
        (lambda d: d.update(path={"type": "waypoints", "points": [[0, 0]]}), "path.points", "at least 2"),
        (lambda d: d["controller"].update(max_steer_deg=95), "controller.max_steer_deg", "below 90"),
        (lambda d: d["controller"].update(speed_limits_mps=[2, 0]), "controller.speed_limits_mps", "exceeds"),
        (lambda d: d.pop("controller"), "controller", "required key missing"),
        (lambda d: d["path"].update(type="spiral"), "path", "spiral"),
    ],
)
def test_bad_scenarios_give_one_line_errors_naming_file_and_field(tmp_path, mutate, field, words):
    data = yaml.safe_load(yaml.safe_dump(BASE))
    mutate(data)
    p = write(tmp_path, data)
    with pytest.raises(ScenarioError) as e:
        load_scenario(p)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{p}: {field}: "), msg  # the field where the problem is, never "(top level)"
    assert words.lower() in msg.lower()


def test_malformed_yaml_and_missing_file(tmp_path):
    with pytest.raises(ScenarioError, match="not valid YAML"):
        load_scenario(write(tmp_path, "id: [unclosed\n"))
    with pytest.raises(ScenarioError, match="mapping"):
        load_scenario(write(tmp_path, "- 1\n- 2\n"))
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(tmp_path / "nope.yaml")
    with pytest.raises(ScenarioError, match="no built-in scenario"):
        load_scenario("paper-exp99")


def test_resolved_scenario_round_trips():
    for sid in builtin_ids():
        spec = load_scenario(sid)
        again = ScenarioSpec.model_validate(yaml.safe_load(dump_scenario(spec)))
        assert again == spec


@pytest.mark.parametrize(
    "backend, solver, shown",
    [("fast", "osqp", None), ("osqp", "osqp", "osqp"), ("fast", "projected_gradient", "projected_gradient")],
)
def test_the_resolved_scenario_names_the_solver_only_where_it_ran(backend, solver, shown):
    """The condensed solver runs on backend fast: a ``solver: osqp`` beside it would read as if
    OSQP had; the reference's solver is written where it solves (and the file loads back)."""
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["controller"].update(backend=backend, solver=solver)
    spec = ScenarioSpec.model_validate(data)
    resolved = yaml.safe_load(dump_scenario(spec))
    assert resolved["controller"]["backend"] == backend
    assert resolved["controller"].get("solver") == shown
    assert ScenarioSpec.model_validate(resolved) == spec


@settings(max_examples=30, deadline=None)
@given(
    horizon=st.integers(1, 60),
    q=st.lists(st.floats(0, 100, allow_nan=False), min_size=3, max_size=3),
    steer=st.floats(1, 89),
    yaw=st.floats(-720, 720),
)
def test_random_valid_scenarios_round_trip(horizon, q, steer, yaw):
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["controller"].update(horizon=horizon, Q=q, max_steer_deg=steer)
    data["initial_state"] = {"yaw_deg": yaw}
    spec = ScenarioSpec.model_validate(data)
    assert ScenarioSpec.model_validate(yaml.safe_load(dump_scenario(spec))) == spec
