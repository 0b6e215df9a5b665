"""Controllers: the Controller protocol and the LTV-MPC, baselines and wrappers.

``LtvMpc(...)`` (:mod:`~mpcdrive.control.mpc`) builds one of its two implementations, which
differ only in who assembles each step's stage QP: the compiled step
(:class:`CompiledLtvMpc`, :mod:`~mpcdrive.control.compiled_mpc`, imported when first needed) or
Python (:class:`PythonLtvMpc`, :mod:`~mpcdrive.control.python_mpc`); either solved by
the condensed solver, OSQP or projected gradient. What both share is in
:mod:`~mpcdrive.control.mpc_base` and :mod:`~mpcdrive.control.mpc_config`."""

from typing import TYPE_CHECKING

from .adapters import StateAdapter
from .base import Controller
from .baselines import BaselineLimits, PurePursuit, Stanley
from .delay import DelayCompensator, DelayWarmStart
from .fallback import FALLBACK_KINDS, FallbackConfig
from .mpc import ASSEMBLIES, SOLVERS, FastPathUnavailable, LtvMpc, MpcConfig, PythonLtvMpc

if TYPE_CHECKING:
    from .compiled_mpc import CompiledLtvMpc

__all__ = [
    "ASSEMBLIES",
    "FALLBACK_KINDS",
    "SOLVERS",
    "BaselineLimits",
    "CompiledLtvMpc",
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


def __getattr__(name: str):
    """``CompiledLtvMpc``, imported when first asked for (as ``LtvMpc(...)`` does)."""
    if name == "CompiledLtvMpc":
        from .compiled_mpc import CompiledLtvMpc

        return CompiledLtvMpc
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
