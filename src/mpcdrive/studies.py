"""Studies on the dynamic plant: which model the controller needs at high lateral acceleration,
robustness to parameter errors, and steering delay.

* :func:`compare_models` -- on each packaged track, the F1TENTH car on the Pacejka dynamic plant
  at the speed profile of a given fraction of mu g, driven by dynamic-model MPC, kinematic-model
  MPC, pure pursuit and Stanley (same speed profile, same actuator limits);
* :func:`mismatch_study` -- dynamic MPC whose parameters are off by +-20 % (one at a time, and the
  combined case), plus the kinematic MPC;
* :func:`delay_study` -- steering dead times with and without delay compensation.

Each run is a built-in track scenario modified in code; :func:`write_study` writes the figures,
``study.json`` and ``report.md``. ``mpcdrive compare-models`` runs all three.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .control.baselines import BaselineLimits, PurePursuit, Stanley
from .models.kinematic import KinematicBicycle4, KinematicParams
from .scenarios import build_experiment, load_scenario, run_experiment
from .scenarios.schema import ScenarioSpec
from .sim.analysis import lap_time_s, lateral_acceleration_mps2, road_excess_m
from .sim.metrics import compute_metrics
from .types import SimResult

TRACKS = ("raceway", "hairpins")
CONTROLLERS = ("dynamic MPC", "kinematic MPC", "pure pursuit", "Stanley")
Log = Callable[[str], None]


@dataclass(frozen=True)
class StudyRun:
    """One closed-loop run of a study: its label, the result and its figures of merit.

    summary keys: ``finished`` (lap / road completed), ``lap_time_s`` (None if not), ``rms_e_y_m``,
    ``max_abs_e_y_m``, ``road_excess_m`` (footprint beyond the road edge, 0 inside),
    ``max_abs_lateral_accel_mps2`` (None when the run did not finish), ``solver_failures``,
    ``step_p50_us``.
    """

    label: str
    track: str
    result: SimResult
    summary: dict


def _summary(result: SimResult, exp) -> dict:
    m = compute_metrics(result)
    excess = (
        road_excess_m(result, exp.track, exp.footprint)
        if exp.track is not None and exp.track.has_widths
        else m.max_lane_excess_m
    )
    ay = lateral_acceleration_mps2(result)
    inner = ay[2:-2] if ay.size > 6 else ay  # central differences are one-sided at the ends
    return {
        "finished": bool(result.goal_reached),
        "lap_time_s": lap_time_s(result),
        "profile_time_s": None if exp.speed_profile is None else float(exp.speed_profile.lap_time_s),
        "rms_e_y_m": m.rms_lateral_error_m,
        "max_abs_e_y_m": m.max_abs_lateral_error_m,
        "road_excess_m": excess,
        # after leaving the road the car spins: its accelerations say nothing about the controller
        "max_abs_lateral_accel_mps2": (float(np.max(np.abs(inner))) if inner.size else 0.0)
        if result.goal_reached
        else None,
        "solver_failures": m.solver_failures,
        "step_p50_us": m.solve_time_us.p50,
    }


def _with(spec: ScenarioSpec, **changes) -> ScenarioSpec:
    """A copy of ``spec`` with nested changes given as ``section={key: value}`` (validated)."""
    data = spec.model_dump(mode="json")
    for key, val in changes.items():
        if isinstance(val, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **val}
        else:
            data[key] = val
    return ScenarioSpec.model_validate(data)


def track_spec(track: str, lateral_fraction: float = 0.8) -> ScenarioSpec:
    """The built-in ``track-<track>`` scenario with its speed profile at ``lateral_fraction`` of mu g."""
    spec = load_scenario(f"track-{track}")
    sp = spec.controller.speed_profile.model_dump(mode="json")
    sp["lateral_accel_fraction"] = lateral_fraction
    return _with(spec, controller={"speed_profile": sp})


def _run(label: str, track: str, spec: ScenarioSpec, controller_factory=None) -> StudyRun:
    exp = build_experiment(spec)
    if controller_factory is not None:
        exp = dataclasses.replace(exp, controller=controller_factory(exp))
    result = run_experiment(exp)
    result.meta["id"] = f"{track}: {label}"
    return StudyRun(label, track, result, _summary(result, exp))


def _baseline(kind: str):
    def make(exp):
        spec = exp.spec
        c = spec.controller
        v = spec.vehicle
        a_lo, a_hi = c.accel_limits_mps2 or (-math.inf, math.inf)
        rate = math.inf if c.max_steer_rate_deg_s is None else math.radians(c.max_steer_rate_deg_s)
        lim = BaselineLimits(math.radians(c.max_steer_deg), rate, a_lo, a_hi)
        plant_model = exp.plant.model
        common = dict(wheelbase_m=v.lf_m + v.lr_m, lr_m=v.lr_m)
        if kind == "pure pursuit":
            return PurePursuit(plant_model, exp.path, spec.dt_s, exp.speed_profile, lim, **common)
        # Stanley with the geometric (kinematic) curvature feedforward, no tire knowledge
        ff = KinematicBicycle4(KinematicParams(v.lf_m, v.lr_m))
        return Stanley(plant_model, exp.path, spec.dt_s, exp.speed_profile, lim, feedforward_model=ff, **common)

    return make


def _kinematic_spec(spec: ScenarioSpec) -> ScenarioSpec:
    """The same run with kinematic-model MPC (4 states) on the scenario's dynamic plant."""
    c = spec.controller
    return _with(
        spec,
        vehicle={"model": "kinematic4"},
        plant={"model": spec.plant_model},
        controller={"Q": c.Q[:4], "QN": None if c.QN is None else c.QN[:4]},
    )


