"""The compiled condensed solver as a backend of any stage QP.

:class:`CondensedBackend` solves the stage QP of a step given as
:class:`~mpcdrive.control.mpc.StepData` -- whoever assembled it: :class:`~mpcdrive.control.mpc.LtvMpc`
in Python for a model, path or obstacle the compiled step has no form of -- with the solver
the compiled step runs (:func:`mpcdrive.solvers.condensed.condensed_solve`: the Riccati shortcut,
condensing onto the inputs, the dual active-set method with slacks only where they can be
nonzero; its limits: :func:`~mpcdrive.solvers.condensed_setup.condensed_unsupported_reason`). It
allocates its work arrays once; a solve writes the stage data into them and allocates only the
returned plan.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..ocp.problem import MpcProblem
from ..ocp.stage_qp import new_stage_qp
from ..solvers.condensed import condensed_solve, write_plan
from ..solvers.condensed_setup import CondensedSettings, condensed_unsupported_reason, new_condensed_work
from ..solvers.dense_qp import STATUS_WORDS
from ..types import SolveResult


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
        #: the stage QP the solver reads (its arrays written from each StepData) and its work
        self._qp = new_stage_qp(pb, int(pb.obstacle_rows))
        self._work = new_condensed_work(pb, settings, int(pb.obstacle_rows))
        self._qp_struct, self._work_struct = self._qp.struct(), self._work.struct()
        self._Wq = self._qp.We.copy()
        #: the plan as the compiled step writes it: [u, X, U, xref]
        self._out = np.empty(nu + (N + 1) * nx + N * nu + (N + 1) * nx)

    def solve_stage(self, d, u_prev: np.ndarray) -> SolveResult:
        """Solve the stage QP ``d`` (:class:`~mpcdrive.control.mpc.StepData`) after input
        ``u_prev``; the plan's states are rolled out through its affine model."""
        t0 = time.perf_counter()
        pb, N, nx, nu, qp = self.problem, self.N, self.nx, self.nu, self._qp
        u_prev = np.ascontiguousarray(u_prev, dtype=float)
        qp.xref[...] = d.xref
        qp.We[...] = self._Wq
        np.einsum("kij,kj->ki", self._Wq, qp.xref[1:], out=qp.qt)
        if d.H is not None and d.g is not None and pb.position_cost:
            # 1/2 p'Hp + g.p on the positions, in the form x'We x - 2 qt'x
            qp.We[:, :2, :2] += 0.5 * d.H
            qp.qt[:, :2] -= 0.5 * d.g
        if d.u_lo is not None and d.u_hi is not None:
            qp.ulo[...] = d.u_lo
            qp.uhi[...] = d.u_hi
        else:
            qp.ulo[...] = pb.u_min
            qp.uhi[...] = pb.u_max
        if qp.lane:
            qp.lane_n[...] = d.lane_normal
            qp.lane_b[...] = d.lane_offset
            qp.lane_lo[...] = d.lane_lo
            qp.lane_hi[...] = d.lane_hi
            if d.lane_slopes is not None:
                qp.lane_dlo[...] = d.lane_slopes[0]
                qp.lane_dhi[...] = d.lane_slopes[1]
            else:
                qp.lane_dlo[...] = 0.0
                qp.lane_dhi[...] = 0.0
        if qp.nrow and d.rows_a is not None and d.rows_b is not None:
            qp.rowa[...] = d.rows_a
            qp.rowb[...] = d.rows_b
        qp.A[...] = d.Ad
        qp.B[...] = d.Bd
        qp.c[...] = d.c
        qp.uref[...] = d.uref
        qp.Xlin[...] = d.Xlin
        x = np.ascontiguousarray(d.x, dtype=float)
        code, iters = condensed_solve(self._qp_struct, self._work_struct, x, u_prev)
        status = STATUS_WORDS[code]
        if code != 0:
            nan = math.nan
            return SolveResult(
                status, np.full((N + 1, nx), nan), np.full((N, nu), nan), nan, int(iters), time.perf_counter() - t0
            )
        out = self._out
        write_plan(self._qp_struct, self._work.z, x, out)  # X rolled out through A, B, c
        oU = nu + (N + 1) * nx
        X = out[nu:oU].reshape(N + 1, nx).copy()
        U = out[oU : oU + N * nu].reshape(N, nu).copy()
        return SolveResult(status, X, U, math.nan, int(iters), time.perf_counter() - t0)
