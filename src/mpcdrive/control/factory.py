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

    ``osqp``: :class:`~mpcdrive.control.mpc.LtvMpc` (sparse QP updated in place, OSQP), the
    reference. ``fast``: :class:`~mpcdrive.control.fast.FastLtvMpc` (the whole step compiled);
    when it does not cover the problem (see ``fast_unsupported_reason``) the OSQP controller is
    returned and a :class:`FastPathUnavailable` warning names the reason -- no constraint or
    setting is ever dropped. The returned controller's ``backend_name`` tells which one runs.
    Both keep the body inside ``problem.road`` by the same rule (:mod:`mpcdrive.scene.road`).
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "fast":
        from ..scene.footprint import Footprint
        from .fast import FastLtvMpc, FastSettings, fast_unsupported_reason

        settings = fast_settings if fast_settings is not None else FastSettings()
        fp = footprint if footprint is not None else Footprint()
        reason = fast_unsupported_reason(model, path, problem, config, settings, obstacles, avoidance)
        if reason is None:
            return FastLtvMpc(model, path, problem, config, settings, obstacles, avoidance, fp)
        warnings.warn(f"fast backend not used: {reason}; using the OSQP controller", FastPathUnavailable, stacklevel=2)
    kw = {} if footprint is None else {"footprint": footprint}
    return LtvMpc(model, path, problem, config, osqp_settings, obstacles=obstacles, avoidance=avoidance, **kw)
