"""Monte Carlo sweeps: planning (determinism, distributions, model errors), running (local pool,
in-process, Ray), the results table, the summary explaining every failure, and the CLI."""

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from mpcdrive.scenarios import build_experiment, load_scenario, run_experiment
from mpcdrive.sim import compute_metrics
from mpcdrive.sweep import (
    TIMING_COLUMNS,
    RunTask,
    plan_sweep,
    result_columns,
    run_sweep,
    run_task,
    summarize,
    write_sweep_outputs,
)

SHORT = ["duration_s=0.3"]
VARY = [
    "initial_state.y_m=uniform(-0.3, 0.3)",
    "initial_state.yaw_deg=offset_normal(0, 10)",
    "vehicle.lr_m=scale_uniform(0.8, 1.2)",
]


def plan(runs=4, seed=7, vary=VARY, set_=SHORT, scenario="paper-exp3", **kw):
    return plan_sweep(load_scenario(scenario), runs, seed, vary, set_, **kw)


def comparable(rows):
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def test_plan_is_deterministic_and_run_i_does_not_depend_on_the_number_of_runs():
    a, b, c = plan(5), plan(5), plan(8)
    assert [t.values for t in a.tasks] == [t.values for t in b.tasks]
    assert [(t.seed, t.values) for t in a.tasks] == [(t.seed, t.values) for t in c.tasks[:5]]
    assert len({t.seed for t in c.tasks}) == 8
    assert [t.values for t in plan(5, seed=8).tasks] != [t.values for t in a.tasks]
    for t in a.tasks:
        assert t.scenario["seed"] == t.seed and t.scenario["id"].startswith("paper-exp3-run")


def test_distributions_relative_to_the_scenario_and_model_errors():
    base = load_scenario("paper-exp3")
    p = plan(200, vary=VARY + ["controller.horizon=uniform(5, 15)", "controller.Q.0=choice(1, 10)"])
    vals = {k: np.array([t.values[k] for t in p.tasks]) for k in p.varied_names}
    assert np.all(np.abs(vals["initial_state.y_m"]) <= 0.3)
    assert np.all((vals["vehicle.lr_m"] >= 0.8 * 0.16 - 1e-12) & (vals["vehicle.lr_m"] <= 1.2 * 0.16 + 1e-12))
    yaw = vals["initial_state.yaw_deg"] - base.initial_state.yaw_deg
    assert abs(np.mean(yaw)) < 2.5 and 7 < np.std(yaw) < 13  # offset_normal(0, 10) around 90 deg
    assert vals["controller.horizon"].dtype.kind == "i" and set(vals["controller.horizon"]) <= set(range(5, 16))
    assert set(vals["controller.Q.0"]) == {1.0, 10.0}
    # the controller's model is varied, the true vehicle (plant) keeps the scenario's values
    t = p.tasks[0]
    assert t.scenario["vehicle"]["lr_m"] == t.values["vehicle.lr_m"]
    assert t.scenario["plant"]["lr_m"] == base.vehicle.lr_m and t.scenario["plant"]["speed_mps"] == 1.0
    exp = build_experiment(load_scenario("paper-exp3").model_validate(t.scenario))
    assert exp.plant.model.params.lr_m == base.vehicle.lr_m
    assert exp.controller.model.params.lr_m == pytest.approx(t.values["vehicle.lr_m"])


def test_set_creates_a_lane_and_vary_can_then_scale_it():
    p = plan(3, vary=["road.lane_width_m=scale_uniform(0.9, 1.1)"], set_=SHORT + ["road.lane_width_m=0.8"])
    assert p.base.road.lane_width_m == 0.8
    assert all(0.72 <= t.scenario["road"]["lane_width_m"] <= 0.88 for t in p.tasks)


