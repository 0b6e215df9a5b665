"""A closed loop gives the same numbers on every machine: the SQP iterations stop on an
iteration cap and the inputs' settling (``sqp_tol``), never on wall time, unless a user asks
for real-time mode (``MpcConfig.sqp_max_time_s``). Here the same loop runs twice, once with
every QP solve slowed down by a sleep (a loaded or slower machine), and must give the same
trajectory bit for bit."""

import math
import time

import numpy as np
import pytest

from mpcdrive.control.compiled_mpc import CompiledLtvMpc
from mpcdrive.control.mpc import MpcConfig, PythonLtvMpc
from mpcdrive.ocp import MpcProblem
from mpcdrive.models.kinematic import KinematicBicycle4
from mpcdrive.ocp.avoidance import AvoidanceConfig
from mpcdrive.paths import StraightPath
from mpcdrive.scenarios import builtin_ids, load_scenario
from mpcdrive.scene.obstacles import Circle, Obstacle
from mpcdrive.scene.road import Road
from mpcdrive.sim.closed_loop import Plant, simulate

#: longer than the old default wall-time cap (0.05 s) once two QPs ran: a slow machine
SLOW_S = 0.03
STEPS = 12


def _problem():
    model = KinematicBicycle4()
    path = StraightPath([0.0, 0.0], [100.0, 0.0])
    pb = MpcProblem(
        4,
        2,
        20,
        0.1,
        Q=np.diag([1.0, 5.0, 1.0, 1.0]),
        R=np.diag([1.0, 0.1]),
        Rc=np.diag([0.1, 0.01]),
        u_min=[-0.5, -3.0],
        u_max=[0.5, 2.0],
        du_max_per_s=[1.0, 5.0],
        road=Road.constant(4.0, 0.05),
    )
    # SQP to convergence on the potential cost: several QPs per step, each re-linearized
    cfg = MpcConfig(v_ref_mps=5.0, sqp_max_iterations=4, sqp_tol=1e-12)
    obstacles = (Obstacle(Circle(0.5), (6.0, 0.3, 0.0)),)
    av = AvoidanceConfig("potential", weight=50.0)
    x0 = np.array([0.0, 0.0, 0.0, 5.0])
    return model, path, pb, cfg, obstacles, av, x0


def _build(kind: str):
    model, path, pb, cfg, obstacles, av, x0 = _problem()
    if kind == "fast":
        c = CompiledLtvMpc(model, path, pb, cfg, obstacles=obstacles, avoidance=av)
    else:
        c = PythonLtvMpc(model, path, pb, cfg, "osqp", obstacles=obstacles, avoidance=av)
    return c, model, path, x0


def _slow(c, kind: str, monkeypatch, sleep_s: float = SLOW_S) -> list:
    """Every QP solve of ``c`` sleeps ``sleep_s`` first; returns the list the solves are counted in."""
    name = "_run" if kind == "fast" else "_solve"
    inner = getattr(c, name)
    calls: list = []

    def slowed(*args, **kwargs):
        calls.append(1)
        time.sleep(sleep_s)
        return inner(*args, **kwargs)

    monkeypatch.setattr(c, name, slowed)
    return calls


def _loop(c, model, path, x0):
    return simulate(c, Plant(model), path, x0, 0.1, STEPS, stop_at_path_end=False)


def test_no_wall_time_cap_by_default():
    assert MpcConfig().sqp_max_time_s is None


@pytest.mark.parametrize("kind", ["fast", "osqp"])
def test_a_slowed_solver_drives_the_same_loop(kind, monkeypatch):
    c, model, path, x0 = _build(kind)
    counted = _slow(c, kind, monkeypatch, 0.0)
    ref = _loop(c, model, path, x0)
    c2, *_ = _build(kind)
    _slow(c2, kind, monkeypatch)
    slow = _loop(c2, model, path, x0)
    assert np.array_equal(ref.x, slow.x)
    assert np.array_equal(ref.u, slow.u)
    assert np.array_equal(ref.X_pred, slow.X_pred)
    # the loop did run SQP near the obstacle: more QPs than steps (else the test shows nothing)
    assert len(counted) > STEPS + 3


@pytest.mark.parametrize("kind", ["fast", "osqp"])
def test_real_time_mode_is_opt_in_and_caps_the_iterations(kind, monkeypatch):
    """With ``sqp_max_time_s`` set, a slowed solver runs fewer QPs: the opt-in real-time mode
    (the loop's numbers then depend on the machine's speed, which is why it is off by default)."""
    model, path, pb, cfg, obstacles, av, x0 = _problem()
    import dataclasses

    rt = dataclasses.replace(cfg, sqp_max_time_s=0.05)
    c = (
        CompiledLtvMpc(model, path, pb, rt, obstacles=obstacles, avoidance=av)
        if kind == "fast"
        else PythonLtvMpc(model, path, pb, rt, "osqp", obstacles=obstacles, avoidance=av)
    )
    near = np.array([4.0, 0.0, 0.0, 5.0])  # 2 m before the obstacle: its cost bends the plan
    _slow(c, kind, monkeypatch)
    out = c.step(near, c.initial_warm(near))
    assert out.sqp_iterations < cfg.sqp_max_iterations
    free, *_ = _build(kind)
    assert free.step(near, free.initial_warm(near)).sqp_iterations == cfg.sqp_max_iterations


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan, True])
def test_real_time_cap_must_be_a_positive_time(bad):
    with pytest.raises(ValueError, match="sqp_max_time_s"):
        MpcConfig(sqp_max_time_s=bad)


def test_no_built_in_scenario_sets_a_wall_time_cap():
    for sid in builtin_ids():
        spec = load_scenario(sid)
        av = spec.avoidance
        assert av is None or av.sqp_max_time_s is None, sid
        assert spec.controller.osqp_time_limit_s == 0, sid
