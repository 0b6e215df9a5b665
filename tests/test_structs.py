"""The typed containers of the compiled step: one field list, shared memory, clear errors."""

import dataclasses

import numpy as np
import pytest

from mpcdrive._structs import struct_values
from mpcdrive.ocp import MpcProblem
from mpcdrive.ocp.stage_qp import StageQp, new_stage_qp
from mpcdrive.solvers.condensed import CondensedWork, condensed_solve, write_plan
from mpcdrive.solvers.condensed_setup import CondensedSettings, new_condensed_work


def _problem(N=4):
    return MpcProblem(2, 1, N, 0.1, Q=np.ones(2), R=1.0, u_min=-1.0, u_max=1.0)


def test_struct_values_are_the_fields_in_order():
    qp = new_stage_qp(_problem())
    values = struct_values(qp)
    assert len(values) == len(dataclasses.fields(StageQp))
    assert values[3] is qp.A  # arrays are handed over as they are: the same memory


def test_a_strided_or_wrongly_typed_array_is_a_clear_error():
    qp = new_stage_qp(_problem())
    strided = dataclasses.replace(qp, c=np.zeros((8, 2))[::2])
    with pytest.raises(ValueError, match=r"StageQp\.c: a C-contiguous float64 or int64 array is needed"):
        struct_values(strided)
    as_float32 = dataclasses.replace(qp, c=np.zeros((4, 2), dtype=np.float32))
    with pytest.raises(ValueError, match=r"StageQp\.c: .* got float32"):
        struct_values(as_float32)
    with pytest.raises(TypeError, match="container dataclass"):
        struct_values((1, 2))


def test_writes_on_the_python_side_reach_the_compiled_solve():
    """A double integrator x' = (p + v dt, v + u dt): the struct is made once, then the stage QP
    is written from Python; the compiled solve must see the new model and references (here:
    the unconstrained plan to a reference ahead equals the Riccati shortcut's, and moves with
    the reference)."""
    pb = _problem(N=10)
    qp = new_stage_qp(pb)
    work = new_condensed_work(pb, CondensedSettings())
    assert isinstance(work, CondensedWork)
    qs, ws = qp.struct(), work.struct()
    dt = 0.1
    qp.A[...] = np.array([[1.0, dt], [0.0, 1.0]])
    qp.B[...] = np.array([[0.0], [dt]])
    x = np.zeros(2)
    firsts = []
    for target in (0.5, 1.0):
        qp.xref[...] = [target, 0.0]
        np.einsum("kij,kj->ki", qp.We, qp.xref[1:], out=qp.qt)
        code, _ = condensed_solve(qs, ws, x, np.zeros(1), qp.nx, qp.nu, True)
        assert code == 0
        out = np.empty(1 + 11 * 2 + 10 + 11 * 2)
        write_plan(qs, work.z, x, out)
        firsts.append(out[0])
    assert 0.0 < firsts[0] < firsts[1] <= 1.0  # a farther reference, a harder push (within the bound)
