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
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..models.base import VehicleModel
from ..models.discretize import Method, discrete_step_and_jacobians, rollout
from ..ocp.problem import MpcProblem
from ..paths.base import Path
from ..paths.reference import HorizonMode, horizon_arc_lengths, horizon_states
from ..solvers.osqp_backend import OsqpBackend, OsqpSettings
from ..types import ControlOutput, SolveResult, WarmStart
from ..units import TWO_PI, wrap_angle

FALLBACK_SHIFTED_PLAN = "shifted_plan"
FALLBACK_HOLD = "hold_last"


@dataclass(frozen=True)
class StepData:
    """What :meth:`LtvMpc.prepare` computes for one step (arrays in the model's units).

    x : (nx,) measured state; s_m, e_y_m, e_psi_rad : its path coordinates; xref : (N+1, nx) and
    uref : (N, nu) references; Xbar, Ubar : (N, nx), (N, nu) linearization points; Fbar : (N, nx)
    the model's prediction from them; Ad, Bd, c : the affine model x+ = Ad x + Bd u + c;
    lane_normal : (N, 2), lane_offset : (N,) the lane rows (used when the problem has a lane).
    """

    x: np.ndarray
    s_m: float
    e_y_m: float
    e_psi_rad: float
    xref: np.ndarray
    uref: np.ndarray
    Xbar: np.ndarray
    Ubar: np.ndarray
    Fbar: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    c: np.ndarray
    lane_normal: np.ndarray
    lane_offset: np.ndarray


@dataclass(frozen=True)
class MpcConfig:
    """How the tracking MPC builds its problem each step.

    linearization : ``trajectory`` (along the previous plan, shifted) or ``paper`` (at the
        current state and previous input, frozen over the horizon, eqs. 9-12);
    discretization : ``rk4`` or ``euler`` (the paper) for the prediction model;
    horizon : ``arc_length`` (references spaced by the distance driven at the reference speed) or
        ``paper`` (fixed ``horizon_step_m`` per step, the authors' code);
    v_ref_mps : reference speed [m/s] (the model's constant speed for 3-state models when None);
    feedforward : ``curvature`` (steering reference = the model's steady-state steering on the
        path curvature, so R does not fight the turn, and yaw reference = path heading minus the
        steady-state slip angle, since the centre of gravity moves along yaw + beta) or ``none``
        (the paper: ``u' R u`` and the path heading as yaw reference);
    projection_window_m : half-width of the arc-length window searched around the last s [m].
    """

    linearization: Literal["trajectory", "paper"] = "trajectory"
    discretization: Method = "rk4"
    horizon: HorizonMode = "arc_length"
    horizon_step_m: float = 0.025
    v_ref_mps: float | None = None
    feedforward: Literal["curvature", "none"] = "curvature"
    projection_window_m: float = 2.0

    def __post_init__(self):
        if self.linearization not in ("trajectory", "paper"):
            raise ValueError(f"linearization must be 'trajectory' or 'paper', got {self.linearization!r}")
        if self.discretization not in ("rk4", "euler"):
            raise ValueError(f"discretization must be 'rk4' or 'euler', got {self.discretization!r}")
        if self.horizon not in ("arc_length", "paper"):
            raise ValueError(f"horizon must be 'arc_length' or 'paper', got {self.horizon!r}")
        if self.feedforward not in ("curvature", "none"):
            raise ValueError(f"feedforward must be 'curvature' or 'none', got {self.feedforward!r}")


