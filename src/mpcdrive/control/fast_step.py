"""The compiled step of :class:`~mpcdrive.control.fast.CompiledLtvMpc`.

:func:`control_step` is one control step (or one SQP iteration of it) in one numba call: the
step assembly of :mod:`mpcdrive.ocp.assembly` writes the stage QP
(:class:`~mpcdrive.ocp.stage_qp.StageQp`), the condensed solver of :mod:`mpcdrive.solvers`
solves it (:func:`~mpcdrive.solvers.condensed.condensed_solve`) and the plan is written out. It
takes one :class:`CompiledStep`: the controller's assembly, stage QP and solver work space as
typed containers (numba structs over arrays allocated once at construction).

Compiled functions use numba's on-disk cache; numba keys it to this file only, so the cache
is dropped (by :mod:`mpcdrive._jitcache`) when a file whose code the step links in changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from .._structs import define_struct, to_struct
from ..ocp.assembly import linearize, stage_costs
from ..solvers.condensed import condensed_solve, write_plan

#: stages of a step: all of it; up to the linearization trajectory (obstacle rows are built from
#: it in Python by ``ocp.avoidance``); the rest, with those rows in the stage QP; of the rest,
#: only the stage costs and road rows (the stage QP complete, for another solver)
STAGE_ALL, STAGE_LINEARIZE, STAGE_SOLVE, STAGE_COST = 0, 1, 2, 3

#: status code of a non-finite measured state (raised as ValueError by
#: :meth:`CompiledLtvMpc.step <mpcdrive.control.fast.CompiledLtvMpc.step>`)
_BAD_STATE = 4


@dataclass(frozen=True, eq=False)
class CompiledStep:
    """What one compiled step works on: the structs of the controller's
    :class:`~mpcdrive.ocp.assembly.StepAssembly` (``assembly``),
    :class:`~mpcdrive.ocp.stage_qp.StageQp` (``qp``) and
    :class:`~mpcdrive.solvers.condensed.CondensedWork` (``work``), the passing side per obstacle
    (``sides``, read and updated by the compiled detour) and ``info`` (s [m], e_y [m], e_psi
    [rad], iterations)."""

    assembly: Any
    qp: Any
    work: Any
    sides: np.ndarray
    info: np.ndarray

    def struct(self):
        """The compiled struct of this step (the same arrays and structs)."""
        return to_struct(self, _build_compiled_step)


@njit(cache=True)
def control_step(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """One control step (or one SQP iteration of it) at time ``t_s`` [s]; returns a status code
    (0 ok, 1 infeasible, 2 max_iter, 3 failed, 4 non-finite state). ``mode`` says what (Xw, Uw)
    is (``MODE_*`` of :mod:`mpcdrive.ocp.assembly`: no plan, the previous step's plan, the
    current SQP iterate). ``stage`` (``STAGE_*``): the whole step; or only up to the
    linearization trajectory, after which the caller writes the obstacle rows, road bounds and
    detour offsets of the step and runs the rest (``STAGE_SOLVE``); or, of the rest, only the
    stage costs and road rows (``STAGE_COST``: the stage QP is then complete, for another
    solver). A solve writes ``out = [u (nu), X ((N+1) nx), U (N nu), xref ((N+1) nx)]``."""
    asm, qp, work, info = step.assembly, step.qp, step.work, step.info
    for i in range(asm.nx):
        if not math.isfinite(x[i]):
            return _BAD_STATE
    if stage == STAGE_LINEARIZE or stage == STAGE_ALL:
        code = linearize(asm, qp, x, s_guess, t_s, u_prev, Xw, Uw, mode, step.sides, info)
        if code != 0 or stage == STAGE_LINEARIZE:
            return code
    stage_costs(asm, qp, t_s, stage != STAGE_ALL)
    if stage == STAGE_COST:
        return 0
    code, iters = condensed_solve(qp, work, x, u_prev)
    info[3] = iters
    if code != 0:
        return code
    write_plan(qp, work.z, x, out)
    return 0


_CompiledStepType, _CompiledStepStruct = define_struct(CompiledStep, __name__)


@njit(cache=True)
def _build_compiled_step(values):
    return _CompiledStepStruct(*values)


# numba caches control_step keyed to this file only; it inlines the assembly and the solver, and
# what they link in
from .. import _jitcache  # noqa: E402
from ..ocp import assembly as _assembly  # noqa: E402
from ..solvers import condensed as _condensed, dense_qp as _dense_qp  # noqa: E402

_jitcache.refresh(
    control_step,
    [*_assembly.LINKED_SOURCES, *(m.__file__ for m in (_assembly, _condensed, _dense_qp) if m.__file__ is not None)],
)