def test_local_pool_gives_the_same_rows_as_in_process_runs():
    p = plan(4)
    pooled = run_sweep(p, "local", workers=2)
    inline = run_sweep(p, "local", workers=1)
    assert [r["run_id"] for r in pooled] == [0, 1, 2, 3]
    assert comparable(pooled) == comparable(inline)
    assert all(r["termination"] == "completed" and r["steps"] == 30 for r in pooled)


def test_runs_that_fail_are_explained_and_the_sweep_goes_on():
    # some draws give a negative axle distance: those runs are invalid, reported and skipped
    p = plan(12, seed=3, vary=["vehicle.lr_m=uniform(-0.1, 0.3)"])
    invalid = [t for t in p.tasks if t.scenario is None]
    assert invalid and len(invalid) < 12
    rows = run_sweep(p, "local", workers=1)
    for t, r in zip(p.tasks, rows):
        if t.scenario is None:
            assert not r["success"] and r["termination"] == "invalid"
            assert r["failure_reason"].startswith("invalid scenario: vehicle.lr_m:")
    # an error inside a run becomes that run's failure reason
    bad = run_task(RunTask(99, 1, {}, {"id": "x"}))
    assert bad["success"] is False and bad["failure_reason"].startswith("error: ValidationError")
    s = summarize(p, rows)
    assert s["failures"] == len(s["failed_runs"]) == sum(1 for r in rows if not r["success"])
    assert all(f["reason"] for f in s["failed_runs"])
    assert s["failure_categories"]["invalid scenario"] == len(invalid)


def test_solver_failures_in_a_sweep_are_counted_per_fallback_kind():
    p = plan(
        3,
        set_=SHORT
        + ["controller.backend=osqp", "controller.osqp_max_iter=3", "controller.fallback=[shifted_plan, brake]"],
    )
    rows = run_sweep(p, "local", workers=1)
    s = summarize(p, rows)
    assert s["solver_failures"]["total"] > 0
    assert s["fallbacks"]["total"] == s["solver_failures"]["total"]
    assert s["fallbacks"]["total"] == sum(s["fallbacks"]["by_kind"].values())
    assert s["fallbacks"]["by_kind"]["brake"] > 0 and s["fallbacks"]["by_kind"]["relax"] == 0
    for r in rows:
        assert r["fallbacks"] == sum(r[f"fallbacks_{k}"] for k in ("relax", "shifted_plan", "brake", "hold_last"))


def test_outputs_table_summary_figures_and_replayable_failed_runs(tmp_path):
    # a narrow lane and large initial offsets: some runs leave the lane
    p = plan(
        6, seed=1, vary=["initial_state.y_m=uniform(-0.45, 0.45)"], set_=["duration_s=1.0", "road.lane_width_m=0.8"]
    )
    rows = run_sweep(p, "local", workers=1)
    s = write_sweep_outputs(p, rows, tmp_path)
    with open(tmp_path / "runs.csv") as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == result_columns(p) and len(table) == 6
    assert [float(r["initial_state.y_m"]) for r in table] == [r["initial_state.y_m"] for r in rows]
    js = json.loads((tmp_path / "summary.json").read_text())
    assert js["runs"] == 6 and js["successes"] + js["failures"] == 6 and js["lane"]["lane_width_m"] == 0.8
    md = (tmp_path / "summary.md").read_text()
    assert f"{s['successes']} / 6" in md
    assert (tmp_path / "histograms.png").stat().st_size > 1000 and (tmp_path / "varied.png").exists()
    assert s["failures"] > 0
    for f in s["failed_runs"]:
        y = tmp_path / "failed" / f"run-{f['run_id']:04d}.yaml"
        assert f["reason"] in md and f["reason"] in y.read_text().splitlines()[0]
        # replaying a failed run gives the same numbers (the simulation is deterministic)
        exp = build_experiment(load_scenario(y))
        m = compute_metrics(run_experiment(exp))
        assert m["rms_lateral_error_m"] == rows[f["run_id"]]["rms_lateral_error_m"]
    if js["lane"]["runs_outside"]:
        assert "left the lane" in md
    try:
        import pyarrow.parquet as pq
    except ImportError:
        return
    t = pq.read_table(tmp_path / "runs.parquet").to_pylist()
    assert comparable(t) == comparable(rows)


