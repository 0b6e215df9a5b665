"""Linear time-varying MPC for path tracking (the paper's controller, done properly).

Each step: project the measured state onto the path, place the horizon references, linearize
the discrete model (at the current state and frozen over the horizon -- the paper's ``paper``
mode -- or along the previous plan shifted by one step -- ``trajectory``, the default), write
the numbers into the QP built once at construction, solve warm-started, check the status, and
fall back deliberately when the solve fails.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np

from ..models.base import VehicleModel
from ..models.discretize import Method, discrete_step_and_jacobians, rollout
from ..ocp.avoidance import Avoidance, AvoidanceConfig, AvoidanceMemory
from ..ocp.follow import follow_references
from ..ocp.friction import friction_bounds
from ..ocp.problem import MpcProblem
from ..ocp.road_rows import RoadRows
from ..ocp.stage_qp import StageQp, new_stage_qp
from ..paths.base import ReferencePath
from ..scene.footprint import Footprint
from ..scene.obstacles import Obstacle
from ..scene.road import Road, lin_arc_lengths, reach_first_step
from ..scene.world import Scene
from ..paths.reference import HorizonMode, horizon_arc_lengths, horizon_states
from ..paths.speed_profile import SpeedReference
from ..solvers.osqp_backend import OsqpBackend, OsqpSettings
from ..solvers.projected_gradient import ProjectedGradientBackend, ProjectedGradientSettings
from ..types import ControlOutput, SolveResult, WarmStart
from ..units import TWO_PI, wrap_angle
from .fallback import FallbackConfig, FallbackLadder
from .base import TrackingWarmStart, checked_obstacles, checked_road, checked_speed_cap, resolve_scene

if TYPE_CHECKING:
    from ..ocp.qp import LtvQp
    from .condensed import CondensedBackend
    from ..solvers.condensed_setup import CondensedSettings


def _shift_references(xref: np.ndarray, refs: np.ndarray, s_arr: np.ndarray, e: np.ndarray) -> None:
    """Shift the state references ``xref`` sideways by ``e`` (N+1,) [m] from the path points
    ``refs`` and turn their heading with the slope of the shift."""
    h = refs[:, 2]
    xref[:, 0] -= np.sin(h) * e
    xref[:, 1] += np.cos(h) * e
    xref[1:, 2] += np.arctan(np.diff(e) / np.maximum(np.diff(s_arr), 1e-9))


@dataclass(frozen=True)
class StepData:
    """One step as a controller's ``prepare`` gives it: the measured state ``x`` (nx,), its path
    coordinates ``s_m`` [m], ``e_y_m`` [m], ``e_psi_rad`` [rad], the step's stage QP ``qp``
    (:class:`~mpcdrive.ocp.stage_qp.StageQp`: the affine model, costs, bounds, road and
    obstacle rows and the linearization trajectory ``qp.Xlin``, which every solver consumes as
    it is), the linearization inputs ``Ubar`` (N, nu) and the passing sides for the next step.
    The arrays are the controller's, valid until its next step."""

    x: np.ndarray
    s_m: float
    e_y_m: float
    e_psi_rad: float
    qp: StageQp
    Ubar: np.ndarray
    sides: tuple = ()


