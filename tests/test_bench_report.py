"""Bench entries per backend, the horizon and obstacle sweeps, cold start, allocations and the
bench report: checked by structure and consistency, never by time."""

import json
import math
import warnings

import numpy as np
import pytest

from mpcdrive.bench import run_bench
from mpcdrive.bench.extras import cold_start, horizon_sweep, obstacle_sweep, step_allocations
from mpcdrive.bench.problems import p3, p3_obstacles
from mpcdrive.bench.runner import make_controller
from mpcdrive.bench.runner import BACKENDS
from mpcdrive.control import FastPathUnavailable
from mpcdrive.plots.bench import make_horizon_figure, make_obstacle_figure, plot_horizon_scaling, plot_obstacle_scaling
from mpcdrive.report.bench import render_bench_report, write_bench_report

KEYS = {"p50_us", "p99_us", "max_us", "steps", "rms_lateral_error_m"}


@pytest.fixture(scope="module")
def results():
    return run_bench(["P1", "P2"], steps=40)


def test_bench_has_an_entry_per_backend_and_the_default(results):
    for prob in ("P1", "P2"):
        impls = results[prob]
        assert set(impls) >= {"mpcdrive", "mpcdrive_osqp", "mpcdrive_fast"}
        for rec in impls.values():
            assert KEYS <= set(rec) and rec["steps"] == 40 and rec["p50_us"] > 0
        assert impls["mpcdrive_fast"]["backend"] == "fast" and impls["mpcdrive_osqp"]["backend"] == "osqp"
        assert impls["mpcdrive"] == impls["mpcdrive_fast"]  # the bench headline is the fast path
        # both backends drove the same closed loop
        assert impls["mpcdrive_fast"]["rms_lateral_error_m"] == pytest.approx(
            impls["mpcdrive_osqp"]["rms_lateral_error_m"], rel=1e-4, abs=1e-6
        )


def test_horizon_sweep_report_and_figure(results, tmp_path):
    sweep = horizon_sweep(horizons=(5, 12), steps=25)
    assert set(sweep) == {5, 12} and set(sweep[5]) == {"osqp", "fast"}
    assert sweep[12]["fast"]["steps"] == 25
    fig = make_horizon_figure(sweep)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "horizon N [steps]" and "[us]" in ax.get_ylabel()
    assert len(ax.lines) == 4 and list(ax.lines[0].get_xdata()) == [5, 12]
    assert plot_horizon_scaling(sweep, tmp_path / "h.png").stat().st_size > 1000
    alloc = {"fast": step_allocations("fast", steps=20), "osqp": step_allocations("osqp", steps=20)}
    assert all(a["peak_extra_bytes"] >= 0 for a in alloc.values())
    cold = {"fast": {"import_build_first_step_s": 0.5, "process_1000_steps_s": 1.0, "peak_rss_mib": 100.0}}
    path = write_bench_report(tmp_path, results, sweep, cold, alloc, figure="h.png", note="noisy machine")
    text = path.read_text()
    assert "| P1 | mpcdrive (fast) |" in text and "| P2 | mpcdrive_osqp |" in text
    assert "## P1: per-step time as the horizon grows" in text and "| 12 |" in text
    assert "![per-step time vs horizon](h.png)" in text and "noisy machine" in text
    assert "| P1 | mpcdrive_osqp |" in text.split("## Speed-up")[1]
    assert "## P3: per-step time as obstacles are added" not in text  # no sweep given, no section
    assert render_bench_report(results).split("## Speed-up")[0].count("| P1 |") == 3


def test_cold_start_runs_a_fresh_process():
    r = cold_start("fast", steps=20, repeats=1)
    assert r["backend"] == "fast"
    assert 0 < r["import_build_first_step_s"] < r["process_1000_steps_s"]
    assert np.isfinite(r["peak_rss_mib"]) and r["peak_rss_mib"] > 0


