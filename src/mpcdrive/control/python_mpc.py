"""The tracking LTV-MPC with each step's stage QP assembled in Python: :class:`PythonLtvMpc`.

One of the two implementations of :class:`~mpcdrive.control.mpc.LtvMpc` (the other, the
compiled step, is :mod:`~mpcdrive.control.compiled_mpc`): for any model, path, speed reference
and obstacle, and the reference the compiled one is checked against. It and the compiled one
share the base of :mod:`~mpcdrive.control.mpc_base` and import nothing of each other.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..models.base import VehicleModel
from ..models.discretize import discrete_step_and_jacobians, rollout
from ..ocp.avoidance import Avoidance, AvoidanceConfig, AvoidanceMemory
from ..ocp.follow import follow_references
from ..ocp.friction import friction_bounds
from ..ocp.problem import MpcProblem
from ..ocp.road_rows import RoadRows
from ..ocp.stage_qp import new_stage_qp
from ..paths.base import ReferencePath
from ..paths.reference import horizon_arc_lengths, horizon_states
from ..scene.footprint import Footprint
from ..scene.road import Road, lin_arc_lengths, reach_first_step
from ..scene.world import Scene
from ..solvers.osqp_backend import OsqpBackend, OsqpSettings
from ..solvers.projected_gradient import ProjectedGradientBackend, ProjectedGradientSettings
from ..types import WarmStart
from ..units import TWO_PI, wrap_angle
from .base import (
    checked_obstacles,
    checked_plan,
    checked_road,
    checked_speed_cap,
    plan_arc_lengths,
    projection_guess,
    resolve_scene,
)
from .fallback import FallbackLadder
from .mpc_base import SOLVERS, Assembly, LtvMpc, Solver, StepData, solver_in_reach
from .mpc_config import MpcConfig

if TYPE_CHECKING:
    from ..solvers.condensed_setup import CondensedSettings


def _shift_references(xref: np.ndarray, refs: np.ndarray, s_arr: np.ndarray, e: np.ndarray) -> None:
    """Shift the state references ``xref`` sideways by ``e`` (N+1,) [m] from the path points
    ``refs`` and turn their heading with the slope of the shift."""
    h = refs[:, 2]
    xref[:, 0] -= np.sin(h) * e
    xref[:, 1] += np.cos(h) * e
    xref[1:, 2] += np.arctan(np.diff(e) / np.maximum(np.diff(s_arr), 1e-9))


class PythonLtvMpc(LtvMpc):
    """:class:`LtvMpc` with each step's stage QP assembled here in Python: for any model, path,
    speed reference and obstacle (the compiled step, :class:`~mpcdrive.control.compiled_mpc.CompiledLtvMpc`,
    assembles the same QP for those it has a compiled form of), solved by the condensed solver
    (:mod:`mpcdrive.control.condensed_backend`, which reads the stage QP as it is), OSQP or projected
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
            from .condensed_backend import CondensedBackend

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
        #: (s (N+1,) [m], v (N+1,) [m/s]) of set_longitudinal_plan, or None
        self._plan: tuple[np.ndarray, np.ndarray] | None = None
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

    def set_obstacle_relations(self, relations) -> None:
        """Keep the planned maneuver's relation to each obstacle it names (obstacle index -> (N,)
        ``REL_*`` codes of steps 1..N, :meth:`~mpcdrive.ocp.avoidance.Avoidance.set_relations`)
        from the next step on; None: the controller's own decisions."""
        if self.avoidance is None:
            if relations:
                raise ValueError("this controller was built without obstacles: it has no obstacle rows")
            return
        self.avoidance.set_relations(relations)

    def set_longitudinal_plan(self, s_m, v_mps) -> None:
        """Track a planned longitudinal motion at the next step: the horizon references at arc
        lengths ``s_m`` (N+1,) [m] (from the car's own at step 0) driven at ``v_mps`` (N+1,)
        [m/s], e.g. a maneuver planner's, instead of the speed profile's; an obstacle's stop line
        still holds them back (car following). ``None, None``: the speed profile again."""
        self._plan = checked_plan(s_m, v_mps, self.N)

    def set_obstacles(self, obstacles) -> None:
        """Replace the obstacles, e.g. with fresh predictions of moving ones each step; the QP is
        not rebuilt (``AvoidanceConfig.max_obstacles``, nearest first, fixes its rows, so any
        number may be given). Poses and motions are on the controller's clock: an obstacle is
        at ``pose_at(warm.t_s)`` at the step that receives ``warm``. Index ``j`` must keep naming
        the same obstacle from call to call: the passing side chosen for it is remembered in
        ``warm.sides`` under that index. Only a controller built with obstacles has the rows."""
        avoidance, obstacles = checked_obstacles(self.avoidance, obstacles)
        avoidance.obstacles = tuple(obstacles)

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
            s0, e_y = self.path.project(x[:2], projection_guess(warm), cfg.projection_window_m)
        else:
            s0, e_y = self.path.project(x[:2], s_m, cfg.projection_window_m)
        e_psi = wrap_angle(x[2] - float(self.path.heading(s0)))
        self._weigh_steering(self._stage, x)

        # references over the horizon: a plan's (from the car's arc length), else the profile's
        if self._plan is not None:
            s_arr = plan_arc_lengths(self._plan[0], s0)
            v_arr = self._plan[1]
        else:
            s_arr, v_arr = self._horizon(s0)
        refs = self._references(s_arr, v_arr, x[2], cfg.speed_profile is not None or self._plan is not None)
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
            st.lane_t[:, 0] = at[1:, 3] * st.lane_n[:, 1]  # the road's turn per metre moved along it
            st.lane_t[:, 1] = -at[1:, 3] * st.lane_n[:, 0]
            if rows is not None:  # the first step's bounds hold where f(x, Ubar[0]) puts the car
                e1 = float(st.lane_n[0] @ Fbar[0, :2] - st.lane_b[0])
                dw1 = float(Fbar[0, 2] - Xlin[1, 2] - st.lane_t[0] @ (Fbar[0, :2] - Xlin[1, :2]))
                reach_first_step(rows.lo, rows.hi, rows.dlo, rows.dhi, e1, dw1)
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