def compare_models(
    tracks: Sequence[str] = TRACKS,
    lateral_fraction: float = 0.8,
    controllers: Sequence[str] = CONTROLLERS,
    log: Log | None = None,
) -> list[StudyRun]:
    """Dynamic MPC, kinematic MPC, pure pursuit and Stanley on the Pacejka plant of each track."""
    unknown = [c for c in controllers if c not in CONTROLLERS]
    if unknown:
        raise ValueError(f"unknown controller(s) {', '.join(unknown)} (known: {', '.join(CONTROLLERS)})")
    runs = []
    for track in tracks:
        base = track_spec(track, lateral_fraction)
        for label in controllers:
            t0 = time.perf_counter()
            if label == "dynamic MPC":
                run = _run(label, track, base)
            elif label == "kinematic MPC":
                run = _run(label, track, _kinematic_spec(base))
            else:
                run = _run(label, track, base, _baseline(label))
            runs.append(run)
            if log:
                log(f"{track} / {label}: {format_summary(run.summary)} ({time.perf_counter() - t0:.1f} s)")
    return runs


#: one-at-a-time parameter errors of the mismatch study: label -> plant.param_scale
PARAMETER_ERRORS: dict[str, dict] = {
    "mass +20 %": {"mass": 1.2},
    "mass -20 %": {"mass": 0.8},
    "yaw inertia +20 %": {"yaw_inertia": 1.2},
    "yaw inertia -20 %": {"yaw_inertia": 0.8},
    "cornering stiffness +20 %": {"cornering_stiffness_front": 1.2, "cornering_stiffness_rear": 1.2},
    "cornering stiffness -20 %": {"cornering_stiffness_front": 0.8, "cornering_stiffness_rear": 0.8},
    "friction -20 %": {"friction": 0.8},
    "mass, inertia +20 %, stiffness -20 %": {
        "mass": 1.2,
        "yaw_inertia": 1.2,
        "cornering_stiffness_front": 0.8,
        "cornering_stiffness_rear": 0.8,
    },
}


def mismatch_study(
    track: str = "raceway", lateral_fraction: float = 0.8, errors: Iterable[str] | None = None, log: Log | None = None
) -> list[StudyRun]:
    """Dynamic (Pacejka) MPC with the nominal parameters on a plant whose parameters are off
    (``PARAMETER_ERRORS``), the nominal case, and kinematic MPC (a model error of another kind)."""
    base = track_spec(track, lateral_fraction)
    cases = [("nominal", None)] + [(k, PARAMETER_ERRORS[k]) for k in (errors or PARAMETER_ERRORS)]
    runs = []
    for label, scale in cases:
        spec = base if scale is None else _with(base, plant={"model": "dynamic_pacejka", "param_scale": scale})
        runs.append(_run(label, track, spec))
        if log:
            log(f"{track} / {label}: {format_summary(runs[-1].summary)}")
    runs.append(_run("kinematic MPC (model structure)", track, _kinematic_spec(base)))
    if log:
        log(f"{track} / kinematic MPC: {format_summary(runs[-1].summary)}")
    return runs


