"""Pick the LTV-MPC implementation for a problem: the compiled fast path where it covers the
problem, else the OSQP reference, saying so."""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Literal

from ..ocp.problem import MpcProblem
from ..paths.base import ReferencePath
from ..solvers.osqp_backend import OsqpSettings
from .mpc import LtvMpc, MpcConfig

Backend = Literal["osqp", "fast"]
BACKENDS: tuple[str, ...] = ("osqp", "fast")
#: the compiled controller unless the caller asks for the OSQP reference (as scenarios and the CLI)
DEFAULT_BACKEND: Backend = "fast"


def _rows_per_step(obstacles, avoidance, footprint) -> int:
    """The obstacle rows per step the controller's QP will have (0 without constraint rows)."""
    from ..ocp.avoidance import AvoidanceConfig

    av = avoidance or AvoidanceConfig()
    return av.rows_per_step(footprint) if obstacles and av.uses_rows else 0


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
    same stage QP in Python and OSQP solves it. A ``fast`` request that is not met says so in a
    :class:`FastPathUnavailable` warning naming the reason -- no constraint or setting is ever
    dropped. The returned controller's ``backend_name`` names the solver that runs and its
    ``assembly`` (``compiled`` or ``python``) who builds the QP. Both keep the body inside
    ``problem.road`` by the same rule (:mod:`mpcdrive.scene.road`).
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    from ..scene.footprint import Footprint
    from .fast import FastLtvMpc, FastSettings, fast_unsupported_reason

    settings = fast_settings if fast_settings is not None else FastSettings()
    fp = footprint if footprint is not None else Footprint()
    compiled_assembly = (
        fast_unsupported_reason(model, path, problem, config, settings, obstacles, avoidance, solver="osqp") is None
    )
    if backend == "fast":
        reason = fast_unsupported_reason(model, path, problem, config, settings, obstacles, avoidance)
        if reason is None:
            return FastLtvMpc(model, path, problem, config, settings, obstacles, avoidance, fp)
        if compiled_assembly:  # only the condensed solver's limits: the compiled step assembles, OSQP solves
            warnings.warn(
                f"condensed solver not used: {reason}; OSQP solves the compiled step's QP",
                FastPathUnavailable,
                stacklevel=2,
            )
        else:
            from .condensed import condensed_unsupported_reason

            rows = replace(problem, obstacle_rows=_rows_per_step(obstacles, avoidance, fp))
            if condensed_unsupported_reason(rows, settings) is None:
                # no compiled assembly, but the condensed solver takes the Python assembly's QP
                warnings.warn(
                    f"compiled step not used: {reason}; the stage QP is assembled in Python, "
                    "solved by the condensed solver",
                    FastPathUnavailable,
                    stacklevel=2,
                )
                kw = {} if footprint is None else {"footprint": footprint}
                return LtvMpc(model, path, problem, config, settings, obstacles=obstacles, avoidance=avoidance, **kw)
            warnings.warn(
                f"fast backend not used: {reason}; using the OSQP controller", FastPathUnavailable, stacklevel=2
            )
    if compiled_assembly:
        return FastLtvMpc(
            model, path, problem, config, settings, obstacles, avoidance, fp, solver="osqp", osqp_settings=osqp_settings
        )
    kw = {} if footprint is None else {"footprint": footprint}
    return LtvMpc(model, path, problem, config, osqp_settings, obstacles=obstacles, avoidance=avoidance, **kw)
