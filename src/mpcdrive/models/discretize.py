"""Discretization of a continuous model: forward Euler (the paper) and classic RK4.

Discrete Jacobians are exact derivatives of the discrete map, built from the model's
analytic continuous Jacobians by the chain rule (no finite differences).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .base import VehicleModel

Method = Literal["euler", "rk4"]


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
    if method == "rk4":
        k1 = model.f(x, u)
        k2 = model.f(x + 0.5 * dt * k1, u)
        k3 = model.f(x + 0.5 * dt * k2, u)
        k4 = model.f(x + dt * k3, u)
        return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    raise ValueError(f"unknown discretization method {method!r}; use 'euler' or 'rk4'")


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
    Jacobians of the composed substeps are chained (A = A_n ... A_1, B accumulated)."""
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
    eye = np.eye(model.nx)
    Ac, Bc = model.jacobians(x, u)
    k1 = model.f(x, u)
    if method == "euler":
        return x + dt * k1, eye + dt * Ac, dt * Bc
    if method != "rk4":
        raise ValueError(f"unknown discretization method {method!r}; use 'euler' or 'rk4'")
    # stage derivatives d k_i / d x and d k_i / d u by the chain rule
    J1x, J1u = Ac, Bc
    x2 = x + 0.5 * dt * k1
    A2, B2 = model.jacobians(x2, u)
    J2x = A2 @ (eye + 0.5 * dt * J1x)
    J2u = A2 @ (0.5 * dt * J1u) + B2
    k2 = model.f(x2, u)
    x3 = x + 0.5 * dt * k2
    A3, B3 = model.jacobians(x3, u)
    J3x = A3 @ (eye + 0.5 * dt * J2x)
    J3u = A3 @ (0.5 * dt * J2u) + B3
    k3 = model.f(x3, u)
    x4 = x + dt * k3
    A4, B4 = model.jacobians(x4, u)
    J4x = A4 @ (eye + dt * J3x)
    J4u = A4 @ (dt * J3u) + B4
    k4 = model.f(x4, u)
    Ad = eye + dt / 6.0 * (J1x + 2.0 * J2x + 2.0 * J3x + J4x)
    Bd = dt / 6.0 * (J1u + 2.0 * J2u + 2.0 * J3u + J4u)
    return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4), Ad, Bd


def rollout(model: VehicleModel, x0, U, dt: float, method: Method = "rk4", substeps: int = 1) -> np.ndarray:
    """States (N+1, nx) from ``x0`` under inputs ``U`` (N, nu)."""
    U = np.atleast_2d(np.asarray(U, float))
    X = np.empty((U.shape[0] + 1, model.nx))
    X[0] = x0
    for k in range(U.shape[0]):
        X[k + 1] = discrete_step(model, X[k], U[k], dt, method, substeps)
    return X
