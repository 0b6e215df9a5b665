"""Pick the LTV-MPC implementation for a problem: the compiled fast path where it covers the
problem, else the OSQP reference, saying so."""

from __future__ import annotations

import warnings
from typing import Literal

from ..ocp.problem import MpcProblem
from ..paths.base import Path
from ..solvers.osqp_backend import OsqpSettings
from .mpc import LtvMpc, MpcConfig

Backend = Literal["osqp", "fast"]
BACKENDS: tuple[str, ...] = ("osqp", "fast")
DEFAULT_BACKEND: Backend = "osqp"


class FastPathUnavailable(UserWarning):
    """The fast backend was asked for but does not cover the problem; OSQP is used instead."""


def make_mpc(model, path: Path, problem: MpcProblem, config: MpcConfig = MpcConfig(),
             backend: Backend = DEFAULT_BACKEND, osqp_settings: OsqpSettings = OsqpSettings(),
             fast_settings=None, obstacles=(), avoidance=None, footprint=None, lane_margin_m: float = 0.05):
    """An LTV-MPC controller solving ``problem`` with ``backend``.

    ``osqp``: :class:`~mpcdrive.control.mpc.LtvMpc` (sparse QP updated in place, OSQP), the
    reference. ``fast``: :class:`~mpcdrive.control.fast.FastLtvMpc` (the whole step compiled);
    when it does not cover the problem (see ``fast_unsupported_reason``) the OSQP controller is
    returned and a :class:`FastPathUnavailable` warning names the reason -- no constraint or
    setting is ever dropped. The returned controller's ``backend_name`` tells which one runs.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "fast":
        from .fast import FastLtvMpc, FastSettings, fast_unsupported_reason

        from dataclasses import replace

        from ..scene.footprint import Footprint

        settings = fast_settings if fast_settings is not None else FastSettings()
        fp = footprint if footprint is not None else Footprint()
        reason = None
        fast_problem = problem
        if reason is None and problem.lane_half_width_m is not None:
            # the same body-inside-the-lane bound the OSQP controller keeps
            lim = problem.lane_half_width_m - 0.5 * fp.width_m - lane_margin_m
            if lim <= 0:
                reason = "the lane is not wider than the car plus its margin"
            else:
                fast_problem = replace(problem, lane_half_width_m=lim)
        if reason is None:
            reason = fast_unsupported_reason(model, path, fast_problem, config, settings, obstacles, avoidance)
        if reason is None:
            return FastLtvMpc(model, path, fast_problem, config, settings, obstacles, avoidance, fp, lane_margin_m)
        warnings.warn(f"fast backend not used: {reason}; using the OSQP controller", FastPathUnavailable,
                      stacklevel=2)
    kw = {} if footprint is None else {"footprint": footprint}
    return LtvMpc(model, path, problem, config, osqp_settings, obstacles=obstacles, avoidance=avoidance,
                  lane_margin_m=lane_margin_m, **kw)
