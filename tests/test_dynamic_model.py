"""The dynamic bicycle model: Jacobians, low speed, steady-state cornering, presets, the ``exp``
discretization and state conversion between models."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcdrive.models import (
    PRESETS,
    DynamicBicycle,
    DynamicParams,
    KinematicBicycle3,
    KinematicBicycle4,
    KinematicParams,
    discrete_step,
    discrete_step_and_jacobians,
    get_preset,
    rollout,
    state_converter,
)

finite = dict(allow_nan=False, allow_infinity=False)
TIRES = ("linear", "pacejka")


def fd_jacobians(fun, x, u, h=1e-6):
    Jx = np.zeros((6, 6))
    Ju = np.zeros((6, 2))
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        Jx[:, i] = (fun(x + e, u) - fun(x - e, u)) / (2 * h)
    for i in range(2):
        e = np.zeros(2)
        e[i] = h
        Ju[:, i] = (fun(x, u + e) - fun(x, u - e)) / (2 * h)
    return Jx, Ju


def _away_from_kinks(model, vx, h=1e-5):
    p = model.params
    kinks = (model._v_eps, p.v_blend_low_mps, p.v_blend_high_mps)
    return all(abs(vx - k) > 10 * h for k in kinks)


@settings(max_examples=150, deadline=None)
@given(
    tire=st.sampled_from(TIRES),
    pose=st.tuples(st.floats(-20, 20, **finite), st.floats(-20, 20, **finite), st.floats(-7, 7, **finite)),
    vx=st.floats(-2.0, 10.0, **finite),
    vy=st.floats(-1.5, 1.5, **finite),
    r=st.floats(-4.0, 4.0, **finite),
    delta=st.floats(-0.6, 0.6, **finite),
    a=st.floats(-9.0, 9.0, **finite),
)
def test_jacobians_match_finite_differences(tire, pose, vx, vy, r, delta, a):
    m = DynamicBicycle(tire=tire)
    if not _away_from_kinks(m, vx):
        return
    x = np.array([*pose, vx, vy, r])
    u = np.array([delta, a])
    A, B = m.jacobians(x, u)
    Ax, Bx = fd_jacobians(m.f, x, u)
    scale = 1.0 + max(np.abs(Ax).max(), np.abs(Bx).max())
    np.testing.assert_allclose(A, Ax, atol=2e-6 * scale)
    np.testing.assert_allclose(B, Bx, atol=2e-6 * scale)
    f, A2, B2 = m.f_and_jacobians(x, u)
    np.testing.assert_allclose(f, m.f(x, u), rtol=1e-13, atol=1e-12)
    np.testing.assert_array_equal(A, A2)


@pytest.mark.parametrize("tire", TIRES)
def test_batched_and_single_evaluation_agree(tire):
    m = DynamicBicycle(tire=tire)
    rng = np.random.default_rng(3)
    X = rng.normal(size=(50, 6)) * [3, 3, 2, 3, 0.4, 1.5] + [0, 0, 0, 2, 0, 0]
    U = rng.normal(size=(50, 2)) * [0.3, 3]
    F = m.f(X, U)
    A, B = m.jacobians(X, U)
    for k in range(50):
        np.testing.assert_allclose(F[k], m.f(X[k], U[k]), rtol=1e-12, atol=1e-12)
        Ak, Bk = m.jacobians(X[k], U[k])
        np.testing.assert_allclose(A[k], Ak, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(B[k], Bk, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("tire", TIRES)
def test_f_components_is_the_single_definition_for_casadi_too(tire):
    ca = pytest.importorskip("casadi")
    m = DynamicBicycle(tire=tire)
    xs, us = ca.SX.sym("x", 6), ca.SX.sym("u", 2)
    expr = ca.vertcat(*m.f_components([xs[i] for i in range(6)], [us[i] for i in range(2)], ca))
    fun = ca.Function("f", [xs, us], [expr, ca.jacobian(expr, xs), ca.jacobian(expr, us)])
    for x, u in (
        ([1, 2, 0.3, 4.0, 0.2, 0.7], [0.1, 1.0]),
        ([0, 0, 0, 0.7, -0.1, 0.3], [-0.2, -2.0]),
        ([0, 0, 1, 0.0, 0.0, 0.0], [0.3, 0.0]),
    ):
        fx, Ax, Bx = (np.array(v) for v in fun(x, u))
        np.testing.assert_allclose(fx.ravel(), m.f(np.array(x, float), np.array(u, float)), atol=1e-12)
        A, B = m.jacobians(np.array(x, float), np.array(u, float))
        np.testing.assert_allclose(Ax, A, atol=1e-9)
        np.testing.assert_allclose(Bx, B, atol=1e-9)


# ------------------------------------------------------------------ low speed, stop and go
@pytest.mark.parametrize("tire", TIRES)
def test_no_nan_at_zero_and_negative_speed(tire):
    m = DynamicBicycle(tire=tire)
    for vx in (0.0, -0.0, 1e-12, -0.3, m._v_eps, m.params.v_blend_low_mps):
        for u in ([0.0, 0.0], [0.4, 0.0], [-0.4, -3.0], [0.2, 5.0]):
            x = np.array([1.0, -2.0, 0.5, vx, 0.05, -0.1])
            u = np.array(u)
            for out in (
                m.f(x, u),
                *m.jacobians(x, u),
                *discrete_step_and_jacobians(m, x, u, 0.05, "exp"),
                discrete_step(m, x, u, 0.05, "rk4", 10),
            ):
                assert np.all(np.isfinite(out))
    d, b, a = m.steady_state_full(np.array([0.0, 0.5, -1.0]), np.array([0.0, 0.0, 0.0]))
    assert np.all(np.isfinite(d)) and np.all(np.isfinite(b)) and np.all(np.isfinite(a))


def test_below_the_blend_speed_the_pose_moves_like_the_kinematic_bicycle():
    p = DynamicParams()
    dyn = DynamicBicycle(p)
    kin = KinematicBicycle4(KinematicParams(p.lf_m, p.lr_m))
    v, delta = 0.3, 0.3
    beta = math.atan(p.lq * math.tan(delta))
    # a state already at its kinematic values: vx = v cos(beta), vy = v sin(beta), r = v sin(beta) / lr
    x_dyn = np.array([0.0, 0.0, 0.2, v * math.cos(beta), v * math.sin(beta), v * math.sin(beta) / p.lr_m])
    x_kin = np.array([0.0, 0.0, 0.2, v])
    fd, fk = dyn.f(x_dyn, [delta, 0.0]), kin.f(x_kin, [delta, 0.0])
    np.testing.assert_allclose(fd[:3], fk[:3], atol=1e-12)
    np.testing.assert_allclose(fd[3:], 0.0, atol=1e-12)  # an equilibrium of the relaxed velocities


def test_standstill_start_and_stop_stays_finite_and_stops():
    """Accelerate from rest through the blend into the dynamic regime, brake back to rest."""
    m = DynamicBicycle()
    X = rollout(m, np.zeros(6), np.array([[0.2, 3.0]] * 40), 0.05, "rk4", 10)
    assert np.all(np.isfinite(X))
    assert X[-1, 3] > 5.0  # well into the dynamic regime
    x = X[-1]
    for _ in range(120):  # brake to rest with a speed loop, through the blend to standstill
        x = discrete_step(m, x, [0.2, float(np.clip(-3.0 * x[3], -4.0, 4.0))], 0.05, "rk4", 10)
        assert np.all(np.isfinite(x))
    assert abs(x[3]) < 0.01 and abs(x[4]) < 0.01 and abs(x[5]) < 0.05


# ------------------------------------------------------------------ steady-state cornering
@pytest.mark.parametrize("v, delta", [(2.0, 0.05), (4.0, 0.03), (4.0, 0.1), (6.0, 0.05), (6.0, 0.1)])
def test_steady_state_cornering_matches_the_linear_understeer_relation(v, delta):
    """Drive the linear-tire model at constant steering and speed until steady: the measured
    curvature and lateral acceleration satisfy delta = L kappa + K_us a_y (textbook relation, no
    load transfer)."""
    p = DynamicParams(h_cg_m=0.0)
    m = DynamicBicycle(p, tire="linear")
    x = np.array([0.0, 0.0, 0.0, v, 0.0, 0.0])
    for _ in range(1500):
        x = discrete_step(m, x, [delta, 5.0 * (v - x[3])], 0.004)
    V = math.hypot(x[3], x[4])
    kappa, ay = x[5] / V, V * x[5]
    predicted = p.wheelbase_m * kappa + p.understeer_gradient_rad_per_mps2 * ay
    assert predicted == pytest.approx(delta, rel=0.015)
    # and the understeer term matters here: the kinematic relation alone is off
    assert abs(p.wheelbase_m * kappa - delta) > 3 * abs(predicted - delta)


@pytest.mark.parametrize("tire", TIRES)
@pytest.mark.parametrize("v, delta", [(3.0, 0.15), (5.0, 0.15), (6.0, 0.25)])
def test_steady_state_solver_reproduces_simulated_steady_cornering(tire, v, delta):
    m = DynamicBicycle(tire=tire)  # with load transfer
    x = np.array([0.0, 0.0, 0.0, v, 0.0, 0.0])
    for _ in range(1500):
        x = discrete_step(m, x, [delta, 5.0 * (v - x[3])], 0.004)
    a_hold = 5.0 * (v - x[3])
    V = math.hypot(x[3], x[4])
    d_ss, b_ss, a_ss = m.steady_state_full(np.array([x[5] / V]), np.array([V]))
    assert float(d_ss[0]) == pytest.approx(delta, abs=1e-6)
    assert float(b_ss[0]) == pytest.approx(math.atan2(x[4], x[3]), abs=1e-6)
    assert float(a_ss[0]) == pytest.approx(a_hold, abs=1e-4)


def test_reference_state_is_an_equilibrium_of_the_model():
    m = DynamicBicycle()
    pose = np.array([[0.0, 0.0, 0.4], [1.0, 2.0, -1.0]])
    kappa = np.array([0.3, -0.4])
    v = np.array([4.0, 3.5])
    xr, ur = m.reference(pose, kappa, v)
    f = m.f(xr, ur)
    np.testing.assert_allclose(f[:, 3:], 0.0, atol=1e-7)  # steady velocities
    np.testing.assert_allclose(f[:, 2], v * kappa, rtol=1e-7)  # yaw rate = v kappa
    speed_dir = np.arctan2(f[:, 1], f[:, 0])  # the centre of gravity moves along the path heading
    np.testing.assert_allclose(speed_dir, pose[:, 2], atol=1e-7)
    xr0, ur0 = m.reference(pose, kappa, v, feedforward=False)
    np.testing.assert_array_equal(ur0, 0.0)
    np.testing.assert_array_equal(xr0[:, 2], pose[:, 2])


def test_steady_state_needs_a_speed():
    with pytest.raises(ValueError, match="speed"):
        DynamicBicycle().steady_state(0.1)


# ------------------------------------------------------------------ parameters and presets
def test_f1tenth_preset_is_the_f1tenth_gym_car():
    pre = get_preset("f1tenth")
    p = pre.params
    assert (p.mass_kg, p.yaw_inertia_kgm2, p.lf_m, p.lr_m) == (3.74, 0.04712, 0.15875, 0.17145)
    assert (p.friction, p.cs_front_per_rad, p.cs_rear_per_rad, p.h_cg_m) == (1.0489, 4.718, 5.4562, 0.074)
    assert pre.max_steer_rad == 0.4189 and pre.max_steer_rate_rad_s == 3.2
    assert pre.min_turning_radius_m == pytest.approx(0.3302 / math.tan(0.4189))
    # cornering stiffness C_alpha = mu C_S m g l / L
    assert p.cornering_stiffness_front_n_per_rad == pytest.approx(1.0489 * 4.718 * 3.74 * 9.81 * 0.17145 / 0.3302)


@pytest.mark.parametrize(
    "name, mass, iz, lf, lr, steer",
    [
        ("commonroad_ford_escort", 1225.887, 1538.853, 0.88392, 1.50876, 0.910),
        ("commonroad_bmw_320i", 1093.295, 1791.600, 1.15620, 1.42272, 1.066),
        ("commonroad_vw_vanagon", 1478.898, 2473.118, 1.15079, 1.32114, 1.023),
    ],
)
def test_commonroad_presets(name, mass, iz, lf, lr, steer):
    pre = PRESETS[name]
    p = pre.params
    assert p.mass_kg == pytest.approx(mass, rel=1e-5)
    assert p.yaw_inertia_kgm2 == pytest.approx(iz, rel=1e-5)
    assert (p.lf_m, p.lr_m) == (pytest.approx(lf, rel=1e-4), pytest.approx(lr, rel=1e-4))
    assert p.friction == 1.0489 and p.cs_front_per_rad == pytest.approx(21.92 / 1.0489)
    assert pre.max_steer_rad == steer and pre.max_steer_rate_rad_s == 0.4
    DynamicBicycle(p).f(np.array([0, 0, 0, 20.0, 0, 0]), np.array([0.02, 0.0]))


@pytest.mark.parametrize(
    "bad",
    [
        dict(mass_kg=0.0),
        dict(lf_m=-0.1),
        dict(friction=float("nan")),
        dict(v_blend_low_mps=2.0, v_blend_high_mps=1.0),
        dict(pacejka_c=2.5),
        dict(h_cg_m=-0.1),
        dict(pacejka_e=1.0),
    ],
)
def test_bad_parameters_are_rejected_naming_the_field(bad):
    with pytest.raises(ValueError, match=next(iter(bad)).split("_")[0]):
        DynamicParams(**bad)


def test_unknown_preset_and_tire():
    with pytest.raises(ValueError, match="known"):
        get_preset("trabant")
    with pytest.raises(ValueError, match="tire"):
        DynamicBicycle(tire="bias-ply")
    with pytest.raises(ValueError, match="unknown parameter"):
        DynamicParams().scaled(weight=1.2)
    assert DynamicParams().scaled(mass_kg=1.2).mass_kg == pytest.approx(3.74 * 1.2)


# ------------------------------------------------------------------ discretization
def test_exp_discretization_is_the_exact_zero_order_hold_of_the_linearization():
    m = DynamicBicycle()
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = rng.normal(size=6) * [1, 1, 1, 1, 0.2, 0.5] + [0, 0, 0, 3.0, 0, 0]
        u = rng.normal(size=2) * [0.2, 1.0]
        dt = 0.05
        F, Ad, Bd = discrete_step_and_jacobians(m, x, u, dt, "exp")
        A, B = m.jacobians(x, u)
        M = np.zeros((9, 9))
        M[:6, :6], M[:6, 6:8], M[:6, 8] = A * dt, B * dt, m.f(x, u) * dt
        E = sla.expm(M)
        np.testing.assert_allclose(Ad, E[:6, :6], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(Bd, E[:6, 6:8], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(F, x + E[:6, 8], rtol=1e-10, atol=1e-12)
        # second order (exponential Rosenbrock-Euler): local error ~ dt^3
        errs = [
            np.abs(discrete_step(m, x, u, h, "exp") - discrete_step(m, x, u, h, "rk4", 50)).max() for h in (0.02, 0.01)
        ]
        assert 5.0 < errs[0] / errs[1] < 11.0


def test_exp_prediction_is_stable_where_explicit_rk4_is_not():
    """At low speed the lateral dynamics are stiff (eigenvalues ~ -100 1/s at 1 m/s): one RK4 step
    of 0.05 s amplifies them, the exactly discretized linearization does not."""
    m = DynamicBicycle()
    x = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    u = np.array([0.1, 0.0])
    _, Ad_rk4, _ = discrete_step_and_jacobians(m, x, u, 0.05, "rk4")
    _, Ad_exp, _ = discrete_step_and_jacobians(m, x, u, 0.05, "exp")
    assert np.max(np.abs(np.linalg.eigvals(Ad_rk4))) > 1.0
    assert np.max(np.abs(np.linalg.eigvals(Ad_exp))) <= 1.0 + 1e-9


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_substeps_equal_repeated_steps_with_chained_jacobians(method):
    m = DynamicBicycle()
    x = np.array([0.0, 0.0, 0.1, 3.0, 0.1, 0.3])
    u = np.array([0.1, 0.5])
    F, Ad, Bd = discrete_step_and_jacobians(m, x, u, 0.04, method, substeps=4)
    y = x.copy()
    A_acc, B_acc = np.eye(6), np.zeros((6, 2))
    for _ in range(4):
        y, Ai, Bi = discrete_step_and_jacobians(m, y, u, 0.01, method)
        A_acc, B_acc = Ai @ A_acc, Ai @ B_acc + Bi
    np.testing.assert_allclose(F, y, atol=1e-14)
    np.testing.assert_allclose(Ad, A_acc, atol=1e-13)
    np.testing.assert_allclose(Bd, B_acc, atol=1e-13)
    np.testing.assert_allclose(F, discrete_step(m, x, u, 0.04, method, 4), atol=1e-14)
    with pytest.raises(ValueError, match="substeps"):
        discrete_step(m, x, u, 0.04, method, 0)


# ------------------------------------------------------------------ state conversion
def test_state_conversion_between_models():
    dyn = DynamicBicycle()
    k4 = KinematicBicycle4()
    k3 = KinematicBicycle3(2.5)
    xd = np.array([[1.0, 2.0, 0.3, 3.0, 0.4, 0.5]])
    np.testing.assert_allclose(state_converter(dyn, k4)(xd), [[1.0, 2.0, 0.3, math.hypot(3.0, 0.4)]])
    np.testing.assert_allclose(state_converter(dyn, k3)(xd), [[1.0, 2.0, 0.3]])
    np.testing.assert_allclose(state_converter(k4, dyn)(np.array([1.0, 2.0, 0.3, 3.0])), [1.0, 2.0, 0.3, 3.0, 0, 0])
    np.testing.assert_allclose(state_converter(k3, dyn)(np.array([1.0, 2.0, 0.3])), [1.0, 2.0, 0.3, 2.5, 0, 0])
    same = state_converter(dyn, DynamicBicycle(tire="linear"))
    np.testing.assert_array_equal(same(xd), xd)
