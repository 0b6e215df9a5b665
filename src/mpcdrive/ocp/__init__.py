"""Solver-independent MPC problem description (``MpcProblem``, the obstacles' ``AvoidanceConfig``)
and its sparse QP layout."""

from .problem import MpcProblem

__all__ = ["AvoidanceConfig", "LtvQp", "MpcProblem", "QpData"]


def __getattr__(name):
    # the sparse layout imports scipy.sparse: loaded when first asked for (the compiled
    # controller never needs it, and its start-up time counts); the obstacle terms likewise
    if name in ("LtvQp", "QpData"):
        from . import qp

        return getattr(qp, name)
    if name == "AvoidanceConfig":
        from .avoidance import AvoidanceConfig

        return AvoidanceConfig
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
