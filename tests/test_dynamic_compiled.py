"""The compiled dynamic bicycle (models.compiled) against DynamicBicycle and models.discretize:
right-hand side and Jacobians (both tires, below, inside and above the low-speed blend), the
discrete step and its Jacobians (Euler, RK4, exp), rollouts, and the horizon references with and
without feedforward.

Tolerances: JAC_TOL for the continuous model (the same equations compiled: rounding only, scaled
by the size of the entries), FD_TOL for the finite-difference check of the Jacobians, REF_TOL for
the references (see below).
"""

import numpy as np
import pytest

from mpcdrive.models import DynamicBicycle
from mpcdrive.models.compiled import (
    KIND_DYNAMIC,
    METHOD_EULER,
    METHOD_EXP,
    METHOD_RK4,
    discrete_step_jacobians,
    model_code,
    model_f,
    model_jacobians,
    model_references,
    rollout_into,
)
from mpcdrive.models.discretize import discrete_step, discrete_step_and_jacobians
from mpcdrive.models.dynamic import STEADY_ACCEL_TOL_MPS2
from mpcdrive.models.presets import get_preset

JAC_TOL = 1e-9
FD_TOL = 1e-6
#: The steady cornering references come from a secant iteration on the drive acceleration that
#: stops when the residual |G(a) - a| < STEADY_ACCEL_TOL_MPS2 (1e-8 m/s^2) at every point. Two
#: implementations whose libm rounds differently may stop one iteration apart, so each is only
#: known to lie within tol / (1 - |G'|) of the fixed point: with |G'| <= 0.7 and |d delta / d a|,
#: |d beta / d a| <= 1.5 (s^2 / m; measured on these horizons at the converged points) the
#: references of the two agree within 2 tol / 0.3 * 1.5 = 1e-7. Where the secant runs out of
#: iterations (high curvature at speed, the front tire near its peak) there is no fixed point to
#: agree on: rounding decides where it stops (3.4e-8 apart on another CPU), so those points are
#: not compared; the closed-loop suites judge the references there.
REF_TOL = 2 * STEADY_ACCEL_TOL_MPS2 / (1 - 0.7) * 1.5
TIRES = ["linear", "pacejka"]
#: longitudinal speeds [m/s]: below the slip-speed floor (0.25), below the blend (0.5), inside it
#: (0.5 - 1.0), above it
SPEEDS = [0.1, 0.35, 0.6, 0.85, 2.0, 7.0]


def _model(tire):
    return DynamicBicycle(get_preset("f1tenth").params, tire)


def _states(n, seed):
    rng = np.random.default_rng(seed)
    X = np.column_stack(
        [
            rng.normal(size=n),
            rng.normal(size=n),
            rng.uniform(-3, 3, n),
            rng.choice(SPEEDS, n),
            rng.uniform(-0.5, 0.5, n),
            rng.uniform(-2, 2, n),
        ]
    )
    U = np.column_stack([rng.uniform(-0.4, 0.4, n), rng.uniform(-5, 5, n)])
    return X, U


def _close(a, b, tol):
    """|a - b| <= tol (1 + |b|) entrywise."""
    err = np.abs(np.asarray(a) - np.asarray(b)) / (1.0 + np.abs(b))
    assert err.max() <= tol, f"max scaled error {err.max():.2e}"


def test_model_code_of_the_dynamic_bicycle():
    kind, mp = model_code(_model("pacejka"))
    assert kind == KIND_DYNAMIC and mp[-1] == 1.0
    assert model_code(_model("linear"))[1][-1] == 0.0


@pytest.mark.parametrize("tire", TIRES)
def test_compiled_rhs_and_jacobians_equal_the_model(tire):
    model = _model(tire)
    kind, mp = model_code(model)
    X, U = _states(200, 1)
    f0, A0, B0 = model.f_and_jacobians(X, U)
    f, A, B = np.zeros(6), np.zeros((6, 6)), np.zeros((6, 2))
    for k in range(len(X)):
        model_f(kind, mp, X[k], U[k], f)
        model_jacobians(kind, mp, X[k], U[k], A, B)
        _close(f, model.f(X[k], U[k]), JAC_TOL)
        _close(f, f0[k], JAC_TOL)
        _close(A, A0[k], JAC_TOL)
        _close(B, B0[k], JAC_TOL)


