"""The compiled LTV-MPC step: the whole of :class:`~mpcdrive.control.mpc.LtvMpc`'s step behind
one Python call.

:class:`CompiledLtvMpc` solves the same problem as ``LtvMpc`` (same projection, horizon
references with curvature feedforward and slip-corrected yaw -- at a constant reference speed or
following a speed profile (:class:`~mpcdrive.paths.SpeedProfile` or
:class:`~mpcdrive.paths.ConstantSpeed`, arc-length horizon: the references move along the path as
the profile does in time, take its speed, and an ``accel`` input gets its acceleration as
reference; see :mod:`mpcdrive.paths.profile_compiled`) --, linearization along the shifted
previous plan or the paper's frozen point, Euler / RK4 / ``exp`` discrete models, cost, input /
rate / state bounds, soft lane bound with slack, the fallback ladder of ``config.fallback`` --
its ``relax`` rung on a second compiled controller for the relaxed problem) but runs every step in one numba-compiled
function that works in buffers allocated at construction (the step in :mod:`mpcdrive.control.fast_step`, its
obstacle terms in :mod:`mpcdrive.control.fast_obstacles`, the layout of its buffers in
:mod:`mpcdrive.control.fast_layout`, the QP solve in :mod:`mpcdrive.solvers`). The QP is condensed onto the inputs
(and lane slacks): the states are eliminated with the linearized dynamics, the Hessian is built
by a backward recursion ``P_k = W_k + A_k' P_{k+1} A_k`` (O(N^2) blocks), and the dense QP is
solved by the dual active-set method of :mod:`mpcdrive.solvers.dense_qp`, which is exact (no
tolerance on optimality; feasibility to 1e-9) and costs a single Cholesky factorization when no
constraint is active. The soft lane's slacks enter that QP only where they can be nonzero
(:func:`~mpcdrive.solvers.condensed.soft_solve`: first without slacks, checked by the exact-penalty condition), so a car
inside its lane pays for N nu variables, not N (nu + 1).

Obstacles with the potential (eq. 55) or Gaussian (eq. 56) cost -- static or at constant
velocity, circles or polygons -- add their convex second-order model at the linearization
trajectory to the state weights of each step, exactly as ``ocp.avoidance`` does for the OSQP
controller; SQP iterations (``MpcConfig.sqp_max_iterations``) re-run the compiled step around
the current iterate.

The constraint formulations (``hard`` half-planes, ``corridor`` bounds with stop half-planes)
run the compiled step in two stages: up to the linearization trajectory, then -- after
``ocp.avoidance`` (the same Python code as for the OSQP controller: side choice, Frenet boxes of
any obstacle shape and motion, linearized rows) has written the step's rows, lane bounds and
detour offsets into the buffers -- condensing and the solve. Their rows are soft with one
slack per step, as in ``ocp.qp``, and get the same treatment as the lane rows: slacks only for
the steps that can need them (:func:`~mpcdrive.solvers.condensed.soft_solve`).

Models: the kinematic bicycle with 3 and 4 states and the dynamic bicycle (6 states, linear or
Pacejka tires, low-speed blend), their equations and references compiled in
:mod:`mpcdrive.models.compiled` (the dynamic model's references are its steady cornering state
and inputs, as ``DynamicBicycle.reference`` computes them).

Compiled functions use numba's on-disk cache, so only the first process on a machine compiles
(tens of seconds); later processes load the machine code.

Problems the compiled step does not cover (see :func:`~mpcdrive.control.fast_setup.fast_unsupported_reason`)
are refused here with a ValueError naming the reason; :class:`~mpcdrive.control.mpc.LtvMpc` then
builds the Python assembly (:class:`~mpcdrive.control.mpc.PythonLtvMpc`) and says so.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace
from types import SimpleNamespace
from typing import Literal

import numpy as np

from .. import _jitcache
from ..models.compiled import METHOD_EULER, METHOD_EXP, METHOD_RK4, model_code
from ..ocp.avoidance import Avoidance, AvoidanceConfig, AvoidanceMemory
from ..ocp.follow import follow_references
from ..ocp.friction import friction_bounds
from ..ocp.problem import MpcProblem
from ..ocp.road_rows import narrow_road_rows
from ..paths.base import ReferencePath
from ..paths.compiled import path_arrays
from ..paths.profile_compiled import profile_array
from ..scene.footprint import Footprint
from ..scene.road import Road
from ..solvers.dense_qp import STATUS_WORDS
from ..solvers.osqp_backend import OsqpSettings
from ..types import ControlOutput, WarmStart
from .base import checked_obstacles, checked_road, checked_speed_cap

# the layout of the compiled step's buffers
from .fast_layout import _I_MODEL, _I_NX, _I_NU, _I_N, _I_PATH, _I_LIN, _I_METHOD, _I_HORIZON, _I_FF, _I_LANE, _I_MCONST
from .fast_layout import _I_RATE0, _I_MAXITER, _I_GAMMA, _I_NZ, _I_RICCATI, _I_MQ, _I_OFORM, _I_NOBS, _I_OMAX, _I_DETOUR
from .fast_layout import _I_OROWS, _I_PROFILE, _I_ACCEL, _I_STEER, _I_FRICTION, _NIP
from .fast_layout import _SIDE_NONE, _OBS_POTENTIAL, _OBS_GAUSSIAN, MODE_NO_PLAN, MODE_SHIFTED_PLAN, MODE_ITERATE
from .fast_layout import STAGE_ALL, STAGE_LINEARIZE, STAGE_SOLVE, STAGE_COST
from .fast_layout import _W_FP, _W_MP, _W_BND, _W_GEO, _W_WQ, _W_RM, _W_RC, _W_TABS, _W_TABXY, _W_TABH, _W_TABK, _W_C
from .fast_layout import _W_B, _W_REFS, _W_XREF, _W_UREF, _W_XBAR, _W_UBAR, _W_F, _W_A, _W_BD, _W_CD, _W_LANEN, _W_LANEB
from .fast_layout import _W_XF, _W_P, _W_LAM, _W_VB, _W_S, _W_T2, _W_GAM, _W_H, _W_G, _W_Z, _W_L, _W_J, _W_RQ, _W_D
from .fast_layout import _W_ZDIR, _W_R, _W_UQ, _W_SQ, _W_ROWN, _W_LAMQ, _W_DW, _W_KG, _W_KF, _W_PA, _W_MG, _W_GG, _W_QV
from .fast_layout import _W_WE, _W_QT, _W_OBS, _W_ODIST, _W_OPROJ, _W_SARR, _W_EREF, _W_ROWA, _W_ROWB, _W_LLO, _W_LHI
from .fast_layout import _W_XLIN, _W_GSUM, _W_PROF, _W_VARR, _W_REFW, _W_RDS, _W_RDL, _W_RDR, _W_LDLO, _W_LDHI, _W_ULO
from .fast_layout import _W_UHI, _W_VLIN, _W_SLIN, _W_RLIN, _NW
from .fast_layout import _F_DT, _F_VREF, _F_HSTEP, _F_WINDOW, _F_RMARGIN, _F_SLACK2, _F_SLACK1, _F_TOL, _F_OW, _F_OEPS
from .fast_layout import _F_OSX, _F_OSY, _F_OINF, _F_OMARGIN, _F_HW, _F_HL, _F_RAMP, _F_OSLACK2, _F_OSLACK1, _F_BOFF
from .fast_layout import _F_RPERIOD, _F_FRIC, _F_WHEELBASE, _NFP
from .fast_setup import CondensedSettings, fast_unsupported_reason, obstacles_unsupported_reason, uses_rows
from .fast_setup import _obstacle_table, condensed_variables, constant_rows, riccati_shortcut
from .fast_step import _BAD_STATE, _control_step, follow_references_into  # the compiled step
from .fallback import FALLBACK_HOLD, FALLBACK_RELAX, FallbackConfig, FallbackLadder, relaxed_problem
from .mpc import FastPathUnavailable, LtvMpc, MpcConfig, StageQpSolve, StepData, solver_in_reach


_announced = [False]

#: the solvers of the compiled controller's stage QP: the condensed dual active-set solve in the
#: compiled step, or OSQP on the sparse layout of ``ocp.qp``
SOLVERS: tuple[str, ...] = ("condensed", "osqp")


def _announce_compile() -> None:
    """Log one line (logger ``mpcdrive``, INFO; the CLI prints it) before the first compile on a
    machine: the compiled step is built from numba's cache when one exists for these sources."""
    if _announced[0]:
        return
    _announced[0] = True
    if not _jitcache.has_cache(_control_step):
        import logging

        logging.getLogger("mpcdrive").info(
            "compiling the fast controller for this machine (once: numba caches it; about 40-100 s on 2 cores)"
        )


