"""What the commands share: the app, the input and output errors, loading a scenario, one run
into a directory with a progress bar, and the output directory that is all or nothing."""

from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from ..scenarios import ScenarioError, load_scenario
from . import interrupt

if TYPE_CHECKING:
    from ..sim import Metrics


app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="mpcdrive: safe autonomous driving with Model Predictive Control.",
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain click help: flags without a '<bool>' metavar
)


def _print_version(value: bool) -> None:
    if value:
        from .. import __version__

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
    """A progress bar on stderr (a step callback that does nothing when disabled)."""
    if not enabled:
        yield None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    with (
        _shown(),
        Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total} steps"),
            TimeRemainingColumn(),
            transient=True,
            console=_stderr_console(),
        ) as prog,
    ):
        task = prog.add_task(label, total=total)
        last = [0.0]

        def cb(k: int, n: int) -> None:
            now = time.monotonic()
            if k == n or now - last[0] > 0.1:
                last[0] = now
                prog.update(task, completed=k)

        yield cb


@contextmanager
def _shown():
    """A progress bar is on the terminal in this block (an interrupt shows the cursor again)."""
    interrupt.progress_shown = True
    try:
        yield
    finally:
        interrupt.progress_shown = False


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


def _check_vehicle_flags(vehicle: str | None, plant: str | None) -> None:
    """``--vehicle`` / ``--plant`` of a CommonRoad run: known names, and the vehicle models
    package where they need it."""
    from ..adapters.commonroad_vehicles import PLANT_MODELS, VEHICLES, available

    plants = tuple(PLANT_MODELS.values())
    if vehicle is not None and vehicle not in VEHICLES:
        raise BadInput(f"--vehicle: unknown CommonRoad vehicle {vehicle!r} (known: {', '.join(VEHICLES)})")
    if plant is not None and plant not in plants:
        raise BadInput(f"--plant: unknown CommonRoad plant model {plant!r} (known: {', '.join(plants)})")
    if (vehicle is not None or plant is not None) and not available():
        raise BadInput("--vehicle/--plant need commonroad-vehicle-models (pip install 'mpcdrive[commonroad]')")


def _check_traffic_flags(traffic: str | None, prediction: str | None) -> None:
    """``--traffic`` / ``--prediction`` of a CommonRoad run: known names, a combination that
    exists, and the sumo extra where it is needed."""
    from ..adapters.commonroad_traffic import check_modes

    try:
        traffic, _ = check_modes(traffic, prediction)
    except ValueError as e:
        raise BadInput(str(e)) from None
    if traffic == "sumo":
        from ..adapters.commonroad_sumo import INSTALL_HINT, available

        if not available():
            raise BadInput(f"--traffic sumo needs the sumo extra ({INSTALL_HINT})")


def _run_into(spec, out_dir: Path, show_progress: bool, source: str | None = None, extra_outputs=None, prepare=None):
    """:func:`mpcdrive.runs.run_into` with a progress bar on stderr; a scenario that does not
    build is bad input. CommonRoad plants are built by the CommonRoad adapter."""
    from ..adapters.commonroad_vehicles import commonroad_plant
    from ..runs import BuildError, run_into

    try:
        return run_into(
            spec,
            out_dir,
            lambda label, n: _progress(show_progress, label, n),
            source=source,
            extra_outputs=extra_outputs,
            prepare=prepare,
            plant_factory=commonroad_plant,
        )
    except BuildError as e:
        raise BadInput(str(e)) from None


class OutputAbandoned(Exception):
    """A command failed part-way; its output directory was not created (exit code 1)."""


@contextmanager
def _output_dir(out_dir: Path, flag: str = "--out"):
    """:func:`atomic_output_dir` that, when the block fails, says no partial output was kept; an
    output directory that cannot be made is bad input naming ``flag`` (before the block runs)."""
    from ..io.atomic import OutputPathError, atomic_output_dir

    try:
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
    except OutputPathError as e:  # (raised only on entering: the block's errors are OutputAbandoned)
        raise BadInput(f"{flag}: {e}") from None


def _default_out(stem: str) -> Path:
    return Path("runs") / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}"


def _summary_line(sid: str, m: Metrics) -> str:
    """The run's verdict (``m.verdict``) in words (``UNSAFE:`` first when it collided, left the
    road or diverged, ``FAILED:`` when it missed its goal or an external check), then its
    tracking figures."""
    return (
        f"{m.verdict.line(sid)} | {m.steps} steps, rms |e_y| "
        f"{m.rms_lateral_error_m:.4g} m, final |e_y| {m.final_lateral_error_m:.3g} m, max |steer| "
        f"{m.max_abs_steer_rad:.3f} rad, step p50 {m.solve_time_us.p50:.0f} us"
    )


def _file_stem(file: str) -> str:
    from ..adapters.commonroad_batch import file_stem

    return file_stem(file)
