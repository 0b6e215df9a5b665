"""The compiled step of :class:`~mpcdrive.control.fast.CompiledLtvMpc`.

:func:`control_step_kinematic3` (and its siblings in :data:`CONTROL_STEPS`, one per vehicle
model, with or without the compiled obstacle cost) is one control step (or one SQP iteration of
it) in one numba call: the step assembly of :mod:`mpcdrive.ocp.assembly` writes the stage QP
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
from .._subroutine import subroutine
from ..models.compiled import KIND_DYNAMIC, KIND_KINEMATIC3, KIND_KINEMATIC4
from ..ocp.assembly import follow_references_into, linearize, stage_costs
from ..ocp.obstacle_cost_compiled import OBS_NONE
from ..solvers.condensed import condensed_solve, write_plan

#: stages of a step: all of it; up to the linearization trajectory (obstacle rows are built from
#: it in Python by ``ocp.avoidance``); the rest, with those rows in the stage QP; of the rest,
#: only the stage costs and road rows (the stage QP complete, for another solver); between the
#: two, the references of car following (``StepAssembly.follow_s``, ``follow_v``)
STAGE_ALL, STAGE_LINEARIZE, STAGE_SOLVE, STAGE_COST, STAGE_FOLLOW = 0, 1, 2, 3, 4

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


@subroutine
def _control_step(kind, cost_obstacles, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """One control step (or one SQP iteration of it) at time ``t_s`` [s] for the model ``kind``
    (``KIND_*`` of :mod:`mpcdrive.models.compiled`), with the compiled obstacle cost and detour
    if ``cost_obstacles`` (code 3 if the assembly has an obstacle cost and the step does not);
    returns a status code (0 ok, 1 infeasible, 2 max_iter,
    3 failed, 4 non-finite state). ``mode`` says what (Xw, Uw) is (``MODE_*`` of
    :mod:`mpcdrive.ocp.assembly`: no plan, the previous step's plan, the current SQP iterate).
    ``stage`` (``STAGE_*``): the whole step; or only up to the linearization trajectory, after
    which the caller writes the obstacle rows, road bounds and detour offsets of the step and
    runs the rest (``STAGE_SOLVE``); or, of the rest, only the stage costs and road rows
    (``STAGE_COST``: the stage QP is then complete, for another solver); or the references of
    car following (``STAGE_FOLLOW``). A solve writes
    ``out = [u (nu), X ((N+1) nx), U (N nu), xref ((N+1) nx)]``."""
    asm, qp, work, info = step.assembly, step.qp, step.work, step.info
    # a kind's code is its number of states; the kinematic bicycle at constant speed has one
    # input, the others two (constants where kind is one: the solver is specialized to them)
    nx = kind
    nu = 1 if kind == KIND_KINEMATIC3 else 2
    for i in range(nx):
        if not math.isfinite(x[i]):
            return _BAD_STATE
    if not cost_obstacles and asm.obstacle_form != OBS_NONE:
        return 3
    if stage == STAGE_FOLLOW:
        follow_references_into(kind, asm, qp, x[2])
        return 0
    if stage == STAGE_LINEARIZE or stage == STAGE_ALL:
        code = linearize(kind, cost_obstacles, asm, qp, x, s_guess, t_s, u_prev, Xw, Uw, mode, step.sides, info)
        if code != 0 or stage == STAGE_LINEARIZE:
            return code
    stage_costs(cost_obstacles, asm, qp, t_s, stage != STAGE_ALL)
    if stage == STAGE_COST:
        return 0
    code, iters = condensed_solve(qp, work, x, u_prev, nx, nu)
    info[3] = iters
    if code != 0:
        return code
    write_plan(qp, work.z, x, out)
    return 0


# One compiled step per vehicle model, with and without the compiled obstacle cost, each with
# the model and that choice as constants: a program compiles (or loads) only the
# steps it uses, with none of the other models' code (and no obstacle-cost code where there is
# no obstacle cost). ``CONTROL_STEPS[(kind, cost_obstacles)]`` is the one to use.


@njit(cache=True)
def control_step_kinematic3(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """:func:`_control_step` of the kinematic bicycle at constant speed (3 states, 1 input)."""
    return _control_step(KIND_KINEMATIC3, False, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out)


@njit(cache=True)
def control_step_kinematic3_cost(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """:func:`control_step_kinematic3` with the compiled obstacle cost."""
    return _control_step(KIND_KINEMATIC3, True, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out)


@njit(cache=True)
def control_step_kinematic4(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """:func:`_control_step` of the kinematic bicycle with speed (4 states, 2 inputs)."""
    return _control_step(KIND_KINEMATIC4, False, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out)


@njit(cache=True)
def control_step_kinematic4_cost(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """:func:`control_step_kinematic4` with the compiled obstacle cost."""
    return _control_step(KIND_KINEMATIC4, True, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out)


@njit(cache=True)
def control_step_dynamic(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """:func:`_control_step` of the dynamic bicycle (6 states, 2 inputs)."""
    return _control_step(KIND_DYNAMIC, False, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out)


@njit(cache=True)
def control_step_dynamic_cost(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """:func:`control_step_dynamic` with the compiled obstacle cost."""
    return _control_step(KIND_DYNAMIC, True, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out)


#: the compiled step of each model kind, without and with the compiled obstacle cost
CONTROL_STEPS = {
    (KIND_KINEMATIC3, False): control_step_kinematic3,
    (KIND_KINEMATIC3, True): control_step_kinematic3_cost,
    (KIND_KINEMATIC4, False): control_step_kinematic4,
    (KIND_KINEMATIC4, True): control_step_kinematic4_cost,
    (KIND_DYNAMIC, False): control_step_dynamic,
    (KIND_DYNAMIC, True): control_step_dynamic_cost,
}


_CompiledStepType, _CompiledStepStruct = define_struct(CompiledStep, __name__)


@njit(cache=True)
def _build_compiled_step(values):
    return _CompiledStepStruct(*values)


# numba caches the steps keyed to this file only; it inlines the assembly and the solver, and
# what they link in
from .. import _jitcache  # noqa: E402
from ..ocp import assembly as _assembly  # noqa: E402
from ..solvers import condensed as _condensed, dense_qp as _dense_qp  # noqa: E402

_jitcache.refresh(  # one file: one fingerprint for its six steps
    control_step_kinematic3,
    [*_assembly.LINKED_SOURCES, *(m.__file__ for m in (_assembly, _condensed, _dense_qp) if m.__file__ is not None)],
)
