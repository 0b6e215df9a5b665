"""Both controllers' QP solutions against an independent oracle, one MPC step at a time.

Random instances of one step of the tracking MPC with everything that makes the QP hard: input
bounds and rate limits that bind, a car starting partly outside its road (the soft road rows'
slacks are nonzero), and a static obstacle ahead in the lane whose ``hard`` half-plane rows
bind. For each step the OSQP controller (:class:`LtvMpc`: the sparse QP of ``ocp.qp``), the
compiled controller (:class:`CompiledLtvMpc`: the condensed QP and its dual active-set solver) and
the compiled controller with ``solver="osqp"`` (its compiled assembly's stage QP, checked field
by field against the OSQP controller's, solved by OSQP) and the OSQP controller's assembly solved
by the condensed solver (``PythonLtvMpc(..., "condensed")``) take the same measured state and warm
start, and their first inputs, plans and objective values are
compared with the optimum of the same stage problem written here in cvxpy from
:class:`MpcProblem`'s documented cost and constraints and solved with Clarabel.

The oracle takes as given only what defines the instance: the affine prediction model (A_k,
B_k, c_k), the references, and the coefficients of the road and obstacle rows (the OSQP
controller's ``prepare``; the compiled controller is checked to have built the same numbers).
The cost, the slacks, the bounds, the rate limits and the form of the rows are written from the
documentation, not taken from either controller's matrices.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import pytest
import scipy.linalg as sla

from mpcdrive.control import LtvMpc, MpcConfig, PythonLtvMpc
from mpcdrive.control.compiled_mpc import CompiledLtvMpc, CondensedSettings
from mpcdrive.models import KinematicBicycle3, KinematicBicycle4
from mpcdrive.models.discretize import discrete_step
from mpcdrive.ocp import MpcProblem
from mpcdrive.ocp.avoidance import AvoidanceConfig
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.scene import Circle, Footprint, Obstacle
from mpcdrive.scene.road import Road
from mpcdrive.solvers.osqp_backend import OsqpSettings

#: the OSQP controller's settings in these tests (the tolerances below follow from them)
OSQP = OsqpSettings(eps_abs=1e-9, eps_rel=1e-9, max_iter=100000)
FAST = CondensedSettings()
#: Clarabel's tolerances, tightest first (it occasionally stalls short of the tightest)
CLARABEL_TOLS = (1e-10, 1e-9, 1e-8)
#: a constraint counts as active at the oracle's optimum within this (for the KKT matrix and
#: for the checks that the instance has active bounds, rates and rows)
ACTIVE_TOL = 1e-7


# --------------------------------------------------------------------------------------------
# instances
# --------------------------------------------------------------------------------------------
@dataclass
class Case:
    ref: LtvMpc
    fast: CompiledLtvMpc
    x: np.ndarray
    #: the compiled assembly's stage QP solved by OSQP
    fast_osqp: CompiledLtvMpc
    #: the Python assembly's stage QP solved by the condensed solver
    py_condensed: LtvMpc


#: where the obstacle is: ahead on the car's way back to the centre line, passed on the far side
#: (the car crosses in front of it: the rows bind, mostly with their slack), beside the car's side
#: of the lane (passed on that side: the rows bind, the slack stays 0), or blocking the lane (stop
#: rows; at constant speed, without the speed state, they hold only with their slack)
OBSTACLE_KINDS = ("cross", "beside", "blocked")


def make_case(seed: int) -> Case:
    """One random instance: a kinematic bicycle (4 states, or 3 at constant speed), a straight or
    circular road, the car partly outside it, a static obstacle ahead (OBSTACLE_KINDS), tight
    input and rate bounds."""
    rng = np.random.default_rng(seed)
    four = seed % 4 != 3
    kind = OBSTACLE_KINDS[seed % 3]
    width = float(rng.uniform(2.1, 2.5)) if kind == "beside" else float(rng.uniform(1.8, 2.4))
    N, dt = int(rng.integers(12, 22)), 0.1
    if seed % 2 == 0:
        path = StraightPath([0.0, 0.0], [40.0, 0.0])
    else:
        path = CirclePath((0.0, 0.0), float(rng.uniform(4.0, 8.0)), ccw=bool(rng.integers(0, 2)))
    road = Road.constant(width, 0.05)
    steer = math.radians(rng.uniform(15.0, 30.0))
    dsteer = math.radians(rng.uniform(60.0, 150.0))
    slack = dict(
        lane_slack_weight=float(rng.choice([50.0, 300.0, 1e3])),
        lane_slack_weight_l1=float(rng.choice([1.0, 10.0, 50.0])),
    )
    if four:
        model = KinematicBicycle4()
        pb = MpcProblem(
            4,
            2,
            N,
            dt,
            Q=np.diag(rng.uniform([0.5, 2.0, 0.5, 0.5], [2.0, 6.0, 2.0, 2.0])),
            R=np.diag(rng.uniform([0.5, 0.05], [2.0, 0.3])),
            Rc=np.diag(rng.uniform([0.1, 0.01], [1.0, 0.1])),
            u_min=[-steer, -float(rng.uniform(1.5, 3.0))],
            u_max=[steer, float(rng.uniform(0.6, 1.2))],
            du_max_per_s=[dsteer, float(rng.uniform(3.0, 6.0))],
            # no lower speed bound before a blocked lane: a car stopped at the stop line would
            # meet it and the stop rows at every later step (rows that depend on each other)
            x_min=[-np.inf, -np.inf, -np.inf, -np.inf if kind == "blocked" else 0.0],
            x_max=[np.inf, np.inf, np.inf, 1.5],
            road=road,
            **slack,
        )
        v0 = float(rng.uniform(0.8, 1.2))
    else:
        v0 = float(rng.uniform(0.8, 1.2))
        model = KinematicBicycle3(v0)
        pb = MpcProblem(
            3,
            1,
            N,
            dt,
            Q=np.diag(rng.uniform([0.5, 2.0, 0.5], [2.0, 6.0, 2.0])),
            R=float(rng.uniform(0.5, 2.0)),
            Rc=float(rng.uniform(0.1, 1.0)),
            u_min=-steer,
            u_max=steer,
            du_max_per_s=dsteer,
            road=road,
            **slack,
        )
    # the car: its reference point near the left edge, so that the body reaches past it
    s0 = float(rng.uniform(0.0, 1.0))
    e0 = 0.5 * width - float(rng.uniform(-0.05, 0.12))
    p0 = path.position(s0)
    h0 = float(path.heading(s0))
    n0 = np.array([-math.sin(h0), math.cos(h0)])
    x = np.array([*(p0 + e0 * n0), h0 + float(rng.uniform(-0.2, 0.25))] + ([v0] if four else []))
    # the obstacle (e_ob > 0: left of the centre line, so the side with more room is the right)
    if kind == "cross":
        radius, e_ob = float(rng.uniform(0.2, 0.35)), float(rng.uniform(0.05, 0.3))
        s_ob = s0 + float(rng.uniform(1.0, 2.0))
    elif kind == "beside":
        radius, e_ob = float(rng.uniform(0.3, 0.4)), float(rng.uniform(-0.1, 0.0))
        s_ob = s0 + float(rng.uniform(1.0, 2.0))
    else:
        radius, e_ob = 0.5 * width - 0.1, float(rng.uniform(-0.1, 0.1))
        s_ob = s0 + radius + float(rng.uniform(0.6, 1.2))
    h_ob = float(path.heading(s_ob))
    c_ob = path.position(s_ob) + e_ob * np.array([-math.sin(h_ob), math.cos(h_ob)])
    obstacles = (Obstacle(Circle(radius), (float(c_ob[0]), float(c_ob[1]), 0.0)),)
    av = AvoidanceConfig("hard", margin_m=0.1, influence_m=10.0, max_obstacles=2)
    cfg = MpcConfig(v_ref_mps=1.0)
    fp = Footprint()
    ref = PythonLtvMpc(
        model, path, pb, cfg, "osqp", osqp_settings=OSQP, obstacles=obstacles, avoidance=av, footprint=fp
    )
    fast = CompiledLtvMpc(
        model, path, pb, cfg, condensed_settings=FAST, obstacles=obstacles, avoidance=av, footprint=fp
    )
    fast_osqp = CompiledLtvMpc(
        model,
        path,
        pb,
        cfg,
        condensed_settings=FAST,
        obstacles=obstacles,
        avoidance=av,
        footprint=fp,
        solver="osqp",
        osqp_settings=OSQP,
    )
    py_condensed = PythonLtvMpc(
        model, path, pb, cfg, "condensed", condensed_settings=FAST, obstacles=obstacles, avoidance=av, footprint=fp
    )
    return Case(ref, fast, x, fast_osqp, py_condensed)


# --------------------------------------------------------------------------------------------
# the oracle: MpcProblem's documented stage problem in cvxpy, solved with Clarabel
# --------------------------------------------------------------------------------------------
@dataclass
class Oracle:
    X: np.ndarray
    U: np.ndarray
    eps: np.ndarray  # road slacks, steps 1..N
    sig: np.ndarray  # obstacle slacks, steps 1..N
    J: float  # the documented cost at the optimum (constants included)
    r_d: float  # its stationarity residual (a posteriori, below)
    r_p: float  # its primal residual on the active rows
    dual_bound: float  # largest multiplier of the input bounds
    dual_rate: float  # largest multiplier of the rate limits
    dual_obstacle: float  # largest multiplier of the obstacle rows


def road_excess(d, X):
    """(N,) how far the lateral offsets of X[1:] lie outside the road rows: the documented
    ``lo_k + dlo_k psi_k <= n_k . p_k - offset_k <= hi_k + dhi_k psi_k``, psi_k the yaw off the
    linearization's less the road's turn over the distance moved along it."""
    dlo, dhi = d.qp.lane_dlo, d.qp.lane_dhi
    e = np.einsum("ki,ki->k", d.qp.lane_n, X[1:, :2]) - d.qp.lane_b
    lin = d.qp.Xlin[1:]
    dy = X[1:, 2] - lin[:, 2] - np.einsum("ki,ki->k", d.qp.lane_t, X[1:, :2] - lin[:, :2])
    return np.maximum.reduce([e - d.qp.lane_hi - dhi * dy, d.qp.lane_lo + dlo * dy - e, np.zeros_like(e)])


def obstacle_excess(d, X):
    """(N,) the largest violation of the obstacle rows ``a . (x_k, y_k, yaw_k) >= b`` per step."""
    used = np.isfinite(d.qp.rowb)
    lhs = np.einsum("kmi,ki->km", d.qp.rowa, X[1:, :3])
    gap = np.where(used, d.qp.rowb - lhs, -np.inf)
    return np.maximum(gap.max(axis=1), 0.0)


def documented_cost(pb: MpcProblem, d, X, U, eps, sig, u_prev) -> float:
    """MpcProblem's documented cost, evaluated in numpy."""
    N = pb.N
    J = 0.0
    for k in range(1, N + 1):
        e = X[k] - d.qp.xref[k]
        J += e @ (pb.QN if k == N else pb.Q) @ e
    up = u_prev
    for k in range(N):
        du = U[k] - d.qp.uref[k]
        dd = U[k] - up
        J += du @ pb.R @ du + dd @ pb.Rc @ dd
        up = U[k]
    J += pb.lane_slack_weight * eps @ eps + pb.lane_slack_weight_l1 * eps.sum()
    J += pb.obstacle_slack_weight * sig @ sig + pb.obstacle_slack_weight_l1 * sig.sum()
    return float(J)


