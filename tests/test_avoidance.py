"""Obstacle avoidance: corridor geometry, SQP vs IPOPT, closed-loop safety of every formulation."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.control import LtvMpc, MpcConfig, PythonLtvMpc
from mpcdrive.scene.road import Road
from mpcdrive.experiments import AVOIDANCE_SCENARIOS
from mpcdrive.models import KinematicBicycle4, KinematicParams
from mpcdrive.ocp import MpcProblem
from mpcdrive.ocp.avoidance import (
    SIDE_BLOCKED,
    SIDE_LEFT,
    SIDE_RIGHT,
    Avoidance,
    AvoidanceConfig,
    AvoidanceMemory,
    frenet_box,
)
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.scenarios import ScenarioSpec, build_experiment, load_scenario, run_experiment
from mpcdrive.scene import Circle, ConstantVelocity, Footprint, Obstacle, TrajectoryMotion, rectangle
from mpcdrive.sim import Plant, compute_metrics, simulate
from mpcdrive.solvers.osqp_backend import OsqpSettings


@settings(max_examples=60, deadline=None)
@given(
    obs=st.lists(
        st.tuples(st.floats(1.0, 6.0), st.floats(-1.2, 1.2), st.floats(0.1, 0.6), st.booleans()), min_size=1, max_size=3
    ),
    x0=st.floats(0.0, 2.0),
)
def test_corridor_never_contains_an_obstacle(obs, x0):
    path = StraightPath([0, 0], [20, 0])
    fp = Footprint(0.5, 0.27)
    obstacles = [Obstacle(Circle(r) if circ else rectangle(2 * r, r), (x, y, 0.3)) for x, y, r, circ in obs]
    cfg = AvoidanceConfig("corridor", margin_m=0.1, max_obstacles=3, influence_m=50.0)
    N, lane = 30, 1.5
    road = Road.constant(2 * lane, 0.05)
    av = Avoidance(cfg, obstacles, path, fp, N, 0.1, road)
    s_arr = x0 + 0.2 * np.arange(N + 1)
    Xlin = np.column_stack([s_arr, np.zeros(N + 1), np.zeros(N + 1)])
    lo0, hi0 = road.bounds(s_arr[1:], 0.0, 0.0, fp)  # the road's bounds, which the corridor narrows
    t = av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory(), lo0, hi0)
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
    cfg = dataclasses.replace(prob.config, sqp_max_iterations=300, sqp_tol=1e-9)
    sqp = PythonLtvMpc(
        prob.model,
        prob.path,
        prob.problem,
        cfg,
        "osqp",
        osqp_settings=OsqpSettings(eps_abs=1e-9, eps_rel=1e-9, max_iter=100000),
        obstacles=prob.obstacles,
        avoidance=prob.avoidance,
        footprint=prob.footprint,
    )
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
    conv = prob.controller(sqp_max_iterations=20, sqp_tol=1e-6)
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
    return r, compute_metrics(r)


@pytest.mark.slow
@pytest.mark.parametrize("formulation", ["hard", "corridor"])
@pytest.mark.parametrize("sid", AVOIDANCE_SCENARIOS)
def test_hard_and_corridor_are_safe_in_every_obstacle_scenario(sid, formulation):
    r, m = _run(sid, formulation=formulation)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.0, m
    assert m["max_lane_excess_m"] == 0.0, m
    assert np.all(np.isfinite(r.u))


@pytest.mark.slow
@pytest.mark.parametrize(
    "sid", ["paper-exp5-potential", "paper-exp5-gaussian", "paper-exp5-hard", "paper-exp5-corridor"]
)
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
    # its goal is to stop (verdict.goal: standstill), safely: that is what it did
    assert m["goal_reached"] is True and m["verdict"]["passed"]


@pytest.mark.slow
def test_moving_obstacle_is_avoided_where_a_static_assumption_collides():
    base = load_scenario("obstacle-crossing").model_dump()
    base["obstacles"] = [dict(base["obstacles"][0], position=[4.0, -3.2], velocity_mps=[0.0, 0.8])]
    base["controller"]["backend"] = "osqp"  # its prepare step is hooked below
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
        results[variant] = compute_metrics(r)
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
        PythonLtvMpc(
            prob.model,
            path,
            prob.problem,
            MpcConfig(),
            "osqp",
            obstacles=(Obstacle(Circle(0.2), (3, 0, 0)),),
            avoidance=AvoidanceConfig("corridor"),
        )


@pytest.mark.parametrize(
    "bad",
    [
        dict(formulation="cone"),
        dict(margin_m=-1),
        dict(sigma_m=(0.0, 1.0)),
        dict(max_obstacles=0),
        dict(detour="triangle"),
    ],
)
def test_avoidance_config_rejects_bad_values(bad):
    with pytest.raises(ValueError):
        AvoidanceConfig(**bad)


def test_obstacle_rows_are_separating_half_planes():
    """Each active hard row, evaluated at its own linearization point, says the disc is at least
    r + margin from the obstacle along the row's normal -- never the wrong way round."""
    path = StraightPath([0, 0], [20, 0])
    fp = Footprint(0.5, 0.27)
    ob = Obstacle(Circle(0.3), (3.0, 1.2, 0.0))
    av = Avoidance(AvoidanceConfig("hard", margin_m=0.1), [ob], path, fp, 20, 0.05, Road.constant(4, 0.0))
    s_arr = 1.0 + 0.05 * np.arange(21)
    Xlin = np.column_stack([s_arr, np.zeros(21), np.zeros(21)])
    t = av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory())
    active = np.isfinite(t.rows_b)
    assert active.any()
    lhs = np.einsum("kmi,ki->km", t.rows_a, Xlin[1:, :3])
    # the car on the path is far from an obstacle at y = 1.2: every row holds there
    assert np.all(lhs[active] >= t.rows_b[active] - 1e-9)
    assert math.isfinite(float(t.rows_b[active].max()))