@pytest.mark.parametrize("tire", TIRES)
def test_compiled_jacobians_equal_finite_differences(tire):
    """Central differences of the compiled f, away from the kinks of the speed floor and blend."""
    model = _model(tire)
    kind, mp = model_code(model)
    X, U = _states(60, 2)
    f_p, f_m = np.zeros(6), np.zeros(6)
    A, B = np.zeros((6, 6)), np.zeros((6, 2))
    h = 1e-6
    for k in range(len(X)):
        model_jacobians(kind, mp, X[k], U[k], A, B)
        for j in range(8):
            xp, xm, up, um = X[k].copy(), X[k].copy(), U[k].copy(), U[k].copy()
            if j < 6:
                xp[j] += h
                xm[j] -= h
            else:
                up[j - 6] += h
                um[j - 6] -= h
            model_f(kind, mp, xp, up, f_p)
            model_f(kind, mp, xm, um, f_m)
            col = A[:, j] if j < 6 else B[:, j - 6]
            _close(col, (f_p - f_m) / (2 * h), FD_TOL)


@pytest.mark.parametrize("tire", TIRES)
@pytest.mark.parametrize("method", ["euler", "rk4", "exp"])
def test_compiled_discrete_step_equals_numpy(tire, method):
    model = _model(tire)
    kind, mp = model_code(model)
    N, nx, nu, dt = 24, 6, 2, 0.05
    X, U = _states(N, 3)
    F, A, B = np.zeros((N, nx)), np.zeros((N, nx, nx)), np.zeros((N, nx, nu))
    code = {"rk4": METHOD_RK4, "euler": METHOD_EULER, "exp": METHOD_EXP}[method]
    W = np.zeros((7, nx + nu + 1, nx + nu + 1))
    for k in range(N):
        discrete_step_jacobians(kind, mp, nx, nu, X, U, k, dt, code, F, A, B, W)
    F0, A0, B0 = discrete_step_and_jacobians(model, X, U, dt, method)
    _close(F, F0, JAC_TOL)
    _close(A, A0, JAC_TOL)
    _close(B, B0, JAC_TOL)
    if method == "exp":  # the Jacobians are the rollout's: rollout_into does Euler and RK4
        return
    Xr = np.zeros((N, nx))
    Xr[0] = X[0]
    rollout_into(kind, mp, nx, Xr, U, N - 1, dt, code, 1, np.zeros((4, nx)))
    for k in range(N - 1):
        _close(Xr[k + 1], discrete_step(model, Xr[k], U[k], dt, method), JAC_TOL)


def _horizons():
    """(kappa, v) rows of horizons: constant, changing curvature at constant speed, a speed
    profile, beyond the grip, at low speed (the blend), repeated points."""
    rng = np.random.default_rng(4)
    n = 21
    return {
        "straight": (np.zeros(n), np.full(n, 3.0)),
        "corner": (np.linspace(0.0, 0.6, n), np.full(n, 4.0)),
        "profile": (rng.uniform(-0.6, 0.6, n), np.linspace(1.0, 7.0, n)),
        "beyond-grip": (np.linspace(-1.5, 1.5, n), np.full(n, 6.0)),
        "low-speed": (np.full(n, 0.5), np.linspace(0.0, 1.2, n)),
        "repeated": (np.repeat([0.2, 0.2, -0.4], 7), np.repeat([2.0, 3.0, 3.0], 7)),
    }


@pytest.mark.parametrize("tire", TIRES)
@pytest.mark.parametrize("feedforward", [True, False])
@pytest.mark.parametrize("horizon", list(_horizons()))
def test_compiled_references_equal_the_model(tire, feedforward, horizon):
    model = _model(tire)
    kind, mp = model_code(model)
    kappa, v = _horizons()[horizon]
    n = len(kappa)
    rng = np.random.default_rng(5)
    refs = np.column_stack([rng.normal(size=n), rng.normal(size=n), rng.uniform(-3, 3, n), kappa])
    xr0, ur0 = model.reference(refs[:, :3], kappa, v, feedforward)
    xref, uref = np.full((n, 6), np.nan), np.full((n - 1, 2), np.nan)
    model_references(kind, mp, refs, v, n, feedforward, xref, uref, np.zeros((n, 8)))
    converged = np.ones(n, bool)
    if feedforward:
        converged = model.steady_state_residual(kappa, v)[3] < STEADY_ACCEL_TOL_MPS2
        # the iteration converges at most points (the others lie at the high-curvature, high-speed
        # end of the horizons, where the front tire nears its peak)
        # ('beyond-grip' asks for up to 1.5 times the grip: no steady state exists at most points)
        assert horizon == "beyond-grip" or converged.mean() >= 0.5, np.flatnonzero(~converged)
    np.testing.assert_allclose(xref[converged], xr0[converged], rtol=0, atol=REF_TOL)
    np.testing.assert_allclose(uref[converged[: n - 1]], ur0[: n - 1][converged[: n - 1]], rtol=0, atol=REF_TOL)