def plan_cost(pb, d, X, U, u_prev) -> float:
    """The documented cost of a plan (X, U) with its smallest slacks (the cost grows with them)."""
    return documented_cost(pb, d, X, U, road_excess(d, X), obstacle_excess(d, X), u_prev)


def solve_oracle(pb: MpcProblem, d, u_prev) -> Oracle:
    N, nx, nu = pb.N, pb.nx, pb.nu
    X = cp.Variable((N + 1, nx))
    U = cp.Variable((N, nu))
    eps = cp.Variable(N)
    sig = cp.Variable(N)
    cons = [X[0] == d.x, eps >= 0, sig >= 0]
    for k in range(N):
        cons.append(X[k + 1] == d.qp.A[k] @ X[k] + d.qp.B[k] @ U[k] + d.qp.c[k])
    cost = 0
    for k in range(1, N + 1):
        cost += cp.quad_form(X[k] - d.qp.xref[k], cp.psd_wrap(pb.QN if k == N else pb.Q))
    bounds, rates = [], []
    dmax = pb.du_max_per_s * pb.dt_s
    for k in range(N):
        prev = u_prev if k == 0 else U[k - 1]
        cost += cp.quad_form(U[k] - d.qp.uref[k], cp.psd_wrap(pb.R)) + cp.quad_form(U[k] - prev, cp.psd_wrap(pb.Rc))
        bounds += [U[k] >= pb.u_min, U[k] <= pb.u_max]
        rates += [U[k] - prev <= dmax, prev - U[k] <= dmax]
    cons += bounds + rates
    for k in range(1, N + 1):
        for i in pb.bounded_states:
            if np.isfinite(pb.x_min[i]):
                cons.append(X[k, i] >= pb.x_min[i])
            if np.isfinite(pb.x_max[i]):
                cons.append(X[k, i] <= pb.x_max[i])
    # the soft road rows (one slack per step for both sides) and the obstacle rows (one slack per
    # step shared by its rows; b = -inf: an unused row)
    dlo, dhi, lin, tk = d.qp.lane_dlo, d.qp.lane_dhi, d.qp.Xlin, d.qp.lane_t
    obstacle_rows = []
    for k in range(1, N + 1):
        e = d.qp.lane_n[k - 1] @ X[k, :2] - d.qp.lane_b[k - 1]
        dy = X[k, 2] - lin[k, 2] - tk[k - 1] @ (X[k, :2] - lin[k, :2])
        cons += [
            e <= d.qp.lane_hi[k - 1] + dhi[k - 1] * dy + eps[k - 1],
            e >= d.qp.lane_lo[k - 1] + dlo[k - 1] * dy - eps[k - 1],
        ]
        for m in np.flatnonzero(np.isfinite(d.qp.rowb[k - 1])):
            obstacle_rows.append(d.qp.rowa[k - 1, m] @ X[k, :3] + sig[k - 1] >= d.qp.rowb[k - 1, m])
    cons += obstacle_rows
    cost += pb.lane_slack_weight * cp.sum_squares(eps) + pb.lane_slack_weight_l1 * cp.sum(eps)
    cost += pb.obstacle_slack_weight * cp.sum_squares(sig) + pb.obstacle_slack_weight_l1 * cp.sum(sig)
    prob = cp.Problem(cp.Minimize(cost), cons)
    # solved through cvxpy's problem data, to read Clarabel's own point and multipliers below
    data, chain, inverse = prob.get_problem_data(cp.CLARABEL, solver_opts={})
    dims = data["dims"]
    assert dims.zero + dims.nonneg == data["A"].shape[0], "a QP: only equality and inequality rows"
    for tol in CLARABEL_TOLS:
        opts = dict(tol_gap_abs=tol, tol_gap_rel=1e-3 * tol, tol_feas=tol, tol_ktratio=tol, max_iter=500)
        raw = chain.solve_via_data(prob, data, False, False, opts)
        prob.unpack_results(raw, chain, inverse)
        if prob.status == cp.OPTIMAL:
            break
    assert prob.status == cp.OPTIMAL, prob.status
    # Clarabel's point x and multipliers w solve the KKT conditions of the problem as written
    # (min 1/2 x'Px + q'x s.t. Ax + s = b, s in {0}^zero x R+^nonneg) up to residuals, measured
    # here: stationarity P x + q + A_a' w_a with the rows taken as active (the equations, and the
    # inequalities whose multiplier exceeds their slack), and the primal residual (|b - Ax| on
    # the active rows, the violation of the others)
    Pc, qc, Ac, bc = data["P"], data["c"], data["A"], data["b"]
    xc, wc = np.asarray(raw.x), np.asarray(raw.z)
    slack = bc - Ac @ xc
    act = np.ones(len(bc), bool)
    act[dims.zero :] = wc[dims.zero :] >= slack[dims.zero :]
    r_d = float(np.abs(Pc @ xc + qc + Ac.T @ np.where(act, wc, 0.0)).max())
    r_p = float(np.abs(np.where(act, slack, np.minimum(slack, 0.0))).max())

    def largest(cs):
        return max((float(np.max(c.dual_value)) for c in cs), default=0.0)

    return Oracle(
        X.value,
        U.value,
        np.maximum(eps.value, 0.0),
        np.maximum(sig.value, 0.0),
        float(prob.value),
        r_d,
        r_p,
        largest(bounds),
        largest(rates),
        largest(obstacle_rows),
    )