def test_lateral_rows_start_where_the_disc_can_reach_the_obstacle_side_within_a_step():
    """A car standing with its front 2 m behind a parked car, passing left: its front disc is
    not yet beside the car (1.6 m of disc radius and margin short of it), so its row is the
    nearest-point half-plane (a car turning out from standstill may go round the corner), not
    the lateral one that asked for the full passing offset 2 m before the car, with speed
    as the only way to get it. On a plan moving 3 m per step from the same place the disc may
    be beside the car by the next step: the row is lateral, as it was. Before a moving car the
    lateral zone keeps its half car length (a hedge on the prediction: with less, a car driving
    beside the ego got corner rows that had the ego swerve): lateral for the standing plan too."""
    path = StraightPath([0, 0], [100, 0])
    ob = Obstacle(rectangle(4.0, 2.0), (20.0, 0.0, 0.0))
    N = 10
    av = Avoidance(
        AvoidanceConfig("hard", margin_m=0.3, influence_m=20.0), [ob], path, CAR, N, 0.1, Road.constant(12.0)
    )
    front = int(np.argmax(CAR.disc_offsets_m))
    x_stand = 20.0 - 2.0 - 2.0 - 2.5
    for step_m, lateral in ((0.0, False), (3.0, True)):
        xs = x_stand + step_m * np.arange(N + 1)
        Xlin = np.column_stack([xs, np.zeros(N + 1), np.zeros(N + 1), np.full(N + 1, 10.0 * step_m)])
        mem = AvoidanceMemory({0: SIDE_LEFT})
        t = av.terms(0.0, Xlin[0], Xlin, xs, mem)
        n = t.rows_a[0, front, :2]  # the front disc's row at step 1
        if lateral:
            np.testing.assert_allclose(n, [0.0, 1.0], atol=1e-12)
        else:
            assert n[0] < -0.9  # the nearest-point plane: the parked car's rear faces the disc
            assert t.rows_a[0, front] @ Xlin[1, :3] >= t.rows_b[0, front] - 1e-9  # the standing car keeps it
            # the same car driving at 1 m/s (0.1 m per step), starting where the parked one stands
            moving = Obstacle(rectangle(4.0, 2.0), (20.0 - 0.1, 0.0, 0.0), ConstantVelocity(1.0, 0.0))
            av_m = Avoidance(
                AvoidanceConfig("hard", margin_m=0.3, influence_m=20.0),
                [moving],
                path,
                CAR,
                N,
                0.1,
                Road.constant(12.0),
            )
            t_m = av_m.terms(0.0, Xlin[0], Xlin, xs, AvoidanceMemory({0: SIDE_LEFT}))
            np.testing.assert_allclose(t_m.rows_a[0, front, :2], [0.0, 1.0], atol=1e-12)


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


# --------------------------------------------------------------------------- full-size cars in lanes
CAR = Footprint(5.0, 2.0)  # highway-env's car: 5 m x 2 m, three discs


