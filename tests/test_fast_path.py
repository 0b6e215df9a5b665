"""The compiled fast path against the OSQP reference: same commands, same closed loops, exact
QP solutions, statuses and fallbacks, and a compile cache that a new process reuses.

Tolerances (named here, used below):
* COMMAND_TOL_RAD: |u_fast - u_osqp| per step when both controllers see the same measured states
  (the first 200 steps of every built-in scenario, and random states of problems with every
  supported constraint). OSQP solves to 1e-5 (polished), the active-set solver exactly.
* Closed-loop metrics of a whole run: RMS lateral error within METRIC_TOL_M + 1 %, max |steer|
  within COMMAND_TOL_RAD, the same failure and fallback counts.
"""

import json
import math
import subprocess
import sys
import warnings
from pathlib import Path
from dataclasses import replace

import numpy as np
import pytest

from mpcdrive.control import FastPathUnavailable, LtvMpc, MpcConfig, PythonLtvMpc
from mpcdrive.control.compiled_mpc import CompiledLtvMpc, CondensedSettings, fast_unsupported_reason
from mpcdrive.models import KinematicBicycle3, KinematicBicycle4, KinematicParams
from mpcdrive.models.discretize import discrete_step, discrete_step_and_jacobians
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import CirclePath, ConstantSpeed, SpeedProfile, StraightPath, WaypointPath
from mpcdrive.scenarios import build_experiment, builtin_ids, load_scenario, run_experiment
from mpcdrive.sim import Plant, compute_metrics, simulate
from mpcdrive.solvers.dense_qp import DenseQpSolver
from mpcdrive.solvers.osqp_backend import OsqpSettings
from mpcdrive.control.fallback import FallbackConfig
from mpcdrive.scene import Footprint
from mpcdrive.scene.road import Road
from mpcdrive.types import WarmStart

COMMAND_TOL_RAD = 1e-4
METRIC_TOL_M = 1e-3
STEER = math.radians(60)
TIGHT = OsqpSettings(eps_abs=1e-9, eps_rel=1e-9, max_iter=50000)


def _with_backend(spec, backend):
    return spec.model_copy(update={"controller": spec.controller.model_copy(update={"backend": backend})})


# ------------------------------------------------------------------------------ built-in scenarios
#: built-in scenarios the fast path covers (kinematic and dynamic models, obstacle costs, speed
#: profiles, the kinematic MPC on a dynamic plant, actuator delay, parameter mismatch)
FAST_SCENARIOS = [
    "paper-exp1",
    "paper-exp2",
    "paper-exp3",
    "paper-exp4",
    "paper-disturbance-v1",
    "paper-disturbance-v4",
    "paper-smoothing",
    "paper-exp5-potential",
    "paper-exp5-gaussian",
    "paper-exp5-hard",
    "paper-exp5-corridor",
    "mismatch-kinematic-mpc",
    "track-hairpins",
    "delay-compensated",
]
#: dynamic-model scenarios checked against OSQP at 1e-10 instead (test_fast_dynamic_scenarios_match_tight_osqp):
#: on delay-uncompensated OSQP at its scenario tolerance (1e-5) stops short on some steps (status
#: ok, acceleration off by 0.05 m/s^2 at step 163; at 1e-10 it agrees with the fast path); the
#: closed loop of track-raceway is chaotic: a 1e-12 m change of the start position changes OSQP's
#: own RMS lateral error by more than METRIC_TOL_M (test_track_raceway_closed_loop_is_chaotic) --
#: DynamicBicycle.steady_state_full, the references of both controllers, jumps near the grip limit
#: (the slip of a horizon point can switch branch for a 1e-9 m change of the state) --, so its
#: closed-loop metrics are compared only where they do not depend on rounding
#: mismatch-params: the road rows (the body inside the raceway's edges, linearized in the yaw) are
#: active on some steps, where OSQP at the scenario's 1e-5 stops up to 0.12 m/s^2 short
TIGHT_DYNAMIC_SCENARIOS = ["track-raceway", "delay-uncompensated", "mismatch-params"]
#: built-in scenarios with obstacle constraint rows where OSQP at its scenario tolerance stops short
#: on some steps (status max_iter / inaccurate, then a fallback): checked against OSQP at 1e-9
ROW_SCENARIOS = ["obstacle-overtake", "obstacle-slalom", "obstacle-crossing", "obstacle-blocked"]


def test_unsupported_scenarios_fall_back_to_osqp():
    assert set(FAST_SCENARIOS) | set(ROW_SCENARIOS) | set(TIGHT_DYNAMIC_SCENARIOS) <= set(builtin_ids())
    # a speed profile on the paper's fixed-step horizon has no compiled form: declined by name
    b = build_experiment(_with_backend(load_scenario("track-raceway"), "osqp")).mpc
    # (no compiled assembly: the stage QP is assembled in Python, the condensed solver solves it)
    paper = replace(b.config, horizon="paper")
    with pytest.warns(UserWarning, match="compiled step not used: a speed profile with the 'paper' horizon"):
        ctrl = LtvMpc(b.model, b.path, b.problem, paper)
    assert isinstance(ctrl, LtvMpc) and (ctrl.backend_name, ctrl.assembly) == ("fast", "python")
    # and where the condensed solver's limits exclude it too, OSQP
    pb = replace(b.problem, R=0.0 * b.problem.R, Rc=0.0 * b.problem.Rc)
    with pytest.warns(FastPathUnavailable) as told:
        ctrl = LtvMpc(b.model, b.path, pb, paper)
    said = [str(w.message) for w in told]
    assert any(m.startswith("compiled step not used: a speed profile") for m in said), said
    assert any(m.startswith("condensed solver not used: R + Rc") for m in said), said
    assert (ctrl.backend_name, ctrl.assembly) == ("osqp", "python")


@pytest.mark.parametrize("linearization", ["trajectory", "paper"])
def test_prediction_substeps_are_compiled(linearization):
    """Prediction substeps (each model step taken as several, the Jacobians chained) run on the
    compiled step: the dynamic bicycle with its exact (``exp``) discretization on the raceway,
    the stage QP the Python assembly's field by field, from a rolled-out first step (no plan)
    and from the plan after it."""
    from test_solver_oracle import same_step_data

    b = build_experiment(_with_backend(load_scenario("track-raceway"), "osqp")).mpc
    cfg = replace(b.config, prediction_substeps=3, linearization=linearization)
    assert cfg.discretization == "exp"
    with warnings.catch_warnings():
        warnings.simplefilter("error", FastPathUnavailable)
        fast = LtvMpc(b.model, b.path, b.problem, cfg)
    assert (fast.assembly, fast.backend_name) == ("compiled", "fast") and fast._asm.substeps == 3
    ref = PythonLtvMpc(b.model, b.path, b.problem, cfg, "osqp")
    x = np.array([0.0, 0.3, 0.1, 3.0, 0.1, 0.2])
    warm = ref.initial_warm(x)
    for _ in range(2):
        d = ref.prepare(x, warm)
        same_step_data(fast.prepare(x, warm), d, atol=1e-9, sides=False)
        warm = ref.step(x, warm).warm
    # three substeps are not one: the test above would see a model that ignored them
    one = PythonLtvMpc(b.model, b.path, b.problem, replace(cfg, prediction_substeps=1), "osqp")
    assert np.abs(one.prepare(x, warm).qp.A - d.qp.A).max() > 1e-6


#: scenarios whose closed loop on OSQP at its scenario tolerance (1e-5) parts from OSQP's own at
#: 1e-9, so the reference is OSQP at 1e-9: paper-exp5-potential's max |steer| is 0.35247 rad at
#: 1e-5 and 0.35505 at 1e-9 (the fast path: 0.35505, within 1e-13), since the first step's road
#: bounds follow the previous plan (scene.road.reach_first_step; before that they agreed within 1e-4)
LOOSE_OSQP_SCENARIOS = ["paper-exp5-potential"]