# --------------------------------------------------------------------------------------------
# tolerances from the stopping rules
# --------------------------------------------------------------------------------------------
# Each solver stops at a point whose KKT residuals are below its stopping rule:
#   OSQP: primal |Az - z_c|_inf <= eps_abs + eps_rel max(|Az|_inf, |z_c|_inf) (z_c: Az projected
#     onto [l, u]), dual |Pz + q + A'y|_inf <= eps_abs + eps_rel max(|Pz|_inf, |A'y|_inf, |q|_inf),
#     with eps_abs, eps_rel as the controller is configured (OSQP above);
#   the dual active-set solver: every row holds to feasibility_tol times the row's norm, and it is
#     exactly stationary on its active set, up to rounding;
#   Clarabel (the oracle): its residuals are measured, not assumed (solve_oracle).
# To first order, residuals r_d (stationarity) and r_p (on the active rows) move a solution by
# K^-1 [r_d; r_p] from the exact optimum, K = [[P, A_a'], [A_a, 0]] the KKT matrix of the QP on
# its active set A_a there; so |dz|_inf <= kd r_d + kp r_p, with kd and kp the largest row sums
# of |K^-1|'s two blocks. The tolerance of a comparison is the solver's bound plus the oracle's.
# The objective moves by y' r_p at first order (y the multipliers; the step K^-1 [r_d; 0] keeps
# the active rows and is orthogonal to the objective's gradient -A_a' y), and by 1/2 dz' P dz at
# second order, at most 1/2 sum |P_ij| |dz|_inf^2.
# On these instances (all seeds below) kd is at most 9 and kp 20 - 6e3, and |q|_inf, mostly the
# obstacle slack's l1 weight 1e3, dominates the dual norms: the bounds come out at 1e-7 - 1e-4
# (median 4e-6) for OSQP at 1e-9, 4e-8 - 8e-6 for the active-set solver and 1e-13 - 3e-4 for
# Clarabel, while a wrong row, bound or weight moves the plan by 1e-2 or more; MAX_TOL keeps it
# that way (a larger tolerance would say nothing). The errors found are at most 1e-7 (OSQP) and
# 3e-8 (active set).
MAX_TOL = 1e-3


