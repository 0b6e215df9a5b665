"""Command-line interface: the only place that parses arguments, converts units for people,
and prints. Exit codes: 0 done, 2 bad input (one line on stderr: file, field, problem), 1 other
failures."""

from __future__ import annotations

import math
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import typer

from .scenarios import ScenarioError, builtin_ids, load_scenario

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="mpcdrive: safe autonomous driving with Model Predictive Control.",
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain click help: flags without a '<bool>' metavar
)


def _print_version(value: bool) -> None:
    if value:
        from . import __version__

        typer.echo(f"mpcdrive {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_print_version, is_eager=True, help="print the version and exit"
    ),
) -> None:
    """mpcdrive: safe autonomous driving with Model Predictive Control."""


class BadInput(Exception):
    """Raised for user input problems; printed as one line, exit code 2."""


@contextmanager
def _progress(enabled: bool, label: str, total: int):
    """A progress bar on stderr (a no-op callback when disabled)."""
    if not enabled:
        yield None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} steps"),
        TimeRemainingColumn(),
        transient=True,
        console=_stderr_console(),
    ) as prog:
        task = prog.add_task(label, total=total)
        last = [0.0]

        def cb(k: int, n: int) -> None:
            now = time.monotonic()
            if k == n or now - last[0] > 0.1:
                last[0] = now
                prog.update(task, completed=k)

        yield cb


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


def _load(name: str):
    try:
        return load_scenario(name)
    except ScenarioError as e:
        raise BadInput(str(e)) from None


def _on_backend(spec, fast: bool, osqp: bool = False):
    """``spec`` with its controller on the compiled fast path when ``fast``, on the OSQP reference
    when ``osqp`` (else as written: ``controller.backend``, compiled by default)."""
    if fast and osqp:
        raise BadInput("--fast and --osqp exclude each other")
    if not (fast or osqp):
        return spec
    backend = "fast" if fast else "osqp"
    return spec.model_copy(update={"controller": spec.controller.model_copy(update={"backend": backend})})


def _load_commonroad(file: str, vehicle: str | None = None, plant: str | None = None):
    from .adapters.commonroad import available, load_commonroad, with_vehicle

    if not available():
        raise BadInput(f"{file}: CommonRoad scenarios need the commonroad extra (pip install 'mpcdrive[commonroad]')")
    _check_vehicle_flags(vehicle, plant)
    try:
        return with_vehicle(load_commonroad(file), vehicle, plant)
    except (OSError, ValueError) as e:
        raise BadInput(f"{file}: {e}") from None


def _check_vehicle_flags(vehicle: str | None, plant: str | None) -> None:
    """``--vehicle`` / ``--plant`` of a CommonRoad run: known names, and the vehicle models
    package where they need it."""
    from .adapters.commonroad_vehicles import PLANT_MODELS, VEHICLES, available

    plants = tuple(PLANT_MODELS.values())
    if vehicle is not None and vehicle not in VEHICLES:
        raise BadInput(f"--vehicle: unknown CommonRoad vehicle {vehicle!r} (known: {', '.join(VEHICLES)})")
    if plant is not None and plant not in plants:
        raise BadInput(f"--plant: unknown CommonRoad plant model {plant!r} (known: {', '.join(plants)})")
    if (vehicle is not None or plant is not None) and not available():
        raise BadInput("--vehicle/--plant need commonroad-vehicle-models (pip install 'mpcdrive[commonroad]')")


def _run_into(spec, out_dir: Path, show_progress: bool, source: str | None = None, extra_outputs=None):
    """:func:`mpcdrive.runs.run_into` with a progress bar on stderr; a scenario that does not
    build is bad input."""
    from .runs import BuildError, run_into

    try:
        return run_into(
            spec,
            out_dir,
            (lambda label, n: _progress(True, label, n)) if show_progress else None,
            source=source,
            extra_outputs=extra_outputs,
        )
    except BuildError as e:
        raise BadInput(str(e)) from None


class OutputAbandoned(Exception):
    """A command failed part-way; its output directory was not created (exit code 1)."""


@contextmanager
def _output_dir(out_dir: Path):
    """:func:`atomic_output_dir` that, when the block fails, says no partial output was kept."""
    from .io.atomic import atomic_output_dir

    with atomic_output_dir(out_dir) as tmp:
        try:
            yield tmp
        except (BadInput, KeyboardInterrupt, OutputAbandoned):
            raise
        except Exception as e:
            msg = " ".join(str(e).split())
            raise OutputAbandoned(
                f"{type(e).__name__}: {msg}; no partial output was kept ({out_dir} not written)"
            ) from e


