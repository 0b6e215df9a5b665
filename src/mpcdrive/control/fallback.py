"""The fallback ladder: what the tracking MPC does, explicitly and in order, when a solve fails.

A ladder is a sequence of rungs tried one after the other until one yields a command:

* ``relax``: re-solve the same step on a second QP (built once, next to the main one) whose
  constraints are relaxed: no input-rate limits, no hard state bounds (speed limits), the lane's
  slack ``relax_slack_factor`` times cheaper, and a looser solver tolerance with twice the
  iterations. Fails when that solve fails too.
* ``shifted_plan``: the previous plan shifted by one step. Fails when there is no plan, or when
  the plan has already been shifted ``N - 1`` times (nothing of it is left).
* ``brake``: controlled braking. Models with a speed state ``v`` and an ``accel`` input
  decelerate at ``brake_decel_mps2`` (default: the vehicle's full braking, the lower bound of
  its ``accel`` input; never past standstill, never into reverse) with the
  steering held (``brake_steering="hold"``) or brought back to straight at the steering-rate
  limit (``"straighten"``); constant-speed models hold the last steering angle. Always succeeds.
* ``hold_last``: the last applied input. Always succeeds.

The ``relax`` rung, whose plan comes from a problem without rate limits and with a cheap lane
slack, is applied only when it is safer than braking: its predicted trajectory keeps the
footprint clear of every obstacle at its predicted pose and inside the road when the controller
has one (``road``), or, where it does not, it does so for longer than the braking
plan does (a car closing in from behind can make braking the worse choice). Otherwise the ladder goes on to the next rung, in the end to braking: a fallback never
makes a failed step worse than braking would (``check_plans``). (A shifted plan was solved under
the full constraints one step before; checking it against recorded traffic that does not react to
the car made it brake where the plan was safe, measured on CommonRoad scenarios.)

Whatever the rung, the command is clipped to the input bounds and to the rate limit from the
previous input, and it is never NaN. The rung used is logged per step (``ControlOutput.fallback``,
the ``fallback`` column of ``trajectory.csv``) and counted in the metrics. A ladder must end with
a rung that always succeeds (``brake`` or ``hold_last``), and only there.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from ..ocp.problem import MpcProblem
from ..ocp.stage_qp import StageQp
from ..scene.footprint import Footprint
from ..scene.geometry import shape_distance
from ..scene.road import Road
from ..units import wrap_angle
from ..solvers.osqp_backend import OsqpBackend, OsqpSettings
from ..types import (  # noqa: F401  (the rung names are re-exported here, their home for controllers)
    FALLBACK_BRAKE,
    FALLBACK_HOLD,
    FALLBACK_KINDS,
    FALLBACK_RELAX,
    FALLBACK_SHIFTED_PLAN,
    SolveResult,
    WarmStart,
)

if TYPE_CHECKING:
    from ..ocp.qp import LtvQp
    from .condensed_backend import CondensedBackend

#: rungs that always yield a command
TERMINAL_FALLBACKS: tuple[str, ...] = (FALLBACK_BRAKE, FALLBACK_HOLD)
DEFAULT_LADDER: tuple[str, ...] = (FALLBACK_RELAX, FALLBACK_SHIFTED_PLAN, FALLBACK_BRAKE)


def check_ladder(ladder) -> tuple[str, ...]:
    """The ladder as a tuple, or ValueError naming what is wrong with it."""
    if isinstance(ladder, str):
        raise ValueError(f"fallback must be a list of rungs, got the string {ladder!r}")
    steps = tuple(ladder)
    if not steps:
        raise ValueError(f"fallback ladder is empty; end it with one of {', '.join(TERMINAL_FALLBACKS)}")
    unknown = [s for s in steps if s not in FALLBACK_KINDS]
    if unknown:
        raise ValueError(f"unknown fallback {unknown[0]!r} (known: {', '.join(FALLBACK_KINDS)})")
    dup = [s for i, s in enumerate(steps) if s in steps[:i]]
    if dup:
        raise ValueError(f"fallback {dup[0]!r} appears twice in the ladder")
    if steps[-1] not in TERMINAL_FALLBACKS:
        raise ValueError(
            f"fallback ladder must end with {' or '.join(TERMINAL_FALLBACKS)} (a rung that always yields "
            f"a command), got {list(steps)}"
        )
    early = [s for s in steps[:-1] if s in TERMINAL_FALLBACKS]
    if early:
        raise ValueError(f"fallback {early[0]!r} always succeeds, so it must be the last rung, got {list(steps)}")
    return steps


@dataclass(frozen=True)
class FallbackConfig:
    """The fallback ladder of a tracking MPC (see the module docstring).

    ladder : rungs in order; brake_decel_mps2 : braking deceleration [m/s^2] (> 0; None: the
    vehicle's full braking, the lower bound of the ``accel`` input, 1 m/s^2 if it has none);
    brake_steering : ``hold`` or ``straighten``; relax_slack_factor : how many times cheaper the
    lane slack is in the relaxed problem (>= 1); check_plans : apply the ``relax`` rung only when its
    predicted trajectory is collision-free and inside the road, or stays so longer than braking's.
    """

    ladder: tuple[str, ...] = DEFAULT_LADDER
    brake_decel_mps2: float | None = None
    brake_steering: Literal["hold", "straighten"] = "hold"
    relax_slack_factor: float = 100.0
    check_plans: bool = True

    def __post_init__(self):
        object.__setattr__(self, "ladder", check_ladder(self.ladder))
        if self.brake_decel_mps2 is not None and not (
            isinstance(self.brake_decel_mps2, (int, float))
            and math.isfinite(self.brake_decel_mps2)
            and self.brake_decel_mps2 > 0
        ):
            raise ValueError(f"brake_decel_mps2 must be a positive finite number, got {self.brake_decel_mps2!r}")
        if self.brake_steering not in ("hold", "straighten"):
            raise ValueError(f"brake_steering must be 'hold' or 'straighten', got {self.brake_steering!r}")
        if not (
            isinstance(self.relax_slack_factor, (int, float))
            and math.isfinite(self.relax_slack_factor)
            and self.relax_slack_factor >= 1
        ):
            raise ValueError(f"relax_slack_factor must be a finite number >= 1, got {self.relax_slack_factor!r}")


def relaxed_problem(pb: MpcProblem, slack_factor: float) -> MpcProblem:
    """``pb`` without rate limits and hard state bounds, with a ``slack_factor`` times cheaper lane slack."""
    return dataclasses.replace(
        pb,
        du_max_per_s=np.full(pb.nu, np.inf),
        x_min=np.full(pb.nx, -np.inf),
        x_max=np.full(pb.nx, np.inf),
        lane_slack_weight=pb.lane_slack_weight / slack_factor,
        lane_slack_weight_l1=pb.lane_slack_weight_l1 / slack_factor,
    )


def relaxed_settings(s) -> OsqpSettings:
    """Looser tolerance (10x, at least 1e-4) and twice the iterations (OSQP's defaults relaxed when
    the controller uses another solver)."""
    if not isinstance(s, OsqpSettings):
        s = OsqpSettings()
    return dataclasses.replace(
        s, eps_abs=max(10 * s.eps_abs, 1e-4), eps_rel=max(10 * s.eps_rel, 1e-4), max_iter=2 * s.max_iter
    )


class FallbackLadder:
    """Runs a :class:`FallbackConfig` ladder for one controller (the relaxed QP is built once here).

    ``controller`` provides ``model``, ``problem``, ``N``, ``dt_s``, ``config.discretization`` and,
    for ``relax``, ``backend`` (the built-in rung solves the step's stage QP for the relaxed
    problem with the controller's solver: the condensed one on the stage QP posed for it, twice
    the iterations; else OSQP on a second sparse QP, looser tolerance) -- unless ``relax`` is
    given: a callable ``(d, warm)``
    returning ``(u, WarmStart, X_pred)`` from the controller's own relaxed solve, or None when it
    fails. The rungs read ``x`` and ``s_m`` of the step data ``d`` (and, for the built-in
    ``relax``, its stage QP and linearization: :class:`~mpcdrive.control.mpc_base.StepData`).
    """

    def __init__(
        self,
        controller,
        config: FallbackConfig,
        relax=None,
        *,
        footprint: Footprint = Footprint(),
        road: Road | None = None,
    ):
        self.ctrl = controller
        self.config = config
        self._relax_fn = relax
        self.footprint = footprint
        self.road = road
        pb = controller.problem
        model = controller.model
        self._rate = pb.du_max_per_s * pb.dt_s  # (nu,) largest change per step
        names_x, names_u = tuple(model.state_names), tuple(model.input_names)
        self._iv = names_x.index("v") if "v" in names_x else None
        self._ia = names_u.index("accel") if "accel" in names_u else None
        self._is = names_u.index("steer") if "steer" in names_u else None
        self.brake_decel_mps2 = config.brake_decel_mps2
        if self.brake_decel_mps2 is None:
            full = -float(pb.u_min[self._ia]) if self._ia is not None else math.nan
            self.brake_decel_mps2 = full if math.isfinite(full) and full > 0 else 1.0
        self.relax_qp: LtvQp | None = None
        self.relax_backend: OsqpBackend | CondensedBackend | None = None
        self._relaxed_pb: MpcProblem | None = None
        #: (the controller's stage QP, it posed for the relaxed problem), made at the first relax
        self._posed: tuple[StageQp, StageQp] | None = None
        if FALLBACK_RELAX in config.ladder and relax is None:
            self._relaxed_pb = rpb = relaxed_problem(pb, config.relax_slack_factor)
            backend = controller.backend
            if getattr(backend, "name", None) == "condensed":
                # the controller's own solver, on the step's stage QP posed for the relaxed problem
                from .condensed_backend import CondensedBackend

                s = backend.settings
                self.relax_backend = CondensedBackend(rpb, dataclasses.replace(s, max_iter=2 * s.max_iter))
            else:
                from ..ocp.qp import LtvQp  # scipy.sparse: imported when an OSQP controller is built

                self.relax_qp = LtvQp(rpb)
                self.relax_backend = OsqpBackend(self.relax_qp, relaxed_settings(controller.backend.settings))

    # -- helpers --------------------------------------------------------------------------------
    def _bound(self, u_raw: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        """Clip to the rate limit from ``u_prev`` and to the input bounds; NaN -> previous input."""
        pb = self.ctrl.problem
        u = np.where(np.isfinite(u_raw), u_raw, u_prev)
        u = np.clip(u, u_prev - self._rate, u_prev + self._rate)
        return np.clip(u, pb.u_min, pb.u_max)

    def _brake_input(self, x: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        dt = self.ctrl.dt_s
        u = u_prev.astype(float).copy()
        if self._iv is not None and self._ia is not None:
            v = float(x[self._iv])
            a = min(self.brake_decel_mps2, abs(v) / dt)  # stop at standstill, not beyond
            u[self._ia] = -math.copysign(a, v) if v != 0.0 else 0.0
        if self._is is not None and self.config.brake_steering == "straighten":
            u[self._is] = 0.0  # reached at the rate limit by _bound
        return self._bound(u, u_prev)

    # -- rungs ----------------------------------------------------------------------------------
    def _relax(self, d, warm: WarmStart):
        if self._relax_fn is not None:
            got = self._relax_fn(d, warm)
            if got is None:
                return None
            u, new_warm, X = got
            u = self._bound(u, warm.u_prev)
            return u, dataclasses.replace(new_warm, u_prev=u), X
        qp, be = self.relax_qp, self.relax_backend
        assert be is not None and self._relaxed_pb is not None  # built in __init__ for relax without relax_fn
        # obstacles stay in the relaxed problem (their slacks keep it feasible)
        res: SolveResult
        if qp is None:  # the condensed solver: the step's stage QP as it is, the relaxed constants
            assert not isinstance(be, OsqpBackend)
            if self._posed is None or self._posed[0] is not d.qp:
                self._posed = (d.qp, d.qp.posed_for(self._relaxed_pb))
            res = be.solve_stage(self._posed[1], d.x, warm.u_prev)
        else:
            assert isinstance(be, OsqpBackend)
            qp.load_stage(d.qp, d.x, warm.u_prev)
            res = be.solve(d.qp.Xlin, d.Ubar)
        if not (res.ok and np.all(np.isfinite(res.U)) and np.all(np.isfinite(res.X))):
            return None
        u = self._bound(res.U[0], warm.u_prev)
        return u, WarmStart(s_m=d.s_m, u_prev=u, X=res.X, U=res.U), res.X

    def _shifted_plan(self, d, warm: WarmStart):
        if warm.U is None or warm.X is None or warm.U.shape[0] < 2 or warm.plan_age >= self.ctrl.N - 1:
            return None
        U = np.vstack([warm.U[1:], warm.U[-1:]])
        X = np.vstack([warm.X[1:], warm.X[-1:]])
        u = self._bound(U[0], warm.u_prev)
        return u, WarmStart(s_m=d.s_m, u_prev=u, X=X, U=U, plan_age=warm.plan_age + 1), X

    def _brake(self, d, warm: WarmStart):
        from ..models.discretize import discrete_step

        c = self.ctrl
        N = c.N
        U = np.empty((N, c.nu))
        X = np.empty((N + 1, c.nx))
        X[0] = d.x
        u_prev = warm.u_prev
        for k in range(N):  # the braking plan, for the log and the next step's warm start
            U[k] = u_prev = self._brake_input(X[k], u_prev)
            X[k + 1] = discrete_step(c.model, X[k], U[k], c.dt_s, c.config.discretization)
        if not np.all(np.isfinite(X)):
            X = np.repeat(d.x[None, :], N + 1, axis=0)
        return U[0].copy(), WarmStart(s_m=d.s_m, u_prev=U[0].copy(), X=X, U=U), X

    def _hold_last(self, d, warm: WarmStart):
        u = self._bound(warm.u_prev, warm.u_prev)
        X = np.repeat(d.x[None, :], self.ctrl.N + 1, axis=0)
        return u, WarmStart(s_m=d.s_m, u_prev=u), X

    def first_unsafe_step(self, X: np.ndarray, t0_s: float) -> float:
        """The first k at which the footprint along the predicted states ``X`` (K, nx) [x m, y m,
        yaw rad, ...] (state k at time ``t0_s + k dt``) touches an obstacle the controller avoids,
        at the obstacle's predicted pose, or has part of its body outside the road (``road``, by
        :meth:`Road.body_excess_m`, when there is one); ``inf`` when it never does."""
        X = np.asarray(X, float)
        if X.ndim != 2 or not np.all(np.isfinite(X[:, :3])):
            return 0.0
        av = getattr(self.ctrl, "avoidance", None)
        obstacles = list(av.obstacles) if av is not None else []
        dt = self.ctrl.dt_s
        path = self.ctrl.path
        s_m = None
        for k, x in enumerate(X):
            if obstacles:
                body = self.footprint.polygon(float(x[0]), float(x[1]), float(x[2]))
                t = t0_s + k * dt
                if any(ob.present(t) and shape_distance(body, ob.at(t)) <= 0.0 for ob in obstacles):
                    return float(k)
            if self.road is not None:
                s_m, e_y = path.project(x[:2], s_guess=s_m)
                rel = wrap_angle(float(x[2]) - float(path.heading(s_m)))
                if float(self.road.body_excess_m(s_m, e_y, float(path.curvature(s_m)), rel, self.footprint)) > 0.0:
                    return float(k)
        return math.inf

    # -- the ladder -----------------------------------------------------------------------------
    def run(self, d, warm: WarmStart) -> tuple[np.ndarray, str, WarmStart, np.ndarray]:
        """(command (nu,), rung name, next warm start, predicted states (N+1, nx)) for step data
        ``d`` (:class:`~mpcdrive.control.mpc_base.StepData`, or anything with ``x`` and ``s_m`` when
        ``relax`` was given) after a failed solve."""
        rungs = {
            FALLBACK_RELAX: self._relax,
            FALLBACK_SHIFTED_PLAN: self._shifted_plan,
            FALLBACK_BRAKE: self._brake,
            FALLBACK_HOLD: self._hold_last,
        }
        braking_unsafe_at = None
        for name in self.config.ladder:
            got = rungs[name](d, warm)
            if got is not None:
                u, new_warm, X_pred = got
                if not np.all(np.isfinite(u)):
                    continue
                if self.config.check_plans and name == FALLBACK_RELAX:
                    unsafe_at = self.first_unsafe_step(X_pred, warm.t_s)
                    if unsafe_at < math.inf:
                        if braking_unsafe_at is None:
                            braking_unsafe_at = self.first_unsafe_step(self._brake(d, warm)[2], warm.t_s)
                        if unsafe_at <= braking_unsafe_at:
                            continue  # its plan collides or leaves the road no later than braking's
                return u, name, new_warm, X_pred
        raise RuntimeError("internal error: the fallback ladder yielded no finite command")  # pragma: no cover