@dataclass(frozen=True)
class MpcConfig:
    """How the tracking MPC builds its problem each step.

    linearization : ``trajectory`` (along the previous plan, shifted) or ``paper`` (at the
        current state and previous input, frozen over the horizon, eqs. 9-12);
    discretization : ``rk4``, ``euler`` (the paper) or ``exp`` (linearize, then discretize exactly:
        stable for stiff models such as the dynamic bicycle) for the prediction model;
    horizon : ``arc_length`` (references spaced by the distance driven at the reference speed) or
        ``paper`` (fixed ``horizon_step_m`` per step, the authors' code);
    v_ref_mps : reference speed [m/s] (the model's constant speed for 3-state models when None);
    speed_profile : reference speed along the path instead of a constant: a
        :class:`~mpcdrive.paths.SpeedReference`, any object with ``speed(s_m) -> v_mps`` (e.g.
        :class:`~mpcdrive.paths.SpeedProfile`); each horizon step
        then gets the profile's speed at its arc length, and a model with an ``accel`` input gets
        the profile's acceleration as input reference;
    feedforward : ``curvature`` (steering reference = the model's steady-state steering on the
        path curvature, so R does not fight the turn, and yaw reference = path heading minus the
        steady-state slip angle, since the centre of gravity moves along yaw + beta) or ``none``
        (the paper: ``u' R u`` and the path heading as yaw reference);
    projection_window_m : half-width of the arc-length window searched around the last s [m];
    sqp_max_iterations : QPs per step: 1 is the real-time iteration (one QP on the model and
        obstacle terms linearized along the shifted previous plan); more re-linearize at each new
        solution until the inputs move less than ``sqp_tol`` [input units] or ``sqp_max_iterations``
        QPs ran: an iteration cap, so a closed loop gives the same numbers on every machine;
    sqp_max_time_s : real-time mode, opt-in (default None: off): no SQP iteration starts that
        would end past this much wall time [s] (judged by the last one's time). The number of QPs
        per step then depends on the machine's speed and load, and so does the closed loop: a
        setting for a car with a deadline, never for tests, reproductions or sweeps.
    prediction_substeps : integration substeps per control step in the prediction model (stiff
        models such as the dynamic bicycle need them at long steps).
    fallback : what to do, in order, when a solve fails (:class:`~mpcdrive.control.fallback.FallbackConfig`).
    """

    linearization: Literal["trajectory", "paper"] = "trajectory"
    discretization: Method = "rk4"
    horizon: HorizonMode = "arc_length"
    horizon_step_m: float = 0.025
    v_ref_mps: float | None = None
    feedforward: Literal["curvature", "none"] = "curvature"
    projection_window_m: float = 2.0
    sqp_max_iterations: int = 1
    sqp_tol: float = 1e-4
    sqp_max_time_s: float | None = None
    speed_profile: SpeedReference | None = None
    prediction_substeps: int = 1
    fallback: FallbackConfig = FallbackConfig()

    def __post_init__(self):
        if self.linearization not in ("trajectory", "paper"):
            raise ValueError(f"linearization must be 'trajectory' or 'paper', got {self.linearization!r}")
        if self.discretization not in ("rk4", "euler", "exp"):
            raise ValueError(f"discretization must be 'rk4', 'euler' or 'exp', got {self.discretization!r}")
        if self.horizon not in ("arc_length", "paper"):
            raise ValueError(f"horizon must be 'arc_length' or 'paper', got {self.horizon!r}")
        if self.sqp_max_iterations < 1:
            raise ValueError(f"sqp_max_iterations must be >= 1, got {self.sqp_max_iterations}")
        if self.sqp_max_time_s is not None and not (
            isinstance(self.sqp_max_time_s, (int, float))
            and not isinstance(self.sqp_max_time_s, bool)
            and math.isfinite(self.sqp_max_time_s)
            and self.sqp_max_time_s > 0
        ):
            raise ValueError(
                f"sqp_max_time_s must be None (no wall-time cap) or a positive time [s], got {self.sqp_max_time_s!r}"
            )
        if self.feedforward not in ("curvature", "none"):
            raise ValueError(f"feedforward must be 'curvature' or 'none', got {self.feedforward!r}")
        if self.speed_profile is not None and not callable(getattr(self.speed_profile, "speed", None)):
            raise ValueError("speed_profile must have a speed(s_m) method")
        if int(self.prediction_substeps) != self.prediction_substeps or self.prediction_substeps < 1:
            raise ValueError(f"prediction_substeps must be a positive integer, got {self.prediction_substeps}")
        for name in ("horizon_step_m", "projection_window_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        if self.v_ref_mps is not None and not (
            isinstance(self.v_ref_mps, (int, float)) and math.isfinite(self.v_ref_mps)
        ):
            raise ValueError(f"v_ref_mps must be a finite number, got {self.v_ref_mps!r}")
        if not isinstance(self.fallback, FallbackConfig):
            raise ValueError(f"fallback must be a FallbackConfig, got {type(self.fallback).__name__}")


