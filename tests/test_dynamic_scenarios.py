"""Scenario files with dynamic models, CSV tracks, speed profiles, mismatch and actuators; the
lap figures; the compare-models command's input checks."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from mpcdrive.cli import app
from mpcdrive.plots.laps import _make_lateral_acceleration, _make_speed_map, _make_tracking_comparison
from mpcdrive.scenarios import ScenarioError, ScenarioSpec, build_experiment, builtin_ids, dump_scenario, load_scenario
from mpcdrive.types import SimResult

BASE = {
    "id": "dyn",
    "dt_s": 0.05,
    "duration_s": 0.5,
    "vehicle": {"model": "dynamic_pacejka", "preset": "f1tenth"},
    "path": {"type": "csv", "file": "raceway"},
    "controller": {
        "horizon": 5,
        "Q": [1, 1, 1, 1, 0, 0],
        "R": [1, 0.1],
        "discretization": "exp",
        "speed_profile": {"lateral_accel_fraction": 0.5},
    },
    "plant": {"substeps": 5},
}


def write(tmp_path, data, name="s.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data))
    return p


def test_new_builtins_exist_and_round_trip():
    ids = builtin_ids()
    for sid in (
        "track-raceway",
        "track-hairpins",
        "mismatch-kinematic-mpc",
        "mismatch-params",
        "delay-uncompensated",
        "delay-compensated",
    ):
        assert sid in ids
        spec = load_scenario(sid)
        assert ScenarioSpec.model_validate(yaml.safe_load(dump_scenario(spec))) == spec


def test_preset_fills_parameters_but_explicit_keys_win():
    spec = ScenarioSpec.model_validate(
        {**BASE, "vehicle": {"model": "dynamic_linear", "preset": "commonroad_bmw_320i", "mass_kg": 1200.0}}
    )
    v = spec.vehicle
    assert v.mass_kg == 1200.0 and v.lf_m == pytest.approx(1.15620, rel=1e-4) and v.width_m == 1.610
    exp = build_experiment(load_scenario("track-raceway"))
    assert exp.mpc.model.params.yaw_inertia_kgm2 == 0.04712 and exp.footprint.width_m == 0.31


def test_csv_path_relative_to_the_scenario_file(tmp_path):
    (tmp_path / "tracks").mkdir()
    (tmp_path / "tracks" / "loop.csv").write_text(
        "# x_m, y_m, w_tr_right_m, w_tr_left_m\n"
        + "".join(
            f"{5 * np.cos(t):.5f}, {5 * np.sin(t):.5f}, 0.9, 1.1\n"
            for t in np.linspace(0, 2 * np.pi, 60, endpoint=False)
        )
    )
    data = {
        **BASE,
        "path": {"type": "csv", "file": "tracks/loop.csv"},
        "initial_state": {"x_m": 5.0, "y_m": 0.0, "yaw_deg": 90.0},
    }
    spec = load_scenario(write(tmp_path, data))
    assert spec.path.file == str((tmp_path / "tracks" / "loop.csv").resolve())
    exp = build_experiment(spec)
    # the road is the track's, its widths per side followed as they are (1.1 m left, 0.9 m right);
    # the controller keeps the body (half the car's width, no margin) inside it
    assert exp.track.closed and exp.road is exp.mpc.problem.road
    left, right = exp.road.edges([0.0, 7.0])
    np.testing.assert_allclose(left, 1.1) and np.testing.assert_allclose(right, -0.9)
    assert exp.road.period_m == pytest.approx(exp.path.length_m)
    lo, hi = exp.road.bounds(0.0, 0.0, 0.0, exp.footprint)
    assert (lo, hi) == (pytest.approx(-0.9 + 0.31 / 2), pytest.approx(1.1 - 0.31 / 2))
    assert exp.x0[3] == pytest.approx(exp.speed_profile.speed(exp.path.project(exp.x0[:2])[0]))


@pytest.mark.parametrize(
    "path, words",
    [
        ({"type": "csv", "file": "nowhere/track.csv"}, "path.file: track file not found"),
        ({"type": "csv", "file": "monza"}, "path.file: track file not found"),
        ({"type": "csv", "file": ""}, "path.file"),
    ],
)
def test_bad_track_reference_is_a_one_line_scenario_error(tmp_path, path, words):
    p = write(tmp_path, {**BASE, "path": path})
    with pytest.raises(ScenarioError) as e:
        load_scenario(p)
    assert str(e.value).startswith(str(p)) and words in str(e.value) and "\n" not in str(e.value)


def test_bad_track_file_content_is_reported_at_build(tmp_path):
    (tmp_path / "bad.csv").write_text("x_m, y_m\n0, 0\n1, oops\n2, 2\n")
    spec = load_scenario(write(tmp_path, {**BASE, "path": {"type": "csv", "file": "bad.csv"}}))
    with pytest.raises(ValueError, match="line 3: column y_m: not a number"):
        build_experiment(spec)


@pytest.mark.parametrize(
    "change, words",
    [
        (
            lambda d: (d["controller"].update(delay_compensation=True), d.update(plant={"steering_actuator": "ideal"})),
            "steering_actuator.dead_time_s",
        ),
        (lambda d: d.update(plant={"model": "kinematic4", "param_scale": {"mass": 1.2}}), "dynamic plant"),
        (
            lambda d: d.update(
                vehicle={"model": "kinematic3"},
                controller={"horizon": 5, "Q": [1, 1, 1], "R": [1]},
                plant={"model": "dynamic_pacejka"},
            ),
            "inputs of size",
        ),
        (lambda d: d["controller"].update(Q=[1, 1, 1, 1]), "controller.Q: needs 6 entries"),
        (lambda d: d["vehicle"].update(preset="trabant"), "vehicle.preset"),
        (lambda d: d["vehicle"].update(v_blend_low_mps=2.0), "v_blend_low_mps"),
        (lambda d: d["controller"]["speed_profile"].update(lateral_accel_fraction=1.5), "lateral_accel_fraction"),
        (lambda d: d.update(plant={"steering_actuator": {"dead_time_s": -0.1}}), "dead_time_s"),
        (lambda d: d.update(measurement_noise={"distribution": "normal", "std": [0.1, 0.1, 0.1]}), "6 entries"),
    ],
)
def test_inconsistent_dynamic_scenarios_are_rejected(tmp_path, change, words):
    data = yaml.safe_load(yaml.safe_dump(BASE))
    change(data)
    with pytest.raises(ScenarioError) as e:
        load_scenario(write(tmp_path, data))
    assert words in str(e.value)


def test_projected_gradient_solver_selectable_from_a_scenario(tmp_path):
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["controller"]["solver"] = "projected_gradient"  # input bounds only: no road, no rate limit
    data["path"] = {"type": "waypoints", "points": [[0, 0], [5, 0], [10, 2]]}
    exp = build_experiment(load_scenario(write(tmp_path, data)))
    assert exp.mpc.backend.name == "projected_gradient"
    # the run records the solver that ran (it said osqp before)
    assert (exp.mpc.assembly, exp.mpc.backend_name) == ("python", "pg")


# ------------------------------------------------------------------ figures
def _lap_result(n=60):
    t = np.arange(n) * 0.05
    th = t * 0.8
    xy = np.c_[3 * np.cos(th), 3 * np.sin(th)]
    x = np.c_[xy, th + np.pi / 2, np.full(n, 2.4), np.zeros(n), np.full(n, 0.8)]
    z = np.zeros(n)
    return SimResult(
        t_s=t,
        x=x,
        u=np.zeros((n, 2)),
        x_final=x[-1],
        s_m=3 * th,
        e_y_m=0.01 * np.sin(t),
        e_psi_rad=z,
        yaw_rad=x[:, 2],
        v_mps=2.4 + 0.1 * np.sin(t),
        steer_rad=z,
        accel_mps2=z,
        X_pred=x[:, None, :],
        refs=x[:, None, :],
        status=("ok",) * n,
        fallback=("",) * n,
        solve_time_s=z,
        path_xy=xy,
        dt_s=0.05,
        state_names=("x", "y", "yaw", "vx", "vy", "r"),
        input_names=("steer", "accel"),
        road_profile=np.array([[0.0, 0.5, -0.5], [20.0, 0.5, -0.5]]),
        lane_excess_m=np.zeros(n),
        meta={"id": "lap"},
    )


def test_lap_figures_have_labelled_axes_and_data():
    res = _lap_result()
    fig = _make_speed_map(res)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]"
    assert fig.axes[1].get_ylabel() == "speed v [m/s]"  # the colour bar
    assert len(ax.collections) == 1 and len(ax.collections[0].get_segments()) == res.steps - 1
    fig = _make_lateral_acceleration(res, limit_mps2=5.0)
    ax = fig.axes[0]
    assert "[m/s^2]" in ax.get_ylabel() and "[m]" in ax.get_xlabel()
    ay = ax.lines[0].get_ydata()
    assert np.median(ay) == pytest.approx(2.4**2 / 3.0, rel=0.05)  # v^2 / r
    fig = _make_tracking_comparison({"a": res, "b": res})
    assert len(fig.axes[0].lines) == 2 and fig.axes[0].get_ylabel() == "|e_y| [m]"


def test_compare_models_rejects_unknown_tracks_with_exit_2():
    from mpcdrive.cli import main  # noqa: F401  (the console entry maps BadInput to exit code 2)

    result = CliRunner().invoke(app, ["compare-models", "--track", "monza"], standalone_mode=False)
    assert result.exception is not None and "unknown track" in str(result.exception)
