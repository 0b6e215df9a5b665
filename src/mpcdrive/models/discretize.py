"""Discretization of a continuous model: forward Euler (the paper), classic RK4, and ``exp``
(linearize, then discretize exactly).

For ``euler`` and ``rk4`` the discrete Jacobians are exact derivatives of the discrete map, built
from the model's analytic continuous Jacobians by the chain rule (no finite differences).

``exp`` (exponential Rosenbrock-Euler) linearizes the continuous model at (x, u),
``xdot ~ f + A (x' - x) + B (u' - u)``, and integrates that affine model exactly over ``dt``
(zero-order hold on u): ``F = x + Gamma f`` with ``Ad = expm(A dt)``, ``Gamma = int_0^dt expm(A t) dt``,
``Bd = Gamma B``. It is exact for linear models and stable for stiff ones at any ``dt`` (the dynamic
bicycle at low speed), at the cost of one Jacobian evaluation per step; the ``Ad, Bd`` it returns
are this affine model's, the usual LTV-MPC prediction model (not the derivatives of ``F``).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .base import VehicleModel

Method = Literal["euler", "rk4", "exp"]
METHODS = ("euler", "rk4", "exp")


def _expm(M: np.ndarray) -> np.ndarray:
    """Matrix exponential of a batch (..., n, n): scaling and squaring with a degree-12 Taylor
    polynomial (relative error below 1e-14 after scaling the norm under 1/2)."""
    norm = float(np.max(np.sum(np.abs(M), axis=-1))) if M.size else 0.0
    sq = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0.5 else 0
    X = M / (2.0**sq)
    eye = np.eye(M.shape[-1])
    E = eye + X / 12.0
    for j in range(11, 0, -1):  # Horner: I + X/1 (I + X/2 (I + ...))
        E = eye + (X @ E) / j
    for _ in range(sq):
        E = E @ E
    return E


def _fj(model: VehicleModel):
    """f and Jacobians in one call when the model offers it."""
    fj = getattr(model, "f_and_jacobians", None)
    if fj is not None:
        return fj

    def both(x, u):
        A, B = model.jacobians(x, u)
        return model.f(x, u), A, B

    return both


def _exp_step(model: VehicleModel, x, u, dt: float):
    """(F, Ad, Bd) of the ``exp`` method: one augmented exponential [[A, B, f], [0, 0, 0]] dt."""
    f0, A, B = _fj(model)(x, u)
    nx, nu = A.shape[-1], B.shape[-1]
    M = np.zeros(A.shape[:-2] + (nx + nu + 1, nx + nu + 1))
    M[..., :nx, :nx] = A * dt
    M[..., :nx, nx : nx + nu] = B * dt
    M[..., :nx, -1] = f0 * dt
    E = _expm(M)
    return x + E[..., :nx, -1], E[..., :nx, :nx], E[..., :nx, nx : nx + nu]


def _check_substeps(substeps: int) -> int:
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps}")
    return int(substeps)


def discrete_step(model: VehicleModel, x, u, dt: float, method: Method = "rk4", substeps: int = 1) -> np.ndarray:
    """x_{k+1} = F(x_k, u_k) over ``dt`` [s] (zero-order hold on u); batches allowed.

    substeps : the step is taken as this many equal steps of ``dt / substeps`` (for stiff models
    such as the dynamic bicycle at low speed)."""
    x = np.asarray(x, float)
    if _check_substeps(substeps) > 1:
        h = dt / substeps
        for _ in range(substeps):
            x = discrete_step(model, x, u, h, method)
        return x
    if method == "euler":
        return x + dt * model.f(x, u)
    if method == "exp":
        return _exp_step(model, x, np.asarray(u, float), dt)[0]
    if method == "rk4":
        k1 = model.f(x, u)
        k2 = model.f(x + 0.5 * dt * k1, u)
        k3 = model.f(x + 0.5 * dt * k2, u)
        k4 = model.f(x + dt * k3, u)
        return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    raise ValueError(f"unknown discretization method {method!r}; use 'euler', 'rk4' or 'exp'")


def discrete_jacobians(
    model: VehicleModel, x, u, dt: float, method: Method = "rk4", substeps: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians (dF/dx (..., nx, nx), dF/du (..., nx, nu)) of :func:`discrete_step`.

    For Euler these are the paper's eqs. 9-11: ``A = I + dt*df/dx``, ``B = dt*df/du``.
    """
    _, Ad, Bd = discrete_step_and_jacobians(model, x, u, dt, method, substeps)
    return Ad, Bd


def discrete_step_and_jacobians(
    model: VehicleModel, x, u, dt: float, method: Method = "rk4", substeps: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F(x, u), dF/dx, dF/du) in one pass (the stages are shared); with ``substeps`` > 1 the
    Jacobians of the composed substeps are chained (A = A_n ... A_1, B accumulated). For ``exp``
    the Jacobians are those of the exactly discretized linearization (see the module docstring)."""
    x = np.asarray(x, float)
    u = np.asarray(u, float)
    if _check_substeps(substeps) > 1:
        h = dt / substeps
        x, Ad, Bd = discrete_step_and_jacobians(model, x, u, h, method)
        for _ in range(substeps - 1):
            x, Ai, Bi = discrete_step_and_jacobians(model, x, u, h, method)
            Ad = Ai @ Ad
            Bd = Ai @ Bd + Bi
        return x, Ad, Bd
    if method == "exp":
        return _exp_step(model, x, u, dt)
    if method not in METHODS:
        raise ValueError(f"unknown discretization method {method!r}; use 'euler', 'rk4' or 'exp'")
    eye = np.eye(model.nx)
    fj = _fj(model)
    k1, Ac, Bc = fj(x, u)
    if method == "euler":
        return x + dt * k1, eye + dt * Ac, dt * Bc
    # stage derivatives d k_i / d x and d k_i / d u by the chain rule
    J1x, J1u = Ac, Bc
    x2 = x + 0.5 * dt * k1
    k2, A2, B2 = fj(x2, u)
    J2x = A2 @ (eye + 0.5 * dt * J1x)
    J2u = A2 @ (0.5 * dt * J1u) + B2
    x3 = x + 0.5 * dt * k2
    k3, A3, B3 = fj(x3, u)
    J3x = A3 @ (eye + 0.5 * dt * J2x)
    J3u = A3 @ (0.5 * dt * J2u) + B3
    x4 = x + dt * k3
    k4, A4, B4 = fj(x4, u)
    J4x = A4 @ (eye + dt * J3x)
    J4u = A4 @ (dt * J3u) + B4
    Ad = eye + dt / 6.0 * (J1x + 2.0 * J2x + 2.0 * J3x + J4x)
    Bd = dt / 6.0 * (J1u + 2.0 * J2u + 2.0 * J3u + J4u)
    return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4), Ad, Bd


def rollout(model: VehicleModel, x0, U, dt: float, method: Method = "rk4", substeps: int = 1) -> np.ndarray:
    """States (N+1, nx) from ``x0`` under inputs ``U`` (N, nu); a single-input model also takes (N,)."""
    U = np.asarray(U, float)
    if U.ndim == 1 and model.nu == 1:
        U = U[:, None]
    if U.ndim != 2 or U.shape[1] != model.nu:
        raise ValueError(f"inputs must have shape (N, {model.nu}), got {U.shape}")
    X = np.empty((U.shape[0] + 1, model.nx))
    X[0] = x0
    for k in range(U.shape[0]):
        X[k + 1] = discrete_step(model, X[k], U[k], dt, method, substeps)
    return X