@pytest.fixture(scope="module", params=FAST_SCENARIOS)
def builtin_pair(request):
    spec = load_scenario(request.param)
    ref = build_experiment(_tight(spec) if request.param in LOOSE_OSQP_SCENARIOS else _with_backend(spec, "osqp"))
    fast = build_experiment(_with_backend(spec, "fast"))
    assert isinstance(fast.mpc, CompiledLtvMpc), "every built-in scenario must run on the fast path"
    assert isinstance(ref.mpc, LtvMpc)
    return request.param, ref, fast, run_experiment(ref)


def test_fast_commands_match_osqp_on_the_reference_states(builtin_pair):
    """Fed the states of the OSQP closed loop, the fast controller gives the same commands."""
    sid, _, fast, ref_result = builtin_pair
    ctrl = fast.controller
    warm = ctrl.initial_warm(ref_result.x[0])
    n = min(200, ref_result.steps)
    du = np.empty(n)
    for k in range(n):
        out = ctrl.step(ref_result.x[k], warm)
        assert out.status == "ok", (sid, k, out.status)
        du[k] = np.abs(out.u - ref_result.u[k]).max()
        warm = out.warm
    assert du.max() <= COMMAND_TOL_RAD, f"{sid}: max |du| {du.max():.2e} at step {du.argmax()}"


def test_fast_closed_loop_metrics_match_osqp(builtin_pair):
    sid, ref, fast, ref_result = builtin_pair
    fast_result = run_experiment(fast)
    m_ref = compute_metrics(ref_result)
    m_fast = compute_metrics(fast_result)
    assert m_fast["steps"] == m_ref["steps"]
    assert (
        abs(m_fast["rms_lateral_error_m"] - m_ref["rms_lateral_error_m"])
        <= METRIC_TOL_M + 0.01 * m_ref["rms_lateral_error_m"]
    )
    assert abs(m_fast["max_abs_steer_rad"] - m_ref["max_abs_steer_rad"]) <= COMMAND_TOL_RAD
    assert (m_fast["solver_failures"], m_fast["fallbacks"]) == (m_ref["solver_failures"], m_ref["fallbacks"])
    assert fast_result.meta["backend"] == "fast" and ref_result.meta["backend"] == "osqp"


# ------------------------------------------------------------------- every supported feature
def _lane(w: float) -> Road:
    """A road in which the default body's centre, aligned with a straight path, keeps
    |e_y| <= ``w`` [m] (half the body's width and the margin on each side)."""
    return Road.constant(2.0 * (w + 0.5 * Footprint().width_m + 0.05))


def _feature_cases():
    wp = WaypointPath([[0, 0], [3, 1], [6, -1], [9, 0.5], [12, 0]], smoothing=0.0)
    loop = WaypointPath([[0, 0], [4, 0], [5, 3], [2, 5], [-1, 3]], closed=True)
    m3, m4 = KinematicBicycle3(1.5, KinematicParams(0.2, 0.14)), KinematicBicycle4()
    p4 = dict(
        Q=[5, 5, 10, 2],
        R=[0.1, 0.05],
        u_min=[-STEER, -2.0],
        u_max=[STEER, 1.5],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [1.4],
    )
    return {
        "rate+Rc+lane, waypoints, rk4": (
            m3,
            wp,
            MpcProblem(
                3,
                1,
                15,
                0.02,
                Q=[1, 4, 1],
                R=0.5,
                Rc=2.0,
                u_min=-STEER,
                u_max=STEER,
                du_max_per_s=math.radians(120),
                road=_lane(0.15),
            ),
            MpcConfig(),
            np.array([0.5, 0.4, 0.3]),
        ),
        "lane+speed bounds, closed waypoints, euler, paper horizon": (
            m4,
            loop,
            MpcProblem(4, 2, 12, 0.05, road=_lane(0.2), lane_slack_weight=50.0, lane_slack_weight_l1=5.0, **p4),
            MpcConfig(discretization="euler", horizon="paper", horizon_step_m=0.05, v_ref_mps=1.2),
            np.array([0.3, -0.5, 0.4, 1.3]),
        ),
        "paper linearization, no feedforward, circle": (
            m4,
            CirclePath((1.0, -1.0), 2.0, ccw=False),
            MpcProblem(4, 2, 20, 0.02, du_max_per_s=[1.0, 3.0], **p4),
            MpcConfig(linearization="paper", feedforward="none", v_ref_mps=1.0),
            np.array([1.0, 1.2, -0.2, 0.8]),
        ),
        "speed profile from rest, closed waypoints, accel feedforward": (
            m4,
            loop,
            MpcProblem(4, 2, 15, 0.05, du_max_per_s=[3.0, 20.0], **p4),
            MpcConfig(speed_profile=SpeedProfile(loop, 3.0, 1.5, 2.0, 1.4)),
            np.array([0.3, -0.2, 0.1, 0.0]),
        ),
        "speed profile, exp discretization": (
            m4,
            loop,
            MpcProblem(4, 2, 15, 0.05, **p4),
            MpcConfig(discretization="exp", speed_profile=SpeedProfile(loop, 3.0, 1.5, 2.0, 1.4)),
            np.array([0.2, 0.1, 0.05, 0.8]),
        ),
        "speed profile to a stop, open waypoints, euler, lane": (
            m4,
            wp,
            MpcProblem(4, 2, 12, 0.05, road=_lane(0.3), **p4),
            MpcConfig(
                discretization="euler",
                speed_profile=SpeedProfile(wp, 2.0, 1.0, 1.5, 1.3, v_start_mps=0.5, v_end_mps=0.0),
            ),
            np.array([0.1, 0.05, 0.3, 0.6]),
        ),
        "speed profile, three-state model": (
            m3,
            wp,
            MpcProblem(3, 1, 15, 0.02, Q=[1, 4, 1], R=0.5, u_min=-STEER, u_max=STEER),
            MpcConfig(speed_profile=SpeedProfile(wp, 3.0, 2.0, 2.0, 1.5)),
            np.array([0.2, 0.3, 0.4]),
        ),
        "constant-speed profile": (
            m4,
            CirclePath((1.0, -1.0), 2.0),
            MpcProblem(4, 2, 20, 0.02, **p4),
            MpcConfig(speed_profile=ConstantSpeed(0.9)),
            np.array([1.0, -3.1, 0.1, 0.5]),
        ),
    }


@pytest.mark.parametrize("case", list(_feature_cases()))
def test_fast_matches_osqp_with_every_supported_constraint(case):
    """Rate bounds, Rc, state bounds, the soft lane with slack, Euler, the paper's horizon and
    linearization, waypoint and circle paths, speed profiles: the same commands and plans as OSQP
    at random states, warm-started from each controller's own previous plan."""
    model, path, pb, cfg, x0 = _feature_cases()[case]
    # both keep the (default) body inside the road by the same rule, its yaw and the path's
    # curvature included
    fast = CompiledLtvMpc(model, path, pb, cfg)
    ref = PythonLtvMpc(model, path, pb, cfg, "osqp", osqp_settings=TIGHT)
    rng = np.random.default_rng(3)
    plant = Plant(model)
    x = x0.copy()
    wf, wr = fast.initial_warm(x), ref.initial_warm(x)
    for k in range(60):
        of, orf = fast.step(x, wf), ref.step(x, wr)
        assert of.status == "ok" and orf.status in ("ok", "inaccurate"), (k, of.status, orf.status)
        # OSQP's own accuracy: 1e-9 when it converges, looser when it stops 'inaccurate'
        tol = 1e-5 if orf.status == "ok" else COMMAND_TOL_RAD
        assert np.abs(of.u - orf.u).max() <= tol, (k, of.u, orf.u, orf.status)
        np.testing.assert_allclose(of.X_pred, orf.X_pred, atol=tol)
        np.testing.assert_allclose(of.refs, orf.refs, atol=1e-9)
        assert (of.s_m, of.e_y_m, of.e_psi_rad) == pytest.approx((orf.s_m, orf.e_y_m, orf.e_psi_rad), abs=1e-9)
        wf, wr = of.warm, orf.warm
        x = plant.step(x, orf.u, pb.dt_s)
        x[:3] += rng.normal(0, [0.01, 0.01, 0.03])  # kicks so the bounds and the lane become active


