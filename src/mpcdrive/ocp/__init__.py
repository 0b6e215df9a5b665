"""Solver-independent MPC problem description and its sparse QP layout."""

from .problem import MpcProblem
from .qp import LtvQp, QpData

__all__ = ["LtvQp", "MpcProblem", "QpData"]
