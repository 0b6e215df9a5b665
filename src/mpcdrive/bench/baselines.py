"""What people use today, on the same closed loop as mpcdrive (``mpcdrive bench --baselines``).

* ``cvxpy_rebuild``: the PythonRobotics style -- the QP is written in cvxpy and rebuilt from
  scratch every step (same references, linearization and constraints as mpcdrive's QP: input
  and state bounds, input rates).
* ``casadi_ipopt``: CasADi Opti + IPOPT on the nonlinear model (RK4 of the same equations),
  the problem built once with parameters and warm-started each step, with the QP's input and
  state bounds and input-rate limits; with a Gaussian or
  potential obstacle cost and a lane, the same non-convex cost and the same soft lane bound, so
  it is also the reference NLP the SQP is checked against. With hard avoidance (P4) it gets the
  same obstacle rows as the QP: each step's half-planes ``a . (x_k, y_k, yaw_k) + sigma_k >= b``
  on the footprint discs, linearized along the linearization trajectory by ``ocp.avoidance``,
  with the QP's slack ``sigma_k >= 0`` per predicted step and the same slack weights.

Both reuse :meth:`LtvMpc.prepare` so references and linearization are identical to ours and only
the problem building and solving differ. Optional: needs the ``bench`` extra.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from ..types import STATUS_FAILED, STATUS_OK, SolveResult
from .problems import BenchProblem


#: right-hand side standing in for an unused obstacle row (its a is 0, so 0 >= this holds)
_UNUSED_ROW_B = -1e9


class CvxpyRebuildMpc:
    """LTV-MPC whose QP is rebuilt in cvxpy every step."""

    def __init__(self, prob: BenchProblem):
        import cvxpy as cp

        self.cp = cp
        self.core = prob.controller()
        self.nx, self.nu, self.N = self.core.nx, self.core.nu, self.core.N

    def initial_warm(self, x0):
        return self.core.initial_warm(x0)

    def step(self, x, warm):
        cp = self.cp
        t0 = time.perf_counter()
        d = self.core.prepare(x, warm)
        pb = self.core.problem
        N, nx, nu = self.N, self.nx, self.nu
        X = cp.Variable((N + 1, nx))
        U = cp.Variable((N, nu))
        cost = 0
        dmax = pb.du_max_per_s * pb.dt_s  # largest input change per step
        cons = [X[0] == d.x]
        for k in range(N):
            cons.append(X[k + 1] == d.qp.A[k] @ X[k] + d.qp.B[k] @ U[k] + d.qp.c[k])
            cost += cp.quad_form(U[k] - d.qp.uref[k], pb.R)
            prev = warm.u_prev if k == 0 else U[k - 1]
            if np.any(pb.Rc):
                cost += cp.quad_form(U[k] - prev, pb.Rc)
            W = pb.QN if k == N - 1 else pb.Q
            cost += cp.quad_form(X[k + 1] - d.qp.xref[k + 1], W)
            for i in range(nu):
                if np.isfinite(dmax[i]):  # the input-rate rows
                    cons.append(cp.abs(U[k, i] - prev[i]) <= dmax[i])
                if np.isfinite(pb.u_min[i]):
                    cons.append(U[k, i] >= pb.u_min[i])
                if np.isfinite(pb.u_max[i]):
                    cons.append(U[k, i] <= pb.u_max[i])
            for i in pb.bounded_states:
                if np.isfinite(pb.x_min[i]):
                    cons.append(X[k + 1, i] >= pb.x_min[i])
                if np.isfinite(pb.x_max[i]):
                    cons.append(X[k + 1, i] <= pb.x_max[i])
        prob = cp.Problem(cp.Minimize(cost), cons)
        try:
            prob.solve(solver=cp.CLARABEL)
            ok = prob.status in ("optimal", "optimal_inaccurate") and U.value is not None
        except cp.error.SolverError:
            ok = False
        res = SolveResult(
            STATUS_OK if ok else STATUS_FAILED,
            X.value if ok else np.full((N + 1, nx), np.nan),
            U.value if ok else np.full((N, nu), np.nan),
            float(prob.value) if ok else float("nan"),
            0,
            time.perf_counter() - t0,
        )
        return self.core.finish(d, warm, res, t0)


class CasadiIpoptMpc:
    """Nonlinear MPC with CasADi Opti + IPOPT, built once, parameters updated each step."""

    def __init__(self, prob: BenchProblem):
        import casadi as ca

        self.core = prob.controller()
        core, pb = self.core, self.core.problem
        self.nx, self.nu, self.N = core.nx, core.nu, core.N
        N, nx, nu, dt = self.N, self.nx, self.nu, pb.dt_s
        ns = SimpleNamespace(cos=ca.cos, sin=ca.sin, tan=ca.tan, arctan=ca.atan, sqrt=ca.sqrt)
        xs, us = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
        f = ca.Function(
            "f",
            [xs, us],
            [ca.vertcat(*prob.model.f_components([xs[i] for i in range(nx)], [us[i] for i in range(nu)], ns))],
        )
        k1 = f(xs, us)
        k2 = f(xs + dt / 2 * k1, us)
        k3 = f(xs + dt / 2 * k2, us)
        k4 = f(xs + dt * k3, us)
        F = ca.Function("F", [xs, us], [xs + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
        opti = ca.Opti()
        X = opti.variable(nx, N + 1)
        U = opti.variable(nu, N)
        x0 = opti.parameter(nx)
        xref = opti.parameter(nx, N + 1)
        uref = opti.parameter(nu, N)
        uprev = opti.parameter(nu)
        cost = 0
        dmax = pb.du_max_per_s * dt  # largest input change per step
        opti.subject_to(X[:, 0] == x0)
        for k in range(N):
            opti.subject_to(X[:, k + 1] == F(X[:, k], U[:, k]))
            du = U[:, k] - (uprev if k == 0 else U[:, k - 1])
            for i in range(nu):  # the QP's input-rate rows
                if np.isfinite(dmax[i]):
                    opti.subject_to(opti.bounded(-dmax[i], du[i], dmax[i]))
            eu = U[:, k] - uref[:, k]
            ex = X[:, k + 1] - xref[:, k + 1]
            W = pb.QN if k == N - 1 else pb.Q
            cost += ca.mtimes([eu.T, pb.R, eu]) + ca.mtimes([du.T, pb.Rc, du]) + ca.mtimes([ex.T, W, ex])
            for i in range(nu):
                if np.isfinite(pb.u_min[i]):
                    opti.subject_to(U[i, k] >= pb.u_min[i])
                if np.isfinite(pb.u_max[i]):
                    opti.subject_to(U[i, k] <= pb.u_max[i])
            for i in pb.bounded_states:
                if np.isfinite(pb.x_min[i]):
                    opti.subject_to(X[i, k + 1] >= pb.x_min[i])
                if np.isfinite(pb.x_max[i]):
                    opti.subject_to(X[i, k + 1] <= pb.x_max[i])
        # soft road bound, as in the QP: n_k . (p_k - c_k) in [lo_k, hi_k] +- eps (the body inside
        # the road, linearized in the yaw relative to the road: lo_k + dlo_k psi_k, the same for hi)
        self.lane_n = self.lane_b = None
        if core.qp.lane:
            eps = opti.variable(N)
            self.lane_n = opti.parameter(2, N)
            self.lane_b = opti.parameter(N)
            self.lane_rows = opti.parameter(5, N)  # lo, hi, dlo, dhi, yawbar - t . pbar
            self.lane_t = opti.parameter(2, N)  # the road's turn per metre moved along it
            opti.subject_to(eps >= 0)
            for k in range(N):
                e = ca.dot(self.lane_n[:, k], X[:2, k + 1]) - self.lane_b[k]
                dyaw = X[2, k + 1] - ca.dot(self.lane_t[:, k], X[:2, k + 1]) - self.lane_rows[4, k]
                opti.subject_to(e <= self.lane_rows[1, k] + self.lane_rows[3, k] * dyaw + eps[k])
                opti.subject_to(e >= self.lane_rows[0, k] + self.lane_rows[2, k] * dyaw - eps[k])
                cost += pb.lane_slack_weight * eps[k] ** 2 + pb.lane_slack_weight_l1 * eps[k]
        # hard avoidance: the QP's linearized half-plane rows, one slack per predicted step
        self.rows_a = self.rows_b = None
        if core.problem.obstacle_rows:
            M = core.problem.obstacle_rows
            sig = opti.variable(N)
            self.rows_a = [opti.parameter(M, 3) for _ in range(N)]
            self.rows_b = opti.parameter(M, N)
            opti.subject_to(sig >= 0)
            for k in range(N):
                opti.subject_to(ca.mtimes(self.rows_a[k], X[:3, k + 1]) + sig[k] >= self.rows_b[:, k])
                cost += pb.obstacle_slack_weight * sig[k] ** 2 + pb.obstacle_slack_weight_l1 * sig[k]
        # non-convex obstacle cost on the predicted centre of gravity
        self.obs_c = []
        av = core.avoidance
        if av is not None and av.config.uses_cost:
            w = av.config.weight
            for ob in av.obstacles:
                c = opti.parameter(2, N)
                self.obs_c.append((ob, c))
                h = float(core.path.heading(core.path.project(np.array(ob.pose[:2]))[0]))
                Sinv = av.sigma_inv(h)
                for k in range(N):
                    d = X[:2, k + 1] - c[:, k]
                    if av.config.formulation == "gaussian":
                        cost += w * ca.exp(-0.5 * ca.mtimes([d.T, Sinv, d]))
                    else:
                        cost += w / (ca.dot(d, d) + av.config.epsilon_m2)
        opti.minimize(cost)
        opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "max_iter": 500})
        self.opti, self.X, self.U, self.x0, self.xref, self.uref, self.uprev = opti, X, U, x0, xref, uref, uprev

    def initial_warm(self, x0):
        return self.core.initial_warm(x0)

    def step(self, x, warm):
        t0 = time.perf_counter()
        d = self.core.prepare(x, warm)
        opti = self.opti
        opti.set_value(self.x0, d.x)
        opti.set_value(self.xref, d.qp.xref.T)
        opti.set_value(self.uref, d.qp.uref.T)
        opti.set_value(self.uprev, warm.u_prev)
        if self.lane_n is not None:
            opti.set_value(self.lane_n, d.qp.lane_n.T)
            opti.set_value(self.lane_b, d.qp.lane_b)
            dlo, dhi, lin = d.qp.lane_dlo, d.qp.lane_dhi, d.qp.Xlin[1:]
            wbar = lin[:, 2] - np.einsum("ki,ki->k", d.qp.lane_t, lin[:, :2])
            opti.set_value(self.lane_t, d.qp.lane_t.T)
            opti.set_value(self.lane_rows, np.vstack([d.qp.lane_lo, d.qp.lane_hi, dlo, dhi, wbar]))
        if self.rows_a is not None:
            for k, a in enumerate(self.rows_a):
                opti.set_value(a, d.qp.rowa[k])
            # an unused row (b = -inf) as a row that always holds
            opti.set_value(self.rows_b, np.where(np.isfinite(d.qp.rowb), d.qp.rowb, _UNUSED_ROW_B).T)
        for ob, c in self.obs_c:
            opti.set_value(c, np.array([ob.pose_at(warm.t_s + (k + 1) * self.core.dt_s)[:2] for k in range(self.N)]).T)
        opti.set_initial(self.X, d.qp.Xlin.T)
        opti.set_initial(self.U, d.Ubar.T)
        try:
            sol = opti.solve()
            Xv = np.asarray(sol.value(self.X)).reshape(self.nx, -1).T
            Uv = np.asarray(sol.value(self.U)).reshape(self.nu, -1).T
            res = SolveResult(
                STATUS_OK, Xv, Uv, float(sol.value(opti.f)), int(sol.stats()["iter_count"]), time.perf_counter() - t0
            )
        except RuntimeError:
            nan = float("nan")
            res = SolveResult(
                STATUS_FAILED,
                np.full((self.N + 1, self.nx), nan),
                np.full((self.N, self.nu), nan),
                nan,
                0,
                time.perf_counter() - t0,
            )
        return self.core.finish(d, warm, res, t0)


def available_baselines(prob: BenchProblem | None = None) -> dict:
    """Baseline factories whose packages are installed (the cvxpy rebuild only for problems
    without obstacles: it is the convex LTV QP)."""
    out = {}
    try:
        import cvxpy  # noqa: F401

        if prob is None or not prob.obstacles:
            out["cvxpy_rebuild"] = CvxpyRebuildMpc
    except ImportError:
        pass
    try:
        import casadi  # noqa: F401

        out["casadi_ipopt"] = CasadiIpoptMpc
    except ImportError:
        pass
    return out
