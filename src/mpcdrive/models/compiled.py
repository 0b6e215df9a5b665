"""Compiled (numba) form of the vehicle models and their discretization, for the fast controller.

The equations are not written again here: the functions of :mod:`mpcdrive.models.kinematic`
(slip angle, right-hand side and partial derivatives at a slip angle, steady state) are compiled
as they stand, with numpy as their math namespace. This module only places their results in
state order and chains them through Euler / RK4 exactly as :mod:`mpcdrive.models.discretize`
does. The input is constant over a step, so the slip angle and its derivative are evaluated
once per step rather than once per RK4 stage. The ``exp`` method takes the matrix exponential
of the augmented linearization with :func:`expm_into`, the scaling and squaring Taylor
polynomial of ``discretize`` (the scaling chosen per step, where numpy picks one for a whole
batch: both are accurate to about 1e-14).

A model is described to compiled code by ``(kind, mp)``: ``kind`` an integer (see
:data:`KIND_KINEMATIC3`) and ``mp`` a float array of parameters ``[lq, lr_m, v_mps]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kinematic import (
    KinematicBicycle3,
    KinematicBicycle4,
    kinematic_partials_at_slip,
    kinematic_rhs_at_slip,
    slip_terms,
    slip_angle_derivative,
    steady_state_equations,
)

KIND_KINEMATIC3 = 3  # x, y, yaw; steer; constant speed mp[2]
KIND_KINEMATIC4 = 4  # x, y, yaw, v; steer, accel

METHOD_EULER = 0
METHOD_RK4 = 1
METHOD_EXP = 2

_slip = njit(cache=True, inline="always")(slip_terms)
_dslip = njit(cache=True, inline="always")(slip_angle_derivative)
_rhs = njit(cache=True, inline="always")(kinematic_rhs_at_slip)
_partials = njit(cache=True, inline="always")(kinematic_partials_at_slip)
_ss = njit(cache=True)(steady_state_equations)


def model_code(model) -> tuple[int, np.ndarray] | None:
    """``(kind, mp)`` of a model the compiled path knows, else None."""
    if type(model) is KinematicBicycle3:
        p = model.params
        return KIND_KINEMATIC3, np.array([p.lq, p.lr_m, model.v_mps])
    if type(model) is KinematicBicycle4:
        p = model.params
        return KIND_KINEMATIC4, np.array([p.lq, p.lr_m, 0.0])
    return None


@njit(cache=True)
def model_slip(kind, mp, u):
    """(slip terms (beta [rad], sin beta, cos beta), d beta / d steer) for input u (both kinematic
    models steer with u[0])."""
    return _slip(u[0], mp[0], np), _dslip(u[0], mp[0], np)


@njit(cache=True, inline="always")
def model_f_at(kind, mp, x, u, beta, out):
    """out (nx,) = f(x, u), given beta = the slip terms of u."""
    v = x[3] if kind == KIND_KINEMATIC4 else mp[2]
    xd, yd, psid = _rhs(x[2], v, beta, mp[1], np)
    out[0] = xd
    out[1] = yd
    out[2] = psid
    if kind == KIND_KINEMATIC4:
        out[3] = u[1]


@njit(cache=True)
def model_f(kind, mp, x, u, out):
    """out (nx,) = f(x, u), the continuous dynamics."""
    model_f_at(kind, mp, x, u, _slip(u[0], mp[0], np), out)


@njit(cache=True, inline="always")
def _jacobians_into(kind, mp, yaw, v, beta, dbeta, W, ia, ib):
    """W[ia] = df/dx (nx, nx), W[ib][:, :nu] = df/du, given beta and dbeta (all entries written)."""
    for i in range(W.shape[1]):
        for j in range(W.shape[2]):
            W[ia, i, j] = 0.0
            W[ib, i, j] = 0.0
    j0, j1, j2, j3, j4, j5, j6, j7 = _partials(yaw, v, beta, dbeta, mp[1], np)
    W[ia, 0, 2] = j0
    W[ia, 1, 2] = j1
    W[ib, 0, 0] = j5
    W[ib, 1, 0] = j6
    W[ib, 2, 0] = j7
    if kind == KIND_KINEMATIC4:
        W[ia, 0, 3] = j2
        W[ia, 1, 3] = j3
        W[ia, 2, 3] = j4
        W[ib, 3, 1] = 1.0


@njit(cache=True)
def model_jacobians(kind, mp, x, u, A, B):
    """A (nx, nx) = df/dx, B (nx, nu) = df/du at (x, u)."""
    nx = A.shape[0]
    W = np.zeros((2, nx, nx))
    v = x[3] if kind == KIND_KINEMATIC4 else mp[2]
    _jacobians_into(kind, mp, x[2], v, _slip(u[0], mp[0], np), _dslip(u[0], mp[0], np), W, 0, 1)
    A[:, :] = W[0]
    B[:, :] = W[1, :, :B.shape[1]]


# rows of the work array of discrete_step_jacobians
_WA, _WB, _WJX, _WJU, _WTX, _WTU, _WV = range(7)


@njit(cache=True)
def expm_into(W, n, im, ie, it):
    """W[ie, :n, :n] = expm(W[im, :n, :n]) as :func:`mpcdrive.models.discretize._expm` computes it:
    scaling the norm under 1/2, a degree-12 Taylor polynomial (Horner), squaring back. W[im] is
    overwritten with the scaled matrix, W[it] is scratch."""
    norm = 0.0
    for i in range(n):
        t = 0.0
        for j in range(n):
            t += abs(W[im, i, j])
        norm = max(norm, t)
    sq = max(0, int(math.ceil(math.log2(norm / 0.5)))) if norm > 0.5 else 0
    scale = 2.0 ** sq
    for i in range(n):
        for j in range(n):
            W[im, i, j] = W[im, i, j] / scale
            W[ie, i, j] = (1.0 if i == j else 0.0) + W[im, i, j] / 12.0
    for p in range(11, 0, -1):  # E = I + X E / p
        for i in range(n):
            for j in range(n):
                t = 0.0
                for l in range(n):
                    t += W[im, i, l] * W[ie, l, j]
                W[it, i, j] = t
        for i in range(n):
            for j in range(n):
                W[ie, i, j] = (1.0 if i == j else 0.0) + W[it, i, j] / p
    for _ in range(sq):
        for i in range(n):
            for j in range(n):
                t = 0.0
                for l in range(n):
                    t += W[ie, i, l] * W[ie, l, j]
                W[it, i, j] = t
        for i in range(n):
            for j in range(n):
                W[ie, i, j] = W[it, i, j]


@njit(cache=True)
def discrete_step_jacobians(kind, mp, nx, nu, X, U, k, dt, method, F, A, B, W):
    """F[k] = x_{k+1} (nx,), A[k] (nx, nx), B[k] (nx, nu): the discrete map of
    :func:`mpcdrive.models.discretize.discrete_step_and_jacobians` at (X[k], U[k]) and its
    exact Jacobians.

    W : work array (7, nw, nw), nw >= nx (nu <= nx) for Euler and RK4, nw >= nx + nu + 1 for
    ``exp``. Works by index, without array views (each view costs a reference count in compiled
    code)."""
    beta, dbeta = _slip(U[k, 0], mp[0], np), _dslip(U[k, 0], mp[0], np)
    # stage state in W[_WV, 0], stage derivative in W[_WV, 1]
    for i in range(nx):
        W[_WV, 0, i] = X[k, i]
    if kind == KIND_KINEMATIC4:
        v = X[k, 3]
    else:
        v = mp[2]
    _jacobians_into(kind, mp, X[k, 2], v, beta, dbeta, W, _WA, _WB)
    xd, yd, psid = _rhs(X[k, 2], v, beta, mp[1], np)
    W[_WV, 1, 0] = xd
    W[_WV, 1, 1] = yd
    W[_WV, 1, 2] = psid
    if kind == KIND_KINEMATIC4:
        W[_WV, 1, 3] = U[k, 1]
    if method == METHOD_EXP:
        # expm of [[A, B, f], [0, 0, 0]] dt: F = x + its last column, Ad, Bd its blocks
        n = nx + nu + 1
        for i in range(n):
            for j in range(n):
                W[_WJX, i, j] = 0.0
        for i in range(nx):
            for j in range(nx):
                W[_WJX, i, j] = W[_WA, i, j] * dt
            for j in range(nu):
                W[_WJX, i, nx + j] = W[_WB, i, j] * dt
            W[_WJX, i, n - 1] = W[_WV, 1, i] * dt
        expm_into(W, n, _WJX, _WJU, _WTX)
        for i in range(nx):
            F[k, i] = X[k, i] + W[_WJU, i, n - 1]
            for j in range(nx):
                A[k, i, j] = W[_WJU, i, j]
            for j in range(nu):
                B[k, i, j] = W[_WJU, i, nx + j]
        return
    if method == METHOD_EULER:
        for i in range(nx):
            F[k, i] = X[k, i] + dt * W[_WV, 1, i]
            for j in range(nx):
                A[k, i, j] = (1.0 if i == j else 0.0) + dt * W[_WA, i, j]
            for j in range(nu):
                B[k, i, j] = dt * W[_WB, i, j]
        return
    # RK4: accumulate (k1 + 2 k2 + 2 k3 + k4) in F[k], the stage Jacobians in A[k], B[k]
    for i in range(nx):
        F[k, i] = W[_WV, 1, i]
        for j in range(nx):
            W[_WJX, i, j] = W[_WA, i, j]
            A[k, i, j] = W[_WA, i, j]
        for j in range(nu):
            W[_WJU, i, j] = W[_WB, i, j]
            B[k, i, j] = W[_WB, i, j]
    for stage in range(3):
        h = dt if stage == 2 else 0.5 * dt
        wgt = 1.0 if stage == 2 else 2.0
        for i in range(nx):
            W[_WV, 0, i] = X[k, i] + h * W[_WV, 1, i]
        yaw = W[_WV, 0, 2]
        if kind == KIND_KINEMATIC4:
            v = W[_WV, 0, 3]
        _jacobians_into(kind, mp, yaw, v, beta, dbeta, W, _WA, _WB)
        xd, yd, psid = _rhs(yaw, v, beta, mp[1], np)
        W[_WV, 1, 0] = xd
        W[_WV, 1, 1] = yd
        W[_WV, 1, 2] = psid
        if kind == KIND_KINEMATIC4:
            W[_WV, 1, 3] = U[k, 1]
        # J_next_x = A_s (I + h J_x) ; J_next_u = A_s (h J_u) + B_s
        for i in range(nx):
            for j in range(nx):
                W[_WTX, i, j] = W[_WA, i, j]
            for j in range(nu):
                W[_WTU, i, j] = W[_WB, i, j]
            for l in range(nx):
                ha = h * W[_WA, i, l]
                if ha != 0.0:  # continuous Jacobians are sparse
                    for j in range(nx):
                        W[_WTX, i, j] += ha * W[_WJX, l, j]
                    for j in range(nu):
                        W[_WTU, i, j] += ha * W[_WJU, l, j]
        for i in range(nx):
            F[k, i] += wgt * W[_WV, 1, i]
            for j in range(nx):
                W[_WJX, i, j] = W[_WTX, i, j]
                A[k, i, j] += wgt * W[_WTX, i, j]
            for j in range(nu):
                W[_WJU, i, j] = W[_WTU, i, j]
                B[k, i, j] += wgt * W[_WTU, i, j]
    c6 = dt / 6.0
    for i in range(nx):
        F[k, i] = X[k, i] + c6 * F[k, i]
        for j in range(nx):
            A[k, i, j] = (1.0 if i == j else 0.0) + c6 * A[k, i, j]
        for j in range(nu):
            B[k, i, j] = c6 * B[k, i, j]


@njit(cache=True)
def rollout_into(kind, mp, nx, X, U, n, dt, method, w):
    """X[k + 1] = F(X[k], U[k]) for k < n (no Jacobians) by Euler or RK4 (``exp`` needs the
    Jacobians: :func:`discrete_step_jacobians`). w : work array (3, nx)."""
    for k in range(n):
        beta = _slip(U[k, 0], mp[0], np)
        for i in range(nx):
            w[0, i] = X[k, i]
        for stage in range(4 if method == METHOD_RK4 else 1):
            h = 0.5 * dt if stage < 2 else dt
            v = w[0, 3] if kind == KIND_KINEMATIC4 else mp[2]
            xd, yd, psid = _rhs(w[0, 2], v, beta, mp[1], np)
            w[1, 0] = xd
            w[1, 1] = yd
            w[1, 2] = psid
            if kind == KIND_KINEMATIC4:
                w[1, 3] = U[k, 1]
            wgt = 1.0 if (stage == 0 or stage == 3) else 2.0
            for i in range(nx):
                if stage == 0:
                    w[2, i] = w[1, i]
                else:
                    w[2, i] += wgt * w[1, i]
                if stage < 3:
                    w[0, i] = X[k, i] + h * w[1, i]
        for i in range(nx):
            if method == METHOD_RK4:
                X[k + 1, i] = X[k, i] + dt / 6.0 * w[2, i]
            else:
                X[k + 1, i] = X[k, i] + dt * w[1, i]


@njit(cache=True)
def model_steady_state(kind, mp, kappa):
    """(steering [rad], slip angle [rad]) on curvature kappa [1/m]."""
    return _ss(kappa, mp[0], mp[1], np)


def _refresh_cache():
    from .. import _jitcache
    from . import kinematic

    # functions here inline the equations of kinematic.py; numba only watches this file
    _jitcache.refresh(discrete_step_jacobians, [kinematic.__file__])


_refresh_cache()