@dataclass
class Sensitivity:
    kd: float
    kp: float
    y1: float  # |y|_1, the multipliers of the active rows
    p1: float  # sum |P_ij|
    scale_p: float  # max(|Az|_inf, 1): the primal norm of OSQP's stopping rule
    scale_d: float  # max(|Pz|_inf, |A'y|_inf, |q|_inf, 1): its dual norm

    def z_tol(self, r_d: float, r_p: float) -> float:
        return self.kd * r_d + self.kp * r_p

    def cost_tol(self, r_d: float, r_p: float) -> float:
        return self.y1 * r_p + 0.5 * self.p1 * self.z_tol(r_d, r_p) ** 2


def sensitivity(qp, z: np.ndarray) -> Sensitivity:
    """The first-order sensitivity of the solution of the QP ``qp`` (an assembled ``LtvQp``: the
    problem both solvers are given, in the sparse layout) at its optimum ``z`` (the oracle's):
    a property of the problem, whichever solver's residuals it is applied to."""
    P = qp.P.toarray()
    P = P + P.T - np.diag(np.diag(P))
    A = qp.A.toarray()
    Az = A @ z
    near = ACTIVE_TOL * (1.0 + np.abs(Az))
    act = (np.isfinite(qp.l) & (np.abs(Az - qp.l) <= near)) | (np.isfinite(qp.u) & (np.abs(Az - qp.u) <= near))
    # active rows that depend on the others (a car stopped at a stop line meets it at two steps)
    # carry no information of their own: keep a basis of them (pivoted QR)
    Aa = A[act]
    if Aa.shape[0]:
        R, piv = sla.qr(Aa.T, mode="r", pivoting=True)
        diag = np.abs(np.diag(R))
        Aa = Aa[np.sort(piv[: int(np.sum(diag > 1e-9 * diag[0]))])]
    n, m = P.shape[0], Aa.shape[0]
    K = np.block([[P, Aa.T], [Aa, np.zeros((m, m))]])
    Ki = np.linalg.inv(K)
    g = P @ z + qp.q
    y = -(Ki[n:, :n] @ g)  # the multipliers: P z + q + A_a' y = 0
    return Sensitivity(
        kd=float(np.abs(Ki[:n, :n]).sum(axis=1).max()),
        kp=float(np.abs(Ki[:n, n:]).sum(axis=1).max()),
        y1=float(np.abs(y).sum()),
        p1=float(np.abs(P).sum()),
        scale_p=max(1.0, float(np.abs(Az).max())),
        scale_d=max(1.0, float(np.abs(P @ z).max()), float(np.abs(g).max()), float(np.abs(qp.q).max())),
    )