def delay_study(
    track: str = "raceway",
    lateral_fraction: float = 0.7,
    dead_times_s: Sequence[float] = (0.05, 0.1, 0.15),
    time_constant_s: float = 0.05,
    log: Log | None = None,
) -> list[StudyRun]:
    """Dynamic MPC with the steering actuator's dead time (and lag), without and with compensation."""
    base = track_spec(track, lateral_fraction)
    runs = []
    for dead in dead_times_s:
        for comp in (False, True):
            spec = _with(
                base,
                plant={"steering_actuator": {"dead_time_s": dead, "time_constant_s": time_constant_s}},
                controller={"delay_compensation": comp},
            )
            label = f"dead time {dead:g} s, {'compensated' if comp else 'uncompensated'}"
            runs.append(_run(label, track, spec))
            if log:
                log(f"{track} / {label}: {format_summary(runs[-1].summary)}")
    return runs


# ----------------------------------------------------------------------------------- output
def format_summary(s: dict) -> str:
    """One line of a run's figures of merit."""
    lap = "did not finish" if not s["finished"] else f"time {s['lap_time_s']:.2f} s"
    ay = s["max_abs_lateral_accel_mps2"]
    return (
        f"{lap}, RMS e_y {s['rms_e_y_m']:.4f} m, max |e_y| {s['max_abs_e_y_m']:.3f} m, road excess "
        f"{s['road_excess_m']:.3f} m" + ("" if ay is None else f", max |a_y| {ay:.2f} m/s^2")
    )


_COLUMNS = [
    ("finished", "finished"),
    ("lap / road time [s]", "lap_time_s"),
    ("RMS e_y [m]", "rms_e_y_m"),
    ("max abs e_y [m]", "max_abs_e_y_m"),
    ("road excess [m]", "road_excess_m"),
    ("max abs a_y [m/s^2]", "max_abs_lateral_accel_mps2"),
    ("solver failures", "solver_failures"),
    ("step p50 [us]", "step_p50_us"),
]


_FORMATS = {
    "lap_time_s": "{:.2f}",
    "rms_e_y_m": "{:.4f}",
    "max_abs_e_y_m": "{:.3f}",
    "road_excess_m": "{:.3f}",
    "max_abs_lateral_accel_mps2": "{:.2f}",
    "step_p50_us": "{:.0f}",
}


def _cell(key: str, v) -> str:
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "yes" if v else "no"
    return _FORMATS.get(key, "{}").format(v)


def _table(runs: Sequence[StudyRun], first: str = "run") -> list[str]:
    lines = ["| " + " | ".join([first] + [c for c, _ in _COLUMNS]) + " |", "|" + "---|" * (len(_COLUMNS) + 1)]
    for r in runs:
        cells = [r.label] + [_cell(k, r.summary[k]) for _, k in _COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def write_study(out_dir: str | os.PathLike, sections: dict[str, list[StudyRun]], intro: str = "") -> Path:
    """Write ``study.json``, ``report.md`` and the figures of the runs into ``out_dir``; returns the
    report path. ``sections``: title -> runs (runs of several tracks are grouped per track)."""
    from .io import write_json
    from .io.atomic import atomic_write_text
    from .plots.laps import plot_lateral_acceleration, plot_speed_map, plot_tracking_comparison

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# mpcdrive — dynamic-model studies", ""]
    if intro:
        lines += [intro, ""]
    data = {}
    for n, (title, runs) in enumerate(sections.items(), 1):
        lines += [f"## {title}", ""]
        data[title] = {}
        for track in dict.fromkeys(r.track for r in runs):
            tr = [r for r in runs if r.track == track]
            data[title][track] = {r.label: r.summary for r in tr}
            lines += [f"### {track}", ""] + _table(tr) + [""]
            stem = f"s{n}_{track}"
            fig = plot_tracking_comparison(
                {r.label: r.result for r in tr},
                out / f"{stem}_tracking.png",
                title=f"{title} — {track}: tracking error and speed",
            )
            lines += [f"![tracking error along the track]({fig.name})", ""]
            for i, r in enumerate(tr):
                if i == 0 or n == 1:
                    safe = "".join(ch if ch.isalnum() else "_" for ch in r.label).strip("_")
                    f1 = plot_speed_map(
                        r.result,
                        out / f"{stem}_{safe}_speed_map.png",
                        title=f"{track}: {r.label} — trajectory coloured by speed",
                    )
                    f2 = plot_lateral_acceleration(r.result, out / f"{stem}_{safe}_lateral_acceleration.png")
                    lines += [f"![{r.label}: speed]({f1.name}) ![{r.label}: lateral acceleration]({f2.name})", ""]
    write_json(out / "study.json", data)
    report = out / "report.md"
    atomic_write_text(report, "\n".join(lines) + "\n")
    return report
