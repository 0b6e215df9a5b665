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
its ``relax`` rung on a second compiled controller for the relaxed problem) but runs every step in one
numba-compiled call (:func:`~mpcdrive.control.compiled_step.control_step` of its
:class:`~mpcdrive.control.compiled_step.StepSpec`, compiled for the
vehicle model and the features the problem uses) on typed containers allocated at
construction: the step assembly's description and work (:class:`~mpcdrive.ocp.assembly.StepAssembly`; the
assembly in :mod:`mpcdrive.ocp.assembly`, its obstacle cost terms in :mod:`mpcdrive.ocp.obstacle_cost_compiled`),
the stage QP it writes (:class:`~mpcdrive.ocp.stage_qp.StageQp`) and the condensed solver's work space
(:class:`~mpcdrive.solvers.condensed.CondensedWork`; the QP solve in :mod:`mpcdrive.solvers`). The QP is
condensed onto the inputs
(and lane slacks): the states are eliminated with the linearized dynamics, the Hessian is built
by a backward recursion ``P_k = W_k + A_k' P_{k+1} A_k`` (O(N^2) blocks), and the dense QP is
solved by the dual active-set method of :mod:`mpcdrive.solvers.dense_qp`, which is exact (no
tolerance on optimality; feasibility to 1e-9) and costs a single Cholesky factorization when no
constraint is active. The soft lane's slacks enter that QP only where they can be nonzero
(:func:`~mpcdrive.solvers.condensed.soft_solve`: first without slacks, checked by the exact-penalty condition), so a car
inside its lane pays for N nu variables, not N (nu + 1).

Obstacles with the potential (eq. 55) or Gaussian (eq. 56) cost -- static, at constant
velocity or on a recorded trajectory, with or without a lifetime, circles or polygons -- add
their convex second-order model at the linearization
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

Problems the compiled step does not cover (see :func:`~mpcdrive.control.compiled_setup.fast_unsupported_reason`)
are refused here with a ValueError naming the reason; :class:`~mpcdrive.control.mpc.LtvMpc` then
builds the Python assembly (:class:`~mpcdrive.control.python_mpc.PythonLtvMpc`) and says so.
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
from ..scene.world import Scene
from ..solvers.dense_qp import STATUS_WORDS
from ..solvers.osqp_backend import OsqpSettings
from ..types import ControlOutput, WarmStart
from .base import (
    checked_obstacles,
    checked_plan,
    checked_road,
    checked_speed_cap,
    plan_arc_lengths,
    projection_guess,
    resolve_scene,
)

from ..ocp.assembly import MODE_ITERATE, MODE_NO_PLAN, MODE_ROLLOUT, MODE_SHIFTED_PLAN, StepAssembly
from ..ocp.avoidance_compiled import SIDE_NONE
from ..ocp.obstacle_cost_compiled import OBS_GAUSSIAN, OBS_NONE, OBS_POTENTIAL, cost_obstacle_arrays
from ..ocp.stage_qp import new_stage_qp
from ..solvers.condensed_setup import CondensedSettings, new_condensed_work
from .compiled_setup import fast_unsupported_reason, obstacles_unsupported_reason, uses_rows
from .compiled_step import (
    _BAD_STATE,
    STAGE_ALL,
    STAGE_COST,
    STAGE_FOLLOW,
    STAGE_LINEARIZE,
    STAGE_SOLVE,
    CompiledStep,
    StepSpec,
    control_step,
)
from .fallback import FALLBACK_HOLD, FALLBACK_RELAX, FallbackConfig, FallbackLadder, relaxed_problem
from .mpc_base import FastPathUnavailable, LtvMpc, StageQpSolve, StepData, solver_in_reach
from .mpc_config import MpcConfig


_announced: set = set()

#: the solvers of the compiled controller's stage QP: the condensed dual active-set solve in the
#: compiled step, or OSQP on the sparse layout of ``ocp.qp``
SOLVERS: tuple[str, ...] = ("condensed", "osqp")