def osqp_residuals(s: Sensitivity, settings: OsqpSettings, status: str) -> tuple[float, float]:
    """OSQP's stopping rule: (dual, primal) residual bounds. Status ``inaccurate`` (OSQP's "solved
    inaccurate", which the controller accepts): it met the rule with eps_abs and eps_rel ten times
    larger when it ran out of iterations."""
    f = 10.0 if status == "inaccurate" else 1.0
    eps_abs, eps_rel = f * settings.eps_abs, f * settings.eps_rel
    return (eps_abs + eps_rel * s.scale_d, eps_abs + eps_rel * s.scale_p)


def fast_residuals(fast) -> tuple[float, float]:
    """The active-set solver's (dual, primal) residual bounds: stationarity to rounding,
    n eps_mach (n |H| |z| + |g|), and rows to feasibility_tol times their norm (the condensed rows
    of the step, in the compiled controller's buffers or the condensed backend's work arrays)."""
    work = fast._work if isinstance(fast, CompiledLtvMpc) else fast.backend._work
    C, H, g, z = work.C, work.H, work.g, work.z
    n = H.shape[0]
    r_d = n * np.finfo(float).eps * (n * np.abs(H).max() * np.abs(z).max() + np.abs(g).max())
    return float(r_d), float(FAST.feasibility_tol * max(1.0, np.linalg.norm(C, axis=1).max()))


