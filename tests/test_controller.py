"""The LTV-MPC controller: bad state input, bounds, fallbacks, linearization modes."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.control import FallbackConfig, MpcConfig, PythonLtvMpc
from mpcdrive.models import KinematicBicycle3, KinematicBicycle4
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.sim import Plant, compute_metrics, simulate
from mpcdrive.types import SolveResult

STEER = math.radians(60)


class _UserModel(KinematicBicycle3):
    """A model of the user's own: the compiled step knows only the built-in model types."""


def p1_controller(**cfg):
    model = KinematicBicycle3(1.0)
    pb = MpcProblem(3, 1, 20, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER, du_max_per_s=math.radians(300))
    return PythonLtvMpc(model, StraightPath([0, 0], [10, 0]), pb, MpcConfig(**cfg), "osqp")


@pytest.mark.parametrize("bad, field", [([np.nan, 0, 0], "x"), ([0, np.inf, 0], "y"), ([0, 0, -np.inf], "yaw")])
def test_non_finite_state_is_a_clear_value_error(bad, field):
    c = p1_controller()
    warm = c.initial_warm([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=f"state field\\(s\\) {field} not finite"):
        c.step(np.array(bad, float), warm)
    with pytest.raises(ValueError, match="shape"):
        c.step(np.zeros(4), warm)


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-3, 12),
    y=st.floats(-3, 3),
    yaw=st.floats(-math.pi, math.pi),
    u_prev=st.floats(-STEER, STEER),
    lin=st.sampled_from(["trajectory", "paper"]),
)
def test_commands_respect_steering_and_rate_bounds_from_random_states(x, y, yaw, u_prev, lin):
    c = p1_controller(linearization=lin)
    warm = c.initial_warm([x, y, yaw])
    warm = type(warm)(s_m=warm.s_m, u_prev=np.array([u_prev]))
    out = c.step(np.array([x, y, yaw]), warm)
    assert out.status == "ok"
    assert abs(out.u[0]) <= STEER + 1e-9
    assert abs(out.u[0] - u_prev) <= math.radians(300) * 0.01 + 1e-6
    assert np.all(np.isfinite(out.X_pred))


def test_infeasible_problem_falls_back_deliberately_and_is_counted():
    """Speed bounds [0, 1] with the car at 3 m/s and braking limited to 0.1 m/s^2: every QP is
    infeasible. The controller must report it, never output NaN, and count the fallbacks."""
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
    # the default ladder: the relaxed problem (no hard speed bounds) solves every step
    c = PythonLtvMpc(model, path, pb, MpcConfig(v_ref_mps=1.0), "osqp")
    r = simulate(c, Plant(model), path, [0, 0.2, 0, 3.0], 0.01, 30)
    m = compute_metrics(r)
    assert set(r.status) == {"infeasible"}
    assert m["solver_failures"] == 30 and m["fallbacks"] == 30
    assert set(r.fallback) == {"relax"} and m["fallback_counts"]["relax"] == 30
    assert np.all(np.isfinite(r.u)) and np.all(np.abs(r.u[:, 1]) <= 0.1 + 1e-9)
    assert np.all(np.diff(r.v_mps) < 0)  # slowing towards the limit at the largest braking allowed
    # the paper-era ladder: no plan to shift, so the last input is held
    c = PythonLtvMpc(
        model, path, pb, MpcConfig(v_ref_mps=1.0, fallback=FallbackConfig(("shifted_plan", "hold_last"))), "osqp"
    )
    r = simulate(c, Plant(model), path, [0, 0.2, 0, 3.0], 0.01, 30)
    m = compute_metrics(r)
    assert m["solver_failures"] == 30 and m["fallbacks"] == 30
    assert set(r.fallback) == {"hold_last"}
    assert np.all(np.isfinite(r.u))


def test_shifted_plan_fallback_after_a_good_solve():
    model = KinematicBicycle3(1.0)
    path = StraightPath([0, 0], [10, 0])
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    c = PythonLtvMpc(model, path, pb, MpcConfig(fallback=FallbackConfig(("shifted_plan", "brake"))), "osqp")
    x = np.array([0.0, 0.3, 0.0])
    out = c.step(x, c.initial_warm(x))
    assert out.status == "ok" and out.fallback == ""
    # a solver that fails on the next step
    failed = SolveResult("max_iter", np.full((11, 3), np.nan), np.full((10, 1), np.nan), np.nan, 4000, 0.0)
    c.backend.solve = lambda *a, **k: failed
    out2 = c.step(x, out.warm)
    assert out2.status == "max_iter"
    assert out2.fallback == "shifted_plan"
    assert out2.u[0] == pytest.approx(out.warm.U[1, 0])
    assert np.all(np.isfinite(out2.X_pred))


