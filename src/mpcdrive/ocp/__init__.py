"""Solver-independent MPC problem description and its sparse QP layout."""

from .problem import MpcProblem

__all__ = ["LtvQp", "MpcProblem", "QpData"]


def __getattr__(name):
    # the sparse layout imports scipy.sparse: loaded when first asked for (the compiled
    # controller never needs it, and its start-up time counts)
    if name in ("LtvQp", "QpData"):
        from . import qp

        return getattr(qp, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