def test_a_gap_narrower_than_the_body_blocks_the_lane():
    """A 2 m car centred in a 5 m lane leaves 1.5 m each side: too little for a 2 m wide car, so
    the lane is blocked (stop behind it), not passed on a side that would need the lane slack."""
    path = StraightPath([0, 0], [100, 0])
    for formulation in ("hard", "corridor"):
        av = Avoidance(
            AvoidanceConfig(formulation, margin_m=0.1, influence_m=30.0),
            [Obstacle(rectangle(5, 2), (20, 0, 0))],
            path,
            CAR,
            10,
            0.2,
            Road.constant(5, 0.0),
        )
        needed = av.passing_room_m
        # the body's full width and both margins, plus (hard) the discs' overhang beyond the body
        assert needed == pytest.approx(2.0 + 0.1 + (CAR.disc_radius_m - 1.0 if formulation == "hard" else 0.0))
        s_arr = 2.0 * np.arange(11.0)
        Xlin = np.column_stack([s_arr, np.zeros(11), np.zeros(11)])
        assert av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory()).sides == {0: SIDE_BLOCKED}
        # moved 1.5 m to the right it leaves 3 m on the left: pass there
        av.obstacles = [Obstacle(rectangle(5, 2), (20, -1.5, 0))]
        assert av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory()).sides == {0: SIDE_LEFT}


def test_a_moving_obstacle_is_judged_where_the_car_meets_it():
    """A car now in the next lane, cutting into ours: beside the lane now, in it when we get
    there -- the lane is blocked."""
    path = StraightPath([0, 0], [200, 0])
    cutting_in = Obstacle(rectangle(5, 2), (10.0, -5.0, 0.0), ConstantVelocity(5.0, 2.5))
    av = Avoidance(
        AvoidanceConfig("hard", margin_m=0.1, influence_m=40.0), [cutting_in], path, CAR, 15, 0.2, Road.constant(5, 0.0)
    )
    s_arr = 2.0 * np.arange(16.0)  # 10 m/s
    Xlin = np.column_stack([s_arr, np.zeros(16), np.zeros(16)])
    assert av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory()).sides == {0: SIDE_BLOCKED}
    # the same car staying in its lane is passed on our side of it
    av.obstacles = [Obstacle(rectangle(5, 2), (10.0, -5.0, 0.0), ConstantVelocity(5.0, 0.0))]
    assert av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory()).sides == {0: SIDE_LEFT}


def test_stop_line_lies_across_the_cars_own_road_in_a_bend():
    """Behind a car blocking the lane in a bend, the stop half-plane is the path's tangent where
    the car's front disc will be (a plane through the bend further on would reward moving
    sideways), or at the stop line once it would pass it; its boundary holds the disc back by
    the clearance along the path."""
    path = CirclePath((0.0, 0.0), 20.0)
    cfg = AvoidanceConfig("hard", margin_m=0.3, influence_m=40.0)
    s_ob = 12.0  # the blocking car's centre, 12 m along the circle
    th = s_ob / 20.0
    ob = Obstacle(rectangle(5, 2), (20 * math.cos(th), 20 * math.sin(th), th + math.pi / 2))
    N = 10
    av = Avoidance(cfg, [ob], path, CAR, N, 0.2, Road.constant(5, 0.0))
    s_arr = 0.7 * np.arange(N + 1.0)  # 3.5 m/s: the front disc passes the stop line at the end
    Xlin = np.column_stack([20 * np.cos(s_arr / 20), 20 * np.sin(s_arr / 20), s_arr / 20 + math.pi / 2])
    t = av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory())
    assert t.sides == {0: SIDE_BLOCKED}
    front = CAR.n_discs - 1
    o = CAR.disc_offsets_m[front]
    s_stop = s_ob - 2.5 - (CAR.disc_radius_m + cfg.margin_m)
    s_bar = np.minimum(s_arr[1:] + o, s_stop)
    assert s_bar[0] < s_stop - 4.0 and s_bar[-1] == s_stop
    tangent = np.column_stack([np.cos(s_bar / 20 + math.pi / 2), np.sin(s_bar / 20 + math.pi / 2)])
    np.testing.assert_allclose(t.rows_a[:, front, :2], -tangent, atol=0.01)
    # on the boundary: the front disc on the path at the stop arc length (a bend bends it by a few cm)
    for k in (0, 4, N - 1):
        yaw = Xlin[k + 1, 2]
        centre = path.position(s_stop) - o * np.array([math.cos(yaw), math.sin(yaw)])
        assert t.rows_a[k, front] @ [*centre, yaw] - t.rows_b[k, front] == pytest.approx(0.0, abs=0.1)