# ------------------------------------------------------------------------------ the QP solver
def _kkt_residuals(H, g, C, b, r):
    stat = np.abs(H @ r.z + g - C.T @ r.lam).max()
    feas = max(0.0, -(C @ r.z - b).min()) if len(b) else 0.0
    comp = np.abs(r.lam * (C @ r.z - b)).max() if len(b) else 0.0
    return stat, feas, comp, r.lam.min() if len(b) else 0.0


def test_dense_qp_solutions_are_exact_and_agree_with_clarabel_and_osqp():
    clarabel = pytest.importorskip("clarabel")
    import osqp
    import scipy.sparse as sp

    rng = np.random.default_rng(11)
    solver = DenseQpSolver(40, 100)
    for trial in range(60):
        n, m = int(rng.integers(1, 40)), int(rng.integers(0, 100))
        M = rng.normal(size=(n, n))
        H = M @ M.T + 0.1 * np.eye(n)
        g = 5 * rng.normal(size=n)
        C = np.vstack([np.eye(n), -np.eye(n)])[: min(m, 2 * n)] if trial % 2 else rng.normal(size=(m, n))
        b = C @ rng.normal(size=n) - rng.uniform(0, 1, size=C.shape[0])
        r = solver.solve(H, g, C, b)
        assert r.status == "ok"
        stat, feas, comp, lam_min = _kkt_residuals(H, g, C, b, r)
        scale = 1 + np.abs(g).max() + np.abs(H).max()
        assert stat <= 1e-9 * scale and feas <= 1e-9 and comp <= 1e-8 * scale and lam_min >= 0
        if C.shape[0]:
            st = clarabel.DefaultSettings()
            st.verbose = False
            cl = clarabel.DefaultSolver(
                sp.csc_matrix(np.triu(H)), g, sp.csc_matrix(-C), -b, [clarabel.NonnegativeConeT(C.shape[0])], st
            ).solve()
            zc = np.array(cl.x)
            assert r.objective <= 0.5 * zc @ H @ zc + g @ zc + 1e-7 * scale
            assert np.abs(r.z - zc).max() <= 1e-5 * (1 + np.abs(zc).max())
            o = osqp.OSQP()
            o.setup(
                sp.csc_matrix(np.triu(H)),
                g,
                sp.csc_matrix(C),
                b,
                np.full(C.shape[0], np.inf),
                eps_abs=1e-9,
                eps_rel=1e-9,
                max_iter=100000,
                verbose=False,
                polishing=True,
            )
            zo = o.solve(raise_error=False).x
            assert np.abs(r.z - zo).max() <= 1e-5 * (1 + np.abs(zo).max())


def test_dense_qp_reports_infeasible_and_not_positive_definite():
    solver = DenseQpSolver(5, 10)
    H, g = np.eye(3), np.ones(3)
    c = np.array([1.0, 2.0, -1.0])
    r = solver.solve(H, g, np.vstack([c, -c]), np.array([5.0, -4.0]))  # c'z >= 5 and c'z <= 4
    assert r.status == "infeasible" and not np.isfinite(r.objective)
    zero = np.zeros((1, 3))
    assert solver.solve(H, g, zero, np.array([1e-3])).status == "infeasible"  # 0 >= 1e-3
    assert solver.solve(H, g, zero, np.array([-1.0])).status == "ok"  # 0 >= -1 always holds
    assert solver.solve(np.diag([1.0, 0.0, 1.0]), g).status == "failed"
    assert solver.solve(H, np.array([1.0, np.nan, 0.0])).status == "failed"
    with pytest.raises(ValueError, match="exceeds"):
        solver.solve(np.eye(6), np.zeros(6))


def test_infeasible_controller_problem_is_reported_and_falls_back_counted():
    """Speed bounds [0, 1] with the car at 3 m/s and braking limited: every QP is infeasible;
    both backends say so, never output NaN, and count the same fallbacks."""
    model = KinematicBicycle4()
    pb = MpcProblem(
        4,
        2,
        10,
        0.01,
        Q=[1, 1, 1, 1],
        R=0.1,
        u_min=[-STEER, -0.1],
        u_max=[STEER, 0.1],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [1.0],
    )
    path = StraightPath([0, 0], [50, 0])
    for ladder, rung in (
        (("shifted_plan", "hold_last"), None),
        (("relax", "shifted_plan", "brake"), "relax"),
        (("brake",), "brake"),
    ):
        cfg = MpcConfig(v_ref_mps=1.0, fallback=FallbackConfig(ladder))
        runs = {}
        for ctrl in (CompiledLtvMpc(model, path, pb, cfg), PythonLtvMpc(model, path, pb, cfg, "osqp")):
            r = simulate(ctrl, Plant(model), path, [0, 0.2, 0, 3.0], 0.01, 30)
            assert all(np.isfinite(r.u).ravel())
            runs[ctrl.backend_name] = r
        assert set(runs["fast"].status) == {"infeasible"}
        assert runs["fast"].fallback == runs["osqp"].fallback, ladder
        assert compute_metrics(runs["fast"])["fallbacks"] == 30
        if rung is not None:
            # relax: the problem without the speed bound, solved (OSQP to its relaxed 1e-4);
            # brake: full braking within the input bounds, the steering held
            assert set(runs["fast"].fallback) == {rung}
            np.testing.assert_allclose(runs["fast"].u, runs["osqp"].u, atol=2e-3 if rung == "relax" else 1e-12)
            if rung == "brake":
                assert np.all(runs["fast"].u[:, 1] == -0.1)


def test_iteration_cap_gives_max_iter_and_a_deliberate_fallback():
    """At the P1 start the steering saturates over most of the horizon (many active-set
    changes): with a cap of 2 the step stops with ``max_iter`` and holds the last input."""
    model = KinematicBicycle3(1.0)
    pb = MpcProblem(3, 1, 30, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER, du_max_per_s=math.radians(90))
    path = StraightPath([1, 0], [11, 0])
    cfg = MpcConfig(v_ref_mps=1.0, fallback=FallbackConfig(("shifted_plan", "hold_last")))
    ctrl = CompiledLtvMpc(model, path, pb, cfg, condensed_settings=CondensedSettings(max_iter=2))
    x = np.array([2.0, -2.0, math.pi / 2])
    warm = ctrl.initial_warm(x)
    warm = WarmStart(warm.s_m, np.array([0.3]))
    out = ctrl.step(x, warm)
    assert out.status == "max_iter" and out.fallback == "hold_last"
    assert abs(out.u[0] - 0.3) <= math.radians(90) * 0.01 + 1e-12
    full = CompiledLtvMpc(model, path, pb, MpcConfig(v_ref_mps=1.0)).step(x, warm)
    assert full.status == "ok"
    plan = CompiledLtvMpc(model, path, pb, cfg, condensed_settings=CondensedSettings(max_iter=2)).step(x, full.warm)
    assert plan.status == "max_iter" and plan.fallback == "shifted_plan"
    rate = math.radians(90) * 0.01
    np.testing.assert_allclose(plan.u, np.clip(full.warm.U[1], full.u - rate, full.u + rate))