def test_cli_sweep(tmp_path):
    out = tmp_path / "sw"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "mpcdrive.cli",
            "sweep",
            "paper-exp3",
            "--runs",
            "3",
            "--seed",
            "2",
            "--set",
            "duration_s=0.2",
            "--vary",
            "initial_state.y_m=uniform(-0.1,0.1)",
            "--workers",
            "1",
            "--out",
            str(out),
            "-q",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert "runs successful" in r.stdout and str(out) in r.stdout
    js = json.loads((out / "summary.json").read_text())
    assert js["runs"] == 3 and js["vary"] == ["initial_state.y_m=uniform(-0.1, 0.1)"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_ray_backend_gives_the_same_rows_as_the_local_pool():
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'mpcdrive[ray]')")
    p = plan(4)
    local = run_sweep(p, "local", workers=1)
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    try:
        got = []
        remote = run_sweep(p, "ray", progress=lambda done, total, row: got.append(done))
    finally:
        ray.shutdown()
    assert got == [1, 2, 3, 4]
    assert comparable(remote) == comparable(local)
    assert all(math.isfinite(r["rms_lateral_error_m"]) for r in remote)


def test_sweep_figures_have_labelled_axes_with_units_and_data():
    from mpcdrive.plots.sweep import make_sweep_histograms, make_sweep_varied

    rows = [
        {
            "run_id": i,
            "success": i % 3 != 0,
            "rms_lateral_error_m": 0.01 * i,
            "final_lateral_error_m": 0.001 * i,
            "max_abs_steer_rad": 0.5,
            "max_lane_excess_m": 0.0,
            "fallbacks": i % 2,
            "solve_time_p99_us": 300.0 + i,
            "initial_state.y_m": 0.1 * i - 0.5,
        }
        for i in range(10)
    ]
    rows.append({"run_id": 10, "success": False, "rms_lateral_error_m": None})  # a run that did not run
    fig = make_sweep_histograms(rows, lane=False)
    axes = [a for a in fig.axes if a.get_visible()]
    assert len(axes) == 5 and all("[" in a.get_xlabel() for a in axes)
    assert all(len(a.patches) > 0 for a in axes)
    assert "11 runs, 6 successful" in fig._suptitle.get_text()
    fig = make_sweep_varied(rows, ["initial_state.y_m"])
    ax = fig.axes[0]
    assert ax.get_xlabel() == "initial_state.y_m" and ax.get_ylabel() == "RMS lateral error [m]"
    assert sorted(len(line.get_xdata()) for line in ax.get_lines()) == [4, 6]


def _die_on_two(task):
    """A task function whose process dies (a segmentation fault) on task 2 (top level: the
    workers import it)."""
    import os
    import signal

    if task == 2:
        os.kill(os.getpid(), signal.SIGSEGV)
    return {"task": task}


@pytest.mark.skipif(sys.platform == "win32", reason="SIGSEGV by os.kill")
@pytest.mark.parametrize("workers", [1, 2])
def test_a_task_whose_process_dies_gets_its_row_and_the_others_go_on(workers):
    """A crash in compiled code kills its worker and breaks the pool: the task it ran gets the
    crash row (tried again alone first), every other task its own row."""
    from mpcdrive.sweep.runner import SweepError, run_parallel

    rows = run_parallel(_die_on_two, list(range(6)), workers=workers, crashed=lambda t, why: {"task": t, "died": why})
    by = {r["task"]: r for r in rows}
    assert sorted(by) == list(range(6)) and len(rows) == 6
    assert "process died" in by[2]["died"]
    assert all("died" not in r for t, r in by.items() if t != 2)
    with pytest.raises(SweepError, match="worker process died"):
        run_parallel(_die_on_two, list(range(4)), workers=2)