def test_no_stop_line_for_a_car_on_a_stretch_of_road_that_only_passes_near_by():
    """On a closed track the far side of the loop may lie within the influence distance: a car
    there blocks 'the lane' 60 m ahead along the path, beyond the horizon -- no stop line and no
    reference cap, so the car drives on."""
    path = CirclePath((0.0, 0.0), 15.0)  # the far side is 30 m away, 47 m along the path
    ob = Obstacle(rectangle(5, 2), (-15.0, 0.0, -math.pi / 2))
    cfg = AvoidanceConfig("hard", margin_m=0.3, influence_m=40.0, follow_gap_s=1.0)
    N = 10
    av = Avoidance(cfg, [ob], path, CAR, N, 0.2, Road.constant(5, 0.0))
    s_arr = 2.0 * np.arange(N + 1.0)
    Xlin = np.column_stack([15 * np.cos(s_arr / 15), 15 * np.sin(s_arr / 15), s_arr / 15 + math.pi / 2])
    t = av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory())
    assert t.sides == {0: SIDE_BLOCKED} and t.s_max is None
    # every row holds on the car's own plan (no half-plane cuts across its road)
    active = np.isfinite(t.rows_b)
    lhs = np.einsum("kmi,ki->km", t.rows_a, Xlin[1:, :3])
    assert np.all(lhs[active] >= t.rows_b[active] - 1e-9)
    # the same car 8 m ahead of us is within reach: stop line and cap
    av.obstacles = [Obstacle(rectangle(5, 2), (15 * math.cos(8 / 15), 15 * math.sin(8 / 15), 8 / 15 + math.pi / 2))]
    t = av.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory())
    assert t.s_max is not None and t.s_max[0] == pytest.approx(8.0 - 2.5 - av.stop_distance_m, abs=0.05)


def _circle_follower(path: CirclePath, s0: float, v: float, t_end: float) -> Obstacle:
    """A 5 m x 2 m car driving along the circle from arc length s0 at v [m/s]."""
    t = np.arange(0.0, t_end, 0.1)
    s = s0 + v * t
    P = path.position(s)
    yaw = np.asarray(path.heading(s))
    return Obstacle(
        rectangle(5, 2),
        (P[0, 0], P[0, 1], yaw[0]),
        TrajectoryMotion(t, P[:, 0] - P[0, 0], P[:, 1] - P[0, 1], yaw - yaw[0]),
        "leader",
    )


def _bend_follower(follow_gap_s, backend: str, osqp: OsqpSettings = OsqpSettings()):
    """A car at 10 m/s closing on a car driving 6 m/s ahead in its lane on a 20 m circle: the
    controller (``backend``), the leader, the plant's start and its step count."""
    path = CirclePath((0.0, 0.0), 20.0)
    model = KinematicBicycle4(KinematicParams(2.5, 2.5))
    dt, N, steps = 0.2, 15, 120
    pb = MpcProblem(
        4,
        2,
        N,
        dt,
        Q=[1.0, 1.0, 2.0, 0.5],
        R=[1.0, 0.05],
        Rc=[20.0, 0.05],
        u_min=[-0.78, -5.0],
        u_max=[0.78, 5.0],
        du_max_per_s=[1.0, np.inf],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [20.0],
        road=Road.constant(5.0, 0.0),
    )
    leader = _circle_follower(path, 25.0, 6.0, dt * steps + 10.0)
    cfg = AvoidanceConfig("hard", margin_m=0.3, influence_m=30.0, follow_gap_s=follow_gap_s)
    c = LtvMpc(
        model,
        path,
        pb,
        MpcConfig(v_ref_mps=10.0, projection_window_m=6.0),
        "condensed" if backend == "fast" else "osqp",
        osqp_settings=osqp,
        obstacles=(leader,),
        avoidance=cfg,
        footprint=CAR,
    )
    assert c.backend_name == backend
    return c, leader, np.array([20.0, 0.0, math.pi / 2, 10.0]), steps