@pytest.mark.parametrize("bad, field", [([np.nan, 0, 0], "x"), ([0, np.inf, 0], "y"), ([0, 0, -np.inf], "yaw")])
def test_non_finite_state_and_bad_warm_start_are_clear_value_errors(bad, field):
    model = KinematicBicycle3(1.0)
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    c = CompiledLtvMpc(model, StraightPath([0, 0], [10, 0]), pb)
    warm = c.initial_warm([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=f"state field\\(s\\) {field} not finite"):
        c.step(np.array(bad, float), warm)
    with pytest.raises(ValueError, match="shape"):
        c.step(np.zeros(4), warm)
    with pytest.raises(ValueError, match="warm plan"):
        c.step(np.zeros(3), WarmStart(0.0, np.zeros(1), np.zeros((5, 3)), np.zeros((4, 1))))
    out = c.step([0.0, 0.1, 0.0], warm)  # a list is accepted
    assert out.status == "ok"


# ------------------------------------------------------------------------------ the factory
def test_factory_falls_back_to_osqp_and_says_why():
    model = KinematicBicycle3(1.0)
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=0.0, u_min=-STEER, u_max=STEER)  # R + Rc singular
    path = StraightPath([0, 0], [10, 0])
    assert "positive definite" in fast_unsupported_reason(model, path, pb)
    # a limit of the condensed solver only: the compiled step assembles, OSQP solves
    with pytest.warns(FastPathUnavailable, match="condensed solver not used: .*positive definite"):
        c = LtvMpc(model, path, pb)
    assert isinstance(c, CompiledLtvMpc) and (c.backend_name, c.assembly) == ("osqp", "compiled")
    assert c.step(np.zeros(3), c.initial_warm(np.zeros(3))).status == "ok"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert LtvMpc(model, path, MpcProblem(3, 1, 10, 0.01, Q=1.0, R=1.0)).backend_name == "fast"
        assert LtvMpc(model, path, pb, solver="osqp").backend_name == "osqp"
        # compiled unless the caller asks for OSQP, as scenarios and the CLI
        c = LtvMpc(model, path, MpcProblem(3, 1, 10, 0.01, Q=1.0, R=1.0))
        assert (type(c), c.backend_name, c.assembly) == (CompiledLtvMpc, "fast", "compiled")
    with pytest.raises(ValueError, match="solver must be one of"):
        LtvMpc(model, path, pb, solver="gpu")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="assembly must be one of"):
        LtvMpc(model, path, pb, assembly="gpu")  # type: ignore[arg-type]


def test_speed_profiles_the_fast_path_declines_are_named():
    model, path = KinematicBicycle4(), StraightPath([0, 0], [10, 0])
    pb = MpcProblem(4, 2, 10, 0.05, Q=[1, 1, 1, 1], R=[1, 1])

    class Ramp:
        def speed(self, s_m):
            return 1.0 + 0.1 * np.asarray(s_m)

    assert "Ramp has no compiled form" in fast_unsupported_reason(model, path, pb, MpcConfig(speed_profile=Ramp()))
    paper = MpcConfig(horizon="paper", speed_profile=ConstantSpeed(1.0))
    assert "'paper' horizon" in fast_unsupported_reason(model, path, pb, paper)
    assert fast_unsupported_reason(model, path, pb, MpcConfig(speed_profile=ConstantSpeed(1.0))) is None


# --------------------------------------------------------------- compiled models and paths
@pytest.mark.parametrize("substeps", [1, 3])
@pytest.mark.parametrize("model", [KinematicBicycle3(2.0, KinematicParams(0.2, 0.1)), KinematicBicycle4()])
@pytest.mark.parametrize("method", ["rk4", "euler", "exp"])
def test_compiled_discretization_equals_numpy(model, method, substeps):
    from mpcdrive.models.compiled import (
        METHOD_EULER,
        METHOD_EXP,
        METHOD_RK4,
        discrete_step_jacobians_substeps,
        model_code,
        rollout_into,
    )

    kind, mp = model_code(model)
    rng = np.random.default_rng(0)
    N, nx, nu = 8, model.nx, model.nu
    X = rng.normal(size=(N, nx))
    U = rng.uniform(-1, 1, size=(N, nu))
    F, A, B = np.zeros((N, nx)), np.zeros((N, nx, nx)), np.zeros((N, nx, nu))
    code = {"rk4": METHOD_RK4, "euler": METHOD_EULER, "exp": METHOD_EXP}[method]
    nw = nx + nu + 1 if method == "exp" else nx + nu
    sub = (np.zeros((N, nx)), np.zeros((N, nx)), np.zeros((N, nx, nx)), np.zeros((N, nx, nu)))
    for k in range(N):
        discrete_step_jacobians_substeps(
            kind, mp, nx, nu, X, U, k, 0.05, code, substeps, F, A, B, np.zeros((7, nw, nw)), *sub
        )
    if substeps == 1:
        F0, A0, B0 = discrete_step_and_jacobians(model, X, U, 0.05, method)
    else:  # the numpy form chains substeps one state at a time
        steps = [discrete_step_and_jacobians(model, X[k], U[k], 0.05, method, substeps) for k in range(N)]
        F0, A0, B0 = (np.array(v) for v in zip(*steps))
    np.testing.assert_allclose(F, F0, atol=1e-13)
    np.testing.assert_allclose(A, A0, atol=1e-13)
    np.testing.assert_allclose(B, B0, atol=1e-13)
    if method == "exp":  # the Jacobians are the rollout's: rollout_into does Euler and RK4
        return
    Xr = np.zeros((N, nx))
    Xr[0] = X[0]
    rollout_into(kind, mp, nx, Xr, U, N - 1, 0.05, code, substeps, np.zeros((4, nx)))
    for k in range(N - 1):
        np.testing.assert_allclose(Xr[k + 1], discrete_step(model, Xr[k], U[k], 0.05, method, substeps), atol=1e-13)


@pytest.mark.parametrize(
    "path",
    [
        StraightPath([1.0, -2.0], [4.0, 2.0]),
        CirclePath((0.5, 0.2), 1.5, ccw=False, start_angle_rad=0.7),
        WaypointPath([[0, 0], [2, 1], [4, 0], [6, 2]]),
        WaypointPath([[0, 0], [4, 0], [5, 3], [2, 5], [-1, 3]], closed=True),
    ],
    ids=["straight", "circle", "waypoints", "closed-waypoints"],
)
def test_compiled_path_geometry_equals_the_path_objects(path):
    from mpcdrive.paths.compiled import path_arrays, path_eval, path_project
    from test_paths import _nearest_on_table

    pa = path_arrays(path)
    rng = np.random.default_rng(1)
    L = path.length_m
    for s in rng.uniform(-0.3 * L, 2.3 * L, size=200):
        x, y, h, k = path_eval(pa.kind, pa.geo, pa.tab_s, pa.tab_xy, pa.tab_h, pa.tab_k, s)
        np.testing.assert_allclose([x, y], path.position(s), atol=1e-12)
        assert h == pytest.approx(float(path.heading(s)), abs=1e-12)
        assert k == pytest.approx(float(path.curvature(s)), abs=1e-9)
    for s_guess in rng.uniform(0, 2 * L, size=100):
        p = path.position(s_guess) + rng.normal(0, 0.3, size=2)
        for window in (0.5, 2.0, L):
            s_c, ey_c = path_project(pa.kind, pa.geo, pa.tab_s, pa.tab_xy, s_guess, window, p[0], p[1])
            if isinstance(path, WaypointPath):
                # WaypointPath.project runs this same kernel: where the whole path is searched,
                # compare with the independent nearest-point oracle instead (windowed searches:
                # test_paths.test_waypoint_projection_is_the_nearest_table_point)
                if window < L:
                    continue
                s_r, ey_r = _nearest_on_table(path, p)
                if path.closed:
                    s_r += L * round((s_guess - s_r) / L)
            else:
                s_r, ey_r = path.project(p, s_guess, window)
            assert (s_c, ey_c) == pytest.approx((s_r, ey_r), abs=1e-9)