class StageQpSolve:
    """The step of a controller that assembles each step's stage QP (its ``prepare``, giving
    :class:`StepData` with the :class:`~mpcdrive.ocp.stage_qp.StageQp`) and hands it to a
    solver ``backend``: OSQP or projected gradient on the sparse layout ``qp`` (an
    :class:`~mpcdrive.ocp.qp.LtvQp`, written from the stage QP), or the condensed solver, which
    takes the stage QP as it is; with the SQP iterations of ``config`` and the fallback ladder
    after a failed solve. The solver only solves: it never rebuilds the problem and knows no
    model. Needs ``prepare``, ``qp``, ``backend``, ``config``, ``problem``, ``dt_s``,
    ``fallback`` and ``_du_step`` on the instance."""

    config: MpcConfig
    problem: MpcProblem
    dt_s: float
    qp: LtvQp
    backend: OsqpBackend | ProjectedGradientBackend | CondensedBackend
    fallback: FallbackLadder
    _du_step: np.ndarray

    def prepare(self, x, warm: WarmStart, around=None, s_m: float | None = None) -> StepData:
        raise NotImplementedError  # pragma: no cover

    def step(self, x, warm: WarmStart) -> ControlOutput:
        """Compute the command for measured state ``x`` (nx,) given the previous step's ``warm``."""
        t0 = time.perf_counter()
        d = self.prepare(x, warm)
        res = self._solve(d, warm)
        it = 1
        cap = self.config.sqp_max_time_s  # real-time mode only (None: the iteration cap alone)
        t_qp = time.perf_counter() - t0  # the last iteration's time: none that would end past the cap
        while it < self.config.sqp_max_iterations and res.ok and (cap is None or time.perf_counter() - t0 + t_qp < cap):
            dU = float(np.max(np.abs(res.U - d.Ubar)))
            if dU < self.config.sqp_tol:
                break
            t1 = time.perf_counter()
            d = self.prepare(x, warm, around=(res.X, res.U), s_m=d.s_m)
            res = self._solve(d, warm)
            it += 1
            t_qp = time.perf_counter() - t1
        return self.finish(d, warm, res, t0, it)

    def _solve(self, d: StepData, warm: WarmStart) -> SolveResult:
        backend = self.backend
        if not isinstance(backend, (OsqpBackend, ProjectedGradientBackend)):  # it takes the stage QP as it is
            return backend.solve_stage(d.qp, d.x, warm.u_prev)
        self.qp.load_stage(d.qp, d.x, warm.u_prev)
        # primal warm start: the linearization trajectory
        return backend.solve(d.qp.Xlin, d.Ubar)

    def finish(self, d: StepData, warm: WarmStart, res: SolveResult, t0: float, iterations: int = 1) -> ControlOutput:
        """Check the solve, pick the command (or fall back) and package the step's output."""
        t_next = warm.t_s + self.dt_s
        if res.ok and np.all(np.isfinite(res.U[0])):
            # exactly within the bounds, whatever the solver's tolerance
            u_prev = warm.u_prev
            lo, hi = d.qp.ulo[0], d.qp.uhi[0]  # the step's (the friction circle's, else the problem's)
            u = np.clip(np.clip(res.U[0], u_prev - self._du_step, u_prev + self._du_step), lo, hi)
            fallback = ""
            new_warm = WarmStart(s_m=d.s_m, u_prev=u, X=res.X, U=res.U, t_s=t_next, sides=d.sides)
            X_pred = res.X
        else:
            u, fallback, new_warm, X_pred = self.fallback.run(d, warm)
            new_warm = replace(new_warm, t_s=t_next, sides=d.sides)
        return ControlOutput(
            u=u,
            status=res.status,
            fallback=fallback,
            solve_time_s=time.perf_counter() - t0,
            s_m=d.s_m,
            e_y_m=d.e_y_m,
            e_psi_rad=d.e_psi_rad,
            X_pred=X_pred,
            refs=d.qp.xref.copy(),
            warm=new_warm,
            sqp_iterations=iterations,
        )


class FastPathUnavailable(UserWarning):
    """The compiled step or the condensed solver was asked for but does not cover the problem:
    the message names the reason and who assembles and solves the stage QP instead."""


#: the solvers of a controller's stage QP: the compiled condensed dual active-set solve (the
#: default), OSQP on the sparse layout of ``ocp.qp`` (the reference), the paper's projected
#: gradient descent
SOLVERS: tuple[str, ...] = ("condensed", "osqp", "projected_gradient")
#: who builds each step's stage QP: the compiled step where it covers the problem (``auto``)
ASSEMBLIES: tuple[str, ...] = ("auto", "compiled", "python")
Solver = Literal["condensed", "osqp", "projected_gradient"]
Assembly = Literal["auto", "compiled", "python"]


