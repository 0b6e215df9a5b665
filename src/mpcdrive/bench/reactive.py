"""Baseline: wall time of commonroad-reactive-planner's ``plan()`` on CommonRoad files.

An optional bench helper (docs/benchmarks.md, "Maneuver planner vs commonroad-reactive-planner"),
run in its own environment: commonroad-reactive-planner (2025.1) needs Python < 3.12 and pulls
osqp 0.6.7, so it is no dependency of mpcdrive, and nothing in mpcdrive imports this module::

    python -m mpcdrive.bench.reactive tests/data/commonroad/*.xml* --repeat 5 --loop 30 --json out.json

Per file, for its first planning problem, the planner is set up as its own examples do, with its
shipped configuration (``ReactivePlannerConfiguration()``: dt 0.1 s, 60 steps = 6 s horizon,
replanning every 3 steps, 4 sampling levels, vehicle BMW 320i): route and reference path
(``create_initial_ref_path``), curvilinear frame (``create_coordinate_system``), collision
checker with the road boundary (``ReactivePlanner(config)``). One exception: the planner runs in
one process (``debug.multiproc = False``; ``--multiproc`` restores the shipped 6 worker processes
forked in every call, which hang for good when one of them raises); ``--steps`` sets the horizon.
Only ``plan()`` is timed (``time.perf_counter`` around the call): sampling the trajectory bundle,
level by level until one is valid, kinematic checks, sorting by cost, collision checks and the
output trajectory. Setup is reported once, apart.

* initial: ``plan()`` from the problem's initial state, once cold, then ``--repeat`` times;
* loop: the planner's own closed loop (it follows its plan, replans every 3 steps) for up to
  ``--loop`` ``plan()`` calls, ending earlier at the goal, at a failed or raising plan, at the budget.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from ..adapters.commonroad_file import read_file

INSTALL_HINT = (
    "commonroad-reactive-planner is not installed: it is an optional baseline with an environment of its own "
    "(Python < 3.12), e.g. python3.11 -m venv rp-venv && rp-venv/bin/pip install commonroad-reactive-planner==2025.1, "
    "then PYTHONPATH=src rp-venv/bin/python -m mpcdrive.bench.reactive FILES..."
)


class ReactivePlannerMissing(ImportError):
    """commonroad-reactive-planner (module ``commonroad_rp``) cannot be imported."""


def load_planner() -> SimpleNamespace:
    """The reactive planner's classes and helpers, imported on demand; ReactivePlannerMissing if absent."""
    try:
        from commonroad_rp.reactive_planner import ReactivePlanner
        from commonroad_rp.utility.config import ReactivePlannerConfiguration
        from commonroad_rp.utility.utils_coordinate_system import create_coordinate_system, create_initial_ref_path

        from commonroad.common.file_reader import CommonRoadFileReader  # after commonroad_rp: fail fast without it
    except ImportError as e:
        raise ReactivePlannerMissing(f"{INSTALL_HINT} ({type(e).__name__}: {e})") from e
    return SimpleNamespace(
        reader=CommonRoadFileReader,
        planner=ReactivePlanner,
        config=ReactivePlannerConfiguration,
        ref_path=create_initial_ref_path,
        frame=create_coordinate_system,
    )


@dataclass
class CallTimes:
    """Wall times of ``plan()`` calls [ms]; None without calls."""

    calls: int = 0
    median_ms: float | None = None
    mean_ms: float | None = None
    p99_ms: float | None = None
    max_ms: float | None = None

    @classmethod
    def of(cls, times_s: list[float]) -> CallTimes:
        if not times_s:
            return cls()
        ms = 1e3 * np.asarray(times_s)
        return cls(len(ms), *(round(float(v), 3) for v in (np.median(ms), ms.mean(), np.percentile(ms, 99), ms.max())))


@dataclass
class FileResult:
    """One file's figures; times in ms."""

    file: str
    setup_ms: float | None = None  # route, reference path, curvilinear frame, collision checker (once)
    cold_ms: float | None = None  # first plan() from the initial state
    found: bool | None = None  # that first call returned a trajectory
    samples: int | None = None  # trajectories sampled in its last sampling level
    initial: CallTimes = field(default_factory=CallTimes)  # the repeats after the cold call
    loop: CallTimes = field(default_factory=CallTimes)  # closed-loop replannings, the first included
    loop_steps: int = 0  # closed-loop time steps driven [planner dt]
    loop_end: str | None = None  # goal / not found / calls / budget / trajectory ended / the error raised
    error: str | None = None  # one line: setup or the initial plan() raised


def _one_line(e: Exception) -> str:
    return f"{type(e).__name__}: {e}".splitlines()[0][:200]


def _timed_plan(planner: Any) -> tuple[Any, float]:
    planner.set_desired_velocity(current_speed=planner.x_0.velocity)  # as its examples do before each plan()
    t0 = time.perf_counter()
    out = planner.plan()
    return out, time.perf_counter() - t0


