"""The fallback ladder: relax, shifted_plan, brake, hold_last; configured, logged, counted, never NaN."""

import csv
import math

import numpy as np
import pytest

from mpcdrive.control import FallbackConfig, MpcConfig, PythonLtvMpc
from mpcdrive.scene.road import Road
from mpcdrive.control.fallback import check_ladder, relaxed_problem
from mpcdrive.io import write_trajectory_csv
from mpcdrive.models import KinematicBicycle3, KinematicBicycle4
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.scenarios import build_experiment, run_experiment, validate_scenario_data
from mpcdrive.sim import Plant, compute_metrics, simulate
from mpcdrive.types import SolveResult

STEER = math.radians(60)
RATE = math.radians(300)


def failing(N, nx, nu, status="max_iter"):
    return SolveResult(status, np.full((N + 1, nx), np.nan), np.full((N, nu), np.nan), np.nan, 4000, 0.0)


def speed_controller(ladder, **fb):
    model = KinematicBicycle4()
    pb = MpcProblem(
        4,
        2,
        10,
        0.01,
        Q=[1, 1, 1, 1],
        R=0.1,
        u_min=[-STEER, -3.0],
        u_max=[STEER, 3.0],
        du_max_per_s=[RATE, np.inf],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [2.0],
    )
    path = CirclePath(radius_m=1.5)
    cfg = MpcConfig(v_ref_mps=1.0, fallback=FallbackConfig(tuple(ladder), **fb))
    return model, path, PythonLtvMpc(model, path, pb, cfg, "osqp")


@pytest.mark.parametrize(
    "ladder, words",
    [
        ([], "empty"),
        (["relax"], "must end with brake or hold_last"),
        (["relax", "teleport", "brake"], "unknown fallback 'teleport'"),
        (["relax", "relax", "brake"], "appears twice"),
        (["brake", "relax", "hold_last"], "must be the last rung"),
        ("brake", "list of rungs"),
    ],
)
def test_bad_ladders_are_refused_with_the_reason(ladder, words):
    with pytest.raises(ValueError, match=words):
        check_ladder(ladder)
    with pytest.raises(ValueError, match=words):
        FallbackConfig(ladder)


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"brake_decel_mps2": 0.0}, "brake_decel_mps2"),
        ({"brake_decel_mps2": float("nan")}, "brake_decel_mps2"),
        ({"brake_steering": "left"}, "brake_steering"),
        ({"relax_slack_factor": 0.5}, "relax_slack_factor"),
    ],
)
def test_bad_fallback_settings_are_refused(kw, words):
    with pytest.raises(ValueError, match=words):
        FallbackConfig(**kw)


def test_relaxed_problem_drops_rate_limits_and_state_bounds_keeps_input_bounds():
    pb = MpcProblem(
        4,
        2,
        5,
        0.01,
        Q=1.0,
        R=0.1,
        u_min=[-1, -2],
        u_max=[1, 2],
        du_max_per_s=[1, 1],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [2.0],
        road=Road.constant(1.0),
    )
    r = relaxed_problem(pb, 100.0)
    assert not r.has_rate_limit and r.bounded_states.size == 0
    np.testing.assert_array_equal(r.u_min, pb.u_min)
    np.testing.assert_array_equal(r.u_max, pb.u_max)
    assert r.lane_slack_weight == pytest.approx(pb.lane_slack_weight / 100)
    assert r.road is pb.road