class LtvMpc(StageQpSolve, TrackingWarmStart):
    """Tracking LTV-MPC of ``model`` along ``path`` solving ``problem``: the one public
    controller.

    ``LtvMpc(model, path, problem, config, solver=..., scene=..., avoidance=...)`` returns the
    controller that covers the problem, an instance of one of two subclasses that differ only in who assembles each step's stage QP (``assembly``):

    - :class:`~mpcdrive.control.compiled_mpc.CompiledLtvMpc` (``compiled``, the default wherever it
      covers the problem): the whole step in numba-compiled code;
    - :class:`PythonLtvMpc` (``python``): the same stage QP assembled in Python, for any model,
      path, speed reference and obstacle.

    ``solver`` names who solves it: ``condensed`` (default: the compiled condensed dual
    active-set solver, exact), ``osqp`` (OSQP on the sparse layout, the reference), or
    ``projected_gradient`` (the paper's, Python assembly only). Each has its settings argument
    (``condensed_settings``, ``osqp_settings``, ``pg_settings``). ``assembly="python"`` or
    ``"compiled"`` asks for one assembly (``compiled`` raises a ValueError naming the reason where
    it does not cover the problem). Where the default cannot be used -- the compiled step does not
    cover the problem, or the condensed solver's limits exclude it (R + Rc singular, a slack
    without quadratic weight, more than ``condensed_settings.max_variables`` variables) -- a
    :class:`FastPathUnavailable` warning names the reason and what runs instead (the Python
    assembly; OSQP with ``osqp_settings``); no constraint or setting is ever dropped.
    ``backend_name`` names the solver that runs (``fast``: the condensed one; ``osqp``; ``pg``) and
    ``assembly`` who builds the QP. Both keep the body inside ``problem.road`` by the rule of
    :mod:`mpcdrive.scene.road`.

    scene : the world, given once (:class:`~mpcdrive.scene.Scene`: the road, the obstacles, the
    body), kept as :attr:`scene`, which :func:`~mpcdrive.sim.simulate` judges a drive against;
    its road becomes ``problem.road``. The older way names the parts: the road in
    ``problem.road``, ``obstacles=`` and ``footprint=`` (the scene is made of them; naming a part
    both ways is a ValueError unless it is the same). avoidance : how the obstacles enter the
    problem (see ``ocp.avoidance``). ``set_road`` and ``set_obstacles`` change what the problem
    keeps to from the next step on (a lane band, fresh predictions), never :attr:`scene`.
    """

    name = "ltv-mpc"
    backend_name = "osqp"
    #: who builds each step's stage QP
    assembly = "python"
    avoidance: Avoidance | None
    _road: Road | None
    #: the world the controller was built for (road, obstacles, body): what a run is judged against
    scene: Scene

    def __new__(
        cls,
        model: VehicleModel,
        path: ReferencePath,
        problem: MpcProblem,
        config: MpcConfig = MpcConfig(),
        solver: Solver = "condensed",
        *,
        scene: Scene | None = None,
        obstacles=(),
        avoidance: AvoidanceConfig | None = None,
        footprint: Footprint | None = None,
        condensed_settings: CondensedSettings | None = None,
        osqp_settings: OsqpSettings = OsqpSettings(),
        pg_settings: ProjectedGradientSettings = ProjectedGradientSettings(),
        assembly: Assembly = "auto",
        **options,
    ):
        if not isinstance(config, MpcConfig):
            raise ValueError(f"config must be an MpcConfig, got {type(config).__name__}")
        if cls is not LtvMpc:  # a subclass named directly (its own options go to its __init__)
            return super().__new__(cls)
        if options:
            raise TypeError(f"LtvMpc() got unexpected keyword arguments: {', '.join(sorted(options))}")
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        if assembly not in ASSEMBLIES:
            raise ValueError(f"assembly must be one of {', '.join(ASSEMBLIES)}, got {assembly!r}")
        if assembly == "python" or solver == "projected_gradient":
            return super().__new__(PythonLtvMpc)
        from .compiled_mpc import CompiledLtvMpc  # numba: loaded when a compiled controller may be built

        if assembly == "compiled":
            return super().__new__(CompiledLtvMpc)
        from .compiled_setup import fast_unsupported_reason

        problem, scene = resolve_scene(problem, scene, obstacles, footprint)
        reason = fast_unsupported_reason(
            model, path, problem, config, obstacles=scene.obstacles, avoidance=avoidance, solver="osqp"
        )
        if reason is None:
            return super().__new__(CompiledLtvMpc)
        warnings.warn(
            f"compiled step not used: {reason}; the stage QP is assembled in Python", FastPathUnavailable, stacklevel=2
        )
        return super().__new__(PythonLtvMpc)

    # -- obstacles and road ---------------------------------------------------------------------
    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The obstacles the controller avoids (empty without avoidance)."""
        return () if self.avoidance is None else tuple(self.avoidance.obstacles)

    @property
    def road(self) -> Road | None:
        """The road the body is kept inside (``problem.road``, or the last :meth:`set_road`)."""
        return self._road


def solver_in_reach(solver: str, problem: MpcProblem, settings: CondensedSettings, rows: bool) -> str:
    """The solver that solves ``problem``'s stage QPs (with obstacle rows when ``rows``) when
    ``solver`` is asked for: OSQP, with a :class:`FastPathUnavailable` warning naming the reason,
    where the condensed solver's limits exclude the problem."""
    if solver != "condensed":
        return solver
    from ..solvers.condensed_setup import condensed_unsupported_reason

    reason = condensed_unsupported_reason(problem, settings, rows)
    if reason is None:
        return solver
    warnings.warn(f"condensed solver not used: {reason}; OSQP solves the stage QP", FastPathUnavailable, stacklevel=3)
    return "osqp"


