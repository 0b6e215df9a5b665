"""Controllers: the Controller protocol, LTV-MPC on the sparse QP, baselines and wrappers."""

from .adapters import StateAdapter
from .base import Controller
from .baselines import BaselineLimits, PurePursuit, Stanley
from .delay import DelayCompensator, DelayWarmStart
from .fallback import FALLBACK_KINDS, FallbackConfig
from .mpc import LtvMpc, MpcConfig

__all__ = [
    "FALLBACK_KINDS",
    "BaselineLimits",
    "Controller",
    "DelayCompensator",
    "DelayWarmStart",
    "FallbackConfig",
    "LtvMpc",
    "MpcConfig",
    "PurePursuit",
    "StateAdapter",
    "Stanley",
]