def test_ladder_walks_down_relax_shifted_plan_then_brakes_when_the_plan_runs_out():
    """Both QPs fail after a good first step: relax fails, the solved plan is shifted N-1 times,
    then brake, whose braking plan is shifted in turn until it runs out too."""
    model, path, c = speed_controller(["relax", "shifted_plan", "brake"], brake_decel_mps2=2.0)
    x = np.array([1.5, 0.0, math.pi / 2, 1.0])
    out = c.step(x, c.initial_warm(x))
    assert out.fallback == "" and out.warm.plan_age == 0
    c.backend.solve = lambda *a, **k: failing(10, 4, 2)
    c.fallback.relax_backend.solve = lambda *a, **k: failing(10, 4, 2, "infeasible")
    fb, warm, xk, us = [], out.warm, x, []
    for _ in range(30):
        o = c.step(xk, warm)
        fb.append(o.fallback)
        us.append(o.u)
        warm = o.warm
        xk = Plant(model).step(xk, o.u, 0.01)
    # a plan of N = 10 inputs can be shifted 9 times
    assert fb == ["shifted_plan"] * 9 + ["brake"] + ["shifted_plan"] * 9 + ["brake"] + ["shifted_plan"] * 9 + ["brake"]
    us = np.array(us)
    assert np.all(np.isfinite(us))
    assert np.all(np.abs(us[:, 0]) <= STEER) and np.all(np.abs(np.diff(us[:, 0])) <= RATE * 0.01 + 1e-9)
    # braking at 2 m/s^2: from step 10 on the acceleration is -2 m/s^2 (the car is still moving)
    assert np.allclose(us[9:, 1], -2.0)
    # the same from simulate's point of view: every step logged and counted, never NaN
    r = simulate(c, Plant(model), path, x, 0.01, 40)
    m = compute_metrics(r)
    assert m["fallbacks"] == 40 and m["solver_failures"] == 40
    assert m["fallback_counts"] == {"relax": 0, "shifted_plan": 36, "brake": 4, "hold_last": 0}
    assert np.all(np.diff(r.v_mps) < 0) and np.all(r.v_mps >= 0)


def test_brake_never_reverses_and_straightens_at_the_rate_limit():
    model, path, c = speed_controller(["brake"], brake_decel_mps2=5.0, brake_steering="straighten")
    c.backend.solve = lambda *a, **k: failing(10, 4, 2)
    x = np.array([1.5, 0.0, math.pi / 2, 0.3])
    warm = c.initial_warm(x)
    warm = type(warm)(s_m=warm.s_m, u_prev=np.array([0.5, 0.0]))
    r = simulate(c, Plant(model), path, x, 0.01, 20)
    assert set(r.fallback) == {"brake"}
    assert np.all(r.v_mps >= -1e-12)
    assert r.v_mps[-1] == pytest.approx(0.0, abs=1e-9)  # 0.3 m/s stopped within 6 steps at 5 m/s^2
    # steering started at 0 (initial_warm) and stays straight
    assert np.all(np.abs(r.steer_rad) <= 1e-12)
    out = c.step(r.x_final, warm)
    assert out.fallback == "brake"
    assert out.u[0] == pytest.approx(0.5 - RATE * 0.01)  # straightening at the rate limit


def test_constant_speed_brake_holds_the_last_steering_within_bounds():
    model = KinematicBicycle3(1.0)
    path = StraightPath([0, 0], [10, 0])
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-0.3, u_max=0.3)
    c = PythonLtvMpc(model, path, pb, MpcConfig(fallback=FallbackConfig(("brake",))), "osqp")
    c.backend.solve = lambda *a, **k: failing(10, 3, 1)
    x = np.array([0.0, 0.2, 0.0])
    warm = c.initial_warm(x)
    out = c.step(x, type(warm)(s_m=warm.s_m, u_prev=np.array([0.25])))
    assert out.fallback == "brake" and out.status == "max_iter"
    assert out.u[0] == pytest.approx(0.25)
    assert np.all(np.isfinite(out.X_pred)) and out.X_pred.shape == (11, 3)


def test_relax_rescues_a_solver_that_runs_out_of_iterations():
    """One OSQP iteration is never enough; the relaxed solve (looser, 2x iterations) is not
    either, but a looser tolerance with more iterations is: relax must be tried and counted."""
    model = KinematicBicycle3(1.0)
    path = StraightPath([0, 0], [10, 0])
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    c = PythonLtvMpc(model, path, pb, MpcConfig(), "osqp")
    c.backend.solve = lambda *a, **k: failing(10, 3, 1)
    r = simulate(c, Plant(model), path, [0.0, 0.3, 0.0], 0.01, 50)
    assert set(r.fallback) == {"relax"}
    assert compute_metrics(r)["fallback_counts"]["relax"] == 50
    assert abs(r.e_y_m[-1]) < abs(r.e_y_m[0])  # the relaxed plans still steer back to the line


