"""Pick the LTV-MPC implementation for a problem: the compiled fast path where it covers the
problem, else the OSQP reference, saying so."""

from __future__ import annotations

import warnings
from typing import Literal

from ..ocp.problem import MpcProblem
from ..paths.base import ReferencePath
from ..solvers.osqp_backend import OsqpSettings
from .mpc import LtvMpc, MpcConfig

Backend = Literal["osqp", "fast"]
BACKENDS: tuple[str, ...] = ("osqp", "fast")
#: the compiled controller unless the caller asks for the OSQP reference (as scenarios and the CLI)
DEFAULT_BACKEND: Backend = "fast"


class FastPathUnavailable(UserWarning):
    """The fast backend was asked for but does not cover the problem; OSQP is used instead."""


def make_mpc(
    model,
    path: ReferencePath,
    problem: MpcProblem,
    config: MpcConfig = MpcConfig(),
    backend: Backend = DEFAULT_BACKEND,
    osqp_settings: OsqpSettings = OsqpSettings(),
    fast_settings=None,
    obstacles=(),
    avoidance=None,
    footprint=None,
):
    """An LTV-MPC controller solving ``problem`` with ``backend`` (default ``fast``).

    Where the compiled step covers the problem (see ``fast_unsupported_reason``) it assembles
    each step's stage QP (:class:`~mpcdrive.control.fast.FastLtvMpc`) and ``backend`` names the
    solver: ``fast`` the condensed dual active-set solve compiled into the step, ``osqp`` OSQP on
    the sparse layout (the reference solver). When only the condensed solver's limits exclude
    the problem (the dense size limit ``max_variables``, a cost not strictly convex in the
    inputs, a slack without quadratic weight), ``fast`` solves with OSQP. Where the compiled step
    does not cover the problem at all (a model, path, speed profile or obstacle it has no
    compiled form of, prediction substeps), :class:`~mpcdrive.control.mpc.LtvMpc` assembles the
    same stage QP in Python and the condensed solver (``fast``, within its limits) or OSQP
    solves it. A ``fast`` request that is not met says so in a
    :class:`FastPathUnavailable` warning naming the reason -- no constraint or setting is ever
    dropped. The returned controller's ``backend_name`` names the solver that runs and its
    ``assembly`` (``compiled`` or ``python``) who builds the QP. Both keep the body inside
    ``problem.road`` by the same rule (:mod:`mpcdrive.scene.road`).
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    from ..scene.footprint import Footprint
    from .fast import FastLtvMpc, FastSettings, fast_unsupported_reason
    from .fast_setup import condensed_unsupported_reason, uses_rows

    settings = fast_settings if fast_settings is not None else FastSettings()
    fp = footprint if footprint is not None else Footprint()
    kw = {} if footprint is None else {"footprint": footprint}
    # who can assemble the stage QP (the compiled step?) and who can solve it (the condensed solver?)
    assembly_reason = fast_unsupported_reason(
        model, path, problem, config, settings, obstacles, avoidance, solver="osqp"
    )
    if backend == "fast":
        solver_reason = condensed_unsupported_reason(problem, settings, uses_rows(obstacles, avoidance))
        if assembly_reason is None and solver_reason is None:
            return FastLtvMpc(model, path, problem, config, settings, obstacles, avoidance, fp)
        if assembly_reason is None:
            message = f"condensed solver not used: {solver_reason}; OSQP solves the compiled step's QP"
        elif solver_reason is None:
            message = (
                f"compiled step not used: {assembly_reason}; the stage QP is assembled in Python, "
                "solved by the condensed solver"
            )
        else:
            message = f"fast backend not used: {assembly_reason}; using the OSQP controller"
        warnings.warn(message, FastPathUnavailable, stacklevel=2)
        if assembly_reason is not None and solver_reason is None:
            return LtvMpc(model, path, problem, config, settings, obstacles=obstacles, avoidance=avoidance, **kw)
    if assembly_reason is None:
        return FastLtvMpc(
            model, path, problem, config, settings, obstacles, avoidance, fp, solver="osqp", osqp_settings=osqp_settings
        )
    return LtvMpc(model, path, problem, config, osqp_settings, obstacles=obstacles, avoidance=avoidance, **kw)