def _announce_compile(step_fn, what: str = "") -> None:
    """Log one line (logger ``mpcdrive``, INFO; the CLI prints it) before the first compile of
    the compiled step ``step_fn`` (one per :class:`~mpcdrive.control.compiled_step.StepSpec`) on a machine: it is
    built from numba's cache when one exists for these sources. ``what`` names the step."""
    if step_fn in _announced:
        return
    _announced.add(step_fn)
    if not _jitcache.has_cache(step_fn):
        import logging

        logging.getLogger("mpcdrive").info(
            f"compiling the fast controller{what} (once: numba caches it; about 20-35 s on 2 cores)"
        )


class CompiledLtvMpc(LtvMpc):
    """:class:`~mpcdrive.control.mpc.LtvMpc` with every step compiled (see the module text).

    Same interface and results as the Python assembly
    (:class:`~mpcdrive.control.python_mpc.PythonLtvMpc`); statuses ``ok``, ``infeasible``,
    ``max_iter``, ``failed``; after a failed solve the ladder of ``config.fallback`` (its
    ``relax`` rung on a second compiled controller built here for the relaxed problem), the rung
    named in ``ControlOutput.fallback``. Obstacles with a cost formulation (see
    :func:`~mpcdrive.control.compiled_setup.obstacles_unsupported_reason`) enter each QP as the cost's
    convex model at the linearization trajectory; the constraint formulations (``hard``,
    ``corridor``) as rows built by ``ocp.avoidance`` between two compiled stages, their passing
    sides kept in ``WarmStart.sides``; ``config.sqp_max_iterations > 1`` re-linearizes and
    re-solves (each iteration one compiled call) until the inputs move less than
    ``config.sqp_tol``. The body stays inside ``problem.road`` by the rule of
    :mod:`mpcdrive.scene.road`, evaluated in the compiled step on the road's tables. Built
    directly, a problem the compiled step does not cover is a ValueError naming the reason.

    ``step_spec``: the compiled step to run (:class:`~mpcdrive.control.compiled_step.StepSpec`);
    None: the least one the problem needs (``self.step_spec``). A spec with more features runs
    the same problem with the same results, and lets controllers share one compiled step (the
    relax rung's controller takes its parent's); one that lacks a feature the problem needs is
    a ValueError.
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
        scene: Scene | None = None,
        obstacles=(),
        avoidance: AvoidanceConfig | None = None,
        footprint: Footprint | None = None,
        condensed_settings: CondensedSettings | None = None,
        osqp_settings: OsqpSettings = OsqpSettings(),
        pg_settings=None,
        assembly: str = "compiled",
        step_spec: StepSpec | None = None,
    ):
        problem, self.scene = resolve_scene(problem, scene, obstacles, footprint)
        obstacles, footprint = self.scene.obstacles, self.scene.footprint
        if solver not in SOLVERS:
            raise ValueError(f"the compiled step's solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        settings = condensed_settings if condensed_settings is not None else CondensedSettings()
        reason = fast_unsupported_reason(model, path, problem, config, settings, obstacles, avoidance, solver="osqp")
        if reason is not None:
            raise ValueError(f"the compiled step cannot assemble this problem: {reason}")
        solver = solver_in_reach(solver, problem, settings, uses_rows(obstacles, avoidance))  # type: ignore[assignment]
        self.solver = solver
        self.model, self.path, self.problem, self.config, self.settings = model, path, problem, config, settings
        obstacles = tuple(obstacles)
        self.footprint = footprint
        #: passing sides are kept (in WarmStart.sides) only where a detour uses them
        self._sides = np.full(max(len(obstacles), 1), SIDE_NONE, dtype=np.int64)
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
        #: (s (N+1,) [m], v (N+1,) [m/s]) of set_longitudinal_plan, or None
        self._plan: tuple[np.ndarray, np.ndarray] | None = None
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
        fric = friction_bounds(problem, model)  # validates the model for the friction circle
        cost_av = av if av is not None and not rows else None  # the compiled obstacle cost's settings
        n_ob = max(len(obstacles), 1)
        f = np.ascontiguousarray
        #: the compiled step's containers: the assembly's description and work, the stage QP it
        #: writes, the condensed solver's work space (the arrays are shared with their structs)
        self._asm = StepAssembly(
            N=N,
            nx=nx,
            nu=nu,
            model=int(kind),
            mp=f(mp, dtype=float),
            method={"rk4": METHOD_RK4, "euler": METHOD_EULER, "exp": METHOD_EXP}[config.discretization],
            substeps=int(config.prediction_substeps),
            dt=float(problem.dt_s),
            path=int(pa.kind),
            geo=f(pa.geo, dtype=float),
            tab_s=f(pa.tab_s, dtype=float),
            tab_xy=f(pa.tab_xy, dtype=float),
            tab_h=f(pa.tab_h, dtype=float),
            tab_k=f(pa.tab_k, dtype=float),
            window=float(config.projection_window_m),
            paper_horizon=config.horizon == "paper",
            horizon_step=float(config.horizon_step_m),
            v_ref=self.v_ref_mps,
            has_profile=config.speed_profile is not None,
            profile=f(prof, dtype=float),
            feedforward=config.feedforward == "curvature",
            paper_linearization=config.linearization == "paper",
            Wq=problem.stage_weights(),
            accel=list(model.input_names).index("accel") if "accel" in model.input_names else -1,
            steer=int(fric.i_steer) if fric is not None else -1,
            friction=fric is not None,
            friction_accel=float(fric.a_fric) if fric is not None else 0.0,
            wheelbase=float(fric.wheelbase_m) if fric is not None else 0.0,
            lane=lane,
            road_s=f(road.s_m, dtype=float) if road is not None else np.zeros(1),
            road_left=f(road.left_m, dtype=float) if road is not None else np.zeros(1),
            road_right=f(road.right_m, dtype=float) if road is not None else np.zeros(1),
            road_period=float(road.period_m) if road is not None else 0.0,
            road_margin=np.array([road.margin_m if road is not None else 0.0], dtype=float),
            half_width=0.5 * footprint.width_m,
            half_length=0.5 * footprint.length_m,
            body_offset=float(footprint.center_offset_m),
            obstacle_form=OBS_NONE
            if cost_av is None
            else (OBS_POTENTIAL if cost_av.formulation == "potential" else OBS_GAUSSIAN),
            omax=int(cost_av.max_obstacles) if cost_av is not None else 0,
            **cost_obstacle_arrays(obstacles if cost_av is not None else ()),
            obstacle_influence=float(av.influence_m) if av is not None else 0.0,
            obstacle_weight=float(av.weight) if av is not None else 0.0,
            obstacle_epsilon=float(av.epsilon_m2) if av is not None else 0.0,
            obstacle_sigma_x=float(av.sigma_m[0]) if av is not None else 1.0,
            obstacle_sigma_y=float(av.sigma_m[1]) if av is not None else 1.0,
            detour=self._detour,
            obstacle_margin=float(av.margin_m) if av is not None else 0.0,
            detour_ramp=float(av.detour_ramp_m) if av is not None else 0.0,
            nsel=0,
            osel=np.zeros(n_ob, dtype=np.int64),
            odist=np.zeros(n_ob),
            oproj=np.zeros((n_ob, 2)),
            refs=np.zeros((N + 1, 4)),
            refw=np.zeros((N + 1, 8)),
            s_arr=np.zeros(N + 1),
            v_arr=np.zeros(N + 1),
            follow_s=np.zeros(N + 1),
            follow_v=np.zeros(N + 1),
            e_ref=np.zeros(N + 1),
            Xbar=np.zeros((N, nx)),
            Ubar=np.zeros((N, nu)),
            F=np.zeros((N, nx)),
            dw=np.zeros((7, nx + nu + 1, nx + nu + 1)),
            sub_x=np.zeros((N, nx)),
            sub_f=np.zeros((N, nx)),
            sub_a=np.zeros((N, nx, nx)),
            sub_b=np.zeros((N, nx, nu)),
            vlin=np.zeros(N + 1),
            s_lin=np.zeros(N + 1),
            rlin=np.zeros((N + 1, 4)),
        )
        self._qp = new_stage_qp(problem, n_orow)
        self._work = new_condensed_work(problem, settings, n_orow)
        #: what the compiled step is compiled for (numba compiles one per spec, then caches it)
        needed = StepSpec.needed_by(self._asm, self._work)
        if step_spec is not None and not step_spec.covers(needed):
            raise ValueError(f"step_spec {step_spec} lacks what this problem needs: a step {needed.describe()}")
        self.step_spec = needed if step_spec is None else step_spec
        self._step_fn = control_step(self.step_spec)
        _announce_compile(self._step_fn, f" for the {type(model).__name__} {self.step_spec.describe()}")
        self._info = np.zeros(4)
        self._asm_struct, self._qp_struct = self._asm.struct(), self._qp.struct()
        self._step = CompiledStep(self._asm_struct, self._qp_struct, self._work.struct(), self._sides, self._info)
        self._step_struct = self._step.struct()
        self._noX = np.zeros((N + 1, nx))
        self._noU = np.zeros((N, nu))
        #: the inputs a first step with a plan rolls out, and the plan's arc lengths (see _run)
        self._rollout_U = np.zeros((N, nu))
        self._plan_s = np.zeros(N + 1)
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
                    step_spec=self.step_spec,  # its own (fewer rows) would be another compile
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
        sides = self._sides.copy()
        for stage in (STAGE_ALL,) if self.solver == "condensed" else (STAGE_LINEARIZE, STAGE_COST):
            self._step_fn(
                self._step_struct, x, 0.0, 0.0, np.zeros(self.nu), self._noX, self._noU, MODE_NO_PLAN, stage, out
            )
        self._sides[:] = sides
        # the car-following references (a lane blocked ahead, a speed cap) come in mid-run: the
        # step that first needs them would load them (the next step recomputes the references)
        a = self._asm
        a.follow_s[:] = a.s_arr
        a.follow_v[:] = a.v_arr
        self._step_fn(
            self._step_struct, x, 0.0, 0.0, np.zeros(self.nu), self._noX, self._noU, MODE_NO_PLAN, STAGE_FOLLOW, out
        )
        follow_references(a.s_arr, a.v_arr, None, 0.0, self.dt_s, 1.0)  # its compiled loop, loaded

    # -- obstacles and road (the properties from LtvMpc) ---------------------------------------
    def set_road(self, road: Road) -> None:
        """As :meth:`LtvMpc.set_road`: the compiled step reads the new edges from its tables."""
        self._road = checked_road(self._road, road)
        self._asm.road_left[...] = road.left_m
        self._asm.road_right[...] = road.right_m
        self._asm.road_margin[0] = road.margin_m
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
        """As :meth:`LtvMpc.set_speed_cap <mpcdrive.control.python_mpc.PythonLtvMpc.set_speed_cap>` (the step
        then runs in two stages, the capped references placed between them)."""
        self._speed_cap = checked_speed_cap(v_mps, decel_mps2, self._follow_decel)
        if self._relaxed is not None:
            self._relaxed.set_speed_cap(v_mps, decel_mps2)

    def set_obstacle_relations(self, relations) -> None:
        """As :meth:`LtvMpc.set_obstacle_relations <mpcdrive.control.mpc.PythonLtvMpc.set_obstacle_relations>`."""
        if self.avoidance is None:
            if relations:
                raise ValueError("this controller was built without obstacles: it has no obstacle rows")
            return
        self.avoidance.set_relations(relations)
        if self._relaxed is not None:
            self._relaxed.set_obstacle_relations(relations)

    def set_longitudinal_plan(self, s_m, v_mps) -> None:
        """As :meth:`LtvMpc.set_longitudinal_plan <mpcdrive.control.mpc.PythonLtvMpc.set_longitudinal_plan>`
        (the step then runs in two stages, the plan's references placed between them)."""
        self._plan = checked_plan(s_m, v_mps, self.N)
        if self._relaxed is not None:
            self._relaxed.set_longitudinal_plan(s_m, v_mps)

    def set_obstacles(self, obstacles) -> None:
        """Replace the obstacles, as :meth:`LtvMpc.set_obstacles <mpcdrive.control.python_mpc.PythonLtvMpc.set_obstacles>`
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
            self._load_cost_obstacles(obstacles)
        avoidance.obstacles = tuple(obstacles)
        if self._relaxed is not None:  # the relax rung avoids the same obstacles
            self._relaxed.set_obstacles(obstacles)

    def _load_cost_obstacles(self, obstacles) -> None:
        """The compiled obstacle cost's arrays for ``obstacles``: written in place where their
        shapes are the same, else a new assembly struct (a recorded trajectory of another
        length, polygons of more vertices)."""
        arrays = cost_obstacle_arrays(obstacles)
        if all(getattr(self._asm, k).shape == v.shape for k, v in arrays.items()):
            for k, v in arrays.items():
                getattr(self._asm, k)[...] = v
            return
        self._asm = replace(self._asm, **arrays)
        self._asm_struct = self._asm.struct()
        self._step = replace(self._step, assembly=self._asm_struct)
        self._step_struct = self._step.struct()

    # -- warm start: initial_warm and _check_state from TrackingWarmStart ---------------------
    def _load_sides(self, sides: tuple) -> np.ndarray:
        """The side memory array of ``WarmStart.sides`` (untouched without a detour)."""
        arr = self._sides
        if self._detour:
            arr[:] = SIDE_NONE
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
        step = self._step_struct
        plan = self._plan
        if (
            last == STAGE_SOLVE
            and self._rows is None
            and self._lateral is None
            and self._speed_cap is None
            and plan is None
        ):
            code = self._step_fn(step, x, s_guess, t_s, u_prev, X, U, mode, STAGE_ALL, out)
            if self._detour:
                return code, tuple((j, int(v)) for j, v in enumerate(sides) if v != SIDE_NONE)
            return code, warm_sides
        code = self._step_fn(step, x, s_guess, t_s, u_prev, X, U, mode, STAGE_LINEARIZE, out)
        if code != 0:
            return code, warm_sides
        a, qp = self._asm, self._qp
        s_plan = None if plan is None else plan_arc_lengths(plan[0], a.s_arr[0], self._plan_s)
        if mode == MODE_NO_PLAN and plan is not None:
            # no plan of its own to linearize along (a first step): roll out the inputs of the
            # plan's references, as LtvMpc does, not those of the speed profile's (placed first:
            # a car braking hard for a crossing was linearized running on at the profile's
            # speed, and the rows made along that asked for slacks the solution did not need)
            a.follow_s[:] = s_plan
            a.follow_v[:] = plan[1]
            self._step_fn(step, x, s_guess, t_s, u_prev, X, U, mode, STAGE_FOLLOW, out)
            U = self._rollout_U
            U[...] = qp.uref
            code = self._step_fn(step, x, s_guess, t_s, u_prev, X, U, MODE_ROLLOUT, STAGE_LINEARIZE, out)
            if code != 0:
                return code, warm_sides
        a.e_ref[...] = 0.0
        if plan is not None:  # the plan's references
            a.s_arr[:] = s_plan
            a.v_arr[:] = plan[1]
        new_sides = warm_sides
        s_max = None
        if self._rows is not None:
            memory = AvoidanceMemory(dict(warm_sides))
            terms = self._rows.terms(t_s, x, qp.Xlin, a.s_arr, memory, qp.lane_lo, qp.lane_hi)
            qp.rowa[...] = terms.rows_a
            qp.rowb[...] = terms.rows_b
            if terms.lane_lo is not None and terms.lane_hi is not None:
                narrow_road_rows(qp.lane_lo, qp.lane_hi, qp.lane_dlo, qp.lane_dhi, terms.lane_lo, terms.lane_hi)
            if terms.e_ref is not None:
                a.e_ref[...] = terms.e_ref
            s_max = terms.s_max
            new_sides = tuple(sorted(memory.sides.items()))
        if s_max is not None or self._speed_cap is not None or plan is not None:
            # car following: the references approach the stop line behind the obstacle blocking
            # the lane ahead and move on with its prediction; and a speed cap (as LtvMpc.prepare);
            # a plan's references are placed in any case
            cap, decel = self._speed_cap or (math.inf, self._follow_decel)
            follow = follow_references(a.s_arr, a.v_arr, s_max, float(self.model.speed(x)), self.dt_s, decel, cap)
            if follow is None and plan is not None:
                follow = (a.s_arr, a.v_arr)
            if follow is not None:
                a.follow_s[:] = follow[0]
                a.follow_v[:] = follow[1]
                self._step_fn(step, x, s_guess, t_s, u_prev, X, U, mode, STAGE_FOLLOW, out)
        if self._lateral is not None:
            a.e_ref[...] += np.asarray(self._lateral(a.s_arr), float)
        code = self._step_fn(step, x, s_guess, t_s, u_prev, X, U, mode, last, out)
        return code, new_sides

    def prepare(self, x, warm: WarmStart, around=None, s_m: float | None = None) -> StepData:
        """The stage QP of one step, as :meth:`LtvMpc.prepare <mpcdrive.control.python_mpc.PythonLtvMpc.prepare>`
        gives it (:class:`~mpcdrive.control.mpc_base.StepData`) but assembled by the compiled step:
        projection, references, linearization, road rows, obstacle rows or cost terms, per-stage
        input bounds. ``around=(X, U)`` re-linearizes at an SQP iterate. The stage QP is the one
        the compiled step solves, valid until the controller's next step; a step whose model or
        references are not finite gives NaN dynamics (any solver then fails it)."""
        x = self._check_state(x)
        u_prev = self._check_warm(warm)
        N, nx, nu = self.N, self.nx, self.nu
        if around is not None:
            X, U, mode = around[0], around[1], MODE_ITERATE
            s_guess = projection_guess(warm) if s_m is None else float(s_m)
        elif warm.X is not None and warm.U is not None:
            X, U, mode, s_guess = warm.X, warm.U, MODE_SHIFTED_PLAN, projection_guess(warm)
        else:
            X, U, mode, s_guess = self._noX, self._noU, MODE_NO_PLAN, projection_guess(warm)
        X = np.ascontiguousarray(X, dtype=float)
        U = np.ascontiguousarray(U, dtype=float)
        if X.shape != (N + 1, nx) or U.shape != (N, nu):
            raise ValueError(f"warm plan must be X ({N + 1}, {nx}) and U ({N}, {nu}), got {X.shape} and {U.shape}")
        self._weigh_steering(self._qp, x)
        code, sides = self._run(
            x, s_guess, float(warm.t_s), u_prev, X, U, mode, warm.sides, np.empty(self._out_size), last=STAGE_COST
        )
        qp, info = self._qp, self._info
        if code != 0:  # a non-finite model or references: no usable stage QP
            qp.c[...] = math.nan
        return StepData(x, float(info[0]), float(info[1]), float(info[2]), qp, self._asm.Ubar, sides)

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
        self._weigh_steering(self._qp, x)
        code, new_sides = self._run(
            x,
            projection_guess(warm),
            t_s,
            u_prev,
            X,
            U,
            MODE_SHIFTED_PLAN if has_plan else MODE_NO_PLAN,
            warm.sides,
            out,
        )
        N, nx, nu = self.N, self.nx, self.nu
        cfg = self.config
        it = 1
        e_y, e_psi = info[1], info[2]
        cap = cfg.sqp_max_time_s  # real-time mode only (None: the iteration cap alone)
        t_qp = time.perf_counter() - t0  # the last QP's time: no new QP that would end past the cap
        while code == 0 and it < cfg.sqp_max_iterations and (cap is None or time.perf_counter() - t0 + t_qp < cap):
            t1 = time.perf_counter()
            U_it = out[self._o_U : self._o_R].reshape(N, nu)
            if float(np.max(np.abs(U_it - self._asm.Ubar))) < cfg.sqp_tol:
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
        refs = self._qp.xref.copy()
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