# ------------------------------------------------------------------------------ compile cache
def test_a_second_process_loads_the_compiled_step_from_the_cache():
    """This process has compiled (or loaded) the step; a fresh one must find it in numba's
    on-disk cache (cache hits, no misses) instead of recompiling."""
    from mpcdrive.control import compiled_mpc, compiled_step

    c = CompiledLtvMpc(KinematicBicycle4(), StraightPath([0, 0], [5, 0]), MpcProblem(4, 2, 5, 0.01, Q=1.0, R=1.0))
    x0 = np.array([0.0, 0.0, 0.0, 1.0])
    c.step(x0, c.initial_warm(x0))
    assert c.step_spec == compiled_step.StepSpec(4)
    cache_dir = Path(c._step_fn.stats.cache_path)
    assert any(cache_dir.glob("compiled_step.control_step_kinematic4-*.nbi")), f"no cache index in {cache_dir}"
    code = (
        "import json, numpy as np\n"
        "from mpcdrive.control import compiled_mpc\n"
        "from mpcdrive.models import KinematicBicycle4\n"
        "from mpcdrive.ocp import MpcProblem\n"
        "from mpcdrive.paths import CirclePath\n"
        "c = compiled_mpc.CompiledLtvMpc(KinematicBicycle4(), CirclePath(), MpcProblem(4, 2, 7, 0.01, Q=1.0, R=1.0))\n"
        "x = np.array([1.5, 0.0, 1.6, 1.0])\n"
        "c.step(x, c.initial_warm(x))\n"
        "st = compiled_mpc.control_step(compiled_mpc.StepSpec(4)).stats\n"
        "import sys\n"
        "print(json.dumps({'hits': sum(st.cache_hits.values()), 'misses': sum(st.cache_misses.values()),\n"
        "                  'sparse': 'scipy.sparse' in sys.modules}))\n"
    )
    src = str(Path(compiled_mpc.__file__).resolve().parents[2])
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={**__import__("os").environ, "PYTHONPATH": src},
    )
    stats = json.loads(proc.stdout.strip().splitlines()[-1])
    # the machine code came from the cache, and the process never loaded the sparse QP stack
    # (scipy.sparse is for the OSQP controller; it would add a few tenths of a second to start-up)
    assert stats == {"hits": 1, "misses": 0, "sparse": False}, stats


@pytest.mark.slow
def test_a_kinematic_step_compiles_without_the_other_models_code(run_with_empty_numba_cache):
    """The step of P1 (a kinematic model, no obstacle, no road, no state bound) is compiled with
    the model, its sizes and its spec as constants: the dynamic model's code, the obstacle cost,
    the constraint rows (road rows, soft rows), the speed profile, the friction circle and the
    Riccati copies of other sizes are never compiled (a fresh cache, so this process compiles
    instead of loading)."""
    code = (
        "import gc, json, numpy as np\n"
        "from mpcdrive.bench.problems import p1\n"
        "from mpcdrive.control import LtvMpc\n"
        "from mpcdrive._subroutine import Subroutine\n"
        "bp = p1()\n"
        "c = LtvMpc(bp.model, bp.path, bp.problem, bp.config)\n"
        "subs = {s.__name__: [[str(t) for t in a] for a in s._compiled] for s in gc.get_objects()\n"
        "        if isinstance(s, Subroutine)}\n"
        "print(json.dumps({'spec': c.step_spec.name, 'compiled': subs}))\n"
    )
    result = json.loads(run_with_empty_numba_cache(code).strip().splitlines()[-1])
    assert result["spec"] == "control_step_kinematic3"
    compiled = result["compiled"]
    assert compiled["linearize"] and compiled["condensed_solve"]  # it did compile the step
    dead = ("dynamic_steady_states", "dynamic_rhs_and_partials", "obstacle_cost", "select_obstacles")
    dead += ("horizon_bounds", "reach_first_step", "_group_excess", "_flag_later_groups")
    dead += ("profile_arc_lengths", "profile_speed", "friction_input_bounds")
    for name in dead:
        assert compiled[name] == [], name
    # one Riccati copy, at P1's constant sizes (3 states, 1 input)
    assert [sig[1:3] for sig in compiled["_riccati"]] == [["Literal[int](3)", "Literal[int](1)"]]


def _guard_cases():
    """Controllers whose assembly needs one feature more than a smaller spec has: (controller
    arguments, keywords, its spec[, the smaller spec; else its spec without extras])."""
    from mpcdrive.control.compiled_step import StepSpec
    from mpcdrive.ocp.avoidance import AvoidanceConfig
    from mpcdrive.scene import Circle, Obstacle

    m3, m4 = KinematicBicycle3(1.0), KinematicBicycle4()
    line = StraightPath([0, 0], [10, 0])
    kin3 = dict(Q=1.0, R=1.0, u_min=-STEER, u_max=STEER)
    speed = dict(Q=1.0, R=1.0, u_min=[-STEER, -3.0], u_max=[STEER, 3.0], x_min=[-np.inf] * 3 + [0.0])
    profile = MpcConfig(speed_profile=SpeedProfile(WaypointPath([[0, 0], [5, 0.5], [10, 0]]), 2.0, 1.0, 1.5, 1.3))
    return {
        "obstacle cost": (
            (m3, line, MpcProblem(3, 1, 10, 0.05, road=_lane(0.9), **kin3)),
            dict(obstacles=(Obstacle(Circle(0.25), (3.0, 0.5, 0.0)),), avoidance=AvoidanceConfig("gaussian")),
            StepSpec(3, obstacle_cost=True, extras=True),
            StepSpec(3, extras=True),
        ),
        "road rows": ((m3, line, MpcProblem(3, 1, 10, 0.05, road=_lane(0.9), **kin3)), {}, StepSpec(3, extras=True)),
        "state bounds": ((m4, line, MpcProblem(4, 2, 10, 0.05, **speed)), {}, StepSpec(4, extras=True)),
        "speed profile": ((m3, line, MpcProblem(3, 1, 10, 0.05, **kin3), profile), {}, StepSpec(3, extras=True)),
        "friction circle": (
            (
                m4,
                line,
                MpcProblem(
                    4, 2, 10, 0.05, Q=1.0, R=1.0, u_min=[-STEER, -3.0], u_max=[STEER, 3.0], friction_accel_mps2=4.0
                ),
            ),
            {},
            StepSpec(4, extras=True),
        ),
    }


@pytest.mark.parametrize("case", list(_guard_cases()))
def test_a_step_refuses_an_assembly_that_needs_more_than_its_spec(case):
    """Each compiled step is compiled for its StepSpec, the code of what it leaves out left out;
    a step handed an assembly that needs one of those fails loudly (status 3) instead of
    ignoring it, and the controller's own step solves it."""
    from mpcdrive.control import compiled_step
    from mpcdrive.ocp.assembly import MODE_NO_PLAN

    args, kwargs, spec, *smaller = _guard_cases()[case]
    smaller = smaller[0] if smaller else replace(spec, extras=False)
    c = CompiledLtvMpc(*args, **kwargs)
    assert c.step_spec == spec and c._step_fn is compiled_step.control_step(spec)
    out = np.empty(c._out_size)
    x = np.zeros(c.nx)
    if c.nx == 4:
        x[3] = 1.0
    call = (c._step_struct, x, 0.0, 0.0, np.zeros(c.nu), c._noX, c._noU, MODE_NO_PLAN, compiled_step.STAGE_ALL, out)
    assert compiled_step.control_step(smaller)(*call) == 3
    assert c._step_fn(*call) == 0


