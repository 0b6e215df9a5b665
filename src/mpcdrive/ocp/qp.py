"""The LTV-MPC problem as one sparse QP, built once and updated in place.

Decision vector ``z = [x_0..x_N, u_0..u_{N-1}, eps_1..eps_N, sigma_1..sigma_N]`` (lane slacks
``eps`` only with a lane bound, obstacle slacks ``sigma`` only with obstacle rows). The QP is
``min 1/2 z'Pz + q'z  s.t.  l <= Az <= u`` (OSQP's form). The sparsity patterns of ``P`` and
``A`` never change; each step only numbers change: :meth:`LtvQp.load_stage` writes a step's
stage QP (:class:`~mpcdrive.ocp.stage_qp.StageQp`, what every solver consumes) through fixed
maps ("slots") into the CSC data arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .problem import MpcProblem
from .stage_qp import StageQp


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
        # states x_1..x_N: the full upper triangle of each block is a slot (a stage's weights We
        # hold an obstacle cost's (x, y) Hessian there); x_0 is fixed by a constraint and has no cost
        self._triu = iu_, ju_ = np.triu_indices(nx)
        self._slot_Px = np.empty((N, iu_.size), dtype=np.intp)
        for k in range(1, N + 1):
            W = pb.QN if k == N else pb.Q
            self._slot_Px[k - 1] = pat.add(self.ix(k) + iu_, self.ix(k) + ju_, 2.0 * W[iu_, ju_])
        # inputs: R on each u_k, Rc on differences (u_0 - u_prev is handled in q); the entries
        # where R or Rc have one (a step may scale them: StageQp.R, StageQp.Rc)
        D = np.eye(N) - np.eye(N, k=-1)
        self._DtD = D.T @ D
        nz = np.kron(np.eye(N), pb.R != 0) + np.kron(self._DtD != 0, pb.Rc != 0)
        self._uu = iu, ju = np.nonzero(np.triu(nz))
        self._R, self._Rc = pb.R.copy(), pb.Rc.copy()
        self._slot_Pu = pat.add(self.n_x + iu, self.n_x + ju, 2.0 * self._input_block(pb.R, pb.Rc))
        if self.lane:
            j = self.ie(1) + np.arange(N)
            pat.add(j, j, 2.0 * pb.lane_slack_weight)
        if self.n_sig:
            j = self.isig(1) + np.arange(N)
            pat.add(j, j, 2.0 * pb.obstacle_slack_weight)
        self.P, self._P_base, self._perm_P = pat.freeze((self.n_var, self.n_var))
        self._P_vals = self._P_base.copy()
        self._P_dirty = False  # _P_vals differs from P.data
        self.q = np.zeros(self.n_var)
        self._q_const = np.zeros(self.n_var)
        if self.lane:
            self._q_const[self.ie(1) : self.ie(1) + N] = pb.lane_slack_weight_l1
        if self.n_sig:
            self._q_const[self.isig(1) : self.isig(1) + N] = pb.obstacle_slack_weight_l1
        self.q[:] = self._q_const
        self._We = pb.stage_weights()  # (N, nx, nx) the state weights of x_1..x_N in P

    def _input_block(self, R: np.ndarray, Rc: np.ndarray) -> np.ndarray:
        """The input cost's Hessian entries (halved) at the pattern's input slots for weights R, Rc."""
        M = np.kron(np.eye(self.N), R) + np.kron(self._DtD, Rc)
        return M[self._uu]

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
    def load_stage(self, st: StageQp, x0: np.ndarray, u_prev: np.ndarray) -> None:
        """Write one step's stage QP ``st`` (:class:`~mpcdrive.ocp.stage_qp.StageQp`, the data
        every solver consumes) into ``q``, ``l``, ``u``, ``A.data`` and, where its state weights
        changed, ``P``, in place; ``x0`` (nx,) is the measured state, ``u_prev`` (nu,) the input
        applied before it.

        From ``st`` this reads what changes per step: the affine model, the state weights ``We``
        and their linear terms ``qt`` (the cost ``x' We x - 2 qt' x``), the input weights ``R``,
        ``Rc`` (a step may scale the steering's, ``MpcConfig.steer_weight_speed_mps``; the
        entries where the problem's are zero stay zero), the input references, the
        per-stage input bounds, the road rows (linearized in the yaw at ``Xlin``, when the model
        has one) and the obstacle rows. The slack weights, rate limits and state bounds are this
        QP's problem's (the relaxed problem of the fallback reads the same stage data). Raises
        ``ValueError`` when ``st`` is not sized for this QP."""
        N, nx, nu = self.N, self.nx, self.nu
        if (st.N, st.nx, st.nu) != (N, nx, nu) or st.nrow != self.n_obs_rows or st.lane != self.lane:
            raise ValueError(
                f"the stage QP (N={st.N}, nx={st.nx}, nu={st.nu}, {st.nrow} obstacle rows, road rows "
                f"{st.lane}) does not fit this QP (N={N}, nx={nx}, nu={nu}, {self.n_obs_rows} obstacle "
                f"rows, road rows {self.lane})"
            )
        self.l[self.r_init : self.r_init + nx] = x0
        self.u[self.r_init : self.r_init + nx] = x0
        cflat = st.c.reshape(-1)
        self.l[self.r_dyn : self.r_dyn + N * nx] = cflat
        self.u[self.r_dyn : self.r_dyn + N * nx] = cflat
        self._coo_vals[self._slot_A] = -st.A.reshape(-1)
        self._coo_vals[self._slot_B] = -st.B.reshape(-1)
        # cost: P_x = 2 We, q_x = -2 qt ; q_u = -2 R ur ; minus 2 Rc u_prev on u_0
        if not np.array_equal(st.We, self._We):
            self._We[...] = st.We
            iu_, ju_ = self._triu
            self._P_vals[self._slot_Px] = 2.0 * st.We[:, iu_, ju_]
            self._P_dirty = True
        if not (np.array_equal(st.R, self._R) and np.array_equal(st.Rc, self._Rc)):
            self._R[...], self._Rc[...] = st.R, st.Rc
            self._P_vals[self._slot_Pu] = 2.0 * self._input_block(st.R, st.Rc)
            self._P_dirty = True
        self.q[:] = self._q_const
        np.multiply(st.qt, -2.0, out=self.q[nx : self.n_x].reshape(N, nx))
        qu = self.q[self.n_x : self.n_x + self.n_u].reshape(N, nu)
        np.matmul(st.uref, st.R.T, out=qu)
        qu *= -2.0
        qu[0] -= 2.0 * (st.Rc @ u_prev)
        if self.r_rate is not None:
            self.l[self.r_rate : self.r_rate + nu] = self._rate_base_lo + u_prev
            self.u[self.r_rate : self.r_rate + nu] = self._rate_base_hi + u_prev
        self.l[self.r_ubound : self.r_ubound + N * nu] = st.ulo.reshape(-1)
        self.u[self.r_ubound : self.r_ubound + N * nu] = st.uhi.reshape(-1)
        if self.lane:
            n2 = np.repeat(st.lane_n[:, None, :], 2, axis=1)  # (N, 2 rows, 2)
            hi, lo = st.lane_b + st.lane_hi, st.lane_b + st.lane_lo
            if self.lane_yaw:
                # the rows in w = yaw - t . p, the yaw relative to the road (ocp.stage_qp)
                lin = st.Xlin[1:]
                wbar = lin[:, 2] - np.einsum("ki,ki->k", st.lane_t, lin[:, :2])
                n2 = n2 + np.stack([st.lane_dhi, st.lane_dlo], axis=1)[:, :, None] * st.lane_t[:, None, :]
                self._coo_vals[self._slot_yaw] = np.column_stack([-st.lane_dhi, -st.lane_dlo]).ravel()
                hi = hi - st.lane_dhi * wbar
                lo = lo - st.lane_dlo * wbar
            self._coo_vals[self._slot_n] = n2.ravel()
            self.u[self.r_lane : self.r_lane + 2 * N : 2] = hi
            self.l[self.r_lane + 1 : self.r_lane + 2 * N : 2] = lo
        if self.n_obs_rows:  # a_km . (x_k, y_k, yaw_k) + sigma_k >= b_km (b -inf: unused)
            self._coo_vals[self._slot_o] = st.rowa.reshape(-1)
            self.l[self.r_obs : self.r_obs + N * self.n_obs_rows] = st.rowb.reshape(-1)
        np.take(self._coo_vals, self._perm, out=self.A.data)

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
