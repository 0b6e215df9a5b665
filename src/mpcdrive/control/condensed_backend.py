"""The compiled condensed solver as a backend of any stage QP.

:class:`CondensedBackend` solves the stage QP of a step (:class:`~mpcdrive.ocp.stage_qp.StageQp`)
as it is -- whoever assembled it: :class:`~mpcdrive.control.mpc.LtvMpc` in Python for a model,
path or obstacle the compiled step has no form of -- with the solver
the compiled step runs (:func:`mpcdrive.solvers.condensed.condensed_solve`: the Riccati shortcut,
condensing onto the inputs, the dual active-set method with slacks only where they can be
nonzero; its limits: :func:`~mpcdrive.solvers.condensed_setup.condensed_unsupported_reason`). It
allocates its work arrays once; a solve allocates only the returned plan.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..ocp.problem import MpcProblem
from ..ocp.stage_qp import CONSTANT_FIELDS, StageQp, new_stage_qp
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
        self._work = new_condensed_work(pb, settings, int(pb.obstacle_rows))
        self._work_struct = self._work.struct()
        self._constants = new_stage_qp(pb, int(pb.obstacle_rows))  # the problem's constant parts
        #: the stage QP last solved and its struct (a controller writes the same one every step)
        self._stage: StageQp | None = None
        self._stage_struct = None
        #: the plan as the compiled step writes it: [u, X, U, xref]
        self._out = np.empty(nu + (N + 1) * nx + N * nu + (N + 1) * nx)

    def _check_fits(self, stage: StageQp) -> None:
        """ValueError unless ``stage`` is sized and posed for this solver's problem: its work
        space holds the rows that problem's bounds, rate limits and slacks make (a stage QP of
        another problem would be read past them)."""
        N, nx, nu, nrow = self.N, self.nx, self.nu, int(self.problem.obstacle_rows)
        if (stage.N, stage.nx, stage.nu, stage.nrow, stage.lane) != (N, nx, nu, nrow, bool(self.problem.lane)):
            raise ValueError(
                f"the stage QP (N={stage.N}, nx={stage.nx}, nu={stage.nu}, {stage.nrow} obstacle rows, road rows "
                f"{stage.lane}) does not fit this solver (N={N}, nx={nx}, nu={nu}, {nrow} obstacle rows, road "
                f"rows {bool(self.problem.lane)})"
            )
        mine = self._constants
        for f in CONSTANT_FIELDS:
            if not np.array_equal(getattr(stage, f), getattr(mine, f)):
                raise ValueError(
                    f"the stage QP was posed for another problem ({f} differs): pose it for this "
                    "solver's problem (StageQp.posed_for)"
                )

    def solve_stage(self, stage: StageQp, x: np.ndarray, u_prev: np.ndarray) -> SolveResult:
        """Solve the stage QP ``stage`` (:class:`~mpcdrive.ocp.stage_qp.StageQp`, as it is) from
        the measured state ``x`` (nx,) after input ``u_prev`` (nu,); the plan's states are
        rolled out through its affine model."""
        t0 = time.perf_counter()
        N, nx, nu = self.N, self.nx, self.nu
        if stage is not self._stage:
            self._check_fits(stage)
            self._stage, self._stage_struct = stage, stage.struct()
        u_prev = np.ascontiguousarray(u_prev, dtype=float)
        x = np.ascontiguousarray(x, dtype=float)
        code, iters = condensed_solve(self._stage_struct, self._work_struct, x, u_prev, nx, nu, True)
        status = STATUS_WORDS[code]
        if code != 0:
            nan = math.nan
            return SolveResult(
                status, np.full((N + 1, nx), nan), np.full((N, nu), nan), nan, int(iters), time.perf_counter() - t0
            )
        out = self._out
        write_plan(self._stage_struct, self._work.z, x, out)  # X rolled out through A, B, c
        oU = nu + (N + 1) * nx
        X = out[nu:oU].reshape(N + 1, nx).copy()
        U = out[oU : oU + N * nu].reshape(N, nu).copy()
        return SolveResult(status, X, U, math.nan, int(iters), time.perf_counter() - t0)
