"""The compiled step of :class:`~mpcdrive.control.compiled_mpc.CompiledLtvMpc`.

:func:`control_step` gives the compiled step of a :class:`StepSpec` (the vehicle model, and
whether there is an obstacle cost; constraint rows, a speed profile or the friction circle): one
control step (or one SQP iteration of it) in one numba call, compiled with that spec as
constants, so it holds no code of the models and features it leaves out. The step assembly of
:mod:`mpcdrive.ocp.assembly` writes the stage QP (:class:`~mpcdrive.ocp.stage_qp.StageQp`),
the condensed solver of :mod:`mpcdrive.solvers` solves it
(:func:`~mpcdrive.solvers.condensed.condensed_solve`) and the plan is written out. It takes one
:class:`CompiledStep`: the controller's assembly, stage QP and solver work space as typed
containers (numba structs over arrays allocated once at construction).

Compiled functions use numba's on-disk cache, each spec's step under its own name; numba keys it
to this file only, so the cache is dropped (by :mod:`mpcdrive._jitcache`) when a file whose code
the step links in changes.
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
from ..ocp.assembly import MODE_ITERATE, MODE_SHIFTED_PLAN, follow_references_into, linearize, stage_costs
from ..ocp.obstacle_cost_compiled import OBS_NONE
from ..solvers.condensed import condensed_solve, shift_soft_guess, write_plan

#: stages of a step: all of it; up to the linearization trajectory (obstacle rows are built from
#: it in Python by ``ocp.avoidance``); the rest, with those rows in the stage QP; of the rest,
#: only the stage costs and road rows (the stage QP complete, for another solver); between the
#: two, the references of car following (``StepAssembly.follow_s``, ``follow_v``)
STAGE_ALL, STAGE_LINEARIZE, STAGE_SOLVE, STAGE_COST, STAGE_FOLLOW = 0, 1, 2, 3, 4

#: status code of a non-finite measured state (raised as ValueError by
#: :meth:`CompiledLtvMpc.step <mpcdrive.control.compiled_mpc.CompiledLtvMpc.step>`)
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


@dataclass(frozen=True)
class StepSpec:
    """What a compiled step is compiled for; each field is a constant of its code, so the code of
    what is off is left out of it (and each distinct spec is compiled once, then cached).

    ``kind``: the vehicle model (``KIND_*`` of :mod:`mpcdrive.models.compiled`);
    ``obstacle_cost``: the compiled obstacle cost and detour; ``extras``: constraint rows beyond
    the input bounds and rates (state bounds, the road's rows, obstacle rows), a speed profile
    and the friction circle's per-stage input bounds. The three extras share one flag: a step
    without them is the plain tracking step (as P1 and most of the paper's experiments run);
    separate flags would have a program that runs several scenarios compile more distinct
    steps, for little more code left out. A step handed an assembly that needs something its
    spec leaves out returns status 3.
    """

    kind: int
    obstacle_cost: bool = False
    extras: bool = False

    @classmethod
    def needed_by(cls, assembly, work) -> StepSpec:
        """The least spec whose step runs a controller's ``assembly``
        (:class:`~mpcdrive.ocp.assembly.StepAssembly`) and solver ``work``
        (:class:`~mpcdrive.solvers.condensed.CondensedWork`): read from the fields that
        :func:`_control_step` checks against its spec."""
        return cls(
            int(assembly.model),
            obstacle_cost=assembly.obstacle_form != OBS_NONE,
            extras=bool(work.gamma or assembly.has_profile or assembly.friction),
        )

    def __post_init__(self):
        if self.kind not in _KIND_NAMES:
            raise ValueError(f"no compiled step for model kind {self.kind!r}; kinds: {sorted(_KIND_NAMES)}")

    @property
    def name(self) -> str:
        """The compiled function's name, e.g. ``control_step_kinematic3_extras``."""
        flags = [f for f in _FLAGS if getattr(self, f)]
        return "_".join(["control_step", _KIND_NAMES[self.kind], *flags])

    def covers(self, other: StepSpec) -> bool:
        """Whether this spec's step runs what ``other``'s does: the same model kind, and every
        feature of ``other`` on here too."""
        return self.kind == other.kind and all(getattr(self, f) or not getattr(other, f) for f in _FLAGS)

    def describe(self) -> str:
        """What the step has code for, in words: "for tracking alone", "with code for the
        obstacle cost", ..."""
        if self.obstacle_cost and self.extras:
            return f"with code for the obstacle cost, {_EXTRAS_WORDS}"
        if self.obstacle_cost or self.extras:
            return f"with code for {'the obstacle cost' if self.obstacle_cost else _EXTRAS_WORDS}"
        return "for tracking alone"


_FLAGS = ("obstacle_cost", "extras")
_KIND_NAMES = {KIND_KINEMATIC3: "kinematic3", KIND_KINEMATIC4: "kinematic4", KIND_DYNAMIC: "dynamic"}
_EXTRAS_WORDS = "constraint rows, speed profiles and the friction circle"


@subroutine
def _control_step(kind, cost_obstacles, extras, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
    """One control step (or one SQP iteration of it) at time ``t_s`` [s], compiled for the
    :class:`StepSpec` (``kind``, ``cost_obstacles``, ``extras``; code 3 if the assembly needs
    what the spec leaves out); returns a status code (0 ok, 1 infeasible,
    2 max_iter, 3 failed, 4 non-finite state). ``mode`` says what (Xw, Uw) is (``MODE_*`` of
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
    # what the assembly needs that the spec leaves out (the fields StepSpec.needed_by reads)
    if not cost_obstacles and asm.obstacle_form != OBS_NONE:
        return 3
    if not extras and (work.gamma or asm.has_profile or asm.friction):
        return 3
    if stage == STAGE_FOLLOW:
        follow_references_into(kind, asm, qp, x[2])
        return 0
    if stage == STAGE_LINEARIZE or stage == STAGE_ALL:
        code = linearize(kind, cost_obstacles, extras, asm, qp, x, s_guess, t_s, u_prev, Xw, Uw, mode, step.sides, info)
        if code != 0 or stage == STAGE_LINEARIZE:
            return code
    stage_costs(cost_obstacles, extras, asm, qp, t_s, stage != STAGE_ALL)
    if stage == STAGE_COST:
        return 0
    if mode != MODE_ITERATE:  # a new control step: the last one's slack groups a step on
        shift_soft_guess(work, qp.N, mode == MODE_SHIFTED_PLAN)
    code, iters = condensed_solve(qp, work, x, u_prev, nx, nu, extras)
    info[3] = iters
    if code != 0:
        return code
    write_plan(qp, work.z, x, out)
    return 0


#: the compiled steps made so far, by spec
_STEPS: dict[StepSpec, Any] = {}


def control_step(spec: StepSpec) -> Any:
    """The compiled step for ``spec``: a ``@njit(cache=True)`` function ``(step, x, s_guess, t_s,
    u_prev, Xw, Uw, mode, stage, out)`` that calls :func:`_control_step` with the spec's fields
    as constants. A program compiles (or loads from numba's cache) only the specs it uses, each
    without the code of what it leaves out; numba caches each under its own name
    (:attr:`StepSpec.name`), keyed also to the constants."""
    fn = _STEPS.get(spec)
    if fn is None:
        kind, cost, extras = int(spec.kind), bool(spec.obstacle_cost), bool(spec.extras)

        def entry(step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out):
            return _control_step(kind, cost, extras, step, x, s_guess, t_s, u_prev, Xw, Uw, mode, stage, out)

        entry.__name__ = entry.__qualname__ = spec.name
        entry.__doc__ = f":func:`_control_step` {spec.describe()}, for model kind {kind}."
        fn = _STEPS[spec] = njit(cache=True)(entry)
    return fn


_CompiledStepType, _CompiledStepStruct = define_struct(CompiledStep, __name__)


@njit(cache=True)
def _build_compiled_step(values):
    return _CompiledStepStruct(*values)


# numba caches the steps keyed to this file only; it inlines the assembly and the solver, and
# what they link in
from .. import _jitcache  # noqa: E402
from ..ocp import assembly as _assembly  # noqa: E402
from ..solvers import condensed as _condensed, dense_qp as _dense_qp  # noqa: E402

_jitcache.refresh(  # one file: one fingerprint for all its steps
    _build_compiled_step,
    [*_assembly.LINKED_SOURCES, *(m.__file__ for m in (_assembly, _condensed, _dense_qp) if m.__file__ is not None)],
)
