"""Command-line interface: the only place that parses arguments, converts units for people,
and prints. Exit codes: 0 done, 2 bad input (one line on stderr: file, field, problem), 1 other
failures."""

from __future__ import annotations

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
)


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
        TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total} steps"),
        TimeRemainingColumn(), transient=True, console=_stderr_console(),
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


def _run_into(spec, out_dir: Path, show_progress: bool):
    """Run one scenario and write its files into ``out_dir``; returns (result, metrics, figures)."""
    from .io import write_json, write_trajectory_csv
    from .io.atomic import atomic_write_text
    from .plots import write_run_figures
    from .scenarios import build_experiment, dump_scenario, run_experiment
    from .sim import compute_metrics

    try:
        exp = build_experiment(spec)
    except ValueError as e:
        raise BadInput(f"{spec.id}: {e}") from None
    with _progress(show_progress, spec.id, exp.steps) as cb:
        result = run_experiment(exp, progress=cb)
    metrics = compute_metrics(result, exp.footprint)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_trajectory_csv(result, out_dir / "trajectory.csv")
    write_json(out_dir / "metrics.json", metrics)
    atomic_write_text(out_dir / "scenario.yaml", dump_scenario(spec))
    figures = write_run_figures(result, out_dir)
    return result, metrics, figures


def _default_out(stem: str) -> Path:
    return Path("runs") / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}"


def _summary_line(sid: str, m: dict) -> str:
    st = m["solve_time_us"]
    return (
        f"{sid}: {m['steps']} steps, rms |e_y| {m['rms_lateral_error_m']:.4g} m, final |e_y| "
        f"{m['final_lateral_error_m']:.3g} m, max |steer| {m['max_abs_steer_rad']:.3f} rad, "
        f"failures {m['solver_failures']}, fallbacks {m['fallbacks']}, step p50 {st['p50']:.0f} us"
    )


@app.command("list")
def list_cmd() -> None:
    """List the built-in scenarios, one id a line with a short description."""
    for sid in builtin_ids():
        typer.echo(f"{sid}\t{load_scenario(sid).description}")


@app.command()
def run(
    scenario: str = typer.Argument(..., help="built-in scenario id or a YAML scenario file"),
    out: Path | None = typer.Option(None, "--out", help="output directory (default runs/<id>-<timestamp>)"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
) -> None:
    """Run one scenario; write trajectory.csv, metrics.json, figures and the resolved scenario."""
    from .io.atomic import atomic_output_dir

    spec = _load(scenario)
    out_dir = out or _default_out(spec.id)
    with atomic_output_dir(out_dir) as tmp:
        _, metrics, _ = _run_into(spec, tmp, not quiet)
    typer.echo(_summary_line(spec.id, metrics))
    typer.echo(f"wrote {out_dir}")


@app.command()
def reproduce(
    out: Path | None = typer.Option(None, "--out", help="output directory (default runs/reproduce-<timestamp>)"),
    only: list[str] | None = typer.Option(None, "--only", help="run only these experiment ids"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
) -> None:
    """Run every paper experiment; write DIR/<id>/, DIR/metrics.json and DIR/report.md."""
    from .experiments import PAPER_EXPERIMENTS, PAPER_VALUES, STEERING_COMPARISONS
    from .io import write_json
    from .io.atomic import atomic_output_dir
    from .plots import plot_steering_comparison
    from .report import ReportEntry, write_reproduce_report

    ids = list(PAPER_EXPERIMENTS)
    if only:
        unknown = [i for i in only if i not in ids]
        if unknown:
            raise BadInput(f"--only: unknown experiment id(s) {', '.join(unknown)} (known: {', '.join(ids)})")
        ids = [i for i in ids if i in only]
    specs = [_load(i) for i in ids]
    out_dir = out or _default_out("reproduce")
    all_metrics, entries, results = {}, [], {}
    t0 = time.perf_counter()
    with atomic_output_dir(out_dir) as tmp:
        for n, spec in enumerate(specs, 1):
            typer.echo(f"[{n}/{len(specs)}] {spec.id}", err=True)
            result, metrics, figures = _run_into(spec, tmp / spec.id, not quiet)
            results[spec.id] = result
            all_metrics[spec.id] = metrics
            entries.append(ReportEntry(spec.id, spec.description, metrics,
                                       [f"{spec.id}/{Path(f).name}" for f in figures]))
            typer.echo("  " + _summary_line(spec.id, metrics), err=True)
        for name, (a, b) in STEERING_COMPARISONS.items():
            if a in results and b in results:
                fig = plot_steering_comparison({a: results[a], b: results[b]}, tmp / f"steering_{name}.png",
                                               title=f"Steering: {a} vs {b}")
                entries.append(ReportEntry(f"{name} comparison", f"steering of {a} and {b} overlaid",
                                           {}, [Path(fig).name]))
        write_json(tmp / "metrics.json", all_metrics)
        write_reproduce_report(tmp, entries, PAPER_VALUES)
    typer.echo(f"{len(specs)} experiments in {time.perf_counter() - t0:.1f} s; report: {out_dir / 'report.md'}")


@app.command()
def bench(
    problem: list[str] | None = typer.Option(None, "--problem", help="P1, P2 (repeatable; default all)"),
    baselines: bool = typer.Option(False, "--baselines", help="also time the cvxpy rebuild and CasADi+IPOPT baselines"),
    json_file: Path | None = typer.Option(None, "--json", help="write the results as JSON"),
    steps: int = typer.Option(1000, "--steps", min=20, help="closed-loop steps per problem"),
    baseline_steps: int = typer.Option(200, "--baseline-steps", min=20, help="closed-loop steps for the slow baselines"),
    report: Path | None = typer.Option(None, "--report", help="also measure per-step time against the horizon "
                                       "(P1, N = 10..100), cold start and memory; write DIR/bench.md, a figure and JSON"),
) -> None:
    """Per-step latency of the PERF.md benchmark problems (median, p99, max; warm-up excluded)."""
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
    from .bench.extras import cold_start, horizon_sweep, step_allocations
    from .control.factory import BACKENDS
    from .io import write_json
    from .io.atomic import atomic_output_dir
    from .plots.bench import plot_horizon_scaling
    from .report.bench import write_bench_report

    sweep = horizon_sweep(log=log)
    cold, alloc = {}, {}
    for b in BACKENDS:
        log(f"cold start and memory: {b}")
        cold[b] = cold_start(b)
        alloc[b] = step_allocations(b)
    note = ("Timings on a shared machine vary from run to run: compare ratios measured in one run, and "
            "the medians of repeated runs.")
    with atomic_output_dir(out_dir) as tmp:
        plot_horizon_scaling(sweep, tmp / "horizon.png")
        write_json(tmp / "bench.json", {"latency": results, "horizon_sweep_P1": sweep, "cold_start": cold,
                                        "allocations": alloc})
        write_bench_report(tmp, results, sweep, cold, alloc, figure="horizon.png", note=note)
    typer.echo(f"wrote {out_dir / 'bench.md'}")


def main() -> None:
    """Console-script entry point with the exit codes of CONTRACT.md."""
    try:
        app(standalone_mode=False)
    except BadInput as e:
        typer.echo(f"mpcdrive: {e}", err=True)
        sys.exit(2)
    except FileExistsError as e:
        typer.echo(f"mpcdrive: --out: {e}", err=True)
        sys.exit(2)
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


if __name__ == "__main__":
    main()
