"""OSQP backend: sparse QP set up once, then numbers updated in place and warm-started."""

from __future__ import annotations

import ctypes
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..types import (
    STATUS_FAILED,
    STATUS_INACCURATE,
    STATUS_INFEASIBLE,
    STATUS_MAX_ITER,
    STATUS_OK,
    SolveResult,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..ocp.qp import LtvQp

_STATUS_WORDS = {
    "solved": STATUS_OK,
    "solved inaccurate": STATUS_INACCURATE,
    "primal infeasible": STATUS_INFEASIBLE,
    "primal infeasible inaccurate": STATUS_INFEASIBLE,
    "dual infeasible": STATUS_INFEASIBLE,
    "dual infeasible inaccurate": STATUS_INFEASIBLE,
    "maximum iterations reached": STATUS_MAX_ITER,
    "run time limit reached": STATUS_MAX_ITER,
}


def _interrupt_record(ext) -> Callable[[], int] | None:
    """OSQP's own record of a Ctrl-C (SIGINT) caught during its last solve, as a function, or
    None where the extension does not export it.

    From the start of a solve to its end OSQP replaces the process's SIGINT handler by its own,
    which only sets this record; the solve's loop reads it at the top of each iteration. A signal
    that lands after the last such read (in the final convergence test, the polish, the
    unscaling) leaves the solve "solved" and the record set, and the process's own handler never
    sees it: the interrupt would be lost. The record stays set until the next solve starts."""
    try:
        fn = ctypes.CDLL(ext.__file__).osqp_is_interrupted
    except (AttributeError, OSError, TypeError):
        return None
    fn.restype, fn.argtypes = ctypes.c_int, []
    return fn


@dataclass(frozen=True)
class OsqpSettings:
    """OSQP options used by mpcdrive (see OSQP's documentation for their meaning). ``max_iter``:
    the road rows linearized in the yaw, with a car starting outside its lane, need up to about
    8,000 iterations at 1e-5 (measured on P3 without obstacles); 4,000 left such steps to the
    fallback ladder."""

    eps_abs: float = 1e-5
    eps_rel: float = 1e-5
    max_iter: int = 20000
    polish: bool = True
    adaptive_rho: bool = True
    time_limit_s: float = 0.0  # 0 = none

    def __post_init__(self):
        for name in ("eps_abs", "eps_rel"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"OSQP {name} must be a finite number >= 0, got {v!r}")
        if self.eps_abs == 0 and self.eps_rel == 0:
            raise ValueError("OSQP eps_abs and eps_rel cannot both be 0")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 1:
            raise ValueError(f"OSQP max_iter must be an integer >= 1, got {self.max_iter!r}")
        if not (
            isinstance(self.time_limit_s, (int, float)) and np.isfinite(self.time_limit_s) and self.time_limit_s >= 0
        ):
            raise ValueError(f"OSQP time_limit_s must be a finite number >= 0 (0 = none), got {self.time_limit_s!r}")

    def as_kwargs(self) -> dict:
        kw = dict(
            eps_abs=self.eps_abs,
            eps_rel=self.eps_rel,
            max_iter=self.max_iter,
            polishing=self.polish,
            adaptive_rho=self.adaptive_rho,
            warm_starting=True,
            verbose=False,
        )
        if self.time_limit_s > 0:
            kw["time_limit"] = self.time_limit_s
        return kw


class OsqpBackend:
    """Solve an :class:`LtvQp` with OSQP; ``setup`` happens once in the constructor."""

    name = "osqp"

    def __init__(self, qp: LtvQp, settings: OsqpSettings = OsqpSettings()):
        self.qp = qp
        self.settings = settings
        import osqp  # here, not at module import: start-up time of processes that never use OSQP

        self._solver = osqp.OSQP()
        self._sigint = osqp.SolverStatus.OSQP_SIGINT
        self._interrupted = _interrupt_record(getattr(self._solver, "ext", None))
        d = qp.data()
        self._solver.setup(d.P, d.q, d.A, d.l, d.u, **settings.as_kwargs())
        self._z0 = np.zeros(qp.n_var)

    def solve(self, warm_X: np.ndarray | None = None, warm_U: np.ndarray | None = None) -> SolveResult:
        """Push the QP's current numbers to OSQP and solve.

        warm_X, warm_U : optional primal warm start (N+1, nx), (N, nu); otherwise OSQP starts
        from its previous solution.
        """
        t0 = time.perf_counter()
        qp = self.qp
        # non-finite problem data (NaN anywhere, inf outside the bounds) is a failed step, not a
        # 4000-iteration OSQP run on garbage
        finite = (
            np.isfinite(qp.q).all()
            and np.isfinite(qp.A.data).all()
            and not np.isnan(qp.l).any()
            and not np.isnan(qp.u).any()
        )
        try:
            if not finite:
                raise ValueError("non-finite QP data")
            if qp.finalize_cost():
                if not np.isfinite(qp.P.data).all():
                    raise ValueError("non-finite QP cost")
                self._solver.update(q=qp.q, l=qp.l, u=qp.u, Px=qp.P.data, Ax=qp.A.data)
            else:
                self._solver.update(q=qp.q, l=qp.l, u=qp.u, Ax=qp.A.data)
        except Exception:  # OSQP rejects the data: a failed step
            nan = float("nan")
            return SolveResult(
                STATUS_FAILED,
                np.full((qp.N + 1, qp.nx), nan),
                np.full((qp.N, qp.nu), nan),
                nan,
                0,
                time.perf_counter() - t0,
            )
        if warm_X is not None and warm_U is not None:
            self._solver.warm_start(x=qp.pack(warm_X, warm_U, out=self._z0))
        res = self._solver.solve(raise_error=False)
        if res.info.status_val == self._sigint or (self._interrupted is not None and self._interrupted()):
            # OSQP catches Ctrl-C during a solve and returns "interrupted", or, when it came after
            # the solve's last look, returns its result with the record set: the user's
            # interrupt either way, not a failed step to fall back from
            raise KeyboardInterrupt
        status = _STATUS_WORDS.get(res.info.status, STATUS_FAILED)
        z = res.x
        if z is None or not np.all(np.isfinite(z)):
            status = STATUS_FAILED if status in (STATUS_OK, STATUS_INACCURATE) else status
            X = np.full((qp.N + 1, qp.nx), np.nan)
            U = np.full((qp.N, qp.nu), np.nan)
        else:
            X, U, _ = qp.unpack(z)
            X, U = X.copy(), U.copy()
        return SolveResult(
            status=status,
            X=X,
            U=U,
            cost=float(res.info.obj_val) if res.info.obj_val is not None else float("nan"),
            iterations=int(res.info.iter),
            solve_time_s=time.perf_counter() - t0,
        )
