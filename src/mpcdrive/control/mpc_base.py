"""What the two implementations of the tracking LTV-MPC share: :class:`LtvMpc`, their base.

Each step: project the measured state onto the path, place the horizon references, linearize
the discrete model (at the current state and frozen over the horizon -- the paper's ``paper``
mode -- or along the previous plan shifted by one step -- ``trajectory``, the default), write
the numbers into the QP built once at construction, solve warm-started, check the status, and
fall back deliberately when the solve fails.

Here: the step's data (:class:`StepData`), the step that hands a stage QP to a solver and falls
back (:class:`StageQpSolve`), the base class :class:`LtvMpc`, the solver and assembly names, and
the warning and the check that say when the compiled step or the condensed solver does not
cover a problem. The implementations subclass :class:`LtvMpc`: the Python assembly
(:mod:`~mpcdrive.control.python_mpc`) and the compiled one (:mod:`~mpcdrive.control.compiled_mpc`).
This module imports neither; :mod:`mpcdrive.control.mpc`, which imports both, hands
:class:`LtvMpc` the choice between them (:func:`set_implementation_chooser`).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np

from ..models.base import VehicleModel
from ..ocp.avoidance import Avoidance, AvoidanceConfig
from ..ocp.problem import MpcProblem
from ..ocp.stage_qp import StageQp, steering_weight_factor, weigh_steering
from ..paths.base import ReferencePath
from ..scene.footprint import Footprint
from ..scene.obstacles import Obstacle
from ..scene.road import Road
from ..scene.world import Scene
from ..solvers.osqp_backend import OsqpBackend, OsqpSettings
from ..solvers.projected_gradient import ProjectedGradientBackend, ProjectedGradientSettings
from ..types import ControlOutput, SolveResult, WarmStart
from .base import TrackingWarmStart
from .fallback import FallbackLadder
from .mpc_config import MpcConfig

if TYPE_CHECKING:
    from ..ocp.qp import LtvQp
    from ..solvers.condensed_setup import CondensedSettings
    from .condensed_backend import CondensedBackend


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
    controller that covers the problem, an instance of one of two subclasses that differ only in
    who assembles each step's stage QP (``assembly``; the choice is
    :func:`mpcdrive.control.mpc.implementation_for`'s):

    - :class:`~mpcdrive.control.compiled_mpc.CompiledLtvMpc` (``compiled``, the default wherever it
      covers the problem): the whole step in numba-compiled code;
    - :class:`~mpcdrive.control.python_mpc.PythonLtvMpc` (``python``): the same stage QP
      assembled in Python, for any model, path, speed reference and obstacle.

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
        choose = _implementation_for
        if choose is None:  # pragma: no cover (importing mpcdrive.control sets it)
            raise RuntimeError("LtvMpc has no implementations to choose from: import mpcdrive.control")
        return super().__new__(
            choose(
                model,
                path,
                problem,
                config,
                solver,
                scene=scene,
                obstacles=obstacles,
                avoidance=avoidance,
                footprint=footprint,
                assembly=assembly,
            )
        )

    #: the factor the stage QP's steering weights carry now (:meth:`_weigh_steering`)
    _steer_factor = 1.0

    def _weigh_steering(self, qp: StageQp, x: np.ndarray) -> None:
        """The steering's weights of this step in ``qp`` (``R``, ``Rc``), for the measured state
        ``x``: the problem's, grown above ``config.steer_weight_speed_mps``
        (:func:`~mpcdrive.ocp.stage_qp.steering_weight_factor`); written only when they change."""
        speed = self.config.steer_weight_speed_mps
        if speed is None:
            return
        f = steering_weight_factor(float(self.model.speed(x)), speed)
        if f != self._steer_factor:
            weigh_steering(qp, self.problem, self.model.input_names.index("steer"), f)
            self._steer_factor = f

    # -- obstacles and road ---------------------------------------------------------------------
    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The obstacles the controller avoids (empty without avoidance)."""
        return () if self.avoidance is None else self.avoidance.obstacles

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


#: the class ``LtvMpc(...)`` builds, as a function of the constructor's arguments: set by
#: :mod:`mpcdrive.control.mpc` (:func:`~mpcdrive.control.mpc.implementation_for`) when
#: :mod:`mpcdrive.control` is imported
_implementation_for: Callable[..., type[LtvMpc]] | None = None


def set_implementation_chooser(choose: Callable[..., type[LtvMpc]]) -> None:
    """Have ``LtvMpc(...)`` build the class ``choose`` returns for its arguments (``model, path,
    problem, config, solver`` and the keywords ``scene, obstacles, avoidance, footprint,
    assembly``). The implementations subclass :class:`LtvMpc`, so the module that knows them
    (:mod:`mpcdrive.control.mpc`) hands the choice in; this one never imports them."""
    global _implementation_for
    _implementation_for = choose