@pytest.mark.parametrize("backend", ["osqp", "fast"])
@pytest.mark.parametrize("follow_gap_s", [None, 1.0])
def test_following_a_slower_car_in_a_bend(follow_gap_s, backend):
    """A car at 10 m/s closes on a car driving 6 m/s ahead in its lane on a 20 m circle. With a
    follow gap the references trail the leader by that time gap: the car settles at its speed,
    the gap and the lane centre. Without it the references run on at 10 m/s and pull the car
    against the stop constraint, which in a bend it eases by cutting inwards. Both solvers."""
    c, leader, x0, steps = _bend_follower(follow_gap_s, backend)
    road = c.problem.road
    r = simulate(c, Plant(c.model), c.path, x0, c.dt_s, steps, obstacles=(leader,), footprint=CAR, road=road)
    m = compute_metrics(r)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] > 0.2
    assert m["solver_failures"] == 0 and m["fallbacks"] == 0
    late = slice(steps // 2, None)
    assert np.abs(r.v_mps[late] - 6.0).max() < 0.2
    # centre to centre along the path: a car length, the stop line's bumper gap, the time gap
    stop_gap = c.avoidance.stop_distance_m - 2.5
    arc_gap = 25.0 + 6.0 * r.t_s[late] - r.s_m[late]
    if follow_gap_s is None:  # held back by the stop constraint alone, a little off-centre
        np.testing.assert_allclose(arc_gap, 5.0 + stop_gap, atol=0.1)
        assert abs(r.e_y_m[-1]) > 0.05
    else:
        np.testing.assert_allclose(arc_gap, 5.0 + stop_gap + follow_gap_s * 6.0, atol=0.2)
        assert np.abs(r.e_y_m).max() < 0.15 and abs(r.e_y_m[-1]) < 0.03


def test_car_following_on_the_compiled_controller_gives_tight_osqps_commands():
    """Car following's references (behind the moving stop line) on the compiled controller: fed
    the states of OSQP's closed loop (at 1e-9) and OSQP's own warm start, it gives OSQP's command
    on every step OSQP solves, within 1e-5 (the comparison of the other constraint rows)."""
    tight = OsqpSettings(eps_abs=1e-9, eps_rel=1e-9, max_iter=50000)
    ref, leader, x0, steps = _bend_follower(1.0, "osqp", tight)
    fast = _bend_follower(1.0, "fast")[0]
    r = simulate(ref, Plant(ref.model), ref.path, x0, ref.dt_s, steps, obstacles=(leader,), footprint=CAR)
    warm = ref.initial_warm(r.x[0])
    du, held = [], 0
    for k in range(r.steps):
        o_ref, o_fast = ref.step(r.x[k], warm), fast.step(r.x[k], warm)
        assert o_fast.status == "ok", (k, o_fast.status)
        if o_ref.status == "ok":
            du.append(float(np.abs(o_fast.u - o_ref.u).max()))
        held += int(o_ref.refs[-1, 3] < 9.0)  # references held back behind the leader
        warm = o_ref.warm
    assert held > steps // 2 and len(du) >= 0.97 * r.steps
    assert max(du) <= 1e-5, f"max |du| {max(du):.2e}"


def test_set_obstacles_replaces_what_the_controller_avoids():
    """Moving obstacles handed over afresh each step: the QP keeps its size, the plan follows."""
    path = StraightPath([0, 0], [300, 0])
    model = KinematicBicycle4(KinematicParams(2.5, 2.5))
    pb = MpcProblem(
        4,
        2,
        15,
        0.2,
        Q=[1.0, 1.0, 2.0, 0.5],
        R=[1.0, 0.05],
        u_min=[-0.78, -5.0],
        u_max=[0.78, 5.0],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [20.0],
        road=Road.constant(5.0, 0.0),
    )
    stopped_ahead = Obstacle(rectangle(5, 2), (20.0, 0.0, 0.0), name="stopped")
    cfg = AvoidanceConfig("hard", margin_m=0.3, influence_m=30.0, max_obstacles=2, follow_gap_s=1.0)
    c = PythonLtvMpc(
        model, path, pb, MpcConfig(v_ref_mps=10.0), "osqp", obstacles=(stopped_ahead,), avoidance=cfg, footprint=CAR
    )
    x = np.array([0.0, 0.0, 0.0, 10.0])
    rows = c.qp.problem.obstacle_rows
    brake = c.step(x, c.initial_warm(x))
    assert brake.u[1] < -2.0  # 12.5 m to its rear at 10 m/s
    # it drives off at 10 m/s and a second car appears far behind: no reason to brake
    moving = Obstacle(rectangle(5, 2), (20.0, 0.0, 0.0), ConstantVelocity(10.0, 0.0), name="moving")
    behind = Obstacle(rectangle(5, 2), (-60.0, -5.0, 0.0), ConstantVelocity(10.0, 0.0), name="behind")
    c.set_obstacles([moving, behind])
    assert c.obstacles == (moving, behind)
    free = c.step(x, c.initial_warm(x))
    assert free.u[1] > -0.5 and free.status == "ok"
    assert c.qp.problem.obstacle_rows == rows == 2 * CAR.n_discs
    with pytest.raises(ValueError, match=r"obstacles\[1\] must be an Obstacle"):
        c.set_obstacles([moving, (1.0, 2.0)])
    bare = PythonLtvMpc(model, path, pb, MpcConfig(v_ref_mps=10.0), "osqp")
    assert bare.obstacles == ()
    with pytest.raises(ValueError, match="built without obstacles"):
        bare.set_obstacles([moving])
