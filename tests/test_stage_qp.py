"""One stage QP, two solvers: the compiled assembly's stage QP (``CompiledLtvMpc.prepare``) is the
OSQP controller's (``LtvMpc.prepare``) field by field, and OSQP solving it (``solver="osqp"``)
drives the closed loop the OSQP controller drives.

The cases cover what the oracle test (``test_solver_oracle``, hard rows) does not: the cost
formulations (their convex model enters the stage QP as the position cost ``H``, ``g``), the
corridor, the friction circle's per-stage input bounds, the paper's frozen linearization, a
lateral reference with a speed cap (the step in two stages), a planner's longitudinal plan
(the first step, with no plan of its own, linearized along the plan's rollout), SQP iterates, prediction
substeps (each step of the model taken as three, their Jacobians chained), and the cost
formulations on recorded trajectories (a turning box with a lifetime, a drifting disc).
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from mpcdrive.control import FastPathUnavailable, LtvMpc, MpcConfig, PythonLtvMpc
from mpcdrive.control.compiled_mpc import CompiledLtvMpc, CondensedSettings
from mpcdrive.models import KinematicBicycle3, KinematicBicycle4
from mpcdrive.models.discretize import discrete_step
from mpcdrive.ocp import MpcProblem
from mpcdrive.ocp.avoidance import AvoidanceConfig
from mpcdrive.ocp.stage_qp import new_stage_qp, steering_weight_factor, weigh_steering
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.scene import Circle, Obstacle, Polygon, TrajectoryMotion
from mpcdrive.scene.road import Road
from mpcdrive.solvers.osqp_backend import OsqpSettings

from test_solver_oracle import same_step_data

#: both OSQP solves at 1e-9 (the tolerances below follow from it)
OSQP = OsqpSettings(eps_abs=1e-9, eps_rel=1e-9, max_iter=100000)
#: the two assemblies compute the same numbers in a different order: they agree to rounding
#: (measured: 3e-11 at most on these cases, in fields of size up to 1e2); 1e-9 is the room for
#: rounding through the linearization
ASSEMBLY_TOL = 1e-9
#: OSQP on two stage QPs equal to rounding, with the same settings and warm starts: the plans
#: differ by rounding carried through its iterations and through the closed loop (measured:
#: 5e-12 at most over 40 steps), far below its stopping rule's 1e-9 scaled by the problem's
#: sensitivity; a wrong row, weight or bound moves a plan by centimetres
LOOP_TOL = 1e-6

CASES = [
    "plain",
    "potential",
    "gaussian",
    "hard",
    "corridor",
    "friction",
    "paper",
    "lateral-cap",
    "plan",
    "sqp",
    "substeps",
    "recorded-potential",
    "recorded-gaussian",
    "steer-speed",
]


def _controllers(case: str, curved: bool):
    model = KinematicBicycle4()
    path = CirclePath((0.0, 0.0), 20.0) if curved else StraightPath([0.0, 0.0], [100.0, 0.0])
    kw = dict(
        Q=np.diag([1.0, 5.0, 1.0, 1.0]),
        R=np.diag([1.0, 0.1]),
        Rc=np.diag([0.1, 0.01]),
        u_min=[-0.5, -3.0],
        u_max=[0.5, 2.0],
        du_max_per_s=[1.0, 5.0],
        road=Road.constant(4.0, 0.05),
    )
    if case == "friction":
        kw["friction_accel_mps2"] = 4.0
    pb = MpcProblem(4, 2, 20, 0.1, **kw)
    cfg = MpcConfig(
        v_ref_mps=5.0,
        linearization="paper" if case == "paper" else "trajectory",
        sqp_max_iterations=3 if case == "sqp" else 1,
        sqp_tol=1e-9,
        prediction_substeps=3 if case == "substeps" else 1,
        # the steering's weights grow as (v / 2.5)^4 while the plan brakes from 5 m/s: 16 times,
        # then a different factor each step (the sparse layout rewrites its entries)
        steer_weight_speed_mps=2.5 if case == "steer-speed" else None,
    )
    obstacles, av = (), None
    form = {
        "potential": "potential",
        "gaussian": "gaussian",
        "hard": "hard",
        "corridor": "corridor",
        "sqp": "potential",
    }
    if case in form:
        s_ob = 6.0
        p, h = path.position(s_ob), float(path.heading(s_ob))
        obstacles = (Obstacle(Circle(0.5), (p[0] - 0.3 * math.sin(h), p[1] + 0.3 * math.cos(h), 0.0)),)
        av = AvoidanceConfig(form[case], weight=50.0)
    if case.startswith("recorded-"):
        obstacles = _recorded_obstacles(path)
        # Sigma longer along the path than across: the path's heading at the box enters the cost
        av = AvoidanceConfig(case.removeprefix("recorded-"), weight=50.0, sigma_m=(1.2, 0.5))
    ref = PythonLtvMpc(model, path, pb, cfg, "osqp", osqp_settings=OSQP, obstacles=obstacles, avoidance=av)
    fo = CompiledLtvMpc(model, path, pb, cfg, obstacles=obstacles, avoidance=av, solver="osqp", osqp_settings=OSQP)
    if case == "lateral-cap":
        for c in (ref, fo):
            c.set_lateral_reference(lambda s: 0.4 * np.sin(0.2 * np.asarray(s)))
            c.set_speed_cap(3.0, 2.0)
    if case in ("plan", "steer-speed"):  # a planner's: braking to a stop at 3 m/s^2 where the profile holds 5 m/s
        v = np.maximum(5.0 - 3.0 * 0.1 * np.arange(pb.N + 1), 0.0)
        s = np.r_[0.0, np.cumsum(0.05 * (v[1:] + v[:-1]))]
        for c in (ref, fo):
            c.set_longitudinal_plan(s, v)
    x0 = np.array([*path.position(0.0), float(path.heading(0.0)), 5.0])
    return model, ref, fo, x0


def _recorded_obstacles(path):
    """A box that a recording moves across the path ahead while turning, present from 0.5 s to
    2.5 s (its lifetime starts and ends inside the horizons of the drive), and a disc that
    drifts along beside the path for the whole drive."""
    t = np.array([0.0, 1.0, 2.0, 3.0])
    p, h = path.position(9.0), float(path.heading(9.0))
    n = np.array([-math.sin(h), math.cos(h)])
    box = Obstacle(
        Polygon(np.array([[-0.2, -0.4], [1.4, -0.4], [1.4, 0.4], [-0.2, 0.4]])),  # its vertex mean off its pose
        (*(p + 1.5 * n), h + 0.3),
        TrajectoryMotion(t, -0.6 * t * n[0], -0.6 * t * n[1], np.array([0.0, 0.2, 0.5, 0.6])),
        t_start_s=0.5,
        t_end_s=2.5,
    )
    q = path.position(14.0)
    disc = Obstacle(Circle(0.4), (*(q - 0.9 * n), 0.0), TrajectoryMotion(t, 0.8 * t, 0.1 * t, np.zeros(4)))
    return (box, disc)


@pytest.mark.parametrize("curved", [False, True], ids=["straight", "circle"])
@pytest.mark.parametrize("case", CASES)
def test_compiled_assembly_is_the_osqp_controllers_stage_qp_and_drives_the_same_loop(case, curved):
    model, ref, fo, x = _controllers(case, curved)
    warm = ref.initial_warm(x)
    wo = fo.initial_warm(x)
    cost_terms = False
    factors = set()
    for k in range(40):
        d = ref.prepare(x, warm)
        rows = case in ("hard", "corridor")
        same_step_data(fo.prepare(x, warm), d, atol=ASSEMBLY_TOL, sides=rows)
        cost_terms |= bool(np.abs(d.qp.We - ref.problem.stage_weights()).max() > 1e-6)
        factors.add(round(float(d.qp.R[0, 0] / ref.problem.R[0, 0]), 9))
        if case == "sqp" and k == 3:  # an SQP iterate: re-linearized at a plan of its own
            res = ref._solve(d, warm)
            around = (res.X.copy(), res.U.copy())
            d2 = ref.prepare(x, warm, around=around, s_m=d.s_m)
            same_step_data(fo.prepare(x, warm, around=around, s_m=d.s_m), d2, atol=ASSEMBLY_TOL, sides=False)
        a = ref.step(x, warm)
        b = fo.step(x, wo)
        assert (a.status, a.fallback) == (b.status, b.fallback) == ("ok", "")
        np.testing.assert_allclose(b.X_pred, a.X_pred, rtol=0, atol=LOOP_TOL)
        np.testing.assert_allclose(b.u, a.u, rtol=0, atol=LOOP_TOL)
        assert a.sqp_iterations == b.sqp_iterations
        x = discrete_step(model, x, a.u, 0.1, "rk4")
        warm, wo = a.warm, b.warm
    if case in ("potential", "gaussian", "sqp") or case.startswith("recorded-"):
        assert cost_terms, "the obstacle cost never entered the stage QP: the case tests nothing"
    if case == "steer-speed":
        assert len(factors) > 10 and max(factors) == 16.0, factors
        assert ref.problem.R[0, 0] == 1.0  # the problem's own weights untouched
    else:
        assert factors == {1.0}


def test_steering_weight_factor_holds_the_lateral_bandwidth_and_scales_only_the_steering():
    assert steering_weight_factor(5.0, None) == 1.0
    assert steering_weight_factor(10.0, 13.9) == steering_weight_factor(13.9, 13.9) == 1.0
    assert steering_weight_factor(27.8, 13.9) == pytest.approx(16.0)  # twice the speed: 2^4
    assert steering_weight_factor(math.nan, 13.9) == 1.0
    # the double integrator e'' = (v^2 / L) delta under LQR q e^2 + r delta^2 has the natural
    # frequency (q / r)^(1/4) sqrt(v^2 / L): with r grown by the factor it is that of 13.9 m/s
    L, v0, v, q_over_r = 2.6, 13.9, 33.0, 0.1
    w0 = q_over_r**0.25 * math.sqrt(v0**2 / L)
    w = (q_over_r / steering_weight_factor(v, v0)) ** 0.25 * math.sqrt(v**2 / L)
    assert w == pytest.approx(w0)
    pb = MpcProblem(4, 2, 5, 0.1, Q=np.eye(4), R=[[2.0, 0.5], [0.5, 1.0]], Rc=np.diag([3.0, 0.0]))
    qp = new_stage_qp(pb)
    weigh_steering(qp, pb, 0, 9.0)
    np.testing.assert_array_equal(qp.R, [[18.0, 1.5], [1.5, 1.0]])  # the cross term sqrt(9) times
    np.testing.assert_array_equal(qp.Rc, [[27.0, 0.0], [0.0, 0.0]])
    np.testing.assert_array_equal(pb.R, [[2.0, 0.5], [0.5, 1.0]])  # the problem's untouched
    weigh_steering(qp, pb, 0, 1.0)
    np.testing.assert_array_equal(qp.R, pb.R)
    with pytest.raises(ValueError, match="steer_weight_speed_mps"):
        MpcConfig(steer_weight_speed_mps=-1.0)


def test_steering_weights_grown_with_speed_reach_osqp_and_the_condensed_solver_alike():
    """``steer_weight_speed_mps``: the step's steering weights (16 times the problem's at 5 m/s
    above 2.5 m/s, less as the plan brakes) are what OSQP on the sparse layout and the condensed
    solver both minimize: the same loop from 0.5 m off the line, which the constant weights drive
    differently (the grown ones steer back more gently: measured, at most 0.10 rad against
    0.17 rad with constant weights)."""
    model, ref, _, x = _controllers("steer-speed", False)
    fc = CompiledLtvMpc(model, ref.path, ref.problem, ref.config)
    plain = CompiledLtvMpc(model, ref.path, ref.problem, dataclasses.replace(ref.config, steer_weight_speed_mps=None))
    for c in (fc, plain):
        c.set_longitudinal_plan(*ref._plan)
    x = x + np.array([0.0, 0.5, 0.0, 0.0])
    w1, w2, w3 = ref.initial_warm(x), fc.initial_warm(x), plain.initial_warm(x)
    apart = 0.0
    for _ in range(30):
        a, b, c = ref.step(x, w1), fc.step(x, w2), plain.step(x, w3)
        assert (a.status, b.status) == ("ok", "ok")
        np.testing.assert_allclose(b.u, a.u, rtol=0, atol=LOOP_TOL)
        apart = max(apart, abs(float(c.u[0] - a.u[0])))
        x = discrete_step(model, x, a.u, 0.1, "rk4")
        w1, w2, w3 = a.warm, b.warm, c.warm
    assert apart > 0.01  # rad: the weights changed the steering


def test_condensed_solver_keeps_the_obstacle_cost_when_the_step_runs_in_two_stages():
    """A speed cap (or a lateral reference) runs the compiled step in two stages; the obstacles
    the first selects for the cost formulations must reach the second (they once did not: the
    compiled controller drove 0.63 m from the OSQP controller's plan, as if without obstacles)."""
    model, ref, _, x = _controllers("potential", False)
    x[0] = 3.0  # 3 m behind the obstacle, within its influence
    fast = CompiledLtvMpc(
        model, ref.path, ref.problem, ref.config, obstacles=ref.obstacles, avoidance=ref.avoidance.config
    )
    bare = CompiledLtvMpc(model, ref.path, ref.problem, ref.config)
    for c in (ref, fast, bare):
        c.set_speed_cap(30.0)
    a = ref.step(x, ref.initial_warm(x))
    b = fast.step(x, fast.initial_warm(x))
    c = bare.step(x, bare.initial_warm(x))
    assert np.abs(c.X_pred - a.X_pred).max() > 0.1  # the obstacle matters here
    # the condensed QP's exact optimum against OSQP's at 1e-9 (test_fast_path's tolerance)
    np.testing.assert_allclose(b.X_pred, a.X_pred, rtol=0, atol=1e-6)


def test_factory_lets_osqp_solve_the_compiled_stage_qp_beyond_the_condensed_limits():
    """Only the condensed solver's limits exclude the problem: the compiled step still assembles,
    OSQP solves, and the notice says so."""
    model = KinematicBicycle3(1.0)
    path = StraightPath([0.0, 0.0], [20.0, 0.0])
    pb = MpcProblem(3, 1, 200, 0.05, Q=np.diag([1.0, 5.0, 1.0]), R=1.0, u_min=-0.5, u_max=0.5)  # 200 variables
    from mpcdrive.control.compiled_mpc import CondensedSettings

    with pytest.warns(FastPathUnavailable, match="condensed solver not used: .*max_variables=100.*OSQP solves"):
        c = LtvMpc(model, path, pb, condensed_settings=CondensedSettings(max_variables=100))
    assert isinstance(c, CompiledLtvMpc) and (c.backend_name, c.assembly) == ("osqp", "compiled")
    ref = LtvMpc(model, path, pb, solver="osqp", osqp_settings=OsqpSettings(eps_abs=1e-9, eps_rel=1e-9))
    x = np.array([0.0, 0.3, 0.05])
    a, b = ref.step(x, ref.initial_warm(x)), c.step(x, c.initial_warm(x))
    assert a.status == b.status == "ok"
    # c's OSQP runs at the default settings (1e-5 here): its stopping rule bounds the difference
    np.testing.assert_allclose(b.u, a.u, rtol=0, atol=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert LtvMpc(model, path, pb).backend_name == "fast"  # within the default limit
    with pytest.raises(ValueError, match="solver must be"):
        CompiledLtvMpc(model, path, pb, solver="ipopt")


@pytest.mark.parametrize("curved", [False, True], ids=["straight", "circle"])
@pytest.mark.parametrize("case", CASES)
def test_condensed_solver_on_the_python_assembly_drives_the_compiled_controllers_loop(case, curved):
    """``PythonLtvMpc(..., "condensed")``: the Python assembly's stage QP solved by the compiled
    condensed solver gives the compiled controller's plans (the same QP to rounding, the same
    exact active-set solver: measured 3e-12 m at most over 40 steps)."""
    model, ref, fo, x = _controllers(case, curved)
    av = ref.avoidance.config if ref.avoidance is not None else None
    py = PythonLtvMpc(
        model,
        ref.path,
        fo.problem,
        ref.config,
        "condensed",
        condensed_settings=CondensedSettings(),
        obstacles=ref.obstacles,
        avoidance=av,
    )
    fc = CompiledLtvMpc(model, ref.path, fo.problem, ref.config, obstacles=ref.obstacles, avoidance=av)
    assert (py.backend_name, py.assembly, fc.assembly) == ("fast", "python", "compiled")
    if case == "lateral-cap":
        for c in (py, fc):
            c.set_lateral_reference(lambda s: 0.4 * np.sin(0.2 * np.asarray(s)))
            c.set_speed_cap(3.0, 2.0)
    w1, w2 = py.initial_warm(x), fc.initial_warm(x)
    for _ in range(40):
        a, b = py.step(x, w1), fc.step(x, w2)
        assert (a.status, a.fallback) == (b.status, b.fallback) == ("ok", "")
        np.testing.assert_allclose(a.X_pred, b.X_pred, rtol=0, atol=LOOP_TOL)
        np.testing.assert_allclose(a.u, b.u, rtol=0, atol=LOOP_TOL)
        x = discrete_step(model, x, a.u, 0.1, "rk4")
        w1, w2 = a.warm, b.warm


def test_a_problem_without_compiled_assembly_is_solved_by_the_condensed_solver():
    """A speed profile with the paper's fixed-step horizon has no compiled assembly: ``LtvMpc``
    assembles in Python and solves with the condensed solver, says so, and drives OSQP's loop."""
    from dataclasses import replace

    from mpcdrive.paths import ConstantSpeed

    model, ref, _, x = _controllers("hard", True)
    cfg = replace(ref.config, v_ref_mps=None, speed_profile=ConstantSpeed(5.0), horizon="paper", horizon_step_m=0.5)
    av = ref.avoidance.config
    with pytest.warns(FastPathUnavailable, match="compiled step not used: a speed profile with the 'paper' horizon"):
        c = LtvMpc(model, ref.path, _controllers("hard", True)[2].problem, cfg, obstacles=ref.obstacles, avoidance=av)
    assert isinstance(c, LtvMpc) and (c.backend_name, c.assembly) == ("fast", "python")
    o = PythonLtvMpc(model, ref.path, c.problem, cfg, "osqp", osqp_settings=OSQP, obstacles=ref.obstacles, avoidance=av)
    w1, w2 = c.initial_warm(x), o.initial_warm(x)
    for _ in range(30):
        a, b = c.step(x, w1), o.step(x, w2)
        assert a.status == b.status == "ok"
        # the condensed QP's exact optimum against OSQP's at 1e-9 (test_fast_path's tolerance)
        np.testing.assert_allclose(a.X_pred, b.X_pred, rtol=0, atol=1e-6)
        x = discrete_step(model, x, a.u, 0.1, "rk4")
        w1, w2 = a.warm, b.warm


def test_replaced_recorded_obstacles_reach_the_compiled_cost():
    """``set_obstacles`` with recordings of other lengths (the compiled arrays change shape, so
    the assembly's struct is made anew) and with the same shapes (written in place): the
    compiled stage QP stays the Python assembly's."""
    model, ref, fo, x = _controllers("recorded-potential", True)
    warm = ref.initial_warm(x)
    box, disc = ref.obstacles
    t = np.linspace(0.0, 3.0, 7)

    def recorded_box(vx, vy):
        motion = TrajectoryMotion(t, vx * t, vy * t, 0.1 * t)
        return Obstacle(box.shape, box.pose, motion, t_start_s=box.t_start_s, t_end_s=box.t_end_s)

    longer, moved = recorded_box(-0.5, 0.2), recorded_box(-0.4, -0.3)
    used = 0
    for k in range(12):
        if k in (3, 8):
            new = (longer, disc) if k == 3 else (moved, disc)
            ref.set_obstacles(new)
            fo.set_obstacles(new)
        d = ref.prepare(x, warm)
        same_step_data(fo.prepare(x, warm), d, atol=ASSEMBLY_TOL, sides=False)
        used += k >= 3 and bool(np.abs(d.qp.We - ref.problem.stage_weights()).max() > 1e-6)
        a = ref.step(x, warm)
        x = discrete_step(model, x, a.u, 0.1, "rk4")
        warm = a.warm
    assert used, "the replaced obstacles never entered the cost: the test tests nothing"


def test_a_new_road_margin_survives_new_obstacle_arrays():
    """``set_road`` with another margin, then recordings of another length (the assembly's struct
    is made anew from its arrays): the compiled road bounds keep the new margin, as the Python
    assembly's do."""
    model, ref, fo, x = _controllers("recorded-potential", True)
    warm = ref.initial_warm(x)
    wider = Road.constant(4.0, 0.4)
    box, disc = ref.obstacles
    t = np.linspace(0.0, 3.0, 7)
    longer = Obstacle(disc.shape, disc.pose, TrajectoryMotion(t, 0.5 * t, 0.1 * t, 0.0 * t))
    for c in (ref, fo):
        c.set_road(wider)
        c.set_obstacles((box, longer))
    d = ref.prepare(x, warm)
    same_step_data(fo.prepare(x, warm), d, atol=ASSEMBLY_TOL, sides=False)
