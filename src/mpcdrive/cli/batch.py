"""The commands that drive many runs, on local processes or Ray: ``sweep`` (Monte Carlo over one
scenario) and ``commonroad`` (a folder of CommonRoad files judged by CommonRoad's checker)."""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager
from pathlib import Path

import typer

from .common import (
    BadInput,
    _check_traffic_flags,
    _check_vehicle_flags,
    _default_out,
    _load,
    _output_dir,
    _shown,
    _stderr_console,
    app,
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
    max_final_error: float | None = typer.Option(
        None,
        "--max-final-error",
        help="override of the verdict's final |lateral error| allowed [m] (default: the scenario's "
        "verdict.max_final_lateral_error_m, half the car's width)",
    ),
    max_lane_excess: float | None = typer.Option(
        None,
        "--max-lane-excess",
        help="override of the verdict's lane excess allowed [m] (default: the scenario's verdict.max_lane_excess_m, 0.001)",
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
) -> None:
    """Monte Carlo sweep: run SCENARIO many times with varied values; write runs.csv, summary.json/md, histograms."""
    from ..sweep import SuccessCriteria, SweepError, plan_sweep, run_sweep, write_sweep_outputs

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

    with (
        _shown(),
        Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("runs"),
            TextColumn("{task.fields[failed]} failed"),
            TimeRemainingColumn(),
            transient=True,
            console=_stderr_console(),
        ) as prog,
    ):
        task = prog.add_task("sweep", total=total, failed=0)
        failed = [0]

        def cb(done: int, n: int, row: dict) -> None:
            failed[0] += 0 if row.get("success") else 1
            prog.update(task, completed=done, failed=failed[0])

        yield cb


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
    traffic: str | None = typer.Option(
        None, "--traffic", help="recorded (default) or sumo (SUMO drives the vehicles; extra sumo)"
    ),
    prediction: str | None = typer.Option(
        None, "--prediction", help="known (recorded futures; default with recorded traffic) or lane (default with sumo)"
    ),
) -> None:
    """Drive every CommonRoad file and judge it with CommonRoad's drivability checker; write
    OUT/summary.json, OUT/summary.md and OUT/<file stem>/ per file (as mpcdrive run writes it)."""
    from ..adapters.commonroad import available
    from ..adapters.commonroad_batch import collect_files, run_batch, verdict

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
    _check_traffic_flags(traffic, prediction)
    try:
        paths = collect_files(files)
    except ValueError as e:
        raise BadInput(str(e)) from None
    configure = None
    if any(f is not None for f in (vehicle, plant, traffic, prediction)):
        from functools import partial

        from ..adapters.commonroad_batch import configure_import

        configure = partial(configure_import, vehicle=vehicle, plant=plant, traffic=traffic, prediction=prediction)
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