class PythonLtvMpc(LtvMpc):
    """:class:`LtvMpc` with each step's stage QP assembled here in Python: for any model, path,
    speed reference and obstacle (the compiled step, :class:`~mpcdrive.control.compiled_mpc.CompiledLtvMpc`,
    assembles the same QP for those it has a compiled form of), solved by the condensed solver
    (:mod:`mpcdrive.control.condensed`, which reads the stage QP as it is), OSQP or projected
    gradient descent (on the sparse QP of ``ocp.qp``, built here for those two only). Both are
    built once here and only updated in place in :meth:`step`.
    """

    #: who builds each step's stage QP
    assembly = "python"

    def __init__(
        self,
        model: VehicleModel,
        path: ReferencePath,
        problem: MpcProblem,
        config: MpcConfig = MpcConfig(),
        solver: Solver = "condensed",
        *,
        scene: Scene | None = None,
        obstacles=(),
        avoidance: AvoidanceConfig | None = None,
        footprint: Footprint | None = None,
        condensed_settings: CondensedSettings | None = None,
        osqp_settings: OsqpSettings = OsqpSettings(),
        pg_settings: ProjectedGradientSettings = ProjectedGradientSettings(),
        assembly: Assembly = "auto",
    ):
        problem, self.scene = resolve_scene(problem, scene, obstacles, footprint)
        obstacles, footprint = self.scene.obstacles, self.scene.footprint
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        if (problem.nx, problem.nu) != (model.nx, model.nu):
            raise ValueError(
                f"problem is sized nx={problem.nx}, nu={problem.nu} but the model has nx={model.nx}, nu={model.nu}"
            )
        self.model, self.path, self.problem, self.config = model, path, problem, config
        self.nx, self.nu, self.N = model.nx, model.nu, problem.N
        self.dt_s = problem.dt_s
        if config.v_ref_mps is not None:
            self.v_ref_mps = float(config.v_ref_mps)
        elif config.speed_profile is not None:
            self.v_ref_mps = float(config.speed_profile.speed(0.0))
        else:
            self.v_ref_mps = float(model.speed(np.zeros(model.nx)))
        if not np.isfinite(self.v_ref_mps):
            raise ValueError(f"reference speed must be finite, got {self.v_ref_mps}")
        self.avoidance: Avoidance | None = None
        if obstacles:
            avoidance = avoidance or AvoidanceConfig()
            if avoidance.formulation == "corridor" and problem.road is None:
                raise ValueError("the corridor formulation needs a road (MpcProblem.road / road.lane_width_m)")
            problem = replace(
                problem, obstacle_rows=avoidance.rows_per_step(footprint), position_cost=avoidance.uses_cost
            )
            self.problem = problem
            self.avoidance = Avoidance(
                avoidance, list(obstacles), path, footprint, problem.N, problem.dt_s, problem.road
            )
        if solver == "condensed":
            from ..solvers.condensed_setup import CondensedSettings

            settings = condensed_settings if condensed_settings is not None else CondensedSettings()
            solver = solver_in_reach(solver, problem, settings, bool(problem.obstacle_rows))  # type: ignore[assignment]
        if solver == "condensed":
            from .condensed import CondensedBackend

            self.backend = CondensedBackend(problem, settings)  # it reads the stage QP as it is
            self.backend_name = "fast"
        else:  # the sparse QP, written from the stage QP each step
            from ..ocp.qp import LtvQp  # scipy.sparse: imported when an OSQP controller is built

            self.qp = LtvQp(problem)
            if solver == "projected_gradient":
                self.backend = ProjectedGradientBackend(self.qp, pg_settings)
                self.backend_name = "pg"
            else:
                self.backend = OsqpBackend(self.qp, osqp_settings)
                self.backend_name = "osqp"
        self._accel_index = list(model.input_names).index("accel") if "accel" in model.input_names else None
        N, nx, nu = self.N, self.nx, self.nu
        # the stage QP each step writes (what the solvers consume) and the linearization points
        self._stage = new_stage_qp(problem, int(problem.obstacle_rows))
        self._Wq = self._stage.We.copy()  # the problem's state weights, before an obstacle cost's model
        self._Xbar = np.zeros((N, nx))
        self._Ubar = np.zeros((N, nu))
        # the road's bounds of the reference point, per step (the body inside: scene.road)
        self.footprint = footprint
        self._road_rows = RoadRows.empty(N)
        self._du_step = problem.du_max_per_s * problem.dt_s  # (nu,) largest input change per step
        self._road = problem.road
        self._lateral = None
        #: (cap [m/s], braking to it [m/s^2]) of set_speed_cap, or None
        self._speed_cap: tuple[float, float] | None = None
        self._follow_decel = (
            self.avoidance.config.follow_decel_mps2 if self.avoidance else AvoidanceConfig().follow_decel_mps2
        )
        self._friction = friction_bounds(problem, model)
        self.fallback = FallbackLadder(self, config.fallback, footprint=footprint, road=problem.road)

    # -- obstacles and road (the properties from LtvMpc) ---------------------------------------
    def set_road(self, road: Road) -> None:
        """Keep the body inside ``road`` from the next step on (e.g. the lanes a decision layer
        allows now); it must have the knots of the problem's road. The QP is not rebuilt."""
        self._road = checked_road(self._road, road)
        if self.avoidance is not None:
            self.avoidance.road = road
        self.fallback.road = road

    def set_lateral_reference(self, offset) -> None:
        """Track the path shifted sideways by ``offset(s)`` [m] (a callable of the arc lengths
        [m] of the horizon, positive left; e.g. a lane change's ramp), its heading turned with the
        slope; None: the path itself."""
        if offset is not None and not callable(offset):
            raise ValueError("the lateral reference must be a callable of arc length, or None")
        self._lateral = offset

    def set_speed_cap(self, v_mps: float | None, decel_mps2: float | None = None) -> None:
        """Cap the horizon references' speed at ``v_mps`` [m/s] from the next step on (reached by
        braking at ``decel_mps2`` [m/s^2], default the avoidance's ``follow_decel_mps2``; e.g. a
        decision layer turning out past an obstacle slowly); None: the free references."""
        self._speed_cap = checked_speed_cap(v_mps, decel_mps2, self._follow_decel)

    def set_obstacles(self, obstacles) -> None:
        """Replace the obstacles, e.g. with fresh predictions of moving ones each step; the QP is
        not rebuilt (``AvoidanceConfig.max_obstacles``, nearest first, fixes its rows, so any
        number may be given). Poses and motions are on the controller's clock: an obstacle is
        at ``pose_at(warm.t_s)`` at the step that receives ``warm``. Index ``j`` must keep naming
        the same obstacle from call to call: the passing side chosen for it is remembered in
        ``warm.sides`` under that index. Only a controller built with obstacles has the rows."""
        avoidance, obstacles = checked_obstacles(self.avoidance, obstacles)
        avoidance.obstacles = list(obstacles)

    # -- one control step (step, _solve and finish from StageQpSolve; initial_warm, _check_state
    # and _check_warm from TrackingWarmStart) -------------------------------------------------
    def prepare(self, x, warm: WarmStart, around=None, s_m: float | None = None) -> StepData:
        """Projection, horizon references, linearization and obstacle terms for measured state
        ``x``: the part of a step every solver of this problem shares. ``around=(X, U)``
        re-linearizes at a new iterate (SQP). Arrays are views of work buffers, valid until the
        next call."""
        x = self._check_state(x)
        self._check_warm(warm)
        cfg, model = self.config, self.model
        N, dt = self.N, self.dt_s
        if s_m is None:
            s0, e_y = self.path.project(x[:2], warm.s_m, cfg.projection_window_m)
        else:
            s0, e_y = self.path.project(x[:2], s_m, cfg.projection_window_m)
        e_psi = wrap_angle(x[2] - float(self.path.heading(s0)))

        # references over the horizon
        s_arr, v_arr = self._horizon(s0)
        refs = self._references(s_arr, v_arr, x[2], cfg.speed_profile is not None)
        st = self._stage
        xref, uref = st.xref, st.uref
        # linearization points
        Xbar, Ubar = self._Xbar, self._Ubar
        if around is not None:
            Xbar[0] = x
            Xbar[1:] = around[0][1:N]
            Ubar[:] = around[1]
        elif cfg.linearization == "paper":
            Xbar[:] = x
            Ubar[:] = warm.u_prev
        elif warm.X is None or warm.U is None:
            Ubar[:] = uref
            Xbar[:] = rollout(model, x, Ubar, dt, cfg.discretization, cfg.prediction_substeps)[:-1]
        else:
            Xbar[0] = x
            Xbar[1:] = warm.X[2:]
            Xbar[1:, 2] += TWO_PI * np.round((x[2] - warm.X[1, 2]) / TWO_PI)
            Ubar[:-1] = warm.U[1:]
            Ubar[-1] = warm.U[-1]
        Fbar, Ad, Bd = discrete_step_and_jacobians(model, Xbar, Ubar, dt, cfg.discretization, cfg.prediction_substeps)
        c = Fbar - np.einsum("kij,kj->ki", Ad, Xbar) - np.einsum("kij,kj->ki", Bd, Ubar)
        Xlin = st.Xlin
        Xlin[:N] = Xbar
        Xlin[N] = Fbar[-1]
        u_lo = u_hi = None
        if self._friction is not None:
            u_lo, u_hi = self._friction.fill(Xlin, Ubar, warm.u_prev)
        terms = None
        sides = warm.sides
        road = self._road
        rows = None
        if road is not None:
            # the body inside the road, linearized where the linearization trajectory has the car
            # (its arc lengths, not the references', which run on ahead of a car held back: rows
            # from a stretch of the bend it is not on let it gain ground sideways) and in its yaw
            s_lin = lin_arc_lengths(Xlin, s0)
            refs_lin = horizon_states(self.path, s_lin, x[2])
            rows = self._road_rows.fill(road, self.footprint, s_lin, refs_lin, Xlin)
        if self.avoidance is not None:
            memory = AvoidanceMemory(dict(warm.sides))
            terms = self.avoidance.terms(
                warm.t_s, x, Xlin, s_arr, memory, None if rows is None else rows.lo, None if rows is None else rows.hi
            )
            if rows is not None:
                rows.narrow(terms.lane_lo, terms.lane_hi)
            sides = tuple(sorted(memory.sides.items()))
        s_max = None if terms is None else terms.s_max
        if s_max is not None or self._speed_cap is not None:
            # car following: the references approach the stop line behind the obstacle blocking
            # the lane ahead and move on with its prediction; and a speed cap (set_speed_cap)
            cap, decel = self._speed_cap or (math.inf, self._follow_decel)
            follow = follow_references(s_arr, v_arr, s_max, float(model.speed(x)), dt, decel, cap)
            if follow is not None:
                refs = self._references(*follow, x[2], True)
        if terms is not None:
            if terms.e_ref is not None and np.any(terms.e_ref):
                # the paper's detour: shift the reference sideways, turn its heading with the slope
                _shift_references(xref, refs, s_arr, terms.e_ref)
        if self._lateral is not None:  # a lateral reference (set_lateral_reference): the same shift
            _shift_references(xref, refs, s_arr, np.asarray(self._lateral(s_arr), float))
        # lane normals at the (undetoured) centreline where the road rows are linearized
        if st.lane:
            at = refs if rows is None else refs_lin
            yaw = at[1:, 2]
            st.lane_n[:, 0] = -np.sin(yaw)
            st.lane_n[:, 1] = np.cos(yaw)
            st.lane_b[:] = np.einsum("ki,ki->k", st.lane_n, at[1:, :2])
            if rows is not None:  # the first step's bounds hold where f(x, Ubar[0]) puts the car
                e1 = float(st.lane_n[0] @ Fbar[0, :2] - st.lane_b[0])
                reach_first_step(rows.lo, rows.hi, rows.dlo, rows.dhi, e1, float(Fbar[0, 2] - Xlin[1, 2]))
                st.lane_lo[:] = rows.lo
                st.lane_hi[:] = rows.hi
                st.lane_dlo[:] = rows.dlo
                st.lane_dhi[:] = rows.dhi
        # the stage QP: the affine model, the costs (an obstacle cost's convex model 1/2 p'Hp +
        # g.p on the positions, in the form x'We x - 2 qt'x), the input bounds, the obstacle rows
        st.A[...] = Ad
        st.B[...] = Bd
        st.c[...] = c
        st.We[...] = self._Wq
        np.einsum("kij,kj->ki", self._Wq, xref[1:], out=st.qt)
        if terms is not None and terms.H is not None and terms.g is not None:
            st.We[:, :2, :2] += 0.5 * terms.H
            st.qt[:, :2] -= 0.5 * terms.g
        st.ulo[...] = self.problem.u_min if u_lo is None else u_lo
        st.uhi[...] = self.problem.u_max if u_hi is None else u_hi
        if st.nrow and terms is not None and terms.rows_a is not None and terms.rows_b is not None:
            st.rowa[...] = terms.rows_a
            st.rowb[...] = terms.rows_b
        return StepData(x, float(s0), float(e_y), float(e_psi), st, Ubar, sides)

    def _references(self, s_arr: np.ndarray, v_arr: np.ndarray, yaw_now: float, accel_ff: bool) -> np.ndarray:
        """Fill the state and input references for path points at arc lengths ``s_arr`` (N+1,)
        driven at speeds ``v_arr`` (N+1,) [m/s] (with ``accel_ff`` the speed changes become the
        acceleration reference); returns the path states ``[x, y, yaw, kappa]`` (N+1, 4)."""
        refs = horizon_states(self.path, s_arr, yaw_now)
        xr, ur = self.model.reference(refs[:, :3], refs[:, 3], v_arr, self.config.feedforward == "curvature")
        st = self._stage
        st.xref[:] = xr
        st.uref[:] = ur[: self.N]
        if accel_ff and self._accel_index is not None:
            st.uref[:, self._accel_index] += np.diff(v_arr) / self.dt_s
        return refs

    def _horizon(self, s0: float) -> tuple[np.ndarray, np.ndarray]:
        """(N+1,) arc lengths [m] and reference speeds [m/s] of the horizon references. With a
        speed profile the references move along the path as the profile does in time (exactly, via
        its ``arc_length_after``; else trapezoidal in the speed, two fixed-point passes) and each
        step gets the profile's speed there."""
        cfg, N, dt = self.config, self.N, self.dt_s
        prof = cfg.speed_profile
        if prof is None:
            s_arr = horizon_arc_lengths(s0, N, cfg.horizon, dt, self.v_ref_mps, cfg.horizon_step_m)
            return s_arr, np.full(N + 1, self.v_ref_mps)
        after = getattr(prof, "arc_length_after", None) if cfg.horizon == "arc_length" else None
        if callable(after):  # optional on a SpeedReference
            s_arr = np.asarray(after(s0, dt * np.arange(N + 1)), float)
            return s_arr, np.asarray(prof.speed(s_arr), float)
        v = np.full(N + 1, float(prof.speed(s0)))
        for _ in range(2):
            s_arr = horizon_arc_lengths(s0, N, cfg.horizon, dt, 0.5 * (v[1:] + v[:-1]), cfg.horizon_step_m)
            v = np.asarray(prof.speed(s_arr), float)
        return s_arr, v