def test_scenario_fallback_keys_reach_the_controller_and_the_csv(tmp_path):
    data = {
        "id": "fb",
        "duration_s": 0.3,
        "vehicle": {"model": "kinematic4"},
        "path": {"type": "straight", "start": [0, 0], "end": [20, 0]},
        "initial_state": {"y_m": 0.2, "v_mps": 3.0},
        "controller": {
            "horizon": 10,
            "Q": [1, 1, 1, 1],
            "R": [0.1, 0.1],
            "speed_limits_mps": [0, 1],
            "accel_limits_mps2": [-0.1, 0.1],
            "fallback": ["shifted_plan", "brake"],
            "brake_decel_mps2": 0.05,
            "brake_steering": "straighten",
        },
    }
    spec = validate_scenario_data(data, "test")
    exp = build_experiment(spec)
    assert exp.controller.config.fallback == FallbackConfig(("shifted_plan", "brake"), 0.05, "straighten")
    r = run_experiment(exp)
    assert r.fallback[0] == "brake" and set(r.fallback) == {"brake", "shifted_plan"}
    assert set(r.status) == {"infeasible"}
    assert np.allclose(np.diff(r.v_mps), -0.05 * 0.01)
    write_trajectory_csv(r, tmp_path / "t.csv")
    with open(tmp_path / "t.csv") as f:
        rows = list(csv.DictReader(f))
    assert [row["fallback"] for row in rows] == list(r.fallback)
    counts = compute_metrics(r)["fallback_counts"]
    assert counts["brake"] + counts["shifted_plan"] == 30 and counts["brake"] == 3


def _straight_speed_controller(obstacles=(), road=None):
    """KinematicBicycle4 at 5 m/s on a straight road, braking limit 6 m/s^2, main solve failing."""
    from mpcdrive.ocp.avoidance import AvoidanceConfig

    model = KinematicBicycle4()
    pb = MpcProblem(4, 2, 10, 0.05, Q=[1, 1, 1, 1], R=0.1, u_min=[-STEER, -6.0], u_max=[STEER, 2.0], road=road)
    path = StraightPath([0, 0], [100, 0])
    c = PythonLtvMpc(
        model,
        path,
        pb,
        MpcConfig(v_ref_mps=5.0),
        "osqp",
        obstacles=tuple(obstacles),
        avoidance=AvoidanceConfig() if obstacles else None,
    )
    c.backend.solve = lambda *a, **k: failing(10, 4, 2)
    return c


def _plan(X):
    X = np.asarray(X, float)
    return SolveResult("ok", X, np.zeros((X.shape[0] - 1, 2)), 0.0, 10, 0.0)


def _drive_straight(x0, v, n, dt, dy_per_step=0.0):
    return np.array([[x0 + v * dt * k, dy_per_step * k, 0.0, v] for k in range(n + 1)])


def test_relax_plan_into_an_obstacle_is_not_applied_the_car_brakes_at_full_deceleration():
    from mpcdrive.scene.obstacles import Circle, Obstacle

    c = _straight_speed_controller([Obstacle(Circle(0.5), (6.0, 0.0, 0.0))])
    x = np.array([0.0, 0.0, 0.0, 5.0])
    # the relaxed solve "succeeds" with a plan that drives straight through the obstacle at 6 m
    c.fallback.relax_backend.solve = lambda *a, **k: _plan(_drive_straight(0.0, 5.0, 10, 0.05 * 3))
    out = c.step(x, c.initial_warm(x))
    assert out.fallback == "brake"
    assert out.u[1] == pytest.approx(-6.0)  # the vehicle's full braking (u_min), not 1 m/s^2
    # the same plan without the obstacle in its way is applied
    c2 = _straight_speed_controller([Obstacle(Circle(0.5), (6.0, 5.0, 0.0))])
    c2.fallback.relax_backend.solve = c.fallback.relax_backend.solve
    assert c2.step(x, c2.initial_warm(x)).fallback == "relax"


