"""The compiled step of :class:`~mpcdrive.control.fast.CompiledLtvMpc`.

:func:`_control_step` is one control step (or one SQP iteration of it) in one numba call:
projection onto the path, horizon references (constant speed or a speed profile), the compiled
obstacle cost and detour (:mod:`mpcdrive.control.fast_obstacles`), linearization points and the
discrete model, the road's rows at the linearization trajectory, then condensing onto the
inputs (Hessian, gradient, constraint rows ``C z >= b``) and the solve, which it hands to
:mod:`mpcdrive.solvers`: the Riccati shortcut and the soft-row solve of
:mod:`mpcdrive.solvers.condensed`, the dual active-set kernel of
:mod:`mpcdrive.solvers.dense_qp`. It works in one float buffer (``wbuf``) and one integer
buffer (``ibuf``) that :class:`~mpcdrive.control.fast.CompiledLtvMpc` allocates at construction;
the constants of :mod:`mpcdrive.control.fast_layout` name their parts (``_I_*``: integer
parameters, ``_F_*``: float parameters, ``_W_*``: the arrays of ``wbuf``, ``_OB_*``: the
columns of the obstacle table).

Compiled functions use numba's on-disk cache; numba keys it to this file only, so the cache
is dropped (by :mod:`mpcdrive._jitcache`) when a file whose code the step links in changes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..models.compiled import METHOD_EXP, discrete_step_jacobians, model_references, model_speed, rollout_into
from ..ocp.friction import friction_input_bounds
from ..paths.compiled import path_eval, path_project, wrap_angle
from ..paths.profile_compiled import profile_arc_lengths, profile_speed
from ..scene.road import horizon_bounds, reach_first_step
from ..solvers.condensed import condensed_solve

# the layout of the compiled step's buffers
from .fast_layout import _I_MODEL, _I_NX, _I_NU, _I_N, _I_PATH, _I_LIN, _I_METHOD, _I_HORIZON, _I_FF, _I_LANE, _I_MCONST
from .fast_layout import _I_RATE0, _I_MAXITER, _I_GAMMA, _I_NZ, _I_RICCATI, _I_MQ, _I_OFORM, _I_NOBS, _I_OMAX, _I_DETOUR
from .fast_layout import _I_OROWS, _I_PROFILE, _I_ACCEL, _I_STEER, _I_FRICTION, _I_NSEL, _NIP
from .fast_layout import _OBS_NONE, MODE_SHIFTED_PLAN, MODE_ITERATE, STAGE_LINEARIZE, STAGE_COST
from .fast_layout import STAGE_ALL
from .fast_layout import _W_FP, _W_MP, _W_BND, _W_GEO, _W_WQ, _W_RM, _W_RC, _W_TABS, _W_TABXY, _W_TABH, _W_TABK, _W_C
from .fast_layout import _W_B, _W_REFS, _W_XREF, _W_UREF, _W_XBAR, _W_UBAR, _W_F, _W_A, _W_BD, _W_CD, _W_LANEN, _W_LANEB
from .fast_layout import _W_XF, _W_P, _W_LAM, _W_VB, _W_S, _W_T2, _W_GAM, _W_H, _W_G, _W_Z, _W_L, _W_J, _W_RQ, _W_D
from .fast_layout import _W_ZDIR, _W_R, _W_UQ, _W_SQ, _W_ROWN, _W_LAMQ, _W_DW, _W_KG, _W_KF, _W_PA, _W_MG, _W_GG, _W_QV
from .fast_layout import _W_WE, _W_QT, _W_OBS, _W_ODIST, _W_OPROJ, _W_SARR, _W_EREF, _W_ROWA, _W_ROWB, _W_LLO, _W_LHI
from .fast_layout import _W_XLIN, _W_GSUM, _W_PROF, _W_VARR, _W_REFW, _W_RDS, _W_RDL, _W_RDR, _W_LDLO, _W_LDHI, _W_ULO
from .fast_layout import _W_UHI, _W_VLIN, _W_SLIN, _W_RLIN, _NW
from .fast_layout import _F_DT, _F_VREF, _F_HSTEP, _F_WINDOW, _F_RMARGIN, _F_SLACK2, _F_SLACK1, _F_TOL, _F_HW, _F_HL
from .fast_layout import _F_OSLACK2, _F_OSLACK1, _F_BOFF, _F_RPERIOD, _F_FRIC, _F_WHEELBASE
from .fast_layout import _O_S, _O_EY, _O_EPSI, _O_ITER
from .fast_obstacles import _detour, _obstacle_cost, _select_obstacles, _shift_references

_TWO_PI = 2.0 * math.pi

#: status code of a non-finite measured state (raised as ValueError by
#: :meth:`CompiledLtvMpc.step <mpcdrive.control.fast.CompiledLtvMpc.step>`)
_BAD_STATE = 4


@njit(cache=True, inline="always")
def _v1(w, fo, i):
    return w[fo[i] : fo[i + 1]]


@njit(cache=True, inline="always")
def _v2(w, fo, fs, i):
    return w[fo[i] : fo[i + 1]].reshape((fs[3 * i], fs[3 * i + 1]))


@njit(cache=True, inline="always")
def _v3(w, fo, fs, i):
    return w[fo[i] : fo[i + 1]].reshape((fs[3 * i], fs[3 * i + 1], fs[3 * i + 2]))


@njit(cache=True, inline="always")
def _place_references(
    pkind, geo, tab_s, tab_xy, tab_h, tab_k, mkind, mp, N, ff, yaw, s_arr, v_arr, refs, xref, uref, rw
):
    """The horizon references at arc lengths ``s_arr`` (N+1,) [m] driven at ``v_arr`` [m/s]:
    the path points ``refs`` (x, y, heading unwrapped next to the car's ``yaw``, curvature) and the
    model's state and input references (``model.reference``: path pose, speed states, the
    steady-state feedforward with ``ff == 1``)."""
    for k in range(N + 1):
        px, py, hk, kap = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s_arr[k])
        refs[k, 0] = px
        refs[k, 1] = py
        refs[k, 2] = hk
        refs[k, 3] = kap
    shift = _TWO_PI * np.rint((yaw - refs[0, 2]) / _TWO_PI)
    for k in range(N + 1):
        refs[k, 2] += shift
    model_references(mkind, mp, refs, v_arr, N + 1, ff == 1, xref, uref, rw)


@njit(cache=True)
def follow_references_into(yaw, s_arr, v_arr, wbuf, ibuf):
    """Between the two stages of a step: the references of car following
    (:func:`~mpcdrive.ocp.follow.follow_references`: arc lengths ``s_arr`` (N+1,) [m] and speeds
    ``v_arr`` [m/s] behind a moving stop line) replace the step's, their speed changes the
    acceleration reference (as ``LtvMpc`` does); the horizon arc lengths the rows were built on
    stay."""
    ip = ibuf[:_NIP]
    fo = ibuf[_NIP : _NIP + _NW + 1]
    fs = ibuf[_NIP + _NW + 1 : _NIP + 4 * _NW + 1]
    mp, geo, fp = _v1(wbuf, fo, _W_MP), _v1(wbuf, fo, _W_GEO), _v1(wbuf, fo, _W_FP)
    tab_s, tab_xy = _v1(wbuf, fo, _W_TABS), _v2(wbuf, fo, fs, _W_TABXY)
    tab_h, tab_k = _v1(wbuf, fo, _W_TABH), _v1(wbuf, fo, _W_TABK)
    refs, xref, uref = _v2(wbuf, fo, fs, _W_REFS), _v2(wbuf, fo, fs, _W_XREF), _v2(wbuf, fo, fs, _W_UREF)
    N = ip[_I_N]
    _place_references(
        ip[_I_PATH], geo, tab_s, tab_xy, tab_h, tab_k, ip[_I_MODEL], mp, N, ip[_I_FF], yaw, s_arr, v_arr, refs, xref,
        uref, _v2(wbuf, fo, fs, _W_REFW),
    )  # fmt: skip
    if ip[_I_ACCEL] >= 0:
        for k in range(N):
            uref[k, ip[_I_ACCEL]] += (v_arr[k + 1] - v_arr[k]) / fp[_F_DT]


@njit(cache=True)
def _stage_costs(
    N, nx, ip, fp, lane, Wq, We, qt, xref, obs, oproj, osel, t_s, dt, Xbar, F, pkind, geo, tab_s, tab_xy, tab_h,
    tab_k, lane_n, lane_b, lane_lo, lane_hi, lane_dlo, lane_dhi, rlin, Xlin,
):  # fmt: skip
    """The stage costs and road rows of a step, from its references and linearization: the state
    cost of x_1..x_N as ``x' We_k x - 2 qt_k' x`` (the weights plus the obstacle cost's convex
    model at the linearization trajectory), the road rows' normals and offsets where they are
    linearized (``rlin``), and the first step's bounds made reachable. With these the stage QP
    is complete in the buffers."""
    for k in range(N):
        for i in range(nx):
            t = 0.0
            for j in range(nx):
                t += Wq[k, i, j] * xref[k + 1, j]
            qt[k, i] = t
    if ip[_I_OFORM] != _OBS_NONE:
        for k in range(N):
            for i in range(nx):
                for j in range(nx):
                    We[k, i, j] = Wq[k, i, j]
        _obstacle_cost(
            ip[_I_OFORM], ip[_I_NSEL], osel, obs, oproj, fp, t_s, dt, Xbar, F, N, pkind, geo, tab_s, tab_xy, tab_h,
            tab_k, We, qt,
        )  # fmt: skip
    if lane == 1:
        for k in range(N):
            yaw = rlin[k + 1, 2]
            lane_n[k, 0] = -math.sin(yaw)
            lane_n[k, 1] = math.cos(yaw)
            lane_b[k] = lane_n[k, 0] * rlin[k + 1, 0] + lane_n[k, 1] * rlin[k + 1, 1]
        # the first step's bounds hold where the model puts the car with the first input of the
        # linearization (F[0] = f(x, Ubar[0])): reachable, so never bought with slack
        reach_first_step(
            lane_lo,
            lane_hi,
            lane_dlo,
            lane_dhi,
            lane_n[0, 0] * F[0, 0] + lane_n[0, 1] * F[0, 1] - lane_b[0],
            F[0, 2] - Xlin[1, 2],
        )


@njit(cache=True)
def _control_step(x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, sides, wbuf, ibuf, out, info):
    """One control step (or one SQP iteration of it) at time ``t_s`` [s]; returns a status code
    (0 ok, 1 infeasible, 2 max_iter, 3 failed, 4 non-finite state). ``mode`` says what (Xw, Uw)
    is (``MODE_*``: no plan, the previous step's plan, the current SQP iterate). ``stage``
    (``STAGE_*``): the whole step; or only up to the linearization trajectory (written to the
    ``_W_XLIN`` buffer, horizon arc lengths in ``_W_SARR``), after which the caller writes the
    obstacle rows, lane bounds and detour offsets of the step and runs the rest (``STAGE_SOLVE``);
    or, of the rest, only the stage costs and road rows (``STAGE_COST``: the stage QP is then
    complete in the buffers, for another solver). A solve writes
    ``out = [u (nu), X ((N+1) nx), U (N nu), xref ((N+1) nx)]`` and
    ``info = [s, e_y, e_psi, iterations]``. ``sides`` : passing side per obstacle (``_SIDE_*``),
    read and updated by the detour. ``wbuf`` holds every float array (constants and work),
    ``ibuf`` the integer parameters, the layout of ``wbuf`` and the active-set work."""
    ip = ibuf[:_NIP]
    fo = ibuf[_NIP : _NIP + _NW + 1]
    fs = ibuf[_NIP + _NW + 1 : _NIP + 4 * _NW + 1]
    a0 = _NIP + 4 * _NW + 1
    active = ibuf[a0 : a0 + ip[_I_NZ]]
    isact = ibuf[a0 + ip[_I_NZ] : a0 + ip[_I_NZ] + ip[_I_MQ]]
    rowcol = ibuf[a0 + ip[_I_NZ] + ip[_I_MQ] : a0 + ip[_I_NZ] + 2 * ip[_I_MQ]]
    a1 = a0 + ip[_I_NZ] + 2 * ip[_I_MQ]
    kpos = ibuf[a1 : a1 + 2 * ip[_I_N]]
    a2 = a1 + 2 * ip[_I_N] + max(ip[_I_NOBS], 1)
    osel = ibuf[a1 + 2 * ip[_I_N] : a2]
    rgrp = ibuf[a2 : a2 + ip[_I_MQ]]
    fp, mp, bnd, geo = _v1(wbuf, fo, _W_FP), _v1(wbuf, fo, _W_MP), _v1(wbuf, fo, _W_BND), _v1(wbuf, fo, _W_GEO)
    Wq, Rm, Rc = _v3(wbuf, fo, fs, _W_WQ), _v2(wbuf, fo, fs, _W_RM), _v2(wbuf, fo, fs, _W_RC)
    tab_s, tab_xy = _v1(wbuf, fo, _W_TABS), _v2(wbuf, fo, fs, _W_TABXY)
    tab_h, tab_k = _v1(wbuf, fo, _W_TABH), _v1(wbuf, fo, _W_TABK)
    C, b = _v2(wbuf, fo, fs, _W_C), _v1(wbuf, fo, _W_B)
    refs, xref, uref = _v2(wbuf, fo, fs, _W_REFS), _v2(wbuf, fo, fs, _W_XREF), _v2(wbuf, fo, fs, _W_UREF)
    Xbar, Ubar, F = _v2(wbuf, fo, fs, _W_XBAR), _v2(wbuf, fo, fs, _W_UBAR), _v2(wbuf, fo, fs, _W_F)
    A, B, c = _v3(wbuf, fo, fs, _W_A), _v3(wbuf, fo, fs, _W_BD), _v2(wbuf, fo, fs, _W_CD)
    lane_n, lane_b = _v2(wbuf, fo, fs, _W_LANEN), _v1(wbuf, fo, _W_LANEB)
    xf, P, lam = _v2(wbuf, fo, fs, _W_XF), _v3(wbuf, fo, fs, _W_P), _v2(wbuf, fo, fs, _W_LAM)
    Vb, S, T2, Gam = (
        _v3(wbuf, fo, fs, _W_VB),
        _v3(wbuf, fo, fs, _W_S),
        _v2(wbuf, fo, fs, _W_T2),
        _v3(wbuf, fo, fs, _W_GAM),
    )
    H, g, z = _v2(wbuf, fo, fs, _W_H), _v1(wbuf, fo, _W_G), _v1(wbuf, fo, _W_Z)
    L, J, Rq = _v2(wbuf, fo, fs, _W_L), _v2(wbuf, fo, fs, _W_J), _v2(wbuf, fo, fs, _W_RQ)
    d, zdir, r, uq = _v1(wbuf, fo, _W_D), _v1(wbuf, fo, _W_ZDIR), _v1(wbuf, fo, _W_R), _v1(wbuf, fo, _W_UQ)
    sq, rown, lamq = _v1(wbuf, fo, _W_SQ), _v1(wbuf, fo, _W_ROWN), _v1(wbuf, fo, _W_LAMQ)
    dw, Kg, kf = _v3(wbuf, fo, fs, _W_DW), _v3(wbuf, fo, fs, _W_KG), _v2(wbuf, fo, fs, _W_KF)
    PA, Mg, Gg, qv = _v2(wbuf, fo, fs, _W_PA), _v2(wbuf, fo, fs, _W_MG), _v2(wbuf, fo, fs, _W_GG), _v1(wbuf, fo, _W_QV)
    We, qt = _v3(wbuf, fo, fs, _W_WE), _v2(wbuf, fo, fs, _W_QT)
    obs, oproj, s_arr = _v2(wbuf, fo, fs, _W_OBS), _v2(wbuf, fo, fs, _W_OPROJ), _v1(wbuf, fo, _W_SARR)
    lane_lo, lane_hi = _v1(wbuf, fo, _W_LLO), _v1(wbuf, fo, _W_LHI)
    lane_dlo, lane_dhi = _v1(wbuf, fo, _W_LDLO), _v1(wbuf, fo, _W_LDHI)
    ulo, uhi = _v2(wbuf, fo, fs, _W_ULO), _v2(wbuf, fo, fs, _W_UHI)  # per-stage input bounds
    rowa, rowb, nrow = _v3(wbuf, fo, fs, _W_ROWA), _v2(wbuf, fo, fs, _W_ROWB), ip[_I_OROWS]
    prof, v_arr = _v1(wbuf, fo, _W_PROF), _v1(wbuf, fo, _W_VARR)
    mkind, nx, nu, N = ip[_I_MODEL], ip[_I_NX], ip[_I_NU], ip[_I_N]
    pkind, lin, meth, hmode, ff, lane = ip[_I_PATH], ip[_I_LIN], ip[_I_METHOD], ip[_I_HORIZON], ip[_I_FF], ip[_I_LANE]
    nz = ip[_I_NZ]
    dt, v_ref = fp[_F_DT], fp[_F_VREF]
    u_min = bnd[0:nu]
    u_max = bnd[nu : 2 * nu]
    dmax = bnd[2 * nu : 3 * nu]
    x_min = bnd[3 * nu : 3 * nu + nx]
    x_max = bnd[3 * nu + nx : 3 * nu + 2 * nx]
    for i in range(nx):
        if not math.isfinite(x[i]):
            return _BAD_STATE

    if stage == STAGE_LINEARIZE or stage == STAGE_ALL:
        ip[_I_NSEL] = 0
        # -- projection and horizon references -------------------------------------------------
        s0, e_y = path_project(pkind, geo, tab_s, tab_xy, s_guess, fp[_F_WINDOW], x[0], x[1])
        h0 = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s0)[2]
        info[_O_S] = s0
        info[_O_EY] = e_y
        info[_O_EPSI] = wrap_angle(x[2] - h0)
        info[_O_ITER] = 0.0
        # horizon arc lengths and reference speeds: as the profile moves in time, or the constant
        # reference speed (or the paper's fixed step)
        has_prof = ip[_I_PROFILE] == 1
        if has_prof:
            profile_arc_lengths(prof, s0, dt, s_arr)
        acc = 0.0
        vdt = abs(v_ref) * dt
        for k in range(N + 1):
            if has_prof:
                v_arr[k] = profile_speed(prof, s_arr[k])
            else:
                s_arr[k] = s0 + fp[_F_HSTEP] * k if hmode == 1 else s0 + acc
                acc += vdt
                v_arr[k] = v_ref
        _place_references(
            pkind, geo, tab_s, tab_xy, tab_h, tab_k, mkind, mp, N, ff, x[2], s_arr, v_arr, refs, xref, uref,
            _v2(wbuf, fo, fs, _W_REFW),
        )  # fmt: skip
        if has_prof and ip[_I_ACCEL] >= 0:  # the profile's speed changes as acceleration reference
            for k in range(N):
                uref[k, ip[_I_ACCEL]] += (v_arr[k + 1] - v_arr[k]) / dt

        if ip[_I_OFORM] != _OBS_NONE:
            ip[_I_NSEL] = _select_obstacles(
                ip[_I_NOBS],
                ip[_I_OMAX],
                obs,
                _v1(wbuf, fo, _W_ODIST),
                oproj,
                osel,
                fp,
                t_s,
                x,
                s0,
                pkind,
                geo,
                tab_s,
                tab_xy,
                tab_h,
                tab_k,
            )
            if ip[_I_DETOUR] == 1:
                _detour(
                    ip[_I_NSEL],
                    osel,
                    obs,
                    oproj,
                    sides,
                    fp,
                    N,
                    s_arr,
                    refs,
                    xref,
                    _v1(wbuf, fo, _W_EREF),
                    lane,
                    _v1(wbuf, fo, _W_RDS),
                    _v1(wbuf, fo, _W_RDL),
                    _v1(wbuf, fo, _W_RDR),
                )

        # -- linearization points and discrete model ---------------------------------------------
        if mode == MODE_ITERATE:
            for i in range(nx):
                Xbar[0, i] = x[i]
            for k in range(1, N):
                for i in range(nx):
                    Xbar[k, i] = Xw[k, i]
            for k in range(N):
                for a in range(nu):
                    Ubar[k, a] = Uw[k, a]
        elif lin == 1:
            for k in range(N):
                for i in range(nx):
                    Xbar[k, i] = x[i]
                for a in range(nu):
                    Ubar[k, a] = u_prev[a]
        elif mode == MODE_SHIFTED_PLAN:
            sh = _TWO_PI * np.rint((x[2] - Xw[1, 2]) / _TWO_PI)
            for i in range(nx):
                Xbar[0, i] = x[i]
            for k in range(1, N):
                for i in range(nx):
                    Xbar[k, i] = Xw[k + 1, i]
                Xbar[k, 2] += sh
            for k in range(N):
                for a in range(nu):
                    Ubar[k, a] = Uw[min(k + 1, N - 1), a]
        else:
            for k in range(N):
                for a in range(nu):
                    Ubar[k, a] = uref[k, a]
            for i in range(nx):
                Xbar[0, i] = x[i]
            if meth == METHOD_EXP:
                for k in range(N - 1):
                    discrete_step_jacobians(mkind, mp, nx, nu, Xbar, Ubar, k, dt, meth, F, A, B, dw)
                    for i in range(nx):
                        Xbar[k + 1, i] = F[k, i]
            else:
                rollout_into(mkind, mp, nx, Xbar, Ubar, N - 1, dt, meth, dw[0])
        kmax = 1 if lin == 1 and mode != MODE_ITERATE else N
        for k in range(kmax):
            discrete_step_jacobians(mkind, mp, nx, nu, Xbar, Ubar, k, dt, meth, F, A, B, dw)
        for k in range(kmax, N):
            for i in range(nx):
                F[k, i] = F[0, i]
                for j in range(nx):
                    A[k, i, j] = A[0, i, j]
                for a in range(nu):
                    B[k, i, a] = B[0, i, a]
        finite = True
        for k in range(N):
            for i in range(nx):
                t = F[k, i]
                for j in range(nx):
                    t -= A[k, i, j] * Xbar[k, j]
                for j in range(nu):
                    t -= B[k, i, j] * Ubar[k, j]
                c[k, i] = t
                finite = finite and math.isfinite(t) and math.isfinite(xref[k + 1, i])
            for j in range(nu):
                finite = finite and math.isfinite(uref[k, j])
        if not finite:
            return 3
        Xlin = _v2(wbuf, fo, fs, _W_XLIN)
        for k in range(N):
            for i in range(nx):
                Xlin[k, i] = Xbar[k, i]
        for i in range(nx):
            Xlin[N, i] = F[N - 1, i]
        if ip[_I_FRICTION] == 1:  # the friction circle as per-stage input bounds (ocp.friction)
            vlin = _v1(wbuf, fo, _W_VLIN)
            for k in range(N + 1):
                vlin[k] = model_speed(mkind, mp, Xlin[k])
            friction_input_bounds(
                N,
                vlin,
                Ubar,
                ip[_I_STEER],
                ip[_I_ACCEL],
                fp[_F_WHEELBASE],
                fp[_F_FRIC],
                u_min,
                u_max,
                dmax,
                u_prev,
                ulo,
                uhi,
            )
            input_bound_rows(N, nu, u_min, u_max, ulo, uhi, C, b, False)
        if lane == 1:
            # the body inside the road where the linearization trajectory has the car, in its yaw
            # (scene.road; as LtvMpc.prepare: its arc lengths, not the references')
            s_lin, rlin = _v1(wbuf, fo, _W_SLIN), _v2(wbuf, fo, fs, _W_RLIN)
            s_lin[0] = s0
            for k in range(N):
                s_lin[k + 1] = s_lin[k] + math.hypot(Xlin[k + 1, 0] - Xlin[k, 0], Xlin[k + 1, 1] - Xlin[k, 1])
            for k in range(N + 1):
                px, py, ph, pk = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s_lin[k])
                rlin[k, 0], rlin[k, 1], rlin[k, 2], rlin[k, 3] = px, py, ph, pk
            horizon_bounds(
                _v1(wbuf, fo, _W_RDS),
                _v1(wbuf, fo, _W_RDL),
                _v1(wbuf, fo, _W_RDR),
                fp[_F_RPERIOD],
                s_lin[1:],
                rlin[1:, 2],
                rlin[1:, 3],
                Xlin[1:, 2],
                fp[_F_HL],
                fp[_F_HW],
                fp[_F_BOFF],
                fp[_F_RMARGIN],
                lane_lo,
                lane_hi,
                lane_dlo,
                lane_dhi,
            )
        if stage == STAGE_LINEARIZE:
            return 0
    else:  # the detour of the rows, or a lateral reference, written between the stages
        e_ref = _v1(wbuf, fo, _W_EREF)
        for k in range(N + 1):
            if e_ref[k] != 0.0:
                _shift_references(N, s_arr, refs, e_ref, xref)
                break
    _stage_costs(N, nx, ip, fp, lane, Wq, We, qt, xref, obs, oproj, osel, t_s, dt, Xbar, F, pkind, geo,
                 tab_s, tab_xy, tab_h, tab_k, lane_n, lane_b, lane_lo, lane_hi, lane_dlo, lane_dhi,
                 _v2(wbuf, fo, fs, _W_RLIN), _v2(wbuf, fo, fs, _W_XLIN))  # fmt: skip
    if stage == STAGE_COST:
        return 0
    code, iters = condensed_solve(
        N, nx, nu, nz, x, u_prev, A, B, c, We, qt, Rm, Rc, uref, ulo, uhi, dmax, x_min, x_max, lane, lane_n, lane_b,
        lane_lo, lane_hi, lane_dlo, lane_dhi, _v2(wbuf, fo, fs, _W_XLIN), nrow, rowa, rowb, ip[_I_RICCATI] == 1,
        ip[_I_GAMMA] == 1, ip[_I_MCONST], ip[_I_RATE0], C, b, rowcol, rgrp, kpos, fp[_F_SLACK2], fp[_F_SLACK1],
        fp[_F_OSLACK2], fp[_F_OSLACK1], fp[_F_TOL], ip[_I_MAXITER], xf, P, lam, Vb, S, T2, Gam, H, g, z, L, J, Rq, d,
        zdir, r, uq, sq, rown, lamq, active, isact, _v1(wbuf, fo, _W_GSUM), Kg, kf, PA, Mg, Gg, qv,
    )  # fmt: skip
    info[_O_ITER] = iters
    if code != 0:
        return code
    _write_plan(N, nx, nu, x, z, A, B, c, xref, ulo, uhi, out)
    return 0


@njit(cache=True)
def input_bound_rows(N, nu, u_min, u_max, lo, hi, C, b, write_rows):
    """The input-bound rows of ``C z >= b``, which lead the constant rows: stage by stage, input
    by input, ``u_ka >= lo[k, a]`` then ``-u_ka >= -hi[k, a]``, each only where the problem's bound
    (``u_min``, ``u_max``) is finite. Writes their ``b`` (and, with ``write_rows``, their unit
    entries of C); returns how many there are."""
    r = 0
    for k in range(N):
        for a in range(nu):
            for upper in (False, True):
                if not math.isfinite(u_max[a] if upper else u_min[a]):
                    continue
                if write_rows:
                    C[r, k * nu + a] = -1.0 if upper else 1.0
                b[r] = -hi[k, a] if upper else lo[k, a]
                r += 1
    return r


@njit(cache=True)
def _write_plan(N, nx, nu, x, z, A, B, c, xref, ulo, uhi, out):
    """out = [u (nu) = U_0 clipped to its stage's input bounds ulo[0], uhi[0], X ((N+1) nx) rolled out through the
    linearized model, U (N nu), xref ((N+1) nx)]."""
    oX = nu
    oU = oX + (N + 1) * nx
    oR = oU + N * nu
    for i in range(nx):
        out[oX + i] = x[i]
    for k in range(N):
        for i in range(nx):
            t = c[k, i]
            for j in range(nx):
                t += A[k, i, j] * out[oX + k * nx + j]
            for a in range(nu):
                t += B[k, i, a] * z[k * nu + a]
            out[oX + (k + 1) * nx + i] = t
    for j in range(N * nu):
        out[oU + j] = z[j]
    for k in range(N + 1):
        for i in range(nx):
            out[oR + k * nx + i] = xref[k, i]
    for a in range(nu):
        out[a] = min(max(z[a], ulo[0, a]), uhi[0, a])


# numba caches _control_step keyed to this file only; it inlines code (and constants) from these
from .. import _jitcache  # noqa: E402
from . import fast_layout as _fast_layout, fast_obstacles as _fast_obstacles  # noqa: E402
from ..models import compiled as _models_compiled, dynamic as _dynamic, kinematic as _kinematic  # noqa: E402
from ..ocp import friction as _friction  # noqa: E402
from ..paths import compiled as _paths_compiled, profile_compiled as _profile_compiled  # noqa: E402
from ..scene import road as _road  # noqa: E402
from ..solvers import condensed as _condensed, dense_qp as _dense_qp  # noqa: E402

_jitcache.refresh(
    _control_step,
    [
        m.__file__
        for m in (
            _kinematic,
            _dynamic,
            _models_compiled,
            _paths_compiled,
            _profile_compiled,
            _road,
            _friction,
            _dense_qp,
            _condensed,
            _fast_layout,
            _fast_obstacles,
        )
        if m.__file__ is not None
    ],
)
