"""Obstacle avoidance: corridor geometry, SQP vs IPOPT, closed-loop safety of every formulation."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.control import LtvMpc
from mpcdrive.experiments import AVOIDANCE_SCENARIOS
from mpcdrive.ocp.avoidance import SIDE_BLOCKED, SIDE_LEFT, SIDE_RIGHT, Avoidance, AvoidanceConfig, AvoidanceMemory, frenet_box
from mpcdrive.paths import StraightPath
from mpcdrive.scenarios import ScenarioSpec, build_experiment, load_scenario, run_experiment
from mpcdrive.scene import Circle, Footprint, Obstacle, rectangle
from mpcdrive.sim import compute_metrics
from mpcdrive.solvers.osqp_backend import OsqpSettings


@settings(max_examples=60, deadline=None)
@given(
    obs=st.lists(st.tuples(st.floats(1.0, 6.0), st.floats(-1.2, 1.2), st.floats(0.1, 0.6), st.booleans()),
                 min_size=1, max_size=3),
    x0=st.floats(0.0, 2.0),
)
def test_corridor_never_contains_an_obstacle(obs, x0):
    path = StraightPath([0, 0], [20, 0])
    fp = Footprint(0.5, 0.27)
    obstacles = [Obstacle(Circle(r) if circ else rectangle(2 * r, r), (x, y, 0.3)) for x, y, r, circ in obs]
    cfg = AvoidanceConfig("corridor", margin_m=0.1, max_obstacles=3, influence_m=50.0)
    N, lane = 30, 1.5
    av = Avoidance(cfg, obstacles, path, fp, N, 0.1, lane, 0.05)
    s_arr = x0 + 0.2 * np.arange(N + 1)
    Xlin = np.column_stack([s_arr, np.zeros(N + 1), np.zeros(N + 1)])
    t = av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory())
    half = 0.5 * fp.width_m
    for j, ob in enumerate(obstacles):
        box = frenet_box(path, ob.at(0.0), 0.0)
        side = t.sides[j]
        for k in range(1, N + 1):
            if not (box.s_lo - 0.1 - 0.25 <= s_arr[k] <= box.s_hi + 0.1 + 0.25):
                continue
            lo, hi = t.lane_lo[k - 1], t.lane_hi[k - 1]
            if side == SIDE_BLOCKED or lo >= hi:  # no tube here: a stop-before row must exist
                assert np.any(np.isfinite(t.rows_b[k - 1])) or lo >= hi
                continue
            # the whole body band [lo - half, hi + half] stays clear of the obstacle by the margin
            assert lo - half >= box.e_hi + 0.1 - 1e-9 or hi + half <= box.e_lo - 0.1 + 1e-9
            assert side in (SIDE_LEFT, SIDE_RIGHT)


def test_passing_side_is_kept_from_step_to_step():
    exp = build_experiment(load_scenario("paper-exp5-corridor"))
    c = exp.controller
    x = exp.x0.copy()
    warm = c.initial_warm(x)
    seen = set()
    for _ in range(500):
        out = c.step(x, warm)
        warm = out.warm
        seen |= {side for _, side in warm.sides}
        x = exp.plant.step(x, out.u, exp.spec.dt_s)
    assert len(seen) == 1


def _p3_controllers():
    casadi = pytest.importorskip("casadi")  # noqa: F841
    from mpcdrive.bench.baselines import CasadiIpoptMpc
    from mpcdrive.bench.problems import p3

    prob = p3()
    cfg = dataclasses.replace(prob.config, sqp_max_iterations=300, sqp_tol=1e-9, sqp_max_time_s=60.0)
    sqp = LtvMpc(prob.model, prob.path, prob.problem, cfg, OsqpSettings(eps_abs=1e-9, eps_rel=1e-9, max_iter=100000),
                 obstacles=prob.obstacles, avoidance=prob.avoidance, footprint=prob.footprint)
    return sqp, CasadiIpoptMpc(prob)


@pytest.mark.parametrize("x", [[4.2, -0.05, 0.05], [3.5, 0.3, -0.1], [4.6, 0.45, 0.1]])
def test_sqp_reaches_the_ipopt_optimum_on_p3(x):
    sqp, ipopt = _p3_controllers()
    x = np.array(x)
    a = sqp.step(x, sqp.initial_warm(x))
    b = ipopt.step(x, ipopt.initial_warm(x))
    assert a.status == "ok" and b.status == "ok"
    np.testing.assert_allclose(a.warm.U, b.warm.U, atol=2e-5)
    np.testing.assert_allclose(a.warm.X, b.warm.X, atol=2e-5)


def test_real_time_iteration_is_one_qp_and_converged_mode_iterates():
    from mpcdrive.bench.problems import p3

    prob = p3()
    x = np.array([4.2, -0.05, 0.05])
    rti = prob.controller()
    conv = prob.controller(sqp_max_iterations=20, sqp_tol=1e-6, sqp_max_time_s=10.0)
    assert rti.step(x, rti.initial_warm(x)).sqp_iterations == 1
    assert conv.step(x, conv.initial_warm(x)).sqp_iterations > 1


def _run(sid, **avoidance):
    spec = load_scenario(sid)
    if avoidance:
        data = spec.model_dump()
        data["avoidance"] = {**data["avoidance"], **avoidance}
        spec = ScenarioSpec.model_validate(data)
    exp = build_experiment(spec)
    r = run_experiment(exp)
    return r, compute_metrics(r, exp.footprint)


@pytest.mark.slow
@pytest.mark.parametrize("formulation", ["hard", "corridor"])
@pytest.mark.parametrize("sid", AVOIDANCE_SCENARIOS)
def test_hard_and_corridor_are_safe_in_every_obstacle_scenario(sid, formulation):
    r, m = _run(sid, formulation=formulation)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.0, m
    assert m["max_lane_excess_m"] == 0.0, m
    assert np.all(np.isfinite(r.u))


@pytest.mark.slow
@pytest.mark.parametrize("sid", ["paper-exp5-potential", "paper-exp5-gaussian", "paper-exp5-hard", "paper-exp5-corridor"])
def test_paper_experiment5_is_passed_safely(sid):
    r, m = _run(sid)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.1
    assert m["max_lane_excess_m"] == 0.0
    assert m["goal_reached"] is True
    assert m["final_lateral_error_m"] < 0.15


@pytest.mark.slow
def test_blocked_lane_stops_before_the_barrier():
    r, m = _run("obstacle-blocked")
    assert m["collisions"] == 0
    assert 0.1 <= m["min_obstacle_clearance_m"] < 0.6  # stopped close, with a margin
    assert r.v_mps[-1] < 0.05 and r.x[-1, 0] < 5.0 - 0.15 - 0.25
    assert m["goal_reached"] is False


@pytest.mark.slow
def test_moving_obstacle_is_avoided_where_a_static_assumption_collides():
    base = load_scenario("obstacle-crossing").model_dump()
    base["obstacles"] = [dict(base["obstacles"][0], position=[4.0, -3.2], velocity_mps=[0.0, 0.8])]
    spec = ScenarioSpec.model_validate(base)
    results = {}
    for variant in ("predicted", "static"):
        exp = build_experiment(spec)
        c = exp.controller
        if variant == "static":  # the same controller, told each step that obstacles stand still
            real, orig = list(c.avoidance.obstacles), c.prepare

            def prepare(x, warm, around=None, s_m=None, orig=orig, real=real, c=c):
                c.avoidance.obstacles = [Obstacle(o.shape, o.pose_at(warm.t_s), name=o.name) for o in real]
                return orig(x, warm, around, s_m)

            c.prepare = prepare
        r = run_experiment(exp)
        results[variant] = compute_metrics(r, exp.footprint)
    assert results["predicted"]["collisions"] == 0 and results["predicted"]["min_obstacle_clearance_m"] > 0.1
    assert results["static"]["collisions"] >= 1


def test_symmetric_soft_costs_alone_do_not_leave_the_path():
    """An honest negative result: an obstacle exactly on a straight path gives the potential and
    Gaussian costs no lateral gradient, so without a detour reference the car drives into it."""
    r, m = _run("paper-exp5-gaussian", detour="none")
    assert m["collisions"] >= 1


def test_corridor_requires_a_lane():
    path = StraightPath([0, 0], [10, 0])
    from mpcdrive.bench.problems import p1

    prob = p1()
    with pytest.raises(ValueError, match="corridor"):
        LtvMpc(prob.model, path, prob.problem, obstacles=(Obstacle(Circle(0.2), (3, 0, 0)),),
               avoidance=AvoidanceConfig("corridor"))


@pytest.mark.parametrize("bad", [dict(formulation="cone"), dict(margin_m=-1), dict(sigma_m=(0.0, 1.0)),
                                 dict(max_obstacles=0), dict(detour="triangle")])
def test_avoidance_config_rejects_bad_values(bad):
    with pytest.raises(ValueError):
        AvoidanceConfig(**bad)


def test_obstacle_rows_are_separating_half_planes():
    """Each active hard row, evaluated at its own linearization point, says the disc is at least
    r + margin from the obstacle along the row's normal -- never the wrong way round."""
    path = StraightPath([0, 0], [20, 0])
    fp = Footprint(0.5, 0.27)
    ob = Obstacle(Circle(0.3), (3.0, 1.2, 0.0))
    av = Avoidance(AvoidanceConfig("hard", margin_m=0.1), [ob], path, fp, 20, 0.05, 2.0)
    s_arr = 1.0 + 0.05 * np.arange(21)
    Xlin = np.column_stack([s_arr, np.zeros(21), np.zeros(21)])
    t = av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory())
    active = np.isfinite(t.rows_b)
    assert active.any()
    lhs = np.einsum("kmi,ki->km", t.rows_a, Xlin[1:, :3])
    # the car on the path is far from an obstacle at y = 1.2: every row holds there
    assert np.all(lhs[active] >= t.rows_b[active] - 1e-9)
    assert math.isfinite(float(t.rows_b[active].max()))


def test_frenet_box_finds_an_obstacle_far_from_the_guess():
    """A full-size car 40 m ahead of the arc-length guess is placed where it is, not at the end of
    a short search window around the guess."""
    from mpcdrive.paths import WaypointPath

    c = math.sqrt(0.5)
    path = WaypointPath([(0.0, 0.0), (50.0 * c, 50.0 * c), (100.0 * c, 100.0 * c)], ds_m=0.2)
    # 60 m along the diagonal, 0.5 m left of it, aligned with it
    ob = Obstacle(rectangle(4.5, 2.0), (60.0 * c - 0.5 * c, 60.0 * c + 0.5 * c, math.pi / 4))
    box = frenet_box(path, ob.at(0.0), 20.0)
    assert box.s_ref == pytest.approx(60.0, abs=0.05)
    assert (box.s_lo, box.s_hi) == pytest.approx((57.75, 62.25), abs=0.05)
    assert (box.e_lo, box.e_hi) == pytest.approx((-0.5, 1.5), abs=0.05)