def test_step_specs_name_their_compiled_function():
    """Each spec has its own function name (numba's cache files are named after it) and says in
    words what it has; a model kind without a compiled step is refused."""
    from mpcdrive.control.compiled_step import StepSpec, control_step

    assert StepSpec(3).name == "control_step_kinematic3"
    assert StepSpec(6, obstacle_cost=True, extras=True).name == "control_step_dynamic_obstacle_cost_extras"
    assert StepSpec(3).describe() == "for tracking alone"
    extras = "constraint rows, speed profiles and the friction circle"
    assert StepSpec(4, extras=True).describe() == f"with code for {extras}"
    assert StepSpec(3, obstacle_cost=True).describe() == "with code for the obstacle cost"
    assert StepSpec(3, obstacle_cost=True, extras=True).describe() == f"with code for the obstacle cost, {extras}"
    assert control_step(StepSpec(3)) is control_step(StepSpec(3))
    assert control_step(StepSpec(3)).py_func.__name__ == "control_step_kinematic3"
    with pytest.raises(ValueError, match="kind 5"):
        StepSpec(5)


def test_modules_of_subroutines_keep_their_cache_fingerprint(tmp_path, run_with_empty_numba_cache):
    """The dependency fingerprint is kept for a module whose anchor function is a subroutine
    (``ocp.assembly``: ``linearize``), located through numba's own cache locator."""
    run_with_empty_numba_cache("import mpcdrive.ocp.assembly, mpcdrive.solvers.condensed, mpcdrive.models.compiled")
    for stem in ("assembly", "condensed", "compiled"):
        assert list(tmp_path.rglob(f"{stem}.deps-sha1")), stem


def test_stale_cache_files_are_dropped_when_a_dependency_changes(tmp_path):
    """numba watches only a function's own file; the controller's cache must also follow the
    files whose code it inlines."""
    from mpcdrive._jitcache import drop_stale_cache

    dep = tmp_path / "dep.py"
    dep.write_text("a = 1\n")
    cache = tmp_path / "cache"
    cache.mkdir()

    def fake_cache():
        for name in ("fast._control_step-1.py311.nbi", "fast._control_step-1.py311.1.nbc", "other.f-1.py311.nbi"):
            (cache / name).write_text("x")

    fake_cache()
    assert drop_stale_cache(cache, "fast", [dep])  # no fingerprint yet: dropped
    assert sorted(p.name for p in cache.iterdir()) == ["fast.deps-sha1", "other.f-1.py311.nbi"]
    fake_cache()
    assert not drop_stale_cache(cache, "fast", [dep])  # unchanged: kept
    assert (cache / "fast._control_step-1.py311.nbi").exists()
    dep.write_text("a = 2\n")
    assert drop_stale_cache(cache, "fast", [dep])  # changed: dropped
    assert not (cache / "fast._control_step-1.py311.nbi").exists() and (cache / "other.f-1.py311.nbi").exists()


# ------------------------------------------------------------------ obstacles on the fast path
def _obstacle_cases():
    from mpcdrive.bench.problems import p3
    from mpcdrive.ocp.avoidance import AvoidanceConfig
    from mpcdrive.scene import Circle, ConstantVelocity, Obstacle, rectangle

    b3 = p3()
    m4 = KinematicBicycle4()
    pb4 = MpcProblem(
        4,
        2,
        25,
        0.02,
        Q=[5, 5, 10, 2],
        R=[0.1, 0.05],
        u_min=[-STEER, -2.0],
        u_max=[STEER, 1.5],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [1.4],
        road=_lane(0.9),
        du_max_per_s=[3.0, 5.0],
    )
    crossing = Obstacle(rectangle(0.4, 0.3), (3.0, -1.5, 0.3), ConstantVelocity(0.0, 0.5), name="crossing")
    cone = Obstacle(Circle(0.2), (5.5, 0.15, 0.0), name="cone")
    far = Obstacle(Circle(0.2), (40.0, 0.0, 0.0), name="far away")
    return {
        "P3: gaussian, lane, start outside the lane": (
            b3.model,
            b3.path,
            b3.problem,
            b3.config,
            b3.x0,
            b3.obstacles,
            b3.avoidance,
            1,
        ),
        "potential, moving rectangle + cone + far, speed, rates, waypoints": (
            m4,
            WaypointPath([[0, 0], [4, 0.3], [8, -0.2], [12, 0]]),
            pb4,
            MpcConfig(v_ref_mps=1.0),
            np.array([0.0, 0.2, 0.0, 0.8]),
            (crossing, cone, far),
            AvoidanceConfig("potential", weight=0.5, epsilon_m2=0.05, max_obstacles=2, influence_m=4.0),
            1,
        ),
        "gaussian, SQP to convergence": (
            b3.model,
            b3.path,
            b3.problem,
            replace(b3.config, sqp_max_iterations=8, sqp_tol=1e-6),
            np.array([2.0, 0.3, 0.0]),
            b3.obstacles,
            b3.avoidance,
            8,
        ),
    }


@pytest.mark.parametrize("case", list(_obstacle_cases()))
def test_fast_matches_osqp_with_obstacle_costs(case):
    """Potential and Gaussian obstacle costs (static and constant-velocity obstacles, circles and
    rectangles, the nearest max_obstacles within reach), RTI and SQP: the fast path's commands
    and plans are OSQP's, fed the states of OSQP's closed loop."""
    model, path, pb, cfg, x0, obstacles, av, max_sqp = _obstacle_cases()[case]
    fp = Footprint()
    fast = LtvMpc(model, path, pb, cfg, obstacles=obstacles, avoidance=av, footprint=fp)
    ref = LtvMpc(model, path, pb, cfg, "osqp", osqp_settings=TIGHT, obstacles=obstacles, avoidance=av, footprint=fp)
    assert fast.backend_name == "fast" and ref.backend_name == "osqp"
    plant = Plant(model)
    x = x0.copy()
    wr = ref.initial_warm(x)
    worst, iters, near, unsolved = 0.0, [], 0, 0
    for k in range(450):
        orf = ref.step(x, wr)
        of = fast.step(x, wr)  # the same warm start (plan, time)
        assert of.status == "ok", (k, of.status)
        assert of.warm.t_s == pytest.approx(orf.warm.t_s)
        if orf.status != "ok":  # OSQP did not reach 1e-9 (its command is a fallback's): nothing to compare
            unsolved += 1
        else:
            worst = max(worst, float(np.abs(of.u - orf.u).max()))
            np.testing.assert_allclose(of.X_pred, orf.X_pred, atol=1e-5)
            iters.append((of.sqp_iterations, orf.sqp_iterations))
        near += any(np.hypot(*(np.array(o.pose_at(wr.t_s)[:2]) - x[:2])) < 1.5 for o in obstacles)
        wr = orf.warm
        x = plant.step(x, orf.u, pb.dt_s)
    assert worst <= 1e-5, worst
    assert unsolved <= 20, unsolved
    assert near > 20  # the obstacles were close enough to matter
    if max_sqp > 1:
        assert max(i for i, _ in iters) > 1
        assert all(abs(a - b) <= 1 for a, b in iters)  # the same SQP path (give or take the last test)


def test_fast_path_obstacle_cost_changes_the_command():
    """The obstacle cost really enters the fast QP: without it the command differs."""
    from mpcdrive.bench.problems import p3

    b = p3()
    x = np.array([4.2, 0.05, 0.0])
    with_ob = LtvMpc(b.model, b.path, b.problem, b.config, obstacles=b.obstacles, avoidance=b.avoidance)
    without = LtvMpc(b.model, b.path, b.problem, b.config)
    u1 = with_ob.step(x, with_ob.initial_warm(x)).u
    u0 = without.step(x, without.initial_warm(x)).u
    assert abs(u1[0] - u0[0]) > 1e-3