def _default_out(stem: str) -> Path:
    return Path("runs") / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}"


def _summary_line(sid: str, m: dict) -> str:
    """The run's safety verdict in words (``UNSAFE:`` first when it collided, left the road or
    diverged), then its tracking figures."""
    from .sim import run_verdict

    st = m["solve_time_us"]
    v = run_verdict(m)
    return (
        f"{'UNSAFE: ' if v.unsafe else ''}{sid}: {'; '.join(v.findings)} | {m['steps']} steps, rms |e_y| "
        f"{m['rms_lateral_error_m']:.4g} m, final |e_y| {m['final_lateral_error_m']:.3g} m, max |steer| "
        f"{m['max_abs_steer_rad']:.3f} rad, step p50 {st['p50']:.0f} us"
    )


@app.command("list")
def list_cmd() -> None:
    """List the built-in scenarios, one id a line with a short description."""
    for sid in builtin_ids():
        typer.echo(f"{sid}\t{load_scenario(sid).description}")


@app.command()
def run(
    scenario: str = typer.Argument(
        ..., metavar="SCENARIO", help="built-in scenario id, a YAML scenario file or a CommonRoad .xml"
    ),
    out: Path | None = typer.Option(
        None, "--out", metavar="DIR", help="output directory (default runs/<id>-<timestamp>)"
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
    fast: bool = typer.Option(
        False,
        "--fast",
        help="run the controller on the compiled fast path "
        "(controller.backend: fast, the default; same commands as the OSQP reference)",
    ),
    osqp: bool = typer.Option(
        False, "--osqp", help="run the controller on the OSQP reference solver (controller.backend: osqp)"
    ),
    check: bool = typer.Option(
        False,
        "--check",
        help="exit with code 3 when the run collided, left the road or missed its goal (outputs are still written)",
    ),
    plant: str | None = typer.Option(
        None, "--plant", help="CommonRoad files: the plant, a CommonRoad vehicle model (ks, st, mb)"
    ),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="CommonRoad files: the vehicle (ford_escort, bmw_320i, vw_vanagon; default ford_escort)"
    ),
) -> None:
    """Run one scenario; write trajectory.csv, metrics.json, figures, the resolved scenario and
    report.html (an interactive replay)."""
    extra = None
    is_cr = scenario.lower().endswith((".xml", ".xml.gz"))
    if not is_cr and (plant is not None or vehicle is not None):
        raise BadInput("--plant/--vehicle are for CommonRoad files (.xml, .xml.gz)")
    if is_cr:
        from .scenarios import reject_initial_overlap, warn_suspicious

        imported = _load_commonroad(scenario, vehicle, plant)
        spec, extra = imported.spec, imported.write_outputs
        try:
            warn_suspicious(reject_initial_overlap(spec, scenario), scenario)
        except ScenarioError as e:
            raise BadInput(str(e)) from None
    else:
        spec = _load(scenario)
    spec = _on_backend(spec, fast, osqp)
    # a CommonRoad run is named after the file passed, not the benchmark id inside it
    out_dir = out or _default_out(_file_stem(scenario) if extra is not None else spec.id)
    with _output_dir(out_dir) as tmp:
        _, metrics, _, _ = _run_into(spec, tmp, not quiet, source=scenario, extra_outputs=extra)
    typer.echo(_summary_line(spec.id, metrics))
    typer.echo(f"wrote {out_dir}")
    if check:
        from .sim import run_verdict

        problems = run_verdict(metrics).problems()
        if problems:
            typer.echo(f"mpcdrive: --check: {spec.id} failed: {', '.join(problems)}", err=True)
            raise typer.Exit(3)


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
    from .experiments import PAPER_EXPERIMENTS, PAPER_VALUES, STEERING_COMPARISONS, TRAJECTORY_OVERLAYS
    from .io import write_json
    from .plots import plot_steering_comparison, plot_trajectory_overlay
    from .report import HtmlRun, ReportEntry, write_reproduce_html, write_reproduce_report

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
            all_metrics[spec.id] = metrics
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
    from .experiments import AVOIDANCE_SCENARIOS, FORMULATION_TUNING, FORMULATIONS
    from .io import write_json
    from .io.atomic import atomic_write_text
    from .ocp.avoidance import AvoidanceConfig, obstacle_cost
    from .plots import plot_cost_map, plot_trajectory_overlay
    from .scenarios import ScenarioSpec

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
                table.setdefault(sp.id, {})[f] = m
                st = m["solve_time_us"]
                rows.append(
                    f"| `{sp.id}` | {f} | {m['min_obstacle_clearance_m']:.3f} | {m['collisions']} | "
                    f"{m['max_lane_excess_m']:.3f} | {math.degrees(m['max_abs_steer_rad']):.1f} | "
                    f"{math.degrees(m['max_abs_steer_rate_rad_s']):.0f} | {m['rms_lateral_error_m']:.3f} | "
                    f"{m['solver_failures']} | {m['fallbacks']} | {'yes' if m['goal_reached'] else 'no'} | "
                    f"{st['p50']:.0f} / {st['p99']:.0f} |"
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

    from .ocp.avoidance import obstacle_cost
    from .plots import plot_cost_map
    from .scenarios import build_experiment

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
    from .bench import PROBLEMS, format_table, run_bench
    from .io import write_json

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
    from .bench.extras import cold_start, horizon_sweep, obstacle_sweep, step_allocations
    from .control.factory import BACKENDS
    from .io import write_json
    from .io.atomic import atomic_output_dir
    from .plots.bench import plot_horizon_scaling, plot_obstacle_scaling
    from .report.bench import write_bench_report

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
    with atomic_output_dir(out_dir) as tmp:
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
    from .scenarios.tracks import packaged_track_names
    from .studies import compare_models, delay_study, mismatch_study, write_study

    tracks = list(track or ["raceway", "hairpins"])
    unknown = [t for t in tracks if t not in packaged_track_names()]
    if unknown:
        raise BadInput(
            f"--track: unknown track(s) {', '.join(unknown)} (packaged: {', '.join(packaged_track_names())})"
        )
    out_dir = out or _default_out("compare-models")
    log = lambda msg: typer.echo(msg, err=True)  # noqa: E731
    t0 = time.perf_counter()
    sections = {
        f"Controllers on the Pacejka dynamic plant at {lateral_fraction:g} mu g": compare_models(
            tracks, lateral_fraction, log=log
        )
    }
    if robustness:
        sections[f"Parameter mismatch (dynamic MPC, {tracks[0]}, {lateral_fraction:g} mu g)"] = mismatch_study(
            tracks[0], lateral_fraction, log=log
        )
        sections[f"Steering delay (dynamic MPC, {tracks[0]}, 0.7 mu g, 0.05 s lag)"] = delay_study(tracks[0], log=log)
    intro = (
        "F1TENTH car (F1TENTH gym parameters) on the Pacejka dynamic bicycle plant, speed profile limited "
        "by curvature and friction, 0.05 s control period. Road excess: how far the footprint left the "
        "road (0 = stayed on it). Produced by `mpcdrive compare-models`."
    )
    with _output_dir(out_dir) as tmp:
        write_study(tmp, sections, intro)
    typer.echo(
        f"{sum(len(r) for r in sections.values())} runs in {time.perf_counter() - t0:.1f} s; "
        f"report: {out_dir / 'report.md'}"
    )


@app.command()
def sweep(
    scenario: str = typer.Argument(..., metavar="SCENARIO", help="built-in scenario id or a YAML scenario file"),
    runs: int = typer.Option(100, "--runs", min=1, help="number of runs"),
    seed: int = typer.Option(0, "--seed", min=0, help="seed of the whole sweep (each run gets its own from it)"),
    vary: list[str] | None = typer.Option(
        None,
        "--vary",
        metavar="NAME=DIST",
        help="NAME=DISTRIBUTION (repeatable): uniform(a,b), normal(mu,sigma), offset_uniform, "
        "offset_normal, scale_uniform, scale_normal, choice(v1,...); NAME a dotted path such as initial_state.y_m",
    ),
    set_: list[str] | None = typer.Option(
        None,
        "--set",
        metavar="NAME=VALUE",
        help="NAME=VALUE fixed for every run (repeatable), e.g. road.lane_width_m=0.8",
    ),
    out: Path | None = typer.Option(None, "--out", help="output directory (default runs/sweep-<id>-<timestamp>)"),
    workers: int | None = typer.Option(None, "--workers", min=1, help="local processes (default: all cores)"),
    backend: str = typer.Option("local", "--backend", help="local (process pool) or ray"),
    address: str | None = typer.Option(None, "--address", help="Ray cluster address (default: a new local Ray)"),
    max_final_error: float = typer.Option(
        0.1, "--max-final-error", help="largest final |lateral error| of a successful run [m]"
    ),
    max_lane_excess: float = typer.Option(0.0, "--max-lane-excess", help="largest lane excess of a successful run [m]"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
) -> None:
    """Monte Carlo sweep: run SCENARIO many times with varied values; write runs.csv, summary.json/md, histograms."""
    from .sweep import SuccessCriteria, SweepError, plan_sweep, run_sweep, write_sweep_outputs

    spec = _load(scenario)
    try:
        criteria = SuccessCriteria(max_final_error, max_lane_excess)
        plan = plan_sweep(spec, runs, seed, vary or [], set_ or [], criteria, source=scenario)
        if backend not in ("local", "ray"):
            raise SweepError(f"--backend must be 'local' or 'ray', got {backend!r}")
        if backend == "ray":
            import importlib.util

            if importlib.util.find_spec("ray") is None:
                raise SweepError("--backend ray: Ray is not installed (pip install 'mpcdrive[ray]')")
    except SweepError as e:
        raise BadInput(str(e)) from None
    out_dir = out or _default_out(f"sweep-{spec.id}")
    t0 = time.perf_counter()
    with _output_dir(out_dir) as tmp, _sweep_progress(not quiet, runs) as cb:
        try:
            rows = run_sweep(plan, backend, workers, address, progress=cb)
        except SweepError as e:
            raise BadInput(str(e)) from None
        s = write_sweep_outputs(plan, rows, tmp, backend)
    fb = s["fallbacks"]
    typer.echo(
        f"{spec.id}: {s['successes']}/{s['runs']} runs successful, {s['collisions']['runs']} with collisions, "
        f"{fb['runs_with']} with fallbacks ({fb['total']} steps), {time.perf_counter() - t0:.1f} s"
    )
    typer.echo(f"wrote {out_dir}")


@contextmanager
def _sweep_progress(enabled: bool, total: int):
    """A progress bar over runs on stderr, counting failures (a no-op when disabled); when stderr
    is not a terminal (a log file, CI), a plain line every 5 % of the runs or 10 s instead."""
    if not enabled:
        yield None
        return
    if not sys.stderr.isatty():
        every = max(1, total // 20)
        state = {"failed": 0, "last": time.monotonic()}

        def line(done: int, n: int, row: dict) -> None:
            state["failed"] += 0 if row.get("success") else 1
            now = time.monotonic()
            if done == n or done % every == 0 or now - state["last"] > 10.0:
                state["last"] = now
                typer.echo(f"sweep: {done}/{n} runs, {state['failed']} failed", err=True)

        yield line
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("runs"),
        TextColumn("{task.fields[failed]} failed"),
        TimeRemainingColumn(),
        transient=True,
        console=_stderr_console(),
    ) as prog:
        task = prog.add_task("sweep", total=total, failed=0)
        failed = [0]

        def cb(done: int, n: int, row: dict) -> None:
            failed[0] += 0 if row.get("success") else 1
            prog.update(task, completed=done, failed=failed[0])

        yield cb


def _log_to_stderr() -> None:
    """The library's INFO lines (logger ``mpcdrive``: e.g. the one-time compile notice) go to
    stderr as ``mpcdrive: <message>``."""
    import logging

    log = logging.getLogger("mpcdrive")
    if not log.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("mpcdrive: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)
        log.propagate = False


def _scenario_warnings_as_lines() -> None:
    """Print each :class:`~mpcdrive.types.ScenarioWarning` as one line on stderr,
    ``mpcdrive: warning: <file>: <field>: <problem>`` (other warnings as Python prints them)."""
    import warnings

    from .types import ScenarioWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, ScenarioWarning):
            typer.echo(f"mpcdrive: warning: {' '.join(str(message).split())}", err=True)
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def main() -> None:
    """Console-script entry point. Exit codes: 0 done, 1 other failures, 2 bad input, 3 a
    ``run --check`` that collided, left the road or missed its goal, 130 interrupted."""
    import signal

    def _terminated(signum, frame):  # SIGTERM cleans up like Ctrl-C: no partial output is kept
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _terminated)
    _log_to_stderr()
    _scenario_warnings_as_lines()
    if len(sys.argv) == 1:  # a bare `mpcdrive` shows the help as it is, not folded into a usage error
        sys.argv.append("--help")
    try:
        rc = app(standalone_mode=False)
        if rc == 130:  # typer turns Ctrl-C into a returned exit code 130 in this mode
            raise KeyboardInterrupt
        if isinstance(rc, int) and not isinstance(rc, bool) and rc:
            sys.exit(rc)
    except BadInput as e:
        typer.echo(f"mpcdrive: {e}", err=True)
        sys.exit(2)
    except FileExistsError as e:
        typer.echo(f"mpcdrive: --out: {e}", err=True)
        sys.exit(2)
    except OutputAbandoned as e:
        typer.echo(f"mpcdrive: error: {e}", err=True)
        sys.exit(1)
    except typer.Exit as e:
        sys.exit(e.exit_code)
    except KeyboardInterrupt:
        typer.echo("mpcdrive: interrupted; no partial output was kept", err=True)
        sys.exit(130)
    except Exception as e:
        fmt = getattr(e, "format_message", None)
        code = getattr(e, "exit_code", None)
        if callable(fmt) and isinstance(code, int):  # usage errors carry their own code (2)
            ctx = getattr(e, "ctx", None)
            where = ctx.command_path if ctx is not None else "mpcdrive"
            typer.echo(f"{where}: {' '.join(fmt().split())}", err=True)
            sys.exit(code)
        if type(e).__name__ == "Abort":
            typer.echo("mpcdrive: aborted; no partial output was kept", err=True)
            sys.exit(130)
        typer.echo(f"mpcdrive: error: {type(e).__name__}: {e}", err=True)
        sys.exit(1)


def _file_stem(file: str) -> str:
    from .adapters.commonroad_batch import file_stem

    return file_stem(file)


@app.command("commonroad")
def commonroad_cmd(
    files: list[str] = typer.Argument(
        ..., metavar="FILE", help="CommonRoad files (.xml, .xml.gz) or folders holding them"
    ),
    out: Path | None = typer.Option(None, "--out", help="output directory (default runs/commonroad-<timestamp>)"),
    plant: str | None = typer.Option(None, "--plant", help="the plant, a CommonRoad vehicle model (ks, st, mb)"),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="ford_escort, bmw_320i or vw_vanagon (default ford_escort)"
    ),
    workers: int | None = typer.Option(None, "--workers", min=1, help="local processes (default: all cores)"),
    backend: str = typer.Option("local", "--backend", help="local (process pool) or ray"),
) -> None:
    """Drive every CommonRoad file and judge it with CommonRoad's drivability checker; write
    OUT/summary.json, OUT/summary.md and OUT/<file stem>/ per file (as mpcdrive run writes it)."""
    from .adapters.commonroad import available
    from .adapters.commonroad_batch import collect_files, run_batch, verdict

    if not available():
        raise BadInput(
            "commonroad: CommonRoad scenarios need the commonroad extra (pip install 'mpcdrive[commonroad]')"
        )
    if backend not in ("local", "ray"):
        raise BadInput(f"--backend must be 'local' or 'ray', got {backend!r}")
    if backend == "ray":
        import importlib.util

        if importlib.util.find_spec("ray") is None:
            raise BadInput("--backend ray: Ray is not installed (pip install 'mpcdrive[ray]')")
        if workers is not None:
            raise BadInput("--workers is only for --backend local (Ray uses the cluster's CPUs)")
    _check_vehicle_flags(vehicle, plant)
    try:
        paths = collect_files(files)
    except ValueError as e:
        raise BadInput(str(e)) from None
    configure = None
    if vehicle is not None or plant is not None:
        from functools import partial

        from .adapters.commonroad import with_vehicle

        configure = partial(with_vehicle, vehicle=vehicle, plant=plant)
    out_dir = out or _default_out("commonroad")
    t0 = time.perf_counter()

    def progress(k: int, n: int, row: dict) -> None:
        typer.echo(f"[{k}/{n}] {row['file']} {verdict(row)}", err=True)

    with _output_dir(out_dir) as tmp:
        rows = run_batch(paths, tmp, workers=workers, backend=backend, configure=configure, progress=progress)
    passed = sum(1 for r in rows.values() if r["passed"])
    errors = sum(1 for r in rows.values() if r["error"])
    typer.echo(
        f"{passed}/{len(rows)} files passed, {errors} with errors, {time.perf_counter() - t0:.1f} s; "
        f"summary: {out_dir / 'summary.md'}"
    )


if __name__ == "__main__":
    main()
