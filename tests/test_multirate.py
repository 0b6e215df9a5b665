"""Multi-rate control: a controller slower than the plant (``simulate(control_period_s=...)``,
YAML ``controller.period_s`` / ``controller.between_solves``)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from mpcdrive.control import LtvMpc, MpcConfig, PythonLtvMpc
from mpcdrive.io.results import read_trajectory_csv, write_trajectory_csv
from mpcdrive.models import KinematicBicycle3
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.scenarios.build import build_experiment, run_experiment
from mpcdrive.scenarios.loader import ScenarioError, validate_scenario_data
from mpcdrive.sim import Plant, compute_metrics, simulate
from mpcdrive.sim.closed_loop import Disturbance
from mpcdrive.types import STATUS_HELD, STATUS_OK

PLANT_DT_S = 0.01  # 100 Hz plant
PERIOD_S = 0.1  # 10 Hz controller
M = 10  # plant steps per controller period
MAX_STEER_RAD = np.radians(60)
MODEL = KinematicBicycle3(v_mps=1.0)
CIRCLE = CirclePath(radius_m=1.5)
X0_CIRCLE = [1.5, 0.1, np.pi / 2]  # 0.1 m off the circle, on its normal


def mpc(dt_s: float, path=CIRCLE, N: int = 10) -> LtvMpc:
    problem = MpcProblem(nx=3, nu=1, N=N, dt_s=dt_s, Q=[1, 1, 1], R=1.0, u_min=-MAX_STEER_RAD, u_max=MAX_STEER_RAD)
    return PythonLtvMpc(MODEL, path, problem, MpcConfig(), "osqp")


class Recorder:
    """Wraps a controller and keeps every output it returns (to check what the loop applied)."""

    def __init__(self, inner):
        self.inner, self.outs = inner, []
        self.nx, self.nu, self.N, self.dt_s, self.problem = inner.nx, inner.nu, inner.N, inner.dt_s, inner.problem

    def initial_warm(self, x0):
        return self.inner.initial_warm(x0)

    def step(self, x, warm):
        out = self.inner.step(x, warm)
        self.outs.append(out)
        return out


def run(ctrl, steps=600, path=CIRCLE, x0=X0_CIRCLE, **kw):
    return simulate(ctrl, Plant(MODEL), path, x0, PLANT_DT_S, steps, **kw)


def test_period_equal_to_dt_is_the_one_solve_per_step_loop_bit_for_bit():
    noise = dict(
        disturbance=Disturbance("normal", std=np.array([1e-4, 1e-4, 1e-3])),
        measurement_noise=Disturbance("normal", std=np.array([1e-4, 1e-4, 1e-3])),
        seed=3,
    )
    base = run(mpc(PLANT_DT_S), steps=300, **noise)
    for mode in ("hold", "plan"):
        r = run(mpc(PLANT_DT_S), steps=300, control_period_s=PLANT_DT_S, between_solves=mode, **noise)
        for name in ("t_s", "x", "u", "x_final", "s_m", "e_y_m", "e_psi_rad", "X_pred", "refs"):
            assert np.array_equal(getattr(r, name), getattr(base, name)), (mode, name)
        assert r.status == base.status and r.fallback == base.fallback
        assert STATUS_HELD not in r.status
        assert r.meta == base.meta


def test_hold_equals_the_same_controller_on_a_plant_stepping_once_per_period():
    """Zero-order hold: 10 plant steps of 10 ms with the command held are the plant's 10 RK4
    substeps of one 0.1 s step, so the 100 Hz run meets the 10 Hz run at every solve exactly."""
    fast = run(mpc(PERIOD_S), steps=400, control_period_s=PERIOD_S)
    slow = simulate(mpc(PERIOD_S), Plant(MODEL, substeps=M), CIRCLE, X0_CIRCLE, PERIOD_S, 40)
    assert fast.steps == 400 and slow.steps == 40
    np.testing.assert_allclose(fast.x[::M], slow.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.u[::M], slow.u, rtol=0, atol=1e-12)


def test_hold_keeps_the_input_constant_between_solves_and_logs_every_plant_step(tmp_path):
    rec = Recorder(mpc(PERIOD_S))
    r = run(rec, steps=600, control_period_s=PERIOD_S)
    assert r.steps == 600 and len(rec.outs) == 60
    assert np.allclose(np.diff(r.t_s), PLANT_DT_S)
    for i, out in enumerate(rec.outs):
        block = slice(i * M, (i + 1) * M)
        assert np.array_equal(r.u[block], np.repeat(out.u[None], M, axis=0))
        assert r.status[i * M] == out.status and r.solve_time_s[i * M] == out.solve_time_s > 0
        assert r.status[i * M + 1 : (i + 1) * M] == (STATUS_HELD,) * (M - 1)
        assert r.fallback[i * M + 1 : (i + 1) * M] == ("",) * (M - 1)
        assert np.all(r.solve_time_s[i * M + 1 : (i + 1) * M] == 0.0)
        assert np.array_equal(r.X_pred[block], np.repeat(out.X_pred[None], M, axis=0))
    assert len({float(u) for u in r.u[::M, 0]}) > 10  # the solves do change the command
    assert r.meta["control_period_s"] == PERIOD_S and r.meta["between_solves"] == "hold"
    # held steps measure the true state's own path coordinates
    fr = CIRCLE.frenet(r.x[5, :3], r.s_m[4])
    assert r.e_y_m[5] == fr.e_y_m and r.s_m[5] == fr.s_m
    # trajectory.csv: one row per plant step, the held ones marked
    table = read_trajectory_csv(write_trajectory_csv(r, tmp_path / "trajectory.csv"))
    assert len(table["t"]) == 600 and table["status"].count(STATUS_HELD) == 540
    assert np.all(np.asarray(table["solve_time_us"])[np.asarray(table["status"]) == STATUS_HELD] == 0)


def test_plan_applies_the_plans_inputs_interpolated_between_solves():
    rec = Recorder(mpc(PERIOD_S))
    r = run(rec, steps=300, control_period_s=PERIOD_S, between_solves="plan")
    hold = run(mpc(PERIOD_S), steps=300, control_period_s=PERIOD_S)
    assert len(rec.outs) == 30
    for i, out in enumerate(rec.outs):
        u0, u1 = out.u, np.clip(out.warm.U[1], -MAX_STEER_RAD, MAX_STEER_RAD)
        assert r.u[i * M] == u0  # the solve's command at the solve
        for j in range(1, M):
            np.testing.assert_allclose(r.u[i * M + j], u0 + (j / M) * (u1 - u0), rtol=0, atol=1e-15)
        assert r.status[i * M + 1 : (i + 1) * M] == (STATUS_HELD,) * (M - 1)
    # it is not the hold: the steering moves between solves
    assert not np.array_equal(r.u[1:M], hold.u[1:M])
    assert np.max(np.abs(np.diff(r.u[:M, 0]))) > 0


@pytest.mark.parametrize("mode", ["hold", "plan"])
def test_ten_hz_controller_on_hundred_hz_plant_tracks_a_circle(mode):
    """A circle at constant steering: once converged the held (or interpolated) command is the
    circle's, so the error decays from the 0.1 m start offset to a small fraction of it."""
    r = run(mpc(PERIOD_S), steps=1000, control_period_s=PERIOD_S, between_solves=mode)
    m = compute_metrics(r)
    assert m["max_abs_lateral_error_m"] <= 0.1 + 1e-9  # never further off than at the start
    assert m["converged_max_abs_lateral_error_m"] < 0.01 * 0.1
    assert m["solver_failures"] == 0


