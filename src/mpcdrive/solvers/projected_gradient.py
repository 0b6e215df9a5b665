"""The paper's projected gradient descent (eq. 52) on the condensed LTV-MPC problem.

The states are eliminated with the (linearized) dynamics, ``X = Phi x0 + Gamma U + gamma``, which
turns the sparse QP of :class:`~mpcdrive.ocp.qp.LtvQp` into ``min_U 1/2 U'HU + g'U`` over the input
box ``u_min <= u_k <= u_max``. Each iteration takes a gradient step of length ``1 / L``
(``L = lambda_max(H)``, the Lipschitz constant of the gradient) and projects onto the box::

    U <- clip(U - (H U + g) / L, u_min, u_max)            (eq. 52)

``accelerated=True`` adds Nesterov momentum with adaptive restart (FISTA), same projection and
step. The method handles input bounds only: problems with input-rate limits, state bounds or a
lane bound are refused at construction (use OSQP for those).

The backend reads the QP's current numbers (``A``, ``l``, ``q``) after
:meth:`~mpcdrive.ocp.qp.LtvQp.load_stage`, exactly like the OSQP backend, and returns the same
:class:`~mpcdrive.types.SolveResult`; ``cost`` is the QP objective ``1/2 z'Pz + q'z`` as OSQP
reports it, so the two can be compared on the same problem.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..types import STATUS_FAILED, STATUS_INACCURATE, STATUS_OK, SolveResult

if TYPE_CHECKING:  # scipy.sparse is imported when an OSQP or projected-gradient controller is built
    from ..ocp.qp import LtvQp


@dataclass(frozen=True)
class ProjectedGradientSettings:
    """Projected gradient options.

    max_iter : iteration cap; tol : stop when the projected-gradient step
    ``||clip(U - grad / L) - U||_inf`` is below ``tol`` (input units: rad, m/s^2);
    accelerated : Nesterov momentum with adaptive restart (False: the paper's plain eq. 52).
    ``status`` is ``ok`` on convergence and ``inaccurate`` at the iteration cap (the iterate is
    feasible -- inside the box, dynamics satisfied by construction -- but not optimal to ``tol``).
    """

    max_iter: int = 2000
    tol: float = 1e-6
    accelerated: bool = True

    def __post_init__(self):
        if int(self.max_iter) != self.max_iter or self.max_iter < 1:
            raise ValueError(f"max_iter must be a positive integer, got {self.max_iter}")
        if not (np.isfinite(self.tol) and self.tol > 0):
            raise ValueError(f"tol must be positive, got {self.tol}")


class ProjectedGradientBackend:
    """Projected gradient descent on the condensed form of an :class:`LtvQp`."""

    name = "projected_gradient"

    def __init__(self, qp: LtvQp, settings: ProjectedGradientSettings = ProjectedGradientSettings()):
        pb = qp.problem
        unsupported = []
        if pb.has_rate_limit:
            unsupported.append("input-rate limits (du_max_per_s)")
        if pb.bounded_states.size:
            unsupported.append("state bounds (x_min / x_max)")
        if qp.lane:
            unsupported.append("a road bound (MpcProblem.road)")
        if unsupported:
            raise ValueError(
                "the projected gradient solver handles input bounds only; this problem has " + ", ".join(unsupported)
            )
        self.qp = qp
        self.settings = settings
        N, nx, nu = qp.N, qp.nx, qp.nu
        P = qp.P.toarray()
        self._P = P + P.T - np.diag(np.diag(P))  # full symmetric cost matrix of z = [X, U]
        self._lo = np.tile(pb.u_min, N)
        self._hi = np.tile(pb.u_max, N)
        self._nz = qp.n_x + qp.n_u
        self._M = np.zeros((self._nz, qp.n_u))  # z = M U + m0
        self._M[qp.n_x :, :] = np.eye(qp.n_u)
        self._m0 = np.zeros(self._nz)
        self._N, self._nx, self._nu = N, nx, nu
        self.last_condensed: tuple[np.ndarray, np.ndarray] | None = None

    # -- condensing ---------------------------------------------------------------------------
    def _condense(self) -> tuple[np.ndarray, np.ndarray]:
        """(H, g) of the condensed cost from the QP's current numbers; fills ``_M``, ``_m0``."""
        qp = self.qp
        N, nx, nu = self._N, self._nx, self._nu
        A = qp.A.toarray()
        x0 = qp.l[qp.r_init : qp.r_init + nx]
        M, m0 = self._M, self._m0
        Gk = np.zeros((nx, N * nu))  # dX_k / dU
        gk = x0.copy()
        M[0:nx, :] = 0.0
        m0[0:nx] = gk
        for k in range(N):
            rows = slice(qp.r_dyn + k * nx, qp.r_dyn + (k + 1) * nx)
            Ad = -A[rows, qp.ix(k) : qp.ix(k) + nx]
            Bd = -A[rows, qp.iu(k) : qp.iu(k) + nu]
            c = qp.l[rows]
            Gk = Ad @ Gk
            Gk[:, k * nu : (k + 1) * nu] += Bd
            gk = Ad @ gk + c
            M[qp.ix(k + 1) : qp.ix(k + 1) + nx, :] = Gk
            m0[qp.ix(k + 1) : qp.ix(k + 1) + nx] = gk
        q = qp.q[: self._nz]
        PM = self._P @ M
        H = M.T @ PM
        g = M.T @ (self._P @ m0 + q)
        return 0.5 * (H + H.T), g

    # -- solve ----------------------------------------------------------------------------------
    def solve(self, warm_X: np.ndarray | None = None, warm_U: np.ndarray | None = None) -> SolveResult:
        """Minimize the condensed cost over the input box from ``warm_U`` (N, nu) (zeros when None)."""
        t0 = time.perf_counter()
        qp, st = self.qp, self.settings
        nan = float("nan")
        finite = (
            np.isfinite(qp.q).all()
            and np.isfinite(qp.A.data).all()
            and np.isfinite(qp.l[: qp.r_dyn + qp.N * qp.nx]).all()
        )
        if not finite:
            return SolveResult(
                STATUS_FAILED,
                np.full((qp.N + 1, qp.nx), nan),
                np.full((qp.N, qp.nu), nan),
                nan,
                0,
                time.perf_counter() - t0,
            )
        H, g = self._condense()
        self.last_condensed = (H, g)
        L = float(np.linalg.eigvalsh(H)[-1])
        if not (np.isfinite(L) and L > 0):
            return SolveResult(
                STATUS_FAILED,
                np.full((qp.N + 1, qp.nx), nan),
                np.full((qp.N, qp.nu), nan),
                nan,
                0,
                time.perf_counter() - t0,
            )
        step = 1.0 / L
        lo, hi = self._lo, self._hi
        U = np.zeros(qp.n_u) if warm_U is None else np.ravel(np.asarray(warm_U, float)).copy()
        if not np.all(np.isfinite(U)):
            U = np.zeros(qp.n_u)
        U = np.clip(U, lo, hi)
        Y, U_prev, t = U.copy(), U.copy(), 1.0
        status, it = STATUS_INACCURATE, st.max_iter
        for i in range(1, st.max_iter + 1):
            base = Y if st.accelerated else U
            U_new = np.clip(base - step * (H @ base + g), lo, hi)
            if st.accelerated:
                # adaptive restart when the momentum points uphill
                if np.dot(base - U_new, U_new - U) > 0.0:
                    t = 1.0
                t_next = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
                Y = U_new + ((t - 1.0) / t_next) * (U_new - U)
                t = t_next
            U_prev, U = U, U_new
            # projected-gradient step at the current iterate (the optimality measure)
            res = (
                np.max(np.abs(np.clip(U - step * (H @ U + g), lo, hi) - U))
                if st.accelerated
                else np.max(np.abs(U - U_prev))
            )
            if res <= st.tol:
                status, it = STATUS_OK, i
                break
        z = self._M @ U + self._m0
        cost = float(0.5 * z @ (self._P @ z) + qp.q[: self._nz] @ z)
        X = z[: qp.n_x].reshape(qp.N + 1, qp.nx).copy()
        return SolveResult(status, X, U.reshape(qp.N, qp.nu).copy(), cost, it, time.perf_counter() - t0)