def test_osqp_backend_reports_failure_on_non_finite_data():
    c = p1_controller()
    c.qp.q[:] = np.nan
    res = c.backend.solve()
    assert res.status == "failed" and not res.ok
    assert np.all(np.isnan(res.U))


def test_trajectory_linearization_is_at_least_as_good_as_the_papers_on_the_circle():
    model = KinematicBicycle3(1.0)
    path = CirclePath(radius_m=1.5)
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    errs = {}
    for lin in ("trajectory", "paper"):
        c = PythonLtvMpc(model, path, pb, MpcConfig(linearization=lin), "osqp")
        r = simulate(c, Plant(model), path, [1.5, 0, math.pi / 2], 0.01, 1000)
        errs[lin] = compute_metrics(r)["converged_max_abs_lateral_error_m"]
    assert errs["trajectory"] <= errs["paper"] + 1e-4
    assert errs["trajectory"] < 0.005


def test_heading_reference_never_jumps_by_two_pi_over_several_laps():
    model = KinematicBicycle3(2.0)
    path = CirclePath(radius_m=1.5)
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    c = PythonLtvMpc(model, path, pb, MpcConfig(), "osqp")
    r = simulate(c, Plant(model), path, [1.5, 0, math.pi / 2], 0.01, 1600)  # ~3.4 laps
    assert r.yaw_rad[-1] > 3 * 2 * math.pi  # yaw kept unwrapped by the plant
    ref_yaw = r.refs[:, 0, 2]
    assert np.max(np.abs(np.diff(ref_yaw))) < 0.1
    assert np.max(np.abs(r.e_y_m[800:])) < 0.01
    assert r.s_m[-1] > 3 * path.length_m


def test_ltv_mpc_is_one_controller_for_every_assembly_and_solver():
    """``LtvMpc(...)`` returns the controller that covers the problem: the compiled step with the
    condensed solver by default, the Python assembly where asked for or needed (projected
    gradient), OSQP where asked for; every one an ``LtvMpc`` with the same closed loop."""
    import warnings

    from mpcdrive.control import FastPathUnavailable, LtvMpc
    from mpcdrive.control.compiled_mpc import CompiledLtvMpc
    from mpcdrive.solvers.osqp_backend import OsqpSettings

    model = KinematicBicycle3(1.0)
    path = CirclePath(radius_m=1.5)
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    tight = OsqpSettings(eps_abs=1e-10, eps_rel=1e-10, max_iter=100000)
    cases = {
        (): (CompiledLtvMpc, "compiled", "fast"),
        (("solver", "osqp"),): (CompiledLtvMpc, "compiled", "osqp"),
        (("assembly", "python"),): (PythonLtvMpc, "python", "fast"),
        (("assembly", "python"), ("solver", "osqp")): (PythonLtvMpc, "python", "osqp"),
        (("solver", "projected_gradient"),): (PythonLtvMpc, "python", "pg"),
    }
    x0 = np.array([1.5, 0.0, math.pi / 2])
    rms = {}
    with warnings.catch_warnings():
        warnings.simplefilter("error", FastPathUnavailable)  # the default covers this problem
        for kw, (cls, assembly, backend) in cases.items():
            c = LtvMpc(model, path, pb, osqp_settings=tight, **dict(kw))
            assert type(c) is cls and isinstance(c, LtvMpc)
            assert (c.assembly, c.backend_name) == (assembly, backend)
            res = simulate(c, Plant(model), path, x0=x0, dt_s=0.01, steps=200)
            rms[kw] = compute_metrics(res).rms_lateral_error_m
    exact = rms[()]
    for kw, v in rms.items():
        # the exact solvers agree to OSQP's stopping rule; projected gradient to its own (1e-6)
        assert v == pytest.approx(exact, abs=1e-4 if kw == (("solver", "projected_gradient"),) else 1e-7), kw
    with pytest.raises(ValueError, match="solver must be one of"):
        LtvMpc(model, path, pb, solver="ipopt")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="config must be an MpcConfig, got str"):
        LtvMpc(model, path, pb, "osqp")  # type: ignore[arg-type]
    with pytest.raises(
        ValueError, match="compiled step cannot assemble this problem: model _UserModel has no compiled"
    ):
        LtvMpc(_UserModel(1.0), path, pb, assembly="compiled")
    with pytest.raises(ValueError, match="compiled step's solver must be one of"):
        CompiledLtvMpc(model, path, pb, solver="projected_gradient")  # type: ignore[arg-type]
