"""The LTV-MPC problem as one sparse QP, built once and updated in place.

Decision vector ``z = [x_0, ..., x_N, u_0, ..., u_{N-1}, eps_1, ..., eps_N]`` (``eps`` only
with a lane bound). The QP is ``min 1/2 z'Pz + q'z  s.t.  l <= Az <= u`` (OSQP's form). The
sparsity pattern of ``A`` never changes; each step only the numbers of the dynamics blocks and
of the lane rows change, written through a fixed map into the CSC data array ``Ax``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .problem import MpcProblem


@dataclass(frozen=True)
class QpData:
    """The QP in OSQP form; ``P`` upper-triangular CSC, ``A`` CSC (views of live buffers)."""

    P: sp.csc_matrix
    q: np.ndarray
    A: sp.csc_matrix
    l: np.ndarray
    u: np.ndarray


class LtvQp:
    """Layout and in-place update of the tracking QP of an :class:`MpcProblem`."""

    def __init__(self, problem: MpcProblem):
        self.problem = pb = problem
        nx, nu, N = pb.nx, pb.nu, pb.N
        self.nx, self.nu, self.N = nx, nu, N
        self.lane = pb.lane_half_width_m is not None
        self.n_x = (N + 1) * nx
        self.n_u = N * nu
        self.n_eps = N if self.lane else 0
        self.n_var = self.n_x + self.n_u + self.n_eps
        self._build_cost()
        self._build_constraints()

    # -- indices --------------------------------------------------------------------------
    def ix(self, k: int) -> int:
        return k * self.nx

    def iu(self, k: int) -> int:
        return self.n_x + k * self.nu

    def ie(self, k: int) -> int:
        """Slack of step k = 1..N."""
        return self.n_x + self.n_u + (k - 1)

    # -- cost ---------------------------------------------------------------------------
    def _build_cost(self):
        pb, N, nx = self.problem, self.N, self.nx
        blocks = [sp.csc_matrix((nx, nx))]  # x_0 is fixed by a constraint
        blocks += [sp.csc_matrix(2.0 * pb.Q)] * (N - 1) + [sp.csc_matrix(2.0 * pb.QN)]
        # inputs: R on each u_k, Rc on differences (u_0 - u_prev is handled in q)
        D = sp.eye(N, format="csc") - sp.eye(N, k=-1, format="csc")
        Puu = sp.kron(sp.eye(N), pb.R) + sp.kron(D.T @ D, pb.Rc)
        blocks.append(sp.csc_matrix(2.0 * Puu))
        if self.lane:
            blocks.append(sp.eye(N, format="csc") * (2.0 * pb.lane_slack_weight))
        P = sp.block_diag(blocks, format="csc")
        self.P = sp.triu(P, format="csc")
        self.P.sort_indices()
        self.q = np.zeros(self.n_var)
        if self.lane:
            self.q[self.n_x + self.n_u:] = pb.lane_slack_weight_l1
        self._Qstack = np.stack([pb.Q] * (N - 1) + [pb.QN])  # (N, nx, nx) weights of x_1..x_N

    # -- constraints --------------------------------------------------------------------
    def _build_constraints(self):
        pb, N, nx, nu = self.problem, self.N, self.nx, self.nu
        rows, cols, vals = [], [], []
        lo, hi = [], []
        r = 0

        def add(rr, cc, vv):
            rows.append(np.asarray(rr).ravel())
            cols.append(np.asarray(cc).ravel())
            vals.append(np.broadcast_to(np.asarray(vv, float), np.shape(rr)).ravel())

        # initial state x_0 = x_meas
        self.r_init = r
        add(r + np.arange(nx), self.ix(0) + np.arange(nx), 1.0)
        lo.append(np.zeros(nx))
        hi.append(np.zeros(nx))
        r += nx
        # dynamics x_{k+1} - A_k x_k - B_k u_k = c_k ; A_k, B_k blocks are updatable slots
        self.r_dyn = r
        ii, jj = np.meshgrid(np.arange(nx), np.arange(nx), indexing="ij")
        iu_, ju_ = np.meshgrid(np.arange(nx), np.arange(nu), indexing="ij")
        slot_A, slot_B = [], []
        nnz = nx  # the initial-state rows
        for k in range(N):
            rk = r + k * nx
            add(rk + np.arange(nx), self.ix(k + 1) + np.arange(nx), 1.0)
            nnz += nx
            slot_A.append(nnz + np.arange(nx * nx))
            add(rk + ii, self.ix(k) + jj, -1.0)
            nnz += nx * nx
            slot_B.append(nnz + np.arange(nx * nu))
            add(rk + iu_, self.iu(k) + ju_, -1.0)
            nnz += nx * nu
        lo.append(np.zeros(N * nx))
        hi.append(np.zeros(N * nx))
        r += N * nx
        self._slot_A = np.concatenate(slot_A)
        self._slot_B = np.concatenate(slot_B)
        # input bounds
        self.r_ubound = r
        add(r + np.arange(N * nu), self.n_x + np.arange(N * nu), 1.0)
        nnz += N * nu
        lo.append(np.tile(pb.u_min, N))
        hi.append(np.tile(pb.u_max, N))
        r += N * nu
        # input rate: u_0 - u_prev and u_k - u_{k-1}
        self.r_rate = None
        if pb.has_rate_limit:
            self.r_rate = r
            add(r + np.arange(N * nu), self.n_x + np.arange(N * nu), 1.0)
            nnz += N * nu
            add(r + nu + np.arange((N - 1) * nu), self.n_x + np.arange((N - 1) * nu), -1.0)
            nnz += (N - 1) * nu
            dmax = np.tile(pb.du_max_per_s * pb.dt_s, N)
            lo.append(-dmax)
            hi.append(dmax.copy())
            r += N * nu
        # state bounds on bounded components, k = 1..N
        bs = pb.bounded_states
        self.r_xbound = r
        if bs.size:
            for k in range(1, N + 1):
                add(r + np.arange(bs.size), self.ix(k) + bs, 1.0)
                nnz += bs.size
                lo.append(pb.x_min[bs])
                hi.append(pb.x_max[bs])
                r += bs.size
        # lane: n_k . p_k - eps_k <= b_k + w ; n_k . p_k + eps_k >= b_k - w ; eps_k >= 0
        self.r_lane = None
        if self.lane:
            self.r_lane = r
            slot_n = []
            for k in range(1, N + 1):
                ra, rb = r + 2 * (k - 1), r + 2 * (k - 1) + 1
                slot_n.append(nnz + np.arange(2))
                add([ra, ra], [self.ix(k), self.ix(k) + 1], 0.0)
                add([ra], [self.ie(k)], -1.0)
                slot_n.append(nnz + 3 + np.arange(2))
                add([rb, rb], [self.ix(k), self.ix(k) + 1], 0.0)
                add([rb], [self.ie(k)], 1.0)
                nnz += 6
            self._slot_n = np.concatenate(slot_n)  # (N*4,) order: k, row(a,b), (nx, ny)
            lo.append(np.zeros(2 * N))
            hi.append(np.zeros(2 * N))
            r += 2 * N
            add(r + np.arange(N), self.ie(1) + np.arange(N), 1.0)
            nnz += N
            lo.append(np.zeros(N))
            hi.append(np.full(N, np.inf))
            r += N
        self.n_con = r
        rows = np.concatenate(rows)
        cols = np.concatenate(cols)
        self._coo_vals = np.concatenate(vals)
        if self._coo_vals.size != nnz:
            raise RuntimeError("internal error: QP slot map out of step with its pattern")
        # CSC pattern and the map CSC position -> COO slot
        tag = sp.csc_matrix((np.arange(1, nnz + 1, dtype=float), (rows, cols)), shape=(r, self.n_var))
        tag.sort_indices()
        if tag.nnz != nnz:
            raise RuntimeError("internal error: duplicate entries in the QP constraint pattern")
        self._perm = (tag.data - 1).astype(np.intp)
        self.A = sp.csc_matrix((self._coo_vals[self._perm], tag.indices.copy(), tag.indptr.copy()), shape=(r, self.n_var))
        self.l = np.concatenate(lo)
        self.u = np.concatenate(hi)
        if self.lane:
            self.u[self.r_lane:self.r_lane + 2 * N:2] = 0.0
            self.l[self.r_lane:self.r_lane + 2 * N:2] = -np.inf
            self.l[self.r_lane + 1:self.r_lane + 2 * N:2] = 0.0
            self.u[self.r_lane + 1:self.r_lane + 2 * N:2] = np.inf
        self._rate_base_lo = self.l[self.r_rate:self.r_rate + nu].copy() if self.r_rate is not None else None
        self._rate_base_hi = self.u[self.r_rate:self.r_rate + nu].copy() if self.r_rate is not None else None

    # -- per-step update --------------------------------------------------------------------
    def update(self, x0, Ad, Bd, c, xref, uref, u_prev, lane_normal=None, lane_offset=None) -> None:
        """Write one step's numbers into ``q``, ``l``, ``u`` and ``A.data`` in place.

        x0 : (nx,) measured state; Ad : (N, nx, nx), Bd : (N, nx, nu), c : (N, nx) the affine
        prediction model ``x_{k+1} = Ad_k x_k + Bd_k u_k + c_k``; xref : (N+1, nx) state references
        (row 0 unused); uref : (N, nu) input references; u_prev : (nu,) last applied input;
        lane_normal : (N, 2) unit left normals of the path at steps 1..N; lane_offset : (N,)
        ``n_k . p_ref,k`` [m] (the lane centre).
        """
        N, nx, nu = self.N, self.nx, self.nu
        pb = self.problem
        # equality rows
        self.l[self.r_init:self.r_init + nx] = x0
        self.u[self.r_init:self.r_init + nx] = x0
        cflat = np.ravel(c)
        self.l[self.r_dyn:self.r_dyn + N * nx] = cflat
        self.u[self.r_dyn:self.r_dyn + N * nx] = cflat
        self._coo_vals[self._slot_A] = -np.ravel(Ad)
        self._coo_vals[self._slot_B] = -np.ravel(Bd)
        # cost: q_x = -2 W r ; q_u = -2 R ur ; minus 2 Rc u_prev on u_0
        qx = self.q[nx:self.n_x].reshape(N, nx)
        np.einsum("kij,kj->ki", self._Qstack, xref[1:], out=qx)
        qx *= -2.0
        qu = self.q[self.n_x:self.n_x + self.n_u].reshape(N, nu)
        np.matmul(uref, pb.R.T, out=qu)
        qu *= -2.0
        qu[0] -= 2.0 * (pb.Rc @ u_prev)
        if self.r_rate is not None:
            self.l[self.r_rate:self.r_rate + nu] = self._rate_base_lo + u_prev
            self.u[self.r_rate:self.r_rate + nu] = self._rate_base_hi + u_prev
        if self.lane:
            if lane_normal is None or lane_offset is None:
                raise ValueError("this problem has a lane bound: pass lane_normal and lane_offset")
            n2 = np.repeat(lane_normal[:, None, :], 2, axis=1)  # (N, 2 rows, 2)
            self._coo_vals[self._slot_n] = n2.ravel()
            w = pb.lane_half_width_m
            self.u[self.r_lane:self.r_lane + 2 * N:2] = lane_offset + w
            self.l[self.r_lane + 1:self.r_lane + 2 * N:2] = lane_offset - w
        np.take(self._coo_vals, self._perm, out=self.A.data)

    def data(self) -> QpData:
        return QpData(self.P, self.q, self.A, self.l, self.u)

    # -- packing ----------------------------------------------------------------------------
    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """z -> (X (N+1, nx), U (N, nu), eps (N,) or empty)."""
        X = z[: self.n_x].reshape(self.N + 1, self.nx)
        U = z[self.n_x:self.n_x + self.n_u].reshape(self.N, self.nu)
        return X, U, z[self.n_x + self.n_u:]

    def pack(self, X: np.ndarray, U: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(X, U) -> z (slacks zero), for warm starts."""
        z = np.zeros(self.n_var) if out is None else out
        z[: self.n_x] = np.ravel(X)
        z[self.n_x:self.n_x + self.n_u] = np.ravel(U)
        z[self.n_x + self.n_u:] = 0.0
        return z
