"""Compiled (numba) form of the vehicle models and their discretization, for the fast controller.

The equations are not written again here: the functions of :mod:`mpcdrive.models.kinematic`
(slip angle, right-hand side and partial derivatives at a slip angle, steady state) and of
:mod:`mpcdrive.models.dynamic` (right-hand side, its partial derivatives with the low-speed
blend and both tire models) are compiled as they stand, with numpy as their math namespace.
This module only places their results in state order and chains them through Euler / RK4
exactly as :mod:`mpcdrive.models.discretize` does. For the kinematic models the input is
constant over a step, so the slip angle and its derivative are evaluated once per step rather
than once per RK4 stage. The ``exp`` method takes the matrix exponential of the augmented
linearization with :func:`expm_into`, the scaling and squaring Taylor polynomial of
``discretize`` (the scaling chosen per step, where numpy picks one for a whole batch: both are
accurate to about 1e-14).

:func:`model_references` writes the horizon references of ``model.reference``: for the dynamic
bicycle with the steady cornering state of :meth:`DynamicBicycle.steady_state_full
<mpcdrive.models.dynamic.DynamicBicycle.steady_state_full>` (:func:`dynamic_steady_states`: its
iteration, point by point, with the convergence test over the whole horizon as numpy's batch
has it).

A model is described to compiled code by ``(kind, mp)``: ``kind`` an integer (see
:data:`KIND_KINEMATIC3`) and ``mp`` a float array of parameters: ``[lq, lr_m, v_mps]`` for the
kinematic models, :func:`~mpcdrive.models.dynamic.dynamic_parameters` for the dynamic bicycle.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.extending import register_jitable

from .._subroutine import subroutine
from . import dynamic
from .dynamic import (
    DYNAMIC_A_ENTRIES,
    DYNAMIC_B_ENTRIES,
    STEADY_ACCEL_TOL_MPS2,
    STEADY_SECANT_ITERATIONS,
    DynamicBicycle,
    dynamic_parameters,
    dynamic_rhs,
    dynamic_rhs_and_partials,
)
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
KIND_DYNAMIC = 6  # x, y, yaw, vx, vy, r; steer, accel; mp = dynamic_parameters(...)

METHOD_EULER = 0
METHOD_RK4 = 1
METHOD_EXP = 2

_slip = subroutine(slip_terms)
_dslip = subroutine(slip_angle_derivative)
_rhs = subroutine(kinematic_rhs_at_slip)
_partials = subroutine(kinematic_partials_at_slip)
_ss = subroutine(steady_state_equations)
# the dynamic equations call these helpers of their module: callable from compiled code as they are
for _helper in (
    dynamic._pacejka,
    dynamic._pacejka_and_slope,
    dynamic._smoothstep,
    dynamic.slip_speed_floor,
    dynamic.axle_tire,
):
    register_jitable(_helper)
_dyn_rhs = subroutine(dynamic_rhs)
_dyn_partials = subroutine(dynamic_rhs_and_partials)
_axle_tire = dynamic.axle_tire
_smoothstep = dynamic._smoothstep
# parameter indices of mp for the dynamic bicycle
_LF, _LR, _M, _MU, _CSF, _CSR, _H, _C, _E, _VLO, _VHI, _G, _PACEJKA = (
    dynamic._P_LF,
    dynamic._P_LR,
    dynamic._P_M,
    dynamic._P_MU,
    dynamic._P_CSF,
    dynamic._P_CSR,
    dynamic._P_H,
    dynamic._P_C,
    dynamic._P_E,
    dynamic._P_VLO,
    dynamic._P_VHI,
    dynamic._P_G,
    dynamic._P_PACEJKA,
)
_NA, _NB = len(DYNAMIC_A_ENTRIES), len(DYNAMIC_B_ENTRIES)


def model_code(model) -> tuple[int, np.ndarray] | None:
    """``(kind, mp)`` of a model the compiled path knows, else None."""
    if type(model) is KinematicBicycle3:
        p = model.params
        return KIND_KINEMATIC3, np.array([p.lq, p.lr_m, model.v_mps])
    if type(model) is KinematicBicycle4:
        p = model.params
        return KIND_KINEMATIC4, np.array([p.lq, p.lr_m, 0.0])
    if type(model) is DynamicBicycle:
        return KIND_DYNAMIC, np.array(dynamic_parameters(model.params, model.tire))
    return None


# rows of the work array of discrete_step_jacobians
_WA, _WB, _WJX, _WJU, _WTX, _WTU, _WV = range(7)


@subroutine
def _stage_into(kind, mp, W, U, k, beta, dbeta):
    """W[_WA] = df/dx (nx, nx), W[_WB][:, :nu] = df/du (their leading nx x nx and nx x 2 blocks
    written: the entries the steps read) and W[_WV, 1] = f, at the state W[_WV, 0] and input U[k]; beta, dbeta : the slip
    terms of U[k, 0] and their derivative (kinematic models; unused for the dynamic one)."""
    for i in range(kind):  # a kind's code is its number of states (3, 4, 6); inputs: at most 2
        for j in range(kind):
            W[_WA, i, j] = 0.0
        W[_WB, i, 0] = 0.0
        W[_WB, i, 1] = 0.0
    if kind == KIND_DYNAMIC:
        f, a, b = _dyn_partials(W[_WV, 0, 2], W[_WV, 0, 3], W[_WV, 0, 4], W[_WV, 0, 5], U[k, 0], U[k, 1], mp, np)
        for i in range(6):
            W[_WV, 1, i] = f[i]
        for n in range(_NA):
            W[_WA, DYNAMIC_A_ENTRIES[n][0], DYNAMIC_A_ENTRIES[n][1]] = a[n]
        for n in range(_NB):
            W[_WB, DYNAMIC_B_ENTRIES[n][0], DYNAMIC_B_ENTRIES[n][1]] = b[n]
        return
    yaw = W[_WV, 0, 2]
    v = W[_WV, 0, 3] if kind == KIND_KINEMATIC4 else mp[2]
    j0, j1, j2, j3, j4, j5, j6, j7 = _partials(yaw, v, beta, dbeta, mp[1], np)
    W[_WA, 0, 2] = j0
    W[_WA, 1, 2] = j1
    W[_WB, 0, 0] = j5
    W[_WB, 1, 0] = j6
    W[_WB, 2, 0] = j7
    xd, yd, psid = _rhs(yaw, v, beta, mp[1], np)
    W[_WV, 1, 0] = xd
    W[_WV, 1, 1] = yd
    W[_WV, 1, 2] = psid
    if kind == KIND_KINEMATIC4:
        W[_WA, 0, 3] = j2
        W[_WA, 1, 3] = j3
        W[_WA, 2, 3] = j4
        W[_WB, 3, 1] = 1.0
        W[_WV, 1, 3] = U[k, 1]


@subroutine
def _step_slip(kind, mp, U, k):
    """(slip terms, d beta / d steer) of the kinematic models for the step's input U[k] (dummies
    for the dynamic model, which needs none)."""
    if kind == KIND_DYNAMIC:
        return (0.0, 0.0, 1.0), 0.0
    return _slip(U[k, 0], mp[0], np), _dslip(U[k, 0], mp[0], np)


@subroutine
def _rhs_into(kind, mp, w, U, k, beta):
    """w[1] = f(w[0], U[k]) (without Jacobians); beta : the slip terms of U[k, 0] (kinematic)."""
    if kind == KIND_DYNAMIC:
        f = _dyn_rhs(w[0, 2], w[0, 3], w[0, 4], w[0, 5], U[k, 0], U[k, 1], mp, np)
        for i in range(6):
            w[1, i] = f[i]
        return
    v = w[0, 3] if kind == KIND_KINEMATIC4 else mp[2]
    xd, yd, psid = _rhs(w[0, 2], v, beta, mp[1], np)
    w[1, 0] = xd
    w[1, 1] = yd
    w[1, 2] = psid
    if kind == KIND_KINEMATIC4:
        w[1, 3] = U[k, 1]


@subroutine
def model_speed(kind, mp, x):
    """The speed [m/s] of state x, as the model's ``speed``: the constant ``mp[2]`` (kinematic3),
    ``v`` (kinematic4), ``hypot(vx, vy)`` (dynamic)."""
    if kind == KIND_KINEMATIC3:
        return mp[2]
    if kind == KIND_KINEMATIC4:
        return x[3]
    return math.hypot(x[3], x[4])


@njit(cache=True)
def model_f(kind, mp, x, u, out):
    """out (nx,) = f(x, u), the continuous dynamics."""
    nx = x.shape[0]
    w = np.zeros((2, nx))
    U = np.zeros((1, u.shape[0]))
    w[0, :] = x
    U[0, :] = u
    beta, _ = _step_slip(kind, mp, U, 0)
    _rhs_into(kind, mp, w, U, 0, beta)
    out[:] = w[1]


@njit(cache=True)
def model_jacobians(kind, mp, x, u, A, B):
    """A (nx, nx) = df/dx, B (nx, nu) = df/du at (x, u)."""
    nx = A.shape[0]
    W = np.zeros((7, nx, nx))
    U = np.zeros((1, u.shape[0]))
    W[_WV, 0, :] = x
    U[0, :] = u
    beta, dbeta = _step_slip(kind, mp, U, 0)
    _stage_into(kind, mp, W, U, 0, beta, dbeta)
    A[:, :] = W[_WA]
    B[:, :] = W[_WB, :, : B.shape[1]]


@subroutine
def _matmul_top_into(W, n, r, ia, ib, io):
    """The first r rows of W[ia, :n, :n] @ W[ib, :n, :n] into W[io] (io differs from ia and ib),
    where the rows r.. of W[ib] are those of the identity: the sum runs over the first r rows of
    W[ib] and adds W[ia, i, j] for j >= r. Every term the full product would add besides is an
    exact zero, so the result is the same to the last bit."""
    for i in range(r):
        for j in range(n):
            t = 0.0
            for l in range(r):
                t += W[ia, i, l] * W[ib, l, j]
            if j >= r:
                t += W[ia, i, j]
            W[io, i, j] = t


@subroutine
def expm_into(W, n, im, ie, it, r):
    """W[ie, :n, :n] = expm(W[im, :n, :n]) as :func:`mpcdrive.models.discretize._expm` computes it:
    scaling the norm under 1/2, a degree-12 Taylor polynomial (Horner), squaring back. The rows
    r.. of W[im] are zero (an augmented linearization [[A, B, f], [0, 0, 0]]): the powers then
    keep identity rows r.., and only the first r rows are multiplied (for 6 states, 2 inputs:
    6 x 6 x 9 products in place of 9 x 9 x 9). W[im] is overwritten with the scaled matrix,
    W[it] is scratch."""
    norm = 0.0
    for i in range(r):
        t = 0.0
        for j in range(n):
            t += abs(W[im, i, j])
        norm = max(norm, t)
    sq = max(0, int(math.ceil(math.log2(norm / 0.5)))) if norm > 0.5 else 0
    scale = 2.0**sq
    for i in range(n):
        for j in range(n):
            W[im, i, j] = W[im, i, j] / scale
            W[ie, i, j] = (1.0 if i == j else 0.0) + W[im, i, j] / 12.0
    for p in range(11, 0, -1):  # E = I + X E / p
        _matmul_top_into(W, n, r, im, ie, it)
        for i in range(r):
            for j in range(n):
                W[ie, i, j] = (1.0 if i == j else 0.0) + W[it, i, j] / p
    for _ in range(sq):
        _matmul_top_into(W, n, r, ie, ie, it)
        for i in range(r):
            for j in range(n):
                W[ie, i, j] = W[it, i, j]


@subroutine
def discrete_step_jacobians(kind, mp, nx, nu, X, U, k, dt, method, F, A, B, W):
    """F[k] = x_{k+1} (nx,), A[k] (nx, nx), B[k] (nx, nu): the discrete map of
    :func:`mpcdrive.models.discretize.discrete_step_and_jacobians` at (X[k], U[k]) and its
    exact Jacobians.

    W : work array (7, nw, nw), nw >= nx + nu for Euler and RK4, nw >= nx + nu + 1 for ``exp``.
    Works by index, without array views (each view costs a reference count in compiled code).
    RK4 for the kinematic models gets their sizes as constants: the compiler then unrolls the
    small matrix loops of :func:`_rk4_jacobians` (30 steps of P1: 12.5 us before, 7.5 us
    after; each such call compiles one more copy of that function, so only RK4 has them)."""
    if method == METHOD_RK4:
        if kind == KIND_KINEMATIC3:
            _rk4_jacobians(KIND_KINEMATIC3, mp, 3, 1, X, U, k, dt, F, A, B, W)
        elif kind == KIND_KINEMATIC4:
            _rk4_jacobians(KIND_KINEMATIC4, mp, 4, 2, X, U, k, dt, F, A, B, W)
        else:
            _rk4_jacobians(kind, mp, nx, nu, X, U, k, dt, F, A, B, W)
        return
    beta, dbeta = _step_slip(kind, mp, U, k)
    # stage state in W[_WV, 0], stage derivative in W[_WV, 1]
    for i in range(nx):
        W[_WV, 0, i] = X[k, i]
    _stage_into(kind, mp, W, U, k, beta, dbeta)
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
        expm_into(W, n, _WJX, _WJU, _WTX, nx)
        for i in range(nx):
            F[k, i] = X[k, i] + W[_WJU, i, n - 1]
            for j in range(nx):
                A[k, i, j] = W[_WJU, i, j]
            for j in range(nu):
                B[k, i, j] = W[_WJU, i, nx + j]
        return
    # Euler
    for i in range(nx):
        F[k, i] = X[k, i] + dt * W[_WV, 1, i]
        for j in range(nx):
            A[k, i, j] = (1.0 if i == j else 0.0) + dt * W[_WA, i, j]
        for j in range(nu):
            B[k, i, j] = dt * W[_WB, i, j]


@subroutine
def _rk4_jacobians(kind, mp, nx, nu, X, U, k, dt, F, A, B, W):
    """:func:`discrete_step_jacobians` by RK4 for sizes nx, nu."""
    beta, dbeta = _step_slip(kind, mp, U, k)
    for i in range(nx):
        W[_WV, 0, i] = X[k, i]
    _stage_into(kind, mp, W, U, k, beta, dbeta)
    # RK4: the stage Jacobian [J_x | J_u] in W[_WJX, :, :nx + nu], the weighted sum of the
    # stages' Jacobians (k1 + 2 k2 + 2 k3 + k4) in W[_WJU], of their derivatives in F[k]
    n = nx + nu
    for i in range(nx):
        F[k, i] = W[_WV, 1, i]
        for j in range(nx):
            W[_WJX, i, j] = W[_WA, i, j]
        for j in range(nu):
            W[_WJX, i, nx + j] = W[_WB, i, j]
        for j in range(n):
            W[_WJU, i, j] = W[_WJX, i, j]
    for stage in range(3):
        h = dt if stage == 2 else 0.5 * dt
        wgt = 1.0 if stage == 2 else 2.0
        for i in range(nx):
            W[_WV, 0, i] = X[k, i] + h * W[_WV, 1, i]
        _stage_into(kind, mp, W, U, k, beta, dbeta)
        # [J_x | J_u] <- A_s [I + h J_x | h J_u] + [0 | B_s]
        for i in range(nx):
            for j in range(nx):
                W[_WTX, i, j] = W[_WA, i, j]
            for j in range(nu):
                W[_WTX, i, nx + j] = W[_WB, i, j]
            for l in range(nx):
                ha = h * W[_WA, i, l]
                if ha != 0.0:  # continuous Jacobians are sparse
                    for j in range(n):
                        W[_WTX, i, j] += ha * W[_WJX, l, j]
        for i in range(nx):
            F[k, i] += wgt * W[_WV, 1, i]
            for j in range(n):
                W[_WJX, i, j] = W[_WTX, i, j]
                W[_WJU, i, j] += wgt * W[_WTX, i, j]
    c6 = dt / 6.0
    for i in range(nx):
        F[k, i] = X[k, i] + c6 * F[k, i]
        for j in range(nx):
            A[k, i, j] = (1.0 if i == j else 0.0) + c6 * W[_WJU, i, j]
        for j in range(nu):
            B[k, i, j] = c6 * W[_WJU, i, nx + j]


@subroutine
def rollout_into(kind, mp, nx, X, U, n, dt, method, substeps, w):
    """X[k + 1] = F(X[k], U[k]) for k < n (no Jacobians) by Euler or RK4 (``exp`` needs the
    Jacobians: :func:`discrete_step_jacobians_substeps`), each step taken as ``substeps`` equal
    steps of dt / substeps. w : work array (4, nx)."""
    h_sub = dt / substeps
    for k in range(n):
        beta, _ = _step_slip(kind, mp, U, k)
        for i in range(nx):
            w[3, i] = X[k, i]  # the state at the start of a substep
        for _sub in range(substeps):
            for i in range(nx):
                w[0, i] = w[3, i]
            for stage in range(4 if method == METHOD_RK4 else 1):
                h = 0.5 * h_sub if stage < 2 else h_sub
                _rhs_into(kind, mp, w, U, k, beta)
                wgt = 1.0 if (stage == 0 or stage == 3) else 2.0
                for i in range(nx):
                    if stage == 0:
                        w[2, i] = w[1, i]
                    else:
                        w[2, i] += wgt * w[1, i]
                    if stage < 3:
                        w[0, i] = w[3, i] + h * w[1, i]
            for i in range(nx):
                if method == METHOD_RK4:
                    w[3, i] = w[3, i] + h_sub / 6.0 * w[2, i]
                else:
                    w[3, i] = w[3, i] + h_sub * w[1, i]
        for i in range(nx):
            X[k + 1, i] = w[3, i]


@subroutine
def discrete_step_jacobians_substeps(kind, mp, nx, nu, X, U, k, dt, method, substeps, F, A, B, W, sx, sf, sa, sb):
    """:func:`discrete_step_jacobians` with the step taken as ``substeps`` equal steps of
    dt / substeps, their Jacobians chained as :func:`mpcdrive.models.discretize.discrete_step_and_jacobians`
    chains them (A = A_n ... A_1, B = A_n (... (A_2 B_1 + B_2) ...) + B_n). Work, shaped as the
    outputs, row k used: sx, sf (N, nx), sa (N, nx, nx), sb (N, nx, nu) (every call of the
    single-step kernel then has the same argument types: numba compiles it once). With one
    substep a caller calls :func:`discrete_step_jacobians` itself: each array handed on through
    one more compiled call costs reference counts, about 2 us a step at N = 30."""
    if substeps == 1:
        discrete_step_jacobians(kind, mp, nx, nu, X, U, k, dt, method, F, A, B, W)
        return
    h = dt / substeps
    discrete_step_jacobians(kind, mp, nx, nu, X, U, k, h, method, F, A, B, W)
    for _sub in range(substeps - 1):
        for i in range(nx):
            sx[k, i] = F[k, i]
        discrete_step_jacobians(kind, mp, nx, nu, sx, U, k, h, method, sf, sa, sb, W)
        # A <- A_i A, B <- A_i B + B_i (W[_WTX], W[_WTU] as scratch: free after the step)
        for i in range(nx):
            for j in range(nx):
                t = 0.0
                for l in range(nx):
                    t += sa[k, i, l] * A[k, l, j]
                W[_WTX, i, j] = t
            for j in range(nu):
                t = 0.0
                for l in range(nx):
                    t += sa[k, i, l] * B[k, l, j]
                W[_WTU, i, j] = t + sb[k, i, j]
        for i in range(nx):
            F[k, i] = sf[k, i]
            for j in range(nx):
                A[k, i, j] = W[_WTX, i, j]
            for j in range(nu):
                B[k, i, j] = W[_WTU, i, j]


@subroutine
def _inverse_tire(n, front, mp):
    """Slip angle [rad] at which the front (``front`` true) or rear axle gives the normalized force
    Fy / Fz = n (clipped below the peak): ``DynamicBicycle._inverse_tire`` for one value."""
    cs = mp[_CSF] if front else mp[_CSR]
    if mp[_PACEJKA] == 0.0:
        return n / (mp[_MU] * cs)
    C, E = mp[_C], mp[_E]
    B = cs / C
    psi = math.tan(math.asin(min(max(n / mp[_MU], -0.999), 0.999)) / C)
    if E == 0:
        return psi / B
    z = psi
    for i in range(30):  # Newton on z - E (z - atan z) = psi, as dynamic._pacejka_inverse
        step = (z - E * (z - math.atan(z)) - psi) / (1.0 - E * (1.0 - 1.0 / (1.0 + z * z)))
        z = z - step
        if i >= 2 and (abs(E) < 0.1 or abs(step) < 1e-13):
            break
    return z / B


@subroutine
def _solve_given_accel(mp, kappa, v, a, beta, delta):
    """One pass of ``DynamicBicycle.steady_state_full``'s inner solve at curvature kappa [1/m],
    speed v [m/s] and drive acceleration a [m/s^2] (which sets the axle loads), from the slip
    beta and steering delta [rad] of the last pass: (the acceleration they require, beta, delta)."""
    m, lf, lr = mp[_M], mp[_LF], mp[_LR]
    L = lf + lr
    v_eps = 0.5 * mp[_VLO]
    pacejka = mp[_PACEJKA] != 0.0
    r = v * kappa
    Fzf = m * (mp[_G] * lr - a * mp[_H]) / L
    Fzr = m * (mp[_G] * lf + a * mp[_H]) / L
    for _ in range(2):
        vx = max(v * math.cos(beta), v_eps)
        ar = _inverse_tire(m * r * vx * lf / (L * Fzr), False, mp)
        qr = math.tan(-ar) if pacejka else -ar
        beta = math.atan2(qr * vx + lr * r, vx)
    vx = max(v * math.cos(beta), v_eps)
    vy = v * math.sin(beta)
    q = (vy + lf * r) / vx
    gf = math.atan(q) if pacejka else q
    n0 = m * r * vx * lr / (L * Fzf)
    for _ in range(3):
        n = n0 / math.cos(delta)
        af = _inverse_tire(n, True, mp)
        slope = _axle_tire(af, True, mp, np)[1]
        dg = 1.0 - n * math.tan(delta) / max(slope, 1e-9)
        delta = delta - (delta - af - gf) / (dg if abs(dg) > 0.1 else 1.0)
    return n0 / math.cos(delta) * Fzf * math.sin(delta) / m - r * vy, beta, delta


# columns of the work array of dynamic_steady_states
_SD, _SB, _SA0, _SG0, _SA1, _SG1, _SAN, _SLEAD = range(8)


@subroutine
def dynamic_steady_states(mp, refs, v, n, ws):
    """``DynamicBicycle.steady_state_full`` of the points k < n at curvature refs[k, 3] [1/m] and
    speed v[k] [m/s], as one numpy batch: the secant iteration on the acceleration stops when all
    points have converged. Writes ws[k, 0:3] = (steering [rad], slip beta [rad], accel [m/s^2]);
    ws : work array (n, 8). A point with the curvature and speed of the one before copies it."""
    L = mp[_LF] + mp[_LR]
    for k in range(n):
        lead = k == 0 or refs[k, 3] != refs[k - 1, 3] or v[k] != v[k - 1]
        ws[k, _SLEAD] = 1.0 if lead else 0.0
        if lead:
            g0, beta, delta = _solve_given_accel(mp, refs[k, 3], v[k], 0.0, 0.0, L * refs[k, 3])
            ws[k, _SA0] = 0.0
            ws[k, _SG0] = g0
            ws[k, _SA1] = g0
            ws[k, _SB] = beta
            ws[k, _SD] = delta
    for _ in range(STEADY_SECANT_ITERATIONS):
        converged = True
        for k in range(n):
            if ws[k, _SLEAD] == 0.0:
                continue
            a0, g0, a1 = ws[k, _SA0], ws[k, _SG0], ws[k, _SA1]
            g1, beta, delta = _solve_given_accel(mp, refs[k, 3], v[k], a1, ws[k, _SB], ws[k, _SD])
            ws[k, _SB] = beta
            ws[k, _SD] = delta
            res0, res1 = g0 - a0, g1 - a1
            converged = converged and abs(res1) < STEADY_ACCEL_TOL_MPS2  # (NaN: not converged, as numpy's max)
            den = res1 - res0
            ws[k, _SG1] = g1
            ws[k, _SAN] = a1 - res1 * (a1 - a0) / den if abs(den) > 1e-14 else g1
        if converged:
            break
        for k in range(n):
            if ws[k, _SLEAD] != 0.0:
                ws[k, _SA0] = ws[k, _SA1]
                ws[k, _SG0] = ws[k, _SG1]
                ws[k, _SA1] = ws[k, _SAN]
    lr = mp[_LR]
    for k in range(n):
        if ws[k, _SLEAD] == 0.0:
            for i in range(3):
                ws[k, i] = ws[k - 1, i]
            continue
        kappa, delta, beta, a = refs[k, 3], ws[k, _SD], ws[k, _SB], ws[k, _SA1]
        # kinematic steady state and the blend
        beta_k = math.asin(min(max(lr * kappa, -0.999), 0.999))
        delta_k = math.atan(math.tan(beta_k) / (lr / L))
        w = _smoothstep(v[k] * math.cos(beta), mp[_VLO], mp[_VHI], np)
        ws[k, 0] = w * delta + (1 - w) * delta_k
        ws[k, 1] = w * beta + (1 - w) * beta_k
        ws[k, 2] = w * a


@subroutine
def model_references(kind, mp, refs, v, n, feedforward, xref, uref, ws):
    """``model.reference`` of the path points k < n (``refs[k] = [x m, y m, heading rad, kappa
    1/m]``, speeds ``v[k]`` [m/s]): xref[k] (nx,) for k < n, uref[k] (nu,) for k < n - 1 (the
    horizon's last point has no input). ``feedforward``: the steady-state cornering state and
    inputs, else the path pose (and speed) with zero inputs. ws : work array (n, 8) (dynamic model)."""
    for k in range(n):
        xref[k, 0] = refs[k, 0]
        xref[k, 1] = refs[k, 1]
        xref[k, 2] = refs[k, 2]
    for k in range(n - 1):
        for a in range(uref.shape[1]):
            uref[k, a] = 0.0
    if kind == KIND_DYNAMIC:
        if feedforward:
            dynamic_steady_states(mp, refs, v, n, ws)
        for k in range(n):
            xref[k, 5] = v[k] * refs[k, 3]
            if feedforward:
                beta = ws[k, 1]
                xref[k, 2] -= beta
                xref[k, 3] = v[k] * math.cos(beta)
                xref[k, 4] = v[k] * math.sin(beta)
                if k < n - 1:
                    uref[k, 0] = ws[k, 0]
                    uref[k, 1] = ws[k, 2]
            else:
                xref[k, 3] = v[k]
                xref[k, 4] = 0.0
        return
    if kind == KIND_KINEMATIC4:
        for k in range(n):
            xref[k, 3] = v[k]
    if feedforward:
        steer, slip = 0.0, 0.0
        for k in range(n):
            if k == 0 or refs[k, 3] != refs[k - 1, 3]:  # same curvature, same steady state
                steer, slip = _ss(refs[k, 3], mp[0], mp[1], np)
            if k < n - 1:
                uref[k, 0] = steer
            xref[k, 2] -= slip


def _refresh_cache():
    from .. import _jitcache
    from . import kinematic

    # functions here inline the equations of kinematic.py and dynamic.py; numba only watches this file
    _jitcache.refresh(discrete_step_jacobians, [kinematic.__file__, dynamic.__file__])


_refresh_cache()
