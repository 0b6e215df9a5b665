"""Typed results shared by the layers (numpy only).

Every array carries its unit in the docstring; angles in radians, SI units throughout.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: solver status words used in logs and ``trajectory.csv``
STATUS_OK = "ok"
STATUS_INACCURATE = "inaccurate"
STATUS_INFEASIBLE = "infeasible"
STATUS_MAX_ITER = "max_iter"
STATUS_FAILED = "failed"
STATUS_BAD_STATE = "bad_state"
#: a plant step between two solves of a slower controller (``simulate(control_period_s=...)``):
#: no solve happened, the input is held or follows the plan; neither a solve nor a failure
STATUS_HELD = "held"

#: fallback rungs, as logged in ``SimResult.fallback`` and ``trajectory.csv`` (``control.fallback``)
FALLBACK_RELAX = "relax"
FALLBACK_SHIFTED_PLAN = "shifted_plan"
FALLBACK_BRAKE = "brake"
FALLBACK_HOLD = "hold_last"
#: every rung, in the order a report lists them
FALLBACK_KINDS: tuple[str, ...] = (FALLBACK_RELAX, FALLBACK_SHIFTED_PLAN, FALLBACK_BRAKE, FALLBACK_HOLD)


class ScenarioWarning(UserWarning):
    """Something in a scenario that is legal but probably not what the user meant (an angle in a
    ``_deg`` field that looks like radians, a speed far beyond the model's range, ...). The run
    goes on; the CLI prints each as one line on stderr."""


@dataclass(frozen=True)
class SolveResult:
    """One solve of a finite-horizon problem.

    status : solver status word (``ok`` when solved to tolerance)
    X : (N+1, nx) predicted states; U : (N, nu) planned inputs
    cost : objective value; iterations : solver iterations; solve_time_s : wall time [s]
    """

    status: str
    X: np.ndarray
    U: np.ndarray
    cost: float
    iterations: int
    solve_time_s: float

    @property
    def ok(self) -> bool:
        return self.status in (STATUS_OK, STATUS_INACCURATE)


# The two per-step results below are frozen dataclasses with a hand-written __init__: the
# generated one of a frozen dataclass sets each field through object.__setattr__ (1.2 and
# 0.8 us); this one writes the instance dict once (0.5 and 0.4 us). Fields and defaults are the
# declared ones (tests/test_types.py checks that they agree).
_set_attr = object.__setattr__


@dataclass(frozen=True, init=False)
class WarmStart:
    """What a controller needs from its previous step; returned by ``step`` and passed back.

    s_m : arc length of the last projection [m]; u_prev : (nu,) last applied input;
    X, U : (N+1, nx), (N, nu) last plan (None before the first solve);
    t_s : time of the next step [s] (moving obstacles are predicted from it);
    sides : passing side chosen per obstacle index, ((index, +1 left / -1 right / 0 blocked), ...).
    plan_age : steps since that plan was solved (0 = solved this step; a fallback that shifts the
    plan adds one).
    """

    s_m: float
    u_prev: np.ndarray
    X: np.ndarray | None = None
    U: np.ndarray | None = None
    t_s: float = 0.0
    sides: tuple = ()
    plan_age: int = 0

    def __init__(self, s_m, u_prev, X=None, U=None, t_s=0.0, sides=(), plan_age=0):
        _set_attr(
            self,
            "__dict__",
            {"s_m": s_m, "u_prev": u_prev, "X": X, "U": U, "t_s": t_s, "sides": sides, "plan_age": plan_age},
        )


@dataclass(frozen=True, init=False)
class ControlOutput:
    """Result of one controller step.

    u : (nu,) command to apply [rad, m/s^2]; status : solver status word;
    fallback : name of the fallback used ("" when the solve succeeded);
    solve_time_s : wall time of the whole step [s]; s_m, e_y_m, e_psi_rad : path errors at the
    measured state; X_pred : (N+1, nx) predicted states; refs : (N+1, nx) horizon references;
    warm : state to pass to the next call; sqp_iterations : QPs solved this step.
    """

    u: np.ndarray
    status: str
    fallback: str
    solve_time_s: float
    s_m: float
    e_y_m: float
    e_psi_rad: float
    X_pred: np.ndarray
    refs: np.ndarray
    warm: WarmStart
    sqp_iterations: int = 1

    def __init__(self, u, status, fallback, solve_time_s, s_m, e_y_m, e_psi_rad, X_pred, refs, warm, sqp_iterations=1):
        _set_attr(
            self,
            "__dict__",
            {
                "u": u,
                "status": status,
                "fallback": fallback,
                "solve_time_s": solve_time_s,
                "s_m": s_m,
                "e_y_m": e_y_m,
                "e_psi_rad": e_psi_rad,
                "X_pred": X_pred,
                "refs": refs,
                "warm": warm,
                "sqp_iterations": sqp_iterations,
            },
        )


@dataclass(frozen=True)
class SimResult:
    """Complete log of a closed-loop run; K plant steps of ``dt_s``.

    t_s : (K,) time [s]; x : (K, nx) true (plant) states when each command was computed;
    u : (K, nu) applied inputs; x_final : (nx,) state after the last step;
    s_m, e_y_m, e_psi_rad : (K,) path coordinates of the true state [m, m, rad];
    yaw_rad : (K,) unwrapped yaw; v_mps : (K,) speed [m/s];
    steer_rad, accel_mps2 : (K,) applied steering [rad] and acceleration [m/s^2] (0 if no input);
    X_pred : (K, N+1, nx) predictions; refs : (K, N+1, nx) horizon references;
    status : (K,) solver status words (``held`` on a plant step without a solve, when the
    controller runs slower than the plant); fallback : (K,) fallback names ("" if none);
    solve_time_s : (K,) controller step wall time [s] (0 on ``held`` steps);
    path_xy : (M, 2) reference path polyline for plots [m];
    road_profile : (M, 3) rows ``[s_m, left_m, right_m]``: the road edges' lateral offsets [m]
    from the path along it (``Road.profile``), or None without a road;
    lane_excess_m : (K,) how far [m] the body was outside the road at each step (0 inside; the
    road's own measure, ``Road.measure_excess_m``), or None without a road; state_names/input_names: labels;
    clearance_m : (K,) smallest footprint-to-obstacle distance at each logged step [m] (None
    without obstacles; a contact between two steps is in ``meta["collision_events"]``).
    """

    t_s: np.ndarray
    x: np.ndarray
    u: np.ndarray
    x_final: np.ndarray
    s_m: np.ndarray
    e_y_m: np.ndarray
    e_psi_rad: np.ndarray
    yaw_rad: np.ndarray
    v_mps: np.ndarray
    steer_rad: np.ndarray
    accel_mps2: np.ndarray
    X_pred: np.ndarray
    refs: np.ndarray
    status: tuple[str, ...]
    fallback: tuple[str, ...]
    solve_time_s: np.ndarray
    path_xy: np.ndarray
    dt_s: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    road_profile: np.ndarray | None = None
    lane_excess_m: np.ndarray | None = None
    goal_reached: bool | None = None
    meta: dict = field(default_factory=dict)
    clearance_m: np.ndarray | None = None

    @property
    def steps(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def xy(self) -> np.ndarray:
        """(K, 2) position [m]."""
        return self.x[:, :2]
