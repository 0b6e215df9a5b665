"""One closed-loop run written into a directory: the pieces every command that drives a scenario
shares (``mpcdrive run``, ``reproduce``, ``compare-avoidance``, ``commonroad``)."""

from __future__ import annotations

from pathlib import Path


class BuildError(ValueError):
    """The scenario could not be built into an experiment (bad input)."""


def run_into(
    spec,
    out_dir: Path,
    progress=None,
    source: str | None = None,
    extra_outputs=None,
    prepare=None,
    plant_factory=None,
):
    """Run ``spec`` and write its files into ``out_dir``: ``trajectory.csv``, ``metrics.json``,
    ``scenario.yaml``, the figures and the interactive ``report.html`` (``extra_outputs(result,
    out_dir)`` writes more and returns a dict: under ``commonroad`` a
    :class:`~mpcdrive.sim.CommonRoadCheck`, which becomes the metrics' ``commonroad`` and judges
    the goal, and under ``figures`` the names of figures it wrote; other entries are an error).
    ``progress`` is a context manager factory ``progress(label, steps)`` yielding a step callback
    (or None). Returns (result, metrics, figures, footprint), ``metrics`` a
    :class:`~mpcdrive.sim.Metrics`; BuildError when the scenario does not build. ``prepare(exp)``
    (optional) returns the built experiment to run instead (e.g. another simulator's traffic);
    a plant with a ``close()`` is closed once the run is over. ``plant_factory``: as
    :func:`~mpcdrive.scenarios.build_experiment`'s (a CommonRoad plant needs it)."""
    from contextlib import nullcontext

    from .io import write_json, write_trajectory_csv
    from .io.atomic import atomic_write_text
    from .plots import write_run_figures
    from .report import write_run_html
    from .scenarios import build_experiment, dump_scenario, run_experiment
    from .sim import apply_goal_region, compute_metrics

    out_dir = Path(out_dir).resolve()  # figure paths relative to the working directory would not embed
    try:
        exp = build_experiment(spec, plant_factory=plant_factory)
        if prepare is not None:
            exp = prepare(exp)
    except ValueError as e:
        raise BuildError(f"{source or spec.id}: {e}") from None
    try:
        with progress(spec.id, exp.steps) if progress is not None else nullcontext() as cb:
            result = run_experiment(exp, progress=cb)
    finally:
        close = getattr(exp.plant, "close", None)
        if callable(close):
            close()
    metrics = compute_metrics(result)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_trajectory_csv(result, out_dir / "trajectory.csv")
    write_json(out_dir / "metrics.json", metrics.as_dict())
    atomic_write_text(out_dir / "scenario.yaml", dump_scenario(spec))
    extra_figures = []
    if extra_outputs is not None:
        extra = dict(extra_outputs(result, out_dir))
        extra_figures = [Path(out_dir) / f for f in extra.pop("figures", [])]
        cr = extra.pop("commonroad", None)
        if extra:
            raise ValueError(f"extra_outputs returned unknown entries {sorted(extra)} (known: commonroad, figures)")
        if cr is not None:  # the goal is the planning problem's, the checker's verdicts count too
            metrics = apply_goal_region(metrics, cr.goal_reached, cr)
        write_json(out_dir / "metrics.json", metrics.as_dict())
    figures = list(write_run_figures(result, out_dir)) + extra_figures
    write_run_html(out_dir, result, metrics, figures, exp.footprint, run_id=spec.id, description=spec.description)
    return result, metrics, figures, exp.footprint