@pytest.mark.parametrize("mode", ["hold", "plan"])
def test_ten_hz_controller_on_hundred_hz_plant_tracks_a_straight_line(mode):
    line = StraightPath((0.0, 0.0), (30.0, 0.0))
    r = run(
        mpc(PERIOD_S, path=line),
        steps=1000,
        path=line,
        x0=[0.5, 0.3, 0.0],
        control_period_s=PERIOD_S,
        between_solves=mode,
    )
    ey = np.abs(r.e_y_m)
    assert ey.max() <= 0.3 + 1e-9
    assert ey[-200:].max() < 0.01 * 0.3  # the last 2 s: within 1 % of the 0.3 m start offset


def test_metrics_count_only_real_solves():
    r = run(mpc(PERIOD_S), steps=300, control_period_s=PERIOD_S)
    solved = np.array([s != STATUS_HELD for s in r.status])
    assert solved.sum() == 30
    m = compute_metrics(r)
    st = r.solve_time_s[solved] * 1e6
    assert m["solve_time_us"]["p50"] == pytest.approx(np.percentile(st, 50), rel=1e-12)
    assert m["solve_time_us"]["p99"] == pytest.approx(np.percentile(st, 99), rel=1e-12)
    assert m["solve_time_us"]["p50"] > 0  # 90 % of the steps are held with solve time 0
    assert m["solver_failures"] == 0 and m["fallbacks"] == 0
    # one failed solve among them is one failure, however many held steps follow it
    status = list(r.status)
    status[20] = "max_iter"
    fallback = list(r.fallback)
    fallback[20] = "shifted_plan"
    bad = compute_metrics(dataclasses.replace(r, status=tuple(status), fallback=tuple(fallback)))
    assert bad["solver_failures"] == 1 and bad["fallbacks"] == 1 and bad["fallback_counts"]["shifted_plan"] == 1


@pytest.mark.parametrize(
    "period, words", [(0.015, "whole multiple"), (0.005, "shorter than"), (0.0, "positive"), (float("nan"), "positive")]
)
def test_bad_period_is_a_clear_error(period, words):
    with pytest.raises(ValueError, match=words) as e:
        run(mpc(PLANT_DT_S), steps=10, control_period_s=period)
    assert "control_period_s" in str(e.value)
    if words != "positive":
        assert "dt_s" in str(e.value)


