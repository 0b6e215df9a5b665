"""Controllers: the Controller protocol, LTV-MPC on the sparse QP (OSQP, the reference) and its
compiled fast path (``mpcdrive.control.fast``, loaded on demand: it imports numba)."""

from .adapters import StateAdapter
from .base import Controller
from .baselines import BaselineLimits, PurePursuit, Stanley
from .delay import DelayCompensator, DelayWarmStart
from .factory import BACKENDS, DEFAULT_BACKEND, FastPathUnavailable, make_mpc
from .fallback import FALLBACK_KINDS, FallbackConfig
from .mpc import LtvMpc, MpcConfig

__all__ = [
    "BACKENDS",
    "DEFAULT_BACKEND",
    "FALLBACK_KINDS",
    "BaselineLimits",
    "Controller",
    "DelayCompensator",
    "DelayWarmStart",
    "FallbackConfig",
    "FastPathUnavailable",
    "LtvMpc",
    "MpcConfig",
    "PurePursuit",
    "StateAdapter",
    "Stanley",
    "make_mpc",
]
