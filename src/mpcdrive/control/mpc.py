"""Linear time-varying MPC for path tracking (the paper's controller, done properly): the public
entry, ``LtvMpc(...)``, and the choice of its implementation.

``LtvMpc(model, path, problem, config, ...)`` builds the implementation that covers the problem
(:func:`implementation_for`): the compiled step
(:class:`~mpcdrive.control.compiled_mpc.CompiledLtvMpc`, imported when first needed) wherever it
covers the problem, else the stage QP assembled in Python
(:class:`~mpcdrive.control.python_mpc.PythonLtvMpc`). The modules under it:

- :mod:`~mpcdrive.control.mpc_config`: :class:`MpcConfig`, how the problem is built each step;
- :mod:`~mpcdrive.control.mpc_base`: what both implementations share (the base class
  :class:`LtvMpc`, :class:`StepData`, :class:`StageQpSolve`, the solver and assembly names,
  :class:`FastPathUnavailable`, :func:`solver_in_reach`);
- :mod:`~mpcdrive.control.python_mpc` and :mod:`~mpcdrive.control.compiled_mpc`: the two
  implementations, which import nothing of each other nor of this module.

Every name users import from here stays here (re-exported from its module).
"""

from __future__ import annotations

import warnings

from ..models.base import VehicleModel
from ..ocp.avoidance import AvoidanceConfig
from ..ocp.problem import MpcProblem
from ..paths.base import ReferencePath
from ..scene.footprint import Footprint
from ..scene.world import Scene
from .base import resolve_scene
from .mpc_base import (
    ASSEMBLIES,
    SOLVERS,
    Assembly,
    FastPathUnavailable,
    LtvMpc,
    Solver,
    StageQpSolve,
    StepData,
    set_implementation_chooser,
    solver_in_reach,
)
from .mpc_config import MpcConfig
from .python_mpc import PythonLtvMpc

__all__ = [
    "ASSEMBLIES",
    "SOLVERS",
    "Assembly",
    "FastPathUnavailable",
    "LtvMpc",
    "MpcConfig",
    "PythonLtvMpc",
    "Solver",
    "StageQpSolve",
    "StepData",
    "implementation_for",
    "solver_in_reach",
]


def implementation_for(
    model: VehicleModel,
    path: ReferencePath,
    problem: MpcProblem,
    config: MpcConfig,
    solver: Solver,
    *,
    scene: Scene | None,
    obstacles,
    avoidance: AvoidanceConfig | None,
    footprint: Footprint | None,
    assembly: Assembly,
) -> type[LtvMpc]:
    """The class ``LtvMpc(...)`` builds for these arguments (checked by ``LtvMpc.__new__``): the
    Python assembly where asked for (``assembly="python"``, or the projected gradient solver,
    which only it runs), the compiled one where asked for (``"compiled"``: its constructor says
    why when it does not cover the problem), and for ``"auto"`` the compiled one wherever it
    covers the problem, else the Python assembly with a :class:`FastPathUnavailable` warning
    naming the reason."""
    if assembly == "python" or solver == "projected_gradient":
        return PythonLtvMpc
    from .compiled_mpc import CompiledLtvMpc  # numba: loaded when a compiled controller may be built

    if assembly == "compiled":
        return CompiledLtvMpc
    from .compiled_setup import fast_unsupported_reason

    problem, scene = resolve_scene(problem, scene, obstacles, footprint)
    reason = fast_unsupported_reason(
        model, path, problem, config, obstacles=scene.obstacles, avoidance=avoidance, solver="osqp"
    )
    if reason is None:
        return CompiledLtvMpc
    # stacklevel: this function, LtvMpc.__new__, the caller of LtvMpc(...)
    warnings.warn(
        f"compiled step not used: {reason}; the stage QP is assembled in Python", FastPathUnavailable, stacklevel=3
    )
    return PythonLtvMpc


set_implementation_chooser(implementation_for)