@pytest.mark.parametrize("n", [0, 1, 2, 5, 20])
def test_obstacle_problem_has_n_obstacles_all_in_play_over_the_drive(n):
    prob = p3_obstacles(n)
    base = p3()
    assert len(prob.obstacles) == n
    assert repr(prob.problem.road) == repr(base.problem.road)
    assert type(prob.model) is type(base.model) and np.array_equal(prob.x0, base.x0)
    assert prob.problem.N == base.problem.N and np.array_equal(prob.problem.Q, base.problem.Q)
    assert prob.config == base.config
    if n == 0:
        assert prob.avoidance is None
        return
    av = prob.avoidance
    assert av.formulation == base.avoidance.formulation and av.sigma_m == base.avoidance.sigma_m
    assert av.weight == base.avoidance.weight and av.max_obstacles == n
    centres = np.array([ob.pose[:2] for ob in prob.obstacles])
    assert len({tuple(c) for c in centres}) == n
    assert np.all(np.abs(centres[:, 1]) < 1.0)  # near the centreline, inside the lane
    # every obstacle within the influence distance from anywhere on the drive: the start and the
    # path from its start to 3 m past its end (more than a 1000-step drive covers at 1 m/s)
    s = np.linspace(0.0, prob.path.length_m + 3.0, 60)
    drive = np.vstack([prob.x0[:2], prob.path.position(s)])
    far = max(
        math.hypot(*(c - p)) - ob.shape.bounding_radius_m for p in drive for c, ob in zip(centres, prob.obstacles)
    )
    assert far <= av.influence_m
    # and the controller puts all of them in the problem, at the start and at the end
    ctrl = prob.controller()
    for t, xy in ((0.0, prob.x0[:2]), (10.0, drive[-1])):
        assert sorted(ctrl.avoidance.relevant(t, xy)) == list(range(n))


def test_obstacle_problem_rejects_negative_count():
    with pytest.raises(ValueError, match="obstacle count"):
        p3_obstacles(-1)


def test_one_obstacle_is_p3s():
    assert p3_obstacles(1).obstacles[0].pose == p3().obstacles[0].pose


@pytest.fixture(scope="module")
def obstacles():
    with warnings.catch_warnings():
        warnings.simplefilter("error", FastPathUnavailable)  # the sweep must not let it through
        return obstacle_sweep(counts=(0, 2), steps=20)


def test_obstacle_sweep_structure(obstacles):
    assert set(obstacles) == {0, 2}
    for n, per in obstacles.items():
        assert set(per) == set(BACKENDS)
        for b, r in per.items():
            assert KEYS <= set(r) and r["steps"] == 20 and r["p50_us"] > 0
            assert r["p50_us"] <= r["p99_us"] <= r["max_us"]
            assert r["solver_failures"] == 0
            # the backend that ran is the one make_controller returns, and a fallback says why
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FastPathUnavailable)
                ran = make_controller(p3_obstacles(n), b).backend_name
            assert r["backend"] == ran
            assert (r["fallback"] is None) == (ran == b)
            if n == 0:
                assert r["min_obstacle_clearance_m"] is None
            else:
                assert r["min_obstacle_clearance_m"] > 0
    # the same problem whichever backend ran
    assert obstacles[2]["fast"]["rms_lateral_error_m"] == pytest.approx(
        obstacles[2]["osqp"]["rms_lateral_error_m"], rel=1e-3, abs=1e-5
    )


def test_obstacle_sweep_report_and_figure(results, obstacles, tmp_path):
    fig = make_obstacle_figure(obstacles)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "obstacles [count]" and "[us]" in ax.get_ylabel()
    assert len(ax.lines) == 2 * len(BACKENDS) and list(ax.lines[0].get_xdata()) == [0, 2]
    assert ax.get_yscale() == "log" and list(ax.get_xticks()) == [0, 2]
    fell = any(r["fallback"] for per in obstacles.values() for r in per.values())
    assert bool(ax.collections) == fell  # fallback points are marked
    # as read back from JSON (string keys) too
    back = json.loads(json.dumps(obstacles))
    assert plot_obstacle_scaling(back, tmp_path / "o.png").stat().st_size > 1000
    path = write_bench_report(tmp_path, results, obstacles=back, obstacle_figure="o.png")
    text = path.read_text()
    section = text.split("## P3: per-step time as obstacles are added")[1]
    assert "min clearance [m]" in section and "solver failures" in section
    for n in (0, 2):
        for b in BACKENDS:
            r = obstacles[n][b]
            assert f"| {n} | {b} | {r['backend']} |" in section
    assert "![per-step time vs obstacle count](o.png)" in section
    if fell:
        assert "Fallbacks:" in section
