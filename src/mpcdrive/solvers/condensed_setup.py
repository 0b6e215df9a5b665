"""The condensed solver's setup: its settings, the problems it takes, and its work space.

:class:`CondensedSettings` are the settings of the compiled QP solve;
:func:`condensed_unsupported_reason` says why the condensed solver cannot solve a problem's stage
QPs (then OSQP does); :func:`new_condensed_work` sizes the
:class:`~mpcdrive.solvers.condensed.CondensedWork` of a problem once, with the rows of ``C z >=
b`` that are the same every step (input bounds and rates) already in place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..ocp.problem import MpcProblem
from .condensed import CondensedWork, input_bound_rows
from .dense_qp import row_spans, single_nonzero_columns


@dataclass(frozen=True)
class CondensedSettings:
    """Settings of the compiled QP solve.

    max_iter : cap on active-set changes per step (status ``max_iter`` beyond it);
    feasibility_tol : accepted violation of a constraint row, scaled by the row's norm;
    max_variables : the largest condensed QP (N * nu + lane slacks) the fast path accepts.
    """

    max_iter: int = 500
    feasibility_tol: float = 1e-9
    max_variables: int = 400

    def __post_init__(self):
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        if not (self.feasibility_tol > 0 and math.isfinite(self.feasibility_tol)):
            raise ValueError(f"feasibility_tol must be positive, got {self.feasibility_tol}")
        if self.max_variables < 1:
            raise ValueError(f"max_variables must be >= 1, got {self.max_variables}")


def condensed_unsupported_reason(problem: MpcProblem, settings: CondensedSettings, rows: bool) -> str | None:
    """Why the condensed solver cannot solve the stage QPs of ``problem`` (with obstacle rows
    when ``rows``), whoever assembles them, or None."""
    if np.linalg.eigvalsh(problem.R + problem.Rc).min() <= 1e-12 * max(1.0, float(np.abs(problem.R).max())):
        return "R + Rc is not positive definite (the condensed QP needs a strictly convex cost in the inputs)"
    lane = problem.lane
    if lane and problem.lane_slack_weight <= 0:
        return "lane_slack_weight is 0 (the slack needs a quadratic weight)"
    if rows and problem.obstacle_slack_weight <= 0:
        return "obstacle_slack_weight is 0 (the slack needs a quadratic weight)"
    nz = condensed_variables(problem, rows)
    if nz > settings.max_variables:
        return f"the condensed QP has {nz} variables, more than max_variables={settings.max_variables}"
    return None


def condensed_variables(problem: MpcProblem, rows: bool) -> int:
    """The variables of the condensed QP: the inputs, and one slack per step for the road rows
    and one for the obstacle rows (``rows``) where the problem has them."""
    return problem.N * problem.nu + (problem.N if problem.lane else 0) + (problem.N if rows else 0)


def riccati_shortcut(problem: MpcProblem, rows: bool) -> bool:
    """Whether the condensed solve first tries the unconstrained minimizer (a Riccati recursion):
    no input-change weight, no road rows, no obstacle rows (``rows``)."""
    return not problem.lane and not rows and not np.any(problem.Rc)


@dataclass(frozen=True)
class ConstantRows:
    """The rows of ``C z >= b`` of the condensed QP, sized for every row a step can add:
    ``C`` (mq, nz), ``b`` (mq,) hold the constant rows first (``m_const`` of them; the u_0 rate
    rows from ``r_rate0`` have a b that follows u_prev); ``rowcol`` (mq,) the single nonzero
    column of each constant row (-1: dense); ``gamma``: a step adds state, road or obstacle rows;
    ``rowspan`` (mq, 2) where each row may be nonzero (``gi_solve``'s argument; the rows a step
    writes get theirs with them)."""

    C: np.ndarray
    b: np.ndarray
    rowcol: np.ndarray
    m_const: int
    r_rate0: int
    gamma: bool
    rowspan: np.ndarray

    @property
    def mq(self) -> int:
        return len(self.b)


def constant_rows(problem: MpcProblem, nz: int, n_orow: int = 0) -> ConstantRows:
    """:func:`_constant_rows` as the arrays the condensed solve works in."""
    crows, rhs, r_rate0, n_var, n_slack = _constant_rows(problem, nz, n_orow)
    mq = max(len(crows) + n_var + n_slack, 1)
    C, b = np.zeros((mq, nz)), np.zeros(mq)
    if crows:
        C[: len(crows)] = np.array(crows)
        b[: len(crows)] = rhs
    rowcol = np.full(mq, -1, dtype=np.int64)
    rowcol[: len(crows)] = single_nonzero_columns(C[: len(crows)])
    rowspan = np.full((mq, 2), -1, dtype=np.int64)
    rowspan[:, 0] = nz  # whole rows; the rows a step writes get their spans with them
    rowspan[: len(crows)] = row_spans(C[: len(crows)])
    return ConstantRows(C, b, rowcol, len(crows), r_rate0, n_var > 0, rowspan)


def _constant_rows(problem: MpcProblem, nz: int, n_orow: int = 0):
    """Rows of ``C z >= b`` that do not change between steps (input bounds, input rates), the row
    of the first u_0 rate row (its b follows u_prev), how many rows the step adds after them
    (state bounds, lane, ``n_orow`` obstacle rows per step) and how many slack sign rows may
    follow those (one per step for the lane and for the obstacle rows; written per step by
    ``soft_solve``)."""
    N, nu = problem.N, problem.nu
    rows, rhs = [], []

    def unit(j, sign=1.0):
        r = np.zeros(nz)
        r[j] = sign
        return r

    n_bound = N * int(np.isfinite(problem.u_min).sum() + np.isfinite(problem.u_max).sum())
    Cb, bb = np.zeros((n_bound, nz)), np.zeros(n_bound)
    lo, hi = np.tile(problem.u_min, (N, 1)), np.tile(problem.u_max, (N, 1))
    # the Python function itself, once per controller: a compiled copy for this one call would
    # cost about a second of the first build
    input_bound_rows.py_func(N, nu, problem.u_min, problem.u_max, lo, hi, Cb, bb, True)
    rows += list(Cb)
    rhs += bb.tolist()
    r_rate0 = len(rows)
    dmax = problem.du_max_per_s * problem.dt_s
    for i in range(nu):  # |u_0 - u_prev| <= d: b written each step
        if np.isfinite(dmax[i]):
            rows += [unit(i), unit(i, -1.0)]
            rhs += [0.0, 0.0]
    for k in range(1, N):
        for i in range(nu):
            if np.isfinite(dmax[i]):
                r = np.zeros(nz)
                r[k * nu + i], r[(k - 1) * nu + i] = 1.0, -1.0
                rows += [r, -r]
                rhs += [-dmax[i], -dmax[i]]
    lane = problem.lane
    n_slack = (N if lane else 0) + (N if n_orow else 0)
    n_state = N * int(np.isfinite(problem.x_min).sum() + np.isfinite(problem.x_max).sum())
    n_var = n_state + (2 * N if lane else 0) + N * n_orow
    return rows, rhs, r_rate0, n_var, n_slack


def new_condensed_work(problem: MpcProblem, settings: CondensedSettings, obstacle_rows: int = 0) -> CondensedWork:
    """The work space of :func:`~mpcdrive.solvers.condensed.condensed_solve` for the stage QPs
    of ``problem`` with ``obstacle_rows`` obstacle rows per stage."""
    rows = obstacle_rows > 0
    N, nx, nu = problem.N, problem.nx, problem.nu
    nz = condensed_variables(problem, rows)
    cr = constant_rows(problem, nz, obstacle_rows)
    mq, nw = cr.mq, max(nx, nu)
    z = np.zeros
    return CondensedWork(
        nz=nz,
        mq=mq,
        m_const=cr.m_const,
        r_rate0=cr.r_rate0,
        gamma=cr.gamma,
        riccati=riccati_shortcut(problem, rows),
        max_iter=int(settings.max_iter),
        tol=float(settings.feasibility_tol),
        C=cr.C,
        b=cr.b,
        rowcol=cr.rowcol,
        rowspan=cr.rowspan,
        xf=z((N + 1, nx)),
        P=z((N + 1, nx, nx)),
        lam=z((N + 1, nx)),
        Vb=z((N, nx, nu)),
        S=z((2, nx, N * nu)),
        T2=z((nx, nw)),
        Gam=z((N, nx, N * nu)) if cr.gamma else z((1, 1, 1)),
        H=z((nz, nz)),
        g=z(nz),
        z=z(nz),
        L=z((nz, nz)),
        J=z((nz, nz)),
        Rq=z((nz, nz)),
        d=z(nz),
        zdir=z(nz),
        r=z(nz),
        uq=z(nz),
        sq=z(mq),
        rown=z(mq),
        lamq=z(mq),
        active=np.zeros(nz, dtype=np.int64),
        isact=np.zeros(mq, dtype=np.int64),
        rgrp=np.zeros(mq, dtype=np.int64),
        kpos=np.zeros(2 * N, dtype=np.int64),
        kprev=np.zeros(2 * N, dtype=np.int64),
        gsum=z(2 * N),
        Kg=z((N, nu, nx)),
        kf=z((N, nu)),
        PA=z((nx, nx)),
        Mg=z((nu, nx)),
        Gg=z((nu, nu)),
        qv=z(nx),
    )