def test_relax_plan_leaving_the_road_is_not_applied():
    c = _straight_speed_controller(road=Road.constant(3.5))
    x = np.array([0.0, 0.0, 0.0, 5.0])
    # drifting 0.3 m left per step: the body's corner leaves the 1.75 m half-width road
    c.fallback.relax_backend.solve = lambda *a, **k: _plan(_drive_straight(0.0, 5.0, 10, 0.05, 0.3))
    assert c.step(x, c.initial_warm(x)).fallback == "brake"
    c.fallback.relax_backend.solve = lambda *a, **k: _plan(_drive_straight(0.0, 5.0, 10, 0.05, 0.01))
    assert c.step(x, c.initial_warm(x)).fallback == "relax"


def test_plan_check_can_be_switched_off():
    c = _straight_speed_controller(road=Road.constant(3.5))
    c.fallback.config = FallbackConfig(check_plans=False)
    x = np.array([0.0, 0.0, 0.0, 5.0])
    c.fallback.relax_backend.solve = lambda *a, **k: _plan(_drive_straight(0.0, 5.0, 10, 0.05, 0.3))
    assert c.step(x, c.initial_warm(x)).fallback == "relax"


def test_relax_on_the_condensed_solver_solves_the_step_posed_for_the_relaxed_problem():
    """A controller on the condensed solver relaxes with the same solver (no OSQP): the step's
    stage QP posed for the relaxed problem, whose plan is the one a controller built on the
    relaxed problem makes, and not the plan of the problem itself (the rate limit binds)."""
    from dataclasses import replace

    model, path, ref = speed_controller(["relax", "brake"])
    pb, cfg = ref.problem, ref.config
    c = PythonLtvMpc(model, path, pb, cfg, "condensed")
    assert c.backend_name == "fast" and c.fallback.relax_qp is None
    relaxed = PythonLtvMpc(model, path, relaxed_problem(pb, cfg.fallback.relax_slack_factor), cfg, "condensed")
    x = np.array([1.5, 0.2, math.pi / 2 + 0.3, 1.9])
    warm = replace(c.initial_warm(x), u_prev=np.array([-0.8, 0.0]))  # far from the plan: the rate limit binds
    plain = c.step(x, warm)
    assert plain.fallback == ""
    c.backend.solve_stage = lambda *a, **k: failing(pb.N, 4, 2)
    out = c.step(x, warm)
    want = relaxed.step(x, warm)
    assert out.fallback == "relax" and want.fallback == ""
    np.testing.assert_allclose(out.warm.U, want.warm.U, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out.X_pred, want.X_pred, rtol=0, atol=1e-9)
    assert np.abs(plain.warm.U - want.warm.U).max() > 1e-3  # the relaxed constants made a difference


def test_the_condensed_solver_refuses_a_stage_qp_of_another_problem():
    """Its work space holds the rows of its own problem: a stage QP posed for another (here the
    relaxed one, without rate limits) or sized for another is a clear error, not a solve that
    reads past them."""
    from dataclasses import replace

    from mpcdrive.control.condensed_backend import CondensedBackend
    from mpcdrive.ocp.stage_qp import new_stage_qp

    pb = speed_controller(["brake"])[2].problem
    be = CondensedBackend(pb)
    x, u = np.array([1.5, 0.0, math.pi / 2, 1.0]), np.zeros(2)
    with pytest.raises(ValueError, match="posed for another problem"):
        be.solve_stage(new_stage_qp(relaxed_problem(pb, 10.0)), x, u)
    longer = replace(pb, N=pb.N + 1)
    with pytest.raises(ValueError, match="does not fit this solver"):
        be.solve_stage(new_stage_qp(longer), x, u)
    with pytest.raises(ValueError, match="cannot be posed"):
        new_stage_qp(pb).posed_for(longer)
    assert be.solve_stage(new_stage_qp(relaxed_problem(pb, 10.0)).posed_for(pb), x, u).status == "ok"