def test_controller_built_for_another_step_or_unknown_mode_is_an_error():
    with pytest.raises(ValueError, match=r"horizon step dt_s 0.01 s differs from control_period_s 0.1"):
        run(mpc(PLANT_DT_S), steps=10, control_period_s=PERIOD_S)
    with pytest.raises(ValueError, match="between_solves must be 'hold' or 'plan'"):
        run(mpc(PERIOD_S), steps=10, control_period_s=PERIOD_S, between_solves="zoh")


def scenario(**controller):
    return {
        "id": "mr",
        "dt_s": PLANT_DT_S,
        "duration_s": 3.0,
        "path": {"type": "circle", "radius_m": 1.5},
        "road": {"lane_width_m": 1.0},
        "initial_state": {"x_m": 1.5, "y_m": 0.0, "yaw_deg": 90},
        "controller": {"horizon": 10, "Q": [1, 1, 1], "R": [1], **controller},
    }


@pytest.mark.parametrize("mode", ["hold", "plan"])
def test_yaml_period_runs_the_controller_at_its_period_on_the_plant_step(mode):
    spec = validate_scenario_data(scenario(period_s=0.1, between_solves=mode), "mr.yaml")
    exp = build_experiment(spec)
    assert exp.mpc.problem.dt_s == 0.1 and exp.steps == 300
    r = run_experiment(exp)
    assert r.dt_s == PLANT_DT_S and r.steps == 300
    assert r.status.count(STATUS_HELD) == 270 and r.status[::M] == (STATUS_OK,) * 30
    assert r.meta["between_solves"] == mode
    held_same = all(np.array_equal(r.u[i * M], r.u[i * M + 1]) for i in range(30))
    assert held_same == (mode == "hold")


def test_yaml_default_period_is_the_plant_step():
    spec = validate_scenario_data(scenario(), "mr.yaml")
    assert spec.control_period_s == PLANT_DT_S and spec.controller.between_solves == "hold"
    assert build_experiment(spec).mpc.problem.dt_s == PLANT_DT_S


@pytest.mark.parametrize(
    "controller, field, words",
    [
        ({"period_s": 0.015}, "controller.period_s", "0.015 s is not a whole multiple of the plant step dt_s 0.01 s"),
        ({"period_s": 0.005}, "controller.period_s", "0.005 s is shorter than the plant step dt_s 0.01 s"),
        ({"period_s": -0.1}, "controller.period_s", "greater than 0"),
        ({"between_solves": "zoh"}, "controller.between_solves", "'hold' or 'plan'"),
    ],
)
def test_yaml_bad_period_names_file_field_and_problem(controller, field, words):
    with pytest.raises(ScenarioError) as e:
        validate_scenario_data(scenario(**controller), "mr.yaml")
    assert e.value.source == "mr.yaml" and e.value.field == field and words in e.value.problem
    assert "\n" not in str(e.value)


def test_yaml_plan_with_delay_compensation_is_rejected():
    data = scenario(between_solves="plan", delay_compensation=True, period_s=0.1)
    data["plant"] = {"steering_actuator": {"dead_time_s": 0.1}}
    with pytest.raises(ScenarioError) as e:
        validate_scenario_data(data, "mr.yaml")
    assert e.value.field == "controller.between_solves" and "delay_compensation" in e.value.problem


def test_cli_bad_period_exits_2_and_writes_nothing(tmp_path):
    import yaml

    f = tmp_path / "mr.yaml"
    f.write_text(yaml.safe_dump(scenario(period_s=0.015)))
    out = tmp_path / "out"
    p = subprocess.run(
        [sys.executable, "-m", "mpcdrive.cli", "run", str(f), "--out", str(out)], capture_output=True, text=True
    )
    assert p.returncode == 2
    assert "controller.period_s" in p.stderr and "whole multiple" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_yaml_period_of_a_second_or_more_warns_like_milliseconds():
    from mpcdrive.scenarios.build import scenario_warnings

    data = scenario(period_s=2.0)
    data["duration_s"] = 4.0
    fields = [f for f, _ in scenario_warnings(validate_scenario_data(data, "mr.yaml"))]
    assert fields == ["controller.period_s"]
    assert scenario_warnings(validate_scenario_data(scenario(period_s=0.1), "mr.yaml")) == []


class NoPlan(Recorder):
    """A controller whose commands come without a plan (as a brake or hold_last fallback's)."""

    def step(self, x, warm):
        out = self.inner.step(x, warm)
        return dataclasses.replace(out, warm=dataclasses.replace(out.warm, U=None, X=None))


def test_plan_holds_a_command_that_comes_without_a_plan():
    r = run(NoPlan(mpc(PERIOD_S)), steps=100, control_period_s=PERIOD_S, between_solves="plan")
    for i in range(10):
        assert np.all(r.u[i * M : (i + 1) * M] == r.u[i * M])
