"""The compiled condensed solver as a backend of any stage QP.

:class:`CondensedBackend` solves the stage QP of a step given as
:class:`~mpcdrive.control.mpc.StepData` -- whoever assembled it: :class:`~mpcdrive.control.mpc.LtvMpc`
in Python for a model, path or obstacle the compiled step has no form of -- with the solver
the compiled step runs (:func:`mpcdrive.solvers.condensed.condensed_solve`: the Riccati shortcut,
condensing onto the inputs, the dual active-set method with slacks only where they can be
nonzero; its limits: :func:`~mpcdrive.control.fast_setup.condensed_unsupported_reason`). It
allocates its work arrays once; a solve writes the stage data into them and allocates only the
returned plan.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..ocp.problem import MpcProblem
from ..solvers.condensed import condensed_solve
from ..solvers.dense_qp import STATUS_WORDS
from ..types import SolveResult
from .fast_setup import (
    CondensedSettings,
    condensed_unsupported_reason,
    condensed_variables,
    constant_rows,
    riccati_shortcut,
)
from .fast_step import _write_plan, input_bound_rows


class CondensedBackend:
    """The condensed solver for the stage QPs of ``problem`` (its ``obstacle_rows`` per step and
    ``position_cost`` as the controller set them), settings ``settings``."""

    name = "condensed"

    def __init__(self, problem: MpcProblem, settings: CondensedSettings = CondensedSettings()):
        reason = condensed_unsupported_reason(problem, settings, bool(problem.obstacle_rows))
        if reason is not None:
            raise ValueError(f"the condensed solver cannot solve this problem: {reason}")
        self.problem = pb = problem
        self.settings = settings
        N, nx, nu = pb.N, pb.nx, pb.nu
        self.N, self.nx, self.nu = N, nx, nu
        self._lane = pb.lane
        self._nrow = int(pb.obstacle_rows)
        self._nz = nz = condensed_variables(pb, bool(self._nrow))
        cr = constant_rows(pb, nz, self._nrow)
        self._C, self._b, self._rowcol = cr.C, cr.b, cr.rowcol
        self._m_const, self._r_rate0, self._gamma = cr.m_const, cr.r_rate0, cr.gamma
        mq = cr.mq
        self._riccati = riccati_shortcut(pb, bool(self._nrow))
        self._Wq = np.stack([pb.Q] * (N - 1) + [pb.QN])
        self._We = self._Wq.copy()
        self._qt = np.zeros((N, nx))
        self._dmax = pb.du_max_per_s * pb.dt_s
        self._ulo, self._uhi = np.tile(pb.u_min, (N, 1)), np.tile(pb.u_max, (N, 1))
        self._none_n = np.zeros((N, 2))
        self._none_1 = np.zeros(N)
        self._rowa = np.zeros((N, max(self._nrow, 1), 3))
        self._rowb = np.full((N, max(self._nrow, 1)), -np.inf)
        nw = max(nx, nu)
        z = np.zeros
        # the work arrays of condensed_solve, as the compiled controller sizes them
        self._work = (
            z((N + 1, nx)),  # xf
            z((N + 1, nx, nx)),  # P
            z((N + 1, nx)),  # lam
            z((N, nx, nu)),  # Vb
            z((2, nx, N * nu)),  # S
            z((nx, nw)),  # T2
            z((N, nx, N * nu)) if self._gamma else z((1, 1, 1)),  # Gam
            z((nz, nz)),  # H
            z(nz),  # g
            z(nz),  # z
            z((nz, nz)),  # L
            z((nz, nz)),  # J
            z((nz, nz)),  # Rq
            z(nz),  # d
            z(nz),  # zdir
            z(nz),  # r
            z(nz),  # uq
            z(mq),  # sq
            z(mq),  # rown
            z(mq),  # lamq
            np.zeros(nz, dtype=np.int64),  # active
            np.zeros(mq, dtype=np.int64),  # isact
            z(2 * N),  # gsum
            z((N, nu, nx)),  # Kg
            z((N, nu)),  # kf
            z((nx, nx)),  # PA
            z((nu, nx)),  # Mg
            z((nu, nu)),  # Gg
            z(nx),  # qv
        )
        self._rgrp = np.zeros(mq, dtype=np.int64)
        self._kpos = np.zeros(2 * N, dtype=np.int64)
        #: the plan as the compiled step writes it: [u, X, U, xref]
        self._out = np.empty(nu + (N + 1) * nx + N * nu + (N + 1) * nx)

    def solve_stage(self, d, u_prev: np.ndarray) -> SolveResult:
        """Solve the stage QP ``d`` (:class:`~mpcdrive.control.mpc.StepData`) after input
        ``u_prev``; the plan's states are rolled out through its affine model."""
        t0 = time.perf_counter()
        pb, N, nx, nu = self.problem, self.N, self.nx, self.nu
        u_prev = np.ascontiguousarray(u_prev, dtype=float)
        xref = np.ascontiguousarray(d.xref, dtype=float)
        We, qt = self._We, self._qt
        np.einsum("kij,kj->ki", self._Wq, xref[1:], out=qt)
        if d.H is not None and d.g is not None and pb.position_cost:
            # 1/2 p'Hp + g.p on the positions, in the form x'We x - 2 qt'x
            We[...] = self._Wq
            We[:, :2, :2] += 0.5 * d.H
            qt[:, :2] -= 0.5 * d.g
        ulo, uhi, C, b = self._ulo, self._uhi, self._C, self._b
        if d.u_lo is not None and d.u_hi is not None:
            ulo[...] = d.u_lo
            uhi[...] = d.u_hi
            input_bound_rows(N, nu, pb.u_min, pb.u_max, ulo, uhi, C, b, False)
        lane = self._lane
        if lane:
            dlo, dhi, _ = d.lane_slopes if d.lane_slopes is not None else (self._none_1,) * 3
            lane_n, lane_b, lane_lo, lane_hi = d.lane_normal, d.lane_offset, d.lane_lo, d.lane_hi
        else:
            dlo = dhi = lane_lo = lane_hi = lane_b = self._none_1
            lane_n = self._none_n
        if self._nrow and d.rows_a is not None and d.rows_b is not None:
            self._rowa[...] = d.rows_a
            self._rowb[...] = d.rows_b
        A, B, c = (np.ascontiguousarray(v, dtype=float) for v in (d.Ad, d.Bd, d.c))
        x = np.ascontiguousarray(d.x, dtype=float)
        code, iters = condensed_solve(
            N, nx, nu, self._nz, x, u_prev, A, B, c, We, qt, pb.R, pb.Rc, np.ascontiguousarray(d.uref), ulo, uhi,
            self._dmax, pb.x_min, pb.x_max, int(lane), np.ascontiguousarray(lane_n), np.ascontiguousarray(lane_b),
            np.ascontiguousarray(lane_lo), np.ascontiguousarray(lane_hi), np.ascontiguousarray(dlo),
            np.ascontiguousarray(dhi), np.ascontiguousarray(d.Xlin), self._nrow, self._rowa, self._rowb,
            self._riccati, self._gamma, self._m_const, self._r_rate0, C, b, self._rowcol, self._rgrp, self._kpos,
            pb.lane_slack_weight, pb.lane_slack_weight_l1, pb.obstacle_slack_weight, pb.obstacle_slack_weight_l1,
            self.settings.feasibility_tol, self.settings.max_iter, *self._work,
        )  # fmt: skip
        status = STATUS_WORDS[code]
        if code != 0:
            nan = math.nan
            return SolveResult(
                status, np.full((N + 1, nx), nan), np.full((N, nu), nan), nan, int(iters), time.perf_counter() - t0
            )
        out = self._out
        _write_plan(N, nx, nu, x, self._work[9], A, B, c, xref, ulo, uhi, out)  # X rolled out through A, B, c
        oU = nu + (N + 1) * nx
        X = out[nu:oU].reshape(N + 1, nx).copy()
        U = out[oU : oU + N * nu].reshape(N, nu).copy()
        return SolveResult(status, X, U, math.nan, int(iters), time.perf_counter() - t0)
