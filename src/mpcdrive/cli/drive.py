"""The commands that drive one scenario: ``list`` and ``run``."""

from __future__ import annotations

from pathlib import Path

import typer

from ..scenarios import ScenarioError, builtin_ids, load_scenario
from .common import (
    BadInput,
    _check_traffic_flags,
    _check_vehicle_flags,
    _default_out,
    _file_stem,
    _load,
    _on_backend,
    _output_dir,
    _run_into,
    _summary_line,
    app,
)


def _load_commonroad(
    file: str,
    vehicle: str | None = None,
    plant: str | None = None,
    traffic: str | None = None,
    prediction: str | None = None,
):
    from ..adapters.commonroad import available, load_commonroad, with_vehicle
    from ..adapters.commonroad_traffic import with_traffic

    if not available():
        raise BadInput(f"{file}: CommonRoad scenarios need the commonroad extra (pip install 'mpcdrive[commonroad]')")
    _check_vehicle_flags(vehicle, plant)
    _check_traffic_flags(traffic, prediction)
    try:
        return with_traffic(with_vehicle(load_commonroad(file), vehicle, plant), traffic, prediction)
    except (OSError, ValueError) as e:
        raise BadInput(f"{file}: {e}") from None


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
        None,
        "--out",
        metavar="DIR",
        help="output directory (default runs/<file name without extension>-<timestamp>; "
        "for a built-in, runs/<id>-<timestamp>)",
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
    traffic: str | None = typer.Option(
        None, "--traffic", help="CommonRoad files: recorded (default) or sumo (SUMO drives the vehicles; extra sumo)"
    ),
    prediction: str | None = typer.Option(
        None,
        "--prediction",
        help="CommonRoad files: known (the recorded futures; default with recorded traffic) or lane "
        "(constant speed along the lane, growing uncertainty; default with sumo)",
    ),
) -> None:
    """Run one scenario; write trajectory.csv, metrics.json, figures, the resolved scenario and
    report.html (an interactive replay)."""
    extra = None
    is_cr = scenario.lower().endswith((".xml", ".xml.gz"))
    prepare = None
    if not is_cr and any(f is not None for f in (plant, vehicle, traffic, prediction)):
        raise BadInput("--plant/--vehicle/--traffic/--prediction are for CommonRoad files (.xml, .xml.gz)")
    if is_cr:
        from ..scenarios import reject_initial_overlap, warn_suspicious

        imported = _load_commonroad(scenario, vehicle, plant, traffic, prediction)
        spec, extra, prepare = imported.spec, imported.write_outputs, imported.prepare_experiment
        try:
            warn_suspicious(reject_initial_overlap(spec, scenario), scenario)
        except ScenarioError as e:
            raise BadInput(str(e)) from None
    else:
        spec = _load(scenario)
    spec = _on_backend(spec, fast, osqp)
    # a file's run is named after the file passed (not the id or benchmark id inside it)
    out_dir = out or _default_out(spec.id if scenario in builtin_ids() else _file_stem(scenario))
    with _output_dir(out_dir) as tmp:
        _, metrics, _, _ = _run_into(spec, tmp, not quiet, source=scenario, extra_outputs=extra, prepare=prepare)
    typer.echo(_summary_line(spec.id, metrics))
    typer.echo(f"wrote {out_dir}")
    if check and not metrics.verdict.passed:
        v = metrics.verdict
        typer.echo(f"mpcdrive: --check: {spec.id} failed ({', '.join(v.problems())}): {'; '.join(v.reasons)}", err=True)
        raise typer.Exit(3)
