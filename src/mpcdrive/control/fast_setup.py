"""What the compiled LTV-MPC step covers, and the parts of its setup that do not change per step.

:func:`fast_unsupported_reason` (and :func:`obstacles_unsupported_reason` for the obstacles)
says why :class:`~mpcdrive.control.fast.CompiledLtvMpc` cannot solve a problem exactly as
:class:`~mpcdrive.control.mpc.PythonLtvMpc` would, so that :class:`~mpcdrive.control.mpc.LtvMpc`
can use the Python assembly instead (:func:`condensed_unsupported_reason`: why the condensed
solver cannot, so that OSQP solves); :class:`CondensedSettings` are the settings of the compiled
QP solve. The rows of ``C z >= b`` that are the same every step and the compiled obstacle table
(columns ``_OB_*`` of :mod:`mpcdrive.control.fast_layout`) are built here for the controller's
buffers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..models.compiled import model_code
from ..ocp.avoidance import AvoidanceConfig
from ..ocp.problem import MpcProblem
from ..paths.base import ReferencePath
from ..paths.compiled import path_arrays
from ..paths.profile_compiled import profile_array
from ..scene.obstacles import Circle, ConstantVelocity, Polygon, Static
from ..solvers.dense_qp import single_nonzero_columns
from .fast_step import input_bound_rows
from .fast_layout import _OB_X, _OB_Y, _OB_VX, _OB_VY, _OB_RB, _OB_OX, _OB_OY, _OB_WIN, _NOB
from .mpc import MpcConfig


@dataclass(frozen=True)
class CondensedSettings:
    """Settings of the compiled QP solve.

    max_iter : cap on active-set changes per step (status ``max_iter`` beyond it);
    feasibility_tol : accepted violation of a constraint row, scaled by the row's norm;
    max_variables : the largest condensed QP (N * nu + lane slacks) the fast path accepts.
    """

    max_iter: int = 500
    feasibility_tol: float = 1e-9
    max_variables: int = 400

    def __post_init__(self):
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        if not (self.feasibility_tol > 0 and math.isfinite(self.feasibility_tol)):
            raise ValueError(f"feasibility_tol must be positive, got {self.feasibility_tol}")
        if self.max_variables < 1:
            raise ValueError(f"max_variables must be >= 1, got {self.max_variables}")


def obstacles_unsupported_reason(obstacles, avoidance: AvoidanceConfig | None) -> str | None:
    """Why the compiled step cannot take these obstacles as ``LtvMpc`` would, or None.

    Covered: the cost formulations (``potential``, ``gaussian``) on circle and polygon obstacles
    that stand still or move at constant velocity, compiled; with the trapezoidal detour
    reference, on static circles. The constraint formulations (``hard``, ``corridor``) on any
    obstacle, their rows (and, with car following, ``follow_gap_s``, the references behind the
    stop line) built by ``ocp.avoidance`` between two compiled stages."""
    if not obstacles:
        return None
    av = avoidance or AvoidanceConfig()
    if av.uses_rows:
        return None
    for ob in obstacles:
        if av.detour != "none" and not (isinstance(ob.motion, Static) and isinstance(ob.shape, Circle)):
            return f"the {av.detour!r} detour around obstacle {ob.name or '?'} (not a static circle) needs the OSQP controller"
        if ob.has_lifetime:
            return f"obstacle {ob.name or '?'} has a lifetime (present only from t_start_s to t_end_s)"
        if not isinstance(ob.motion, (Static, ConstantVelocity)):
            return f"obstacle {ob.name or '?'} follows a {type(ob.motion).__name__} (only static or constant velocity)"
        if not isinstance(ob.shape, (Circle, Polygon)):
            return f"obstacle {ob.name or '?'} has a {type(ob.shape).__name__} shape"
    return None


def _obstacle_table(obstacles) -> np.ndarray:
    """(n, _NOB) rows of the compiled obstacle description (see ``_OB_*``)."""
    tab = np.zeros((max(len(obstacles), 1), _NOB))
    for j, ob in enumerate(obstacles):
        x0, y0, yaw0 = ob.pose
        vx, vy = (ob.motion.vx_mps, ob.motion.vy_mps) if isinstance(ob.motion, ConstantVelocity) else (0.0, 0.0)
        tab[j, [_OB_X, _OB_Y, _OB_VX, _OB_VY, _OB_RB]] = x0, y0, vx, vy, ob.shape.bounding_radius_m
        if isinstance(ob.shape, Circle):
            tab[j, _OB_WIN] = max(2.0, 2.0 * ob.shape.radius_m)
        else:  # as ocp.avoidance.frenet_box: the vertex mean is projected (a fixed offset: no rotation)
            pts = ob.at(0.0).points
            tab[j, _OB_OX], tab[j, _OB_OY] = pts.mean(axis=0) - (x0, y0)
            tab[j, _OB_WIN] = 2.0 + float(np.ptp(pts))
    return tab


def fast_unsupported_reason(
    model,
    path: ReferencePath,
    problem: MpcProblem,
    config: MpcConfig = MpcConfig(),
    settings: CondensedSettings = CondensedSettings(),
    obstacles=(),
    avoidance: AvoidanceConfig | None = None,
    *,
    solver: str = "condensed",
) -> str | None:
    """Why the compiled step cannot solve this problem exactly as ``LtvMpc`` would, or None.
    ``solver="osqp"`` (the compiled assembly, OSQP solving its stage QP): only the assembly's
    limits; the condensed solver's (a strictly convex cost in the inputs, quadratic slack
    weights, ``settings.max_variables``) do not apply."""
    prof = config.speed_profile
    if prof is not None:
        if profile_array(prof) is None:
            return f"speed profile {type(prof).__name__} has no compiled form"
        if config.horizon != "arc_length":
            return f"a speed profile with the {config.horizon!r} horizon needs the OSQP controller"
    if config.prediction_substeps != 1:
        return "prediction substeps need the OSQP controller"
    reason = obstacles_unsupported_reason(obstacles, avoidance)
    if reason is not None:
        return reason
    if model_code(model) is None:
        return f"model {type(model).__name__} has no compiled form"
    if path_arrays(path) is None:
        return f"path {type(path).__name__} has no compiled form"
    if (problem.nx, problem.nu) != (model.nx, model.nu):
        return f"problem is sized nx={problem.nx}, nu={problem.nu} but the model has nx={model.nx}, nu={model.nu}"
    if problem.friction_accel_mps2 is not None:
        limited = [i for i, n in enumerate(model.input_names) if n in ("steer", "accel")]
        if not np.all(np.isfinite(problem.u_min[limited]) & np.isfinite(problem.u_max[limited])):
            return "the friction circle needs finite steer and accel bounds on the compiled path"
    rows = uses_rows(obstacles, avoidance)
    if rows and not problem.lane and (avoidance or AvoidanceConfig()).formulation == "corridor":
        return "the corridor formulation needs a road (MpcProblem.road)"
    if solver == "osqp":
        return None
    return condensed_unsupported_reason(problem, settings, rows)


def uses_rows(obstacles, avoidance: AvoidanceConfig | None) -> bool:
    """Whether these obstacles enter the QP as constraint rows (``hard``, ``corridor``)."""
    return bool(obstacles) and (avoidance or AvoidanceConfig()).uses_rows


def condensed_unsupported_reason(problem: MpcProblem, settings: CondensedSettings, rows: bool) -> str | None:
    """Why the condensed solver cannot solve the stage QPs of ``problem`` (with obstacle rows
    when ``rows``), whoever assembles them, or None."""
    if np.linalg.eigvalsh(problem.R + problem.Rc).min() <= 1e-12 * max(1.0, float(np.abs(problem.R).max())):
        return "R + Rc is not positive definite (the condensed QP needs a strictly convex cost in the inputs)"
    lane = problem.lane
    if lane and problem.lane_slack_weight <= 0:
        return "lane_slack_weight is 0 (the slack needs a quadratic weight)"
    if rows and problem.obstacle_slack_weight <= 0:
        return "obstacle_slack_weight is 0 (the slack needs a quadratic weight)"
    nz = condensed_variables(problem, rows)
    if nz > settings.max_variables:
        return f"the condensed QP has {nz} variables, more than max_variables={settings.max_variables}"
    return None


def condensed_variables(problem: MpcProblem, rows: bool) -> int:
    """The variables of the condensed QP: the inputs, and one slack per step for the road rows
    and one for the obstacle rows (``rows``) where the problem has them."""
    return problem.N * problem.nu + (problem.N if problem.lane else 0) + (problem.N if rows else 0)


def riccati_shortcut(problem: MpcProblem, rows: bool) -> bool:
    """Whether the condensed solve first tries the unconstrained minimizer (a Riccati recursion):
    no input-change weight, no road rows, no obstacle rows (``rows``)."""
    return not problem.lane and not rows and not np.any(problem.Rc)


@dataclass(frozen=True)
class ConstantRows:
    """The rows of ``C z >= b`` of the condensed QP, sized for every row a step can add:
    ``C`` (mq, nz), ``b`` (mq,) hold the constant rows first (``m_const`` of them; the u_0 rate
    rows from ``r_rate0`` have a b that follows u_prev); ``rowcol`` (mq,) the single nonzero
    column of each constant row (-1: dense); ``gamma``: a step adds state, road or obstacle rows."""

    C: np.ndarray
    b: np.ndarray
    rowcol: np.ndarray
    m_const: int
    r_rate0: int
    gamma: bool

    @property
    def mq(self) -> int:
        return len(self.b)


def constant_rows(problem: MpcProblem, nz: int, n_orow: int = 0) -> ConstantRows:
    """:func:`_constant_rows` as the arrays the condensed solve works in."""
    crows, rhs, r_rate0, n_var, n_slack = _constant_rows(problem, nz, n_orow)
    mq = max(len(crows) + n_var + n_slack, 1)
    C, b = np.zeros((mq, nz)), np.zeros(mq)
    if crows:
        C[: len(crows)] = np.array(crows)
        b[: len(crows)] = rhs
    rowcol = np.full(mq, -1, dtype=np.int64)
    rowcol[: len(crows)] = single_nonzero_columns(C[: len(crows)])
    return ConstantRows(C, b, rowcol, len(crows), r_rate0, n_var > 0)


def _constant_rows(problem: MpcProblem, nz: int, n_orow: int = 0):
    """Rows of ``C z >= b`` that do not change between steps (input bounds, input rates), the row
    of the first u_0 rate row (its b follows u_prev), how many rows the step adds after them
    (state bounds, lane, ``n_orow`` obstacle rows per step) and how many slack sign rows may
    follow those (one per step for the lane and for the obstacle rows; written per step by
    ``soft_solve``)."""
    N, nu = problem.N, problem.nu
    rows, rhs = [], []

    def unit(j, sign=1.0):
        r = np.zeros(nz)
        r[j] = sign
        return r

    n_bound = N * int(np.isfinite(problem.u_min).sum() + np.isfinite(problem.u_max).sum())
    Cb, bb = np.zeros((n_bound, nz)), np.zeros(n_bound)
    lo, hi = np.tile(problem.u_min, (N, 1)), np.tile(problem.u_max, (N, 1))
    input_bound_rows(N, nu, problem.u_min, problem.u_max, lo, hi, Cb, bb, True)
    rows += list(Cb)
    rhs += bb.tolist()
    r_rate0 = len(rows)
    dmax = problem.du_max_per_s * problem.dt_s
    for i in range(nu):  # |u_0 - u_prev| <= d: b written each step
        if np.isfinite(dmax[i]):
            rows += [unit(i), unit(i, -1.0)]
            rhs += [0.0, 0.0]
    for k in range(1, N):
        for i in range(nu):
            if np.isfinite(dmax[i]):
                r = np.zeros(nz)
                r[k * nu + i], r[(k - 1) * nu + i] = 1.0, -1.0
                rows += [r, -r]
                rhs += [-dmax[i], -dmax[i]]
    lane = problem.lane
    n_slack = (N if lane else 0) + (N if n_orow else 0)
    n_state = N * int(np.isfinite(problem.x_min).sum() + np.isfinite(problem.x_max).sum())
    n_var = n_state + (2 * N if lane else 0) + N * n_orow
    return rows, rhs, r_rate0, n_var, n_slack