def oracle_residuals(o: Oracle) -> tuple[float, float]:
    """Clarabel's (dual, primal) residuals, measured (solve_oracle)."""
    return (o.r_d, o.r_p)


def pack(o: Oracle) -> np.ndarray:
    """The oracle's solution in the layout of ``ocp.qp`` (documented there): X, U, eps, sigma."""
    return np.concatenate([o.X.ravel(), o.U.ravel(), o.eps, o.sig])


def constant_cost(pb: MpcProblem, d, u_prev) -> float:
    """The documented cost's terms that do not depend on the decision variables (the QP drops them)."""
    N = pb.N
    c = sum(d.qp.xref[k] @ (pb.QN if k == N else pb.Q) @ d.qp.xref[k] for k in range(1, N + 1))
    c += sum(d.qp.uref[k] @ pb.R @ d.qp.uref[k] for k in range(N)) + u_prev @ pb.Rc @ u_prev
    return float(c)


# --------------------------------------------------------------------------------------------
# one step, both controllers against the oracle
# --------------------------------------------------------------------------------------------
def same_stage_qp(a, b, atol=1e-10) -> None:
    """Two stage QPs (:class:`~mpcdrive.ocp.stage_qp.StageQp`) agree field by field."""
    for f in dataclasses.fields(b):
        np.testing.assert_allclose(getattr(a, f.name), getattr(b, f.name), rtol=0, atol=atol, err_msg=f"qp.{f.name}")


def same_instance(fast: CompiledLtvMpc, d) -> None:
    """The compiled controller built the instance the oracle solves: the stage QP of the OSQP
    controller's ``prepare``, every field."""
    same_stage_qp(fast._qp, d.qp)


