"""Controllers: the Controller protocol and LTV-MPC on the sparse QP."""

from .base import Controller
from .fallback import FALLBACK_KINDS, FallbackConfig
from .mpc import LtvMpc, MpcConfig

__all__ = ["FALLBACK_KINDS", "Controller", "FallbackConfig", "LtvMpc", "MpcConfig"]
