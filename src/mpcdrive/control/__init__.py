"""Controllers: the Controller protocol and LTV-MPC on the sparse QP."""

from .base import Controller
from .mpc import LtvMpc, MpcConfig

__all__ = ["Controller", "LtvMpc", "MpcConfig"]