def same_step_data(dc, d, atol=1e-10, sides=True) -> None:
    """The compiled assembly's step ``dc`` is the OSQP controller's ``d``
    (:class:`~mpcdrive.control.mpc.StepData`, every field, and every field of its stage QP; the
    passing sides unless ``sides`` is False: the compiled cost formulations keep them only for
    a detour, where they matter)."""
    for f in dataclasses.fields(d):
        a, b = getattr(dc, f.name), getattr(d, f.name)
        if f.name == "sides":
            assert not sides or a == b
        elif f.name == "qp":
            same_stage_qp(a, b, atol)
        else:
            np.testing.assert_allclose(a, b, rtol=0, atol=atol, err_msg=f.name)


def compare(name, out, o: Oracle, s: Sensitivity, residuals, pb, d, u_prev) -> None:
    """A controller's output ``out`` for the step against the oracle's optimum: the first input,
    the planned inputs and states, and the plan's documented cost, to the tolerance its solver's
    (dual, primal) residual bounds ``residuals`` and the oracle's give."""
    statuses = ("ok", "inaccurate") if name == "OSQP" else ("ok",)  # OSQP's "solved inaccurate": below
    assert out.status in statuses and out.fallback == "", (name, out.status, out.fallback)
    r_o = oracle_residuals(o)
    tol = s.z_tol(*residuals) + s.z_tol(*r_o)
    tol_J = s.cost_tol(*residuals) + s.cost_tol(*r_o)
    assert tol <= MAX_TOL, (name, tol)
    np.testing.assert_allclose(out.u, o.U[0], rtol=0, atol=tol, err_msg=f"{name}: first input")
    np.testing.assert_allclose(out.warm.U, o.U, rtol=0, atol=tol, err_msg=f"{name}: planned inputs")
    np.testing.assert_allclose(out.X_pred, o.X, rtol=0, atol=tol, err_msg=f"{name}: planned states")
    J = plan_cost(pb, d, out.X_pred, out.warm.U, u_prev)
    assert abs(J - o.J) <= tol_J, f"{name}: cost {J} against the oracle's {o.J} (tolerance {tol_J:.2e})"


def check_step(case: Case, x, warm) -> tuple[Oracle, object]:
    """Solve one step with both controllers and the oracle and compare; returns the oracle's
    solution and the output the next step starts from (the OSQP controller's)."""
    ref, fast = case.ref, case.fast
    pb = ref.problem  # with the obstacle rows the controller added
    d = copy.deepcopy(ref.prepare(x, warm))  # (its arrays are the controller's: the step rewrites them)
    o = solve_oracle(pb, d, warm.u_prev)
    assert documented_cost(pb, d, o.X, o.U, o.eps, o.sig, warm.u_prev) == pytest.approx(o.J, rel=1e-9, abs=1e-9)
    # the QP the OSQP controller assembles for this step: the oracle's optimum is feasible for it
    # (to its own primal residual: the rows are the same up to their sign and order, the factor 10
    # is room for the rows' rounding), and its objective there is the documented cost less the
    # constant terms
    ref.qp.load_stage(d.qp, d.x, warm.u_prev)
    qp = ref.qp
    z = pack(o)
    s = sensitivity(qp, z)
    Az = qp.A @ z
    violation = max(float((qp.l - Az).max()), float((Az - qp.u).max()))
    assert violation <= 10 * o.r_p + 1e-10, f"the oracle's optimum violates the assembled QP by {violation:.2e}"
    P = qp.P.toarray()
    obj = 0.5 * z @ (P + P.T - np.diag(np.diag(P))) @ z + qp.q @ z
    assert obj + constant_cost(pb, d, warm.u_prev) == pytest.approx(o.J, rel=1e-9, abs=1e-9)
    # the OSQP controller's step (prepare, load, solve, check, clip: the same data again)
    out = ref.step(x, warm)
    compare("OSQP", out, o, s, osqp_residuals(s, OSQP, out.status), pb, d, warm.u_prev)
    # the compiled controller's step, on the same state and warm start, and the same instance
    of = fast.step(x, warm)
    same_instance(fast, d)
    compare("compiled", of, o, s, fast_residuals(fast), pb, d, warm.u_prev)
    # the compiled assembly's stage QP (the same instance, field by field), solved by OSQP
    same_step_data(case.fast_osqp.prepare(x, warm), d)
    ofo = case.fast_osqp.step(x, warm)
    compare("OSQP", ofo, o, s, osqp_residuals(s, OSQP, ofo.status), pb, d, warm.u_prev)
    # the Python assembly's stage QP solved by the condensed solver
    opc = case.py_condensed.step(x, warm)
    compare("compiled", opc, o, s, fast_residuals(case.py_condensed), pb, d, warm.u_prev)
    return o, out


