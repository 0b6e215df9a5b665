"""The LTV-MPC controller: bad state input, bounds, fallbacks, linearization modes."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.control import FallbackConfig, LtvMpc, MpcConfig
from mpcdrive.models import KinematicBicycle3, KinematicBicycle4
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.sim import Plant, compute_metrics, simulate
from mpcdrive.types import SolveResult

STEER = math.radians(60)


def p1_controller(**cfg):
    model = KinematicBicycle3(1.0)
    pb = MpcProblem(3, 1, 20, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER, du_max_per_s=math.radians(300))
    return LtvMpc(model, StraightPath([0, 0], [10, 0]), pb, MpcConfig(**cfg))


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
    c = LtvMpc(model, path, pb, MpcConfig(v_ref_mps=1.0))
    r = simulate(c, Plant(model), path, [0, 0.2, 0, 3.0], 0.01, 30)
    m = compute_metrics(r)
    assert set(r.status) == {"infeasible"}
    assert m["solver_failures"] == 30 and m["fallbacks"] == 30
    assert set(r.fallback) == {"relax"} and m["fallback_counts"]["relax"] == 30
    assert np.all(np.isfinite(r.u)) and np.all(np.abs(r.u[:, 1]) <= 0.1 + 1e-9)
    assert np.all(np.diff(r.v_mps) < 0)  # slowing towards the limit at the largest braking allowed
    # the paper-era ladder: no plan to shift, so the last input is held
    c = LtvMpc(model, path, pb, MpcConfig(v_ref_mps=1.0, fallback=FallbackConfig(("shifted_plan", "hold_last"))))
    r = simulate(c, Plant(model), path, [0, 0.2, 0, 3.0], 0.01, 30)
    m = compute_metrics(r)
    assert m["solver_failures"] == 30 and m["fallbacks"] == 30
    assert set(r.fallback) == {"hold_last"}
    assert np.all(np.isfinite(r.u))


def test_shifted_plan_fallback_after_a_good_solve():
    model = KinematicBicycle3(1.0)
    path = StraightPath([0, 0], [10, 0])
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    c = LtvMpc(model, path, pb, MpcConfig(fallback=FallbackConfig(("shifted_plan", "brake"))))
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
        c = LtvMpc(model, path, pb, MpcConfig(linearization=lin))
        r = simulate(c, Plant(model), path, [1.5, 0, math.pi / 2], 0.01, 1000)
        errs[lin] = compute_metrics(r)["converged_max_abs_lateral_error_m"]
    assert errs["trajectory"] <= errs["paper"] + 1e-4
    assert errs["trajectory"] < 0.005


def test_heading_reference_never_jumps_by_two_pi_over_several_laps():
    model = KinematicBicycle3(2.0)
    path = CirclePath(radius_m=1.5)
    pb = MpcProblem(3, 1, 10, 0.01, Q=np.ones(3), R=1.0, u_min=-STEER, u_max=STEER)
    c = LtvMpc(model, path, pb)
    r = simulate(c, Plant(model), path, [1.5, 0, math.pi / 2], 0.01, 1600)  # ~3.4 laps
    assert r.yaw_rad[-1] > 3 * 2 * math.pi  # yaw kept unwrapped by the plant
    ref_yaw = r.refs[:, 0, 2]
    assert np.max(np.abs(np.diff(ref_yaw))) < 0.1
    assert np.max(np.abs(r.e_y_m[800:])) < 0.01
    assert r.s_m[-1] > 3 * path.length_m