class LtvMpc:
    """Tracking LTV-MPC of ``model`` along ``path`` solving ``problem`` with OSQP.

    model : the controller's prediction model (states start with x, y, yaw; a 4th state is the
    speed [m/s]); the QP is built once here and only updated in place in :meth:`step`.
    """

    name = "ltv-mpc"
    backend_name = "osqp"

    def __init__(
        self,
        model: VehicleModel,
        path: Path,
        problem: MpcProblem,
        config: MpcConfig = MpcConfig(),
        solver_settings: OsqpSettings = OsqpSettings(),
    ):
        if (problem.nx, problem.nu) != (model.nx, model.nu):
            raise ValueError(
                f"problem is sized nx={problem.nx}, nu={problem.nu} but the model has nx={model.nx}, nu={model.nu}"
            )
        self.model, self.path, self.problem, self.config = model, path, problem, config
        self.nx, self.nu, self.N = model.nx, model.nu, problem.N
        self.dt_s = problem.dt_s
        if config.v_ref_mps is not None:
            self.v_ref_mps = float(config.v_ref_mps)
        else:
            self.v_ref_mps = float(model.speed(np.zeros(model.nx)))
        if not np.isfinite(self.v_ref_mps):
            raise ValueError(f"reference speed must be finite, got {self.v_ref_mps}")
        from ..ocp.qp import LtvQp  # scipy.sparse: imported when an OSQP controller is built

        self.qp = LtvQp(problem)
        self.backend = OsqpBackend(self.qp, solver_settings)
        N, nx, nu = self.N, self.nx, self.nu
        # per-step work buffers
        self._xref = np.zeros((N + 1, nx))
        self._uref = np.zeros((N, nu))
        self._Xbar = np.zeros((N, nx))
        self._Ubar = np.zeros((N, nu))
        self._Xws = np.zeros((N + 1, nx))
        self._lane_n = np.zeros((N, 2))
        self._lane_b = np.zeros(N)

    # -- warm start ---------------------------------------------------------------------------
    def initial_warm(self, x0) -> WarmStart:
        """Warm start of the first step: a global projection of x0, zero previous input."""
        x0 = self._check_state(x0)
        s0, _ = self.path.project(x0[:2])
        return WarmStart(s_m=float(s0), u_prev=np.zeros(self.nu))

    def _check_state(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape != (self.nx,):
            raise ValueError(f"state must have shape ({self.nx},) {self.model.state_names}, got {x.shape}")
        bad = [n for n, v in zip(self.model.state_names, x) if not math.isfinite(v)]
        if bad:
            raise ValueError(f"state field(s) {', '.join(bad)} not finite: {dict(zip(self.model.state_names, x.tolist()))}")
        return x

    # -- one control step -----------------------------------------------------------------------
    def step(self, x, warm: WarmStart) -> ControlOutput:
        """Compute the command for measured state ``x`` (nx,) given the previous step's ``warm``."""
        t0 = time.perf_counter()
        d = self.prepare(x, warm)
        self.qp.update(d.x, d.Ad, d.Bd, d.c, d.xref, d.uref, warm.u_prev, d.lane_normal, d.lane_offset)
        # primal warm start: the linearization trajectory, closed with its last prediction
        Xws = self._Xws
        Xws[: self.N] = d.Xbar
        Xws[self.N] = d.Fbar[-1]
        res = self.backend.solve(Xws, d.Ubar)
        return self.finish(d, warm, res, t0)

    def prepare(self, x, warm: WarmStart) -> StepData:
        """Projection, horizon references and linearization for measured state ``x``: the part of
        a step every solver of this problem shares. Arrays are views of work buffers, valid until
        the next call."""
        x = self._check_state(x)
        cfg, model = self.config, self.model
        N, dt = self.N, self.dt_s
        s0, e_y = self.path.project(x[:2], warm.s_m, cfg.projection_window_m)
        e_psi = wrap_angle(x[2] - float(self.path.heading(s0)))

        # references over the horizon
        s_arr = horizon_arc_lengths(s0, N, cfg.horizon, dt, self.v_ref_mps, cfg.horizon_step_m)
        refs = horizon_states(self.path, s_arr, x[2])
        xref, uref = self._xref, self._uref
        xref[:, :3] = refs[:, :3]
        if self.nx >= 4:
            xref[:, 3] = self.v_ref_mps
        if cfg.feedforward == "curvature":
            steer_ss, slip_ss = model.steady_state(refs[:, 3], self.v_ref_mps)
            uref[:, 0] = steer_ss[:N]
            xref[:, 2] -= slip_ss
        # linearization points
        Xbar, Ubar = self._Xbar, self._Ubar
        if cfg.linearization == "paper":
            Xbar[:] = x
            Ubar[:] = warm.u_prev
        elif warm.X is None or warm.U is None:
            Ubar[:] = uref
            Xbar[:] = rollout(model, x, Ubar, dt, cfg.discretization)[:-1]
        else:
            Xbar[0] = x
            Xbar[1:] = warm.X[2:]
            Xbar[1:, 2] += TWO_PI * np.round((x[2] - warm.X[1, 2]) / TWO_PI)
            Ubar[:-1] = warm.U[1:]
            Ubar[-1] = warm.U[-1]
        Fbar, Ad, Bd = discrete_step_and_jacobians(model, Xbar, Ubar, dt, cfg.discretization)
        c = Fbar - np.einsum("kij,kj->ki", Ad, Xbar) - np.einsum("kij,kj->ki", Bd, Ubar)
        if self.qp.lane:
            yaw = refs[1:, 2]
            self._lane_n[:, 0] = -np.sin(yaw)
            self._lane_n[:, 1] = np.cos(yaw)
            self._lane_b[:] = np.einsum("ki,ki->k", self._lane_n, refs[1:, :2])
        return StepData(x, float(s0), float(e_y), float(e_psi), xref, uref, Xbar, Ubar, Fbar, Ad, Bd, c,
                        self._lane_n, self._lane_b)

    def finish(self, d: StepData, warm: WarmStart, res: SolveResult, t0: float) -> ControlOutput:
        """Check the solve, pick the command (or fall back) and package the step's output."""
        pb = self.problem
        if res.ok and np.all(np.isfinite(res.U[0])):
            u = np.clip(res.U[0], pb.u_min, pb.u_max)
            fallback = ""
            new_warm = WarmStart(s_m=d.s_m, u_prev=u, X=res.X, U=res.U)
            X_pred = res.X
        else:
            u, fallback, new_warm, X_pred = self._fallback(d.x, d.s_m, warm)
        return ControlOutput(
            u=u,
            status=res.status,
            fallback=fallback,
            solve_time_s=time.perf_counter() - t0,
            s_m=d.s_m,
            e_y_m=d.e_y_m,
            e_psi_rad=d.e_psi_rad,
            X_pred=X_pred,
            refs=d.xref.copy(),
            warm=new_warm,
        )

    def _fallback(self, x, s0, warm: WarmStart):
        return plan_fallback(self.problem, x, s0, warm)


def plan_fallback(problem: MpcProblem, x, s0: float, warm: WarmStart):
    """Deliberate fallback when the QP did not solve: the previous plan shifted by one step,
    or (no plan) the last applied input; either is kept within the input and rate bounds.

    Returns ``(u (nu,), fallback name, WarmStart for the next step, X_pred (N+1, nx))``."""
    pb = problem
    rate = pb.du_max_per_s * pb.dt_s
    if warm.U is not None and warm.X is not None and warm.U.shape[0] > 1:
        U = np.vstack([warm.U[1:], warm.U[-1:]])
        X = np.vstack([warm.X[1:], warm.X[-1:]])
        u_raw, name = U[0], FALLBACK_SHIFTED_PLAN
    else:
        U = X = None
        u_raw, name = warm.u_prev, FALLBACK_HOLD
    u = np.clip(np.clip(u_raw, warm.u_prev - rate, warm.u_prev + rate), pb.u_min, pb.u_max)
    X_pred = X if X is not None else np.repeat(np.asarray(x, float)[None, :], pb.N + 1, axis=0)
    return u, name, WarmStart(s_m=float(s0), u_prev=u, X=X, U=U), X_pred