def run_case(seed: int, steps: int = 2) -> None:
    """``steps`` consecutive steps of one instance (the first linearized along the rolled-out
    references, the later ones along the OSQP controller's shifted plan, fed to both), and the
    instance's features: every one active at the oracle's optimum on some step."""
    case = make_case(seed)
    x = case.x
    warm = case.ref.initial_warm(x)
    model = case.ref.model
    found = dict(bound=False, rate=False, road_slack=False, obstacle=False)
    for _ in range(steps):
        o, out = check_step(case, x, warm)
        found["bound"] |= o.dual_bound > ACTIVE_TOL
        found["rate"] |= o.dual_rate > ACTIVE_TOL
        found["road_slack"] |= bool(o.eps.max() > 1e-3)
        found["obstacle"] |= o.dual_obstacle > ACTIVE_TOL
        x = discrete_step(model, x, out.u, case.ref.dt_s, "rk4")
        warm = out.warm
    assert all(found.values()), found


#: every obstacle kind, with and without the speed state, on straight and circular roads; seeds 4
#: and 31 are left out: at their optimum (on the steps run) the input bounds (4) or the obstacle
#: rows (31) happen not to bind, which run_case refuses; seeds 29 and 37 are near degenerate on a
#: step (a car braking to the stop line before a blocked lane): the tolerance the residuals give
#: there is above MAX_TOL, where the comparison says nothing (29, third step: 3.1e-3 for either
#: solver, since the road rows are linearized where the plan has the car; 37, fourth step: primal
#: sensitivity 1.1e5, OSQP stops at its iteration cap, 9e-3 from the active-set solver's residuals)
FAST_SEEDS = [0, 1, 2, 3, 5, 6, 7, 8]
SLOW_SEEDS = [s for s in range(9, 40) if s not in (29, 31, 37)]


@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_both_solvers_match_the_oracle(seed):
    run_case(seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SLOW_SEEDS)
def test_both_solvers_match_the_oracle_on_more_instances(seed):
    run_case(seed, steps=4)


@pytest.mark.parametrize("seed", FAST_SEEDS[:4])
def test_a_guess_of_the_slack_groups_changes_the_rounds_not_the_solution(seed):
    """The compiled solver flags the slack groups of the last solve that needed slacks (shifted
    a step) from the first round of a solve that needs them (``soft_solve``'s ``kprev``): a
    guess. Whatever the guess (none, every group, a random half), the step's inputs and plan are
    the same, and the groups a solve ends with, given back as the guess, never cost more
    active-set iterations than no guess."""
    case = make_case(seed)
    fast, x = case.fast, case.x
    warm = case.ref.initial_warm(x)
    out = case.ref.step(x, warm)  # a plan to go on from (the steps below shift it)
    x = discrete_step(case.ref.model, x, out.u, case.ref.dt_s, "rk4")
    warm = out.warm
    kprev = fast._work.kprev
    rng = np.random.default_rng(seed)
    runs = {}
    for name, guess in (
        ("none", np.zeros_like(kprev)),
        ("all", np.ones_like(kprev)),
        ("random", rng.integers(0, 2, kprev.shape)),
    ):
        kprev[:] = np.roll(guess, 1)  # (the step moves it on a step before the solve)
        o = fast.step(x, warm)
        runs[name] = (o, int(fast._info[3]), kprev.copy())
    base = runs["none"][0]
    assert runs["none"][2].any(), "the instance's solve needs no slack: the guess is never used"
    for name, (o, _, _) in runs.items():
        assert o.status == base.status == "ok", name
        np.testing.assert_allclose(o.u, base.u, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(o.X_pred, base.X_pred, atol=1e-6, err_msg=name)
    # the groups the unguessed solve ended with, as the guess
    kprev[:] = np.roll(runs["none"][2], 1)
    fast.step(x, warm)
    assert int(fast._info[3]) <= runs["none"][1]