def test_obstacle_formulations_the_fast_path_declines_are_named():
    from mpcdrive.control.compiled_mpc import obstacles_unsupported_reason
    from mpcdrive.ocp.avoidance import AvoidanceConfig
    from mpcdrive.scene import Circle, Obstacle
    from mpcdrive.scene.obstacles import ConstantVelocity, TrajectoryMotion

    ob = Obstacle(Circle(0.2), (1.0, 0.0, 0.0))
    assert obstacles_unsupported_reason((ob,), AvoidanceConfig("gaussian")) is None
    assert obstacles_unsupported_reason((ob,), AvoidanceConfig("hard")) is None
    assert obstacles_unsupported_reason((ob,), AvoidanceConfig("corridor")) is None
    assert obstacles_unsupported_reason((ob,), AvoidanceConfig("hard", follow_gap_s=0.5)) is None  # car following
    m4 = KinematicBicycle4()
    pb = MpcProblem(4, 2, 10, 0.05, Q=[1, 1, 1, 1], R=[1, 1])
    assert "needs a road" in fast_unsupported_reason(
        m4, StraightPath((0, 0), (5, 0)), pb, obstacles=(ob,), avoidance=AvoidanceConfig("corridor")
    )
    rec = Obstacle(Circle(0.2), (1.0, 0.0, 0.0), TrajectoryMotion([0.0, 1.0], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]))
    assert obstacles_unsupported_reason((rec,), AvoidanceConfig("potential")) is None  # recorded: compiled

    class Swerving(ConstantVelocity):
        """A motion of the user's own: the compiled kernels know only the built-in ones."""

    own = Obstacle(Circle(0.2), (1.0, 0.0, 0.0), Swerving(0.5, 0.0))
    assert "follows a Swerving (no compiled form)" in obstacles_unsupported_reason((own,), AvoidanceConfig("potential"))


# --------------------------------------------------------------- obstacle constraint rows
def _tight(spec):
    c = spec.controller.model_copy(update={"backend": "osqp", "osqp_eps": 1e-9, "osqp_max_iter": 50000})
    return spec.model_copy(update={"controller": c})


@pytest.mark.slow
@pytest.mark.parametrize("sid", ROW_SCENARIOS)
def test_fast_constraint_rows_match_tight_osqp(sid):
    """Hard half-planes (discs against circles and moving rectangles, stop half-planes) and the
    corridor: fed the states of OSQP's closed loop (at 1e-9) and OSQP's own warm start, the fast
    controller gives OSQP's command on every step OSQP solves; its own closed loop is as safe
    and as accurate."""
    spec = load_scenario(sid)
    ref = build_experiment(_tight(spec))
    fast = build_experiment(_with_backend(spec, "fast"))
    assert isinstance(fast.controller, CompiledLtvMpc)
    assert fast.controller.avoidance.config.uses_rows
    ref_result = run_experiment(ref)
    rc, fc = ref.controller, fast.controller
    warm = rc.initial_warm(ref_result.x[0])
    skipped, du = 0, []
    for k in range(ref_result.steps):
        o_ref = rc.step(ref_result.x[k], warm)
        o_fast = fc.step(ref_result.x[k], warm)
        assert o_fast.status == "ok", (sid, k, o_fast.status)
        if o_ref.status == "ok":
            du.append(float(np.abs(o_fast.u - o_ref.u).max()))
            assert o_fast.warm.sides == o_ref.warm.sides
        else:
            skipped += 1
        warm = o_ref.warm
    # OSQP at 1e-9 runs into its iteration cap on a few steps near the obstacles (6 of the slalom's
    # 280 steps): the comparison needs the steps it solves, and those must be at least 97 % of them
    assert skipped <= max(5, math.ceil(0.03 * ref_result.steps)), (sid, skipped, ref_result.steps)
    assert max(du) <= 1e-5, f"{sid}: max |du| {max(du):.2e}"
    m_ref = compute_metrics(ref_result)
    m_fast = compute_metrics(run_experiment(fast))
    # the two closed loops (solvers at different tolerances) drift apart by centimetres over the
    # run (obstacle-crossing: 3 cm at the path's end, less than the 5 cm one step covers), so the
    # step that crosses the goal may differ by one, and their lateral errors by up to what one
    # step covers (obstacle-crossing, its steering at the rate limit 15 % of the time: 1.1 cm RMS)
    assert abs(m_fast["steps"] - m_ref["steps"]) <= 1 and m_fast["goal_reached"] == m_ref["goal_reached"]
    assert m_fast["collisions"] == 0 and m_fast["solver_failures"] == 0
    one_step_m = float(np.max(ref_result.v_mps)) * spec.dt_s
    assert abs(m_fast["rms_lateral_error_m"] - m_ref["rms_lateral_error_m"]) <= one_step_m


# ---------------------------------------------------------- dynamic model against tight OSQP
@pytest.mark.slow
@pytest.mark.parametrize("sid", TIGHT_DYNAMIC_SCENARIOS)
def test_fast_dynamic_scenarios_match_tight_osqp(sid):
    """Fed the states of OSQP's closed loop (at 1e-10) and OSQP's own warm start, the fast
    controller gives OSQP's command on every step; its own closed loop ends within two steps of
    OSQP's, without failures or fallbacks, and with the same saturated steering."""
    spec = load_scenario(sid)
    c = spec.controller.model_copy(update={"backend": "osqp", "osqp_eps": 1e-10, "osqp_max_iter": 200000})
    ref = build_experiment(spec.model_copy(update={"controller": c}))
    fast = build_experiment(_with_backend(spec, "fast"))
    assert isinstance(fast.mpc, CompiledLtvMpc)
    ref_result = run_experiment(ref)
    rc, fc = ref.controller, fast.controller
    warm = rc.initial_warm(ref_result.x[0])
    du = np.empty(ref_result.steps)
    for k in range(ref_result.steps):
        o_ref = rc.step(ref_result.x[k], warm)
        o_fast = fc.step(ref_result.x[k], warm)
        assert o_ref.status == "ok" and o_fast.status == "ok", (sid, k, o_ref.status, o_fast.status)
        du[k] = np.abs(o_fast.u - o_ref.u).max()
        warm = o_ref.warm
    assert du.max() <= COMMAND_TOL_RAD, f"{sid}: max |du| {du.max():.2e} at step {du.argmax()}"
    m_ref = compute_metrics(ref_result)
    m_fast = compute_metrics(run_experiment(fast))
    # the closed loops part by roundoff (see test_track_raceway_closed_loop_is_chaotic): the goal
    # may be reached a step earlier or later
    assert abs(m_fast["steps"] - m_ref["steps"]) <= 2 and m_fast["goal_reached"] == m_ref["goal_reached"]
    assert (m_fast["solver_failures"], m_fast["fallbacks"]) == (0, 0)
    assert abs(m_fast["max_abs_steer_rad"] - m_ref["max_abs_steer_rad"]) <= COMMAND_TOL_RAD


@pytest.mark.slow
def test_track_raceway_closed_loop_is_chaotic():
    """Why track-raceway's closed-loop RMS lateral error is not compared with OSQP's: OSQP's own
    closed loop changes it by more than the metric tolerance when the start moves by 1e-12 m."""
    exp = build_experiment(_with_backend(load_scenario("track-raceway"), "osqp"))
    rms = []
    for dy in (0.0, 1e-12, -1e-12):
        x0 = exp.x0.copy()
        x0[1] += dy
        result = run_experiment(replace(exp, x0=x0))
        rms.append(compute_metrics(result)["rms_lateral_error_m"])
    assert max(rms) - min(rms) > METRIC_TOL_M + 0.01 * min(rms), rms


