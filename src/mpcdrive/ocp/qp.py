"""The LTV-MPC problem as one sparse QP, built once and updated in place.

Decision vector ``z = [x_0..x_N, u_0..u_{N-1}, eps_1..eps_N, sigma_1..sigma_N]`` (lane slacks
``eps`` only with a lane bound, obstacle slacks ``sigma`` only with obstacle rows). The QP is
``min 1/2 z'Pz + q'z  s.t.  l <= Az <= u`` (OSQP's form). The sparsity patterns of ``P`` and
``A`` never change; each step only numbers change, written through fixed maps ("slots") into
the CSC data arrays.
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


class _Pattern:
    """COO entries collected with their slot numbers, frozen into a CSC matrix + slot map."""

    def __init__(self):
        self.rows, self.cols, self.vals = [], [], []
        self.nnz = 0

    def add(self, rr, cc, vv) -> np.ndarray:
        rr = np.asarray(rr).ravel()
        cc = np.asarray(cc).ravel()
        self.rows.append(rr)
        self.cols.append(cc)
        self.vals.append(np.broadcast_to(np.asarray(vv, float), rr.shape).ravel())
        slots = self.nnz + np.arange(rr.size)
        self.nnz += rr.size
        return slots

    def freeze(self, shape) -> tuple[sp.csc_matrix, np.ndarray, np.ndarray]:
        rows = np.concatenate(self.rows)
        cols = np.concatenate(self.cols)
        vals = np.concatenate(self.vals)
        tag = sp.csc_matrix((np.arange(1, self.nnz + 1, dtype=float), (rows, cols)), shape=shape)
        tag.sort_indices()
        if tag.nnz != self.nnz:
            raise RuntimeError("internal error: duplicate entries in a QP pattern")
        perm = (tag.data - 1).astype(np.intp)
        M = sp.csc_matrix((vals[perm], tag.indices.copy(), tag.indptr.copy()), shape=shape)
        return M, vals, perm


class LtvQp:
    """Layout and in-place update of the tracking QP of an :class:`MpcProblem`."""

    def __init__(self, problem: MpcProblem):
        self.problem = pb = problem
        nx, nu, N = pb.nx, pb.nu, pb.N
        self.nx, self.nu, self.N = nx, nu, N
        self.lane = pb.lane
        #: the road rows are linearized in the yaw (state 2) when the model has one
        self.lane_yaw = self.lane and nx >= 3
        self.n_obs_rows = int(pb.obstacle_rows)
        self.n_x = (N + 1) * nx
        self.n_u = N * nu
        self.n_eps = N if self.lane else 0
        self.n_sig = N if self.n_obs_rows else 0
        self.n_var = self.n_x + self.n_u + self.n_eps + self.n_sig
        self._build_cost()
        self._build_constraints()

    # -- indices --------------------------------------------------------------------------
    def ix(self, k: int) -> int:
        return k * self.nx

    def iu(self, k: int) -> int:
        return self.n_x + k * self.nu

    def ie(self, k: int) -> int:
        """Lane slack of step k = 1..N."""
        return self.n_x + self.n_u + (k - 1)

    def isig(self, k: int) -> int:
        """Obstacle slack of step k = 1..N."""
        return self.n_x + self.n_u + self.n_eps + (k - 1)

    # -- cost ---------------------------------------------------------------------------
    def _build_cost(self):
        pb, N, nx = self.problem, self.N, self.nx
        pat = _Pattern()
        # states x_1..x_N: the full upper triangle of each block is a slot (non-convex costs add
        # (x, y) Hessians there); x_0 is fixed by a constraint and has no cost
        iu_, ju_ = np.triu_indices(nx)
        self._slot_Px = np.empty((N, iu_.size), dtype=np.intp)
        for k in range(1, N + 1):
            W = pb.QN if k == N else pb.Q
            self._slot_Px[k - 1] = pat.add(self.ix(k) + iu_, self.ix(k) + ju_, 2.0 * W[iu_, ju_])
        if nx >= 2:
            self._Pxy = [int(np.flatnonzero((iu_ == a) & (ju_ == b))[0]) for a, b in ((0, 0), (0, 1), (1, 1))]
        # inputs: R on each u_k, Rc on differences (u_0 - u_prev is handled in q)
        D = sp.eye(N, format="csc") - sp.eye(N, k=-1, format="csc")
        Puu = sp.triu(sp.kron(sp.eye(N), pb.R) + sp.kron(D.T @ D, pb.Rc), format="coo")
        keep = Puu.data != 0
        pat.add(self.n_x + Puu.row[keep], self.n_x + Puu.col[keep], 2.0 * Puu.data[keep])
        if self.lane:
            j = self.ie(1) + np.arange(N)
            pat.add(j, j, 2.0 * pb.lane_slack_weight)
        if self.n_sig:
            j = self.isig(1) + np.arange(N)
            pat.add(j, j, 2.0 * pb.obstacle_slack_weight)
        self.P, self._P_base, self._perm_P = pat.freeze((self.n_var, self.n_var))
        self._P_vals = self._P_base.copy()
        self._P_has_terms = False  # step terms added to _P_vals since the last reset
        self._P_dirty = False  # _P_vals differs from P.data
        self.q = np.zeros(self.n_var)
        self._q_const = np.zeros(self.n_var)
        if self.lane:
            self._q_const[self.ie(1) : self.ie(1) + N] = pb.lane_slack_weight_l1
        if self.n_sig:
            self._q_const[self.isig(1) : self.isig(1) + N] = pb.obstacle_slack_weight_l1
        self.q[:] = self._q_const
        self._Qstack = pb.stage_weights()  # (N, nx, nx) weights of x_1..x_N

    # -- constraints --------------------------------------------------------------------
    def _build_constraints(self):
        pb, N, nx, nu = self.problem, self.N, self.nx, self.nu
        pat = _Pattern()
        lo, hi = [], []
        r = 0
        # initial state x_0 = x_meas
        self.r_init = r
        pat.add(r + np.arange(nx), self.ix(0) + np.arange(nx), 1.0)
        lo.append(np.zeros(nx))
        hi.append(np.zeros(nx))
        r += nx
        # dynamics x_{k+1} - A_k x_k - B_k u_k = c_k ; A_k, B_k blocks are slots
        self.r_dyn = r
        ii, jj = np.meshgrid(np.arange(nx), np.arange(nx), indexing="ij")
        iu_, ju_ = np.meshgrid(np.arange(nx), np.arange(nu), indexing="ij")
        slot_A, slot_B = [], []
        for k in range(N):
            rk = r + k * nx
            pat.add(rk + np.arange(nx), self.ix(k + 1) + np.arange(nx), 1.0)
            slot_A.append(pat.add(rk + ii, self.ix(k) + jj, -1.0))
            slot_B.append(pat.add(rk + iu_, self.iu(k) + ju_, -1.0))
        self._slot_A = np.concatenate(slot_A)
        self._slot_B = np.concatenate(slot_B)
        lo.append(np.zeros(N * nx))
        hi.append(np.zeros(N * nx))
        r += N * nx
        # input bounds
        self.r_ubound = r
        pat.add(r + np.arange(N * nu), self.n_x + np.arange(N * nu), 1.0)
        lo.append(np.tile(pb.u_min, N))
        hi.append(np.tile(pb.u_max, N))
        r += N * nu
        # input rate: u_0 - u_prev and u_k - u_{k-1}
        self.r_rate = None
        if pb.has_rate_limit:
            self.r_rate = r
            pat.add(r + np.arange(N * nu), self.n_x + np.arange(N * nu), 1.0)
            pat.add(r + nu + np.arange((N - 1) * nu), self.n_x + np.arange((N - 1) * nu), -1.0)
            dmax = np.tile(pb.du_max_per_s * pb.dt_s, N)
            lo.append(-dmax)
            hi.append(dmax.copy())
            r += N * nu
        # state bounds on bounded components, k = 1..N
        bs = pb.bounded_states
        if bs.size:
            for k in range(1, N + 1):
                pat.add(r + np.arange(bs.size), self.ix(k) + bs, 1.0)
                lo.append(pb.x_min[bs])
                hi.append(pb.x_max[bs])
                r += bs.size
        # lane: n_k . p_k - eps_k <= hi_k ; n_k . p_k + eps_k >= lo_k ; eps_k >= 0
        self.r_lane = None
        if self.lane:
            self.r_lane = r
            slot_n = []
            slot_yaw = []
            for k in range(1, N + 1):
                ra, rb = r + 2 * (k - 1), r + 2 * (k - 1) + 1
                slot_n.append(pat.add([ra, ra], [self.ix(k), self.ix(k) + 1], 0.0))
                pat.add([ra], [self.ie(k)], -1.0)
                slot_n.append(pat.add([rb, rb], [self.ix(k), self.ix(k) + 1], 0.0))
                pat.add([rb], [self.ie(k)], 1.0)
                if self.lane_yaw:
                    slot_yaw.append(pat.add([ra, rb], [self.ix(k) + 2, self.ix(k) + 2], 0.0))
            self._slot_n = np.concatenate(slot_n)  # order: k, row (a, b), (nx, ny)
            if self.lane_yaw:
                self._slot_yaw = np.concatenate(slot_yaw)  # order: k, row (a, b)
            lo.append(np.tile([-np.inf, 0.0], N))
            hi.append(np.tile([0.0, np.inf], N))
            r += 2 * N
            pat.add(r + np.arange(N), self.ie(1) + np.arange(N), 1.0)
            lo.append(np.zeros(N))
            hi.append(np.full(N, np.inf))
            r += N
        # obstacles: a_km . (x_k, y_k, yaw_k) + sigma_k >= b_km ; sigma_k >= 0
        self.r_obs = None
        if self.n_obs_rows:
            M = self.n_obs_rows
            self.r_obs = r
            slot_o = np.empty((N, M, 3), dtype=np.intp)
            for k in range(1, N + 1):
                for m in range(M):
                    row = r + (k - 1) * M + m
                    slot_o[k - 1, m] = pat.add([row] * 3, self.ix(k) + np.arange(3), 0.0)
                    pat.add([row], [self.isig(k)], 1.0)
            self._slot_o = slot_o.reshape(-1)
            lo.append(np.full(N * M, -np.inf))
            hi.append(np.full(N * M, np.inf))
            r += N * M
            pat.add(r + np.arange(N), self.isig(1) + np.arange(N), 1.0)
            lo.append(np.zeros(N))
            hi.append(np.full(N, np.inf))
            r += N
        self.n_con = r
        self.A, self._coo_vals, self._perm = pat.freeze((r, self.n_var))
        self.l = np.concatenate(lo)
        self.u = np.concatenate(hi)
        if self.r_rate is not None:
            self._rate_base_lo = self.l[self.r_rate : self.r_rate + nu].copy()
            self._rate_base_hi = self.u[self.r_rate : self.r_rate + nu].copy()

    # -- per-step update --------------------------------------------------------------------
    def update(
        self,
        x0,
        Ad,
        Bd,
        c,
        xref,
        uref,
        u_prev,
        lane_normal=None,
        lane_offset=None,
        lane_lo=None,
        lane_hi=None,
        lane_slopes=None,
    ) -> None:
        """Write one step's numbers into ``q``, ``l``, ``u`` and ``A.data`` in place.

        x0 : (nx,) measured state; Ad : (N, nx, nx), Bd : (N, nx, nu), c : (N, nx) the affine
        prediction model ``x_{k+1} = Ad_k x_k + Bd_k u_k + c_k``; xref : (N+1, nx) state references
        (row 0 unused); uref : (N, nu) input references; u_prev : (nu,) last applied input;
        lane_normal : (N, 2) unit left normals of the path at steps 1..N; lane_offset : (N,)
        ``n_k . p_ref,k`` [m] (the path); lane_lo, lane_hi : (N,) lateral bounds [m] relative to
        the path (the road's, possibly narrowed); lane_slopes : optional ``(dlo, dhi, yaw)``
        (N,) each: the bounds' slopes [m/rad] in the yaw at linearization yaws ``yaw`` [rad],
        making the rows ``n . p - dhi yaw_k <= offset + hi - dhi yaw`` (and the same for lo);
        :class:`~mpcdrive.ocp.road_rows.RoadRows`.
        Obstacle rows and cost terms are written separately (:meth:`set_obstacle_rows`,
        :meth:`add_position_cost`) after this call.
        """
        N, nx, nu = self.N, self.nx, self.nu
        pb = self.problem
        self.l[self.r_init : self.r_init + nx] = x0
        self.u[self.r_init : self.r_init + nx] = x0
        cflat = np.ravel(c)
        self.l[self.r_dyn : self.r_dyn + N * nx] = cflat
        self.u[self.r_dyn : self.r_dyn + N * nx] = cflat
        self._coo_vals[self._slot_A] = -np.ravel(Ad)
        self._coo_vals[self._slot_B] = -np.ravel(Bd)
        # cost: q_x = -2 W r ; q_u = -2 R ur ; minus 2 Rc u_prev on u_0
        self.q[:] = self._q_const
        qx = self.q[nx : self.n_x].reshape(N, nx)
        np.einsum("kij,kj->ki", self._Qstack, xref[1:], out=qx)
        qx *= -2.0
        qu = self.q[self.n_x : self.n_x + self.n_u].reshape(N, nu)
        np.matmul(uref, pb.R.T, out=qu)
        qu *= -2.0
        qu[0] -= 2.0 * (pb.Rc @ u_prev)
        if self.r_rate is not None:
            self.l[self.r_rate : self.r_rate + nu] = self._rate_base_lo + u_prev
            self.u[self.r_rate : self.r_rate + nu] = self._rate_base_hi + u_prev
        if self.lane:
            if lane_normal is None or lane_offset is None or lane_lo is None or lane_hi is None:
                raise ValueError("this problem has a road: pass lane_normal, lane_offset, lane_lo and lane_hi")
            n2 = np.repeat(lane_normal[:, None, :], 2, axis=1)  # (N, 2 rows, 2)
            self._coo_vals[self._slot_n] = n2.ravel()
            if self.lane_yaw:
                dlo, dhi, yaw = (np.zeros(N),) * 3 if lane_slopes is None else lane_slopes
                self._coo_vals[self._slot_yaw] = np.column_stack([-dhi, -dlo]).ravel()
                self.u[self.r_lane : self.r_lane + 2 * N : 2] = lane_offset + lane_hi - dhi * yaw
                self.l[self.r_lane + 1 : self.r_lane + 2 * N : 2] = lane_offset + lane_lo - dlo * yaw
            else:
                self.u[self.r_lane : self.r_lane + 2 * N : 2] = lane_offset + lane_hi
                self.l[self.r_lane + 1 : self.r_lane + 2 * N : 2] = lane_offset + lane_lo
        if self.n_obs_rows:
            self.l[self.r_obs : self.r_obs + N * self.n_obs_rows] = -np.inf
        if self._P_has_terms:
            self._P_vals[:] = self._P_base
            self._P_has_terms = False
            self._P_dirty = True
        np.take(self._coo_vals, self._perm, out=self.A.data)

    def load_step(self, d, u_prev) -> None:
        """Everything of one step's data ``d`` (:class:`~mpcdrive.control.mpc.StepData`: the
        affine model, references, road rows, per-stage input bounds, obstacle rows, position cost)
        into the QP, the input
        applied before it being ``u_prev``."""
        self.update(
            d.x,
            d.Ad,
            d.Bd,
            d.c,
            d.xref,
            d.uref,
            u_prev,
            d.lane_normal,
            d.lane_offset,
            d.lane_lo,
            d.lane_hi,
            d.lane_slopes,
        )
        if d.u_lo is not None and d.u_hi is not None:
            self.set_input_bounds(d.u_lo, d.u_hi)
        if d.rows_a is not None and d.rows_b is not None and self.n_obs_rows:  # set together (AvoidanceTerms)
            self.set_obstacle_rows(d.rows_a, d.rows_b)
        if d.H is not None and d.g is not None and self.problem.position_cost:
            self.add_position_cost(d.H, d.g)

    def set_input_bounds(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Per-stage input bounds ``lo[k] <= u_k <= hi[k]`` (N, nu) for this step (e.g. the
        friction circle's, :mod:`mpcdrive.ocp.friction`), in place of the problem's."""
        n = self.N * self.nu
        self.l[self.r_ubound : self.r_ubound + n] = np.ravel(lo)
        self.u[self.r_ubound : self.r_ubound + n] = np.ravel(hi)

    def set_obstacle_rows(self, a: np.ndarray, b: np.ndarray) -> None:
        """Obstacle half-planes ``a[k-1, m] . (x_k, y_k, yaw_k) >= b[k-1, m]`` (soft, slack sigma_k).

        a : (N, M, 3); b : (N, M) with -inf for unused rows. Call after :meth:`update`."""
        N, M = self.N, self.n_obs_rows
        if a.shape != (N, M, 3) or b.shape != (N, M):
            raise ValueError(f"obstacle rows must have shapes ({N}, {M}, 3) and ({N}, {M})")
        self._coo_vals[self._slot_o] = a.reshape(-1)
        self.l[self.r_obs : self.r_obs + N * M] = b.reshape(-1)
        np.take(self._coo_vals, self._perm, out=self.A.data)

    def add_position_cost(self, H: np.ndarray, g: np.ndarray) -> None:
        """Add ``sum_k 1/2 p_k' H_k p_k + g_k . p_k`` on positions p_k = (x_k, y_k), k = 1..N.

        H : (N, 2, 2) positive semidefinite; g : (N, 2). Call after :meth:`update`."""
        if not self.problem.position_cost:
            raise ValueError("this problem was built without position_cost=True")
        i00, i01, i11 = self._Pxy
        self._P_vals[self._slot_Px[:, i00]] += H[:, 0, 0]
        self._P_vals[self._slot_Px[:, i01]] += H[:, 0, 1]
        self._P_vals[self._slot_Px[:, i11]] += H[:, 1, 1]
        qx = self.q[self.nx : self.n_x].reshape(self.N, self.nx)
        qx[:, :2] += g
        self._P_has_terms = True
        self._P_dirty = True

    def finalize_cost(self) -> bool:
        """Write the P values into ``P.data``; True when P changed since the last solve."""
        if not self._P_dirty:
            return False
        np.take(self._P_vals, self._perm_P, out=self.P.data)
        self._P_dirty = False
        return True

    def data(self) -> QpData:
        return QpData(self.P, self.q, self.A, self.l, self.u)

    # -- packing ----------------------------------------------------------------------------
    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """z -> (X (N+1, nx), U (N, nu), slacks (lane then obstacle) or empty)."""
        X = z[: self.n_x].reshape(self.N + 1, self.nx)
        U = z[self.n_x : self.n_x + self.n_u].reshape(self.N, self.nu)
        return X, U, z[self.n_x + self.n_u :]

    def pack(self, X: np.ndarray, U: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(X, U) -> z (slacks zero), for warm starts."""
        z = np.zeros(self.n_var) if out is None else out
        z[: self.n_x] = np.ravel(X)
        z[self.n_x : self.n_x + self.n_u] = np.ravel(U)
        z[self.n_x + self.n_u :] = 0.0
        return z
