"""Bench entries per backend, the horizon sweep, cold start, allocations and the bench report:
checked by structure and consistency, never by time."""

import numpy as np
import pytest

from mpcdrive.bench import run_bench
from mpcdrive.bench.extras import cold_start, horizon_sweep, step_allocations
from mpcdrive.plots.bench import make_horizon_figure, plot_horizon_scaling
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
            impls["mpcdrive_osqp"]["rms_lateral_error_m"], rel=1e-4, abs=1e-6)


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
    assert "Obstacle sweep" in text
    assert render_bench_report(results).split("## Speed-up")[0].count("| P1 |") == 3


def test_cold_start_runs_a_fresh_process():
    r = cold_start("fast", steps=20, repeats=1)
    assert r["backend"] == "fast"
    assert 0 < r["import_build_first_step_s"] < r["process_1000_steps_s"]
    assert np.isfinite(r["peak_rss_mib"]) and r["peak_rss_mib"] > 0
