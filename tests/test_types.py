"""The per-step result types: their hand-written constructors agree with the declared fields."""

import dataclasses
import inspect

import numpy as np
import pytest

from mpcdrive.types import ControlOutput, WarmStart


@pytest.mark.parametrize("cls", [WarmStart, ControlOutput])
def test_constructor_matches_declared_fields(cls):
    params = list(inspect.signature(cls.__init__).parameters.values())[1:]
    fields = dataclasses.fields(cls)
    assert [p.name for p in params] == [f.name for f in fields]
    for p, f in zip(params, fields):
        expected = inspect.Parameter.empty if f.default is dataclasses.MISSING else f.default
        assert p.default == expected, f.name


def test_fields_set_frozen_and_replaceable():
    u = np.array([0.1])
    w = WarmStart(2.0, u, t_s=0.3, sides=((1, 1),))
    assert (w.s_m, w.u_prev is u, w.X, w.U, w.t_s, w.sides, w.plan_age) == (2.0, True, None, None, 0.3, ((1, 1),), 0)
    out = ControlOutput(u, "ok", "", 1e-5, 2.0, 0.1, 0.2, None, None, w)
    assert out.sqp_iterations == 1 and out.warm is w and out.e_psi_rad == 0.2
    with pytest.raises(dataclasses.FrozenInstanceError):
        w.s_m = 3.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        out.status = "failed"  # type: ignore[misc]
    w2 = dataclasses.replace(w, plan_age=2)
    assert w2.plan_age == 2 and w2.s_m == 2.0 and w.plan_age == 0
    assert dataclasses.replace(out, status="relax").status == "relax"
    assert w2 == dataclasses.replace(w, plan_age=2) and w2 != w