class CompiledLtvMpc(LtvMpc):
    """:class:`~mpcdrive.control.mpc.LtvMpc` with every step compiled (see the module text).

    Same interface and results as the Python assembly
    (:class:`~mpcdrive.control.mpc.PythonLtvMpc`); statuses ``ok``, ``infeasible``,
    ``max_iter``, ``failed``; after a failed solve the ladder of ``config.fallback`` (its
    ``relax`` rung on a second compiled controller built here for the relaxed problem), the rung
    named in ``ControlOutput.fallback``. Obstacles with a cost formulation (see
    :func:`~mpcdrive.control.fast_setup.obstacles_unsupported_reason`) enter each QP as the cost's
    convex model at the linearization trajectory; the constraint formulations (``hard``,
    ``corridor``) as rows built by ``ocp.avoidance`` between two compiled stages, their passing
    sides kept in ``WarmStart.sides``; ``config.sqp_max_iterations > 1`` re-linearizes and
    re-solves (each iteration one compiled call) until the inputs move less than
    ``config.sqp_tol``. The body stays inside ``problem.road`` by the rule of
    :mod:`mpcdrive.scene.road`, evaluated in the compiled step on the road's tables. Built
    directly, a problem the compiled step does not cover is a ValueError naming the reason.
    """

    name = "ltv-mpc-fast"
    #: the solver that runs: ``fast`` (condensed) or ``osqp``
    backend_name = "fast"
    #: who builds each step's stage QP
    assembly = "compiled"

    def __init__(
        self,
        model,
        path: ReferencePath,
        problem: MpcProblem,
        config: MpcConfig = MpcConfig(),
        solver: Literal["condensed", "osqp"] = "condensed",
        *,
        obstacles=(),
        avoidance: AvoidanceConfig | None = None,
        footprint: Footprint = Footprint(),
        condensed_settings: CondensedSettings | None = None,
        osqp_settings: OsqpSettings = OsqpSettings(),
        pg_settings=None,
        assembly: str = "compiled",
    ):
        if solver not in SOLVERS:
            raise ValueError(f"the compiled step's solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        settings = condensed_settings if condensed_settings is not None else CondensedSettings()
        reason = fast_unsupported_reason(model, path, problem, config, settings, obstacles, avoidance, solver="osqp")
        if reason is not None:
            raise ValueError(f"the compiled step cannot assemble this problem: {reason}")
        solver = solver_in_reach(solver, problem, settings, uses_rows(obstacles, avoidance))  # type: ignore[assignment]
        self.solver = solver
        _announce_compile()
        self.model, self.path, self.problem, self.config, self.settings = model, path, problem, config, settings
        obstacles = tuple(obstacles)
        self.footprint = footprint
        #: passing sides are kept (in WarmStart.sides) only where a detour uses them
        self._sides = np.full(max(len(obstacles), 1), _SIDE_NONE, dtype=np.int64)
        av = (avoidance or AvoidanceConfig()) if obstacles else None
        rows = av is not None and av.uses_rows
        #: the compiled detour (cost formulations; with rows ocp.avoidance shifts the references)
        self._detour = av is not None and av.detour != "none" and not rows
        nx, nu, N = model.nx, model.nu, problem.N
        road = problem.road
        self._road = road
        self._lateral = None
        #: (cap [m/s], braking to it [m/s^2]) of set_speed_cap, or None
        self._speed_cap: tuple[float, float] | None = None
        self._follow_decel = (av or AvoidanceConfig()).follow_decel_mps2
        lane = road is not None
        #: the obstacle terms as LtvMpc keeps them (``avoidance.config``, ``.obstacles``,
        #: ``.relevant``). With a constraint formulation it builds each step's rows between the two
        #: stages.
        self.avoidance: Avoidance | None = None
        if av is not None:
            self.avoidance = Avoidance(av, list(obstacles), path, footprint, N, problem.dt_s, road)
        self._rows = self.avoidance if rows else None
        n_orow = av.rows_per_step(footprint) if av is not None and rows else 0
        self.nx, self.nu, self.N = nx, nu, N
        self.dt_s = problem.dt_s
        if config.v_ref_mps is not None:
            self.v_ref_mps = float(config.v_ref_mps)
        elif config.speed_profile is not None:
            self.v_ref_mps = float(config.speed_profile.speed(0.0))
        else:
            self.v_ref_mps = float(model.speed(np.zeros(nx)))
        if not np.isfinite(self.v_ref_mps):
            raise ValueError(f"reference speed must be finite, got {self.v_ref_mps}")
        # fast_unsupported_reason above rejects models, paths and speed profiles compiled code lacks
        code = model_code(model)
        pa = path_arrays(path)
        prof = np.zeros(1) if config.speed_profile is None else profile_array(config.speed_profile)
        assert code is not None and pa is not None and prof is not None
        kind, mp = code
        nz = condensed_variables(problem, rows)
        cr = constant_rows(problem, nz, n_orow)
        mq, need_gamma = cr.mq, cr.gamma
        ip = np.zeros(_NIP, dtype=np.int64)
        ip[[_I_MODEL, _I_NX, _I_NU, _I_N, _I_PATH]] = [kind, nx, nu, N, pa.kind]
        ip[_I_LIN] = 1 if config.linearization == "paper" else 0
        ip[_I_METHOD] = {"rk4": METHOD_RK4, "euler": METHOD_EULER, "exp": METHOD_EXP}[config.discretization]
        ip[_I_HORIZON] = 1 if config.horizon == "paper" else 0
        ip[_I_FF] = 1 if config.feedforward == "curvature" else 0
        ip[_I_LANE] = int(lane)
        ip[_I_MCONST] = cr.m_const
        ip[_I_RATE0] = cr.r_rate0
        ip[_I_MAXITER] = settings.max_iter
        ip[_I_GAMMA] = int(need_gamma)
        ip[_I_NZ] = nz
        ip[_I_RICCATI] = int(riccati_shortcut(problem, rows))
        ip[_I_MQ] = mq
        ip[_I_OROWS] = n_orow
        ip[_I_PROFILE] = int(config.speed_profile is not None)
        ip[_I_ACCEL] = list(model.input_names).index("accel") if "accel" in model.input_names else -1
        fric = friction_bounds(problem, model)  # validates the model for the friction circle
        if fric is not None:
            ip[_I_FRICTION], ip[_I_STEER] = 1, fric.i_steer
        if av is not None and not rows:
            ip[_I_OFORM] = _OBS_POTENTIAL if av.formulation == "potential" else _OBS_GAUSSIAN
            ip[_I_NOBS] = len(obstacles)
            ip[_I_OMAX] = av.max_obstacles
            ip[_I_DETOUR] = int(self._detour)
        fp = np.zeros(_NFP)
        fp[[_F_HW, _F_HL, _F_BOFF]] = (0.5 * footprint.width_m, 0.5 * footprint.length_m, footprint.center_offset_m)
        if av is not None:
            fp[[_F_OW, _F_OEPS, _F_OSX, _F_OSY, _F_OINF]] = (av.weight, av.epsilon_m2, *av.sigma_m, av.influence_m)
            fp[[_F_OMARGIN, _F_RAMP]] = (av.margin_m, av.detour_ramp_m)
        fp[_F_DT], fp[_F_VREF] = problem.dt_s, self.v_ref_mps
        fp[_F_HSTEP], fp[_F_WINDOW] = config.horizon_step_m, config.projection_window_m
        fp[_F_RMARGIN] = road.margin_m if road is not None else 0.0
        fp[_F_RPERIOD] = road.period_m if road is not None else 0.0
        fp[_F_SLACK2], fp[_F_SLACK1] = problem.lane_slack_weight, problem.lane_slack_weight_l1
        fp[_F_OSLACK2], fp[_F_OSLACK1] = problem.obstacle_slack_weight, problem.obstacle_slack_weight_l1
        fp[_F_TOL] = settings.feasibility_tol
        if fric is not None:
            fp[_F_FRIC], fp[_F_WHEELBASE] = fric.a_fric, fric.wheelbase_m
        bnd = np.concatenate(
            [problem.u_min, problem.u_max, problem.du_max_per_s * problem.dt_s, problem.x_min, problem.x_max]
        )
        nw = max(nx, nu)
        arrays: dict[int, np.ndarray | tuple[int, ...]] = {  # initial values, or the shape of a work array
            _W_FP: fp,
            _W_MP: mp,
            _W_BND: bnd,
            _W_GEO: pa.geo,
            _W_WQ: np.stack([problem.Q] * (N - 1) + [problem.QN]),
            _W_RM: problem.R,
            _W_RC: problem.Rc,
            _W_TABS: pa.tab_s,
            _W_TABXY: pa.tab_xy,
            _W_TABH: pa.tab_h,
            _W_TABK: pa.tab_k,
            _W_C: cr.C,
            _W_B: cr.b,
            _W_REFS: (N + 1, 4),
            _W_XREF: (N + 1, nx),
            _W_UREF: (N, nu),
            _W_XBAR: (N, nx),
            _W_UBAR: (N, nu),
            _W_F: (N, nx),
            _W_A: (N, nx, nx),
            _W_BD: (N, nx, nu),
            _W_CD: (N, nx),
            _W_LANEN: (N, 2),
            _W_LANEB: (N,),
            _W_XF: (N + 1, nx),
            _W_P: (N + 1, nx, nx),
            _W_LAM: (N + 1, nx),
            _W_VB: (N, nx, nu),
            _W_S: (2, nx, N * nu),
            _W_T2: (nx, nw),
            _W_GAM: (N, nx, N * nu) if need_gamma else (1, 1, 1),
            _W_H: (nz, nz),
            _W_G: (nz,),
            _W_Z: (nz,),
            _W_L: (nz, nz),
            _W_J: (nz, nz),
            _W_RQ: (nz, nz),
            _W_D: (nz,),
            _W_ZDIR: (nz,),
            _W_R: (nz,),
            _W_UQ: (nz,),
            _W_SQ: (mq,),
            _W_ROWN: (mq,),
            _W_LAMQ: (mq,),
            _W_DW: (7, nx + nu + 1, nx + nu + 1),
            _W_KG: (N, nu, nx),
            _W_KF: (N, nu),
            _W_PA: (nx, nx),
            _W_MG: (nu, nx),
            _W_GG: (nu, nu),
            _W_QV: (nx,),
            _W_WE: np.stack([problem.Q] * (N - 1) + [problem.QN]),
            _W_QT: (N, nx),
            _W_OBS: _obstacle_table(obstacles),
            _W_ODIST: (max(len(obstacles), 1),),
            _W_OPROJ: (max(len(obstacles), 1), 2),
            _W_SARR: (N + 1,),
            _W_EREF: (N + 1,),
            _W_ROWA: (N, max(n_orow, 1), 3),
            _W_ROWB: np.full((N, max(n_orow, 1)), -np.inf),
            _W_LLO: (N,),
            _W_LHI: (N,),
            _W_LDLO: (N,),
            _W_LDHI: (N,),
            _W_XLIN: (N + 1, nx),
            _W_GSUM: (2 * N,),
            _W_PROF: prof,
            _W_VARR: (N + 1,),
            _W_REFW: (N + 1, 8),
            _W_RDS: road.s_m if road is not None else np.zeros(1),
            _W_RDL: road.left_m if road is not None else np.zeros(1),
            _W_RDR: road.right_m if road is not None else np.zeros(1),
            _W_ULO: np.tile(problem.u_min, (N, 1)),
            _W_UHI: np.tile(problem.u_max, (N, 1)),
            _W_VLIN: (N + 1,),
            _W_SLIN: (N + 1,),
            _W_RLIN: (N + 1, 4),
        }
        shapes: list[tuple[int, ...]] = [
            np.shape(a) if isinstance(a, np.ndarray) else a for a in (arrays[i] for i in range(_NW))
        ]
        sizes = [int(np.prod(sh)) for sh in shapes]
        fo = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        fs = np.ones((_NW, 3), dtype=np.int64)
        for i, sh in enumerate(shapes):
            fs[i, : len(sh)] = sh
        self._wbuf = np.zeros(int(fo[-1]))
        #: named views of the buffer (constants and work arrays), for inspection
        self._w = {i: self._wbuf[fo[i] : fo[i + 1]].reshape(shapes[i]) for i in range(_NW)}
        for i, v in arrays.items():
            if isinstance(v, np.ndarray):
                self._w[i][...] = v
        # active-set work: active (nz), isact (mq), rowcol (mq: the constant rows' single nonzero
        # columns, -1 for a dense row; the step marks the rows it writes), kpos (2N), osel
        # (obstacles), rgrp (mq)
        self._ibuf = np.concatenate(
            [
                ip,
                fo,
                fs.ravel(),
                np.zeros(nz + mq, dtype=np.int64),
                cr.rowcol,
                np.zeros(2 * N + max(len(obstacles), 1) + mq, dtype=np.int64),
            ]
        )
        self._info = np.zeros(4)
        self._noX = np.zeros((N + 1, nx))
        self._noU = np.zeros((N, nu))
        self._o_X = nu
        self._o_U = nu + (N + 1) * nx
        self._o_R = self._o_U + N * nu
        self._out_size = self._o_R + (N + 1) * nx
        self._du_step = problem.du_max_per_s * problem.dt_s  # (nu,) largest input change per step
        if solver == "osqp":
            # the stage QP of the compiled assembly (prepare), solved by OSQP on the sparse layout
            from ..ocp.qp import LtvQp  # scipy.sparse: imported when an OSQP controller is built
            from ..solvers.osqp_backend import OsqpBackend

            self.qp = LtvQp(replace(problem, obstacle_rows=n_orow, position_cost=av is not None and av.uses_cost))
            self.backend = OsqpBackend(self.qp, osqp_settings)
            self.backend_name = "osqp"
        self._warm_up()
        # the fallback ladder of config.fallback; its relax rung solves the step again on a second
        # compiled controller without rate limits and state bounds, with a cheaper lane slack
        self._relaxed = None
        if FALLBACK_RELAX in config.fallback.ladder:
            with warnings.catch_warnings():  # this controller's solver: already said above
                warnings.simplefilter("ignore", FastPathUnavailable)
                self._relaxed = CompiledLtvMpc(
                    model,
                    path,
                    relaxed_problem(problem, config.fallback.relax_slack_factor),
                    replace(config, sqp_max_iterations=1, fallback=FallbackConfig((FALLBACK_HOLD,))),
                    solver,
                    obstacles=obstacles,
                    avoidance=avoidance,
                    footprint=footprint,
                    condensed_settings=replace(settings, max_iter=2 * settings.max_iter),
                    osqp_settings=osqp_settings,
                )
        self.fallback = FallbackLadder(
            self,
            config.fallback,
            relax=self._relax_step if self._relaxed is not None else None,
            footprint=footprint,
            road=road,
        )

    def _warm_up(self) -> None:
        """One discarded step at the path start, so that loading (or, on a first run, compiling)
        the machine code happens while building, not in the first control step."""
        x = np.zeros(self.nx)
        x[:2] = self.path.position(0.0)
        x[2] = float(self.path.heading(0.0))
        if self.nx >= 4:  # the speed state: v (kinematic bicycle) or vx (dynamic bicycle)
            x[3] = self.v_ref_mps
        out = np.empty(self._out_size)
        for stage in (STAGE_ALL,) if self.solver == "condensed" else (STAGE_LINEARIZE, STAGE_COST):
            _control_step(
                x,
                0.0,
                0.0,
                np.zeros(self.nu),
                self._noX,
                self._noU,
                MODE_NO_PLAN,
                stage,
                self._sides.copy(),
                self._wbuf,
                self._ibuf,
                out,
                self._info,
            )
        # the car-following references (a lane blocked ahead, a speed cap) come in mid-run: the
        # step that first needs them would load them (the next step recomputes the references)
        w = self._w
        follow_references_into(float(x[2]), w[_W_SARR].copy(), w[_W_VARR].copy(), self._wbuf, self._ibuf)

    # -- obstacles and road (the properties from LtvMpc) ---------------------------------------
    def set_road(self, road: Road) -> None:
        """As :meth:`LtvMpc.set_road`: the compiled step reads the new edges from its tables."""
        self._road = checked_road(self._road, road)
        self._w[_W_RDL][...] = road.left_m
        self._w[_W_RDR][...] = road.right_m
        self._w[_W_FP][_F_RMARGIN] = road.margin_m
        if self.avoidance is not None:
            self.avoidance.road = road
        self.fallback.road = road
        if self._relaxed is not None:
            self._relaxed.set_road(road)

    def set_lateral_reference(self, offset) -> None:
        """As :meth:`LtvMpc.set_lateral_reference` (the step then runs in two stages, the offsets
        written between them); not with the compiled detour of the cost formulations."""
        if offset is not None and not callable(offset):
            raise ValueError("the lateral reference must be a callable of arc length, or None")
        if offset is not None and self._detour:
            raise ValueError("a lateral reference does not combine with the compiled detour")
        self._lateral = offset
        if self._relaxed is not None:
            self._relaxed.set_lateral_reference(offset)

    def set_speed_cap(self, v_mps: float | None, decel_mps2: float | None = None) -> None:
        """As :meth:`LtvMpc.set_speed_cap <mpcdrive.control.mpc.PythonLtvMpc.set_speed_cap>` (the step
        then runs in two stages, the capped references placed between them)."""
        self._speed_cap = checked_speed_cap(v_mps, decel_mps2, self._follow_decel)
        if self._relaxed is not None:
            self._relaxed.set_speed_cap(v_mps, decel_mps2)

    def set_obstacles(self, obstacles) -> None:
        """Replace the obstacles, as :meth:`LtvMpc.set_obstacles <mpcdrive.control.mpc.PythonLtvMpc.set_obstacles>`
        does (fresh predictions of moving ones each step; index j keeps naming the same
        obstacle; nothing is rebuilt). With a constraint formulation any number may be given;
        with a cost formulation the compiled obstacle table keeps the number given at
        construction, and each obstacle must be one the compiled cost covers."""
        avoidance, obstacles = checked_obstacles(self.avoidance, obstacles)
        if self._rows is None:
            if len(obstacles) != len(self.obstacles):
                raise ValueError(
                    f"the compiled obstacle cost was built for {len(self.obstacles)} obstacle(s), "
                    f"got {len(obstacles)}: build the controller with that many"
                )
            reason = obstacles_unsupported_reason(obstacles, avoidance.config)
            if reason is not None:
                raise ValueError(f"the fast backend cannot take these obstacles: {reason}")
            self._w[_W_OBS][...] = _obstacle_table(obstacles)
        avoidance.obstacles = list(obstacles)
        if self._relaxed is not None:  # the relax rung avoids the same obstacles
            self._relaxed.set_obstacles(obstacles)

    # -- warm start: initial_warm and _check_state from TrackingWarmStart ---------------------
    def _load_sides(self, sides: tuple) -> np.ndarray:
        """The side memory array of ``WarmStart.sides`` (untouched without a detour)."""
        arr = self._sides
        if self._detour:
            arr[:] = _SIDE_NONE
            for j, side in sides:
                if 0 <= j < len(arr):
                    arr[j] = side
        return arr

    def _relax_step(self, d, warm: WarmStart):
        """The relax rung: the relaxed controller's step (None if it fails too)."""
        assert self._relaxed is not None  # __init__ passes this rung only with a relaxed controller
        out = self._relaxed.step(d.x, warm)
        if out.status != "ok":
            return None
        return out.u, replace(out.warm, s_m=d.s_m), out.X_pred

    def _run(self, x, s_guess: float, t_s: float, u_prev, X, U, mode: int, warm_sides: tuple, out, last=STAGE_SOLVE):
        """One compiled step (or SQP iteration); with constraint rows, in two stages around
        ``ocp.avoidance``. Returns the status code and the passing sides for the next step.
        ``last=STAGE_COST``: only the stage QP, into the buffers (for :meth:`prepare`)."""
        sides = self._load_sides(warm_sides)
        if last == STAGE_SOLVE and self._rows is None and self._lateral is None and self._speed_cap is None:
            code = _control_step(
                x, s_guess, t_s, u_prev, X, U, mode, STAGE_ALL, sides, self._wbuf, self._ibuf, out, self._info
            )
            if self._detour:
                return code, tuple((j, int(v)) for j, v in enumerate(sides) if v != _SIDE_NONE)
            return code, warm_sides
        code = _control_step(
            x, s_guess, t_s, u_prev, X, U, mode, STAGE_LINEARIZE, sides, self._wbuf, self._ibuf, out, self._info
        )
        if code != 0:
            return code, warm_sides
        w = self._w
        w[_W_EREF][...] = 0.0
        new_sides = warm_sides
        s_max = None
        if self._rows is not None:
            memory = AvoidanceMemory(dict(warm_sides))
            terms = self._rows.terms(t_s, x, w[_W_XLIN], w[_W_SARR], memory, w[_W_LLO], w[_W_LHI])
            w[_W_ROWA][...] = terms.rows_a
            w[_W_ROWB][...] = terms.rows_b
            if terms.lane_lo is not None and terms.lane_hi is not None:
                narrow_road_rows(w[_W_LLO], w[_W_LHI], w[_W_LDLO], w[_W_LDHI], terms.lane_lo, terms.lane_hi)
            if terms.e_ref is not None:
                w[_W_EREF][...] = terms.e_ref
            s_max = terms.s_max
            new_sides = tuple(sorted(memory.sides.items()))
        if s_max is not None or self._speed_cap is not None:
            # car following: the references approach the stop line behind the obstacle blocking
            # the lane ahead and move on with its prediction; and a speed cap (as LtvMpc.prepare)
            cap, decel = self._speed_cap or (math.inf, self._follow_decel)
            follow = follow_references(w[_W_SARR], w[_W_VARR], s_max, float(self.model.speed(x)), self.dt_s, decel, cap)
            if follow is not None:
                follow_references_into(float(x[2]), follow[0], follow[1], self._wbuf, self._ibuf)
        if self._lateral is not None:
            w[_W_EREF] += np.asarray(self._lateral(w[_W_SARR]), float)
        code = _control_step(x, s_guess, t_s, u_prev, X, U, mode, last, sides, self._wbuf, self._ibuf, out, self._info)
        return code, new_sides

    def prepare(self, x, warm: WarmStart, around=None, s_m: float | None = None) -> StepData:
        """The stage QP of one step, as :meth:`LtvMpc.prepare <mpcdrive.control.mpc.PythonLtvMpc.prepare>`
        gives it (:class:`~mpcdrive.control.mpc.StepData`) but assembled by the compiled step:
        projection, references, linearization, road rows, obstacle rows or cost terms, per-stage
        input bounds. ``around=(X, U)`` re-linearizes at an SQP iterate. The arrays are views of
        the controller's buffers, valid until its next step; a step whose model or references are
        not finite gives NaN dynamics (any solver then fails it)."""
        x = self._check_state(x)
        u_prev = self._check_warm(warm)
        N, nx, nu = self.N, self.nx, self.nu
        if around is not None:
            X, U, mode = around[0], around[1], MODE_ITERATE
            s_guess = float(warm.s_m if s_m is None else s_m)
        elif warm.X is not None and warm.U is not None:
            X, U, mode, s_guess = warm.X, warm.U, MODE_SHIFTED_PLAN, float(warm.s_m)
        else:
            X, U, mode, s_guess = self._noX, self._noU, MODE_NO_PLAN, float(warm.s_m)
        X = np.ascontiguousarray(X, dtype=float)
        U = np.ascontiguousarray(U, dtype=float)
        if X.shape != (N + 1, nx) or U.shape != (N, nu):
            raise ValueError(f"warm plan must be X ({N + 1}, {nx}) and U ({N}, {nu}), got {X.shape} and {U.shape}")
        code, sides = self._run(
            x, s_guess, float(warm.t_s), u_prev, X, U, mode, warm.sides, np.empty(self._out_size), last=STAGE_COST
        )
        w, info = self._w, self._info
        if code != 0:  # a non-finite model or references: no usable stage QP
            w[_W_CD][...] = math.nan
        Wq, xref = w[_W_WQ], w[_W_XREF]
        H = g = None
        if self.avoidance is not None and self._rows is None:  # the cost's model, added to the state weights
            H = 2.0 * (w[_W_WE][:, :2, :2] - Wq[:, :2, :2])
            g = -2.0 * (w[_W_QT][:, :2] - np.einsum("kij,kj->ki", Wq, xref[1:])[:, :2])
        road = self._road is not None
        rows = self._rows is not None
        friction = self._ibuf[_I_FRICTION] == 1
        Xlin = w[_W_XLIN]
        return StepData(
            x,
            float(info[0]),
            float(info[1]),
            float(info[2]),
            xref,
            w[_W_UREF],
            w[_W_XBAR],
            w[_W_UBAR],
            w[_W_F],
            w[_W_A],
            w[_W_BD],
            w[_W_CD],
            w[_W_LANEN],
            w[_W_LANEB],
            Xlin,
            w[_W_LLO] if road else None,
            w[_W_LHI] if road else None,
            w[_W_ROWA] if rows else None,
            w[_W_ROWB] if rows else None,
            H,
            g,
            sides,
            (w[_W_LDLO], w[_W_LDHI], Xlin[1:, 2]) if road else None,
            w[_W_ULO] if friction else None,
            w[_W_UHI] if friction else None,
        )

    # -- one control step -----------------------------------------------------------------------
    def step(self, x, warm: WarmStart) -> ControlOutput:
        """Compute the command for measured state ``x`` (nx,) given the previous step's ``warm``."""
        if self.solver == "osqp":  # prepare, then OSQP on the stage QP (StageQpSolve)
            return StageQpSolve.step(self, x, warm)
        t0 = time.perf_counter()
        if type(x) is not np.ndarray or x.dtype != np.float64 or not x.flags.c_contiguous:
            x = np.ascontiguousarray(x, dtype=float)
        if x.shape != (self.nx,):
            self._check_state(x)
        u_prev = warm.u_prev
        if type(u_prev) is not np.ndarray or u_prev.dtype != np.float64 or u_prev.shape != (self.nu,):
            u_prev = np.ascontiguousarray(u_prev, dtype=float)
            if u_prev.shape != (self.nu,):
                raise ValueError(f"warm.u_prev must have shape ({self.nu},), got {u_prev.shape}")
        X, U = warm.X, warm.U
        has_plan = X is not None and U is not None
        if X is not None and U is not None:
            if X.shape != (self.N + 1, self.nx) or U.shape != (self.N, self.nu):
                raise ValueError(
                    f"warm plan must be X ({self.N + 1}, {self.nx}) and U ({self.N}, {self.nu}), "
                    f"got {X.shape} and {U.shape}"
                )
            if X.dtype != np.float64 or U.dtype != np.float64 or not (X.flags.c_contiguous and U.flags.c_contiguous):
                X, U = np.ascontiguousarray(X, dtype=float), np.ascontiguousarray(U, dtype=float)
        else:
            X, U = self._noX, self._noU
        out = np.empty(self._out_size)
        t_s = float(warm.t_s)
        info = self._info
        code, new_sides = self._run(
            x, float(warm.s_m), t_s, u_prev, X, U, MODE_SHIFTED_PLAN if has_plan else MODE_NO_PLAN, warm.sides, out
        )
        N, nx, nu = self.N, self.nx, self.nu
        cfg = self.config
        it = 1
        e_y, e_psi = info[1], info[2]
        t_qp = time.perf_counter() - t0  # the last QP's time: no new QP that would end past the cap
        while code == 0 and it < cfg.sqp_max_iterations and time.perf_counter() - t0 + t_qp < cfg.sqp_max_time_s:
            t1 = time.perf_counter()
            U_it = out[self._o_U : self._o_R].reshape(N, nu)
            if float(np.max(np.abs(U_it - self._w[_W_UBAR]))) < cfg.sqp_tol:
                break
            X_it = out[self._o_X : self._o_U].reshape(N + 1, nx)
            out = np.empty(self._out_size)
            code, new_sides = self._run(x, float(info[0]), t_s, u_prev, X_it, U_it, MODE_ITERATE, warm.sides, out)
            it += 1
            t_qp = time.perf_counter() - t1
        t_next = t_s + self.dt_s
        if code == 0:
            u = out[:nu]
            X_pred = out[self._o_X : self._o_U].reshape(N + 1, nx)
            U_plan = out[self._o_U : self._o_R].reshape(N, nu)
            refs: np.ndarray = out[self._o_R :].reshape(N + 1, nx)
            return ControlOutput(
                u,
                "ok",
                "",
                time.perf_counter() - t0,
                info[0],
                e_y,
                e_psi,
                X_pred,
                refs,
                WarmStart(info[0], u, X_pred, U_plan, t_next, new_sides),
                it,
            )
        if code == _BAD_STATE:
            self._check_state(x)  # raises, naming the field
        status = STATUS_WORDS[code]
        refs = self._w[_W_XREF].copy()
        u, name, new_warm, X_pred = self.fallback.run(SimpleNamespace(x=x, s_m=float(info[0])), warm)
        new_warm = replace(new_warm, t_s=t_next, sides=new_sides)
        return ControlOutput(
            u,
            status,
            name,
            time.perf_counter() - t0,
            float(info[0]),
            float(e_y),
            float(e_psi),
            X_pred,
            refs,
            new_warm,
            it,
        )
