"""The compiled step assembly: from the measured state to the step's stage QP.

One step of the LTV-MPC is assembled in two compiled calls on a :class:`StepAssembly` (what the
controller describes once: model, path, road, weights, obstacle cost, settings, and its work
arrays) and writes a :class:`~mpcdrive.ocp.stage_qp.StageQp`:

* :func:`linearize`: projection onto the path, horizon references (constant speed or a speed
  profile), the obstacle selection and the compiled detour of the cost formulations, the
  linearization trajectory (the shifted previous plan, an SQP iterate, the paper's frozen point,
  or a roll-out of the references), the discrete affine model, the friction circle's per-stage
  input bounds, and the road's bounds of the body at the linearization trajectory (the rule of
  :mod:`mpcdrive.scene.road`).
* :func:`stage_costs`: the references shifted by a detour written in between (obstacle rows of
  ``ocp.avoidance``, a lateral reference), the stage costs with the obstacle cost's convex
  model (:mod:`mpcdrive.ocp.obstacle_cost_compiled`) and the road rows.

Between the two, Python code may write the obstacle rows and narrowed road bounds of
``ocp.avoidance`` into the stage QP, the detour offsets into ``e_ref``, and car-following
references (:func:`follow_references_into`). A solver then takes the stage QP (see
:mod:`mpcdrive.solvers`). Compiled with numba's on-disk cache; numba keys it to this file only,
so the cache is dropped (by :mod:`mpcdrive._jitcache`) when a file whose code it links in
changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .._subroutine import subroutine
from .._structs import define_struct, to_struct
from ..models.compiled import METHOD_EXP, discrete_step_jacobians, discrete_step_jacobians_substeps, model_references
from ..models.compiled import model_speed, rollout_into
from ..paths.compiled import path_eval, path_project, wrap_angle
from ..paths.profile_compiled import profile_arc_lengths, profile_speed
from ..scene.road import horizon_bounds, reach_first_step
from .friction import friction_input_bounds
from .obstacle_cost_compiled import detour, obstacle_cost, select_obstacles, shift_references

_TWO_PI = 2.0 * math.pi

#: linearization modes of a step: no plan (roll out the references), the previous step's plan
#: shifted by one step (real-time iteration), the current SQP iterate as it is, no plan but
#: inputs to roll out (the references a longitudinal plan handed in gives: the step's own, from
#: the profile, are placed before that plan is)
MODE_NO_PLAN, MODE_SHIFTED_PLAN, MODE_ITERATE, MODE_ROLLOUT = 0, 1, 2, 3
#: outputs of :func:`linearize` in ``info``: arc length [m], lateral and heading errors [m, rad]
#: of the measured state, iterations of the solve
INFO_S, INFO_EY, INFO_EPSI, INFO_ITER = range(4)


@dataclass(frozen=True, eq=False)
class StepAssembly:
    """What the compiled assembly needs of a controller, described once.

    Sizes ``N``, ``nx``, ``nu``; the model (``model`` code and parameters ``mp`` of
    :mod:`mpcdrive.models.compiled`, discretization ``method``, step ``dt`` [s] taken as
    ``substeps`` equal steps in the prediction); the path
    (``path`` code, ``geo`` and tables of :mod:`mpcdrive.paths.compiled`; projection window
    [m]); the horizon (``paper_horizon``: a fixed ``horizon_step`` [m] per step; else at the
    reference speed ``v_ref`` [m/s], or the speed profile ``profile`` with ``has_profile``);
    ``feedforward`` (curvature feedforward); ``paper_linearization`` (the frozen point); the
    state weights ``Wq`` (N, nx, nx); ``accel``, ``steer``: input indices (-1: none); the friction
    circle (``friction``, its acceleration [m/s^2] and the ``wheelbase`` [m]); the road (``lane``;
    its tables ``road_s``, ``road_left``, ``road_right`` [m], ``road_period`` [m], the body kept
    ``road_margin[0]`` [m] inside (an array: ``set_road`` changes it in place); the body's
    ``half_width``, ``half_length`` and ``body_offset``
    [m]); the obstacle cost (``obstacle_form`` ``OBS_*``, the obstacles in the ``ob_*`` arrays of
    :func:`~mpcdrive.ocp.obstacle_cost_compiled.cost_obstacle_arrays`, at most ``omax``
    considered, within ``obstacle_influence`` [m]; weight, epsilon [m^2], sigma [m]; the
    compiled ``detour`` with its margin and ramp [m]). The rest is work: references
    ``refs`` (N+1, 4: x, y, heading, curvature), arc lengths ``s_arr`` and speeds ``v_arr``
    (N+1,), those of car following (``follow_s``, ``follow_v``, written by the caller), the
    linearization ``Xbar``, ``Ubar``, ``F`` = f(Xbar, Ubar), the detour ``e_ref``,
    the selected obstacles ``osel`` (``nsel`` of them), their distances and Frenet positions,
    the road's arc lengths and path points at the linearization trajectory, the discretization's
    work (``dw``; ``sub_*`` for substeps)."""

    N: int
    nx: int
    nu: int
    model: int
    mp: np.ndarray
    method: int
    substeps: int
    dt: float
    path: int
    geo: np.ndarray
    tab_s: np.ndarray
    tab_xy: np.ndarray
    tab_h: np.ndarray
    tab_k: np.ndarray
    window: float
    paper_horizon: bool
    horizon_step: float
    v_ref: float
    has_profile: bool
    profile: np.ndarray
    feedforward: bool
    paper_linearization: bool
    Wq: np.ndarray
    accel: int
    steer: int
    friction: bool
    friction_accel: float
    wheelbase: float
    lane: bool
    road_s: np.ndarray
    road_left: np.ndarray
    road_right: np.ndarray
    road_period: float
    road_margin: np.ndarray
    half_width: float
    half_length: float
    body_offset: float
    obstacle_form: int
    omax: int
    ob_pose: np.ndarray
    ob_vel: np.ndarray
    ob_tr_lo: np.ndarray
    ob_tr_hi: np.ndarray
    ob_tr_t: np.ndarray
    ob_tr_d: np.ndarray
    ob_bound_r: np.ndarray
    ob_life: np.ndarray
    ob_has_life: np.ndarray
    ob_shape: np.ndarray
    ob_radius: np.ndarray
    ob_verts: np.ndarray
    ob_nverts: np.ndarray
    obstacle_influence: float
    obstacle_weight: float
    obstacle_epsilon: float
    obstacle_sigma_x: float
    obstacle_sigma_y: float
    detour: bool
    obstacle_margin: float
    detour_ramp: float
    nsel: int
    osel: np.ndarray
    odist: np.ndarray
    oproj: np.ndarray
    refs: np.ndarray
    refw: np.ndarray
    s_arr: np.ndarray
    v_arr: np.ndarray
    follow_s: np.ndarray
    follow_v: np.ndarray
    e_ref: np.ndarray
    Xbar: np.ndarray
    Ubar: np.ndarray
    F: np.ndarray
    dw: np.ndarray
    sub_x: np.ndarray
    sub_f: np.ndarray
    sub_a: np.ndarray
    sub_b: np.ndarray
    vlin: np.ndarray
    s_lin: np.ndarray
    rlin: np.ndarray

    def struct(self):
        """The compiled struct of this assembly (the same arrays)."""
        return to_struct(self, _build_step_assembly)


@subroutine
def _place_references(kind, asm, qp, yaw, s_arr, v_arr):
    """The horizon references at arc lengths ``s_arr`` (N+1,) [m] driven at ``v_arr`` [m/s] for
    the model ``kind`` (``KIND_*`` of :mod:`mpcdrive.models.compiled`, ``asm.model``):
    the path points ``asm.refs`` (x, y, heading unwrapped next to the car's ``yaw``, curvature)
    and the model's state and input references ``qp.xref``, ``qp.uref`` (``model.reference``:
    path pose, speed states, the steady-state feedforward)."""
    refs, N = asm.refs, asm.N
    # the struct's arrays read once, out of the loop (each read costs a reference count)
    pkind, geo, tab_s, tab_xy, tab_h, tab_k = asm.path, asm.geo, asm.tab_s, asm.tab_xy, asm.tab_h, asm.tab_k
    for k in range(N + 1):
        px, py, hk, kap = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s_arr[k])
        refs[k, 0] = px
        refs[k, 1] = py
        refs[k, 2] = hk
        refs[k, 3] = kap
    shift = _TWO_PI * np.rint((yaw - refs[0, 2]) / _TWO_PI)
    for k in range(N + 1):
        refs[k, 2] += shift
    model_references(kind, asm.mp, refs, v_arr, N + 1, asm.feedforward, qp.xref, qp.uref, asm.refw)


@subroutine
def follow_references_into(kind, asm, qp, yaw):
    """Between the two calls of a step: the references of car following
    (:func:`~mpcdrive.ocp.follow.follow_references`: arc lengths ``asm.follow_s`` (N+1,) [m]
    and speeds ``asm.follow_v`` [m/s] behind a moving stop line) replace the step's, their speed
    changes the acceleration reference (as ``LtvMpc`` does); the horizon arc lengths the rows
    were built on stay."""
    s_arr, v_arr = asm.follow_s, asm.follow_v
    _place_references(kind, asm, qp, yaw, s_arr, v_arr)
    if asm.accel >= 0:
        uref, ia, dt = qp.uref, asm.accel, asm.dt
        for k in range(asm.N):
            uref[k, ia] += (v_arr[k + 1] - v_arr[k]) / dt


@subroutine
def _discrete_substeps(kind, asm, X, U, k, A, B):
    """asm.F[k], A[k], B[k] of the prediction model ``kind`` at (X[k], U[k]) taken in
    ``asm.substeps`` steps. A step without substeps calls ``discrete_step_jacobians`` itself: each array handed
    on through one more compiled call costs reference counts, about 2 us a step at N = 30."""
    discrete_step_jacobians_substeps(
        kind, asm.mp, asm.nx, asm.nu, X, U, k, asm.dt, asm.method, asm.substeps, asm.F, A, B, asm.dw,
        asm.sub_x, asm.sub_f, asm.sub_a, asm.sub_b,
    )  # fmt: skip


@subroutine
def linearize(kind, cost_obstacles, extras, asm, qp, x, s_guess, t_s, u_prev, Xw, Uw, mode, sides, info):
    """The first half of a step's assembly at time ``t_s`` [s] from the measured state ``x``
    (nx,) after input ``u_prev`` (nu,), the projection searched near ``s_guess`` [m]: references,
    obstacle selection and detour (``sides``: the passing side per obstacle, read and updated),
    linearization trajectory and affine model (``mode``, ``MODE_*``: what (Xw, Uw) is -- no plan,
    the previous step's plan, the current SQP iterate), per-stage input bounds and the road's
    bounds, written into ``asm`` and ``qp``; ``info[INFO_*]`` the projection. Returns 0, or 3
    when the model or the references are not finite. ``kind`` is ``asm.model``;
    ``cost_obstacles``: ``asm.obstacle_form`` is not ``OBS_NONE`` (the obstacle cost and the
    compiled detour); ``extras``: there may be road rows (``asm.lane``), a speed profile
    (``asm.has_profile``) or the friction circle (``asm.friction``). Handed in as constants (a
    step's ``StepSpec``), they leave the code of the other models and of what is off out of the
    compiled step."""
    N, nx, nu = asm.N, asm.nx, asm.nu
    mp, dt, meth = asm.mp, asm.dt, asm.method
    pkind, geo, tab_s, tab_xy, tab_h, tab_k = asm.path, asm.geo, asm.tab_s, asm.tab_xy, asm.tab_h, asm.tab_k
    s_arr, v_arr, prof = asm.s_arr, asm.v_arr, asm.profile
    Xbar, Ubar, F, dw = asm.Xbar, asm.Ubar, asm.F, asm.dw
    nsub = asm.substeps
    A, B, c, xref, uref, Xlin = qp.A, qp.B, qp.c, qp.xref, qp.uref, qp.Xlin
    asm.nsel = 0
    # -- projection and horizon references -----------------------------------------------------
    s0, e_y = path_project(pkind, geo, tab_s, tab_xy, s_guess, asm.window, x[0], x[1])
    h0 = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s0)[2]
    info[INFO_S] = s0
    info[INFO_EY] = e_y
    info[INFO_EPSI] = wrap_angle(x[2] - h0)
    info[INFO_ITER] = 0.0
    # horizon arc lengths and reference speeds: as the profile moves in time, or the constant
    # reference speed (or the paper's fixed step)
    if extras and asm.has_profile:
        profile_arc_lengths(prof, s0, dt, s_arr)
    acc = 0.0
    vdt = abs(asm.v_ref) * dt
    for k in range(N + 1):
        if extras and asm.has_profile:
            v_arr[k] = profile_speed(prof, s_arr[k])
        else:
            s_arr[k] = s0 + asm.horizon_step * k if asm.paper_horizon else s0 + acc
            acc += vdt
            v_arr[k] = asm.v_ref
    _place_references(kind, asm, qp, x[2], s_arr, v_arr)
    if extras and asm.has_profile and asm.accel >= 0:  # the profile's speed changes as acceleration reference
        for k in range(N):
            uref[k, asm.accel] += (v_arr[k + 1] - v_arr[k]) / dt
    if cost_obstacles:
        asm.nsel = select_obstacles(asm, t_s, x, s0)
        if asm.detour:
            detour(asm, xref, sides)

    # -- linearization points and discrete model -------------------------------------------------
    if mode == MODE_ITERATE:
        for i in range(nx):
            Xbar[0, i] = x[i]
        for k in range(1, N):
            for i in range(nx):
                Xbar[k, i] = Xw[k, i]
        for k in range(N):
            for a in range(nu):
                Ubar[k, a] = Uw[k, a]
    elif asm.paper_linearization:
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
    else:  # no plan: roll out the references' inputs (or those handed in, MODE_ROLLOUT)
        for k in range(N):
            for a in range(nu):
                Ubar[k, a] = Uw[k, a] if mode == MODE_ROLLOUT else uref[k, a]
        for i in range(nx):
            Xbar[0, i] = x[i]
        if meth == METHOD_EXP:
            for k in range(N - 1):
                if nsub == 1:
                    discrete_step_jacobians(kind, mp, nx, nu, Xbar, Ubar, k, dt, meth, F, A, B, dw)
                else:
                    _discrete_substeps(kind, asm, Xbar, Ubar, k, A, B)
                for i in range(nx):
                    Xbar[k + 1, i] = F[k, i]
        else:
            rollout_into(kind, mp, nx, Xbar, Ubar, N - 1, dt, meth, nsub, dw[0])
    kmax = 1 if asm.paper_linearization and mode != MODE_ITERATE else N
    for k in range(kmax):
        if nsub == 1:
            discrete_step_jacobians(kind, mp, nx, nu, Xbar, Ubar, k, dt, meth, F, A, B, dw)
        else:
            _discrete_substeps(kind, asm, Xbar, Ubar, k, A, B)
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
    for k in range(N):
        for i in range(nx):
            Xlin[k, i] = Xbar[k, i]
    for i in range(nx):
        Xlin[N, i] = F[N - 1, i]
    if extras and asm.friction:  # the friction circle as per-stage input bounds (ocp.friction)
        vlin = asm.vlin
        for k in range(N + 1):
            vlin[k] = model_speed(kind, mp, Xlin[k])
        friction_input_bounds(
            N,
            vlin,
            Ubar,
            asm.steer,
            asm.accel,
            asm.wheelbase,
            asm.friction_accel,
            qp.u_min,
            qp.u_max,
            qp.dmax,
            u_prev,
            qp.ulo,
            qp.uhi,
        )
    if extras and asm.lane:
        # the body inside the road where the linearization trajectory has the car, in its yaw
        # (scene.road; as LtvMpc.prepare: its arc lengths, not the references')
        s_lin, rlin = asm.s_lin, asm.rlin
        s_lin[0] = s0
        for k in range(N):
            s_lin[k + 1] = s_lin[k] + math.hypot(Xlin[k + 1, 0] - Xlin[k, 0], Xlin[k + 1, 1] - Xlin[k, 1])
        for k in range(N + 1):
            px, py, ph, pk = path_eval(pkind, geo, tab_s, tab_xy, tab_h, tab_k, s_lin[k])
            rlin[k, 0], rlin[k, 1], rlin[k, 2], rlin[k, 3] = px, py, ph, pk
        horizon_bounds(
            asm.road_s,
            asm.road_left,
            asm.road_right,
            asm.road_period,
            s_lin[1:],
            rlin[1:, 2],
            rlin[1:, 3],
            Xlin[1:, 2],
            asm.half_length,
            asm.half_width,
            asm.body_offset,
            asm.road_margin[0],
            qp.lane_lo,
            qp.lane_hi,
            qp.lane_dlo,
            qp.lane_dhi,
        )
    return 0


@subroutine
def stage_costs(cost_obstacles, extras, asm, qp, t_s, shifted):
    """The second half of a step's assembly: with ``shifted``, the references moved sideways by
    the detour written into ``asm.e_ref`` between the halves; then the state cost of x_1..x_N as
    ``x' We x - 2 qt' x`` (the weights plus the obstacle cost's convex model at the linearization
    trajectory), the road rows' normals and offsets where they are linearized, and the first
    step's bounds made reachable. The stage QP is then complete. ``cost_obstacles``,
    ``extras``: as for :func:`linearize`."""
    N, nx = asm.N, asm.nx
    Wq, We, qt, xref = asm.Wq, qp.We, qp.qt, qp.xref
    if shifted:
        e_ref = asm.e_ref
        for k in range(N + 1):
            if e_ref[k] != 0.0:
                shift_references(N, asm.s_arr, asm.refs, e_ref, xref)
                break
    for k in range(N):
        for i in range(nx):
            t = 0.0
            for j in range(nx):
                t += Wq[k, i, j] * xref[k + 1, j]
            qt[k, i] = t
    if cost_obstacles:
        for k in range(N):
            for i in range(nx):
                for j in range(nx):
                    We[k, i, j] = Wq[k, i, j]
        obstacle_cost(asm, t_s, We, qt)
    if extras and asm.lane:
        lane_n, lane_b, lane_t, rlin, F, Xl = qp.lane_n, qp.lane_b, qp.lane_t, asm.rlin, asm.F, qp.Xlin
        for k in range(N):
            yaw, kappa = rlin[k + 1, 2], rlin[k + 1, 3]
            lane_n[k, 0] = -math.sin(yaw)
            lane_n[k, 1] = math.cos(yaw)
            lane_b[k] = lane_n[k, 0] * rlin[k + 1, 0] + lane_n[k, 1] * rlin[k + 1, 1]
            lane_t[k, 0] = kappa * lane_n[k, 1]  # the road's turn per metre moved along it
            lane_t[k, 1] = -kappa * lane_n[k, 0]
        # the first step's bounds hold where the model puts the car with the first input of the
        # linearization (F[0] = f(x, Ubar[0])): reachable, so never bought with slack
        reach_first_step(
            qp.lane_lo,
            qp.lane_hi,
            qp.lane_dlo,
            qp.lane_dhi,
            lane_n[0, 0] * F[0, 0] + lane_n[0, 1] * F[0, 1] - lane_b[0],
            F[0, 2] - Xl[1, 2] - lane_t[0, 0] * (F[0, 0] - Xl[1, 0]) - lane_t[0, 1] * (F[0, 1] - Xl[1, 1]),
        )


_StepAssemblyType, _StepAssemblyStruct = define_struct(StepAssembly, __name__)


@njit(cache=True)
def _build_step_assembly(values):
    return _StepAssemblyStruct(*values)


# numba caches these functions keyed to this file only; they inline code from these
from .. import _jitcache  # noqa: E402
from ..models import compiled as _models_compiled, dynamic as _dynamic, kinematic as _kinematic  # noqa: E402
from ..paths import compiled as _paths_compiled, profile_compiled as _profile_compiled  # noqa: E402
from ..scene import road as _road  # noqa: E402
from . import avoidance_compiled as _avoidance_compiled, friction as _friction  # noqa: E402
from . import obstacle_cost_compiled as _obstacle_cost_compiled  # noqa: E402

#: the source files whose code the assembly links in (and so any compiled step that calls it)
_LINKED = (_kinematic, _dynamic, _models_compiled, _paths_compiled, _profile_compiled, _road, _friction)
LINKED_SOURCES: list[str] = [
    m.__file__ for m in (*_LINKED, _obstacle_cost_compiled, _avoidance_compiled) if m.__file__ is not None
]

_jitcache.refresh(linearize, LINKED_SOURCES)  # one file: one fingerprint for all its functions
