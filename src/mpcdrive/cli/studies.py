"""The commands that write a study up as a report: ``reproduce`` (the paper's experiments),
``compare-avoidance`` (the obstacle formulations), ``bench`` (latency) and ``compare-models``
(vehicle models and controllers at the limit)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import typer

from .common import BadInput, _default_out, _load, _on_backend, _output_dir, _run_into, _summary_line, app


@app.command()
def reproduce(
    out: Path | None = typer.Option(None, "--out", help="output directory (default runs/reproduce-<timestamp>)"),
    only: list[str] | None = typer.Option(
        None, "--only", metavar="ID", help="run only this experiment id (repeatable)"
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
    fast: bool = typer.Option(False, "--fast", help="run the controllers on the compiled fast path (the default)"),
    osqp: bool = typer.Option(False, "--osqp", help="run the controllers on the OSQP reference solver"),
) -> None:
    """Run every paper experiment; write DIR/<id>/, DIR/metrics.json, DIR/report.md and
    DIR/report.html (every experiment's replay, metrics and figures in one page)."""
    from ..experiments import PAPER_EXPERIMENTS, PAPER_VALUES, STEERING_COMPARISONS, TRAJECTORY_OVERLAYS
    from ..io import write_json
    from ..plots import plot_steering_comparison, plot_trajectory_overlay
    from ..report import HtmlRun, ReportEntry, write_reproduce_html, write_reproduce_report

    ids = list(PAPER_EXPERIMENTS)
    if only:
        unknown = [i for i in only if i not in ids]
        if unknown:
            raise BadInput(f"--only: unknown experiment id(s) {', '.join(unknown)} (known: {', '.join(ids)})")
        ids = [i for i in ids if i in only]
    specs = [_on_backend(_load(i), fast, osqp) for i in ids]
    out_dir = out or _default_out("reproduce")
    all_metrics, entries, results, html_runs = {}, [], {}, []
    t0 = time.perf_counter()
    with _output_dir(out_dir) as tmp:
        for n, spec in enumerate(specs, 1):
            typer.echo(f"[{n}/{len(specs)}] {spec.id}", err=True)
            result, metrics, figures, footprint = _run_into(spec, tmp / spec.id, not quiet)
            results[spec.id] = result
            all_metrics[spec.id] = metrics.as_dict()
            entries.append(
                ReportEntry(spec.id, spec.description, metrics, [f"{spec.id}/{Path(f).name}" for f in figures])
            )
            html_runs.append(HtmlRun(spec.id, spec.description, metrics, entries[-1].figures, result, footprint))
            typer.echo("  " + _summary_line(spec.id, metrics), err=True)
        for name, (a, b) in STEERING_COMPARISONS.items():
            if a in results and b in results:
                fig = plot_steering_comparison(
                    {a: results[a], b: results[b]}, tmp / f"steering_{name}.png", title=f"Steering: {a} vs {b}"
                )
                entries.append(
                    ReportEntry(f"{name} comparison", f"steering of {a} and {b} overlaid", {}, [Path(fig).name])
                )
                html_runs.append(HtmlRun(entries[-1].id, entries[-1].description, {}, entries[-1].figures))
        for name, ids_ in TRAJECTORY_OVERLAYS.items():
            have = {i: results[i] for i in ids_ if i in results}
            if len(have) >= 2:
                fig = plot_trajectory_overlay(
                    have, tmp / f"trajectories_{name}.png", title=f"Trajectories: {', '.join(have)}"
                )
                entries.append(ReportEntry(f"{name} trajectories", "trajectories overlaid", {}, [Path(fig).name]))
                html_runs.append(HtmlRun(entries[-1].id, entries[-1].description, {}, entries[-1].figures))
        if "paper-exp5-gaussian" in results:
            fig = _gaussian_cost_map(specs, tmp / "gaussian_cost_map.png")
            entries.append(
                ReportEntry(
                    "Gaussian cost map",
                    "the Gaussian obstacle cost of paper-exp5-gaussian (the paper's Fig. 14)",
                    {},
                    [Path(fig).name],
                )
            )
            html_runs.append(HtmlRun(entries[-1].id, entries[-1].description, {}, entries[-1].figures))
        write_json(tmp / "metrics.json", all_metrics)
        write_reproduce_report(tmp, entries, PAPER_VALUES)
        write_reproduce_html(tmp, html_runs, PAPER_VALUES)
    typer.echo(
        f"{len(specs)} experiments in {time.perf_counter() - t0:.1f} s; report: "
        f"{out_dir / 'report.md'}, {out_dir / 'report.html'}"
    )


@app.command("compare-avoidance")
def compare_avoidance(
    out: Path | None = typer.Option(None, "--out", help="output directory (default runs/avoidance-<timestamp>)"),
    scenario: list[str] | None = typer.Option(
        None, "--scenario", metavar="ID", help="obstacle scenario (repeatable; default: all built-in)"
    ),
    formulation: list[str] | None = typer.Option(
        None, "--formulation", metavar="NAME", help="hard, corridor, potential or gaussian (repeatable; default all)"
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
) -> None:
    """Run every obstacle scenario with every obstacle formulation; write avoidance.md (one table:
    clearance, lane excess, steering, tracking error, solve time), overlaid trajectories and cost maps."""
    from ..experiments import AVOIDANCE_SCENARIOS, FORMULATION_TUNING, FORMULATIONS
    from ..io import write_json
    from ..io.atomic import atomic_write_text
    from ..ocp.avoidance import AvoidanceConfig, obstacle_cost
    from ..plots import plot_cost_map, plot_trajectory_overlay
    from ..scenarios import ScenarioSpec

    sids = list(scenario or AVOIDANCE_SCENARIOS)
    forms = list(formulation or FORMULATIONS)
    bad = [f for f in forms if f not in FORMULATIONS]
    if bad:
        raise BadInput(f"--formulation: unknown {', '.join(bad)} (known: {', '.join(FORMULATIONS)})")
    specs = [_load(sid) for sid in sids]
    for sp in specs:
        if not sp.obstacles:
            raise BadInput(f"--scenario: {sp.id} has no obstacles")
    out_dir = out or _default_out("avoidance")
    rows, table = [], {}
    n_runs, k_run = len(specs) * len(forms), 0
    with _output_dir(out_dir) as tmp:
        for sp in specs:
            runs = {}
            for f in forms:
                k_run += 1
                data = sp.model_dump()
                data["avoidance"] = {**(data.get("avoidance") or {}), **FORMULATION_TUNING[f]}
                data["id"] = f"{sp.id}--{f}"
                spec = ScenarioSpec.model_validate(data)
                typer.echo(f"[{k_run}/{n_runs}] {sp.id} / {f}", err=True)
                result, m, _, _ = _run_into(spec, tmp / sp.id / f, not quiet)
                runs[f] = result
                table.setdefault(sp.id, {})[f] = m.as_dict()
                st = m.solve_time_us
                rows.append(
                    f"| `{sp.id}` | {f} | {m.min_obstacle_clearance_m:.3f} | {m.collisions} | "
                    f"{m.max_lane_excess_m:.3f} | {math.degrees(m.max_abs_steer_rad):.1f} | "
                    f"{math.degrees(m.max_abs_steer_rate_rad_s):.0f} | {m.rms_lateral_error_m:.3f} | "
                    f"{m.solver_failures} | {m.fallbacks} | {'yes' if m.goal_reached else 'no'} | "
                    f"{st.p50:.0f} / {st.p99:.0f} |"
                )
            plot_trajectory_overlay(runs, tmp / f"{sp.id}.png", title=f"{sp.id}: every formulation")
        maps = []
        for f in ("potential", "gaussian"):
            if f in forms:
                import numpy as np

                cfg = AvoidanceConfig(
                    **{k: (tuple(v) if isinstance(v, list) else v) for k, v in FORMULATION_TUNING[f].items()}
                )
                X, Y = np.meshgrid(np.linspace(-2, 2, 161), np.linspace(-1.5, 1.5, 121))
                C = np.minimum(obstacle_cost(cfg, X, Y), 20.0)
                plot_cost_map(
                    X, Y, C, tmp / f"cost_map_{f}.png", title=f"{f} cost around an obstacle at (0, 0) (clipped at 20)"
                )
                maps.append(f"cost_map_{f}.png")
        write_json(tmp / "metrics.json", table)
        head = (
            "| scenario | formulation | min clearance [m] | collisions | lane excess [m] | peak steer [deg] | "
            "peak steer rate [deg/s] | RMS e_y [m] | solver failures | fallbacks | goal reached | solve p50 / p99 [µs] |"
        )
        text = [
            "# Obstacle formulations compared",
            "",
            "Every obstacle scenario driven with each formulation (``hard``: the paper's keep-out constraint as "
            "half-planes on footprint discs; ``corridor``: a convex obstacle-free tube; ``potential`` and "
            "``gaussian``: the paper's soft costs, solved by SQP). Clearance is footprint-to-obstacle; lane excess "
            "is how far the body left the lane. Soft costs give no guarantee: their rows say what happened.",
            "",
            head,
            "|" + "---|" * 12,
            *rows,
            "",
        ]
        text += [f"## {sp.id}\n\n{sp.description}\n\n![{sp.id}]({sp.id}.png)\n" for sp in specs]
        text += [f"![{m}]({m})\n" for m in maps]
        atomic_write_text(tmp / "avoidance.md", "\n".join(text))
    typer.echo(f"{len(specs) * len(forms)} runs; report: {out_dir / 'avoidance.md'}")


def _gaussian_cost_map(specs, path: Path):
    """The paper's Fig. 14: the Gaussian obstacle cost around paper-exp5-gaussian's obstacle."""
    import numpy as np

    from ..ocp.avoidance import obstacle_cost
    from ..plots import plot_cost_map
    from ..scenarios import build_experiment

    spec = next(s for s in specs if s.id == "paper-exp5-gaussian")
    exp = build_experiment(spec)
    cfg = exp.controller.avoidance.config
    ob = exp.obstacles[0]
    ox, oy, _ = ob.pose
    X, Y = np.meshgrid(np.linspace(ox - 2, ox + 2, 161), np.linspace(oy - 1.5, oy + 1.5, 121))
    C = obstacle_cost(cfg, X - ox, Y - oy, float(exp.path.heading(exp.path.project([ox, oy])[0])))
    return plot_cost_map(X, Y, C, path, title=f"Gaussian cost map, sigma = {cfg.sigma_m} m, w = {cfg.weight}")


@app.command()
def bench(
    problem: list[str] | None = typer.Option(
        None,
        "--problem",
        metavar="P",
        help="P1 line, P2 circle with speed, P3 obstacle cost, P4 three-lane traffic (repeatable; default all)",
    ),
    baselines: bool = typer.Option(
        False,
        "--baselines",
        help="also time the cvxpy rebuild and CasADi+IPOPT baselines (cvxpy only without obstacles)",
    ),
    json_file: Path | None = typer.Option(None, "--json", help="write the results as JSON"),
    steps: int = typer.Option(1000, "--steps", min=20, help="closed-loop steps per problem (P4: at most its 300)"),
    baseline_steps: int = typer.Option(
        200, "--baseline-steps", min=20, help="closed-loop steps for the slow baselines (P4: at most its 300)"
    ),
    report: Path | None = typer.Option(
        None,
        "--report",
        help="also measure per-step time against the horizon "
        "(P1, N = 10..100) and the obstacle count (P3, 0..20 obstacles), cold start "
        "and memory; write DIR/bench.md, figures and JSON",
    ),
) -> None:
    """Per-step latency of the benchmark problems P1-P4 of docs/benchmarks.md (median, p99, max;
    warm-up excluded), with collisions and clearance where there are obstacles."""
    from ..bench import PROBLEMS, format_table, run_bench
    from ..io import write_json

    names = [p.upper() for p in (problem or list(PROBLEMS))]
    unknown = [p for p in names if p not in PROBLEMS]
    if unknown:
        raise BadInput(f"--problem: unknown problem(s) {', '.join(unknown)} (known: {', '.join(PROBLEMS)})")
    if report is not None and report.exists():
        raise BadInput(f"--report: {report} already exists")
    log = lambda msg: typer.echo(msg, err=True)  # noqa: E731
    results = run_bench(names, baselines=baselines, steps=steps, baseline_steps=baseline_steps, log=log)
    typer.echo(format_table(results))
    if json_file is not None:
        write_json(json_file, results)
        typer.echo(f"wrote {json_file}")
    if report is not None:
        _bench_report(report, results, log)


def _bench_report(out_dir: Path, results: dict, log) -> None:
    from ..bench.extras import cold_start, horizon_sweep, obstacle_sweep, step_allocations
    from ..bench.runner import BACKENDS
    from ..io import write_json
    from ..plots.bench import plot_horizon_scaling, plot_obstacle_scaling
    from ..report.bench import write_bench_report

    sweep = horizon_sweep(log=log)
    obstacles = obstacle_sweep(log=log)
    cold, alloc = {}, {}
    for b in BACKENDS:
        log(f"cold start and memory: {b}")
        cold[b] = cold_start(b)
        alloc[b] = step_allocations(b)
    note = (
        "Timings on a shared machine vary from run to run: compare ratios measured in one run, and "
        "the medians of repeated runs."
    )
    with _output_dir(out_dir, flag="--report") as tmp:
        plot_horizon_scaling(sweep, tmp / "horizon.png")
        plot_obstacle_scaling(obstacles, tmp / "obstacles.png")
        write_json(
            tmp / "bench.json",
            {
                "latency": results,
                "horizon_sweep_P1": sweep,
                "obstacle_sweep_P3": obstacles,
                "cold_start": cold,
                "allocations": alloc,
            },
        )
        write_bench_report(
            tmp,
            results,
            sweep,
            cold,
            alloc,
            figure="horizon.png",
            note=note,
            obstacles=obstacles,
            obstacle_figure="obstacles.png",
        )
    typer.echo(f"wrote {out_dir / 'bench.md'}")


@app.command("compare-models")
def compare_models_cmd(
    out: Path | None = typer.Option(None, "--out", help="output directory (default runs/compare-models-<timestamp>)"),
    track: list[str] | None = typer.Option(
        None, "--track", metavar="NAME", help="packaged track (repeatable; default all)"
    ),
    lateral_fraction: float = typer.Option(
        0.8, "--lateral-fraction", min=0.05, max=1.0, help="speed profile's lateral acceleration as a fraction of mu g"
    ),
    robustness: bool = typer.Option(
        True, "--robustness/--no-robustness", help="also run the parameter-mismatch and steering-delay studies"
    ),
) -> None:
    """Dynamic- vs kinematic-model MPC vs pure pursuit / Stanley on the Pacejka dynamic plant at high
    lateral acceleration (plus parameter mismatch and steering delay); writes report.md, study.json
    and figures."""
    from ..scenarios.tracks import packaged_track_names
    from ..studies import compare_models, delay_study, mismatch_study, write_study

    tracks = list(track or ["raceway", "hairpins"])
    unknown = [t for t in tracks if t not in packaged_track_names()]
    if unknown:
        raise BadInput(
            f"--track: unknown track(s) {', '.join(unknown)} (packaged: {', '.join(packaged_track_names())})"
        )
    out_dir = out or _default_out("compare-models")
    log = lambda msg: typer.echo(msg, err=True)  # noqa: E731
    t0 = time.perf_counter()
    intro = (
        "F1TENTH car (F1TENTH gym parameters) on the Pacejka dynamic bicycle plant, speed profile limited "
        "by curvature and friction, 0.05 s control period. Road excess: how far the footprint left the "
        "road (0 = stayed on it). Produced by `mpcdrive compare-models`."
    )
    with _output_dir(out_dir) as tmp:  # (made first: an --out that cannot be made stops it before the runs)
        sections = {
            f"Controllers on the Pacejka dynamic plant at {lateral_fraction:g} mu g": compare_models(
                tracks, lateral_fraction, log=log
            )
        }
        if robustness:
            sections[f"Parameter mismatch (dynamic MPC, {tracks[0]}, {lateral_fraction:g} mu g)"] = mismatch_study(
                tracks[0], lateral_fraction, log=log
            )
            sections[f"Steering delay (dynamic MPC, {tracks[0]}, 0.7 mu g, 0.05 s lag)"] = delay_study(
                tracks[0], log=log
            )
        write_study(tmp, sections, intro)
    typer.echo(
        f"{sum(len(r) for r in sections.values())} runs in {time.perf_counter() - t0:.1f} s; "
        f"report: {out_dir / 'report.md'}"
    )
