"""What the compiled LTV-MPC step covers.

:func:`fast_unsupported_reason` (and :func:`obstacles_unsupported_reason` for the obstacles)
says why :class:`~mpcdrive.control.compiled_mpc.CompiledLtvMpc` cannot solve a problem exactly as
:class:`~mpcdrive.control.python_mpc.PythonLtvMpc` would, so that :class:`~mpcdrive.control.mpc.LtvMpc`
can use the Python assembly instead (and
:func:`~mpcdrive.solvers.condensed_setup.condensed_unsupported_reason`: why the condensed solver
cannot, so that OSQP solves).
"""

from __future__ import annotations

import numpy as np

from ..models.compiled import model_code
from ..ocp.avoidance import AvoidanceConfig
from ..ocp.problem import MpcProblem
from ..paths.base import ReferencePath
from ..paths.compiled import path_arrays
from ..paths.profile_compiled import profile_array
from ..scene.obstacles import Circle, ConstantVelocity, Polygon, Static, TrajectoryMotion
from ..solvers.condensed_setup import CondensedSettings, condensed_unsupported_reason
from .mpc_config import MpcConfig


def obstacles_unsupported_reason(obstacles, avoidance: AvoidanceConfig | None) -> str | None:
    """Why the compiled step cannot take these obstacles as ``LtvMpc`` would, or None.

    Covered: the cost formulations (``potential``, ``gaussian``) on circle and polygon obstacles
    that stand still, move at constant velocity or follow a recorded trajectory, with or without
    a lifetime, compiled; with the trapezoidal detour reference, on static circles. The
    constraint formulations (``hard``, ``corridor``) on any obstacle, their rows (and, with car
    following, ``follow_gap_s``, the references behind the stop line) built by
    ``ocp.avoidance`` between two compiled stages."""
    if not obstacles:
        return None
    av = avoidance or AvoidanceConfig()
    if av.uses_rows:
        return None
    for ob in obstacles:
        if av.detour != "none" and not (isinstance(ob.motion, Static) and isinstance(ob.shape, Circle)):
            return f"the {av.detour!r} detour around obstacle {ob.name or '?'} (not a static circle) needs the OSQP controller"
        if type(ob.motion) not in (Static, ConstantVelocity, TrajectoryMotion):
            return f"obstacle {ob.name or '?'} follows a {type(ob.motion).__name__} (no compiled form)"
        if not isinstance(ob.shape, (Circle, Polygon)):
            return f"obstacle {ob.name or '?'} has a {type(ob.shape).__name__} shape"
    return None


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