@pytest.mark.parametrize("sid", ["paper-exp5-gaussian", "paper-exp5-hard"])
def test_fast_controller_keeps_its_obstacles_as_the_osqp_one_does(sid):
    """Reports and adapters read ``controller.avoidance`` (config, obstacles): the same on both."""
    spec = load_scenario(sid)
    ref, fast = (build_experiment(_with_backend(spec, b)).controller for b in ("osqp", "fast"))
    assert isinstance(fast, CompiledLtvMpc)
    assert fast.avoidance.config == ref.avoidance.config
    assert list(map(repr, fast.avoidance.obstacles)) == list(map(repr, ref.avoidance.obstacles))
    assert repr(fast.avoidance.road) == repr(ref.avoidance.road)


@pytest.mark.slow
@pytest.mark.parametrize("sid", ["obstacle-overtake", "paper-exp5-gaussian"])
def test_set_obstacles_moves_them_as_on_the_osqp_controller(sid):
    """Obstacles replaced every step (here: nudged sideways by a few centimetres) reach the fast
    controller's rows (hard) or its compiled cost (gaussian) exactly as they reach OSQP's."""
    from mpcdrive.scene import Obstacle

    spec = load_scenario(sid)
    ref = build_experiment(_tight(spec))
    fast = build_experiment(_with_backend(spec, "fast"))
    rc, fc = ref.controller, fast.controller
    base = rc.obstacles
    ref_result = run_experiment(ref)
    warm = rc.initial_warm(ref_result.x[0])
    moved_any = False
    for k in range(min(150, ref_result.steps)):
        dy = 0.05 * math.sin(0.2 * k)
        nudged = [Obstacle(ob.shape, (ob.pose[0], ob.pose[1] + dy, ob.pose[2]), ob.motion, ob.name) for ob in base]
        plain = fc.step(ref_result.x[k], warm)
        rc.set_obstacles(nudged)
        fc.set_obstacles(nudged)
        o_ref, o_fast = rc.step(ref_result.x[k], warm), fc.step(ref_result.x[k], warm)
        rc.set_obstacles(base)
        fc.set_obstacles(base)
        if o_ref.status == "ok":
            assert np.abs(o_fast.u - o_ref.u).max() <= 1e-5, (sid, k)
            moved_any |= bool(np.abs(o_fast.u - plain.u).max() > 1e-6)
        warm = o_ref.warm
    assert moved_any, "the nudged obstacles never changed a command"


def test_set_obstacles_is_refused_where_the_compiled_cost_cannot_take_them():
    from mpcdrive.scene import Circle, Obstacle

    fc = build_experiment(_with_backend(load_scenario("paper-exp5-gaussian"), "fast")).controller
    ob = fc.obstacles[0]
    with pytest.raises(ValueError, match="built for 1 obstacle"):
        fc.set_obstacles([ob, ob])
    with pytest.raises(ValueError, match="must be an Obstacle"):
        fc.set_obstacles([(1.0, 2.0)])
    with pytest.raises(ValueError, match="built without obstacles"):
        build_experiment(_with_backend(load_scenario("paper-exp1"), "fast")).controller.set_obstacles([ob])
    fc.set_obstacles([Obstacle(Circle(0.3), (2.0, 0.1, 0.0))])  # one static circle: taken
    assert fc.obstacles[0].pose == (2.0, 0.1, 0.0)


def test_the_relax_rung_avoids_the_obstacles_set_last():
    """After ``set_obstacles`` the relax rung (a second compiled controller) sees the new
    obstacles: its command equals that of a controller built with them."""
    from mpcdrive.ocp.avoidance import AvoidanceConfig
    from mpcdrive.scene import Circle, Obstacle

    model = KinematicBicycle4()
    # speed bound [0, 1] with the car at 3 m/s and braking limited: every QP is infeasible and
    # the relaxed problem (no state bounds) solves
    pb = MpcProblem(
        4,
        2,
        10,
        0.05,
        Q=[1, 1, 1, 1],
        R=0.1,
        u_min=[-STEER, -0.1],
        u_max=[STEER, 0.1],
        x_min=[-np.inf] * 3 + [0.0],
        x_max=[np.inf] * 3 + [1.0],
    )
    path = StraightPath([0, 0], [50, 0])
    far, near = Obstacle(Circle(0.3), (40.0, 0.0, 0.0)), Obstacle(Circle(0.3), (1.5, 0.1, 0.0))
    av = AvoidanceConfig("hard", influence_m=3.0)
    moved = CompiledLtvMpc(model, path, pb, MpcConfig(v_ref_mps=1.0), obstacles=(far,), avoidance=av)
    moved.set_obstacles((near,))
    built = CompiledLtvMpc(model, path, pb, MpcConfig(v_ref_mps=1.0), obstacles=(near,), avoidance=av)
    kept = CompiledLtvMpc(model, path, pb, MpcConfig(v_ref_mps=1.0), obstacles=(far,), avoidance=av)
    x = np.array([0.0, 0.0, 0.0, 3.0])
    outs = [c.step(x, c.initial_warm(x)) for c in (moved, built, kept)]
    assert [o.fallback for o in outs] == ["relax"] * 3
    np.testing.assert_array_equal(outs[0].u, outs[1].u)
    assert np.abs(outs[0].u - outs[2].u).max() > 1e-6  # the obstacle matters to this command


def test_the_relax_rung_shares_its_parents_compiled_step():
    """The relax rung's controller drops the state bounds, so its problem alone would need a
    smaller step: it runs its parent's instead of compiling another; a spec that lacks a feature
    the problem needs is refused."""
    from mpcdrive.control.compiled_step import StepSpec

    bounds = dict(Q=1.0, R=1.0, u_min=[-STEER, -3.0], u_max=[STEER, 3.0], x_min=[-np.inf] * 3 + [0.0])
    args = (KinematicBicycle4(), StraightPath([0, 0], [10, 0]), MpcProblem(4, 2, 10, 0.05, **bounds))
    c = CompiledLtvMpc(*args)
    assert c.step_spec == StepSpec(4, extras=True)
    assert c._relaxed is not None and c._relaxed.step_spec == c.step_spec
    assert c._relaxed._step_fn is c._step_fn
    with pytest.raises(ValueError, match="lacks what this problem needs"):
        CompiledLtvMpc(*args, step_spec=StepSpec(4))
    with pytest.raises(ValueError, match="lacks what this problem needs"):
        CompiledLtvMpc(*args, step_spec=StepSpec(3, extras=True))


def test_a_spec_with_more_features_runs_the_problem_the_same():
    """``step_spec`` may name a step with more code than the problem needs (the relax rung runs
    its parent's): the branches it adds are off for this assembly, so the plans are the same."""
    from mpcdrive.bench.problems import p1
    from mpcdrive.control.compiled_step import StepSpec

    bp = p1(N=10)
    plain = CompiledLtvMpc(bp.model, bp.path, bp.problem, bp.config)
    full = CompiledLtvMpc(
        bp.model, bp.path, bp.problem, bp.config, step_spec=StepSpec(3, obstacle_cost=True, extras=True)
    )
    assert plain.step_spec == StepSpec(3) and full._step_fn is not plain._step_fn
    x_a = x_b = bp.x0.copy()
    warm_a, warm_b = plain.initial_warm(x_a), full.initial_warm(x_b)
    for _ in range(5):
        out_a, out_b = plain.step(x_a, warm_a), full.step(x_b, warm_b)
        assert out_a.status == out_b.status == "ok"
        np.testing.assert_allclose(out_b.u, out_a.u, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out_b.X_pred, out_a.X_pred, rtol=0, atol=1e-12)
        x_a = x_b = out_a.X_pred[1]
        warm_a, warm_b = out_a.warm, out_b.warm
