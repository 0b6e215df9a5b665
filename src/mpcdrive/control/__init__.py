"""Controllers: the Controller protocol, LTV-MPC on the sparse QP (OSQP, the reference) and its
compiled fast path (``mpcdrive.control.fast``, loaded on demand: it imports numba)."""

from .base import Controller
from .factory import BACKENDS, DEFAULT_BACKEND, FastPathUnavailable, make_mpc
from .mpc import LtvMpc, MpcConfig

__all__ = ["BACKENDS", "DEFAULT_BACKEND", "Controller", "FastPathUnavailable", "LtvMpc", "MpcConfig", "make_mpc"]