def bench_file(
    file: str | Path, repeat: int = 5, loop: int = 30, budget_s: float = 60.0, multiproc: bool = False, steps: int = 0
) -> FileResult:
    """Time ``plan()`` on one file's first planning problem (module docstring); errors end up in ``error``."""
    rp = load_planner()
    file = Path(file)
    res = FileResult(file.name)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the frame's resampling and smoothing warn on straight roads
            scenario, pps = read_file(rp.reader, file)
            if not pps.planning_problem_dict:
                raise ValueError("no planning problem")
            problem = next(iter(pps.planning_problem_dict.values()))
            config = rp.config()
            config.debug.multiproc = multiproc
            if steps:  # planning horizon [planner steps of dt]; shipped: 60
                config.planning.time_steps_computation = steps
            config.update(scenario=scenario, planning_problem=problem)
            config.planning_problem_set = pps
            t0 = time.perf_counter()
            frame = rp.frame(rp.ref_path(scenario.lanelet_network, problem))
            planner = rp.planner(config)
            planner.set_reference_path(coordinate_system=frame)
            res.setup_ms = round(1e3 * (time.perf_counter() - t0), 3)
            cc = planner.collision_checker
            kw = {"collision_checker": cc, "coordinate_system": frame}
            planner.reset(initial_state_cart=planner.x_0, **kw)  # the curvilinear initial state, as its first
            x0, x0_cl = copy.deepcopy(planner.x_0), copy.deepcopy(planner.x_0_cl)  # plan() sees it (speed mode!)

            def restart() -> None:  # every call from the initial state gets the same input as the cold one
                planner.reset(initial_state_cart=copy.deepcopy(x0), initial_state_curv=copy.deepcopy(x0_cl), **kw)

            restart()
            out, dt_s = _timed_plan(planner)
            res.cold_ms, res.found, res.samples = round(1e3 * dt_s, 3), out is not None, planner.total_count_samples
            times: list[float] = []
            for _ in range(repeat):
                restart()
                times.append(_timed_plan(planner)[1])
            res.initial = CallTimes.of(times)
            if loop > 0:
                restart()
                res.loop, res.loop_steps, res.loop_end = _closed_loop(planner, frame, cc, loop, budget_s)
    except Exception as e:  # any failure of reading, setup or planning is a result of this file
        res.error = _one_line(e)
    return res


def _closed_loop(planner: Any, frame: Any, cc: Any, calls: int, budget_s: float) -> tuple[CallTimes, int, str]:
    """The planner's own loop (its examples): follow the plan, replan every ``replanning_frequency`` steps;
    (plan() times, steps driven, how it ended)."""
    every = planner.config.planning.replanning_frequency
    times: list[float] = []
    plan: Any = None  # (trajectory, longitudinal states, lateral states) of the last plan()
    step = 0
    while not planner.goal_reached():
        k = step % every
        if k == 0:
            if len(times) >= calls or sum(times) >= budget_s:
                return CallTimes.of(times), step, "calls" if len(times) >= calls else "budget"
            try:
                plan, dt_s = _timed_plan(planner)
            except Exception as e:  # the planner raises, e.g. when a sample leaves its reference path's domain
                return CallTimes.of(times), step, _one_line(e)
            times.append(dt_s)
            if plan is None:
                return CallTimes.of(times), step, "not found"
        if 1 + k >= len(plan[0].state_list):
            return CallTimes.of(times), step, "trajectory ended"
        state, curv = plan[0].state_list[1 + k], (plan[1][1 + k], plan[2][1 + k])
        planner.reset(initial_state_cart=state, initial_state_curv=curv, collision_checker=cc, coordinate_system=frame)
        step += 1
    return CallTimes.of(times), step, "goal"


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": sys.version.split()[0]}
    for name in ("commonroad-reactive-planner", "commonroad-route-planner", "commonroad-io", "commonroad-clcs"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "missing"
    return out


def _ms(v: float | None) -> str:
    return "      -" if v is None else f"{v:7.1f}"


def _row(r: FileResult) -> str:
    if r.error:
        return f"{r.file:40s} error: {r.error}"
    return (
        f"{r.file:40s} [ms] cold {_ms(r.cold_ms)} initial median {_ms(r.initial.median_ms)} max {_ms(r.initial.max_ms)}"
        f" found {r.found!s:5s} | loop {r.loop.calls:2d} calls median {_ms(r.loop.median_ms)} max {_ms(r.loop.max_ms)}"
        f" ({r.loop_end})"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mpcdrive.bench.reactive", description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", type=Path, help="CommonRoad .xml or .xml.gz files")
    ap.add_argument("--repeat", type=int, default=5, help="plan() calls from the initial state after the cold one")
    ap.add_argument("--loop", type=int, default=30, help="most plan() calls in the closed loop (0: none)")
    ap.add_argument("--loop-budget-s", type=float, default=60.0, help="stop a file's loop after this much plan() [s]")
    ap.add_argument("--multiproc", action="store_true", help="the shipped default: 6 worker processes per call")
    ap.add_argument("--steps", type=int, default=0, help="planning horizon [steps of 0.1 s]; 0: as shipped (60)")
    ap.add_argument("--json", type=Path, help="write the figures to this file")
    args = ap.parse_args(argv)
    try:
        load_planner()
    except ReactivePlannerMissing as e:
        print(e, file=sys.stderr)
        return 2
    meta = {"versions": _versions(), "cpus": os.cpu_count(), "loadavg_start": os.getloadavg()}
    meta |= {k: v for k, v in vars(args).items() if k not in ("files", "json")}  # repeat, loop, budget, multiproc
    results = []
    for file in args.files:
        results.append(bench_file(file, args.repeat, args.loop, args.loop_budget_s, args.multiproc, args.steps))
        print(_row(results[-1]), flush=True)
    meta["loadavg_end"] = os.getloadavg()
    if args.json:
        args.json.write_text(json.dumps({"meta": meta, "files": [asdict(r) for r in results]}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
