"""Controllers: the Controller protocol and the LTV-MPC (``LtvMpc``: its stage QP assembled by
the compiled step, ``mpcdrive.control.compiled_mpc``, loaded on demand as it imports numba, or in Python;
solved by the condensed solver, OSQP or projected gradient), baselines and wrappers."""

from .adapters import StateAdapter
from .base import Controller
from .baselines import BaselineLimits, PurePursuit, Stanley
from .delay import DelayCompensator, DelayWarmStart
from .fallback import FALLBACK_KINDS, FallbackConfig
from .mpc import ASSEMBLIES, SOLVERS, FastPathUnavailable, LtvMpc, MpcConfig, PythonLtvMpc

__all__ = [
    "ASSEMBLIES",
    "FALLBACK_KINDS",
    "SOLVERS",
    "BaselineLimits",
    "Controller",
    "DelayCompensator",
    "DelayWarmStart",
    "FallbackConfig",
    "FastPathUnavailable",
    "LtvMpc",
    "MpcConfig",
    "PurePursuit",
    "PythonLtvMpc",
    "StateAdapter",
    "Stanley",
]
